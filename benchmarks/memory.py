"""Peak memory of ``python -m mechanism run`` (issue 11: a 20-revolution run under 200 MB peak).

    python benchmarks/memory.py [--revs 2 20] [--root CHECKOUT] [--fmu dist/BallBearing.fmu] [--plots]
                                [--phases N] [--each] [-- EXTRA RUN ARGUMENTS]

Each run is a fresh ``python -m mechanism run --revs N --quiet --no-plots`` (``--plots``: with the plots) in a
subprocess of the checkout ``--root`` (default this one; e.g. a worktree of the commit before, to measure
before/after in one go); its peak resident set size is the child's ``ru_maxrss`` (``os.wait4``: that child
and its own children, as ``/usr/bin/time -v`` reports it). Printed per run: the peak, the recorded data
(timeseries.csv and ideal_timeseries.csv as float64 tables: rows x columns x 8 bytes) and the peak less the
data; then the growth per revolution between the first and the last run (the data's own growth beside it).

``--each`` runs each command once more in-process of a child (``mechanism.cli.main``) and prints its own peak
(``RUSAGE_SELF``) and its output workers' (``RUSAGE_CHILDREN``: the largest reaped child).

``--phases N`` instead runs one N-revolution command (``mechanism.cli.main``) in a child that prints its resident
set size and its peak within each phase (imports, the run, the ideal counterpart's run and resample, the summary
and the CSV files: ``/proc/self/status`` VmRSS and VmHWM after each of these functions returns, the peak reset
through ``/proc/self/clear_refs``): where the peak is. With ``--root`` an older checkout, the phases its
functions have.

The first run of a checkout compiles the numba kernels into its cache: run it once before measuring.

Measured (2 shared cores, 04:05 UTC, ``python benchmarks/memory.py`` here and with ``--root`` a worktree of
a1e65ab and ``--fmu`` this checkout's dist/BallBearing.fmu; default step 5e-6 s, output every 1e-5 s; MB = 1000 kB):

                          before (a1e65ab)   after
    2 revolutions             216.5 MB      186.9 MB
    20 revolutions            258.2 MB      211.0 MB   (/usr/bin/time -v: 258,240 and 211,048 kbytes)
    growth per revolution      2.32 MB       1.34 MB   (the recorded data's own: 1.96 MB, the run's table 1.38)

Where it went (``--phases 20``, before -> after): scipy.interpolate is no longer imported for the ideal
counterpart's resampling (``mechanism.cosim.spline``, scipy's CubicSpline to the bit: ~23 MB); without plots
the run's table is written and let go before the ideal counterpart runs, so the two tables (27.7 and 13.4 MB)
are never held together; the summary takes its peaks over views (the stacked ball loads and the window's life
were ~11 MB of temporaries); CSV chunks of 256 rows (2,000 rows left ~5 MB of freed heap resident). What is
left of a 20-revolution run's 211 MB: interpreter, numpy and the project's modules 35 MB, numba 62 MB, the
compiled kernels ~70 MB, the FMU ~6-10 MB, the run's table 27.7 MB (1.38 MB per revolution) and ~4 MB while
the table is written (the summary, the compared columns kept for the ideal counterpart).
With ``--plots`` the peak was ~297-306 MB (the tables pickled to the output workers).

With plots (05:05-05:12 UTC, ``python benchmarks/memory.py --plots --each`` here and with ``--root`` a checkout of
a6e803a, ``--fmu`` this checkout's dist/BallBearing.fmu; the other columns ``--no-plots``):

                          with plots: before (a6e803a)   after       without plots: before   after
    2 revolutions             194.1 MB                  185.9 MB                   185.2 MB   185.3 MB
    20 revolutions            297.2 MB                  213.6 MB                   210.0 MB   210.4 MB
                                                                    (/usr/bin/time -v: 297,088 and 213,504 kbytes)
    the command alone (20)    297.4 MB                  213.7 MB
    its worker (largest, 20)  202.7 MB                  109.1 MB   (two workers: 109.2 MB)

Where it went (``--phases 20 --plots``): the workers receive only the columns the figures read, one column at a
time as raw bytes (``workers.ColumnsOf``, ``Connection.send_bytes``), not the pickled tables (the command's
pickled copy was ~65 MB: 297.5 -> 225 MB); the resampled ideal comes back the same way (no pickled copy on
receipt: 238 -> 224 MB); a worker draws the figures of the run alone while the command writes the run's table and
lets it go (it keeps the 7 columns the other figures read, 5.9 MB) before the ideal counterpart runs, as without
plots (224 -> 214 MB: the peak is now the run's own, 206.5 MB, and the 5.9 MB copy kept); the workers no longer
import scipy.interpolate (~20 MB each). Every file (PNGs, CSVs, summary.json) of a 20-revolution run is the
same bytes as before.

Streamed (issue 11, 07:30 UTC 2026-11-26, ``python benchmarks/memory.py --revs 2 20 [--plots --each]`` here and with
``--root`` a checkout of d8ee290; the 40-revolution row ``--revs 40``; /usr/bin/time -v agrees within 1 MB):

                          without plots: before (d8ee290)   after      with plots: before   after
    2 revolutions             186.7 MB                      186.5 MB               186.9 MB   186.7 MB
    20 revolutions            211.4 MB                      194.0 MB               214.9 MB   195.6 MB
    40 revolutions                                          204.1 MB
    growth per revolution      1.38 MB                       0.42 MB                1.55 MB    0.50 MB
    its output workers (20)                                                        106.3 MB   103.5 MB

Where it went: the run's table is never whole. ``record.Recorder`` with a sink (``output.stream.TableStream``) holds
``record.STREAM_ROWS`` rows and hands them on as the compiled loop's chunks fill them: they are appended to
timeseries.csv (a temporary name, renamed where the table was written before), the summary's peaks, energy figures
and (a component without life outputs) life are accumulated, the second revolution's rows are kept until the
summary has their figures, and only the columns the command still needs stay: those summary.json compares with the
ideal counterpart (3 of 35) and, with plots, none more on a long run (the columns of the figures of the run alone go
to the first output worker during the run, 1 MB at a time, those of the figures with the ideal curve to the second);
the ideal counterpart is resampled straight into ideal_timeseries.csv in blocks (the spline keeps its knot slopes,
not the 4x larger coefficients; the workers resample the columns they draw themselves). ``--phases 20 --plots``: the
run 189.5 MB (was 206.5), the peak is now the ideal counterpart's resample, 195.7 MB. What still grows (~0.45 MB
per revolution) is the ideal counterpart's: its own table at 1e-4 s, its slopes and the compared columns of both
(summary.json's RMS deviation is a pairwise sum over the whole columns). Every file (CSVs, summary.json, PNGs) of
the 2- and 20-revolution runs is the same bytes as before (``cmp``).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

PHASES = r'''
import sys

def mark(name):
    status = dict(line.split(":", 1) for line in open("/proc/self/status"))
    mb = lambda key: int(status[key].split()[0]) / 1000
    print(f"  {name:40s} RSS {mb('VmRSS'):7.1f} MB   peak within the phase {mb('VmHWM'):7.1f} MB", flush=True)
    try:
        with open("/proc/self/clear_refs", "w") as f:   # reset VmHWM to the current RSS
            f.write("5")
    except OSError:
        pass

mark("interpreter")
import mechanism.cli as cli
import mechanism.output.results as results
import mechanism.run as runs
mark("imports")

def marked(module, name, label):
    function = getattr(module, name, None)
    if function is None:   # an older checkout without it
        return
    def wrapper(*args, **kwargs):
        value = function(*args, **kwargs)
        mark(label(args) if callable(label) else label)
        return value
    setattr(module, name, wrapper)

marked(runs, "run", lambda a: f"run ({a[0].joint}: kernels, component, samples)")
marked(cli, "ideal_counterpart", "ideal counterpart's resample")
marked(results, "write_run_table", "summary, timeseries.csv")
marked(results, "compared_columns", "the run's table let go")
marked(results, "write_ideal_tables", "ideal_timeseries.csv, summary.json")
marked(results, "write_outputs", "write_outputs (CSV files, summary.json)")
rc = cli.main(["run", "--revs", sys.argv[1], "--quiet", "--out", sys.argv[2]] + sys.argv[3:])
print("  modules: scipy.interpolate", "scipy.interpolate" in sys.modules, "| matplotlib", "matplotlib" in sys.modules,
      "| pandas", "pandas" in sys.modules, "| exit status", rc)
'''


EACH = r'''
import resource, sys
from mechanism import cli
rc = cli.main(sys.argv[1:])
peak = lambda who: resource.getrusage(who).ru_maxrss / 1000
print(f"EACH {peak(resource.RUSAGE_SELF):.1f} {peak(resource.RUSAGE_CHILDREN):.1f} {rc}")
'''


def each_peak(argv: list[str], root: Path) -> tuple[float, float, int]:
    """(the command's own peak RSS, its output workers' largest [MB], exit status) of ``run argv`` in ``root``."""
    out = subprocess.run([sys.executable, "-c", EACH, *argv], cwd=root, env=child_env(root), capture_output=True, check=False,
                         text=True).stdout
    line = [x for x in out.splitlines() if x.startswith("EACH ")][-1].split()
    return float(line[1]), float(line[2]), int(line[3])


def child_env(root: Path) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(root) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def peak_of(argv: list[str], root: Path) -> tuple[float, int]:
    """(peak RSS [MB], exit status) of the command ``argv`` run in ``root`` (MB: 1000 kB, as the kbytes of
    ``/usr/bin/time -v`` are quoted in issue 11)."""
    proc = subprocess.Popen(argv, cwd=root, env=child_env(root), stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return usage.ru_maxrss / 1000, proc.returncode


def table_mb(path: Path) -> float:
    """A CSV written by ``write_csv`` as a float64 table [MB] (rows x columns x 8 bytes)."""
    if not path.exists():
        return 0.0
    with open(path, "rb") as f:
        columns = f.readline().count(b",") + 1
        rows = sum(1 for _ in f)
    return rows * columns * 8 / 1e6


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--revs", type=float, nargs="+", default=[2.0, 20.0])
    parser.add_argument("--root", type=Path, default=ROOT, help="the checkout to run (default this one)")
    parser.add_argument("--fmu", default="", help="the component FMU (default: the checkout's dist/)")
    parser.add_argument("--plots", action="store_true", help="with the plots (default --no-plots)")
    parser.add_argument("--phases", type=float, default=None, metavar="N",
                        help="the phases of one N-revolution run instead")
    parser.add_argument("--each", action="store_true",
                        help="also the command's own peak and its output workers' (largest) in a second run")
    parser.add_argument("extra", nargs="*", help="more arguments for `run` (after --)")
    args = parser.parse_args(argv)
    root = args.root.resolve()
    with tempfile.TemporaryDirectory(prefix="memory-") as tmp:
        if args.phases is not None:
            print(f"phases of a {args.phases:g}-revolution run ({root}):")
            extra = ([] if args.plots else ["--no-plots"]) + (["--fmu", args.fmu] if args.fmu else []) + args.extra
            return subprocess.call([sys.executable, "-c", PHASES, f"{args.phases:g}", tmp, *extra],
                                   cwd=root, env=child_env(root))
        peaks = []
        for revs in args.revs:
            out = Path(tmp) / f"r{revs:g}"
            cmd = [sys.executable, "-m", "mechanism", "run", "--revs", f"{revs:g}", "--quiet", "--out", str(out)]
            cmd += ([] if args.plots else ["--no-plots"]) + (["--fmu", args.fmu] if args.fmu else []) + args.extra
            peak, status = peak_of(cmd, root)
            data = table_mb(out / "timeseries.csv") + table_mb(out / "ideal_timeseries.csv")
            peaks.append((revs, peak, data))
            print(f"{revs:6g} revolutions: peak RSS {peak:7.1f} MB, data {data:6.1f} MB, peak less data "
                  f"{peak - data:7.1f} MB" + (f"  (exit status {status})" if status else ""), flush=True)
            if args.each:
                own, workers, status = each_peak(cmd[3:], root)
                print(f"{'':21s}the command {own:7.1f} MB, its output workers (largest) {workers:7.1f} MB"
                      + (f"  (exit status {status})" if status else ""), flush=True)
        if len(peaks) > 1 and peaks[-1][0] != peaks[0][0]:
            (r0, p0, d0), (r1, p1, d1) = peaks[0], peaks[-1]
            print(f"growth per revolution ({r0:g} -> {r1:g}): {(p1 - p0) / (r1 - r0):.2f} MB "
                  f"(the data's own: {(d1 - d0) / (r1 - r0):.2f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
