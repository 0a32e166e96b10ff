"""The built FMUs as guests of a host process (issue 13): sealed physics, a clean sys.path/sys.modules after
fmi2FreeInstance, errors that name their cause with logging off, an honest model description, and a run
in a fresh virtual environment that has only fmpy (no scipy, no project)."""
from __future__ import annotations

import ctypes
import json
import os
import shutil
import subprocess
import sys
import textwrap
import venv
from pathlib import Path

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, free)
from fmpy.validation import validate_fmu

from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.clearance_joint import ClearanceJoint

ROOT = Path(__file__).resolve().parent.parent
DISCARD = 2
E_X = 3e-5                       # 20 um into the Table 2 bearing (P_d/2 = 10 um); 12 um into the bushing


def expected_forces():
    """F_x, F_y of both joints at e = (E_X, 0), v = 0, cage angle 0, from the project's own fmu_bearing."""
    r = BallBearing().evaluate(E_X, 0.0, 0.0, 0.0, 0.0)
    c = ClearanceJoint().evaluate(E_X, 0.0, 0.0, 0.0, 0.0)
    return {"BallBearing": [r.F_x, r.F_y], "JournalClearance": [c.F_x, c.F_y]}


# A host script: runs each FMU given on the command line (path, unzip folder) through fmpy: two instances,
# fmi2Reset of one, a step at e = (E_X, 0), and reports the forces and what sys.path / sys.modules look like
# before instantiation, while instances live, and after the last fmi2FreeInstance.
HOST = textwrap.dedent("""
    import importlib.util, json, sys
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    E_X = float(sys.argv[1])
    report = {"scipy": importlib.util.find_spec("scipy") is not None, "fmus": {}}
    for path, unzip in zip(sys.argv[2::2], sys.argv[3::2]):
        extract(path, unzipdir=unzip)
        md = read_model_description(unzip)
        vr = {v.name: v.valueReference for v in md.modelVariables}
        path_before, modules_before = list(sys.path), set(sys.modules)
        instances, forces = [], []
        for k in range(2):
            s = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                          instanceName=f"i{k}")
            s.instantiate(loggingOn=False)
            instances.append(s)
        instances[1].reset()                      # fmi2Reset: pythonfmu replaces the slave object
        for s in instances:
            s.setupExperiment(startTime=0.0); s.enterInitializationMode()
            s.setReal([vr["e_x"]], [E_X]); s.exitInitializationMode(); s.doStep(0.0, 1e-4)
            forces.append(s.getReal([vr["F_x"], vr["F_y"]]))
        during = [m for m in set(sys.modules) - modules_before]
        for s in instances:
            s.terminate(); s.freeInstance()
        # one instance alone, reset: its old slave object is the last one when pythonfmu frees it
        s = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="alone")
        s.instantiate(loggingOn=False); s.setupExperiment(startTime=0.0); s.enterInitializationMode()
        s.exitInitializationMode(); s.reset()
        s.setupExperiment(startTime=0.0); s.enterInitializationMode()
        s.setReal([vr["e_x"]], [E_X]); s.exitInitializationMode(); s.doStep(0.0, 1e-4)
        forces.append(s.getReal([vr["F_x"], vr["F_y"]]))
        s.terminate(); s.freeInstance()
        left = {name: str(getattr(m, "__file__", None)) for name, m in sys.modules.items()
                if name not in modules_before and str(getattr(m, "__file__", None)).startswith(unzip)}
        report["fmus"][md.modelName] = {
            "forces": forces, "path_restored": sys.path == path_before,
            "private_during": sorted(m for m in during if m.split(".")[0] in json.load(
                open(unzip + "/resources/build_options.json")).get("private_modules", [])),
            "fmu_modules_left": left}
    print(json.dumps(report))
""")


def run_host(python, fmus: dict[str, Path], tmp: Path, prelude: str = "", env_extra=None) -> dict:
    args = [str(E_X)]
    for name, path in fmus.items():
        args += [str(path), str(tmp / f"unzip_{name}")]
    script = tmp / "host.py"
    script.write_text(prelude + HOST)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.update(env_extra or {})
    proc = subprocess.run([str(python), str(script), *args], cwd=tmp, env=env, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def check_report(report: dict, names) -> None:
    expected = expected_forces()
    for name in names:
        r = report["fmus"][name]
        assert r["forces"] == [expected[name]] * 3, name           # bit for bit, all instances (two reset)
        assert r["path_restored"], name
        private = {m.split(".")[0].rsplit("_", 1)[0] for m in r["private_during"]}
        assert {"_fmu_bearing", "_pythonfmu"} <= private, name      # the FMU did import its private modules ...
        assert r["fmu_modules_left"] == {}, name                    # ... and none is left after the last free


@pytest.fixture(scope="module")
def fmus(ball_bearing_fmu, journal_clearance_fmu):
    return {"BallBearing": ball_bearing_fmu, "JournalClearance": journal_clearance_fmu}


def test_host_with_a_doctored_fmu_bearing_gets_the_fmus_own_physics(fmus, tmp_path):
    """A host that imported another ``fmu_bearing`` (and pythonfmu) first: the FMUs use their packed copies."""
    doctored = tmp_path / "doctored"
    shutil.copytree(ROOT / "fmu_bearing", doctored / "fmu_bearing", ignore=shutil.ignore_patterns("__pycache__"))
    with open(doctored / "fmu_bearing" / "ball_bearing.py", "a") as fh:
        fh.write("\n_init = BallBearing.__init__\n"
                 "def _doubled(self, *a, **k):\n    _init(self, *a, **k)\n    self.stiffness *= 2.0\n"
                 "BallBearing.__init__ = _doubled\n")
    with open(doctored / "fmu_bearing" / "clearance_joint.py", "a") as fh:
        fh.write("\n_init = ClearanceJoint.__init__\n"
                 "def _doubled(self, *a, **k):\n    _init(self, *a, **k)\n    self.stiffness *= 2.0\n"
                 "ClearanceJoint.__init__ = _doubled\n")
    prelude = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(doctored)!r})
        import fmu_bearing.ball_bearing, fmu_bearing.clearance_joint, pythonfmu
        assert fmu_bearing.__file__.startswith({str(doctored)!r})
        _K = fmu_bearing.ball_bearing.BallBearing().stiffness
        print("doctored K", _K)
    """)
    report = run_host(sys.executable, fmus, tmp_path, prelude)
    check_report(report, fmus)
    # the host's copy really is the doctored one: the FMU's force is half what it would give
    doctored_force = expected_forces()["BallBearing"][0] * 2.0
    assert report["fmus"]["BallBearing"]["forces"][0][0] == pytest.approx(doctored_force / 2.0, rel=1e-15)


def _fmpy_venv(cache_dir: Path) -> Path:
    """A plain virtual environment (no system site-packages) with only ``pip install fmpy``, cached."""
    python = cache_dir / "bin" / "python"
    if python.is_file() and (cache_dir / "ok").is_file():
        return python
    shutil.rmtree(cache_dir, ignore_errors=True)
    venv.EnvBuilder(with_pip=True, system_site_packages=False, clear=True).create(cache_dir)
    proc = subprocess.run([str(python), "-m", "pip", "install", "--quiet", "fmpy"], capture_output=True, text=True,
                          timeout=900)
    if proc.returncode != 0:
        pytest.skip(f"pip install fmpy failed in a fresh venv (no index reachable?): {proc.stderr[-500:]}")
    (cache_dir / "ok").write_text("fmpy\n")
    return python


def test_fmus_run_in_a_venv_with_only_fmpy(fmus, tmp_path, request):
    """BallBearing and JournalClearance in a fresh venv with nothing but fmpy and its dependencies (numpy,
    no scipy, not this project): the same force, bit for bit, as the project's force law in this process.
    The venv is created once and kept in pytest's cache (about 15 s with local wheels)."""
    cache = Path(request.config.cache.mkdir(f"fmpy-only-venv-py{sys.version_info[0]}{sys.version_info[1]}"))
    python = _fmpy_venv(cache)
    report = run_host(python, fmus, tmp_path)
    assert report["scipy"] is False
    check_report(report, fmus)


# A host script: instantiate/step/free BallBearing from one extraction, delete it, then again from a second
# extraction; reports the forces, sys.path/sys.modules after each free, and whether the second instance ran the
# modules of the first (the build's module cache, issue 14) or compiled them again.
CACHE_HOST = textwrap.dedent("""
    import json, os, shutil, sys
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    fmu, first, second, e_x = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
    compiled = []
    sys.addaudithook(lambda event, args: compiled.append(str(args[1])) if event == "compile" else None)
    path_before, modules_before = list(sys.path), set(sys.modules)
    report = {"forces": [], "clean_after_free": [], "compiled_private": []}
    package = None
    for unzip in (first, second):
        extract(fmu, unzipdir=unzip)
        md = read_model_description(unzip)
        private = json.load(open(unzip + "/resources/build_options.json"))["private_modules"]
        vr = {v.name: v.valueReference for v in md.modelVariables}
        s = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="cache")
        del compiled[:]
        s.instantiate(loggingOn=False)
        report["compiled_private"].append(
            sorted({os.path.basename(c) for c in compiled if os.path.join("resources", "_") in c}))
        name = next(n for n in private if n.startswith("_fmu_bearing_"))
        if package is None:
            package, report["package"] = sys.modules[name], name
        else:
            report["same_package"] = sys.modules[name] is package
            report["package_path"] = list(package.__path__)
        s.setupExperiment(startTime=0.0); s.enterInitializationMode()
        s.setReal([vr["e_x"]], [e_x]); s.exitInitializationMode(); s.doStep(0.0, 1e-4)
        report["forces"].append(s.getReal([vr["F_x"], vr["F_y"]]))
        s.terminate(); s.freeInstance()
        left = sorted(m for m in sys.modules if m.split(".")[0] in private)
        report["clean_after_free"].append(sys.path == path_before and not left
                                          and not (set(sys.modules) - modules_before) & set(private))
        shutil.rmtree(unzip)
    print(json.dumps(report))
""")


def test_reinstantiation_reuses_the_builds_modules_and_leaves_the_host_clean(ball_bearing_fmu, tmp_path):
    """Issue 14 (memory) without giving up issue 13.4 (sealing): after the last fmi2FreeInstance the FMU's
    modules have left sys.modules and its folder sys.path; a later instance, from another extraction (the first
    one deleted), runs the same module objects again (nothing of the private package is compiled a second
    time), their package path pointing at the new extraction, and gives the same force."""
    script = tmp_path / "cache_host.py"
    script.write_text(CACHE_HOST)
    first, second = tmp_path / "first", tmp_path / "second"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    proc = subprocess.run([sys.executable, str(script), str(ball_bearing_fmu), str(first), str(second), str(E_X)],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    assert report["forces"] == [expected_forces()["BallBearing"]] * 2
    assert report["clean_after_free"] == [True, True]
    assert "ball_bearing.py" in report["compiled_private"][0]     # the first instance imports the package ...
    assert report["compiled_private"][1] == []                      # ... the second one does not
    assert report["same_package"] is True
    assert report["package_path"] == [str(second / "resources" / report["package"])]


# --- errors: a cause, a category, also with logging off ----------------------------------------------

class Host:
    """FMU2Slave with a logger callback that records (status, category, message)."""

    def __init__(self, path: Path, unzip: Path, logging_on: bool):
        extract(str(path), unzipdir=str(unzip))
        self.md = read_model_description(str(unzip))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.messages = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.s = FMU2Slave(guid=self.md.guid, unzipDirectory=str(unzip),
                           modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="guest")
        self.s.instantiate(callbacks=self.callbacks, loggingOn=logging_on)
        self.s.setupExperiment(startTime=0.0)
        self.s.enterInitializationMode()

    def _log(self, env, instance, status, category, message):
        self.messages.append((status, category and category.decode(), message.decode("utf-8", "replace")))


@pytest.mark.parametrize("logging_on", [False, True])
def test_failed_initialisation_names_its_cause_with_a_category(ball_bearing_fmu, tmp_path, logging_on):
    host = Host(ball_bearing_fmu, tmp_path / "x", logging_on)
    host.s.setInteger([host.vr["n_balls"]], [2])
    with pytest.raises(FMICallException):
        host.s.exitInitializationMode()
    host.s.freeInstance()
    errors = [(c, m) for s, c, m in host.messages if s >= 3]
    assert any(c == "logStatusError" and m.startswith("initialisation failed: invalid parameter n_balls = 2: ")
               for c, m in errors), errors
    assert not any("unknown error" in m for _, m in errors)
    if not logging_on:                          # nothing but the error reaches a host that switched logging off
        assert len(host.messages) == 1


@pytest.mark.parametrize("name", ["BallBearing", "JournalClearance"])
def test_failed_instantiation_names_its_cause_with_logging_off(fmus, tmp_path, name):
    unzip = tmp_path / "x"
    extract(str(fmus[name]), unzipdir=str(unzip))
    (unzip / "resources" / "build_options.json").write_text("{not json")   # a damaged FMU
    messages = []
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(lambda env, inst, status, cat, msg: messages.append(
        (status, cat.decode(), msg.decode())))
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    md = read_model_description(str(unzip))
    s = FMU2Slave(guid=md.guid, unzipDirectory=str(unzip), modelIdentifier=name, instanceName="damaged")
    with pytest.raises(Exception, match="Failed to instantiate"):
        s.instantiate(callbacks=callbacks, loggingOn=False)
    assert len(messages) == 1 and messages[0][:2] == (3, "logStatusError"), messages
    assert messages[0][2].startswith("instantiation failed: JSONDecodeError(")


@pytest.mark.parametrize("name", ["BallBearing", "JournalClearance"])
def test_do_step_after_terminate_is_refused(fmus, tmp_path, name):
    host = Host(fmus[name], tmp_path / "x", logging_on=False)
    host.s.setReal([host.vr["e_x"]], [E_X])
    host.s.exitInitializationMode()
    host.s.doStep(0.0, 1e-4)
    host.s.terminate()
    with pytest.raises(FMICallException) as err:
        host.s.doStep(1e-4, 1e-4)
    assert err.value.status == DISCARD
    assert [(c, "fmi2Terminate" in m) for s, c, m in host.messages] == [("logStatusError", True)]
    host.s.freeInstance()


# --- the loader's logging filter and status mapping (fmu_bearing/native/loader.c; issues 13.5, 14.7) --------
# These hosts use fmpy's logger proxy (mechanism.cosim.fmpy_logging), behind which the slaves do not call the
# host's logger themselves (HostLogger): every message reaches the host through pythonfmu and the loader.

ERROR = 3


def _fmpy_host(path: Path, unzip: Path, logging_on: bool):
    from mechanism.cosim.fmpy_logging import fmpy_callbacks
    extract(str(path), unzipdir=str(unzip))
    md = read_model_description(str(unzip))
    messages = []
    callbacks = fmpy_callbacks(lambda env, inst, status, cat, msg: messages.append(
        (status, cat and cat.decode(), msg.decode("utf-8", "replace"))))
    s = FMU2Slave(guid=md.guid, unzipDirectory=str(unzip), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="filtered")
    s.instantiate(callbacks=callbacks, loggingOn=logging_on)
    return s, {v.name: v.valueReference for v in md.modelVariables}, messages, callbacks


def _free(s, callbacks):
    from mechanism.cosim.fmpy_logging import release
    s.freeInstance()
    release(callbacks)


def test_import_failure_of_a_damaged_fmu_reaches_the_host_with_logging_off(ball_bearing_fmu, tmp_path):
    """A module missing when pythonfmu imports the slave module (before any slave code runs): only pythonfmu can
    report it, and only to a logging instance; the loader keeps pythonfmu's logging on and passes errors on.
    In a subprocess: the half-imported private package would stay in this process's sys.modules."""
    script = textwrap.dedent(f"""
        import glob, json, os
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        from mechanism.cosim.fmpy_logging import fmpy_callbacks
        unzip = extract({str(ball_bearing_fmu)!r}, unzipdir={str(tmp_path / "x")!r})
        os.remove(glob.glob(os.path.join(unzip, "resources", "_fmu_bearing_*", "life.py"))[0])   # damaged
        md = read_model_description(unzip)
        messages = []
        callbacks = fmpy_callbacks(lambda env, inst, status, cat, msg: messages.append(
            (status, cat and cat.decode(), msg.decode())))
        s = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier="BallBearing", instanceName="damaged")
        try:
            s.instantiate(callbacks=callbacks, loggingOn=False)
            failed = False
        except Exception as err:
            failed = "Failed to instantiate" in str(err)
        print(json.dumps({{"failed": failed, "messages": messages}}))
    """)
    proc = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    assert report["failed"]
    [(status, category, message)] = report["messages"]          # the cause, once
    assert status >= ERROR and category == {3: "logStatusError", 4: "logStatusFatal"}[status]
    assert "ImportError" in message and "'life'" in message, message


@pytest.mark.parametrize("logging_on", [False, True])
def test_bad_parameter_fails_exit_initialization_with_error_not_fatal(ball_bearing_fmu, tmp_path, logging_on):
    """n_balls = 2: fmi2Error (the call failed, the instance is intact: FMI 2.0), not pythonfmu's fmi2Fatal;
    the message names the parameter, comes once, with the status the call returns; fmi2Reset recovers."""
    s, vr, messages, callbacks = _fmpy_host(ball_bearing_fmu, tmp_path / "x", logging_on)
    try:
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.setInteger([vr["n_balls"]], [2])
        with pytest.raises(FMICallException) as err:
            s.exitInitializationMode()
        assert err.value.status == ERROR
        assert len(messages) == 1, messages
        status, category, message = messages[0]
        assert (status, category) == (ERROR, "logStatusError") and "n_balls = 2" in message, messages
        s.reset()                                               # recovered: a valid initialisation and a step
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.setReal([vr["e_x"]], [E_X])
        s.exitInitializationMode()
        s.doStep(0.0, 1e-4)
        assert s.getReal([vr["F_x"]])[0] == pytest.approx(expected_forces()["BallBearing"][0], rel=1e-9)
    finally:
        _free(s, callbacks)


def test_non_error_messages_follow_the_hosts_logging_and_categories(ball_bearing_fmu, tmp_path, monkeypatch):
    """pythonfmu logs for the loader whatever the host said; the loader passes errors always, other messages
    only while the host has logging on (fmi2Instantiate, fmi2SetDebugLogging) and in its categories."""
    monkeypatch.setenv("BEARING_FMU_C_STEP", "0")   # the probe patches the Python step: no loader C step
    s, vr, messages, callbacks = _fmpy_host(ball_bearing_fmu, tmp_path / "x", logging_on=False)
    try:
        shim = next(m for n, m in sys.modules.items() if n.startswith("ball_bearing_fmu_"))
        module = sys.modules[shim.BallBearing.__module__]   # the slave module in the FMU's private package
        status = module.Fmi2Status
        original = module.BallBearing.do_step

        def do_step(self, t, h):   # the slaves log only errors: a probe that logs one of each
            self.log("probe ok", status.ok)
            self.log("probe warning", status.warning)
            self.log("probe error", status.error)
            return original(self, t, h)

        monkeypatch.setattr(module.BallBearing, "do_step", do_step)
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.setReal([vr["e_x"]], [E_X])
        s.exitInitializationMode()

        def step(t):
            messages.clear()
            s.doStep(t, 1e-4)
            return sorted(m for _, _, m in messages)

        assert step(0.0) == ["probe error"]                                   # logging off: errors only
        s.setDebugLogging(True, [])
        assert step(1e-4) == ["probe error", "probe ok", "probe warning"]     # on, all categories
        s.setDebugLogging(True, ["logStatusWarning"])
        assert step(2e-4) == ["probe error", "probe warning"]                 # on, one category
        s.setDebugLogging(False, [])
        assert step(3e-4) == ["probe error"]                                  # off again
    finally:
        _free(s, callbacks)


# --- model description ---------------------------------------------------------------------------------

def test_all_fmus_validate_and_declare_outputs_calculated(fmus, slider_crank_fmu):
    for path in [*fmus.values(), slider_crank_fmu]:
        assert validate_fmu(str(path)) == [], path.name
        md = read_model_description(str(path))
        outputs = [v for v in md.modelVariables if v.causality == "output"]
        assert outputs and all(v.initial == "calculated" and v.start is None for v in outputs), path.name
        assert [u.variable for u in md.initialUnknowns] == outputs, path.name


def test_slider_crank_fmu_runs_without_tqdm(slider_crank_fmu, tmp_path):
    """SliderCrank.fmu packs ``mechanism`` (which needs numpy and scipy) but not tqdm: a host without tqdm runs it."""
    script = textwrap.dedent(f"""
        import math, sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] == "tqdm":
                    raise ImportError("no tqdm in this host")
        sys.meta_path.insert(0, Block())
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        d = extract({str(slider_crank_fmu)!r}, unzipdir={str(tmp_path / "x")!r})
        md = read_model_description(d)
        vr = {{v.name: v.valueReference for v in md.modelVariables}}
        s = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier="SliderCrank", instanceName="crank")
        s.instantiate(); s.setupExperiment(startTime=0.0); s.enterInitializationMode(); s.exitInitializationMode()
        for k in range(10):
            s.doStep(k * 1e-5, 1e-5)
        x = s.getReal([vr["slider_x"]])[0]
        s.terminate(); s.freeInstance()
        assert "tqdm" not in sys.modules and math.isfinite(x)
        print(x)
    """)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
