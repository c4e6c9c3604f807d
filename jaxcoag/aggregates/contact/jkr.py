"""JKR normal interaction of two identical monomers as a function of the compression delta (cgs).

With x = a/a_0 (contact radius over its equilibrium value) and delta_0 = a_0^2/(3R), the JKR theory gives
    delta/delta_0 = 3 x^2 - 2 x^(1/2)                                  (Wada et al. 2007 eq. 4)
    F/F_c         = 4 (x^3 - x^(3/2)),   F > 0 repulsive                 (eq. 5)
    U_n/(F_c delta_c) = 4 6^(1/3) [(4/5) x^5 - (4/3) x^(7/2) + (1/3) x^2]   (eq. 6), dU_n/ddelta = F.
A contact exists from its creation at delta = 0 until it breaks at delta = -delta_c (x = 6^(-2/3)), where
delta_c = (9/16)^(1/3) delta_0. The functions here give the in-contact branch; compressions below -delta_c are
clamped to the separation point (the caller decides whether a pair is in contact; before contact U_n = 0).

Inverting eq. 4: with y = x^(1/2) and d = delta/delta_0, y is the largest root of 3 y^4 - 2 y - d = 0 on the
branch y >= 6^(-1/3). The closed form (Ferrari: resolvent cubic m^3 + (d/3) m - 1/18 = 0, solved by Cardano)
is evaluated in a cancellation-free way and polished by one Newton step; ``contact_radius_ratio`` carries a
``jax.custom_jvp`` with the implicit derivative dy/dd = 1/(12 y^3 - 2). That derivative is infinite at the
separation point (F(delta) has a vertical tangent at delta = -delta_c); it is masked to 0 there (and below, where
delta is clamped), so gradients stay finite.

Dimensionless constants (exact expressions, units F_c delta_c, F_c delta_c/m_1 v_0^2 = 1):
    DELTA0_OVER_DELTAC = (16/9)^(1/3) = 1.21141
    U_AT_ZERO          = U_n(delta = 0)       = -0.846614  (x = (2/3)^(2/3))
    U_AT_SEPARATION    = U_n(delta = -delta_c) = 4/45       (x = 6^(-2/3))
    U_AT_EQUILIBRIUM   = U_n(delta_0)         = -(4/5) 6^(1/3) = -1.453696
    E_BREAK_UNITS      = U_AT_SEPARATION - U_AT_EQUILIBRIUM = 1.542585       (eq. 45)
    REBOUND_LOSS_UNITS = 4 (U_AT_SEPARATION - U_AT_ZERO) = 3.74201: v_out^2 = v^2 - 3.74201 v_0^2 for a head-on
                         collision of two free monomers (reduced mass m_1/2, normal forces only)
    V_STICK_UNITS      = sqrt(REBOUND_LOSS_UNITS) = 1.93443: they stick below 1.93443 v_0.

References: Wada et al. (2007, ApJ 661, 320) eqs. 1-7, 45, 48; Johnson, Kendall & Roberts (1971).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from ...physics.contact import C_BREAK, jkr_potential

__all__ = [
    "DELTA0_OVER_DELTAC",
    "D_SEPARATION",
    "U_AT_ZERO",
    "U_AT_SEPARATION",
    "U_AT_EQUILIBRIUM",
    "E_BREAK_UNITS",
    "REBOUND_LOSS_UNITS",
    "V_STICK_UNITS",
    "contact_radius_ratio",
    "compression",
    "normal_force",
    "normal_potential",
    "normal_force_and_potential",
    "normal_stiffness",
]

DELTA0_OVER_DELTAC = (16.0 / 9.0) ** (1.0 / 3.0)
D_SEPARATION = -((9.0 / 16.0) ** (1.0 / 3.0))  # delta/delta_0 at separation (-delta_c)
_Y_SEPARATION = 6.0 ** (-1.0 / 3.0)  # (a/a0)^(1/2) at separation
# U_n/(F_c delta_c) at x = (2/3)^(2/3) (delta = 0): x^5 = (2/3)^(10/3), x^(7/2) = (2/3)^(7/3), x^2 = (2/3)^(4/3)
U_AT_ZERO = 4.0 * 6.0 ** (1.0 / 3.0) * (
    0.8 * (2.0 / 3.0) ** (10.0 / 3.0) - (4.0 / 3.0) * (2.0 / 3.0) ** (7.0 / 3.0) + (2.0 / 3.0) ** (4.0 / 3.0) / 3.0
)
U_AT_SEPARATION = 4.0 / 45.0
U_AT_EQUILIBRIUM = -0.8 * 6.0 ** (1.0 / 3.0)
E_BREAK_UNITS = C_BREAK  # = U_AT_SEPARATION - U_AT_EQUILIBRIUM (Wada eq. 45)
REBOUND_LOSS_UNITS = 4.0 * (U_AT_SEPARATION - U_AT_ZERO)
V_STICK_UNITS = math.sqrt(REBOUND_LOSS_UNITS)


# initial guess of a cube root from the bit pattern: (bits of z)/3 + this constant, fdlibm's B1 = (682 - 0.03306)
# 2^20 of the high word (s_cbrt.c) extended to 64 bits; within 3.2 % of z^(1/3) (measured, 1e-300..1e300)
_CBRT_MAGIC = 0x2A9F7893782DA1CE


def _cbrt_positive(z):
    """Cube root of float64 ``z`` in [1e-200, 1e200] in vectorisable arithmetic (no libm call), to 4.5e-16 relative.

    Initial guess from the bit pattern (``_CBRT_MAGIC``), then three Halley steps y <- y (y^3 + 2 z)/(2 y^3 + z)
    (cubic convergence: three steps reach round-off from the 3.2 % guess; beyond ~1e230, y (y^3 + 2 z) overflows).
    XLA's CPU backend calls libm's scalar ``cbrt`` per element (~15 ns; the largest single cost of a contact-DEM
    step's force pass, 38 us of ~540 us at 3-D 1024 + 1024); this is ~3 ns per element and fuses with its
    neighbours. The JKR inversion uses it only on z = 1/36 + sqrt(D) >= 1/36 (and carries its own custom
    derivative). Checked against ``jnp.cbrt`` over [1e-200, 1e200] (tests/test_contact_physics.py)."""
    i = jax.lax.bitcast_convert_type(z, jnp.uint64)
    guess = (i.astype(jnp.float64) * (1.0 / 3.0)).astype(jnp.uint64) + jnp.uint64(_CBRT_MAGIC)
    y = jax.lax.bitcast_convert_type(guess, jnp.float64)
    for _ in range(3):
        y3 = y * y * y
        y = y * (y3 + 2.0 * z) / (2.0 * y3 + z)
    return y


def _y_closed_form(d):
    """Largest real root y >= 6^(-1/3) of 3 y^4 - 2 y - d = 0 for d >= D_SEPARATION (closed form + Newton)."""
    # resolvent: m = u + v with u^3, v^3 = 1/36 +- sqrt(D), D = 1/1296 + (d/9)^3, u v = -d/9
    D = jnp.maximum(1.0 / 1296.0 + (d / 9.0) ** 3, 0.0)
    u = _cbrt_positive(1.0 / 36.0 + jnp.sqrt(D))
    v = -d / (9.0 * u)
    # m^3 = u^3 + v^3 + 3 u v m: for d > 0 use m = (u^3 + v^3)/(u^2 - u v + v^2) = (1/18)/(u^2 + v^2 + d/9),
    # which has no cancellation; for d <= 0, u and v are both >= 0 and u + v is exact.
    m = jnp.where(d > 0, (1.0 / 18.0) / (u * u + v * v + jnp.abs(d) / 9.0), u + v)
    s = jnp.sqrt(2.0 * m)
    y = 0.5 * (s + jnp.sqrt(jnp.maximum(-2.0 * m + 4.0 / (3.0 * s), 0.0)))
    # one Newton polish on 3 y^4 - 2 y - d where it matters (d > 0: there 12 y^3 - 2 >= 6; near separation the
    # closed form is exact to round-off and the Newton denominator vanishes)
    den = jnp.where(d > 0, 12.0 * y**3 - 2.0, 1.0)
    y = jnp.where(d > 0, y - (3.0 * y**4 - 2.0 * y - d) / den, y)
    return jnp.maximum(y, _Y_SEPARATION)


# compressions within a few ulps of separation are snapped onto it: y is sqrt-sensitive there (y - y_sep ~ sqrt(d -
# d_sep)), so the last-bit differences of delta/delta_0 between eager and jit-fused evaluation would otherwise move
# a/a_0 by ~1e-8 at -delta_c (the snap itself moves it by at most ~3e-8 relative)
_D_SNAP = D_SEPARATION * (1.0 - 8.0 * 2.0**-52)


@jax.custom_jvp
def _y_of_d(d):
    d = jnp.where(d <= _D_SNAP, D_SEPARATION, d)
    return _y_closed_form(d)


@_y_of_d.defjvp
def _y_of_d_jvp(primals, tangents):
    (d,), (dd,) = primals, tangents
    y = _y_of_d(d)
    den = 12.0 * y**3 - 2.0  # = dd/dy; 0 at separation (vertical tangent of F(delta))
    ok = (d > _D_SNAP) & (den > 0.0)
    dy = jnp.where(ok, 1.0 / jnp.where(ok, den, 1.0), 0.0)
    return y, dy * dd


def contact_radius_ratio(delta, mat):
    """Contact radius over its equilibrium value, a/a_0, at compression ``delta``.

    Arguments:
        delta: compression length delta = 2 r1 - |x_1 - x_2| [cm], any shape. Values below -delta_c are clamped
            to -delta_c (the contact has broken there).
        mat: :class:`~jaxcoag.aggregates.contact.materials.Material` (uses delta_0).

    Returns:
        a/a_0 [-], same shape as ``delta``; 1 at delta_0, (2/3)^(2/3) at 0, 6^(-2/3) at -delta_c. Residual of
        Wada eq. 4 below 1e-12 relative. The derivative (custom_jvp) is the implicit one,
        d(a/a_0)/ddelta = 2 y/((12 y^3 - 2) delta_0), y = (a/a_0)^(1/2); it diverges at -delta_c and is set to 0
        there and below (finite gradients; the force has a vertical tangent at separation).

    References: Wada et al. (2007) eq. 4 (inverted in closed form).
    """
    d = jnp.asarray(delta) / mat.delta0
    y = _y_of_d(d)
    return y * y


def compression(ratio, mat):
    """Compression delta [cm] at contact-radius ratio x = a/a_0: delta = delta_0 (3 x^2 - 2 x^(1/2)) (Wada eq. 4).

    Arguments: ratio: a/a_0 [-] (>= 6^(-2/3) on the contact branch); mat: Material.
    Returns: delta [cm].
    """
    x = jnp.asarray(ratio)
    return mat.delta0 * (3.0 * x**2 - 2.0 * jnp.sqrt(x))


def normal_force(delta, mat):
    """JKR normal force F = 4 F_c [(a/a_0)^3 - (a/a_0)^(3/2)] [dyn] (Wada et al. 2007 eq. 5); F > 0 repulsive.

    Arguments: delta: compression [cm] (in contact: -delta_c <= delta); mat: Material.
    Returns: F [dyn]; 0 at delta_0, -8/9 F_c at 0, -F_c (maximum pull) at -0.48075 delta_c, -5/9 F_c at -delta_c.
    """
    x = contact_radius_ratio(delta, mat)
    return 4.0 * mat.F_c * (x**3 - x**1.5)


def normal_potential(delta, mat):
    """JKR normal potential U_n [erg] of a contact (Wada et al. 2007 eq. 6); dU_n/ddelta = F (eq. 5).

    Arguments: delta: compression [cm] (in contact: -delta_c <= delta); mat: Material.
    Returns: U_n [erg]; U_AT_EQUILIBRIUM F_c delta_c at delta_0, U_AT_ZERO F_c delta_c at 0, 4/45 F_c delta_c at
    -delta_c. (Before a contact forms, U_n = 0: that branch is the caller's.)
    """
    x = contact_radius_ratio(delta, mat)
    return mat.F_c * mat.delta_c * jkr_potential(x)


def normal_force_and_potential(delta, mat):
    """JKR normal force F [dyn] (eq. 5) and potential U_n [erg] (eq. 6) of a contact from one inversion of eq. 4.

    Same values as :func:`normal_force` and :func:`normal_potential`, written in y = (a/a_0)^(1/2) so that only
    integer powers appear (F = 4 F_c (y^6 - y^3), U_n = 4 6^(1/3) F_c delta_c ((4/5) y^10 - (4/3) y^7 + y^4/3)):
    the DEM step evaluates this on every contact slot, where a float64 ``pow`` per slot is a measurable cost.

    Arguments: delta: compression [cm] (in contact: -delta_c <= delta); mat: Material.
    Returns: (F, U_n).
    """
    y = _y_of_d(jnp.asarray(delta) / mat.delta0)
    y2 = y * y
    y3 = y2 * y
    y4 = y2 * y2
    F = 4.0 * mat.F_c * (y3 * y3 - y3)
    U = (4.0 * 6.0 ** (1.0 / 3.0)) * mat.F_c * mat.delta_c * (0.8 * y4 * y4 * y2 - (4.0 / 3.0) * y4 * y3 + y4 / 3.0)
    return F, U


def normal_stiffness(delta, mat):
    """dF/ddelta [dyn cm^-1] of the JKR force: (F_c/delta_0) (12 x^2 - 6 x^(1/2)) / (6 x - x^(-1/2)) with x = a/a_0.

    From eqs. 4-5 by the chain rule; (6/5) F_c/delta_0 at delta_0 (Material.k_n_eq); diverges at -delta_c.
    Arguments: delta [cm]; mat: Material. Returns: stiffness [dyn cm^-1].
    """
    x = contact_radius_ratio(delta, mat)
    sx = jnp.sqrt(x)
    return mat.F_c / mat.delta0 * (12.0 * x**2 - 6.0 * sx) / (6.0 * x - 1.0 / sx)
