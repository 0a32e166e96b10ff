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
