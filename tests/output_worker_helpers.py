"""Helpers for the output workers' tests (tests/test_output_workers.py, tests/test_memory.py)."""
from __future__ import annotations


def kill_worker(w, k: int) -> None:
    """SIGKILL output worker ``k`` of ``w`` and wait until it is gone (the second is the first's child: its process
    is gone when it is a zombie or reaped)."""
    import os
    import signal
    import time
    pid = w.pid(k)
    os.kill(pid, signal.SIGKILL)
    if k == 0:
        w._procs[0].join(5)
        return
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:
        try:
            with open(f"/proc/{pid}/stat") as f:
                if f.read().rsplit(")", 1)[1].split()[0] in ("Z", "X"):
                    return
        except OSError:
            return
        time.sleep(0.01)
