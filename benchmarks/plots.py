"""The cost of the reproduction report's figures (issue 11).

Prints, measured in one run, each variant interleaved ``--repeat`` times (the machine is shared: read the ratios):

* the report of ``python -m mechanism reproduce --out DIR`` built from DIR's cached runs (run the command once
  first): every figure drawn in-process, drawn in forked processes (``drawing.FigureFiles``, the default),
  and not drawn again because its inputs did not change (what ``reproduce --force`` does when the runs come
  out the same); wall seconds, this process's CPU and its children's CPU.

Forked drawing pays (wall) only where a second core is free; it costs some CPU (each child's text caches are
its own).

    python benchmarks/plots.py --reproduce DIR [--repeat 3]

Runs against whatever ``mechanism`` is on the path (PYTHONPATH=<checkout>).
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from pathlib import Path


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
    parser.add_argument("--reproduce", required=True,
                        help="output folder of `python -m mechanism reproduce` (its cached runs are used)")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
