"""The step-size study's reference scheduling: a missing reference is computed beside the cases (its run and its
rtol/10 floor run as two jobs), the cases run meanwhile and are compared once it is there; a cached reference
is compared with in the worker. Both paths give the same rows; a failing reference makes error rows."""
from __future__ import annotations

import math

import pytest

from mechanism.studies import stepsize as st
from mechanism.studies.stepsize import reference as reference_module
from mechanism.studies.stepsize import runs as runs_module
from mechanism.studies.stepsize.reference import compute_reference


def _config(tmp_path, cache, **kw) -> st.StudyConfig:
    kw.setdefault("schemes", ["jacobian-drift", "zoh"])
    kw.setdefault("steps", [5e-6, 1e-5])
    return st.StudyConfig(out=str(tmp_path), mode="inprocess", rpms=[1200.0], revs=0.04, workers=1,
                          reference_cache=str(cache), progress=False, plots=False, **kw)


def _same(a: dict, b: dict) -> None:
    for c in st.COLUMN_NAMES:
        if c in st.PLACEMENT_COLUMNS:
            continue
        assert a[c] == b[c] or (isinstance(a[c], float) and math.isclose(a[c], b[c], rel_tol=1e-12)), c


def test_rows_with_a_fresh_reference_equal_the_rows_with_the_cached_one(tmp_path):
    """First study: no cached reference (cases run beside it, compared in the parent); second: cached (compared in
    the worker, ``run_case``). Same rows; the cached reference holds the floor of compute_reference."""
    cache = tmp_path / "refs"
    fresh = st.run_study(_config(tmp_path / "a", cache))
    assert len(list(cache.glob("reference_*.npz"))) == 1
    cached = st.run_study(_config(tmp_path / "b", cache))
    assert [r["status"] for r in fresh.rows].count(st.STABLE) >= 2
    for a, b in zip(fresh.rows, cached.rows):
        _same(a, b)
        assert a["ref_floor_force_max_rel"] is not None and a["ref_floor_force_max_rel"] < 1e-4
    (key,) = {c["reference"] for c in st.build_cases(_config(tmp_path, cache), None)}
    phys = st.cases.physical_case(1200.0, None, {}, _config(tmp_path, cache))
    floor = compute_reference(phys)["floor"]
    saved = reference_module.load_reference(cache, key)
    assert saved["floor__force_max_rel"] == pytest.approx(floor["force_max_rel"], rel=1e-12)


def test_a_failing_reference_makes_error_rows_and_keeps_the_sweep(tmp_path, monkeypatch):
    """The reference's run fails: every case that needed it is an error row naming the cause; nothing cached."""
    def broken(phys, rtol=None):
        return {"error": "RuntimeError: LSODA failed: boom"}
    monkeypatch.setattr(runs_module, "reference_run_job", broken)
    cache = tmp_path / "refs"
    result = st.run_study(_config(tmp_path / "a", cache))
    assert len(result.rows) == 4
    for row in result.rows:
        assert row["status"] == st.ERROR
        assert "reference failed" in row["message"] and "boom" in row["message"]
        assert row["wall_time"] is not None                 # the case itself ran
    assert not list(cache.glob("reference_*.npz"))
    (info,) = result.summary["references"].values()
    assert "boom" in info["error"]


def test_skipped_cases_do_not_wait_for_a_reference(tmp_path):
    """A cost cap below every case: all skipped, their rows written; the reference is still computed and cached."""
    cache = tmp_path / "refs"
    result = st.run_study(_config(tmp_path / "a", cache, max_steps_per_case=10))
    assert [r["status"] for r in result.rows] == [st.SKIPPED] * 4
    assert len(list(cache.glob("reference_*.npz"))) == 1
