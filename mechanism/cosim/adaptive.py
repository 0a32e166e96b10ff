"""Adaptive communication step with rollback: step doubling on the co-simulation, FMU state saved and restored.

Each macro step from (y, t) with size H:

1. save everything the step changes: the coupling scheme's history and last exchange, and the
   component's state (``getFMUstate`` through ``FmuEndpoint.get_state``; ``CouplingLoop.snapshot``);
   the mechanism state y is kept as it is (steps return new arrays);
2. *one* communication step of H (mechanism and FMU) -> y_big;
3. roll back (``setFMUstate``), then *two* communication steps of H/2 -> y_small;
4. the local error estimate is the difference of the two on the bearing's inputs
   e = (e_x, e_y) and v = (v_x, v_y) (eq. 10-12), each relative to its scale:

       err = max( |e_small - e_big| / E,  |v_small - v_big| / V ) / tol

   E = max(P_d/2, largest |e| so far), V = max(1 mm/s, largest |v| so far): the error is measured
   against the amplitude of the signal (as the study measures the global error: relative to the
   peak), with the radial clearance per side (10 µm by default) and 1 mm/s as floors while the
   amplitudes are still unknown;
5. err <= 1: accept y_small (the more accurate of the two; no Richardson extrapolation, as the
   FMU's state cannot be extrapolated) and keep the FMU in its state after the two half steps;
   err > 1: reject, roll back (``setFMUstate``) and retry with H/2 (H/4 if err > 8). A failed
   trial (an error status from the FMU, a non-finite state) is a rejection with err = inf.

Step sizes are *dyadic*: H = output_interval / 2^k. The step halves on rejection and doubles
only after ``patience`` (4) consecutive accepted steps with 8 err <= ``safety`` (0.5), i.e. where
the error would stay under tol at twice the step (the coupling's local error is O(H^3) where the
force is smooth), and only where the doubled step stays on the dyadic grid. So every output time
is reached exactly (samples need no interpolation, H <= output_interval) and the step changes
rarely: the default scheme's drift term d_n is estimated over the previous step and extrapolated
over the next one, which favours piecewise-constant steps.

The coupling inside is the run's scheme (``settings.scheme``, default ``law-model``,
``mechanism.cosim.coupling``); each step is ``master.CouplingLoop.communicate``, the same code the
fixed-step master runs (an iterative scheme repeats each of the three steps with its own rollback).

Cost per attempt (non-iterative scheme): three component steps (one of H, two of H/2), one get-state and one set-state
(two on rejection); ``meta`` reports accepted and rejected steps, mean/min/max accepted step H
(the state advances with two H/2 steps per accepted H), component calls and state saves/restores.

Contact onsets (issue 12): with the paper's constant damping a ball's force jumps by C v_r when it
enters the load zone, an O(H) impulse error in a step that straddles the onset, which the error
estimate sees only partly. With ``contact_step`` set, a step across which the component's
loaded-ball count changes is rejected (err = 2, the step halves) until H <= ``contact_step``: the
onsets and releases are resolved to that step (``meta["contact_rejections"]`` counts them).

What ``tol`` does and does not bound: it bounds the *local* error of each macro step relative to
the signal amplitude. The global error against the reference is measured by the step-size study
(``python -m mechanism stepsize-study --schemes adaptive``) and reported in docs/stepsize-study.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from mechanism.cosim.joint import BearingLink
from mechanism.cosim.master import (
    CouplingLoop,
    MasterSettings,
    Observer,
    RunFailure,
    await_warmup,
    finish,
)
from mechanism.cosim.record import Recorder, RunResult
from mechanism.multibody.solver import System


@dataclass
class AdaptiveSettings(MasterSettings):
    """Adaptive-step settings (SI). ``step`` is the first step tried; ``scheme`` the coupling inside."""

    tol: float = 1e-3                    # local error bound, relative to the signal amplitude
    step: float = 1e-6                   # first step tried [s]
    h_min: float = 1e-10                 # below this the run fails [s]
    h_max: float | None = None           # largest step [s]; None: the output interval
    safety: float = 0.5                  # the step doubles only if 8 err <= safety (local error O(H^3))
    e_floor: float = 1e-5                # eccentricity scale floor [m] (the radial clearance per side)
    v_floor: float = 1e-3                # relative velocity scale floor [m/s]
    patience: int = 4                    # accepted steps with room to spare before the step doubles
    keep_history: bool = False           # meta["step_history"]: (t, H, err, accepted) of every attempt
    contact_step: float | None = None    # reject a step whose loaded-ball count changes while H > this [s]
    description: str = "adaptive co-simulation"

    def __post_init__(self):
        if not self.tol > 0:
            raise ValueError(f"tol must be positive, not {self.tol!r}")
        if not (0 < self.h_min <= self.step):
            raise ValueError("h_min must be positive and <= the initial step")


#: the finest step is output_interval / 2^LEVELS (times are counted in integer ticks of that size)
LEVELS = 30


def run_adaptive(system: System, q0: np.ndarray, qd0: np.ndarray, settings: AdaptiveSettings,
                 observe: Observer, link: BearingLink, endpoint, meta: dict | None = None,
                 energy=None, contact_law=None) -> RunResult:
    """Integrate to ``settings.t_end`` with adaptive communication steps and rollback (see the module docstring).

    ``endpoint`` must offer ``get_state``/``set_state``/``free_state`` (``FmuEndpoint`` needs an FMU
    with canGetAndSetFMUstate; ``InProcessEndpoint`` always can).
    """
    dt_out = settings.output_interval
    n_out = int(round(settings.t_end / dt_out))
    h_max = min(settings.h_max or dt_out, dt_out)
    loop = CouplingLoop(system, settings, observe, link, endpoint, energy=energy, contact_law=contact_law)
    await_warmup(loop)      # a first run's warm-up still compiling kernels.advance, which this loop calls
    rec = Recorder(loop.columns, n_out + 2)
    info = dict(meta or {})
    info.update(output_interval_s=dt_out, t_end_s=n_out * dt_out, scheme="adaptive", inner_scheme=loop.scheme.name,
                endpoint=getattr(endpoint, "kind", "none"), tol=settings.tol)
    counts = {"accepted": 0, "rejected": 0, "failed_trials": 0, "saves": 0, "restores": 0, "contact_rejections": 0}
    contact_step = settings.contact_step
    loaded_index = list(loop.sample_names).index("loaded_balls") if contact_step is not None else -1
    steps: list[float] = []
    y = np.concatenate((q0, qd0)).astype(float)
    # dyadic steps: H = dt_out / 2^level, times counted in ticks of dt_out / 2^LEVELS (exact)
    top = max(0, math.ceil(math.log2(dt_out / h_max - 1e-9)))
    bottom = max(top, math.floor(math.log2(dt_out / settings.h_min)))
    if bottom > LEVELS:
        raise ValueError(f"h_min = {settings.h_min:g} s is below dt_out / 2^{LEVELS}")
    level = min(bottom, max(top, math.ceil(math.log2(dt_out / settings.step - 1e-9))))
    tick, ticks_out = 0, 1 << LEVELS
    good = 0
    e_amp, v_amp = settings.e_floor, settings.v_floor
    bar = tqdm(total=n_out, desc=settings.description, unit="sample", disable=not settings.progress,
               mininterval=0.5, leave=False)
    attempt = 0
    t = 0.0
    history: list | None = [] if settings.keep_history else None
    try:
        loop.start(y)
        loop.record(rec, 0.0, y)
        while tick < n_out * ticks_out:
            t = tick * dt_out / ticks_out
            snap = loop.snapshot()
            if contact_step is not None:
                loaded_before = loop.endpoint.sample()[loaded_index]
            counts["saves"] += 1
            try:
                while True:
                    attempt += 1
                    if level > bottom:
                        raise RunFailure(attempt, t, f"the step fell below h_min = {settings.h_min:g} s "
                                                     f"(the local error cannot be brought under tol)")
                    dticks = 1 << (LEVELS - level)
                    H = dt_out / (1 << level)
                    t_half = (tick + dticks // 2) * dt_out / ticks_out
                    t_new = (tick + dticks) * dt_out / ticks_out
                    try:
                        loop.communicate(y, t, H, attempt, t_new)
                        u_big = loop.inputs
                        loop.restore(snap)
                        counts["restores"] += 1
                        y_half = loop.communicate(y, t, t_half - t, attempt, t_half)
                        y_small = loop.communicate(y_half, t_half, t_new - t_half, attempt, t_new)
                        u_small = loop.inputs
                        de = math.hypot(u_small[0] - u_big[0], u_small[1] - u_big[1])
                        dv = math.hypot(u_small[2] - u_big[2], u_small[3] - u_big[3])
                        e_scale = max(e_amp, math.hypot(u_small[0], u_small[1]))
                        v_scale = max(v_amp, math.hypot(u_small[2], u_small[3]))
                        err = max(de / e_scale, dv / v_scale) / settings.tol
                        if contact_step is not None and H > contact_step:
                            now = loop.endpoint.sample()[loaded_index]
                            if now != loaded_before:             # a contact onset or release inside: refine
                                counts["contact_rejections"] += 1
                                err = max(err, 2.0)
                    except Exception:  # an error status from the FMU, divergence: a rejected trial
                        counts["failed_trials"] += 1
                        err = math.inf
                    if history is not None:
                        history.append((t, H, err, err <= 1.0))
                    if err <= 1.0:
                        break
                    counts["rejected"] += 1
                    loop.restore(snap)
                    counts["restores"] += 1
                    good = 0
                    level += 1 if err <= 8.0 else 2          # local error O(H^3): halving gains 8
            finally:
                loop.release(snap)
            counts["accepted"] += 1
            steps.append(H)
            y, tick = y_small, tick + dticks
            e_amp = max(e_amp, math.hypot(u_small[0], u_small[1]))
            v_amp = max(v_amp, math.hypot(u_small[2], u_small[3]))
            if tick % ticks_out == 0:
                loop.record(rec, tick * dt_out / ticks_out, y)
                bar.update(1)
            # grow only after `patience` steps whose error would stay under tol at twice the step
            good = good + 1 if err * 8.0 <= settings.safety else 0
            if good >= settings.patience and level > top and tick % (2 * dticks) == 0:
                level -= 1
                good = 0
        t = tick * dt_out / ticks_out
    except RunFailure as err:
        info["failure"] = {"step": err.step, "time_s": err.time, "cause": err.cause}
        result = finish(rec, info, "failed", str(err), endpoint, bar, loop)
    except Exception as err:
        cause = f"{type(err).__name__}: {err}"
        info["failure"] = {"step": attempt, "time_s": t, "cause": cause}
        result = finish(rec, info, "failed", f"stopped at attempt {attempt} (t = {t:.9g} s): {cause}",
                        endpoint, bar, loop)
    else:
        result = finish(rec, info, "completed", "", endpoint, bar, loop)
    arr = np.asarray(steps)
    result.meta.update(accepted_steps=counts["accepted"], rejected_steps=counts["rejected"],
                       failed_trials=counts["failed_trials"], contact_rejections=counts["contact_rejections"],
                       state_saves=counts["saves"],
                       state_restores=counts["restores"],
                       step_s=float(arr.mean()) if arr.size else 0.0,
                       mean_step_s=float(arr.mean()) if arr.size else 0.0,
                       min_step_s=float(arr.min()) if arr.size else 0.0,
                       max_step_s=float(arr.max()) if arr.size else 0.0)
    if history is not None:
        result.meta["step_history"] = history
    return result
