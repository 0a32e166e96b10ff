"""Running the reproduction: every run of ``cases.run_specs`` in parallel processes, cached, then the report."""
from __future__ import annotations

import re
import shutil
import time
from dataclasses import asdict, replace
from pathlib import Path
from mechanism.run import RunConfig
from mechanism.studies.reproduce.cache import (cache_dir, code_version, config_key, ensure_fmus, is_cached, load_result, save_result)
from mechanism.studies.reproduce.cases import (RunSpec, run_specs)
from mechanism.studies.parallel import map_jobs, requested_workers, worker_count


def _compute(name: str, config: RunConfig, path: str, key: str, version: str) -> dict:
    """Worker: run one configuration, cache it, return its name, status and wall time."""
    from mechanism.run import run
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
    requested_workers(workers)   # a bad --workers before any FMU is built
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
    n_workers = worker_count(workers, len(jobs))
    t0 = time.perf_counter()
    done = {info["name"]: info for info in map_jobs(_compute, jobs, n_workers, "reproduce", progress,
                                                     names=[job[0] for job in jobs])}
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
        from mechanism.studies.reproduce.report import write_report
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
