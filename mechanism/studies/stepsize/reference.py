"""The monolithic reference of each physical case (LSODA at rtol 1e-11), computed once and cached on
disk, and the comparison of a run with it (errors over the window, peak errors)."""
from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

import numpy as np

from mechanism.studies.stepsize.cases import REFERENCE_COLUMNS, window


# ------------------------------------------------------------------------------------- reference
def reference_run(phys: dict, rtol: float | None = None) -> dict:
    """One monolithic run of a physical case (at ``rtol``, default the case's): {"columns": the sampled
    ``REFERENCE_COLUMNS`` (arrays), "ok", "message", "wall_time_s", "rhs_calls", "pid"}."""
    from mechanism.run import RunConfig, run
    config = RunConfig(rpm=phys["rpm"], revs=phys["revs"], balls=phys["balls"], mode="monolithic",
                       settings=dict(phys["settings"]), output_interval=phys["output_interval"],
                       method=phys["method"], rtol=phys["rtol"] if rtol is None else rtol, progress=False)
    start = time.perf_counter()
    result = run(config)
    wall = time.perf_counter() - start
    return {"columns": {c: np.asarray(result[c]) for c in REFERENCE_COLUMNS if result.has(c)}, "ok": result.ok,
            "message": result.message, "wall_time_s": wall, "rhs_calls": result.meta.get("rhs_calls"),
            "pid": os.getpid()}


def reference_run_job(phys: dict, rtol: float | None = None) -> dict:
    """``reference_run`` for an executor: never raises (a failure is {"error": message})."""
    try:
        return reference_run(phys, rtol)
    except Exception as err:
        return {"error": f"{type(err).__name__}: {err}"}


def check_rtol(phys: dict) -> float:
    """The tolerance of the run that measures the reference's own error (its floor): rtol / 10."""
    return phys["rtol"] / 10


def combine_reference(phys: dict, main: dict, check: dict | None) -> dict:
    """The reference of a physical case from its run (``reference_run``) and the run at ``check_rtol`` (or
    None): the sampled columns of the first (lists), the floor (max relative force and eccentricity
    differences of the two over the window; {} without a usable check) and meta. RuntimeError if the run
    failed."""
    if "error" in main:
        raise RuntimeError(f"the monolithic reference failed: {main['error']}")
    if not main["ok"]:
        raise RuntimeError(f"the monolithic reference failed: {main['message']}")
    data = {c: np.asarray(v).tolist() for c, v in main["columns"].items()}
    floor = {}
    if check and check.get("ok") and len(check["columns"]["time"]) == len(data["time"]):
        case = {"dt_ref": phys["output_interval"], "window": window(phys["revs"], 60.0 / phys["rpm"])}
        metrics = compare(check["columns"], data, case)
        floor = {"force_max_rel": metrics["err_force_max_rel"], "ecc_max_rel": metrics["err_ecc_max_rel"],
                 "force_rms_rel": metrics["err_force_rms_rel"], "peak_error_rel": metrics["peak_error_rel"]}
    return {"columns": data, "floor": floor, "wall_time_s": main["wall_time_s"], "rhs_calls": main["rhs_calls"],
            "check_wall_time_s": (check or {}).get("wall_time_s"), "pid": main["pid"]}


def compute_reference(phys: dict) -> dict:
    """Run the monolithic reference of a physical case, and again at rtol/10 to measure its own error
    (the *floor*: max relative force and eccentricity differences over the window); return the sampled
    columns of the first (lists), the floor and meta (``combine_reference``)."""
    main = reference_run(phys)
    if not main["ok"]:
        return combine_reference(phys, main, None)           # raises
    return combine_reference(phys, main, reference_run(phys, check_rtol(phys)))


def reference_job(phys: dict) -> dict:
    """``compute_reference`` for an executor: never raises (a failure is {"error": message}), so that no
    exception has to cross a process boundary (custom exceptions may not unpickle there)."""
    try:
        return compute_reference(phys)
    except Exception as err:
        return {"error": f"{type(err).__name__}: {err}"}


def reference_path(cache: Path, key: str) -> Path:
    return cache / f"reference_{key}.npz"


def load_reference(cache: Path, key: str) -> dict | None:
    path = reference_path(cache, key)
    if not path.is_file():
        return None
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def save_reference(cache: Path, key: str, phys: dict, ref: dict) -> None:
    cache.mkdir(parents=True, exist_ok=True)
    arrays = {k: np.asarray(v, dtype=float) for k, v in ref["columns"].items()}
    arrays.update({f"floor__{k}": np.asarray(v if v is not None else np.nan, dtype=float)
                   for k, v in ref.get("floor", {}).items()})
    tmp = cache / f".reference_{key}.{os.getpid()}.npz"
    np.savez(tmp, **arrays)
    tmp.replace(reference_path(cache, key))
    meta = {"physical_case": phys, "wall_time_s": ref.get("wall_time_s"), "rhs_calls": ref.get("rhs_calls"),
            "check_wall_time_s": ref.get("check_wall_time_s"),
            "floor (rtol vs rtol/10, over the window)": ref.get("floor")}
    (cache / f"reference_{key}.json").write_text(json.dumps(meta, indent=2) + "\n")


def _clean(x):
    """float, or None if not finite (the table never holds NaN)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def compare(result_columns: dict, ref: dict, case: dict) -> dict:
    """Error metrics of a run's samples against the reference over the case's window (see module doc)."""
    dt = case["dt_ref"]
    w0, w1 = case["window"]
    t = np.asarray(result_columns["time"], dtype=float)
    idx = np.rint(t / dt).astype(np.int64)
    on_grid = np.abs(t - idx * dt) <= 1e-6 * dt
    lo, hi = int(math.ceil(w0 / dt - 1e-9)), int(math.floor(w1 / dt + 1e-9))
    sel = on_grid & (idx >= lo) & (idx <= hi) & (idx < len(ref["time"]))
    if not sel.any():
        raise ValueError("the run has no samples in the comparison window")
    ri = idx[sel]
    out = {}

    def get(cols, source, rows):
        return [np.asarray(source[c], dtype=float)[rows] for c in cols]

    quantities = {"ecc": ("e_x", "e_y"), "force": ("F_x", "F_y"), "slider_a": ("slider_a",),
                  "crank_moment": ("crank_moment",)}
    finite = True
    for name, cols in quantities.items():
        run_v = get(cols, result_columns, sel)
        ref_v = get(cols, ref, ri)
        diff = np.sqrt(sum((a - b) ** 2 for a, b in zip(run_v, ref_v)))
        mag = np.sqrt(sum(b ** 2 for b in ref_v))
        finite &= bool(np.all(np.isfinite(diff)))
        scale = float(np.max(mag)) if mag.size else 0.0
        emax, erms = float(np.max(diff)), float(np.sqrt(np.mean(diff ** 2)))
        out[f"err_{name}_max"], out[f"err_{name}_rms"] = emax, erms
        out[f"err_{name}_max_rel"] = emax / scale if scale > 0 else None
        out[f"err_{name}_rms_rel"] = erms / scale if scale > 0 else None
    peaks = {"peak_force": ("F_x", "F_y"), "max_ecc": ("e_x", "e_y")}
    for name, cols in peaks.items():
        run_peak = float(np.max(np.hypot(*get(cols, result_columns, sel))))
        ref_peak = float(np.max(np.hypot(*get(cols, ref, ri))))
        out[name], out[f"{name}_ref"] = run_peak, ref_peak
        out[f"{name}_err_rel"] = run_peak / ref_peak - 1.0 if ref_peak > 0 else None
    if "max_ball_load" in result_columns and "max_ball_load" in ref:
        run_peak = float(np.max(np.asarray(result_columns["max_ball_load"], dtype=float)[sel]))
        ref_peak = float(np.max(np.asarray(ref["max_ball_load"], dtype=float)[ri]))
        out["max_ball_load"], out["max_ball_load_ref"] = run_peak, ref_peak
        out["max_ball_load_err_rel"] = run_peak / ref_peak - 1.0 if ref_peak > 0 else None
    # the coupling energy error (mechanism.cosim.energy): the run's energy residual at its end (the whole
    # run, start-up included), relative to the energy its damping dissipated; the reference's is the floor
    for prefix, source in (("", result_columns), ("ref_", ref)):
        if "energy_residual" in source and "damping_dissipation" in source and len(source["energy_residual"]):
            last = -1 if prefix == "" else min(int(idx[sel][-1]), len(source["energy_residual"]) - 1)
            res = float(np.asarray(source["energy_residual"], dtype=float)[last])
            dis = float(np.asarray(source["damping_dissipation"], dtype=float)[last])
            if prefix == "":
                out["energy_residual"], out["damping_dissipation"] = res, dis
            out[f"{prefix}energy_residual_rel"] = res / dis if dis > 0 else None
    pe = [abs(out[k]) for k in ("peak_force_err_rel", "max_ecc_err_rel") if out.get(k) is not None]
    out["peak_error_rel"] = max(pe) if pe else None
    out = {k: _clean(v) for k, v in out.items()}
    out["_finite"] = finite
    return out
