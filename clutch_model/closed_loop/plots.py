"""Plot of a closed-loop scenario run: speeds, slip against its target, force, clutch torque."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_scenario(run, path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r, o, sc = run.controlled, run.open_clutch, run.scenario
    t = r.t
    fig, ax = plt.subplots(4, 1, figsize=(9, 10), sharex=True, constrained_layout=True)
    ax[0].plot(t, r.speed_a_rad_s, label="side a (case, gripping wheel)")
    ax[0].plot(t, r.speed_b_rad_s, label="side b (wheel on ice)")
    ax[0].plot(t, o.speed_b_rad_s, "--", color="C1", alpha=0.6, label="side b, clutch open")
    top = 1.5 * float(max(r.speed_a_rad_s.max(), r.speed_b_rad_s.max()))
    ax[0].set_ylim(min(0.0, float(r.speed_b_rad_s.min())), top)
    if o.speed_b_rad_s.max() > top:
        ax[0].annotate(f"open clutch: ice wheel up to {o.speed_b_rad_s.max():.0f} rad/s",
                       xy=(0.35, 0.9), xycoords="axes fraction", fontsize=8, color="C1")
    ax[0].set_ylabel("speed [rad/s]")
    ax[0].legend(loc="upper left", fontsize=8)
    ax[1].plot(t, r.slip_speed_rad_s, label="slip w_a - w_b")
    ax[1].plot(t, [-sc.target_slip(tk) for tk in t], "k:", label="target (-|slip|)")
    ax[1].fill_between(t, 0, 1, where=r.locked, transform=ax[1].get_xaxis_transform(), color="0.85",
                       label="locked")
    lo = min(-6.0, float(np.min(r.slip_speed_rad_s)) * 1.1)
    ax[1].set_ylim(lo, 1.0)
    ax[1].set_ylabel("slip [rad/s]")
    ax[1].legend(loc="lower right", fontsize=8)
    ax[2].plot(t, r.applied_force_n * 1e-3, color="C2")
    ax[2].set_ylabel("force [kN]")
    ax[3].plot(t, r.clutch_torque_nm, label="clutch torque (transmitted)")
    ax[3].plot(t, -r.static_capacity_nm, ":", color="0.4", label="-static capacity")
    ax[3].plot(t, sc.torque_b_nm, "--", color="C3", alpha=0.7, label="torque_b (drive - ice road)")
    ax[3].set_ylabel("torque [N m]")
    ax[3].set_xlabel("time [s]")
    ax[3].legend(loc="lower left", fontsize=8)
    fig.suptitle(f"{sc.name}: {sc.description}", fontsize=10)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
