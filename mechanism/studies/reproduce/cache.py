"""The run cache: a run is recomputed exactly when its configuration or the code that computes it changes.

The key is SHA-256 over the run's ``RunConfig`` (less ``KEY_EXCLUDE``) and the code version (SHA-256 over
the run-relevant sources and the numeric packages' versions); the FMUs are built from the current sources."""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
from dataclasses import asdict
from pathlib import Path
import numpy as np
from mechanism.cosim.record import RunResult
from mechanism.run import FMU_NAMES, RunConfig
from mechanism.studies.reproduce.cases import (RunSpec)


ROOT = Path(__file__).resolve().parents[3]   # the repository
#: source trees hashed into the code version, and what inside them only presents results
CODE_EXCLUDE = ("mechanism/studies/", "mechanism/output/", "mechanism/ssp/", "mechanism/cli.py",
                "mechanism/__main__.py")
CODE_FILES = ("build_fmu.py",)
VERSIONED_PACKAGES = ("numpy", "scipy", "fmpy", "pythonfmu")
#: RunConfig fields left out of the cache key (they do not change the result)
KEY_EXCLUDE = ("progress", "fmu")


def _package_version(name: str) -> str:
    try:
        from importlib.metadata import version
        return version(name)
    except Exception:
        return "unknown"


def code_files(root: Path = ROOT) -> list[Path]:
    """The source files whose content is the code version (sorted): every ``fmu_bearing`` file (the FMUs
    pack the whole package), ``build_fmu.py``, and every ``mechanism`` module below the studies that a run
    can execute (all of it less CODE_EXCLUDE: the studies, the output files and plots, the command line
    and the SSP tooling only present or package results)."""
    files = {p for p in (root / "fmu_bearing").rglob("*.py") if "__pycache__" not in p.parts}
    files |= {root / f for f in CODE_FILES if (root / f).is_file()}
    files |= {p for p in (root / "mechanism").rglob("*.py")
              if "__pycache__" not in p.parts
              and not any(p.relative_to(root).as_posix().startswith(x) for x in CODE_EXCLUDE)}
    return sorted(files)


def code_version(root: Path = ROOT) -> str:
    """SHA-256 over the run-relevant sources and the numeric packages' versions (hex)."""
    h = hashlib.sha256()
    for path in code_files(root):
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    for name in VERSIONED_PACKAGES:
        h.update(f"{name}=={_package_version(name)}\0".encode())
    return h.hexdigest()


def config_key(config: RunConfig, version: str) -> str:
    """Cache key of a run: 16 hex digits of SHA-256 over its RunConfig (less KEY_EXCLUDE) and the code version."""
    fields = {k: v for k, v in asdict(config).items() if k not in KEY_EXCLUDE}
    text = json.dumps({"config": fields, "code_version": version}, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def cache_dir(out: Path, spec: RunSpec, version: str) -> Path:
    return Path(out) / "cache" / f"{spec.name}-{config_key(spec.config, version)}"


def save_result(path: Path, result: RunResult, info: dict) -> None:
    """Write result.npz and meta.json into ``path`` atomically (a staging folder, then a rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    stage = path.parent / f".{path.name}.{os.getpid()}.tmp"
    shutil.rmtree(stage, ignore_errors=True)
    stage.mkdir()
    np.savez(stage / "result.npz", data=result.data, columns=np.array(result.columns))
    meta = {"status": result.status, "message": result.message, "meta": result.meta, **info}
    (stage / "meta.json").write_text(json.dumps(meta, indent=2, default=repr) + "\n")
    shutil.rmtree(path, ignore_errors=True)
    os.replace(stage, path)


def load_result(path: Path) -> tuple[RunResult, dict]:
    """(RunResult, meta.json contents) of a cached run."""
    path = Path(path)
    info = json.loads((path / "meta.json").read_text())
    with np.load(path / "result.npz") as z:
        result = RunResult([str(c) for c in z["columns"]], z["data"], info.get("meta", {}),
                           info.get("status", "completed"), info.get("message", ""))
    return result, info


def is_cached(path: Path) -> bool:
    return (Path(path) / "meta.json").is_file() and (Path(path) / "result.npz").is_file()


# --- FMUs -----------------------------------------------------------------------------------------
def ensure_fmus(out: Path, version: str, joints: set[str]) -> dict[str, Path]:
    """FMU paths per joint, built from the current sources into ``out/fmu`` unless already built from them
    (``out/fmu/<Name>.code_version`` records the code version each FMU was built from)."""
    fmu_dir = Path(out) / "fmu"
    paths = {}
    for joint in sorted(j for j in joints if j in FMU_NAMES):
        name = FMU_NAMES[joint]
        path, stamp = fmu_dir / f"{name}.fmu", fmu_dir / f"{name}.code_version"
        if not (path.is_file() and stamp.is_file() and stamp.read_text().strip() == version):
            if str(ROOT) not in sys.path:
                sys.path.insert(0, str(ROOT))
            import build_fmu
            fmu_dir.mkdir(parents=True, exist_ok=True)
            stamp.unlink(missing_ok=True)
            build_fmu.build(fmu_dir, names=[name], verbose=False)
            if not path.is_file():
                raise FileNotFoundError(f"building {name}.fmu failed (is its slave script there?)")
            stamp.write_text(version + "\n")
        paths[joint] = path.resolve()
    return paths


# --- running ----------------------------------------------------------------------------------------
