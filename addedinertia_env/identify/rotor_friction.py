"""The energy method's model of the motor rotor's bearing friction, ``M_f = f_visc Omega + f_coul tanh(Omega / w_s)``.

The rig block states ``f_visc`` and ``f_coul``; the smoothing rate ``w_s`` of the dry term is the
estimator's own choice, not the simulator's (an estimator must not take its constants from the
law that made the data). See :data:`ROTOR_COULOMB_RATE_SCALE`.
"""

from __future__ import annotations

import numpy as np

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


CREEP_SPAN_S = 2.0  # s, the longest stretch of a hold fitted (cost; a coast's law shows within it)
CREEP_MIN_TRAVEL_STEPS = 20  # motor-encoder steps the flywheel must creep over a hold for its law to be read


def creep_rate_scale(t, psi, i, a: int, b: int, J_f: float, f_visc: float, f_coul: float, k_t: float,
                     psi_step: float) -> float | None:
    """The rate (rad/s) over which the rotor's dry friction sets in, read from the flywheel's coast in a hold
    (samples ``a..b``) where the motor drives no current; None where the record does not show it.

    The block states ``f_coul`` but not how the dry torque goes through zero rate. A flywheel left turning
    slowly in a hold coasts by ``J_f Omega' = -f_visc Omega - f_coul tanh(Omega / w)``: for each ``w`` on a
    grid, and each starting rate near the one the first 0.2 s show, that coast is integrated and fitted to
    the encoder's angle (the start angle free); the ``w`` of the best fit is the law's. With a sign-like dry
    friction (``w`` at :data:`ROTOR_COULOMB_RATE_SCALE`) the coast is a constant deceleration; a smoothed
    one slows less as the rate falls. Read only where the current is idle (its torque's rms under 5 % of
    ``f_coul``), the flywheel coasts over :data:`CREEP_MIN_TRAVEL_STEPS` encoder steps, the best ``w`` is
    inside the grid, its fit explains the coast to a step (or 3e-3 of the travel) rms, and it fits at least
    four times better (residual sum of squares) than the block's sign-like law.
    """
    if not f_coul > 0.0 or not J_f > 0.0 or b - a < 100:
        return None
    b = min(b, int(np.searchsorted(t, t[a] + CREEP_SPAN_S)))  # the coast's first seconds tell the law
    seg = np.asarray(psi[a:b + 1], dtype=float)
    cur = np.asarray(i[a:b + 1], dtype=float)
    if k_t * float(np.sqrt(np.mean(cur**2))) > 0.05 * f_coul:
        return None
    travel = float(seg[-1] - seg[0])
    step = psi_step if psi_step > 0.0 else 0.0
    if abs(travel) < max(CREEP_MIN_TRAVEL_STEPS * step, 1e-6):
        return None
    tau = np.asarray(t[a:b + 1], dtype=float) - float(t[a])
    early = tau <= min(0.2, 0.5 * tau[-1])
    start_rate = float(np.polyfit(tau[early], seg[early], 2)[1])
    if start_rate == 0.0:
        return None
    sign = np.sign(start_rate)
    widths = np.logspace(np.log10(ROTOR_COULOMB_RATE_SCALE), -1.0, 121)  # rad/s, the grid of w
    starts = abs(start_rate) * np.linspace(0.7, 1.3, 41)
    W, S = np.meshgrid(widths, starts, indexing="ij")
    w_flat, omega = W.ravel(), S.ravel().copy()
    angle = np.zeros((len(tau), len(w_flat)))
    h = np.diff(tau)

    def slowing(o):  # the coast's deceleration, rad/s^2, for every (w, start) pair
        return (f_visc * o + f_coul * np.tanh(o / w_flat)) / J_f

    for k in range(len(h)):  # midpoint steps of the coast (the rate only falls; it stops at zero)
        mid = np.maximum(omega - 0.5 * h[k] * slowing(omega), 0.0)
        new = np.maximum(omega - h[k] * slowing(mid), 0.0)
        angle[k + 1] = angle[k] + 0.5 * h[k] * (omega + new)
        omega = new
    model = sign * angle
    resid = (seg - seg.mean())[:, None] - (model - model.mean(axis=0))
    rss = np.einsum("ij,ij->j", resid, resid).reshape(W.shape)
    best = rss.min(axis=1)  # per w, over the starting rates
    j = int(np.argmin(best))
    if not 0 < j < len(widths) - 1:
        return None
    if np.sqrt(best[j] / len(tau)) > max(step, 3e-3 * abs(travel)) or not best[j] * 4.0 < best[0]:
        return None
    den = best[j - 1] - 2.0 * best[j] + best[j + 1]
    frac = 0.5 * (best[j - 1] - best[j + 1]) / den if den > 0 else 0.0
    return float(10.0 ** (np.log10(widths[j]) + frac * (np.log10(widths[1]) - np.log10(widths[0]))))
