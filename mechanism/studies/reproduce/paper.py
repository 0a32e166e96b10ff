"""The paper's numbers (axis ranges read off its figures, in SI) and its claims, as data."""
from __future__ import annotations






#: magnitudes read off the paper's figures (extraction's axis labels), converted from its units:
#: a plotted "N" is kg mm/s^2 = 1 mN, "mm/s^2" is 1e-3 m/s^2, "Nmm" is kg mm^2/s^2 = 1 uN m.
PAPER = {
    "fig12_Fx_axis_N": 1e5 * 1e-3,      # Fig. 12 x axis spans +-1e5 "N" (600 rpm, ideal joint)
    "fig12_Fy_axis_N": 4e4 * 1e-3,      # Fig. 12 y axis spans +-4e4 "N"
    "fig13_error_axis_m": 1e-3,         # Fig. 13(b) position-error axis spans +-1 mm (four speeds)
    "fig21a_accel_axis_m_s2": (-1.2e6 * 1e-3, 9e5 * 1e-3),  # Fig. 21(a), 1200 rpm: -12e5 ... 9e5 mm/s^2
    "fig15_load_axis_N": 6e4 * 1e-3,    # Fig. 15 ball-load axes reach 6e4 "N" (600 rpm)
    "fig16_load_axis_N": 5e4 * 1e-3,    # Fig. 16 polar radius 5e4 "N" for most balls (600 rpm)
}

#: short quotes of the paper's claims (Section 5), keyed by figure
CLAIMS = {
    "fig11": "\"the eccentric displacement increases with the increase of the crank rotational velocity\"; "
             "\"the eccentric trajectories ... are quite similar to the trajectory of joint constraint force vector\"",
    "fig12": "Fig. 12: the ideal joint's force vector at 600 rpm spans about ±1e5 \"N\" in X and ±4e4 \"N\" in Y",
    "fig13": "\"the position errors increase with the increase of the crank rotational velocity\"; "
             "\"the slider position error has a minimum value at crank angle position about 0.4π (72°) and 1.6π "
             "(288°). When the mechanism is located at the horizontal position ... maximum value\"",
    "fig14": "\"When the crank has a lower angular velocity, the slider acceleration curves resemble those obtained "
             "for models with ideal joints. But, with the increase of the crank rotational speed, the vibration "
             "of the curves is becoming more and more obvious\"",
    "fig15": "\"the changes of the force on each ball are not the same. At some location, the balls bear a great "
             "contact force. On the contrary, in some other location, the balls are not in the load zone and the "
             "contact force is zero\"",
    "fig16": "\"due to the change of the ball angular position, the load variation on a ball element is always "
             "different at different crank rotational cycles\"",
    "fig17": "Fig. 17-18: the equivalent joint force of the bearing against the ideal joint's; conclusions: "
             "\"relatively smooth and no impulsive effects are observed in bearing joint\"",
    "fig19": "\"The crank moment is the moment necessary to maintain constant the crank angular velocity\"",
    "fig20": "\"the amplitude of the bearing relative eccentricity decreases with the increase of number of balls\"",
    "fig21": "\"with the increase of the number of balls the dynamic responses ... tend to be closer to the ideal "
             "response\"",
    "fig22": "\"with the increase of the number of balls, the load on ball element is decreasing\"",
    "fig24": "\"the variation of the eccentric trajectory is quite similar to the simulations with a real bearing "
             "joint ... no impulsive effects are observed\"",
    "fig25": "\"these dynamic responses are roughly the same. The only difference is that the elastic vibration "
             "frequency of the curves is slightly different\"",
}

#: a vibration frequency is taken above this multiple of the crank frequency (the crank harmonics are the
#: quasi-static response, not a contact vibration)
VIBRATION_MIN_HARMONIC = 8


# --- analysis helpers (also used by the tests) --------------------------------------------------------
