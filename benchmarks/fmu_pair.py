"""Exchange cost of two builds of the BallBearing FMU in ONE process, interleaved: a before/after comparison
that holds on a loaded machine.

    python benchmarks/fmu_pair.py OLD.fmu NEW.fmu [--repeat 150] [--calls 500]

One exchange = fmi2SetReal of the 6 inputs, fmi2DoStep, fmi2GetReal of F_x, F_y through fmpy's fmi2* wrappers
with prebuilt ctypes arrays (what the master does). The two FMUs run side by side in this process (possible
since the builds are sealed under private module names, issue 13; an FMU built before that may only be
paired with a sealed one). Each repeat times ``--calls`` exchanges of OLD, then of NEW; printed are min and
median per exchange [us] and the median of the per-repeat ratios NEW/OLD (pairing cancels load drift).
"""
from __future__ import annotations

import argparse
import ctypes
import math
import statistics
import sys
import tempfile
import time

INPUTS = ("e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer")
STATES = [(3e-5 * math.cos(a), 3e-5 * math.sin(a), -0.01 * math.sin(a), 0.01 * math.cos(a), 100.0, 0.0)
          for a in (2 * math.pi * k / 64 for k in range(64))]


def exchange(path: str, name: str):
    """An initialised instance of the FMU at ``path`` and a function running n exchanges with it."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path, unzipdir=tempfile.mkdtemp()),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    vr_in = (ctypes.c_uint * 6)(*[vr[n] for n in INPUTS])
    vr_out = (ctypes.c_uint * 2)(vr["F_x"], vr["F_y"])
    val_in, val_out = (ctypes.c_double * 6)(), (ctypes.c_double * 2)()
    comp, set_real, do_step, get_real = fmu.component, fmu.fmi2SetReal, fmu.fmi2DoStep, fmu.fmi2GetReal

    def run(n: int) -> None:
        for i in range(n):
            val_in[0], val_in[1], val_in[2], val_in[3], val_in[4], val_in[5] = STATES[i % 64]
            set_real(comp, vr_in, 6, val_in)
            do_step(comp, i * 1e-5, 1e-5, 1)
            get_real(comp, vr_out, 2, val_out)
    return fmu, run


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old")
    parser.add_argument("new")
    parser.add_argument("--repeat", type=int, default=150)
    parser.add_argument("--calls", type=int, default=500)
    args = parser.parse_args(argv)
    fmus, runs = zip(exchange(args.old, "old"), exchange(args.new, "new"))
    times = ([], [])
    for _ in range(args.repeat):
        for run, t in zip(runs, times):
            t0 = time.perf_counter()
            run(args.calls)
            t.append((time.perf_counter() - t0) / args.calls * 1e6)
    for label, t in zip(("old", "new"), times):
        print(f"{label}: min {min(t):.2f} us, median {statistics.median(t):.2f} us per exchange")
    print(f"new/old: median of paired ratios {statistics.median(y / x for x, y in zip(*times)):.3f} "
          f"({args.repeat} x {args.calls} exchanges each)")
    for fmu in fmus:
        fmu.terminate()
        fmu.freeInstance()
    return 0


if __name__ == "__main__":
    sys.exit(main())
