"""The joint-component interface: the variables every joint FMU (BallBearing, JournalClearance) shares.

A contract between the components and their masters: the BallBearing and JournalClearance
slaves declare these inputs and coupling outputs, the SliderCrank FMU declares them the other
way round, and the Python master (``mechanism.cosim.endpoints``) exchanges them each step.
Each entry is (name, unit, description).
"""
from __future__ import annotations

#: inputs of a joint component, in value-reference order (eq. 10-12 and the ring speeds of eq. 16)
JOINT_INPUTS = (
    ("e_x", "m", "eccentricity x: journal (inner ring) centre minus housing (outer ring) centre, global frame"),
    ("e_y", "m", "eccentricity y: journal (inner ring) centre minus housing (outer ring) centre, global frame"),
    ("v_x", "m/s", "time derivative of e_x (journal minus housing velocity, x)"),
    ("v_y", "m/s", "time derivative of e_y (journal minus housing velocity, y)"),
    ("omega_inner", "rad/s", "absolute angular velocity of the journal body (inner ring)"),
    ("omega_outer", "rad/s", "absolute angular velocity of the housing body (outer ring)"),
)

#: outputs exchanged every communication step: the force (eq. 19) and its tangent matrices
COUPLING_OUTPUTS = (
    ("F_x", "N", "joint force on the housing body, x (the journal body receives -F_x), end of step"),
    ("F_y", "N", "joint force on the housing body, y (the journal body receives -F_y), end of step"),
    ("stiffness_xx", "N/m", "tangent stiffness dF_x/de_x"),
    ("stiffness_xy", "N/m", "tangent stiffness dF_x/de_y = dF_y/de_x (symmetric part)"),
    ("stiffness_yy", "N/m", "tangent stiffness dF_y/de_y"),
    ("damping_xx", "N.s/m", "tangent damping dF_x/dv_x"),
    ("damping_xy", "N.s/m", "tangent damping dF_x/dv_y = dF_y/dv_x"),
    ("damping_yy", "N.s/m", "tangent damping dF_y/dv_y"),
)

JOINT_INPUT_NAMES = tuple(name for name, _, _ in JOINT_INPUTS)
COUPLING_OUTPUT_NAMES = tuple(name for name, _, _ in COUPLING_OUTPUTS)
