"""Step-size sweep benchmark (issue 6): 13 steps x 4 schemes at 1200 rpm over two revolutions, through the FMU.

Runs ``mechanism.studies.stepsize.run_study`` with steps 1e-7 .. 1e-4 s (13, log-spaced, snapped
to the 1e-5 s output grid) for jacobian-drift, jacobian, extrap1 and zoh, and the monolithic
reference (cached in OUT/references: delete it, or use a fresh OUT, to time the reference too; its
run and its rtol/10 floor run are two jobs beside the cases), cases in parallel on the local
cores, and prints the wall time, the reference's and the summary.

Cost cap: 2 revolutions at 1200 rpm are 0.1 s, i.e. 1e6 communication steps at 1e-7 s (10-15 s
each through the FMU on the compiled loop). Cases above ``--max-steps-per-case`` (default 2e6
steps) are reported as "skipped (cost)", so by default all 52 cases run; ``--allow-slow`` runs
every case whatever its cost.

    python benchmarks/stepsize_sweep.py [--out results/stepsize_benchmark] [--workers N] [--allow-slow]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from mechanism.studies.stepsize import (
    MAX_STEPS_PER_CASE,
    StudyConfig,
    parse_grid,
    run_study,
)

SCHEMES = ["jacobian-drift", "jacobian", "extrap1", "zoh"]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="results/stepsize_benchmark")
    p.add_argument("--rpm", type=float, default=1200.0)
    p.add_argument("--revs", type=float, default=2.0)
    p.add_argument("--steps", default="1e-7:1e-4:13")
    p.add_argument("--mode", choices=("cosim", "inprocess"), default="cosim")
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--max-steps-per-case", type=int, default=MAX_STEPS_PER_CASE)
    p.add_argument("--allow-slow", action="store_true")
    p.add_argument("--fmu", default=None, help="BallBearing FMU (default dist/BallBearing.fmu, built on first use)")
    p.add_argument("--quiet", action="store_true")
    args = p.parse_args()
    config = StudyConfig(out=args.out, rpms=[args.rpm], schemes=SCHEMES, steps=parse_grid(args.steps),
                         revs=args.revs, mode=args.mode, fmu=args.fmu, workers=args.workers,
                         max_steps_per_case=args.max_steps_per_case, allow_slow=args.allow_slow,
                         progress=not args.quiet)
    start = time.perf_counter()
    result = run_study(config)
    wall = time.perf_counter() - start
    counts = result.summary["counts"]
    print(f"step-size sweep: {len(result.rows)} cases ({', '.join(f'{v} {k}' for k, v in counts.items())}) "
          f"in {wall:.1f} s wall on {result.summary['executor']}")
    cpu = sum(r["wall_time"] or 0.0 for r in result.rows)
    print(f"  sum of per-case wall times {cpu:.1f} s; outputs in {result.out}")
    for key in result.summary["references"]:
        meta = Path(result.out) / "references" / f"reference_{key}.json"
        if meta.is_file():
            m = json.loads(meta.read_text())
            print(f"  reference {key}: run {m.get('wall_time_s') or 0:.1f} s, rtol/10 floor run "
                  f"{m.get('check_wall_time_s') or 0:.1f} s ({m.get('rhs_calls')} rhs calls; cached, "
                  f"may be from an earlier run)")
    for info in result.summary["groups"].values():
        for scheme, e in info["schemes"].items():
            o = e["order"].get("order")
            print(f"  {scheme:15s} largest stable step {e['largest_stable_step_s']}, "
                  f"largest step within 1 %: {e['largest_step_within_1pct_s']}, "
                  f"order {'—' if o is None else f'{o:.2f}'}")


if __name__ == "__main__":
    main()
