"""The first run's compile (issue 11): the progress bar says it is compiling instead of an ETA measured on the
compile, and ``compiled_driver.cached`` tells a fresh numba cache from a warm one. Compile times themselves are
measured by benchmarks/compile.py, not here."""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from mechanism.cosim import compiled_driver
from mechanism.run import RunConfig, run

ROOT = Path(__file__).resolve().parents[1]


def test_a_fresh_cache_is_not_cached(tmp_path):
    code = "from mechanism.cosim import compiled_driver as d; print(d.cached())"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=tmp_path,
                         check=True).stdout
    assert out.strip() == "False"


def test_compiled_in_this_process_is_cached():
    assert run(RunConfig(mode="inprocess", revs=0.01, progress=False)).ok
    assert compiled_driver.cached()


@pytest.mark.parametrize("first", [True, False])
def test_progress_bar_says_compiling_on_the_first_run(first, monkeypatch, capsys):
    """On a first run the bar shows "compiling kernels (first run)" until the first chunk is done, then counts
    the steps from there (a reset clock: its rate and ETA without the compile); the numbers are the same."""
    monkeypatch.setattr(compiled_driver, "cached", lambda: not first)
    config = RunConfig(mode="inprocess", revs=0.05, rpm=1200, step=1e-5)
    with_bar = run(config)
    err = capsys.readouterr().err
    assert ("compiling kernels (first run)" in err) == first
    quiet = run(RunConfig(mode="inprocess", revs=0.05, rpm=1200, step=1e-5, progress=False))
    assert with_bar.ok and quiet.ok
    assert np.array_equal(with_bar.data, quiet.data, equal_nan=True)


_COMPILED_IN_RUN = """
import sys
from numba.core import event
names = []
class Rec(event.Listener):
    def on_start(self, ev):
        pass
    def on_end(self, ev):
        f = getattr(ev.data.get("dispatcher"), "py_func", None)
        if f is not None:
            names.append(f.__module__ + "." + f.__qualname__)
event.register("numba:compile", Rec())
from mechanism.run import RunConfig, run
assert run(RunConfig(mode="inprocess", revs=0.002, progress=False)).ok
print("\\n".join(names))
"""


def test_warmup_compiles_what_run_steps_calls(tmp_path):
    """In a fresh cache, after ``mechanism.cosim.warmup`` with the stages an in-process law-model run needs
    (``warmup.needed``), the run's compile of ``run_steps`` loads the loop's functions and their callees from the
    cache (the warm-up's argument types are run_steps' own): the run compiles only run_steps and the multibody
    kernels it calls from Python before the first chunk. Nothing of the other schemes' force models (the
    ``force-model`` stage, not warmed here) is compiled into law-model's step."""
    from mechanism.cosim import warmup
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), PYTHONPATH=str(ROOT), MECHANISM_COMPILE_WORKER="0")
    assert "force-model" not in warmup.needed(False, True)
    stages = [*warmup.needed(False, True), "energy"]     # (the energy account's: the run calls them from Python)
    subprocess.run([sys.executable, "-m", "mechanism.cosim.warmup", *stages], env=env, cwd=ROOT, check=True)
    out = subprocess.run([sys.executable, "-c", _COMPILED_IN_RUN], env=env, cwd=ROOT, capture_output=True,
                         text=True, check=True).stdout.split()
    loop_side = ("mechanism.cosim.compiled_loop.", "mechanism.cosim.component_call.",
                 "mechanism.cosim.component_kernel.", "mechanism.cosim.fmu_native.", "mechanism.cosim.law_kernel.",
                 "mechanism.cosim.law_model_kernel.")
    allowed = {"mechanism.cosim.compiled_loop.run_steps"}
    compiled_again = {name for name in out if name.startswith(loop_side)} - allowed
    assert not compiled_again
    assert "mechanism.cosim.compiled_loop.run_steps" in out


def test_a_misspelt_compile_worker_setting_is_refused(monkeypatch):
    """``MECHANISM_COMPILE_WORKER`` is 0 or 1; anything else ("no", "off") is an error naming it, not "on"."""
    from mechanism.cosim import compiled_driver
    monkeypatch.setenv("MECHANISM_COMPILE_WORKER", "no")
    with pytest.raises(ValueError, match="MECHANISM_COMPILE_WORKER='no'"):
        compiled_driver.start_warmup()


def test_the_run_waits_only_for_the_stages_its_step_needs(monkeypatch):
    """``finish_warmup`` returns once the worker has printed the stages the step of the last ``CompiledLoop`` needs
    (an FMU run with jacobian-implicit: not the in-process law's nor law-model's) and ends the worker then."""
    from mechanism.cosim import warmup
    monkeypatch.setattr(compiled_driver, "_variant", (True, False))
    assert warmup.needed(True, False) == ["loop", "fmu", "force-model", "advance"]
    worker = "import time\nfor s in ('loop', 'advance', 'fmu', 'force-model'):\n    print(s, flush=True)\ntime.sleep(60)"
    process = compiled_driver.collect_stages(subprocess.Popen([sys.executable, "-c", worker],
                                                              stdout=subprocess.PIPE, text=True))
    start = time.monotonic()
    compiled_driver.finish_warmup(process, timeout=50.0)
    assert time.monotonic() - start < 30.0
    assert process.poll() is not None and process.done == {"loop", "advance", "fmu", "force-model"}
    monkeypatch.setattr(compiled_driver, "_variant", (False, True))     # in-process law-model: it would wait
    assert set(warmup.needed(False, True)) == {"loop", "in-process", "law-model"}


@pytest.mark.parametrize("executable", [None, "", "/bin/sleep"])
def test_the_warmup_is_started_with_a_python_interpreter(executable, monkeypatch):
    """In a host that embeds Python, ``sys.executable`` may be None or the host's own program: the warm-up is then
    started with the interpreter of ``sys.exec_prefix`` (or not at all), never with the host's program (which would
    not compile anything, and the first run would wait for it) and never with an error escaping."""
    from mechanism.cosim import compiled_driver
    monkeypatch.setattr(sys, "executable", executable)
    python = compiled_driver.python_executable()
    assert python is None or (Path(python).name.startswith("python") and Path(python).is_file())
    started = []
    monkeypatch.setattr(compiled_driver.subprocess, "Popen", lambda args, **kw: started.append(args) or None)
    monkeypatch.setattr(compiled_driver, "cached", lambda: False)
    monkeypatch.setattr(compiled_driver, "collect_stages", lambda process: process)
    monkeypatch.setenv("MECHANISM_COMPILE_WORKER", "1")
    compiled_driver.start_warmup()
    assert all(args[0] == python for args in started) and (python is None) == (not started)


@pytest.mark.parametrize("variant", [(True, True), (True, False), (False, True), None])
def test_the_warmup_compiles_only_the_stages_of_the_runs_step(variant, monkeypatch):
    """``run_master`` knows the step it will compile (through an FMU or not, law-model's or not) before the loop
    starts: the warm-up process is asked for that step's stages only (``warmup.needed``: an FMU run's first run does
    not wait behind the in-process law's stage), every stage without a variant; ``cached`` then looks for it."""
    from mechanism.cosim import compiled_driver, warmup
    started = []
    monkeypatch.setattr(compiled_driver.subprocess, "Popen", lambda args, **kw: started.append(args) or None)
    monkeypatch.setattr(compiled_driver, "cached", lambda: False)
    monkeypatch.setattr(compiled_driver, "collect_stages", lambda process: process)
    monkeypatch.setattr(compiled_driver, "_variant", None)
    monkeypatch.setenv("MECHANISM_COMPILE_WORKER", "1")
    monkeypatch.setattr(compiled_driver.os, "cpu_count", lambda: 2)
    compiled_driver.start_warmup(variant)
    assert len(started) == 1
    asked = started[0][started[0].index("mechanism.cosim.warmup") + 1:]
    wanted = warmup.needed(*variant) if variant is not None else []
    later = warmup.later(*variant) if variant is not None else []
    assert asked == [name for name in wanted if name not in warmup.RUN_SHARE] + later   # the rest: the run's share
    assert compiled_driver._variant == variant
    if variant == (True, True):     # the headline: the ideal counterpart's advance last, after the step's stages
        assert "in-process" not in asked and "law-model" in asked and "force-model" not in asked
        assert asked[-1] == "advance"
    if variant == (True, False):    # another scheme: its step calls advance, which the run compiles itself
        assert "advance" not in asked and "force-model" in asked


def test_the_run_compiles_its_share_then_waits_for_the_rest(monkeypatch):
    """``finish_warmup`` first compiles the stages left to the run's process (``warmup.RUN_SHARE``, recorded as
    done), then waits for the worker's; ``advance`` (the run's share) compiled here in a fresh process loads
    from the cache a second time (the signatures are run_steps' own: tests above)."""
    from mechanism.cosim import warmup
    compiled = []
    monkeypatch.setattr(warmup, "compile_stages", lambda names, done: [compiled.append(n) or done(n) for n in names])
    monkeypatch.setattr(compiled_driver, "_variant", (True, False))
    worker = "import time\nfor s in ('loop', 'fmu', 'force-model'):\n    print(s, flush=True)\ntime.sleep(60)"
    process = compiled_driver.collect_stages(subprocess.Popen([sys.executable, "-c", worker],
                                                              stdout=subprocess.PIPE, text=True))
    process.share = ["advance"]
    start = time.monotonic()
    compiled_driver.finish_warmup(process, timeout=50.0)
    assert time.monotonic() - start < 30.0 and compiled == ["advance"]
    assert process.poll() is not None and process.done == {"loop", "advance", "fmu", "force-model"}


def _raise_interrupt():
    raise KeyboardInterrupt


@pytest.fixture
def stand_in(monkeypatch):
    """Stand-in warm-up processes: ``stand_in(lines)`` starts one printing the stages ``lines`` (a Python statement
    list), then sleeping; every one is ended after the test, passed or not."""
    started = []
    monkeypatch.setattr(compiled_driver, "_later", None)

    def start(lines: str):
        process = compiled_driver.collect_stages(subprocess.Popen(
            [sys.executable, "-c", f"import time\n{lines}\ntime.sleep(60)"], stdout=subprocess.PIPE, text=True))
        started.append(process)
        return process
    yield start
    for process in started:
        compiled_driver.end_warmup(process)


def test_the_warmup_compiles_the_ideal_counterparts_advance_while_the_run_compiles_its_step(monkeypatch, stand_in):
    """A law-model run does not wait for ``kernels.advance`` (``warmup.later``: its step does not call it): the
    worker is kept (``_later``) while the run compiles ``run_steps``, and ``await_later``, before the ideal
    counterpart's run, waits for that stage, then ends the worker."""
    monkeypatch.setattr(compiled_driver, "_variant", (True, True))
    process = stand_in("for s in ('loop', 'fmu', 'law-model'):\n    print(s, flush=True)\ntime.sleep(1.5)\n"
                      "print('advance', flush=True)")
    compiled_driver.finish_warmup(process, timeout=50.0)
    assert compiled_driver._later is process and process.poll() is None
    compiled_driver.finish_warmup(process, 0)      # run_master's end calls it again: the kept worker is left alone
    assert compiled_driver._later is process and process.poll() is None
    assert "advance" not in process.done
    polled = []
    compiled_driver.await_later(timeout=50.0, poll=lambda: polled.append(1))
    assert "advance" in process.done and process.poll() is not None and compiled_driver._later is None
    assert polled      # the run's signal check while it waited
    compiled_driver.await_later()        # nothing left: nothing happens


def test_a_warmup_that_never_finishes_its_later_stage_is_ended(monkeypatch, stand_in):
    """``await_later`` waits at most its timeout (the run then compiles what it calls itself); a worker whose later
    stages are done already is not kept."""
    monkeypatch.setattr(compiled_driver, "_variant", (True, True))
    process = stand_in("for s in ('loop', 'fmu', 'law-model'):\n    print(s, flush=True)")
    compiled_driver.finish_warmup(process, timeout=50.0)
    assert compiled_driver._later is process
    with pytest.raises(KeyboardInterrupt):     # a noted signal ends the wait, and the worker with it
        compiled_driver.await_later(timeout=50.0, poll=_raise_interrupt)
    assert process.poll() is not None and compiled_driver._later is None
    process = stand_in("for s in ('loop', 'fmu', 'law-model'):\n    print(s, flush=True)")
    compiled_driver.finish_warmup(process, timeout=50.0)
    start = time.monotonic()
    compiled_driver.await_later(timeout=0.5)
    assert 0.4 < time.monotonic() - start < 10.0 and process.poll() is not None and compiled_driver._later is None
    done = stand_in("for s in ('loop', 'fmu', 'law-model', 'advance'):\n    print(s, flush=True)")
    deadline = time.monotonic() + 30.0
    while len(done.done) < 4 and time.monotonic() < deadline:     # all four read before finish_warmup looks
        time.sleep(0.05)
    compiled_driver.finish_warmup(done, timeout=50.0)
    assert compiled_driver._later is None and done.poll() is not None


def test_a_first_fmu_run_starts_the_warmup_for_its_own_step(monkeypatch):
    """The headline's step (FMU, the default law-model): ``run_master`` passes (True, True) to ``start_warmup``."""
    from mechanism.cosim import compiled_driver
    seen = []
    monkeypatch.setattr(compiled_driver, "start_warmup", lambda variant=None: seen.append(variant))
    assert run(RunConfig(revs=0.002, progress=False)).ok
    assert seen == [(True, True)]


def _kernel_modules() -> list[str]:
    """The modules that compile with numba, as the cache key finds them (``kernel_cache.sources``): a new one is
    checked here without a list to extend."""
    from mechanism import kernel_cache
    names = [kernel_cache._module_name(p)[0] for p in kernel_cache.sources()]
    return [name for name in names if name != "mechanism.kernel_cache"]    # (its docstring mentions njit)


def _kernels():
    """Every numba dispatcher defined in the kernel modules: (module name, name, dispatcher)."""
    import importlib

    from numba.core.registry import CPUDispatcher
    for name in _kernel_modules():
        module = importlib.import_module(name)
        for attr, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.py_func.__module__ == name:
                yield name, attr, value


def test_every_kernel_is_cached_and_compiled_without_the_cfunc_wrapper():
    """Every kernel goes through ``kernels.KERNEL`` (or ``LEAF``): cached on disk, no C-callable wrapper. A kernel
    declared with a bare ``@njit(cache=True)`` would compile that wrapper again on every first run."""
    found = list(_kernels())
    assert len(found) > 60
    for module, name, dispatcher in found:
        assert dispatcher._cache.__class__.__name__ == "FunctionCache", (module, name)
        assert dispatcher.targetoptions.get("no_cfunc_wrapper") is True, (module, name)


def test_a_kernel_for_compiled_callers_refuses_a_python_call():
    """A kernel compiled without numba's CPython wrapper (``kernels.internal``) raises a TypeError naming itself when
    Python calls it (numba would jump to the missing wrapper and crash the interpreter); compiled code calls it."""
    from mechanism.multibody import kernels as kn
    internal = [(m, n, d) for m, n, d in _kernels() if isinstance(d, kn.CompiledOnly)]
    assert {("mechanism.cosim.law_model_kernel", "advance"), ("mechanism.multibody.kernels", "_kinematics"),
            ("mechanism.cosim.compiled_loop", "trial_model"), ("mechanism.cosim.component_kernel", "law_exchange"),
            } <= {(m, n) for m, n, _ in internal}
    assert len(internal) == 27      # docs/kernels.md, "Fifth pass" (28 then; law-model's _eig_max is law_kernel's since)
    for module, name, dispatcher in _kernels():     # no Python entry exactly where a Python call is refused
        assert isinstance(dispatcher, kn.CompiledOnly) == bool(dispatcher.targetoptions.get("no_cpython_wrapper")), \
            (module, name)
    for module, name, dispatcher in internal:
        with pytest.raises(TypeError, match=f"{module}.{name} is called from compiled kernels only"):
            dispatcher(np.zeros(3))
    # compiled callers are unaffected: the first communication steps of a law-model run call several of them
    assert run(RunConfig(mode="inprocess", revs=0.002, progress=False)).ok


def test_the_ideal_counterparts_run_waits_for_the_kept_worker_and_ends_it(monkeypatch, stand_in):
    """The wiring: a run whose Python loop calls the kernels (the ideal joint's, as ``cli.ideal_counterpart`` runs it)
    waits for the worker a first run kept (``run_master`` -> ``await_warmup`` -> ``await_later``) and ends it."""
    process = stand_in("time.sleep(1.0)\nprint('advance', flush=True)")
    process.later = ["advance"]
    monkeypatch.setattr(compiled_driver, "_later", process)
    assert run(RunConfig(joint="ideal", revs=0.002, progress=False)).ok
    assert "advance" in process.done and process.poll() is not None and compiled_driver._later is None


def test_a_failed_or_interrupted_run_drops_its_kept_worker(monkeypatch, stand_in):
    """No run follows a failed or interrupted one to wait for the kept worker: ``drop_warmup`` ends it and clears
    ``_later``; an unrelated process is ended without touching the kept one."""
    kept, other = stand_in("pass"), stand_in("pass")
    monkeypatch.setattr(compiled_driver, "_later", kept)
    compiled_driver.drop_warmup(other)
    assert other.poll() is not None and compiled_driver._later is kept and kept.poll() is None
    compiled_driver.drop_warmup(kept)
    assert kept.poll() is not None and compiled_driver._later is None


def test_the_warmup_refuses_an_unknown_stage_in_one_line():
    """``python -m mechanism.cosim.warmup`` with a stage it does not have: status 2, one line naming it and the
    stages, nothing compiled (no traceback)."""
    done = subprocess.run([sys.executable, "-m", "mechanism.cosim.warmup", "loop", "lawmodel"], cwd=ROOT,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)), capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.strip().splitlines() == [
        "error: no warm-up stage 'lawmodel' (the stages: loop, force-model, advance, fmu, in-process, law-model, "
        "energy)"]
