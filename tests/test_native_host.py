"""The BallBearing FMU in a native (non-Python) host, and the loader library that makes that work (issue 13).

A C host (fmu_bearing/native/host.c, compiled here with zig cc) loads the extracted FMU's
binaries/linux64/BallBearing.so with a clean environment: no LD_PRELOAD, no PYTHONPATH, no PYTHONHOME.
The loader (fmu_bearing/native/loader.c) must find a CPython shared library itself. The forces must equal
those fmpy gives for the same inputs, and every process must exit with status 0.
Also: the loader's message when no Python can be found, and fmi2GetDirectionalDerivative.
"""
from __future__ import annotations

import ctypes.util
import math
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from fmu_bearing.native.build import LoaderBuildError, glibc_requirement
from fmu_bearing.native.host import clean_env, compile_host, reference_forces, run_host
from test_ssp import slider_crank_fmu, ssp_archive  # noqa: F401  (session fixtures, for ecos on the SSP)

N_STEPS = 1000


def _shared_libpython_available() -> bool:
    """A CPython shared library the loader can find: this interpreter's, or one on the linker's path."""
    if sysconfig.get_config_var("Py_ENABLE_SHARED"):
        return True
    return any(ctypes.util.find_library(f"python3.{minor}") for minor in range(9, 15))


@pytest.fixture(scope="module")
def unzipdir(ball_bearing_fmu, tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("native_fmu")
    with zipfile.ZipFile(ball_bearing_fmu) as z:
        z.extractall(folder)
    return folder


@pytest.fixture(scope="module")
def host(tmp_path_factory) -> Path:
    try:
        return compile_host(tmp_path_factory.mktemp("native_host"))
    except LoaderBuildError as err:
        pytest.skip(f"no C compiler for the native host (pip install ziglang): {err}")


@pytest.fixture(scope="module")
def reference(unzipdir) -> tuple[float, float, float, float]:
    """fmpy (this Python process) on the host's input sequence."""
    return reference_forces(unzipdir, N_STEPS)


@pytest.fixture(scope="module")
def need_libpython():
    if not _shared_libpython_available():
        pytest.skip("no CPython shared library on this machine (Python built without --enable-shared and no "
                    "libpython3.X.so on the linker's path): the loader has nothing to load")


def _assert_same_forces(run, reference, n_instances=1):
    assert run.returncode == 0, (run.returncode, run.stderr[-3000:])
    assert len(run.forces) == n_instances, run.stdout
    for forces in run.forces:
        # same inputs, same force law, same interpreter build: the same doubles
        assert forces == pytest.approx(reference, rel=1e-13, abs=0.0), (forces, reference)
    assert abs(reference[0]) > 100.0  # a loaded bearing, not zeros


def test_loader_is_the_fmu_binary_and_needs_only_an_old_glibc(unzipdir):
    binaries = unzipdir / "binaries" / "linux64"
    assert (binaries / "BallBearing.so").is_file() and (binaries / "BallBearing_pythonfmu.so").is_file()
    assert not list((unzipdir / "resources").rglob("native")), "the loader sources are not FMU runtime files"
    required = glibc_requirement(binaries / "BallBearing.so")
    if required is None:
        pytest.skip("objdump not available")
    if required != "none":
        assert tuple(int(p) for p in required.split("_")[1].split(".")) <= (2, 17), required


def test_native_host_without_setup_matches_fmpy(host, unzipdir, reference, need_libpython):
    """One instance, 1,000 steps, clean environment: the forces fmpy gives, exit status 0."""
    env = clean_env()
    assert not {"LD_PRELOAD", "PYTHONPATH", "PYTHONHOME"} & set(env)
    _assert_same_forces(run_host(host, unzipdir, 1, N_STEPS, "seq", env=env), reference)


def test_native_host_with_the_system_python_only(host, unzipdir, reference, need_libpython):
    """PATH=/usr/bin:/bin: the system's python3 (here Debian's, standard library only, no numpy or scipy),
    or, without one, a libpython3.X.so.1.0 found by name. Same forces."""
    run = run_host(host, unzipdir, 1, N_STEPS, "seq", env=clean_env(PATH="/usr/bin:/bin"))
    if run.returncode == 2 and "no usable CPython shared library" in run.stderr:
        pytest.skip("no system Python with a shared library on this machine")
    _assert_same_forces(run, reference)


def test_native_host_exits_cleanly_50_times_in_a_row(host, unzipdir, reference, need_libpython):
    """50 processes (two at a time): each steps 1,000 times, checks F, frees, exits with status 0."""
    with ThreadPoolExecutor(2) as pool:
        runs = list(pool.map(lambda _: run_host(host, unzipdir, 1, N_STEPS, "seq"), range(50)))
    assert [r.returncode for r in runs] == [0] * 50, [(r.returncode, r.stderr[-500:]) for r in runs if r.returncode]
    for run in runs:
        _assert_same_forces(run, reference)


def test_four_instances_stepped_from_threads_exit_cleanly(host, unzipdir, reference, need_libpython):
    """Four instances stepped concurrently from four native threads, 10 processes: same forces, status 0."""
    with ThreadPoolExecutor(2) as pool:
        runs = list(pool.map(lambda _: run_host(host, unzipdir, 4, N_STEPS, "threads"), range(10)))
    for run in runs:
        _assert_same_forces(run, reference, n_instances=4)


def test_no_python_found_fails_instantiate_with_a_message(host, unzipdir):
    """The loader's search fails (BEARING_FMU_LIBPYTHON names no library): fmi2Instantiate returns NULL
    after an error message with a category that says what was searched and how to fix it; no crash."""
    run = run_host(host, unzipdir, 1, 10, "seq", env=clean_env(BEARING_FMU_LIBPYTHON="/nonexistent/libpython3.so"))
    assert run.returncode == 2, (run.returncode, run.stderr)    # the host's "instantiate failed"
    assert "status 3 [logStatusError]" in run.stderr, run.stderr  # fmi2Error, category not NULL
    assert "no usable CPython shared library" in run.stderr
    assert "/nonexistent/libpython3.so" in run.stderr and "BEARING_FMU_LIBPYTHON=" in run.stderr


def _fmpy_instance(unzipdir, name="dd"):
    from fmpy import read_model_description
    from fmpy.fmi2 import FMU2Slave
    md = read_model_description(str(unzipdir))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(unzipdir), modelIdentifier="BallBearing", instanceName=name)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    return md, fmu, {v.name: v.valueReference for v in md.modelVariables}


def test_directional_derivative_is_declared_and_matches_finite_differences(unzipdir):
    """fmi2GetDirectionalDerivative (the loader, from the tangent outputs) against central differences of
    the force over the same step, each from the same saved FMU state."""
    md, fmu, vr = _fmpy_instance(unzipdir)
    assert md.coSimulation.providesDirectionalDerivative
    try:
        inputs = ["e_x", "e_y", "v_x", "v_y", "omega_inner", "omega_outer"]
        x0 = [2.2e-5, -1.9e-5, 0.004, -0.003, 100.0, 0.0]
        F = [vr["F_x"], vr["F_y"]]
        h = 1e-5
        fmu.setReal([vr[n] for n in inputs], x0)
        fmu.doStep(0.0, h)
        state = fmu.getFMUstate()

        def force_after_step(x):
            fmu.setFMUstate(state)
            fmu.setReal([vr[n] for n in inputs], x)
            fmu.doStep(h, h)
            return fmu.getReal(F)

        force_after_step(x0)
        for k, name in enumerate(inputs[:4]):
            delta = 1e-9 if name.startswith("e") else 1e-6
            seed = [0.0] * 4
            seed[k] = 1.0
            dd = fmu.getDirectionalDerivative(F, [vr[n] for n in inputs[:4]], seed)
            force_after_step(x0)  # dd at x0 (the state after the step with x0)
            dd_at_x0 = fmu.getDirectionalDerivative(F, [vr[name]], [1.0])
            up, down = list(x0), list(x0)
            up[k] += delta
            down[k] -= delta
            fd = [(a - b) / (2 * delta) for a, b in zip(force_after_step(up), force_after_step(down))]
            scale = max(abs(v) for v in fd) or 1.0
            assert all(math.isfinite(v) for v in dd)
            for got, want in zip(dd_at_x0, fd):
                assert abs(got - want) <= 1e-4 * scale + 1e-9, (name, dd_at_x0, fd)
        # a combined seed is the linear combination of the columns
        force_after_step(x0)
        seed = [1.0, -2.0, 0.5, 3.0]
        combined = fmu.getDirectionalDerivative(F, [vr[n] for n in inputs[:4]], seed)
        K = dict(zip(["kxx", "kxy", "kyy", "cxx", "cxy", "cyy"], fmu.getReal(
            [vr[n] for n in ("stiffness_xx", "stiffness_xy", "stiffness_yy", "damping_xx", "damping_xy",
                             "damping_yy")])))
        expect_x = K["kxx"] * 1.0 + K["kxy"] * -2.0 + K["cxx"] * 0.5 + K["cxy"] * 3.0
        expect_y = K["kxy"] * 1.0 + K["kyy"] * -2.0 + K["cxy"] * 0.5 + K["cyy"] * 3.0
        assert combined == pytest.approx([expect_x, expect_y], rel=1e-14)
        fmu.freeFMUstate(state)
    finally:
        fmu.terminate()
        fmu.freeInstance()


def test_directional_derivative_refuses_what_it_cannot_give(unzipdir):
    """dF/d omega_inner has no tangent output: fmi2Error with a logger message, not a wrong number."""
    from fmpy.fmi1 import FMICallException
    _, fmu, vr = _fmpy_instance(unzipdir, "dd_refused")
    try:
        with pytest.raises(FMICallException):
            fmu.getDirectionalDerivative([vr["F_x"]], [vr["omega_inner"]], [1.0])
    finally:
        fmu.terminate()
        fmu.freeInstance()


def test_loader_cross_builds_for_windows(ball_bearing_fmu):
    """The Windows loader is in the FMU next to pythonfmu's DLL (built, not run: no Windows here)."""
    with zipfile.ZipFile(ball_bearing_fmu) as z:
        names = set(z.namelist())
        if "binaries/win64/BallBearing_pythonfmu.dll" not in names:
            pytest.skip("this FMU has no Windows binary")
        dll = z.read("binaries/win64/BallBearing.dll")
    assert dll[:2] == b"MZ"
    objdump = shutil.which("objdump")
    if objdump:
        import tempfile
        with tempfile.NamedTemporaryFile(suffix=".dll") as fh:
            fh.write(dll)
            fh.flush()
            exports = subprocess.run([objdump, "-p", fh.name], capture_output=True, text=True).stdout
        assert "fmi2Instantiate" in exports and "fmi2DoStep" in exports


# ----------------------------------------------------------------------------------------------
# ecos: its command-line tool and its out-of-process proxyfmu are native hosts too
# ----------------------------------------------------------------------------------------------
def _ecos_binary(name: str, folder: Path) -> Path:
    """ecospy's ``name`` executable copied to ``folder`` with its executable bit (the wheel drops it)."""
    try:
        import ecospy
    except ImportError as err:
        pytest.skip(f"ecospy is not installed ({err}); pip install '.[tools]'")
    except OSError as err:
        pytest.skip(f"ecospy's native library does not load ({err}); apt-get install libtbb12")
    exe = Path(ecospy.__file__).parent / "binaries" / name
    if not exe.is_file():
        pytest.skip(f"ecospy ships no {name} executable at {exe}")
    local = folder / name
    shutil.copy(exe, local)
    local.chmod(0o755)
    return local


def test_ecos_command_line_runs_the_ssp_without_setup(ssp_archive, tmp_path, need_libpython):
    """The ecos executable (native) runs both FMUs of the SSP with a clean environment, in parallel mode, with
    the default set bound in SystemStructure.ssd (1200 rpm; the other sets are variant SSDs, docs/ssp.md)."""
    import csv
    ecos = _ecos_binary("ecos", tmp_path)
    proc = subprocess.run([str(ecos), "simulate", "--path", str(ssp_archive), "--stepSize", "1e-5",
                           "--stopTime", "0.0005", "-l", "info"],
                          cwd=tmp_path, env=clean_env(), capture_output=True, text=True, timeout=300)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log[-3000:]
    assert "Wrote CSV data" in log, log[-3000:]
    with open(tmp_path / "SliderCrankBearing.csv", newline="") as fh:
        rows = list(csv.reader(fh, skipinitialspace=True))
    last = dict(zip([h.split("[")[0].strip() for h in rows[0]], rows[-1]))
    assert float(last["mechanism::omega_outer"]) == pytest.approx(1200 * 2 * math.pi / 60, rel=1e-6)
    assert int(float(last["bearing::n_balls"])) == 8
    assert abs(float(last["mechanism::e_x"])) > 0.0


def test_ecos_proxyfmu_runs_the_fmu_out_of_process_without_setup(unzipdir, ball_bearing_fmu, tmp_path,
                                                                  need_libpython):
    """ecos's proxyfmu (a native process per instance) gives the forces fmpy gives, from a clean environment."""
    proxy = _ecos_binary("proxyfmu", tmp_path)
    script = tmp_path / "proxy_run.py"
    script.write_text(
        "import sys\n"
        "from ecospy import EcosSimulation, EcosSimulationStructure\n"
        "with EcosSimulationStructure() as ss:\n"
        "    ss.add_model('bearing', 'proxyfmu://localhost?file=' + sys.argv[1])\n"
        "    with EcosSimulation(structure=ss, step_size=1e-5) as sim:\n"
        "        sim.init()\n"
        "        for k in range(100):\n"
        "            sim.set_real('bearing::e_x', 3e-5)\n"
        "            sim.set_real('bearing::omega_inner', 100.0)\n"
        "            sim.step(1)\n"
        "        print('F', repr(sim.get_real('bearing::F_x')), repr(sim.get_real('bearing::F_y')))\n"
        "        sim.terminate()\n", encoding="utf-8")
    env = clean_env(PATH=os.pathsep.join([str(proxy.parent), os.environ.get("PATH", "")]))
    proc = subprocess.run([sys.executable, str(script), str(ball_bearing_fmu)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert "returned with status 0" in proc.stdout + proc.stderr  # the proxyfmu process exited cleanly
    line = next(l for l in proc.stdout.splitlines() if l.startswith("F "))
    got = [float(v) for v in line.split()[1:]]

    from fmpy import read_model_description
    from fmpy.fmi2 import FMU2Slave
    md = read_model_description(str(unzipdir))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(unzipdir), modelIdentifier="BallBearing", instanceName="ref")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    for k in range(100):
        fmu.setReal([vr["e_x"], vr["omega_inner"]], [3e-5, 100.0])
        fmu.doStep(k * 1e-5, 1e-5)
    want = fmu.getReal([vr["F_x"], vr["F_y"]])
    fmu.terminate()
    fmu.freeInstance()
    assert got == pytest.approx(want, rel=1e-13) and abs(want[0]) > 100.0
