"""Planar multibody master for the ball-bearing FMU (Xu et al. 2012).

- ``model``: the model as data (bodies, points, joints, bearing joints);
- ``solver``: constraint assembly, eq. (9) with Baumgarte, kinematic analysis;
- ``slider_crank``: the paper's Table 1 mechanism as data;
- ``bearing_joint``: the bearing's inputs and loads on the bodies (eq. 10-15, 20-23);
- ``exchange``: the FMU (fmpy) and in-process endpoints; ``coupling``: the coupling schemes;
- ``master``: the co-simulation loop; ``monolithic``: the stiff-integrator reference;
- ``run``, ``results``, ``plots``, ``cli``: one run, its files, the command line;
- ``studies``: the paper reproduction and the step-size studies.
"""
