"""The FMU's per-step fmi2 calls from numba (mechanism.cosim.fmu_native) against the bare fmpy exchange (issue 11).

    python benchmarks/fmu_native.py [--fmu dist/BallBearing.fmu] [--calls 10000] [--repeat 5]

Prints, measured in one run (medians of ``--repeat`` interleaved runs of ``--calls`` calls, µs per call):

* the bare fmpy exchange: ``benchmarks/cosim.py``'s ``bare_exchange_us`` (setReal 6 + doStep + getReal 8,
  ctypes from Python with prebuilt arrays, the inputs computed in Python);
* the same exchange natively from an njit loop (``fmu_native.exchange``, the same inputs computed in the
  loop), and called once per step from Python (numba's dispatch added);
* fmi2GetFMUstate + fmi2FreeFMUstate and fmi2SetFMUstate (of the instance's own state), natively from an
  njit loop and through fmpy's methods from Python (what the masters' rollback costs);
* the same with the loader's C step off (BEARING_FMU_C_STEP=0: the Python step inside the FMU);

then the ratios native / fmpy, and what one iterated communication step's FMU calls (2 exchanges, a
save, a restore) cost natively against the bare exchange (issue 11: the whole loop <= 3 x the bare exchange).
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from cosim import bare_exchange_us

from fmu_bearing.interface import COUPLING_OUTPUT_NAMES, JOINT_INPUT_NAMES
from mechanism.cosim import fmu_native
from mechanism.cosim.endpoints import FmuEndpoint

H_STEP = 1e-5


@njit(cache=True)
def native_loop(H, vr_in, vr_out, calls: int, h: float) -> int:
    """``calls`` exchanges with bare_exchange_us's inputs, from compiled code; the first refusal's status."""
    u, out, t = np.empty(6), np.empty(8), 0.0
    for k in range(calls):
        a = 0.01 * k
        u[0], u[1], u[2], u[3], u[4], u[5] = (3e-5 * math.cos(a), 3e-5 * math.sin(a), -0.01 * math.sin(a),
                                              0.01 * math.cos(a), -52.0, 125.0)
        status = fmu_native.exchange(H, vr_in, u, t, h, vr_out, out)
        if status < 0 or status > 1:
            return status
        t += h
    return 0


@njit(cache=True)
def native_save_loop(H, calls: int) -> int:
    """``calls`` fmi2GetFMUstate + fmi2FreeFMUstate (a master's save before every step)."""
    for _ in range(calls):
        status, state = fmu_native.get_state(H)
        if status < 0 or status > 1:
            return status
        status = fmu_native.free_state(H, state)
        if status < 0 or status > 1:
            return status
    return 0


@njit(cache=True)
def native_restore_loop(H, state: int, calls: int) -> int:
    """``calls`` fmi2SetFMUstate of ``state`` (a rollback)."""
    for _ in range(calls):
        status = fmu_native.set_state(H, state)
        if status < 0 or status > 1:
            return status
    return 0


class Instance:
    """An initialised FmuEndpoint (C step switched at instantiation), its handle and arrays."""

    def __init__(self, fmu: Path, c_step: bool):
        old = os.environ.get("BEARING_FMU_C_STEP")
        os.environ["BEARING_FMU_C_STEP"] = "1" if c_step else "0"
        try:
            self.ep = FmuEndpoint(fmu, instance_name="native")
            self.ep.initialize((3e-5, 0.0, 0.0, 0.0, -52.0, 125.0))
        finally:
            _restore_env("BEARING_FMU_C_STEP", old)
        self.H = fmu_native.endpoint_handle(self.ep)
        self.vr_in = np.array([self.ep.variables[n].valueReference for n in JOINT_INPUT_NAMES], np.uint32)
        self.vr_out = np.array([self.ep.variables[n].valueReference for n in COUPLING_OUTPUT_NAMES], np.uint32)
        # the restored state is saved after a few steps: once the loader's C step owns the instance's state
        # (with the C step on; a state saved before is pythonfmu's, restored by a Python call)
        fmu_native.check(native_loop(self.H, self.vr_in, self.vr_out, 10, H_STEP), "exchange", self.ep)
        status, self.state = fmu_native.get_state(self.H)
        fmu_native.check(status, "getFMUstate", self.ep)
        self.t = 0.0

    def native(self, calls: int) -> float:
        t0 = time.perf_counter()
        fmu_native.check(native_loop(self.H, self.vr_in, self.vr_out, calls, H_STEP), "exchange", self.ep)
        return _us(t0, calls)

    def native_per_call(self, calls: int) -> float:
        """One njit call per exchange from a Python loop (numba's dispatch per call)."""
        H, vr_in, vr_out, exchange = self.H, self.vr_in, self.vr_out, fmu_native.exchange
        u, out, t = np.empty(6), np.empty(8), 0.0
        t0 = time.perf_counter()
        for k in range(calls):
            a = 0.01 * k
            u[0], u[1], u[2], u[3], u[4], u[5] = (3e-5 * math.cos(a), 3e-5 * math.sin(a), -0.01 * math.sin(a),
                                                  0.01 * math.cos(a), -52.0, 125.0)
            if exchange(H, vr_in, u, t, H_STEP, vr_out, out) > 1:
                raise RuntimeError("refused")
            t += H_STEP
        return _us(t0, calls)

    def native_save(self, calls: int) -> float:
        t0 = time.perf_counter()
        fmu_native.check(native_save_loop(self.H, calls), "getFMUstate + freeFMUstate", self.ep)
        return _us(t0, calls)

    def native_restore(self, calls: int) -> float:
        t0 = time.perf_counter()
        fmu_native.check(native_restore_loop(self.H, self.state, calls), "setFMUstate", self.ep)
        return _us(t0, calls)

    def fmpy_save(self, calls: int) -> float:
        get_state, free_state = self.ep.fmu.getFMUstate, self.ep.fmu.freeFMUstate
        t0 = time.perf_counter()
        for _ in range(calls):
            free_state(get_state())
        return _us(t0, calls)

    def fmpy_restore(self, calls: int) -> float:
        import ctypes
        set_state, state = self.ep.fmu.setFMUstate, ctypes.c_void_p(self.state)
        t0 = time.perf_counter()
        for _ in range(calls):
            set_state(state)
        return _us(t0, calls)

    def close(self) -> None:
        fmu_native.free_state(self.H, self.state)
        fmu_native.invalidate(self.H)
        self.ep.close()


def _us(t0: float, calls: int) -> float:
    return (time.perf_counter() - t0) / calls * 1e6


def _restore_env(name: str, old: str | None) -> None:
    if old is None:
        os.environ.pop(name, None)
    else:
        os.environ[name] = old


def bare(fmu: Path, c_step: bool, calls: int) -> float:
    old = os.environ.get("BEARING_FMU_C_STEP")
    os.environ["BEARING_FMU_C_STEP"] = "1" if c_step else "0"
    try:
        return bare_exchange_us(fmu, calls)
    finally:
        _restore_env("BEARING_FMU_C_STEP", old)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--fmu", type=Path, default=ROOT / "dist" / "BallBearing.fmu")
    ap.add_argument("--calls", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    instances = {True: Instance(a.fmu, True), False: Instance(a.fmu, False)}
    for inst in instances.values():      # compile or load the njit functions before timing
        inst.native(10), inst.native_per_call(10), inst.native_save(10), inst.native_restore(10)
    samples: dict[str, list[float]] = {}
    for _ in range(a.repeat):
        for c_step, inst in instances.items():
            tag = "" if c_step else ", C step off"
            for name, measure in ((f"bare fmpy exchange{tag}", lambda n, c=c_step: bare(a.fmu, c, n)),
                                  (f"native exchange, njit loop{tag}", inst.native),
                                  (f"native exchange, one njit call per step from Python{tag}", inst.native_per_call),
                                  (f"native getFMUstate + freeFMUstate{tag}", inst.native_save),
                                  (f"fmpy getFMUstate + freeFMUstate{tag}", inst.fmpy_save),
                                  (f"native setFMUstate{tag}", inst.native_restore),
                                  (f"fmpy setFMUstate{tag}", inst.fmpy_restore)):
                samples.setdefault(name, []).append(measure(a.calls))
    for inst in instances.values():
        inst.close()
    med = {k: statistics.median(v) for k, v in samples.items()}
    print(f"{a.fmu.name}: medians of {a.repeat} interleaved runs of {a.calls} calls, µs per call")
    for name, us in med.items():
        print(f"  {name:62s} {us:8.3f}")
    for tag in ("", ", C step off"):
        b = med[f"bare fmpy exchange{tag}"]
        ex, save, rest = (med[f"native {k}{tag}"] for k in ("exchange, njit loop", "getFMUstate + freeFMUstate",
                                                            "setFMUstate"))
        step = 2 * ex + save + rest
        print(f"ratios{tag or ', C step on'}:")
        print(f"  native exchange / bare fmpy exchange                          {ex / b:8.3f}")
        print(f"  native get+free state / fmpy get+free state                   "
              f"{save / med[f'fmpy getFMUstate + freeFMUstate{tag}']:8.3f}")
        print(f"  native set state / fmpy set state                             "
              f"{rest / med[f'fmpy setFMUstate{tag}']:8.3f}")
        print(f"  iterated step's FMU calls natively (2 exchanges + save + restore) "
              f"{step:7.3f} µs = {step / b:5.2f} x the bare exchange (the loop's budget: 3 x)")


if __name__ == "__main__":
    main()
