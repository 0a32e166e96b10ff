"""The Python side of the compiled communication step (``compiled_loop.run_steps``): eligibility, packing
the master's objects into arrays, running chunks of steps, and leaving the objects as the Python loop would.

``run_master`` uses it when ``MasterSettings.compiled_loop`` is set, the kernels are on, the observer's probes
are compiled, the component is an ``InProcessEndpoint`` with the compiled law or an initialised FMI 2.0
``FmuEndpoint`` (called natively, ``fmu_native``) and the scheme is one of ``SCHEMES``; otherwise (an FMI 3.0
FMU, the law not compiled, the kernels off) the Python loop (the reference) runs.
"""
from __future__ import annotations

import atexit
import contextlib
import math
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numba import types

from fmu_bearing.ball_bearing import BearingInputError
from mechanism.cosim import compiled_loop as cl
from mechanism.cosim import component_call as cc
from mechanism.cosim import component_kernel as ck
from mechanism.cosim import fmu_native
from mechanism.cosim import law_model_kernel as lmk
from mechanism.cosim.coupling import Exchanged
from mechanism.cosim.coupling.base import FORCE_MODEL_FIELDS
from mechanism.cosim.endpoints import ExchangeError
from mechanism.cosim.energy import ENERGY_COLUMNS
from mechanism.cosim.law_kernel import pack_bearing

#: the schemes the compiled loop implements (their force models: ``compiled_loop.drift_model``, ``trial_model``,
#: ``hold_model``; ``law-model``'s: ``law_model_kernel``, ``jacobian-implicit``'s without a law)
SCHEMES = ("jacobian", "jacobian-drift", "jacobian-secant", "jacobian-implicit", "zoh", "extrap1", "extrap2",
           "zoh-jacobi", "law-model")


#: what the compiled loop calls of the FMU's (a handle without one of them: the Python loop runs)
_FMU_CALLS = (fmu_native.SET_REAL, fmu_native.DO_STEP, fmu_native.GET_REAL, fmu_native.GET_INTEGER,
              fmu_native.GET_BOOLEAN, fmu_native.GET_STATE, fmu_native.SET_STATE, fmu_native.FREE_STATE)


def component_kind(endpoint) -> int | None:
    """``component_call``'s kind for ``endpoint``, or None if the compiled loop cannot call it: an
    ``InProcessEndpoint`` with the compiled law, or an initialised FMI 2.0 ``FmuEndpoint`` whose binary has
    every call the loop makes and at most 8 coupling outputs."""
    from mechanism.cosim.endpoints import FmuEndpoint, InProcessEndpoint
    if type(endpoint) is InProcessEndpoint:
        return cc.IN_PROCESS if getattr(endpoint, "_law", None) is not None else None
    if type(endpoint) is FmuEndpoint and endpoint._instantiated and len(endpoint.coupling_names) <= cc.N_COUPLING:
        functions = endpoint.fmu._functions
        if all(functions.get(fmu_native.FUNCTIONS[slot - 1]) is not None for slot in _FMU_CALLS):
            return cc.FMU
    return None


#: the step of the last ``CompiledLoop`` made: (through an FMU, law-model's), i.e. ``run_steps``' arguments ``P``
#: and ``LM`` None or not (its compiled specialisation); None before the first
_variant: tuple[bool, bool] | None = None


def _is_variant(sig, want: tuple[bool, bool] | None) -> bool:
    """True if the argument types ``sig`` of ``run_steps`` are the step ``want`` (None: any)."""
    if want is None:
        return True
    names = list(cl.run_steps.py_func.__code__.co_varnames)
    none = tuple(isinstance(sig[names.index(name)], types.NoneType) for name in ("P", "LM"))
    return none == (want[0], not want[1])


def cached() -> bool:
    """True if ``compiled_loop.run_steps`` for the step of the last ``CompiledLoop`` made (any step before one is
    made) is compiled in this process or in numba's disk cache for the current source (numba's index of the
    function, valid for this file's timestamp); False if the first chunk will compile it (the first run after
    installing or changing the kernels, or the first of another component or scheme: seconds)."""
    overloads = getattr(cl.run_steps, "overloads", None)
    if overloads is None:   # (a plain function under NUMBA_DISABLE_JIT: nothing to compile)
        return True
    want = _variant
    if any(_is_variant(sig, want) for sig in overloads):
        return True
    try:   # numba's cache index (private API): {} when missing or stale; keys (argument types, target, source)
        return any(_is_variant(key[0], want) for key in cl.run_steps._cache._cache_file._load_index())
    except Exception:   # noqa: BLE001  (another numba: assume cached, the bar shows its ETA as before)
        return True


def start_warmup(variant: tuple[bool, bool] | None = None) -> subprocess.Popen | None:
    """On a first run (``cached`` False): start ``mechanism.cosim.warmup`` in a second process, which compiles the
    loop's own functions and the kernels the run calls later into numba's cache (the same source files, the same
    ``NUMBA_CACHE_DIR``) while this process compiles the kernels it calls first; None when cached, with
    ``MECHANISM_COMPILE_WORKER=0`` or one CPU, or if the process cannot start (this one compiles all then). The
    stages it reports done (its output lines) are collected in ``process.done`` by a thread.

    ``variant``: the step the run will compile, (through an FMU, law-model's), as ``CompiledLoop`` will find it
    (``run_master`` knows it from the endpoint and the scheme before the loop starts): ``cached`` looks for that
    ``run_steps``, and the process compiles only the stages that step needs (``warmup.needed``), not the other
    component's exchange nor law-model's for another scheme (about 1.5 s of a first run's critical path), and
    not those the run's process compiles itself (``warmup.RUN_SHARE``, in ``finish_warmup``: ``process.share``).
    None: every stage, for whichever step comes."""
    wanted = os.environ.get("MECHANISM_COMPILE_WORKER", "1").strip()
    if wanted not in ("0", "1"):
        raise ValueError(f"MECHANISM_COMPILE_WORKER={wanted!r} must be 0 (no second process) or 1")
    if variant is not None:
        global _variant
        _variant = variant
    if wanted == "0" or (os.cpu_count() or 1) < 2 or cached():
        return None
    python = python_executable()
    if python is None:
        return None
    from mechanism.cosim import warmup
    wanted = warmup.needed(*variant) if variant is not None else []
    stages = [name for name in wanted if name not in warmup.RUN_SHARE]
    stages += warmup.later(*variant) if variant is not None else []
    root = str(Path(__file__).resolve().parents[2])     # the folder holding the mechanism package imported here
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p))
    try:    # its own session: a Ctrl-C at the terminal reaches the run, which ends the process itself
        process = subprocess.Popen([python, "-m", "mechanism.cosim.warmup", *stages], cwd=root, env=env,
                                   stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                   text=True, start_new_session=True)
    except (OSError, TypeError, ValueError):
        return None
    process = collect_stages(process)
    if process is not None:
        process.share = [name for name in wanted if name in warmup.RUN_SHARE]
    return process


def python_executable() -> str | None:
    """The Python interpreter for the warm-up process: ``sys.executable`` when it is one, else the interpreter
    of ``sys.exec_prefix`` (in a host that embeds Python, ``sys.executable`` may be None or the host's own
    program, which started with ``-m mechanism.cosim.warmup`` would never compile anything); None if neither is."""
    version = f"{sys.version_info[0]}.{sys.version_info[1]}"
    prefix = Path(sys.exec_prefix)
    for candidate in (sys.executable, prefix / "bin" / f"python{version}", prefix / "bin" / "python3",
                      prefix / "python.exe"):
        if not candidate or not isinstance(candidate, (str, Path)):
            continue
        path = Path(candidate)
        if path.name.lower().startswith("python") and path.is_file() and os.access(path, os.X_OK):
            return str(path)
    return None


def collect_stages(process: subprocess.Popen) -> subprocess.Popen:
    """Collect the stage names ``process`` prints (one a line, text mode) into ``process.done``, by a thread."""
    process.done = set()

    def collect() -> None:
        for line in process.stdout:
            process.done.add(line.strip())

    process.reader = threading.Thread(target=collect, daemon=True)
    process.reader.start()
    return process


#: a first run's warm-up process left compiling the stages its run calls later (``warmup.later``), or None
_later: subprocess.Popen | None = None


def finish_warmup(process: subprocess.Popen | None, timeout: float = 300.0,
                  poll: Callable[[], None] | None = None) -> None:
    """Wait for ``start_warmup``'s process (at most ``timeout`` s; 0: not at all) until it has compiled the stages
    the step of the last ``CompiledLoop`` needs (``warmup.needed``; all of them before one is made), calling
    ``poll`` (e.g. the run's signal check, which may raise) every 0.1 s. Then the process is ended, unless it
    has the stages the run calls later still to compile (``warmup.later``: a law-model run's ideal counterpart's
    ``kernels.advance``, while this process compiles ``run_steps``): it is kept in ``_later`` then, for
    ``await_later`` (and ended at exit at the latest). The other stages it may still be compiling are needed by other
    components or schemes only.

    Before waiting, this process compiles the stages left to it (``process.share``, ``warmup.RUN_SHARE``): the
    two processes then end their parts at about the same time."""
    global _later
    if process is None or process is _later:     # (kept already: run_master's end calls this again)
        return
    from mechanism.cosim import warmup
    names = warmup.needed(*_variant) if _variant is not None else [name for name, _ in warmup.STAGES]
    later = warmup.later(*_variant) if _variant is not None else []
    deadline = time.monotonic() + timeout
    keep = False
    try:
        share = [name for name in getattr(process, "share", ()) if name in names]
        if timeout > 0 and share:
            warmup.compile_stages(share, getattr(process, "done", set()).add)
            if poll is not None:
                poll()
        while not set(names) <= getattr(process, "done", set()):
            try:
                process.wait(min(0.1, max(0.0, deadline - time.monotonic())))
                return
            except subprocess.TimeoutExpired:
                if time.monotonic() >= deadline:
                    return
                if poll is not None:
                    poll()
        keep = not set(later) <= getattr(process, "done", set())
    finally:
        if keep and process.poll() is None:
            end_warmup(_later)
            _later, process.later = process, later
            atexit.unregister(end_warmup)       # one at a time is kept: one exit handler, for it
            atexit.register(end_warmup, process)
        else:
            end_warmup(process)


def await_later(timeout: float = 120.0, poll: Callable[[], None] | None = None) -> None:
    """Before a run that may call what a first run's warm-up process is still compiling (``_later``: the stages of
    ``warmup.later``): wait until they are in the cache or the process has ended (at most ``timeout`` s), calling
    ``poll`` (the run's signal check, which may raise) every 0.1 s, then end it. Without such a process nothing
    happens; after the timeout the run compiles what it calls itself."""
    global _later
    process, _later = _later, None
    if process is None:
        return
    deadline = time.monotonic() + timeout
    try:
        while not set(process.later) <= getattr(process, "done", set()) and time.monotonic() < deadline:
            try:
                process.wait(min(0.1, max(0.0, deadline - time.monotonic())))
                return
            except subprocess.TimeoutExpired:
                if poll is not None:
                    poll()
    finally:
        end_warmup(process)


def drop_warmup(process: subprocess.Popen | None) -> None:
    """End ``start_warmup``'s process whether or not it was kept (``_later``): for a run that failed or was
    interrupted, after which no run waits for its later stages."""
    global _later
    if process is not None and process is _later:
        _later = None
    end_warmup(process)


def end_warmup(process: subprocess.Popen | None) -> None:
    """End a warm-up process (killed if it still runs) and its output reader."""
    if process is None:
        return
    if process.poll() is None:
        process.kill()
        process.wait()
    reader = getattr(process, "reader", None)
    if reader is not None:      # at the end of the process's output now
        reader.join(1.0)
    if process.stdout is not None and (reader is None or not reader.is_alive()):
        process.stdout.close()


#: the run_steps variants (P None, LM None) this process has called (compiled or loaded from the cache)
_called: set = set()


@contextlib.contextmanager
def _first_call_lock(variant: tuple[bool, bool]):
    """Hold an exclusive lock on numba's cache folder around this process's first call of a ``run_steps`` variant.

    ``run_steps`` has up to four compiled variants (FMU or in-process law, law-model or not). numba saves a new
    one by reading the function's cache index, taking the first free data-file number and writing the index, then
    the data, without a lock: two processes compiling different variants at once (two first runs after an install,
    parallel test workers) could take the same number and later load each other's machine code. Serialising the
    first call per process closes that; later calls take no lock. No lock where ``fcntl`` is missing (Windows)."""
    if variant in _called:
        yield
        return
    try:
        import fcntl
    except ImportError:     # pragma: no cover - Windows
        fcntl = None
    fd = None
    if fcntl is not None:
        try:
            import numba  # its cache folder: mechanism.kernel_cache's, set when mechanism was imported
            folder = Path(numba.config.CACHE_DIR or os.environ["NUMBA_CACHE_DIR"])
            folder.mkdir(parents=True, exist_ok=True)
            fd = os.open(folder / "run_steps.lock", os.O_RDWR | os.O_CREAT, 0o644)
            fcntl.flock(fd, fcntl.LOCK_EX)
        except (OSError, KeyError):     # no folder, or a read-only one: numba does not write there either
            if fd is not None:
                os.close(fd)
            fd = None
    try:
        yield
        _called.add(variant)
    finally:
        if fd is not None:
            os.close(fd)     # releases the lock


def eligible(loop) -> bool:
    """True if ``loop`` (a started ``CouplingLoop``) can run compiled (see the module docstring)."""
    scheme = loop.scheme
    return bool(getattr(loop.settings, "compiled_loop", False) and loop.kernels and loop._observe_in_kernel
                and loop.link is not None and component_kind(loop.endpoint) is not None
                and scheme is not None and scheme.name in SCHEMES
                and (getattr(scheme, "law", None) is None or scheme.law is loop.contact_law)   # law-model's is PC
                and (loop.energy is None or loop.integrals is not None)
                and loop.settings.substep_limit > 0)   # else the Python loop reports the setting's error at its step


class CompiledLoop:
    """The arrays of one run for ``compiled_loop.run_steps``, made after ``CouplingLoop.start`` and the first
    ``record``; ``run`` advances a chunk of steps, ``sync`` writes the state back into the Python objects."""

    def __init__(self, loop, rec, y: np.ndarray, every: int, last_step: int = 0):
        """``last_step``: the run's last step, recorded also when it is off the output stride (``every``)."""
        self.loop, self.rec, self.every = loop, rec, every
        settings, scheme, endpoint, link = loop.settings, loop.scheme, loop.endpoint, loop.link
        self.h = settings.step
        self.secant = scheme.ring_speeds == "secant"
        index = rec.index
        self.energy = loop.energy if loop.integrals is not None else None
        ecols = ([index[c] for c in ENERGY_COLUMNS] if self.energy is not None
                 else [-1] * len(ENERGY_COLUMNS))
        scols = loop._sample_cols
        scols = list(range(scols.start, scols.stop)) if isinstance(scols, slice) else [int(c) for c in scols]
        self.cols = np.array([index["omega_inner"], index["omega_outer"], index["kinetic_energy"], *ecols, *scols],
                             np.int64)
        self.kind = component_kind(endpoint)
        if self.kind == cc.IN_PROCESS:
            self.P, self.cs = endpoint._law, ck.pack_state(endpoint)
            self.H = np.zeros(fmu_native.SLOTS, np.int64)
            none = np.zeros(0, np.uint32)
            self.refs = fmu_native.References(none, none, none, none, none)
        else:   # P None: the step compiled without the in-process law (``compiled_loop.run_steps``)
            self.P, self.cs = None, np.zeros(0)
            self.H, self.refs = fmu_native.endpoint_handle(endpoint), fmu_native.endpoint_references(endpoint)
        law = loop.contact_law
        self.PC = pack_bearing(law) if law is not None else np.zeros(0)
        fset = np.zeros(cl.N_FSET)
        fset[0:5] = (loop.mobility, settings.substep_limit, settings.max_constraint_violation,
                     settings.iteration_tol, loop._cv)
        if law is not None:
            fset[5:8] = (law.params.cage_angle_start, *loop._angles0)
        if self.energy is not None:
            acct = self.energy
            acct.stage_integrals(np.zeros((5, 8)), 0, 0.0)       # sets up its stage kernel (P, cage offset)
            _, self.PE, offset = acct._stage_kernel
            fset[8:13] = (acct._start, offset, acct.bearing.params.cage_angle_start, *acct._angles0)
        else:
            self.PE = np.zeros(0)
        fset[13] = endpoint.bearing.eccentricity_limit if self.kind == cc.IN_PROCESS else math.inf
        # law-model with its law (bound at ``CouplingLoop.start``: the contact law, ``PC``); without, jacobian-implicit
        self.law_model = bool(getattr(scheme, "uses_law", False) and getattr(scheme, "law", None) is not None)
        if self.law_model:
            fset[14] = scheme.resolution
            fset[15] = scheme.min_substeps
        # law-model's state (zeroed by each chunk), or None: the step compiled without law-model's
        self.LM = np.zeros(lmk.LM_SIZE) if self.law_model else None
        # the other schemes' force model (zeroed by each chunk), or None: the step compiled without them
        self.FM = None if self.law_model else np.zeros(len(FORCE_MODEL_FIELDS))
        global _variant
        _variant = (self.P is None, self.law_model)
        self.fset = fset
        iset = np.zeros(cl.N_ISET, np.int64)
        iset[0:10] = (settings.max_substeps, max(2, settings.max_iterations), settings.iterate_where_needed,
                      scheme.iterative, self.secant, self.energy is not None, link._theta_j, link._theta_i,
                      law is not None, loop.system.m > 0)
        iset[10] = loop._end[0] is y and loop._end[1] == 0.0
        iset[11] = self.kind
        iset[12] = scheme.history == 2
        iset[14] = cl.MODELS.get(scheme.name.replace("-jacobi", ""), 0)
        iset[15] = scheme.ordering == "jacobi"
        iset[16] = scheme.history
        iset[17] = last_step
        iset[18] = self.law_model
        iset[19] = self.law_model and scheme.onset_correction
        self.past = np.zeros((3, 13))
        for k, x in enumerate(scheme.past):
            self.past[k] = (x.t, x.e_x, x.e_y, x.v_x, x.v_y, x.F_x, x.F_y, x.k_xx, x.k_xy, x.k_yy, x.c_xx,
                            x.c_xy, x.c_yy)
        iset[13] = len(scheme.past)
        self.iset = iset
        self.xin = np.array(loop.inputs, np.float64)
        self.xf = np.array(loop.force, np.float64)
        it = loop.iterations
        self.counts = np.array([loop.substeps_max, loop.substeps_total, it["steps"], it["passes"], it["max_passes"],
                                it["not_converged"], it["predicted"], endpoint.calls, rec.rows, 0, 0], np.int64)
        self.integrals = loop.integrals if loop.integrals is not None else np.zeros(5)
        self.acc = loop._acc if self.energy is not None else np.zeros(3)
        self.p1 = loop._p1 if self.energy is not None else np.zeros(3)
        self.stages = loop._stages if self.energy is not None else np.zeros((5 * max(1, settings.max_substeps), 8))
        self.sent = np.zeros(6)
        self.fail = np.zeros(9)
        self.steps_done = 0
        self.t = 0.0
        self.failure: tuple[int, float, str] | None = None

    def run(self, first: int, last: int, y: np.ndarray) -> np.ndarray:
        """Steps ``first`` .. ``last`` from y; returns the state reached. After a failure ``failure`` is
        (step, time, cause) as the Python loop words them (``master.RunFailure``'s arguments), the objects synced
        and the samples kept."""
        loop, rec = self.loop, self.rec
        every = max(1, self.every)    # rows this chunk may write: its multiples of every, and the run's end
        rec.reserve(last // every - (first - 1) // every + 1)   # (a streaming Recorder hands its rows on)
        self.counts[8] = rec.rows
        with _first_call_lock((self.P is None, self.LM is None)):
            y = cl.run_steps(y, first, last, self.h, self.every, loop._I, loop._R, loop._L, loop._LR, loop._W,
                             loop._u, loop._dy, loop._lam, self.p1, self.acc, self.stages, loop._probes,
                             loop._probe_scale, loop._react, rec.data, self.cols, self.P, self.cs, self.H,
                             self.refs.inputs, self.refs.coupling, self.refs.real_samples, self.refs.int_samples,
                             self.refs.bool_samples, self.PC, self.PE, self.past, self.xin, self.xf, self.integrals,
                             self.counts, self.fset, self.iset, self.sent, self.fail, self.LM, self.FM)
        code = int(self.fail[0])
        if code == cl.OK:
            self.steps_done, self.t = last, last * self.h
            self.sync(y)
            return y
        step = int(self.fail[1])
        t = step * self.h
        self.steps_done, self.t = step - 1, (step - 1) * self.h
        self.sync(y)
        self.failure = (step, t, self._cause(code))
        return y

    def _cause(self, code: int) -> str:
        """The failure's cause as the Python loop words it."""
        f = self.fail
        if code == cl.NOT_FINITE:
            return "the mechanism state is not finite (the integration diverged)"
        if code == cl.CONSTRAINT:
            return (f"constraint violation {float(f[3]):.3g} exceeds "
                    f"{self.loop.settings.max_constraint_violation:g} (the integration diverged)")
        if code == cl.FORCE:
            return f"the bearing returned a non-finite force {(float(f[3]), float(f[4]))}"
        if code == cl.COMPONENT:     # the FMU's refusal, as FmuEndpoint words it (with its logged messages)
            what = {cl.DO_STEP: f"doStep at t = {(int(f[1]) - 1) * self.h:.9g} s", cl.GET_STATE: "getFMUState",
                    cl.SET_STATE: "setFMUState", cl.FREE_STATE: "freeFMUState",
                    cl.SAMPLE: "sampling the outputs"}[int(f[4])]
            try:
                fmu_native.check(int(f[3]), what, self.loop.endpoint)
            except ExchangeError as err:
                return f"ExchangeError: {err}"
            return f"ExchangeError: {what} failed"
        sent = [float(v) for v in f[3:9]]
        try:
            self.loop.endpoint.bearing.check_inputs(*sent)
        except BearingInputError as err:
            return f"ExchangeError: {err}"
        return f"ExchangeError: inputs {tuple(sent)} rejected"

    def sync(self, y: np.ndarray) -> None:
        """Leave the loop, the scheme, the component and the energy account as the Python loop would have."""
        loop, endpoint, c = self.loop, self.loop.endpoint, self.counts
        self.rec.rows = int(c[8])
        loop.substeps_max, loop.substeps_total = int(c[0]), int(c[1])
        loop.iterations.update(steps=int(c[2]), passes=int(c[3]), max_passes=int(c[4]), not_converged=int(c[5]),
                               predicted=int(c[6]))
        endpoint.calls = int(c[7])
        self.states = (int(c[9]), int(c[10]))
        if self.kind == cc.IN_PROCESS:
            ck.unpack_state(endpoint, self.cs)
        else:
            endpoint._sampled = False       # its buffered real samples are not the FMU's outputs now
        loop.inputs = tuple(self.xin.tolist())
        loop.force = tuple(self.xf.tolist())
        loop._cv = float(self.fset[4])
        past = loop.scheme.past
        past.clear()
        past.extend(Exchanged(*row) for row in self.past[:int(self.iset[13])].tolist())
        if self.secant and self.steps_done > 0:
            loop.sent_ring_speeds = (float(self.sent[4]), float(self.sent[5]))
        loop._end = (y, self.t) if self.iset[10] else (None, None)
        if self.energy is not None:
            self.energy._sums[:] = self.integrals[:4].tolist()
