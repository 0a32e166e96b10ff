"""timeseries.csv written while the run records it (issue 11: a run's memory does not grow with its length).

``TableStream`` is a ``record.Recorder``'s sink: each block of rows the master records (``record.STREAM_ROWS`` at a
time, handed on as the compiled loop's chunks fill it) is appended to a temporary file beside timeseries.csv, and
what the outputs need of the whole table is kept as it goes by: the columns ``keep`` (those summary.json compares
with the ideal counterpart and, with plots, those the figures draw, at full resolution), the summary's peaks over
all rows, the energy figures, the rows of the second revolution (``results.summary``'s window, all columns) and,
asked for, the whole run's life from the recorded ball loads. The run's ``RunResult`` holds the kept columns and
these figures (``Streamed``); ``results.write_run_table`` renames the file onto timeseries.csv (``commit``) where
the in-memory table was written before, so the files are the same bytes as ``results.write_csv``'s and in the same
order (a failed or interrupted run's file holds the rows up to then). A write error (a full disk) stops the
writing and removes the file; the run goes on and ``commit`` raises the error (summary.json reports it, as before).
With plots, the columns only the figures read can go to the output workers during the run instead of staying in
the command (``gather``, ``for_run``); the ideal counterpart is resampled into a stream of its own (``for_ideal``).
"""
from __future__ import annotations

import contextlib
import csv
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..cosim.record import ENERGY_LAST, RunResult, energy_figures, unit_of

#: bytes of gathered columns held before they go to the output worker (``TableStream``'s ``gather``)
GATHER_BYTES = 1_000_000


@dataclass
class _Target:
    """Columns gathered to an output worker: their names and indexes, and the rows not yet sent (column-major)."""

    names: tuple[str, ...]
    index: list[int]
    pending: np.ndarray | None
    held: int = 0


@dataclass
class Streamed:
    """What ``results.summary`` needs of a streamed run's whole table (``RunResult.streamed``)."""

    columns: list[str]                 # the whole table's columns (timeseries.csv's)
    figures: dict | None               # ``results._figures`` over all rows (None: no rows)
    energy: dict | None                # ``record.energy_summary``'s figures
    window: RunResult | None           # every column, the rows with period - margin <= t <= 2 period + margin
    life: object | None                # the whole run's ``LifeAccumulator`` of the ball loads (when asked for)
    stream: TableStream
    #: a resampled ideal counterpart's table at its own sample times (``results.DRAWN_WITH_IDEAL``): the figures
    #: resample it where they are drawn (``workers._plots_resampled``) instead of the command keeping those columns
    source: RunResult | None = None
    #: the second revolution's figures once ``results.summary`` made them (``window`` is then let go)
    rev2: dict | None = None

    @property
    def ball_load_columns(self) -> list[str]:
        return [c for c in self.columns if c.startswith("ball_load_")]


class TableStream:
    """A ``Recorder`` sink writing ``path`` (timeseries.csv) as the rows arrive; see the module docstring.

    ``keep``: the columns kept in memory at full resolution (those of the table's that exist, and those whose names
    start with ``keep_prefix``); ``period``: the crank period [s], whose second revolution is kept (all columns)
    within ``margin`` [s] (at least two sample intervals) until the summary has its figures; ``life``: the bearing's ``BearingParameters`` to accumulate the whole run's life from the recorded
    ball loads (for a component without life outputs). ``gather``: ``(workers, {k: select})``, the columns
    ``select`` picks of the table's go to output worker ``k`` ``GATHER_BYTES`` at a time instead of staying here
    (the figures drawn there read them: ``results.start_run_plots``, ``finish_outputs``, which send the rows not yet
    sent, ``tail``, with the job); ``lost`` if a worker could not take them (they are read back from the file then).
    Use as a context manager: the temporary file is removed if it was not committed."""

    def __init__(self, path: Path, keep: tuple[str, ...], period: float | None = None, margin: float = 0.0,
                 life=None, keep_prefix: str | None = None, gather: tuple | None = None):
        self.path = Path(path)
        self.tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")    # atomic_open's name
        self.keep, self.period, self.margin, self.life_params = tuple(keep), period, margin, life
        self.keep_prefix = keep_prefix
        self.workers, self._select = gather if gather is not None else (None, {})
        self._targets: dict[int, _Target] = {}
        self.lost = False          # a worker could not take a block: the gathered columns are to be read back
        self.read_back = False     # (``results._read_back`` done)
        self.meta: dict = {}
        self.file = None
        self.error: OSError | None = None
        self.committed = False
        self.columns: list[str] = []

    # ------------------------------------------------------------------------------------ the Recorder's side
    def open(self, columns: list[str], capacity: int) -> None:
        """Start a table of ``columns`` (about ``capacity`` rows): the file with its header, the accumulators."""
        from .results import csv_line
        self.columns = list(columns)
        self.index = {c: k for k, c in enumerate(self.columns)}
        self.kept = [c for c in self.columns
                     if c in self.keep or (self.keep_prefix is not None and c.startswith(self.keep_prefix))]
        self._kept_index = [self.index[c] for c in self.kept]
        self._table = np.empty((max(capacity, 1), len(self.kept)))   # pages touched only as rows arrive
        self.rows = 0
        self._line = csv_line(len(self.columns))
        self._figures: dict | None = None
        self._worst: float | None = None
        self._last: np.ndarray | None = None
        self._window: list[np.ndarray] = []
        self._before: np.ndarray | None = None     # the last row before the window (its first sample's interval)
        self._life = self._life_cols = None
        if self.life_params is not None:
            from mechanism.output.life import accumulator, ball_load_names
            self._life = accumulator(self.life_params)
            names = ball_load_names(self.life_params)
            if all(n in self.index for n in names):   # (else nothing is added, as in life_from_samples)
                self._life_cols = [self.index[n] for n in names]
        self._life_t: float | None = None
        for k, select in self._select.items():
            names = tuple(select(self.columns))
            if names:
                self._targets[k] = _Target(names, [self.index[c] for c in names],
                                           np.empty((len(names), max(1, GATHER_BYTES // (8 * len(names))))))
        try:
            self.file = open(self.tmp, "w", newline="")   # noqa: SIM115 - open across writes; closed by _close
            csv.writer(self.file).writerow([f"{c} [{unit_of(c)}]" for c in self.columns])
        except OSError as err:
            self._failed(err)

    def write(self, block: np.ndarray) -> None:
        """Append the rows ``block`` (a view the Recorder reuses: nothing of it is kept by reference)."""
        if self.file is not None:
            from .results import CSV_CHUNK_ROWS
            try:
                for k in range(0, len(block), CSV_CHUNK_ROWS):
                    self.file.write("".join([self._line % row for row in map(tuple, block[k:k + CSV_CHUNK_ROWS].tolist())]))
            except OSError as err:
                self._failed(err)
        n = len(block)
        if self.rows + n > len(self._table):
            self._table = np.concatenate([self._table, np.empty_like(self._table)])
        self._table[self.rows:self.rows + n] = block[:, self._kept_index]
        self.rows += n
        for k, target in self._targets.items():
            if target.pending is not None:
                self._hold(k, target, block)
        self._accumulate(block)

    def gathers(self, k: int) -> tuple[str, ...]:
        """The columns that go to worker ``k`` (none: ())."""
        target = self._targets.get(k)
        return () if target is None else target.names

    def _hold(self, k: int, target: _Target, block: np.ndarray) -> None:
        """The gathered columns of ``block`` into worker ``k``'s pending buffer, sent when full."""
        j = 0
        while j < len(block) and target.pending is not None:
            n = min(len(block) - j, target.pending.shape[1] - target.held)
            target.pending[:, target.held:target.held + n] = block[j:j + n, target.index].T
            target.held += n
            j += n
            if target.held == target.pending.shape[1]:
                self._send(k, target)

    def _send(self, k: int, target: _Target) -> None:
        """The pending rows to worker ``k`` (``OutputWorkers.gather``); if it cannot take them, the gathering stops
        (``lost``: the columns are read back from the file, ``results._read_back``)."""
        from .workers import ColumnsOf
        part = RunResult(list(target.names), target.pending[:, :target.held].T)
        if self.workers.gather(k, ColumnsOf(part, target.names)):
            target.held = 0
        else:
            self.lost = True
            target.pending = None

    def tail(self, k: int) -> RunResult | None:
        """Worker ``k``'s gathered columns' rows not yet sent (with the run's meta, status and message), handed
        over once: None if there are none to hand over (no gathering to ``k``, or lost)."""
        target = self._targets.get(k)
        if target is None or target.pending is None:
            return None
        data, target.pending = target.pending[:, :target.held].T, None
        return RunResult(list(target.names), data, self.meta, self.status, self.message)

    def result(self, meta: dict, status: str, message: str) -> RunResult:
        """The run's ``RunResult``: the kept columns, and the whole table's figures in ``streamed``; the file is
        complete (closed) but not yet renamed onto ``path`` (``commit``)."""
        self._close()
        self.meta, self.status, self.message = meta, status, message
        data = self._table[:self.rows] if self.rows + 1 >= len(self._table) else self._table[:self.rows].copy()
        self._table = None
        window = None
        if self._window:
            window = RunResult(self.columns, np.concatenate(self._window), meta, status, message)
        self._window = []
        energy = None
        if "energy_residual" in self.index and self._last is not None:
            energy = energy_figures({c: float(self._last[self.index[c]]) for c in ENERGY_LAST}, self._worst_value())
        streamed = Streamed(self.columns, self._figures, energy, window, self._life, self)
        return RunResult(self.kept, data, meta, status, message, streamed)

    def mark(self, meta: dict, status: str, message: str) -> None:
        """The run's meta, status and message as they were settled after ``result`` (``run._mark_interrupted``: an
        interrupted run, not a failed one), for the rows handed over later (``tail``)."""
        self.meta, self.status, self.message = meta, status, message

    # ----------------------------------------------------------------------------------------- accumulating
    def _accumulate(self, block: np.ndarray) -> None:
        from .results import _figures
        if not len(block):
            return
        part = RunResult(self.columns, block)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)   # an all-NaN block: its NaN is ignored below
            figures = _figures(part, slice(None))
        self._figures = figures if self._figures is None else {
            key: _combine(key, value, figures[key]) for key, value in self._figures.items()}
        if "energy_residual" in self.index:
            residual = block[:, self.index["energy_residual"]]
            magnitude = np.abs(residual)
            if not np.all(np.isnan(magnitude)):
                k = int(np.nanargmax(magnitude))     # the first of the largest, as over the whole column
                if self._worst is None or magnitude[k] > abs(self._worst):
                    self._worst = float(residual[k])
        self._last = block[-1].copy()
        if self.period is not None:   # the second revolution's rows, and the one before them
            t = block[:, 0]
            lo, hi = self.period - self.margin, 2 * self.period + self.margin
            a, b = int(np.searchsorted(t, lo, side="left")), int(np.searchsorted(t, hi, side="right"))
            if b > a:
                if not self._window and a == 0 and self._before is not None:
                    self._window.append(self._before[None, :])
                self._window.append(block[a - 1 if not self._window and a > 0 else a:b].copy())
            self._before = self._last
        if self._life_cols is not None:
            self._add_life(block)

    def _add_life(self, block: np.ndarray) -> None:
        """``life.life_from_samples`` over the whole run, a block at a time (``life.add_held_samples``: the loads of
        sample k held over (t_{k-1}, t_k], the last time carried to the next block)."""
        from mechanism.output.life import add_held_samples
        self._life_t = add_held_samples(self._life, block[:, 0], block[:, self._life_cols],
                                        block[:, self.index["omega_inner"]], block[:, self.index["omega_outer"]],
                                        self._life_t)

    def _worst_value(self) -> float:
        if self._worst is None:    # every residual NaN: as ``np.nanargmax`` over the whole column (it raises)
            return float(np.nanargmax(np.array([math.nan])))
        return self._worst

    # ------------------------------------------------------------------------------------------ the file
    def _failed(self, err: OSError) -> None:
        """A write error: no more writing, the file removed; ``commit`` raises ``err``."""
        if self.error is None:
            self.error = err
        if self.file is not None:
            with contextlib.suppress(OSError):
                self.file.close()
            self.file = None
        with contextlib.suppress(OSError):
            self.tmp.unlink()

    def _close(self) -> None:
        if self.file is not None:
            try:
                self.file.close()
            except OSError as err:
                self._failed(err)
            self.file = None

    def commit(self) -> None:
        """Rename the complete file onto ``path`` (the write error, if any, raised instead)."""
        self._close()
        if self.error is not None:
            raise self.error
        os.replace(self.tmp, self.path)
        self.committed = True

    def discard(self) -> None:
        """Remove the file unless it was committed."""
        self._close()
        if not self.committed:
            with contextlib.suppress(OSError):
                self.tmp.unlink()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.discard()
        return False


def _combine(key: str, a, b):
    """Two blocks' peak figure ``key`` combined as over their rows together (NaN only where both are)."""
    if a is None or b is None:
        return a if b is None else b
    if math.isnan(a):
        return b
    if math.isnan(b):
        return a
    return min(a, b) if key.endswith(("_min_m_s2", "_min_N_m")) else max(a, b)


def for_run(out: Path, config, plots: bool, workers=None, ideal: bool = True) -> TableStream:
    """The stream of ``python -m mechanism run``'s timeseries.csv in ``out`` for ``config`` (a ``RunConfig``): it keeps
    the columns summary.json compares with the ideal counterpart and, with ``plots``, those the figures draw, and the
    second revolution's rows (within two sample intervals and two steps). With plots, output ``workers`` and an
    ``ideal`` counterpart to come (``results.start_run_plots``), the columns only the figures of the run alone read
    go to the first worker during the run (``gather``); with two workers and more than ``GATHER_BYTES`` of them, those
    of the figures with the ideal curve go to the second (which then draws all of those: ``finish_outputs``), else
    they stay."""
    from .results import COMPARED, DRAWN_WITH_IDEAL, PLOTTED, run_only_columns
    gather = plots and ideal and workers is not None and len(workers) > 0
    rows = config.revs * config.crank_period / max(config.output_interval, config.step)
    second = gather and len(workers) > 1 and rows * len(DRAWN_WITH_IDEAL) * 8 > GATHER_BYTES
    keep = COMPARED + (() if second else DRAWN_WITH_IDEAL if gather else PLOTTED if plots else ())
    targets = {0: run_only_columns} if gather else {}
    if second:
        targets[1] = _drawn_with_ideal
    return TableStream(Path(out) / "timeseries.csv", keep, config.crank_period,
                       2.0 * (config.output_interval + config.step),
                       keep_prefix="ball_load_" if plots and not gather else None,
                       gather=(workers, targets) if gather else None)


def _drawn_with_ideal(columns: list[str]) -> tuple[str, ...]:
    from .results import DRAWN_WITH_IDEAL
    return tuple(c for c in columns if c in DRAWN_WITH_IDEAL)


def for_ideal(out: Path, config, plots: bool, workers=None) -> TableStream:
    """The stream of the ideal counterpart's ideal_timeseries.csv in ``out``, resampled onto the run's sample times
    (``resample_ideal``): it keeps the columns summary.json compares and, with ``plots``, those its curves in the
    figures read (``results.DRAWN_WITH_IDEAL``), unless output ``workers`` draw them (then they resample those
    columns of the ideal's own table themselves: ``Streamed.source``)."""
    from .results import COMPARED, DRAWN_WITH_IDEAL
    elsewhere = plots and workers is not None and len(workers) > 0
    stream = TableStream(Path(out) / "ideal_timeseries.csv", COMPARED + (DRAWN_WITH_IDEAL if plots and not elsewhere
                                                                         else ()),
                         config.crank_period, 2.0 * (config.output_interval + config.step))
    stream.figures_elsewhere = elsewhere
    return stream


def resample_ideal(ideal: RunResult, times: np.ndarray, sink: TableStream) -> RunResult:
    """``record.resample`` of the ideal counterpart onto ``times`` into ``sink`` (``for_ideal``); with its figures drawn
    by the workers, the columns they read of ``ideal`` itself go with the result (``Streamed.source``)."""
    from ..cosim.record import resample
    from .results import DRAWN_WITH_IDEAL, compared_columns
    source = compared_columns(ideal, DRAWN_WITH_IDEAL) if getattr(sink, "figures_elsewhere", False) else None
    result = resample(ideal, times, sink)
    result.streamed.source = source
    return result
