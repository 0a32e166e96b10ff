"""Deep-groove ball bearing with clearance (Xu et al., Mech. Mach. Theory 56, 2012) as pure functions and FMUs.

- ``hertz``: contact stiffness from geometry, eq. (24)-(28);
- ``parameters``: the bearing's parameters (Table 2 defaults) and their validation;
- ``ball_bearing``: cage kinematics and the per-ball force law, eq. (16)-(19), (29)-(32);
- ``clearance_joint``: journal-in-bushing contact (Lankarani-Nikravesh), for Fig. 23-25;
- ``slaves/``: the thin pythonfmu classes that map FMU variables onto those functions.
"""
from .ball_bearing import BallBearing, BearingForce, BearingInputError, cage_angular_velocity
from .parameters import BearingParameterError, BearingParameters

__all__ = ["BallBearing", "BearingForce", "BearingInputError", "BearingParameterError", "BearingParameters",
           "cage_angular_velocity"]
