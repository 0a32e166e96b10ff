"""The advisor's runs: validate the set-up, get the (cached) monolithic reference, then bisect every
scheme's step ladder with the step-size study's ``run_case`` on its ``Executor`` (processes or Dask)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from fmu_bearing.parameters import BearingParameterError, from_values, validate
from mechanism.studies.advise.search import DEFAULT_MERIT, MERITS, SchemeSearch, ladder
from mechanism.studies.stepsize.cases import (OUTPUT_INTERVAL, StudyConfig, build_cases, physical_case,
                                             reference_key)
from mechanism.studies.stepsize.reference import load_reference, reference_job, save_reference
from mechanism.studies.stepsize.runs import Executor, run_case

#: the reference's rtol (the step-size study's) and the default search range
REFERENCE_RTOL = 1e-11
START_STEP, MAX_STEP, MAX_STEPS = 1e-4, 1e-3, 50_000
#: neighbouring steps of the search differ by at least this ratio (the answer's resolution)
RESOLUTION = 1.25


class Refused(ValueError):
    """A set-up the advisor will not run; the message gives the reason and the option that allows it."""


@dataclass
class AdviceConfig:
    """One operating point and the question asked about it (SI; rpm; tolerance as a fraction)."""

    rpm: float = 1200.0
    balls: int | None = None
    settings: dict = field(default_factory=dict)
    tolerance: float = 0.01
    merits: list[str] = field(default_factory=lambda: [DEFAULT_MERIT])
    schemes: list[str] | None = None
    mode: str = "cosim"
    fmu: str | None = None
    revs: float = 2.0
    output_interval: float = OUTPUT_INTERVAL
    start_step: float = START_STEP
    max_step: float = MAX_STEP
    max_steps: int = MAX_STEPS
    resolution: float = RESOLUTION
    workers: int | None = None
    scheduler: str | None = None
    reference_cache: str = "results/references"
    out: str = "results/advise"
    plots: bool = True
    progress: bool = True

    def __post_init__(self):
        from mechanism.cosim.coupling import SCHEMES
        if self.schemes is None:
            self.schemes = list(SCHEMES)
        unknown = [s for s in self.schemes if s not in SCHEMES]
        if unknown:
            raise ValueError(f"unknown scheme(s) {unknown}; choose from {', '.join(SCHEMES)} "
                             "(the adaptive scheme has no fixed step to advise on)")
        bad = [m for m in self.merits if m not in MERITS]
        if bad or not self.merits:
            raise ValueError(f"unknown figure(s) of merit {bad}; choose from {', '.join(MERITS)}")
        if not 0 < self.tolerance < 1:
            raise ValueError(f"tolerance {self.tolerance:g} must lie in (0, 1) (e.g. 1% or 0.01)")
        if not self.resolution >= 1:
            raise ValueError(f"--resolution {self.resolution:g} must be at least 1")
        if not (self.rpm > 0 and self.revs > 0 and self.max_steps > 0 and self.start_step > 0
                and self.max_step >= self.output_interval):
            raise ValueError("rpm, revs, --start-step and --max-steps must be positive, "
                             "--max-step at least the output interval")

    @property
    def period(self) -> float:
        return 60.0 / self.rpm

    def study_config(self) -> StudyConfig:
        """The step-size study's configuration of this operating point (its cases and reference)."""
        return StudyConfig(out=self.out, rpms=[self.rpm], balls=[self.balls], settings=[dict(self.settings)],
                           schemes=list(self.schemes), steps=[self.output_interval], revs=self.revs,
                           mode=self.mode, fmu=self.fmu, output_interval=self.output_interval,
                           workers=self.workers, scheduler=self.scheduler, reference_rtol=REFERENCE_RTOL,
                           reference_cache=self.reference_cache, plots=self.plots, progress=self.progress)

    def ladder(self) -> list[float]:
        """The steps searched: on the output grid, from the cost cap (``max_steps`` per run) to ``max_step``."""
        return ladder(self.output_interval, self.revs * self.period / self.max_steps, self.max_step, self.resolution)


def check_setup(config: AdviceConfig) -> None:
    """Raise ``Refused`` for a bearing that cannot be built as given (reason + the option that allows it)."""
    values = dict(config.settings)
    if config.balls is not None:
        values["n_balls"] = config.balls
    try:
        validate(from_values(values))
    except BearingParameterError as err:
        if err.name == "n_balls" and "do not fit" in err.reason:
            raise Refused(f"refused: {err.reason.split('; set allow_ball_overlap')[0]}; the paper's 15- and 20-ball "
                          "studies are such hypothetical bearings: to run one anyway add "
                          "--set allow_ball_overlap=true") from None
        raise Refused(f"refused: {err}") from None


@dataclass
class Advice:
    """What the advisor found: the searches per scheme, the answer, the reference and the times."""

    config: AdviceConfig
    ladder: list[float]
    searches: dict[str, SchemeSearch]
    answer: dict | None
    reference: dict
    reference_wall_s: float
    reference_cached: bool
    wall_time_s: float
    executor: str
    probes: int
    out: Path = None


def _reference(config: AdviceConfig, study: StudyConfig, executor: Executor) -> tuple[dict, bool]:
    phys = physical_case(config.rpm, config.balls, config.settings, study)
    key = reference_key(phys)
    cache = Path(config.reference_cache)
    ref = load_reference(cache, key)
    if ref is not None:
        return ref, True
    if config.progress:
        print(f"computing the monolithic reference (LSODA, rtol {REFERENCE_RTOL:g}, and again at rtol/10 for its "
              f"own error); cached in {cache}/ for the next question at this operating point", flush=True)
    [(_, result)] = list(executor.map(reference_job, [(key, (phys,))]))
    if isinstance(result, Exception) or "error" in result:
        raise RuntimeError(f"the monolithic reference failed: {result if isinstance(result, Exception) else result['error']}")
    save_reference(cache, key, phys, result)
    return load_reference(cache, key), False


def timed_case(case: dict, ref: dict) -> dict:
    """The step-size study's ``run_case`` plus the CPU time of the worker process [s] ("cpu_time"): on a
    shared machine a run's wall time measures the load as much as the run, its CPU time the run."""
    start = time.process_time()
    row = run_case(case, ref)
    row["cpu_time"] = time.process_time() - start
    return row


def advise(config: AdviceConfig) -> Advice:
    """Search every scheme's ladder; return the largest stable step, the largest step within the tolerance
    and its wall time per scheme, and the cheapest scheme and step that meet the tolerance."""
    from tqdm import tqdm
    check_setup(config)
    start = time.perf_counter()
    study = config.study_config()
    fmu = None
    if config.mode == "cosim":
        from mechanism.run import RunConfig, fmu_path
        fmu = str(Path(fmu_path(RunConfig(fmu=config.fmu))).resolve())
    steps = config.ladder()
    start_index = min(range(len(steps)), key=lambda i: abs(math.log(steps[i] / config.start_step)))
    searches = {s: SchemeSearch(s, steps, start_index) for s in config.schemes}
    template = build_cases(replace(study, schemes=[config.schemes[0]], steps=[steps[0]]), fmu)[0]
    probes = 0
    with Executor(config.workers, config.scheduler) as executor:
        t_ref = time.perf_counter()
        ref, cached = _reference(config, study, executor)
        ref_wall = time.perf_counter() - t_ref
        bar = tqdm(desc=f"advise ({executor.description})", unit="run", disable=not config.progress,
                   mininterval=0.5)
        while True:
            jobs = []
            for s, search in searches.items():
                for i in search.next_probes():
                    h = steps[i]
                    case = dict(template, scheme=s, step_nominal=h, step=h, case=probes,
                                output_interval=max(h, config.output_interval),
                                estimated_steps=config.revs * config.period / h)
                    probes += 1
                    jobs.append(((s, i), (case, ref)))
            if not jobs:
                break
            jobs.sort(key=lambda j: -j[1][0]["estimated_steps"])   # the longest first: the pool ends evenly
            bar.total = (bar.total or 0) + len(jobs)
            for (s, i), row in executor.map(timed_case, jobs):
                if isinstance(row, Exception):
                    row = {"status": "error", "message": f"{type(row).__name__}: {row}", "step": steps[i]}
                searches[s].record(i, row, config.tolerance, config.merits)
                bar.update(1)
                bar.set_postfix_str(f"{s} {steps[i]:.3g} s {row['status']}", refresh=False)
        bar.close()
        description = executor.description
    return Advice(config, steps, searches, cheapest(searches), ref, ref_wall, cached,
                  time.perf_counter() - start, description, probes)


def cheapest(searches: dict[str, SchemeSearch]) -> dict | None:
    """The scheme and step that meet the tolerance at the least CPU time of the run (None if none does)."""
    best = None
    for s, search in searches.items():
        lim = search.limit("within")
        row = lim["row"]
        if row is None or row.get("wall_time") is None:
            continue
        cost = row.get("cpu_time", row["wall_time"])
        if best is None or cost < best["cpu_time_s"]:
            best = {"scheme": s, "step_s": lim["step"], "wall_time_s": row["wall_time"], "cpu_time_s": cost,
                    "merit_error": row["merit_error"], "bound": lim["above_range"]}
    return best
