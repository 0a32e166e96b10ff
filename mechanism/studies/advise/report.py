"""The advisor's answer: one line, a small table (console and Markdown), the probes as CSV and JSON, a plot."""
from __future__ import annotations

import json
import math
from pathlib import Path

from mechanism.output.atomic import save_figure
from mechanism.studies.advise.runs import Advice
from mechanism.studies.advise.search import MERITS
from mechanism.studies.stepsize.runs import write_csv
from mechanism.studies.stepsize.tables import fmt_percent, fmt_quantity


def operating_point(advice: Advice) -> str:
    c = advice.config
    parts = [f"{c.rpm:g} rpm", f"{c.balls if c.balls is not None else 8} balls"]
    parts += [f"{k}={v}" for k, v in sorted(c.settings.items())]
    return ", ".join(parts)


LABELS = {"peak-force": "peak joint force", "max-eccentricity": "max eccentricity", "max-ball-load": "max ball load",
          "slider-acceleration": "slider acceleration (pointwise)", "force-pointwise": "joint force (pointwise)"}


def merit_label(advice: Advice) -> str:
    return " and ".join(LABELS.get(m, m) for m in advice.config.merits)


def limit_text(advice: Advice, scheme: str, which: str) -> str:
    """'3e-05 s (fails at 4e-05 s)', '≥ 1e-3 s (largest step tried)' or '< 5e-06 s (smallest step tried)'."""
    search = advice.searches[scheme]
    if search.error:
        return f"error: {search.error}"
    lim = search.limit(which)
    if lim["above_range"]:
        return f"≥ {fmt_quantity(lim['step'])} (bound: the largest step tried; raise --max-step)"
    if lim["below_range"]:
        return f"< {fmt_quantity(lim['fails_at'])} (bound: fails at the smallest step the cost cap allows)"
    if lim["step"] is None:
        return "— (not bracketed)"
    return f"{fmt_quantity(lim['step'])} (fails at {fmt_quantity(lim['fails_at'])})"


def one_line(advice: Advice) -> str:
    """The answer in one line."""
    c, a = advice.config, advice.answer
    head = f"{operating_point(advice)}, {merit_label(advice)} within {100 * c.tolerance:g} %: "
    if a is None:
        return head + (f"no scheme meets it at any step ≥ {fmt_quantity(advice.ladder[0])} (the cost cap --max-steps "
                       f"{c.max_steps}); see the table")
    step = ("≥ " if a["bound"] else "") + fmt_quantity(a["step_s"])
    stable = "; ".join(f"{s} {limit_text(advice, s, 'stable').split(' (')[0]}" for s in advice.searches)
    return (head + f"use {a['scheme']} at h = {step} ({fmt_percent(a['merit_error'])} off, {a['cpu_time_s']:.2g} s CPU "
            f"for {c.revs:g} revolutions); largest stable steps: {stable}")


def table_rows(advice: Advice) -> list[list[str]]:
    rows = []
    for s, search in advice.searches.items():
        within = search.limit("within")
        row = within["row"] or {}
        rows.append([s, limit_text(advice, s, "stable"), limit_text(advice, s, "within"),
                     fmt_percent(row.get("merit_error")),
                     "—" if row.get("wall_time") is None else
                     f"{row.get('cpu_time', math.nan):.2g} s ({row['wall_time']:.2g} s)",
                     str(len(search.rows)) + (" (non-monotone)" if search.non_monotone else "")])
    return rows


HEADER = ["scheme", "largest stable step", "largest step within tolerance", "error there",
          "CPU (wall) time there", "runs"]


def table_text(advice: Advice) -> str:
    rows = [HEADER] + table_rows(advice)
    widths = [max(len(r[i]) for r in rows) for i in range(len(HEADER))]
    return "\n".join("  ".join(v.ljust(w) for v, w in zip(r, widths)).rstrip() for r in rows)


def timing_text(advice: Advice) -> str:
    ref = "from the cache" if advice.reference_cached else f"computed in {advice.reference_wall_s:.0f} s"
    rows = [r for search in advice.searches.values() for r in search.rows.values()]
    busy = sum(r.get("wall_time") or 0.0 for r in rows)
    cpu = sum(r.get("cpu_time") or 0.0 for r in rows)
    steps = sum(r.get("steps") or 0 for r in rows)
    return (f"{advice.probes} runs ({steps} communication steps; summed over the runs {cpu:.0f} s CPU, "
            f"{busy:.0f} s wall) on "
            f"{advice.executor}; reference {ref}; total {advice.wall_time_s:.0f} s wall "
            f"(this machine's, under its current load)")


def _window(c) -> str:
    return ("the second crank revolution" if c.revs >= 2 else "the second half of the run") + f" (of {c.revs:g})"


def markdown(advice: Advice) -> str:
    c = advice.config
    floor = {k.split("__", 1)[1]: float(v) for k, v in advice.reference.items() if k.startswith("floor__")}
    lines = [f"# Step-size advice: {operating_point(advice)}", "", f"**{one_line(advice)}**", "",
             "Criteria:", "",
             "- figure(s) of merit: " + "; ".join(f"`{m}` — {MERITS[m][1]} (`{MERITS[m][0]}`)" for m in c.merits)
             + f"; relative error against the monolithic reference ≤ {100 * c.tolerance:g} %",
             f"- window: {_window(c)}; mode `{c.mode}`",
             "- stable: ran to the end with max relative force and eccentricity errors ≤ 50 % (the step-size study's)",
             "- each limit is bracketed by a passing and a failing step and bisected (log h) until the two are "
             "neighbours on the output grid (steps dt/k and dt·k, dt = "
             f"{c.output_interval:g} s); '≥' and '<' mark bounds at the ends of the range searched "
             f"({advice.ladder[0]:.3g} … {advice.ladder[-1]:.3g} s)",
             "- the cheapest scheme is the one whose run at its largest step within the tolerance took the least "
             "CPU time (the wall time, also given, depends on the machine's load)",
             "- reference floor (rtol 1e-11 against 1e-12, relative): " +
             (", ".join(f"{k} {fmt_percent(v)}" for k, v in floor.items()) or "not measured"), "",
             "| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    lines += ["| " + " | ".join(r) + " |" for r in table_rows(advice)]
    lines += ["", timing_text(advice) + ".", "",
              "Every run: `advise.csv` (the step-size study's columns); plot: `advise.png`.", ""]
    return "\n".join(lines)


def as_json(advice: Advice) -> dict:
    return {"question": {"rpm": advice.config.rpm, "balls": advice.config.balls, "settings": advice.config.settings,
                         "tolerance": advice.config.tolerance, "merits": advice.config.merits,
                         "mode": advice.config.mode, "revs": advice.config.revs},
            "answer": advice.answer, "one_line": one_line(advice),
            "schemes": {s: {"stable": {k: v for k, v in search.limit("stable").items() if k != "row"},
                            "within_tolerance": {k: v for k, v in search.limit("within").items() if k != "row"},
                            "error": search.error, "runs": len(search.rows), "non_monotone": search.non_monotone}
                        for s, search in advice.searches.items()},
            "ladder_s": [advice.ladder[0], advice.ladder[-1], len(advice.ladder)],
            "wall_time_s": advice.wall_time_s, "reference_wall_time_s": advice.reference_wall_s,
            "reference_cached": advice.reference_cached, "executor": advice.executor, "runs": advice.probes}


def write(advice: Advice, out: Path) -> list[Path]:
    """advise.md, advise.json, advise.csv and (unless --no-plots) advise.png in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    rows = [r for search in advice.searches.values() for r in search.rows.values() if "case" in r]
    write_csv(sorted(rows, key=lambda r: r["case"]), out / "advise.csv")
    (out / "advise.md").write_text(markdown(advice))
    (out / "advise.json").write_text(json.dumps(as_json(advice), indent=2) + "\n")
    paths = [out / "advise.md", out / "advise.json", out / "advise.csv"]
    if advice.config.plots:
        paths.append(plot(advice, out / "advise.png"))
    return paths


def plot(advice: Advice, path: Path) -> Path:
    """Left: the figure-of-merit error of every run against its step (× unstable), the tolerance and each
    scheme's limits; right: the wall time of every run against its step."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12.5, 4.8))
    for k, (s, search) in enumerate(advice.searches.items()):
        color = plt.cm.tab10(k % 10)
        pts = sorted((r["step"], r) for r in search.rows.values() if r.get("step"))
        good = [(h, r["merit_error"]) for h, r in pts if r.get("stable") and r.get("merit_error")]
        bad = [h for h, r in pts if not r.get("stable")]
        if good:
            ax.loglog(*zip(*good), "o-", color=color, ms=4, label=s)
        else:
            ax.plot([], [], "o-", color=color, label=s)
        for h in bad:
            ax.loglog([h], [0.9 ** k], "x", color=color, ms=8, mew=2)
        lim = search.limit("stable")
        if lim["fails_at"]:
            ax.axvline(lim["fails_at"], color=color, ls=":", lw=1)
        for stable, marker in ((True, "o"), (False, "x")):
            walls = [(h, r.get("cpu_time") or r["wall_time"]) for h, r in pts
                     if r.get("wall_time") and bool(r.get("stable")) == stable]
            if walls:
                bx.loglog(*zip(*walls), marker, color=color, ms=4 if stable else 6, label=s if stable else None)
    ax.axhline(advice.config.tolerance, color="k", ls="-.", lw=0.8)
    ax.set_xlabel("communication step h [s]")
    ax.set_ylabel(f"relative error of {merit_label(advice)} [1]")
    ax.set_title("error against step (×: unstable, at the top; dotted: first unstable step)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    bx.set_xlabel("communication step h [s]")
    bx.set_ylabel("CPU time of the run [s]")
    bx.set_title("cost per run (o: stable, ×: unstable, stopped early or ran to the end)", fontsize=9)
    if bx.get_legend_handles_labels()[0]:
        bx.legend(fontsize=8)
    bx.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"Step-size advice: {operating_point(advice)}, tolerance {100 * advice.config.tolerance:g} %",
                 fontsize=11)
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path
