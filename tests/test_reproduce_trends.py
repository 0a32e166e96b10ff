"""The paper's Section 5 trends on short runs, and the reproduce command's cache and report.

Short runs (half a crank revolution, or one where a spectrum is needed) keep this file to about
half a minute. The trends are measured over the same crank-angle window at every speed or ball
count: 0.5 pi to pi, after the start transient (the journal starts centred and drops through the
clearance), unless said otherwise.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from mechanism.run import RunConfig, run
from mechanism.studies import reproduce as rp
from mechanism.studies.reproduce.analysis import (ball_angles, ball_deflections, ball_loads, eccentricity,
                                                rms_deviation, vibration_frequency)

WINDOW = (0.5 * np.pi, np.pi)   # crank-angle window of the trend checks [rad]


def short(rpm: float, revs: float = 0.5, output_interval: float = 1e-4, **kw) -> RunConfig:
    return RunConfig(rpm=rpm, revs=revs, output_interval=output_interval, progress=False, **kw)


def in_window(r) -> np.ndarray:
    a = r["crank_angle"]
    return (a >= WINDOW[0]) & (a <= WINDOW[1])


@pytest.fixture(scope="module")
def ideal_1200():
    return run(short(1200, joint="ideal"))


# --- speed -------------------------------------------------------------------------------------------
def test_max_eccentricity_grows_with_speed():
    emax = []
    for rpm in rp.SPEEDS:
        r = run(short(rpm, mode="inprocess"))
        assert r.ok, r.message
        emax.append(float(np.max(eccentricity(r)[in_window(r)])))
    assert all(b > a for a, b in zip(emax, emax[1:])), f"max |e| over 0.5pi..pi per speed: {emax}"
    # beyond the clearance: the balls are loaded, not just the free play
    assert emax[0] > 0.5 * rp.BearingParameters().radial_clearance


# --- ball count ----------------------------------------------------------------------------------------
def test_run_list_marks_only_the_overlapping_ball_counts():
    specs = {s.name: s for s in rp.run_specs(revs=0.1)}
    assert rp.balls_fit(8) and rp.balls_fit(13) and not rp.balls_fit(14)
    assert "allow_ball_overlap" not in specs["bearing-1200"].config.settings
    for n in (15, 20):
        cfg = specs[f"bearing-1200-{n}balls"].config
        assert cfg.balls == n and cfg.settings["allow_ball_overlap"] is True
    assert all(s.config.mode == "cosim" for s in specs.values())
    k = rp.paper_stiffness()
    assert k == pytest.approx(rp.BallBearing().stiffness / 1000.0)
    assert all(s.config.settings["contact_stiffness"] == k for n, s in specs.items() if n.startswith("paperK"))


def test_more_balls_smaller_eccentricity_and_load_and_closer_to_ideal(ideal_1200):
    emax, load, dev = [], [], []
    for n in rp.BALL_COUNTS:
        r = run(short(1200, balls=n, mode="inprocess", settings={"allow_ball_overlap": not rp.balls_fit(n)}))
        assert r.ok, r.message
        m = in_window(r)
        emax.append(float(np.max(eccentricity(r)[m])))
        load.append(float(np.max(ball_loads(r)[m])))
        dev.append(rms_deviation(r, ideal_1200, "slider_a", m))
    for name, values in (("max |e|", emax), ("max ball load", load), ("RMS slider acc. deviation", dev)):
        assert all(b < a for a, b in zip(values, values[1:])), f"{name} for {rp.BALL_COUNTS} balls: {values}"


# --- through the FMU -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def bearing_fmu_run(ball_bearing_fmu):
    """One crank revolution at 1200 rpm through the BallBearing FMU, sampled every step."""
    r = run(short(1200, revs=1.0, output_interval=1e-5, fmu=str(ball_bearing_fmu)))
    assert r.ok, r.message
    assert r.meta["endpoint"] == "fmu"
    return r


def test_only_balls_in_the_load_zone_carry_force(bearing_fmu_run):
    r = bearing_fmu_run
    loads, delta = ball_loads(r), ball_deflections(r)
    outside = delta <= 0.0
    assert outside.any() and (~outside).any()
    assert np.all(loads[outside] == 0.0), "a ball outside the load zone (e.u_r - P_d/2 <= 0) carries load"
    # inside the load zone the force is K delta^1.5 plus damping, clamped at zero; well inside it is positive
    deep = delta > 0.2e-6
    assert np.mean(loads[deep] > 0) > 0.99
    # never all balls at once (a clearance bearing), and the resultant is the sum of the recorded ball loads (eq. 19)
    assert np.all(np.sum(loads > 0, axis=1) < loads.shape[1])
    phi = ball_angles(r)
    np.testing.assert_allclose(np.sum(loads * np.cos(phi), axis=1), r["F_x"], atol=1e-6 * np.max(np.abs(r["F_x"])))
    np.testing.assert_allclose(np.sum(loads * np.sin(phi), axis=1), r["F_y"], atol=1e-6 * np.max(np.abs(r["F_x"])))


def test_clearance_joint_alike_in_trajectory_but_vibrates_at_another_frequency(bearing_fmu_run,
                                                                             journal_clearance_fmu):
    b = bearing_fmu_run
    c = run(short(1200, revs=1.0, output_interval=1e-5, joint="clearance", fmu=str(journal_clearance_fmu)))
    assert c.ok, c.message
    ideal = run(short(1200, revs=1.0, output_interval=1e-5, joint="ideal"))
    # after the start transient (crank angle >= 0.5 pi), where both carry the mechanism's loads
    eb = float(np.max(eccentricity(b)[b["crank_angle"] >= WINDOW[0]]))
    ec = float(np.max(eccentricity(c)[c["crank_angle"] >= WINDOW[0]]))
    assert 0.5 < eb / ec < 2.0, f"max |e|: bearing {eb}, clearance {ec}"
    # same shape: the journal goes the same way (direction of e) once both are in contact
    m = (eccentricity(b) > 1.05e-5) & (np.interp(b["time"], c["time"], eccentricity(c)) > 1.05e-5)
    ang_b = np.arctan2(b["e_y"], b["e_x"])[m]
    ang_c = np.interp(b["time"], c["time"], np.unwrap(np.arctan2(c["e_y"], c["e_x"])))[m]
    assert np.degrees(np.sqrt(np.mean(np.angle(np.exp(1j * (ang_b - ang_c))) ** 2))) < 30.0
    # different contact vibration: dominant frequency of slider acceleration minus the ideal joint's,
    # above 8x the crank frequency; the two must differ by more than 50 %
    fb, fc = vibration_frequency(b, ideal), vibration_frequency(c, ideal)
    assert fb > 160 and fc > 160
    assert abs(fc / fb - 1.0) > 0.5, f"vibration frequencies: bearing {fb} Hz, clearance {fc} Hz"


# --- the command: cache and report ------------------------------------------------------------------------
def tiny_specs(revs=0.02):
    base = dict(rpm=1200.0, revs=revs, progress=False)
    return [rp.RunSpec("ideal-1200", "ideal", "ideal", RunConfig(joint="ideal", **base)),
            rp.RunSpec("bearing-1200", "bearing", "bearing", RunConfig(joint="bearing", balls=8, **base))]


def test_cache_second_call_recomputes_nothing(tmp_path):
    first = rp.reproduce(tmp_path, specs=tiny_specs(), report=False, workers=2, progress=False)
    assert sorted(first["computed"]) == ["bearing-1200", "ideal-1200"] and first["cached"] == []
    assert all(r.ok for r in first["results"].values())
    assert first["results"]["bearing-1200"].meta["endpoint"] == "fmu"       # through the FMU
    again = rp.reproduce(tmp_path, specs=tiny_specs(), report=False, workers=2, progress=False)
    assert again["computed"] == [] and sorted(again["cached"]) == ["bearing-1200", "ideal-1200"]
    for name, r in first["results"].items():
        np.testing.assert_array_equal(again["results"][name].data, r.data)
        assert again["results"][name].columns == r.columns
    meta = json.loads((again["paths"]["bearing-1200"] / "meta.json").read_text())
    assert meta["code_version"] == rp.code_version() and meta["wall_time_s"] > 0
    # a changed input is a new key; --force recomputes everything
    changed = rp.reproduce(tmp_path, specs=tiny_specs(revs=0.03), report=False, workers=1, progress=False)
    assert sorted(changed["computed"]) == ["bearing-1200", "ideal-1200"]
    forced = rp.reproduce(tmp_path, specs=tiny_specs(), report=False, workers=1, progress=False, force=True)
    assert sorted(forced["computed"]) == ["bearing-1200", "ideal-1200"]


def test_cache_key_covers_config_and_code_but_not_progress():
    cfg = RunConfig(rpm=600.0, revs=0.1)
    v = rp.code_version()
    assert rp.config_key(cfg, v) == rp.config_key(RunConfig(rpm=600.0, revs=0.1, progress=False, fmu="x.fmu"), v)
    assert rp.config_key(cfg, v) != rp.config_key(RunConfig(rpm=600.0, revs=0.1, settings={"n_balls": 9}), v)
    assert rp.config_key(cfg, v) != rp.config_key(cfg, "another code version")
    names = {p.relative_to(rp.ROOT).as_posix() for p in rp.code_files()}
    assert {"mechanism/run.py", "mechanism/cosim/master.py", "mechanism/multibody/solver.py",
            "fmu_bearing/ball_bearing.py", "build_fmu.py"} <= names
    assert not any(n.startswith(("mechanism/studies/", "mechanism/output/")) for n in names)


def test_command_writes_figures_and_report(tmp_path):
    from mechanism.cli import main
    out = tmp_path / "repro"
    assert main(["reproduce", "--out", str(out), "--revs", "0.04", "--workers", "2", "--quiet"]) == 0
    readme = (out / "report" / "README.md").read_text()
    for text in ("Fig. 11", "Fig. 25", "paper-units", "allow_ball_overlap", "oil_film_damping", "kg·mm·s",
                 "Baumgarte", "bearing-1200-20balls", "clearance-1200", "paperK-600"):
        assert text in readme, text
    # criteria first, then a verdict for every figure (the start-up too), each in the summary table
    assert readme.index("## Criteria of the verdicts") < readme.index("## Verdicts") < readme.index("### Fig. 11")
    for fig in ("11", "12", "13", "14", "15", "16", "17–18", "19", "20", "21", "22", "23–24", "25"):
        assert f"**Verdict (Fig. {fig}, " in readme and f"\n| Fig. {fig} | " in readme, fig
    assert "**Verdict (Fig. 17–18, start-up" in readme and "Believed right:" in readme
    figures = {p.name for p in (out / "report" / "figures").glob("*.png")}
    for stem in ("fig11", "fig12", "fig13", "fig14", "fig15", "fig16", "fig17", "fig18", "fig19", "fig20",
                 "fig21", "fig22", "fig23_24", "fig25", "paperK"):
        assert any(f.startswith(stem) for f in figures), stem
    assert len(list((out / "cache").iterdir())) == len(rp.run_specs())


def test_ideal_joint_runs_at_the_larger_step_give_the_same_result():
    """The ideal runs use IDEAL_STEP (no contact); checked against the contact runs' 1e-5 s step."""
    from mechanism.studies.reproduce.analysis import on_times
    fine = run(short(1200, revs=0.2, output_interval=1e-5, joint="ideal"))
    coarse = run(short(1200, revs=0.2, step=rp.IDEAL_STEP, output_interval=rp.IDEAL_STEP, joint="ideal"))
    every = int(round(rp.IDEAL_STEP / 1e-5))
    for col in ("slider_x", "slider_a", "F_x", "F_y", "crank_moment"):
        scale = np.max(np.abs(fine[col]))
        np.testing.assert_allclose(coarse[col], fine[col][::every][:len(coarse[col])], rtol=0, atol=1e-8 * scale)
        # and interpolated onto the fine grid, as the report compares them with the bearing runs
        np.testing.assert_allclose(on_times(coarse, fine, col), fine[col], rtol=0, atol=1e-7 * scale)


def test_step_size_study_is_added_to_the_report(tmp_path):
    """Issue 6: the step-size summary and plots join the reproduction report when both exist."""
    from mechanism.studies.reproduce import append_stepsize_study
    study = tmp_path / "study"
    study.mkdir()
    (study / "stepsize_summary.md").write_text("# Co-simulation step-size study\n\n## 1200rpm\n\n| scheme |\n")
    (study / "stepsize_error_vs_step_1200rpm.png").write_bytes(b"png")
    report = tmp_path / "report" / "README.md"
    report.parent.mkdir()
    report.write_text("# Reproduction\n")
    assert append_stepsize_study(report, study)
    text = report.read_text()
    assert "## Co-simulation step size" in text and "### 1200rpm" in text
    assert "figures/stepsize_error_vs_step_1200rpm.png" in text
    assert (report.parent / "figures" / "stepsize_error_vs_step_1200rpm.png").is_file()
    assert not append_stepsize_study(report, tmp_path / "missing")
