"""Exit status of native-host processes that run the BallBearing FMU (issue 13: no crash at process exit).

    python benchmarks/native_exit.py [--fmu dist/BallBearing.fmu] [--runs 200] [--steps 200] [--jobs 2]
                                     [--pythonfmu-binary]

Each run is one process of the native C host (fmu_bearing/native/host.c) with a clean environment (no
LD_PRELOAD, no PYTHONPATH): "1 instance" steps one instance from the main thread, "4 threads" steps four
instances, each from its own thread at the same time; both free everything and return from main. Prints
the count of exit statuses per case. ``--pythonfmu-binary`` runs pythonfmu's own binary instead of the
loader (the "before" of issue 13), with libpython preloaded since it cannot find it itself.
"""
from __future__ import annotations

import argparse
import collections
import sys
import tempfile
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from tqdm import tqdm

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fmu_bearing.native.host import clean_env, compile_host, run_host  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu", default=str(ROOT / "dist" / "BallBearing.fmu"))
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--jobs", type=int, default=2, help="processes at a time")
    parser.add_argument("--pythonfmu-binary", action="store_true",
                        help="pythonfmu's binary alone (LD_PRELOAD of libpython), for comparison")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        unzipdir = Path(tmp) / "fmu"
        with zipfile.ZipFile(args.fmu) as z:
            z.extractall(unzipdir)
        host = compile_host(tmp)
        env = clean_env()
        label = "loader"
        if args.pythonfmu_binary:
            import sysconfig
            binaries = unzipdir / "binaries" / "linux64"
            for original in binaries.glob("*_pythonfmu.so"):
                original.replace(binaries / original.name.replace("_pythonfmu", ""))
            libpython = Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("INSTSONAME")
            env = clean_env(LD_PRELOAD=str(libpython))
            label = f"pythonfmu binary, LD_PRELOAD={libpython.name}"
        cases = {"1 instance": (1, "seq"), "4 threads": (4, "threads")}
        print(f"{args.runs} native-host processes per case, {args.steps} steps per instance ({label})")
        for name, (n, mode) in cases.items():
            with ThreadPoolExecutor(args.jobs) as pool:
                runs = list(tqdm(pool.map(lambda _: run_host(host, unzipdir, n, args.steps, mode, env=env),
                                          range(args.runs)), total=args.runs, desc=name, leave=False))
            counts = collections.Counter(r.returncode for r in runs)
            complete = sum(len(r.forces) == n and all(f[0] != 0.0 for f in r.forces) for r in runs)
            print(f"  {name:<11} exit status counts {dict(sorted(counts.items()))}; "
                  f"runs with results for every instance: {complete}/{args.runs}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
