"""Monolithic reference benchmark (issue 11): the compiled right-hand side against the NumPy one, per call and
over a reference run, measured in one process (ratios, interleaved).

    python benchmarks/monolithic_reference.py [--revs 0.2] [--rtol 1e-11] [--calls 2000]

Prints the time per right-hand-side call of each path, and the wall and CPU time of a monolithic run of
``--revs`` revolutions at 1200 rpm (the step-size study's reference: LSODA, events, energy states) with each,
with their rhs call counts and the largest relative difference of the peak joint force.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import from_values
from mechanism.cosim import monolithic
from mechanism.cosim.joint import BearingLink
from mechanism.multibody.solver import System
from mechanism.systems.slider_crank import (
    SliderCrankParameters,
    build,
    initial_state,
    slider_crank_observer,
)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--revs", type=float, default=0.2)
    p.add_argument("--rtol", type=float, default=1e-11)
    p.add_argument("--calls", type=int, default=2000)
    args = p.parse_args()
    params = SliderCrankParameters(rpm=1200.0)
    model = build(params, "bearing")
    system = System(model)
    q0, qd0 = initial_state(system, params)
    link = BearingLink(system, model.bearings[0])
    bearing = BallBearing(from_values({}))
    y = np.concatenate((q0, qd0, [0.0], np.zeros(4)))
    rhs = {"numpy": monolithic.numpy_rhs(system, link, bearing), "compiled": monolithic.compiled_rhs(system, link, bearing)}
    rhs["compiled"](0.0, y)                                        # compile / load the cache
    per_call = {k: [] for k in rhs}
    for _ in range(3):                                             # interleaved
        for k, f in rhs.items():
            t = time.perf_counter()
            for _ in range(args.calls):
                f(0.001, y)
            per_call[k].append((time.perf_counter() - t) / args.calls)
    best = {k: min(v) for k, v in per_call.items()}
    print(f"rhs call: numpy {best['numpy'] * 1e6:.1f} us, compiled {best['compiled'] * 1e6:.2f} us "
          f"(x{best['numpy'] / best['compiled']:.0f})")
    t_end = args.revs * 60.0 / params.rpm
    runs = {}
    for compiled in (False, True):
        wall, cpu = time.perf_counter(), time.process_time()
        r = monolithic.run_monolithic(system, link, bearing, q0, qd0, t_end, 1e-5, slider_crank_observer(system),
                                      rtol=args.rtol, progress=False, compiled=compiled)
        runs[compiled] = (r, time.perf_counter() - wall, time.process_time() - cpu)
    for compiled, (r, wall, cpu) in runs.items():
        print(f"run {'compiled' if compiled else 'numpy   '}: {r.status}, wall {wall:.2f} s, cpu {cpu:.2f} s, "
              f"{r.meta['rhs_calls']} rhs calls, {r.meta['contact_events']} contact events")
    (a, wa, ca), (b, wb, cb) = runs[False], runs[True]
    peak = [float(np.max(np.hypot(r["F_x"], r["F_y"]))) for r in (a, b)]
    print(f"ratio (numpy / compiled): wall x{wa / wb:.1f}, cpu x{ca / cb:.1f}; "
          f"peak |F| differs by {abs(peak[1] / peak[0] - 1):.2g} (relative)")


if __name__ == "__main__":
    main()
