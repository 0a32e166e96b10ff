"""DRAFT (moves into mechanism/cosim/ once the restructuring lands): the master's endpoint for an FMI 3.0 bearing FMU.

``Fmu3Endpoint`` drives a BallBearing3 FMU (or any FMI 3.0 joint component with the joint-component
interface of ``fmu_bearing.interface``) through fmpy's low-level ``FMU3Slave`` API, with the interface and
step semantics of the FMI 2.0 ``FmuEndpoint``: set the 6 inputs, ``fmi3DoStep``, get the coupling outputs.
Array outputs (``ball_loads``, sized by the structural parameter ``n_balls``) are sampled element-wise as
``ball_load_1 .. ball_load_n``, the names the FMI 2.0 FMU and the in-process endpoint use.

``fmu_endpoint(path, ...)`` picks ``FmuEndpoint`` or ``Fmu3Endpoint`` from the modelDescription's fmiVersion.
"""
from __future__ import annotations

import ctypes
import shutil
from pathlib import Path
from typing import Mapping, Sequence

from mechanism.exchange import COUPLING_OUTPUTS, INPUTS, ExchangeError, FmuEndpoint

_STATUS = ("OK", "WARNING", "DISCARD", "ERROR", "FATAL")
#: fmpy type name -> (ctypes element type, fmpy FMU3Slave getter suffix, conversion to the sampled float)
_SAMPLE_TYPES = {"Float64": (ctypes.c_double, "Float64"), "Int32": (ctypes.c_int32, "Int32"),
                 "UInt64": (ctypes.c_uint64, "UInt64"), "Boolean": (ctypes.c_bool, "Boolean")}
_PARAMETER_CAUSALITIES = ("parameter", "structuralParameter", "input")


def fmi_version(fmu_path: str | Path) -> str:
    """The fmiVersion attribute of an FMU's modelDescription.xml ("2.0" or "3.0")."""
    from fmpy import read_model_description
    return read_model_description(str(fmu_path), validate=False).fmiVersion


def fmu_endpoint(fmu_path: str | Path, start_values: Mapping[str, float] | None = None,
                 instance_name: str = "bearing"):
    """The endpoint for a bearing FMU: FMI 2.0 (``FmuEndpoint``) or FMI 3.0 (``Fmu3Endpoint``)."""
    path = Path(fmu_path)
    if not path.is_file():
        raise FileNotFoundError(f"FMU not found: {path} (build it with `python build_fmu.py`)")
    version = fmi_version(path)
    if version.startswith("3."):
        return Fmu3Endpoint(path, start_values, instance_name)
    if version.startswith("2."):
        return FmuEndpoint(path, start_values, instance_name)
    raise ExchangeError(f"{path.name}: FMI version {version} is not supported (2.0 and 3.0 are)")


class Fmu3Endpoint:
    """An FMI 3.0 bearing FMU driven through fmpy's FMU3Slave, with prebuilt ctypes buffers for the hot path."""

    kind = "fmu"

    def __init__(self, fmu_path: str | Path, start_values: Mapping[str, float] | None = None,
                 instance_name: str = "bearing"):
        from fmpy import extract, read_model_description
        from fmpy.fmi3 import FMU3Slave

        self.path = Path(fmu_path)
        if not self.path.is_file():
            raise FileNotFoundError(f"FMU not found: {self.path} (build it with `python build_fmu.py`)")
        self.md = read_model_description(str(self.path))
        if not self.md.fmiVersion.startswith("3."):
            raise ExchangeError(f"{self.path.name} is an FMI {self.md.fmiVersion} FMU: use FmuEndpoint")
        self.variables = {v.name: v for v in self.md.modelVariables}
        missing = [n for n in INPUTS + COUPLING_OUTPUTS[:2] if n not in self.variables]
        if missing:
            raise ExchangeError(f"{self.path.name} lacks the variables {missing} a bearing component must have")
        self._start_values = dict(start_values or {})
        for name in self._start_values:
            v = self.variables.get(name)
            if v is None or v.causality not in _PARAMETER_CAUSALITIES:
                params = sorted(n for n, x in self.variables.items() if x.causality in _PARAMETER_CAUSALITIES[:2])
                raise ExchangeError(f"{self.path.name} has no parameter {name!r} (parameters: {', '.join(params)})")
        self.coupling_names = tuple(n for n in COUPLING_OUTPUTS if n in self.variables)
        self.messages: list[str] = []
        self.calls = 0
        self._instantiated = False
        self._unzipdir = extract(str(self.path))
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
        n_balls = self.variables.get("n_balls")
        self.n_balls = int(self._start_values.get("n_balls", n_balls.start if n_balls is not None else 0))

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
        outputs = [v for v in self.md.modelVariables if v.causality == "output" and v.name not in self.coupling_names]
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
        self.messages.append(f"[{_STATUS[status] if 0 <= status < len(_STATUS) else status}] "
                             f"{message.decode('utf-8', 'replace')}")

    def _fail(self, what: str, err: Exception) -> ExchangeError:
        detail = "; ".join(self.messages[-3:]) or str(err)
        return ExchangeError(f"{self.path.name}: {what} failed: {detail}")

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

    def _coupling(self) -> tuple[float, ...]:
        out = tuple(self._val_out)
        if len(out) < 8:  # a component without tangent matrices: zeros (only force-held schemes then make sense)
            out = out + (0.0,) * (8 - len(out))
        return out

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
        shutil.rmtree(self._unzipdir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
