"""The first run's compile (issue 11): the progress bar says it is compiling instead of an ETA measured on the
compile, and ``compiled_driver.cached`` tells a fresh numba cache from a warm one. Compile times themselves are
measured by benchmarks/compile.py, not here."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mechanism.cosim import compiled_driver
from mechanism.run import RunConfig, run

ROOT = Path(__file__).resolve().parents[1]


def test_a_fresh_cache_is_not_cached(tmp_path):
    code = "from mechanism.cosim import compiled_driver as d; print(d.cached())"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=tmp_path,
                         check=True).stdout
    assert out.strip() == "False"


def test_compiled_in_this_process_is_cached():
    assert run(RunConfig(mode="inprocess", revs=0.01, progress=False)).ok
    assert compiled_driver.cached()


@pytest.mark.parametrize("first", [True, False])
def test_progress_bar_says_compiling_on_the_first_run(first, monkeypatch, capsys):
    """On a first run the bar shows "compiling kernels (first run)" until the first chunk is done, then counts
    the steps from there (a reset clock: its rate and ETA without the compile); the numbers are the same."""
    monkeypatch.setattr(compiled_driver, "cached", lambda: not first)
    config = RunConfig(mode="inprocess", revs=0.05, rpm=1200, step=1e-5)
    with_bar = run(config)
    err = capsys.readouterr().err
    assert ("compiling kernels (first run)" in err) == first
    quiet = run(RunConfig(mode="inprocess", revs=0.05, rpm=1200, step=1e-5, progress=False))
    assert with_bar.ok and quiet.ok
    assert np.array_equal(with_bar.data, quiet.data, equal_nan=True)
