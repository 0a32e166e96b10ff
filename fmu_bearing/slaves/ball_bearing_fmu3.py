"""The BallBearing3 co-simulation FMU (FMI 3.0): a thin pythonfmu3 mapping of FMU variables onto ``fmu_bearing``.

The same physics, inputs, coupling outputs and parameters as the FMI 2.0 ``BallBearing`` FMU
(``ball_bearing_fmu.py``, docs/fmu-interface.md); only the variable mapping differs:

* the per-ball loads are ONE array output ``ball_loads`` [N] whose size is the structural parameter
  ``n_balls`` (FMI 3.0 ``<Dimension valueReference=...>``), so the FMU has no per-ball capacity;
* ``n_balls`` is a ``UInt64`` structural parameter (the type FMI 3.0 dimension sizes are read as), the other
  integers ``Int32``; every unit is registered in ``<UnitDefinitions>`` (pythonfmu3 writes none by itself);
* outputs are ``initial="calculated"``: they are computed when initialisation ends.

The bearing-life outputs are the FMI 2.0 FMU's (docs/bearing-life.md, ``fmu_bearing.life``): the load ratings
computed at initialisation, the life accumulated per step from the end-of-step loads (``BearingStepping``), +inf
before any ball is loaded, the accumulator's sums in the FMU state (checked with the rest before any assignment).

All physics lives in ``fmu_bearing.ball_bearing`` (``BallBearing``: ``check_inputs``, ``advance_cage``,
``evaluate``) and ``fmu_bearing.parameters``; this module only declares variables and calls those.
Step semantics are those of the FMI 2.0 FMU: ``do_step`` checks the inputs, advances the cage angle over
[t, t + h] with the inputs held and evaluates the force law at the new cage angle; a refused step returns
``fmi3Discard`` with a logger message and leaves the outputs of the last good step.

pythonfmu3 0.3.4 maps any Python exception to ``fmi3Fatal`` and then releases the slave's objects twice
(once in its error handler, once in the instance's destructor), like pythonfmu 0.7. So no callback here
lets an exception escape except ``exit_initialization_mode`` on invalid parameters, which parks extra
references first (``hold_before_raise``): ``fmi3ExitInitializationMode`` then returns ``fmi3Fatal`` (the
only non-OK status pythonfmu3 can give that call) after a logger message naming the parameter.

Only the standard library and pythonfmu3's own pure-Python modules are imported at run time (pythonfmu3
imports numpy for array variables unless they bring their own getter and setter, which these do).

pythonfmu3's binary imports the FMU's slave module as a top-level module and finds the class by a regular
expression on its source lines (the first class statement deriving from Fmi3Slave), so no other line may look
like one; this file uses absolute imports only and no ``from __future__`` import. In the built FMU the slave
module is a shim (build_fmu.py, ``SHIM3``) that imports this class from the FMU's private copy of this
package, and after a last fmi3FreeInstance puts the released modules back instead of importing them again
(issue 14; docs/robustness.md, Memory); a package that cannot be imported fails the instantiation there too.
"""
import ctypes
import math
import sys
import weakref
from dataclasses import fields
from functools import partial

from pythonfmu3 import (Boolean, DefaultExperiment, Dimension, Fmi3Causality, Fmi3Initial, Fmi3Slave,
                        Fmi3Status, Fmi3StepResult, Fmi3Variability, Float64, Int32, UInt64, Unit)

# The physics package is imported in a guard: if this module failed to import, pythonfmu3 0.3.4 would go on
# with a NULL module (its PyErr_Print clears the error it then checks) and crash the host. A failure is
# raised instead when the instance is created, which fmi3InstantiateCoSimulation turns into NULL after a
# logger message naming the cause.
try:
    from fmu_bearing import ball_bearing as physics
    from fmu_bearing import life
    from fmu_bearing.interface import COUPLING_OUTPUTS, JOINT_INPUTS
    from fmu_bearing.parameters import BearingParameters, validate
    from fmu_bearing.slaves import (INVALID_STATE, UNIT_DEFINITIONS, guard_pythonfmu_exit, hold_before_raise,
                                    release_on_free, state_from_bytes, weak_accessors)
    from fmu_bearing.slaves.state import check_state
    from fmu_bearing.slaves.stepping import LIFE_STATE, BearingStepping, ignore_value, life_output
    _IMPORT_ERROR = None
except Exception as _err:  # noqa: BLE001 - reported at instantiation
    _IMPORT_ERROR = _err
    BearingStepping, COUPLING_OUTPUTS, JOINT_INPUTS = object, (), ()

#: outputs in the order of physics.BearingForce, (name, unit, description); unit None: Int32
FORCE_OUTPUTS = COUPLING_OUTPUTS + (
    ("loaded_balls", None, "number of balls carrying load"),
    ("max_ball_load", "N", "largest ball load"),
)
assert _IMPORT_ERROR is not None or len(FORCE_OUTPUTS) == len(physics.BearingForce._fields), \
    "FORCE_OUTPUTS out of step with BearingForce"

CAGE_ANGLE = ("cage_angle", "rad",
              "angle of ball 1 (ball r at cage_angle + 2 pi (r-1)/n_balls), time integral of the cage speed (eq. 16)")
BALL_LOADS = ("ball_loads", "N", "load on ball r = 1..n_balls (0 outside the load zone), end of step (eq. 18)")

#: upper bound of n_balls (declared as its max): keeps a mistyped value from allocating without limit
MAX_BALLS = 10_000
#: Int32 parameters: (min, max)
_INT_RANGES = {"damping_model": (0, 2)}

_INPUT_VRS = list(range(len(JOINT_INPUTS)))
#: extra key of a saved state: whether the instance was initialised
_INITIALISED = "__initialised__"


class _Attributes:
    """Mixin: extra XML attributes (min, max) on a variable element, which pythonfmu3 0.3.4 does not write."""

    def __init__(self, name, attributes=None, **kwargs):
        super().__init__(name, **kwargs)
        self.attributes = {k: str(v) for k, v in (attributes or {}).items() if v is not None}

    def to_xml(self):
        node = super().to_xml()
        node.attrib.update(self.attributes)
        return node


class Float64Variable(_Attributes, Float64):
    pass


class Int32Variable(_Attributes, Int32):
    pass


class UInt64Variable(_Attributes, UInt64):
    pass


class BooleanVariable(_Attributes, Boolean):
    pass


class Float64Array(Float64):
    """A Float64 array variable that needs no numpy: pythonfmu3 imports numpy for any ``dimensions`` given to
    its constructor (for its default getter/setter); this one gets its dimensions afterwards and must be
    registered with its own getter and setter."""

    def __init__(self, name, dimensions, **kwargs):
        super().__init__(name, **kwargs)
        self._dimensions = list(dimensions)


class NamedUnit(Unit):
    """A unit declared by name only (no integer base-unit exponents, e.g. N/m1.5)."""

    def to_xml(self):
        node = super().to_xml()
        for child in list(node):
            node.remove(child)
        return node


#: units only this FMU uses (the time of the independent variable)
_OWN_UNITS = {"s": {"s": 1}}


def unit_definitions(names):
    """pythonfmu3 Units for the unit names used, with the SI exponents of fmu_bearing.slaves.UNIT_DEFINITIONS."""
    units = []
    for name in sorted(names):
        exponents = _OWN_UNITS[name] if name in _OWN_UNITS else UNIT_DEFINITIONS[name]
        units.append(NamedUnit(name) if exponents is None else Unit(name, **exponents))
    return units


class BallBearing3(Fmi3Slave, BearingStepping):
    """Deep-groove ball bearing with radial clearance (Xu et al. 2012), FMI 3.0 co-simulation."""

    TERMINATE_CALL = "fmi3Terminate"

    def __init__(self, **kwargs):
        if _IMPORT_ERROR is not None:
            raise ImportError(f"BallBearing3 cannot import its physics from the FMU's resources: {_IMPORT_ERROR!r} "
                              f"(Python {sys.version.split()[0]} at {sys.executable})")
        super().__init__(**kwargs)
        release_on_free(self)   # the last fmi3FreeInstance removes the sealed modules and the sys.path entry
        guard_pythonfmu_exit(self.resources)   # pythonfmu3's binary double-frees its state object at exit
        self.author = "bearing-cosim contributors"
        self.description = ("Deep-groove ball bearing with radial clearance (Xu et al., Mech. Mach. Theory 56, "
                            "2012): force on the housing from the journal eccentricity, per-ball Hertz contact "
                            "with damping; per-ball loads as an array sized by n_balls")
        self.version = "0.1.0"
        self.license = "MIT"
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=0.1, step_size=1e-5)

        self._bearing = None           # physics.BallBearing, built at exit of initialisation
        self._life = None              # life.LifeAccumulator, built at exit of initialisation
        self._terminated = False       # fmi3Terminate was called: no more steps
        self._pending_error = None     # a refused call, reported by the next doStep
        defaults = BearingParameters()
        self._resize_loads(int(defaults.n_balls))      # ball_loads: always n_balls long
        units = set()

        cont, fixed, discrete = Fmi3Variability.continuous, Fmi3Variability.fixed, Fmi3Variability.discrete
        output, calculated, exact = Fmi3Causality.output, Fmi3Initial.calculated, Fmi3Initial.exact
        for name, unit, desc in JOINT_INPUTS:
            self._register(Float64Variable, name, 0.0, desc, unit=unit,
                           causality=Fmi3Causality.input, variability=cont)
            units.add(unit)
        for name, unit, desc in FORCE_OUTPUTS + (CAGE_ANGLE,):
            start = float(defaults.cage_angle_start) if name == "cage_angle" else 0.0
            if unit is None:
                self._register(Int32Variable, name, 0, desc, causality=output, variability=discrete,
                               initial=calculated)
            else:
                self._register(Float64Variable, name, start, desc, unit=unit, causality=output,
                               variability=cont, initial=calculated)
                units.add(unit)
        # Bearing life (fmu_bearing.life): the ratings are set at initialisation; the life outputs are read from
        # the accumulator (an empty one before initialisation), and the FMU state restores the accumulator itself.
        me = weakref.proxy(self)   # the accessors must not keep the slave alive (release_on_free)
        self._empty_life = life.LifeAccumulator(life.LoadRatings.of_bearing(defaults))
        for name, unit, desc, field in life.RATING_OUTPUTS:
            self._register(Float64Variable, name, float(getattr(self._empty_life.ratings, field)), desc, unit=unit,
                           causality=output, variability=discrete, initial=calculated)
            units.add(unit)
        for name, unit, desc, prop in life.LIFE_OUTPUTS:
            self.register_variable(Float64Variable(
                name, description=desc, unit=unit, causality=output, variability=cont, initial=calculated,
                getter=partial(life_output, me, prop), setter=ignore_value))
            units.add(unit)
        # Parameters: one per BearingParameters field, with its default, unit and description; the FMI type
        # follows the default's Python type (bool -> Boolean, int -> Int32, else Float64); n_balls, which sizes
        # ball_loads, is a UInt64 structural parameter.
        for f in fields(BearingParameters):
            desc = f.metadata.get("description", f.name)
            kw = dict(causality=Fmi3Causality.parameter, variability=fixed, initial=exact)
            if f.name == "n_balls":
                desc = "number of balls N_b, the size of ball_loads (structural parameter)"
                kw["causality"] = Fmi3Causality.structuralParameter
                self._n_balls_vr = len(self.vars)
                self._register(UInt64Variable, f.name, int(f.default), desc, {"min": 3, "max": MAX_BALLS}, **kw)
            elif isinstance(f.default, bool):
                self._register(BooleanVariable, f.name, bool(f.default), desc, **kw)
            elif isinstance(f.default, int):
                lo, hi = _INT_RANGES.get(f.name, (None, None))
                self._register(Int32Variable, f.name, int(f.default), desc, {"min": lo, "max": hi}, **kw)
            else:
                unit = f.metadata.get("unit") or None
                self._register(Float64Variable, f.name, float(f.default), desc, unit=unit, **kw)
                units.add(unit)
        name, unit, desc = BALL_LOADS
        self._loads_vr = len(self.vars)
        self.register_variable(Float64Array(
            name, [Dimension(valueReference=str(self._n_balls_vr))], unit=unit, description=desc,
            causality=output, variability=cont, initial=calculated,
            getter=lambda: list(me._loads), setter=lambda values: me._set_loads(values)))
        # FMI 3.0 requires exactly one independent variable: the time, at the end of the last step
        self.time = 0.0
        self._register(Float64Variable, "time", 0.0, "simulation time", unit="s",
                       causality=Fmi3Causality.independent, variability=cont)
        units.add("s")
        self.register_units(unit_definitions(u for u in units if u))
        assert [self.vars[vr].name for vr in _INPUT_VRS] == [n for n, _, _ in JOINT_INPUTS]

        # value reference -> getter / setter; before initialisation every parameter and input may be set,
        # after it the inputs only
        self._get = {vr: v.getter for vr, v in self.vars.items()}
        self._set = {vr: v.setter for vr, v in self.vars.items()
                     if v.causality in (Fmi3Causality.input, Fmi3Causality.parameter,
                                        Fmi3Causality.structuralParameter)}
        self._kind = {vr: next(k for k in ("Float64", "Int32", "UInt64", "Boolean") if isinstance(v, _TYPES[k]))
                      for vr, v in self.vars.items()}
        by_name = {v.name: vr for vr, v in self.vars.items()}
        self._coupling_vrs = [by_name[n] for n, _, _ in COUPLING_OUTPUTS]
        assert [self.vars[vr].name for vr in self._coupling_vrs[:2]] == ["F_x", "F_y"]

    # --- registration helpers (build time and instantiation only) ------------------------------
    def _register(self, cls, name, start, description, attributes=None, unit=None, **kwargs):
        setattr(self, name, start)
        extra = {"unit": unit} if unit else {}
        getter, setter = weak_accessors(self, name)   # no reference cycle: the slave dies with fmi3FreeInstance
        self.register_variable(cls(name, attributes=attributes, description=description,
                                   getter=getter, setter=setter, **extra, **kwargs))

    def _set_loads(self, values):  # FMU state only (outputs cannot be set through the FMI API)
        self._resize_loads(len(values))
        self._loads[:] = [float(x) for x in values]

    def _resize_loads(self, n):
        """ball_loads and the buffer evaluate() writes into, n_balls long (empty for an invalid n_balls)."""
        n = n if 0 <= n <= MAX_BALLS else 0
        self._loads, self._scratch = [0.0] * n, [0.0] * n

    # --- FMI ----------------------------------------------------------------------------------
    def exit_initialization_mode(self):
        try:
            if not 3 <= self.n_balls <= MAX_BALLS:
                raise ValueError(f"invalid parameter n_balls = {self.n_balls}: must lie in [3, {MAX_BALLS}]")
            bearing = physics.BallBearing(self.parameters())  # validates, names the parameter
            accumulator = self._new_life(bearing.params)
            bearing.check_inputs(self.e_x, self.e_y, self.v_x, self.v_y, self.omega_inner, self.omega_outer)
            message = self._evaluate(float(bearing.params.cage_angle_start), bearing)
            if message is not None:
                raise FloatingPointError(message)
        except Exception as err:
            self._bearing = None
            self._error(f"initialisation failed: {err}")
            hold_before_raise(self)  # pythonfmu3 over-releases objects on the exception path
            raise  # -> fmi3ExitInitializationMode returns fmi3Fatal (pythonfmu3 has no route to fmi3Error)
        self._bearing, self._life = bearing, accumulator
        self._publish_ratings(accumulator.ratings)
        self._set = {vr: v.setter for vr, v in self.vars.items() if v.causality == Fmi3Causality.input}

    def do_step(self, current_time, step_size):
        # BearingStepping: check inputs, advance the cage, evaluate, add the end-of-step loads to the life
        reason = self._advance(step_size)
        if reason is not None:
            self._error(f"doStep at t = {current_time!r} s refused: {reason}")
            return Fmi3StepResult(status=Fmi3Status.discard)  # the outputs keep the values of the last good step
        self.time = current_time + step_size
        return Fmi3StepResult()

    def terminate(self):
        self._terminated, self._bearing = True, None   # a later doStep is refused (fmi3Discard, logged)

    def _error(self, message):
        self.log(str(message), Fmi3Status.error)

    # --- get/set: no exception may escape (see the module docstring) ---------------------------
    def _values(self, vrs, kind, default):
        out = []
        get, kinds = self._get, self._kind
        for vr in vrs:
            if kinds.get(vr) != kind:
                out.append(self._refuse(vr, kind, default))
            elif vr == self._loads_vr:
                out.extend(self._loads)
            else:
                out.append(get[vr]())
        return out

    def get_float64(self, vrs):
        if vrs == self._coupling_vrs:  # the master's usual call: the coupling outputs, in declaration order
            return [self.F_x, self.F_y, self.stiffness_xx, self.stiffness_xy, self.stiffness_yy,
                    self.damping_xx, self.damping_xy, self.damping_yy]
        return [float(x) for x in self._values(vrs, "Float64", 0.0)]

    def get_int32(self, vrs):
        return [int(x) for x in self._values(vrs, "Int32", 0)]

    def get_uint64(self, vrs):
        return [ctypes.c_uint64(max(int(x), 0)) for x in self._values(vrs, "UInt64", 0)]

    def get_boolean(self, vrs):
        return [bool(x) for x in self._values(vrs, "Boolean", False)]

    def set_float64(self, vrs, values):
        if vrs == _INPUT_VRS and len(values) == 6:  # the master's usual call: all six inputs, in order
            self.e_x, self.e_y, self.v_x, self.v_y, self.omega_inner, self.omega_outer = values
            return
        self._assign(vrs, values, "Float64", float)

    def set_int32(self, vrs, values):
        self._assign(vrs, values, "Int32", int)

    def set_uint64(self, vrs, values):
        self._assign(vrs, values, "UInt64", int)

    def set_boolean(self, vrs, values):
        self._assign(vrs, values, "Boolean", bool)

    def _assign(self, vrs, values, kind, convert):
        """Scalar variables only (the one array, ball_loads, is an output)."""
        if len(values) != len(vrs):
            self._refuse(None, kind, message=f"set{kind}: {len(values)} values for {len(vrs)} value references")
            return
        put, kinds = self._set, self._kind
        for vr, value in zip(vrs, values):
            if kinds.get(vr) != kind or vr not in put:
                self._refuse(vr, kind)
            elif vr == self._n_balls_vr:
                self.n_balls = convert(value)
                self._resize_loads(self.n_balls)  # an invalid n_balls is refused at initialisation
            else:
                put[vr](convert(value))

    def _refuse(self, vr, kind, value=None, message=None):
        """Log a refused get/set (no exception, see above); the next doStep reports it. Returns ``value``."""
        var = self.vars.get(vr)
        if message is not None:
            msg = message
        elif var is None:
            msg = f"no variable with valueReference {vr}"
        elif self._kind.get(vr) != kind:
            msg = f"{var.name} (valueReference {vr}) is not of type {kind}"
        elif var.causality in (Fmi3Causality.parameter, Fmi3Causality.structuralParameter):
            msg = f"parameter {var.name} is fixed: it cannot be set after initialisation (value ignored)"
        else:
            msg = f"{var.name} is an {var.causality.name}: it cannot be set (value ignored)"
        self._error(msg)
        self._pending_error = self._pending_error or msg
        return value

    # --- FMU state: every variable, whether the instance is initialised, the life accumulator's sums ----
    def _get_fmu_state(self):
        state = {v.name: v.getter() for v in self.vars.values()}
        state[_INITIALISED] = self._bearing is not None
        state.update(self._life_state())
        return state

    @staticmethod
    def _fmu_state_from_bytes(state):
        return state_from_bytes(Fmi3Slave._fmu_state_from_bytes, state,
                                "fmi3DeserializeFMUState: not a serialized BallBearing3 state")

    def _set_fmu_state(self, state):
        """Check the whole state (names, types, parameters, array size, life sums) before assigning any of it."""
        try:
            message = state.get(INVALID_STATE) if isinstance(state, dict) else "not a BallBearing3 state"
            if message is None:
                values, bearing, accumulator = self._check_state(state)
        except Exception as err:
            message = f"setFMUState: invalid state ({err!r})"
        if message is not None:
            self._error(message)
            self._pending_error = self._pending_error or message
            return
        for name, value in values.items():
            if name != "ball_loads" and name not in _LIFE_NAMES:   # life outputs: from the accumulator
                setattr(self, name, value)
        self._set_loads(values["ball_loads"])
        self._bearing, self._life = bearing, accumulator
        if accumulator is not None:
            self._publish_ratings(accumulator.ratings)
        self._set = {vr: v.setter for vr, v in self.vars.items()
                     if v.causality == Fmi3Causality.input or bearing is None and v.causality in
                     (Fmi3Causality.parameter, Fmi3Causality.structuralParameter)}

    def _check_state(self, state):
        """(values to assign, bearing, accumulator) of a state that is completely this instance's, else raise
        ValueError naming the first problem. Nothing is converted: a value of the wrong type (a string, a
        float in an Int32 or UInt64, a number in a Boolean) is refused, as are unknown keys, NaN and
        infinity (JSON carries both; a life output may be infinite), another ``n_balls`` (it sizes
        ``ball_loads``: a state of another instance), and, once initialised, other parameter values."""
        kinds = {v.name: "Real or inf" if v.name in _LIFE_NAMES else _STATE_KINDS[self._kind[vr]]
                 for vr, v in self.vars.items() if vr != self._loads_vr}
        fixed = {"n_balls": self.n_balls}
        if self._bearing is not None:   # parameters are fixed once initialised: they must be this instance's
            fixed.update((name, getattr(self, name)) for name in self._param_names)
        problem = check_state(state, kinds, "BallBearing3", fixed, extra=(BALL_LOADS[0], _INITIALISED, LIFE_STATE))
        if problem is None and type(state.get(_INITIALISED)) is not bool:
            problem = f"not a BallBearing3 state of this build: no Boolean {_INITIALISED!r}"
        loads = state.get(BALL_LOADS[0]) if problem is None else None
        if problem is None and not (isinstance(loads, list) and len(loads) == self.n_balls):
            problem = f"ball_loads = {loads!r} is not a list of n_balls = {self.n_balls} values"
        if problem is None:
            bad = [x for x in loads if type(x) not in (int, float) or not math.isfinite(x) or x < 0.0]
            if bad:
                problem = f"ball_loads holds {bad[0]!r}: " + ("not finite" if type(bad[0]) in (int, float)
                                                               and not math.isfinite(bad[0]) else
                                                               "not a load >= 0 N")
        if problem is not None:
            raise ValueError(problem)
        values = {name: float(state[name]) if kind.startswith("Real") else state[name]
                  for name, kind in kinds.items()}
        values[BALL_LOADS[0]] = [float(x) for x in loads]
        params = BearingParameters(**{name: values[name] for name in self._param_names})
        validate(params, MAX_BALLS)
        bearing = accumulator = None
        if state[_INITIALISED]:
            bearing = (self._bearing if self._bearing is not None and self._bearing.params == params
                       else physics.BallBearing(params))
            accumulator = self._restored_life(params, state.get(LIFE_STATE))
        if len(values["ball_loads"]) != params.n_balls:
            raise ValueError(f"{len(values['ball_loads'])} ball loads for n_balls = {params.n_balls}")
        return values, bearing, accumulator


#: FMI 3.0 type -> the kind ``fmu_bearing.slaves.state.check_state`` checks a saved value against
_STATE_KINDS = {"Float64": "Real", "Int32": "Integer", "UInt64": "Integer", "Boolean": "Boolean"}
_LIFE_NAMES = frozenset(name for name, _, _, _ in life.LIFE_OUTPUTS) if _IMPORT_ERROR is None else frozenset()
_TYPES = {"Float64": Float64, "Int32": Int32, "UInt64": UInt64, "Boolean": Boolean}
