"""What a run records: the sample table (``Recorder``), the run's result (``RunResult``) and column units.

Columns are SI; ``unit_of`` names each column's unit for CSV headers. A run that fails keeps what it
recorded up to the failure: ``RunResult.status`` is then ``"failed"`` and ``message`` says at which
step, at what time and why.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: units of the columns written to timeseries.csv (ball_load_<r> are N)
UNITS = {
    "time": "s", "crank_angle": "rad", "e_x": "m", "e_y": "m", "v_x": "m/s", "v_y": "m/s",
    "F_x": "N", "F_y": "N", "slider_x": "m", "slider_v": "m/s", "slider_a": "m/s^2",
    "crank_moment": "N.m", "constraint_violation": "m or rad", "omega_inner": "rad/s", "omega_outer": "rad/s",
    "cage_angle": "rad", "loaded_balls": "1", "max_ball_load": "N", "penetration": "m",
    "contact_force": "N", "kinetic_energy": "J", "in_contact": "1", "impact_velocity": "m/s",
    "normal_velocity": "m/s", "stiffness_skew": "N/m",
    "contact_energy": "J", "damping_dissipation": "J", "drive_work": "J", "cage_work": "J", "applied_work": "J",
    "energy_residual": "J",
}
BASE_COLUMNS = ("time", "crank_angle", "e_x", "e_y", "v_x", "v_y", "F_x", "F_y", "slider_x", "slider_v",
                "slider_a", "crank_moment", "constraint_violation", "omega_inner", "omega_outer",
                "kinetic_energy")


def unit_of(column: str) -> str:
    return "N" if column.startswith("ball_load_") else UNITS.get(column, "1")


#: rows a streaming ``Recorder`` holds before it hands them to its sink (~0.6 MB at 35 columns)
STREAM_ROWS = 2048


class Recorder:
    """Preallocated table of samples; rows are appended in time order.

    With a ``sink`` (``mechanism.output.stream.TableStream``: issue 11) the table is a buffer of ``STREAM_ROWS``
    rows handed to ``sink.write`` whenever it is full and at ``result``, so that its memory does not grow with the
    run; ``first_row``/``last_row`` keep the run's first and last samples, ``count`` the rows recorded."""

    def __init__(self, columns: list[str], capacity: int, sink=None):
        self.columns = list(columns)
        self.index = {c: i for i, c in enumerate(self.columns)}
        self.sink = sink
        if sink is not None:
            sink.open(self.columns, capacity)
            capacity = min(capacity, STREAM_ROWS)
        self.data = np.full((max(capacity, 1), len(self.columns)), np.nan)
        self.rows = 0
        self.flushed = 0                        # rows handed to the sink so far
        self._first: np.ndarray | None = None
        self._last: np.ndarray | None = None

    @property
    def count(self) -> int:
        """Rows recorded (handed to the sink or held)."""
        return self.flushed + self.rows

    @property
    def first_row(self) -> np.ndarray | None:
        """The first sample recorded (None before it)."""
        return self._first if self._first is not None else (self.data[0] if self.rows else None)

    @property
    def last_row(self) -> np.ndarray | None:
        """The last sample recorded (None before the first)."""
        return self.data[self.rows - 1] if self.rows else self._last

    def next_row(self) -> np.ndarray:
        """The next row (a view, NaN-filled) to write a sample into; the table doubles when full (a streaming
        one hands its rows to the sink instead)."""
        if self.rows == len(self.data):
            self.reserve(1)
        self.rows += 1
        return self.data[self.rows - 1]

    def reserve(self, n: int) -> None:
        """Room for ``n`` more rows from ``rows`` on: the held rows handed to the sink (streaming), else (or if
        still too few) the table grown."""
        if self.rows + n <= len(self.data):
            return
        if self.sink is not None:
            self.flush()
        while self.rows + n > len(self.data):
            self.data = np.vstack([self.data, np.full_like(self.data, np.nan)])

    def flush(self) -> None:
        """Hand the held rows to the sink and start the buffer again (NaN-filled; the last row is kept)."""
        if self.sink is None or not self.rows:
            return
        block = self.data[: self.rows]
        if self._first is None:
            self._first = block[0].copy()
        self._last = block[-1].copy()
        self.sink.write(block)
        self.flushed += self.rows
        block.fill(np.nan)
        self.rows = 0

    def add(self, values: dict[str, float]) -> None:
        row = self.next_row()
        for name, value in values.items():
            row[self.index[name]] = value

    def table(self) -> np.ndarray:
        """The recorded rows (a view while the capacity is used up to one spare row, else a copy, so that
        a table preallocated for a run that stopped early does not stay in memory). Not for a streaming one."""
        if self.sink is not None:
            raise RuntimeError("a streaming Recorder hands its rows to its sink: use result()")
        if self.rows + 1 >= len(self.data):
            return self.data[: self.rows]
        return self.data[: self.rows].copy()

    def result(self, meta: dict, status: str = "completed", message: str = "") -> RunResult:
        """The run's ``RunResult``: the table, or (streaming) the held rows handed over and the sink's result."""
        if self.sink is None:
            return RunResult(self.columns, self.table(), meta, status, message)
        self.flush()
        return self.sink.result(meta, status, message)


@dataclass
class RunResult:
    """A run's samples (one row per output time) and what produced them."""

    columns: list[str]
    data: np.ndarray
    meta: dict = field(default_factory=dict)
    status: str = "completed"
    message: str = ""
    #: a streamed run's (``mechanism.output.stream``): its whole table went to timeseries.csv as it was
    #: recorded; ``data`` holds some columns only, this their summary figures (``Streamed``)
    streamed: Any = None

    def __getitem__(self, column: str) -> np.ndarray:
        return self.data[:, self.columns.index(column)]

    def has(self, column: str) -> bool:
        return column in self.columns

    @property
    def ball_load_columns(self) -> list[str]:
        return [c for c in self.columns if c.startswith("ball_load_")]

    @property
    def ok(self) -> bool:
        return self.status == "completed"


#: the columns whose last values the energy figures are (``energy_figures``)
ENERGY_LAST = ("kinetic_energy", "contact_energy", "damping_dissipation", "drive_work", "cage_work", "applied_work",
               "energy_residual")


def energy_summary(r: RunResult) -> dict | None:
    """End-of-run energy figures of a RunResult with the energy account's columns (None without them) [J]."""
    if r.streamed is not None:    # a streamed run's: accumulated as its table was recorded
        return r.streamed.energy
    if not r.has("energy_residual") or len(r["time"]) == 0:
        return None
    residual = r["energy_residual"]
    worst = float(residual[np.nanargmax(np.abs(residual))])
    return energy_figures({name: float(r[name][-1]) for name in ENERGY_LAST}, worst)


def energy_figures(last: dict[str, float], worst: float) -> dict:
    """``energy_summary``'s figures from the last values of ``ENERGY_LAST`` and the residual of largest magnitude."""
    dissipated = last["damping_dissipation"]
    return {"kinetic_energy_J": last["kinetic_energy"], "contact_energy_J": last["contact_energy"],
            "damping_dissipation_J": dissipated, "drive_work_J": last["drive_work"],
            "cage_work_J": last["cage_work"], "applied_work_J": last["applied_work"],
            "energy_residual_J": last["energy_residual"], "energy_residual_max_abs_J": abs(worst),
            "energy_residual_rel_dissipation": last["energy_residual"] / dissipated if dissipated > 0 else None}


#: columns splined together by ``resample`` (bounds the spline coefficients held at a time)
RESAMPLE_GROUP = 4


def resample(result: RunResult, times: np.ndarray, sink=None) -> RunResult:
    """``result`` at other sample times, by a cubic spline through each column (times within its range;
    ``meta["resampled_from_s"]`` keeps the original sampling interval).

    The spline is scipy's ``CubicSpline`` (not-a-knot) to the bit, computed by ``mechanism.cosim.spline``
    without importing scipy.interpolate; columns with non-finite values are interpolated linearly.
    ``sink`` (a ``Recorder`` sink, ``mechanism.output.stream.TableStream``): the rows are made ``STREAM_ROWS`` at a
    time and handed to it (the same numbers: the spline and the interpolation are evaluated point by point), and
    the result is the sink's; the resampled table is never whole in memory."""
    from mechanism.cosim.spline import NotAKnotSpline
    t = result["time"]
    times = np.asarray(times, float)
    within = times <= t[-1] * (1 + 1e-12)
    if not np.all(within):    # (else no copy)
        times = times[within]
    del within
    meta = dict(result.meta, resampled_from_s=float(t[1] - t[0]) if len(t) > 1 else 0.0)
    finite = [k for k in range(1, len(result.columns)) if np.all(np.isfinite(result.data[:, k]))]
    groups = [finite[g:g + RESAMPLE_GROUP] for g in range(0, len(finite), RESAMPLE_GROUP)]
    if sink is not None:
        return _resample_into(sink, result, times, finite, groups, meta)
    data = np.empty((len(times), len(result.columns)))    # filled column by column: no second copy
    data[:, 0] = times
    for k in range(1, len(result.columns)):
        if k not in finite:
            data[:, k] = np.interp(times, t, result.data[:, k])
    for cols in groups:
        spline = NotAKnotSpline(t, result.data[:, cols])
        if cols == list(range(cols[0], cols[-1] + 1)):   # adjacent columns: evaluated straight into the table
            spline.evaluate_into(times, data[:, cols[0]:cols[-1] + 1])
        else:
            data[:, cols] = spline(times)
    return RunResult(result.columns, data, meta, result.status, result.message)


def _resample_into(sink, result: RunResult, times: np.ndarray, finite: list[int], groups: list[list[int]],
                   meta: dict) -> RunResult:
    """``resample``'s rows handed to ``sink`` a block at a time: every column's spline is made first, keeping its
    knot slopes only (``NotAKnotSpline``'s ``lazy``: n x m numbers, not the 4 x n x m coefficients)."""
    from mechanism.cosim.spline import NotAKnotSpline
    t, data = result["time"], result.data
    splines = []
    for cols in groups:
        adjacent = cols == list(range(cols[0], cols[-1] + 1))
        y = data[:, cols[0]:cols[-1] + 1] if adjacent else data[:, cols]    # a view where it can be
        splines.append((cols, adjacent, NotAKnotSpline(t, y, lazy=True)))
    linear = [k for k in range(1, len(result.columns)) if k not in finite]
    sink.open(result.columns, len(times))
    block = np.empty((min(STREAM_ROWS, max(len(times), 1)), len(result.columns)))
    for k in range(0, len(times), STREAM_ROWS):
        x = times[k:k + STREAM_ROWS]
        rows = block[:len(x)]
        rows[:, 0] = x
        for j in linear:
            rows[:, j] = np.interp(x, t, data[:, j])
        for cols, adjacent, spline in splines:
            if adjacent:
                spline.evaluate_into(x, rows[:, cols[0]:cols[-1] + 1])
            else:
                rows[:, cols] = spline(x)
        sink.write(rows)
    return sink.result(meta, result.status, result.message)
