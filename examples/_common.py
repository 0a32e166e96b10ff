"""Shared by the examples: where the FMUs are (built on first use) and the short-run switch.

Every example takes ``--short`` (or the environment variable ``EXAMPLES_SHORT=1``), which makes it
simulate a fraction of the time so that ``tests/test_examples.py`` can run them all in CI.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:       # run from a clone without installing
    sys.path.insert(0, str(ROOT))


def short() -> bool:
    """True with ``--short`` on the command line or EXAMPLES_SHORT=1 in the environment."""
    return "--short" in sys.argv[1:] or os.environ.get("EXAMPLES_SHORT", "") not in ("", "0")


def fmu(name: str = "BallBearing") -> Path:
    """dist/<name>.fmu of the clone, (re)built when missing or stale."""
    import build_fmu
    path = ROOT / "dist" / f"{name}.fmu"
    if not build_fmu.is_fresh(path, name):
        build_fmu.build(ROOT / "dist", names=[name], verbose=False)
    return path
