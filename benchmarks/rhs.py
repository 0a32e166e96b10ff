"""Cost of the compiled multibody right-hand side (``kernels.rhs``) and of one RK4 pass (``kernels.advance``).

Each figure is measured inside numba (an njit loop of N calls, best of ``--repeat`` loops), so the Python
call overhead is not in it:

* ``rhs``: one ``kernels.rhs`` (applied forces, bearing inputs and force, kinematics, eq. 9);
* ``advance``: one ``kernels.advance`` pass as the compiled loop calls it (one RK4 step, first stage given,
  with the energy account: three ``rhs``, the account's powers and stage rows, the end state's kinematics);
* ``prepare``: the end state's kinematics and bearing inputs (``kernels.prepare``);
* ``finish``: eq. (9) at the end state with the exchanged force, lambda, powers (``kernels.finish``, no row).

Models: the slider-crank with the bearing (the run's model), its ideal-joint variant, the four-bar with
the bearing and the double pendulum, each at its initial state with a stiff linear force model in the joint.

Only the public kernels are called (``pack``, ``pack_link``, ``workspace_size``, ``rhs``, ``advance``,
``prepare``, ``finish``), so the script runs against any checkout. Before/after in one run:

    python benchmarks/rhs.py --before /path/to/the/previous/checkout [--calls 300] [--repeat 300] [--rounds 3]

runs this script's measurement in child processes with PYTHONPATH set to the previous checkout and to this
one, alternated ``--rounds`` times, and prints the medians and the ratios before/after. Without
``--before`` it measures the checkout on the path. The first run against a checkout compiles its kernels.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit

from mechanism.multibody import kernels as kn

FIGURES = ("rhs", "advance", "prepare", "finish")


@njit
def _rhs_loop(calls, y, fm, I, R, L, LR, W, u, dy):
    for k in range(calls):
        kn.rhs(1e-3 + 1e-12 * k, y, fm, I, R, L, LR, W, u, dy)


@njit
def _advance_loop(calls, y, h, fm, k1, I, R, L, LR, W, u, acc, p1, stages):
    s = 0.0
    for k in range(calls):
        y2 = y.copy()
        kn.advance(y2, 1e-3, h, 1, 1e-3 + h, fm, k1, True, I, R, L, LR, W, u, acc, p1, stages)
        s += y2[0]
    return s


@njit
def _prepare_loop(calls, y, I, R, L, LR, W, u):
    for k in range(calls):
        kn.prepare(y, 1e-3, I, R, L, LR, W, u)


@njit
def _finish_loop(calls, y, I, R, L, LR, W, u, dy, lam, row, probes, scale, react, p1):
    for k in range(calls):
        kn.finish(y, u[0], u[1], 10.0, -20.0, I, R, L, LR, W, u, dy, lam, row, probes, scale, 1e-3, 0.0, react, p1)


def _models():
    """(name, system, joint or None, q0, qd0) of the benchmarked models."""
    from mechanism.multibody.solver import System
    from mechanism.systems import double_pendulum, four_bar, slider_crank
    out = []
    for joint in ("bearing", "ideal"):
        p = slider_crank.SliderCrankParameters()
        s = System(slider_crank.build(p, joint))
        out.append((f"slider-crank-{joint}", s, *slider_crank.initial_state(s, p)))
    p = four_bar.FourBarParameters()
    s = System(four_bar.build(p, "bearing"))
    out.append(("four-bar-bearing", s, *four_bar.initial_state(s, p)))
    s = System(double_pendulum.build())
    out.append(("double-pendulum", s, *double_pendulum.initial_state(s)))
    return out


def _best(loop, args: tuple, calls: int, repeat: int) -> float:
    """Best of ``repeat`` timings of loop(calls, *args) [s], per call."""
    loop(calls, *args)
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        loop(calls, *args)
        best = min(best, time.perf_counter() - start)
    return best / calls


def measure(calls: int, repeat: int) -> dict[str, dict[str, float]]:
    """µs per call of each figure, per model, for the ``mechanism`` on the path."""
    from mechanism.cosim.coupling.base import ForceModel
    out = {}
    for name, system, q0, qd0 in _models():
        joint = system.model.bearings[0] if system.model.bearings else None
        I, R = kn.pack(system)
        L, LR = kn.pack_link(system, joint)
        W, u = np.zeros(kn.workspace_size(I)), np.zeros(6)
        fm = ForceModel(0.0, (5.0, -3.0), K=(1e6, 1e4, 1e6), C=(50.0, 0.0, 50.0)).coefficients
        n = system.n
        y = np.concatenate((q0, qd0))
        dy = np.zeros(2 * n)
        kn.rhs(0.0, y, fm, I, R, L, LR, W, u, dy)
        h = 1e-5
        acc, p1, stages = np.zeros(3), np.zeros(3), np.zeros((5, 8))
        lam, row = np.zeros(system.m), np.zeros(0)
        probes, scale, react = np.zeros((0, 3), np.int64), np.zeros(0), np.zeros(0, np.int64)
        kn.prepare(y, 1e-3, I, R, L, LR, W, u)
        loops = {"rhs": (_rhs_loop, (y, fm, I, R, L, LR, W, u, dy)),
                 "advance": (_advance_loop, (y, h, fm, dy, I, R, L, LR, W, u, acc, p1, stages)),
                 "prepare": (_prepare_loop, (y, I, R, L, LR, W, u)),
                 "finish": (_finish_loop, (y, I, R, L, LR, W, u, dy, lam, row, probes, scale, react, p1))}
        out[name] = {k: 1e6 * _best(loop, args, calls, repeat) for k, (loop, args) in loops.items()}
    return out


def _child(checkout: Path, calls: int, repeat: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(checkout))
    res = subprocess.run([sys.executable, __file__, "--child", "--calls", str(calls), "--repeat", str(repeat)],
                         env=env, capture_output=True, text=True, cwd=str(checkout), check=False)
    if res.returncode:
        raise SystemExit(f"measurement in {checkout} failed:\n{res.stderr}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=300, help="calls per timed loop")
    ap.add_argument("--repeat", type=int, default=300, help="timed loops per figure (the best is kept)")
    ap.add_argument("--rounds", type=int, default=3, help="before/after alternations (with --before)")
    ap.add_argument("--before", type=Path, help="the previous checkout (PYTHONPATH for the 'before' figures)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(measure(args.calls, args.repeat)))
        return
    if args.before is None:
        for name, figs in measure(args.calls, args.repeat).items():
            print(f"{name:20s} " + "  ".join(f"{k} {v:6.3f} µs" for k, v in figs.items()))
        return
    after = Path(__file__).resolve().parents[1]
    runs = {"before": [], "after": []}
    for _ in range(args.rounds):
        runs["before"].append(_child(args.before.resolve(), args.calls, args.repeat))
        runs["after"].append(_child(after, args.calls, args.repeat))
    print(f"µs per call, medians of {args.rounds} alternated runs (each the best of {args.repeat} loops of "
          f"{args.calls} calls); before = {args.before}, after = {after}")
    print(f"{'model':20s} {'figure':8s} {'before':>9s} {'after':>9s} {'before/after':>12s}")
    for name in runs["after"][0]:
        for fig in FIGURES:
            b = statistics.median(r[name][fig] for r in runs["before"])
            a = statistics.median(r[name][fig] for r in runs["after"])
            print(f"{name:20s} {fig:8s} {b:9.3f} {a:9.3f} {b / a:12.2f}")


if __name__ == "__main__":
    main()
