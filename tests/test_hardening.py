"""Issue 14: bad input ends in one clear error, never a wrong answer with exit 0, and never lost or mixed data.

Input ranges (``RunConfig``, bearing parameters), the command line's errors and exit codes, the output
folder's lock and atomic files, a full disk, SIGINT, concurrent runs, SSP references, the other tools'
failure detection, the step-size study's exit status and the shared FMU extraction. The fuzz suite
(tests/test_fuzz.py) throws generated malformed input at the same paths.
"""
from __future__ import annotations

import csv
import json
import math
import os
import resource
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from fmu_bearing.parameters import BearingParameterError, from_values, validate
from mechanism.cli import main
from mechanism.output.results import OutputFolderInUse, output_lock, write_outputs
from mechanism.run import RunConfig

ROOT = Path(__file__).resolve().parent.parent


def cli(*args, timeout=300, **kwargs) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "mechanism", *args], capture_output=True, text=True, cwd=ROOT,
                          env=env, timeout=timeout, **kwargs)


def rows_of(path: Path) -> np.ndarray:
    with open(path) as f:
        header = next(csv.reader(f))
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    assert data.shape[1] == len(header)
    return data


def consistent(out: Path) -> dict:
    """The output folder holds whole files of one run: time strictly increasing, rows = summary's samples."""
    summary = json.loads((out / "summary.json").read_text())
    data = rows_of(out / "timeseries.csv")
    assert len(data) == summary["samples"]
    assert np.all(np.diff(data[:, 0]) > 0)
    assert not list(out.glob(".*.tmp"))
    return summary


# ------------------------------------------------------------------------------------- input ranges
@pytest.mark.parametrize("changes, words", [
    ({"step": math.inf}, ["step", "range"]),
    ({"step": 1e300}, ["step", "range"]),
    ({"step": 1.0}, ["step", "range"]),                       # longer than the run, and beyond 1e-2 s
    ({"step": 5e-3, "revs": 0.05}, ["step", "longer than the run"]),
    ({"rpm": -5.0}, ["rpm", "range"]),
    ({"revs": 0.0}, ["revs", "range"]),
    ({"output_interval": math.nan}, ["output_interval", "range"]),
    ({"settings": {"n_balls": 7.9}}, ["n_balls", "integer"]),
    ({"settings": {"damping_model": 1.7}}, ["damping_model", "integer"]),
    ({"settings": {"contact_stiffness": 1e300}}, ["contact_stiffness", "range"]),
    ({"balls": 7.5}, ["balls", "integer"]),
])
def test_run_config_refuses_values_outside_the_documented_ranges(changes, words):
    with pytest.raises(ValueError) as info:
        RunConfig(**changes)
    for word in words:
        assert word in str(info.value)


def test_bearing_parameter_ranges_name_the_parameter_and_range():
    with pytest.raises(BearingParameterError, match=r"contact_stiffness .*\[0, 1e\+14\]"):
        validate(from_values({"contact_stiffness": 1e300}))
    with pytest.raises(BearingParameterError, match="n_balls .* must be an integer"):
        from_values({"n_balls": 7.9})
    with pytest.raises(BearingParameterError, match="--max-balls 21.*--fmu"):
        validate(from_values({"n_balls": 21, "allow_ball_overlap": True}), capacity=20)
    validate(from_values({"contact_stiffness": 1e10, "n_balls": 9}), capacity=20)   # in range: fine


# ----------------------------------------------------------------------------------- command line
def test_cli_errors_are_one_line_before_any_simulation(tmp_path, capsys):
    afile = tmp_path / "file"
    afile.write_text("x")
    assert main(["run", "--out", str(afile), "--joint", "ideal", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "existing file" in err
    assert main(["run", "--step", "1", "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "step" in err and "range" in err
    assert not (tmp_path / "a").exists()
    with pytest.raises(SystemExit) as info:   # argparse: one line too
        main(["run", "--scheme", "nonsense"])
    assert info.value.code == 2
    assert capsys.readouterr().err.strip().count("\n") == 0


@pytest.mark.parametrize("args, option", [
    (["life-study", "--speeds", ","], "--speeds"),              # was: 0 runs, exit 0, "wrote ..." and nothing written
    (["life-study", "--clearances", "5,x"], "--clearances"),
    (["life-study", "--speeds", "nan"], "--speeds"),
    (["life-study", "--workers", "0"], "--workers"),              # was: silently every core
    (["reproduce", "--workers", "-1"], "--workers"),              # was: silently one
    (["stepsize-study", "--workers", "0"], "--workers"),
])
def test_study_options_without_a_usable_value_are_refused_in_one_line(tmp_path, capsys, args, option):
    out = tmp_path / "out"
    try:
        code = main([*args, "--out", str(out), "--quiet"])
    except SystemExit as info:   # argparse
        code = info.code
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and option in err
    assert not list(out.glob("*.csv"))


def test_cli_ball_count_beyond_the_capacity_names_options_that_exist(tmp_path, capsys, ball_bearing_fmu):
    code = main(["run", "--balls", "100", "--set", "allow_ball_overlap=1", "--fmu", str(ball_bearing_fmu),
                 "--out", str(tmp_path / "r"), "--quiet", "--revs", "0.01"])
    err = capsys.readouterr().err
    assert code in (1, 2) and "--max-balls 100" in err and "--fmu" in err and "rebuild" not in err


def test_cli_says_plots_only_when_it_wrote_them(tmp_path, capsys):
    assert main(["run", "--joint", "ideal", "--revs", "0.01", "--quiet", "--no-plots",
                 "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    assert " plots" not in out and "summary.json" in out


# ------------------------------------------------------------------------------- output folder
def test_output_lock_refuses_a_second_holder(tmp_path):
    with output_lock(tmp_path / "o"):
        with pytest.raises(OutputFolderInUse, match="in use"):
            with output_lock(tmp_path / "o"):
                pass
    with output_lock(tmp_path / "o"):   # released
        pass


def test_a_failed_write_keeps_the_old_file_and_leaves_no_partial_file(tmp_path, monkeypatch):
    from mechanism.cosim.record import RunResult
    columns = ["time", "e_x", "e_y", "F_x", "F_y", "slider_a", "crank_moment", "constraint_violation", "slider_x"]
    result = RunResult(columns, np.zeros((5, len(columns))) + np.arange(5)[:, None], {}, "completed", "")
    write_outputs(result, tmp_path, plots=False)
    old = (tmp_path / "timeseries.csv").read_bytes()

    import mechanism.output.atomic as atomic   # where every output file is opened (atomic_open)

    class FullDisk:
        """A file whose write fails once the row for time 3 comes (the disk fills mid-file)."""

        def __init__(self, f):
            self.f = f

        def write(self, text):
            if "\n3," in text or text.startswith("3,"):
                raise OSError(28, "No space left on device", str(self.f.name))
            return self.f.write(text)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return self.f.__exit__(*exc)
    monkeypatch.setattr(atomic, "open", lambda *a, **k: FullDisk(open(*a, **k)), raising=False)
    with pytest.raises(OSError, match="No space"):
        write_outputs(result, tmp_path, plots=False)
    assert (tmp_path / "timeseries.csv").read_bytes() == old
    assert not list(tmp_path.glob(".*.tmp"))
    assert "No space left" in json.loads((tmp_path / "summary.json").read_text())["write_error"]


def test_a_full_disk_ends_with_one_line_and_no_truncated_file(tmp_path):
    """RLIMIT_FSIZE stands in for a full disk (writes beyond it fail with EFBIG; Python ignores SIGXFSZ)."""
    out = tmp_path / "r"

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, 100_000))
    proc = cli("run", "--joint", "ideal", "--revs", "0.5", "--quiet", "--no-plots", "--out", str(out),
               preexec_fn=limit)
    err = proc.stderr.strip()
    assert proc.returncode == 1, err
    assert err.count("\n") == 0 and "File too large" in err and "Traceback" not in err
    assert not (out / "timeseries.csv").exists() and not list(out.glob(".*.tmp"))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and "File too large" in summary["write_error"]


def test_concurrent_runs_never_mix_rows(tmp_path):
    """8 runs into distinct folders and 4 into one, all started at once (on 2 cores: 6 runs per core, each
    overlapping the others from start to end): every folder holds the files of one run; the runs into a folder in
    use are refused (exit 1, naming the lock), not mixed."""
    distinct, shared = 8, 4
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    args = ["--joint", "ideal", "--revs", "0.1", "--quiet", "--no-plots"]
    procs = [subprocess.Popen([sys.executable, "-m", "mechanism", "run", *args, "--rpm", str(600 + k),
                               "--out", str(tmp_path / f"d{k}")], cwd=ROOT, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for k in range(distinct)]
    procs += [subprocess.Popen([sys.executable, "-m", "mechanism", "run", *args, "--rpm", str(900 + k),
                                "--out", str(tmp_path / "same")], cwd=ROOT, env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for k in range(shared)]
    results = [(p.wait(timeout=600), p.stderr.read()) for p in procs]
    for k in range(distinct):
        assert results[k][0] == 0, results[k][1]
        s = consistent(tmp_path / f"d{k}")
        assert s["meta"]["config"]["rpm"] == 600 + k
    same = results[distinct:]
    assert any(code == 0 for code, _ in same)
    for code, err in same:
        assert code == 0 or (code == 1 and "in use" in err), err
    s = consistent(tmp_path / "same")
    rpm = s["meta"]["config"]["rpm"]
    data = rows_of(tmp_path / "same" / "timeseries.csv")
    assert math.isclose(data[-1, 0], s["meta"]["t_end_s"]) and abs(data[-1, 0] - 6 / rpm) < 1e-5   # to its end


def test_sigint_leaves_a_consistent_partial_result(tmp_path, ball_bearing_fmu):
    out = tmp_path / "r"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    # 20 revolutions: the run is still going 2 s after the lock however fast the master is
    proc = subprocess.Popen([sys.executable, "-m", "mechanism", "run", "--revs", "20", "--quiet", "--no-plots",
                             "--fmu", str(ball_bearing_fmu), "--out", str(out)], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while not (out / ".run.lock").exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.05)
    time.sleep(2.0)
    proc.send_signal(signal.SIGINT)
    code = proc.wait(timeout=120)
    err = proc.stderr.read().strip()
    assert code == 130, err
    assert "interrupted by SIGINT" in err and "Traceback" not in err
    s = consistent(out)
    assert s["status"] == "interrupted" and "SIGINT" in s["message"]
    assert not (out / "ideal_timeseries.csv").exists()   # the ideal counterpart is not started after it


# ------------------------------------------------------------------------------------------- SSP
@pytest.fixture(scope="module")
def archive(tmp_path_factory, ball_bearing_fmu, slider_crank_fmu):
    from mechanism import ssp as sm
    return sm.pack(tmp_path_factory.mktemp("ssp") / "a.ssp", {"BallBearing": ball_bearing_fmu,
                                                              "SliderCrank": slider_crank_fmu})


def _edit(archive: Path, target: Path, old: str, new: str) -> Path:
    with zipfile.ZipFile(archive) as z:
        members = {n: z.read(n) for n in z.namelist()}
    ssd = members["SystemStructure.ssd"].decode()
    assert old in ssd
    members["SystemStructure.ssd"] = ssd.replace(old, new, 1).encode()
    with zipfile.ZipFile(target, "w") as z:
        for n, d in members.items():
            z.writestr(n, d)
    return target


@pytest.mark.parametrize("source", ["/etc/passwd", "../BallBearing.fmu", "resources/../../x.fmu",
                                    "file:///etc/passwd"])
def test_ssp_component_source_must_stay_inside_the_archive(archive, tmp_path, source):
    from mechanism import ssp as sm
    bad = _edit(archive, tmp_path / "bad.ssp", 'source="resources/BallBearing.fmu"', f'source="{source}"')
    with pytest.raises(sm.SspError, match="must be a relative path inside the SSP"):
        sm.load_ssp(bad)


def test_ssp_parameter_binding_source_must_stay_inside_the_archive(archive, tmp_path):
    from mechanism import ssp as sm
    with zipfile.ZipFile(archive) as z:
        ssv = next(n for n in z.namelist() if n.endswith("bearing.ssv"))
    bad = _edit(archive, tmp_path / "bad.ssp", f'source="{ssv}"', 'source="/etc/passwd"')
    with pytest.raises(sm.SspError, match="parameter file source '/etc/passwd'"):
        sm.load_ssp(bad)


def test_ssp_unconnected_input_is_named(archive, tmp_path):
    from mechanism import ssp as sm
    with zipfile.ZipFile(archive) as z:
        ssd = z.read("SystemStructure.ssd").decode()
    start = ssd.index('<ssd:Connection startElement="mechanism" startConnector="e_x"')
    line = ssd[start:ssd.index("/>", start) + 2]
    bad = _edit(archive, tmp_path / "bad.ssp", line, "")
    with pytest.raises(sm.SspError, match=r"unconnected inputs: bearing\.e_x"):
        sm.load_ssp(bad)


def test_other_tools_runs_are_checked_for_divergence_and_refused_steps():
    from mechanism.ssp.tools import check_run
    n = 10
    out = {k: np.zeros(n) for k in ("mechanism.e_x", "mechanism.e_y", "bearing.F_x", "bearing.F_y")}
    out["mechanism.e_x"][:] = np.linspace(1e-5, 3e-5, n)
    out["bearing.F_x"][:] = np.linspace(0.0, 900.0, n)
    assert check_run(out, {}, n) is None
    frozen = {k: v.copy() for k, v in out.items()}
    frozen["bearing.F_x"][6:] = frozen["bearing.F_x"][5]    # the bearing refused from step 7 on
    k, cause = check_run(frozen, {}, n)
    assert k == 6 and "refused" in cause
    diverged = {k: v.copy() for k, v in out.items()}
    diverged["mechanism.e_x"][8:] = 0.046                      # 46 mm, as ecos once reported with exit 0
    k, cause = check_run(diverged, {}, n)
    assert k == 8 and "eccentricity limit" in cause


def test_stepsize_study_exits_non_zero_when_every_case_failed(capsys):
    """Errors, refusals and unstable runs are failed cases; one stable case makes the sweep a result."""
    from mechanism.studies.stepsize.cases import ERROR, FAILED, SKIPPED, STABLE
    from mechanism.studies.stepsize.cli import exit_status
    broken = [{"status": ERROR, "message": "ValueError: rpm = -5 is outside its range", "steps": None},
              {"status": FAILED, "message": "stopped at step 0: n_balls", "steps": None},
              {"status": SKIPPED, "message": "cost", "steps": None}]
    assert exit_status(broken) == 1
    assert "every case failed (2 cases)" in capsys.readouterr().err
    assert exit_status(broken + [{"status": STABLE, "message": "", "steps": 100}]) == 0
    assert exit_status(broken + [{"status": FAILED, "message": "unstable", "steps": 40}]) == 1


# ------------------------------------------------------------------------------------------- memory
def test_fmu_endpoints_share_one_extraction(ball_bearing_fmu):
    """One extraction per FMU file and GUID: a second endpoint maps no second copy of the binary."""
    from mechanism.cosim.endpoints import FmuEndpoint
    a = FmuEndpoint(ball_bearing_fmu)
    b = FmuEndpoint(ball_bearing_fmu)
    try:
        assert a._unzipdir == b._unzipdir
        a.initialize((1.2e-5, 0.0, 0.0, 0.0, 0.0, 0.0))
        b.initialize((0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        assert a.exchange(0.0, 1e-5, (1.2e-5, 0.0, 0.0, 0.0, 0.0, 0.0))[0] != 0.0
    finally:
        a.close()
        b.close()
    assert Path(a._unzipdir).is_dir()   # kept for the next endpoint; removed at exit


def test_a_killed_runs_temporary_files_are_removed_by_the_next_run(tmp_path):
    """A run killed while streaming its table (SIGKILL, the OOM killer) leaves ``.timeseries.csv.<pid>.tmp`` (and
    perhaps a figure's ``.<name>.<pid>.tmp.png``): the next run to hold the folder's lock removes them, and
    nothing else."""
    out = tmp_path / "o"
    out.mkdir()
    stale = [out / ".timeseries.csv.99999.tmp", out / ".ideal_timeseries.csv.99999.tmp", out / ".joint_forces.99999.tmp.png"]
    kept = [out / "timeseries.csv", out / "notes.tmp"]
    for path in stale + kept:
        path.write_text("x")
    with output_lock(out):
        assert not any(path.exists() for path in stale)
        assert all(path.exists() for path in kept)
