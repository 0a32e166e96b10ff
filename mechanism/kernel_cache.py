"""Where numba keeps the compiled kernels: a folder keyed by the source of every compiled module.

numba's disk cache (``@njit(cache=True)``) checks only the decorated function's own file: a kernel that calls
into another module (``compiled_loop.run_steps`` into the force law, the multibody kernels, the FMU's calls)
would load its old machine code after an edit of that other module alone, and a run would give the old
numbers with exit status 0. The same holds for a module a kernel takes a constant from (numba folds a global
into the machine code: ``fmu_bearing.parameters.DAMPING_CONSTANT``, ``fmu_bearing.life.P_STATIONARY``). So the
cache folder is named after a SHA-256 over every ``mechanism`` source that compiles with numba (the files that
mention ``njit``) and every module of ``mechanism`` and ``fmu_bearing`` they import, directly or through each
other (``dependencies``): any edit of any of them starts a fresh cache, which the first run fills
(docs/kernels.md, "Caching").

``configure`` runs when ``mechanism`` is imported, before numba is: the folder is
``$NUMBA_CACHE_DIR/mechanism-<key>`` if the user set ``NUMBA_CACHE_DIR``, else
``mechanism/__pycache__/numba/mechanism-<key>``; child processes inherit it unchanged. A process whose sources
differ from its parent's (another checkout, an edit in between) sees another key in the inherited folder's name
and uses a sibling folder for its own key, not a folder inside the parent's (which nested one key's folder in
another's). An unwritable folder makes numba fall back to its own locations (the per-file check then applies
again).
"""
from __future__ import annotations

import hashlib
import os
import re
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent
PREFIX = "mechanism-"
#: the name of a folder ``folder`` made (for any key)
_KEYED = re.compile(re.escape(PREFIX) + "[0-9a-f]{16}")


def sources() -> list[Path]:
    """The package's modules that compile with numba, in a fixed order."""
    return sorted(p for p in PACKAGE.rglob("*.py") if "njit" in p.read_text(encoding="utf-8", errors="replace"))


#: an import of a module of the two packages: ``from mechanism.x import a, b`` (a, b may be submodules) or
#: ``import fmu_bearing.y``, at any indentation
_IMPORT = re.compile(r"^[ \t]*(?:from[ \t]+((?:mechanism|fmu_bearing)(?:\.\w+)*)[ \t]+import[ \t]+"
                     r"(?:\(([^)]*)\)|([\w, \t]*))|import[ \t]+((?:mechanism|fmu_bearing)(?:\.\w+)*))", re.M)


def _module_file(module: str) -> Path | None:
    """The file of a module of ``mechanism`` or ``fmu_bearing`` (their folders side by side), or None."""
    parts = module.split(".")
    base = PACKAGE if parts[0] == "mechanism" else PACKAGE.parent / parts[0]
    path = base.joinpath(*parts[1:])
    for candidate in (path / "__init__.py", path.with_suffix(".py")):
        if candidate.is_file():
            return candidate
    return None


def dependencies() -> list[Path]:
    """The modules of ``mechanism`` and ``fmu_bearing`` that the compiled modules import, directly or through each
    other, that do not compile with numba themselves: a kernel may fold their constants in (found from the import
    statements' text: a conservative superset)."""
    compiled = set(sources())
    seen: set[Path] = set(compiled)
    todo = list(compiled)
    while todo:
        text = todo.pop().read_text(encoding="utf-8", errors="replace")
        for m in _IMPORT.finditer(text):
            module = m.group(1) or m.group(4)
            names = re.findall(r"\w+", m.group(2) or m.group(3) or "")
            for path in (_module_file(module), *(_module_file(f"{module}.{n}") for n in names)):
                if path is not None and path not in seen:
                    seen.add(path)
                    todo.append(path)
    return sorted(seen - compiled)


def key() -> str:
    """16 hex digits of the SHA-256 over the compiled modules' and their dependencies' paths (relative to the
    packages' folder) and bytes."""
    h = hashlib.sha256()
    for path in (*sources(), *dependencies()):
        h.update(path.relative_to(PACKAGE.parent).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def folder(environ: dict | None = None) -> Path:
    """The cache folder for this source (see the module's docstring)."""
    environ = os.environ if environ is None else environ
    given = environ.get("NUMBA_CACHE_DIR", "").strip()
    name = PREFIX + key()
    if given and _KEYED.fullmatch(Path(given).name):   # set by a parent process: its key's folder, this one's or not
        return Path(given).parent / name
    return (Path(given) if given else PACKAGE / "__pycache__" / "numba") / name


def configure() -> Path:
    """Point numba's cache at ``folder()`` (the environment for numba's import and for child processes; numba's
    config too if it is imported already)."""
    path = folder().absolute()        # child processes may start in another folder (the warm-up's is the root's)
    os.environ["NUMBA_CACHE_DIR"] = str(path)
    config = getattr(sys.modules.get("numba"), "config", None)
    if config is not None:
        config.CACHE_DIR = str(path)
    return path
