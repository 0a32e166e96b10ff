"""The SSP in other FMI tools: fmpy (fmpy.ssp), libcosim (libcosimpy) and ecos (ecospy).

All three are fixed-step Jacobi masters running the two FMUs; ``simulate_with`` checks the archive
first and returns the recorded outputs as arrays. A named parameter set is the variant SSD ``<name>.ssd``
of the archive; each tool reads it itself (see ``simulate_with``).
"""
from __future__ import annotations

import atexit
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

    Each tool reads the parameter set from the SSD itself, none is handed values by us: the default set from
    the archive's SystemStructure.ssd, another from its variant SSD ``<name>.ssd`` (libcosim: the .ssd path
    in the unpacked archive; ecos, which reads only a SystemStructure.ssd: the unpacked archive with the
    variant in its place; fmpy.ssp, which parses bindings but applies none: every binding of the SSD as
    fmpy parses it, in order, passed as its parameter set). Returns "time" (the end of each step,
    h ... t_end) and each recorded output at those times.
    """
    if tool not in TOOLS:
        raise ValueError(f"unknown tool {tool!r}; choose from {', '.join(TOOLS)}")
    with sm.load_ssp(ssp, parameter_set) as system:
        name = system.check_parameter_set(parameter_set)
        ssd = system.ssd
    n_steps = int(round(t_end / step))
    runner = {"fmpy": _run_fmpy, "libcosim": _run_libcosim, "ecos": _run_ecos}[tool]
    out = runner(str(ssp), name, ssd, step, n_steps, list(record))
    out["time"] = step * np.arange(1, n_steps + 1)
    return out


def _unpacked(ssp: str, ssd: str | None = None) -> Path:
    """The archive unpacked into a temporary folder (removed at exit); with ``ssd``, that SSD also replaces
    the folder's SystemStructure.ssd (for tools that read no other SSD)."""
    import shutil
    import tempfile
    import zipfile
    folder = Path(tempfile.mkdtemp(prefix="ssp_variant_"))
    atexit.register(shutil.rmtree, folder, True)
    with zipfile.ZipFile(ssp) as z:
        z.extractall(folder)   # load_ssp has checked the members
    if ssd is not None and ssd != sm.SSD_IN_ARCHIVE:
        shutil.copyfile(folder / ssd, folder / sm.SSD_IN_ARCHIVE)
    return folder


def fmpy_parameter_set(ssp: str, ssd: str = sm.SSD_IN_ARCHIVE):
    """fmpy's ParameterSet of an SSD of the archive: every ParameterBinding as fmpy.ssp parses it, applied in
    order (SSP 1.0), each value converted to the type its .ssv declares (fmpy.ssp applies no binding itself,
    and its set_value turns any Boolean text, "false" included, into true)."""
    import zipfile
    from fmpy.ssp.ssd import Parameter, ParameterSet, handle_system, ns
    from lxml import etree

    with zipfile.ZipFile(ssp) as z:
        root = etree.parse(z.open(ssd)).getroot()
    system = handle_system(root.find("ssd:System", namespaces=ns), filename=ssp)
    convert = {"Real": float, "Integer": int, "Boolean": lambda text: text.strip().lower() in ("true", "1")}
    values, names = {}, []
    for component in system.elements:
        for binding in component.parameterBindings:
            for pset in binding.parameterValues:
                names.append(pset.name)
                for p in pset.parameters:
                    values[f"{component.name}.{p.name}"] = convert.get(p.type, str)(p.value)
    name = names[-1] if names else None
    return ParameterSet(name=name, parameters=[Parameter(name=k, value=v) for k, v in values.items()])


def _run_fmpy(ssp, name, ssd, step, n_steps, record):
    """fmpy.ssp.simulate_ssp: fixed-step Jacobi on the archive's SystemStructure.ssd (variants share its
    components and connections), with the SSD's bindings as fmpy parses them (``fmpy_parameter_set``)."""
    from fmpy.ssp.simulation import simulate_ssp

    pset = fmpy_parameter_set(ssp, ssd)
    if pset.name != name:
        raise RuntimeError(f"fmpy.ssp read parameter set {pset.name!r} from {ssd}, expected {name!r}")
    # simulate_ssp loops while time < stop_time with time += step: stop half a step early for n_steps steps
    result = simulate_ssp(ssp, stop_time=(n_steps - 0.5) * step, step_size=step, parameter_set=pset)
    if len(result) != n_steps:
        raise RuntimeError(f"fmpy.ssp made {len(result)} steps, expected {n_steps}")
    return {k: np.asarray(result[k], float) for k in record}   # each row: the values after the step


def _run_libcosim(ssp, name, ssd, step, n_steps, record):
    """libcosim (libcosimpy): fixed-step Jacobi. It reads an archive's SystemStructure.ssd, or the .ssd file
    it is given (a variant, in the unpacked archive), and applies the bindings there."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    step_ns = int(round(step * 1e9))
    if abs(step_ns * 1e-9 - step) > 1e-15:
        raise ValueError(f"libcosim counts time in ns: step {step!r} s is not a whole number of ns")
    source = str(ssp) if ssd == sm.SSD_IN_ARCHIVE else str(_unpacked(ssp) / ssd)
    execution = CosimExecution.from_ssp_file(source, step_size=step_ns)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    index, refs, kinds = {}, {}, {}
    for component in {k.split(".")[0] for k in record}:
        index[component] = execution.slave_index_from_instance_name(component)
        for v in execution.slave_variables(index[component]):
            refs[f"{component}.{v.name.decode()}"] = v.reference
            kinds[f"{component}.{v.name.decode()}"] = v.type
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


def _run_ecos(ssp, name, ssd, step, n_steps, record):
    """ecos (ecospy): fixed-step Jacobi. It reads only a SystemStructure.ssd (of an archive or a folder) and
    applies the bindings whose set is named at init (none without a name): a variant is run from the
    unpacked archive with the variant as its SystemStructure.ssd."""
    from ecospy import EcosSimulation
    from ecospy.lib import EcosLib

    EcosLib.set_log_level("err")
    source = str(ssp) if ssd == sm.SSD_IN_ARCHIVE else str(_unpacked(ssp, ssd))
    sim = EcosSimulation(step_size=step, ssp_path=source)
    try:
        sim.init(parameter_set=name)
        ids = [k.replace(".", "::", 1) for k in record]
        ints = {k for k in record if k.endswith(("loaded_balls", "n_balls"))}
        out = {k: np.zeros(n_steps) for k in record}
        for k in range(n_steps):
            sim.step()
            for key, ident in zip(record, ids):
                out[key][k] = sim.get_integer(ident) if key in ints else sim.get_real(ident)
        sim.terminate()
    finally:
        sim.free()
    return out
