"""The layout is the architecture (docs/architecture.md): import arrows point down, and there is no circle.

Every import statement of ``mechanism`` and ``fmu_bearing`` is read from the source (also imports inside
functions) and held against the table of docs/architecture.md.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: package (or module) -> the project packages it may import (besides itself); matched by longest prefix
ALLOWED = {
    "fmu_bearing": {"fmu_bearing"},
    "mechanism.multibody": set(),
    "mechanism.systems": {"mechanism.multibody"},
    "mechanism.cosim": {"mechanism.multibody", "fmu_bearing"},
    "mechanism.run": {"mechanism.cosim", "mechanism.systems", "mechanism.multibody", "fmu_bearing", "build_fmu"},
    "mechanism.output": {"mechanism.cosim.record", "fmu_bearing"},
    "mechanism.ssp": {"mechanism.run", "mechanism.cosim", "mechanism.systems", "mechanism.multibody",
                      "fmu_bearing", "build_fmu"},
    "mechanism.studies": {"mechanism.run", "mechanism.output", "mechanism.cosim", "mechanism.systems",
                          "mechanism.multibody", "fmu_bearing", "build_fmu"},
    # the advisor is built on the step-size study's machinery (one way: stepsize does not import advise)
    "mechanism.studies.advise": {"mechanism.run", "mechanism.output", "mechanism.cosim", "mechanism.systems",
                                 "mechanism.multibody", "fmu_bearing", "build_fmu", "mechanism.studies.stepsize"},
    "mechanism.cli": {"mechanism"},
    "mechanism.__main__": {"mechanism.cli"},
    "mechanism": set(),
}
#: third-party packages a layer must never import (the FMU's runtime needs the standard library only,
#: apart from its pythonfmu slave scripts)
FORBIDDEN_THIRD_PARTY = {
    "mechanism.multibody": {"fmpy", "pythonfmu"},
    "mechanism.systems": {"fmpy", "pythonfmu"},
}


def _modules() -> dict[str, Path]:
    out = {}
    for package in ("mechanism", "fmu_bearing"):
        for path in (ROOT / package).rglob("*.py"):
            if "__pycache__" in path.parts:
                continue
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def _imports(name: str, path: Path) -> set[str]:
    """Absolute names of every module imported anywhere in the file (relative imports resolved)."""
    tree = ast.parse(path.read_text(), str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module
            found.add(module)
            found.update(f"{module}.{a.name}" for a in node.names)   # from pkg import submodule
    return found


def _owner(name: str) -> str:
    return max((k for k in ALLOWED if name == k or name.startswith(k + ".")), key=len)


def _within(target: str, prefixes) -> bool:
    return any(target == p or target.startswith(p + ".") for p in prefixes)


MODULES = _modules()
PROJECT = ("mechanism", "fmu_bearing", "build_fmu")
#: the module of helpers every study may share (worker counts, parallel map)
STUDY_HELPERS = "mechanism.studies.parallel"


@pytest.mark.parametrize("name", sorted(MODULES))
def test_imports_point_down(name):
    owner = _owner(name)
    allowed = ALLOWED[owner] | {owner}
    if name.startswith("mechanism.studies."):
        # a study may use its own subpackage and the studies' shared helpers, not another study
        # (advise -> stepsize is the one listed exception); the key "mechanism.studies" itself allows nothing
        allowed = (allowed - {"mechanism.studies"}) | {".".join(name.split(".")[:3]), STUDY_HELPERS}
    wrong = []
    for target in _imports(name, MODULES[name]):
        top = target.split(".")[0]
        if top in PROJECT:
            if target in MODULES and target != name and _within(name, [target]):
                continue                                   # a package's own __init__ (its face)
            if not _within(target, allowed) and not (target in ("mechanism",) and owner == "mechanism.cli"):
                if target not in MODULES and target.rpartition(".")[0] in MODULES:
                    target = target.rpartition(".")[0]     # `from pkg import name`: the package itself
                    if _within(target, allowed) or _within(name, [target]):
                        continue
                wrong.append(target)
        elif top in FORBIDDEN_THIRD_PARTY.get(owner, ()):
            wrong.append(target)
    assert not wrong, f"{name} ({owner}) imports {sorted(set(wrong))}; allowed: {sorted(allowed)}"


def test_no_import_circle():
    graph = {}
    for name, path in MODULES.items():
        targets = set()
        for t in _imports(name, path):
            while t and t not in MODULES:
                t = t.rpartition(".")[0]
            if t and t != name and not _within(name, [t]):    # importing one's own package face is not a cycle
                targets.add(t)
        graph[name] = targets
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node):
        state[node] = 1
        stack.append(node)
        for nxt in graph[node]:
            if state.get(nxt) == 1:
                cycle = stack[stack.index(nxt):] + [nxt]
                raise AssertionError("import circle: " + " -> ".join(cycle))
            if nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)


#: third-party packages the FMU's runtime code may import: the slaves need their exporter; nothing else
RUNTIME_EXTRA = {"fmu_bearing.slaves": {"pythonfmu", "pythonfmu3"}}


@pytest.mark.parametrize("name", sorted(n for n in MODULES if n.startswith("fmu_bearing")
                                        and not n.startswith("fmu_bearing.native")))
def test_fmu_runtime_imports_only_the_standard_library(name):
    """What the FMUs pack and run (fmu_bearing less the build-time native/ folder) needs no numpy or scipy."""
    import sys
    extra = next((v for k, v in RUNTIME_EXTRA.items() if name == k or name.startswith(k + ".")), set())
    tops = {t.split(".")[0] for t in _imports(name, MODULES[name])}
    foreign = sorted(t for t in tops if t not in sys.stdlib_module_names and t != "fmu_bearing" and t not in extra)
    assert not foreign, f"{name} imports {foreign} (the FMU's runtime is the standard library only)"
