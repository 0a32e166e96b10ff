"""The BallBearing co-simulation FMU: a thin pythonfmu mapping of FMU variables onto ``fmu_bearing``.

All physics lives in ``fmu_bearing.ball_bearing`` (force law, cage kinematics, input checks) and
``fmu_bearing.parameters`` (parameters, defaults, units, validation); this module only declares the
FMI variables and calls those functions. The interface is documented in docs/fmu-interface.md.

Step semantics: ``do_step(t, h)`` checks the inputs, advances the cage angle over [t, t + h] with the
inputs held, and evaluates the force law at the new cage angle, so every output describes the END of
the step. On an error the message goes to the FMI logger (status error, category logStatusError, also
when logging is off: ``HostLogger``) and the step returns False (pythonfmu 0.7: fmi2Discard), leaving the
outputs of the last good step untouched (never NaN); so does a doStep after fmi2Terminate. Invalid
parameters fail fmi2ExitInitializationMode (pythonfmu 0.7: fmi2Fatal, the only non-OK status it gives
that call). The outputs are computed there: they are declared initial="calculated" (InitialUnknowns).

The per-ball output capacity is a build option (``python build_fmu.py --max-balls N``), read at
instantiation from ``resources/build_options.json``; ``n_balls`` is a parameter up to that capacity.

This file is the FMU's slave module: pythonfmu's binary imports it as a top-level module and finds
the slave class by matching its source lines against a class statement deriving from Fmi2Slave, so
it uses absolute imports only and no ``from __future__`` import.
"""
import copy
import ctypes
from dataclasses import fields
from functools import partial

from pythonfmu import (Boolean, DefaultExperiment, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability,
                       Integer, Real)
from pythonfmu.enums import Fmi2Status

from fmu_bearing import ball_bearing as physics
from fmu_bearing import life
from fmu_bearing.parameters import DAMPING_CONSTANT, DAMPING_NONE, BearingParameters, validate
from fmu_bearing.interface import COUPLING_OUTPUTS, JOINT_INPUTS
from fmu_bearing.slaves import (INVALID_STATE, HostLogger, add_initial_unknowns, add_unit_definitions,
                                guard_pythonfmu_exit, hold_before_raise, loader_libraries, read_build_options,
                                refuse_state, release_on_free, state_from_bytes, weak_accessors)
from fmu_bearing.slaves.state import check_state, variable_kinds
from fmu_bearing.slaves.stepping import LIFE_STATE, BearingStepping, ignore_value, life_output

#: per-ball outputs when the FMU was built without an explicit --max-balls
DEFAULT_CAPACITY = 20

#: (name, unit, description) of the inputs, in value-reference order: the joint-component interface
INPUTS = JOINT_INPUTS

#: outputs in the order of physics.BearingForce, (name, unit, description); unit None: Integer
FORCE_OUTPUTS = COUPLING_OUTPUTS + (
    ("loaded_balls", None, "number of balls carrying load"),
    ("max_ball_load", "N", "largest ball load"),
)
assert len(FORCE_OUTPUTS) == len(physics.BearingForce._fields), "FORCE_OUTPUTS out of step with BearingForce"

#: value references of the inputs (registered first, in INPUTS order)
_INPUT_VRS = list(range(len(INPUTS)))

CAGE_ANGLE = ("cage_angle", "rad",
              "angle of ball 1 (ball r at cage_angle + 2 pi (r-1)/n_balls), time integral of the cage speed (eq. 16)")

#: load ratings and life outputs (name, unit, description, source): one home in fmu_bearing.life
RATING_OUTPUTS, LIFE_OUTPUTS = life.RATING_OUTPUTS, life.LIFE_OUTPUTS

#: Integer parameters: (min, max); max None = the FMU's per-ball capacity
_INTEGER_RANGES = {"n_balls": (3, None), "damping_model": (0, 2)}


def read_capacity(resources) -> int:
    """Per-ball output capacity from the FMU's resources/build_options.json (DEFAULT_CAPACITY without one)."""
    return max(int(read_build_options(resources).get("max_balls", DEFAULT_CAPACITY)), 3)


def register_fast_step(resources, step, log_queue, input_vrs, outputs) -> bool:
    """Hand ``step(t, h, *inputs)`` to the FMU's loader (``bearingLoaderRegisterStep``,
    fmu_bearing/native/loader.c) if the FMU's binary is the loader and it is instantiating this slave on
    this thread: it then makes fmi2SetReal of the inputs, fmi2DoStep and fmi2GetReal of ``outputs``
    ((value reference, index in what ``step`` returns)) one Python call per step instead of three through
    pythonfmu; after a step that left messages in ``log_queue`` (pythonfmu's) it has pythonfmu send them,
    as pythonfmu's fmi2DoStep would. The loader holds ``step`` until fmi2FreeInstance or fmi2Reset.
    False: not registered (no loader, pythonfmu's binary alone, in-process): pythonfmu's path, with the
    same results."""
    for library in loader_libraries(resources, ctypes.PyDLL):   # PyDLL: called with the GIL held
        register = getattr(library, "bearingLoaderRegisterStep", None)
        if register is None:
            continue
        register.restype = ctypes.c_int
        register.argtypes = [ctypes.py_object, ctypes.py_object, ctypes.POINTER(ctypes.c_uint), ctypes.c_int,
                             ctypes.POINTER(ctypes.c_uint), ctypes.POINTER(ctypes.c_int), ctypes.c_int]
        n_in, n_out = len(input_vrs), len(outputs)
        if register(step, log_queue, (ctypes.c_uint * n_in)(*input_vrs), n_in,
                    (ctypes.c_uint * n_out)(*(vr for vr, _ in outputs)),
                    (ctypes.c_int * n_out)(*(k for _, k in outputs)), n_out):
            return True
    return False


def register_kernel(resources, load, store) -> bool:
    """Hand the loader the C step's two callables (``bearingLoaderRegisterKernel``, fmu_bearing/native/loader.c,
    "C step"), after ``register_fast_step`` succeeded: ``load()`` gives the constants and state of the step for
    the kernel (None: the Python step), ``store(values)`` takes the kernel's state back before any call the
    loader forwards. False: not registered (no loader, no fast path, or BEARING_FMU_C_STEP=0)."""
    for library in loader_libraries(resources, ctypes.PyDLL):   # PyDLL: called with the GIL held
        register = getattr(library, "bearingLoaderRegisterKernel", None)
        if register is None:
            continue
        register.restype = ctypes.c_int
        register.argtypes = [ctypes.py_object, ctypes.py_object]
        if register(load, store):
            return True
    return False


class _SavedState(dict):
    """A state as fmi2GetFMUstate saved it (a dict of every registered variable plus the life sums), with the
    physics object of the instance that saved it (``bearing``; None before initialisation).

    fmi2SetFMUstate of a state that this instance saved while initialised, and that was never serialized,
    skips the complete check (``_state_problem``: ~0.2 ms, half the cost of a master's rollback): the host
    cannot change an in-memory state (an opaque pointer), its values were this instance's own, and the
    parameters of an initialised instance are fixed (the same ``bearing`` object proves both are the same
    initialisation). Every other state -- deserialized (a plain dict), saved before initialisation, or
    from another instance -- gets the complete check."""

    __slots__ = ("bearing",)


class _TypeAttributes:
    """Mixin: extra attributes (unit, min, max) on the <Real>/<Integer> element, which pythonfmu 0.7 omits."""

    def __init__(self, name, type_attributes=None, **kwargs):
        super().__init__(name, **kwargs)
        self.type_attributes = {k: str(v) for k, v in (type_attributes or {}).items() if v is not None}

    def to_xml(self):
        node = super().to_xml()
        node[0].attrib.update(self.type_attributes)
        return node


class RealVariable(_TypeAttributes, Real):
    pass


class IntegerVariable(_TypeAttributes, Integer):
    pass


class BooleanVariable(_TypeAttributes, Boolean):
    pass


class BallBearing(Fmi2Slave, BearingStepping):
    author = "bearing-cosim contributors"
    description = ("Deep-groove ball bearing with radial clearance (Xu et al., Mech. Mach. Theory 56, 2012): "
                   "force on the housing from the journal eccentricity, per-ball Hertz contact with damping")
    version = "0.1.0"
    license = "MIT"
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=0.1, step_size=1e-5)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        # errors reach the host even with logging off
        self._host_log = HostLogger(kwargs.get("logger"), self.instance_name, kwargs.get("resources"))
        guard_pythonfmu_exit(self.resources)
        try:
            release_on_free(self)                  # the last fmi2FreeInstance undoes the FMU's imports
            self.capacity = read_capacity(self.resources)
        except Exception as err:                   # fmi2Instantiate returns NULL: say why, also with logging off
            self._host_log(3, f"instantiation failed: {err!r}")
            raise
        self._bearing = None                       # physics.BallBearing, built at exit of initialisation
        self._life = None                          # life.LifeAccumulator, built at exit of initialisation
        self._pending_error = None                 # a refused call, reported by the next doStep
        self._terminated = False                   # fmi2Terminate was called: no more steps
        self._loads = [0.0] * self.capacity        # ball_load_k outputs (fixed list object: getters bind to it)
        self._scratch = [0.0] * self.capacity      # evaluate() writes here; copied to _loads on success

        cont, fixed, discrete = Fmi2Variability.continuous, Fmi2Variability.fixed, Fmi2Variability.discrete
        output, calculated = Fmi2Causality.output, Fmi2Initial.calculated   # outputs: computed at initialisation
        for name, unit, desc in INPUTS:
            self._register(RealVariable, name, 0.0, desc, {"unit": unit},
                           causality=Fmi2Causality.input, variability=cont)
        for name, unit, desc in FORCE_OUTPUTS:
            if unit is None:
                self._register(IntegerVariable, name, 0, desc, None,
                               causality=output, variability=discrete, initial=calculated)
            else:
                self._register(RealVariable, name, 0.0, desc, {"unit": unit},
                               causality=output, variability=cont, initial=calculated)
        name, unit, desc = CAGE_ANGLE
        self._register(RealVariable, name, float(BearingParameters().cage_angle_start), desc, {"unit": unit},
                       causality=output, variability=cont, initial=calculated)
        self._empty_life = life.LifeAccumulator(life.LoadRatings.of_bearing(BearingParameters()))
        for name, unit, desc, field in RATING_OUTPUTS:
            self._register(RealVariable, name, float(getattr(self._empty_life.ratings, field)), desc, {"unit": unit},
                           causality=output, variability=discrete, initial=calculated)
        # Life outputs are computed from the accumulator when read (not every step); the FMU state restores
        # the accumulator itself, so their setters ignore the saved values. Weak: see weak_accessors.
        proxy = self.__dict__["_weak_self"]
        for name, unit, desc, prop in LIFE_OUTPUTS:
            self.register_variable(RealVariable(
                name, type_attributes={"unit": unit}, description=desc, causality=output, variability=cont,
                initial=calculated, getter=partial(life_output, proxy, prop), setter=ignore_value))
        # Parameters: one per BearingParameters field, with its default, unit and description;
        # the FMI type follows the default's Python type (bool -> Boolean, int -> Integer, else Real).
        for f in fields(BearingParameters):
            desc = f.metadata.get("description", f.name)
            kwargs = dict(causality=Fmi2Causality.parameter, variability=fixed, initial=Fmi2Initial.exact)
            if isinstance(f.default, bool):
                self._register(BooleanVariable, f.name, bool(f.default), desc, None, **kwargs)
            elif isinstance(f.default, int):
                lo, hi = _INTEGER_RANGES.get(f.name, (None, None))
                if f.name in _INTEGER_RANGES and hi is None:
                    hi = self.capacity
                self._register(IntegerVariable, f.name, int(f.default), desc, {"min": lo, "max": hi}, **kwargs)
            else:
                self._register(RealVariable, f.name, float(f.default), desc,
                               {"unit": f.metadata.get("unit") or None}, **kwargs)
        # Per-ball loads last, so every other value reference is the same for any capacity.
        loads = self._loads
        for k in range(self.capacity):
            self.register_variable(RealVariable(
                f"ball_load_{k + 1}", type_attributes={"unit": "N"},
                description=f"load on ball {k + 1} (0 outside the load zone, and for balls beyond n_balls)",
                causality=output, variability=cont, initial=calculated,
                getter=partial(loads.__getitem__, k), setter=partial(loads.__setitem__, k)))
        assert [self.vars[vr].name for vr in _INPUT_VRS] == [name for name, _, _ in INPUTS]
        # Value reference -> getter/setter maps for the fast paths. Before initialisation every
        # variable may be set (FMI 2.0: initial exact/approx); after it, the inputs only.
        self._real_get = {vr: v.getter for vr, v in self.vars.items() if isinstance(v, Real)}
        self._real_set = self._setters(Real, None)
        self._int_set = self._setters(Integer, None)
        self._bool_set = self._setters(Boolean, None)
        # Last: the loader's fast path (one call per doStep; fmu_bearing/native/loader.c). Outputs: the
        # Real fields of BearingForce, which _fast_step returns.
        vr_of = {v.name: vr for vr, v in self.vars.items()}
        self._fast_path = register_fast_step(
            self.resources, self._fast_step, self.log_queue, _INPUT_VRS,
            [(vr_of[name], k) for k, (name, unit, _) in enumerate(FORCE_OUTPUTS) if unit is not None])
        # The C step (loader.c, "C step"): the value references of the outputs it answers
        loads = [vr_of[f"ball_load_{k + 1}"] for k in range(self.capacity)]
        assert loads == list(range(loads[0], loads[0] + self.capacity)), "ball_load_i: consecutive references"
        self._kernel_vrs = tuple(float(vr_of[name]) for name, _, _ in FORCE_OUTPUTS) + (
            float(vr_of[CAGE_ANGLE[0]]), float(loads[0]))
        self._c_step = self._fast_path and register_kernel(self.resources, self._kernel_load, self._kernel_store)

    # --- registration helpers (build time and instantiation only) ------------------------------
    def _register(self, cls, name, start, description, type_attributes, **kwargs):
        setattr(self, name, start)
        getter, setter = weak_accessors(self, name)
        self.register_variable(cls(name, type_attributes=type_attributes, description=description,
                                   getter=getter, setter=setter, **kwargs))

    def _setters(self, kind, causalities):
        return {vr: v.setter for vr, v in self.vars.items()
                if isinstance(v, kind) and (causalities is None or v.causality in causalities)}

    def to_xml(self, model_options=dict()):
        """pythonfmu's modelDescription plus <UnitDefinitions> and the outputs as <InitialUnknowns>."""
        root = super().to_xml(model_options)
        add_unit_definitions(root, self.vars.values())
        add_initial_unknowns(root, self.vars.values())
        return root

    # --- FMI ----------------------------------------------------------------------------------
    # pythonfmu 0.7 maps a Python exception to fmi2Fatal (there is no route to fmi2Error) and mishandles
    # reference counts on that path (see fmu_bearing.slaves), so the only exception raised here is
    # the one that fails exitInitializationMode. Everything else logs (status error) and returns: a
    # refused doStep returns False (fmi2Discard); a refused set/get call is reported by the next doStep.
    def exit_initialization_mode(self):
        try:
            bearing = physics.BallBearing(self.parameters(), self.capacity)  # validates, names the parameter
            accumulator = self._new_life(bearing.params)
            bearing.check_inputs(self.e_x, self.e_y, self.v_x, self.v_y, self.omega_inner, self.omega_outer)
            # evaluate writes the first n_balls loads only: the rest (a failed earlier initialisation with more
            # balls may have left values there) are 0, as ball_load_k's description says, once initialised
            self._scratch[:] = [0.0] * len(self._scratch)
            message = self._evaluate(float(bearing.params.cage_angle_start), bearing)
            if message is not None:
                raise FloatingPointError(message)
        except Exception as err:
            self._bearing = None
            # To the host directly (also with logging off), not through pythonfmu's queue: pythonfmu then
            # logs the exception itself (logging on) instead of "unknown error" after a queued message.
            self._host_log(3, f"initialisation failed: {err}")
            hold_before_raise(self)  # pythonfmu 0.7 over-releases objects on the exception path
            raise  # -> fmi2ExitInitializationMode returns fmi2Fatal (pythonfmu 0.7 has no route to fmi2Error)
        self._bearing = bearing
        self._life = accumulator
        self._publish_ratings(accumulator.ratings)
        inputs = (Fmi2Causality.input,)
        self._real_set = self._setters(Real, inputs)   # fixed parameters and outputs are read-only now
        self._int_set = self._setters(Integer, inputs)
        self._bool_set = self._setters(Boolean, inputs)

    def do_step(self, current_time, step_size):
        # BearingStepping: check inputs, advance the cage, evaluate, add the end-of-step loads to the life
        reason = self._advance(step_size)
        if reason is not None:
            self._error(f"doStep at t = {current_time!r} s refused: {reason}")
            return False  # pythonfmu 0.7: fmi2Discard; the outputs keep the values of the last good step
        return True

    def _fast_step(self, current_time, step_size, e_x, e_y, v_x, v_y, omega_inner, omega_outer):
        """fmi2SetReal of the six inputs and fmi2DoStep in one call (the loader's fast path): the step's
        BearingForce (the outputs F_x ... max_ball_load), or None when the step is refused."""
        self.e_x, self.e_y, self.v_x, self.v_y, self.omega_inner, self.omega_outer = (
            e_x, e_y, v_x, v_y, omega_inner, omega_outer)
        return self._force if self.do_step(current_time, step_size) else None

    # --- the loader's C step (fmu_bearing/native/loader.c, "C step") --------------------------------
    def _kernel_load(self):
        """What the loader's C step needs, as one flat tuple of numbers (layout: loader.c, kernel_load):
        header (n_balls, capacity, life on, K, half clearance, C, w_inner, w_outer, eccentricity limit,
        p e, p/p e, 2 pi, load angular velocity, value references of the 10 BearingForce outputs, cage_angle,
        ball_load_1), state (cage_angle, the 10 outputs, the life sums, the capacity ball loads), then the ball
        table of BallBearing (cos, sin, cos^2, cos sin, sin^2 per ball) -- the doubles Python computed, so
        the C step's arithmetic starts from the same numbers. None: the Python step does the next step (not
        initialised, terminated, an error to report, or the oil-film damping, which has no C step)."""
        try:
            bearing, accumulator = self._bearing, self._life
            if (bearing is None or self._pending_error is not None or self._terminated
                    or bearing.damping_model not in (DAMPING_NONE, DAMPING_CONSTANT) or bearing._oil is not None
                    or len(self._loads) != self.capacity
                    or (accumulator is not None and accumulator.n_balls != bearing.n_balls)):
                return None
            damping = bearing.damping_coefficient if bearing.damping_model == DAMPING_CONSTANT else 0.0
            sums = accumulator.state() if accumulator is not None else [0.0] * len(life.LifeAccumulator.STATE_FIELDS)
            header = (float(bearing.n_balls), float(self.capacity), 0.0 if accumulator is None else 1.0,
                      bearing.stiffness, bearing.half_clearance, damping, bearing._w_inner, bearing._w_outer,
                      bearing.eccentricity_limit, life.P_STATIONARY, life._CUBE_OF_STATIONARY, life._TWO_PI, 0.0)
            state = (self.cage_angle, self.F_x, self.F_y, self.stiffness_xx, self.stiffness_xy, self.stiffness_yy,
                     self.damping_xx, self.damping_xy, self.damping_yy, float(self.loaded_balls), self.max_ball_load)
            balls = tuple(x for row in bearing._balls for x in row[1:])
            return header + self._kernel_vrs + state + tuple(sums) + tuple(self._loads) + balls
        except Exception:   # never let an exception reach the loader: the Python step then
            return None

    def _kernel_store(self, values, saved_state=False):
        """Take the C step's state (inputs, cage_angle, the 10 BearingForce outputs, life sums, ball loads): the
        slave is then as the Python step would have left it. True, or None on failure (the loader reports it).
        ``saved_state`` true: change nothing, return ``_kernel_saved_state(values)``."""
        if saved_state:
            return self._kernel_saved_state(values)
        try:
            (self.e_x, self.e_y, self.v_x, self.v_y, self.omega_inner, self.omega_outer,
             self.cage_angle) = values[:7]
            f = values[7:17]
            r = physics.BearingForce(*f[:8], int(f[8]), f[9])
            (self.F_x, self.F_y, self.stiffness_xx, self.stiffness_xy, self.stiffness_yy,
             self.damping_xx, self.damping_xy, self.damping_yy, self.loaded_balls, self.max_ball_load) = r
            self._force = r
            if self._life is not None:
                acc = self._life
                acc.sum_cubed_inner, acc.sum_cubed_outer, acc.revolutions, acc.time = values[17:21]
            self._loads[:] = values[21:]   # (not _scratch: evaluate rewrites its first n_balls, never the rest)
            return True
        except Exception:
            return None

    def _kernel_saved_state(self, values):
        """The ``_SavedState`` that ``_get_fmu_state`` would return after ``_kernel_store(values)``, made without
        changing this slave (the loader's state saved in C, handed to pythonfmu: loader.c, "FMU states in C"):
        the parameters and ratings are this instance's current ones (fixed once initialised; the loader makes
        its states pythonfmu's before a reset), the rest comes from ``values``. pythonfmu 0.7's fmi2FMUstate is
        the object ``_get_fmu_state`` returns, so the loader uses the returned object as one. None on failure."""
        try:
            state = _SavedState((var.name, var.getter()) for var in self.vars.values())
            state.bearing = self._bearing
            for (name, _, _), value in zip(INPUTS, values[:6]):
                state[name] = value
            state[CAGE_ANGLE[0]] = values[6]
            f = values[7:17]
            for (name, _, _), value in zip(FORCE_OUTPUTS, physics.BearingForce(*f[:8], int(f[8]), f[9])):
                state[name] = value
            for k, value in enumerate(values[21:]):
                state[f"ball_load_{k + 1}"] = value
            if self._life is not None:
                acc = copy.copy(self._life)
                acc.sum_cubed_inner, acc.sum_cubed_outer, acc.revolutions, acc.time = values[17:21]
                state[LIFE_STATE] = acc.state()
                for name, _, _, prop in LIFE_OUTPUTS:
                    state[name] = float(getattr(acc, prop))
            return state
        except Exception:
            return None

    def terminate(self):
        self._terminated, self._bearing = True, None   # a later doStep is refused (fmi2Discard, logged)

    def _error(self, message):
        """An error message to the host: directly (category logStatusError, also with logging off), else
        through pythonfmu's queue (only with logging on). The FMI logger's message is a printf format."""
        if not self._host_log(3, message):
            self.log(str(message).replace("%", "%%"), Fmi2Status.error)

    # --- fast paths: pythonfmu loops over Fmi2Slave.vars with isinstance checks per value --------
    def get_real(self, vrs):
        get = self._real_get
        try:
            return [get[vr]() for vr in vrs]
        except KeyError:
            return [get[vr]() if vr in get else self._refuse(vr, "Real", 0.0) for vr in vrs]

    def set_real(self, vrs, values):
        if vrs == _INPUT_VRS:  # the master's usual call: all six inputs, in declaration order
            self.e_x, self.e_y, self.v_x, self.v_y, self.omega_inner, self.omega_outer = values
            return
        put = self._real_set
        try:
            for vr, value in zip(vrs, values):
                put[vr](value)
        except KeyError:
            for vr, value in zip(vrs, values):
                put[vr](value) if vr in put else self._refuse(vr, "Real")

    def get_integer(self, vrs):
        return [int(self.vars[vr].getter()) if isinstance(self.vars.get(vr), Integer)
                else self._refuse(vr, "Integer", 0) for vr in vrs]

    def set_integer(self, vrs, values):
        put = self._int_set
        for vr, value in zip(vrs, values):
            put[vr](int(value)) if vr in put else self._refuse(vr, "Integer")

    def get_boolean(self, vrs):
        return [bool(self.vars[vr].getter()) if isinstance(self.vars.get(vr), Boolean)
                else self._refuse(vr, "Boolean", False) for vr in vrs]

    def set_boolean(self, vrs, values):
        put = self._bool_set
        for vr, value in zip(vrs, values):
            put[vr](bool(value)) if vr in put else self._refuse(vr, "Boolean")

    def _refuse(self, vr, kind, value=None):
        """Log a refused get/set (no exception, see above); the next doStep reports it. Returns ``value``."""
        var = self.vars.get(vr)
        if var is None:
            msg = f"no variable with valueReference {vr}"
        elif not isinstance(var, {"Real": Real, "Integer": Integer, "Boolean": Boolean}[kind]):
            msg = f"{var.name} (valueReference {vr}) is not of type {kind}"
        elif var.causality == Fmi2Causality.parameter:
            msg = f"parameter {var.name} is fixed: it cannot be set after initialisation (value ignored)"
        else:
            msg = f"{var.name} is an {var.causality.name}: it cannot be set after initialisation (value ignored)"
        self._error(msg)
        self._pending_error = self._pending_error or msg
        return value

    # --- FMU state: pythonfmu saves every registered variable (inputs, outputs incl. cage_angle, parameters);
    # the life accumulator's sums are added under LIFE_STATE
    def _get_fmu_state(self):
        state = _SavedState((var.name, var.getter()) for var in self.vars.values())
        state.update(self._life_state())
        state.bearing = self._bearing
        return state

    @staticmethod
    def _fmu_state_from_bytes(state):
        return state_from_bytes(Fmi2Slave._fmu_state_from_bytes, state,
                                "fmi2DeSerializeFMUstate: not a serialized BallBearing state")

    def _set_fmu_state(self, state):
        """Restore a state after checking all of it (``fmu_bearing.slaves.state``); a state that is not ours
        is refused with a logged error, the next doStep is refused, and nothing is assigned."""
        try:
            # this instance's own in-memory state, saved since initialisation (the iterated and adaptive
            # masters' rollback, once per step): its values can only be the instance's own valid ones
            own = type(state) is _SavedState and state.bearing is not None and state.bearing is self._bearing
            if own and self._life is not None:
                # its life sums may still be unusable (inf after an overflowing load): checked like any state's
                life.LifeAccumulator(self._life.ratings).restore(state.get(LIFE_STATE) or [])
            problem = None if own else self._state_problem(state)
        except Exception as err:  # no exception may reach pythonfmu's C++ side
            problem = f"not a BallBearing state ({err!r})"
        if problem is not None:
            refuse_state(self, problem)
            return
        for var in self.vars.values():
            if var.setter is not None:
                var.setter(state[var.name])
        if self._life is not None:
            self._life.restore(state.get(LIFE_STATE) or [])
            self._publish_ratings(self._life.ratings)

    def _state_problem(self, state):
        """None if ``state`` is a complete, valid state of this instance, else what is wrong with it."""
        if isinstance(state, dict) and INVALID_STATE in state:
            return str(state[INVALID_STATE])
        fixed = None
        if self._bearing is not None:   # parameters are fixed once initialised: they must be this instance's
            fixed = {name: getattr(self, name) for name in self._param_names}
        kinds = variable_kinds(self)
        kinds.update((name, "Real or inf") for name in life.LIFE_NAMES if name in kinds)   # an unloaded life
        problem = check_state(state, kinds, "BallBearing", fixed, extra=(LIFE_STATE,))
        if problem is not None:
            return problem
        if self._life is not None:   # the life accumulator's sums (same ratings: the parameters are fixed)
            life.LifeAccumulator(self._life.ratings).restore(state.get(LIFE_STATE) or [])
        params = BearingParameters(**{name: state[name] for name in self._param_names})
        validate(params, self.capacity)
        n = int(params.n_balls)
        if not 0 <= state["loaded_balls"] <= n:
            return f"loaded_balls = {state['loaded_balls']!r} is not in [0, n_balls = {n}]"
        negative = [k for k in ["max_ball_load"] + [f"ball_load_{r + 1}" for r in range(self.capacity)]
                    if state[k] < 0.0]
        if negative:
            return f"{negative[0]} = {state[negative[0]]!r} is negative"
        return None
