"""The life study (``python -m mechanism life-study``) and the life figures of runs (issue 16)."""
from __future__ import annotations

import csv
import math

import pytest

from mechanism.cli import main


def read_rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_life_study_writes_tables_and_plots(tmp_path, capsys):
    out = tmp_path / "life"
    code = main(["life-study", "--out", str(out), "--clearances=-6,20", "--speeds", "1200", "--startup-revs", "0.25",
                 "--window-revs", "0.25", "--workers", "2", "--quiet"])
    assert code == 0, capsys.readouterr().err
    for name in ("clearance", "speed"):
        assert (out / f"life_vs_{name}.png").stat().st_size > 10_000
    rows = read_rows(out / "life_vs_clearance.csv")
    assert [float(r["radial_clearance [m]"]) for r in rows] == pytest.approx([-6e-6, 20e-6])
    lives = [float(r["rating_life_h [h]"]) for r in rows]
    assert all(r["status"] == "completed" for r in rows) and all(0 < x < math.inf for x in lives)
    assert float(rows[0]["window_start_s [s]"]) == pytest.approx(0.25 * 0.05)
    speed = read_rows(out / "life_vs_speed.csv")[0]
    # the same operating point in both sweeps: the same life
    assert float(speed["rating_life_h [h]"]) == pytest.approx(lives[1], rel=1e-12)


def test_life_study_refuses_an_unstable_step(tmp_path, capsys):
    code = main(["life-study", "--out", str(tmp_path), "--step", "1e-4", "--quiet"])
    assert code == 2 and "--step" in capsys.readouterr().err


# --- the life figures of single runs (summary.json) ---------------------------------------------

@pytest.fixture(scope="module")
def runs(ball_bearing_fmu):
    from mechanism.run import RunConfig, run
    base = RunConfig(rpm=1200.0, revs=0.2, step=1e-5, progress=False, fmu=str(ball_bearing_fmu))   # a sample every step
    from dataclasses import replace
    return {mode: run(replace(base, mode=mode)) for mode in ("cosim", "inprocess", "monolithic")}


def test_summary_life_from_the_fmu_equals_the_in_process_accumulator(runs):
    from mechanism.output.results import summary
    fmu, inproc = summary(runs["cosim"])["life"], summary(runs["inprocess"])["life"]
    assert fmu["source"] == inproc["source"] == "component outputs"
    for key in ("equivalent_load_inner_N", "equivalent_load_outer_N", "rating_life_h", "rating_life_Mrev"):
        assert 0 < fmu[key] < math.inf
        assert fmu[key] == pytest.approx(inproc[key], rel=1e-9)


def test_fmi3_fmu_reports_the_same_life(runs, tmp_path_factory):
    """BallBearing3 (FMI 3.0) accumulates the life like the FMI 2.0 FMU (same run, same figures)."""
    from conftest import built_fmu
    from mechanism.output.results import summary
    from mechanism.run import RunConfig, run
    fmu3 = built_fmu("BallBearing3", tmp_path_factory)
    r3 = run(RunConfig(rpm=1200.0, revs=0.2, step=1e-5, progress=False, fmu=str(fmu3)))
    life3, life2 = summary(r3)["life"], summary(runs["cosim"])["life"]
    assert life3["source"] == "component outputs"
    for key in ("dynamic_load_rating_N", "equivalent_load_inner_N", "equivalent_load_outer_N", "rating_life_h"):
        assert life3[key] == pytest.approx(life2[key], rel=1e-12)


def test_fmu_final_outputs_equal_the_recorded_loads_accumulated(runs):
    """The FMU accumulates every step; the samples (every step here) accumulated afterwards agree."""
    from mechanism.output.life import run_life
    r = runs["cosim"]
    t = r["time"]
    fmu = run_life(r)
    samples = run_life(r, (float(t[0]), float(t[-1])))
    assert samples["source"] == "recorded samples"
    for key in ("equivalent_load_inner_N", "equivalent_load_outer_N", "rating_life_h"):
        assert samples[key] == pytest.approx(fmu[key], rel=1e-9)


def test_monolithic_life_is_close_to_the_cosimulation(runs):
    from mechanism.output.results import summary
    mono, fmu = summary(runs["monolithic"])["life"], summary(runs["cosim"])["life"]
    assert mono["source"] == "recorded samples"
    assert mono["rating_life_h"] == pytest.approx(fmu["rating_life_h"], rel=0.01)   # measured 0.4 %


def test_ideal_joint_has_no_life():
    from mechanism.output.results import summary
    from mechanism.run import RunConfig, run
    r = run(RunConfig(rpm=1200.0, revs=0.05, joint="ideal", step=1e-4, output_interval=1e-4, progress=False))
    assert summary(r)["life"] is None


def test_reproduction_report_has_a_life_table(tmp_path):
    """A two-revolution run (3000 rpm keeps it short) gets a steady-cycle and a whole-run life in the report."""
    from mechanism.run import RunConfig
    from mechanism.studies import reproduce as rp
    spec = rp.RunSpec("bearing-3000", "bearing", "bearing",
                      RunConfig(joint="bearing", rpm=3000.0, revs=2.0, balls=8, progress=False))
    rp.reproduce(tmp_path, specs=[spec], workers=1, progress=False)
    text = (tmp_path / "report" / "README.md").read_text()
    table = text[text.index("## Bearing rating life per operating point"):].split("\n\n")[2]
    row = next(line for line in table.splitlines() if line.startswith("| `bearing-3000`"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    steady_h, whole_h = float(cells[6]), float(cells[7])
    assert 0 < steady_h < math.inf and 0 < whole_h < math.inf
    assert whole_h < steady_h        # the start-up transient (the journal drops through the clearance) costs life
