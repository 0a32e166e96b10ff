"""Shared fixtures: the built FMUs (built once per test session, or reused from dist/ when up to date)."""
from __future__ import annotations

import json
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import build_fmu  # noqa: E402

#: per-ball capacity the tests expect of the default build
TEST_CAPACITY = build_fmu.DEFAULT_MAX_BALLS


def _sources(spec) -> list[Path]:
    """Files an FMU is built from: its packages (incl. the slave scripts), its script, the build script."""
    files = [spec.script, Path(build_fmu.__file__)]
    for package in spec.packages:
        files += build_fmu.package_dir(package).rglob("*.py")
    return files


def _fresh(fmu: Path, spec, max_balls: int) -> bool:
    """``fmu`` exists, is newer than every source file, and was built with ``max_balls``."""
    if not fmu.is_file():
        return False
    mtime = fmu.stat().st_mtime
    if any(src.stat().st_mtime >= mtime for src in _sources(spec) if src.is_file()):
        return False
    try:
        with zipfile.ZipFile(fmu) as z:
            options = json.loads(z.read(f"resources/{build_fmu.BUILD_OPTIONS_FILE}"))
    except (KeyError, ValueError, zipfile.BadZipFile):
        return False
    return options.get("max_balls") == max_balls


def built_fmu(name: str, tmp_path_factory, max_balls: int = TEST_CAPACITY) -> Path:
    """Path of FMU ``name`` of build_fmu.REGISTRY: dist/<name>.fmu if up to date, else a fresh build
    into a pytest temporary folder; skips the test if the FMU's slave script does not exist yet."""
    spec = next(s for s in build_fmu.REGISTRY if s.name == name)
    if not spec.script.is_file():
        pytest.skip(f"{spec.script} does not exist yet")
    dist = ROOT / "dist" / f"{name}.fmu"
    if _fresh(dist, spec, max_balls):
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
