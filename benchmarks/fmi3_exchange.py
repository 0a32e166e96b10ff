"""Cost of one master exchange with the FMI 3.0 BallBearing3 FMU against the FMI 2.0 BallBearing FMU.

    python benchmarks/fmi3_exchange.py [--calls 3000] [--repeat 7]

One exchange is what the master does every communication step through its endpoint
(``mechanism.cosim.endpoints``): set the 6 inputs, doStep, get the 8 coupling outputs, each with prebuilt
ctypes arrays (``FmuEndpoint`` through fmpy's FMU2Slave, ``Fmu3Endpoint`` through FMU3Slave), plus one
``sample()`` (all other outputs; for FMI 3.0 the ``ball_loads`` array). Both FMUs run the same physics, so
the difference is pythonfmu vs pythonfmu3 and fmpy's FMI 2 vs FMI 3 wrappers. The two are measured
alternately in one run; every figure is the median over ``--repeat`` runs of ``--calls`` calls, in
microseconds per call, and the ratio FMI 3 / FMI 2 is printed.
"""
from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def states(n=64):
    """Representative loaded inputs: |e| = 30 um (3 of 8 balls loaded) turning, small v, 100 rad/s."""
    return [(3e-5 * math.cos(2 * math.pi * k / n), 3e-5 * math.sin(2 * math.pi * k / n),
             -0.01 * math.sin(2 * math.pi * k / n), 0.01 * math.cos(2 * math.pi * k / n), 100.0, 0.0)
            for k in range(n)]


def per_call_us(endpoint, calls: int, what: str) -> float:
    inputs = states()
    t0 = time.perf_counter()
    if what == "exchange":
        for k in range(calls):
            endpoint.exchange(k * 1e-5, 1e-5, inputs[k % len(inputs)])
    else:
        for _ in range(calls):
            endpoint.sample()
    return (time.perf_counter() - t0) / calls * 1e6


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=3000)
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args(argv)

    import build_fmu
    from mechanism.cosim.endpoints import fmu_endpoint

    with tempfile.TemporaryDirectory() as tmp:
        paths = build_fmu.build(tmp, names=["BallBearing", "BallBearing3"], verbose=False)
        endpoints = {name: fmu_endpoint(paths[name]) for name in ("BallBearing", "BallBearing3")}
        try:
            for ep in endpoints.values():
                ep.initialize(states()[0])
            times = {(name, what): [] for name in endpoints for what in ("exchange", "sample")}
            for _ in range(args.repeat):
                for name, ep in endpoints.items():   # alternate: both see the same machine load
                    for what in ("exchange", "sample"):
                        times[name, what].append(per_call_us(ep, args.calls, what))
        finally:
            for ep in endpoints.values():
                ep.close()
    median = {key: statistics.median(v) for key, v in times.items()}
    print(f"median of {args.repeat} x {args.calls} calls, us per call")
    print(f"{'':28s}{'FMI 2.0 (BallBearing)':>24s}{'FMI 3.0 (BallBearing3)':>24s}{'ratio 3/2':>11s}")
    for what, label in (("exchange", "exchange (set, doStep, get)"), ("sample", "sample (other outputs)")):
        a, b = median["BallBearing", what], median["BallBearing3", what]
        print(f"{label:28s}{a:24.2f}{b:24.2f}{b / a:11.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
