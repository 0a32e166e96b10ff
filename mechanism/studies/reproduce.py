"""Reproduce Section 5 of Xu et al. (2012) with one command: ``python -m mechanism reproduce --out DIR``.

The runs (all through the FMU co-simulation, ``RunConfig(mode="cosim")``, 1e-5 s step and output):

* the ball bearing (8 balls) at 300, 600, 900 and 1200 rpm (Fig. 11-19);
* 15 and 20 balls at 1200 rpm (Fig. 20-22): they do not fit on the 37.9 mm pitch circle (13 at
  most), so these runs set ``allow_ball_overlap`` - the paper's ball-count study is hypothetical;
* the ideal joint at the four speeds: the counterpart of every run at that speed (step 1e-4 s:
  no contact, see ``IDEAL_STEP``);
* the journal-in-bushing clearance joint (``joint="clearance"``, JournalClearance FMU) at 1200 rpm
  (Fig. 23-25);
* the "paper-units stiffness" variant at the four speeds: the Hertz constant divided by 1000
  (through the FMU's ``contact_stiffness`` override), the stiffness a kg-mm-s code gets from
  eq. (26) in N/mm^1.5 used unchanged; shows which stiffness the paper's plotted magnitudes match.

Runs are spread over processes (``ProcessPoolExecutor``, each run its own FMU instance) with a
tqdm bar over runs, and cached under ``DIR/cache/<name>-<key>/`` (``result.npz`` with the columns
and samples, ``meta.json`` with the configuration, status and wall time).  The key is the first
16 hex digits of SHA-256 over the run's ``RunConfig`` (every field except ``progress`` and the
FMU path) and the *code version*: SHA-256 over the source of every ``*.py`` file of
``fmu_bearing/`` (the FMUs pack the whole package), ``build_fmu.py``, the ``mechanism`` modules
that ``mechanism/run.py`` imports directly or indirectly (found by parsing their import
statements; ``plots``, ``cli`` and ``studies`` only present results and are left out), and the
versions of numpy, scipy, fmpy and pythonfmu.  So a run is recomputed exactly when its inputs or the code that
computes it change; ``--force`` recomputes everything.  The FMUs are built from the current
sources into ``DIR/fmu/`` (whenever the code version changed), never taken from a possibly stale
``dist/``.  Then ``reproduce_report`` draws the figures and writes ``DIR/report/README.md``.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shutil
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import BearingParameters
from ..results import RunResult
from ..run import FMU_NAMES, RunConfig

#: the paper's crank speeds [rpm] and ball counts (Section 5)
SPEEDS = (300.0, 600.0, 900.0, 1200.0)
BALL_COUNTS = (8, 15, 20)
#: speed of the ball-count study and of the clearance-joint comparison [rpm]
STUDY_RPM = 1200.0
#: communication step (= output interval) of the ideal-joint runs [s]: no contact, so the step is set by the
#: mechanism alone; RK4 at 1e-4 s matches 1e-5 s to < 1e-9 (relative, at common samples, 1200 rpm, measured),
#: and the cubic splines through its samples with which the report compares it with the contact runs (sampled
#: every 1e-5 s) are within 4e-9 of the 1e-5 s run (relative; slider position within 1e-10 m); it saves a
#: quarter of the reproduction's run time (tests/test_reproduce_trends.py checks both)
IDEAL_STEP = 1e-4
#: the paper-units stiffness variant: K in N/mm^1.5 used as if it were N/m^1.5 is 1000x too soft
PAPER_STIFFNESS_DIVISOR = 1000.0
#: the paper variant's eccentricity guard, as a fraction of the ball diameter (its deflections are ~1 mm)
PAPER_ECCENTRICITY_LIMIT_FRACTION = 0.5

ROOT = Path(__file__).resolve().parents[2]
#: source trees hashed into the code version, and what inside them only presents results
CODE_EXCLUDE = ("mechanism/studies/", "mechanism/plots.py", "mechanism/cli.py")
CODE_FILES = ("build_fmu.py",)
VERSIONED_PACKAGES = ("numpy", "scipy", "fmpy", "pythonfmu")
#: RunConfig fields left out of the cache key (they do not change the result)
KEY_EXCLUDE = ("progress", "fmu")


@dataclass(frozen=True)
class RunSpec:
    """One run of the reproduction: a unique ``name``, its group and the configuration."""

    name: str
    group: str      # "bearing", "ideal", "balls", "clearance", "paper-K"
    label: str
    config: RunConfig = field(compare=False)


# --- the run list -------------------------------------------------------------------------------
def balls_fit(n_balls: int, params: BearingParameters | None = None) -> bool:
    """n_balls balls of diameter D fit on the pitch circle d_m (neighbour chord > D)."""
    p = params or BearingParameters()
    return p.pitch_diameter * math.sin(math.pi / n_balls) > p.ball_diameter


def paper_stiffness() -> float:
    """K / 1000 [N/m^1.5]: the Hertz constant of Table 2 (f = 0.52) as a kg-mm-s code would use it."""
    return BallBearing().stiffness / PAPER_STIFFNESS_DIVISOR


def paper_settings() -> dict:
    """FMU start values of the paper-units stiffness variant (K/1000 and a wider divergence guard)."""
    p = BearingParameters()
    return {"contact_stiffness": paper_stiffness(),
            "eccentricity_limit": PAPER_ECCENTRICITY_LIMIT_FRACTION * p.ball_diameter}


def run_specs(revs: float = 2.0, step: float = 1e-5, output_interval: float = 1e-5,
              ideal_step: float = IDEAL_STEP) -> list[RunSpec]:
    """The full run list of the reproduction (see the module docstring)."""
    base = dict(revs=revs, step=step, output_interval=output_interval, mode="cosim", progress=False)
    ideal_base = dict(base, step=ideal_step, output_interval=max(ideal_step, output_interval))
    specs = []
    for rpm in SPEEDS:
        specs.append(RunSpec(f"bearing-{rpm:g}", "bearing", f"ball bearing, 8 balls, {rpm:g} rpm",
                             RunConfig(rpm=rpm, balls=8, joint="bearing", **base)))
        specs.append(RunSpec(f"ideal-{rpm:g}", "ideal", f"ideal joint, {rpm:g} rpm",
                             RunConfig(rpm=rpm, joint="ideal", **ideal_base)))
    for n in BALL_COUNTS:
        if n == 8:
            continue  # bearing-1200
        settings = {} if balls_fit(n) else {"allow_ball_overlap": True}
        specs.append(RunSpec(f"bearing-{STUDY_RPM:g}-{n}balls", "balls",
                             f"ball bearing, {n} balls{' (overlapping, hypothetical)' if settings else ''}, "
                             f"{STUDY_RPM:g} rpm",
                             RunConfig(rpm=STUDY_RPM, balls=n, joint="bearing", settings=settings, **base)))
    specs.append(RunSpec(f"clearance-{STUDY_RPM:g}", "clearance", f"journal-bushing clearance joint, {STUDY_RPM:g} rpm",
                         RunConfig(rpm=STUDY_RPM, joint="clearance", **base)))
    for rpm in SPEEDS:
        specs.append(RunSpec(f"paperK-{rpm:g}", "paper-K", f"ball bearing, 8 balls, K/1000 (paper units), {rpm:g} rpm",
                             RunConfig(rpm=rpm, balls=8, joint="bearing", settings=paper_settings(), **base)))
    return specs


def ideal_name(spec_or_rpm) -> str:
    """Name of the ideal-joint counterpart of a run (the ideal run at the same speed)."""
    rpm = spec_or_rpm.config.rpm if isinstance(spec_or_rpm, RunSpec) else float(spec_or_rpm)
    return f"ideal-{rpm:g}"


# --- cache ----------------------------------------------------------------------------------------
def _package_version(name: str) -> str:
    try:
        from importlib.metadata import version
        return version(name)
    except Exception:
        return "unknown"


def _imported_modules(path: Path, package: str) -> set[str]:
    """Modules of ``package`` that the source file ``path`` imports anywhere (also inside functions)."""
    import ast
    tree = ast.parse(path.read_text(), str(path))
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level == 1:                                   # from .x import y / from . import x
                base = [node.module] if node.module else [a.name for a in node.names]
                found.update(f"{package}.{b.split('.')[0]}" for b in base)
            elif node.level == 0 and node.module and node.module.split(".")[0] == package:
                found.add(".".join(node.module.split(".")[:2]))
        elif isinstance(node, ast.Import):
            found.update(".".join(a.name.split(".")[:2]) for a in node.names if a.name.split(".")[0] == package)
    return found


def code_files(root: Path = ROOT) -> list[Path]:
    """The source files whose content is the code version (sorted): every ``fmu_bearing`` file (the FMUs
    pack the whole package), ``build_fmu.py``, and the ``mechanism`` modules that ``mechanism/run.py``
    imports directly or indirectly (found by parsing import statements), less CODE_EXCLUDE."""
    files = {p for p in (root / "fmu_bearing").rglob("*.py") if "__pycache__" not in p.parts}
    files |= {root / f for f in CODE_FILES if (root / f).is_file()}
    todo, seen = ["mechanism.run"], set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        rel = name.split(".", 1)[1]
        path = root / "mechanism" / f"{rel}.py"
        if not path.is_file():
            path = root / "mechanism" / rel / "__init__.py"
        if not path.is_file() or any(path.relative_to(root).as_posix().startswith(x) for x in CODE_EXCLUDE):
            continue
        files.add(path)
        todo.extend(_imported_modules(path, "mechanism") - seen)
    return sorted(files)


def code_version(root: Path = ROOT) -> str:
    """SHA-256 over the run-relevant sources and the numeric packages' versions (hex)."""
    h = hashlib.sha256()
    for path in code_files(root):
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    for name in VERSIONED_PACKAGES:
        h.update(f"{name}=={_package_version(name)}\0".encode())
    return h.hexdigest()


def config_key(config: RunConfig, version: str) -> str:
    """Cache key of a run: 16 hex digits of SHA-256 over its RunConfig (less KEY_EXCLUDE) and the code version."""
    fields = {k: v for k, v in asdict(config).items() if k not in KEY_EXCLUDE}
    text = json.dumps({"config": fields, "code_version": version}, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def cache_dir(out: Path, spec: RunSpec, version: str) -> Path:
    return Path(out) / "cache" / f"{spec.name}-{config_key(spec.config, version)}"


def save_result(path: Path, result: RunResult, info: dict) -> None:
    """Write result.npz and meta.json into ``path`` atomically (a staging folder, then a rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    stage = path.parent / f".{path.name}.{os.getpid()}.tmp"
    shutil.rmtree(stage, ignore_errors=True)
    stage.mkdir()
    np.savez(stage / "result.npz", data=result.data, columns=np.array(result.columns))
    meta = {"status": result.status, "message": result.message, "meta": result.meta, **info}
    (stage / "meta.json").write_text(json.dumps(meta, indent=2, default=repr) + "\n")
    shutil.rmtree(path, ignore_errors=True)
    os.replace(stage, path)


def load_result(path: Path) -> tuple[RunResult, dict]:
    """(RunResult, meta.json contents) of a cached run."""
    path = Path(path)
    info = json.loads((path / "meta.json").read_text())
    with np.load(path / "result.npz") as z:
        result = RunResult([str(c) for c in z["columns"]], z["data"], info.get("meta", {}),
                           info.get("status", "completed"), info.get("message", ""))
    return result, info


def is_cached(path: Path) -> bool:
    return (Path(path) / "meta.json").is_file() and (Path(path) / "result.npz").is_file()


# --- FMUs -----------------------------------------------------------------------------------------
def ensure_fmus(out: Path, version: str, joints: set[str]) -> dict[str, Path]:
    """FMU paths per joint, built from the current sources into ``out/fmu`` unless already built from them
    (``out/fmu/<Name>.code_version`` records the code version each FMU was built from)."""
    fmu_dir = Path(out) / "fmu"
    paths = {}
    for joint in sorted(j for j in joints if j in FMU_NAMES):
        name = FMU_NAMES[joint]
        path, stamp = fmu_dir / f"{name}.fmu", fmu_dir / f"{name}.code_version"
        if not (path.is_file() and stamp.is_file() and stamp.read_text().strip() == version):
            if str(ROOT) not in sys.path:
                sys.path.insert(0, str(ROOT))
            import build_fmu
            fmu_dir.mkdir(parents=True, exist_ok=True)
            stamp.unlink(missing_ok=True)
            build_fmu.build(fmu_dir, names=[name], verbose=False)
            if not path.is_file():
                raise FileNotFoundError(f"building {name}.fmu failed (is its slave script there?)")
            stamp.write_text(version + "\n")
        paths[joint] = path.resolve()
    return paths


# --- running ----------------------------------------------------------------------------------------
def _compute(name: str, config: RunConfig, path: str, key: str, version: str) -> dict:
    """Worker: run one configuration, cache it, return its name, status and wall time."""
    from ..run import run
    t0 = time.perf_counter()
    result = run(config)
    wall = time.perf_counter() - t0
    save_result(Path(path), result, {"name": name, "key": key, "code_version": version, "wall_time_s": wall,
                                     "config": asdict(config), "computed_at": time.strftime("%Y-%m-%d %H:%M:%S")})
    return {"name": name, "status": result.status, "message": result.message, "wall_time_s": wall}


def _cost(spec: RunSpec) -> float:
    """Rough relative cost (steps, FMU runs dearer): longest first balances the workers."""
    steps = spec.config.revs * spec.config.crank_period / spec.config.step
    return steps * (1.0 if spec.config.joint == "ideal" else 1.3)


def run_all(out: Path, specs: list[RunSpec], force: bool = False, workers: int | None = None,
            progress: bool = True) -> dict:
    """Run (or take from the cache) every spec; return {"results", "infos", "computed", "cached", ...}."""
    from tqdm import tqdm

    out = Path(out)
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise ValueError("run names must be unique")
    version = code_version()
    paths = {s.name: cache_dir(out, s, version) for s in specs}
    todo = [s for s in specs if force or not is_cached(paths[s.name])]
    todo.sort(key=_cost, reverse=True)
    fmus = ensure_fmus(out, version, {s.config.joint for s in todo}) if todo else {}
    jobs = [(s.name, replace(s.config, fmu=str(fmus[s.config.joint]) if s.config.joint in fmus else None,
                             progress=False), str(paths[s.name]), config_key(s.config, version), version)
            for s in todo]
    n_workers = max(1, min(workers or os.cpu_count() or 1, len(jobs) or 1))
    t0 = time.perf_counter()
    done = {}
    if n_workers == 1:
        with tqdm(total=len(jobs), desc="reproduce", unit="run", disable=not progress or not jobs) as bar:
            for job in jobs:
                bar.set_postfix_str(job[0])
                done[job[0]] = _compute(*job)
                bar.update(1)
    else:
        # the workers are started (forked) before the progress bar's monitor thread exists
        with ProcessPoolExecutor(max_workers=n_workers) as pool:
            futures = {pool.submit(_compute, *job): job[0] for job in jobs}
            with tqdm(total=len(jobs), desc="reproduce", unit="run", disable=not progress) as bar:
                for fut in as_completed(futures):
                    info = fut.result()
                    done[info["name"]] = info
                    bar.set_postfix_str(info["name"])
                    bar.update(1)
    elapsed = time.perf_counter() - t0
    results, infos = {}, {}
    for s in specs:
        results[s.name], infos[s.name] = load_result(paths[s.name])
    return {"results": results, "infos": infos, "computed": [s.name for s in todo if s.name in done],
            "cached": [s.name for s in specs if s.name not in done], "elapsed_s": elapsed,
            "workers": n_workers, "code_version": version, "paths": paths}


def reproduce(out: str | Path, force: bool = False, workers: int | None = None, revs: float = 2.0,
              specs: list[RunSpec] | None = None, report: bool = True, progress: bool = True,
              stepsize: str | Path | None = None) -> dict:
    """Run (or reuse) the reproduction's runs and write the report; ``specs`` limits the run list.

    ``stepsize``: the output folder of a ``stepsize-study``; its summary and plots are added to the report.
    """
    out = Path(out)
    specs = run_specs(revs) if specs is None else list(specs)
    t0 = time.perf_counter()
    outcome = run_all(out, specs, force=force, workers=workers, progress=progress)
    outcome["specs"] = specs
    if report:
        from .reproduce_report import write_report
        outcome["report"] = write_report(out, specs, outcome)
        if stepsize is not None:
            append_stepsize_study(outcome["report"], Path(stepsize))
    outcome["total_s"] = time.perf_counter() - t0
    return outcome


# --- command line -----------------------------------------------------------------------------------
def append_stepsize_study(report: Path, study: Path) -> bool:
    """Append a step-size study's summary (headings one level down) and plots to the report."""
    summary = study / "stepsize_summary.md"
    if not summary.is_file():
        return False
    text = re.sub(r"^(#+)", r"#\1", summary.read_text(encoding="utf-8"), flags=re.M)
    figures = report.parent / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    links = []
    for png in sorted(study.glob("stepsize_*.png")):
        shutil.copy2(png, figures / png.name)
        links.append(f"![{png.stem}](figures/{png.name})")
    with open(report, "a", encoding="utf-8") as f:
        f.write(f"\n## Co-simulation step size\n\nFrom `python -m mechanism stepsize-study` in `{study}`"
                f" (docs/stepsize-study.md).\n\n{text}\n" + "\n\n".join(links) + "\n")
    return True


def cmd_reproduce(args) -> int:
    if args.revs <= 0:
        raise ValueError("--revs must be positive")
    outcome = reproduce(args.out, force=args.force, workers=args.workers, revs=args.revs,
                        progress=not args.quiet, stepsize=args.stepsize)
    failed = [n for n, r in outcome["results"].items() if not r.ok]
    print(f"{len(outcome['computed'])} run(s) computed, {len(outcome['cached'])} from the cache "
          f"({outcome['elapsed_s']:.1f} s on {outcome['workers']} worker(s)); total {outcome['total_s']:.1f} s")
    if "report" in outcome:
        print(f"report: {outcome['report']}")
    for n in failed:
        print(f"warning: run {n} failed: {outcome['results'][n].message}", file=sys.stderr)
    return 1 if failed else 0


def register(subparsers) -> None:
    p = subparsers.add_parser("reproduce", help="reproduce the paper's Section 5 (runs, figures, report)",
                              description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="results/reproduce", help="output folder (default results/reproduce)")
    p.add_argument("--force", action="store_true", help="recompute every run (ignore the cache)")
    p.add_argument("--workers", type=int, default=None, help="parallel runs (default: the number of cores)")
    p.add_argument("--revs", type=float, default=2.0, help="crank revolutions per run (default 2, as the paper)")
    p.add_argument("--stepsize", default=None, metavar="DIR",
                   help="add the results of `stepsize-study --out DIR` to the report")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_reproduce)
