"""The cost of the figures (issue 11): the reproduction's report and the headline run's seven PNGs.

Prints, measured in one run, each variant interleaved ``--repeat`` times (the machine is shared: read the ratios):

* the report of ``python -m mechanism reproduce --out DIR`` built from DIR's cached runs (run the command once
  first): every figure drawn in-process, drawn in forked processes (``drawing.FigureFiles``, the default),
  and not drawn again because its inputs did not change (what ``reproduce --force`` does when the runs come
  out the same); wall seconds, this process's CPU and its children's CPU;
* the seven PNGs of ``python -m mechanism run --out RUN`` (run it once first) drawn from RUN's CSV files by a
  fresh process, with and without ``plots.warm_up`` before (what an output worker does while the run runs):
  the first ``plot_run``'s CPU seconds.

    python benchmarks/plots.py --reproduce DIR --run RUN [--repeat 3]

Runs against whatever ``mechanism`` is on the path (PYTHONPATH=<checkout>).
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: a fresh process that draws RUN's figures once (after ``plots.warm_up`` if asked) and prints its CPU seconds
FIRST_PLOT = """
import json, sys, time
from mechanism.output import plots
from mechanism.output.results import read_csv
run, out, warm = sys.argv[1], sys.argv[2], sys.argv[3] == "warm"
r, i = read_csv(f"{run}/timeseries.csv"), read_csv(f"{run}/ideal_timeseries.csv")
r.meta.update(json.load(open(f"{run}/summary.json"))["meta"])
if warm:
    plots.warm_up()
t = time.process_time()
plots.plot_run(r, out, i)
print(time.process_time() - t)
"""


def report_once(folder: Path, specs, outcome, variant: str) -> dict:
    """Build the report once: ``variant`` "in-process", "forked" or "skipped" (the figures' key left in place)."""
    from mechanism.studies.reproduce import drawing
    from mechanism.studies.reproduce.report import Report
    key = folder / "report" / "figures" / drawing.KEY_FILE
    if variant != "skipped":
        key.unlink(missing_ok=True)
    processes = 0 if variant == "in-process" else None
    original = drawing.FigureFiles.__init__

    def init(self, fig_folder, fig_key, _processes=None):
        original(self, fig_folder, fig_key, processes)

    drawing.FigureFiles.__init__ = init
    try:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu0, wall0 = time.process_time(), time.perf_counter()
        Report(folder, specs, outcome).build()
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    finally:
        drawing.FigureFiles.__init__ = original
    children = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu, "children_cpu_s": children}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--reproduce", help="output folder of `python -m mechanism reproduce` (its cache is used)")
    parser.add_argument("--run", help="output folder of `python -m mechanism run`")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    if args.reproduce:
        from mechanism.studies.reproduce.cases import run_specs
        from mechanism.studies.reproduce.runs import run_all
        folder = Path(args.reproduce)
        specs = run_specs(2.0)
        outcome = run_all(folder, specs, progress=False)
        if outcome["computed"]:
            print(f"(computed {len(outcome['computed'])} runs missing from {folder}/cache first)")
        outcome["specs"] = specs
        variants = ("in-process", "forked", "skipped")
        rows = {v: [] for v in variants}
        for _ in range(args.repeat):
            for v in variants:
                rows[v].append(report_once(folder, specs, outcome, v))
        print(f"report of {len(outcome['results'])} runs, median of {args.repeat} (interleaved), {os.cpu_count()} CPUs")
        print(f"{'figures':<12} {'wall [s]':>9} {'CPU [s]':>8} {'children CPU [s]':>17} {'wall / in-process':>18}")
        base = [r["wall_s"] for r in rows["in-process"]]
        for v in variants:
            med = {k: statistics.median(r[k] for r in rows[v]) for k in rows[v][0]}
            ratio = statistics.median(r["wall_s"] / b for r, b in zip(rows[v], base))
            print(f"{v:<12} {med['wall_s']:>9.2f} {med['cpu_s']:>8.2f} {med['children_cpu_s']:>17.2f} {ratio:>18.2f}")
    if args.run:
        env = dict(os.environ, MPLBACKEND="Agg")
        times = {"cold": [], "warm": []}
        with tempfile.TemporaryDirectory() as out:
            for _ in range(args.repeat):
                for v, values in times.items():
                    done = subprocess.run([sys.executable, "-c", FIRST_PLOT, args.run, out, v], env=env,
                                          capture_output=True, text=True, check=True)
                    values.append(float(done.stdout.split()[-1]))
        cold, warm = statistics.median(times["cold"]), statistics.median(times["warm"])
        print(f"first plot_run of {args.run} (7 PNGs) in a fresh process, CPU median of {args.repeat}: "
              f"{cold:.2f} s without warm-up, {warm:.2f} s after plots.warm_up "
              f"(ratio {statistics.median(w / c for w, c in zip(times['warm'], times['cold'])):.2f})")
    if not (args.reproduce or args.run):
        parser.error("give --reproduce DIR and/or --run RUN")
    return 0


if __name__ == "__main__":
    sys.exit(main())
