"""Build the project's FMUs with pythonfmu: ``python build_fmu.py [--max-balls N] [--out dist]``.

Each FMU in ``REGISTRY`` is built from its slave script with the packages it needs (``fmu_bearing``,
and for the SliderCrank FMU also ``mechanism``) packed into the FMU's resources, so the FMU runs in
any Python host without this project installed: BallBearing and JournalClearance need nothing beyond
the standard library, SliderCrank (``mechanism``) needs numpy and scipy. Build options (the per-ball
output capacity) are written to ``resources/build_options.json`` inside the FMU, where the slave reads
them at instantiation.

Sealing (``seal``): after pythonfmu has built the archive, every Python package in its resources (ours
and pythonfmu's own copy) and the slave module are renamed to private names unique to the build
(``_fmu_bearing_<hash>``, ``ball_bearing_fmu_<hash>``, ...; the hash is taken over the packed files),
their absolute imports rewritten, and the names listed in ``build_options.json`` (``private_modules``).
So the FMU runs its own copy of the physics even in a host that has imported another ``fmu_bearing``,
two builds of one FMU never share modules, and the slave can remove exactly its own modules from
``sys.modules`` when its last instance is freed (``fmu_bearing.slaves.release_on_free``).
"""
from __future__ import annotations

import argparse
import ast
import hashlib
import importlib.util
import json
import os
import re
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import NamedTuple
from xml.etree import ElementTree

ROOT = Path(__file__).resolve().parent
try:
    import fmu_bearing  # the slave scripts import it at build time
except ImportError:  # running from a source tree that is not installed
    sys.path.insert(0, str(ROOT))
    import fmu_bearing

from fmu_bearing.native.build import SOURCE as LOADER_SOURCE, build_loader  # noqa: E402
from fmu_bearing.slaves import MODULE_CACHE  # noqa: E402

PACKAGE = Path(fmu_bearing.__file__).resolve().parent
SLAVES = PACKAGE / "slaves"
DOC = ROOT / "docs" / "fmu-interface.md"
DEFAULT_MAX_BALLS = 20
BUILD_OPTIONS_FILE = "build_options.json"
#: FMI capability flags of our FMUs (pythonfmu's get/set and serialize state are implemented)
STATE_OPTIONS = {"canGetAndSetFMUstate": True, "canSerializeFMUstate": True}
#: the same for FMI 3.0 (pythonfmu3; its default for variable step sizes is wrong, so it is set explicitly)
STATE_OPTIONS_FMI3 = {"canGetAndSetFMUState": True, "canSerializeFMUState": True,
                      "canHandleVariableCommunicationStepSize": True}


class FmuSpec(NamedTuple):
    """One FMU to build: its slave script, its model name, and the options of the build."""

    script: Path
    name: str
    options: dict  # FMI capability flags for FmuBuilder.build_FMU
    packages: tuple[str, ...] = ("fmu_bearing",)  # packed into resources/ so the FMU runs stand-alone
    doc: Path = DOC  # packed as the FMU's documentation
    fmi: int = 2  # FMI version: 2 builds with pythonfmu, 3 with pythonfmu3


REGISTRY: list[FmuSpec] = [
    FmuSpec(SLAVES / "ball_bearing_fmu.py", "BallBearing", dict(STATE_OPTIONS)),
    FmuSpec(SLAVES / "journal_clearance_fmu.py", "JournalClearance", dict(STATE_OPTIONS)),
    FmuSpec(SLAVES / "ball_bearing_fmu3.py", "BallBearing3", dict(STATE_OPTIONS_FMI3), fmi=3),
    FmuSpec(ROOT / "mechanism" / "ssp" / "slaves" / "slider_crank_fmu.py", "SliderCrank", dict(STATE_OPTIONS),
            ("fmu_bearing", "mechanism"), ROOT / "docs" / "ssp.md"),
]


def package_dir(name: str) -> Path:
    """Folder of the top-level package ``name`` (found without importing it)."""
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError(f"package {name!r} not found")
    return Path(next(iter(spec.submodule_search_locations))).resolve()


def build(out_dir: str | Path = "dist", max_balls: int = DEFAULT_MAX_BALLS,
          names: list[str] | tuple[str, ...] | None = None, verbose: bool = True) -> dict[str, Path]:
    """Build the FMUs of ``REGISTRY`` (or only ``names``) into ``out_dir``; return {model name: path}.

    An entry whose slave script does not exist yet is skipped with a message.
    """
    from pythonfmu import FmuBuilder
    from pythonfmu3 import FmuBuilder as Fmu3Builder

    if int(max_balls) != max_balls or max_balls < 3:
        raise ValueError(f"max_balls = {max_balls!r} must be an integer >= 3")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    unknown = set(names or ()) - {spec.name for spec in REGISTRY}
    if unknown:
        raise ValueError(f"unknown FMU(s) {sorted(unknown)}; known: {[spec.name for spec in REGISTRY]}")
    built: dict[str, Path] = {}
    for spec in REGISTRY:
        if names is not None and spec.name not in names:
            continue
        if not spec.script.is_file():
            if verbose:
                print(f"skipping {spec.name}: {spec.script} does not exist yet")
            continue
        saved_path = list(sys.path)
        with tempfile.TemporaryDirectory(prefix=f"build_{spec.name}_") as tmp:
            stage = Path(tmp)
            # Clean copies of the packages (no caches) and the build options, packed as project files.
            project_files = []
            for package in spec.packages:
                shutil.copytree(package_dir(package), stage / package,
                                ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.pyo", "*.fmu", "native"))
                project_files.append(stage / package)
            options_file = stage / BUILD_OPTIONS_FILE
            options_file.write_text(json.dumps({"max_balls": int(max_balls), "sources_sha256": source_digest(spec)})
                                    + "\n", encoding="utf-8")
            doc_dir = None
            if spec.doc.is_file():
                doc_dir = stage / "documentation"
                doc_dir.mkdir()
                shutil.copy2(spec.doc, doc_dir / spec.doc.name)
            # Build into the staging folder, then move: readers of out_dir never see a half-written FMU.
            try:
                builder = Fmu3Builder if spec.fmi == 3 else FmuBuilder
                fmu = builder.build_FMU(spec.script, dest=stage / f"{spec.name}.fmu",
                                           project_files=[*project_files, options_file],
                                           documentation_folder=doc_dir, **spec.options)
            finally:
                sys.path[:] = saved_path  # pythonfmu leaves the script's folder on sys.path
            seal(fmu, max_balls)
            build_loader(fmu)  # native hosts: the loader becomes the FMU's binary (fmu_bearing/native)
            model_name = _model_name(fmu)
            if model_name != spec.name:
                raise RuntimeError(f"{spec.script} defines model {model_name!r}, expected {spec.name!r}")
            target = out / f"{spec.name}.fmu"
            tmp_target = out / f".{spec.name}.fmu.{os.getpid()}.tmp"
            shutil.copyfile(fmu, tmp_target)
            os.replace(tmp_target, target)
        built[spec.name] = target
        if verbose:
            print(f"built {target} ({target.stat().st_size / 1024:.0f} kB, model {spec.name}"
                  + (f", per-ball outputs for up to {max_balls} balls)" if spec.name == "BallBearing" else ")"))
    return built


def _rewrite_imports(source: str, renames: dict[str, str]) -> str:
    """``source`` with every absolute import of a package in ``renames`` (old -> new name) renamed."""
    names = "|".join(map(re.escape, renames))
    pattern = re.compile(rf"^(\s*(?:from|import)\s+)({names})(?=[\s.,;]|$)", re.M)
    return pattern.sub(lambda m: m.group(1) + renames[m.group(2)], source)


def _unsealed_imports(source: str, renames: dict[str, str]) -> list[str]:
    """Absolute imports of a renamed package that survived the rewrite (an import form the pattern missed)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names if a.name.split(".")[0] in renames]
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module.split(".")[0] in renames:
            found.append(node.module)
    return found


#: the slave module pythonfmu's fmi2Instantiate executes (``seal``); {names} is filled in
_SHIM_HEAD = '''"""{model}'s slave module for pythonfmu 0.7: a shim written by build_fmu.py (issue 14).

The slave class lives in {real}. pythonfmu's fmi2Instantiate imports this module and then executes its
source once more to find the slave class; executing the full slave module there made new classes at every
instantiation, which pythonfmu's class search keeps alive (it never releases the MRO lists it makes), and
with them a whole copy of the FMU's modules per instance. Here only the class is imported: the same one
every time. The class search is what finds this line:

class {cls}(Fmi2Slave):
"""
import sys as _sys

if locals() is not globals():
    # pythonfmu's second execution: its class search releases this module's dict once although it only
    # borrowed it (PyModule_GetDict); one more reference balances that, or the dict would be freed in use.
    import ctypes as _ctypes
    _ctypes.pythonapi.Py_IncRef(_ctypes.py_object(globals()))
'''
#: the same for pythonfmu3 0.3.4's fmi3InstantiateCoSimulation, which only imports the slave module and takes
#: the class named by the first class statement deriving from Fmi3Slave in the module's file
_SHIM3_HEAD = '''"""{model}'s slave module for pythonfmu3: a shim written by build_fmu.py (issue 14).

The slave class lives in {real}. pythonfmu3's fmi3InstantiateCoSimulation imports this module and takes the
class named on the first line of this file that looks like a class statement deriving from Fmi3Slave. The
last fmi3FreeInstance of the FMU removes its modules from sys.modules (sealing), so with the full slave module
here every instantiation after a last free imported all of the FMU's modules afresh, and each import left
memory behind (about 200 kB). Here only the class is imported, from the modules the last free kept aside:
the same class every time. The line pythonfmu3 finds:

class {cls}(Fmi3Slave):
"""
import sys as _sys

'''
#: what both shims do: the released modules back into sys.modules, then import the class
_SHIM_BODY = '''\
# The modules the last fmi2FreeInstance of this build removed (fmu_bearing.slaves.module_cache): back into
# sys.modules, their packages pointed at this extraction, instead of a new import of every module.
_cached = getattr(_sys, {cache!r}, {{}}).pop({names!r}, None)
if _cached:
    import os as _os
    _here = _os.path.dirname(_os.path.abspath(__file__))
    for _name, _module in _cached.items():
        if isinstance(getattr(_module, "__path__", None), list):
            _module.__path__[:] = [_os.path.join(_here, *_name.split("."))]
        if _name != __name__:   # this module is the new one: the cached one goes
            _sys.modules.setdefault(_name, _module)
    del _name, _module
del _cached   # a module global on the import: would keep the cached modules (and the old shim) alive
'''
#: pythonfmu3 0.3.4 crashes the host when the slave module fails to import (it goes on with a NULL module):
#: a failed import gives a stand-in class instead, whose instantiation fails with a message (fmi3Fatal, NULL)
_SHIM3_IMPORT = '''try:
    from {real} import {cls}
except Exception as _err:   # noqa: BLE001 - reported at instantiation
    class _Unavailable:
        """Stands in for the slave class when the FMU's modules cannot be imported."""

        def __init__(self, _error=_err, **kwargs):
            raise ImportError(f"{cls} cannot import its physics from the FMU's resources: {{_error!r}} "
                              f"(Python {{_sys.version.split()[0]}} at {{_sys.executable}})")

    {cls} = _Unavailable
    del _err
'''
SHIM = _SHIM_HEAD + _SHIM_BODY + "from {real} import {cls}\n"
SHIM3 = _SHIM3_HEAD + _SHIM_BODY.replace("fmi2FreeInstance", "fmi3FreeInstance") + _SHIM3_IMPORT

#: pythonfmu's (and the shim's) pattern of the slave class statement
_SLAVE_CLASS = re.compile(r"^class (\w+)\(\s*Fmi2Slave\s*[,)]", re.M)
#: pythonfmu3 0.3.4's pattern (its binary's): the first class statement with Fmi3Slave among its bases
_SLAVE_CLASS3 = re.compile(r"^class (\w+)\(([^)]*\bFmi3Slave(?:Base)?\b[^)]*)", re.M)


def seal(fmu: Path, max_balls: int) -> dict[str, str]:
    """Rename the packages and the slave module packed in ``fmu`` to private names unique to the build.

    Rewrites the archive in place: ``resources/<package>/`` -> ``resources/_<package>_<hash>/`` for every
    package folder (ours and pythonfmu's), ``resources/<slave>.py`` -> ``resources/<slave>_<hash>.py``
    (and ``slavemodule.txt``), absolute imports of those names in every packed ``.py`` file, and the build
    options with the list of private module names. The hash (12 hex digits of SHA-256) is taken over the
    packed files, so the same sources give the same names. Returns {old name: private name}.

    When the slave script is also packed inside one of the packages, the slave module becomes
    ``SHIM`` (pythonfmu 0.7, an ``Fmi2Slave`` class) or ``SHIM3`` (pythonfmu3, an ``Fmi3Slave`` class), which
    imports the slave class from its private package module, so that re-instantiating the FMU does not
    re-create the class nor, after a last free, import the FMU's modules again (issue 14).
    """
    with zipfile.ZipFile(fmu) as z:
        entries = [(info, z.read(info)) for info in z.infolist()]
    files = {info.filename: data for info, data in entries}
    slave = files["resources/slavemodule.txt"].decode("utf-8").strip()
    digest = hashlib.sha256()
    for name in sorted(n for n in files if n.startswith("resources/")):
        digest.update(name.encode() + b"\0" + files[name] + b"\0")
    tag = digest.hexdigest()[:12]
    packages = sorted({n.split("/")[1] for n in files if n.startswith("resources/") and n.count("/") >= 2})
    renames = {package: f"_{package}_{tag}" for package in packages}
    renames[slave] = f"{slave}_{tag}"
    options = {**json.loads(files[f"resources/{BUILD_OPTIONS_FILE}"]), "max_balls": int(max_balls),
               "private_modules": sorted(renames.values())}
    shim_text = None
    source = files[f"resources/{slave}.py"]
    inside = sorted(n for n in files if n.startswith("resources/") and n.count("/") >= 2
                    and n.endswith(f"/{slave}.py") and files[n] == source)
    template, found = SHIM, _SLAVE_CLASS.search(source.decode("utf-8"))
    if found is None:
        template, found = SHIM3, _SLAVE_CLASS3.search(source.decode("utf-8"))
    if inside and found:
        parts = inside[0][len("resources/"):-len(".py")].split("/")
        real = ".".join([renames[parts[0]], *parts[1:]])
        model = ElementTree.fromstring(files["modelDescription.xml"]).get("modelName")
        shim_text = template.format(model=model, real=real, cls=found.group(1), cache=MODULE_CACHE,
                                    names=tuple(options["private_modules"]))
    tmp = fmu.with_name(fmu.name + ".sealing")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as out:
        for info, data in entries:
            name = info.filename
            if name.startswith("resources/"):
                parts = name.split("/")
                if len(parts) > 2 and parts[1] in renames:
                    parts[1] = renames[parts[1]]
                elif name == f"resources/{slave}.py":
                    parts[1] = f"{renames[slave]}.py"
                    if shim_text is not None:
                        data = shim_text.encode("utf-8")
                elif name == "resources/slavemodule.txt":
                    data = renames[slave].encode("utf-8")
                elif name == f"resources/{BUILD_OPTIONS_FILE}":
                    data = (json.dumps(options) + "\n").encode("utf-8")
                name = "/".join(parts)
                if name.endswith(".py"):
                    text = _rewrite_imports(data.decode("utf-8"), renames)
                    left = _unsealed_imports(text, renames)
                    if left:
                        raise RuntimeError(f"{name}: imports {left} could not be sealed (rewrite them as "
                                           f"'import x' / 'from x import y' statements)")
                    data = text.encode("utf-8")
            out.writestr(zipfile.ZipInfo(name, date_time=info.date_time), data, zipfile.ZIP_DEFLATED)
    os.replace(tmp, fmu)
    return renames


def _sources(spec: FmuSpec) -> list[Path]:
    """Files an FMU is built from: its packages (incl. the slave scripts), its script, this build script."""
    files = [spec.script, Path(__file__), LOADER_SOURCE]
    for package in spec.packages:
        files += package_dir(package).rglob("*.py")
    return files


def source_digest(spec: FmuSpec) -> str:
    """SHA-256 over the relative paths and contents of the files ``spec`` is built from (hex).

    Content, not modification times: a moved or checked-out file keeps or gets any mtime."""
    h = hashlib.sha256()
    for src in sorted(_sources(spec)):
        if src.is_file():
            rel = src.resolve().relative_to(ROOT) if src.resolve().is_relative_to(ROOT) else src.name
            h.update(str(rel).encode() + b"\0" + src.read_bytes() + b"\0")
    return h.hexdigest()


def is_fresh(fmu: str | Path, spec: FmuSpec | str, max_balls: int = DEFAULT_MAX_BALLS) -> bool:
    """``fmu`` exists and was built from the current sources (``source_digest``) with ``max_balls``."""
    fmu = Path(fmu)
    if isinstance(spec, str):
        spec = next(s for s in REGISTRY if s.name == spec)
    if not fmu.is_file():
        return False
    try:
        with zipfile.ZipFile(fmu) as z:
            options = json.loads(z.read(f"resources/{BUILD_OPTIONS_FILE}"))
    except (KeyError, ValueError, zipfile.BadZipFile):
        return False
    return options.get("max_balls") == max_balls and options.get("sources_sha256") == source_digest(spec)


def _model_name(fmu: Path) -> str:
    with zipfile.ZipFile(fmu) as z:
        return ElementTree.fromstring(z.read("modelDescription.xml")).get("modelName")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-balls", type=int, default=DEFAULT_MAX_BALLS,
                        help=f"per-ball output capacity of the BallBearing FMU (default {DEFAULT_MAX_BALLS}); "
                             "n_balls may not exceed it")
    parser.add_argument("--out", default="dist", help="output folder (default: dist)")
    parser.add_argument("--only", action="append", choices=[spec.name for spec in REGISTRY],
                        help="build only this FMU (repeatable)")
    args = parser.parse_args(argv)
    if args.max_balls < 3:
        parser.error("--max-balls must be at least 3")
    built = build(args.out, args.max_balls, names=args.only)
    if not built:
        print("nothing built")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
