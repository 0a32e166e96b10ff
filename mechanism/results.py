"""Recorded time series of a run, its summary figures, and the files a person can open.

Columns are SI (the CSV header names the unit of each). A run that fails keeps what it
recorded up to the failure: ``RunResult.status`` is then ``"failed"`` and ``message`` says
at which step, at what time and why.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .life import run_life

#: units of the columns written to timeseries.csv (ball_load_<r> are N)
UNITS = {
    "time": "s", "crank_angle": "rad", "e_x": "m", "e_y": "m", "v_x": "m/s", "v_y": "m/s",
    "F_x": "N", "F_y": "N", "slider_x": "m", "slider_v": "m/s", "slider_a": "m/s^2",
    "crank_moment": "N.m", "constraint_violation": "m or rad", "omega_inner": "rad/s", "omega_outer": "rad/s",
    "cage_angle": "rad", "loaded_balls": "1", "max_ball_load": "N", "penetration": "m",
    "contact_force": "N", "kinetic_energy": "J", "in_contact": "1", "impact_velocity": "m/s",
    "normal_velocity": "m/s", "stiffness_skew": "N/m",
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

    def add(self, values: dict[str, float]) -> None:
        if self.rows == len(self.data):
            self.data = np.vstack([self.data, np.full_like(self.data, np.nan)])
        row = self.data[self.rows]
        for name, value in values.items():
            row[self.index[name]] = value
        self.rows += 1

    def table(self) -> np.ndarray:
        return self.data[: self.rows]


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


def _figures(r: RunResult, mask: np.ndarray) -> dict:
    def peak(values):
        return float(np.nanmax(values)) if values.size else math.nan

    out = {
        "max_eccentricity_m": peak(np.hypot(r["e_x"][mask], r["e_y"][mask])),
        "peak_joint_force_N": peak(np.hypot(r["F_x"][mask], r["F_y"][mask])),
        "slider_acceleration_min_m_s2": float(np.nanmin(r["slider_a"][mask])) if mask.any() else math.nan,
        "slider_acceleration_max_m_s2": peak(r["slider_a"][mask]),
        "crank_moment_min_N_m": float(np.nanmin(r["crank_moment"][mask])) if mask.any() else math.nan,
        "crank_moment_max_N_m": peak(r["crank_moment"][mask]),
        "max_constraint_violation_m": peak(np.abs(r["constraint_violation"][mask])),
    }
    loads = r.ball_load_columns
    out["max_ball_load_N"] = peak(np.column_stack([r[c][mask] for c in loads])) if loads else None
    return out


def summary(r: RunResult) -> dict:
    """Peak figures of the whole run and of the second crank revolution alone (key ``rev2``)."""
    t = r["time"]
    period = r.meta.get("crank_period_s")
    result = {"status": r.status, "message": r.message, "meta": r.meta, "samples": int(len(t))}
    if len(t) == 0:
        return result
    result["all"] = _figures(r, np.ones_like(t, dtype=bool))
    result["life"] = run_life(r)     # bearing rating life (docs/bearing-life.md); None for other joints
    half = 0.5 * float(r.meta.get("output_interval_s") or 0.0) + 1e-12   # the step count is rounded
    if period and t[-1] >= 2 * period - half:
        rev2 = (t >= period - half) & (t <= 2 * period + half)
        result["rev2"] = _figures(r, rev2)
        result["rev2"]["life"] = run_life(r, (period, 2 * period))
    return result


def write_csv(r: RunResult, path: Path) -> None:
    """timeseries.csv: one header row 'name [unit]', then one row per sample."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow([f"{c} [{unit_of(c)}]" for c in r.columns])
        for row in r.data:
            w.writerow([f"{x:.10g}" for x in row])


def read_csv(path: Path) -> RunResult:
    """Read a timeseries.csv written by ``write_csv`` back (units are stripped from the names)."""
    with open(path) as f:
        header = next(csv.reader(f))
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return RunResult([h.split(" [")[0] for h in header], data)
