"""Summary figures of a run and the files a person can open (CSV with units in the headers, JSON).

The samples themselves are recorded by ``mechanism.cosim.record`` (``RunResult``). Every file is
written to a temporary name in its folder and renamed when complete, so a reader (or a full disk, or
an interrupt) never sees a truncated file; ``output_lock`` keeps a second run out of a folder in use.
"""
from __future__ import annotations

import contextlib
import copy
import csv
import json
import math
import os
import warnings
from pathlib import Path

import numpy as np

from ..cosim.record import RunResult, energy_summary, unit_of
from .atomic import atomic_open
from .figures import FIGURES
from .life import run_life


def _figures(r: RunResult, rows: slice) -> dict:
    """Peak figures of the samples ``rows`` (a slice: the columns are views, not copies)."""
    def peak(values):
        return float(np.nanmax(values)) if values.size else math.nan

    def column(name):
        return r[name][rows]

    some = column("time").size > 0
    out = {
        "max_eccentricity_m": peak(np.hypot(column("e_x"), column("e_y"))),
        "peak_joint_force_N": peak(np.hypot(column("F_x"), column("F_y"))),
        "slider_acceleration_min_m_s2": float(np.nanmin(column("slider_a"))) if some else math.nan,
        "slider_acceleration_max_m_s2": peak(column("slider_a")),
        "crank_moment_min_N_m": float(np.nanmin(column("crank_moment"))) if some else math.nan,
        "crank_moment_max_N_m": peak(column("crank_moment")),
        "max_constraint_violation_m": peak(np.abs(column("constraint_violation"))),
    }
    loads = r.ball_load_columns   # the peak over all balls: the largest of each ball's peak (no stacked copy)
    out["max_ball_load_N"] = _peak_of_columns([column(c) for c in loads]) if loads else None
    return out


def _peak_of_columns(columns: list[np.ndarray]) -> float:
    """``np.nanmax`` of the columns side by side, without stacking them (the largest of each column's peak;
    NaN, with numpy's warning, only if every value is NaN)."""
    if not columns[0].size:
        return math.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)   # an all-NaN column: warned below if all are
        peaks = np.array([np.nanmax(c) for c in columns])
    return float(np.nanmax(peaks))


def summary(r: RunResult) -> dict:
    """Peak figures of the whole run and of the second crank revolution alone (key ``rev2``)."""
    t = r["time"]
    period = r.meta.get("crank_period_s")
    result = {"status": r.status, "message": r.message, "meta": r.meta, "samples": len(t)}
    if len(t) == 0:
        return result
    streamed = r.streamed      # a streamed run: the whole table's figures were accumulated as it was recorded
    result["all"] = _figures(r, slice(None)) if streamed is None else dict(streamed.figures)
    energy = energy_summary(r)
    if energy is not None:
        result["energy"] = energy
    result["life"] = run_life(r)     # bearing rating life (docs/bearing-life.md); None for other joints
    half = 0.5 * float(r.meta.get("output_interval_s") or 0.0) + 1e-12   # the step count is rounded
    if period and t[-1] >= 2 * period - half:
        if streamed is not None and streamed.rev2 is not None:
            result["rev2"] = copy.deepcopy(streamed.rev2)
            return result
        window = r if streamed is None else streamed.window   # (a streamed run kept the rows of this window)
        t = window["time"]
        # the samples with period - half <= t <= 2 period + half (the times rise): a slice, so views
        rev2 = slice(int(np.searchsorted(t, period - half, side="left")),
                     int(np.searchsorted(t, 2 * period + half, side="right")))
        result["rev2"] = _figures(window, rev2)
        result["rev2"]["life"] = run_life(window, (period, 2 * period))
        if streamed is not None:   # the window's figures kept, its rows let go
            streamed.rev2, streamed.window = copy.deepcopy(result["rev2"]), None
    return result


class OutputFolderInUse(RuntimeError):
    """Another run holds the lock on the output folder."""


LOCK_NAME = ".run.lock"


@contextlib.contextmanager
def output_lock(out: Path):
    """Hold an exclusive lock on the output folder ``out`` (created if missing) for the ``with`` block;
    ``OutputFolderInUse`` at once if another process holds it. The lock file (``.run.lock``) stays."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fd = os.open(out / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            import fcntl
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except ImportError:  # pragma: no cover - Windows
            import msvcrt
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
    except OSError:
        holder = os.read(fd, 64).decode(errors="replace").strip()
        os.close(fd)
        raise OutputFolderInUse(f"output folder {out} is in use by another run (pid {holder or '?'}); "
                                f"choose another --out or wait") from None
    try:
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
        _remove_stale_temporaries(out)
        yield out
    finally:
        os.close(fd)


def _remove_stale_temporaries(out: Path) -> None:
    """Remove the temporary files (``.<name>.<pid>.tmp``, atomic_open's and the streamed table's) a run killed in
    this folder left behind: the folder's lock is held, so no other run is writing one."""
    for stale in [*out.glob(".*.tmp"), *out.glob(".*.tmp.png")]:
        try:
            stale.unlink()
        except OSError:
            pass


#: rows formatted and written at a time by ``write_csv``: a chunk's text (~100 kB at 33 columns) stays below
#: glibc's mmap threshold, so the heap does not keep megabytes of freed chunks resident (issue 11: 2,000 rows
#: kept ~5 MB of a 20-revolution run's peak)
CSV_CHUNK_ROWS = 256


def csv_line(n: int) -> str:
    """The format of a row of ``n`` numbers in timeseries.csv (csv.writer's row format and line end)."""
    return ",".join(["%.10g"] * n) + "\r\n"


def write_csv(r: RunResult, path: Path) -> None:
    """timeseries.csv: one header row 'name [unit]', then one row per sample (written atomically)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(path, "w", newline="") as f:
        csv.writer(f).writerow([f"{c} [{unit_of(c)}]" for c in r.columns])
        line = csv_line(len(r.columns))
        for k in range(0, len(r.data), CSV_CHUNK_ROWS):   # a chunk at a time: no list of the whole file
            f.write("".join([line % row for row in map(tuple, r.data[k:k + CSV_CHUNK_ROWS].tolist())]))


def write_rows(rows: list[dict], columns: tuple[tuple[str, str], ...], path: Path, digits: int = 15) -> None:
    """A table of a study: header 'name [unit]' (just 'name' without a unit), one row per dict; floats to
    ``digits`` significant digits, missing values (absent or None) as empty cells; written atomically."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow([f"{c} [{u}]" if u else c for c, u in columns])
        for row in rows:
            w.writerow(["" if row.get(c) is None else (f"{row[c]:.{digits}g}" if isinstance(row[c], float) else row[c])
                        for c, _ in columns])


def write_json(data: dict, path: Path) -> None:
    """``data`` as indented JSON (written atomically)."""
    with atomic_open(path, "w") as f:
        f.write(json.dumps(data, indent=2, default=float) + "\n")


def read_csv(path: Path) -> RunResult:
    """Read a timeseries.csv written by ``write_csv`` back (units are stripped from the names)."""
    with open(path) as f:
        header = next(csv.reader(f))
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return RunResult([h.split(" [")[0] for h in header], data)


def write_outputs(result: RunResult, out: Path, ideal: RunResult | None = None, plots: bool = True,
                  workers=None) -> dict:
    """timeseries.csv, summary.json (with the ideal joint's figures if given) and the PNG plots into ``out``.

    Returns the figures of summary.json plus ``plots``, the PNG files written. If a CSV cannot be written
    (a full disk) summary.json still is, with ``write_error``, and the OSError is raised. ``workers``
    (``mechanism.output.workers.OutputWorkers``) draw the plots while the CSV files are written; without,
    they are drawn here, after the CSV files.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    draw = plots and len(result["time"]) > 1
    shares = []
    if draw and workers is not None:
        from mechanism.output.workers import ColumnsOf
        from mechanism.output.workers import shares as shares_of
        run_sent = ColumnsOf(result, plotted_columns(result))     # only the plotted columns, as raw bytes
        job, ideal_sent = _ideal_sent(ideal)
        shares = [(k, names) for k, names in enumerate(shares_of(len(workers)))
                  if workers.submit(k, job, run_sent, out, ideal_sent, names=names)]
    try:
        figures = _write_tables(result, out, ideal)
    finally:   # the workers' files are complete before anything else happens (an error is raised after)
        drawn = {}
        for k, names in shares:
            try:
                drawn[names] = workers.result(k, job, result, out, _ideal_source(ideal), names=names)
            except BaseException as err:   # noqa: BLE001 - raised below, after the other share is complete
                drawn[names] = err
    plotted = []
    if draw:
        for value in drawn.values():
            if isinstance(value, BaseException):
                raise value
            plotted += value
        rest = tuple(name for name in FIGURES if not any(name in names for names in drawn))
        if rest:   # no worker (or one that could not take its share): drawn here
            from mechanism.output.plots import plot_run
            plotted += plot_run(result, out, _ideal_here(ideal, result), names=rest)
        order = {name: k for k, name in enumerate(FIGURES)}
        plotted.sort(key=lambda path: order[Path(path).name])
    figures["plots"] = [str(p) for p in plotted]   # returned only (summary.json is written before the plots)
    return figures


#: the columns ``plots.plot_run`` reads (besides the ball loads): the workers receive only these (issue 11)
PLOTTED = ("time", "crank_angle", "e_x", "e_y", "slider_a", "crank_moment", "F_x", "F_y", "slider_x",
           "damping_dissipation", "contact_energy", "cage_work", "energy_residual")


def plotted_columns(r: RunResult) -> tuple[str, ...]:
    """The columns of ``r`` that ``plots.plot_run`` reads (``PLOTTED`` and the ball loads), in ``r``'s order."""
    return tuple(c for c in r.columns if c in PLOTTED or c.startswith("ball_load_"))


#: the figures drawn from the run alone (no ideal curve in them): a worker draws them while the ideal counterpart
#: runs, after which the command keeps only ``DRAWN_WITH_IDEAL`` of the run's table (``start_run_plots``)
RUN_ONLY = ("eccentricity.png", "ball_loads.png", "energy.png")
#: the other figures (drawn with the ideal curve): with two workers, the second draws them all (``finish_outputs``)
#: while the first draws ``RUN_ONLY``: over frames prepared during the run (``plots.prepare``) the figures take ~30-80
#: ms each once the data are complete, and the second worker, whose figures wait for the ideal counterpart, has the
#: time to prepare their frames (at a lower priority, ``workers.SECOND_NICE``); one worker draws them after ``RUN_ONLY``
REST = (("slider_acceleration.png", "joint_force.png"), ("crank_moment.png", "slider_position_error.png"))
#: the run's columns the other figures read (``plots.plot_run``), ``COMPARED`` among them
DRAWN_WITH_IDEAL = ("time", "crank_angle", "slider_a", "crank_moment", "F_x", "F_y", "slider_x")


def drawn_by(n: int, ideal: bool) -> tuple[tuple[str, ...], ...]:
    """The figures each of ``n`` output workers draws, in the order it draws them (its frames are prepared in that
    order while the run runs, ``workers.OutputWorkers``): with an ``ideal`` counterpart, ``RUN_ONLY`` and the rest
    as ``finish_outputs`` shares them; without, ``workers.shares``."""
    if not ideal:
        from mechanism.output.workers import shares
        return shares(n)[:n]
    rest = tuple(name for name in FIGURES if name in REST[0] + REST[1])
    return (RUN_ONLY + rest,)[:n] if n <= 1 else (RUN_ONLY, rest)


def run_only_columns(columns: list[str]) -> tuple[str, ...]:
    """The columns of ``columns`` that only ``RUN_ONLY``'s figures read (with the crank angle and the time): a streamed
    run hands them to the first output worker during the run (``stream.for_run``)."""
    return tuple(c for c in columns if c in ("time", "crank_angle") or c.startswith("ball_load_")
                 or (c in PLOTTED and c not in DRAWN_WITH_IDEAL))


def start_run_plots(result: RunResult, out: Path, workers) -> tuple | None:
    """Hand the first output worker ``RUN_ONLY``'s figures of ``result`` (its plotted columns as raw bytes), so
    that the command can write the run's table and let it go before the ideal counterpart runs (issue 11);
    ``finish_outputs`` collects them. None if there is no worker to take them (then keep the whole table)."""
    from mechanism.output.workers import ColumnsOf
    stream = result.streamed.stream if result.streamed is not None else None
    if workers is None or len(result["time"]) <= 1:
        if stream is not None and stream.gathers(0):
            _read_back(result)
        return None
    remove_previous(out, FIGURES)
    if stream is not None and stream.gathers(0):   # the columns went to the worker during the run: the rest now
        names = stream.gathers(0)
        tail = stream.tail(0)
        if tail is None or not workers.submit(0, "plots_gathered", ColumnsOf(tail, names), Path(out), None,
                                              names=RUN_ONLY):
            _read_back(result)
            return None
    else:
        names = plotted_columns(result)
        if not workers.submit(0, "plots", ColumnsOf(result, names), Path(out), None, names=RUN_ONLY):
            return None
    # should the worker die, the figures are drawn in-process from timeseries.csv (written by then), with the
    # run's meta, status and message (the CSV has none: ball count and titles come from the meta)
    meta, status, message = result.meta, result.status, result.message

    def reread() -> RunResult:
        r = read_csv(Path(out) / "timeseries.csv")
        return RunResult(r.columns, r.data, meta, status, message)
    return 0, ColumnsOf(reread, names)


def _read_back(result: RunResult) -> None:
    """A streamed run whose gathered columns are not with a worker (it died): the columns it lacks read back from its
    complete timeseries.csv (its own kept columns stay as they are), so that it can be drawn here."""
    stream = result.streamed.stream
    if stream.read_back:
        return
    if stream.error is not None:   # the table could not be written (a full disk): its error, as at its commit
        raise stream.error
    stream.read_back = True
    back = read_csv(stream.path if stream.committed else stream.tmp)
    data = np.empty((len(result.data), len(back.columns)))
    for k, name in enumerate(back.columns):
        data[:, k] = result[name] if result.has(name) else back[name]
    result.columns, result.data = back.columns, data


def finish_outputs(figures: dict, result: RunResult, out: Path, ideal: RunResult | None, workers, drawing: tuple,
                   plots: bool = True) -> dict:
    """``write_outputs`` after ``start_run_plots`` and ``write_run_table``: the figures with the ideal curve
    (``result``: at least ``DRAWN_WITH_IDEAL``) drawn by a worker while ideal_timeseries.csv and summary.json are
    written (``write_ideal_tables``); ``plots`` False draws no more (an interrupt). Returns ``figures`` completed,
    with ``plots`` (all the PNG files written)."""
    from mechanism.output.workers import ColumnsOf
    k, fallback = drawing
    stream = result.streamed.stream if result.streamed is not None else None
    if stream is not None and stream.gathers(1):   # the run's columns of these figures went to the second worker
        return _finish_gathered(figures, result, out, ideal, workers, drawing, plots)
    if stream is not None and stream.lost:   # some went to a worker that could not take them: read back
        _read_back(result)
    # two workers: the second takes them all at once (the first only if the second cannot, after its run-only
    # figures); one worker: all of them after its run-only figures, once the tables are written
    shares = (REST[0] + REST[1], ()) if len(workers) > 1 else (REST[0] + REST[1],)
    shares = tuple(tuple(name for name in FIGURES if name in share) for share in shares) if plots else ()
    sent = ColumnsOf(result, tuple(c for c in result.columns if c in DRAWN_WITH_IDEAL))
    job, ideal_sent = _ideal_sent(ideal)
    drawn, errors = [], []

    def collect(j: int, *args, job: str = job, **kwargs) -> None:
        try:
            drawn.extend(workers.result(j, job, *args, **kwargs))
        except BaseException as err:   # noqa: BLE001 - raised below, once the tables are written
            errors.append(err)

    def submit(j: int, names: tuple[str, ...]) -> list:
        return [(j, names)] if workers.submit(j, job, sent, out, ideal_sent, names=names) else []

    submitted = submit(1, shares[0]) if len(shares) > 1 else []
    try:
        figures = write_ideal_tables(figures, result, out, ideal)
    finally:   # the workers' files are complete before anything else happens
        collect(k, fallback, out, None, names=RUN_ONLY, job="plots")
    if not errors:   # the first worker's next share (sent now: it reads it at once, the command does not wait)
        submitted += [share for names in shares[len(submitted):] if names for share in submit(k, names)]
    for j, names in submitted:
        collect(j, sent, out, ideal_sent, names=names)
    if errors:
        raise errors[0]
    rest = [name for names in shares if not any(names == done for _, done in submitted) for name in names]
    if rest:   # no worker could take them: drawn here
        from mechanism.output.plots import plot_run
        drawn += plot_run(result, out, _ideal_here(ideal, result), names=tuple(rest))
    order = {name: n for n, name in enumerate(FIGURES)}
    figures["plots"] = [str(p) for p in sorted(drawn, key=lambda path: order[Path(path).name])]
    return figures


def _finish_gathered(figures: dict, result: RunResult, out: Path, ideal: RunResult | None, workers,
                     drawing: tuple, plots: bool) -> dict:
    """``finish_outputs`` of a run whose columns of the figures with the ideal curve went to the second worker during
    the run (``stream.for_run``, a long run): that worker draws all of them (the rows not yet sent go with the job)
    while the first finishes the figures of the run alone and the tables are written. If it cannot take the job
    (or dies) the columns are read back from timeseries.csv and the figures drawn here."""
    from mechanism.output.workers import ColumnsOf
    k, fallback = drawing
    stream = result.streamed.stream
    names = tuple(name for name in FIGURES if name in REST[0] + REST[1]) if plots else ()
    tail = stream.tail(1)
    job, ideal_sent = _ideal_sent(ideal)
    submitted = bool(names) and tail is not None and workers.submit(
        1, "plots_gathered", ColumnsOf(tail, tail.columns), out, ideal_sent, names=names,
        coarse=job == "plots_resampled")
    del tail
    drawn, errors = [], []

    def whole() -> RunResult:   # the run with every column (read back), should the worker die
        _read_back(result)
        return result

    def collect(j: int, *args, **kwargs) -> None:
        try:
            drawn.extend(workers.result(j, "plots", *args, **kwargs))
        except BaseException as err:   # noqa: BLE001 - raised below, once the tables are written
            errors.append(err)
    try:
        figures = write_ideal_tables(figures, result, out, ideal)
    finally:   # the workers' files are complete before anything else happens
        collect(k, fallback, out, None, names=RUN_ONLY)
        if submitted:
            collect(1, ColumnsOf(whole, ()), out, ColumnsOf(lambda: _ideal_here(ideal, whole()), ()), names=names)
    if errors:
        raise errors[0]
    if names and not submitted:   # no worker could take them: drawn here
        from mechanism.output.plots import plot_run
        drawn += plot_run(whole(), out, _ideal_here(ideal, result), names=names)
    order = {name: n for n, name in enumerate(FIGURES)}
    figures["plots"] = [str(p) for p in sorted(drawn, key=lambda path: order[Path(path).name])]
    return figures


def _ideal_source(ideal: RunResult | None) -> RunResult | None:
    """The ideal counterpart's table the figures read: a streamed one's ``source`` (at its own sample times) if it has
    one, else itself."""
    source = ideal.streamed.source if ideal is not None and ideal.streamed is not None else None
    return ideal if source is None else source


def _ideal_sent(ideal: RunResult | None) -> tuple:
    """The workers' job for figures with the ideal curve and the ideal's columns to send: ``plots_resampled`` with
    ``Streamed.source`` (resampled there) or ``plots`` with the ideal's plotted columns."""
    from mechanism.output.workers import ColumnsOf
    source = _ideal_source(ideal)
    if source is None:
        return "plots", None
    job = "plots" if source is ideal else "plots_resampled"
    return job, ColumnsOf(source, plotted_columns(source))


def _ideal_here(ideal: RunResult | None, result: RunResult) -> RunResult | None:
    """The ideal counterpart for figures drawn in this process: a streamed one's ``source`` resampled again."""
    source = _ideal_source(ideal)
    if source is ideal or source is None:
        return ideal
    from mechanism.cosim.record import resample
    return resample(source, result["time"])


def _write_tables(result: RunResult, out: Path, ideal: RunResult | None) -> dict:
    """``write_outputs``'s CSV files and summary.json; returns the summary's figures."""
    return write_ideal_tables(write_run_table(result, out), result, out, ideal)


def write_run_table(result: RunResult, out: Path) -> dict:
    """The first half of ``write_outputs`` without plots: the run's summary figures and timeseries.csv (the
    run's table can then be let go, ``compared_columns`` kept, before the ideal counterpart runs: issue 11).
    If the CSV cannot be written, summary.json still is, with ``write_error``, and the OSError is raised."""
    figures = summary(result)
    remove_previous(out)
    _write_csv_or_report(result, out / "timeseries.csv", figures, out)
    return figures


#: what a run writes after its timeseries.csv when the table goes first (``write_run_table``)
WRITTEN_LATER = ("summary.json", "ideal_timeseries.csv")


def remove_previous(out: Path, also: tuple[str, ...] = ()) -> None:
    """Remove an earlier run's ``WRITTEN_LATER`` files (and ``also``) from ``out`` before this run's
    timeseries.csv is written ahead of them: a run stopped in between (killed, the ideal counterpart failing)
    leaves its own files only, never a mix with an earlier run's."""
    for name in WRITTEN_LATER + tuple(also):
        with contextlib.suppress(FileNotFoundError):
            (Path(out) / name).unlink()


#: the run's columns compared with the ideal counterpart's in summary.json (``write_ideal_tables``)
COMPARED = ("time", "slider_a", "slider_x")


def compared_columns(result: RunResult, keep: tuple[str, ...] = COMPARED) -> RunResult:
    """``result`` reduced to the columns ``keep`` (default those ``write_ideal_tables`` compares, ``COMPARED``;
    ``result`` itself when it already is)."""
    if tuple(result.columns) == keep or set(result.columns) == {c for c in keep if result.has(c)}:
        return result   # (it has those columns only: in another order, a copy would be all it made)
    names = [c for c in keep if result.has(c)]
    data = np.empty((len(result.data), len(names)))
    for k, name in enumerate(names):
        data[:, k] = result[name]
    return RunResult(names, data, result.meta, result.status, result.message)


def write_ideal_tables(figures: dict, result: RunResult, out: Path, ideal: RunResult | None) -> dict:
    """The second half: ideal_timeseries.csv, the ideal's figures and its deviation from the run (``result``:
    at least ``COMPARED``), then summary.json; returns ``figures`` completed."""
    if ideal is not None:
        _write_csv_or_report(ideal, out / "ideal_timeseries.csv", figures, out)
        figures["ideal"] = summary(ideal)
        if len(result["time"]) and len(ideal["time"]) >= len(result["time"]):
            k = len(result["time"])
            figures["rms_slider_acceleration_deviation_m_s2"] = float(
                np.sqrt(np.mean((result["slider_a"] - ideal["slider_a"][:k]) ** 2)))
            figures["max_slider_position_error_m"] = float(np.max(np.abs(result["slider_x"] - ideal["slider_x"][:k])))
    write_json(figures, out / "summary.json")
    return figures


def _write_csv_or_report(r: RunResult, path: Path, figures: dict, out: Path) -> None:
    """``write_csv``; on an OSError (a full disk) summary.json with ``write_error`` (the small summary at least
    is kept), then the error is raised."""
    try:
        if r.streamed is not None:   # written as it was recorded: renamed onto timeseries.csv now
            r.streamed.stream.commit()
        else:
            write_csv(r, path)
    except OSError as err:
        figures["write_error"] = f"{err.strerror or err} writing {err.filename or out}"
        with contextlib.suppress(OSError):
            write_json(figures, out / "summary.json")
        raise
