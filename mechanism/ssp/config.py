"""Our master on an SSP: ``run --ssp FILE --parameter-set NAME`` maps the archive onto a ``RunConfig``.

Bearing parameters -> ``settings``, rpm and gravity -> the slider-crank, the BallBearing FMU from the
archive, so that our master (in-process mechanism, BallBearing FMU) runs on exactly the values the
other tools get.
"""
from __future__ import annotations

import argparse
import atexit
from dataclasses import fields
from pathlib import Path


from mechanism import ssp as sm
from mechanism.systems.slider_crank import SliderCrankParameters

DEFAULT_ARCHIVE = Path("dist") / sm.ARCHIVE_NAME
#: ``run`` options that an SSP replaces (its parameters and FMU come from the archive): name -> default
_REPLACED_BY_SSP = {"rpm": 1200.0, "balls": None, "gravity": False, "settings": [], "fmu": None, "joint": "bearing"}


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
    from mechanism.run import RunConfig
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
