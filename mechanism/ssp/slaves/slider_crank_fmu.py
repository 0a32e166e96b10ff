"""The SliderCrank co-simulation FMU: the paper's slider-crank (Table 1) as an FMU, for any FMI master.

A thin pythonfmu mapping onto the project's multibody core: ``mechanism.systems.slider_crank.build`` (the
model as data), ``mechanism.multibody.solver.System`` (eq. 3-9), ``mechanism.cosim.joint.BearingLink``
(eq. 10-12 and 20-23), ``mechanism.multibody.integrators.rk4_step`` and ``mechanism.cosim.master.substeps``; the
force model over a step is ``mechanism.cosim.coupling.InterfaceJacobian``. No formula lives here.

Interface (SI): inputs F_x, F_y [N], the force of the bearing on the housing (the crank; the rod
receives -F), and the bearing's tangent matrices stiffness_xx/xy/yy [N/m] and damping_xx/xy/yy
[N.s/m]; outputs the bearing's inputs e_x, e_y [m], v_x, v_y [m/s], omega_inner, omega_outer
[rad/s], and slider_x [m], slider_v [m/s], slider_a [m/s2], crank_angle [rad], crank_moment [N.m];
parameters: the fields of ``SliderCrankParameters`` (Table 1 and rpm) plus three coupling settings.

Step semantics: ``do_step(t, h)`` integrates the mechanism over [t, t + h] with RK4 in equal
substeps (as many as ``master.substeps`` asks for the tangent stiffness and damping), with the force

    F(tau) = F_in + K_in (e(tau) - e_sent) + C_in (v(tau) - v_sent),

where e_sent, v_sent are the outputs this FMU published ``force_lag_steps`` communication points
before t: 1 (default) for a Jacobi master (fmpy.ssp, libcosim, ecos: the bearing computed F_in from
the outputs of the previous communication point), 0 for a Gauss-Seidel master that steps the
bearing after the mechanism. With ``force_drift`` (default true) the model adds d (tau - t), the drift
of the last step's input force that K and C do not explain (mostly the cage turning balls into and
out of the load zone), exactly as the master's default scheme ``jacobian-drift``
(``mechanism.cosim.coupling.InterfaceJacobianDrift``); false gives the plain model above. With the tangent
inputs at 0 (unconnected) and ``force_drift`` false this is a zero-order hold.
Feeding the bearing's own tangent matrices back makes the coupling linearly implicit in any fixed-
step master: the two-FMU system is stable at h = 1e-5 s, where a zero-order hold needs ~1e-7 s.
Outputs describe the end of the step; slider_a and crank_moment are eq. (9)'s accelerations and
driver multiplier there, with the force model evaluated at t + h.

FMU state (get/set/serialize): every registered variable plus the mechanism state q, qd and the
published history, handled explicitly in ``_get_fmu_state``/``_set_fmu_state``.

This file is the FMU's slave module: pythonfmu's binary imports it as a top-level module and finds
the slave class by a regular expression on its source, so it uses absolute imports only and no
``from __future__`` import.
"""
import math
from dataclasses import astuple, fields
from functools import partial
from xml.etree.ElementTree import SubElement

import numpy as np
from pythonfmu import (
    DefaultExperiment,
    Fmi2Causality,
    Fmi2Initial,
    Fmi2Slave,
    Fmi2Variability,
)
from pythonfmu.enums import Fmi2Status

from fmu_bearing.interface import COUPLING_OUTPUTS, JOINT_INPUTS
from fmu_bearing.slaves import (
    add_unit_definitions,
    guard_pythonfmu_exit,
    hold_before_raise,
)
from fmu_bearing.slaves.ball_bearing_fmu import BooleanVariable as _Boolean
from fmu_bearing.slaves.ball_bearing_fmu import IntegerVariable as _Integer
from fmu_bearing.slaves.ball_bearing_fmu import RealVariable as _Real
from fmu_bearing.slaves.state import check_state, finite_rows, variable_kinds
from mechanism.cosim.coupling import (
    Exchanged,
    InterfaceJacobian,
    InterfaceJacobianDrift,
)
from mechanism.cosim.joint import BearingLink
from mechanism.cosim.master import MasterSettings, substeps
from mechanism.multibody.integrators import rk4_step
from mechanism.multibody.solver import System
from mechanism.systems.slider_crank import (
    CRANK,
    SLIDER,
    SliderCrankParameters,
    build,
    initial_state,
)

MODEL_NAME = "SliderCrank"

#: (name, unit, description) of the inputs, in value-reference order: a joint component's coupling
#: outputs (stiffness and damping 0: the force is held, zero-order hold)
INPUTS = COUPLING_OUTPUTS

#: (name, unit, description) of the outputs, in value-reference order: a joint component's inputs first
OUTPUTS = JOINT_INPUTS + (
    ("slider_x", "m", "slider position"),
    ("slider_v", "m/s", "slider velocity"),
    ("slider_a", "m/s2", "slider acceleration (eq. 9 at the end of the step)"),
    ("crank_angle", "rad", "crank angle theta_1"),
    ("crank_moment", "N.m", "driving moment on the crank (the speed constraint's multiplier, Fig. 19)"),
)

#: unit ("" for Boolean) and description of each SliderCrankParameters field
PARAMETER_INFO = {
    "crank_length": ("m", "crank length L1 (Table 1: 50 mm)"),
    "crank_mass": ("kg", "crank mass (Table 1: 0.30 kg)"),
    "crank_inertia": ("kg.m2", "crank moment of inertia about its centre of mass (Table 1: 100 kg mm2)"),
    "rod_length": ("m", "connecting-rod length L2 (Table 1: 120 mm)"),
    "rod_mass": ("kg", "connecting-rod mass (Table 1: 0.21 kg)"),
    "rod_inertia": ("kg.m2", "connecting-rod moment of inertia about its centre of mass (Table 1: 250 kg mm2)"),
    "slider_mass": ("kg", "slider mass (Table 1: 0.14 kg)"),
    "slider_inertia": ("kg.m2", "slider moment of inertia (not in the paper; the slider cannot rotate)"),
    "rpm": ("rev/min", "constant crank speed"),
    "gravity": ("", "gravity -9.81 m/s2 along -y (the paper's example has none)"),
    "housing_radius": ("m", "radius at which the force acts on the housing (eq. 15 option; outer diameter / 2)"),
    "journal_radius": ("m", "radius at which the force acts on the journal (eq. 15 option; bore / 2)"),
}
assert set(PARAMETER_INFO) == {f.name for f in fields(SliderCrankParameters)}, \
    "PARAMETER_INFO out of step with SliderCrankParameters"

#: parameters that must be positive (declared min 0; 0 itself is refused at initialisation)
POSITIVE = ("crank_length", "crank_mass", "crank_inertia", "rod_length", "rod_mass", "rod_inertia",
            "slider_mass", "slider_inertia", "housing_radius", "journal_radius")

_SETTINGS = MasterSettings(t_end=0.0)
#: coupling settings that are not SliderCrankParameters: (name, FMI type, default, min, max, unit, description)
SETTINGS = (
    ("force_lag_steps", "Integer", 1, 0, 1, None,
     "communication steps between the outputs the input force was computed from and the step start: "
     "1 for Jacobi masters (fmpy.ssp, libcosim, ecos), 0 for Gauss-Seidel (bearing steps after the mechanism)"),
    ("force_drift", "Boolean", True, None, None, None,
     "add the extrapolated drift of the input force not explained by the tangent matrices (jacobian-drift)"),
    ("substep_limit", "Real", float(_SETTINGS.substep_limit), 0.0, None, "1",
     "RK4 substeps keep h_sub * (contact frequency + damping rate) below this (master.substeps)"),
    ("max_substeps", "Integer", int(_SETTINGS.max_substeps), 1, None, None, "largest number of RK4 substeps per step"),
)





class SliderCrank(Fmi2Slave):
    author = "bearing-cosim contributors"
    description = ("Slider-crank of Xu et al. (Mech. Mach. Theory 56, 2012), Table 1, with the crank-rod "
                   "joint as a force element: eccentricity out, bearing force and tangent matrices in")
    version = "0.1.0"
    license = "MIT"
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=0.1, step_size=1e-5)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        guard_pythonfmu_exit(self.resources)     # pythonfmu 0.7's exit-time double free (fmu_bearing/slaves)
        self._system = None          # System, BearingLink, ... built at exit of initialisation
        self._pending_error = None   # a refused call, reported by the next doStep
        self._y = None               # mechanism state [q, qd]
        self._published = []         # outputs (e_x, e_y, v_x, v_y) at the last two communication points
        self._param_names = tuple(f.name for f in fields(SliderCrankParameters))
        cont, fixed = Fmi2Variability.continuous, Fmi2Variability.fixed
        for name, unit, desc in INPUTS:
            self._register(_Real, name, 0.0, desc, {"unit": unit},
                           causality=Fmi2Causality.input, variability=cont)
        for name, unit, desc in OUTPUTS:
            self._register(_Real, name, 0.0, desc, {"unit": unit},
                           causality=Fmi2Causality.output, variability=cont, initial=Fmi2Initial.calculated)
        par = dict(causality=Fmi2Causality.parameter, variability=fixed, initial=Fmi2Initial.exact)
        defaults = SliderCrankParameters()
        for f in fields(SliderCrankParameters):
            unit, desc = PARAMETER_INFO[f.name]
            value = getattr(defaults, f.name)
            if isinstance(value, bool):
                self._register(_Boolean, f.name, bool(value), desc, None, **par)
            else:
                attrs = {"unit": unit, "min": 0.0 if (f.name in POSITIVE or f.name == "rpm") else None}
                self._register(_Real, f.name, float(value), desc, attrs, **par)
        for name, kind, default, lo, hi, unit, desc in SETTINGS:
            cls = {"Integer": _Integer, "Boolean": _Boolean}.get(kind, _Real)
            self._register(cls, name, default, desc, {"unit": unit, "min": lo, "max": hi}, **par)

    def _register(self, cls, name, start, description, type_attributes, **kwargs):
        setattr(self, name, start)
        self.register_variable(cls(name, type_attributes=type_attributes, description=description,
                                   getter=partial(getattr, self, name), setter=partial(setattr, self, name),
                                   **kwargs))

    def to_xml(self, model_options=dict()):
        """pythonfmu's modelDescription plus <UnitDefinitions> for every unit the variables use."""
        root = super().to_xml(model_options)
        add_unit_definitions(root, self.vars.values())
        # The outputs are calculated at initialisation (initial="calculated"): list them as InitialUnknowns.
        structure = root.find("ModelStructure")
        initial = SubElement(structure, "InitialUnknowns")
        for index, var in enumerate(self.vars.values(), start=1):
            if var.causality == Fmi2Causality.output:
                SubElement(initial, "Unknown", {"index": str(index)})
        return root

    # --- FMI ----------------------------------------------------------------------------------
    def parameters(self) -> SliderCrankParameters:
        """The current parameter values as SliderCrankParameters."""
        return SliderCrankParameters(**{name: getattr(self, name) for name in self._param_names})

    def exit_initialization_mode(self):
        try:
            self._setup()
        except Exception as err:
            self._system = None
            self._error(f"initialisation failed: {err}")
            hold_before_raise(self)  # pythonfmu 0.7 over-releases objects on the exception path
            raise  # -> fmi2ExitInitializationMode returns an error status

    def _setup(self):
        params = self.parameters()
        for name in POSITIVE:
            value = getattr(params, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"parameter {name} = {value!r} must be positive")
        if not (math.isfinite(params.rpm) and params.rpm >= 0.0):
            raise ValueError(f"parameter rpm = {params.rpm!r} must be >= 0")
        if int(self.force_lag_steps) not in (0, 1):
            raise ValueError(f"parameter force_lag_steps = {self.force_lag_steps!r} must be 0 or 1")
        if not (self.substep_limit > 0.0 and int(self.max_substeps) >= 1):
            raise ValueError("substep_limit must be positive and max_substeps at least 1")
        model = build(params, "bearing")
        system = System(model)
        link = BearingLink(system, model.bearings[0])
        q0, qd0 = initial_state(system, params)
        self._n = system.n
        self._slider = system.slice(SLIDER).start
        self._crank = system.slice(CRANK).start
        self._mobility = link.mobility(q0, 0.0)
        self._system, self._link = system, link
        self._y = np.concatenate((q0, qd0)).astype(float)
        self._scheme = (InterfaceJacobianDrift if self.force_drift else InterfaceJacobian)()
        self._publish(0.0, None)
        self._published = [self._outputs_e_v()]

    def _outputs_e_v(self):
        return (self.e_x, self.e_y, self.v_x, self.v_y)

    def _exchanged(self, t, sent):
        """The inputs as the coupling's Exchanged record, continued from the outputs ``sent``."""
        return Exchanged(t, *sent, self.F_x, self.F_y, self.stiffness_xx, self.stiffness_xy, self.stiffness_yy,
                         self.damping_xx, self.damping_xy, self.damping_yy)

    def _generalized_force(self, q, qd, tau):
        s, link = self._system, self._link
        ex, ey, vx, vy, _, _ = link.inputs(q, qd)
        Fx, Fy = self._scheme.force(tau, ex, ey, vx, vy)
        return s.applied_forces(q, qd, tau) + link.generalized_force(q, ex, ey, Fx, Fy)

    def _rhs(self, tau, y):
        n = self._n
        q, qd = y[:n], y[n:]
        qdd = self._system.accelerations(q, qd, tau, self._generalized_force(q, qd, tau))[0]
        return np.concatenate((qd, qdd))

    def _publish(self, t, exchanged):
        """Set the outputs from the state at time t (force model ``exchanged`` for slider_a, crank_moment;
        None: the inputs continued from these outputs)."""
        n, s = self._n, self._system
        q, qd = self._y[:n], self._y[n:]
        (self.e_x, self.e_y, self.v_x, self.v_y,
         self.omega_inner, self.omega_outer) = self._link.inputs(q, qd)
        if exchanged is None:  # initialisation: the start inputs, continued from the start outputs
            exchanged = self._exchanged(t, self._outputs_e_v())
            self._scheme.push(exchanged)
            self._scheme.begin_step(t, 0.0)
        qdd, lam = s.accelerations(q, qd, t, self._generalized_force(q, qd, t))
        self.slider_x, self.slider_v = float(q[self._slider]), float(qd[self._slider])
        self.slider_a = float(qdd[self._slider])
        self.crank_angle = float(q[self._crank + 2])
        self.crank_moment = s.driving_moment(lam, "crank_driver")

    def do_step(self, current_time, step_size):
        if self._system is None or self._pending_error is not None:
            reason = self._pending_error or "the instance is not initialised"
            self._pending_error = None
            return self._refuse_step(current_time, reason)
        try:
            return self._step(float(current_time), float(step_size))
        except Exception as err:  # never let an exception reach pythonfmu's C++ side
            return self._refuse_step(current_time, f"{type(err).__name__}: {err}")

    def _step(self, t, h):
        if not h >= 0.0:
            return self._refuse_step(t, f"step size {h!r} is not >= 0")
        inputs = (self.F_x, self.F_y, self.stiffness_xx, self.stiffness_xy, self.stiffness_yy,
                  self.damping_xx, self.damping_xy, self.damping_yy)
        if not all(math.isfinite(v) for v in inputs):
            return self._refuse_step(t, f"non-finite input {inputs}")
        lag = int(self.force_lag_steps)
        sent = self._published[0] if lag == 1 else self._published[-1]
        x = self._exchanged(t, sent)
        if self._scheme.past and self._scheme.past[-1].t >= t:   # a step repeated from an earlier time
            self._scheme.past.clear()
        self._scheme.push(x)
        self._scheme.begin_step(t, h)
        m = substeps(h, x, self._mobility, float(self.substep_limit), int(self.max_substeps)) if h > 0 else 1
        hs = h / m
        y = self._y
        for k in range(m):
            y = rk4_step(self._rhs, t + k * hs, y, hs)
        if not np.all(np.isfinite(y)):
            return self._refuse_step(t, "the mechanism state is not finite (the integration diverged)")
        drift = float(np.max(np.abs(self._system.phi(y[:self._n], t + h))))
        if drift > _SETTINGS.max_constraint_violation:
            return self._refuse_step(t, f"constraint violation {drift:.3g} exceeds "
                                        f"{_SETTINGS.max_constraint_violation:g} (the integration diverged)")
        current = self._published[-1]
        self._y = y
        self._publish(t + h, x)
        self._published = [current, self._outputs_e_v()]
        return True

    def _refuse_step(self, current_time, reason):
        self._error(f"doStep at t = {current_time!r} s refused: {reason}")
        return False  # pythonfmu 0.7: fmi2Discard; the outputs keep the values of the last good step

    def _error(self, message):
        self.log(str(message).replace("%", "%%"), Fmi2Status.error)  # the FMI logger's message is a format

    # --- FMU state: the registered variables plus the mechanism state and the published history ----
    def _get_fmu_state(self):
        state = super()._get_fmu_state()
        state["_y"] = None if self._y is None else [float(v) for v in self._y]
        state["_published"] = [list(p) for p in self._published]
        state["_history"] = [list(astuple(x)) for x in self._scheme.past] if self._system is not None else []
        return state

    def _set_fmu_state(self, state):
        """Restore a state after checking all of it (``fmu_bearing.slaves.state``): the registered variables,
        the mechanism state, the published outputs and the coupling history. A state that is not ours is
        refused with a logged error, the next doStep is refused, and nothing is assigned."""
        try:
            problem = self._state_problem(state)
        except Exception as err:  # no exception may reach pythonfmu's C++ side
            problem = f"not a SliderCrank state ({err!r})"
        if problem is not None:
            message = f"setFMUstate refused: {problem}; the instance is unchanged"
            self._error(message)
            self._pending_error = self._pending_error or message
            return
        for var in self.vars.values():
            if var.setter is not None:
                var.setter(state[var.name])
        self._published = [tuple(p) for p in state["_published"]]
        if self._system is not None:
            self._y = np.array(state["_y"], float)
            self._scheme.past.clear()
            for x in state["_history"]:
                self._scheme.push(Exchanged(*x))
            if self._scheme.past:
                self._scheme.begin_step(self._scheme.past[-1].t, 0.0)

    def _state_problem(self, state):
        """None if ``state`` is a complete, valid state of this instance, else what is wrong with it."""
        if isinstance(state, dict) and "_invalid" in state:
            return str(state["_invalid"])
        started = self._system is not None
        fixed = None
        if started:   # parameters and settings are fixed once initialised
            fixed = {v.name: getattr(self, v.name) for v in self.vars.values()
                     if v.causality == Fmi2Causality.parameter}
        problem = check_state(state, variable_kinds(self), "SliderCrank", fixed,
                              extra=("_y", "_published", "_history"))
        if problem is not None:
            return problem
        missing = [k for k in ("_y", "_published", "_history") if k not in state]
        if missing:
            return f"not a SliderCrank state: no value for {missing[0]!r}"
        y, width = state["_y"], len(fields(Exchanged))
        if started and not finite_rows([y], 2 * self._n, 1):
            return f"_y is not the mechanism state of {2 * self._n} finite numbers"
        if not started and y is not None:
            return "a state of an initialised instance cannot be set before initialisation"
        if not finite_rows(state["_published"], 4, 2):
            return "_published is not a list of at most two (e_x, e_y, v_x, v_y) rows of finite numbers"
        history = state["_history"]
        if not finite_rows(history, width, self._scheme.past.maxlen if started else 0):
            return f"_history is not a list of coupling records ({width} finite numbers each)"
        return None

    @staticmethod
    def _fmu_state_from_bytes(state):
        try:
            return Fmi2Slave._fmu_state_from_bytes(state)
        except Exception as err:  # no exception may reach pythonfmu's C++ side
            return {"_invalid": f"fmi2DeSerializeFMUstate: not a serialized SliderCrank state ({err!r})"}
