"""Wall time of a run with the compiled communication step against the Python loop (issue 11).

Runs ``mechanism.run.run`` (``--mode inprocess``, the default, or ``cosim``: BallBearing.fmu, called natively by
the compiled loop and through fmpy by the Python loop) for the same RunConfig with ``MasterSettings.compiled_loop`` True and False,
interleaved, ``--repeat`` times each, after one warm-up run each (kernels compiled/loaded), in one process, and
prints the medians, µs per communication step and their ratio; with ``--cold`` first the wall time of one run in
a fresh numba cache (a subprocess with NUMBA_CACHE_DIR in a new temporary folder: the compile). ``--scheme`` picks
the coupling scheme (default jacobian-implicit); ``--against S`` times scheme S through the compiled loop instead of
the Python loop (e.g. ``--scheme law-model --against jacobian-implicit``: both compiled, interleaved).

    python benchmarks/compiled_loop.py [--mode inprocess|cosim] [--revs 2] [--rpm 1200] [--step 1e-5] [--repeat 3]
                                       [--scheme jacobian-implicit] [--against SCHEME] [--cold]
"""
from __future__ import annotations

import argparse
import dataclasses
import functools
import os
import statistics
import subprocess
import sys
import tempfile
import time

from mechanism import run as run_module
from mechanism.cosim.master import MasterSettings
from mechanism.run import RunConfig, run


def timed(config: RunConfig, compiled: bool) -> float:
    """Wall time [s] of one run with the compiled loop on or off."""
    run_module.MasterSettings = functools.partial(MasterSettings, compiled_loop=compiled)
    try:
        start = time.perf_counter()
        result = run(config)
        elapsed = time.perf_counter() - start
    finally:
        run_module.MasterSettings = MasterSettings
    if not result.ok:
        raise SystemExit(f"run failed: {result.message}")
    return elapsed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mode", choices=("inprocess", "cosim"), default="inprocess")
    ap.add_argument("--revs", type=float, default=2.0)
    ap.add_argument("--rpm", type=float, default=1200.0)
    ap.add_argument("--step", type=float, default=1e-5)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--scheme", default="jacobian-implicit")
    ap.add_argument("--against", default="", help="a second scheme, compiled, instead of the Python loop")
    ap.add_argument("--cold", action="store_true", help="also time one run in a fresh numba cache")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    config = RunConfig(mode=args.mode, rpm=args.rpm, revs=args.revs, step=args.step, progress=False,
                       scheme=args.scheme, settings={"damping_model": 1, "damping_coefficient": 50})
    if args.child:       # the cold run, in a fresh cache (set by the parent)
        print(f"{timed(config, True):.2f}")
        return
    if args.cold:
        with tempfile.TemporaryDirectory() as cache:
            env = dict(os.environ, NUMBA_CACHE_DIR=cache)
            start = time.perf_counter()
            out = subprocess.run([sys.executable, __file__, "--child", "--mode", args.mode, "--revs", str(args.revs),
                                  "--rpm", str(args.rpm), "--step", str(args.step), "--scheme", args.scheme],
                                 env=env, capture_output=True,
                                 text=True, check=True).stdout.strip()
            total = time.perf_counter() - start
        print(f"cold (fresh numba cache): the run {out} s, the process {total:.2f} s")
    steps = round(config.revs * config.crank_period / config.step)
    if args.against:
        other = dataclasses.replace(config, scheme=args.against)
        timed(config, True)
        timed(other, True)
        times = {args.scheme: [], args.against: []}
        for _ in range(args.repeat):
            for c in (config, other):
                times[c.scheme].append(timed(c, True))
        med = {k: statistics.median(v) for k, v in times.items()}
        print(f"{args.revs:g} revolutions at {args.rpm:g} rpm, step {args.step:g} s ({steps} steps), compiled loop, "
              f"{args.mode}, medians of {args.repeat}")
        for k, v in med.items():
            print(f"{k:20s} {v:7.3f} s  {1e6 * v / steps:7.1f} µs/step")
        print(f"ratio {args.scheme} / {args.against}  {med[args.scheme] / med[args.against]:7.2f}")
        return
    timed(config, True)
    timed(config, False)
    times = {True: [], False: []}
    for _ in range(args.repeat):
        for flag in (True, False):
            times[flag].append(timed(config, flag))
    on, off = statistics.median(times[True]), statistics.median(times[False])
    print(f"{args.revs:g} revolutions at {args.rpm:g} rpm, step {args.step:g} s ({steps} steps), "
          f"{args.scheme}, {args.mode}, medians of {args.repeat}")
    print(f"compiled loop   {on:7.3f} s  {1e6 * on / steps:7.1f} µs/step")
    print(f"Python loop     {off:7.3f} s  {1e6 * off / steps:7.1f} µs/step")
    print(f"ratio           {off / on:7.1f} x")


if __name__ == "__main__":
    main()
