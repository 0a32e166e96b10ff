"""Co-simulation cost: two crank revolutions at 1200 rpm at the default step (issue 3).

Prints, measured in one run (ratios matter; this machine is shared and noisy):
wall time of `cosim` (BallBearing.fmu through fmpy) and of the same master with the force
law in-process (same scheme, same step) and their ratio; µs per communication step of the
master alone and of the component exchange; the monolithic reference's wall time.

    python benchmarks/cosim.py [--revs 2] [--rpm 1200] [--step 1e-5]
"""
from __future__ import annotations

import argparse
import time

from mechanism import run as run_module
from mechanism.cosim.endpoints import FmuEndpoint, InProcessEndpoint
from mechanism.run import RunConfig, run


def timed_exchange(cls):
    """Subclass whose exchange() accumulates its own wall time."""

    class Timed(cls):
        exchange_seconds = 0.0

        def exchange(self, t, h, inputs):
            t0 = time.perf_counter()
            try:
                return super().exchange(t, h, inputs)
            finally:
                type(self).exchange_seconds += time.perf_counter() - t0
    return Timed


def measure(config: RunConfig, endpoint_cls, name: str) -> tuple[float, float, int]:
    timed = timed_exchange(endpoint_cls)
    setattr(run_module, name, timed)
    try:
        t0 = time.perf_counter()
        result = run(config)
        wall = time.perf_counter() - t0
    finally:
        setattr(run_module, name, endpoint_cls)
    assert result.ok, result.message
    return wall, timed.exchange_seconds, result.meta["component_calls"]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--revs", type=float, default=2.0)
    p.add_argument("--rpm", type=float, default=1200.0)
    p.add_argument("--step", type=float, default=1e-5)
    a = p.parse_args()
    base = RunConfig(rpm=a.rpm, revs=a.revs, step=a.step, progress=False)
    run_module.fmu_path(base)  # build the FMU before timing
    print(f"{a.revs:g} revolutions at {a.rpm:g} rpm, step {a.step:g} s, scheme {base.scheme}")
    cos_wall, cos_ex, calls = measure(base, FmuEndpoint, "FmuEndpoint")
    inp_wall, inp_ex, _ = measure(RunConfig(**{**base.__dict__, "mode": "inprocess"}), InProcessEndpoint,
                                  "InProcessEndpoint")
    t0 = time.perf_counter()
    mono = run(RunConfig(**{**base.__dict__, "mode": "monolithic"}))
    mono_wall = time.perf_counter() - t0
    print(f"cosim (FMU via fmpy)        {cos_wall:7.2f} s   ({calls} communication steps)")
    print(f"in-process (same master)    {inp_wall:7.2f} s")
    print(f"ratio cosim / in-process    {cos_wall / inp_wall:7.2f}")
    print(f"master alone per step       {1e6 * (inp_wall - inp_ex) / calls:7.1f} µs")
    print(f"FMU exchange per step       {1e6 * cos_ex / calls:7.1f} µs (set 6 inputs, doStep, get 8 outputs)")
    print(f"in-process law per step     {1e6 * inp_ex / calls:7.1f} µs")
    print(f"monolithic reference        {mono_wall:7.2f} s   ({mono.meta['method']}, rtol {mono.meta['rtol']:g}, "
          f"{mono.meta['rhs_calls']} right-hand sides)")


if __name__ == "__main__":
    main()
