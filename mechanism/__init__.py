"""Planar multibody master for the ball-bearing FMU (Xu et al. 2012). The folders are the layers,
each importing only from the layers below it:

- ``cli``: the command line (``python -m mechanism``); subcommands come from the packages below;
- ``studies/``: the paper reproduction and the step-size study (each a subpackage: cases, runs,
  tables, figures, report);
- ``ssp/``: the system as SSP 1.0 (data, generator, reader, other FMI tools, the SliderCrank FMU);
- ``run``: the one driver, a ``RunConfig`` -> system -> master -> ``RunResult``; ``output/``: the
  files a person opens (CSV, JSON, PNG);
- ``cosim/``: the co-simulation master, coupling schemes (one class per scheme), endpoints (the
  FMU through fmpy, the law in-process), the bearing joint's link to the mechanism, the adaptive
  master and the monolithic reference;
- ``systems/``: mechanisms as data (the paper's slider-crank);
- ``multibody/``: the generic planar multibody core (model as data, solver of eq. 3-9,
  integrators); it knows nothing of bearings or FMI.

The bearing physics and its FMUs are the separate package ``fmu_bearing``. See docs/architecture.md.
"""

from mechanism.kernel_cache import configure as _configure_kernel_cache

_configure_kernel_cache()   # before numba is imported: a cache keyed by every compiled source (kernel_cache)
