"""The master's side of the signal exchange with a bearing component.

Endpoints with the same semantics (the FMU's: outputs after a step describe the end of
the step, for the inputs held over it):

* ``FmuEndpoint``: a BallBearing (or JournalClearance) FMU through fmpy's low-level
  ``FMU2Slave`` API: set the 6 inputs, ``doStep``, get the coupling outputs;
* ``Fmu3Endpoint``: the same for an FMI 3.0 FMU (BallBearing3) through fmpy's ``FMU3Slave``; array
  outputs (``ball_loads``, sized by the structural parameter ``n_balls``) are sampled element-wise as
  ``ball_load_1 .. ball_load_n``, the names the FMI 2.0 FMU and the in-process endpoint use;
  ``fmu_endpoint(path, ...)`` picks one of the two from the FMU's ``fmiVersion``;
* ``InProcessEndpoint``: the same force law (``fmu_bearing.ball_bearing``) called in-process,
  so the benchmark and the tests can compare the two paths under one coupling scheme.

Inputs, in order: e_x, e_y [m], v_x, v_y [m/s], omega_inner, omega_outer [rad/s].
Coupling outputs, fetched every step: F_x, F_y [N], stiffness_xx/xy/yy [N/m],
damping_xx/xy/yy [N s/m]. Everything else (ball loads, cage angle, ...) is *sampled*
only at the output interval, because each value fetched through an FMU costs time.
"""
from __future__ import annotations

import atexit
import ctypes
import math
import os
import shutil
import tempfile
import threading
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from fmu_bearing import life
from fmu_bearing.ball_bearing import BallBearing, BearingInputError
from fmu_bearing.interface import COUPLING_OUTPUT_NAMES, JOINT_INPUT_NAMES
from fmu_bearing.parameters import BearingParameters, from_values
from mechanism.cosim.fmpy_logging import fmpy_callbacks, release

INPUTS = JOINT_INPUT_NAMES
COUPLING_OUTPUTS = COUPLING_OUTPUT_NAMES


class ExchangeError(RuntimeError):
    """The bearing component refused a call (error status); the message says why."""


class InProcessEndpoint:
    """The ball-bearing force law called in-process, with the FMU's step semantics."""

    kind = "in-process"

    def __init__(self, parameters: BearingParameters | Mapping[str, float] | None = None,
                 capacity: int | None = None, compiled: bool = True):
        if parameters is None or isinstance(parameters, BearingParameters):
            params = parameters or BearingParameters()
        else:
            params = from_values(parameters)
        self.bearing = BallBearing(params, capacity)
        self.n_balls = self.bearing.n_balls
        # the FMU's life outputs too, from the same accumulator (docs/bearing-life.md)
        self.life = life.LifeAccumulator(life.LoadRatings.of_bearing(params), params.reliability_factor)
        self.sample_names = ("cage_angle", "loaded_balls", "max_ball_load") + tuple(
            f"ball_load_{r + 1}" for r in range(self.n_balls))
        self.calls = 0
        self._loads = [0.0] * self.n_balls
        self._inputs = (0.0,) * 6
        self._cage = float(params.cage_angle_start)
        self._out: tuple = ()
        self._law = None
        if compiled:
            from mechanism.cosim import law_kernel
            self._law, self._law_evaluate = law_kernel.pack_bearing(self.bearing), law_kernel.evaluate
            self._law_out, self._law_loads = np.zeros(10), np.zeros(self.n_balls)

    def initialize(self, inputs: Sequence[float]) -> tuple[float, ...]:
        """Set the start inputs and return the coupling outputs at the start time."""
        self._inputs = tuple(float(x) for x in inputs)
        self._evaluate()
        return self._out[:8]

    def exchange(self, t: float, h: float, inputs: Sequence[float]) -> tuple[float, ...]:
        """Set inputs, advance over [t, t + h] with them held, return the end-of-step coupling outputs."""
        ex, ey, vx, vy, wi, wo = inputs
        if not (math.isfinite(ex + ey + vx + vy + wi + wo) and math.hypot(ex, ey) <= self.bearing.eccentricity_limit):
            try:
                self.bearing.check_inputs(ex, ey, vx, vy, wi, wo)
            except BearingInputError as err:
                raise ExchangeError(str(err)) from None
        self.calls += 1
        self._inputs = (ex, ey, vx, vy, wi, wo)
        self._cage = self.bearing.advance_cage(self._cage, wi, wo, h)
        self._evaluate()
        self.life.add(self._loads, wi, wo, h)
        return self._out[:8]

    def _evaluate(self) -> None:
        ex, ey, vx, vy, wi, wo = self._inputs
        if self._law is None:
            self._out = self.bearing.evaluate(ex, ey, vx, vy, self._cage, wi, wo, self._loads)
        else:   # the compiled second implementation (mechanism.cosim.law_kernel, tested against evaluate)
            self._law_evaluate(self._law, ex, ey, vx, vy, self._cage, wi, wo, self._law_out, self._law_loads)
            self._out = tuple(self._law_out.tolist())
            self._loads[:] = self._law_loads.tolist()

    def sample(self) -> list[float]:
        out = self._out
        if self._law is not None:
            return [self._cage, out[8], out[9], *self._loads]
        return [self._cage, float(out.loaded_balls), out.max_ball_load, *self._loads]

    def life_outputs(self) -> dict[str, float]:
        """The FMU's life outputs (``fmu_bearing.life.LIFE_NAMES``) from the in-process accumulator."""
        return dict(zip(life.LIFE_NAMES, life.output_values(self.life)))

    def get_state(self):
        return (self._cage, self._inputs, self._out, list(self._loads), self.life.state())

    def set_state(self, state) -> None:
        self._cage, self._inputs, self._out, loads, sums = state
        self._loads[:] = loads
        self.life.restore(sums)

    def free_state(self, state) -> None:
        pass

    def close(self) -> None:
        pass


_STATUS = ("OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING")
#: FMI 3.0 output types sampled, in this order: (ctypes element type, suffix of fmpy's fmi3Get<suffix>)
_SAMPLE_TYPES = {"Float64": (ctypes.c_double, "Float64"), "Int32": (ctypes.c_int32, "Int32"),
                 "UInt64": (ctypes.c_uint64, "UInt64"), "Boolean": (ctypes.c_bool, "Boolean")}
#: causalities a start value may be given for (FMI 3.0 adds structural parameters such as n_balls)
_SETTABLE = ("parameter", "structuralParameter", "input")


#: (resolved FMU path, size, mtime, GUID) -> folder it is extracted into, shared by every FMU endpoint
_EXTRACTIONS: dict[tuple, str] = {}
_EXTRACTIONS_LOCK = threading.Lock()


def _remove_extractions() -> None:
    for folder in _EXTRACTIONS.values():
        shutil.rmtree(folder, ignore_errors=True)
    _EXTRACTIONS.clear()


def shared_extraction(path: Path, guid: str) -> str:
    """The folder ``path`` (an FMU of ``guid``) is extracted into: one per FMU file and GUID in a process.

    A loaded FMU binary stays mapped (unloading pythonfmu's library with Python running in it is unsafe),
    so a fresh extraction per instance maps another copy of it every time (issue 14: 200 load/unload
    cycles grew the resident memory by 64 MB). The folders are removed at exit; an extraction that fails
    (a full TMPDIR) is removed at once.
    """
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns, guid)
    with _EXTRACTIONS_LOCK:
        folder = _EXTRACTIONS.get(key)
        if folder is not None and os.path.isdir(folder):
            return folder
        from fmpy import extract
        folder = tempfile.mkdtemp(prefix=f"fmu_{path.stem}_")
        try:
            extract(str(path), unzipdir=folder)
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
        if not _EXTRACTIONS:
            atexit.register(_remove_extractions)
        _EXTRACTIONS[key] = folder
        return folder


class _FmuBase:
    """What the FMI 2.0 and FMI 3.0 endpoints share: the FMU's model description and variables checked
    against the joint-component interface, the start values checked, errors with the FMU's last messages,
    FMU state, closing."""

    kind = "fmu"

    def __init__(self, fmu_path: str | Path, start_values: Mapping[str, float] | None, version: str):
        from fmpy import read_model_description

        self.path = Path(fmu_path)
        if not self.path.is_file():
            raise FileNotFoundError(f"FMU not found: {self.path} (build it with `python build_fmu.py`)")
        self.md = read_model_description(str(self.path))
        if not self.md.fmiVersion.startswith(version):
            raise ExchangeError(f"{self.path.name} is an FMI {self.md.fmiVersion} FMU: use fmu_endpoint()")
        self.variables = {v.name: v for v in self.md.modelVariables}
        missing = [n for n in INPUTS + COUPLING_OUTPUTS[:2] if n not in self.variables]
        if missing:
            raise ExchangeError(f"{self.path.name} lacks the variables {missing} a bearing component must have")
        self._start_values = dict(start_values or {})
        self._check_start_values(self._start_values)
        self.coupling_names = tuple(n for n in COUPLING_OUTPUTS if n in self.variables)
        self.messages: list[str] = []
        self.calls = 0
        self._instantiated = False
        n_balls = self.variables.get("n_balls")
        self.n_balls = int(self._start_values.get("n_balls", n_balls.start if n_balls is not None else 0))
        self._unzipdir = shared_extraction(self.path, self.md.guid)

    def _check_start_values(self, values: Mapping[str, float]) -> None:
        """Each start value is a parameter or input of the FMU, of its type and within its declared min/max
        (n_balls beyond the per-ball capacity: the advice names the options that fix it)."""
        for name, value in values.items():
            v = self.variables.get(name)
            if v is None or v.causality not in _SETTABLE:
                params = sorted(n for n, x in self.variables.items() if x.causality in _SETTABLE[:2])
                raise ExchangeError(f"{self.path.name} has no parameter {name!r} (parameters: {', '.join(params)})")
            integer = v.type.startswith(("Integer", "Int", "UInt"))
            if integer and (isinstance(value, bool) or not float(value).is_integer()):
                raise ExchangeError(f"invalid parameter {name} = {value!r}: must be an integer")
            if (integer or v.type in ("Real", "Float64", "Float32")) and not isinstance(value, bool):
                lo, hi = (float(x) if x not in (None, "") else None for x in (v.min, v.max))
                if lo is not None and float(value) < lo:
                    raise ExchangeError(f"invalid parameter {name} = {value!r}: below {self.path.name}'s min {lo:g}")
                if hi is not None and float(value) > hi:
                    advice = (f" (per-ball output capacity; build an FMU with `python build_fmu.py --max-balls "
                              f"{value}` and pass it with --fmu)" if name == "n_balls" else "")
                    raise ExchangeError(f"invalid parameter {name} = {value!r}: above {self.path.name}'s "
                                        f"max {hi:g}{advice}")

    def _message(self, status: int, message: bytes) -> None:
        self.messages.append(f"[{_STATUS[status] if 0 <= status < len(_STATUS) else status}] "
                             f"{message.decode('utf-8', 'replace')}")

    def _fail(self, what: str, err: Exception) -> ExchangeError:
        detail = "; ".join(self.messages[-3:]) or str(err)
        return ExchangeError(f"{self.path.name}: {what} failed: {detail}")

    def _coupling(self) -> tuple[float, ...]:
        out = tuple(self._val_out)
        if len(out) < 8:  # a component without tangent matrices: zeros (only force-held schemes then make sense)
            out = out + (0.0,) * (8 - len(out))
        return out

    def life_outputs(self) -> dict[str, float] | None:
        """The FMU's life outputs now (``fmu_bearing.life.LIFE_NAMES``), None if it has none or cannot say."""
        names = [n for n in life.LIFE_NAMES if n in self.variables]
        if not names or not self._instantiated:
            return None
        get = getattr(self.fmu, "getReal", None) or self.fmu.getFloat64
        try:
            return dict(zip(names, get([self.variables[n].valueReference for n in names])))
        except Exception:
            return None

    def get_state(self):
        try:
            return self.fmu.getFMUState()
        except Exception as err:
            raise self._fail("getFMUState", err) from None

    def set_state(self, state) -> None:
        try:
            self.fmu.setFMUState(state)
        except Exception as err:
            raise self._fail("setFMUState", err) from None

    def free_state(self, state) -> None:
        self.fmu.freeFMUState(state)

    def close(self) -> None:
        """Terminate and free the instance (always safe to call, also after an error)."""
        if self._instantiated:
            try:
                self.fmu.terminate()
            except Exception:
                pass
            try:
                self.fmu.freeInstance()
            except Exception:
                pass
            self._instantiated = False
        if getattr(self, "_callbacks", None) is not None:
            release(self._callbacks)
            self._callbacks = None
        # the extraction is shared (shared_extraction) and removed at exit

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class FmuEndpoint(_FmuBase):
    """An FMI 2.0 bearing FMU driven through fmpy's FMU2Slave, with prebuilt ctypes buffers for the hot path."""

    def __init__(self, fmu_path: str | Path, start_values: Mapping[str, float] | None = None,
                 instance_name: str = "bearing", logging_on: bool = False):
        from fmpy.fmi2 import FMU2Slave

        super().__init__(fmu_path, start_values, "2.")
        # life outputs are run-level figures, read once at the end (life_outputs), not sampled
        self.sample_names = tuple(v.name for v in self.md.modelVariables
                                  if v.causality == "output" and v.name not in self.coupling_names
                                  and v.name not in life.LIFE_NAMES)

        def _log(component, instance, status, category, message):
            self._message(status, message)

        self._callbacks = fmpy_callbacks(_log)   # fmpy's logger proxy, never dangling (fmpy_logging)
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self._unzipdir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=instance_name)
        n_real = ctypes.c_uint * 6
        self._vr_in = n_real(*(self.variables[n].valueReference for n in INPUTS))
        self._val_in = (ctypes.c_double * 6)()
        nc = len(self.coupling_names)
        self._vr_out = (ctypes.c_uint * nc)(*(self.variables[n].valueReference for n in self.coupling_names))
        self._val_out = (ctypes.c_double * nc)()
        # per-ball outputs beyond the balls present (the FMU's capacity) are always zero: not sampled
        # (the in-process and FMI 3.0 endpoints sample ball_load_1 .. ball_load_n as well)
        present = {f"ball_load_{k + 1}" for k in range(self.n_balls)}
        names = [n for n in self.sample_names if not n.startswith("ball_load_") or n in present]
        self._real_samples = [n for n in names if self.variables[n].type == "Real"]
        self._int_samples = [n for n in names if self.variables[n].type == "Integer"]
        self._bool_samples = [n for n in names if self.variables[n].type == "Boolean"]
        self.sample_names = tuple(self._real_samples + self._int_samples + self._bool_samples)
        # a sampled step fetches the coupling outputs and the real samples in one fmi2GetReal
        # (exchange_sampled); _val_out and _val_sr are views into the one buffer
        nr = len(self._real_samples)
        self._vr_all = (ctypes.c_uint * (nc + nr))(*self._vr_out, *(self.variables[n].valueReference
                                                                    for n in self._real_samples))
        self._val_all = (ctypes.c_double * (nc + nr))()
        self._val_out = (ctypes.c_double * nc).from_buffer(self._val_all)
        self._val_sr = (ctypes.c_double * nr).from_buffer(self._val_all, nc * ctypes.sizeof(ctypes.c_double))
        self._vr_sr = (ctypes.c_uint * nr)(*self._vr_all[nc:])
        self._vr_si = (ctypes.c_uint * len(self._int_samples))(*(self.variables[n].valueReference
                                                                   for n in self._int_samples))
        self._val_si = (ctypes.c_int * len(self._int_samples))()
        self._vr_sb = (ctypes.c_uint * len(self._bool_samples))(*(self.variables[n].valueReference
                                                                   for n in self._bool_samples))
        self._val_sb = (ctypes.c_int * len(self._bool_samples))()
        # the hot path calls the FMU's C functions directly (fmpy's per-call wrapper only adds Python
        # overhead when no call logger is set) and checks the status itself (> fmi2Warning is an error)
        functions = self.fmu._functions
        self._c_set, self._c_step, self._c_get, self._c_get_int, self._c_get_bool = (
            functions[f] for f in ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean"))
        self._sampled = False     # _val_sr holds this step's real samples (exchange_sampled)
        nr, ni = len(self._val_sr), len(self._val_si)
        self._views = (np.ctypeslib.as_array(self._val_sr) if nr else None,     # for sample_into
                       np.ctypeslib.as_array(self._val_si) if ni else None,
                       np.ctypeslib.as_array(self._val_sb) if len(self._val_sb) else None, nr, nr + ni)
        self._pad = (0.0,) * (8 - nc) if nc < 8 else ()
        self._slice_out = slice(0, nc)

    def initialize(self, inputs: Sequence[float]) -> tuple[float, ...]:
        """Instantiate, apply start values and start inputs, initialise; return the coupling outputs at t0."""
        fmu = self.fmu
        try:
            fmu.instantiate(callbacks=self._callbacks, loggingOn=True)
            self._instantiated = True
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            for name, value in self._start_values.items():
                v = self.variables[name]
                if v.type == "Integer":
                    fmu.setInteger([v.valueReference], [int(value)])
                elif v.type == "Boolean":
                    fmu.setBoolean([v.valueReference], [bool(value)])
                else:
                    fmu.setReal([v.valueReference], [float(value)])
            self._set_inputs(inputs)
            fmu.exitInitializationMode()
            fmu.fmi2GetReal(fmu.component, self._vr_out, len(self._vr_out), self._val_out)
        except Exception as err:
            raise self._fail("initialisation", err) from None
        return self._coupling()

    def _set_inputs(self, inputs: Sequence[float]) -> None:
        val = self._val_in
        val[0], val[1], val[2], val[3], val[4], val[5] = inputs
        self.fmu.fmi2SetReal(self.fmu.component, self._vr_in, 6, val)

    def _step(self, t: float, h: float, inputs: Sequence[float], vrs, values) -> None:
        """Set the inputs, doStep over [t, t + h], get ``values`` of ``vrs`` (the C functions, status checked)."""
        val, c = self._val_in, self.fmu.component
        val[0], val[1], val[2], val[3], val[4], val[5] = inputs
        self._sampled = False
        status = self._c_set(c, self._vr_in, 6, val)
        if status <= 1:
            status = self._c_step(c, t, h, 1)
            if status <= 1:
                status = self._c_get(c, vrs, len(vrs), values)
        if status > 1:
            raise self._fail(f"doStep at t = {t:.9g} s", ExchangeError(f"status {_STATUS[min(status, 5)]}"))
        self.calls += 1

    def exchange(self, t: float, h: float, inputs: Sequence[float]) -> tuple[float, ...]:
        self._step(t, h, inputs, self._vr_out, self._val_out)
        return (*self._val_out, *self._pad)

    def exchange_sampled(self, t: float, h: float, inputs: Sequence[float]) -> tuple[float, ...]:
        """``exchange``, fetching the real samples of the end of the step in the same fmi2GetReal (the
        next ``sample`` uses them)."""
        self._step(t, h, inputs, self._vr_all, self._val_all)
        self._sampled = True
        return (*self._val_out, *self._pad)

    def set_state(self, state) -> None:
        self._sampled = False
        super().set_state(state)

    def sample(self) -> list[float]:
        """The non-coupling outputs at the end of the last step, as floats in the order of ``sample_names``."""
        self.sample_values()
        return [*self._val_sr, *map(float, self._val_si), *(float(bool(x)) for x in self._val_sb)]

    def sample_values(self) -> None:
        """Fetch the non-coupling outputs into the ctypes buffers (reals already there after
        ``exchange_sampled``)."""
        c, status = self.fmu.component, 0
        if self._real_samples and not self._sampled:
            status = self._c_get(c, self._vr_sr, len(self._vr_sr), self._val_sr)
        self._sampled = False
        if self._int_samples and status <= 1:
            status = self._c_get_int(c, self._vr_si, len(self._vr_si), self._val_si)
        if self._bool_samples and status <= 1:
            status = self._c_get_bool(c, self._vr_sb, len(self._vr_sb), self._val_sb)
        if status > 1:
            raise self._fail("sampling the outputs", ExchangeError(f"status {_STATUS[min(status, 5)]}"))

    def sample_into(self, out: np.ndarray) -> None:
        """``out[:] = sample()`` without the list: the values copied from the ctypes buffers through numpy
        views (the master's recorded row; columns in the order of ``sample_names``)."""
        self.sample_values()
        real, integer, boolean, nr, ni = self._views
        if real is not None:
            out[:nr] = real
        if integer is not None:
            out[nr:ni] = integer
        if boolean is not None:
            out[ni:] = boolean != 0


class Fmu3Endpoint(_FmuBase):
    """An FMI 3.0 bearing FMU driven through fmpy's FMU3Slave, with prebuilt ctypes buffers for the hot path."""

    def __init__(self, fmu_path: str | Path, start_values: Mapping[str, float] | None = None,
                 instance_name: str = "bearing"):
        from fmpy.fmi3 import FMU3Slave

        super().__init__(fmu_path, start_values, "3.")

        self.fmu = FMU3Slave(guid=self.md.guid, unzipDirectory=self._unzipdir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=instance_name)
        # Hot path: the six inputs and the coupling outputs, as ctypes arrays built once.
        self._vr_in = (ctypes.c_uint32 * 6)(*(self.variables[n].valueReference for n in INPUTS))
        self._val_in = (ctypes.c_double * 6)()
        nc = len(self.coupling_names)
        self._vr_out = (ctypes.c_uint32 * nc)(*(self.variables[n].valueReference for n in self.coupling_names))
        self._val_out = (ctypes.c_double * nc)()
        self._step_flags = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double()]
        self._step_refs = [ctypes.byref(x) for x in self._step_flags]
        self._structural = {v.valueReference: self._start_values.get(v.name, v.start)
                            for v in self.md.modelVariables if v.causality == "structuralParameter"}
        self._samples = self._sample_plan()
        self.sample_names = tuple(name for group in self._samples for name in group[3])

    def _size(self, v) -> int:
        """Number of elements of variable ``v`` for the structural parameters as they will be set."""
        size = 1
        for d in v.dimensions:
            size *= int(d.start) if d.start is not None else int(self._structural[d.valueReference])
        return size

    def _sample_plan(self) -> list[tuple]:
        """[(getter suffix, vr array, value buffer, column names)] per type, in the order Float64, Int32,
        UInt64, Boolean (the FMI 2.0 endpoint's order: Reals, then Integers, then Booleans)."""
        plan = []
        # life outputs are run-level figures, read once at the end (life_outputs), not sampled (as FmuEndpoint)
        outputs = [v for v in self.md.modelVariables if v.causality == "output" and v.name not in self.coupling_names
                   and v.name not in life.LIFE_NAMES]
        for type_name, (ctype, suffix) in _SAMPLE_TYPES.items():
            names, vrs, count = [], [], 0
            for v in outputs:
                if v.type != type_name:
                    continue
                n = self._size(v)
                if v.dimensions:  # ball_loads -> ball_load_1 .. ball_load_n
                    stem = v.name[:-1] if v.name.endswith("s") else v.name
                    names += [f"{stem}_{k + 1}" for k in range(n)]
                else:
                    names.append(v.name)
                vrs.append(v.valueReference)
                count += n
            if vrs:
                plan.append((suffix, (ctypes.c_uint32 * len(vrs))(*vrs), (ctype * count)(), tuple(names)))
        return plan

    def _log(self, env, status, category, message):
        self._message(status, message)

    def initialize(self, inputs: Sequence[float]) -> tuple[float, ...]:
        """Instantiate, set structural parameters (Configuration Mode), the other start values and the start
        inputs (Initialization Mode), initialise; return the coupling outputs at t0."""
        fmu = self.fmu
        try:
            fmu.instantiate(loggingOn=True, logMessage=self._log)
            self._instantiated = True
            structural = {k: v for k, v in self._start_values.items()
                          if self.variables[k].causality == "structuralParameter"}
            if structural:
                fmu.enterConfigurationMode()
                self._set_values(structural)
                fmu.exitConfigurationMode()
            fmu.enterInitializationMode(startTime=0.0)
            self._set_values({k: v for k, v in self._start_values.items() if k not in structural})
            self._set_inputs(inputs)
            fmu.exitInitializationMode()
            fmu.fmi3GetFloat64(fmu.component, self._vr_out, len(self._vr_out), self._val_out, len(self._val_out))
        except Exception as err:
            raise self._fail("initialisation", err) from None
        return self._coupling()

    def _set_values(self, values: Mapping[str, float]) -> None:
        fmu = self.fmu
        for name, value in values.items():
            v = self.variables[name]
            setter = getattr(fmu, f"set{v.type}")
            convert = float if v.type.startswith("Float") else bool if v.type == "Boolean" else int
            setter([v.valueReference], [convert(value)])

    def _set_inputs(self, inputs: Sequence[float]) -> None:
        val = self._val_in
        val[0], val[1], val[2], val[3], val[4], val[5] = inputs
        self.fmu.fmi3SetFloat64(self.fmu.component, self._vr_in, 6, val, 6)

    def exchange(self, t: float, h: float, inputs: Sequence[float]) -> tuple[float, ...]:
        """Set inputs, advance over [t, t + h] with them held, return the end-of-step coupling outputs."""
        fmu = self.fmu
        try:
            self._set_inputs(inputs)
            fmu.fmi3DoStep(fmu.component, t, h, False, *self._step_refs)
            fmu.fmi3GetFloat64(fmu.component, self._vr_out, len(self._vr_out), self._val_out, len(self._val_out))
        except Exception as err:
            raise self._fail(f"doStep at t = {t:.9g} s", err) from None
        self.calls += 1
        return self._coupling()

    def sample(self) -> list[float]:
        """The non-coupling outputs, as floats in the order of ``sample_names`` (arrays expanded)."""
        fmu, out = self.fmu, []
        for suffix, vrs, values, _ in self._samples:
            getattr(fmu, f"fmi3Get{suffix}")(fmu.component, vrs, len(vrs), values, len(values))
            out += [float(x) for x in values]
        return out


def fmu_endpoint(fmu_path: str | Path, start_values: Mapping[str, float] | None = None,
                 instance_name: str = "bearing") -> FmuEndpoint | Fmu3Endpoint:
    """The endpoint for a bearing FMU, chosen from its modelDescription's fmiVersion (2.0 or 3.0)."""
    from fmpy import read_model_description

    path = Path(fmu_path)
    if not path.is_file():
        raise FileNotFoundError(f"FMU not found: {path} (build it with `python build_fmu.py`)")
    version = read_model_description(str(path), validate=False).fmiVersion
    if version.startswith("3."):
        return Fmu3Endpoint(path, start_values, instance_name)
    if version.startswith("2."):
        return FmuEndpoint(path, start_values, instance_name)
    raise ExchangeError(f"{path.name}: FMI version {version} is not supported (2.0 and 3.0 are)")
