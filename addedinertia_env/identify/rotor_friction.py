"""The energy method's model of the motor rotor's bearing friction, ``M_f = f_visc Omega + f_coul tanh(Omega / w_s)``.

The rig block states ``f_visc`` and ``f_coul``; the smoothing rate ``w_s`` of the dry term is the
estimator's own choice, not the simulator's (an estimator must not take its constants from the
law that made the data). See :data:`ROTOR_COULOMB_RATE_SCALE`.
"""

from __future__ import annotations

# Smoothing rate of the rotor's dry friction in the energy method, rad/s.
# Bounded on both sides by what the flywheel's rate estimate can tell:
# * far below the rate the smoothed flywheel angle resolves: one count of the motor encoder over
#   the 0.2 s work-smoothing window (energy_work.WORK_SMOOTHING_S) is 1.9e-3 rad/s for the presets'
#   14-bit encoder (2 pi / 16384 = 3.8e-4 rad), 4.8e-4 rad/s for the 16-bit one of the "good"
#   sensors; any rate a record resolves then gets the full Coulomb torque (tanh(4.8) = 0.9999,
#   tanh(19) = 1 to 1e-16), as a dry bearing gives it, whatever law smoothed it in the rig;
# * far above the rounding noise of a flywheel at rest: the encoder reads a constant there, and
#   the rate from the smoothed angle is zero or rounding noise (eps |psi| / dt, about 1e-11 rad/s
#   for angles of tens of rad at 1 kHz), whose sign a BLAS kernel's rounding picks; seven decades
#   above it, tanh(noise / w_s) is a linear term of 1e-7 f_coul at most, the same on any CPU.
# Measured (docs/RELIABILITY.md section 2b, `python -m addedinertia_env.reports.coulomb_scale`):
# identify() equal across OpenBLAS kernels to 4e-14 for any rate from 1e-2 to 1e-6 rad/s, and
# hard-v0 episodes' as-written errors within 9e-5 points of a sign-like rate (1e-9) at 1e-4.
ROTOR_COULOMB_RATE_SCALE = 1e-4
