"""The study's summary: observed orders, largest stable step and largest step within 1 % per scheme, as Markdown."""
from __future__ import annotations

import math
from dataclasses import asdict
from typing import Callable

import numpy as np

from mechanism.studies.stepsize.cases import (
    ADAPTIVE,
    ERROR,
    ONE_PERCENT,
    ORDER_CEILING,
    ORDER_FLOOR,
    ORDER_METRIC,
    PEAK_METRIC,
    SKIPPED,
    STABLE,
    StudyConfig,
)


# ------------------------------------------------------------------------------------- summaries
def _axis(row: dict) -> float | None:
    return row["step"]


def log_slope(steps, errors) -> tuple[float, float]:
    """Least-squares slope and intercept of log(error) against log(step): the observed order of convergence
    (the study's, the order tests' and ``benchmarks/coarse_step.py``'s)."""
    slope, intercept = np.polyfit(np.log(steps), np.log(errors), 1)
    return float(slope), float(intercept)


def observed_order(steps, errors) -> float:
    """The observed order of convergence: ``log_slope``'s slope."""
    return log_slope(steps, errors)[0]


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
    slope, intercept = log_slope([p[0] for p in pts], [p[1] for p in pts])
    info.update(order=slope, intercept=intercept, steps=[pts[0][0], pts[-1][0]])
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
                "largest_step_tried_s": max((r["step"] for r in ran if r.get("step")), default=None),
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


def fmt_quantity(x, unit: str = "s") -> str:
    """A value to 3 significant digits with its unit (default seconds); "—" for None."""
    if x is None:
        return "—"
    return f"{x:.3g}" + (f" {unit}" if unit else "")


def fmt_percent(x) -> str:
    """A relative error (fraction) in percent."""
    return "—" if x is None else f"{100 * x:.3g} %"


def step_limit(e: dict, key: str) -> str:
    """A largest step, marked as a lower bound ("≥ h, the largest step tried") when nothing larger ran."""
    h, top = e.get(key), e.get("largest_step_tried_s")
    if h is not None and top is not None and h >= top:
        return f"≥ {fmt_quantity(h)} (the largest step tried)"
    return fmt_quantity(h)


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
                  f"(rtol vs rtol/10, max pointwise): joint force {fmt_percent(floors['force_max_rel'])}, "
                  f"eccentricity {fmt_percent(floors['ecc_max_rel'])}.", "",
                  "| scheme | largest stable step | smallest unstable step | largest step with peak error ≤ 1 % "
                  "| peak error there [%] (worse of peak joint force and max eccentricity) "
                  "| largest step with pointwise joint-force error ≤ 1 % | observed order (force) "
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
                largest = f"tol {tol:g} (mean step {fmt_quantity(e['largest_step_within_1pct_s'])})" if tol else "—"
            else:
                largest = step_limit(e, "largest_step_within_1pct_s")
            lines.append(f"| {scheme} | {step_limit(e, 'largest_stable_step_s')} | {fmt_quantity(e['smallest_unstable_step_s'])} | "
                         f"{largest} | {fmt_percent(e['peak_error_at_that_step'])} | "
                         f"{step_limit(e, 'largest_step_within_1pct_pointwise_s')} | {order} | {rng} | {cheap_s} |")
        ad = info["schemes"].get(ADAPTIVE)
        if ad:
            lines += ["", "Adaptive (step doubling, rollback): tolerance against error", "",
                      "| tol | mean step | accepted | rejected | max pointwise joint-force error [%] "
                      "| peak error [%] (peak joint force, max eccentricity) | status |",
                      "|---|---|---|---|---|---|---|"]
            for r in ad["tolerance_vs_error"]:
                lines.append(f"| {r['tol']:g} | {fmt_quantity(r['mean_step_s'])} | {r['accepted']} | {r['rejected']} | "
                             f"{fmt_percent(r['err_force_max_rel'])} | {fmt_percent(r[PEAK_METRIC])} | {r['status']} |")
        lines.append("")
    lines += ["Plots: `stepsize_error_vs_step_<group>.png` (errors against the step, log-log, with the fitted "
              "order and the stability limit), `stepsize_error_vs_walltime_<group>.png`.", ""]
    return "\n".join(lines)
