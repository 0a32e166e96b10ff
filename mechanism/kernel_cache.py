"""Where numba keeps the compiled kernels: a folder keyed by the source of every compiled module.

numba's disk cache (``@njit(cache=True)``) checks only the decorated function's own file: a kernel that calls
into another module (``compiled_loop.run_steps`` into the force law, the multibody kernels, the FMU's calls)
would load its old machine code after an edit of that other module alone, and a run would give the old
numbers with exit status 0. The same holds for a module a kernel takes a constant from (numba folds a global
into the machine code: ``fmu_bearing.parameters.DAMPING_CONSTANT``, ``fmu_bearing.life.P_STATIONARY``). So the
cache folder is named after a SHA-256 over every ``mechanism`` source that compiles with numba (the files that
mention ``njit``) and every module of ``mechanism`` and ``fmu_bearing`` they import, directly or through each
other (``dependencies``, from their import statements): any edit of any of them starts a fresh cache, which the first run fills
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
import importlib.util
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


#: the packages a kernel may take constants from (their modules' files are in the key when the kernels import them)
PACKAGES = ("mechanism", "fmu_bearing")


def _root(top: str) -> Path | None:
    """The folder of the top-level package ``top``: this one for ``mechanism``; ``fmu_bearing`` beside it, as the
    project installs them, else where Python finds it (without importing it)."""
    if top == "mechanism":
        return PACKAGE
    beside = PACKAGE.parent / top
    if beside.is_dir():
        return beside
    spec = importlib.util.find_spec(top)
    locations = spec.submodule_search_locations if spec is not None else None
    return Path(locations[0]) if locations else None


def _module_file(module: str) -> Path | None:
    """The file of a module of ``PACKAGES`` (a package's ``__init__.py``), or None (not one of theirs, or no file)."""
    top, *rest = module.split(".")
    root = _root(top) if top in PACKAGES else None
    if root is None:
        return None
    path = root.joinpath(*rest)
    for candidate in (path / "__init__.py", path.with_suffix(".py")):
        if candidate.is_file():
            return candidate
    return None


def _module_name(path: Path) -> tuple[str, bool]:
    """(the dotted name of the module in ``path``, whether it is a package's ``__init__``)."""
    for top in PACKAGES:
        root = _root(top)
        if root is not None and path.is_relative_to(root):
            parts = [top, *path.relative_to(root).with_suffix("").parts]
            return ".".join(parts[:-1] if parts[-1] == "__init__" else parts), parts[-1] == "__init__"
    raise ValueError(f"{path} is in none of {PACKAGES}")


#: an import statement at any indentation: ``from [dots]module import a, b as c`` or its parenthesised form over
#: several lines (groups: dots, module, the names in parentheses, the names on the line), or ``import a.b as c, d``
_IMPORT = re.compile(r"^[ \t]*(?:from[ \t]+(\.*)((?:\w+(?:\.\w+)*)?)[ \t]+import[ \t]+(?:\(([^)]*)\)|([^\n#;]*))"
                     r"|import[ \t]+([^\n#;]+))", re.M)


def _first_words(names: str) -> list[str]:
    """``a, b as c`` (a parenthesised list's comments and line breaks too) as [a, b]."""
    items = (re.sub(r"#[^\n]*", "", item).split() for item in names.split(","))
    return [words[0] for words in items if words]


def _imported(path: Path) -> set[str]:
    """The dotted names a module's import statements name, anywhere in it (``from . import x`` resolved; for
    ``from m import a`` both m and m.a, as a may be a submodule). Read from the text with a pattern, not parsed:
    this runs at every ``import mechanism`` (an ``ast`` parse of the 23 files took 0.1 s)."""
    module, is_package = _module_name(path)
    package = module if is_package else module.rpartition(".")[0]
    names: set[str] = set()
    for m in _IMPORT.finditer(path.read_text(encoding="utf-8", errors="replace")):
        dots, base, listed = m.group(1), m.group(2), m.group(3) or m.group(4)
        if m.group(5) is not None:
            names.update(_first_words(m.group(5)))
            continue
        if dots:
            try:
                base = importlib.util.resolve_name(dots + base, package)
            except (ImportError, ValueError):      # beyond the top-level package: not one of ours
                continue
        names.add(base)
        names.update(f"{base}.{name}" for name in _first_words(listed or ""))
    return names


def dependencies(compiled: list[Path] | None = None) -> list[Path]:
    """The modules of ``PACKAGES`` that the compiled modules (``sources()``) import, directly or through each other,
    and that do not compile with numba themselves: a kernel may fold their constants into its machine code (a
    superset: every import statement counts, in a function too)."""
    compiled_set = set(sources() if compiled is None else compiled)
    seen = set(compiled_set)
    todo = list(compiled_set)
    while todo:
        for name in _imported(todo.pop()):
            path = _module_file(name)
            if path is not None and path not in seen:
                seen.add(path)
                todo.append(path)
    return sorted(seen - compiled_set)


def key() -> str:
    """16 hex digits of the SHA-256 over the compiled modules' and their dependencies' dotted names and bytes."""
    h = hashlib.sha256()
    compiled = sources()
    for path in (*compiled, *dependencies(compiled)):
        name, is_package = _module_name(path)
        h.update(f"{name}{'.__init__' if is_package else ''}".encode() + b"\0" + path.read_bytes() + b"\0")
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
