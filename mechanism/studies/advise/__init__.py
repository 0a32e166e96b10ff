"""Step-size advisor: ``python -m mechanism advise --rpm 600 --balls 15 --set allow_ball_overlap=true --tolerance 1%``.

For one operating point (speed, balls, any bearing setting) it answers in one line which coupling
scheme and communication step meet a tolerance on the chosen figure(s) of merit against the
monolithic reference at the least wall time, and gives every scheme's largest stable step — each
found by bisection between a passing and a failing step, bounds marked as such. It is built on the
step-size study (``mechanism.studies.stepsize``): its cases, cached references, ``run_case`` and
``Executor`` (process pool or Dask), so a faster master or FMU speeds it up unchanged.

Modules: ``search`` (the step ladder, figures of merit and the bisection per scheme), ``runs``
(set-up check, reference, the rounds of runs), ``report`` (one line, table, files, plot), ``cli``.
"""
from mechanism.studies.advise.cli import register
from mechanism.studies.advise.runs import Advice, AdviceConfig, Refused, advise, check_setup
from mechanism.studies.advise.search import MERITS, SchemeSearch, ladder

__all__ = ["Advice", "AdviceConfig", "MERITS", "Refused", "SchemeSearch", "advise", "check_setup", "ladder",
           "register"]
