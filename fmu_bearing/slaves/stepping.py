"""The step semantics the BallBearing slaves (FMI 2.0 and FMI 3.0) share, independent of pythonfmu/pythonfmu3.

``BearingStepping`` is a mixin for a slave that keeps the six inputs (``e_x`` ... ``omega_outer``), the force
outputs (``F_x`` ... ``max_ball_load``), ``cage_angle``, ``_bearing`` (a validated
``fmu_bearing.ball_bearing.BallBearing`` once initialised, else None), ``_pending_error`` (a refused call to
report at the next step), ``_loads`` (the per-ball load outputs) and ``_scratch`` (a list of the same length
that ``evaluate`` writes into) as attributes. A step checks the inputs, advances the cage angle over
[t, t + h] with the inputs held (eq. 16) and evaluates the force law at the new cage angle (eq. 18-19), so
every output describes the END of the step; on any failure nothing changes and the reason is returned (no
exception escapes: pythonfmu and pythonfmu3 mishandle them, see ``fmu_bearing.slaves``).

Bearing life (docs/bearing-life.md): a slave that also keeps ``_life`` (a ``fmu_bearing.life.LifeAccumulator``
once initialised, from ``_new_life``, else None) and the RATING_OUTPUTS as attributes gets the end-of-step loads
added to it after each good step (held over the step); ``_publish_ratings`` copies the ratings to their outputs,
``life_output`` reads a LIFE_OUTPUTS value (``ignore_value`` is its setter), and the accumulator's sums travel in
the FMU state under ``LIFE_STATE`` (``_life_state``; ``_restored_life`` checks them before any assignment).
"""
import math
from dataclasses import fields

from fmu_bearing import ball_bearing as physics
from fmu_bearing import life
from fmu_bearing.parameters import BearingParameters

#: key of the life accumulator's sums (LifeAccumulator.state()) in a saved FMU state
LIFE_STATE = "__life_accumulator__"


def life_output(slave, prop):
    """A life output (life.LIFE_OUTPUTS) of the slave's accumulator; before initialisation, of an empty one."""
    return float(getattr(slave._life if slave._life is not None else slave._empty_life, prop))


def ignore_value(value):
    """Setter of a life output: read-only and computed (the FMU state restores the accumulator instead)."""


class BearingStepping:
    """Mixin: ``_advance`` (one communication step) and ``_evaluate`` (outputs at a cage angle)."""

    #: the FMI call that set ``_terminated`` (named in the refusal of a later step)
    TERMINATE_CALL = "fmi2Terminate"
    #: defaults of a slave without an accumulator / not terminated (the slaves set both per instance)
    _life = None
    _terminated = False
    #: the BearingForce of the last good evaluation (the outputs F_x ... max_ball_load), None before one
    _force = None
    #: the parameter variables: one per BearingParameters field, same name
    _param_names = tuple(f.name for f in fields(BearingParameters))

    def parameters(self) -> BearingParameters:
        """The current parameter values as BearingParameters."""
        return BearingParameters(**{name: getattr(self, name) for name in self._param_names})

    def _advance(self, step_size):
        """Advance over one step of ``step_size`` [s]; None, or why the step is refused (outputs unchanged)."""
        bearing = self._bearing
        if bearing is None or self._pending_error is not None:
            reason = self._pending_error or (f"the instance was terminated ({self.TERMINATE_CALL})"
                                             if self._terminated else "the instance is not initialised")
            self._pending_error = None
            return reason
        w_i, w_o = self.omega_inner, self.omega_outer
        try:
            bearing.check_inputs(self.e_x, self.e_y, self.v_x, self.v_y, w_i, w_o)
        except physics.BearingInputError as err:
            return str(err)
        if not step_size >= 0.0:
            return f"step size {step_size!r} is not >= 0"
        reason = self._evaluate(bearing.advance_cage(self.cage_angle, w_i, w_o, step_size), bearing)
        accumulator = self._life
        if reason is not None or accumulator is None:
            return reason
        try:  # the loads at the end of the step, held over it (docs/bearing-life.md)
            accumulator.add(self._loads, w_i, w_o, step_size)
        except Exception as err:  # never let an exception reach pythonfmu's C++ side
            return f"life accumulation failed: {err!r}"
        return None

    def _evaluate(self, cage_angle, bearing):
        """Outputs at ``cage_angle`` and the held inputs; on failure return a message and change nothing."""
        try:
            r = bearing.evaluate(self.e_x, self.e_y, self.v_x, self.v_y, cage_angle,
                                 self.omega_inner, self.omega_outer, self._scratch)
        except Exception as err:  # never let an exception reach pythonfmu's C++ side
            return f"force law failed: {err!r}"
        if not math.isfinite(r[0] + r[1] + r[2] + r[3] + r[4] + r[5] + r[6] + r[7] + r[9] + cage_angle):
            return f"non-finite force law result {tuple(r)} (inputs out of any physical range)"
        (self.F_x, self.F_y, self.stiffness_xx, self.stiffness_xy, self.stiffness_yy,
         self.damping_xx, self.damping_xy, self.damping_yy, self.loaded_balls, self.max_ball_load) = r
        self.cage_angle = cage_angle
        self._loads[:] = self._scratch
        self._force = r
        return None

    @staticmethod
    def _new_life(params):
        """A LifeAccumulator for ``params`` (raises life.LifeInputError outside ISO 281's range)."""
        return life.LifeAccumulator(life.LoadRatings.of_bearing(params), params.reliability_factor)

    def _publish_ratings(self, ratings):
        """Copy the load ratings to their output variables (life.RATING_OUTPUTS)."""
        for name, _, _, field in life.RATING_OUTPUTS:
            setattr(self, name, float(getattr(ratings, field)))

    def _life_state(self):
        """{LIFE_STATE: the accumulator's sums}, to add to a saved FMU state ({} without an accumulator)."""
        return {} if self._life is None else {LIFE_STATE: self._life.state()}

    def _restored_life(self, params, sums):
        """A new LifeAccumulator for ``params`` holding the saved ``sums`` (LifeAccumulator.state()); raises
        life.LifeInputError if they are missing or invalid, so a state can be checked before any assignment."""
        if sums is None:
            raise life.LifeInputError("the state holds no life accumulator")
        accumulator = self._new_life(params)
        accumulator.restore(sums)
        return accumulator
