"""Benchmark: the whole ``python -m mechanism reproduce`` from an empty cache.

    python benchmarks/reproduce.py [--out DIR] [--workers N] [--revs R]

Prints the wall time of every run (measured inside its worker), the elapsed time of the runs,
of the report and the total, and writes them to DIR/benchmark.json. DIR defaults to a
temporary folder that is deleted afterwards; a given DIR has its cache/ and fmu/ emptied first.
Target: <= 60 s on a 2-core machine with the paper's 15 runs at 1e-5 s.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from mechanism.studies.reproduce import reproduce, run_specs  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None, help="output folder (default: a temporary folder)")
    parser.add_argument("--workers", type=int, default=None, help="parallel runs (default: the number of cores)")
    parser.add_argument("--revs", type=float, default=2.0, help="crank revolutions per run (default 2)")
    args = parser.parse_args(argv)
    tmp = None
    if args.out is None:
        tmp = tempfile.mkdtemp(prefix="reproduce_bench_")
        out = Path(tmp)
    else:
        out = Path(args.out)
        for sub in ("cache", "fmu"):
            shutil.rmtree(out / sub, ignore_errors=True)
    try:
        specs = run_specs(args.revs)
        t0 = time.perf_counter()
        outcome = reproduce(out, workers=args.workers, revs=args.revs, progress=False)
        total = time.perf_counter() - t0
        report_s = total - outcome["elapsed_s"]
        rows = []
        print(f"{'run':<24} {'status':<10} {'steps':>7} {'wall [s]':>9} {'µs/step':>8}")
        for s in specs:
            info = outcome["infos"][s.name]
            steps = int(round(s.config.revs * s.config.crank_period / s.config.step))
            wall = float(info.get("wall_time_s", float("nan")))
            rows.append({"run": s.name, "status": info["status"], "steps": steps, "wall_s": wall})
            print(f"{s.name:<24} {info['status']:<10} {steps:>7} {wall:>9.2f} {wall / steps * 1e6:>8.1f}")
        cpu = sum(r["wall_s"] for r in rows)
        print(f"sum of run times     {cpu:8.1f} s ({sum(r['steps'] for r in rows)} steps)")
        print(f"runs elapsed         {outcome['elapsed_s']:8.1f} s on {outcome['workers']} worker(s) "
              f"(incl. building the FMUs)")
        print(f"report (figures)     {report_s:8.1f} s")
        print(f"total                {total:8.1f} s  (target <= 60 s)")
        load = os.getloadavg() if hasattr(os, "getloadavg") else None
        record = {"runs": rows, "sum_run_s": cpu, "runs_elapsed_s": outcome["elapsed_s"], "report_s": report_s,
                  "total_s": total, "workers": outcome["workers"], "cpu_count": os.cpu_count(),
                  "load_average_after": load, "python": platform.python_version(), "revs": args.revs,
                  "date": time.strftime("%Y-%m-%d %H:%M:%S")}
        if load:
            print(f"load average after   {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} core(s)")
        (out / "benchmark.json").write_text(json.dumps(record, indent=2) + "\n")
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
