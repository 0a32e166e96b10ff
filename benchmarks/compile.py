"""The first run in a fresh numba cache (compiling every kernel) and a warm run after it (issue 11: first run
<= 15 s, warm headline <= 3 s).

For each setting of ``--env`` (``default``: as the environment is, without ``NUMBA_OPT``; or variables to set, e.g.
``NUMBA_OPT=2`` or ``MECHANISM_COMPILE_WORKER=0,NUMBA_OPT=2``), ``--repeat`` times, interleaved so that load
changes hit the settings alike: one
``python -m mechanism <command> --out <tmp>`` in a new empty ``NUMBA_CACHE_DIR`` (cold: it compiles), then the same
command again in that cache (warm: it loads). Prints the wall time and the CPU time (user + system, of the
child) of each, and the load average (this machine is shared: compare CPU times, and pairs from one run).

With ``--events`` the cold run records numba's compile events (``numba.core.event``) and prints the
functions that took longest to compile, exclusive of their callees, with the number of specialisations
compiled for each (more than one: argument types that differ between calls, e.g. a literal or an omitted
argument).

    python benchmarks/compile.py [--command "run --quiet --no-plots"] [--env default MECHANISM_COMPILE_WORKER=0]
                                 [--repeat 1] [--events] [--checkouts DIR [DIR ...]]

Runs against whatever ``mechanism`` is on the path (PYTHONPATH=<checkout>), or, with ``--checkouts``, against each
of those folders in turn (PYTHONPATH and working folder, e.g. a copy of an earlier commit with its dist/ FMUs),
interleaved with the settings. Each cold run's cache is counted: the compiled functions (numba's index files) and
their specialisations (the index entries), i.e. what a warm run may load.
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _child(out: str, argv: list[str]) -> None:
    """In the child: run the command with numba's compile events recorded into ``out`` (JSON)."""
    from numba.core import event

    stack: list[list] = []
    rows: list[tuple[str, float, str]] = []

    class Recorder(event.Listener):
        def on_start(self, ev):
            stack.append([time.perf_counter(), 0.0])

        def on_end(self, ev):
            start, callees = stack.pop()
            spent = time.perf_counter() - start
            if stack:
                stack[-1][1] += spent
            func = getattr(ev.data.get("dispatcher"), "py_func", None)
            name = f"{func.__module__}.{func.__qualname__}" if func else str(ev.data.get("dispatcher"))
            rows.append((name, spent - callees, str(ev.data.get("args"))))

    event.register("numba:compile", Recorder())
    from mechanism.cli import main
    try:
        main(argv)
    finally:
        Path(out).write_text(json.dumps(rows))


def timed(argv: list[str], env: dict[str, str], events: str | None = None,
          cwd: str | None = None) -> tuple[float, float, int]:
    """(wall s, child CPU s, exit status) of ``python -m mechanism argv`` (or the event-recording child)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    cmd = ([sys.executable, str(Path(__file__).resolve()), "--child", events, "--", *argv] if events
           else [sys.executable, "-m", "mechanism", *argv])
    start = time.perf_counter()
    status = subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, check=False, cwd=cwd).returncode
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, status


def cache_count(cache: str) -> tuple[int, int]:
    """(functions, specialisations) in a numba cache folder: its index files and their entries."""
    import pickle
    functions = entries = 0
    for index in Path(cache).rglob("*.nbi"):
        functions += 1
        try:
            with open(index, "rb") as f:
                pickle.load(f)                      # numba's version
                entries += len(pickle.loads(f.read())[1])   # (source stamp, {key: data file})
        except Exception:  # noqa: BLE001  (another numba's layout: count the function once)
            entries += 1
    return functions, entries


def report_events(path: str, top: int) -> None:
    rows = json.loads(Path(path).read_text())
    total: dict[str, float] = collections.defaultdict(float)
    count: collections.Counter = collections.Counter()
    for name, spent, _ in rows:
        total[name] += spent
        count[name] += 1
    print(f"    compile events: {len(rows)} compilations, {sum(total.values()):.1f} s exclusive in all; the top {top}:")
    for name, spent in sorted(total.items(), key=lambda kv: -kv[1])[:top]:
        print(f"    {spent:7.2f} s  x{count[name]:<3d} {name}")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--command", default="run --quiet --no-plots", help="the mechanism command line to time")
    p.add_argument("--env", nargs="+", default=["default"],
                   help="settings to compare: 'default' or NAME=VALUE[,NAME=VALUE...]")
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--events", action="store_true", help="record and print the cold run's compile events")
    p.add_argument("--top", type=int, default=25)
    p.add_argument("--checkouts", nargs="+", default=[None], help="folders to run (PYTHONPATH and working folder)")
    a = p.parse_args()
    print(f"load average {os.getloadavg()}")
    for r in range(a.repeat):
        for checkout in a.checkouts:
            for setting in a.env:
                with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as out:
                    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
                    env.pop("NUMBA_OPT", None)
                    if checkout is not None:
                        env["PYTHONPATH"] = str(Path(checkout).resolve())
                    if setting != "default":
                        env.update(item.split("=", 1) for item in setting.split(","))
                    argv = [*shlex.split(a.command), "--out", out]
                    events = str(Path(out) / "events.json") if a.events else None
                    cold = timed(argv, env, events, checkout)
                    functions, entries = cache_count(cache)
                    warm = timed(argv, env, None, checkout)
                    name = setting if checkout is None else f"{checkout} {setting}"
                    print(f"[{r + 1}] {name}: cold {cold[0]:6.1f} s wall, {cold[1]:6.1f} s CPU (exit {cold[2]}); "
                          f"warm {warm[0]:5.2f} s wall, {warm[1]:5.2f} s CPU (exit {warm[2]}); "
                          f"{functions} functions cached ({entries} specialisations); "
                          f"load {os.getloadavg()[0]:.1f}", flush=True)
                    if events:
                        report_events(events, a.top)
    return 0


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "--child":
        _child(sys.argv[2], sys.argv[4:])
        sys.exit(0)
    sys.exit(main())
