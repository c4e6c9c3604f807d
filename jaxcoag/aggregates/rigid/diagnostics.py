"""Aggregate diagnostics of the periodic-box runs (Richardson 1995 §3, Figs. 6, 8, 10, 11).

Definitions (R95 §3; the spec's A9 fixes the points the paper leaves open):

* ``R_max`` (R7): largest extent ``max_i (r_i + R_i)`` of the member spheres about the COM.
* fractal dimension per aggregate: sort the member distances from the COM, ``r_(1) <= ... <= r_(N_a)``,
  set ``N(<r_(k)) = k`` and take the least-squares slope of ``log k`` against ``log r_(k)``; its error is
  the regression standard error. Only aggregates with ``N_a >= 3`` are fitted. R95 does not say whether
  the distance is to the sphere centre or to its outer edge; the default (``include_radius=False``) uses the
  member-centre distances ``r_i``, as the spec's A9 reads it (a member exactly at the COM, r = 0, keeps its rank
  k but is left out of the fit); ``include_radius=True`` fits ``r_i + R_i``. Measured on models (iii)/(iv) at
  T = 8.2 (stop 27), the centre reading reproduces R95's f_D = 1.7-1.8 and the edge reading is 0.35-0.4 higher.
  The mean f_D of a population is weighted by ``1/σ²``.
* spherically averaged density ``ρ = M / ((4/3) π R_max³)``; γ is the log-log slope of ρ against N_a,
  and ``f_D = 3 / (1 − γ)`` (R32) relates the two.
* power laws ``R_max ∝ N_a^s`` and ``ρ ∝ N_a^γ``: least-squares slopes in log-log (``N_a >= 2``).
* velocity dispersion: number-weighted standard deviation of each COM velocity component.

Plain numpy (host-side post-processing of :class:`~jaxcoag.aggregates.rigid.box.BoxResult` outputs),
except :func:`velocity_dispersion`, which is traceable.

References: Richardson (1995, Icarus 115, 320) eqs. (7), (32) and §3 (Figs. 6, 8, 10, 11).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from ..._validate import JaxcoagInputError

__all__ = ["r_max", "fractal_dimension", "weighted_mean", "density", "power_law", "fd_from_gamma",
           "velocity_dispersion"]


def r_max(sph_r, sph_agg, sph_R, n_slots=None):
    """R_max of every aggregate slot (R7): ``max over members of (r_i + R_i)``.

    Arguments:
        sph_r: (n,) distance of each sphere centre from its aggregate's COM [length].
        sph_agg: (n,) owning slot of each sphere (int).
        sph_R: (n,) sphere radii [length].
        n_slots: number of slots (default n).

    Returns:
        (n_slots,) R_max [length] (0 for slots without members).

    References: Richardson (1995) eq. (7).
    """
    r = np.asarray(sph_r, np.float64) + np.asarray(sph_R, np.float64)
    g = np.asarray(sph_agg, np.int64)
    out = np.zeros(len(r) if n_slots is None else int(n_slots))
    np.maximum.at(out, g, r)
    return out


def fractal_dimension(sph_r, sph_agg, sph_R, *, include_radius=False, min_members=3):
    """Fractal dimension of every aggregate by the sorted-distance regression (R95 §3, Fig. 6b).

    For the members of one aggregate, sorted by distance ``r_(k)`` from the COM (plus the sphere
    radius when ``include_radius``), the least-squares fit ``log k = f_D log r_(k) + c`` over
    k = 1..N_a gives f_D, and its standard error ``sqrt(Σ res² / (N_a − 2) / Σ (x − x̄)²)``.

    Arguments:
        sph_r: (n,) member-centre distances from their aggregate's COM [length].
        sph_agg: (n,) owning slot of each sphere.
        sph_R: (n,) sphere radii [length].
        include_radius: fit the centre distance ``r`` (False, the default) or ``r + R`` (True).
        min_members: smallest N_a fitted (default 3; a 2-point fit has no error).

    Returns:
        ``(f_D, err)``, each (n,) indexed by slot, NaN for slots with fewer than ``min_members`` members.

    References: Richardson (1995) §3 (Figs. 6b, 8b, 10b).
    """
    r = np.asarray(sph_r, np.float64) + (np.asarray(sph_R, np.float64) if include_radius else 0.0)
    g = np.asarray(sph_agg, np.int64)
    n = len(r)
    if min_members < 3:
        raise JaxcoagInputError("fractal_dimension: min_members must be >= 3 (a regression error needs 3 points).")
    order = np.lexsort((r, g))
    gs, rs = g[order], r[order]
    counts = np.bincount(gs, minlength=n)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    k = np.arange(n) - start[gs] + 1.0
    ok = (counts[gs] >= min_members) & (rs > 0)
    x = np.where(ok, np.log(np.where(rs > 0, rs, 1.0)), 0.0)
    y = np.where(ok, np.log(k), 0.0)
    w = ok.astype(float)
    S = lambda v: np.bincount(gs, weights=v * w, minlength=n)  # noqa: E731
    m = S(np.ones(n))
    sx, sy, sxx, sxy, syy = S(x), S(y), S(x * x), S(x * y), S(y * y)
    with np.errstate(divide="ignore", invalid="ignore"):
        Sxx = sxx - sx * sx / m
        Sxy = sxy - sx * sy / m
        Syy = syy - sy * sy / m
        slope = Sxy / Sxx
        res = np.maximum(Syy - slope * Sxy, 0.0)
        err = np.sqrt(res / (m - 2) / Sxx)
    good = (m >= min_members) & (Sxx > 0)
    return np.where(good, slope, np.nan), np.where(good, err, np.nan)


def weighted_mean(values, errors):
    """Inverse-variance weighted mean ``Σ v/σ² / Σ 1/σ²`` and its error ``(Σ 1/σ²)^(-1/2)`` over the finite
    entries with σ > 0 (R95 §3: the mean f_D). Returns (nan, nan) when there is none."""
    v = np.asarray(values, np.float64)
    s = np.asarray(errors, np.float64)
    ok = np.isfinite(v) & np.isfinite(s) & (s > 0)
    if not ok.any():
        return math.nan, math.nan
    w = 1.0 / s[ok] ** 2
    return float(np.sum(w * v[ok]) / np.sum(w)), float(1.0 / math.sqrt(np.sum(w)))


def density(mass, rmax):
    """Spherically averaged density ``ρ = M / ((4/3) π R_max³)`` [mass / length³] (R95 §3, Fig. 6c)."""
    return np.asarray(mass, np.float64) / (4.0 / 3.0 * math.pi * np.asarray(rmax, np.float64) ** 3)


def power_law(n_a, y, *, n_min=2):
    """Least-squares slope of ``log y`` against ``log N_a`` over ``N_a >= n_min``, with its standard error.

    Used for ``R_max ∝ N_a^s`` (R95: s = 0.57 ± 0.01 in model iii) and ``ρ ∝ N_a^γ`` (γ = −0.71 ± 0.03).

    Returns:
        ``(slope, err, intercept)`` (NaN when fewer than 3 points or a single N_a).

    References: Richardson (1995) §3 (Figs. 6a, 6c, 8, 10).
    """
    n_a = np.asarray(n_a, np.float64)
    y = np.asarray(y, np.float64)
    ok = (n_a >= n_min) & np.isfinite(y) & (y > 0)
    x, yy = np.log(n_a[ok]), np.log(y[ok])
    if len(x) < 3 or np.ptp(x) == 0:
        return math.nan, math.nan, math.nan
    xm, ym = x.mean(), yy.mean()
    Sxx = np.sum((x - xm) ** 2)
    slope = np.sum((x - xm) * (yy - ym)) / Sxx
    res = yy - ym - slope * (x - xm)
    err = math.sqrt(np.sum(res**2) / (len(x) - 2) / Sxx)
    return float(slope), float(err), float(ym - slope * xm)


def fd_from_gamma(gamma):
    """Fractal dimension implied by the density slope, ``f_D = 3 / (1 − γ)`` (R95 eq. 32)."""
    return 3.0 / (1.0 - np.asarray(gamma, np.float64))


def velocity_dispersion(V, alive):
    """(3,) number-weighted standard deviation of each COM velocity component over the live aggregates.

    Arguments:
        V: (n, 3) COM velocities; alive: (n,) bool.

    References: Richardson (1995) §3 (Fig. 11a).
    """
    w = jnp.asarray(alive, jnp.float64)
    nw = jnp.maximum(jnp.sum(w), 1.0)
    mean = jnp.sum(w[:, None] * V, axis=0) / nw
    return jnp.sqrt(jnp.sum(w[:, None] * (V - mean[None, :]) ** 2, axis=0) / nw)
