"""The JournalClearance co-simulation FMU: a thin pythonfmu mapping of FMU variables onto ``fmu_bearing``.

The comparison model of Xu et al. (2012), Fig. 23-25: a journal in a bushing with radial clearance
and the Lankarani-Nikravesh contact force. All physics lives in ``fmu_bearing.clearance_joint``
(force law, contact state, input checks, parameters with units and descriptions); this module only
declares the FMI variables and calls those functions. It is a drop-in replacement for the
BallBearing FMU (``ball_bearing_fmu``): the same six inputs (the ring speeds are accepted and
ignored) and the same F_x, F_y, stiffness_* and damping_* outputs, plus ``stiffness_skew``,
``penetration`` and ``contact_force``.

Step semantics: ``do_step(t, h)`` checks the inputs, advances the contact state to the held inputs
(a contact that begins records its normal approach speed) and evaluates the force law there, so
every output describes the END of the step. The contact state (``in_contact``,
``impact_velocity``) is a registered output, so fmi2GetFMUstate / fmi2SetFMUstate and their
serialised forms restore it with everything else. On an error the message goes to the FMI logger
(status error, category logStatusError, also when logging is off) and the step returns a non-OK status
(pythonfmu 0.7: fmi2Discard), leaving outputs and state of the last good step untouched, so the master
may restore and retry; a doStep after fmi2Terminate is refused the same way. The outputs are computed
in fmi2ExitInitializationMode and declared initial="calculated" (InitialUnknowns).

As in ``ball_bearing_fmu``: pythonfmu finds the class by the literal text
``class JournalClearance(Fmi2Slave):`` and imports this file as a top-level module, so it uses
absolute imports only (and no ``from __future__`` import). The variable classes with units and the
unit table are imported from ``ball_bearing_fmu``.
"""
import math
from dataclasses import fields

from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability
from pythonfmu.enums import Fmi2Status

from fmu_bearing import clearance_joint as physics
from fmu_bearing.ball_bearing import BearingInputError
from fmu_bearing.clearance_joint import ClearanceParameters, ContactState
from fmu_bearing.interface import COUPLING_OUTPUTS, JOINT_INPUTS
from fmu_bearing.slaves import (INVALID_STATE, HostLogger, add_initial_unknowns, add_unit_definitions,
                                guard_pythonfmu_exit, hold_before_raise, refuse_state, release_on_free,
                                state_from_bytes, weak_accessors)
from fmu_bearing.slaves.ball_bearing_fmu import BooleanVariable, RealVariable
from fmu_bearing.slaves.state import check_state, variable_kinds

#: (name, unit, description) of the inputs, in value-reference order: those of the BallBearing FMU
#: (the ring speeds are unused here; present so the FMUs are drop-in replacements)
INPUTS = JOINT_INPUTS

#: outputs in the order of physics.ClearanceForce, (name, unit, description)
FORCE_OUTPUTS = COUPLING_OUTPUTS + (
    ("stiffness_skew", "N/m", "tangent stiffness, skew part (dF_x/de_y - dF_y/de_x)/2"),
    ("penetration", "m", "penetration |e| - radial_clearance (negative inside the clearance)"),
    ("contact_force", "N", "normal contact force F_n >= 0"),
    ("normal_velocity", "m/s", "normal relative velocity v . e/|e| (positive approaching the wall)"),
)
_FORCE_NAMES = tuple(name for name, _, _ in FORCE_OUTPUTS)
assert len(_FORCE_NAMES) == len(physics.ClearanceForce._fields), "FORCE_OUTPUTS out of step with ClearanceForce"

#: the contact state (physics.ContactState), registered so that get/set FMU state restores it
IMPACT_VELOCITY = ("impact_velocity", "m/s",
                   "normal approach speed recorded when the current contact began, 0 when none (state)")
IN_CONTACT = ("in_contact", "a contact is under way: |e| > radial_clearance (state)")


class JournalClearance(Fmi2Slave):
    author = "bearing-cosim contributors"
    description = ("Journal in a bushing with radial clearance, continuous contact force with hysteresis damping "
                   "(Lankarani-Nikravesh; sphere-to-sphere stiffness): the comparison model of Xu et al., "
                   "Mech. Mach. Theory 56 (2012), Fig. 23-25")
    version = "0.1.0"
    license = "MIT"
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=0.1, step_size=1e-5)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        # errors reach the host even with logging off
        self._host_log = HostLogger(kwargs.get("logger"), self.instance_name, kwargs.get("resources"))
        guard_pythonfmu_exit(self.resources)     # pythonfmu 0.7's exit-time double free (fmu_bearing/slaves)
        try:
            release_on_free(self)                  # the last fmi2FreeInstance undoes the FMU's imports
        except Exception as err:                   # fmi2Instantiate returns NULL: say why, also with logging off
            self._host_log(3, f"instantiation failed: {err!r}")
            raise
        self._joint = None                         # physics.ClearanceJoint, built at exit of initialisation
        self._terminated = False                   # fmi2Terminate was called: no more steps
        self._pending_error = None                 # a refused setFMUstate, reported by the next doStep
        self._param_names = tuple(f.name for f in fields(ClearanceParameters))
        cont, fixed, discrete = Fmi2Variability.continuous, Fmi2Variability.fixed, Fmi2Variability.discrete
        for name, unit, desc in INPUTS:
            self._real(name, 0.0, unit, desc, causality=Fmi2Causality.input, variability=cont)
        for name, unit, desc in FORCE_OUTPUTS:
            self._real(name, 0.0, unit, desc, causality=Fmi2Causality.output, variability=cont,
                       initial=Fmi2Initial.calculated)
        name, unit, desc = IMPACT_VELOCITY
        self._real(name, 0.0, unit, desc, causality=Fmi2Causality.output, variability=discrete,
                   initial=Fmi2Initial.calculated)
        name, desc = IN_CONTACT
        setattr(self, name, False)
        getter, setter = weak_accessors(self, name)
        self.register_variable(BooleanVariable(name, description=desc, causality=Fmi2Causality.output,
                                               variability=discrete, initial=Fmi2Initial.calculated,
                                               getter=getter, setter=setter))
        # Parameters: one per ClearanceParameters field, with its default, unit and description.
        for f in fields(ClearanceParameters):
            self._real(f.name, float(f.default), f.metadata.get("unit") or None,
                       f.metadata.get("description", f.name), causality=Fmi2Causality.parameter,
                       variability=fixed, initial=Fmi2Initial.exact)

    def _real(self, name, start, unit, description, **kwargs):
        setattr(self, name, start)
        getter, setter = weak_accessors(self, name)
        self.register_variable(RealVariable(name, type_attributes={"unit": unit}, description=description,
                                            getter=getter, setter=setter, **kwargs))

    def to_xml(self, model_options=dict()):
        """pythonfmu's modelDescription plus <UnitDefinitions> and the outputs as <InitialUnknowns>."""
        root = super().to_xml(model_options)
        add_unit_definitions(root, self.vars.values())
        add_initial_unknowns(root, self.vars.values())
        return root

    # --- FMI ----------------------------------------------------------------------------------
    def parameters(self) -> ClearanceParameters:
        """The current parameter values as ClearanceParameters."""
        return ClearanceParameters(**{name: float(getattr(self, name)) for name in self._param_names})

    def state(self) -> ContactState:
        """The contact state held by the FMU variables."""
        return ContactState(bool(self.in_contact), float(self.impact_velocity))

    def exit_initialization_mode(self):
        try:
            joint = physics.ClearanceJoint(self.parameters())   # validates, names the parameter
            joint.check_inputs(self.e_x, self.e_y, self.v_x, self.v_y, self.omega_inner, self.omega_outer)
        except Exception as err:
            # to the host directly, not queued (see ball_bearing_fmu): pythonfmu then logs the exception itself
            self._host_log(3, f"initialisation failed: {err}")
            hold_before_raise(self)  # pythonfmu 0.7 over-releases objects on the exception path
            raise  # pythonfmu 0.7 turns an exception into a non-OK status (fmi2Fatal)
        self._joint = joint
        message = self._evaluate()
        if message is not None:
            self._joint = None
            self._host_log(3, f"initialisation failed: {message}")
            hold_before_raise(self)
            raise FloatingPointError(message)

    def do_step(self, current_time, step_size):
        joint = self._joint
        if self._pending_error is not None:   # a refused setFMUstate
            message, self._pending_error = self._pending_error, None
            self._error(f"doStep at t = {current_time!r} s rejected: {message}")
            return False
        if joint is None:
            self._error(f"doStep at t = {current_time!r} s rejected: "
                        + ("the instance was terminated (fmi2Terminate)" if self._terminated
                           else "called before initialisation"))
            return False
        try:
            joint.check_inputs(self.e_x, self.e_y, self.v_x, self.v_y, self.omega_inner, self.omega_outer)
        except BearingInputError as err:
            self._error(f"doStep at t = {current_time!r} s rejected: {err}")
            return False  # pythonfmu 0.7 reports fmi2Discard; outputs and state keep the last good step
        if not step_size >= 0.0:
            self._error(f"doStep at t = {current_time!r} s rejected: step size {step_size!r} is not >= 0")
            return False
        message = self._evaluate()
        if message is not None:
            self._error(f"doStep at t = {current_time!r} s rejected: {message}")
            return False
        return True

    def _evaluate(self):
        """Advance the contact state to the held inputs and set the outputs there; on failure return a message."""
        try:
            r, state = self._joint.evaluate_with_state(self.state(), self.e_x, self.e_y, self.v_x, self.v_y)
        except Exception as err:  # never crash the host: report through the FMI logger instead
            return f"force law failed: {err!r}"
        if not all(math.isfinite(x) for x in r):
            return f"non-finite force law result {tuple(r)} (inputs out of any physical range)"
        for name, value in zip(_FORCE_NAMES, r):
            setattr(self, name, float(value))
        self.in_contact, self.impact_velocity = bool(state.in_contact), float(state.impact_velocity)
        return None

    def terminate(self):
        self._terminated, self._joint = True, None   # a later doStep is refused (fmi2Discard, logged)

    def _error(self, message):
        """To the host directly (category logStatusError, also with logging off), else through pythonfmu's
        queue (only with logging on). The FMI logger's message is a printf format: escape '%'."""
        if not self._host_log(3, message):
            self.log(str(message).replace("%", "%%"), Fmi2Status.error)

    def set_real(self, vrs, values):
        """Inputs always; parameters only before initialisation ends (they are fixed); outputs never."""
        for vr in vrs:
            var = self.vars.get(vr)
            if var is None or var.causality == Fmi2Causality.input:
                continue  # an unknown reference: pythonfmu raises below
            if var.causality == Fmi2Causality.parameter and self._joint is None:
                continue
            if var.causality == Fmi2Causality.parameter:
                msg = f"parameter {var.name} is fixed: it cannot be set after initialisation"
            else:
                msg = f"{var.name} is an {var.causality.name} and cannot be set"
            self._error(msg)
            return  # never raise from a set call (pythonfmu 0.7 crash on the exception path): refuse, logged
        super().set_real(vrs, values)

    # --- FMU state: pythonfmu saves every registered variable (inputs, outputs incl. the contact state, parameters)
    @staticmethod
    def _fmu_state_from_bytes(state):
        return state_from_bytes(Fmi2Slave._fmu_state_from_bytes, state, "not a serialized JournalClearance state")

    def _set_fmu_state(self, state):
        """Restore a state after checking all of it (``fmu_bearing.slaves.state``); a state that is not ours
        is refused with a logged error, the next doStep is refused, and nothing is assigned."""
        try:
            if isinstance(state, dict) and INVALID_STATE in state:
                problem = str(state[INVALID_STATE])
            else:
                fixed = {n: getattr(self, n) for n in self._param_names} if self._joint is not None else None
                problem = check_state(state, variable_kinds(self), "JournalClearance", fixed)
                if problem is None:
                    ClearanceParameters(**{n: float(state[n]) for n in self._param_names}).validate()
        except Exception as err:  # no exception may reach pythonfmu's C++ side
            problem = f"not a JournalClearance state ({err!r})"
        if problem is not None:
            refuse_state(self, problem)
            return
        for var in self.vars.values():
            if var.setter is not None:
                var.setter(state[var.name])
