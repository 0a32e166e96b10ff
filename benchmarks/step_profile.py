"""Where the compiled communication step's time goes, per kernel (Linux ``perf``; issue 11).

Samples one run (``--mode`` cosim or inprocess, ``--scheme``, ``--revs`` at 1200 rpm and 1e-5 s, warm kernels) with
``perf record -e cpu-clock`` and prints the time of each function in µs per communication step: the compiled
kernels, the C library's functions they call (sin/cos, pow, memset), numba's runtime, the FMU's own code, the
interpreter around the loop, the OS kernel as one line; perf's sampled CPU time of the function over the run's
steps, exclusive of the functions it calls. numba's machine code has no symbols perf can see, so the run writes perf's map
file (``/tmp/perf-<pid>.map``, removed after the report) of every function numba's JIT engine holds before it
exits; a kernel that LLVM inlined into its caller is counted in the caller, and the specialisations of one function
are counted together.

    python benchmarks/step_profile.py [--mode inprocess] [--scheme law-model] [--revs 10] [--top 30]

Only the measured run is sampled (``perf record -D -1`` and its control FIFO: the imports and the short run that
loads, or on a first run compiles, the kernels are not); the rest of the run's CPU time (its Python set-up, the
recording) is in the total. Sampling adds a few per cent; compare the shares, and measure speed with
``benchmarks/cosim.py``.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _perf(ctl, ack, command: str) -> None:
    """Tell ``perf record`` (its control FIFO) to start or stop sampling, and wait for its acknowledgement."""
    ctl.write(command + "\n")
    ctl.flush()
    ack.readline()


def _child(out: str, fifos: str, mode: str, scheme: str | None, revs: float) -> None:
    """In the sampled process: a short run (loads or compiles the kernels), the measured run (the only one
    sampled), then perf's map of numba's code."""
    from numba.core.registry import cpu_target

    from mechanism.run import RunConfig, run
    kw = {"mode": mode, **({"scheme": scheme} if scheme else {})}
    run(RunConfig(rpm=1200.0, revs=0.01, step=1e-5, output_interval=1e-5, progress=False, **kw))
    config = RunConfig(rpm=1200.0, revs=revs, step=1e-5, output_interval=1e-5, progress=False, **kw)
    ctl_path, ack_path = fifos.split(",")
    with open(ctl_path, "w") as ctl, open(ack_path) as ack:
        _perf(ctl, ack, "enable")
        t0 = time.perf_counter()
        result = run(config)
        wall = time.perf_counter() - t0
        _perf(ctl, ack, "disable")
    engine = cpu_target.target_context.codegen()._engine     # numba's JIT engine: every function it loaded
    addresses = {}
    for name in list(engine._defined_symbols):
        address = engine.get_function_address(name)
        if address:
            addresses[address] = name
    ordered = sorted(addresses)
    with open(f"/tmp/perf-{os.getpid()}.map", "w") as f:
        for i, a in enumerate(ordered):        # a function's size: up to the next one (perf needs one)
            size = min(ordered[i + 1] - a if i + 1 < len(ordered) else 4096, 1 << 20)
            f.write(f"{a:x} {size:x} {addresses[a]}\n")
    steps = round(revs * config.crank_period / config.step)
    Path(out).write_text(json.dumps({"steps": steps, "wall": wall, "ok": result.ok, "scheme": config.scheme,
                                     "pid": os.getpid()}))


_COMPONENT = re.compile(r"(\d+)")


def _unescape(m: re.Match) -> str:
    """numba's escape ``_xx`` of a character not allowed in a name (``_3c`` for ``<``); ``_ad`` in ``_add`` is none."""
    c = chr(int(m.group(1), 16))
    return c if " " <= c <= "~" and not (c.isalnum() or c == "_") else m.group(0)


def python_name(symbol: str) -> str:
    """numba's mangled name (``_ZN9mechanism5cosim10law_kernel8evaluateB..E...``) as ``mechanism.cosim.law_kernel.
    evaluate``; other symbols as they are."""
    if not symbol.startswith("_ZN"):
        return symbol
    parts, i = [], 3
    while i < len(symbol) and symbol[i].isdigit():
        n = _COMPONENT.match(symbol, i)
        length = int(n.group(1))
        i = n.end()
        parts.append(symbol[i:i + length])
        i += length
    prefix = "cpython wrapper of " if parts and parts[0] == "cpython" else ""
    parts = parts[1:] if prefix else parts
    name = ".".join(re.sub(r"_([0-9a-f]{2})", _unescape, p) for p in parts)
    return prefix + name if name else symbol


def report(data: str) -> list[tuple[float, str, str]]:
    """(sampled ns of cpu-clock, shared object, symbol) of each symbol in perf's report of ``data``, largest
    first."""
    text = subprocess.run(["perf", "report", "-i", data, "--stdio", "--no-children", "--no-demangle", "--sort",
                           "dso,sym", "--show-total-period"], check=True, capture_output=True, text=True).stdout
    rows = []
    for line in text.splitlines():
        m = re.match(r"\s*[\d.]+%\s+(\d+)\s+(.+?)\s+\[(\S)\]\s+(\S+)", line)   # a dso may hold spaces
        if m:
            rows.append((float(m.group(1)), m.group(2), m.group(4) if m.group(3) == "." else "[kernel]"))
    return rows




def _numba(dso: str, symbol: str) -> bool:
    """A function of numba's machine code: perf found it through the map (not a C++ symbol of numpy's or LLVM's)."""
    return symbol.startswith("_ZN") and (dso.startswith("perf-") or dso.startswith("[JIT]"))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--mode", choices=("cosim", "inprocess"), default="inprocess")
    p.add_argument("--scheme", default=None, help="coupling scheme (default: the run's default)")
    p.add_argument("--revs", type=float, default=10.0)
    p.add_argument("--top", type=int, default=30)
    p.add_argument("--child", default=None, help=argparse.SUPPRESS)
    p.add_argument("--fifos", default=None, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.child:
        _child(a.child, a.fifos, a.mode, a.scheme, a.revs)
        return 0
    if shutil.which("perf") is None:
        print("error: Linux perf is not installed (apt-get install linux-perf)", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        data, out = str(Path(tmp) / "perf.data"), str(Path(tmp) / "run.json")
        ctl, ack = str(Path(tmp) / "ctl"), str(Path(tmp) / "ack")
        os.mkfifo(ctl)
        os.mkfifo(ack)
        cmd = ["perf", "record", "-q", "-e", "cpu-clock", "-D", "-1", f"--control=fifo:{ctl},{ack}", "-o", data, "--",
               sys.executable, str(Path(__file__).resolve()), "--child", out, "--fifos", f"{ctl},{ack}",
               "--mode", a.mode, "--revs", str(a.revs), *(["--scheme", a.scheme] if a.scheme else [])]
        done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if done.returncode != 0 or not Path(out).exists():
            print(f"error: the sampled run failed ({done.returncode}): {done.stderr.strip()[-300:]}", file=sys.stderr)
            return 1
        run = json.loads(Path(out).read_text())
        try:
            rows = report(data)
        finally:
            Path(f"/tmp/perf-{run['pid']}.map").unlink(missing_ok=True)
    if not run["ok"]:
        print("error: the sampled run did not complete", file=sys.stderr)
        return 1
    steps = run["steps"]
    total = sum(ns for ns, _, _ in rows)
    merged: dict[str, float] = {}          # the specialisations of one function together; the OS kernel as one
    for ns, dso, symbol in rows:
        name = python_name(symbol) if _numba(dso, symbol) else symbol
        merged[name] = merged.get(name, 0.0) + ns
    ranked = sorted(((ns, name) for name, ns in merged.items()), reverse=True)
    numba = sum(ns for ns, dso, symbol in rows if _numba(dso, symbol))
    print(f"{a.mode} run, scheme {run['scheme']}, {a.revs:g} revolutions ({steps} steps): {run['wall'] * 1e6 / steps:.1f} µs "
          f"per step by the wall clock while sampled, {total / 1e3 / steps:.1f} µs of CPU sampled per step, of which "
          f"{numba / 1e3 / steps:.1f} µs in numba's machine code (the rest: the C functions it calls, the interpreter "
          f"around the loop, the OS)")
    for ns, name in ranked[:a.top]:
        print(f"{ns / 1e3 / steps:8.3f} µs/step  {ns / total:6.1%}  {name}")
    rest = sum(ns for ns, _ in ranked[a.top:])
    if rest:
        print(f"{rest / 1e3 / steps:8.3f} µs/step  {rest / total:6.1%}  the other {len(ranked) - a.top} symbols")
    return 0


if __name__ == "__main__":
    sys.exit(main())
