"""Every script in examples/ runs to the end with --short (a fraction of its simulated time) and exit 0."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = sorted(p.name for p in (ROOT / "examples").glob("*.py") if not p.name.startswith("_"))
NEEDS = {"fmu_in_libcosim_and_ecos.py": ("libcosimpy", "ecospy"), "ssp_in_each_engine.py": ("libcosimpy", "ecospy")}


def test_every_example_is_listed_in_its_readme():
    text = (ROOT / "examples" / "README.md").read_text()
    assert EXAMPLES and all(f"({name})" in text for name in EXAMPLES)


@pytest.mark.parametrize("name", EXAMPLES)
def test_example_runs_short(name, ball_bearing_fmu, slider_crank_fmu):
    for module in NEEDS.get(name, ()):
        pytest.importorskip(module, reason=f"{name} needs {module} (pip install -e '.[test]')")
    env = dict(os.environ, EXAMPLES_SHORT="1", PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    done = subprocess.run([sys.executable, str(ROOT / "examples" / name), "--short"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    assert done.stdout.strip(), "an example says what it computed"
