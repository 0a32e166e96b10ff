"""Run a study's jobs, serially or in worker processes, under one tqdm bar (shared by reproduce and life)."""
from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Callable


def requested_workers(workers: int | None) -> int:
    """``--workers`` (default ``None``: the CPU count); zero or negative is an error, not a silent default."""
    if workers is not None and workers < 1:
        raise ValueError(f"--workers {workers}: must be at least 1")
    return workers or os.cpu_count() or 1


def worker_count(workers: int | None, jobs: int) -> int:
    """Processes to use: ``workers`` (default: the CPU count), at most one per job, at least one."""
    return max(1, min(requested_workers(workers), jobs or 1))


def map_jobs(fn: Callable, jobs: list[tuple], workers: int, desc: str, progress: bool = True,
             names: list[str] | None = None) -> list:
    """``fn(*job)`` for every job, in processes when ``workers`` > 1; results in the order of ``jobs``.

    ``names`` (one per job) label the bar as jobs finish.  The worker processes are started (forked)
    before the progress bar's monitor thread exists."""
    from tqdm import tqdm
    results: list = [None] * len(jobs)

    def bar():
        return tqdm(total=len(jobs), desc=desc, unit="run", disable=not progress or not jobs)

    def done(b, k, value):
        results[k] = value
        if names:
            b.set_postfix_str(names[k])
        b.update(1)

    if workers <= 1:
        with bar() as b:
            for k, job in enumerate(jobs):
                done(b, k, fn(*job))
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = {pool.submit(fn, *job): k for k, job in enumerate(jobs)}
            with bar() as b:
                for fut in as_completed(futures):
                    done(b, futures[fut], fut.result())
    return results
