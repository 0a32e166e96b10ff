"""The SSP in other FMI tools: fmpy (fmpy.ssp), libcosim (libcosimpy) and ecos (ecospy).

All three are fixed-step Jacobi masters running the two FMUs; ``simulate_with`` checks the archive
first and returns the recorded outputs as arrays. A named parameter set is the variant SSD ``<name>.ssd``
of the archive; each tool reads it itself (see ``simulate_with``).
"""
from __future__ import annotations

import atexit
import math
from pathlib import Path

import numpy as np

from mechanism import ssp as sm

TOOLS = ("fmpy", "libcosim", "ecos")
#: outputs recorded by ``simulate_with`` (component.variable)
RECORD = ("mechanism.e_x", "mechanism.e_y", "mechanism.v_x", "mechanism.v_y", "mechanism.slider_x",
          "mechanism.slider_v", "mechanism.slider_a", "mechanism.crank_angle", "mechanism.crank_moment",
          "bearing.F_x", "bearing.F_y", "bearing.loaded_balls", "bearing.max_ball_load")


class ToolRunFailed(RuntimeError):
    """A run in another tool failed, diverged or was refused by the bearing; ``result`` holds the rows
    up to the failure (same keys as ``simulate_with``'s result) and ``step`` the failing step (1-based)."""

    def __init__(self, tool: str, step: int, time: float, cause: str, result: dict[str, np.ndarray]):
        super().__init__(f"{tool}: stopped at step {step} (t = {time:.9g} s): {cause}")
        self.tool, self.step, self.time, self.cause, self.result = tool, step, time, cause, result


def simulate_with(tool: str, ssp: str | Path, parameter_set: str | None = None, step: float = sm.DEFAULT_STEP,
                  t_end: float = 0.01, record=RECORD) -> dict[str, np.ndarray]:
    """Run the SSP in ``tool`` (fmpy, libcosim, ecos) with a fixed step; the archive is checked first.

    Each tool reads the parameter set from the SSD itself, none is handed values by us: the default set from
    the archive's SystemStructure.ssd, another from its variant SSD ``<name>.ssd`` (libcosim: the .ssd path
    in the unpacked archive; ecos, which reads only a SystemStructure.ssd: the unpacked archive with the
    variant in its place; fmpy.ssp, which parses bindings but applies none: every binding of the SSD as
    fmpy parses it, in order, passed as its parameter set). Returns "time" (the end of each step,
    h ... t_end) and each recorded output at those times.

    Raises ``ToolRunFailed`` (with the rows before the failure) when the tool fails a step, or when the
    run diverged or the bearing refused steps although the tool went on (``check_run``): a tool that
    ignores a refused doStep would otherwise report a wrong trajectory as a result.
    """
    if tool not in TOOLS:
        raise ValueError(f"unknown tool {tool!r}; choose from {', '.join(TOOLS)}")
    if not (math.isfinite(step) and math.isfinite(t_end) and 0 < step <= t_end):
        raise ValueError(f"step {step!r} s and end time {t_end!r} s: need 0 < step <= end time, both finite")
    with sm.load_ssp(ssp, parameter_set) as system:
        name = system.check_parameter_set(parameter_set)
        ssd = system.ssd
        bearing_values = system.parameters(name).get(system.component_of_model("BallBearing").name, {})
    n_steps = int(round(t_end / step))
    runner = {"fmpy": _run_fmpy, "libcosim": _run_libcosim, "ecos": _run_ecos}[tool]
    record = list(record)
    out = {k: np.full(n_steps, np.nan) for k in record}
    try:
        done, cause = runner(str(ssp), name, ssd, step, n_steps, record, out), None
    except Exception as err:   # the tool's own error; ``out`` holds the steps it completed
        done, cause = getattr(err, "steps_done", 0), " ".join(f"{type(err).__name__}: {err}".split())
    out["time"] = step * np.arange(1, n_steps + 1)
    bad = check_run(out, bearing_values, done)
    if bad is not None and (cause is None or bad[0] < done):
        done, cause = bad
    if cause is not None:
        raise ToolRunFailed(tool, done + 1, (done + 1) * step, cause, {k: v[:done] for k, v in out.items()})
    return out


def check_run(out: dict[str, np.ndarray], bearing_values: dict, done: int) -> tuple[int, str] | None:
    """(index of the first bad row, cause) or None: a non-finite value, |e| beyond the bearing's
    eccentricity limit (divergence), or a force frozen at its last non-zero value while the inputs change
    (the bearing refused the step and kept its outputs; a tool that ignores the refusal goes on).

    (No force although |e| exceeds the clearance is no sign: damping may cancel the contact force of
    rings that separate, eq. 18.)"""
    from fmu_bearing.parameters import from_values
    p = from_values(bearing_values)
    zero = np.zeros(done)   # a record without e or F: those checks find nothing
    ex, ey = (out.get(f"mechanism.{n}", zero)[:done] for n in ("e_x", "e_y"))
    fx, fy = (out.get(f"bearing.{n}", zero)[:done] for n in ("F_x", "F_y"))
    e, force = np.hypot(ex, ey), np.hypot(fx, fy)
    finite = np.all(np.isfinite(np.column_stack([v[:done] for v in out.values()])), axis=1)
    # Jacobi: the force after step k comes from the inputs held over it, the mechanism's e after step k - 1
    held_x, held_y = np.concatenate(([0.0], ex[:-1])), np.concatenate(([0.0], ey[:-1]))
    frozen = np.zeros(done, dtype=bool)
    frozen[2:] = ((fx[2:] == fx[1:-1]) & (fy[2:] == fy[1:-1]) & (force[2:] != 0.0)
                  & ((held_x[2:] != held_x[1:-1]) | (held_y[2:] != held_y[1:-1])))
    checks = [(~finite, "a non-finite value (the run diverged)"),
              (e > p.effective_eccentricity_limit,
               f"|e| beyond the eccentricity limit {p.effective_eccentricity_limit:g} m (the run diverged)"),
              (frozen, "the bearing force did not change although its inputs did (the bearing refused the step)")]
    firsts = [(int(np.argmax(mask)), cause) for mask, cause in checks if mask.any()]
    if not firsts:
        return None
    k, cause = min(firsts)
    return k, f"{cause}: |e| = {e[k]:.6g} m, |F| = {force[k]:.6g} N"


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


def _run_fmpy(ssp, name, ssd, step, n_steps, record, out) -> int:
    """fmpy.ssp.simulate_ssp: fixed-step Jacobi on the archive's SystemStructure.ssd (variants share its
    components and connections), with the SSD's bindings as fmpy parses them (``fmpy_parameter_set``).

    Each step's values are also taken from the connectors as the next step starts (fmpy's ``do_step``
    wrapped), so the rows before a step that raises are kept. Returns the number of steps made."""
    from fmpy.ssp import simulation

    pset = fmpy_parameter_set(ssp, ssd)
    if pset.name != name:
        raise RuntimeError(f"fmpy.ssp read parameter set {pset.name!r} from {ssd}, expected {name!r}")
    rows, first, original = [], [], simulation.do_step

    def do_step(component, time, step_size):
        if not first:
            first.append(component.name)
        if component.name == first[0] and time > 0.5 * step_size and len(rows) < n_steps:
            values = {f"{c.parent.name}.{c.name}": c.value
                      for comp in component.parent.elements for c in comp.connectors}
            for key in record:
                out[key][len(rows)] = float(values.get(key, np.nan))
            rows.append(time)
        return original(component, time, step_size)

    simulation.do_step = do_step
    try:
        # simulate_ssp loops while time < stop_time with time += step: stop half a step early for n_steps steps
        result = simulation.simulate_ssp(ssp, stop_time=(n_steps - 0.5) * step, step_size=step, parameter_set=pset)
    except Exception as err:
        err.steps_done = len(rows)
        raise
    finally:
        simulation.do_step = original
    if len(result) != n_steps:
        raise RuntimeError(f"fmpy.ssp made {len(result)} steps, expected {n_steps}")
    for k in record:
        out[k][:] = np.asarray(result[k], float)   # each row: the values after the step
    return n_steps


def _run_libcosim(ssp, name, ssd, step, n_steps, record, out) -> int:
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
    for k in range(n_steps):
        if not execution.step(1):
            err = RuntimeError("libcosim refused the step (a component returned an error status)")
            err.steps_done = k
            raise err
        for key in record:
            component = key.split(".")[0]
            if kinds[key] == CosimVariableType.INTEGER.value:
                out[key][k] = observer.last_integer_values(index[component], [refs[key]])[0]
            else:
                out[key][k] = observer.last_real_values(index[component], [refs[key]])[0]
    return n_steps


def _run_ecos(ssp, name, ssd, step, n_steps, record, out) -> int:
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
        k = 0
        try:
            for k in range(n_steps):
                sim.step()
                for key, ident in zip(record, ids):
                    out[key][k] = sim.get_integer(ident) if key in ints else sim.get_real(ident)
        except Exception as err:
            err.steps_done = k
            raise
        sim.terminate()
    finally:
        sim.free()
    return n_steps
