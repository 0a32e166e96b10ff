"""Background processes that take the headline command's fixed output costs off its critical path (issue 11).

``python -m mechanism run`` spent, after its two runs, about 0.5-0.7 s importing matplotlib, 1.5-2 s drawing
seven PNGs and 0.4 s importing scipy.interpolate for one cubic-spline resampling (now ``mechanism.cosim.spline``),
while a run's master loop keeps one core busy and leaves the other idle (when the machine is). ``OutputWorkers`` forks a process (or
two) when the command starts: it imports those modules while the master runs, then draws the figures of the run
alone while the command writes the run's table and runs the ideal counterpart, and the others while the command
writes the ideal's table (``results.start_run_plots``, ``finish_outputs``; ``write_outputs``: two workers draw a
share each, ``SHARES``). A worker receives only the columns the figures read, as raw bytes (``ColumnsOf``: the
command makes no pickled copy of its tables, issue 11). The files are the same bytes as drawn in-process (the
same functions, ``plots.plot_run`` and ``record.resample``, run in another process) and are written atomically as before (``atomic.save_canvas``).

The first worker imports matplotlib and then forks the second (a "zygote": matplotlib imported once, ~0.7 s of
CPU less beside the run); each then builds the frames of the figures it will draw (``plots.prepare``: figure,
panels, labels, titles, a first drawing) from the run's ``figures.Plan`` while the run runs, between jobs, so that
only the data's part of each figure is left once the data are complete.

Robustness: the workers ignore SIGINT (the command decides what an interrupt does: ``run.stop_on_signals``)
and end when the command's end of their pipe closes (the command died) or at ``close``; the first ends the second
when it ends (or is terminated). An error in a job is raised in the command as if the job had run there; a worker
that cannot start, dies, or does not answer within ``ANSWER_TIMEOUT_S``, or a job that does not pickle, makes the
job run in-process instead. ``MECHANISM_OUTPUT_WORKERS`` (``count``) sets how many; 0 (or a single CPU, or no fork)
does everything in-process.
"""
from __future__ import annotations

import contextlib
import gc
import importlib
import multiprocessing
import os
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

#: the figures each of two workers draws: about equal drawing times (a 2-revolution run with its ideal
#: counterpart, best of 3: joint force 0.45 s, slider acceleration 0.22, energy 0.17, eccentricity 0.10 against
#: ball loads 0.45, slider position error 0.21, crank moment 0.20); one worker draws them all
SHARES = (("joint_force.png", "slider_acceleration.png", "energy.png", "eccentricity.png"),
          ("ball_loads.png", "slider_position_error.png", "crank_moment.png"))

#: modules the first worker imports while it waits for its first job, before it forks the second (the first also
#: resamples; the resampling no longer needs scipy.interpolate: ``mechanism.cosim.spline``, so ~20 MB less per worker)
IMPORTS = ("mechanism.output.plots", "mechanism.cosim.record", "mechanism.cosim.spline")

#: the second worker's niceness: it prepares its frames while the run runs with time to spare (its figures wait
#: for the ideal counterpart), so it gives way to the run and the first worker. Measured 2026-11-26 10:40 UTC (load
#: average 2.3-2.7 from other jobs, 5 interleaved pairs of ``benchmarks/cosim.py``'s headline): the run phase
#: 2.22-2.98 s against 2.54-2.83 s without, the outputs 0.46-0.68 s against 0.40-0.56 s, the whole command median
#: 3.53 s against 3.78 s
SECOND_NICE = 5

#: seconds the command waits for a worker's answer (a job's, or a block's receipt) before it gives the worker up
#: and runs the job itself: far beyond a job's time (a figure takes ~0.1-0.3 s, a block's receipt milliseconds)
ANSWER_TIMEOUT_S = 120.0


def shares(n: int) -> tuple[tuple[str, ...], ...]:
    """The figures each of ``n`` workers draws (``SHARES`` for two, all of them for one)."""
    if n <= 1:
        return (tuple(name for share in SHARES for name in share),)
    return SHARES


#: the frames this worker prepared (``plots.prepare``), taken by the figures it draws (empty in the command)
_FRAMES: dict = {}


def _plots(*args, **kwargs):
    from mechanism.output.plots import plot_run
    return plot_run(*args, frames=_FRAMES, **kwargs)


def _resample(*args):
    from mechanism.cosim.record import resample
    return resample(*args)


#: the blocks of a streamed run's columns received so far by ``gather`` (in a worker)
_GATHERED: list = []


def _gather(part) -> int:
    """Keep ``part`` (a RunResult of a streamed run's columns, ``stream.TableStream``) for ``plots_gathered``;
    the rows gathered so far."""
    _GATHERED.append(part.data)
    return sum(len(d) for d in _GATHERED)


def _plots_gathered(tail, out, ideal=None, coarse: bool = False, **kwargs):
    """``plots`` of the run whose rows were gathered, ``tail`` (a RunResult: the last rows, the run's meta) after them;
    ``coarse``: ``ideal`` is at its own sample times (resampled here, as ``_plots_resampled``)."""
    from mechanism.cosim.record import RunResult
    data = np.concatenate([*_GATHERED, tail.data]) if _GATHERED else tail.data
    _GATHERED.clear()
    run = RunResult(tail.columns, data, tail.meta, tail.status, tail.message)
    if coarse:
        return _plots_resampled(run, out, ideal, **kwargs)
    return _plots(run, out, ideal, **kwargs)


def _plots_resampled(run, out, coarse, **kwargs):
    """``plots`` with the ideal counterpart ``coarse`` (its own sample times) resampled here onto ``run``'s times:
    ``record.resample`` column by column, so the columns sent are the numbers the command's resampling made."""
    from mechanism.cosim.record import resample
    return _plots(run, out, None if coarse is None else resample(coarse, run["time"]), **kwargs)


JOBS = {"plots": _plots, "resample": _resample, "gather": _gather, "plots_gathered": _plots_gathered,
        "plots_resampled": _plots_resampled}


@dataclass(frozen=True)
class ColumnsOf:
    """The columns ``names`` of a ``RunResult`` as a job's argument: a worker receives them as a RunResult of
    those columns, sent one column at a time as raw bytes (``Connection.send_bytes``: no pickled copy of the
    table in the command, issue 11); a job run in-process gets ``result`` itself (or, a function, what it returns:
    the table read back, given to ``OutputWorkers.result`` once the command has let the table go)."""
    result: Any
    names: tuple[str, ...]


@dataclass(frozen=True)
class _Columns:
    """What is pickled of a ``ColumnsOf``; its columns follow the job on the pipe, in this order."""
    names: tuple[str, ...]
    rows: int
    meta: dict
    status: str
    message: str


def _local(job: str, args: tuple, kwargs: dict):
    """``job`` run in this process (each ``ColumnsOf`` replaced by its ``RunResult``)."""
    def own(value):
        if not isinstance(value, ColumnsOf):
            return value
        return value.result() if callable(value.result) else value.result
    return JOBS[job](*map(own, args), **{key: own(value) for key, value in kwargs.items()})


def _pack(args: tuple, kwargs: dict) -> tuple[tuple, dict, list[np.ndarray]]:
    """``args`` and ``kwargs`` with each ``ColumnsOf`` replaced by its ``_Columns`` header, and the columns to send."""
    columns = []

    def header(value):
        if not isinstance(value, ColumnsOf):
            return value
        r = value.result
        columns.extend(r[name] for name in value.names)
        return _Columns(tuple(value.names), len(r.data), r.meta, r.status, r.message)
    return tuple(map(header, args)), {key: header(value) for key, value in kwargs.items()}, columns


def _unpack(conn, args: tuple, kwargs: dict) -> tuple[tuple, dict]:
    """The worker's side of ``_pack``: each ``_Columns`` header made a ``RunResult`` of the columns received."""
    def result(value):
        return _receive(conn, value) if isinstance(value, _Columns) else value
    return tuple(map(result, args)), {key: result(value) for key, value in kwargs.items()}


def _receive(conn, header: _Columns):
    """The ``RunResult`` of the columns that follow ``header`` on ``conn`` (a column-major table: each column is
    received straight into its place)."""
    from mechanism.cosim.record import RunResult
    data = np.empty((header.rows, len(header.names)), order="F")
    for k in range(len(header.names)):
        size = conn.recv_bytes_into(data[:, k])
        if size != header.rows * data.itemsize:
            raise ValueError(f"column {header.names[k]!r}: {size} bytes received, {header.rows * data.itemsize} expected")
    return RunResult(list(header.names), data, header.meta, header.status, header.message)


def _send_answer(conn, answer: tuple) -> None:
    """``answer`` (``("ok", value)`` or ``("error", exception)``) on ``conn``; a RunResult value as a ``_Columns``
    header and its columns as raw bytes (no pickled copy of its table on either side)."""
    from mechanism.cosim.record import RunResult
    status, value = answer
    if not isinstance(value, RunResult):
        conn.send(answer)
        return
    args, _, columns = _pack((ColumnsOf(value, tuple(value.columns)),), {})
    conn.send((status, args[0]))
    for column in columns:
        conn.send_bytes(np.ascontiguousarray(column))


def _forked(conns: list, ours: list, modules, plan=None, names: tuple = ()) -> None:
    """The first worker process (forked by ``OutputWorkers``): SIGINT ignored, SIGTERM ends it and the second; the
    command's ends of the pipes closed here, so that the command's death is an end of file. It imports ``modules``,
    forks a worker for each further pipe of ``conns`` (the second: matplotlib imported already), then serves
    ``conns[0]``; ``names[k]``: the figures whose frames worker k prepares from ``plan``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    children: list[int] = []

    def end(signum=None, frame=None) -> None:
        """End the workers forked here (the second may be hung: it is not waited for otherwise), reap them."""
        for pid in children:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGTERM)
        for pid in children:
            with contextlib.suppress(OSError):
                os.waitpid(pid, 0)
        children.clear()
        if signum is not None:
            os._exit(0)

    signal.signal(signal.SIGTERM, end)
    for conn in ours:
        conn.close()
    _import(modules)
    for k in range(1, len(conns)):
        for stream in (sys.stdout, sys.stderr):   # nothing buffered twice
            with contextlib.suppress(Exception):
                stream.flush()
        try:
            pid = os.fork()
        except OSError:   # no second worker: the command finds its pipe closed and draws its share itself
            pid = -1
        if pid == 0:   # the second worker: its own pipe only, ended by SIGTERM (the first's), no clean-up of the first's
            try:
                signal.signal(signal.SIGTERM, signal.SIG_DFL)
                with contextlib.suppress(Exception):   # Linux: ended with the first even if that one is killed
                    import ctypes
                    ctypes.CDLL(None).prctl(1, signal.SIGTERM)    # PR_SET_PDEATHSIG
                if os.getppid() == 1:                  # the first ended before that: no orphan
                    os._exit(0)
                with contextlib.suppress(OSError):
                    os.nice(SECOND_NICE)
                children.clear()
                for j, conn in enumerate(conns):
                    if j != k:
                        conn.close()
                serve(conns[k], (), plan, names[k] if k < len(names) else ())
            finally:
                os._exit(0)
        if pid > 0:
            children.append(pid)
        conns[k].close()
    try:
        serve(conns[0], (), plan, names[0] if names else ())
    finally:
        end()


def _import(modules) -> None:
    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError:   # the job will raise it where it is needed
            pass


def _prepare(conn, plan, names) -> list[str]:
    """The frames of ``names`` (``plots.prepare``) into ``_FRAMES``, one at a time while no job waits on ``conn``;
    the names left."""
    pending = list(names)
    while pending and not conn.poll():
        name = pending.pop(0)
        with contextlib.suppress(Exception):   # (then the figure is drawn without a prepared frame: the same bytes)
            from mechanism.output.plots import prepare
            _FRAMES.update(prepare(plan, (name,)))
    return pending


def serve(conn, modules, plan=None, names: tuple = ()) -> None:
    """A worker: import ``modules``, then answer each ``(job, args, kwargs)`` received on ``conn`` with
    ``("ok", value)`` or ``("error", exception)`` until ``None`` or the end of the connection; between jobs,
    prepare the frames of the figures ``names`` of ``plan`` (a ``figures.Plan``)."""
    _import(modules)
    try:
        conn.send(("pid", os.getpid()))   # (the command learns the process id of a worker it did not fork)
    except (OSError, ValueError):
        return
    pending = tuple(names) if plan is not None else ()
    while True:
        try:
            pending = _prepare(conn, plan, pending) if pending else ()
            job = conn.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        name, args, kwargs = job
        try:
            args, kwargs = _unpack(conn, args, kwargs)
        except Exception:   # noqa: BLE001 - the pipe is out of step: the worker ends, the command draws in-process
            return
        try:
            answer = ("ok", JOBS[name](*args, **kwargs))
        except Exception as err:   # noqa: BLE001 - raised again in the command
            answer = ("error", err)
        if name.startswith("plots"):   # (its figures are drawn: their frames are not prepared any more)
            drawn = kwargs.get("names")
            pending = () if drawn is None else tuple(n for n in pending if n not in drawn)
        try:
            _send_answer(conn, answer)
        except (OSError, ValueError):   # the command has gone
            return
        except Exception as err:   # noqa: BLE001 - an exception that does not pickle
            conn.send(("error", RuntimeError(f"{type(err).__name__} in output worker: {err}")))


def count() -> int:
    """How many workers a plotting run starts: ``MECHANISM_OUTPUT_WORKERS`` (default 2, at most 2; 0 draws
    in-process), none on a single-CPU machine (nothing would run beside the master) or in a process with
    other threads (a fork copies only the calling one). One worker moves the
    imports and the CSV writing off the command's path at about the same CPU (the fork inherits numpy;
    docs/kernels.md); two also share the drawing (the second forked from the first once it has imported matplotlib: one import since 2026-11-26; before, each imported it). Measured with two imports at 05:10-05:14
    UTC (2 cores, load average 2-6 from other jobs; 11 interleaved pairs of the 2-revolution headline command,
    ``cli.PHASES``): two workers' outputs phase was shorter in 11 of 11 pairs (median ~0.6 s: 1.9 -> 1.3 s), their
    run phase longer by ~0.2-0.4 s (the second import), the whole command shorter in 8 of 11 (median 0.33 s). At
    05:18-05:19 UTC on the quiet machine: 2.86-3.69 s against 3.07-4.47 s wall (4 pairs, two faster in each) and
    2.99-3.23 s against 2.72-3.53 s (``cli.PHASES``, 3 pairs): so two are the default since 2026-11-26. The
    command's peak memory is the same (the workers are separate processes; each peaks at ~110 MB)."""
    text = os.environ.get("MECHANISM_OUTPUT_WORKERS", "2").strip()
    try:
        n = int(text)
    except ValueError:
        raise ValueError(f"MECHANISM_OUTPUT_WORKERS={text!r} must be 0, 1 or 2") from None
    if not 0 <= n <= 2:
        raise ValueError(f"MECHANISM_OUTPUT_WORKERS={text!r} must be 0, 1 or 2")
    # a fork copies one thread: a process with others (a host application) draws in-process instead
    forks = "fork" in multiprocessing.get_all_start_methods() and threading.active_count() == 1
    return n if (os.cpu_count() or 1) >= 2 and forks else 0


class OutputWorkers:
    """Worker processes that run ``JOBS``; ``submit`` hands one a job, ``result`` waits for its answer. Use as a
    context manager.

    The first worker is forked (``multiprocessing``'s fork context: no helper process such as a resource tracker)
    when the command starts, before the run loads its FMU or compiled kernels (one thread, numba not imported:
    checked when this was written); it inherits the modules imported so far (numpy), imports only matplotlib (and
    the numpy-only spline) and forks the second (``_forked``). ``plan`` (a ``figures.Plan``) and ``names`` (the
    figures each worker will draw) let them prepare those figures' frames meanwhile. Jobs and answers are pickled
    over a pipe, but for the columns of ``ColumnsOf`` arguments and of a RunResult answer (raw bytes)."""

    def __init__(self, n: int = 1, plan=None, names: tuple[tuple[str, ...], ...] = ()):
        self._procs, self._conns, self._busy = [], [], []
        self._pids: list[int | None] = [None] * n
        ctx = multiprocessing.get_context("fork")
        for stream in (sys.stdout, sys.stderr):   # nothing buffered twice
            with contextlib.suppress(Exception):
                stream.flush()
        pipes = []
        try:
            for _ in range(n):
                pipes.append(ctx.Pipe())
            ours, theirs = [p[0] for p in pipes], [p[1] for p in pipes]
            proc = ctx.Process(target=_forked, args=(theirs, ours, IMPORTS, plan, tuple(names)), daemon=True,
                               name="mechanism-output")
            proc.start()
        except (OSError, ValueError):   # cannot start them: their jobs run here
            for pipe in pipes:
                for conn in pipe:
                    conn.close()
            pipes, proc = [], None
        for conn in (p[1] for p in pipes):
            conn.close()
        for k in range(n):
            self._procs.append(proc if k == 0 else None)   # (the second is the first's child, ended by it)
            self._conns.append(pipes[k][0] if pipes else None)
            self._busy.append(False)

    def __len__(self) -> int:
        return len(self._procs)

    def submit(self, k: int, job: str, *args, **kwargs) -> bool:
        """Hand worker ``k`` a job; False if it is not there (then run the job in-process)."""
        conn = self._conns[k] if k < len(self._conns) else None
        if conn is None or self._busy[k]:
            return False
        args, kwargs, columns = _pack(args, kwargs)
        try:
            conn.send((job, args, kwargs))
        except (OSError, ValueError):   # it died (a broken pipe)
            self._lost(k)
            return False
        except Exception:   # noqa: BLE001 - the job does not pickle (nothing was sent): it runs in-process
            return False
        try:
            for column in columns:   # a column at a time (a strided one copied alone), written without a copy
                conn.send_bytes(np.ascontiguousarray(column))
        except (OSError, ValueError):   # it died: the job runs in-process
            self._lost(k)
            return False
        self._busy[k] = True
        return True

    def result(self, k: int, job: str, *args, **kwargs):
        """The answer to worker ``k``'s job (its exception raised here); if the worker died meanwhile (or gave no
        answer within ``ANSWER_TIMEOUT_S``), the job (given again as ``job, args, kwargs``) runs in-process."""
        try:
            status, value = self._answer(k)
            if isinstance(value, _Columns):
                value = _receive(self._conns[k], value)
        except (EOFError, OSError, TimeoutError):
            self._lost(k)
            return _local(job, args, kwargs)
        finally:
            self._busy[k] = False
        if status == "error":
            raise value
        return value

    def _answer(self, k: int, what: str = "answer"):
        """The next message from worker ``k`` (its process id, sent first, noted on the way); TimeoutError if none
        comes within ``ANSWER_TIMEOUT_S``."""
        conn = self._conns[k]
        deadline = time.monotonic() + ANSWER_TIMEOUT_S
        while True:
            if not conn.poll(max(0.0, deadline - time.monotonic())):
                raise TimeoutError(f"output worker {k} gave no {what} within {ANSWER_TIMEOUT_S:g} s")
            message = conn.recv()
            if self._pids[k] is None and isinstance(message, tuple) and message[:1] == ("pid",):
                self._pids[k] = message[1]
                if what == "process id":
                    return message
                continue
            return message

    def pid(self, k: int) -> int | None:
        """Worker ``k``'s process id (waiting for it to start); None if it is not there."""
        if self._pids[k] is None and self._conns[k] is not None and not self._busy[k]:
            with contextlib.suppress(EOFError, OSError, TimeoutError):
                self._answer(k, "process id")
        return self._pids[k]

    def gather(self, k: int, part: ColumnsOf) -> bool:
        """Hand worker ``k`` a block of a streamed run's columns to keep (``_gather``), waiting for its receipt;
        False if it is not there or failed (nothing runs in-process: the caller reads the rows back instead)."""
        if not self.submit(k, "gather", part):
            return False
        try:
            status, _ = self._answer(k)
        except (EOFError, OSError, TimeoutError):
            self._lost(k)
            return False
        finally:
            self._busy[k] = False
        return status == "ok"

    def call(self, k: int, job: str, *args, **kwargs):
        """``job(*args, **kwargs)`` in worker ``k`` (in-process if it is not there)."""
        if not self.submit(k, job, *args, **kwargs):
            return _local(job, args, kwargs)
        return self.result(k, job, *args, **kwargs)

    def _lost(self, k: int) -> None:
        """Worker ``k`` given up: its pipe closed (a worker that reads or writes it again ends), the first worker
        ended (it ends the second too: that one's jobs then run in-process)."""
        conn, proc = self._conns[k], self._procs[k]
        self._conns[k] = self._procs[k] = None
        if conn is not None:
            conn.close()
        if proc is not None:
            proc.join(timeout=1.0)
            _end(proc)

    def close(self) -> None:
        """End every worker: one that answered its jobs is idle (or still importing) and writes nothing; one with a
        job in flight is waited for (its files are written whole). The first is terminated if it has not ended at
        once (it ends the second)."""
        for k, conn in enumerate(self._conns):    # every job in flight answered first: the first worker's end
            if conn is not None and self._busy[k]:  # ends the second, which must not be drawing then
                with contextlib.suppress(EOFError, OSError, TimeoutError):
                    self._answer(k)
                self._busy[k] = False
        for conn in self._conns:
            if conn is not None:
                with contextlib.suppress(OSError, ValueError):
                    conn.send(None)
        for k, (proc, conn) in enumerate(zip(self._procs, self._conns)):
            if proc is not None:
                proc.join(timeout=0.2)   # an idle first worker ends at once (after the second); one importing is ended
                _end(proc)
            if conn is not None:
                conn.close()
            self._procs[k] = self._conns[k] = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def _end(proc) -> None:
    """Terminate ``proc`` if it is alive (SIGTERM: the first worker ends the second too), kill it if that fails."""
    if proc.is_alive():
        proc.terminate()
        proc.join(timeout=5.0)
    if proc.is_alive():
        proc.kill()
        proc.join()


class ForkedSaves:
    """Figures written by forked child processes while this one builds the next (``reproduce``'s report).

    A child inherits the built figure by the fork (copy-on-write: nothing is pickled), draws and writes it
    (``save(fig, path)`` runs there), and ends with ``os._exit`` (no atexit handlers, no stdio buffers flushed
    twice). At most ``n`` children run at once; ``wait`` reaps them all and raises the first child's error as a
    RuntimeError with its traceback (its file is left as it was: the saves write atomically). ``n`` 0, no fork,
    or a process with other threads (a fork copies only the calling one) saves in-process."""

    def __init__(self, n: int, save: Callable[[Any, Path], None]):
        forks = hasattr(os, "fork") and threading.active_count() == 1
        self.n = n if forks else 0
        self._save = save
        self._children: list[tuple[int, int, Path]] = []    # (pid, read end of its error pipe, path)
        self._errors: list[str] = []

    def submit(self, fig, path: Path) -> None:
        """Write ``fig`` to ``path`` (``save``) in a child, or here when no child can run it."""
        if self.n <= 0:
            self._save(fig, path)
            return
        while len(self._children) >= self.n:
            self._reap(0)
        for stream in (sys.stdout, sys.stderr):   # nothing buffered twice
            with contextlib.suppress(Exception):
                stream.flush()
        r, w = os.pipe()
        pid = -1
        gc.freeze()   # the objects so far out of the collector's reach: a child's collections copy none of their pages
        try:
            pid = os.fork()
        except OSError:
            os.close(r)
            os.close(w)
            self._save(fig, path)
            return
        finally:
            if pid != 0:
                gc.unfreeze()
        if pid == 0:   # the child: save, report an error on the pipe, end without Python's clean-up
            code = 0
            try:
                os.close(r)
                self._save(fig, path)
            except BaseException:   # noqa: BLE001 - reported to the parent
                code = 1
                with contextlib.suppress(Exception):
                    os.write(w, traceback.format_exc().encode(errors="replace")[-60000:])
            finally:
                os._exit(code)
        os.close(w)
        self._children.append((pid, r, Path(path)))

    def _reap(self, k: int) -> None:
        """Wait for child ``k`` (its entry stays until it is reaped: an interrupt here leaves no zombie behind
        the next ``wait``)."""
        pid, r, path = self._children[k]
        chunks = []
        while chunk := os.read(r, 65536):
            chunks.append(chunk)
        _, status = os.waitpid(pid, 0)
        del self._children[k]
        os.close(r)
        message = b"".join(chunks).decode(errors="replace")
        if status != 0:
            self._errors.append(f"writing {path.name} failed (exit code {os.waitstatus_to_exitcode(status)}):\n"
                                + message)

    def wait(self) -> None:
        """Reap every child; a RuntimeError if any failed (after all have ended)."""
        while self._children:
            self._reap(0)
        errors, self._errors = self._errors, []
        if errors:
            raise RuntimeError("\n".join(errors))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        try:
            self.wait()
        except RuntimeError:
            if exc[0] is None:
                raise
        return False
