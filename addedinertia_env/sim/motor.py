"""The DC motor's electrical side, integrated exactly.

``L di/dt = u - R i - k_e Omega`` has time constant ``L/R`` (about 1 ms), comparable with
the sample period, so explicit Runge-Kutta on ``i`` is unstable for steps above about
2.8 L/R (physics.md section 2). With ``u`` and ``Omega`` held over a step the equation is
linear, and its exact solution is used instead::

    i(t) = i_ss + (i0 - i_ss) exp(-t R / L),   i_ss = (u - k_e Omega) / R

Modes (what the drive does with the controller's command):

* ``passive``: terminals open, no current, the terminal voltage is the back-EMF;
* ``voltage``: the command is a terminal voltage, clipped to the supply;
* ``current``: the drive's current loop picks the voltage that brings ``i`` to the
  command by the end of the sample (dead-beat), clipped to the supply; the command itself
  is clipped to the current limit.
"""

from __future__ import annotations

import numpy as np

from addedinertia_env.rig.signals import MODES, MotorCommand


def terminal_voltage(cmd: MotorCommand, i0, omega, *, R, L, k_e, u_max, i_max, sample_dt, decay=None, lag=0.0):
    """Voltage the drive holds over the next sample, V (works on arrays). ``decay``: the current's
    decay over a sample, ``exp(-sample_dt R / L)``, when the caller keeps it (else computed here).

    ``lag`` (-): a current driver with its own bandwidth (``exp(-sample_dt / tau)``,
    :func:`~.forces.driver_lag`; 0: dead-beat) aims each sample at
    ``target + (i0 - target) lag`` instead of the (clipped) command ``target``: a first-order
    loop with time constant ``tau``."""
    a = np.exp(-sample_dt * R / L) if decay is None else decay
    value = cmd.value
    if cmd.mode == "current" and np.any(np.asarray(lag) != 0):
        target = np.minimum(np.maximum(value, -i_max), i_max)
        value = target + (i0 - target) * lag
    return drive_voltage(MODES.index(cmd.mode), value, i0, omega, R, k_e, u_max, i_max, a)


def drive_voltage(mode, value, i0, omega, R, k_e, u_max, i_max, decay):
    """:func:`terminal_voltage` with the mode as its index in :data:`MODES` (0 passive, 1 current,
    2 voltage) and the current's decay over a sample ``exp(-sample_dt R / L)`` given, V.

    Plain arguments (floats or arrays), so that the batched rig's compiled loop
    (:mod:`.kernels`) runs this very function for each environment.
    """
    if mode == 2:  # voltage: the command, clipped to the supply
        return np.minimum(np.maximum(value, -u_max), u_max)
    if mode == 1:  # current: dead-beat to the (clipped) command by the end of the sample
        target = np.minimum(np.maximum(value, -i_max), i_max)
        i_ss = (target - decay * i0) / (1.0 - decay)
        return np.minimum(np.maximum(R * i_ss + k_e * omega, -u_max), u_max)
    return k_e * omega  # passive: open circuit, the terminals show the back-EMF


def current_step(i0, u, omega, h, *, R, L, k_e):
    """Exact current after ``h`` seconds, and its mean over the step, A.

    The mean is what produces torque over the step, so ``k_t * mean * dpsi`` is the
    motor's mechanical work exactly when ``Omega`` is constant.
    """
    tau = L / R
    i_ss = (u - k_e * omega) / R
    decay = np.exp(-h / tau)
    i1 = i_ss + (i0 - i_ss) * decay
    mean = i_ss + (i0 - i_ss) * tau / h * (1.0 - decay)
    return i1, mean
