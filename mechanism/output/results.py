"""Summary figures of a run and the files a person can open (CSV with units in the headers, JSON).

The samples themselves are recorded by ``mechanism.cosim.record`` (``RunResult``).
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from ..cosim.record import RunResult, energy_summary, unit_of


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
    energy = energy_summary(r)
    if energy is not None:
        result["energy"] = energy
    half = 0.5 * float(r.meta.get("output_interval_s") or 0.0) + 1e-12   # the step count is rounded
    if period and t[-1] >= 2 * period - half:
        rev2 = (t >= period - half) & (t <= 2 * period + half)
        result["rev2"] = _figures(r, rev2)
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


def write_outputs(result: RunResult, out: Path, ideal: RunResult | None = None, plots: bool = True) -> dict:
    """timeseries.csv, summary.json (with the ideal joint's figures if given) and the PNG plots into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(result, out / "timeseries.csv")
    figures = summary(result)
    if ideal is not None:
        write_csv(ideal, out / "ideal_timeseries.csv")
        figures["ideal"] = summary(ideal)
        if len(result["time"]) and len(ideal["time"]) >= len(result["time"]):
            k = len(result["time"])
            figures["rms_slider_acceleration_deviation_m_s2"] = float(
                np.sqrt(np.mean((result["slider_a"] - ideal["slider_a"][:k]) ** 2)))
            figures["max_slider_position_error_m"] = float(np.max(np.abs(result["slider_x"] - ideal["slider_x"][:k])))
    (out / "summary.json").write_text(json.dumps(figures, indent=2, default=float) + "\n")
    if plots and len(result["time"]) > 1:
        from mechanism.output.plots import plot_run
        plot_run(result, out, ideal)
    return figures
