"""The standard-library Hertz stiffness (AGM elliptic integrals, Brent root search) against SciPy.

The FMUs' runtime may not import numpy or scipy (issue 13), so ``fmu_bearing.hertz`` computes K(m),
E(m) and the contact ellipticity in plain Python. SciPy is the independent reference here (tests
only): ``scipy.special.ellipk/ellipe`` (Cephes polynomial approximations) and the previous
implementation of the ellipticity, ``scipy.optimize.brentq`` on the same transcendental equation
written with SciPy's integrals (copied below as ``scipy_ellipticity``).
"""
import math
import subprocess
import sys
from pathlib import Path

import pytest

from fmu_bearing import hertz
from fmu_bearing.ball_bearing import BallBearing
from fmu_bearing.parameters import BearingParameters

scipy_special = pytest.importorskip("scipy.special")
scipy_optimize = pytest.importorskip("scipy.optimize")

ROOT = Path(__file__).resolve().parent.parent
TOL = 1e-13


def scipy_curvature_difference(kappa):
    """F(rho)(kappa) as fmu_bearing.hertz computed it before issue 13, with SciPy's integrals."""
    m = 1.0 - 1.0 / (kappa * kappa)
    E, K = scipy_special.ellipe(m), scipy_special.ellipk(m)
    return ((kappa * kappa + 1.0) * E - 2.0 * K) / ((kappa * kappa - 1.0) * E)


def scipy_ellipticity(F_rho):
    return scipy_optimize.brentq(lambda k: scipy_curvature_difference(k) - F_rho, 1.0 + 1e-9, 1e4,
                                 xtol=1e-14, rtol=1e-14)


def scipy_ball_stiffness(p: BearingParameters):
    """eq. (24)-(28) with SciPy's integrals and root search (the implementation before issue 13)."""
    ks = []
    for c in hertz.raceway_contacts(p.ball_diameter, p.pitch_diameter, p.inner_groove_conformity,
                                    p.outer_groove_conformity):
        kappa = scipy_ellipticity(c.F_rho)
        m = 1.0 - 1.0 / (kappa * kappa)
        delta_star = (2.0 * scipy_special.ellipk(m) / math.pi) * (
            math.pi / (2.0 * kappa * kappa * scipy_special.ellipe(m))) ** (1.0 / 3.0)
        ks.append((2.0 * math.sqrt(2.0) / 3.0) * p.youngs_modulus / (1.0 - p.poisson_ratio ** 2)
                  * c.sum_rho ** -0.5 * delta_star ** -1.5)
    return (ks[0] ** (-2.0 / 3.0) + ks[1] ** (-2.0 / 3.0)) ** -1.5


M_GRID = [i / 200 for i in range(200)] + [1.0 - 10.0 ** -j for j in range(3, 13)]


@pytest.mark.parametrize("m", M_GRID)
def test_agm_elliptic_integrals_match_scipy(m):
    assert hertz.ellipk(m) == pytest.approx(float(scipy_special.ellipk(m)), rel=TOL)
    assert hertz.ellipe(m) == pytest.approx(float(scipy_special.ellipe(m)), rel=TOL)


def test_elliptic_integrals_closed_forms():
    assert hertz.ellipk(0.0) == hertz.ellipe(0.0) == pytest.approx(math.pi / 2, rel=1e-16)
    # K(1/2) = Gamma(1/4)^2 / (4 sqrt(pi)); Legendre's relation at m = 1/2: 2 E K - K^2 = pi/2
    K, E = hertz.ellipk(0.5), hertz.ellipe(0.5)
    assert K == pytest.approx(math.gamma(0.25) ** 2 / (4 * math.sqrt(math.pi)), rel=1e-15)
    assert 2 * E * K - K * K == pytest.approx(math.pi / 2, rel=1e-15)
    with pytest.raises(ValueError):
        hertz.ellipk(1.0)


# F(rho) of radial ball bearings lies near 0.85-0.97; at the ends of (0, 1) the equation itself is
# ill-conditioned (F flat in kappa, or a 0/0 as kappa -> 1), so both roots agree only to rounding there.
@pytest.mark.parametrize("F_rho", [0.02, 0.05, 0.1, 0.3, 0.5, 0.7, 0.85, 0.9, 0.9096899224806199,
                                   0.9424403705893947, 0.97, 0.99, 0.995])
def test_ellipticity_matches_scipy_brentq(F_rho):
    assert hertz.ellipticity(F_rho) == pytest.approx(scipy_ellipticity(F_rho), rel=TOL)


@pytest.mark.parametrize("F_rho", [1e-6, 1e-3, 0.999, 0.999999])
def test_ellipticity_solves_the_equation_at_the_ill_conditioned_ends(F_rho):
    kappa = hertz.ellipticity(F_rho)
    assert abs(scipy_curvature_difference(kappa) - F_rho) < 1e-10


@pytest.mark.parametrize("changes", [{}, {"inner_groove_conformity": 0.505, "outer_groove_conformity": 0.57},
                                     {"ball_diameter": 12e-3, "pitch_diameter": 60e-3, "inner_race_diameter": 48e-3,
                                      "outer_race_diameter": 72e-3, "youngs_modulus": 2.1e11,
                                      "poisson_ratio": 0.29}])
def test_ball_stiffness_matches_the_scipy_implementation(changes):
    p = BearingParameters().replace(**changes)
    assert BallBearing(p).stiffness == pytest.approx(scipy_ball_stiffness(p), rel=TOL)


def test_runtime_modules_import_without_numpy_scipy_tqdm():
    """The FMUs' runtime path (physics and slaves) works in a Python where numpy, scipy and tqdm cannot be imported."""
    code = """
import sys
class Block:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('numpy', 'scipy', 'tqdm'):
            raise ImportError('blocked for the test: ' + name)
sys.meta_path.insert(0, Block())
from fmu_bearing import ball_bearing, clearance_joint, hertz, interface, parameters
from fmu_bearing.slaves import ball_bearing_fmu, journal_clearance_fmu
b = ball_bearing.BallBearing()
r = b.evaluate(3e-5, 0.0, 0.0, 0.0, 0.0)
j = clearance_joint.ClearanceJoint()
assert r.F_x > 0 and j.stiffness > 0
print(repr(b.stiffness))
"""
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr
    assert float(out.stdout) == pytest.approx(scipy_ball_stiffness(BearingParameters()), rel=TOL)
