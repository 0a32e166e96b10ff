"""Hertzian point-contact stiffness of a radial ball bearing (Xu et al. 2012, Section 4.1).

All quantities are SI: lengths in m, moduli in Pa, curvatures in 1/m, forces in N,
load-deflection constants in N/m^1.5.

The paper reads the dimensionless deflection delta* off a chart in Harris's
*Rolling Bearing Analysis* (its eq. 24-26).  We compute it exactly from the complete
elliptic integrals instead (``dimensionless_deflection``); eq. 26's 2.15e5 form and the
Hamrock-Brewe closed-form approximation are kept only as cross-checks
(``stiffness_eq26``, ``stiffness_hamrock_brewe``), see docs/modelling-choices.md.

Only the Python standard library is used (this module runs inside the FMUs, whose host may
have neither numpy nor scipy): the complete elliptic integrals come from the arithmetic-geometric
mean (``ellipk``, ``ellipe``) and the ellipticity from Brent's bracketed root search
(``_brent``); tests/test_hertz_stdlib.py holds them against scipy.special / scipy.optimize to 1e-13.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

#: machine epsilon of IEEE double precision
_EPS = 2.220446049250313e-16


def _agm_k_e(m1: float) -> tuple[float, float]:
    """Complete elliptic integrals (K(m), E(m)) for the complementary parameter m1 = 1 - m in (0, 1].

    Gauss's arithmetic-geometric mean (Abramowitz & Stegun 17.6.1-17.6.4): a_0 = 1, b_0 = sqrt(m1),
    c_0 = sqrt(m); a_{n+1} = (a_n + b_n)/2, b_{n+1} = sqrt(a_n b_n), c_{n+1} = (a_n - b_n)/2;
    K = pi / (2 a_N) and E = K (1 - sum_{n>=0} 2^(n-1) c_n^2). Converges quadratically (5-7 steps).
    Taking m1 rather than m keeps full precision near m = 1 (slender contact ellipses).
    """
    a, b = 1.0, math.sqrt(m1)
    total = 0.5 * (1.0 - m1)                       # 2^-1 c_0^2, c_0^2 = m
    power = 0.5
    while True:
        c = 0.5 * (a - b)
        a, b = 0.5 * (a + b), math.sqrt(a * b)
        power *= 2.0
        total += power * c * c
        if c <= _EPS * a:
            break
    k = math.pi / (2.0 * a)
    return k, k * (1.0 - total)


def ellipk(m: float) -> float:
    """Complete elliptic integral of the first kind K(m) = int_0^{pi/2} (1 - m sin^2 t)^(-1/2) dt, 0 <= m < 1."""
    if not 0.0 <= m < 1.0:
        raise ValueError(f"parameter m = {m!r} must lie in [0, 1)")
    return _agm_k_e(1.0 - m)[0]


def ellipe(m: float) -> float:
    """Complete elliptic integral of the second kind E(m) = int_0^{pi/2} (1 - m sin^2 t)^(1/2) dt, 0 <= m < 1."""
    if not 0.0 <= m < 1.0:
        raise ValueError(f"parameter m = {m!r} must lie in [0, 1)")
    return _agm_k_e(1.0 - m)[1]


def _brent(f: Callable[[float], float], xa: float, xb: float, xtol: float, rtol: float,
           maxiter: int = 200) -> float:
    """A root of f in the bracket [xa, xb] (f(xa) f(xb) <= 0) by Brent's method (Brent 1973, ch. 4).

    Inverse quadratic interpolation / secant steps, safeguarded by bisection; stops when the bracket
    is narrower than xtol + rtol |x|. The same algorithm as scipy.optimize.brentq.
    """
    xpre, xcur = float(xa), float(xb)
    fpre, fcur = f(xpre), f(xcur)
    if fpre * fcur > 0.0:
        raise ValueError(f"f({xpre!r}) = {fpre!r} and f({xcur!r}) = {fcur!r} do not bracket a root")
    if fpre == 0.0:
        return xpre
    if fcur == 0.0:
        return xcur
    xblk = fblk = spre = scur = 0.0
    for _ in range(maxiter):
        if fpre * fcur < 0.0:                      # the root lies between xpre and xcur
            xblk, fblk = xpre, fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):                  # keep the best estimate in xcur
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = 0.5 * (xtol + rtol * abs(xcur))
        sbis = 0.5 * (xblk - xcur)
        if fcur == 0.0 or abs(sbis) < delta:
            return xcur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:                       # secant
                stry = -fcur * (xcur - xpre) / (fcur - fpre)
            else:                                  # inverse quadratic interpolation
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            if 2.0 * abs(stry) < min(abs(spre), 3.0 * abs(sbis) - delta):
                spre, scur = scur, stry            # accept the interpolation step
            else:
                spre = scur = sbis                 # bisect
        else:
            spre = scur = sbis                     # bisect
        xpre, fpre = xcur, fcur
        xcur += scur if abs(scur) > delta else (delta if sbis > 0.0 else -delta)
        fcur = f(xcur)
    raise RuntimeError(f"Brent's method did not converge in {maxiter} iterations")


@dataclass(frozen=True)
class ContactGeometry:
    """Curvature data of one ball-raceway contact (contact angle 0).

    sum_rho: curvature sum [1/m]; F_rho: curvature difference [-];
    R_x, R_y: effective radii in the rolling and transverse directions [m]
    (Hamrock's notation; R_x is the rolling radius used by the oil-film model).
    """

    sum_rho: float
    F_rho: float
    R_x: float
    R_y: float


def raceway_contacts(ball_diameter: float, pitch_diameter: float,
                     inner_conformity: float, outer_conformity: float
                     ) -> tuple[ContactGeometry, ContactGeometry]:
    """Inner and outer contact geometry of a radial ball bearing.

    Harris's curvature sums with gamma = D/d_m (contact angle 0):
    sum_rho_i = (4 - 1/f_i + 2g/(1-g))/D, sum_rho_o = (4 - 1/f_o - 2g/(1+g))/D,
    F_i = (1/f_i + 2g/(1-g))/(D sum_rho_i), F_o = (1/f_o - 2g/(1+g))/(D sum_rho_o).
    f is the groove radius divided by the ball diameter (the paper gives none; 0.52 is
    the textbook value used by default).
    """
    D, g = ball_diameter, ball_diameter / pitch_diameter
    rho_i = (4.0 - 1.0 / inner_conformity + 2.0 * g / (1.0 - g)) / D
    rho_o = (4.0 - 1.0 / outer_conformity - 2.0 * g / (1.0 + g)) / D
    F_i = (1.0 / inner_conformity + 2.0 * g / (1.0 - g)) / (D * rho_i)
    F_o = (1.0 / outer_conformity - 2.0 * g / (1.0 + g)) / (D * rho_o)
    # Effective radii 1/R_x = sum of principal curvatures in the rolling plane, 1/R_y across it.
    race_i, race_o = (pitch_diameter - D) / 2.0, (pitch_diameter + D) / 2.0
    Rx_i = 1.0 / (2.0 / D + 1.0 / race_i)
    Rx_o = 1.0 / (2.0 / D - 1.0 / race_o)
    Ry_i = 1.0 / (2.0 / D - 1.0 / (inner_conformity * D))
    Ry_o = 1.0 / (2.0 / D - 1.0 / (outer_conformity * D))
    return ContactGeometry(rho_i, F_i, Rx_i, Ry_i), ContactGeometry(rho_o, F_o, Rx_o, Ry_o)


def _curvature_difference(kappa: float) -> float:
    """F(rho) as a function of the contact ellipticity kappa = a/b >= 1 (exact Hertz)."""
    K, E = _agm_k_e(1.0 / (kappa * kappa))         # m1 = 1 - m = 1/kappa^2
    return ((kappa * kappa + 1.0) * E - 2.0 * K) / ((kappa * kappa - 1.0) * E)


def ellipticity(F_rho: float) -> float:
    """Solve F(rho) = [(k^2+1)E(m) - 2K(m)] / [(k^2-1)E(m)], m = 1 - 1/k^2, for k (exact Hertz)."""
    if not 0.0 < F_rho < 1.0:
        raise ValueError(f"curvature difference F(rho) = {F_rho!r} must lie in (0, 1)")
    # F(kappa) rises monotonically from 0 (kappa -> 1) to 1 (kappa -> inf).
    return _brent(lambda k: _curvature_difference(k) - F_rho, 1.0 + 1e-9, 1e4, xtol=1e-14, rtol=1e-14)


def dimensionless_deflection(F_rho: float) -> float:
    """Harris's delta* = (2K(m)/pi) * [pi / (2 k^2 E(m))]^(1/3), exact (replaces the chart of eq. 24-25)."""
    kappa = ellipticity(F_rho)
    K, E = _agm_k_e(1.0 / (kappa * kappa))
    return (2.0 * K / math.pi) * (math.pi / (2.0 * kappa * kappa * E)) ** (1.0 / 3.0)


def contact_stiffness(sum_rho: float, delta_star: float, youngs_modulus: float, poisson_ratio: float) -> float:
    """Load-deflection constant of one point contact [N/m^1.5], eq. (24)-(25).

    K_p = (2 sqrt(2)/3) * E/(1 - nu^2) * sum_rho^(-1/2) * delta*^(-3/2)   (both bodies of one material)
    """
    reduced = youngs_modulus / (1.0 - poisson_ratio ** 2)
    return (2.0 * math.sqrt(2.0) / 3.0) * reduced * sum_rho ** -0.5 * delta_star ** -1.5


def series_stiffness(k_inner: float, k_outer: float) -> float:
    """Ball stiffness of the inner and outer contacts in series, eq. (27)-(28).

    delta = delta_i + delta_o with delta_p = (W/K_p)^(2/3)  =>  K = [K_i^(-2/3) + K_o^(-2/3)]^(-3/2).
    """
    return ((1.0 / k_inner) ** (2.0 / 3.0) + (1.0 / k_outer) ** (2.0 / 3.0)) ** -1.5


def ball_stiffness(ball_diameter: float, pitch_diameter: float, youngs_modulus: float, poisson_ratio: float,
                   inner_conformity: float = 0.52, outer_conformity: float = 0.52) -> float:
    """Total load-deflection constant K of one ball between both raceways [N/m^1.5], eq. (24)-(28), exact Hertz."""
    ci, co = raceway_contacts(ball_diameter, pitch_diameter, inner_conformity, outer_conformity)
    k_i = contact_stiffness(ci.sum_rho, dimensionless_deflection(ci.F_rho), youngs_modulus, poisson_ratio)
    k_o = contact_stiffness(co.sum_rho, dimensionless_deflection(co.F_rho), youngs_modulus, poisson_ratio)
    return series_stiffness(k_i, k_o)


# --- cross-checks (tests only; not used by the force law) ----------------------------------------

def stiffness_eq26(sum_rho: float, delta_star: float) -> float:
    """Eq. (26) as printed, K_p = 2.15e5 sum_rho^(-1/2) delta*^(-3/2) in N and mm (steel), returned in N/m^1.5.

    sum_rho is given in 1/m and converted to 1/mm; N/mm^1.5 -> N/m^1.5 is a factor 1000^1.5.
    """
    return 2.15e5 * (sum_rho * 1e-3) ** -0.5 * delta_star ** -1.5 * 1000.0 ** 1.5


def stiffness_hamrock_brewe(contact: ContactGeometry, youngs_modulus: float, poisson_ratio: float) -> float:
    """Load-deflection constant [N/m^1.5] from Hamrock and Brewe's closed-form ellipticity approximations.

    k ~ 1.0339 (R_y/R_x)^0.636, E ~ 1.0003 + 0.5968 R_x/R_y, K ~ 1.5277 + 0.6023 ln(R_y/R_x),
    delta = K [ (9/(2 E R)) (W/(pi k E'))^2 ]^(1/3) with 1/R = 1/R_x + 1/R_y and E' = E/(1 - nu^2)
    (Hamrock's E' = 2/[(1-nu_a^2)/E_a + (1-nu_b^2)/E_b] for one material).
    """
    alpha = contact.R_y / contact.R_x
    kappa = 1.0339 * alpha ** 0.636
    Ebar = 1.0003 + 0.5968 / alpha
    Kbar = 1.5277 + 0.6023 * math.log(alpha)
    R = 1.0 / (1.0 / contact.R_x + 1.0 / contact.R_y)
    e_prime = youngs_modulus / (1.0 - poisson_ratio ** 2)
    # delta = c * W^(2/3)  =>  K_p = W / delta^1.5 = c^-1.5
    c = Kbar * (9.0 / (2.0 * Ebar * R) * (1.0 / (math.pi * kappa * e_prime)) ** 2) ** (1.0 / 3.0)
    return c ** -1.5
