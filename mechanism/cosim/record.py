"""What a run records: the sample table (``Recorder``), the run's result (``RunResult``) and column units.

Columns are SI; ``unit_of`` names each column's unit for CSV headers. A run that fails keeps what it
recorded up to the failure: ``RunResult.status`` is then ``"failed"`` and ``message`` says at which
step, at what time and why.
"""
from __future__ import annotations

from dataclasses import dataclass, field

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


class Recorder:
    """Preallocated table of samples; rows are appended in time order."""

    def __init__(self, columns: list[str], capacity: int):
        self.columns = list(columns)
        self.index = {c: i for i, c in enumerate(self.columns)}
        self.data = np.full((max(capacity, 1), len(self.columns)), np.nan)
        self.rows = 0

    def next_row(self) -> np.ndarray:
        """The next row (a view, NaN-filled) to write a sample into; the table doubles when full."""
        if self.rows == len(self.data):
            self.data = np.vstack([self.data, np.full_like(self.data, np.nan)])
        self.rows += 1
        return self.data[self.rows - 1]

    def add(self, values: dict[str, float]) -> None:
        row = self.next_row()
        for name, value in values.items():
            row[self.index[name]] = value

    def table(self) -> np.ndarray:
        """The recorded rows (a view while the capacity is used up to one spare row, else a copy, so that
        a table preallocated for a run that stopped early does not stay in memory)."""
        if self.rows + 1 >= len(self.data):
            return self.data[: self.rows]
        return self.data[: self.rows].copy()


@dataclass
class RunResult:
    """A run's samples (one row per output time) and what produced them."""

    columns: list[str]
    data: np.ndarray
    meta: dict = field(default_factory=dict)
    status: str = "completed"
    message: str = ""

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


def energy_summary(r: RunResult) -> dict | None:
    """End-of-run energy figures of a RunResult with the energy account's columns (None without them) [J]."""
    if not r.has("energy_residual") or len(r["time"]) == 0:
        return None
    residual = r["energy_residual"]
    dissipated = float(r["damping_dissipation"][-1])
    worst = float(residual[np.nanargmax(np.abs(residual))])
    return {"kinetic_energy_J": float(r["kinetic_energy"][-1]), "contact_energy_J": float(r["contact_energy"][-1]),
            "damping_dissipation_J": dissipated, "drive_work_J": float(r["drive_work"][-1]),
            "cage_work_J": float(r["cage_work"][-1]), "applied_work_J": float(r["applied_work"][-1]),
            "energy_residual_J": float(residual[-1]), "energy_residual_max_abs_J": abs(worst),
            "energy_residual_rel_dissipation": float(residual[-1]) / dissipated if dissipated > 0 else None}


#: columns splined together by ``resample`` (bounds the spline coefficients held at a time)
RESAMPLE_GROUP = 4


def resample(result: RunResult, times: np.ndarray) -> RunResult:
    """``result`` at other sample times, by a cubic spline through each column (times within its range;
    ``meta["resampled_from_s"]`` keeps the original sampling interval).

    The spline is scipy's ``CubicSpline`` (not-a-knot) to the bit, computed by ``mechanism.cosim.spline``
    without importing scipy.interpolate; columns with non-finite values are interpolated linearly."""
    from mechanism.cosim.spline import NotAKnotSpline
    t = result["time"]
    times = np.asarray(times, float)
    times = times[times <= t[-1] * (1 + 1e-12)]
    data = np.empty((len(times), len(result.columns)))    # filled column by column: no second copy
    data[:, 0] = times
    finite = []
    for k in range(1, len(result.columns)):
        column = result.data[:, k]
        if np.all(np.isfinite(column)):
            finite.append(k)
        else:
            data[:, k] = np.interp(times, t, column)
    for g in range(0, len(finite), RESAMPLE_GROUP):
        cols = finite[g:g + RESAMPLE_GROUP]
        spline = NotAKnotSpline(t, result.data[:, cols])
        if cols == list(range(cols[0], cols[-1] + 1)):   # adjacent columns: evaluated straight into the table
            spline.evaluate_into(times, data[:, cols[0]:cols[-1] + 1])
        else:
            data[:, cols] = spline(times)
    meta = dict(result.meta, resampled_from_s=float(t[1] - t[0]) if len(t) > 1 else 0.0)
    return RunResult(result.columns, data, meta, result.status, result.message)
