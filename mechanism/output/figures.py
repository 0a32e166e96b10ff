"""The names of a run's PNG files and what their frames are built from before the run's data (no matplotlib here:
``results.write_outputs`` orders the files an output worker drew, ``workers.SHARES`` shares them out, and the
command plans the frames, without importing it)."""
from __future__ import annotations

from dataclasses import dataclass

#: the files ``plots.plot_run`` can write, in the order it writes (and returns) them
FIGURES = ("eccentricity.png", "slider_acceleration.png", "crank_moment.png", "joint_force.png", "ball_loads.png",
           "energy.png", "slider_position_error.png")


@dataclass(frozen=True)
class Plan:
    """What a run's figures will show, known before the run (``plots.prepare`` builds their frames from it while
    the run runs): the run's ``meta`` as the run will record it (its configuration, crank period and clearance per
    side), whether an ideal counterpart will be drawn beside it, and the crank angle at the run's end [π rad]
    (the x limits to warm the frames with). A frame that does not fit the run's actual data is built again."""
    meta: dict
    ideal: bool
    x_end: float | None = None
