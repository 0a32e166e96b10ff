"""fmpy host callbacks whose logger can never dangle.

fmpy formats an FMU's variadic log message in a native proxy (``fmpy.logging.addLoggerProxy``) that
forwards to ONE global Python callback: the one most recently registered, in any struct. Once that
callback is garbage collected (an FMU object freed, a test finished), every later message through any
proxied struct, fmpy's ``defaultCallbacks`` included, calls freed memory and crashes the process.

So this module registers one dispatcher, kept for the life of the process, and gives each host its own
``fmi2CallbackFunctions`` whose ``componentEnvironment`` is a key into a table of Python loggers:
``fmpy_callbacks(log)`` returns the struct, ``release(callbacks)`` drops the logger when the host frees
its instance. Messages for any other environment (fmpy's ``defaultCallbacks``, whose proxy now also ends
here) go to fmpy's ``printLogMessage``, as fmpy's default would print them; a released key's are dropped.
"""
from __future__ import annotations

import ctypes
import itertools
import threading
from typing import Callable

#: log(environment, instance_name: bytes, status: int, category: bytes, message: bytes)
Logger = Callable[[object, bytes, int, bytes, bytes], None]

_lock = threading.Lock()
_loggers: dict[int, Logger] = {}
_keys = itertools.count(1)
_dispatcher = None     # the fmi2CallbackLoggerTYPE registered with fmpy's proxy, never released


_released: set[int] = set()


def _dispatch(environment, instance, status, category, message):
    key = int(environment or 0)
    log = _loggers.get(key)
    try:
        if log is not None:
            log(environment, instance, status, category, message)
        elif key not in _released:
            from fmpy.fmi1 import printLogMessage
            printLogMessage(environment, instance, status, category, message)
    except Exception:   # a logger must never raise into the FMU
        pass


def fmpy_callbacks(log: Logger):
    """An ``fmi2CallbackFunctions`` for fmpy's ``FMU2Slave.instantiate`` routing this host's messages to ``log``."""
    global _dispatcher
    from fmpy.fmi2 import (calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                           fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, free)
    from fmpy.logging import addLoggerProxy
    with _lock:
        if _dispatcher is None:
            _dispatcher = fmi2CallbackLoggerTYPE(_dispatch)
        key = next(_keys)
        _loggers[key] = log
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = _dispatcher
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    callbacks.componentEnvironment = ctypes.c_void_p(key)
    addLoggerProxy(ctypes.byref(callbacks))    # the global proxy target becomes the (pinned) dispatcher
    return callbacks


def release(callbacks) -> None:
    """Stop routing messages of ``callbacks`` (after ``fmi2FreeInstance``); a second call does nothing."""
    with _lock:
        key = int(callbacks.componentEnvironment or 0)
        if _loggers.pop(key, None) is not None:
            _released.add(key)
