"""Resident-memory growth of long-lived hosts (issue 14): instantiate/free cycles and load/unload cycles.

    python benchmarks/fmu_memory.py [--fmu dist/BallBearing.fmu] [--fmu3 dist/BallBearing3.fmu]
                                    [--instances 1000] [--loads 200] [--runs 100]

* instantiate/free: one fmpy ``FMU2Slave`` (one loaded binary), ``instantiate``, initialise, a few
  ``doStep``s, ``terminate``, ``fmi2FreeInstance`` -- repeated (fmpy's ``freeInstance()`` would also
  unload the library);
* load/unload: a new ``FmuEndpoint`` each cycle (reads the FMU, loads its binary, instantiates,
  initialises, steps, closes) -- what a study or a service that runs many cases in one process does;
* master runs: ``mechanism.run.run`` of a short slider-crank co-simulation with the FMU (``FmuEndpoint``),
  as the issue's "100 master runs" (no target of its own; 0 skips it);
* FMI 3.0 (``--fmu3``, the BallBearing3 FMU; ``--fmu3 ''`` skips it): instantiate/free with fmpy's
  ``FMU3Slave`` (``fmi3FreeInstance``) and load/unload with ``Fmu3Endpoint``, same counts and targets.

Each phase warms up for a few cycles first (Python's and the allocator's first-use growth is not a
leak), then prints the resident set size before and after, the growth and the growth per cycle. The
targets of issue 14 are <= 5 MB for 1,000 instantiate/free cycles and <= 10 MB for 200 load/unload
cycles; ``tests/test_fuzz.py::test_memory_growth_of_a_long_lived_host`` asserts both (``..._fmi3`` for
the FMI 3.0 FMU).

Measured (2 shared cores, one run each, ``--fmu`` the FMU before and after the slave shim of issue 14):
before, 593 kB per instantiate/free cycle (580 MB for 1,000), 602 kB per load/unload cycle (117 MB for
200), 610 kB per master run (60 MB for 100); after, 1.9 kB, 3.0 kB and 10.7 kB (1.9 MB, 0.6 MB, 1.0 MB).
What is left per instance is pythonfmu 0.7's: its class search keeps a list of the slave class's MRO and
a few strings (docs/robustness.md, Memory).

FMI 3.0 (``--fmu '' --fmu3`` before and after the FMI 3.0 shim, ``build_fmu.SHIM3``): before, 19.9 kB per
instantiate/free cycle (19.5 MB for 1,000; a climb of about 25 MB over the first 150 cycles, then about
4-5 kB per cycle); after, 0.8 kB (0.8 MB). Load/unload (``Fmu3Endpoint``, 200): before 2.8 kB, after 9.2 kB
per cycle, a one-off (1,000 cycles: 1.9 MB as well). What grew was the fresh import of the FMU's modules
after every last free; pythonfmu3 itself keeps nothing per instance.
"""
from __future__ import annotations

import argparse
import gc
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

INPUTS = (1.2e-5, -0.4e-5, 1e-3, 0.0, 125.0, 0.0)


def rss_mb() -> float:
    """Resident set size of this process [MB] (Linux /proc)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def instantiate_free(fmu: Path, cycles: int, warmup: int = 20) -> tuple[float, float]:
    """(RSS before, RSS after) ``cycles`` instantiate/initialise/step/free cycles on one loaded binary."""
    from fmpy.fmi2 import FMU2Slave
    slave, vr, inputs = _loaded(fmu, FMU2Slave)

    def cycle():
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.setReal(inputs, list(INPUTS))
        slave.exitInitializationMode()
        for k in range(3):
            slave.doStep(k * 1e-5, 1e-5)
        slave.getReal([vr["F_x"], vr["F_y"]])
        slave.terminate()
        slave.fmi2FreeInstance(slave.component)   # fmpy's freeInstance() would also unload the library

    return _measure(cycle, cycles, warmup)


def _loaded(fmu: Path, slave_class):
    """(an fmpy ``slave_class`` instance on the FMU's shared extraction, {name: value reference}, the input
    value references): one loaded binary for the instantiate/free cycles."""
    from fmpy import read_model_description

    from mechanism.cosim.endpoints import shared_extraction
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    inputs = [vr[n] for n in ("e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer")]
    slave = slave_class(guid=md.guid, unzipDirectory=shared_extraction(fmu, md.guid),
                        modelIdentifier=md.coSimulation.modelIdentifier, instanceName="memory")
    return slave, vr, inputs


def instantiate_free3(fmu: Path, cycles: int, warmup: int = 20) -> tuple[float, float]:
    """``instantiate_free`` for an FMI 3.0 FMU (BallBearing3): fmpy's ``FMU3Slave``, ``fmi3FreeInstance``."""
    from fmpy.fmi3 import FMU3Slave
    slave, vr, inputs = _loaded(fmu, FMU3Slave)

    def cycle():
        slave.instantiate()
        slave.enterInitializationMode()
        slave.setFloat64(inputs, list(INPUTS))
        slave.exitInitializationMode()
        for k in range(3):
            slave.doStep(k * 1e-5, 1e-5)
        slave.getFloat64([vr["F_x"], vr["F_y"]])
        slave.terminate()
        slave.fmi3FreeInstance(slave.component)   # fmpy's freeInstance() would also unload the library

    return _measure(cycle, cycles, warmup)


def load_unload3(fmu: Path, cycles: int, warmup: int = 10) -> tuple[float, float]:
    """``load_unload`` for an FMI 3.0 FMU: a new ``Fmu3Endpoint`` each cycle."""
    from mechanism.cosim.endpoints import Fmu3Endpoint
    return load_unload(fmu, cycles, warmup, Fmu3Endpoint)


def _measure(cycle, cycles: int, warmup: int) -> tuple[float, float]:
    """(RSS before, RSS after) ``cycles`` calls of ``cycle``, after ``warmup`` calls."""
    for _ in range(warmup):
        cycle()
    gc.collect()
    before = rss_mb()
    for _ in range(cycles):
        cycle()
    gc.collect()
    return before, rss_mb()


def load_unload(fmu: Path, cycles: int, warmup: int = 10, endpoint_class=None) -> tuple[float, float]:
    """(RSS before, RSS after) ``cycles`` FmuEndpoint (or ``endpoint_class``) create/initialise/step/close
    cycles."""
    from mechanism.cosim.endpoints import FmuEndpoint
    endpoint_class = endpoint_class or FmuEndpoint

    def cycle():
        endpoint = endpoint_class(fmu, {"n_balls": 8})
        try:
            endpoint.initialize(INPUTS)
            for k in range(3):
                endpoint.exchange(k * 1e-5, 1e-5, INPUTS)
        finally:
            endpoint.close()

    return _measure(cycle, cycles, warmup)


def master_runs(fmu: Path, cycles: int, warmup: int = 5) -> tuple[float, float]:
    """(RSS before, RSS after) ``cycles`` slider-crank co-simulations (0.05 revolutions) with the FMU."""
    from mechanism.run import RunConfig, run

    def cycle():
        result = run(RunConfig(revs=0.05, progress=False, fmu=str(fmu)))
        if result.status != "completed":
            raise RuntimeError(f"master run {result.status}: {result.message}")

    for _ in range(warmup):
        cycle()
    gc.collect()
    before = rss_mb()
    for _ in range(cycles):
        cycle()
    gc.collect()
    return before, rss_mb()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fmu", default="dist/BallBearing.fmu", help="FMI 2.0 FMU ('': skip its phases)")
    parser.add_argument("--fmu3", default="dist/BallBearing3.fmu", help="FMI 3.0 FMU ('': skip its phases)")
    parser.add_argument("--instances", type=int, default=1000)
    parser.add_argument("--loads", type=int, default=200)
    parser.add_argument("--runs", type=int, default=100, help="master runs (0: skip)")
    args = parser.parse_args()
    fmu = Path(args.fmu)
    phases = [("instantiate/free", instantiate_free, fmu, args.instances, 5.0),
              ("load/unload (FmuEndpoint)", load_unload, fmu, args.loads, 10.0),
              ("master runs (FmuEndpoint)", master_runs, fmu, args.runs, None)] if args.fmu else []
    if args.fmu3:
        phases += [("FMI 3.0 instantiate/free", instantiate_free3, Path(args.fmu3), args.instances, 5.0),
                   ("FMI 3.0 load/unload (Fmu3Endpoint)", load_unload3, Path(args.fmu3), args.loads, 10.0)]
    for label, func, path, n, target in phases:
        if n <= 0:
            continue
        before, after = func(path, n)
        growth = after - before
        verdict = ("no target" if target is None
                   else f"target <= {target:g} MB: {'met' if growth <= target else 'NOT met'}")
        print(f"{label}: {n} cycles, RSS {before:.1f} -> {after:.1f} MB, growth {growth:.2f} MB "
              f"({growth * 1024 / n:.1f} kB per cycle; {verdict})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
