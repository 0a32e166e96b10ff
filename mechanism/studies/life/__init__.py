"""Bearing life study (issue 16): ``python -m mechanism life-study --out DIR``.

Rating life L10r (ISO/TS 16281, docs/bearing-life.md) of the paper's slider-crank against the radial
clearance (preload to several times the paper's 20 µm) and against the crank speed; CSV tables and PNG
plots. ``cases`` holds the operating points, ``runs`` runs them, ``tables`` and ``figures`` write the files,
``cli`` registers the subcommand.
"""
from mechanism.studies.life.cli import register

__all__ = ["register"]
