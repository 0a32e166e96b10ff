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
  use and the host crashes. Parking extra references balances that (a small leak per failure). Better still, never let an exception escape where a status can be
  returned instead (``do_step`` returning False gives fmi2Discard).
* ``guard_pythonfmu_exit(resources)``: call it from the slave's ``__init__``. At process exit the binary's
  C++ static destructors delete its Python-state object and then the library destructor,
  ``finalizePythonInterpreter``, deletes it again: a double free that corrupts the heap after the host has
  finished ("corrupted double-linked list", SIGABRT, at random; Linux). Calling the exported
  ``finalizePythonInterpreter`` once, early, releases the object and turns both later calls into no-ops.
  The FMUs' loader library (``fmu_bearing/native/loader.c``, the FMU's binary since issue 13) does this
  in every host from a C exit handler; this function only covers an FMU without the loader (pythonfmu's
  binary alone), from a Python ``atexit`` hook.

and what makes a built FMU a good guest in its host process (issue 13):

* ``release_on_free(slave)``: call it from the slave's ``__init__``. build_fmu.py packs the FMU's Python
  code under private module names unique to the build (``_fmu_bearing_<hash>`` ...), listed in
  ``resources/build_options.json``; when the last instance of the FMU is freed, those modules leave
  ``sys.modules`` and the resources folder pythonfmu put on ``sys.path`` leaves it.
* ``HostLogger``: the host's fmi2CallbackLogger, called directly, so errors reach the host with a
  category even when logging is off (pythonfmu 0.7 forwards nothing then).
* ``weak_accessors(slave, name)``: variable getters/setters that hold the slave weakly, so the slave has
  no reference cycle and is released by ``fmi2FreeInstance`` itself (which triggers ``release_on_free``).
* ``add_initial_unknowns(root, variables)``: outputs computed at initialisation as ``<InitialUnknowns>``.
"""
import atexit
import ctypes
import glob
import json
import math
import os
import platform
import sys
import threading
import weakref
from functools import partial
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


def add_initial_unknowns(root, variables) -> None:
    """List every output with initial="calculated" under <ModelStructure><InitialUnknowns> (FMI 2.0, 2.2.8):
    our FMUs compute their outputs in fmi2ExitInitializationMode. ``variables`` in value-reference order."""
    indices = [i for i, v in enumerate(variables, start=1)
               if v.causality.name == "output" and v.initial is not None and v.initial.name == "calculated"]
    if indices:
        node = SubElement(root.find("ModelStructure"), "InitialUnknowns")
        for index in indices:
            SubElement(node, "Unknown", {"index": str(index)})


#: key of the state that stands for bytes which are not a serialized state (``state_from_bytes``)
INVALID_STATE = "__invalid_state__"


def state_from_bytes(parse, data, what: str) -> dict:
    """``parse(data)`` (the base class's ``_fmu_state_from_bytes``), or {INVALID_STATE: "<what> (<error>)"} for
    bytes it cannot read: the slave's ``_set_fmu_state`` then refuses it (no exception may reach the C++ side)."""
    try:
        return parse(data)
    except Exception as err:
        return {INVALID_STATE: f"{what} ({err!r})"}


def refuse_state(slave, problem: str) -> None:
    """A refused fmi2SetFMUstate: logged (status error), reported again by the next doStep; nothing assigned."""
    message = f"setFMUstate refused: {problem}; the instance is unchanged"
    slave._error(message)
    slave._pending_error = slave._pending_error or message


def weak_accessors(slave, name):
    """(getter, setter) of attribute ``name`` of ``slave`` that do not keep the slave alive.

    pythonfmu keeps the getters in ``slave.vars``; bound to the slave itself they would make a reference
    cycle, and the slave would outlive fmi2FreeInstance until Python's cycle collector runs.
    """
    proxy = slave.__dict__.get("_weak_self")
    if proxy is None:
        proxy = slave.__dict__["_weak_self"] = weakref.proxy(slave)
    return partial(getattr, proxy, name), partial(setattr, proxy, name)


# --- the host's logger --------------------------------------------------------------------------------

#: fmi2CallbackLogger(componentEnvironment, instanceName, status, category, message, ...)
_LOGGER_TYPE = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                                ctypes.c_char_p)
#: FMI 2.0 status -> log category (the categories every pythonfmu model description declares)
STATUS_CATEGORIES = {0: "logAll", 1: "logStatusWarning", 2: "logStatusDiscard", 3: "logStatusError",
                     4: "logStatusFatal"}


class HostLogger:
    """The host's fmi2CallbackLogger, found through pythonfmu 0.7's logger object, called directly.

    pythonfmu 0.7 hands every message to the host only when the host switched logging on, and its own
    messages (the exception that fails a call) with a NULL category. FMI 2.0 lets an FMU report errors
    regardless (the Modelica reference FMUs always log errors), which is what a host needs to learn why
    fmi2Instantiate or fmi2ExitInitializationMode failed; so errors go straight to the host's callback.

    fmpy hosts: fmpy's loggers go through one native proxy that forwards to the Python callback most recently
    registered with ``fmpy.logging.addLoggerProxy`` (a single global), which dangles once that callback is
    garbage collected. So a host using fmpy's default callbacks gets fmpy's own ``printLogMessage`` called
    directly (what the default would do), and a host with its own callbacks behind fmpy's proxy gets the
    message through pythonfmu's queue only (``available`` False), as before: never the possibly dangling proxy.

    The slave receives the address of pythonfmu's C++ ``Fmi2Logger`` as the ``logger`` keyword. Its layout in
    pythonfmu 0.7's Linux x86-64 binary (libstdc++): vtable pointer, ``bool debugLogging_``, ``std::string
    instanceName_`` at byte 16 (data pointer, length, 16-byte local buffer), ``std::vector categories_`` at 48,
    ``const fmi2CallbackFunctions* f_`` at 72. The layout is used only if the string at byte 16 is this
    instance's name (length, and the local buffer for short names); otherwise ``available`` is False and
    the slave logs through pythonfmu's queue as before.
    """

    def __init__(self, address, instance_name, resources=None):
        self._call = None
        self._note_error = None
        if not address or not sys.platform.startswith("linux") or platform.machine() not in ("x86_64", "AMD64"):
            return
        name = str(instance_name).encode("utf-8")
        try:
            words = (ctypes.c_void_p * 10).from_address(int(address))
            data, length = words[2] or 0, words[3] or 0
            if length != len(name) or not data:
                return
            if len(name) < 16 and data != int(address) + 32:   # libstdc++'s short-string buffer
                return
            if ctypes.string_at(data, length) != name or not words[9]:
                return
            functions = words[9]                                         # fmi2CallbackFunctions*
            callbacks = (ctypes.c_void_p * 5).from_address(functions)
            host, note = _loader_host_callbacks(resources, callbacks[4])
            if host:   # pythonfmu was given the loader's callbacks (fmu_bearing/native): look behind them
                functions = host
                self._note_error = note   # so the loader drops pythonfmu's repeat of this error (logging off)
                callbacks = (ctypes.c_void_p * 5).from_address(functions)
            if not callbacks[0]:
                return
            self._environment, self._name = callbacks[4], name
            fmpy = sys.modules.get("fmpy.fmi2")
            if fmpy is not None and hasattr(fmpy, "defaultCallbacks"):
                if functions == ctypes.addressof(fmpy.defaultCallbacks):   # fmpy's defaults: its printer
                    printer = getattr(sys.modules.get("fmpy.fmi1"), "printLogMessage", None)
                    self._call = partial(_call_python, printer) if callable(printer) else None
                    return
                if callbacks[0] == ctypes.cast(fmpy.defaultCallbacks.logger, ctypes.c_void_p).value:
                    return                                                # fmpy's proxy: may dangle
            self._call = partial(_call_native, _LOGGER_TYPE(callbacks[0]))
        except (TypeError, ValueError, OSError, AttributeError):
            self._call = None

    @property
    def available(self) -> bool:
        return self._call is not None

    def __call__(self, status: int, message: str, category=None) -> bool:
        """Send ``message`` with FMI ``status`` (3 = error) to the host; False if the host's logger is unknown."""
        if self._call is None:
            return False
        category = category or STATUS_CATEGORIES.get(int(status), "logAll")
        try:
            self._call(self._environment, self._name, int(status), category.encode(), str(message))
            if self._note_error is not None and int(status) >= 3:
                self._note_error()
        except Exception:   # never let a logging problem fail the FMU
            return False
        return True


def _loader_host_callbacks(resources, environment):
    """(the host's fmi2CallbackFunctions* behind ``environment``, a function that tells the loader an error
    went to the host directly) when ``environment`` is one of the FMU loader's instances
    (``bearingLoaderHostCallbacks``/``bearingLoaderDirectError`` of fmu_bearing/native/loader.c, the FMU's
    binary), else (0, None)."""
    if not environment:
        return 0, None
    for library in loader_libraries(resources, ctypes.CDLL):
        function = getattr(library, "bearingLoaderHostCallbacks", None)
        if function is None:
            continue
        function.restype, function.argtypes = ctypes.c_void_p, [ctypes.c_void_p]
        found = function(ctypes.c_void_p(environment))
        if found:
            note = getattr(library, "bearingLoaderDirectError", None)
            if note is not None:
                note.restype, note.argtypes = None, [ctypes.c_void_p]
                note = partial(note, ctypes.c_void_p(environment))
            return int(found), note
    return 0, None


def loader_libraries(resources, kind=ctypes.CDLL):
    """The FMU's own binaries beside ``resources`` other than pythonfmu's (``*_pythonfmu``): the loader
    (fmu_bearing/native/loader.c) when the FMU has one, opened as ``kind`` (ctypes.CDLL, or ctypes.PyDLL for
    functions called with the GIL held). The host has loaded it already, so this returns the same handle."""
    if not resources:
        return
    binaries = os.path.join(os.path.dirname(os.path.abspath(str(resources))), "binaries")
    for path in sorted(glob.glob(os.path.join(binaries, "*", "*"))):
        stem, ext = os.path.splitext(os.path.basename(path))
        if ext not in (".so", ".dll", ".dylib") or stem.endswith("_pythonfmu"):
            continue
        try:
            yield kind(path)
        except OSError:
            continue


def _call_native(function, environment, name, status, category, message):
    """An fmi2CallbackLogger: the message is a printf format, so '%' is escaped (no variadic arguments)."""
    function(environment, name, status, category, message.replace("%", "%%").encode("utf-8", "replace"))


def _call_python(printer, environment, name, status, category, message):
    """fmpy's printLogMessage, which takes the formatted message."""
    printer(environment, name, status, category, message.encode("utf-8", "replace"))


# --- sealed modules: leave sys.path and sys.modules as the FMU found them -----------------------------

BUILD_OPTIONS_FILE = "build_options.json"
#: live instances per sealed FMU build, keyed by its private module names
_LIVE = {}
#: attribute of ``sys`` that holds, per sealed build (its private module names), the modules its last free
#: removed from ``sys.modules``; the build's slave shim (build_fmu.py, ``SHIM``) puts them back at the next
#: fmi2Instantiate instead of importing them again (issue 14). It lives on ``sys`` because it must outlive
#: the FMU's own modules, which have left ``sys.modules`` and ``sys.path`` by then.
MODULE_CACHE = "_sealed_fmu_modules"


def module_cache() -> dict:
    """{private module names of a build: {name: module}}: the released modules of every sealed build (one
    copy per build and process, whatever the number of instantiations; see ``MODULE_CACHE``)."""
    return sys.__dict__.setdefault(MODULE_CACHE, {})


def read_build_options(resources) -> dict:
    """resources/build_options.json of a built FMU ({} in-process, or without the file)."""
    if not resources:
        return {}
    path = os.path.join(str(resources), BUILD_OPTIONS_FILE)
    if not os.path.isfile(path):
        return {}
    with open(path, encoding="utf-8") as fh:
        return json.load(fh)


def release_on_free(slave) -> None:
    """Register ``slave`` so that freeing the FMU's last instance undoes its imports.

    pythonfmu's fmi2Instantiate puts the resources folder at the front of ``sys.path`` (once per instance)
    and imports the slave module from it. build_fmu.py names every packed module privately for the build
    (``build_options.json``: ``private_modules``), so the modules it added are exactly those names: at the
    free of the last instance they are removed from ``sys.modules`` and one ``sys.path`` entry per
    instance is removed. Standard-library modules imported on the way stay (they are the host's own).
    The removed module objects are kept in ``module_cache()``: the build's slave shim puts them back at the
    next fmi2Instantiate, so one process imports an FMU's code once, not once per instance (issue 14: every
    re-import left a whole copy of the package behind). Needs the slave to be free of reference cycles
    (``weak_accessors``): it is released when fmi2FreeInstance drops pythonfmu's reference. No-op
    in-process (no resources) and for unsealed builds.
    """
    names = tuple(read_build_options(slave.resources).get("private_modules", ()))
    if not names:
        return
    resources = str(slave.resources)
    if not _LIVE.get(names):
        modules = module_cache().pop(names, None)
        home = type(slave).__module__
        if modules is not None and home in modules and home not in sys.modules:
            # fmi2Reset after the last free: a new instance of the released class, no new fmi2Instantiate
            for name, module in modules.items():
                sys.modules.setdefault(name, module)
            sys.path.insert(0, resources)
        # else a fresh import of the FMU's modules (an FMU built without the shim): the cached copy is not
        # this one and is dropped
    _LIVE[names] = _LIVE.get(names, 0) + 1
    release = weakref.finalize(slave, _release, names, resources)
    release.atexit = False
    slave.__dict__["_release_imports"] = release   # hold_before_raise runs it early (the slave stays alive)


def _release(names, resources) -> None:
    try:
        sys.path.remove(resources)             # the entry fmi2Instantiate inserted for this instance
    except ValueError:
        pass
    _LIVE[names] -= 1
    if _LIVE[names] > 0:
        return
    prefixes = tuple(name + "." for name in names)
    removed = {name: sys.modules.pop(name) for name in list(sys.modules)
               if name in names or name.startswith(prefixes)}
    if resources not in sys.path:
        sys.path_importer_cache.pop(resources, None)
    module_cache()[names] = removed


#: extra references that balance pythonfmu 0.7's over-release on the exception path (see above)
PYTHONFMU_EXCEPTION_REFS = []

#: FMU binaries whose exit-time double free is already guarded
_EXIT_GUARDED = set()


def hold_before_raise(slave) -> None:
    """Keep the slave's class, the slave and its log queue alive across pythonfmu's exception path.

    pythonfmu releases each of the three once in its error handler and once more in fmi2FreeInstance, one
    release too many. The slave is parked twice: it holds no reference cycle (``weak_accessors``), so one
    parked reference would let the second release free it while this list still points to it. A failed
    instance thus stays alive (a small leak per failure); what ``release_on_free`` would undo at its free is
    undone now (its ``sys.path`` entry; the FMU's modules if no other instance lives): the failed instance
    can still refuse steps, be terminated, freed or reset, none of which imports anything.
    """
    PYTHONFMU_EXCEPTION_REFS.append((type(slave), slave, slave, getattr(slave, "log_queue", None)))
    release = slave.__dict__.get("_release_imports")
    if release is not None:
        release()


def guard_pythonfmu_exit(resources) -> None:
    """Release pythonfmu's (or pythonfmu3's) Python-state object from an ``atexit`` hook (once per FMU binary).

    Only in a Python host whose main thread drives the FMU: Python then belongs to the host, and the
    pythonfmu worker thread that ``finalizePythonInterpreter`` joins has already returned. In native hosts
    and on foreign threads (where Python's main thread is pythonfmu's own) nothing is done.
    """
    if not sys.platform.startswith("linux") or not resources:
        return
    if threading.current_thread() is not threading.main_thread():
        return
    root = os.path.join(os.path.dirname(os.path.normpath(str(resources))), "binaries")
    binaries = os.path.join(root, "linux64")   # FMI 2.0's platform folder; FMI 3.0's is x86_64-linux
    if glob.glob(os.path.join(binaries, "*_pythonfmu.so")):
        return  # the FMU's binary is the loader (fmu_bearing/native): it finalises at exit itself
    for path in glob.glob(os.path.join(binaries, "*.so")) + glob.glob(os.path.join(root, "x86_64-linux", "*.so")):
        if path in _EXIT_GUARDED:
            continue
        _EXIT_GUARDED.add(path)
        try:
            finalize = ctypes.CDLL(path).finalizePythonInterpreter  # loaded by the host already: same handle
        except (OSError, AttributeError):
            continue
        finalize.argtypes, finalize.restype = [], None
        atexit.register(finalize)
