"""The FMU's per-step fmi2 calls made from numba-compiled code (issue 11: the FMU side of the compiled loop).

fmpy loads the FMU's binary, instantiates, initialises, terminates and frees it (``FmuEndpoint`` or a bare
``fmpy.fmi2.FMU2Slave``); the per-step calls go to the *same* binary functions fmpy resolved, called from
``@njit`` code instead of through ctypes from Python:

* ``handle(slave)`` / ``endpoint_handle(endpoint)``: an int64 array ``H`` with the component pointer and the
  addresses of fmi2SetReal, fmi2DoStep, fmi2GetReal, fmi2GetInteger, fmi2GetBoolean, fmi2GetFMUstate,
  fmi2SetFMUstate, fmi2FreeFMUstate (slots below). The array's buffer holds a reference to the fmpy objects
  (slave, callbacks, endpoint), so they live as long as ``H`` does.
* ``endpoint_references(endpoint)``: the value references an endpoint exchanges and samples, as uint32 arrays.
* ``exchange``, ``set_reals``, ``do_step``, ``get_reals``, ``get_integers``, ``get_booleans``, ``sample_into``,
  ``get_state``, ``set_state``, ``free_state``: ``@njit(**KERNEL)`` functions (cached) callable from other njit code. They return
  the fmi2Status (0 OK, 1 warning, 2 discard, 3 error, 4 fatal) or ``BAD_ARGUMENT`` (array sizes or layout
  wrong, nothing called) / ``NO_FUNCTION`` (the FMU lacks the function, or ``H`` is invalidated or not a whole
  handle; nothing called); ``check`` raises the
  ``ExchangeError`` ``FmuEndpoint`` raises, with the FMU's logged messages.

How the call is made: the addresses are *data* (the int64 slots), not compile-time constants, so the machine
code cached by ``cache=True`` is valid in every process. A numba ``@intrinsic`` per C signature turns the
int64 into a function pointer (LLVM ``inttoptr``) and calls it with the C types of ``fmi2Functions.h``:
fmi2Component and arrays as pointers, size_t as i64, fmi2Real as double, fmi2Boolean and fmi2Status as int.
numba's compiled code holds the GIL, so the FMU's logger (a ctypes callback, ``fmpy_logging``) and the
Python step inside the FMU (BEARING_FMU_C_STEP=0) run as they do under fmpy's calls.

The component pointer dangles once the instance is freed: ``handle`` wraps the slave's ``freeInstance``
(called by ``FmuEndpoint.close``) so that it first zeroes every handle of the instance (``invalidate``), and
every native call then returns NO_FUNCTION instead of reaching freed memory.
"""
from __future__ import annotations

import ctypes
import weakref
from typing import NamedTuple

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic

from mechanism.cosim.endpoints import _STATUS, ExchangeError
from mechanism.multibody.kernels import KERNEL

#: slots of the handle array
COMPONENT, SET_REAL, DO_STEP, GET_REAL, GET_INTEGER, GET_BOOLEAN, GET_STATE, SET_STATE, FREE_STATE = range(9)
FUNCTIONS = ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean",
             "fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate")
SLOTS = 1 + len(FUNCTIONS)
#: statuses of this module (negative: no fmi2 function was called)
BAD_ARGUMENT, NO_FUNCTION = -1, -2

_I8P = ir.IntType(8).as_pointer()
_I32, _I64, _F64 = ir.IntType(32), ir.IntType(64), ir.DoubleType()


# ---- the C calls ---------------------------------------------------------------------------------------

def _int64(context, builder, value, ty):
    return context.cast(builder, value, ty, types.int64)


def _function(builder, address, restype, argtypes):
    return builder.inttoptr(address, ir.FunctionType(restype, argtypes).as_pointer())


@intrinsic
def _call_arrays(typingctx, fn, component, vr, n, values):
    """fmi2Status f(fmi2Component, const fmi2ValueReference*, size_t, T*): fmi2Set/GetReal/Integer/Boolean;
    every argument an integer (addresses as int64)."""
    args = (fn, component, vr, n, values)
    if not all(isinstance(a, types.Integer) for a in args):
        raise TypingError("_call_arrays takes integers (function, component and array addresses, count)")
    sig = types.int32(*args)

    def codegen(context, builder, signature, llargs):
        a = [_int64(context, builder, v, t) for v, t in zip(llargs, signature.args)]
        f = _function(builder, a[0], _I32, [_I8P, _I8P, _I64, _I8P])
        return builder.call(f, [builder.inttoptr(a[1], _I8P), builder.inttoptr(a[2], _I8P), a[3],
                                builder.inttoptr(a[4], _I8P)])
    return sig, codegen


@intrinsic
def _call_do_step(typingctx, fn, component, t, h, no_prior):
    """fmi2Status fmi2DoStep(fmi2Component, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint)."""
    if not (isinstance(fn, types.Integer) and isinstance(component, types.Integer)
            and isinstance(no_prior, types.Integer)):
        raise TypingError("_call_do_step takes (int64 function, int64 component, float t, float h, int flag)")
    sig = types.int32(fn, component, types.float64, types.float64, no_prior)

    def codegen(context, builder, signature, llargs):
        f = _function(builder, _int64(context, builder, llargs[0], signature.args[0]), _I32,
                      [_I8P, _F64, _F64, _I32])
        c = builder.inttoptr(_int64(context, builder, llargs[1], signature.args[1]), _I8P)
        flag = context.cast(builder, llargs[4], signature.args[4], types.int32)
        return builder.call(f, [c, llargs[2], llargs[3], flag])
    return sig, codegen


@intrinsic
def _call_pointer(typingctx, fn, component, pointer):
    """fmi2Status f(fmi2Component, void*): fmi2SetFMUstate (the state by value)."""
    if not all(isinstance(a, types.Integer) for a in (fn, component, pointer)):
        raise TypingError("_call_pointer takes integers (function, component, pointer)")
    sig = types.int32(fn, component, pointer)

    def codegen(context, builder, signature, llargs):
        a = [_int64(context, builder, v, t) for v, t in zip(llargs, signature.args)]
        f = _function(builder, a[0], _I32, [_I8P, _I8P])
        return builder.call(f, [builder.inttoptr(a[1], _I8P), builder.inttoptr(a[2], _I8P)])
    return sig, codegen


@intrinsic
def _call_out_pointer(typingctx, fn, component, pointer):
    """fmi2Status f(fmi2Component, fmi2FMUstate*) with the fmi2FMUstate in a stack slot holding ``pointer``:
    fmi2GetFMUstate (0 in, the new state out), fmi2FreeFMUstate (the state in, NULL out). Returns
    (status, the slot's pointer after the call, as int64)."""
    if not all(isinstance(a, types.Integer) for a in (fn, component, pointer)):
        raise TypingError("_call_out_pointer takes integers (function, component, pointer)")
    sig = types.UniTuple(types.int64, 2)(fn, component, pointer)

    def codegen(context, builder, signature, llargs):
        a = [_int64(context, builder, v, t) for v, t in zip(llargs, signature.args)]
        slot = cgutils.alloca_once(builder, _I8P)
        builder.store(builder.inttoptr(a[2], _I8P), slot)
        f = _function(builder, a[0], _I32, [_I8P, _I8P.as_pointer()])
        status = builder.sext(builder.call(f, [builder.inttoptr(a[1], _I8P), slot]), _I64)
        after = builder.ptrtoint(builder.load(slot), _I64)
        return context.make_tuple(builder, signature.return_type, (status, after))
    return sig, codegen


def _address_of(dtype, what: str):
    """An intrinsic giving the data address (int64) of a 1-d array of ``dtype``; any other array is a
    typing error naming ``what`` (compile time: a wrong buffer can never reach the FMU)."""
    @intrinsic
    def address(typingctx, array):
        if not (isinstance(array, types.Array) and array.ndim == 1 and array.dtype == dtype):
            raise TypingError(f"{what} must be a 1-d numpy array of {dtype}, got {array}")
        sig = types.int64(array)

        def codegen(context, builder, signature, llargs):
            data = context.make_array(signature.args[0])(context, builder, value=llargs[0]).data
            return builder.ptrtoint(data, _I64)
        return sig, codegen
    return address


_vr_address = _address_of(types.uint32, "value references (fmi2ValueReference)")
_real_address = _address_of(types.float64, "real values (fmi2Real)")
_int_address = _address_of(types.int32, "integer/boolean values (fmi2Integer, fmi2Boolean)")


# ---- the calls for njit code ---------------------------------------------------------------------------

@njit(**KERNEL, inline="always")
def _missing(H, slot) -> bool:
    """The handle is too short, invalidated, or the FMU lacks the function of ``slot``. Callers pass the slot
    as ``np.int64``: a literal constant would compile one specialisation per slot (first run's compile)."""
    return H.size < SLOTS or H[COMPONENT] == 0 or H[slot] == 0


@njit(**KERNEL, inline="always")
def _fits(vr, size, contiguous) -> bool:
    """``vr`` fits values of ``size`` (C-contiguous if ``contiguous``); the values' size and flag, not the array:
    one specialisation for the float64 and the int32 values."""
    return vr.size <= size and vr.flags.c_contiguous and contiguous


@njit(**KERNEL)
def set_reals(H, vr, values) -> int:
    """fmi2SetReal of ``values[:len(vr)]`` (float64) to ``vr`` (uint32)."""
    if _missing(H, np.int64(SET_REAL)):
        return NO_FUNCTION
    if not _fits(vr, values.size, values.flags.c_contiguous):
        return BAD_ARGUMENT
    return _call_arrays(H[SET_REAL], H[COMPONENT], _vr_address(vr), np.int64(vr.size), _real_address(values))


@njit(**KERNEL)
def get_reals(H, vr, out) -> int:
    """fmi2GetReal of ``vr`` (uint32) into ``out[:len(vr)]`` (float64)."""
    if _missing(H, np.int64(GET_REAL)):
        return NO_FUNCTION
    if not _fits(vr, out.size, out.flags.c_contiguous):
        return BAD_ARGUMENT
    return _call_arrays(H[GET_REAL], H[COMPONENT], _vr_address(vr), np.int64(vr.size), _real_address(out))


@njit(**KERNEL)
def get_integers(H, vr, out) -> int:
    """fmi2GetInteger of ``vr`` (uint32) into ``out[:len(vr)]`` (int32)."""
    if _missing(H, np.int64(GET_INTEGER)):
        return NO_FUNCTION
    if not _fits(vr, out.size, out.flags.c_contiguous):
        return BAD_ARGUMENT
    return _call_arrays(H[GET_INTEGER], H[COMPONENT], _vr_address(vr), np.int64(vr.size), _int_address(out))


@njit(**KERNEL)
def get_booleans(H, vr, out) -> int:
    """fmi2GetBoolean of ``vr`` (uint32) into ``out[:len(vr)]`` (int32: fmi2Boolean is a C int)."""
    if _missing(H, np.int64(GET_BOOLEAN)):
        return NO_FUNCTION
    if not _fits(vr, out.size, out.flags.c_contiguous):
        return BAD_ARGUMENT
    return _call_arrays(H[GET_BOOLEAN], H[COMPONENT], _vr_address(vr), np.int64(vr.size), _int_address(out))


@njit(**KERNEL)
def do_step(H, t, h) -> int:
    """fmi2DoStep(t, h, noSetFMUStatePriorToCurrentPoint = fmi2True)."""
    if _missing(H, np.int64(DO_STEP)):
        return NO_FUNCTION
    return _call_do_step(H[DO_STEP], H[COMPONENT], np.float64(t), np.float64(h), np.int32(1))


@njit(**KERNEL)
def exchange(H, vr_in, u, t, h, vr_out, out) -> int:
    """One exchange: fmi2SetReal(vr_in, u), fmi2DoStep(t, h, True), fmi2GetReal(vr_out, out); stops at the
    first status above fmi2Warning and returns it (else the last status)."""
    status = set_reals(H, vr_in, u)
    if status < 0 or status > 1:
        return status
    status = do_step(H, t, h)
    if status < 0 or status > 1:
        return status
    return get_reals(H, vr_out, out)


@njit(**KERNEL)
def sample_into(H, vr_real, vr_int, vr_bool, row) -> int:
    """The sampled outputs into ``row`` (float64) in ``FmuEndpoint.sample_names``'s order: the reals of
    ``vr_real``, then the integers of ``vr_int``, then the booleans of ``vr_bool`` as 0.0/1.0
    (``FmuEndpoint.sample_into``; ``endpoint_references`` gives the three)."""
    nr, ni, nb = vr_real.size, vr_int.size, vr_bool.size
    if row.size < nr + ni + nb:
        return BAD_ARGUMENT
    status = get_reals(H, vr_real, row[:nr]) if nr else 0
    if ni and 0 <= status <= 1:
        ints = np.empty(ni, np.int32)
        status = get_integers(H, vr_int, ints)
        for k in range(ni):
            row[nr + k] = ints[k]
    if nb and 0 <= status <= 1:
        flags = np.empty(nb, np.int32)
        status = get_booleans(H, vr_bool, flags)
        for k in range(nb):
            row[nr + ni + k] = 1.0 if flags[k] != 0 else 0.0
    return status


@njit(**KERNEL)
def get_state(H):
    """fmi2GetFMUstate: (status, the new state's pointer as int64; 0 if none was made)."""
    if _missing(H, np.int64(GET_STATE)):
        return NO_FUNCTION, np.int64(0)
    status, state = _call_out_pointer(H[GET_STATE], H[COMPONENT], np.int64(0))
    return status, state


@njit(**KERNEL)
def set_state(H, state) -> int:
    """fmi2SetFMUstate of the state ``state`` (a pointer from ``get_state``)."""
    if _missing(H, np.int64(SET_STATE)):
        return NO_FUNCTION
    if state == 0:
        return BAD_ARGUMENT
    return _call_pointer(H[SET_STATE], H[COMPONENT], np.int64(state))


@njit(**KERNEL)
def free_state(H, state) -> int:
    """fmi2FreeFMUstate of ``state`` (a pointer from ``get_state``; 0: nothing to free, OK)."""
    if _missing(H, np.int64(FREE_STATE)):
        return NO_FUNCTION
    if state == 0:
        return 0
    status, _ = _call_out_pointer(H[FREE_STATE], H[COMPONENT], np.int64(state))
    return status


# ---- Python side: the handle, the errors ---------------------------------------------------------------

class _Slots(ctypes.c_int64 * SLOTS):
    """The handle's buffer; ``keep`` holds the fmpy objects whose binary and instance the addresses point into."""


def handle(slave, *keep) -> np.ndarray:
    """The handle (int64 array, slots above) of an instantiated ``fmpy.fmi2.FMU2Slave``; ``keep``: more
    objects to keep alive with it (the endpoint, the callbacks)."""
    component = getattr(slave, "component", None)
    functions = getattr(slave, "_functions", None)
    if not component or functions is None:
        raise ValueError("fmu_native.handle needs an FMU2Slave that fmpy loaded and instantiated")
    slots = _Slots()
    slots[COMPONENT] = int(component)
    for k, name in enumerate(FUNCTIONS, start=1):
        f = functions.get(name)
        slots[k] = (ctypes.cast(f, ctypes.c_void_p).value or 0) if f is not None else 0
    slots.keep = (slave, getattr(slave, "callbacks", None), *keep)
    H = np.ctypeslib.as_array(slots)     # its base (a memoryview of slots) keeps slots, and so keep, alive
    _invalidate_on_free(slave, H)
    return H


def _invalidate_on_free(slave, H: np.ndarray) -> None:
    """Make ``slave.freeInstance()`` (which ``FmuEndpoint.close`` calls) zero ``H`` before the instance goes:
    a call through a handle of a freed instance would reach freed memory (it hangs or crashes the host)."""
    handles = slave.__dict__.get("_fmu_native_handles")
    if handles is None:
        handles = slave.__dict__["_fmu_native_handles"] = []
        free = slave.freeInstance

        def freeInstance():
            for ref in handles:
                live = ref()
                if live is not None:
                    invalidate(live)
            handles.clear()
            return free()
        slave.freeInstance = freeInstance
    handles[:] = [ref for ref in handles if ref() is not None] + [weakref.ref(H)]


def endpoint_handle(endpoint) -> np.ndarray:
    """The handle of an initialised ``FmuEndpoint`` (the FMI 2.0 endpoint; its instance, callbacks and
    buffers live as long as the handle)."""
    if not getattr(endpoint, "_instantiated", False):
        raise ValueError("the endpoint is not initialised (call initialize first) or already closed")
    return handle(endpoint.fmu, endpoint)


class References(NamedTuple):
    """An FmuEndpoint's value references as uint32 arrays for the native calls (its own order)."""

    inputs: np.ndarray        #: the six joint inputs (``endpoints.INPUTS``)
    coupling: np.ndarray      #: the coupling outputs (``endpoint.coupling_names``: F_x, F_y, stiffness, damping)
    real_samples: np.ndarray  #: the sampled outputs of ``endpoint.sample_names``: reals first,
    int_samples: np.ndarray   #: then integers,
    bool_samples: np.ndarray  #: then booleans (``FmuEndpoint.sample``'s order)


def endpoint_references(endpoint) -> References:
    """The value references an ``FmuEndpoint`` exchanges and samples, for ``exchange``/``get_*``.

    Sampling natively (``get_reals``/``get_integers``/``get_booleans`` of these) gives ``endpoint.sample()``'s
    values; after native calls do not rely on the endpoint's own ``exchange_sampled`` buffer (it does not
    see them)."""
    def vrs(ctypes_array) -> np.ndarray:
        return np.array(list(ctypes_array), dtype=np.uint32)
    return References(vrs(endpoint._vr_in), vrs(endpoint._vr_out), vrs(endpoint._vr_sr), vrs(endpoint._vr_si),
                      vrs(endpoint._vr_sb))


def invalidate(H: np.ndarray) -> None:
    """Zero the handle's slots: every later call returns NO_FUNCTION instead of reaching a freed instance."""
    H[:] = 0


def status_name(status: int) -> str:
    """The fmi2Status's name, or what this module's own negative statuses mean."""
    if status == BAD_ARGUMENT:
        return "BAD_ARGUMENT (array sizes, types or layout; nothing called)"
    if status == NO_FUNCTION:
        return "NO_FUNCTION (the FMU lacks the function, or the handle was invalidated or is not one; nothing called)"
    return _STATUS[status] if 0 <= status < len(_STATUS) else str(status)


def check(status: int, what: str, endpoint=None) -> int:
    """``status`` if it is OK or a warning, else the ``ExchangeError`` FmuEndpoint raises: ``endpoint``'s
    last logged messages (``FmuEndpoint._fail``), else the status."""
    status = int(status)
    if 0 <= status <= 1:
        return status
    err = ExchangeError(f"status {status_name(status)}")
    if endpoint is not None and hasattr(endpoint, "_fail") and status > 1:
        raise endpoint._fail(what, err)
    raise ExchangeError(f"{what} failed: {err}")
