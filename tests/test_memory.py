"""A run's memory (issue 11): the resampling spline without scipy.interpolate is scipy's CubicSpline to the bit,
the summary's peaks without stacked copies are the stacked peaks, the life of a window accumulated over the
window's samples alone is the whole loop's, and a --no-plots run does not import scipy.interpolate.

Peak memory itself is measured in benchmarks/memory.py, not here."""
from __future__ import annotations

import math
import subprocess
import sys
import warnings

import numpy as np
import pytest
from output_worker_helpers import kill_worker
from scipy.interpolate import CubicSpline

from fmu_bearing.life import LifeAccumulator, LoadRatings, output_values
from fmu_bearing.parameters import BearingParameters
from mechanism.cosim.record import RunResult, resample
from mechanism.cosim.spline import NotAKnotSpline
from mechanism.output.life import life_from_samples
from mechanism.output.results import _figures, _peak_of_columns

ROOT = __import__("pathlib").Path(__file__).resolve().parent.parent


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal to the bit (signed zeros and NaN payloads included)."""
    a, b = np.ascontiguousarray(a, float), np.ascontiguousarray(b, float)
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def _knots(rng, n: int, kind: str) -> np.ndarray:
    if kind == "uniform":                  # a run's sample times: k * h
        return np.arange(n) * 1e-4
    if kind == "random":
        return np.cumsum(rng.uniform(0.01, 1.0, n))
    return np.cumsum(rng.choice([1e-3, 1.0, 50.0], n))   # wild spacing: dgtsv's row interchanges


@pytest.mark.parametrize("kind", ["uniform", "random", "wild"])
def test_spline_is_scipys_cubic_spline_to_the_bit(kind):
    rng = np.random.default_rng({"uniform": 1, "random": 2, "wild": 3}[kind])
    for _ in range(40):
        n = int(rng.integers(2, 300))
        x = _knots(rng, n, kind)
        y = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-9, 9)
        y[:, 1] = np.where(rng.random(n) < 0.3, 0.0, y[:, 1])       # zeros of both signs
        y[::3, 2] = -0.0
        # the knots themselves, points between them, and a run's last time just past the last knot
        x_new = np.sort(np.concatenate([x, rng.uniform(x[0], x[-1], 3 * n), [x[-1] * (1 + 1e-12)]]))
        assert same_bits(NotAKnotSpline(x, y)(x_new), CubicSpline(x, y)(x_new)), n
        assert same_bits(NotAKnotSpline(x, y[:, 0])(x_new), CubicSpline(x, y[:, 0])(x_new)), n


def test_spline_of_fewer_than_four_knots_is_scipys():
    x, y = np.array([0.0, 0.4, 1.0]), np.array([[1.0, -2.0], [3.0, 0.5], [2.0, 7.0]])
    x_new = np.linspace(0.0, 1.0, 11)
    for n in (2, 3):
        assert same_bits(NotAKnotSpline(x[:n], y[:n])(x_new), CubicSpline(x[:n], y[:n])(x_new))


def test_spline_refuses_knots_that_do_not_rise():
    with pytest.raises(ValueError, match="strictly increasing"):
        NotAKnotSpline(np.array([0.0, 1.0, 1.0, 2.0]), np.zeros(4))
    with pytest.raises(ValueError, match="strictly increasing"):
        NotAKnotSpline(np.array([0.0]), np.zeros(1))


def test_resample_is_a_cubic_spline_per_column_and_linear_where_not_finite():
    """The reference is scipy's CubicSpline column by column (``resample`` before issue 11)."""
    rng = np.random.default_rng(4)
    t = np.arange(1001) * 1e-4
    columns = ["time"] + [f"c{k}" for k in range(9)]
    data = np.column_stack([t] + [np.sin(rng.uniform(1, 300) * t + rng.uniform(0, 6)) * rng.uniform(1e-6, 1e3)
                                  for _ in range(9)])
    data[17, 3] = np.nan                       # a column with a gap: linear
    data[:, 6] = np.nan                        # a column never recorded
    times = np.arange(10001) * 1e-5
    got = resample(RunResult(columns, data, {"a": 1}), times)
    assert got.columns == columns and got.meta["resampled_from_s"] == t[1] - t[0] and got.meta["a"] == 1
    assert same_bits(got["time"], times)
    for k in range(1, len(columns)):
        column = data[:, k]
        want = CubicSpline(t, column)(times) if np.all(np.isfinite(column)) else np.interp(times, t, column)
        assert same_bits(got.data[:, k], want), columns[k]


def test_peaks_without_stacking_are_the_stacked_peaks():
    rng = np.random.default_rng(5)
    a, b, c = rng.normal(size=(3, 50))
    a[::4] = np.nan
    assert _peak_of_columns([a, b, c]) == float(np.nanmax(np.column_stack([a, b, c])))
    nan = np.full(50, np.nan)
    assert _peak_of_columns([nan, b]) == float(np.nanmax(np.column_stack([nan, b])))
    with pytest.warns(RuntimeWarning):
        assert math.isnan(_peak_of_columns([nan, nan]))
    assert math.isnan(_peak_of_columns([a[:0], b[:0]]))


def test_figures_of_a_slice_are_the_figures_of_a_mask():
    """``_figures`` on rows given as a slice (views) against the same figures from boolean-mask copies."""
    rng = np.random.default_rng(6)
    columns = ["time", "e_x", "e_y", "F_x", "F_y", "slider_a", "crank_moment", "constraint_violation",
               "ball_load_1", "ball_load_2"]
    data = rng.normal(size=(200, len(columns)))
    data[:, 0] = np.arange(200) * 1e-3
    data[5, 8] = np.nan
    r = RunResult(columns, data)
    for rows in (slice(None), slice(40, 120), slice(0, 0)):
        mask = np.zeros(200, bool)
        mask[rows] = True
        got = _figures(r, rows)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            want = {
                "max_eccentricity_m": np.hypot(r["e_x"][mask], r["e_y"][mask]),
                "peak_joint_force_N": np.hypot(r["F_x"][mask], r["F_y"][mask]),
                "slider_acceleration_max_m_s2": r["slider_a"][mask],
                "crank_moment_max_N_m": r["crank_moment"][mask],
                "max_constraint_violation_m": np.abs(r["constraint_violation"][mask]),
                "max_ball_load_N": np.column_stack([r["ball_load_1"][mask], r["ball_load_2"][mask]]),
            }
        for key, values in want.items():
            expect = float(np.nanmax(values)) if values.size else math.nan
            assert got[key] == expect or (math.isnan(got[key]) and math.isnan(expect)), key
        if mask.any():
            assert got["slider_acceleration_min_m_s2"] == float(np.nanmin(r["slider_a"][mask]))
            assert got["crank_moment_min_N_m"] == float(np.nanmin(r["crank_moment"][mask]))


def test_life_of_a_window_is_the_loop_over_every_sample():
    """The window's samples alone give the accumulator of the loop over every sample (the form before)."""
    params = BearingParameters()
    n_balls = int(params.n_balls)
    rng = np.random.default_rng(7)
    t = np.arange(400) * 2.5e-4
    loads = rng.uniform(0.0, 300.0, size=(400, n_balls))
    loads[100, 2] = np.nan                                        # a sample skipped
    w_i, w_o = rng.uniform(100, 130, 400), np.zeros(400)
    columns = ["time", "omega_inner", "omega_outer"] + [f"ball_load_{k + 1}" for k in range(n_balls)]
    r = RunResult(columns, np.column_stack([t, w_i, w_o, loads]))
    for window in ((-math.inf, math.inf), (0.0125, 0.05), (0.01255, 0.0501), (0.2, 0.3), (0.05, 0.05)):
        acc = LifeAccumulator(LoadRatings.of_bearing(params), params.reliability_factor)
        for k in range(1, len(t)):
            lo, hi = max(t[k - 1], window[0]), min(t[k], window[1])
            if hi > lo and np.all(np.isfinite(loads[k])):
                acc.add(loads[k].tolist(), float(w_i[k]), float(w_o[k]), float(hi - lo))
        got = life_from_samples(r, params, *window)
        assert output_values(got) == output_values(acc) and got.speed == acc.speed, window


def test_a_run_without_plots_does_not_import_scipy_interpolate(tmp_path):
    """The ideal counterpart is resampled (1e-4 s -> 1e-5 s) without scipy.interpolate's ~22 MB."""
    code = ("import sys; from mechanism.cli import main; "
            f"rc = main(['run', '--revs', '0.1', '--mode', 'inprocess', '--quiet', '--no-plots', '--out', {str(tmp_path)!r}]); "
            "print(rc, 'scipy.interpolate' in sys.modules, 'matplotlib' in sys.modules)")
    proc = subprocess.run([sys.executable, "-c", code], check=False, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert proc.stdout.split()[-3:] == ["0", "False", "False"], proc.stdout + proc.stderr
    assert (tmp_path / "ideal_timeseries.csv").exists()


def test_the_command_without_plots_writes_what_write_outputs_writes(tmp_path):
    """``run --no-plots`` writes the run's table and lets it go before the ideal counterpart runs: the files are
    the bytes ``write_outputs`` writes from the run and its ideal counterpart held together."""
    from mechanism.cli import ideal_counterpart, main
    from mechanism.output.results import write_outputs
    from mechanism.run import RunConfig, run
    assert main(["run", "--revs", "0.2", "--mode", "inprocess", "--quiet", "--no-plots",
                 "--out", str(tmp_path / "cli")]) == 0
    config = RunConfig(revs=0.2, mode="inprocess", progress=False)
    result = run(config)
    write_outputs(result, tmp_path / "held", ideal_counterpart(config, result), plots=False)
    for name in ("timeseries.csv", "ideal_timeseries.csv", "summary.json"):
        assert (tmp_path / "cli" / name).read_bytes() == (tmp_path / "held" / name).read_bytes(), name


@pytest.mark.parametrize("n", [1, 2])
def test_the_command_with_plots_writes_what_write_outputs_writes(tmp_path, monkeypatch, n):
    """``run`` with plots also lets the run's table go before the ideal counterpart runs (a worker draws the
    run-only figures meanwhile): every file, the PNGs too, is the bytes ``write_outputs`` writes in-process from
    the run and its ideal counterpart held together."""
    from mechanism.cli import ideal_counterpart, main
    from mechanism.output.results import write_outputs
    from mechanism.run import RunConfig, run
    monkeypatch.setenv("MECHANISM_OUTPUT_WORKERS", str(n))
    assert main(["run", "--revs", "0.2", "--mode", "inprocess", "--quiet", "--out", str(tmp_path / "cli")]) == 0
    config = RunConfig(revs=0.2, mode="inprocess", progress=False)
    result = run(config)
    held = write_outputs(result, tmp_path / "held", ideal_counterpart(config, result))
    assert len(held["plots"]) == 7
    names = sorted(p.name for p in (tmp_path / "held").iterdir() if not p.name.startswith("."))
    assert names == sorted(p.name for p in (tmp_path / "cli").iterdir() if not p.name.startswith("."))
    for name in names:
        assert (tmp_path / "cli" / name).read_bytes() == (tmp_path / "held" / name).read_bytes(), name


def test_a_worker_that_dies_with_the_run_only_figures_leaves_them_drawn_in_process(tmp_path):
    """``start_run_plots``'s worker killed: ``finish_outputs`` draws its figures from timeseries.csv read back."""
    import os
    import signal

    from mechanism.cli import ideal_counterpart
    from mechanism.output import workers
    from mechanism.output.figures import FIGURES
    from mechanism.output.results import (
        DRAWN_WITH_IDEAL,
        compared_columns,
        finish_outputs,
        start_run_plots,
        write_run_table,
    )
    from mechanism.run import RunConfig, run
    config = RunConfig(revs=0.1, mode="inprocess", progress=False)
    result = run(config)
    with workers.OutputWorkers(1) as w:
        # stopped, it draws nothing; the job (~80 kB of columns) fits in the socket pair's buffers; then it dies
        os.kill(w._procs[0].pid, signal.SIGSTOP)
        drawing = start_run_plots(result, tmp_path, w)
        assert drawing is not None
        early = write_run_table(result, tmp_path)
        kept = compared_columns(result, DRAWN_WITH_IDEAL)
        os.kill(w._procs[0].pid, signal.SIGKILL)
        w._procs[0].join(5)
        figures = finish_outputs(early, kept, tmp_path, ideal_counterpart(config, kept), w, drawing)
    assert [os.path.basename(p) for p in figures["plots"]] == list(FIGURES)
    assert all((tmp_path / name).stat().st_size > 0 for name in FIGURES)


def test_run_only_figures_redrawn_from_the_csv_keep_the_run_meta(tmp_path):
    """Should the output worker die, ``start_run_plots``'s fallback reads timeseries.csv back: with the run's
    meta, status and message (the ball count and the titles come from the meta; a CSV has none)."""
    from mechanism.cosim.record import RunResult
    from mechanism.output import results
    meta = {"config": {"rpm": 600.0, "balls": 12}, "clearance_per_side_m": 1e-5}
    t = np.linspace(0.0, 1e-3, 11)
    run = RunResult(["time", "crank_angle", "e_x", "e_y"], np.column_stack([t, t, 0 * t + 1e-6, 0 * t]), meta,
                    "failed", "a cause")
    results.write_csv(run, tmp_path / "timeseries.csv")

    class Taker:
        def submit(self, *args, **kwargs):
            return True
    _, fallback = results.start_run_plots(run, tmp_path, Taker())
    back = fallback.result()
    assert back.meta == meta and back.status == "failed" and back.message == "a cause"
    assert np.allclose(back["e_x"], run["e_x"], rtol=1e-14)


def test_a_table_written_first_leaves_no_earlier_run_beside_it(tmp_path):
    """``write_run_table`` writes timeseries.csv before the ideal counterpart runs: an earlier run's
    summary.json and ideal_timeseries.csv go first (with plots, its figures too), so a run stopped in between
    leaves no mix of two runs in the folder."""
    from mechanism.output import results
    for name in ("summary.json", "ideal_timeseries.csv", "eccentricity.png"):
        (tmp_path / name).write_text("an earlier run")
    t = np.linspace(0.0, 1e-3, 11)
    from mechanism.cosim.record import BASE_COLUMNS
    names = list(dict.fromkeys(["time", "crank_angle", *BASE_COLUMNS]))
    run = RunResult(names, np.column_stack([t] * len(names)), {})
    results.write_run_table(run, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["eccentricity.png", "timeseries.csv"]

    class Taker:
        def submit(self, *args, **kwargs):
            return True
    results.start_run_plots(run, tmp_path, Taker())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["timeseries.csv"]


# --------------------------------------------------------------------- the table streamed during the run
def _synthetic_table(rng, rows: int, n_balls: int = 8) -> tuple[list[str], np.ndarray]:
    """A table with the columns the summary reads (times rising at 1e-3 s, a crank period of 0.1 s)."""
    from mechanism.cosim.record import BASE_COLUMNS, ENERGY_LAST
    columns = list(BASE_COLUMNS) + [c for c in ENERGY_LAST if c not in BASE_COLUMNS] \
        + [f"ball_load_{r + 1}" for r in range(n_balls)]
    data = rng.normal(size=(rows, len(columns))) * 100.0
    data[:, 0] = np.arange(rows) * 1e-3
    loads = data[:, -n_balls:]
    loads[loads < 0] = 0.0                        # unloaded balls
    data[rng.random(rows) < 0.01, -1] = np.nan    # a ball load not recorded now and then
    data[:, columns.index("omega_inner")] = 125.0 + rng.normal(size=rows)
    data[:, columns.index("omega_outer")] = 0.0
    return columns, data


@pytest.mark.parametrize("rows", [1, 2, 150, 257, 333])
def test_a_streamed_table_is_the_in_memory_writers_bytes_and_summary(tmp_path, monkeypatch, rows):
    """A table recorded through a streaming ``Recorder`` (blocks of 37 rows): timeseries.csv is ``write_csv``'s bytes
    and summary.json (peaks, energy, the second revolution's window and the whole run's and the window's life from
    the ball loads) is the in-memory summary's, for runs shorter and longer than the second revolution."""
    import json

    from fmu_bearing.parameters import from_values
    from mechanism.cosim import record
    from mechanism.cosim.record import Recorder
    from mechanism.output.results import summary, write_csv, write_json
    from mechanism.output.stream import TableStream
    monkeypatch.setattr(record, "STREAM_ROWS", 37)
    columns, data = _synthetic_table(np.random.default_rng(rows), rows)
    meta = {"config": {"joint": "bearing", "settings": {}, "balls": None}, "crank_period_s": 0.1,
            "output_interval_s": 1e-3}
    with TableStream(tmp_path / "s" / "timeseries.csv", ("time", "slider_a", "slider_x"), 0.1, 4e-3,
                     life=from_values({})) as sink:
        (tmp_path / "s").mkdir()
        rec = Recorder(columns, rows + 2, sink)
        for row in data:
            rec.next_row()[:] = row
        streamed = rec.result(meta, "completed", "")
        sink.commit()
    held = RunResult(columns, data, meta)
    write_csv(held, tmp_path / "h" / "timeseries.csv")
    assert (tmp_path / "s" / "timeseries.csv").read_bytes() == (tmp_path / "h" / "timeseries.csv").read_bytes()
    assert streamed.columns == ["time", "slider_x", "slider_a"] and same_bits(streamed.data, data[:, [0, 8, 10]])
    write_json(summary(streamed), tmp_path / "s.json")
    write_json(summary(held), tmp_path / "h.json")
    assert (tmp_path / "s.json").read_bytes() == (tmp_path / "h.json").read_bytes()
    if rows >= 250:
        assert json.loads((tmp_path / "s.json").read_text())["rev2"]["life"]["source"] == "recorded samples"
    assert not list((tmp_path / "s").glob(".*.tmp"))


def test_a_streamed_resample_is_resample(tmp_path, monkeypatch):
    """``resample`` into a sink (blocks of 37 rows, lazy spline coefficients) writes the bytes of the resampled
    table held whole, and keeps its columns to the bit."""
    from mechanism.cosim import record
    from mechanism.output.results import write_csv
    from mechanism.output.stream import TableStream
    monkeypatch.setattr(record, "STREAM_ROWS", 37)
    columns, data = _synthetic_table(np.random.default_rng(7), 120)
    t = data[:, 0]
    for k in range(1, len(columns)):                   # smooth columns (splined) ...
        data[:, k] = np.sin((k + 30) * 7.0 * t + k) * 10.0 ** (k % 7 - 3)
    data[5, 4] = np.nan                                # ... one with a gap (linear)
    data[:, 2] = np.nan                                # ... and one never recorded
    coarse = RunResult(columns, data, {"m": 1})
    times = np.arange(1200) * 1e-4
    held = resample(coarse, times)
    with TableStream(tmp_path / "s.csv", ("time", "slider_a", "slider_x"), 0.05, 1e-3) as sink:
        streamed = resample(coarse, times, sink)
        sink.commit()
    write_csv(held, tmp_path / "h.csv")
    assert (tmp_path / "s.csv").read_bytes() == (tmp_path / "h.csv").read_bytes()
    assert streamed.meta == held.meta
    assert same_bits(streamed["slider_a"], held["slider_a"]) and same_bits(streamed["slider_x"], held["slider_x"])


def test_a_run_failing_midway_keeps_the_streamed_rows(tmp_path, monkeypatch):
    """The command streams timeseries.csv (blocks of 16 rows): a run that diverges mid-way leaves the
    rows up to the failure, the bytes ``write_csv`` writes of the same run held in memory, and a failed status."""
    import json

    from mechanism.cli import main
    from mechanism.cosim import record
    from mechanism.output.results import summary, write_csv
    from mechanism.run import RunConfig, run
    monkeypatch.setattr(record, "STREAM_ROWS", 16)
    args = ["run", "--mode", "inprocess", "--revs", "0.5", "--step", "2e-5", "--scheme", "zoh",
            "--quiet", "--no-plots", "--no-ideal", "--out", str(tmp_path / "cli")]
    assert main(args) == 1
    held = run(RunConfig(mode="inprocess", revs=0.5, step=2e-5, scheme="zoh", progress=False))
    assert held.status == "failed" and 16 * 3 < len(held.data) < 1000
    write_csv(held, tmp_path / "timeseries.csv")
    assert (tmp_path / "cli" / "timeseries.csv").read_bytes() == (tmp_path / "timeseries.csv").read_bytes()
    got = json.loads((tmp_path / "cli" / "summary.json").read_text())
    assert got["status"] == "failed" and got["samples"] == len(held.data)
    assert got["all"] == json.loads(json.dumps(summary(held)["all"]))
    assert not list((tmp_path / "cli").glob(".*.tmp"))


@pytest.mark.parametrize("n", [1, 2])
def test_the_command_gathering_columns_in_its_workers_writes_what_write_outputs_writes(tmp_path, monkeypatch, n):
    """With 20 kB gathered at a time (``stream.GATHER_BYTES``) a 0.2-revolution run sends its columns of the
    run-only figures to the first worker in blocks during the run and (two workers) those of the figures with the
    ideal curve to the second, and keeps neither: every file, PNGs too, is what ``write_outputs`` writes in-process
    from the run and its ideal counterpart held whole."""
    from mechanism.cli import ideal_counterpart, main
    from mechanism.output import stream, workers
    from mechanism.output.results import write_outputs
    from mechanism.run import RunConfig, run
    monkeypatch.setenv("MECHANISM_OUTPUT_WORKERS", str(n))
    monkeypatch.setattr(stream, "GATHER_BYTES", 20_000)
    # (an earlier run in this process left tqdm's monitor thread, with which no worker would be forked)
    monkeypatch.setattr(workers.threading, "active_count", lambda: 1)
    sinks = []
    monkeypatch.setattr(stream, "for_run", lambda *a, f=stream.for_run, **k: sinks.append(f(*a, **k)) or sinks[-1])
    assert main(["run", "--revs", "0.2", "--mode", "inprocess", "--quiet", "--out", str(tmp_path / "cli")]) == 0
    assert bool(sinks[0].gathers(1)) == (n == 2) and sinks[0].gathers(0) and not sinks[0].lost
    config = RunConfig(revs=0.2, mode="inprocess", progress=False)
    result = run(config)
    held = write_outputs(result, tmp_path / "held", ideal_counterpart(config, result))
    names = sorted(p.name for p in (tmp_path / "held").iterdir() if not p.name.startswith("."))
    assert len(held["plots"]) == 7
    assert names == sorted(p.name for p in (tmp_path / "cli").iterdir() if not p.name.startswith("."))
    for name in names:
        assert (tmp_path / "cli" / name).read_bytes() == (tmp_path / "held" / name).read_bytes(), name


@pytest.mark.parametrize("dies", ["during the run", "after the run"])
def test_columns_gathered_by_a_worker_that_died_are_read_back(tmp_path, monkeypatch, dies):
    """The second worker, holding the run's columns of the figures with the ideal curve, killed (during the run:
    a block it cannot take; after it: the job it cannot take): those figures are drawn here from the columns read
    back from timeseries.csv (and the tables are the streamed bytes)."""
    import os

    from mechanism.cli import ideal_counterpart
    from mechanism.output import stream, workers
    from mechanism.output.figures import FIGURES
    from mechanism.output.results import (
        DRAWN_WITH_IDEAL,
        compared_columns,
        finish_outputs,
        start_run_plots,
        write_run_table,
    )
    from mechanism.run import RunConfig, run
    monkeypatch.setattr(stream, "GATHER_BYTES", 20_000)
    config = RunConfig(revs=0.2, mode="inprocess", progress=False)
    with workers.OutputWorkers(2) as w, stream.for_run(tmp_path, config, True, w) as sink, \
            stream.for_ideal(tmp_path, config, True, w) as ideal_sink:
        if dies == "during the run":
            kill_worker(w, 1)
        result = run(config, sink)
        assert sink.gathers(1) and sink.lost == (dies == "during the run")
        if dies == "after the run":
            kill_worker(w, 1)
        drawing = start_run_plots(result, tmp_path, w)
        early = write_run_table(result, tmp_path)
        kept = compared_columns(result, DRAWN_WITH_IDEAL)
        figures = finish_outputs(early, kept, tmp_path, ideal_counterpart(config, kept, w, ideal_sink), w, drawing)
    assert [os.path.basename(p) for p in figures["plots"]] == list(FIGURES)
    assert all((tmp_path / name).stat().st_size > 0 for name in FIGURES)
    assert not list(tmp_path.glob(".*.tmp"))


def test_only_a_component_without_life_variables_has_its_life_accumulated_from_the_stream(ball_bearing_fmu,
                                                                                          journal_clearance_fmu):
    """A streamed run accumulates the whole run's life from the recorded ball loads (~4 µs a sample) only when the
    component gives no life outputs at the end: not for the in-process law or the BallBearing FMU (asked before it
    is instantiated), as for a component without the life variables."""
    from fmu_bearing.parameters import from_values
    from mechanism.cosim.endpoints import InProcessEndpoint, fmu_endpoint
    from mechanism.run import _life_outputs
    assert _life_outputs(InProcessEndpoint(from_values({})))
    bearing, clearance = fmu_endpoint(ball_bearing_fmu), fmu_endpoint(journal_clearance_fmu)
    try:
        assert _life_outputs(bearing) and not _life_outputs(clearance)
    finally:
        bearing.close()
        clearance.close()


def test_an_interrupted_streamed_run_hands_its_rows_on_as_interrupted(tmp_path, monkeypatch):
    """``run._mark_interrupted`` settles a stopped run as "interrupted": the streamed table's rows still to be handed
    to an output worker (``TableStream.tail``) carry that status and message, not the master's "failed"."""
    from mechanism import run as run_module
    from mechanism.output.results import run_only_columns
    from mechanism.output.stream import TableStream

    class Keeps:   # an output worker that takes every block
        def gather(self, k, part):
            return True

    original = run_module._interruptible

    def interrupting(observe):   # as if SIGINT came as the run started: it stops at its first sample
        run_module._Stop.signal = "SIGINT"
        return original(observe)
    monkeypatch.setattr(run_module._Stop, "signal", None)
    monkeypatch.setattr(run_module, "_interruptible", interrupting)
    sink = TableStream(tmp_path / "timeseries.csv", ("time", "slider_a"), gather=(Keeps(), {0: run_only_columns}))
    with sink:
        r = run_module.run(run_module.RunConfig(revs=0.2, mode="inprocess", progress=False), sink)
        tail = sink.tail(0)
    assert r.status == "interrupted" and r.message.startswith("interrupted by SIGINT")
    assert (tail.status, tail.message, tail.meta["interrupted"]) == (r.status, r.message, r.meta["interrupted"])
