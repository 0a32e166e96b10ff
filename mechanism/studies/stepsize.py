"""Co-simulation step-size study: error, cost and stability of each coupling scheme against the monolithic reference.

``python -m mechanism stepsize-study --rpm 1200 --steps 1e-7:1e-4:13 --schemes all --out DIR``

For every case (crank speed x ball count x component setting x scheme x step) the study runs the
co-simulation (through the FMU by default) and compares it with the monolithic reference of the
same physical case (``mechanism.monolithic``: LSODA at rtol 1e-11, computed once per physical case
and cached on disk under a hash of its parameters). See docs/stepsize-study.md for the method and
the measured results; in short:

* **Steps** are log-spaced (``lo:hi:count``) and *snapped* to the output grid: a step below the
  output interval dt (1e-5 s) becomes dt/round(dt/h), one above it dt*round(h/dt), so every run
  is sampled on the reference's grid (a step above dt is sampled every step, and compared at
  those times). The CSV gives the nominal and the snapped step.
* **Window**: the second crank revolution [T, 2T] (``--revs`` >= 2, default 2); for shorter runs
  the second half of the run [revs T/2, revs T].
* **Errors** over the window, on the common samples: max and RMS of |e - e_ref| (the vector
  eccentricity error, m), |F - F_ref| (joint force, N), slider acceleration (m/s^2) and crank
  moment (N m); each also relative to the reference's peak magnitude in the window (``_rel``).
  Peak errors: the relative error of the window's peak |F| and max |e| (and max ball load);
  ``peak_error_rel`` = max(|peak |F| error|, |max |e| error|) is the **1 % criterion**.
* **Stability**: a run that stops (an error status from the FMU, the eccentricity limit,
  a non-finite state, constraint drift) is "unstable (failed)"; one whose max relative force or
  eccentricity error exceeds ``--divergence`` (50 %) is "unstable (divergent)"; runs whose step
  count exceeds ``--max-steps-per-case`` are "skipped (cost)" unless ``--allow-slow``; a case that
  raises is "error". Errors are left empty, never NaN, where they do not exist.
* **Order**: least-squares slope of log(max relative force error) against log(step) over the
  stable points whose error lies between max(1e-5, 3x the reference's floor) and 20 % (``--order-range``).
  The floor is the reference's own error, measured by running it again at rtol/10.
* **Adaptive**: scheme ``adaptive`` (``mechanism.adaptive``) runs once per ``--tols`` value; its
  step axis is the mean accepted step.

Cases run in parallel (a process pool of ``--workers``, default the core count, or a Dask
cluster given by ``--scheduler tcp://HOST:PORT``; the same case function either way); each case
opens and frees its own FMU instance and records its pid/worker and start/end time. A failing case
is a row with its message; it never stops the sweep.
"""
from __future__ import annotations

import argparse
import csv
import hashlib
import itertools
import json
import math
import os
import socket
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np

#: the reference's sampling interval and the study's default output interval [s]
OUTPUT_INTERVAL = 1e-5
DEFAULT_STEPS = "1e-7:1e-4:13"
DEFAULT_TOLS = "1e-2:1e-5:4"
#: fixed-step runs longer than this many communication steps are skipped unless --allow-slow
MAX_STEPS_PER_CASE = 200_000
DIVERGENCE = 0.5
#: order fits use stable points with max relative force error in [ORDER_FLOOR, ORDER_CEILING]
ORDER_FLOOR, ORDER_CEILING = 1e-5, 0.2
ONE_PERCENT = 0.01
REFERENCE_VERSION = 2          # bump when the reference's model or sampling changes (invalidates the cache)
ADAPTIVE = "adaptive"

STABLE = "stable"
FAILED = "unstable (failed)"
DIVERGENT = "unstable (divergent)"
NONFINITE = "unstable (non-finite)"
SKIPPED = "skipped (cost)"
ERROR = "error"

#: CSV columns and their SI units
COLUMNS: list[tuple[str, str]] = [
    ("case", ""), ("group", ""), ("rpm", "rpm"), ("balls", "1"), ("settings", ""), ("scheme", ""),
    ("mode", ""), ("step_nominal", "s"), ("step", "s"), ("tol", "1"), ("output_interval", "s"),
    ("revs", "1"), ("window_start", "s"), ("window_end", "s"), ("status", ""), ("message", ""),
    ("wall_time", "s"), ("component_calls", "1"), ("steps", "1"), ("rejected_steps", "1"),
    ("substeps_total", "1"), ("min_step", "s"), ("max_step", "s"),
    ("err_ecc_max", "m"), ("err_ecc_rms", "m"), ("err_ecc_max_rel", "1"), ("err_ecc_rms_rel", "1"),
    ("err_force_max", "N"), ("err_force_rms", "N"), ("err_force_max_rel", "1"), ("err_force_rms_rel", "1"),
    ("err_slider_a_max", "m/s^2"), ("err_slider_a_rms", "m/s^2"), ("err_slider_a_max_rel", "1"),
    ("err_slider_a_rms_rel", "1"),
    ("err_crank_moment_max", "N.m"), ("err_crank_moment_rms", "N.m"), ("err_crank_moment_max_rel", "1"),
    ("err_crank_moment_rms_rel", "1"),
    ("peak_force_ref", "N"), ("peak_force", "N"), ("peak_force_err_rel", "1"),
    ("max_ecc_ref", "m"), ("max_ecc", "m"), ("max_ecc_err_rel", "1"),
    ("max_ball_load_ref", "N"), ("max_ball_load", "N"), ("max_ball_load_err_rel", "1"),
    ("peak_error_rel", "1"),
    ("ref_floor_force_max_rel", "1"), ("ref_floor_ecc_max_rel", "1"),
    ("pid", ""), ("host", ""), ("worker", ""), ("started_at", "s"), ("ended_at", "s"),
]
COLUMN_NAMES = [c for c, _ in COLUMNS]
#: columns that depend on where and when a case ran, not on what it computed
PLACEMENT_COLUMNS = ("wall_time", "pid", "host", "worker", "started_at", "ended_at")
REFERENCE_COLUMNS = ("time", "e_x", "e_y", "F_x", "F_y", "slider_a", "crank_moment", "max_ball_load")
ORDER_METRIC = "err_force_max_rel"
PEAK_METRIC = "peak_error_rel"


# ----------------------------------------------------------------------------------------- cases
def parse_grid(text: str) -> list[float]:
    """``lo:hi:count`` (log-spaced, both ends included) or a comma list -> sorted values."""
    text = text.strip()
    if ":" in text:
        parts = text.split(":")
        if len(parts) != 3:
            raise ValueError(f"expected lo:hi:count, got {text!r}")
        lo, hi, count = float(parts[0]), float(parts[1]), int(parts[2])
        if not (lo > 0 and hi > 0 and count >= 1):
            raise ValueError(f"{text!r}: lo and hi must be positive and count >= 1")
        values = [lo] if count == 1 else list(np.geomspace(lo, hi, count))
    else:
        values = [float(x) for x in text.split(",") if x.strip()]
    if not values or any(not (v > 0 and math.isfinite(v)) for v in values):
        raise ValueError(f"{text!r}: values must be positive numbers")
    return sorted(float(v) for v in values)


def snap_step(h: float, dt: float = OUTPUT_INTERVAL) -> float:
    """The step actually used: dt/round(dt/h) below dt, dt*round(h/dt) above it (so it lands on dt's grid)."""
    if h <= dt:
        return dt / max(1, round(dt / h))
    return dt * max(1, round(h / dt))


def parse_settings(items: Sequence[str]) -> list[dict]:
    """``NAME=V1[,V2...]`` items -> the cartesian product of the settings, as dicts (numbers typed)."""
    from ..cli import parse_setting
    axes = []
    for item in items:
        if "=" not in item:
            raise ValueError(f"--set expects NAME=VALUE[,VALUE...], got {item!r}")
        name, raw = item.split("=", 1)
        axes.append([parse_setting(f"{name}={v}") for v in raw.split(",") if v.strip()])
    return [dict(combo) for combo in itertools.product(*axes)] if axes else [{}]


@dataclass
class StudyConfig:
    """Everything the study needs (SI; rpm)."""

    out: str = "results/stepsize"
    rpms: list[float] = field(default_factory=lambda: [1200.0])
    balls: list[int | None] = field(default_factory=lambda: [None])
    settings: list[dict] = field(default_factory=lambda: [{}])
    schemes: list[str] = field(default_factory=lambda: ["jacobian-drift", "jacobian", "extrap1", "zoh"])
    steps: list[float] = field(default_factory=lambda: parse_grid(DEFAULT_STEPS))
    tols: list[float] = field(default_factory=lambda: parse_grid(DEFAULT_TOLS))
    revs: float = 2.0
    mode: str = "cosim"
    fmu: str | None = None
    output_interval: float = OUTPUT_INTERVAL
    workers: int | None = None
    scheduler: str | None = None
    max_steps_per_case: int = MAX_STEPS_PER_CASE
    allow_slow: bool = False
    divergence: float = DIVERGENCE
    reference_rtol: float = 1e-11
    reference_method: str = "LSODA"
    reference_cache: str | None = None
    order_range: tuple[float, float] = (ORDER_FLOOR, ORDER_CEILING)
    plots: bool = True
    progress: bool = True

    def __post_init__(self):
        from ..coupling import SCHEMES
        unknown = [s for s in self.schemes if s not in SCHEMES and s != ADAPTIVE]
        if unknown:
            raise ValueError(f"unknown scheme(s) {unknown}; choose from {', '.join(list(SCHEMES) + [ADAPTIVE])}")
        if self.mode not in ("cosim", "inprocess"):
            raise ValueError(f"mode must be cosim or inprocess, not {self.mode!r}")
        if not (self.revs > 0 and self.output_interval > 0):
            raise ValueError("revs and output_interval must be positive")


def group_label(rpm: float, balls, settings: dict) -> str:
    parts = [f"{rpm:g}rpm"]
    if balls is not None:
        parts.append(f"{balls}balls")
    parts += [f"{k}={v}" for k, v in sorted(settings.items())]
    return "_".join(parts)


def window(revs: float, period: float) -> tuple[float, float]:
    """The comparison window [s]: the second revolution, or the second half of a shorter run."""
    if revs >= 2.0:
        return period, 2.0 * period
    return 0.5 * revs * period, revs * period


def physical_case(rpm: float, balls, settings: dict, config: StudyConfig) -> dict:
    """What defines a reference (JSON-able); its hash names the cache file."""
    return {"rpm": float(rpm), "balls": balls, "settings": dict(sorted(settings.items())), "revs": float(config.revs),
            "output_interval": config.output_interval, "rtol": config.reference_rtol,
            "method": config.reference_method, "version": REFERENCE_VERSION}


def reference_key(phys: dict) -> str:
    return hashlib.sha1(json.dumps(phys, sort_keys=True).encode()).hexdigest()[:16]


def build_cases(config: StudyConfig, fmu: str | None) -> list[dict]:
    """The cases of the sweep, in a stable order (their ``case`` index)."""
    cases = []
    for rpm, balls, settings in itertools.product(config.rpms, config.balls, config.settings):
        phys = physical_case(rpm, balls, settings, config)
        period = 60.0 / rpm
        w0, w1 = window(config.revs, period)
        for scheme in config.schemes:
            grid = config.tols if scheme == ADAPTIVE else config.steps
            for value in grid:
                case = {"group": group_label(rpm, balls, settings), "rpm": float(rpm), "balls": balls,
                        "settings": dict(settings), "scheme": scheme, "mode": config.mode, "fmu": fmu,
                        "revs": config.revs, "window": (w0, w1), "reference": reference_key(phys),
                        "dt_ref": config.output_interval, "divergence": config.divergence}
                if scheme == ADAPTIVE:
                    case.update(tol=float(value), step_nominal=None, step=None,
                                output_interval=config.output_interval)
                else:
                    h = snap_step(value, config.output_interval)
                    case.update(tol=None, step_nominal=float(value), step=h,
                                output_interval=max(h, config.output_interval))
                case["estimated_steps"] = (config.revs * period / case["step"]) if case["step"] else 0.0
                cases.append(case)
    for i, case in enumerate(cases):
        case["case"] = i
    return cases


# ------------------------------------------------------------------------------------- reference
def compute_reference(phys: dict) -> dict:
    """Run the monolithic reference of a physical case, and again at rtol/10 to measure its own error
    (the *floor*: max relative force and eccentricity differences over the window); return the sampled
    columns of the first (lists), the floor and meta."""
    from ..run import RunConfig, run
    config = RunConfig(rpm=phys["rpm"], revs=phys["revs"], balls=phys["balls"], mode="monolithic",
                       settings=dict(phys["settings"]), output_interval=phys["output_interval"],
                       method=phys["method"], rtol=phys["rtol"], progress=False)
    start = time.perf_counter()
    result = run(config)
    wall = time.perf_counter() - start
    if not result.ok:
        raise RuntimeError(f"the monolithic reference failed: {result.message}")
    data = {c: result[c].tolist() for c in REFERENCE_COLUMNS if result.has(c)}
    check = run(replace(config, rtol=phys["rtol"] / 10))
    floor = {}
    if check.ok and len(check["time"]) == len(result["time"]):
        case = {"dt_ref": phys["output_interval"], "window": window(phys["revs"], 60.0 / phys["rpm"])}
        metrics = compare({c: check[c] for c in REFERENCE_COLUMNS if check.has(c)}, data, case)
        floor = {"force_max_rel": metrics["err_force_max_rel"], "ecc_max_rel": metrics["err_ecc_max_rel"],
                 "force_rms_rel": metrics["err_force_rms_rel"], "peak_error_rel": metrics["peak_error_rel"]}
    return {"columns": data, "floor": floor, "wall_time_s": wall, "rhs_calls": result.meta.get("rhs_calls"),
            "pid": os.getpid()}


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
            "floor (rtol vs rtol/10, over the window)": ref.get("floor")}
    (cache / f"reference_{key}.json").write_text(json.dumps(meta, indent=2) + "\n")


# ------------------------------------------------------------------------------------ one case
def _worker_name() -> str:
    if "distributed" in sys.modules:  # only a Dask worker has imported it
        try:
            from distributed import get_worker
            return f"dask {get_worker().address}"
        except Exception:
            pass
    return f"pid {os.getpid()}"


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
    pe = [abs(out[k]) for k in ("peak_force_err_rel", "max_ecc_err_rel") if out.get(k) is not None]
    out["peak_error_rel"] = max(pe) if pe else None
    out = {k: _clean(v) for k, v in out.items()}
    out["_finite"] = finite
    return out


def run_case(case: dict, ref: dict | None) -> dict:
    """Run one case and measure it against ``ref`` (the reference's columns); never raises: a row."""
    started = time.time()
    row = {k: None for k in COLUMN_NAMES}
    row.update(case=case["case"], group=case["group"], rpm=case["rpm"], balls=case["balls"],
               settings=";".join(f"{k}={v}" for k, v in sorted(case["settings"].items())),
               scheme=case["scheme"], mode=case["mode"], step_nominal=case["step_nominal"], step=case["step"],
               tol=case["tol"], output_interval=case["output_interval"], revs=case["revs"],
               window_start=case["window"][0], window_end=case["window"][1],
               pid=os.getpid(), host=socket.gethostname(), worker=_worker_name(), started_at=started)
    wall0 = time.perf_counter()
    try:
        if ref is None:
            raise RuntimeError(case.get("reference_error") or "no reference")
        from ..run import RunConfig, run
        config = RunConfig(rpm=case["rpm"], revs=case["revs"], balls=case["balls"], mode=case["mode"],
                           step=case["step"] or case["output_interval"], output_interval=case["output_interval"],
                           settings=dict(case["settings"]), fmu=case["fmu"], progress=False)
        if case["scheme"] == ADAPTIVE:
            from ..adaptive import run_adaptive_config
            result = run_adaptive_config(config, case["tol"], h_max=case["output_interval"])
        else:
            result = run(replace(config, scheme=case["scheme"]))
        row["wall_time"] = time.perf_counter() - wall0
        meta = result.meta
        row["component_calls"] = meta.get("component_calls")
        row["substeps_total"] = meta.get("substeps_total")
        if case["scheme"] == ADAPTIVE:
            row.update(step=_clean(meta.get("mean_step_s")), steps=meta.get("accepted_steps"),
                       rejected_steps=meta.get("rejected_steps"), min_step=_clean(meta.get("min_step_s")),
                       max_step=_clean(meta.get("max_step_s")))
        else:
            row.update(steps=int(round(meta.get("t_end_s", 0.0) / case["step"])) if result.ok else
                       (meta.get("failure") or {}).get("step"), rejected_steps=0,
                       min_step=case["step"], max_step=case["step"])
        if not result.ok:
            row["status"], row["message"] = FAILED, result.message
        else:
            cols = {c: result[c] for c in REFERENCE_COLUMNS if result.has(c)}
            metrics = compare(cols, ref, case)
            finite = metrics.pop("_finite")
            row.update(metrics)
            row["ref_floor_force_max_rel"] = _clean(ref["floor__force_max_rel"]) if "floor__force_max_rel" in ref else None
            row["ref_floor_ecc_max_rel"] = _clean(ref["floor__ecc_max_rel"]) if "floor__ecc_max_rel" in ref else None
            worst = max((metrics.get(k) or 0.0) for k in ("err_force_max_rel", "err_ecc_max_rel"))
            if not finite:
                row["status"], row["message"] = NONFINITE, "non-finite samples in the window"
            elif worst > case["divergence"]:
                row["status"] = DIVERGENT
                row["message"] = (f"max relative error {worst:.3g} exceeds {case['divergence']:g} "
                                  f"(ran to the end on a wrong trajectory)")
            else:
                row["status"], row["message"] = STABLE, ""
    except Exception as err:  # a case that cannot run is a row, not the end of the sweep
        row["wall_time"] = time.perf_counter() - wall0
        row["status"], row["message"] = ERROR, f"{type(err).__name__}: {err}"
    row["ended_at"] = time.time()
    return row


def skipped_row(case: dict, reason: str) -> dict:
    row = {k: None for k in COLUMN_NAMES}
    row.update(case=case["case"], group=case["group"], rpm=case["rpm"], balls=case["balls"],
               settings=";".join(f"{k}={v}" for k, v in sorted(case["settings"].items())),
               scheme=case["scheme"], mode=case["mode"], step_nominal=case["step_nominal"], step=case["step"],
               tol=case["tol"], output_interval=case["output_interval"], revs=case["revs"],
               window_start=case["window"][0], window_end=case["window"][1], status=SKIPPED, message=reason)
    return row


# ------------------------------------------------------------------------------------- executors
class Executor:
    """Runs ``fn(*args)`` jobs on a local process pool or a Dask cluster; yields (key, result) as they finish."""

    def __init__(self, workers: int | None = None, scheduler: str | None = None):
        self.workers = max(1, workers or os.cpu_count() or 1)
        self.scheduler = scheduler
        self._pool = None
        self._client = None

    def __enter__(self):
        if self.scheduler:
            try:
                from distributed import Client
            except ImportError as err:
                raise RuntimeError("--scheduler needs dask.distributed: pip install 'bearing-cosim[studies]'") from err
            self._client = Client(self.scheduler)
        elif self.workers > 1:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor
            self._pool = ProcessPoolExecutor(max_workers=self.workers,
                                             mp_context=multiprocessing.get_context("spawn"))
        return self

    def __exit__(self, *exc):
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        if self._client is not None:
            self._client.close()

    @property
    def description(self) -> str:
        if self._client is not None:
            return f"Dask cluster {self.scheduler}"
        return f"{self.workers} local process(es)" if self._pool is not None else "this process"

    def map(self, fn: Callable, jobs: Iterable[tuple[object, tuple]]) -> Iterable[tuple[object, object]]:
        """jobs: (key, args); yields (key, result or exception instance)."""
        jobs = list(jobs)
        if self._client is not None:
            from distributed import as_completed
            futures = {}
            for key, args in jobs:
                futures[self._client.submit(fn, *args, pure=False)] = key
            for fut in as_completed(list(futures)):
                try:
                    yield futures[fut], fut.result()
                except Exception as err:
                    yield futures[fut], err
        elif self._pool is not None:
            from concurrent.futures import as_completed
            futures = {self._pool.submit(fn, *args): key for key, args in jobs}
            for fut in as_completed(futures):
                try:
                    yield futures[fut], fut.result()
                except Exception as err:
                    yield futures[fut], err
        else:
            for key, args in jobs:
                try:
                    yield key, fn(*args)
                except Exception as err:
                    yield key, err


# ------------------------------------------------------------------------------------- the study
@dataclass
class StudyResult:
    rows: list[dict]
    summary: dict
    out: Path
    wall_time: float


def _progress(total: int, desc: str, enabled: bool):
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit="case", disable=not enabled, mininterval=0.5)


def run_study(config: StudyConfig) -> StudyResult:
    """Run the sweep, write stepsize.csv, stepsize_summary.json/.md and the plots into ``config.out``."""
    start = time.perf_counter()
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    cache = Path(config.reference_cache) if config.reference_cache else out / "references"
    fmu = None
    if config.mode == "cosim":
        from ..run import RunConfig, fmu_path
        fmu = str(Path(fmu_path(RunConfig(fmu=config.fmu))).resolve())
    cases = build_cases(config, fmu)
    physical = {}
    for rpm, balls, settings in itertools.product(config.rpms, config.balls, config.settings):
        phys = physical_case(rpm, balls, settings, config)
        physical[reference_key(phys)] = phys
    references: dict[str, dict] = {}
    reference_errors: dict[str, str] = {}
    with Executor(config.workers, config.scheduler) as executor:
        missing = []
        for key, phys in physical.items():
            ref = load_reference(cache, key)
            if ref is None:
                missing.append((key, (phys,)))
            else:
                references[key] = ref
        if missing:
            bar = _progress(len(missing), "references (monolithic)", config.progress)
            for key, result in executor.map(reference_job, missing):
                if isinstance(result, Exception):
                    reference_errors[key] = f"reference failed: {type(result).__name__}: {result}"
                elif "error" in result:
                    reference_errors[key] = f"reference failed: {result['error']}"
                else:
                    save_reference(cache, key, physical[key], result)
                    references[key] = load_reference(cache, key)
                bar.update(1)
            bar.close()
        rows: dict[int, dict] = {}
        jobs = []
        for case in cases:
            if (case["scheme"] != ADAPTIVE and not config.allow_slow
                    and case["estimated_steps"] > config.max_steps_per_case):
                rows[case["case"]] = skipped_row(
                    case, f"{case['estimated_steps']:.3g} steps > --max-steps-per-case {config.max_steps_per_case} "
                          f"(run with --allow-slow)")
                continue
            ref = references.get(case["reference"])
            if ref is None:
                case["reference_error"] = reference_errors.get(case["reference"], "no reference")
            jobs.append((case, ref))
        # the longest cases first, so the pool ends evenly
        jobs.sort(key=lambda j: -(j[0]["estimated_steps"] or 3e4))
        bar = _progress(len(cases), f"step-size study ({executor.description})", config.progress)
        bar.update(len(rows))
        by_id = {case["case"]: case for case, _ in jobs}
        for key, result in executor.map(run_case, [(case["case"], (case, ref)) for case, ref in jobs]):
            if isinstance(result, Exception):  # the worker itself died (run_case never raises)
                failure = result
                result = skipped_row(by_id[key], "")
                result.update(status=ERROR, message=f"{type(failure).__name__}: {failure}")
            rows[key] = result
            bar.update(1)
            bar.set_postfix_str(f"{result['scheme']} {result['status']}", refresh=False)
        bar.close()
    ordered = [rows[i] for i in sorted(rows)]
    summary = summarize(ordered, config)
    summary["wall_time_s"] = time.perf_counter() - start
    summary["executor"] = config.scheduler or f"{max(1, config.workers or os.cpu_count() or 1)} local processes"
    summary["references"] = {k: {"physical_case": physical[k], "error": reference_errors.get(k)} for k in physical}
    write_csv(ordered, out / "stepsize.csv")
    (out / "stepsize_summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "stepsize_summary.md").write_text(summary_markdown(summary, config))
    if config.plots:
        plot_study(ordered, summary, out)
    return StudyResult(ordered, summary, out, time.perf_counter() - start)


def write_csv(rows: list[dict], path: Path) -> None:
    """One row per case; header 'name [unit]'; missing values are empty cells (never NaN)."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow([f"{c} [{u}]" if u else c for c, u in COLUMNS])
        for row in rows:
            w.writerow(["" if row.get(c) is None else (f"{row[c]:.15g}" if isinstance(row[c], float) else row[c])
                        for c in COLUMN_NAMES])


def read_csv(path: Path) -> list[dict]:
    """The rows of a stepsize.csv, as strings keyed by column name (units stripped)."""
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = [h.split(" [")[0] for h in next(reader)]
        return [dict(zip(header, r)) for r in reader]


INTEGER_COLUMNS = ("case", "balls", "component_calls", "steps", "rejected_steps", "substeps_total", "pid")


def rows_from_csv(path: Path) -> list[dict]:
    """The rows of a stepsize.csv with the types ``run_study`` produced (numbers, None for empty cells)."""
    units = dict(COLUMNS)
    rows = []
    for raw in read_csv(path):
        row = {}
        for c in COLUMN_NAMES:
            v = raw.get(c, "")
            if v == "":
                row[c] = "" if c in ("settings", "message") else None
            elif c in INTEGER_COLUMNS:
                row[c] = int(float(v))
            elif units[c]:
                row[c] = float(v)
            else:
                row[c] = v
        rows.append(row)
    return rows


def replot(config: StudyConfig) -> dict:
    """Rewrite the summaries and plots of ``config.out`` from its stepsize.csv (no run)."""
    out = Path(config.out)
    rows = rows_from_csv(out / "stepsize.csv")
    previous = out / "stepsize_summary.json"
    summary = summarize(rows, config)
    if previous.is_file():
        old = json.loads(previous.read_text())
        for k in ("wall_time_s", "executor", "references"):
            if k in old:
                summary[k] = old[k]
        summary["config"] = old.get("config", summary["config"])
    previous.write_text(json.dumps(summary, indent=2) + "\n")
    (out / "stepsize_summary.md").write_text(summary_markdown(summary, config))
    if config.plots:
        plot_study(rows, summary, out)
    return summary


# ------------------------------------------------------------------------------------- summaries
def _axis(row: dict) -> float | None:
    return row["step"]


def fit_order(rows: list[dict], metric: str = ORDER_METRIC, floor: float = ORDER_FLOOR,
              ceiling: float = ORDER_CEILING) -> dict:
    """Least-squares slope of log(metric) vs log(step) over stable rows with floor <= metric <= ceiling."""
    pts = sorted((r["step"], r[metric]) for r in rows
                 if r["status"] == STABLE and r.get("step") and r.get(metric) is not None
                 and floor <= r[metric] <= ceiling)
    info = {"metric": metric, "points": len(pts), "range": [floor, ceiling]}
    if len(pts) < 3:
        info.update(order=None, reason=f"{len(pts)} point(s) in the asymptotic range (need 3)")
        return info
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    slope, intercept = np.polyfit(x, y, 1)
    info.update(order=float(slope), intercept=float(intercept), steps=[pts[0][0], pts[-1][0]])
    return info


def _largest_ok(rows: list[dict], ok: Callable[[dict], bool]) -> float | None:
    """Largest step h such that every step <= h that ran satisfies ``ok``."""
    ran = sorted((r for r in rows if r["status"] not in (SKIPPED, ERROR) and r.get("step")), key=_axis)
    best = None
    for r in ran:
        if not ok(r):
            break
        best = r["step"]
    return best


def summarize(rows: list[dict], config: StudyConfig) -> dict:
    """Per group and scheme: largest stable step, largest step within 1 %, orders, cost; per case counts."""
    groups: dict[str, dict] = {}
    for g in dict.fromkeys(r["group"] for r in rows):
        per_scheme = {}
        for scheme in dict.fromkeys(r["scheme"] for r in rows if r["group"] == g):
            rs = [r for r in rows if r["group"] == g and r["scheme"] == scheme]
            ran = [r for r in rs if r["status"] not in (SKIPPED, ERROR)]
            unstable = sorted(r["step"] for r in ran if r["status"] != STABLE and r.get("step"))
            within = [r for r in ran if r["status"] == STABLE and r.get(PEAK_METRIC) is not None
                      and r[PEAK_METRIC] <= ONE_PERCENT]
            largest_1pct = _largest_ok(rs, lambda r: r["status"] == STABLE and r.get(PEAK_METRIC) is not None
                                       and r[PEAK_METRIC] <= ONE_PERCENT)
            at = next((r for r in rs if r.get("step") == largest_1pct), None) if largest_1pct else None
            largest_1pct_pointwise = _largest_ok(rs, lambda r: r["status"] == STABLE and r.get(ORDER_METRIC) is not None
                                                 and r[ORDER_METRIC] <= ONE_PERCENT)
            cheapest = min(within, key=lambda r: r["wall_time"] or math.inf, default=None)
            lo, hi = config.order_range
            floor_f = max((r["ref_floor_force_max_rel"] for r in rs if r.get("ref_floor_force_max_rel")), default=None)
            floor_e = max((r["ref_floor_ecc_max_rel"] for r in rs if r.get("ref_floor_ecc_max_rel")), default=None)
            entry = {
                "cases": len(rs), "ran": len(ran), "stable": sum(r["status"] == STABLE for r in rs),
                "skipped": sum(r["status"] == SKIPPED for r in rs), "errors": sum(r["status"] == ERROR for r in rs),
                "largest_stable_step_s": _largest_ok(rs, lambda r: r["status"] == STABLE),
                "smallest_unstable_step_s": unstable[0] if unstable else None,
                "largest_step_within_1pct_s": largest_1pct,
                "peak_error_at_that_step": at.get(PEAK_METRIC) if at else None,
                "largest_step_within_1pct_pointwise_s": largest_1pct_pointwise,
                "wall_time_at_that_step_s": at.get("wall_time") if at else None,
                "cheapest_run_within_1pct": ({"step_s": cheapest["step"], "tol": cheapest["tol"],
                                              "wall_time_s": cheapest["wall_time"],
                                              "component_calls": cheapest["component_calls"],
                                              PEAK_METRIC: cheapest[PEAK_METRIC]} if cheapest else None),
                "reference_floor": {"force_max_rel": floor_f, "ecc_max_rel": floor_e},
                "order": fit_order(rs, ORDER_METRIC, max(lo, 3 * (floor_f or 0.0)), hi),
                "order_eccentricity": fit_order(rs, "err_ecc_max_rel", max(lo, 3 * (floor_e or 0.0)), hi),
            }
            if scheme == ADAPTIVE:  # its step follows the tolerance: no order in the step
                entry["order"] = entry["order_eccentricity"] = {
                    "metric": ORDER_METRIC, "order": None, "points": 0,
                    "reason": "n/a: the adaptive step follows the tolerance"}
                entry["largest_tol_within_1pct"] = max((r["tol"] for r in within), default=None)
                entry["tolerance_vs_error"] = [
                    {"tol": r["tol"], "mean_step_s": r["step"], "err_force_max_rel": r["err_force_max_rel"],
                     PEAK_METRIC: r[PEAK_METRIC], "accepted": r["steps"], "rejected": r["rejected_steps"],
                     "status": r["status"]} for r in sorted(rs, key=lambda r: -(r["tol"] or 0))]
            per_scheme[scheme] = entry
        first = next(r for r in rows if r["group"] == g)
        groups[g] = {"rpm": first["rpm"], "balls": first["balls"], "settings": first["settings"],
                     "window_s": [first["window_start"], first["window_end"]], "schemes": per_scheme}
    return {
        "criteria": {
            "one_percent_metric": f"{PEAK_METRIC} = max(|rel. error of the window's peak |F||, "
                                  f"|rel. error of its max |e||) <= {ONE_PERCENT:g}",
            "pointwise_one_percent": f"{ORDER_METRIC} = max over the window of |F - F_ref| / max |F_ref| <= "
                                     f"{ONE_PERCENT:g} (stricter; reported beside the peak criterion)",
            "largest_step": "the largest step such that every step <= it that ran meets the criterion",
            "stable": f"ran to the end with max relative force and eccentricity errors <= {config.divergence:g}",
            "order": f"least-squares slope of log({ORDER_METRIC}) vs log(step) over stable points with "
                     f"max({config.order_range[0]:g}, 3 x the reference's floor) <= error <= "
                     f"{config.order_range[1]:g} (at least 3)",
            "reference_floor": "the reference's own error: rtol vs rtol/10, max relative force / eccentricity "
                               "difference over the window (errors near it are not resolved)",
            "window": "second revolution [T, 2T] (revs >= 2), else the second half of the run",
            "steps": "snapped to the output grid: dt/round(dt/h) below dt, dt*round(h/dt) above",
        },
        "config": {k: v for k, v in asdict(config).items() if k not in ("progress",)},
        "counts": {s: sum(r["status"] == s for r in rows) for s in dict.fromkeys(r["status"] for r in rows)},
        "groups": groups,
    }


def _fmt(x, unit: str = "s") -> str:
    if x is None:
        return "—"
    return f"{x:.3g}" + (f" {unit}" if unit else "")


def summary_markdown(summary: dict, config: StudyConfig) -> str:
    lines = ["# Co-simulation step-size study", "",
             f"Mode `{config.mode}`, {config.revs:g} revolutions, output interval {config.output_interval:g} s, "
             f"reference {config.reference_method} at rtol {config.reference_rtol:g}. "
             f"Wall time {summary.get('wall_time_s', 0):.0f} s on {summary.get('executor')}.", "",
             "Criteria:", ""]
    lines += [f"- **{k}**: {v}" for k, v in summary["criteria"].items()]
    lines += ["", "Cases: " + ", ".join(f"{v} {k}" for k, v in summary["counts"].items()), ""]
    for g, info in summary["groups"].items():
        floors = next(iter(info["schemes"].values()))["reference_floor"]
        lines += [f"## {g}", "", f"Window {info['window_s'][0]:.4g} .. {info['window_s'][1]:.4g} s. Reference floor "
                  f"(rtol vs rtol/10): force {_fmt(floors['force_max_rel'], '')}, "
                  f"eccentricity {_fmt(floors['ecc_max_rel'], '')} (max relative).", "",
                  "| scheme | largest stable step | smallest unstable step | largest step with peak error ≤ 1 % "
                  "| peak error there | largest step with pointwise force error ≤ 1 % | observed order (force) "
                  "| points, step range | cheapest run within 1 % (peak) |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for scheme, e in info["schemes"].items():
            o = e["order"]
            order = f"{o['order']:.2f}" if o.get("order") is not None else f"— ({o.get('reason')})"
            rng = (f"{o['points']}, {o['steps'][0]:.3g}..{o['steps'][1]:.3g} s" if o.get("order") is not None
                   else str(o["points"]))
            cheap = e["cheapest_run_within_1pct"]
            cheap_s = (f"{cheap['wall_time_s']:.3g} s wall at h = {cheap['step_s']:.3g} s" if cheap else "—")
            if scheme == ADAPTIVE:
                tol = e.get("largest_tol_within_1pct")
                largest = f"tol {tol:g} (mean step {_fmt(e['largest_step_within_1pct_s'])})" if tol else "—"
            else:
                largest = _fmt(e["largest_step_within_1pct_s"])
            lines.append(f"| {scheme} | {_fmt(e['largest_stable_step_s'])} | {_fmt(e['smallest_unstable_step_s'])} | "
                         f"{largest} | {_fmt(e['peak_error_at_that_step'], '')} | "
                         f"{_fmt(e['largest_step_within_1pct_pointwise_s'])} | {order} | {rng} | {cheap_s} |")
        ad = info["schemes"].get(ADAPTIVE)
        if ad:
            lines += ["", "Adaptive (step doubling, rollback): tolerance against error", "",
                      "| tol | mean step | accepted | rejected | max rel. force error | peak error | status |",
                      "|---|---|---|---|---|---|---|"]
            for r in ad["tolerance_vs_error"]:
                lines.append(f"| {r['tol']:g} | {_fmt(r['mean_step_s'])} | {r['accepted']} | {r['rejected']} | "
                             f"{_fmt(r['err_force_max_rel'], '')} | {_fmt(r[PEAK_METRIC], '')} | {r['status']} |")
        lines.append("")
    lines += ["Plots: `stepsize_error_vs_step_<group>.png` (errors against the step, log-log, with the fitted "
              "order and the stability limit), `stepsize_error_vs_walltime_<group>.png`.", ""]
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------- plots
def plot_study(rows: list[dict], summary: dict, out: Path) -> list[Path]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for g, info in summary["groups"].items():
        rs = [r for r in rows if r["group"] == g]
        schemes = list(info["schemes"])
        colors = {s: plt.cm.tab10(i % 10) for i, s in enumerate(schemes)}
        fig, axes = plt.subplots(1, 2, figsize=(13, 5.2), sharex=True)
        for ax, metric, title in ((axes[0], ORDER_METRIC, "max |F − F_ref| / max |F_ref| over the window"),
                                  (axes[1], PEAK_METRIC, "peak error: max(|Δ peak |F||, |Δ max |e||), relative")):
            top = 1.0
            for s in schemes:
                pts = sorted((r for r in rs if r["scheme"] == s and r.get("step")), key=_axis)
                ok = [(r["step"], r[metric]) for r in pts if r["status"] == STABLE and r.get(metric)]
                bad = [r for r in pts if r["status"] in (FAILED, DIVERGENT, NONFINITE)]
                label = s
                o = info["schemes"][s]["order"]
                if metric == ORDER_METRIC and o.get("order") is not None:
                    label += f" (order {o['order']:.2f})"
                if s == ADAPTIVE:
                    label += " (x: mean step)"
                if ok:
                    ax.loglog(*zip(*ok), "o-", color=colors[s], label=label, ms=4, lw=1.2)
                else:
                    ax.plot([], [], "o-", color=colors[s], label=label)
                if metric == ORDER_METRIC and o.get("order") is not None:
                    xs = np.geomspace(*o["steps"], 20)
                    ax.loglog(xs, np.exp(o["intercept"]) * xs ** o["order"], "--", color=colors[s], lw=0.8)
                edge = top * 0.8 ** schemes.index(s)  # one row of markers per scheme
                for r in bad:  # unstable: marked near the top edge (divergent ones at their error if lower)
                    yv = r.get(metric) if r["status"] == DIVERGENT and r.get(metric) else edge
                    ax.loglog([r["step"]], [min(yv, edge)], "x", color=colors[s], ms=8, mew=2)
                limit = info["schemes"][s]["smallest_unstable_step_s"]
                if limit:
                    ax.axvline(limit, color=colors[s], ls=":", lw=1)
            ax.axhline(ONE_PERCENT, color="k", lw=0.6, ls="-.")
            ax.text(0.01, ONE_PERCENT * 1.1, "1 %", fontsize=8, transform=ax.get_yaxis_transform())
            ax.set_xlabel("communication step h [s] (adaptive: mean step)")
            ax.set_ylabel("relative error [1]")
            ax.set_title(title, fontsize=10)
            ax.grid(True, which="both", alpha=0.3)
        axes[0].legend(fontsize=8, loc="lower right")
        fig.suptitle(f"{g}: error against step (× unstable: failed or > {summary['config']['divergence']:.0%}; "
                     "dotted: smallest unstable step)",
                     fontsize=11)
        fig.tight_layout()
        p = out / f"stepsize_error_vs_step_{g}.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)
        fig, ax = plt.subplots(figsize=(7.5, 5.2))
        for s in schemes:
            pts = [(r["wall_time"], r[ORDER_METRIC]) for r in sorted(rs, key=lambda r: r["step"] or 0.0)
                   if r["scheme"] == s and r["status"] == STABLE and r.get(ORDER_METRIC) and r.get("wall_time")]
            if pts:  # joined in step order
                ax.loglog(*zip(*pts), "o-", color=colors[s], label=s, ms=4)
        ax.axhline(ONE_PERCENT, color="k", lw=0.6, ls="-.")
        ax.set_xlabel("wall time per case [s]")
        ax.set_ylabel("max relative force error [1]")
        ax.set_title(f"{g}: error against cost (stable runs)", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
        fig.tight_layout()
        p = out / f"stepsize_error_vs_walltime_{g}.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)
    return paths


# ------------------------------------------------------------------------------------------ CLI
def config_from_args(args) -> StudyConfig:
    from ..coupling import SCHEMES
    if args.schemes.strip() == "all":
        schemes = list(SCHEMES) + [ADAPTIVE]
    else:
        schemes = [s.strip() for s in args.schemes.split(",") if s.strip()]
    return StudyConfig(out=args.out, rpms=list(args.rpm), balls=list(args.balls) if args.balls else [None],
                       settings=parse_settings(args.settings), schemes=schemes, steps=parse_grid(args.steps),
                       tols=parse_grid(args.tols), revs=args.revs, mode=args.mode, fmu=args.fmu,
                       output_interval=args.output_interval, workers=args.workers, scheduler=args.scheduler,
                       max_steps_per_case=args.max_steps_per_case, allow_slow=args.allow_slow,
                       divergence=args.divergence, reference_rtol=args.reference_rtol,
                       order_range=tuple(args.order_range),
                       reference_cache=args.reference_cache, plots=not args.no_plots, progress=not args.quiet)


def cmd_stepsize(args) -> int:
    if args.replot:
        replot(config_from_args(args))
        print(f"rewrote {args.out}/stepsize_summary.json, stepsize_summary.md and plots from stepsize.csv")
        return 0
    result = run_study(config_from_args(args))
    print(f"wrote {result.out}/stepsize.csv, stepsize_summary.json, stepsize_summary.md and plots "
          f"({len(result.rows)} cases, {result.wall_time:.0f} s)")
    for g, info in result.summary["groups"].items():
        for scheme, e in info["schemes"].items():
            o = e["order"].get("order")
            print(f"  {g} {scheme:15s} largest stable step {_fmt(e['largest_stable_step_s'])}, "
                  f"within 1 %: {_fmt(e['largest_step_within_1pct_s'])}, order {o:.2f}" if o is not None else
                  f"  {g} {scheme:15s} largest stable step {_fmt(e['largest_stable_step_s'])}, "
                  f"within 1 %: {_fmt(e['largest_step_within_1pct_s'])}, order —")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "stepsize-study", help="error, cost and stability of the coupling schemes against the step size",
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rpm", type=float, nargs="+", default=[1200.0], help="crank speed(s) [rpm] (default 1200)")
    p.add_argument("--balls", type=int, nargs="+", default=None, help="ball count(s) (default: the FMU's 8)")
    p.add_argument("--set", dest="settings", action="append", default=[], metavar="NAME=V1[,V2...]",
                   help="bearing-component parameter value(s); repeat for several names (cartesian product)")
    p.add_argument("--steps", default=DEFAULT_STEPS,
                   help=f"communication steps [s]: lo:hi:count log-spaced, or a comma list (default {DEFAULT_STEPS}); "
                        "snapped to the output grid")
    p.add_argument("--tols", default=DEFAULT_TOLS, help=f"tolerances of the adaptive scheme (default {DEFAULT_TOLS})")
    p.add_argument("--schemes", default="jacobian-drift,jacobian,extrap1,zoh",
                   help="'all' (every scheme and adaptive) or a comma list (default jacobian-drift,jacobian,extrap1,zoh)")
    p.add_argument("--revs", type=float, default=2.0,
                   help="revolutions per run (default 2; errors over the second revolution)")
    p.add_argument("--mode", choices=("cosim", "inprocess"), default="cosim",
                   help="cosim: through the FMU (default); inprocess: the same force law in-process")
    p.add_argument("--fmu", default=None, help="BallBearing FMU (default dist/BallBearing.fmu, built on first use)")
    p.add_argument("--output-interval", type=float, default=OUTPUT_INTERVAL,
                   help=f"sampling grid of the reference and the runs [s] (default {OUTPUT_INTERVAL:g})")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: the core count)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run the cases on this Dask distributed scheduler instead (needs the 'studies' extra)")
    p.add_argument("--max-steps-per-case", type=int, default=MAX_STEPS_PER_CASE,
                   help=f"skip fixed-step cases with more communication steps (default {MAX_STEPS_PER_CASE}: "
                        "about a minute through the FMU; 1e-7 s over 2 revs at 1200 rpm is 1e6 steps)")
    p.add_argument("--allow-slow", action="store_true", help="run every case whatever its step count")
    p.add_argument("--divergence", type=float, default=DIVERGENCE,
                   help=f"max relative error beyond which a completed run counts as unstable (default {DIVERGENCE})")
    p.add_argument("--order-range", type=float, nargs=2, default=(ORDER_FLOOR, ORDER_CEILING), metavar=("LO", "HI"),
                   help=f"errors fitted for the observed order (default {ORDER_FLOOR:g} {ORDER_CEILING:g})")
    p.add_argument("--reference-rtol", type=float, default=1e-11, help="monolithic reference rtol (default 1e-11)")
    p.add_argument("--reference-cache", default=None, help="folder of cached references (default OUT/references)")
    p.add_argument("--no-plots", action="store_true", help="no PNG plots")
    p.add_argument("--replot", action="store_true",
                   help="only rewrite the summaries and plots from OUT/stepsize.csv (e.g. with another --order-range)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--out", default="results/stepsize", help="output folder (default results/stepsize)")
    p.set_defaults(func=cmd_stepsize)
