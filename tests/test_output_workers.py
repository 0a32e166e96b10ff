"""The headline command's output workers (mechanism/output/workers.py, issue 11): the files drawn in a worker are
the bytes drawn in-process, a job's error is raised in the command, a dead worker's job runs in-process."""
import os
import signal

import numpy as np
import pytest
from output_worker_helpers import kill_worker

from mechanism.cosim.record import RunResult, resample
from mechanism.output import plots, workers
from mechanism.output.results import write_outputs


@pytest.fixture(scope="module")
def runs():
    """A short run (the force law in-process) and its ideal counterpart, as the command makes them."""
    from mechanism.cli import ideal_counterpart
    from mechanism.run import RunConfig, run
    config = RunConfig(revs=0.1, mode="inprocess", progress=False)
    r = run(config)
    return r, ideal_counterpart(config, r)


def _ideal(r: RunResult) -> RunResult:
    """Every 10th sample of a run, as a coarser run to resample."""
    return RunResult(r.columns, r.data[::10].copy(), dict(r.meta))


def test_worker_files_are_the_in_process_files(tmp_path, runs):
    """With or without frames prepared from the run's plan (``figures.Plan``, as the command gives it)."""
    from mechanism.output.figures import Plan
    from mechanism.output.results import drawn_by
    r, ideal = runs
    here = write_outputs(r, tmp_path / "here", ideal)
    for n, plan in ((1, None), (2, None), (1, Plan(r.meta, True, 0.2)), (2, Plan(r.meta, True, 0.2))):
        with workers.OutputWorkers(n, plan, drawn_by(n, False) if plan else ()) as w:
            there = write_outputs(r, tmp_path / f"w{n}", ideal, workers=w)
        assert [os.path.basename(p) for p in there["plots"]] == [os.path.basename(p) for p in here["plots"]]
        assert len(there["plots"]) == len(plots.FIGURES)
        for name in os.listdir(tmp_path / "here"):
            assert (tmp_path / f"w{n}" / name).read_bytes() == (tmp_path / "here" / name).read_bytes(), name
        assert not list((tmp_path / f"w{n}").glob(".*.tmp*"))


def test_worker_resampling_is_the_in_process_resampling(runs):
    r = runs[0]
    coarse = _ideal(r)
    with workers.OutputWorkers(1) as w:
        got = w.call(0, "resample", coarse, r["time"])
    ref = resample(coarse, r["time"])
    assert got.columns == ref.columns and np.array_equal(got.data, ref.data) and got.meta == ref.meta


def test_a_job_error_is_raised_in_the_command_and_the_worker_goes_on(tmp_path, runs):
    r = runs[0]
    with workers.OutputWorkers(1) as w:
        with pytest.raises(ValueError, match="no such plot"):
            w.call(0, "plots", r, tmp_path, None, names=("nonsense.png",))
        assert [p.name for p in w.call(0, "plots", r, tmp_path, None, names=("energy.png", "joint_force.png"))] \
            == ["joint_force.png", "energy.png"]


def test_a_dead_worker_job_runs_in_process(tmp_path, runs):
    r = runs[0]
    with workers.OutputWorkers(1) as w:
        w.call(0, "resample", _ideal(r), r["time"][:5])      # it is up
        kill_worker(w, 0)
        out = write_outputs(r, tmp_path, None, workers=w)
    assert [os.path.basename(p) for p in out["plots"]] == ["eccentricity.png", "slider_acceleration.png",
                                                           "crank_moment.png", "joint_force.png", "ball_loads.png",
                                                           "energy.png"]


def test_worker_count_is_checked(monkeypatch):
    monkeypatch.setenv("MECHANISM_OUTPUT_WORKERS", "3")
    with pytest.raises(ValueError, match="MECHANISM_OUTPUT_WORKERS"):
        workers.count()
    monkeypatch.setenv("MECHANISM_OUTPUT_WORKERS", "0")
    assert workers.count() == 0
    monkeypatch.setenv("MECHANISM_OUTPUT_WORKERS", "1")
    import threading
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert workers.count() == 0      # not forked beside another thread
    finally:
        stop.set()
        other.join()


def test_the_shares_are_the_figures_once_each():
    names = [name for share in workers.SHARES for name in share]
    assert sorted(names) == sorted(plots.FIGURES) and workers.shares(1) == (tuple(names),)


def test_the_command_does_not_import_matplotlib_when_a_worker_draws(tmp_path):
    """The point of the worker: matplotlib and scipy.interpolate are imported in it, not in the command."""
    import subprocess
    import sys
    code = ("import sys; from mechanism import cli; code = cli.main(sys.argv[1:]); "
            "print(sorted(m for m in ('matplotlib', 'scipy.interpolate') if m in sys.modules)); sys.exit(code)")
    out = subprocess.run([sys.executable, "-c", code, "run", "--mode", "inprocess", "--revs", "0.05", "--quiet",
                          "--out", str(tmp_path)], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]" and len(list(tmp_path.glob("*.png"))) == len(plots.FIGURES)


def test_only_the_plotted_columns_draw_the_same_files(tmp_path, runs):
    """``results.PLOTTED`` held against ``plot_run``: the figures of a run and its ideal reduced to
    ``plotted_columns`` (as the workers receive them) are the bytes of the whole tables'."""
    from mechanism.output.results import plotted_columns
    r, ideal = runs

    def reduced(x: RunResult) -> RunResult:
        names = list(plotted_columns(x))
        return RunResult(names, np.asfortranarray(np.column_stack([x[c] for c in names])), x.meta)
    assert len(plotted_columns(r)) < len(r.columns)
    (tmp_path / "whole").mkdir()
    (tmp_path / "part").mkdir()
    whole = plots.plot_run(r, tmp_path / "whole", ideal)
    part = plots.plot_run(reduced(r), tmp_path / "part", reduced(ideal))
    assert [p.name for p in part] == [p.name for p in whole] and len(whole) == len(plots.FIGURES)
    for a, b in zip(whole, part):
        assert a.read_bytes() == b.read_bytes(), a.name


def test_columns_are_sent_as_raw_bytes(runs):
    """A ``ColumnsOf`` argument reaches the worker as a RunResult of those columns, values and metadata intact;
    in-process (the worker died) the job gets the whole RunResult."""
    r = runs[0]
    coarse = _ideal(r)
    names = ("time", "slider_a", "F_x")
    with workers.OutputWorkers(1) as w:
        got = w.call(0, "resample", workers.ColumnsOf(coarse, names), r["time"])
        again = w.call(0, "resample", workers.ColumnsOf(coarse, names), r["time"][:7])   # the pipe is in step
        kill_worker(w, 0)
        local = w.call(0, "resample", workers.ColumnsOf(coarse, names), r["time"])
    ref = resample(RunResult(list(names), np.column_stack([coarse[c] for c in names]), coarse.meta), r["time"])
    assert got.columns == list(names) and np.array_equal(got.data, ref.data) and got.meta == ref.meta
    assert np.array_equal(again.data, ref.data[:7])
    assert local.columns == coarse.columns and np.array_equal(local.data, resample(coarse, r["time"]).data)


def test_the_run_only_figures_and_the_rest_are_the_figures_once_each():
    from mechanism.output.results import REST, RUN_ONLY
    names = [*RUN_ONLY, *REST[0], *REST[1]]
    assert sorted(names) == sorted(plots.FIGURES)


def test_a_worker_that_does_not_answer_is_given_up_and_its_job_runs_in_process(tmp_path, runs, monkeypatch):
    """A hung worker (stopped here) does not hang the command: after ``ANSWER_TIMEOUT_S`` its job runs in-process,
    with the same result, and the worker is ended."""
    r = runs[0]
    coarse = _ideal(r)
    monkeypatch.setattr(workers, "ANSWER_TIMEOUT_S", 1.0)
    with workers.OutputWorkers(1) as w:
        pid = w.pid(0)
        proc = w._procs[0]
        os.kill(pid, signal.SIGSTOP)
        try:
            got = w.call(0, "resample", coarse, r["time"])
        finally:
            if proc.is_alive():   # (given up: it was killed)
                os.kill(pid, signal.SIGCONT)
        assert w._conns[0] is None and not proc.is_alive()
    assert np.array_equal(got.data, resample(coarse, r["time"]).data)


def _slow_write(path: str) -> str:
    """A job that takes a while and writes its file atomically (as a figure is)."""
    import time
    from pathlib import Path
    time.sleep(1.0)
    Path(path + ".tmp").write_text("done")
    os.replace(path + ".tmp", path)
    return path


def test_close_waits_for_the_second_workers_job_in_flight(tmp_path, monkeypatch):
    """``close`` answers every job in flight before it ends any worker: the first worker's end ends the second
    (its child), which must not be drawing then (a reviewer's finding: its files were lost, its temporary left)."""
    monkeypatch.setitem(workers.JOBS, "slow_write", _slow_write)
    target = tmp_path / "done.txt"
    with workers.OutputWorkers(2) as w:
        assert w.submit(1, "slow_write", str(target))
    assert target.read_text() == "done"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["done.txt"]
