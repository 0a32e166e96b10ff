"""Bearing rating life of a run (issue 16): the figures summary.json and the studies report.

The physics is ``fmu_bearing.life`` (one home). The master keeps the component's life outputs at
the end of a run (BallBearing FMU, or the in-process endpoint's accumulator) in ``meta["life_outputs"]``,
so a co-simulation's life is the FMU's final outputs (``life_from_outputs``); runs without them (the
monolithic reference, or a window of any run) accumulate the recorded ball loads with the same
``LifeAccumulator`` (``life_from_samples``): the loads of sample k held over (t_{k-1}, t_k], which is the
FMU's own rule when samples are taken every communication step.
"""
from __future__ import annotations

import math

import numpy as np

from fmu_bearing.life import (
    LIFE_OUTPUTS,
    RATING_OUTPUTS,
    LifeAccumulator,
    LoadRatings,
    output_values,
)
from fmu_bearing.parameters import BearingParameters, from_values

#: FMU life output -> summary key (unit in the key, as the other summary figures)
OUTPUT_KEYS = {name: f"{name.replace('_revolutions', '')}_{unit}" for name, unit, _, _ in RATING_OUTPUTS + LIFE_OUTPUTS}


def figures(acc: LifeAccumulator, source: str, window: tuple[float, float]) -> dict:
    """The summary figures of an accumulator (an infinite life is written as JSON Infinity)."""
    out = {"source": source, "window_s": [float(window[0]), float(window[1])]}
    out.update(zip(OUTPUT_KEYS.values(), output_values(acc)))
    out["mean_relative_speed_rpm"] = acc.speed * 60.0
    return out


def accumulator(params: BearingParameters) -> LifeAccumulator:
    """An empty ``LifeAccumulator`` of the bearing ``params`` (its load ratings, its reliability factor)."""
    return LifeAccumulator(LoadRatings.of_bearing(params), params.reliability_factor)


def ball_load_names(params: BearingParameters) -> list[str]:
    """The recorded ball-load columns of the bearing ``params``."""
    return [f"ball_load_{r + 1}" for r in range(int(params.n_balls))]


def add_held_samples(acc: LifeAccumulator, t: np.ndarray, loads: np.ndarray, w_i: np.ndarray, w_o: np.ndarray,
                     previous: float | None, t_start: float = -math.inf, t_end: float = math.inf) -> float | None:
    """Add the samples k (times ``t``, ball loads [N] ``loads`` (rows), ring speeds [rad/s]) to ``acc``, each held
    over (t_{k-1}, t_k] within [t_start, t_end] (the FMU's own rule when samples are taken every communication
    step); ``previous``: the time of the sample before the first (None: the first is not added). A sample with a
    non-finite load adds nothing. Returns the last time (the next block's ``previous``)."""
    t, w_i, w_o = np.asarray(t).tolist(), np.asarray(w_i).tolist(), np.asarray(w_o).tolist()
    finite = np.all(np.isfinite(loads), axis=1).tolist()
    loads = np.asarray(loads).tolist()
    for k, tk in enumerate(t):
        if previous is not None:
            lo, hi = max(previous, t_start), min(tk, t_end)
            if hi > lo and finite[k]:
                acc.add(loads[k], w_i[k], w_o[k], hi - lo)
        previous = tk
    return previous


def life_from_samples(result, params: BearingParameters, t_start: float = -math.inf,
                      t_end: float = math.inf) -> LifeAccumulator:
    """Accumulate the recorded ball loads of ``result`` (a RunResult) over the window [t_start, t_end]."""
    acc = accumulator(params)
    t = result["time"]
    names = ball_load_names(params)
    if len(t) < 2 or not all(result.has(n) for n in names):
        return acc
    # only the samples k whose interval (t_{k-1}, t_k] meets the window add (the times rise): their rows alone
    # are stacked, not the whole run's ball loads
    first = max(1, int(np.searchsorted(t, t_start, side="right")))
    stop = min(len(t), int(np.searchsorted(t, t_end, side="left")) + 1)
    if stop > first:
        loads = np.column_stack([result[n][first:stop] for n in names])
        add_held_samples(acc, t[first:stop], loads, result["omega_inner"][first:stop],
                         result["omega_outer"][first:stop], float(t[first - 1]), t_start, t_end)
    return acc


def life_from_outputs(result) -> dict | None:
    """The component's life outputs at the end of the run (BallBearing FMU, or the in-process endpoint's
    accumulator; the master keeps them in ``meta["life_outputs"]``), or None if it has none."""
    values = result.meta.get("life_outputs")
    if not values or len(result["time"]) == 0:
        return None
    out = {"source": "component outputs", "window_s": [float(result["time"][0]), float(result["time"][-1])]}
    out.update({key: float(values[name]) for name, key in OUTPUT_KEYS.items() if name in values})
    return out


def run_parameters(result) -> BearingParameters | None:
    """The bearing parameters of a ball-bearing run from its meta data (None for other joints)."""
    config = result.meta.get("config") or {}
    if config.get("joint", "bearing") != "bearing":
        return None
    settings = dict(config.get("settings") or {})
    if config.get("balls") is not None:
        settings["n_balls"] = int(config["balls"])
    try:
        return from_values(settings)
    except ValueError:
        return None


def run_life(result, window: tuple[float, float] | None = None) -> dict | None:
    """Life figures of a ball-bearing run: over the whole run the component's final outputs if it has them,
    else (and over a ``window`` [s]) the recorded ball loads accumulated; None for other joints."""
    if window is None:
        out = life_from_outputs(result)
        if out is not None:
            return out
    params = run_parameters(result)
    streamed = result.streamed if window is None else None    # the whole of a streamed run: accumulated
    loads = result.ball_load_columns if streamed is None else streamed.ball_load_columns
    if params is None or not loads or len(result["time"]) < 2:
        return None
    t = result["time"]
    window = window or (float(t[0]), float(t[-1]))
    if streamed is not None:   # (None if its component was expected to give life outputs and did not at the end)
        return None if streamed.life is None else figures(streamed.life, "recorded samples", window)
    return figures(life_from_samples(result, params, *window), "recorded samples", window)
