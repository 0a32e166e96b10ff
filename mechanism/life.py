"""Bearing rating life of a run (issue 16): the figures summary.json and the studies report.

The physics is ``fmu_bearing.life`` (one home). A co-simulation run records the BallBearing FMU's life
outputs as sample columns, so its life is the FMU's final outputs (``life_from_outputs``); runs without
them (the monolithic reference, or a window of any run) accumulate the recorded ball loads with the same
``LifeAccumulator`` (``life_from_samples``): the loads of sample k held over (t_{k-1}, t_k], which is the
FMU's own rule when samples are taken every communication step.
"""
from __future__ import annotations

import math

import numpy as np

from fmu_bearing.life import LifeAccumulator, LoadRatings
from fmu_bearing.parameters import BearingParameters

#: FMU output -> summary key (SI units in the key)
OUTPUT_KEYS = {
    "dynamic_load_rating": "dynamic_load_rating_N",
    "raceway_rating_inner": "raceway_rating_inner_N",
    "raceway_rating_outer": "raceway_rating_outer_N",
    "equivalent_load_inner": "equivalent_load_inner_N",
    "equivalent_load_outer": "equivalent_load_outer_N",
    "rating_life": "rating_life_h",
    "rating_life_revolutions": "rating_life_Mrev",
}
#: units of the life columns in timeseries.csv
LIFE_UNITS = {"dynamic_load_rating": "N", "raceway_rating_inner": "N", "raceway_rating_outer": "N",
              "equivalent_load_inner": "N", "equivalent_load_outer": "N", "rating_life": "h",
              "rating_life_revolutions": "Mrev"}


def figures(acc: LifeAccumulator, source: str, window: tuple[float, float]) -> dict:
    """The summary figures of an accumulator (infinite life is written as JSON Infinity)."""
    r = acc.ratings
    return {"source": source, "window_s": [float(window[0]), float(window[1])],
            "reliability_factor": acc.reliability_factor,
            "dynamic_load_rating_N": r.C_r, "raceway_rating_inner_N": r.Q_ci, "raceway_rating_outer_N": r.Q_ce,
            "equivalent_load_inner_N": acc.equivalent_load_inner,
            "equivalent_load_outer_N": acc.equivalent_load_outer,
            "rating_life_h": acc.life_hours, "rating_life_Mrev": acc.life_revolutions,
            "mean_relative_speed_rpm": acc.speed * 60.0}


def life_from_samples(result, params: BearingParameters, t_start: float = -math.inf,
                      t_end: float = math.inf) -> LifeAccumulator:
    """Accumulate the recorded ball loads of ``result`` (a RunResult) over the window [t_start, t_end]."""
    acc = LifeAccumulator(LoadRatings.of_bearing(params), params.reliability_factor)
    t = result["time"]
    names = [f"ball_load_{r + 1}" for r in range(int(params.n_balls))]
    if len(t) < 2 or not all(result.has(n) for n in names):
        return acc
    loads = np.column_stack([result[n] for n in names])
    w_i, w_o = result["omega_inner"], result["omega_outer"]
    for k in range(1, len(t)):
        lo, hi = max(t[k - 1], t_start), min(t[k], t_end)
        if hi > lo and np.all(np.isfinite(loads[k])):
            acc.add(loads[k].tolist(), float(w_i[k]), float(w_o[k]), float(hi - lo))
    return acc


def life_from_outputs(result) -> dict | None:
    """The FMU's life outputs at the last sample of ``result``, or None if it has none."""
    if not result.has("rating_life") or len(result["time"]) == 0:
        return None
    out = {"source": "fmu outputs", "window_s": [float(result["time"][0]), float(result["time"][-1])]}
    out.update({key: float(result[name][-1]) for name, key in OUTPUT_KEYS.items() if result.has(name)})
    return out
