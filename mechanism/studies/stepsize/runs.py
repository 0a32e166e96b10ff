"""Running the study: one case against its reference, the executors (process pool or Dask), the sweep, its CSV."""
from __future__ import annotations

import csv
import itertools
import json
import os
import socket
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from pathlib import Path

from mechanism.output.results import write_rows
from mechanism.studies.parallel import requested_workers
from mechanism.studies.stepsize.cases import (
    ADAPTIVE,
    ADAPTIVE_SCHEME,
    COLUMN_NAMES,
    COLUMNS,
    DIVERGENT,
    ERROR,
    FAILED,
    NONFINITE,
    REFERENCE_COLUMNS,
    SKIPPED,
    STABLE,
    StudyConfig,
    build_cases,
    physical_case,
    reference_key,
)
from mechanism.studies.stepsize.figures import plot_study
from mechanism.studies.stepsize.reference import (
    _clean,
    check_rtol,
    combine_reference,
    compare,
    load_reference,
    reference_run_job,
    save_reference,
)
from mechanism.studies.stepsize.tables import summarize, summary_markdown


# ------------------------------------------------------------------------------------ one case
def _worker_name() -> str:
    if "distributed" in sys.modules:  # only a Dask worker has imported it
        try:
            from distributed import get_worker
            return f"dask {get_worker().address}"
        except Exception:
            pass
    return f"pid {os.getpid()}"


def run_case(case: dict, ref: dict | None) -> dict:
    """Run one case and measure it against ``ref`` (the reference's columns); never raises: a row."""
    if ref is None:
        row = _new_row(case)
        row["wall_time"] = 0.0
        row["status"], row["message"] = ERROR, f"RuntimeError: {case.get('reference_error') or 'no reference'}"
        row["ended_at"] = time.time()
        return row
    return assess_case(case, case_job(case), ref)


def case_job(case: dict) -> dict:
    """Run one case without its reference (the comparison follows in ``assess_case``, where the reference
    is): {"row": the row so far, "columns": the run's ``REFERENCE_COLUMNS`` (arrays), or None if it did not
    complete}. Never raises."""
    row = _new_row(case)
    wall0 = time.perf_counter()
    columns = None
    try:
        from mechanism.run import RunConfig, run
        config = RunConfig(rpm=case["rpm"], revs=case["revs"], balls=case["balls"], mode=case["mode"],
                           step=case["step"] or case["output_interval"], output_interval=case["output_interval"],
                           settings=dict(case["settings"]), fmu=case["fmu"], progress=False)
        if case["scheme"] == ADAPTIVE:
            from mechanism.run import run_adaptive
            result = run_adaptive(replace(config, scheme=ADAPTIVE_SCHEME), case["tol"], h_max=case["output_interval"])
        else:
            result = run(replace(config, scheme=case["scheme"]))
        row["wall_time"] = time.perf_counter() - wall0
        meta = result.meta
        row["component_calls"] = meta.get("component_calls")
        row["substeps_total"] = meta.get("substeps_total")
        if case["scheme"] == ADAPTIVE:
            row.update(step=_clean(meta.get("mean_step_s")), steps=meta.get("accepted_steps"),
                       rejected_steps=meta.get("rejected_steps"), min_step=_clean(meta.get("min_step_s")),
                       max_step=_clean(meta.get("max_step_s")))
        else:
            row.update(steps=int(round(meta.get("t_end_s", 0.0) / case["step"])) if result.ok else
                       (meta.get("failure") or {}).get("step"), rejected_steps=0,
                       min_step=case["step"], max_step=case["step"])
        if not result.ok:
            row["status"], row["message"] = FAILED, result.message
        else:
            columns = {c: result[c] for c in REFERENCE_COLUMNS if result.has(c)}
    except Exception as err:  # a case that cannot run is a row, not the end of the sweep
        row["wall_time"] = time.perf_counter() - wall0
        row["status"], row["message"] = ERROR, f"{type(err).__name__}: {err}"
    row["ended_at"] = time.time()
    return {"row": row, "columns": columns}


def assess_case(case: dict, done: dict, ref: dict | None) -> dict:
    """The row of a case run by ``case_job`` (``done``) measured against ``ref`` (the reference's columns;
    None: the reference failed, an error row); never raises."""
    row, columns = dict(done["row"]), done["columns"]
    if row["status"] is not None:                        # it failed or could not run: no comparison
        return row
    if ref is None:
        row["status"], row["message"] = ERROR, f"RuntimeError: {case.get('reference_error') or 'no reference'}"
        return row
    try:
        metrics = compare(columns, ref, case)
        finite = metrics.pop("_finite")
        row.update(metrics)
        row["ref_floor_force_max_rel"] = _clean(ref["floor__force_max_rel"]) if "floor__force_max_rel" in ref else None
        row["ref_floor_ecc_max_rel"] = _clean(ref["floor__ecc_max_rel"]) if "floor__ecc_max_rel" in ref else None
        worst = max((metrics.get(k) or 0.0) for k in ("err_force_max_rel", "err_ecc_max_rel"))
        if not finite:
            row["status"], row["message"] = NONFINITE, "non-finite samples in the window"
        elif worst > case["divergence"]:
            row["status"] = DIVERGENT
            row["message"] = (f"max relative error {worst:.3g} exceeds {case['divergence']:g} "
                              f"(ran to the end on a wrong trajectory)")
        else:
            row["status"], row["message"] = STABLE, ""
    except Exception as err:
        row["status"], row["message"] = ERROR, f"{type(err).__name__}: {err}"
    return row


def _new_row(case: dict) -> dict:
    row = {k: None for k in COLUMN_NAMES}
    row.update(case=case["case"], group=case["group"], rpm=case["rpm"], balls=case["balls"],
               settings=";".join(f"{k}={v}" for k, v in sorted(case["settings"].items())),
               scheme=case["scheme"], mode=case["mode"], step_nominal=case["step_nominal"], step=case["step"],
               tol=case["tol"], output_interval=case["output_interval"], revs=case["revs"],
               window_start=case["window"][0], window_end=case["window"][1],
               pid=os.getpid(), host=socket.gethostname(), worker=_worker_name(), started_at=time.time())
    return row


def skipped_row(case: dict, reason: str) -> dict:
    row = {k: None for k in COLUMN_NAMES}
    row.update(case=case["case"], group=case["group"], rpm=case["rpm"], balls=case["balls"],
               settings=";".join(f"{k}={v}" for k, v in sorted(case["settings"].items())),
               scheme=case["scheme"], mode=case["mode"], step_nominal=case["step_nominal"], step=case["step"],
               tol=case["tol"], output_interval=case["output_interval"], revs=case["revs"],
               window_start=case["window"][0], window_end=case["window"][1], status=SKIPPED, message=reason)
    return row


# ------------------------------------------------------------------------------------- executors
class Executor:
    """Runs ``fn(*args)`` jobs on a local process pool or a Dask cluster; yields (key, result) as they finish."""

    def __init__(self, workers: int | None = None, scheduler: str | None = None):
        self.workers = requested_workers(workers)
        self.scheduler = scheduler
        self._pool = None
        self._client = None

    def __enter__(self):
        if self.scheduler:
            try:
                from distributed import Client
            except ImportError as err:
                raise RuntimeError("--scheduler needs dask.distributed: pip install 'bearing-cosim[studies]'") from err
            self._client = Client(self.scheduler)
        elif self.workers > 1:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor
            self._pool = ProcessPoolExecutor(max_workers=self.workers,
                                             mp_context=multiprocessing.get_context("spawn"))
        return self

    def __exit__(self, *exc):
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        if self._client is not None:
            self._client.close()

    @property
    def description(self) -> str:
        if self._client is not None:
            return f"Dask cluster {self.scheduler}"
        return f"{self.workers} local process(es)" if self._pool is not None else "this process"

    def map(self, fn: Callable, jobs: Iterable[tuple[object, tuple]]) -> Iterable[tuple[object, object]]:
        """jobs: (key, args); yields (key, result or exception instance)."""
        return self.run_jobs((key, fn, args) for key, args in jobs)

    def run_jobs(self, jobs: Iterable[tuple[object, Callable, tuple]]) -> Iterable[tuple[object, object]]:
        """jobs: (key, fn, args), submitted in their order; yields (key, fn(*args) or exception instance) as
        they finish."""
        jobs = list(jobs)
        if self._client is not None:
            from distributed import as_completed
            futures = {}
            for key, fn, args in jobs:
                futures[self._client.submit(fn, *args, pure=False)] = key
            for fut in as_completed(list(futures)):
                try:
                    yield futures[fut], fut.result()
                except Exception as err:
                    yield futures[fut], err
        elif self._pool is not None:
            from concurrent.futures import as_completed
            futures = {self._pool.submit(fn, *args): key for key, fn, args in jobs}
            for fut in as_completed(futures):
                try:
                    yield futures[fut], fut.result()
                except Exception as err:
                    yield futures[fut], err
        else:
            for key, fn, args in jobs:
                try:
                    yield key, fn(*args)
                except Exception as err:
                    yield key, err


# ------------------------------------------------------------------------------------- the study
@dataclass
class StudyResult:
    rows: list[dict]
    summary: dict
    out: Path
    wall_time: float


def _progress(total: int, desc: str, enabled: bool):
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit="case", disable=not enabled, mininterval=0.5)


def run_study(config: StudyConfig) -> StudyResult:
    """Run the sweep, write stepsize.csv, stepsize_summary.json/.md and the plots into ``config.out``."""
    start = time.perf_counter()
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    cache = Path(config.reference_cache) if config.reference_cache else out / "references"
    fmu = None
    if config.mode == "cosim":
        from mechanism.run import RunConfig, fmu_path
        fmu = str(Path(fmu_path(RunConfig(fmu=config.fmu))).resolve())
    cases = build_cases(config, fmu)
    physical = {}
    for rpm, balls, settings in itertools.product(config.rpms, config.balls, config.settings):
        phys = physical_case(rpm, balls, settings, config)
        physical[reference_key(phys)] = phys
    references: dict[str, dict] = {}
    reference_errors: dict[str, str] = {}
    with Executor(config.workers, config.scheduler) as executor:
        rows = _sweep(executor, config, cases, physical, cache, references, reference_errors)
    ordered = [rows[i] for i in sorted(rows)]
    summary = summarize(ordered, config)
    summary["wall_time_s"] = time.perf_counter() - start
    summary["executor"] = config.scheduler or f"{requested_workers(config.workers)} local processes"
    summary["references"] = {k: {"physical_case": physical[k], "error": reference_errors.get(k)} for k in physical}
    write_csv(ordered, out / "stepsize.csv")
    (out / "stepsize_summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "stepsize_summary.md").write_text(summary_markdown(summary, config))
    if config.plots:
        plot_study(ordered, summary, out)
    return StudyResult(ordered, summary, out, time.perf_counter() - start)


def _sweep(executor: Executor, config: StudyConfig, cases: list[dict], physical: dict[str, dict], cache: Path,
           references: dict[str, dict], reference_errors: dict[str, str]) -> dict[int, dict]:
    """Run the cases and the missing references on ``executor``, all at once; return the rows by case index.

    A missing reference is two jobs (its run and the run at rtol/10 that measures its floor); the cases of
    a physical case whose reference is cached compare with it in the worker (``run_case``), the others run
    beside the reference (``case_job``) and are compared here once it is there (``assess_case``). The
    references first, then the longest cases, so that the pool ends evenly. ``references`` and
    ``reference_errors`` are filled in."""
    pending: dict[str, dict] = {}                 # key -> {"main": ..., "check": ...} of a reference being computed
    for key, phys in physical.items():
        ref = load_reference(cache, key)
        if ref is None:
            pending[key] = {}
        else:
            references[key] = ref
    rows: dict[int, dict] = {}
    jobs: list[tuple[object, Callable, tuple]] = []
    for key in pending:
        phys = physical[key]
        jobs += [(("reference", key, "main"), reference_run_job, (phys,)),
                 (("reference", key, "check"), reference_run_job, (phys, check_rtol(phys)))]
    runnable = []
    for case in cases:
        if (case["scheme"] != ADAPTIVE and not config.allow_slow
                and case["estimated_steps"] > config.max_steps_per_case):
            rows[case["case"]] = skipped_row(
                case, f"{case['estimated_steps']:.3g} steps > --max-steps-per-case {config.max_steps_per_case} "
                      f"(run with --allow-slow)")
        else:
            runnable.append(case)
    runnable.sort(key=lambda c: -(c["estimated_steps"] or 3e4))
    for case in runnable:
        if case["reference"] in pending:
            jobs.append((("case", case["case"]), case_job, (case,)))
        else:
            jobs.append((("case", case["case"]), run_case, (case, references[case["reference"]])))
    by_id = {case["case"]: case for case in runnable}
    waiting: dict[str, list[tuple[dict, dict]]] = {key: [] for key in pending}
    bar = _progress(len(cases) + 2 * len(pending), f"step-size study ({executor.description})", config.progress)
    bar.update(len(rows))

    def finish(case: dict, row: dict) -> None:
        rows[case["case"]] = row
        bar.update(1)
        bar.set_postfix_str(f"{row['scheme']} {row['status']}", refresh=False)

    for job, result in executor.run_jobs(jobs):
        if job[0] == "reference":
            _, key, part = job
            pending[key][part] = result if not isinstance(result, Exception) else {
                "error": f"{type(result).__name__}: {result}"}
            bar.update(1)
            if len(pending[key]) < 2:
                continue
            parts = pending.pop(key)
            check = parts["check"] if "error" not in parts["check"] else None
            try:
                ref = combine_reference(physical[key], parts["main"], check)
            except Exception as err:
                reference_errors[key] = f"reference failed: {type(err).__name__}: {err}"
            else:
                save_reference(cache, key, physical[key], ref)
                references[key] = load_reference(cache, key)
            for case, done in waiting.pop(key):
                case["reference_error"] = reference_errors.get(key)
                finish(case, assess_case(case, done, references.get(key)))
            continue
        case = by_id[job[1]]
        if isinstance(result, Exception):  # the worker itself died (run_case and case_job never raise)
            row = skipped_row(case, "")
            row.update(status=ERROR, message=f"{type(result).__name__}: {result}")
            finish(case, row)
        elif case["reference"] in waiting and "row" in result:
            waiting[case["reference"]].append((case, result))
        elif "row" in result:   # a case_job whose reference has come meanwhile
            case["reference_error"] = reference_errors.get(case["reference"])
            finish(case, assess_case(case, result, references.get(case["reference"])))
        else:
            finish(case, result)
    bar.close()
    return rows


def write_csv(rows: list[dict], path: Path) -> None:
    """One row per case; header 'name [unit]'; missing values are empty cells (never NaN); written atomically."""
    write_rows(rows, COLUMNS, path)


def read_csv(path: Path) -> list[dict]:
    """The rows of a stepsize.csv, as strings keyed by column name (units stripped)."""
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = [h.split(" [")[0] for h in next(reader)]
        return [dict(zip(header, r)) for r in reader]


INTEGER_COLUMNS = ("case", "balls", "component_calls", "steps", "rejected_steps", "substeps_total", "pid")


def rows_from_csv(path: Path) -> list[dict]:
    """The rows of a stepsize.csv with the types ``run_study`` produced (numbers, None for empty cells)."""
    units = dict(COLUMNS)
    rows = []
    for raw in read_csv(path):
        row = {}
        for c in COLUMN_NAMES:
            v = raw.get(c, "")
            if v == "":
                row[c] = "" if c in ("settings", "message") else None
            elif c in INTEGER_COLUMNS:
                row[c] = int(float(v))
            elif units[c]:
                row[c] = float(v)
            else:
                row[c] = v
        rows.append(row)
    return rows


def replot(config: StudyConfig) -> dict:
    """Rewrite the summaries and plots of ``config.out`` from its stepsize.csv (no run)."""
    out = Path(config.out)
    rows = rows_from_csv(out / "stepsize.csv")
    previous = out / "stepsize_summary.json"
    summary = summarize(rows, config)
    if previous.is_file():
        old = json.loads(previous.read_text())
        for k in ("wall_time_s", "executor", "references"):
            if k in old:
                summary[k] = old[k]
        summary["config"] = old.get("config", summary["config"])
    previous.write_text(json.dumps(summary, indent=2) + "\n")
    (out / "stepsize_summary.md").write_text(summary_markdown(summary, config))
    if config.plots:
        plot_study(rows, summary, out)
    return summary
