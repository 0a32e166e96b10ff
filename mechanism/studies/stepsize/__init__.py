"""Co-simulation step-size study: error, cost and stability of each coupling scheme against the monolithic reference.

``python -m mechanism stepsize-study --rpm 1200 --steps 1e-7:1e-4:13 --schemes all --out DIR``

For every case (crank speed x ball count x component setting x scheme x step) the study runs the
co-simulation (through the FMU by default) and compares it with the monolithic reference of the
same physical case (``mechanism.cosim.monolithic``: LSODA at rtol 1e-11, computed once per physical case
and cached on disk under a hash of its parameters). See docs/stepsize-study.md for the method and
the measured results; in short:

* **Steps** are log-spaced (``lo:hi:count``) and *snapped* to the output grid: a step below the
  output interval dt (1e-5 s) becomes dt/round(dt/h), one above it dt*round(h/dt), so every run
  is sampled on the reference's grid (a step above dt is sampled every step, and compared at
  those times). The CSV gives the nominal and the snapped step.
* **Window**: the second crank revolution [T, 2T] (``--revs`` >= 2, default 2); for shorter runs
  the second half of the run [revs T/2, revs T].
* **Errors** over the window, on the common samples: max and RMS of |e - e_ref| (the vector
  eccentricity error, m), |F - F_ref| (joint force, N), slider acceleration (m/s^2) and crank
  moment (N m); each also relative to the reference's peak magnitude in the window (``_rel``).
  Peak errors: the relative error of the window's peak |F| and max |e| (and max ball load);
  ``peak_error_rel`` = max(|peak |F| error|, |max |e| error|) is the **1 % criterion**.
* **Stability**: a run that stops (an error status from the FMU, the eccentricity limit,
  a non-finite state, constraint drift) is "unstable (failed)"; one whose max relative force or
  eccentricity error exceeds ``--divergence`` (50 %) is "unstable (divergent)"; runs whose step
  count exceeds ``--max-steps-per-case`` are "skipped (cost)" unless ``--allow-slow``; a case that
  raises is "error". Errors are left empty, never NaN, where they do not exist.
* **Order**: least-squares slope of log(max relative force error) against log(step) over the
  stable points whose error lies between max(1e-5, 3x the reference's floor) and 20 % (``--order-range``).
  The floor is the reference's own error, measured by running it again at rtol/10.
* **Adaptive**: scheme ``adaptive`` (``mechanism.cosim.adaptive``) runs once per ``--tols`` value; its
  step axis is the mean accepted step.

A missing reference is computed beside the cases (its run and its rtol/10 floor run are two jobs of the
pool); the cases that need it are compared with it once it is there (``runs.case_job``, ``runs.assess_case``).
Cases run in parallel (a process pool of ``--workers``, default the core count, or a Dask
cluster given by ``--scheduler tcp://HOST:PORT``; the same case function either way); each case
opens and frees its own FMU instance and records its pid/worker and start/end time. A failing case
is a row with its message; it never stops the sweep.

Modules: ``cases`` (options and cases as data), ``reference`` (the monolithic reference and the
comparison with it), ``runs`` (one case, the executors, the sweep and its CSV), ``tables`` (orders,
largest stable / 1 % steps, Markdown), ``figures`` (PNG), ``cli`` (the subcommand).
"""
from mechanism.studies.stepsize.cases import (ADAPTIVE, COLUMN_NAMES, COLUMNS, DEFAULT_STEPS, DEFAULT_TOLS,
                                             DIVERGENT, ERROR, FAILED, MAX_STEPS_PER_CASE, NONFINITE,
                                             OUTPUT_INTERVAL, PLACEMENT_COLUMNS, SKIPPED, STABLE, StudyConfig,
                                             build_cases, parse_grid, parse_settings, snap_step)
from mechanism.studies.stepsize.cli import register
from mechanism.studies.stepsize.runs import StudyResult, read_csv, replot, rows_from_csv, run_case, run_study
from mechanism.studies.stepsize.tables import fit_order, summarize, summary_markdown

__all__ = ["ADAPTIVE", "COLUMN_NAMES", "COLUMNS", "DEFAULT_STEPS", "DEFAULT_TOLS", "DIVERGENT", "ERROR", "FAILED",
           "MAX_STEPS_PER_CASE", "NONFINITE", "OUTPUT_INTERVAL", "PLACEMENT_COLUMNS", "SKIPPED", "STABLE",
           "StudyConfig", "StudyResult", "build_cases", "fit_order", "parse_grid", "parse_settings", "read_csv",
           "register", "replot", "rows_from_csv", "run_case", "run_study", "snap_step", "summarize",
           "summary_markdown"]
