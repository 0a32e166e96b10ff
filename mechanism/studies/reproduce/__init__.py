"""Reproduce Section 5 of Xu et al. (2012) with one command: ``python -m mechanism reproduce --out DIR``.

The runs (all through the FMU co-simulation, ``RunConfig(mode="cosim")``, 1e-5 s step and output):

* the ball bearing (8 balls) at 300, 600, 900 and 1200 rpm (Fig. 11-19);
* 15 and 20 balls at 1200 rpm (Fig. 20-22): they do not fit on the 37.9 mm pitch circle (13 at
  most), so these runs set ``allow_ball_overlap`` - the paper's ball-count study is hypothetical;
* the ideal joint at the four speeds: the counterpart of every run at that speed (step 1e-4 s:
  no contact, see ``IDEAL_STEP``);
* the journal-in-bushing clearance joint (``joint="clearance"``, JournalClearance FMU) at 1200 rpm
  (Fig. 23-25);
* the "paper-units stiffness" variant at the four speeds: the Hertz constant divided by 1000
  (through the FMU's ``contact_stiffness`` override), the stiffness a kg-mm-s code gets from
  eq. (26) in N/mm^1.5 used unchanged; shows which stiffness the paper's plotted magnitudes match.

Runs are spread over processes (``ProcessPoolExecutor``, each run its own FMU instance) with a
tqdm bar over runs, and cached under ``DIR/cache/<name>-<key>/`` (``result.npz`` with the columns
and samples, ``meta.json`` with the configuration, status and wall time).  The key is the first
16 hex digits of SHA-256 over the run's ``RunConfig`` (every field except ``progress`` and the
FMU path) and the *code version*: SHA-256 over the source of every ``*.py`` file of
``fmu_bearing/`` (the FMUs pack the whole package), ``build_fmu.py``, the ``mechanism`` modules
that ``mechanism/run.py`` imports directly or indirectly (found by parsing their import
statements; ``plots``, ``cli`` and ``studies`` only present results and are left out), and the
versions of numpy, scipy, fmpy and pythonfmu.  So a run is recomputed exactly when its inputs or the code that
computes it change; ``--force`` recomputes every run; a figure is drawn again only if
the data it shows or the drawing code changed (``report/figures/.inputs-key``).  The FMUs are built from the current
sources into ``DIR/fmu/`` (whenever the code version changed), never taken from a possibly stale
``dist/``.  Then ``report`` draws the figures and writes ``DIR/report/README.md``.

Modules: ``cases`` (the operating points as data), ``cache`` (code version, cache keys, stored
results, FMUs), ``runs`` (the parallel runs and ``reproduce``), ``paper`` (the paper's numbers and
claims), ``analysis`` (figures of merit from the runs), ``figures_speed``, ``figures_design`` and
``sections`` (the report's parts), ``report`` (assembles ``report/README.md``), ``cli``.
"""
from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import BearingParameters
from mechanism.studies.reproduce.cache import ROOT, code_files, code_version, config_key
from mechanism.studies.reproduce.cases import (BALL_COUNTS, IDEAL_STEP, SPEEDS, STUDY_RPM, RunSpec, balls_fit,
                                               paper_stiffness, run_specs)
from mechanism.studies.reproduce.cli import register
from mechanism.studies.reproduce.runs import append_stepsize_study, reproduce

__all__ = ["BALL_COUNTS", "BallBearing", "BearingParameters", "IDEAL_STEP", "ROOT", "RunSpec", "SPEEDS",
           "STUDY_RPM", "append_stepsize_study", "balls_fit", "code_files", "code_version", "config_key",
           "paper_stiffness", "register", "reproduce", "run_specs"]
