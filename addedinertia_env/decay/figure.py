"""The figure of ``addedinertia decay --plot``: fitted envelopes and nu against amplitude."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from addedinertia_env.foundation.atomic import save_figure
from addedinertia_env.decay.amplitudes import READING_RESOLUTION_DEG, read_amplitudes
from addedinertia_env.decay.laws import envelope, law_nu

def plot(result: dict, path: str | Path) -> Path:
    """Amplitudes with the fitted envelopes, and nu against amplitude (textbook vs laws)."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    amp = read_amplitudes(result["file"])
    n = amp.swing - amp.swing[0]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    ax1.errorbar(amp.swing, amp.theta, yerr=READING_RESOLUTION_DEG / 2, fmt="ko", ms=3, label="read amplitudes")
    ax2r = ax2
    for m in result["models"]:
        if m["law"] in ("linear", "linear+quadratic", "linear+coulomb"):
            p = {k: v for k, v in m["params"].items() if k != "theta0"}
            nn = np.linspace(0, n[-1], 200)
            ax1.plot(nn + amp.swing[0], envelope(m["law"], m["params"]["theta0"], p, nn),
                     label=f"{m['law']} (BIC {m['bic']:.1f})")
            th = np.linspace(amp.theta[-1], amp.theta[0], 100)
            ax2r.plot(th, law_nu(m["law"], p, th), label=m["law"])
    ax1.set_xlabel("half swing N")
    ax1.set_ylabel("amplitude theta [deg]")
    ax1.legend(fontsize=8)
    raw = result["textbook"]["raw"]
    ax2.plot(raw["theta_mean_deg"], raw["nu_6_17"], "k.", label="raw decrements, formula 6.17")
    pr = result["textbook"].get("printed")
    if pr:
        ax2.plot(pr["theta_mean_deg"], pr["nu_6_17_printed"], "s", mfc="none", label="textbook printed 6.17")
        ax2.plot(pr["theta_mean_deg"], pr["nu_6_18_printed"], "^", mfc="none", label="textbook printed 6.18")
    ax2.set_xlabel("mean amplitude theta_m [deg]")
    ax2.set_ylabel("nu")
    ax2.legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)
