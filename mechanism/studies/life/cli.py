"""``python -m mechanism life-study``: the subcommand (see the package docstring)."""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from mechanism.studies.life import cases, figures, runs, tables


def _floats(text: str) -> tuple[float, ...]:
    """A comma-separated list of finite numbers, at least one (argparse names the option on an error)."""
    try:
        values = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        values = ()
    if not values or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}")
    return values


def cmd_life_study(args) -> int:
    if not (args.startup_revs >= 0 and args.window_revs > 0 and args.step > 0):
        raise ValueError("--startup-revs must be >= 0, --window-revs and --step positive")
    if args.step > cases.MAX_STEP:
        raise ValueError(f"--step {args.step:g} s is above {cases.MAX_STEP:g} s, the largest step measured to "
                         f"give the life of 1e-5 s steps (larger steps diverge or give wrong lives)")
    settings = cases.Settings(startup_revs=args.startup_revs, window_revs=args.window_revs, step=args.step,
                              balls=args.balls)
    clearances = tuple(c * 1e-6 for c in args.clearances) if args.clearances else cases.CLEARANCES
    speeds = args.speeds if args.speeds else cases.SPEEDS
    pts = cases.points(clearances, speeds, args.rpm)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    rows = runs.sweep(pts, settings, workers=args.workers, progress=not args.quiet)
    window = (f"window: crank revolutions {settings.startup_revs:g} to "
              f"{settings.startup_revs + settings.window_revs:g}, step {settings.step:g} s")
    for name, x, title in (("clearance", "radial_clearance", f"life vs radial clearance at {args.rpm:g} rpm"),
                           ("speed", "rpm", f"life vs crank speed at P_d = {cases.PAPER_CLEARANCE * 1e6:g} µm")):
        part = [r for r in rows if r["sweep"] == name]
        if part:
            tables.write_csv(part, out / f"life_vs_{name}.csv")
            figures.plot(part, x, out / f"life_vs_{name}.png", f"{title}; {window}")
    print(f"{len(rows)} run(s) in {time.perf_counter() - started:.1f} s; wrote {out}/life_vs_*.csv and .png")
    for r in rows:
        life = r["rating_life_h"]
        print(f"  {r['sweep']:9s} {r['rpm']:6g} rpm  P_d = {r['radial_clearance'] * 1e6:6.1f} µm  "
              f"L10r = {life:.4g} h" + ("" if r["status"] == "completed" and not math.isnan(life)
                                        else f"  FAILED: {r['message']}"))
    failed = [r for r in rows if r["status"] != "completed"]
    if failed:
        print(f"error: {len(failed)} of {len(rows)} run(s) failed (kept in the CSV with status 'failed')",
              file=sys.stderr)
        return 1
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("life-study", help="bearing rating life vs radial clearance and crank speed (CSV, PNG)",
                              description=(__import__("mechanism.studies.life", fromlist=["x"]).__doc__ or "")
                              .split("\n\n")[0].replace("``", ""))
    p.add_argument("--out", default="results/life", help="output folder (default results/life)")
    p.add_argument("--clearances", type=_floats, default=None, metavar="LIST",
                   help="radial clearances [µm], comma-separated (default -15,-10,-6,-3,0,5,10,20,40,60,100)")
    p.add_argument("--speeds", type=_floats, default=None, metavar="LIST",
                   help="crank speeds [rpm] of the speed sweep (default 300,450,600,900,1200,1500,1800)")
    p.add_argument("--rpm", type=float, default=cases.CLEARANCE_RPM, help="crank speed of the clearance sweep")
    p.add_argument("--balls", type=int, default=8, help="number of balls (default 8)")
    p.add_argument("--startup-revs", type=float, default=1.0,
                   help="crank revolutions simulated before the life window (default 1)")
    p.add_argument("--window-revs", type=float, default=1.0,
                   help="crank revolutions over which the life is accumulated (default 1)")
    p.add_argument("--step", type=float, default=cases.DEFAULT_STEP,
                   help=f"communication step = sampling interval [s] (default {cases.DEFAULT_STEP:g}, at most {cases.MAX_STEP:g})")
    p.add_argument("--workers", type=int, default=None, help="parallel runs (default: the number of cores)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_life_study)
