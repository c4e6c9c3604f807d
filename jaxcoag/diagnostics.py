"""Diagnostics on binned mass distributions: moments, errors vs a reference, peak, m^2 f(m).

All functions accept numpy or JAX arrays (mass per bin rho_b [g cm^-3] on a grid with edges
[g]) and broadcast over leading axes (e.g. output times), so they work on any result's
``mass_per_bin(edges)`` with ``bin_edges(edges)`` (binned and Monte Carlo alike; the results'
``m2f`` and ``mass_peak`` methods call them), on a dataset's ``mass_per_bin`` with ``m_edge``, and
inside jit/grad. JAX arrays (and tracers) are computed with ``jax.numpy`` and give JAX arrays; numpy
input is computed with numpy and gives numpy (float64) values: eager ``jax.numpy`` compiles every
operation for every new shape, ~0.1-0.5 s of a ``jaxcoag run``'s output phase for a few such calls.

References: error metrics and noise floor in docs/design_notes.md (Monte Carlo conventions);
Ormel (2008) thesis §5.3 (m^2 f(m) plots); Birnstiel et al. (2010) (mass peak).
"""

from __future__ import annotations

import jax
import numpy as np
import jax.numpy as jnp

from ._validate import JaxcoagInputError

__all__ = ["moments", "moment", "l1_error", "mass_peak", "m2f", "bin_centers"]


def _log_edges(edges):
    e = np.asarray(getattr(edges, "edges", edges), float)
    if e.ndim != 1 or e.size < 2 or not np.all(e > 0) or not np.all(np.diff(e) > 0):
        raise JaxcoagInputError("edges must be strictly increasing positive masses [g] (or a MassGrid).")
    if hasattr(edges, "log_edges"):
        return np.asarray(edges.log_edges)
    return np.log(e)


def _xp(*xs):
    """``jax.numpy`` when any argument is a JAX array or tracer, else ``numpy`` (module docstring)."""
    return jnp if any(isinstance(x, jax.Array) for x in xs) else np


def _row(v, like, xp=jnp):
    """Reshape a per-bin vector (nbins,) to broadcast explicitly against ``like`` (..., nbins)."""
    v = xp.asarray(v)
    return v.reshape((1,) * (xp.ndim(like) - 1) + v.shape)


def bin_centers(edges):
    """Geometric bin centers sqrt(m_lo m_hi) [g] from edges [g] (or a MassGrid)."""
    le = _log_edges(edges)
    return np.exp(0.5 * (le[:-1] + le[1:]))


def moment(rho, edges, p):
    """Moment M_p = sum_b rho_b m_b^{p-1} [g^p cm^-3] of a mass-per-bin distribution.

    Arguments:
        rho: mass density per bin [g cm^-3], shape (..., nbins).
        edges: bin edges [g] (nbins+1,) or a MassGrid; m_b is the geometric center.
        p: order (float; p = 1 is the total mass, p = 0 the number density [cm^-3]).
    Returns: array (...,).
    References: thesis eq. 5.4 (moments), Table 5.1.
    """
    xp = _xp(rho, p)
    le = _log_edges(edges)
    lc = 0.5 * (le[:-1] + le[1:])
    rho = xp.asarray(rho, np.float64) if xp is np else rho
    w = xp.exp((p - 1.0) * xp.asarray(lc))
    return xp.sum(rho * _row(w, rho, xp), axis=-1)


def moments(rho, edges, ps=(0, 1, 2)):
    """Tuple of moments M_p for p in ``ps`` (see :func:`moment`)."""
    return tuple(moment(rho, edges, p) for p in ps)


def l1_error(rho, rho_ref):
    """Relative L1 error of mass per bin: sum_b |rho_b - rho_b^A| / sum_b rho_b^A.

    Arguments: rho, rho_ref: mass per bin [g cm^-3] on the same bins, (..., nbins).
    Returns: dimensionless array (...,) (0 = exact; 2 = disjoint supports).
    References: E_mass in docs/design_notes.md (it is half of this for normalised spectra).
    """
    xp = _xp(rho, rho_ref)
    rho = xp.asarray(rho)
    rho_ref = xp.asarray(rho_ref)
    return xp.sum(xp.abs(rho - rho_ref), axis=-1) / xp.sum(rho_ref, axis=-1)


def mass_peak(rho, edges):
    """Mass peak m_p [g]: center of the bin holding the most mass per ln m (rho_b / dln m_b),
    refined by a parabola through the neighbouring log values (uniform log grids).

    Arguments: rho (..., nbins) [g cm^-3]; edges [g] or MassGrid.
    Returns: (...,) peak mass [g].
    References: thesis §5.3 (peak of m^2 f); Birnstiel et al. (2010).
    """
    xp = _xp(rho)
    le = _log_edges(edges)
    lc = xp.asarray(0.5 * (le[:-1] + le[1:]))
    dl = xp.asarray(np.diff(le))
    rho = xp.asarray(rho, np.float64) if xp is np else rho
    y = rho / _row(dl, rho, xp)
    i = xp.argmax(y, axis=-1)
    n = y.shape[-1]
    im, ip = xp.clip(i - 1, 0, n - 1), xp.clip(i + 1, 0, n - 1)
    ly = xp.log(xp.maximum(y, 1e-300))
    take = lambda a, j: xp.take_along_axis(a, j[..., None], axis=-1)[..., 0]
    y0, ym, yp = take(ly, i), take(ly, im), take(ly, ip)
    den = ym - 2.0 * y0 + yp
    with np.errstate(divide="ignore", invalid="ignore"):
        h = xp.where((i > 0) & (i < n - 1) & (den < 0), 0.5 * (ym - yp) / xp.where(den < 0, den, -1.0), 0.0)
        return xp.exp(lc[i] + h * dl[i])


def m2f(rho, edges):
    """m^2 f(m) per bin [g cm^-3] ~ mass per unit ln m: rho_b / dln m_b (thesis plots' ordinate).

    Arguments: rho (..., nbins) [g cm^-3]; edges [g] or MassGrid.
    Returns: (..., nbins) [g cm^-3] (m^2 f = m dN/dm m = d rho/d ln m).
    References: Ormel (2008) thesis Figs. 5.3-5.9.
    """
    xp = _xp(rho)
    le = _log_edges(edges)
    rho = xp.asarray(rho, np.float64) if xp is np else rho
    return rho / _row(np.diff(le), rho, xp)
