"""``python -m mechanism reproduce``: options, the command and its registration."""
from __future__ import annotations

import sys
from mechanism.studies.reproduce.runs import (reproduce)


def cmd_reproduce(args) -> int:
    if args.revs <= 0:
        raise ValueError("--revs must be positive")
    outcome = reproduce(args.out, force=args.force, workers=args.workers, revs=args.revs,
                        progress=not args.quiet, stepsize=args.stepsize)
    failed = [n for n, r in outcome["results"].items() if not r.ok]
    print(f"{len(outcome['computed'])} run(s) computed, {len(outcome['cached'])} from the cache "
          f"({outcome['elapsed_s']:.1f} s on {outcome['workers']} worker(s)); total {outcome['total_s']:.1f} s")
    if "report" in outcome:
        print(f"report: {outcome['report']}")
    for n in failed:
        print(f"warning: run {n} failed: {outcome['results'][n].message}", file=sys.stderr)
    return 1 if failed else 0


def register(subparsers) -> None:
    p = subparsers.add_parser("reproduce", help="reproduce the paper's Section 5 (runs, figures, report)",
                              description="Reproduce Section 5 of Xu et al. (2012): run every case (cached), draw the figures "
                                          "and write OUT/report/README.md with a verdict per figure.")
    p.add_argument("--out", default="results/reproduce", help="output folder (default results/reproduce)")
    p.add_argument("--force", action="store_true", help="recompute every run (ignore the cache)")
    p.add_argument("--workers", type=int, default=None, help="parallel runs (default: the number of cores)")
    p.add_argument("--revs", type=float, default=2.0, help="crank revolutions per run (default 2, as the paper)")
    p.add_argument("--stepsize", default=None, metavar="DIR",
                   help="add the results of `stepsize-study --out DIR` to the report")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_reproduce)
