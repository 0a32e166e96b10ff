"""PNG plots of one run (SI inside; axes in µm, N, m/s², N·m and crank angle in π rad, as they read best).

Each figure is drawn in two parts: its frame (``build``: the figure, its panels, labels, titles, legend and the
curves without their points: nothing that depends on the run's data) and its filling (``FILL``: the points, the
limits, the texts that depend on the data). ``prepare`` builds the frames before the data exist and draws each
once (so the tick marks, the fonts and the texts that do not change are ready): the output workers do that while
the run runs (issue 11), so that only the filling, drawing and saving are left once the data are complete.
``plot_run`` fills a prepared frame if it fits the run (its ``key``), else builds one: the same functions either
way, so a file is the same bytes whether its frame was prepared or not.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from fmu_bearing.parameters import BearingParameters
from mechanism.cosim.record import RunResult
from mechanism.output.atomic import save_canvas
from mechanism.output.figures import FIGURES, Plan

#: the PNGs' resolution [dots per inch]; the figures are made at it, so that a warm draw (``prepare``) and the
#: save use the same renderer
DPI = 120


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


def _set_line(line, x: np.ndarray, y: np.ndarray) -> None:
    """``line``'s points: the min/max envelope of y (``envelope``)."""
    k = envelope(y)
    line.set_data(x[k], y[k])


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


#: a panel's title stands at its top (axes coordinates), given rather than placed by matplotlib at each draw (which
#: lays out every tick label of the y axis again to see whether an offset text is in the way: ~10 % of the drawing;
#: these panels' y axes have no offset text)
TITLE_Y = 1.0


def _figure(figsize: tuple[float, float]) -> Figure:
    """A figure on its own Agg canvas (no pyplot: nothing global keeps it) at ``DPI``."""
    fig = Figure(figsize=figsize, dpi=DPI)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path: Path) -> Path:
    """The picture ``render`` drew into ``fig``'s canvas as a PNG, written atomically (zlib level 1: a few percent
    larger files, several times faster to encode than the default 6)."""
    save_canvas(fig.canvas, path, compress_level=1)
    return path


def plot_trajectory(ax, r: RunResult, label: str | None = None, clearance: bool = True) -> None:
    """Journal centre relative to the housing centre [µm], with the clearance circle P_d/2."""
    k = envelope(r["e_x"], r["e_y"])
    ax.plot(r["e_x"][k] * 1e6, r["e_y"][k] * 1e6, lw=0.7, label=label)
    if clearance:
        _clearance_circle(ax, half_clearance(r))
    _trajectory_axes(ax)


def _clearance_circle(ax, c: float):
    """The clearance circle of radius ``c`` [m] (drawn in µm)."""
    phi = np.linspace(0, 2 * np.pi, 200)
    return ax.plot(c * 1e6 * np.cos(phi), c * 1e6 * np.sin(phi), "k--", lw=0.6, label="clearance (per side)")


def _trajectory_axes(ax) -> None:
    ax.set_xlabel("e_x [µm]")
    ax.set_ylabel("e_y [µm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)


def n_balls(r: RunResult) -> int:
    """The number of balls of the run (its configuration, else the FMU's default)."""
    return _n_balls(r.meta)


def _n_balls(meta: dict) -> int:
    config = meta.get("config", {})
    n = config.get("balls") or (config.get("settings") or {}).get("n_balls")
    return int(n) if n else BearingParameters().n_balls


def run_title(r: RunResult) -> str:
    """Speed, joint, and for the ball bearing its ball count, damping and clearance (from the run's configuration)."""
    return _title(r.meta)


def _title(meta: dict) -> str:
    config = meta.get("config", {})
    rpm = config.get("rpm")
    head = f"{rpm:g} rpm" if isinstance(rpm, (int, float)) else "run"
    joint = config.get("joint", "bearing")
    if joint == "ideal":
        return f"{head}, ideal joint"
    settings = dict(config.get("settings") or {})
    if joint == "clearance":
        return f"{head}, journal clearance c = {_clearance(meta) * 1e6:.3g} µm"
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


def _clearance(meta: dict) -> float:
    return float(meta.get("clearance_per_side_m", 0.5 * BearingParameters().radial_clearance))


#: the start-up panel shows the first START_REVS revolutions
START_REVS = 0.1
#: crank angles [π rad] this close are the same end of a window (the recorded crank angle of a run of whole
#: revolutions ends ~1e-9 short of them)
ANGLE_TOL = 1e-6


def windows(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, str]:
    """Masks of the start-up (first START_REVS revolutions) and of the steady part (the last whole
    revolution, or the second half of a run shorter than two), and the latter's name; x in π rad."""
    end = float(x[-1]) if len(x) else 0.0
    start = x <= 2 * START_REVS
    if end >= 4.0 - ANGLE_TOL:
        lo = 2.0 * np.floor(end / 2.0 + ANGLE_TOL) - 2.0
        return start, (x >= lo - ANGLE_TOL) & (x <= lo + 2.0 + ANGLE_TOL), f"revolution {int(lo / 2) + 1}"
    return start, x >= end / 2, "second half of the run"


def spans(end: float) -> tuple[tuple[float, float], tuple[float, float], str]:
    """The crank angle spans [π rad] of ``windows``' start-up and steady windows of a run ending at ``end``
    (rounded to ``ANGLE_TOL``), and the steady window's name: the panels' x limits, the same whether the end is
    planned (``figures.Plan``) or recorded."""
    end = float(np.round(end, 6))
    if end >= 4.0 - ANGLE_TOL:
        lo = 2.0 * np.floor(end / 2.0 + ANGLE_TOL) - 2.0
        steady, name = (lo, lo + 2.0), f"revolution {int(lo / 2) + 1}"
    else:
        steady, name = (end / 2, end), "second half of the run"
    return (0.0, min(2 * START_REVS, end)), steady, name


def _xlim(ax, span: tuple[float, float]) -> None:
    """x limits of ``span`` with autoscale's margins (5 % each side)."""
    lo, hi = span
    pad = 0.05 * (hi - lo) if hi > lo else 0.5
    ax.set_xlim(lo - pad, hi + pad)


def time_panels(rows: int = 1, height: float = 3.6):
    """A figure of ``rows`` x 2 axes: a narrow start-up panel and a wide steady-revolution panel per row."""
    fig = _figure((11, height * rows))
    axes = fig.subplots(rows, 2, squeeze=False, gridspec_kw={"width_ratios": [1, 3]})
    return fig, axes


def plot_time(axes_row, x: np.ndarray, series: list[tuple[np.ndarray, np.ndarray, dict]], ylabel: str) -> None:
    """Each (x, y, style) on the start-up panel (full scale) and the steady panel (its own scale)."""
    lines = _time_row(axes_row, [style for _, _, style in series], ylabel)
    _fill_time_row(axes_row, lines, [(xs, ys) for xs, ys, _ in series])


def _time_row(axes_row, styles: list[dict], ylabel: str) -> list[tuple[Any, Any]]:
    """``plot_time``'s frame: a curve per style on each panel (no points yet), titles, label, grid; the curves."""
    start_ax, steady_ax = axes_row
    lines = [(start_ax.plot([], [], **style)[0], steady_ax.plot([], [], **style)[0]) for style in styles]
    start_ax.set_title(f"start-up ({START_REVS:g} rev)", fontsize=9, y=TITLE_Y)
    steady_ax.set_title("steady", fontsize=9, y=TITLE_Y)
    start_ax.set_ylabel(ylabel)
    for ax in axes_row:
        ax.grid(alpha=0.3)
    return lines


def _frame_time_row(axes_row, end: float) -> None:
    """The x limits and the steady panel's title of a run ending at ``end`` [π rad] (``spans``)."""
    start, steady, name = spans(end)
    _xlim(axes_row[0], start)
    _xlim(axes_row[1], steady)
    axes_row[1].set_title(f"steady: {name}", fontsize=9, y=TITLE_Y)


def _fill_time_row(axes_row, lines, series: list[tuple[np.ndarray, np.ndarray]]) -> None:
    """``plot_time``'s filling: each curve's points in the start-up and the steady window, the x limits and the
    steady panel's title (the window of the last series), the y limits."""
    # paired from the end: the run's curve is the last; an ideal run without this column leaves the ideal's empty
    for (start_line, steady_line), (xs, ys) in zip(list(lines)[::-1], series[::-1]):
        start, steady, _ = windows(xs)
        _set_line(start_line, xs[start], ys[start])
        _set_line(steady_line, xs[steady], ys[steady])
    _frame_time_row(axes_row, float(series[-1][0][-1]) if len(series[-1][0]) else 0.0)
    _rescale_y(axes_row)


def _rescale_y(axes) -> None:
    """The y limits of ``axes`` from their curves' points, as autoscale makes them."""
    for ax in axes:
        ax.relim()
    for ax in axes:
        ax.autoscale_view(scalex=False)


def _label_x(axes_row) -> None:
    for ax in axes_row:
        ax.set_xlabel("crank angle [π rad]")


@dataclass
class Frame:
    """A figure without its data (``build``): ``key`` what it was built for (``frame_key``), ``panels`` the axes,
    ``lines`` its curves in the order ``FILL`` gives them their points, ``dynamic`` the artists that depend on the
    data (y axes, curves, legends, data's texts: drawn over ``background``, the rest drawn once: ``render``)."""
    name: str
    key: tuple
    fig: Any
    panels: list
    lines: list = field(default_factory=list)
    dynamic: list = field(default_factory=list)
    background: Any = None
    drawn_for: tuple | None = None


#: the curves of the time plots: (file, columns, y label, heading)
TIME_PLOTS = {
    "slider_acceleration.png": (("slider_a",), "slider acceleration [m/s²]", "Slider acceleration"),
    "crank_moment.png": (("crank_moment",), "crank moment [N·m]", "Driving moment for constant crank speed"),
    "joint_force.png": (("F_x", "F_y"), "joint force {} [N]", "Joint force on the crank (housing)"),
}


def frame_key(name: str, meta: dict, ideal: bool, loads: tuple[str, ...]) -> tuple:
    """What the frame of ``name`` depends on: the run's title, joint and clearance (``meta``), whether an ideal
    counterpart is drawn, the ball-load columns drawn."""
    joint = meta.get("config", {}).get("joint", "run")
    return (name, _title(meta), joint, _clearance(meta), ideal if name in TIME_PLOTS else None,
            loads if name == "ball_loads.png" else None)


def _dynamic(ax) -> list:
    """The artists of panel ``ax`` drawn over the background: its y axis (ticks, labels, grid), curves, legend."""
    return [ax.yaxis, *ax.get_lines(), *([ax.get_legend()] if ax.get_legend() else [])]


def build(name: str, meta: dict, ideal: bool, loads: tuple[str, ...] = ()) -> Frame:
    """The frame of figure ``name`` for a run of ``meta``, with or without an ``ideal`` curve, with the ball-load
    columns ``loads`` (ball_loads.png)."""
    frame = _build(name, meta, ideal, loads)
    for artist in frame.dynamic:
        artist.set_animated(True)     # (left out of the figure's drawing: the background)
    return frame


def _build(name: str, meta: dict, ideal: bool, loads: tuple[str, ...]) -> Frame:
    key = frame_key(name, meta, ideal, loads)
    title = _title(meta)
    if name == "eccentricity.png":   # (both axes scale with the data: drawn whole, no background)
        fig = _figure((5.5, 5))
        ax = fig.subplots()
        line = ax.plot([], [], lw=0.7, label="journal centre")[0]
        _clearance_circle(ax, _clearance(meta))
        _trajectory_axes(ax)
        ax.set_title(f"Eccentricity trajectory\n({title})", fontsize=10, y=TITLE_Y)
        ax.legend(fontsize=8)
        _margins(fig, top=0.55)
        return Frame(name, key, fig, [ax], [line])
    if name in TIME_PLOTS or name == "slider_position_error.png":
        columns, ylabel, heading = TIME_PLOTS.get(name, ((None,), "slider position error [µm]",
                                                         "Slider position minus the ideal joint's"))
        joint = meta.get("config", {}).get("joint", "run")
        styles = [{"lw": 0.8}] if name not in TIME_PLOTS else \
            [{"color": "k", "lw": 1.0, "label": "ideal joint"}] * ideal + [{"lw": 0.8, "label": joint}]
        fig, axes = time_panels(len(columns), 3.0 if len(columns) > 1 else 3.6)
        lines = [_time_row(row, styles, ylabel.format(col)) for row, col in zip(axes, columns)]
        _label_x(axes[-1])
        if name in TIME_PLOTS:
            axes[0, 1].legend(fontsize=8)
        fig.suptitle(f"{heading} ({title})", fontsize=10)
        _margins(fig, top=0.6, **({"hspace": 0.6} if len(columns) > 1 else {}))
        panels = list(axes.flat)
        return Frame(name, key, fig, panels, lines, [a for ax in panels for a in _dynamic(ax)])
    if name == "ball_loads.png":
        cols = 1 if len(loads) <= 8 else 2
        rows = -(-len(loads) // cols)
        fig = _figure((8 * cols, 1.2 * rows + 1.2))
        axes = fig.subplots(rows, cols, sharex=True, sharey=True, squeeze=False)
        lines = []
        for k, col in enumerate(loads):
            ax = axes[k % rows, k // rows]
            lines.append(ax.plot([], [], lw=0.7)[0])
            ax.set_ylabel(col.replace("ball_load_", "ball "), fontsize=8)
            ax.grid(alpha=0.3)
        for ax in axes[-1]:
            ax.set_xlabel("crank angle [π rad]")
        for k in range(len(loads), rows * cols):
            axes[k % rows, k // rows].set_visible(False)
        fig.suptitle(f"Load on each ball [N]\n({title})", fontsize=10)
        _margins(fig, top=0.55, wspace=0.6, hspace=0.12)
        panels = [axes[k % rows, k // rows] for k in range(len(loads))]
        return Frame(name, key, fig, panels, lines, [fig._suptitle, *(a for ax in panels for a in _dynamic(ax))])
    if name == "energy.png":
        fig = _figure((8, 4))
        ax = fig.subplots()
        lines = [ax.plot([], [], lw=0.8, label=label)[0] for label in ENERGY.values()]
        ax.set_xlabel("crank angle [π rad]")
        ax.set_ylabel("energy [mJ]")
        ax.set_title(f"Energy account: T + V + D - W_drive - W_cage - E_0 = residual\n({title})", fontsize=10,
                     y=TITLE_Y)
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        _margins(fig, top=0.55)
        return Frame(name, key, fig, [ax], lines, _dynamic(ax))
    raise ValueError(f"no such plot: {name!r} (plots are {FIGURES})")


#: the curves of energy.png: column -> label
ENERGY = {"damping_dissipation": "damping dissipation D", "contact_energy": "contact energy V",
          "cage_work": "cage work", "energy_residual": "residual (coupling)"}


def _frame_x(frame: Frame, start: float, end: float) -> None:
    """The data-independent part of ``frame`` for a run from ``start`` to ``end`` [π rad of crank angle]: the x
    limits (``spans``) and the steady panels' titles."""
    if frame.name == "eccentricity.png":
        return
    if frame.name == "ball_loads.png":
        for ax in frame.panels:
            _xlim(ax, spans(end)[1])
    elif frame.name == "energy.png":
        _xlim(frame.panels[0], (float(np.round(start, 6)), float(np.round(end, 6))))
    else:
        for j in range(0, len(frame.panels), 2):
            _frame_time_row(frame.panels[j:j + 2], end)


def _fill_eccentricity(frame: Frame, r: RunResult, ideal, x) -> None:
    k = envelope(r["e_x"], r["e_y"])
    frame.lines[0].set_data(r["e_x"][k] * 1e6, r["e_y"][k] * 1e6)
    for ax in frame.panels:
        ax.relim()
        ax.autoscale_view()


def _fill_time(frame: Frame, r: RunResult, ideal, x) -> None:
    columns = TIME_PLOTS[frame.name][0]
    for j, col in enumerate(columns):
        series = ([(crank_pi(ideal), ideal[col])] if ideal is not None and ideal.has(col) else []) + [(x, r[col])]
        _fill_time_row(frame.panels[2 * j:2 * j + 2], frame.lines[j], series)


def _fill_position_error(frame: Frame, r: RunResult, ideal, x) -> None:
    k = len(r["time"])
    _fill_time_row(frame.panels, frame.lines[0], [(x, (r["slider_x"] - ideal["slider_x"][:k]) * 1e6)])


def _fill_ball_loads(frame: Frame, r: RunResult, ideal, x) -> None:
    start, steady, name = windows(x)
    loads = frame.key[-1]      # (the run's ball-load columns: the frame fits the run)
    for line, col in zip(frame.lines, loads):
        _set_line(line, x[steady], r[col][steady])
    peak0 = max(float(np.max(r[c][start])) if np.any(start) else 0.0 for c in loads)
    frame.fig.suptitle(f"Load on each ball [N], {name} (start-up peak {peak0:.3g} N not shown)\n({run_title(r)})",
                       fontsize=10)
    _frame_x(frame, float(x[0]), float(x[-1]))
    _rescale_y(frame.panels)


def _fill_energy(frame: Frame, r: RunResult, ideal, x) -> None:
    for line, col in zip(frame.lines, ENERGY):
        _set_line(line, x, r[col] * 1e3)
    _frame_x(frame, float(x[0]), float(x[-1]))
    _rescale_y(frame.panels)


#: each figure's filling: (frame, run, ideal or None, crank angle in π rad)
FILL = {"eccentricity.png": _fill_eccentricity, "slider_acceleration.png": _fill_time,
        "crank_moment.png": _fill_time, "joint_force.png": _fill_time, "ball_loads.png": _fill_ball_loads,
        "energy.png": _fill_energy, "slider_position_error.png": _fill_position_error}


def _planned_loads(meta: dict) -> tuple[str, ...]:
    return tuple(f"ball_load_{k + 1}" for k in range(_n_balls(meta)))


def prepare(plan: Plan, names) -> dict[str, Frame]:
    """The frames of the figures ``names`` of a run as ``plan`` describes it, their backgrounds drawn (``render``:
    the x limits and titles of a run ending at ``plan.x_end``); the figures a run of that joint does not draw are
    skipped."""
    joint = plan.meta.get("config", {}).get("joint", "bearing")
    frames = {}
    for name in names:
        if joint != "bearing" and name in ("ball_loads.png", "energy.png") or joint == "ideal" and (
                name == "eccentricity.png") or not plan.ideal and name == "slider_position_error.png":
            continue
        frame = build(name, plan.meta, plan.ideal, _planned_loads(plan.meta))
        if frame.dynamic and plan.x_end is not None and plan.x_end > 0:   # (a frame without is drawn whole)
            _frame_x(frame, 0.0, plan.x_end)
            _draw_background(frame)
            for ax in frame.panels:   # the y axes' tick marks made now (the background leaves the y axes out)
                ax.yaxis.get_major_ticks(Y_TICKS)
        frames[name] = frame
    return frames


#: tick marks made beforehand on a prepared frame's y axes (these panels show 4-9; more are made when drawn)
Y_TICKS = 10


def _static_state(frame: Frame) -> tuple:
    """What the background shows that a run could change: the panels' x limits and titles, the figure's title."""
    suptitle = frame.fig._suptitle
    return (tuple(ax.get_xlim() for ax in frame.panels), tuple(ax.get_title() for ax in frame.panels),
            None if suptitle is None or suptitle in frame.dynamic else suptitle.get_text())


def _draw_background(frame: Frame) -> None:
    """Draw everything of ``frame`` but its ``dynamic`` artists and keep the picture (``render``)."""
    canvas = frame.fig.canvas
    canvas.draw()
    frame.background = canvas.copy_from_bbox(frame.fig.bbox)
    frame.drawn_for = _static_state(frame)


def render(frame: Frame) -> None:
    """Draw ``frame`` into its canvas: its background (drawn again if the run changed it: ``_static_state``), then
    its ``dynamic`` artists over it, in the order a whole drawing puts them (y axis, curves, legend: their z order)."""
    if not frame.dynamic:
        frame.fig.canvas.draw()
        return
    if frame.background is None or frame.drawn_for != _static_state(frame):
        _draw_background(frame)
    canvas = frame.fig.canvas
    canvas.restore_region(frame.background)
    renderer = canvas.get_renderer()
    for artist in frame.dynamic:
        artist.draw(renderer)


def _drawn(r: RunResult, ideal: RunResult | None) -> dict[str, bool]:
    """Which figures a run (and its ideal counterpart) has the data for."""
    bearing = r.has("e_x") and bool(np.any(r["e_x"] != 0))
    return {"eccentricity.png": bearing, "slider_acceleration.png": True, "crank_moment.png": True,
            "joint_force.png": True, "ball_loads.png": bearing and bool(r.ball_load_columns[:n_balls(r)]),
            "energy.png": r.has("energy_residual"),
            "slider_position_error.png": ideal is not None and len(ideal["time"]) >= len(r["time"])}


def plot_run(r: RunResult, out: Path, ideal: RunResult | None = None, names=None,
             frames: dict[str, Frame] | None = None) -> list[Path]:
    """The standard plots of a bearing (or ideal) run; the ideal joint drawn for comparison if given.
    Time plots have a start-up panel beside the steady revolution, so the start-up impacts do not set the
    scale of the steady motion. ``names`` (of ``FIGURES``) draws only those (``mechanism.output.workers``
    shares the figures between processes); None draws all. ``frames``: prepared frames (``prepare``), used (and
    removed from it) where they fit the run."""
    out = Path(out)
    unknown = set(names or ()) - set(FIGURES)
    if unknown:
        raise ValueError(f"no such plot: {sorted(unknown)} (plots are {FIGURES})")
    x = crank_pi(r)
    drawn = _drawn(r, ideal)
    loads = tuple(r.ball_load_columns[:n_balls(r)])
    paths = []
    for name in FIGURES:
        if not drawn[name] or names is not None and name not in names:
            continue
        key = frame_key(name, r.meta, ideal is not None, loads)
        frame = (frames or {}).pop(name, None)
        if frame is None or frame.key != key:
            frame = build(name, r.meta, ideal is not None, loads)
        FILL[name](frame, r, ideal, x)
        render(frame)
        paths.append(_save(frame.fig, out / name))
    return paths
