"""Pairwise relative velocities of dust particles in a radial disk cell, as DustPy 1.0.9 computes them.

Every function returns the pair array (..., nm, nm) [cm s^-1] for per-cell inputs (radial quantities of
shape (...,), i.e. () for one cell or (nr,) for the whole grid; per-bin quantities (..., nm)). The arrays
are symmetric, as DustPy's ``std.dust.vrel_*`` routines fill both triangles. All functions are pure jnp,
jit-able, vmap-able over a leading parameter batch and differentiable: components are combined with ONE
safe square root of the quadrature sum (:func:`dv_total`), so gradients stay finite on the diagonal
where several components vanish.

Components (Stammler & Birnstiel 2022, ApJ 935, 35, §2.3.1; Birnstiel, Dullemond & Brauer 2010, A&A 513,
A79, §3.1):

* :func:`dv_brownian` -- Brownian motion, capped at the sound speed (as DustPy 1.0.9);
* :func:`dv_turbulent_oc07_dustpy` -- DustPy's closed-form Ormel & Cuzzi (2007) turbulent velocities
  with its six regimes;
* :func:`dv_radial_drift`, :func:`dv_azimuthal_drift` -- differential radial and azimuthal drift;
* :func:`dv_settling` -- differential vertical settling;
* :func:`dv_total` / :func:`dv_total_dustpy` -- the quadrature sum.

How these differ from the 0-D engine's physics (``jaxcoag.physics.drift`` and ``turbulence``): there the
Brownian velocity is not capped, the drift velocities are written with eta and v_K, settling uses
St/(1+St) at a height z, and turbulence offers the exact OC07 eq. (21) root. DustPy's forms are kept
here so that the disk model reproduces DustPy's numbers; they are written out below, not imported.
"""

from __future__ import annotations

import jax.numpy as jnp

from .. import constants as C
from .._validate import JaxcoagInputError
from ..physics.safe import safe_sqrt

__all__ = ["dv_brownian", "dv_turbulent_oc07_dustpy", "dv_radial_drift", "dv_azimuthal_drift", "dv_settling",
           "dv_total", "dv_total_dustpy"]

# DustPy 1.0.9 constants.f90 values (identical to jaxcoag.constants): k_B [erg K^-1], sigma_H2 [cm^2]
_K_B = C.k_B
_SIGMA_H2 = C.sigma_mol

# Ormel & Cuzzi (2007) eq. (28) fit y*(St) = c0 + c1 St + c2 St^2 + c3 St^3 and y_a = 1.6 (their §3.4),
# the coefficients DustPy 1.0.9 uses in ``vrel_ormel_cuzzi_2007``.
_OC07_C = (1.6015125, -0.63119577, 0.32938936, -0.29847604)
_OC07_YA = 1.6


def _f(x):
    return jnp.asarray(x, dtype=jnp.result_type(float))


def _col(x, batch=None):
    """A radial quantity (...,) as (..., 1, 1) to broadcast against pair arrays (..., nm, nm); with
    ``batch`` (a shape), first broadcast to it (explicit ranks: the project runs with
    jax_numpy_rank_promotion='raise')."""
    x = _f(x)
    if batch is not None:
        x = jnp.broadcast_to(x, jnp.broadcast_shapes(jnp.shape(x), tuple(batch)))
    return x[..., None, None]


def _pair_diff_abs(q):
    """|q_j - q_i| as (..., nm, nm) from q (..., nm)."""
    q = jnp.asarray(q)
    return jnp.abs(q[..., :, None] - q[..., None, :])


def dv_brownian(cs, m, T):
    """Brownian relative velocity [cm s^-1], (..., nm, nm).

    dv_ij = min( sqrt(8 k_B T (m_i + m_j) / (pi m_i m_j)), c_s )  (Birnstiel et al. 2010 eq. 14 with
    DustPy 1.0.9's cap at the sound speed, ``vrel_brownian_motion``). Note that DustPy's formula has no
    mean molecular weight: the gas enters only through T and the cap c_s; our 0-D ``physics.drift.
    dv_brownian`` has the same square root but no cap.

    Arguments:
        cs: (...,) isothermal sound speed [cm s^-1]; m: (nm,) particle masses [g]; T: (...,) gas
        temperature [K].
    """
    m = _f(m)
    batch = jnp.broadcast_shapes(jnp.shape(cs), jnp.shape(T))
    fac = (8.0 * _K_B / jnp.pi) * _col(T, batch)
    msum_over_mprod = (m[:, None] + m[None, :]) / (m[:, None] * m[None, :])
    msum_over_mprod = msum_over_mprod.reshape((1,) * len(batch) + msum_over_mprod.shape)
    return jnp.minimum(jnp.sqrt(fac * msum_over_mprod), _col(cs, batch))


def dv_turbulent_oc07_dustpy(alpha, cs, mu, omega, Sigma_g, St):
    """Turbulent relative velocity of Ormel & Cuzzi (2007) in DustPy 1.0.9's closed form [cm s^-1].

    With Re = alpha Sigma_g sigma_H2 / (2 mu) (mu: the mean molecular MASS [g], DustPy's ``gas.mu``),
    v_n = sqrt(alpha) c_s, the Kolmogorov time and speed t_s = Re^(-1/2)/Omega, v_s = Re^(-1/4) v_n,
    v_g^2 = 1.5 v_n^2, St_L = max(St_i, St_j), St_S = min, eps = St_S/St_L, tau = St/Omega and
    y* = c0 + c1 St_L + c2 St_L^2 + c3 St_L^3 (OC07 eq. 28 fit), dv^2 is (DustPy's regimes, tested in
    this order):

    1. tau_L < 0.2 t_s:            1.5 (v_s/t_s (tau_L - tau_S))^2                 (OC07 eq. 27)
    2. tau_L y_a < t_s:            v_g^2 (St_L-St_S)/(St_L+St_S) (St_L^2/(St_L+Re^-1/2) - St_S^2/(St_S+Re^-1/2))
                                                                                  (OC07 eq. 16 limit)
    3. tau_L < 5 t_s:              v_g^2 (h1 + h2) (OC07 eqs. 17-18 with St* = y_a St_L)
    4. tau_L < 0.2/Omega:          v_g^2 St_L (2 y_a - 1 - eps + 2/(1+eps) (1/(1+y_a) + eps^3/(y_a+eps)))
                                                                                  (OC07 eq. 29)
    5. tau_L < 1/Omega:            the same with y* in place of y_a
    6. otherwise:                  v_g^2 (2 + St_L + St_S)/(1 + St_L + St_S + St_L St_S)   (OC07 eq. 30)

    and dv = sqrt(dv^2) (a safe square root: 0 with zero gradient where dv^2 <= 0, e.g. equal particles in
    regimes 1-2). Every branch is evaluated with finite values, so gradients are finite. Our 0-D
    ``physics.turbulence.dv_turbulent_oc07`` solves OC07's eq. (21) instead of these fits.

    Arguments:
        alpha: (...,) turbulence parameter delta_turb; cs: (...,) sound speed [cm s^-1]; mu: (...,) or
        scalar mean molecular mass [g]; omega: (...,) Keplerian frequency [s^-1]; Sigma_g: (...,) gas
        surface density [g cm^-2]; St: (..., nm) Stokes numbers.
    Returns (..., nm, nm) [cm s^-1].
    """
    c0, c1, c2, c3 = _OC07_C
    ya = _OC07_YA
    yap1inv = 1.0 / (1.0 + ya)
    St = _f(St)
    batch = St.shape[:-1]
    alpha, cs, mu, omega, Sigma_g = (_col(x, batch) for x in (alpha, cs, mu, omega, Sigma_g))
    omkinv = 1.0 / omega
    Re = 0.5 * alpha * Sigma_g * _SIGMA_H2 / mu
    re_inv_sqrt = jnp.sqrt(1.0 / Re)
    vn = jnp.sqrt(alpha) * cs
    vs = Re ** (-0.25) * vn
    ts = omkinv * re_inv_sqrt
    vg2 = 1.5 * vn ** 2

    sti, stj = St[..., :, None], St[..., None, :]
    stl = jnp.maximum(sti, stj)
    sts = jnp.minimum(sti, stj)
    eps = sts / stl
    taul = stl * omkinv
    taus = sts * omkinv
    ys = c0 + c1 * stl + c2 * stl ** 2 + c3 * stl ** 3
    h1 = (stl - sts) / (stl + sts) * (stl * yap1inv - sts ** 2 / (sts + ya * stl))
    h2 = (2.0 * (ya * stl - re_inv_sqrt) + stl * yap1inv - stl ** 2 / (stl + re_inv_sqrt)
          + sts ** 2 / (ya * stl + sts) - sts ** 2 / (sts + re_inv_sqrt))

    v1 = 1.5 * (vs / ts * (taul - taus)) ** 2
    v2 = vg2 * (stl - sts) / (stl + sts) * (stl ** 2 / (stl + re_inv_sqrt) - sts ** 2 / (sts + re_inv_sqrt))
    v3 = vg2 * (h1 + h2)
    v4 = vg2 * stl * (2.0 * ya - 1.0 - eps + 2.0 / (1.0 + eps) * (yap1inv + eps ** 3 / (ya + eps)))
    v5 = vg2 * stl * (2.0 * ys - 1.0 - eps + 2.0 / (1.0 + eps) * (1.0 / (1.0 + ys) + eps ** 3 / (ys + eps)))
    v6 = vg2 * (2.0 + stl + sts) / (1.0 + stl + sts + stl * sts)

    dv2 = jnp.where(taul < 0.2 * ts, v1,
          jnp.where(taul * ya < ts, v2,
          jnp.where(taul < 5.0 * ts, v3,
          jnp.where(taul < 0.2 * omkinv, v4,
          jnp.where(taul < omkinv, v5, v6)))))
    return safe_sqrt(dv2)


def dv_radial_drift(v_rad):
    """Relative velocity from differential radial drift |v_i - v_j| [cm s^-1], (..., nm, nm).

    DustPy 1.0.9 ``vrel_radial_drift`` (Birnstiel et al. 2010 §3.1), from the radial dust velocities
    v_rad (..., nm) [cm s^-1] (drift plus gas advection, Stammler & Birnstiel 2022 eq. 16).
    """
    return _pair_diff_abs(v_rad)


def dv_azimuthal_drift(v_drift_max, St):
    """Relative velocity from differential azimuthal drift [cm s^-1], (..., nm, nm).

    dv_ij = | v_dm ((1+St_i^2) - (1+St_j^2)) / ((1+St_i^2)(1+St_j^2)) |, i.e. |v_dm| |1/(1+St_j^2) -
    1/(1+St_i^2)| in DustPy 1.0.9's algebraic form (``vrel_azimuthal_drift``; Weidenschilling 1977,
    Nakagawa et al. 1986). v_drift_max: (...,) maximum drift velocity [cm s^-1]; St: (..., nm).
    """
    St = _f(St)
    s2 = St ** 2 + 1.0
    si, sj = s2[..., :, None], s2[..., None, :]
    return jnp.abs(_col(v_drift_max, St.shape[:-1]) * (sj - si) / (sj * si))


def dv_settling(H, omega, St):
    """Relative velocity from differential vertical settling [cm s^-1], (..., nm, nm).

    dv_ij = | Omega H_i min(St_i, 1/2) - Omega H_j min(St_j, 1/2) |: the settling speed Omega St z at
    one dust scale height, with St capped at 1/2 (DustPy 1.0.9 ``vrel_vertical_settling``; Birnstiel et
    al. 2010 §3.1). Our 0-D ``physics.drift.dv2_settling`` uses St/(1+St) at a given height z instead.
    H: (..., nm) dust scale heights [cm]; omega: (...,) [s^-1]; St: (..., nm).
    """
    H, St = _f(H), _f(St)
    om = jnp.broadcast_to(_f(omega), H.shape[:-1])[..., None]
    w = om * H * jnp.minimum(St, 0.5)
    return _pair_diff_abs(w)


def dv_total(*components):
    """Quadrature sum sqrt(sum_c dv_c^2) [cm s^-1] of pair arrays (DustPy 1.0.9 ``vrel_tot``), with a safe
    square root (finite gradient where the sum is 0)."""
    if not components:
        raise JaxcoagInputError("dv_total(*components) needs at least one (..., nm, nm) velocity array.")
    tot = components[0] ** 2
    for c in components[1:]:
        tot = tot + c ** 2
    return safe_sqrt(tot)


def dv_total_dustpy(*, m, T, cs, mu, alpha, omega, sigma_gas, St, v_rad, v_drift_max, H):
    """DustPy's total relative velocity (..., nm, nm) [cm s^-1]: azimuthal drift, Brownian motion, radial
    drift, Ormel & Cuzzi (2007) turbulence and vertical settling added in quadrature (DustPy 1.0.9
    ``vrel_tot``; Stammler & Birnstiel 2022 §2.3.1).

    Arguments (radial quantities (...,), per-bin (..., nm)): m (nm,) [g]; T [K]; cs [cm s^-1]; mu mean
    molecular mass [g]; alpha the turbulence parameter delta_turb; omega [s^-1]; sigma_gas [g cm^-2];
    St (..., nm); v_rad (..., nm) [cm s^-1]; v_drift_max [cm s^-1]; H (..., nm) dust scale heights [cm].
    """
    return dv_total(dv_azimuthal_drift(v_drift_max, St), dv_brownian(cs, m, T), dv_radial_drift(v_rad),
                    dv_turbulent_oc07_dustpy(alpha, cs, mu, omega, sigma_gas, St), dv_settling(H, omega, St))
