"""The SSP in other FMI tools: fmpy (fmpy.ssp), libcosim (libcosimpy) and ecos (ecospy).

All three are fixed-step Jacobi masters running the two FMUs; ``simulate_with`` checks the archive
first and returns the recorded outputs as arrays.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from mechanism import ssp as sm

TOOLS = ("fmpy", "libcosim", "ecos")
#: outputs recorded by ``simulate_with`` (component.variable)
RECORD = ("mechanism.e_x", "mechanism.e_y", "mechanism.v_x", "mechanism.v_y", "mechanism.slider_x",
          "mechanism.slider_v", "mechanism.slider_a", "mechanism.crank_angle", "mechanism.crank_moment",
          "bearing.F_x", "bearing.F_y", "bearing.loaded_balls", "bearing.max_ball_load")


def simulate_with(tool: str, ssp: str | Path, parameter_set: str | None = None, step: float = sm.DEFAULT_STEP,
                  t_end: float = 0.01, record=RECORD) -> dict[str, np.ndarray]:
    """Run the SSP in ``tool`` (fmpy, libcosim, ecos) with a fixed step; the archive is checked first.

    Returns "time" (the end of each step, h ... t_end) and each recorded output at those times.
    """
    if tool not in TOOLS:
        raise ValueError(f"unknown tool {tool!r}; choose from {', '.join(TOOLS)}")
    with sm.load_ssp(ssp, parameter_set) as system:
        name = system.check_parameter_set(parameter_set)
        values = system.parameters(name)
    n_steps = int(round(t_end / step))
    runner = {"fmpy": _run_fmpy, "libcosim": _run_libcosim, "ecos": _run_ecos}[tool]
    out = runner(str(ssp), name, values, step, n_steps, list(record))
    out["time"] = step * np.arange(1, n_steps + 1)
    return out


def _run_fmpy(ssp, name, values, step, n_steps, record):
    """fmpy.ssp.simulate_ssp: fixed-step Jacobi; it applies no parameter binding itself, so the set is passed."""
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import Parameter, ParameterSet

    pset = ParameterSet(name=name)
    for component, params in values.items():
        for pname, value in params.items():
            pset.parameters.append(Parameter(name=f"{component}.{pname}", value=value))
    # simulate_ssp loops while time < stop_time with time += step: stop half a step early for n_steps steps
    result = simulate_ssp(ssp, stop_time=(n_steps - 0.5) * step, step_size=step, parameter_set=pset)
    if len(result) != n_steps:
        raise RuntimeError(f"fmpy.ssp made {len(result)} steps, expected {n_steps}")
    return {k: np.asarray(result[k], float) for k in record}   # each row: the values after the step


def _run_libcosim(ssp, name, values, step, n_steps, record):
    """libcosim (libcosimpy): fixed-step Jacobi. Through libcosimc it applies each component's first
    binding (the default set); another set's values are applied as initial values."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    step_ns = int(round(step * 1e9))
    if abs(step_ns * 1e-9 - step) > 1e-15:
        raise ValueError(f"libcosim counts time in ns: step {step!r} s is not a whole number of ns")
    execution = CosimExecution.from_ssp_file(str(ssp), step_size=step_ns)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    index, refs, kinds = {}, {}, {}
    for component in {k.split(".")[0] for k in record} | set(values):
        index[component] = execution.slave_index_from_instance_name(component)
        for v in execution.slave_variables(index[component]):
            refs[f"{component}.{v.name.decode()}"] = v.reference
            kinds[f"{component}.{v.name.decode()}"] = v.type
    if name != sm.DEFAULT_PARAMETER_SET:
        for component, params in values.items():
            for pname, value in params.items():
                key, i = f"{component}.{pname}", index[component]
                if isinstance(value, bool):
                    execution.boolean_initial_value(i, refs[key], value)
                elif isinstance(value, int):
                    execution.integer_initial_value(i, refs[key], value)
                else:
                    execution.real_initial_value(i, refs[key], float(value))
    from libcosimpy.CosimEnums import CosimVariableType
    out = {k: np.zeros(n_steps) for k in record}
    for k in range(n_steps):
        if not execution.step(1):
            raise RuntimeError(f"libcosim: step {k + 1} failed")
        for key in record:
            component = key.split(".")[0]
            if kinds[key] == CosimVariableType.INTEGER.value:
                out[key][k] = observer.last_integer_values(index[component], [refs[key]])[0]
            else:
                out[key][k] = observer.last_real_values(index[component], [refs[key]])[0]
    return out


def _run_ecos(ssp, name, values, step, n_steps, record):
    """ecos (ecospy): fixed-step Jacobi; applies the named parameter set of the SSP."""
    from ecospy import EcosSimulation
    from ecospy.lib import EcosLib

    EcosLib.set_log_level("err")
    sim = EcosSimulation(step_size=step, ssp_path=str(ssp))
    try:
        sim.init(parameter_set=name)
        ids = [k.replace(".", "::", 1) for k in record]
        ints = {k for k in record if k.endswith("loaded_balls")}
        out = {k: np.zeros(n_steps) for k in record}
        for k in range(n_steps):
            sim.step()
            for key, ident in zip(record, ids):
                out[key][k] = sim.get_integer(ident) if key in ints else sim.get_real(ident)
        sim.terminate()
    finally:
        sim.free()
    return out
