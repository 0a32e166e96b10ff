"""``python -m mechanism stepsize-study``: options, the command, and its registration."""
from __future__ import annotations

from collections import Counter

from mechanism.studies.stepsize.cases import (
    ADAPTIVE,
    DEFAULT_STEPS,
    DEFAULT_TOLS,
    DIVERGENCE,
    MAX_STEPS_PER_CASE,
    ORDER_CEILING,
    ORDER_FLOOR,
    OUTPUT_INTERVAL,
    STABLE,
    StudyConfig,
    parse_grid,
    parse_settings,
)
from mechanism.studies.stepsize.runs import replot, run_study
from mechanism.studies.stepsize.tables import step_limit


# ------------------------------------------------------------------------------------------ CLI
def config_from_args(args) -> StudyConfig:
    from mechanism.cosim.coupling import SCHEMES
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
    config = config_from_args(args)
    check_physical_cases(config)
    result = run_study(config)
    print(f"wrote {result.out}/stepsize.csv, stepsize_summary.json, stepsize_summary.md and plots "
          f"({len(result.rows)} cases, {result.wall_time:.0f} s)")
    for g, info in result.summary["groups"].items():
        for scheme, e in info["schemes"].items():
            o = e["order"].get("order")
            print(f"  {g} {scheme:15s} largest stable step {step_limit(e, 'largest_stable_step_s')}, "
                  f"peak error (peak joint force, max eccentricity) ≤ 1 % up to "
                  f"{step_limit(e, 'largest_step_within_1pct_s')}, order {'—' if o is None else f'{o:.2f}'}")
    failures = Counter((r["status"], (r.get("message") or "").split(":")[0][:80]) for r in result.rows
                       if r["status"] != STABLE)
    for (status, cause), n in failures.most_common():
        print(f"  {n} case(s) {status}: {cause or 'no message'}")
    return exit_status(result.rows)


def check_physical_cases(config: StudyConfig) -> None:
    """Before any run: each (rpm, balls, settings) must make a valid run (``RunConfig``'s ranges and the
    bearing's validation); ValueError naming the cause otherwise."""
    import itertools

    from mechanism.run import RunConfig
    for rpm, balls, settings in itertools.product(config.rpms, config.balls, config.settings):
        RunConfig(rpm=rpm, balls=balls, settings=dict(settings), revs=config.revs, fmu=config.fmu,
                  step=config.output_interval, output_interval=config.output_interval, progress=False)


def exit_status(rows: list[dict]) -> int:
    """1 (with the causes on stderr) when every case failed: none that was not skipped for its cost ended
    stable (an error, a refusal at the first step or an unstable run); 0 otherwise, where an unstable scheme
    among stable ones is a result of the study, not an error."""
    import sys

    from mechanism.studies.stepsize.cases import SKIPPED
    ran = [r for r in rows if r["status"] != SKIPPED]
    broken = [r for r in ran if r["status"] != STABLE]
    if ran and len(broken) == len(ran):
        causes = list(dict.fromkeys(" ".join(str(r["message"]).split()) for r in broken))
        print(f"error: every case failed ({len(ran)} cases): {causes[0]}"
              + (f" (and {len(causes) - 1} other causes; see stepsize.csv)" if len(causes) > 1 else ""),
              file=sys.stderr)
        return 1
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "stepsize-study", help="error, cost and stability of the coupling schemes against the step size",
        description="Error, cost and stability of each coupling scheme against the communication step, "
                    "measured against the monolithic reference (docs/stepsize-study.md).")
    p.add_argument("--rpm", type=float, nargs="+", default=[1200.0], help="crank speed(s) [rpm] (default 1200)")
    p.add_argument("--balls", type=int, nargs="+", default=None, help="ball count(s) (default: the FMU's 8)")
    p.add_argument("--set", dest="settings", action="append", default=[], metavar="NAME=V1[,V2...]",
                   help="bearing-component parameter value(s); repeat for several names (cartesian product)")
    p.add_argument("--steps", default=DEFAULT_STEPS,
                   help=f"communication steps [s]: lo:hi:count log-spaced, or a comma list (default {DEFAULT_STEPS}); "
                        "snapped to the output grid")
    p.add_argument("--tols", default=DEFAULT_TOLS, help=f"tolerances of the adaptive scheme (default {DEFAULT_TOLS})")
    p.add_argument("--schemes", default="law-model,jacobian-implicit,jacobian-drift,jacobian,extrap1,zoh",
                   help="'all' (every scheme and adaptive) or a comma list "
                        "(default law-model,jacobian-implicit,jacobian-drift,jacobian,extrap1,zoh)")
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
                        "about 30 s through the FMU; 1e-7 s over 2 revs at 1200 rpm is 1e6 steps)")
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
