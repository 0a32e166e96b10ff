"""PNG plots of one run (SI inside; axes in µm, N, m/s², N·m and crank angle in π rad, as they read best)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fmu_bearing.parameters import BearingParameters  # noqa: E402
from mechanism.cosim.record import RunResult  # noqa: E402
from mechanism.output.atomic import save_figure  # noqa: E402
from mechanism.output.figures import FIGURES  # noqa: E402  (re-exported: its home is matplotlib-free)


def crank_pi(r: RunResult) -> np.ndarray:
    """Crank angle in units of pi rad (the paper's x axis)."""
    return r["crank_angle"] / np.pi


def half_clearance(r: RunResult) -> float:
    """Free play per side [m] recorded by the run (P_d/2 for the ball bearing)."""
    return float(r.meta.get("clearance_per_side_m", 0.5 * BearingParameters().radial_clearance))


#: a drawn curve keeps at most about this many points (a panel is at most ~1000 pixels wide)
MAX_POINTS = 4000


def envelope(*ys: np.ndarray, max_points: int = MAX_POINTS) -> np.ndarray:
    """Indices that draw the curves ``ys`` (equal lengths, sampled together) with about ``max_points`` points:
    per bin of consecutive samples the first sample and each curve's minimum and maximum, in order, so that
    every peak stays visible (a min/max envelope); all indices if the curve is short already."""
    n = len(ys[0])
    if n <= max_points:
        return np.arange(n)
    width = -(-n * (1 + 2 * len(ys)) // max_points)     # samples per bin; 1 + 2 len(ys) kept per bin
    m = n - n % width
    start = np.arange(0, m, width)
    keep = [start, np.arange(m, n)]
    for y in ys:
        block = np.asarray(y)[:m].reshape(-1, width)
        keep += [start + np.argmin(block, axis=1), start + np.argmax(block, axis=1)]
    keep.append(np.array([n - 1]))
    return np.unique(np.concatenate(keep))


def _line(ax, x: np.ndarray, y: np.ndarray, *args, **style):
    """``ax.plot(x, y, ...)`` of the min/max envelope of y (``envelope``)."""
    k = envelope(y)
    return ax.plot(x[k], y[k], *args, **style)


def _margins(fig, top: float, left: float = 0.85, right: float = 0.2, bottom: float = 0.55,
             wspace: float = 0.75, hspace: float = 0.7) -> None:
    """Fixed margins [inches] instead of ``tight_layout`` (which lays out every tick label's text once more
    before the drawing does: it was about a third of the plotting time). ``top`` leaves room for the titles;
    ``wspace``/``hspace`` are the gaps between panels [inches]."""
    w, h = fig.get_size_inches()
    axes = [ax for ax in fig.axes if ax.get_visible()]
    spec = axes[0].get_subplotspec().get_gridspec() if axes and axes[0].get_subplotspec() else None
    rows, cols = spec.get_geometry() if spec is not None else (1, 1)
    pw = (w - left - right - (cols - 1) * wspace) / cols       # a panel's mean width and height [inches]
    ph = (h - top - bottom - (rows - 1) * hspace) / rows
    fig.subplots_adjust(left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h,
                        wspace=wspace / pw if cols > 1 else 0.2, hspace=hspace / ph if rows > 1 else 0.2)


def _save(fig, path: Path) -> Path:
    # zlib level 1: a few percent larger files, several times faster to encode than the default 6
    save_figure(fig, path, dpi=120, pil_kwargs={"compress_level": 1})
    plt.close(fig)
    return path


def plot_trajectory(ax, r: RunResult, label: str | None = None, clearance: bool = True) -> None:
    """Journal centre relative to the housing centre [µm], with the clearance circle P_d/2."""
    k = envelope(r["e_x"], r["e_y"])
    ax.plot(r["e_x"][k] * 1e6, r["e_y"][k] * 1e6, lw=0.7, label=label)
    if clearance:
        phi = np.linspace(0, 2 * np.pi, 200)
        c = half_clearance(r) * 1e6
        ax.plot(c * np.cos(phi), c * np.sin(phi), "k--", lw=0.6, label="clearance (per side)")
    ax.set_xlabel("e_x [µm]")
    ax.set_ylabel("e_y [µm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)


def n_balls(r: RunResult) -> int:
    """The number of balls of the run (its configuration, else the FMU's default)."""
    config = r.meta.get("config", {})
    n = config.get("balls") or (config.get("settings") or {}).get("n_balls")
    return int(n) if n else BearingParameters().n_balls


def run_title(r: RunResult) -> str:
    """Speed, joint, and for the ball bearing its ball count, damping and clearance (from the run's configuration)."""
    config = r.meta.get("config", {})
    rpm = config.get("rpm")
    head = f"{rpm:g} rpm" if isinstance(rpm, (int, float)) else "run"
    joint = config.get("joint", "bearing")
    if joint == "ideal":
        return f"{head}, ideal joint"
    settings = dict(config.get("settings") or {})
    if joint == "clearance":
        return f"{head}, journal clearance c = {half_clearance(r) * 1e6:.3g} µm"
    try:
        from fmu_bearing.parameters import from_values
        values = dict(settings)
        if config.get("balls"):
            values["n_balls"] = config["balls"]
        p = from_values(values)
    except (ValueError, TypeError):
        return f"{head}, {joint}"
    damping = {0: "no damping", 1: f"C = {p.damping_coefficient:g} N·s/m per ball", 2: "oil-film damping"}
    return (f"{head}, {p.n_balls} balls, {damping.get(p.damping_model, 'damping ?')}, "
            f"P_d = {p.radial_clearance * 1e6:.3g} µm")


#: the start-up panel shows the first START_REVS revolutions
START_REVS = 0.1


def windows(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, str]:
    """Masks of the start-up (first START_REVS revolutions) and of the steady part (the last whole
    revolution, or the second half of a run shorter than two), and the latter's name; x in π rad."""
    end = float(x[-1]) if len(x) else 0.0
    start = x <= 2 * START_REVS
    if end >= 4.0 - 1e-9:
        lo = 2.0 * np.floor(end / 2.0 + 1e-9) - 2.0
        return start, (x >= lo - 1e-9) & (x <= lo + 2.0 + 1e-9), f"revolution {int(lo / 2) + 1}"
    return start, x >= end / 2, "second half of the run"


def time_panels(rows: int = 1, height: float = 3.6):
    """A figure of ``rows`` x 2 axes: a narrow start-up panel and a wide steady-revolution panel per row."""
    fig, axes = plt.subplots(rows, 2, figsize=(11, height * rows), squeeze=False,
                             gridspec_kw={"width_ratios": [1, 3]})
    return fig, axes


def plot_time(axes_row, x: np.ndarray, series: list[tuple[np.ndarray, np.ndarray, dict]], ylabel: str) -> None:
    """Each (x, y, style) on the start-up panel (full scale) and the steady panel (its own scale)."""
    start_ax, steady_ax = axes_row
    for xs, ys, style in series:
        start, steady, name = windows(xs)
        _line(start_ax, xs[start], ys[start], **style)
        _line(steady_ax, xs[steady], ys[steady], **style)
    start_ax.set_title(f"start-up ({START_REVS:g} rev)", fontsize=9)
    steady_ax.set_title(f"steady: {name}", fontsize=9)
    start_ax.set_ylabel(ylabel)
    for ax in axes_row:
        ax.grid(alpha=0.3)


def _label_x(axes_row) -> None:
    for ax in axes_row:
        ax.set_xlabel("crank angle [π rad]")


def plot_run(r: RunResult, out: Path, ideal: RunResult | None = None, names=None) -> list[Path]:
    """The standard plots of a bearing (or ideal) run; the ideal joint drawn for comparison if given.
    Time plots have a start-up panel beside the steady revolution, so the start-up impacts do not set the
    scale of the steady motion. ``names`` (of ``FIGURES``) draws only those (``mechanism.output.workers``
    shares the figures between processes); None draws all."""
    out = Path(out)
    unknown = set(names or ()) - set(FIGURES)
    if unknown:
        raise ValueError(f"no such plot: {sorted(unknown)} (plots are {FIGURES})")

    def want(name: str) -> bool:
        return names is None or name in names

    paths = []
    x = crank_pi(r)
    title = run_title(r)
    joint = r.meta.get("config", {}).get("joint", "run")
    bearing = r.has("e_x") and np.any(r["e_x"] != 0)

    def series(col: str, scale: float = 1.0) -> list:
        items = []
        if ideal is not None and ideal.has(col):
            items.append((crank_pi(ideal), ideal[col] * scale, {"color": "k", "lw": 1.0, "label": "ideal joint"}))
        items.append((x, r[col] * scale, {"lw": 0.8, "label": joint}))
        return items

    if bearing and want("eccentricity.png"):
        fig, ax = plt.subplots(figsize=(5.5, 5))
        plot_trajectory(ax, r, "journal centre")
        ax.set_title(f"Eccentricity trajectory\n({title})", fontsize=10)
        ax.legend(fontsize=8)
        _margins(fig, top=0.55)
        paths.append(_save(fig, out / "eccentricity.png"))

    for name, col, ylabel, heading in (
            ("slider_acceleration.png", "slider_a", "slider acceleration [m/s²]", "Slider acceleration"),
            ("crank_moment.png", "crank_moment", "crank moment [N·m]", "Driving moment for constant crank speed")):
        if not want(name):
            continue
        fig, axes = time_panels()
        plot_time(axes[0], x, series(col), ylabel)
        _label_x(axes[0])
        axes[0, 1].legend(fontsize=8)
        fig.suptitle(f"{heading} ({title})", fontsize=10)
        _margins(fig, top=0.6)
        paths.append(_save(fig, out / name))

    if want("joint_force.png"):
        fig, axes = time_panels(2, 3.0)
        for row, col in zip(axes, ("F_x", "F_y")):
            plot_time(row, x, series(col), f"joint force {col} [N]")
        _label_x(axes[-1])
        axes[0, 1].legend(fontsize=8)
        fig.suptitle(f"Joint force on the crank (housing) ({title})", fontsize=10)
        _margins(fig, top=0.6, hspace=0.6)
        paths.append(_save(fig, out / "joint_force.png"))

    loads = r.ball_load_columns[:n_balls(r)] if bearing and want("ball_loads.png") else []
    if loads:
        cols = 1 if len(loads) <= 8 else 2
        rows = -(-len(loads) // cols)
        fig, axes = plt.subplots(rows, cols, figsize=(8 * cols, 1.2 * rows + 1.2), sharex=True,
                                 sharey=True, squeeze=False)
        for k, col in enumerate(loads):
            ax = axes[k % rows, k // rows]
            start, steady, name = windows(x)
            _line(ax, x[steady], r[col][steady], lw=0.7)
            ax.set_ylabel(col.replace("ball_load_", "ball "), fontsize=8)
            ax.grid(alpha=0.3)
        for ax in axes[-1]:
            ax.set_xlabel("crank angle [π rad]")
        for k in range(len(loads), rows * cols):
            axes[k % rows, k // rows].set_visible(False)
        peak0 = max(float(np.max(r[c][windows(x)[0]])) if np.any(windows(x)[0]) else 0.0 for c in loads)
        fig.suptitle(f"Load on each ball [N], {windows(x)[2]} (start-up peak {peak0:.3g} N not shown)\n({title})",
                     fontsize=10)
        _margins(fig, top=0.55, wspace=0.6, hspace=0.12)
        paths.append(_save(fig, out / "ball_loads.png"))

    if r.has("energy_residual") and want("energy.png"):
        fig, ax = plt.subplots(figsize=(8, 4))
        for col, label in (("damping_dissipation", "damping dissipation D"), ("contact_energy", "contact energy V"),
                           ("cage_work", "cage work"), ("energy_residual", "residual (coupling)")):
            _line(ax, x, r[col] * 1e3, lw=0.8, label=label)
        ax.set_xlabel("crank angle [π rad]")
        ax.set_ylabel("energy [mJ]")
        ax.set_title(f"Energy account: T + V + D - W_drive - W_cage - E_0 = residual\n({title})", fontsize=10)
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        _margins(fig, top=0.55)
        paths.append(_save(fig, out / "energy.png"))

    if ideal is not None and len(ideal["time"]) >= len(r["time"]) and want("slider_position_error.png"):
        k = len(r["time"])
        fig, axes = time_panels()
        plot_time(axes[0], x, [(x, (r["slider_x"] - ideal["slider_x"][:k]) * 1e6, {"lw": 0.8})],
                  "slider position error [µm]")
        _label_x(axes[0])
        fig.suptitle(f"Slider position minus the ideal joint's ({title})", fontsize=10)
        _margins(fig, top=0.6)
        paths.append(_save(fig, out / "slider_position_error.png"))
    return paths
