"""The names of a run's PNG files (no matplotlib here: ``results.write_outputs`` orders the files an output
worker drew, and ``workers.SHARES`` shares them out, without importing it)."""

#: the files ``plots.plot_run`` can write, in the order it writes (and returns) them
FIGURES = ("eccentricity.png", "slider_acceleration.png", "crank_moment.png", "joint_force.png", "ball_loads.png",
           "energy.png", "slider_position_error.png")
