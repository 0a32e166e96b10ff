"""Thin pythonfmu ``Fmi2Slave`` classes that map FMU variables onto the physics, and their shared helpers.

* ``ball_bearing_fmu``: the ``BallBearing`` co-simulation FMU (force law of Xu et al. 2012);
* ``journal_clearance_fmu``: the ``JournalClearance`` FMU (journal in a bushing, for Fig. 23-25).

The slave scripts import ``pythonfmu``; ``fmu_bearing`` itself never imports this package, so the physics
stays usable without it. Build the FMUs with ``python build_fmu.py`` (see docs/fmu-interface.md).

This module holds two workarounds for pythonfmu 0.7's C++ layer that every slave should use (only the
standard library is imported here):

* ``hold_before_raise(slave)``: call it right before an exception leaves a slave callback (e.g. to fail
  ``exit_initialization_mode``). When an exception reaches pythonfmu's C++ side, it releases its references
  to the slave class, the slave instance and its log queue once in its error handler and once more in the
  instance's destructor; after a few such exceptions in one process those objects are freed while still in
  use and the host crashes. Parking one extra reference to each balances that (at worst, if pythonfmu is
  fixed, a small leak per failure). Better still, never let an exception escape where a status can be
  returned instead (``do_step`` returning False gives fmi2Discard).
* ``guard_pythonfmu_exit(resources)``: call it from the slave's ``__init__``. At process exit the binary's
  C++ static destructors delete its Python-state object and then the library destructor,
  ``finalizePythonInterpreter``, deletes it again: a double free that corrupts the heap after the host has
  finished ("corrupted double-linked list", SIGABRT, at random; Linux). Calling the exported
  ``finalizePythonInterpreter`` once from a Python ``atexit`` hook releases the object early and turns both
  later calls into no-ops.
"""
import atexit
import ctypes
import glob
import math
import os
import sys
import threading
from xml.etree.ElementTree import Element, SubElement

#: SI base-unit exponents (and factor) of every unit our FMUs declare; None: no integer-exponent form
UNIT_DEFINITIONS = {
    "1": {},
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "rad": {"rad": 1},
    "rad/s": {"rad": 1, "s": -1},
    "rev/min": {"rad": 1, "s": -1, "factor": 2.0 * math.pi / 60.0},
    "kg": {"kg": 1},
    "kg.m2": {"kg": 1, "m": 2},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N/m": {"kg": 1, "s": -2},
    "N.s/m": {"kg": 1, "s": -1},
    "Pa": {"kg": 1, "m": -1, "s": -2},
    "Pa.s": {"kg": 1, "m": -1, "s": -1},
    "1/Pa": {"kg": -1, "m": 1, "s": 2},
    "h": {"s": 1, "factor": 3600.0},
    "Mrev": {"rad": 1, "factor": 2.0e6 * math.pi},   # millions of revolutions (bearing life)
    "N/m1.5": None,                      # FMI exponents are integers: declared by name only
}


def add_unit_definitions(root, variables) -> None:
    """Insert <UnitDefinitions> for every unit the variables use into a modelDescription root (FMI 2.0 order:
    right after CoSimulation). Variables carry their unit in ``type_attributes`` (ball_bearing_fmu)."""
    used = {getattr(v, "type_attributes", {}).get("unit") for v in variables}
    units = Element("UnitDefinitions")
    for unit in sorted(u for u in used if u):
        node = SubElement(units, "Unit", {"name": unit})
        exponents = UNIT_DEFINITIONS[unit]
        if exponents is not None:
            SubElement(node, "BaseUnit", {k: repr(v) if k == "factor" else str(v) for k, v in exponents.items()})
    root.insert(1, units)

#: extra references that balance pythonfmu 0.7's over-release on the exception path (see above)
PYTHONFMU_EXCEPTION_REFS = []

#: FMU binaries whose exit-time double free is already guarded
_EXIT_GUARDED = set()


def hold_before_raise(slave) -> None:
    """Keep the slave's class, the slave and its log queue alive across pythonfmu's exception path."""
    PYTHONFMU_EXCEPTION_REFS.append((type(slave), slave, getattr(slave, "log_queue", None)))


def guard_pythonfmu_exit(resources) -> None:
    """Release pythonfmu's Python-state object from an ``atexit`` hook (once per FMU binary).

    Only in a Python host whose main thread drives the FMU: Python then belongs to the host, and the
    pythonfmu worker thread that ``finalizePythonInterpreter`` joins has already returned. In native hosts
    and on foreign threads (where Python's main thread is pythonfmu's own) nothing is done.
    """
    if not sys.platform.startswith("linux") or not resources:
        return
    if threading.current_thread() is not threading.main_thread():
        return
    binaries = os.path.join(os.path.dirname(os.path.normpath(str(resources))), "binaries", "linux64")
    for path in glob.glob(os.path.join(binaries, "*.so")):
        if path in _EXIT_GUARDED:
            continue
        _EXIT_GUARDED.add(path)
        try:
            finalize = ctypes.CDLL(path).finalizePythonInterpreter  # loaded by the host already: same handle
        except (OSError, AttributeError):
            continue
        finalize.argtypes, finalize.restype = [], None
        atexit.register(finalize)
