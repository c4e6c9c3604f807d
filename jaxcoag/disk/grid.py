"""Radial and mass grids of the 1-D disk model, interface interpolation, and the boundary rows shared
by the gas and dust implicit steps (as DustPy 1.0.9).

Grids (Stammler & Birnstiel 2022, ApJ 935, 35, §2.1; DustPy 1.0.9 ``Simulation._makeradialgrid``,
``_makemassgrid``):

* radial: ``nr + 1`` log-spaced interfaces ``ri`` from ``r_min`` to ``r_max``; cell centres
  ``r = (ri[:-1] + ri[1:]) / 2`` (arithmetic mean, as DustPy 1.0.9); annulus areas
  ``area = pi (ri[1:]^2 - ri[:-1]^2)``;
* mass: ``nm = int(ceil(log10(m_max/m_min)) * bins_per_decade) + 1`` log-spaced masses from ``m_min``
  to ``m_max`` (DustPy rounds the number of decades up before multiplying, so a non-integer number of
  decades gives a slightly coarser spacing than ``bins_per_decade``).

Interpolation to interfaces (:func:`interp_to_interfaces`) is DustPy's ``interp1d``: linear between
neighbouring centres, linear extrapolation of the first and last segment to ``ri[0]`` and ``ri[-1]``.

Boundary conditions (DustPy 1.0.9 ``utils/boundary.py`` and the ``const_grad`` branch of
``std.gas._f_impl_1_direct`` / ``std.dust.jacobian``). DustPy's default inner condition is a
"constant gradient" of r Sigma. It enters twice, with two different weights:

* in the implicit matrix (I - dt J) the first row is ``Sigma0 + K1 Sigma1 + K2 Sigma2 = 0`` with
  ``Di = ri1/ri2 (r1 - r0)/(r2 - r0)``, ``K1 = -r1/r0 (1 + Di)``, ``K2 = r2/r0 Di``
  (:func:`const_grad_row`; the step size cancels: DustPy writes ``-K/dt`` into J);
* after the step, the finaliser overwrites Sigma0 with ``(1 + D) r1/r0 Sigma1 - D r2/r0 Sigma2``,
  ``D = ri1/ri2 (r1 - r0)/(r2 - r1)`` (:func:`const_grad_value`; note r2 - r1, not r2 - r0).

Both are reproduced for parity. All functions are pure, jit/vmap/grad safe; ``nr`` is static.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax.lax.linalg import tridiagonal_solve

from .._validate import JaxcoagInputError

__all__ = [
    "RadialGrid",
    "radial_grid",
    "mass_grid",
    "interp_to_interfaces",
    "const_grad_row",
    "const_grad_value",
    "implicit_tridiagonal_step",
]


class RadialGrid(NamedTuple):
    """Radial grid of the disk (numpy float64, cgs).

    Fields:
        ri: (nr+1,) cell interfaces [cm], log-spaced.
        r: (nr,) cell centres [cm], arithmetic means of the interfaces.
        area: (nr,) annulus areas pi (ri[1:]^2 - ri[:-1]^2) [cm^2].
    """

    ri: np.ndarray
    r: np.ndarray
    area: np.ndarray


def _positive_float(x, name, hint):
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise JaxcoagInputError(f"argument `{name}` must be a positive number; {hint} (got {x!r})") from None
    if not (math.isfinite(v) and v > 0.0):
        raise JaxcoagInputError(f"argument `{name}` must be finite and > 0; {hint} (got {x!r})")
    return v


def radial_grid(r_min, r_max, nr) -> RadialGrid:
    """Log-spaced radial grid as DustPy 1.0.9 (``Simulation._makeradialgrid``).

    Arguments:
        r_min: inner edge of the first cell [cm] (> 0), e.g. 1 au = 1.495978707e13 cm.
        r_max: outer edge of the last cell [cm] (> r_min).
        nr: number of cells (int >= 3: the boundary rows use three cells).

    Returns:
        :class:`RadialGrid` (ri (nr+1,), r (nr,), area (nr,)), numpy float64.

    References: Stammler & Birnstiel (2022) ApJ 935, 35, §2.1.
    """
    r_min = _positive_float(r_min, "r_min", "pass the inner disk edge in cm (1 au = 1.495978707e13 cm)")
    r_max = _positive_float(r_max, "r_max", "pass the outer disk edge in cm (1 au = 1.495978707e13 cm)")
    if not r_max > r_min:
        raise JaxcoagInputError(f"r_max ({r_max!r} cm) must be larger than r_min ({r_min!r} cm); swap them or widen the grid")
    if isinstance(nr, bool) or not isinstance(nr, (int, np.integer)) or nr < 3:
        raise JaxcoagInputError(
            f"argument `nr` must be an int >= 3 (the boundary conditions use three cells), got {nr!r}"
        )
    ri = np.logspace(np.log10(r_min), np.log10(r_max), num=int(nr) + 1, base=10.0)
    r = 0.5 * (ri[:-1] + ri[1:])
    area = np.pi * (ri[1:] ** 2 - ri[:-1] ** 2)
    return RadialGrid(ri=ri, r=r, area=area)


def mass_grid(m_min, m_max, bins_per_decade) -> np.ndarray:
    """Log-spaced mass grid as DustPy 1.0.9 (``Simulation._makemassgrid``).

    ``nm = int(ceil(log10(m_max) - log10(m_min)) * bins_per_decade) + 1``; masses
    ``logspace(log10 m_min, log10 m_max, nm)``.

    Arguments:
        m_min: smallest mass [g] (> 0), DustPy default 1e-12.
        m_max: largest mass [g] (> m_min), DustPy default 1e5.
        bins_per_decade: bins per decade (> 0), DustPy default 7.

    Returns:
        m: (nm,) numpy float64 [g].

    References: Stammler & Birnstiel (2022) §2.1.
    """
    m_min = _positive_float(m_min, "m_min", "pass the smallest grain mass in g (DustPy: 1e-12)")
    m_max = _positive_float(m_max, "m_max", "pass the largest grain mass in g (DustPy: 1e5)")
    bpd = _positive_float(bins_per_decade, "bins_per_decade", "pass the number of mass bins per decade (DustPy: 7)")
    if not m_max > m_min:
        raise JaxcoagInputError(f"m_max ({m_max!r} g) must be larger than m_min ({m_min!r} g)")
    decades = np.ceil(np.log10(m_max) - np.log10(m_min))
    nm = int(decades * bpd) + 1
    return np.logspace(np.log10(m_min), np.log10(m_max), num=nm, base=10.0)


def interp_to_interfaces(y, r, ri):
    """Linear interpolation from cell centres to interfaces, linear extrapolation at both ends.

    DustPy 1.0.9 ``utils/interpolation.f90`` ``interp1d``: ``yi[i] = y[i-1] + m[i-1] (ri[i] - r[i-1])``
    for i = 1..nr-1 with slopes ``m[i] = (y[i+1] - y[i])/(r[i+1] - r[i])``; ``yi[0]`` and ``yi[nr]``
    extrapolate the first and last segment.

    Arguments:
        y: (nr, ...) values at the cell centres (any trailing shape).
        r: (nr,) cell centres [cm].
        ri: (nr+1,) interfaces [cm].

    Returns:
        yi: (nr+1, ...) values at the interfaces.
    """
    y = jnp.asarray(y)
    r = jnp.asarray(r)
    ri = jnp.asarray(ri)
    extra = (1,) * (y.ndim - 1)
    rr = r.reshape(r.shape + extra)
    rri = ri.reshape(ri.shape + extra)
    m = (y[1:] - y[:-1]) / (rr[1:] - rr[:-1])  # (nr-1, ...)
    inner = y[:-1] + m * (rri[1:-1] - rr[:-1])  # interfaces 1..nr-1
    first = y[:1] + m[:1] * (rri[:1] - rr[:1])
    last = y[-1:] + m[-1:] * (rri[-1:] - rr[-1:])
    return jnp.concatenate([first, inner, last], axis=0)


def const_grad_row(r, ri):
    """Coefficients (K1, K2) of the inner "constant gradient" row of the implicit matrix.

    The first row of (I - dt J) in DustPy 1.0.9 (``std.gas._f_impl_1_direct`` and ``std.dust.jacobian``,
    condition ``const_grad``) reads ``Sigma0 + K1 Sigma1 + K2 Sigma2 = 0`` with

        Di = ri1/ri2 (r1 - r0)/(r2 - r0),  K1 = -r1/r0 (1 + Di),  K2 = r2/r0 Di.

    Arguments:
        r: (nr,) cell centres [cm].
        ri: (nr+1,) interfaces [cm].

    Returns:
        (K1, K2): scalars (dimensionless).
    """
    r = jnp.asarray(r)
    ri = jnp.asarray(ri)
    Di = ri[1] / ri[2] * (r[1] - r[0]) / (r[2] - r[0])
    K1 = -r[1] / r[0] * (1.0 + Di)
    K2 = r[2] / r[0] * Di
    return K1, K2


def const_grad_value(S, r, ri):
    """Inner boundary value imposed after a step by DustPy's ``Boundary`` (condition ``const_grad``).

    ``S0 = (1 + D) r1/r0 S1 - D r2/r0 S2`` with ``D = ri1/ri2 (r1 - r0)/(r2 - r1)``
    (DustPy 1.0.9 ``utils/boundary.py`` ``Boundary._getboundary``): r S has the same interface
    gradient times radius, ri d(r S)/dr, at the first two interior interfaces.

    Arguments:
        S: (nr, ...) surface density [g cm^-2] (only rows 1 and 2 are used).
        r: (nr,) cell centres [cm].
        ri: (nr+1,) interfaces [cm].

    Returns:
        S0: (...) the value for cell 0.
    """
    r = jnp.asarray(r)
    ri = jnp.asarray(ri)
    D = ri[1] / ri[2] * (r[1] - r[0]) / (r[2] - r[1])
    return (1.0 + D) * r[1] / r[0] * S[1] - r[2] / r[0] * D * S[2]


def implicit_tridiagonal_step(A, B, C, dt, rhs, K1, K2, outer_value):
    """Solve DustPy's implicit Euler system for a tridiagonal operator with its default boundary rows.

    Rows of (I - dt J) Sigma_new = rhs:

    * row 0 (inner ``const_grad``): ``Sigma0 + K1 Sigma1 + K2 Sigma2 = 0``;
    * rows 1..nr-2: ``-dt A Sigma[i-1] + (1 - dt B) Sigma[i] - dt C Sigma[i+1] = rhs[i]``;
    * row nr-1 (outer ``val``): ``Sigma[nr-1] = outer_value``.

    Row 0 couples three cells; it is folded into row 1 (substituting Sigma0 = -K1 Sigma1 - K2 Sigma2)
    so that the remaining system for cells 1..nr-1 is tridiagonal and is solved with
    ``jax.lax.linalg.tridiagonal_solve`` (LU with partial pivoting; DustPy uses SuperLU without
    pivoting on the same matrix, so results agree to rounding). Sigma0 is then recovered from row 0.

    Arguments:
        A, B, C: (nr,) or (nr, nm) sub-, main and super-diagonal coefficients of J [s^-1] (as
            :func:`jaxcoag.disk.gas.gas_operator` / :func:`jaxcoag.disk.transport.hydro_coefficients`;
            rows 0 and nr-1 are ignored).
        dt: time step [s] (scalar).
        rhs: (nr,) or (nr, nm) right-hand side of the interior rows (Sigma_old + dt S_ext) [g cm^-2];
            rows 0 and nr-1 are ignored.
        K1, K2: inner row coefficients (:func:`const_grad_row`).
        outer_value: () or (nm,) value of the last cell [g cm^-2].

    Returns:
        Sigma_new: same shape as ``rhs`` [g cm^-2].
    """
    A = jnp.asarray(A)
    B = jnp.asarray(B)
    C = jnp.asarray(C)
    rhs = jnp.asarray(rhs)
    squeeze = rhs.ndim == 1
    if squeeze:
        A, B, C, rhs = A[:, None], B[:, None], C[:, None], rhs[:, None]
    nm = rhs.shape[1]
    dt = jnp.asarray(dt, dtype=rhs.dtype)
    lo = -dt * A  # multiplies Sigma[i-1]
    di = 1.0 - dt * B
    up = -dt * C  # multiplies Sigma[i+1]
    # unknowns: cells 1..nr-1 (n = nr-1)
    dl = lo[1:]
    d = di[1:]
    du = up[1:]
    b = rhs[1:]
    # fold row 0 into row 1: lo[1] Sigma0 = -lo[1] K1 Sigma1 - lo[1] K2 Sigma2
    d = d.at[0].add(-lo[1] * K1)
    du = du.at[0].add(-lo[1] * K2)
    dl = dl.at[0].set(0.0)
    # outer row: identity with the fixed value
    dl = dl.at[-1].set(0.0)
    d = d.at[-1].set(1.0)
    du = du.at[-1].set(0.0)
    b = b.at[-1].set(jnp.broadcast_to(outer_value, (nm,)).astype(rhs.dtype))
    x = tridiagonal_solve(dl.T, d.T, du.T, b.T[..., None])[..., 0].T  # (nr-1, nm)
    s0 = -K1 * x[0] - K2 * x[1]
    out = jnp.concatenate([s0[None], x], axis=0)
    return out[:, 0] if squeeze else out
