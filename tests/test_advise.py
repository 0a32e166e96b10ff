"""The step-size advisor: the ladder, the bisection (against a known synthetic limit), the refusal of
impossible set-ups, and one small end-to-end question through the FMU."""
import json
import math

import pytest

from mechanism.cli import main
from mechanism.studies.advise import MERITS, SchemeSearch, ladder
from mechanism.studies.stepsize.cases import DIVERGENT, FAILED, STABLE, snap_step


def test_ladder_lies_on_the_output_grid_and_respects_the_resolution():
    dt = 1e-5
    steps = ladder(dt, 4e-6, 1e-3, 1.25)
    assert steps == sorted(steps) and steps[0] >= 4e-6 and steps[-1] == pytest.approx(1e-3)
    assert all(snap_step(h, dt) == pytest.approx(h) for h in steps)        # comparable on the reference's grid
    assert all(b / a >= 1.25 - 1e-9 for a, b in zip(steps, steps[1:-1]))   # (the top rung is kept as it is)
    assert len(ladder(dt, 4e-6, 1e-3, 1.0)) == 100 + 1                     # dt/2 and 1..100 dt


def synthetic_row(h: float, stable_below: float, error_at_1: float, order: float) -> dict:
    """A run at step h: stable iff h <= stable_below; peak-force error error_at_1 * (h / 1e-5)^order."""
    if h > stable_below:
        return {"status": FAILED if h > 2 * stable_below else DIVERGENT, "step": h}
    return {"status": STABLE, "step": h, "peak_force_err_rel": -error_at_1 * (h / 1e-5) ** order}


@pytest.mark.parametrize("stable_below, error_at_1, order", [(3.3e-5, 4e-3, 1.0), (2.2e-4, 1e-4, 2.0),
                                                              (2e-3, 1e-5, 1.0), (1e-6, 1e-3, 1.0)])
def test_bisection_brackets_both_limits_between_neighbouring_steps(stable_below, error_at_1, order):
    steps = ladder(1e-5, 2e-6, 1e-3, 1.25)
    search = SchemeSearch("x", steps, steps.index(min(steps, key=lambda h: abs(math.log(h / 1e-4)))))
    runs = 0
    while not search.done:
        for i in search.next_probes():
            search.record(i, synthetic_row(steps[i], stable_below, error_at_1, order), 0.01, ["peak-force"])
            runs += 1
    assert runs <= 12 and not search.non_monotone
    truth_stable = [h for h in steps if h <= stable_below]
    truth_within = [h for h in truth_stable if error_at_1 * (h / 1e-5) ** order <= 0.01]
    for which, truth in (("stable", truth_stable), ("within", truth_within)):
        lim = search.limit(which)
        assert lim["step"] == (truth[-1] if truth else None)
        if truth and truth[-1] == steps[-1]:
            assert lim["above_range"] and lim["fails_at"] is None            # a bound, not a limit
        elif not truth:
            assert lim["below_range"] and lim["fails_at"] == steps[0]
        else:
            assert lim["fails_at"] == steps[steps.index(truth[-1]) + 1]     # neighbours on the ladder


def test_fifteen_balls_are_refused_with_the_reason_and_the_option(capsys):
    code = main(["advise", "--rpm", "600", "--balls", "15", "--tolerance", "1%", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert "15 balls" in err and "do not fit" in err and "--set allow_ball_overlap=true" in err


def test_bad_options_are_errors(capsys):
    assert main(["advise", "--merit", "nonsense", "--quiet"]) == 2
    assert "figure(s) of merit" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["advise", "--tolerance", "one percent"])


def test_advise_end_to_end_through_the_fmu(tmp_path, ball_bearing_fmu, capsys):
    """A short window (0.05 revolution at 1200 rpm, the start-up impacts): zoh must be found unstable at a
    smaller step than jacobian-drift, every limit bracketed by runs that show it, and the files written."""
    out = tmp_path / "advice"
    code = main(["advise", "--rpm", "1200", "--revs", "0.05", "--schemes", "jacobian-drift,zoh",
                 "--fmu", str(ball_bearing_fmu), "--max-step", "4e-5", "--max-steps", "3000",
                 "--resolution", "1.5", "--workers", "2", "--quiet", "--no-plots",
                 "--reference-cache", str(tmp_path / "refs"), "--out", str(out), "--tolerance", "2%",
                 "--merit", "peak-force,max-eccentricity"])
    console = capsys.readouterr().out
    assert code == 0, console
    first = console.splitlines()[0]
    assert first.startswith("1200 rpm, 8 balls, peak joint force and max eccentricity within 2 %: use ")
    info = json.loads((out / "advise.json").read_text())
    rows = (out / "advise.csv").read_text().splitlines()
    assert len(rows) == 1 + info["runs"] and (out / "advise.md").is_file()
    zoh, drift = info["schemes"]["zoh"]["stable"], info["schemes"]["jacobian-drift"]["stable"]
    assert (zoh["step"] or 0) < (drift["step"] or math.inf)
    for scheme in ("zoh", "jacobian-drift"):
        for which in ("stable", "within_tolerance"):
            lim = info["schemes"][scheme][which]
            assert lim["step"] is not None or lim["below_range"]
            assert lim["fails_at"] is not None or lim["above_range"]
    assert info["answer"]["merit_error"] <= 0.02
    assert set(MERITS) >= {"peak-force", "max-eccentricity", "max-ball-load", "slider-acceleration"}
