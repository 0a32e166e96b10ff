"""The step-size study's cases as data: options, steps and tolerances, the physical cases (speed x balls x
settings) and every (scheme, step) case to run, with the CSV columns and their SI units."""
from __future__ import annotations

import hashlib
import itertools
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

#: the reference's sampling interval and the study's default output interval [s]
OUTPUT_INTERVAL = 1e-5
DEFAULT_STEPS = "1e-7:1e-4:13"
DEFAULT_TOLS = "1e-2:1e-5:4"
#: fixed-step runs longer than this many communication steps are skipped unless --allow-slow: 2e6 (a compiled
#: loop step is ~10-15 us, so 2e6 steps ~30 s) lets the default sweep run all its cases, down to 1e-7 s over
#: two revolutions at 1200 rpm (1e6 steps)
MAX_STEPS_PER_CASE = 2_000_000
DIVERGENCE = 0.5
#: order fits use stable points with max relative force error in [ORDER_FLOOR, ORDER_CEILING]
ORDER_FLOOR, ORDER_CEILING = 1e-5, 0.2
ONE_PERCENT = 0.01
REFERENCE_VERSION = 2          # bump when the reference's model or sampling changes (invalidates the cache)
ADAPTIVE = "adaptive"
#: the coupling scheme inside the study's adaptive case: jacobian-implicit, with which its figures in
#: docs/stepsize-study.md were measured (law-model, the run's default, is so accurate per step that the adaptive
#: controller at the study's tolerances rarely rejects a step: a different experiment)
ADAPTIVE_SCHEME = "jacobian-implicit"

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
    ("energy_residual", "J"), ("damping_dissipation", "J"), ("energy_residual_rel", "1"), ("ref_energy_residual_rel", "1"),
    ("pid", ""), ("host", ""), ("worker", ""), ("started_at", "s"), ("ended_at", "s"),
]
COLUMN_NAMES = [c for c, _ in COLUMNS]
#: columns that depend on where and when a case ran, not on what it computed
PLACEMENT_COLUMNS = ("wall_time", "pid", "host", "worker", "started_at", "ended_at")
REFERENCE_COLUMNS = ("time", "e_x", "e_y", "F_x", "F_y", "slider_a", "crank_moment", "max_ball_load",
                     "energy_residual", "damping_dissipation")
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
    from mechanism.run import parse_setting
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
    schemes: list[str] = field(default_factory=lambda: ["law-model", "jacobian-implicit", "jacobian-drift", "jacobian",
                                                               "extrap1", "zoh"])
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
        from mechanism.cosim.coupling import SCHEMES
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
