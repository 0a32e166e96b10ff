"""PNG plots of one run (SI inside; axes in µm, N, m/s², N·m and crank angle in π rad, as they read best)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fmu_bearing.parameters import BearingParameters  # noqa: E402
from mechanism.cosim.record import RunResult  # noqa: E402


def crank_pi(r: RunResult) -> np.ndarray:
    """Crank angle in units of pi rad (the paper's x axis)."""
    return r["crank_angle"] / np.pi


def half_clearance(r: RunResult) -> float:
    """Free play per side [m] recorded by the run (P_d/2 for the ball bearing)."""
    return float(r.meta.get("clearance_per_side_m", 0.5 * BearingParameters().radial_clearance))


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_trajectory(ax, r: RunResult, label: str | None = None, clearance: bool = True) -> None:
    """Journal centre relative to the housing centre [µm], with the clearance circle P_d/2."""
    ax.plot(r["e_x"] * 1e6, r["e_y"] * 1e6, lw=0.7, label=label)
    if clearance:
        phi = np.linspace(0, 2 * np.pi, 200)
        c = half_clearance(r) * 1e6
        ax.plot(c * np.cos(phi), c * np.sin(phi), "k--", lw=0.6, label="clearance (per side)")
    ax.set_xlabel("e_x [µm]")
    ax.set_ylabel("e_y [µm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)


def plot_run(r: RunResult, out: Path, ideal: RunResult | None = None) -> list[Path]:
    """The standard plots of a bearing (or ideal) run; the ideal joint drawn for comparison if given."""
    out = Path(out)
    paths = []
    x = crank_pi(r)
    title = f"{r.meta.get('config', {}).get('rpm', '')} rpm, {r.meta.get('config', {}).get('joint', '')}"
    bearing = r.has("e_x") and np.any(r["e_x"] != 0)

    if bearing:
        fig, ax = plt.subplots(figsize=(5.5, 5))
        plot_trajectory(ax, r, "journal centre")
        ax.set_title(f"Eccentricity trajectory ({title})")
        ax.legend(fontsize=8)
        paths.append(_save(fig, out / "eccentricity.png"))

    fig, ax = plt.subplots(figsize=(8, 4))
    if ideal is not None:
        ax.plot(crank_pi(ideal), ideal["slider_a"], "k", lw=1.0, label="ideal joint")
    ax.plot(x, r["slider_a"], lw=0.7, label=r.meta.get("config", {}).get("joint", "run"))
    ax.set_xlabel("crank angle [π rad]")
    ax.set_ylabel("slider acceleration [m/s²]")
    ax.set_title(f"Slider acceleration ({title})")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    paths.append(_save(fig, out / "slider_acceleration.png"))

    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for ax, col in zip(axes, ("F_x", "F_y")):
        if ideal is not None:
            ax.plot(crank_pi(ideal), ideal[col], "k", lw=1.0, label="ideal joint")
        ax.plot(x, r[col], lw=0.7, label=r.meta.get("config", {}).get("joint", "run"))
        ax.set_ylabel(f"joint force {col} [N]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_title(f"Joint force on the crank (housing) ({title})")
    axes[-1].set_xlabel("crank angle [π rad]")
    paths.append(_save(fig, out / "joint_force.png"))

    fig, ax = plt.subplots(figsize=(8, 4))
    if ideal is not None:
        ax.plot(crank_pi(ideal), ideal["crank_moment"], "k", lw=1.0, label="ideal joint")
    ax.plot(x, r["crank_moment"], lw=0.7, label=r.meta.get("config", {}).get("joint", "run"))
    ax.set_xlabel("crank angle [π rad]")
    ax.set_ylabel("crank moment [N·m]")
    ax.set_title(f"Driving moment for constant crank speed ({title})")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    paths.append(_save(fig, out / "crank_moment.png"))

    loads = r.ball_load_columns
    if loads:
        n = len(loads)
        fig, axes = plt.subplots(n, 1, figsize=(8, 1.1 * n + 1), sharex=True, squeeze=False)
        for ax, col in zip(axes[:, 0], loads):
            ax.plot(x, r[col], lw=0.7)
            ax.set_ylabel(col.replace("ball_load_", "ball "), fontsize=8)
            ax.grid(alpha=0.3)
        axes[0, 0].set_title(f"Load on each ball [N] ({title})")
        axes[-1, 0].set_xlabel("crank angle [π rad]")
        paths.append(_save(fig, out / "ball_loads.png"))

    if r.has("energy_residual"):
        fig, ax = plt.subplots(figsize=(8, 4))
        for col, label in (("damping_dissipation", "damping dissipation D"), ("contact_energy", "contact energy V"),
                           ("cage_work", "cage work"), ("energy_residual", "residual (coupling)")):
            ax.plot(x, r[col] * 1e3, lw=0.8, label=label)
        ax.set_xlabel("crank angle [π rad]")
        ax.set_ylabel("energy [mJ]")
        ax.set_title(f"Energy account: T + V + D - W_drive - W_cage - E_0 = residual ({title})")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        paths.append(_save(fig, out / "energy.png"))

    if ideal is not None and len(ideal["time"]) >= len(r["time"]):
        k = len(r["time"])
        fig, ax = plt.subplots(figsize=(8, 4))
        ax.plot(x, (r["slider_x"] - ideal["slider_x"][:k]) * 1e6, lw=0.7)
        ax.set_xlabel("crank angle [π rad]")
        ax.set_ylabel("slider position error [µm]")
        ax.set_title(f"Slider position minus the ideal joint's ({title})")
        ax.grid(alpha=0.3)
        paths.append(_save(fig, out / "slider_position_error.png"))
    return paths
