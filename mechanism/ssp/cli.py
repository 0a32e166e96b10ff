"""The SSP on the command line, with our master and with other FMI tools.

Subcommands (registered by ``register``):

* ``ssp-generate``: write ssp/ (the SSD and the .ssv files) from the dataclass defaults;
  ``--check`` only compares and fails if the committed files drifted;
* ``ssp-pack``: build the two FMUs and pack dist/SliderCrankBearing.ssp (SSD, .ssv files, FMUs),
  checked by ``ssp_model.load_ssp`` before it is written;
* ``ssp-simulate``: run the .ssp in another FMI tool: ``fmpy`` (fmpy.ssp), ``libcosim``
  (libcosimpy) or ``ecos`` (ecospy), all fixed-step Jacobi masters running the two FMUs, and
  write a CSV.

``add_ssp_arguments`` adds ``--ssp FILE --parameter-set NAME`` to the ``run`` subcommand;
``config_from_ssp_args`` maps the SSP onto ``RunConfig`` (bearing parameters -> ``settings``,
rpm and gravity -> the slider-crank, the BallBearing FMU from the archive), so that
``python -m mechanism run --ssp dist/SliderCrankBearing.ssp --parameter-set NAME`` runs our master
(in-process mechanism, BallBearing FMU) on exactly the values the other tools get.
"""
from __future__ import annotations

import csv
import os
import sys
from pathlib import Path

import numpy as np

from mechanism import ssp as sm

from mechanism.ssp.config import DEFAULT_ARCHIVE
from mechanism.ssp.tools import RECORD, TOOLS, ToolRunFailed, simulate_with


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
    """BallBearing.fmu and SliderCrank.fmu in ``out_dir``, each built unless the one there was built from the
    current sources with the same options (``build_fmu.is_fresh``); {model name: path}."""
    import build_fmu
    fmus = {}
    for name, balls in (("BallBearing", max_balls), ("SliderCrank", None)):
        kwargs = {} if balls is None else {"max_balls": balls}
        path = Path(out_dir) / f"{name}.fmu"
        if build_fmu.is_fresh(path, name, **kwargs):
            if verbose:
                print(f"{path} is up to date (built from the current sources)")
            fmus[name] = path
        else:
            fmus[name] = build_fmu.build(out_dir, names=[name], verbose=verbose, **kwargs)[name]
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
    out = Path(args.out)
    if out.is_dir():
        raise ValueError(f"--out {out} is a folder, not a CSV file")
    try:
        result = simulate_with(args.tool, args.ssp, name, args.step, t_end)
    except ToolRunFailed as err:   # a refused or diverged run: the rows before it, and a non-zero exit
        _write_rows(out, err.result)
        print(f"error: {err} ({len(err.result['time'])} steps up to then written to {out})", file=sys.stderr)
        return 1
    _write_rows(out, result)
    peak = float(np.max(np.hypot(result["bearing.F_x"], result["bearing.F_y"])))
    emax = float(np.max(np.hypot(result["mechanism.e_x"], result["mechanism.e_y"])))
    print(f"{args.tool}: {name}, {len(result['time'])} steps of {args.step:g} s to t = {t_end:.6g} s; "
          f"max |e| = {emax * 1e6:.3f} µm, peak |F| = {peak:.2f} N; wrote {out}")
    return 0


def _write_rows(out: Path, result: dict) -> None:
    """The recorded outputs as CSV (time and RECORD columns), written to a temporary name and renamed
    when complete (``mechanism.output`` is above this package, so its ``atomic_open`` is not used here)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    keys = ["time", *RECORD]
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    try:
        with tmp.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(keys)
            for row in zip(*(result[k] for k in keys)):
                w.writerow([repr(float(v)) for v in row])
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)


def register(subparsers) -> None:
    text = "write ssp/ (SSD and .ssv parameter sets) from the dataclass defaults"
    p = subparsers.add_parser("ssp-generate", help=text, description=text[0].upper() + text[1:] + ".")
    p.add_argument("--dest", default=str(sm.SOURCE_DIR), help="output folder (default: the project's ssp/)")
    p.add_argument("--check", action="store_true", help="only check that ssp/ matches the defaults (exit 1 if not)")
    p.set_defaults(func=cmd_generate)

    text = f"build the FMUs and pack {DEFAULT_ARCHIVE} (SSD, .ssv parameter sets, FMUs)"
    p = subparsers.add_parser("ssp-pack", help=text, description=text[0].upper() + text[1:] + ".")
    p.add_argument("--out", default=str(DEFAULT_ARCHIVE), help=f"archive to write (default {DEFAULT_ARCHIVE})")
    p.add_argument("--fmu-dir", default="dist", help="where the FMUs are built (default dist)")
    p.add_argument("--no-build", action="store_true", help="pack the FMUs already in --fmu-dir")
    p.add_argument("--max-balls", type=int, default=None, help="BallBearing per-ball output capacity")
    p.set_defaults(func=cmd_pack)

    text = "run the SSP in another FMI tool (fmpy.ssp, libcosim, ecos) and write a CSV"
    p = subparsers.add_parser("ssp-simulate", help=text, description=text[0].upper() + text[1:] + ".")
    p.add_argument("--tool", choices=TOOLS, default="fmpy",
                   help="fmpy: fmpy.ssp; libcosim: libcosimpy; ecos: ecospy (fixed-step Jacobi masters; default fmpy)")
    p.add_argument("--ssp", default=str(DEFAULT_ARCHIVE), help=f"SSP archive (default {DEFAULT_ARCHIVE})")
    p.add_argument("--parameter-set", default=None, metavar="NAME",
                   help="named parameter set: the variant SSD NAME.ssd (default: the default SSD's set)")
    p.add_argument("--step", type=float, default=sm.DEFAULT_STEP, help="fixed communication step [s] (default 1e-5)")
    p.add_argument("--revs", type=float, default=0.2, help="crank revolutions (default 0.2)")
    p.add_argument("--t-end", type=float, default=None, help="end time [s] (instead of --revs)")
    p.add_argument("--out", default="results/ssp/timeseries.csv", help="CSV to write (default results/ssp/timeseries.csv)")
    p.set_defaults(func=cmd_simulate)
