"""Command line: ``python -m mechanism SUBCOMMAND`` (also installed as ``bearing-cosim``); see ``DESCRIPTION``."""
from __future__ import annotations

import argparse
import itertools
import os
import signal
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from mechanism.cosim.coupling import DEFAULT_SCHEME, SCHEMES
from mechanism.cosim.joint import CONTACT_POINTS
from mechanism.run import DEFAULT_STEP, parse_setting

if TYPE_CHECKING:
    from mechanism.run import RunConfig


class _MonolithicMethods:
    """``mechanism.cosim.monolithic.METHODS`` as argparse choices, imported only when asked (scipy's import
    costs a second; a run that is not monolithic does not need it)."""

    def _names(self) -> tuple[str, ...]:
        from mechanism.cosim.monolithic import METHODS
        return tuple(METHODS)

    def __contains__(self, name) -> bool:
        return name in self._names()

    def __iter__(self):
        return iter(self._names())


METHODS = _MonolithicMethods()


def add_run_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rpm", type=float, default=1200.0, help="constant crank speed [rpm] (default 1200)")
    p.add_argument("--balls", type=int, default=None, help="number of balls (the FMU's n_balls; default 8)")
    p.add_argument("--revs", type=float, default=2.0, help="crank revolutions to simulate (default 2)")
    p.add_argument("--joint", choices=("bearing", "ideal", "clearance"), default="bearing",
                   help="crank-rod joint: ball-bearing FMU, ideal revolute, or journal-bushing clearance FMU")
    p.add_argument("--mode", choices=("cosim", "inprocess", "monolithic"), default="cosim",
                   help="cosim: through the FMU via fmpy; inprocess: same master, force law in-process; "
                        "monolithic: scipy stiff integrator reference")
    p.add_argument("--step", type=float, default=DEFAULT_STEP,
                   help=f"communication step [s] (default {DEFAULT_STEP:g}; docs/coupling.md, 'The default step')")
    p.add_argument("--output-interval", type=float, default=1e-5, help="sampling interval [s] (default 1e-5)")
    p.add_argument("--record-every", type=int, default=None, metavar="N",
                   help="record every N-th communication step (sets --output-interval to N * step; default: "
                        "every 1e-5 s, i.e. every 2nd step at the default step)")
    p.add_argument("--set", dest="settings", action="append", type=parse_setting, default=[],
                   metavar="NAME=VALUE", help="start value of a bearing-component parameter (repeatable)")
    p.add_argument("--scheme", choices=tuple(SCHEMES), default=DEFAULT_SCHEME,
                   help=f"coupling scheme (default {DEFAULT_SCHEME}; see docs/coupling.md)")
    p.add_argument("--contact-points", choices=CONTACT_POINTS, default="centres",
                   help="apply the bearing force at the ring centres (default) or at eq. 15's contact points")
    p.add_argument("--gravity", action="store_true", help="add gravity (-9.81 m/s² along y)")
    p.add_argument("--fmu", default=None, help="component FMU (default dist/<Name>.fmu, built on first use)")
    p.add_argument("--method", choices=METHODS, default="LSODA", metavar="METHOD",
                   help="monolithic integrator: scipy.integrate's Radau, BDF or LSODA (default LSODA)")
    p.add_argument("--rtol", type=float, default=1e-9, help="monolithic relative tolerance")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def config_from_args(args) -> RunConfig:
    from mechanism.run import RunConfig
    return RunConfig(rpm=args.rpm, revs=args.revs, balls=args.balls, joint=args.joint, mode=args.mode,
                     step=args.step, output_interval=args.output_interval, settings=dict(args.settings),
                     scheme=args.scheme, contact_points=args.contact_points, gravity=args.gravity,
                     fmu=args.fmu, method=args.method, rtol=args.rtol, progress=not args.quiet,
                     record_every=args.record_every)


def check_output_folder(out: Path) -> None:
    """Before any simulation: ``--out`` must be a folder (or not exist yet) that this user can write."""
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is an existing file, not a folder")
    parent = next((p for p in (out, *out.parents) if p.exists()), Path("."))
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"--out {out}: cannot write into {parent}")


#: exit status of an interrupted run (128 + SIGINT, as a shell reports Ctrl-C)
EXIT_INTERRUPTED = 130


#: wall seconds of the last ``cmd_run``'s phases: imports (of the run's modules), run (the master, with the
#: compiled kernels' and the FMU's loading), ideal (the counterpart), outputs (CSV, summary, plots);
#: benchmarks/cosim.py prints them
PHASES: dict[str, float] = {}


def cmd_run(args) -> int:
    start = time.perf_counter()
    from mechanism.output import stream
    from mechanism.output.results import (
        COMPARED,
        DRAWN_WITH_IDEAL,
        compared_columns,
        finish_outputs,
        output_lock,
        start_run_plots,
        write_ideal_tables,
        write_outputs,
        write_run_table,
    )
    from mechanism.run import interrupted, run, stop_on_signals
    from mechanism.ssp.config import config_from_ssp_args
    out = Path(args.out)
    check_output_folder(out)
    config = config_from_ssp_args(args) if args.ssp else config_from_args(args)
    PHASES.clear()
    # the streams' files are removed unless they were completed (renamed onto timeseries.csv, ideal_timeseries.csv)
    ideal_planned = config.joint != "ideal" and not args.no_ideal
    with output_lock(out), output_workers(not args.no_plots, figure_plan(config, ideal_planned)) as workers, \
            stream.for_run(out, config, not args.no_plots, workers, config.joint != "ideal" and not args.no_ideal) \
            as sink, \
            stream.for_ideal(out, config, not args.no_plots, workers) as ideal_sink:
        marks = [start, time.perf_counter()]
        result = run(config, sink)     # timeseries.csv written as the samples are recorded (renamed when complete)
        marks.append(time.perf_counter())
        stopped = interrupted()
        wants_ideal = not stopped and config.joint != "ideal" and not args.no_ideal
        # the run's table is written and let go before the ideal runs (issue 11); with plots, once a worker draws
        # the figures of the run alone, keeping the columns of the others
        early = drawing = None
        if wants_ideal and not args.no_plots:
            drawing = start_run_plots(result, out, workers)
        if wants_ideal and (args.no_plots or drawing is not None):
            with stop_on_signals():   # a signal while writing waits until the file is complete (then no ideal)
                early = write_run_table(result, out)
            stopped = interrupted()
            # what summary.json compares with the ideal (and the plots draw beside it); the rest is freed
            result = compared_columns(result, COMPARED if drawing is None else DRAWN_WITH_IDEAL)
        written = time.perf_counter() - marks[-1]
        ideal = None
        if wants_ideal and not stopped:
            # resampled onto the run's times straight into ideal_timeseries.csv (its table never whole in memory)
            ideal = ideal_counterpart(config, result, workers, ideal_sink)
            stopped = interrupted()
        marks.append(time.perf_counter())
        with stop_on_signals():   # a signal while writing waits until the files are complete
            if drawing is not None:
                figures = finish_outputs(early, result, out, ideal, workers, drawing, plots=not stopped)
            elif early is not None:
                figures = dict(write_ideal_tables(early, result, out, ideal), plots=[])
            else:
                figures = write_outputs(result, out, ideal, plots=not args.no_plots and not stopped,
                                        workers=workers)
        marks.append(time.perf_counter())
    PHASES.update(zip(("imports", "run", "ideal", "outputs"), (b - a for a, b in itertools.pairwise(marks))))
    PHASES["ideal"] -= written      # the run's table written before the ideal ran counts as output
    PHASES["outputs"] += written
    files = "timeseries.csv" + (", ideal_timeseries.csv" if ideal is not None else "") + ", summary.json"
    print(f"wrote {out}/{files}" + (f" and {len(figures['plots'])} plots" if figures["plots"] else ""))
    label, part = ("second revolution", figures["rev2"]) if "rev2" in figures else ("whole run", figures.get("all"))
    if part:
        print(f"  {label}: max |e| = {part['max_eccentricity_m'] * 1e6:.3f} µm, "
              f"peak |F| = {part['peak_joint_force_N']:.2f} N, "
              + (f"max ball load = {part['max_ball_load_N']:.2f} N, " if part.get('max_ball_load_N') else "")
              + f"crank moment {part['crank_moment_min_N_m']:.3f} .. {part['crank_moment_max_N_m']:.3f} N·m")
    for r in (result, ideal):
        if r is not None and not r.ok:
            message = " ".join(r.message.split())
            print(f"error: {message} ({len(r.data)} samples up to then are written)", file=sys.stderr)
            return EXIT_INTERRUPTED if r.status == "interrupted" else 1
    if stopped or interrupted():
        print(f"error: interrupted by {stopped or interrupted()} (the run had completed; files are written)",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    return 0


@contextmanager
def output_workers(plots: bool, plan=None):
    """``mechanism.output.workers.OutputWorkers`` for a run that plots (they import matplotlib and, given the
    run's ``plan`` (``figure_plan``), prepare its figures' frames while the run runs), None otherwise or where
    they are disabled."""
    from mechanism.output import workers
    from mechanism.output.results import drawn_by
    n = workers.count() if plots else 0
    if not n:
        yield None
        return
    names = drawn_by(n, plan.ideal) if plan is not None else ()
    with workers.OutputWorkers(n, plan, names) as started:
        yield started


def figure_plan(config: RunConfig, ideal: bool):
    """What the run of ``config`` will record in its meta for the figures (``run.run``'s configuration, crank
    period and clearance), with or without an ``ideal`` counterpart, ending at 2 ``revs`` π rad of crank angle:
    ``mechanism.output.figures.Plan``."""
    from mechanism.output.figures import Plan
    from mechanism.run import run_meta
    return Plan(run_meta(config), ideal, 2.0 * config.revs)


def ideal_counterpart(config: RunConfig, result, workers=None, sink=None):
    """The ideal joint's run for comparison, at the cheapest step that keeps its documented agreement
    (``IDEAL_STEP``: RK4 at 1e-4 s matches 1e-5 s to < 1e-9, mechanism.studies.reproduce.cases), resampled
    by cubic splines onto the bearing run's sample times when those are finer (error < 1e-9 relative
    for these smooth signals; measured in tests/test_kernels.py; ``record.resample``, scipy's spline without
    importing scipy.interpolate). ``workers``: the resampling runs in the first output worker when it is idle (the
    same function, the same numbers); the command resamples itself while that worker draws the run's figures.
    ``sink`` (``mechanism.output.stream.TableStream``): the resampled rows go to it, here (the result is its); when
    there is nothing to resample, it is not used."""
    from dataclasses import replace

    from mechanism.cosim.record import resample
    from mechanism.run import run
    from mechanism.studies.reproduce.cases import IDEAL_STEP
    step = max(config.step, IDEAL_STEP)
    ideal = run(replace(config, joint="ideal", mode="cosim", settings={}, balls=None, step=step, record_every=None,
                        output_interval=max(step, config.output_interval)))
    if ideal.ok and len(ideal.data) > 1 and ideal.meta.get("output_interval_s") != result.meta.get("output_interval_s"):
        if sink is not None:
            from mechanism.output.stream import resample_ideal
            return resample_ideal(ideal, result["time"], sink)
        ideal = workers.call(0, "resample", ideal, result["time"]) if workers else resample(ideal, result["time"])
    return ideal


#: modules that add a subcommand: each defines ``register(subparsers)`` (add_parser + set_defaults(func=...))
SUBCOMMAND_MODULES = ("mechanism.studies.reproduce", "mechanism.studies.stepsize", "mechanism.studies.advise",
                      "mechanism.studies.life",
                      "mechanism.ssp.cli")


class Parser(argparse.ArgumentParser):
    """argparse with a one-line error (the usage is one --help away)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


DESCRIPTION = ("Co-simulate the slider-crank of Xu et al. (2012) with its crank-rod joint as a ball-bearing FMU: "
               "one run, the paper's Section 5, step-size studies and advice, and the system as SSP "
               "(also installed as bearing-cosim). 'python -m mechanism SUBCOMMAND --help' describes each.")


def build_parser(studies: bool = True) -> argparse.ArgumentParser:
    """The parser with every subcommand (each package's ``register`` adds its own); ``studies=False``: ``run``
    alone (``main`` for a ``run`` command line: the other subcommands' modules are not imported)."""
    import importlib
    parser = Parser(prog="python -m mechanism", description=DESCRIPTION)
    sub = parser.add_subparsers(dest="command", required=True, metavar="SUBCOMMAND")
    text = "simulate the paper's slider-crank once and write CSV, JSON and PNG"
    p = sub.add_parser("run", help=text, description=text[0].upper() + text[1:] + ".")
    add_run_arguments(p)
    from mechanism.ssp.config import add_ssp_arguments
    add_ssp_arguments(p)
    p.add_argument("--out", default="results/run", help="output folder (default results/run)")
    p.add_argument("--no-ideal", action="store_true", help="do not run the ideal-joint counterpart")
    p.add_argument("--no-plots", action="store_true", help="write CSV and JSON only")
    p.set_defaults(func=cmd_run)
    for name in SUBCOMMAND_MODULES if studies else ():
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name != name:
                raise
            continue
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser(studies=not argv or argv[0] != "run")
    args = parser.parse_args(argv)
    return call(args.func, args)


def _terminate(signum, frame):
    raise KeyboardInterrupt(signal.Signals(signum).name)


def call(func, args) -> int:
    """``func(args)`` with every failure as one line naming the cause and a non-zero exit status: 2 for bad
    input, 1 for a failed run or an I/O problem (a full disk), 130 for an interrupt (SIGINT, or SIGTERM
    outside a run: within a run both end it with its samples written). ``MECHANISM_TRACEBACK=1`` re-raises."""
    from fmpy.fmi1 import FMICallException
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _terminate)
    try:
        return func(args)
    except KeyboardInterrupt as err:
        print(f"error: interrupted by {err.args[0] if err.args else 'SIGINT'}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as err:
        if os.environ.get("MECHANISM_TRACEBACK"):
            raise
        if isinstance(err, OSError) and err.strerror:
            cause = f"{err.strerror}" + (f": {err.filename}" if err.filename else "")
        elif isinstance(err, (ValueError, RuntimeError, FMICallException)):
            cause = str(err)
        else:
            cause = f"{type(err).__name__}: {err}"
        print(f"error: {cause}".splitlines()[0], file=sys.stderr)
        return 2 if isinstance(err, (ValueError, FileNotFoundError)) else 1

def exit_now(code: int) -> None:
    """End the process with ``code`` as ``sys.exit`` would, without Python's tear-down of every module's objects
    (numba's, fmpy's: ~0.2-0.3 s of the headline command, issue 11): the atexit handlers run (the FMUs' extracted
    folders are removed, logging is flushed), stdout and stderr are flushed, then ``os._exit``. Every file the
    commands write is closed by then. With another non-daemon thread alive, a normal exit (it waits for it)."""
    import atexit
    others = [t for t in threading.enumerate() if t is not threading.main_thread() and not t.daemon and t.is_alive()]
    run_exitfuncs = getattr(atexit, "_run_exitfuncs", None)   # (CPython's; without it, the normal exit)
    if others or run_exitfuncs is None or not (code is None or isinstance(code, int)):
        sys.exit(code)
    run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:          # (None: started with that descriptor closed)
                stream.flush()
        except (OSError, ValueError):   # a closed pipe: nothing more to write there
            pass
    try:   # C's stdio buffers too (an FMU's or a library's printf): os._exit does not flush them
        import ctypes
        ctypes.CDLL(None).fflush(None)
    except Exception:  # noqa: BLE001  (no C library by that name: nothing to flush)
        pass
    os._exit(0 if code is None else code)    # sys.exit's meaning of None


if __name__ == "__main__":
    exit_now(main())
