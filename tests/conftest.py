"""Shared fixtures: the built FMUs (built once per test session, or reused from dist/ when up to date)."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import build_fmu  # noqa: E402

#: per-ball capacity the tests expect of the default build
TEST_CAPACITY = build_fmu.DEFAULT_MAX_BALLS


def built_fmu(name: str, tmp_path_factory, max_balls: int = TEST_CAPACITY) -> Path:
    """Path of FMU ``name`` of build_fmu.REGISTRY: dist/<name>.fmu if up to date, else a fresh build
    into a pytest temporary folder; skips the test if the FMU's slave script does not exist yet."""
    spec = next(s for s in build_fmu.REGISTRY if s.name == name)
    if not spec.script.is_file():
        pytest.skip(f"{spec.script} does not exist yet")
    dist = ROOT / "dist" / f"{name}.fmu"
    if build_fmu.is_fresh(dist, spec, max_balls):
        return dist
    out = tmp_path_factory.mktemp(f"fmu_{name}")
    return build_fmu.build(out, max_balls, names=[name], verbose=False)[name]


@pytest.fixture(scope="session")
def ball_bearing_fmu(tmp_path_factory) -> Path:
    """The BallBearing FMU (per-ball capacity 20), built once per session."""
    return built_fmu("BallBearing", tmp_path_factory)


@pytest.fixture(scope="session")
def journal_clearance_fmu(tmp_path_factory) -> Path:
    """The JournalClearance FMU, built once per session (skips while its slave does not exist)."""
    return built_fmu("JournalClearance", tmp_path_factory)


@pytest.fixture(scope="session")
def slider_crank_fmu(tmp_path_factory) -> Path:
    """The SliderCrank FMU, built once per session (skips while its slave does not exist)."""
    return built_fmu("SliderCrank", tmp_path_factory)
