"""Fitted laws of Wada et al. (2007) for 2D head-on collisions of BCCA clusters (dimensionless).

Compression of the largest cluster vs impact energy (:func:`wada_rg_ratio`,
:func:`wada_rg_slope`), contacts per particle (:func:`wada_ncon`, :func:`wada_ncon_max`), the
BCCA gyration radius (:func:`wada_bcca_rg`) and the impact energy in units of n_k E_break
(:func:`wada_energy_ratio`).

References: Wada et al. 2007 (ApJ 661, 320) §5, eqs. 45, 48, 51-59.
"""

from __future__ import annotations

import jax.numpy as jnp

from .contact import C_BREAK
from .porosity import _chk

__all__ = ["wada_rg_ratio", "wada_ncon", "wada_rg_slope", "wada_ncon_max", "wada_bcca_rg", "wada_energy_ratio"]


def wada_rg_ratio(x, fit: str = "W51", *, n_k=None, strict: bool = False):
    """Gyration radius of the largest cluster, r_g/(r1 sqrt(N_large)), vs x = E_imp/(n_k E_roll).

    W51 (N_tot = 256 fit): 0.84 x^-0.12; W58 (large N): x^-0.137 (= 1/2 - 1/d_f, d_f = 1.57).

    Arguments:
        x: E_imp/(n_k E_roll) [-] (> 0), E_roll in Wada's convention.
        fit: static, "W51" or "W58".
        n_k: number of contacts (needed with strict=True for the lower bound x >= 1/n_k).
        strict: static; NaN outside the fit's validity (W51: 1/n_k <= x <= 0.1;
            W58: 1/n_k <= x <= 1).

    Returns: r_g/(r1 sqrt(N_large)) [-] (2D; plays the role of psi^(1/2)).
    References: Wada et al. 2007 eqs. 51, 55, 58.
    """
    x = jnp.asarray(x)
    if fit == "W51":
        val, x_hi = 0.84 * x**-0.12, 0.1
    elif fit == "W58":
        val, x_hi = x**-0.137, 1.0  # printed exponent; = 1/2 - 1/d_f (W55), see wada_rg_slope
    else:
        raise ValueError(f"fit={fit!r}: choose 'W51' or 'W58'")
    if not strict:
        return val
    if n_k is None:
        raise ValueError("strict=True needs n_k (number of contacts) for the lower validity bound x >= 1/n_k")
    ok = (x * n_k >= 1.0) & (x <= x_hi)
    return jnp.where(ok, val, jnp.nan)


def wada_rg_slope(d_f=1.57):
    """Slope of log r_g vs log E_imp between the BCCA and compact states: 1/2 - 1/d_f.

    Arguments: d_f: fractal dimension of the 2D BCCA [-] (1.57).
    Returns: slope [-] (-0.136943 for d_f = 1.57; Wada print -0.137).
    References: Wada et al. 2007 eqs. 52-55.
    """
    return 0.5 - 1.0 / jnp.asarray(d_f)


def wada_ncon_max(N, k=1.35):
    """Maximum contacts per particle of a compressed 2D aggregate: k - (k - 1)/sqrt(N).

    Arguments: N: particles [-] (> 0); k [-] (1.3-1.4 quartz, 1.6 ice).
    Returns: n_con,max [-].
    References: Wada et al. 2007 eq. 57.
    """
    return k - (k - 1.0) / jnp.sqrt(jnp.asarray(N, dtype=jnp.result_type(float)))


def wada_ncon(x, N=None, k=1.35, *, strict: bool = False):
    """Contacts per particle in the largest cluster: n_con = 1 + x^0.75, x = E_imp/(n_k E_roll),
    capped at n_con,max(N, k) when N is given.

    Arguments: x [-] (> 0); N: particles [-] or None (no cap); k [-]; strict: static, NaN
    for x > 0.1 (W56 validity).
    Returns: n_con [-].
    References: Wada et al. 2007 eqs. 56, 57, 59.
    """
    x = jnp.asarray(x)
    val = 1.0 + x**0.75
    if N is not None:
        val = jnp.minimum(val, wada_ncon_max(N, k))
    if strict:
        val = jnp.where(x <= 0.1, val, jnp.nan)
    return val


def wada_bcca_rg(N):
    """Gyration radius of a 2D BCCA in monomer radii: r_g/r1 = (N/1.37)^(1/1.57).

    Arguments: N: particles [-] (> 0).
    Returns: r_g/r1 [-] (N = 8 -> 3.0770; N = 2048 -> 105.21).
    References: Wada et al. 2007 eq. 53.
    """
    N = _chk(N, "N", positive=True)
    return (N / 1.37) ** (1.0 / 1.57)


def wada_energy_ratio(N, v_over_v0, c_break=C_BREAK):
    """E_imp/(n_k E_break) for a head-on collision of two halves of N_tot = N monomers.

    E_imp = N m1 v^2/8 (centre-of-mass frame), n_k = N - 2, E_break = c_break F_c delta_c,
    v0 = sqrt(F_c delta_c/m1): ratio = N (v/v0)^2 / (8 c_break (N - 2)).

    Arguments: N [-] (> 2); v_over_v0 [-]; c_break [-] (1.542585; Wada rounds to 1.54).
    Returns: x_break [-] (N = 1024, 5.7 v0 -> 2.638; 2.642 with c_break = 1.54).
    References: Wada et al. 2007 §5.1, eqs. 45, 48.
    """
    N = _chk(N, "N", positive=True)
    return N * jnp.asarray(v_over_v0) ** 2 / (8.0 * c_break * (N - 2.0))
