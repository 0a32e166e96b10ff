"""Cost of one co-simulation exchange with the BallBearing FMU against the in-process force law.

    python benchmarks/fmu_step.py [--fmu dist/BallBearing.fmu] [--baseline OLD.fmu] [--calls 3000] [--repeat 7]
                                  [--no-native]

Targets on the development machine: in-process evaluate <= 10 us for 8 balls, exchange <= 25 us;
issue 13: native-host cycle <= 10 us, fmpy cycle (prebuilt arrays) <= 7.5 us.

One exchange = setReal of the 6 inputs in one call, doStep, getReal of F_x and F_y in one call,
through fmpy's FMU2Slave. Measured three ways: fmpy's convenience methods (which build ctypes arrays
per call), fmpy's fmi2* wrappers with prebuilt ctypes arrays (what the master does), and the raw
ctypes function pointers (no fmpy wrapper). The breakdown times each call alone and the slave's own
Python code called directly, so the rest is pythonfmu's C++ layer plus ctypes. Every figure is the
median over ``--repeat`` runs of ``--calls`` calls, in microseconds per call.

For scale (the machine may be busy: compare figures of one run), the same fmpy loops are timed with a
trivial compiled FMU (``TRIVIAL_FMU`` below, compiled with zig cc: fmi2SetReal copies, fmi2DoStep adds,
fmi2GetReal copies): what fmpy and ctypes cost a host without any model, and its native-host cycle is the
floor of the C host's. The ratios printed at the end use those figures.

``--baseline OLD.fmu`` also times an earlier build of the FMU in the same run (fmpy prebuilt arrays and the
native host, interleaved with the others), for a before/after ratio that the machine's load does not blur.

The C step (issue 13's last target; loader.c, "C step"): the loader does the whole doStep in C. The rows "C
step off" time the same FMU and loader with BEARING_FMU_C_STEP=0 (the Python step, one Python call per doStep),
in fmpy and in the native host, interleaved with the others: the ratio on/off is the before/after of one run.

The native-host cycle is the same exchange from the C host ``fmu_bearing/native/host.c`` (a separate,
non-Python process, clean environment; timed inside the host), through the FMU's loader; and, for
comparison, through pythonfmu's binary alone with libpython preloaded (how a native host had to run the
FMU before issue 13). Each of the ``--repeat`` host runs makes ``--calls`` cycles.
"""
from __future__ import annotations

import argparse
import ctypes
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fmu_bearing.ball_bearing import BallBearing  # noqa: E402
from fmu_bearing.parameters import BearingParameters  # noqa: E402

INPUTS = ("e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer")
TARGET_IN_PROCESS_US, TARGET_EXCHANGE_US = 10.0, 25.0
TARGET_NATIVE_US, TARGET_FMPY_US = 10.0, 7.5
RESTORE_KEY = "fmpy setFMUstate of the instance's own state (rollback)"
RESTORE_PY_STEP_KEY = "fmpy setFMUstate of the instance's own state, C step off"
SAVE_KEY = "fmpy getFMUstate + freeFMUstate (a master's save per step)"
SAVE_PY_STEP_KEY = "fmpy getFMUstate + freeFMUstate, C step off"
BASELINE_RESTORE_KEY = "fmpy setFMUstate of the instance's own state, --baseline FMU"
#: the issue's reference: a trivial compiled FMU costs about 2 us per cycle through fmpy (prebuilt arrays)
TRIVIAL_REFERENCE_US = 2.0
TRIVIAL_KEY = "exchange, fmpy fmi2* prebuilt, trivial compiled FMU (no model)"
BASELINE_FMPY_KEY = "exchange, fmpy fmi2* prebuilt, --baseline FMU"
BASELINE_NATIVE_KEY = "exchange, native C host, --baseline FMU"
FMPY_KEY = "exchange, fmpy fmi2* with prebuilt ctypes arrays"
NATIVE_KEY = "exchange, native C host through the loader"
#: the same FMU with the loader's C step switched off (BEARING_FMU_C_STEP=0: the Python step, one call per step)
PY_STEP_FMPY_KEY = "exchange, fmpy fmi2* prebuilt, C step off (BEARING_FMU_C_STEP=0)"
PY_STEP_NATIVE_KEY = "exchange, native C host, C step off (BEARING_FMU_C_STEP=0)"


def states(n=64):
    """Representative loaded inputs: |e| = 30 um (3 of 8 balls loaded) turning, small v, 100 rad/s."""
    out = []
    for k in range(n):
        a = 2 * math.pi * k / n
        out.append((3e-5 * math.cos(a), 3e-5 * math.sin(a), -0.01 * math.sin(a), 0.01 * math.cos(a), 100.0, 0.0))
    return out


def medians_us(benchmarks: dict, calls: int, repeat: int) -> dict:
    """Median time per call [us] of each ``fn(calls)``; the repeats are interleaved (round robin) so
    that a change of load on the (shared) machine affects every benchmark alike."""
    runs = {name: [] for name in benchmarks}
    for _ in range(repeat):
        for name, fn in benchmarks.items():
            t0 = time.perf_counter()
            fn(calls)
            runs[name].append((time.perf_counter() - t0) / calls * 1e6)
    return {name: statistics.median(times) for name, times in runs.items()}


def native_cycles(fmu_path: Path, tmp: Path, calls: int, repeat: int, baseline: Path | None = None) -> dict:
    """Median set/step/get cycle [us] in the native C host: through the loader (clean environment), and
    through pythonfmu's binary alone with libpython preloaded (skipped if this Python has no shared one)."""
    import sysconfig
    import zipfile

    from fmu_bearing.native.host import clean_env, compile_host, run_host
    host = compile_host(tmp)
    loader_dir, plain_dir, baseline_dir = tmp / "native_loader", tmp / "native_pythonfmu", tmp / "native_baseline"
    for folder, path in ((loader_dir, fmu_path), (plain_dir, fmu_path), (baseline_dir, baseline)):
        if path is not None:
            with zipfile.ZipFile(path) as z:
                z.extractall(folder)
    binaries = plain_dir / "binaries" / "linux64"
    plain = list(binaries.glob("*_pythonfmu.so"))
    for original in plain:
        original.replace(binaries / original.name.replace("_pythonfmu", ""))
    libpython = Path(sysconfig.get_config_var("LIBDIR") or "") / (sysconfig.get_config_var("INSTSONAME") or "-")
    cases = {NATIVE_KEY: (loader_dir, clean_env()), PY_STEP_NATIVE_KEY: (loader_dir, clean_env(BEARING_FMU_C_STEP="0"))}
    if baseline is not None:
        cases[BASELINE_NATIVE_KEY] = (baseline_dir, clean_env())
    if plain and libpython.is_file():
        cases["exchange, native C host, pythonfmu binary + LD_PRELOAD"] = (plain_dir, clean_env(LD_PRELOAD=str(libpython)))
    runs = {name: [] for name in cases}
    for _ in range(repeat):
        for name, (folder, env) in cases.items():
            run = run_host(host, folder, 1, calls, "seq", env=env)
            if run.returncode != 0 or run.cycle_us is None:
                raise RuntimeError(f"{name}: host failed ({run.returncode}): {run.stderr[-2000:]}")
            runs[name].append(run.cycle_us)
    return {name: statistics.median(times) for name, times in runs.items()}


#: a trivial FMI 2.0 co-simulation library (the exchange costs of fmpy and ctypes, without any model)
TRIVIAL_FMU = r"""
#include <stdlib.h>
#include <string.h>
#define EXPORT __attribute__((visibility("default")))
typedef struct { double x[16]; } M;
EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char *fmi2GetVersion(void) { return "2.0"; }
EXPORT void *fmi2Instantiate(const char *n, int t, const char *g, const char *r, const void *f, int v, int l) {
    return calloc(1, sizeof(M));
}
EXPORT void fmi2FreeInstance(void *c) { free(c); }
EXPORT int fmi2SetupExperiment(void *c, int a, double b, double d, int e, double f) { return 0; }
EXPORT int fmi2EnterInitializationMode(void *c) { return 0; }
EXPORT int fmi2ExitInitializationMode(void *c) { return 0; }
EXPORT int fmi2Terminate(void *c) { return 0; }
EXPORT int fmi2SetReal(void *c, const unsigned *vr, size_t n, const double *v) {
    for (size_t i = 0; i < n; i++) ((M *)c)->x[vr[i] & 15] = v[i];
    return 0;
}
EXPORT int fmi2GetReal(void *c, const unsigned *vr, size_t n, double *v) {
    for (size_t i = 0; i < n; i++) v[i] = ((M *)c)->x[vr[i] & 15];
    return 0;
}
/* every other FMI 2.0 function (fmpy resolves them all): a stub that returns fmi2OK */
#define STUB(name) EXPORT int name(void *c, void *a, void *b, void *d, void *e, void *f) { return 0; }
STUB(fmi2SetDebugLogging) STUB(fmi2Reset) STUB(fmi2GetInteger) STUB(fmi2GetBoolean) STUB(fmi2GetString)
STUB(fmi2SetInteger) STUB(fmi2SetBoolean) STUB(fmi2SetString) STUB(fmi2GetFMUstate) STUB(fmi2SetFMUstate)
STUB(fmi2FreeFMUstate) STUB(fmi2SerializedFMUstateSize) STUB(fmi2SerializeFMUstate) STUB(fmi2DeSerializeFMUstate)
STUB(fmi2GetDirectionalDerivative) STUB(fmi2SetRealInputDerivatives) STUB(fmi2GetRealOutputDerivatives)
STUB(fmi2CancelStep) STUB(fmi2GetStatus) STUB(fmi2GetRealStatus) STUB(fmi2GetIntegerStatus)
STUB(fmi2GetBooleanStatus) STUB(fmi2GetStringStatus)
EXPORT int fmi2DoStep(void *c, double t, double h, int s) {
    M *m = (M *)c;
    m->x[6] = m->x[0] + m->x[1];
    m->x[7] = m->x[2] + m->x[3] + m->x[4] + m->x[5];
    return 0;
}
"""


def trivial_fmu(tmp: Path):
    """An fmpy FMU2Slave of the trivial library (compiled here), or None without zig."""
    import subprocess

    from fmpy.fmi2 import FMU2Slave

    from fmu_bearing.native.build import LoaderBuildError, zig_cc
    folder = tmp / "trivial"
    binaries = folder / "binaries" / "linux64"
    binaries.mkdir(parents=True)
    (tmp / "trivial.c").write_text(TRIVIAL_FMU, encoding="utf-8")
    try:
        proc = subprocess.run([*zig_cc(), "-shared", "-fPIC", "-O2", "-o", str(binaries / "Trivial.so"),
                               str(tmp / "trivial.c")], capture_output=True, text=True)
    except LoaderBuildError:
        return None
    if proc.returncode != 0:
        return None
    fmu = FMU2Slave(guid="trivial", unzipDirectory=str(folder), modelIdentifier="Trivial", instanceName="trivial")
    fmu.instantiate(loggingOn=False)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    return fmu


def kernel_steps(slave) -> int:
    """Steps the loader's C step did for an fmpy FMU2Slave (bearingLoaderKernelSteps; -1: no such loader)."""
    function = getattr(slave.dll, "bearingLoaderKernelSteps", None)
    if function is None:
        return -1
    function.argtypes, function.restype = [ctypes.c_void_p], ctypes.c_longlong
    return function(slave.component)


def find_fmu(path: str | None, tmp: Path) -> Path:
    """The FMU to measure: ``path``, or a fresh build of the current sources (never a stale dist/)."""
    if path:
        return Path(path)
    import build_fmu
    return build_fmu.build(tmp, names=["BallBearing"], verbose=False)["BallBearing"]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu", help="FMU to measure (default: a fresh build of the current sources)")
    parser.add_argument("--baseline", help="an earlier build of the FMU to time in the same run (before/after)")
    parser.add_argument("--calls", type=int, default=3000)
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--no-native", action="store_true", help="skip the native-host cycle (needs ziglang)")
    args = parser.parse_args(argv)

    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    with tempfile.TemporaryDirectory() as tmp:
        fmu_path = find_fmu(args.fmu, Path(tmp))
        md = read_model_description(str(fmu_path))
        vr = {v.name: v.valueReference for v in md.modelVariables}
        unzipdir = extract(str(fmu_path), unzipdir=str(Path(tmp) / "x"))
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="bench")
        fmu.instantiate(loggingOn=False)
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()

        S = states()
        nS = len(S)
        in_vrs = [vr[n] for n in INPUTS]
        out_vrs = [vr["F_x"], vr["F_y"]]
        h = 1e-5
        comp = fmu.component
        vr_in = (ctypes.c_uint * 6)(*in_vrs)
        val_in = (ctypes.c_double * 6)()
        vr_out = (ctypes.c_uint * 2)(*out_vrs)
        val_out = (ctypes.c_double * 2)()
        set_real, do_step, get_real = fmu.fmi2SetReal, fmu.fmi2DoStep, fmu.fmi2GetReal
        raw_set, raw_step, raw_get = (fmu.dll.fmi2SetReal, fmu.dll.fmi2DoStep, fmu.dll.fmi2GetReal)
        raw_set.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t,
                            ctypes.POINTER(ctypes.c_double)]
        raw_get.argtypes = raw_set.argtypes
        raw_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
        raw_set.restype = raw_step.restype = raw_get.restype = ctypes.c_int

        # The same FMU with pythonfmu's binary alone behind fmpy (no loader): what the loader costs a Python host.
        plain_dir = Path(extract(str(fmu_path), unzipdir=str(Path(tmp) / "x_plain")))
        plain_bins = plain_dir / "binaries" / "linux64"
        plain_fmu = None
        for original in plain_bins.glob("*_pythonfmu.so"):
            original.replace(plain_bins / original.name.replace("_pythonfmu", ""))
            plain_fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(plain_dir),
                                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench_plain")
            plain_fmu.instantiate(loggingOn=False)
            plain_fmu.setupExperiment(startTime=0.0)
            plain_fmu.enterInitializationMode()
            plain_fmu.exitInitializationMode()

        # The same FMU and loader with the C step off (read at fmi2Instantiate): the Python step per doStep.
        os.environ["BEARING_FMU_C_STEP"] = "0"
        try:
            py_step_fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench_py_step")
            py_step_fmu.instantiate(loggingOn=False)
        finally:
            del os.environ["BEARING_FMU_C_STEP"]
        py_step_fmu.setupExperiment(startTime=0.0)
        py_step_fmu.enterInitializationMode()
        py_step_fmu.exitInitializationMode()

        # An earlier build (--baseline), through its own binary, in the same process.
        base_fmu = None
        if args.baseline:
            base_md = read_model_description(args.baseline)
            base_dir = extract(args.baseline, unzipdir=str(Path(tmp) / "x_baseline"))
            base_fmu = FMU2Slave(guid=base_md.guid, unzipDirectory=base_dir,
                                 modelIdentifier=base_md.coSimulation.modelIdentifier, instanceName="bench_baseline")
            base_fmu.instantiate(loggingOn=False)
            base_fmu.setupExperiment(startTime=0.0)
            base_fmu.enterInitializationMode()
            base_fmu.exitInitializationMode()

        def prebuilt_loop(slave):
            """n set(6)/doStep/get(2) cycles on ``slave``'s fmi2* functions with prebuilt ctypes arrays."""
            def loop(n):
                f_set, f_step, f_get, f_comp = slave.fmi2SetReal, slave.fmi2DoStep, slave.fmi2GetReal, slave.component
                for i in range(n):
                    val_in[0], val_in[1], val_in[2], val_in[3], val_in[4], val_in[5] = S[i % nS]
                    f_set(f_comp, vr_in, 6, val_in)
                    f_step(f_comp, i * h, h, 1)
                    f_get(f_comp, vr_out, 2, val_out)
                    val_out[0], val_out[1]
            return loop

        fmpy_prebuilt_baseline = prebuilt_loop(base_fmu) if base_fmu is not None else None
        fmpy_prebuilt_plain = prebuilt_loop(plain_fmu) if plain_fmu is not None else None

        trivial = trivial_fmu(Path(tmp))

        trivial_prebuilt = prebuilt_loop(trivial) if trivial is not None else None

        def fmpy_convenience(n):
            for i in range(n):
                fmu.setReal(in_vrs, S[i % nS])
                fmu.doStep(i * h, h)
                fmu.getReal(out_vrs)

        fmpy_prebuilt = prebuilt_loop(fmu)
        fmpy_prebuilt_py_step = prebuilt_loop(py_step_fmu)

        def raw_ctypes(n):
            for i in range(n):
                val_in[0], val_in[1], val_in[2], val_in[3], val_in[4], val_in[5] = S[i % nS]
                if raw_set(comp, vr_in, 6, val_in) or raw_step(comp, i * h, h, 1) or raw_get(comp, vr_out, 2, val_out):
                    raise RuntimeError("FMI call failed")
                val_out[0], val_out[1]

        def only_set(n):
            for i in range(n):
                val_in[0], val_in[1], val_in[2], val_in[3], val_in[4], val_in[5] = S[i % nS]
                set_real(comp, vr_in, 6, val_in)

        def only_step(n):
            for i in range(n):
                do_step(comp, i * h, h, 1)

        def only_get(n):
            for i in range(n):
                get_real(comp, vr_out, 2, val_out)

        # The slave's own Python code, called directly (no pythonfmu C++, no ctypes).
        from fmu_bearing.slaves.ball_bearing_fmu import BallBearing as Slave
        slave = Slave(instance_name="direct", resources=None)
        slave.exit_initialization_mode()

        def slave_direct(n):
            for i in range(n):
                slave.set_real(in_vrs, list(S[i % nS]))
                slave.do_step(i * h, h)
                slave.get_real(out_vrs)

        def in_process(n_balls):
            b = BallBearing(BearingParameters(n_balls=n_balls, allow_ball_overlap=n_balls > 13))
            loads = [0.0] * n_balls

            def evaluate(n):
                ev = b.evaluate
                for i in range(n):
                    ex, ey, vx, vy, wi, wo = S[i % nS]
                    ev(ex, ey, vx, vy, 0.1 * i, wi, wo, loads)
            return evaluate

        def restore_loop(slave):
            """n fmi2SetFMUstate of a state the instance saved itself after initialisation: the masters'
            rollback (the iterated and adaptive schemes), once per step. The state is saved at the first run
            (after the exchange loops: stepped, as in a master), so with the C step it is saved in C."""
            saved = []

            def loop(n):
                if not saved:
                    saved.append(slave.getFMUstate())
                set_state, state = slave.setFMUstate, saved[0]
                for _ in range(n):
                    set_state(state)
            return loop

        def save_loop(slave):
            """n fmi2GetFMUstate + fmi2FreeFMUstate: the masters save the FMU before every step."""
            def loop(n):
                get_state, free_state = slave.getFMUstate, slave.freeFMUstate
                for _ in range(n):
                    free_state(get_state())
            return loop

        c, r = args.calls, args.repeat
        restore = {SAVE_KEY: save_loop(fmu), SAVE_PY_STEP_KEY: save_loop(py_step_fmu),
                   RESTORE_KEY: restore_loop(fmu), RESTORE_PY_STEP_KEY: restore_loop(py_step_fmu)}
        if base_fmu is not None:
            restore[BASELINE_RESTORE_KEY] = restore_loop(base_fmu)
        plain = {"exchange, fmpy fmi2* prebuilt, pythonfmu binary alone (no loader)": fmpy_prebuilt_plain} \
            if plain_fmu is not None else {}
        trivial_case = {TRIVIAL_KEY: trivial_prebuilt} if trivial is not None else {}
        baseline_case = {BASELINE_FMPY_KEY: fmpy_prebuilt_baseline} if base_fmu is not None else {}
        results = medians_us({
            "exchange, fmpy setReal/doStep/getReal": fmpy_convenience,
            **trivial_case,
            FMPY_KEY: fmpy_prebuilt,
            PY_STEP_FMPY_KEY: fmpy_prebuilt_py_step,
            **baseline_case,
            **plain,
            "exchange, raw ctypes function pointers": raw_ctypes,
            "  of which fmi2SetReal (6 values)": only_set,
            "  of which fmi2DoStep": only_step,
            "  of which fmi2GetReal (2 values)": only_get,
            "  slave Python code alone (set_real, do_step, get_real)": slave_direct,
            "in-process evaluate, 8 balls": in_process(8),
            "in-process evaluate, 20 balls": in_process(20),
            **restore,       # last: restoring a state sets the instance back
        }, c, r)
        c_steps = kernel_steps(fmu), kernel_steps(py_step_fmu)
        fmu.terminate()
        fmu.freeInstance()
        for other in (trivial, base_fmu, py_step_fmu):
            if other is not None:
                other.terminate()
                other.freeInstance()
        if plain_fmu is not None:
            plain_fmu.terminate()
            plain_fmu.freeInstance()
        if not args.no_native:
            results.update(native_cycles(fmu_path, Path(tmp), c, r, Path(args.baseline) if args.baseline else None))

    width = max(map(len, results))
    print(f"BallBearing FMU exchange vs in-process force law ({fmu_path.name}; median of {r} x {c} calls)")
    for name, us in results.items():
        print(f"  {name:<{width}}  {us:8.2f} us")
    print(f"  steps done by the loader's C step: {c_steps[0]} (C step on), {c_steps[1]} (BEARING_FMU_C_STEP=0)")
    exchange = results[FMPY_KEY]
    in_process = results["in-process evaluate, 8 balls"]
    print(f"  ratio exchange (prebuilt arrays) / in-process evaluate (8 balls): {exchange / in_process:.1f}")
    plain_fmpy = results.get("exchange, fmpy fmi2* prebuilt, pythonfmu binary alone (no loader)")
    if plain_fmpy is not None:
        print(f"  ratio fmpy (prebuilt arrays) through the loader / pythonfmu binary alone: "
              f"{exchange / plain_fmpy:.2f}")
    trivial_us = results.get(TRIVIAL_KEY)
    if trivial_us is not None:
        ratio = TARGET_FMPY_US / TRIVIAL_REFERENCE_US
        print(f"  ratio fmpy (prebuilt arrays) / trivial FMU: {exchange / trivial_us:.2f} (the target 7.5 us at the "
              f"issue's {TRIVIAL_REFERENCE_US:g} us trivial cycle is a ratio of {ratio:.2f}; on this run's trivial "
              f"cycle the fmpy target scales to {ratio * trivial_us:.2f} us)")
    print(f"  ratio C step on / off (BEARING_FMU_C_STEP=0): fmpy (prebuilt arrays) "
          f"{exchange / results[PY_STEP_FMPY_KEY]:.2f}"
          + (f", native host {results[NATIVE_KEY] / results[PY_STEP_NATIVE_KEY]:.2f}"
             if PY_STEP_NATIVE_KEY in results else ""))
    print(f"  ratio C step on / off: fmi2GetFMUstate {results[SAVE_KEY] / results[SAVE_PY_STEP_KEY]:.3f}, "
          f"fmi2SetFMUstate of the own state {results[RESTORE_KEY] / results[RESTORE_PY_STEP_KEY]:.3f}")
    base_fmpy, base_native = results.get(BASELINE_FMPY_KEY), results.get(BASELINE_NATIVE_KEY)
    if base_fmpy is not None:
        print(f"  ratio this FMU / --baseline FMU: fmpy (prebuilt arrays) {exchange / base_fmpy:.2f}"
              + (f", native host {results['exchange, native C host through the loader'] / base_native:.2f}"
                 if base_native is not None else ""))
    base_restore = results.get(BASELINE_RESTORE_KEY)
    if base_restore is not None:
        print(f"  ratio this FMU / --baseline FMU: fmi2SetFMUstate of its own state {results[RESTORE_KEY] / base_restore:.2f}")
    native = results.get("exchange, native C host through the loader")
    if native is not None:
        before = results.get("exchange, native C host, pythonfmu binary + LD_PRELOAD")
        print(f"  ratio native host / fmpy (prebuilt arrays): {native / exchange:.2f}"
              + (f"; pythonfmu binary alone / loader (native host): {before / native:.1f}" if before else ""))
        print(f"  issue 13 targets: native <= {TARGET_NATIVE_US:g} us "
              f"({'met' if native <= TARGET_NATIVE_US else 'MISSED'}), fmpy <= {TARGET_FMPY_US:g} us "
              f"({'met' if exchange <= TARGET_FMPY_US else 'MISSED'})")
    print(f"  targets: in-process <= {TARGET_IN_PROCESS_US:g} us for 8 balls "
          f"({'met' if in_process <= TARGET_IN_PROCESS_US else 'MISSED'}), exchange <= {TARGET_EXCHANGE_US:g} us "
          f"({'met' if exchange <= TARGET_EXCHANGE_US else 'MISSED'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
