"""The SSP on the command line, with our master and with other FMI tools.

Subcommands (registered by ``register``):

* ``ssp-generate``: write ssp/ (the SSD and the .ssv files) from the dataclass defaults;
  ``--check`` only compares and fails if the committed files drifted;
* ``ssp-pack``: build the two FMUs and pack dist/SliderCrankBearing.ssp (SSD, .ssv files, FMUs),
  checked by ``ssp_model.load_ssp`` before it is written;
* ``ssp-simulate``: run the .ssp in another FMI tool: ``fmpy`` (fmpy.ssp), ``libcosim``
  (libcosimpy) or ``ecos`` (ecospy), all fixed-step Jacobi masters running the two FMUs, and
  write a CSV. A named parameter set is the variant SSD ``<name>.ssd`` of the archive; each tool
  reads it itself (see ``simulate_with``).

``add_ssp_arguments`` adds ``--ssp FILE --parameter-set NAME`` to the ``run`` subcommand;
``config_from_ssp_args`` maps the SSP onto ``RunConfig`` (bearing parameters -> ``settings``,
rpm and gravity -> the slider-crank, the BallBearing FMU from the archive), so that
``python -m mechanism run --ssp dist/SliderCrankBearing.ssp --parameter-set NAME`` runs our master
(in-process mechanism, BallBearing FMU) on exactly the values the other tools get.
"""
from __future__ import annotations

import argparse
import atexit
import csv
import sys
from dataclasses import fields
from pathlib import Path

import numpy as np

from . import ssp_model as sm
from .slider_crank import SliderCrankParameters

DEFAULT_ARCHIVE = Path("dist") / sm.ARCHIVE_NAME
TOOLS = ("fmpy", "libcosim", "ecos")
#: outputs recorded by ``simulate_with`` (component.variable)
RECORD = ("mechanism.e_x", "mechanism.e_y", "mechanism.v_x", "mechanism.v_y", "mechanism.slider_x",
          "mechanism.slider_v", "mechanism.slider_a", "mechanism.crank_angle", "mechanism.crank_moment",
          "bearing.F_x", "bearing.F_y", "bearing.loaded_balls", "bearing.max_ball_load")
#: ``run`` options that an SSP replaces (its parameters and FMU come from the archive): name -> default
_REPLACED_BY_SSP = {"rpm": 1200.0, "balls": None, "gravity": False, "settings": [], "fmu": None, "joint": "bearing"}


# ------------------------------------------------------------------------------------------------
# Our master on an SSP
# ------------------------------------------------------------------------------------------------
def add_ssp_arguments(parser: argparse.ArgumentParser) -> None:
    """``--ssp FILE`` and ``--parameter-set NAME`` (for the ``run`` subcommand)."""
    parser.add_argument("--ssp", default=None, metavar="FILE",
                        help="take the FMU, connections and parameters from this SSP archive "
                             f"(e.g. {DEFAULT_ARCHIVE}; build it with `python -m mechanism ssp-pack`)")
    parser.add_argument("--parameter-set", default=None, metavar="NAME",
                        help=f"named parameter set of the SSP: the variant SSD NAME.ssd of the archive (default: "
                             f"the default SSD's, {sm.DEFAULT_PARAMETER_SET}; sets: "
                             f"{', '.join(s.name for s in sm.PARAMETER_SETS)})")


def master_parameters(system: sm.SspSystem, parameter_set: str | None = None) -> tuple[str, dict, dict, sm.Component]:
    """(set name, slider-crank values, bearing values, bearing component) for our master.

    Checks that the SSD wires the two components as the master couples them: the bearing's six inputs
    from the mechanism's outputs of the same name, the force and tangent matrices back.
    """
    name = system.check_parameter_set(parameter_set)
    mech = system.component_of_model("SliderCrank")
    bear = system.component_of_model("BallBearing")
    have = {(c.start_element, c.start_connector, c.end_element, c.end_connector) for c in system.connections}
    wanted = [(mech.name, n, bear.name, n) for n in sm.BEARING_INPUTS]
    wanted += [(bear.name, n, mech.name, n) for n in sm.COUPLING_OUTPUTS]
    missing = [f"{a}.{b} -> {c}.{d}" for a, b, c, d in wanted if (a, b, c, d) not in have]
    if missing:
        raise sm.SspError(system.file, "Connections", "our master couples the mechanism and the bearing "
                                                      f"through these connections, which are missing: {', '.join(missing)}")
    values = system.parameters(name)
    return name, values[mech.name], values[bear.name], bear


def config_from_ssp(path: str | Path, parameter_set: str | None = None, **options):
    """(RunConfig, SspSystem) for the SSP's parameter set; ``options``: the remaining RunConfig fields
    (revs, mode, step, ...). Close the SspSystem after the run (it holds the unpacked FMU)."""
    from .run import RunConfig
    system = sm.load_ssp(path, parameter_set)
    try:
        name, mech, bearing, bear = master_parameters(system, parameter_set)
        defaults = SliderCrankParameters()
        params = SliderCrankParameters(**mech)
        for f in fields(SliderCrankParameters):
            if f.name not in ("rpm", "gravity") and getattr(params, f.name) != getattr(defaults, f.name):
                mech_comp = system.component_of_model("SliderCrank")
                raise sm.SspError(f"{system.file}!/{mech_comp.parameter_files[name]}", f"Parameter '{f.name}'",
                                  f"value {getattr(params, f.name)!r}: RunConfig carries rpm and gravity only, "
                                  f"so `run --ssp` needs the other slider-crank parameters at their Table 1 "
                                  f"values ({getattr(defaults, f.name)!r}); the SliderCrank FMU takes any value "
                                  f"(`ssp-simulate`)")
        config = RunConfig(rpm=params.rpm, gravity=params.gravity, joint="bearing", settings=dict(bearing),
                           fmu=str(bear.fmu), **options)
    except BaseException:
        system.close()
        raise
    return config, system


def config_from_ssp_args(args):
    """``run --ssp FILE [--parameter-set NAME]``: the RunConfig from the SSP and the other run options.

    The options an SSP replaces (--rpm, --balls, --gravity, --set, --fmu, --joint) must be left at
    their defaults. The unpacked archive is removed at exit.
    """
    changed = [f"--{k.replace('_', '-')}" if k != "settings" else "--set"
               for k, default in _REPLACED_BY_SSP.items() if getattr(args, k, default) != default]
    if changed:
        raise ValueError(f"--ssp takes the parameters and the FMU from the SSP: drop {', '.join(changed)} "
                         f"(or choose another --parameter-set)")
    config, system = config_from_ssp(
        args.ssp, args.parameter_set, revs=args.revs, mode=args.mode, step=args.step,
        output_interval=args.output_interval, scheme=args.scheme, contact_points=args.contact_points,
        method=args.method, rtol=args.rtol, progress=not args.quiet)
    atexit.register(system.close)
    return config


# ------------------------------------------------------------------------------------------------
# Other FMI tools on the SSP
# ------------------------------------------------------------------------------------------------
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


# ------------------------------------------------------------------------------------------------
# Commands
# ------------------------------------------------------------------------------------------------
def cmd_generate(args) -> int:
    if args.check:
        drift = [rel for rel, text in sm.expected_files().items()
                 if not (sm.SOURCE_DIR / rel).is_file() or (sm.SOURCE_DIR / rel).read_text(encoding="utf-8") != text]
        if drift:
            print(f"ssp/ differs from the dataclass defaults in: {', '.join(drift)} "
                  "(run `python -m mechanism ssp-generate`)", file=sys.stderr)
            return 1
        print("ssp/ matches the dataclass defaults")
        return 0
    for path in sm.generate(args.dest):
        print(f"wrote {path}")
    return 0


def build_fmus(out_dir: str | Path, max_balls: int | None = None, verbose: bool = True) -> dict[str, Path]:
    """Build BallBearing.fmu and SliderCrank.fmu into ``out_dir``; {model name: path}."""
    import build_fmu
    kwargs = {} if max_balls is None else {"max_balls": max_balls}
    fmus = dict(build_fmu.build(out_dir, names=["BallBearing"], verbose=verbose, **kwargs))
    fmus["SliderCrank"] = build_fmu.build(out_dir, names=["SliderCrank"], verbose=verbose)["SliderCrank"]
    return fmus


def cmd_pack(args) -> int:
    out = Path(args.out)
    if args.no_build:
        fmus = {m: Path(args.fmu_dir) / f"{m}.fmu" for m in sm.COMPONENTS.values()}
    else:
        fmus = build_fmus(args.fmu_dir, args.max_balls)
    path = sm.pack(out, fmus)
    print(f"packed {path} ({path.stat().st_size / 1024:.0f} kB): default parameter set "
          f"{sm.DEFAULT_PARAMETER_SET} (SystemStructure.ssd), variants "
          f"{', '.join(sm.variant_ssd_name(s.name) for s in sm.PARAMETER_SETS[1:])}")
    return 0


def cmd_simulate(args) -> int:
    with sm.load_ssp(args.ssp, args.parameter_set) as system:
        name = system.check_parameter_set(args.parameter_set)
        rpm = float(system.parameters(name)[system.component_of_model("SliderCrank").name]["rpm"])
    t_end = args.t_end if args.t_end is not None else args.revs * 60.0 / rpm
    result = simulate_with(args.tool, args.ssp, name, args.step, t_end)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    keys = ["time", *RECORD]
    with out.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for row in zip(*(result[k] for k in keys)):
            w.writerow([repr(float(v)) for v in row])
    peak = float(np.max(np.hypot(result["bearing.F_x"], result["bearing.F_y"])))
    emax = float(np.max(np.hypot(result["mechanism.e_x"], result["mechanism.e_y"])))
    print(f"{args.tool}: {name}, {len(result['time'])} steps of {args.step:g} s to t = {t_end:.6g} s; "
          f"max |e| = {emax * 1e6:.3f} µm, peak |F| = {peak:.2f} N; wrote {out}")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("ssp-generate", help="write ssp/ (SSD and .ssv parameter sets) from the dataclass defaults")
    p.add_argument("--dest", default=str(sm.SOURCE_DIR), help="output folder (default: the project's ssp/)")
    p.add_argument("--check", action="store_true", help="only check that ssp/ matches the defaults (exit 1 if not)")
    p.set_defaults(func=cmd_generate)

    p = subparsers.add_parser("ssp-pack", help=f"build the FMUs and pack {DEFAULT_ARCHIVE}")
    p.add_argument("--out", default=str(DEFAULT_ARCHIVE), help=f"archive to write (default {DEFAULT_ARCHIVE})")
    p.add_argument("--fmu-dir", default="dist", help="where the FMUs are built (default dist)")
    p.add_argument("--no-build", action="store_true", help="pack the FMUs already in --fmu-dir")
    p.add_argument("--max-balls", type=int, default=None, help="BallBearing per-ball output capacity")
    p.set_defaults(func=cmd_pack)

    p = subparsers.add_parser("ssp-simulate", help="run the SSP in another FMI tool (fmpy.ssp, libcosim, ecos)")
    p.add_argument("--tool", choices=TOOLS, default="fmpy")
    p.add_argument("--ssp", default=str(DEFAULT_ARCHIVE), help=f"SSP archive (default {DEFAULT_ARCHIVE})")
    p.add_argument("--parameter-set", default=None, metavar="NAME",
                   help="named parameter set: the variant SSD NAME.ssd (default: the default SSD's set)")
    p.add_argument("--step", type=float, default=sm.DEFAULT_STEP, help="fixed communication step [s] (default 1e-5)")
    p.add_argument("--revs", type=float, default=0.2, help="crank revolutions (default 0.2)")
    p.add_argument("--t-end", type=float, default=None, help="end time [s] (instead of --revs)")
    p.add_argument("--out", default="results/ssp/timeseries.csv", help="CSV to write")
    p.set_defaults(func=cmd_simulate)

