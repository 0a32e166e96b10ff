"""The life study's operating points, one run per point, and the parallel sweep.

Each point is an in-process run of the slider-crank (the same force law as the FMU, without the FMI
exchange cost) of ``startup_revs + window_revs`` crank revolutions; the life is accumulated with
``fmu_bearing.life.LifeAccumulator`` over the window only (``mechanism.output.life.life_from_samples``, samples
every step), so the start-up transient from the paper's initial state (housing and journal centres
coincident) does not count. Default window: the second crank revolution, the steady cycle of the
reproduction's "rev2" figures; the slider-crank's loads differ between the two half revolutions
(the slider's acceleration at the dead centres is r w^2 (1 +- r/l)), so the window is a whole revolution.
Default step 1e-5 s; 2e-5 s at most (``cases.DEFAULT_STEP``, ``cases.MAX_STEP``: measured differences there).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict

from fmu_bearing.parameters import from_values
from mechanism.output.life import life_from_samples
from mechanism.run import RunConfig, run
from mechanism.studies.life.cases import NAN_FIGURES, Point, Settings
from mechanism.studies.parallel import map_jobs, worker_count


def run_point(point: Point, settings: Settings) -> dict:
    """Run one point and return its CSV row (SI; failures give status "failed" and NaN figures)."""
    started = time.perf_counter()
    config = RunConfig(rpm=point.rpm, revs=settings.startup_revs + settings.window_revs, balls=settings.balls,
                       mode="inprocess", step=settings.step, output_interval=settings.step,
                       settings={"radial_clearance": point.radial_clearance}, progress=False)
    period = config.crank_period
    window = (settings.startup_revs * period, (settings.startup_revs + settings.window_revs) * period)
    row = {**asdict(point), "window_start_s": window[0], "window_end_s": window[1]}
    try:
        result = run(config)
        acc = life_from_samples(result, from_values(config.component_settings), *window)
        status, message = result.status, result.message
        covered = acc.time >= 0.999 * (window[1] - window[0])
        if status == "completed" and not covered:
            status, message = "failed", f"the run ended before the window (t = {result['time'][-1]:.6g} s)"
        loads = [result[c] for c in result.ball_load_columns]
        in_window = result["time"] >= window[0]
        max_load = max(float(x[in_window].max()) for x in loads) if loads and in_window.any() else math.nan
        row.update(NAN_FIGURES, dynamic_load_rating_N=acc.ratings.C_r, status=status, message=message)
        if status == "completed":  # a failed run's partial window is no life: its figures stay NaN
            row.update(equivalent_load_inner_N=acc.equivalent_load_inner,
                       equivalent_load_outer_N=acc.equivalent_load_outer, rating_life_Mrev=acc.life_revolutions,
                       rating_life_h=acc.life_hours, max_ball_load_N=max_load)
    except Exception as err:  # a bad point is reported in its row; the sweep goes on
        row.update(NAN_FIGURES, dynamic_load_rating_N=math.nan, status="failed", message=f"{type(err).__name__}: {err}")
    row["wall_s"] = time.perf_counter() - started
    return row


def sweep(pts: list[Point], settings: Settings, workers: int | None = None, progress: bool = True) -> list[dict]:
    """Run every point (in parallel processes when workers > 1), with a tqdm bar; rows in the order of ``pts``."""
    return map_jobs(run_point, [(p, settings) for p in pts], worker_count(workers, len(pts)), "life-study", progress)
