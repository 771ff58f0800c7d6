"""The water every hydrodynamic formula of the project assumes, defined once.

Fresh water near 20 C (998.2 kg/m^3 in the IAPWS-95 tables, rounded to 1000 kg/m^3) and
gravity 9.81 m/s^2: the values the BEM caches ``configs/rigs/*.bem.json`` were solved with
(their ``rho`` and ``g``), which Lamb's and strip theory's estimates, the cross-flow
damping and the course-stability check must share to be comparable.
"""

from __future__ import annotations

RHO_WATER = 1000.0  # kg/m^3, fresh water near 20 C
GRAVITY = 9.81  # m/s^2
