"""Which coupling scheme and communication step meet a tolerance at one operating point, and the
largest stable step of every scheme (python -m mechanism advise).

  python -m mechanism advise --rpm 600 --balls 15 --set allow_ball_overlap=true --tolerance 1%

prints one line (the cheapest scheme and step within the tolerance, the largest stable step of every
scheme) and a small table, and writes advise.md, advise.json, advise.csv and advise.png to --out.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mechanism.studies.advise.runs import (MAX_STEP, MAX_STEPS, RESOLUTION, START_STEP, AdviceConfig, Refused,
                                           advise)
from mechanism.studies.advise.search import DEFAULT_MERIT, MERITS


def parse_tolerance(text: str) -> float:
    """'1%' -> 0.01, '0.01' -> 0.01."""
    t = text.strip()
    try:
        return float(t[:-1]) / 100 if t.endswith("%") else float(t)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--tolerance expects e.g. 1% or 0.01, got {text!r}") from None


def config_from_args(args) -> AdviceConfig:
    settings = dict(args.settings)
    if args.damping is not None:
        settings["damping_coefficient"] = args.damping
    if args.clearance is not None:
        settings["radial_clearance"] = args.clearance
    schemes = None if args.schemes == "all" else [s.strip() for s in args.schemes.split(",") if s.strip()]
    return AdviceConfig(rpm=args.rpm, balls=args.balls, settings=settings, tolerance=args.tolerance,
                        merits=[m.strip() for m in args.merit.split(",") if m.strip()], schemes=schemes,
                        mode=args.mode, fmu=args.fmu, revs=args.revs, output_interval=args.output_interval,
                        start_step=args.start_step, max_step=args.max_step, max_steps=args.max_steps,
                        resolution=args.resolution,
                        workers=args.workers, scheduler=args.scheduler, reference_cache=args.reference_cache,
                        out=args.out, plots=not args.no_plots, progress=not args.quiet)


def cmd_advise(args) -> int:
    from mechanism.studies.advise.report import one_line, table_text, timing_text, write
    try:
        advice = advise(config_from_args(args))
    except Refused as err:
        print(err, file=sys.stderr)
        return 2
    paths = write(advice, Path(args.out))
    print(one_line(advice))
    print(table_text(advice))
    print(timing_text(advice) + f"; wrote {', '.join(p.name for p in paths)} to {args.out}")
    failed = [s for s, search in advice.searches.items() if search.error]
    for s in failed:
        print(f"error: {s}: {advice.searches[s].error}", file=sys.stderr)
    if advice.answer is None or len(failed) == len(advice.searches):
        return 1
    return 0


def register(subparsers) -> None:
    from mechanism.run import parse_setting
    p = subparsers.add_parser(
        "advise", help="the cheapest coupling scheme and step within a tolerance, and each scheme's largest "
                       "stable step, at one operating point",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rpm", type=float, default=1200.0, help="crank speed [rpm] (default 1200)")
    p.add_argument("--balls", type=int, default=None, help="number of balls (default the FMU's 8)")
    p.add_argument("--damping", type=float, default=None,
                   help="damping coefficient per loaded ball [N·s/m] (default the FMU's 50)")
    p.add_argument("--clearance", type=float, default=None,
                   help="radial (diametral) internal clearance P_d [m] (default the FMU's 2e-5)")
    p.add_argument("--set", dest="settings", action="append", type=parse_setting, default=[], metavar="NAME=VALUE",
                   help="any other bearing parameter (repeatable), e.g. allow_ball_overlap=true")
    p.add_argument("--tolerance", type=parse_tolerance, default=0.01,
                   help="largest relative error of the figure(s) of merit, e.g. 1%% or 0.01 (default 1%%)")
    p.add_argument("--merit", default=DEFAULT_MERIT,
                   help=f"figure(s) of merit, comma-separated, all must meet the tolerance: {', '.join(MERITS)} "
                        f"(default {DEFAULT_MERIT})")
    p.add_argument("--schemes", default="all", help="coupling schemes: 'all' (default) or a comma list")
    p.add_argument("--mode", choices=("cosim", "inprocess"), default="cosim",
                   help="cosim: through the FMU (default); inprocess: the same force law in-process")
    p.add_argument("--fmu", default=None, help="BallBearing FMU (default dist/BallBearing.fmu, built on first use)")
    p.add_argument("--revs", type=float, default=2.0, help="revolutions per run; errors over the second (default 2)")
    p.add_argument("--output-interval", type=float, default=1e-5,
                   help="the reference's sampling grid [s]; steps are its fractions and multiples (default 1e-5)")
    p.add_argument("--start-step", type=float, default=START_STEP,
                   help=f"first step tried per scheme [s] (default {START_STEP:g})")
    p.add_argument("--max-step", type=float, default=MAX_STEP,
                   help=f"largest step searched [s] (default {MAX_STEP:g}); stable there is reported as a bound")
    p.add_argument("--max-steps", type=int, default=MAX_STEPS,
                   help=f"cost cap: no run with more communication steps (default {MAX_STEPS}); sets the smallest step")
    p.add_argument("--resolution", type=float, default=RESOLUTION,
                   help=f"neighbouring steps searched differ by at least this ratio (default {RESOLUTION:g}; "
                        "1: every step on the output grid)")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: the core count)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run on this Dask distributed scheduler instead (needs the 'studies' extra)")
    p.add_argument("--reference-cache", default="results/references",
                   help="folder of cached monolithic references (default results/references)")
    p.add_argument("--out", default="results/advise", help="output folder (default results/advise)")
    p.add_argument("--no-plots", action="store_true", help="no PNG plot")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_advise)
