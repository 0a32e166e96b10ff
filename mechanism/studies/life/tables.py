"""The life study's tables: one CSV per sweep (SI, units in the header)."""
from __future__ import annotations

from pathlib import Path

from mechanism.output.results import write_rows

#: CSV columns and their units
COLUMNS = (("sweep", ""), ("rpm", "rev/min"), ("radial_clearance", "m"), ("window_start_s", "s"),
           ("window_end_s", "s"), ("equivalent_load_inner_N", "N"), ("equivalent_load_outer_N", "N"),
           ("max_ball_load_N", "N"), ("dynamic_load_rating_N", "N"), ("rating_life_Mrev", "Mrev"),
           ("rating_life_h", "h"), ("status", ""), ("message", ""), ("wall_s", "s"))


def write_csv(rows: list[dict], path: Path) -> None:
    """Rows of one sweep to ``path`` (header ``name [unit]``, written atomically)."""
    write_rows(rows, COLUMNS, path, digits=10)
