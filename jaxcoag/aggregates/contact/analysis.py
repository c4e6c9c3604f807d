"""Analysis of monomer aggregates: clusters of the contact graph, gyration radius, contact number, fractal fit.

* :func:`clusters`: connected components of the contact graph (jit-able label propagation with pointer jumping in
  ``lax.while_loop``); labels are ranked so that 0 is the largest cluster (Wada et al. 2007 §5.1: N_large).
* :func:`gyration_radius`: r_g = sqrt((1/N) sum_i |x_i - x_M|^2) (Wada et al. 2007 eq. 50), optionally over a mask.
* :func:`contact_number`: n_con = (number of contacts in the largest cluster)/N_large (Wada et al. 2007 §5.3,
  Fig. 11; ~ 1 for an unrestructured BCCA, (N - 1)/N).
* :func:`largest_cluster`: the three above together for a final contact graph.
* :func:`fractal_fit`: prefactor k and exponent D of N = k (r_g/r1)^D (Wada et al. 2007 eqs. 52-53; the 2-D BCCA
  law is N = 1.37 (r_g/r1)^1.57).

Contact graphs are given as an (E, 2) integer array of monomer index pairs plus an optional (E,) boolean ``active``
mask; pairs with an index outside [0, n) are ignored (the DEM's empty-slot sentinel is n). The contact list of
:mod:`jaxcoag.aggregates.contact.dem` is of this form: ``edges = stack([ci, cj], -1)`` with its ``active``.

Discrete outputs (labels, sizes) carry no gradient; r_g is differentiable in the positions (and safe at r_g = 0).

References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007, ApJ 661, 320) §5.1-5.3, eqs. 50, 52, 53.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..._validate import JaxcoagInputError, is_traced

__all__ = ["clusters", "gyration_radius", "contact_number", "largest_cluster", "LargestCluster", "fractal_fit"]


def _n_of(n) -> int:
    """Number of monomers from an int or from a positions array (its length)."""
    if isinstance(n, (int, np.integer)) and not isinstance(n, bool):
        n = int(n)
    elif hasattr(n, "shape") and len(np.shape(n)) >= 1:
        n = int(np.shape(n)[0])
    else:
        raise JaxcoagInputError(
            f"`n` must be the number of monomers (an int) or a positions array (n, dim); got {n!r}.")
    if n < 1:
        raise JaxcoagInputError(f"`n` must be >= 1 monomer; got {n}.")
    return n


def _edges_of(edges, active):
    e = jnp.asarray(edges)
    if e.ndim != 2 or e.shape[-1] != 2:
        raise JaxcoagInputError(f"`edges` must be an (E, 2) array of monomer index pairs; got shape {e.shape}.")
    if not jnp.issubdtype(e.dtype, jnp.integer):
        raise JaxcoagInputError(f"`edges` must hold integer monomer indices; got dtype {e.dtype}.")
    if active is None:
        act = jnp.ones(e.shape[0], bool)
    else:
        act = jnp.asarray(active)
        if act.shape != (e.shape[0],):
            raise JaxcoagInputError(f"`active` must have shape ({e.shape[0]},) like edges[:, 0]; got {act.shape}.")
        act = act.astype(bool)
    return e[:, 0].astype(jnp.int32), e[:, 1].astype(jnp.int32), act


@partial(jax.jit, static_argnums=0)
def _components(n, i, j, act):
    act = act & (i >= 0) & (i < n) & (j >= 0) & (j < n)
    i = jnp.where(act, i, 0)
    j = jnp.where(act, j, 0)
    idx = jnp.arange(n, dtype=jnp.int32)

    def body(c):
        lab, _ = c
        li, lj = lab[i], lab[j]
        m = jnp.where(act, jnp.minimum(li, lj), n)  # n: no update (dropped by the scatter-min below)
        new = lab.at[li].min(m, mode="drop").at[lj].min(m, mode="drop")
        new = new.at[i].min(m, mode="drop").at[j].min(m, mode="drop")
        new = new[new]  # pointer jumping (labels always point into the same component, lab[x] <= x)
        new = new[new]
        return new, jnp.any(new != lab)

    lab, _ = jax.lax.while_loop(lambda c: c[1], body, (idx, jnp.asarray(True)))
    # lab[x] = least monomer index of x's component; rank the components by size (ties: least index first)
    counts = jnp.zeros(n, jnp.int32).at[lab].add(1)
    order = jnp.argsort(-counts, stable=True)
    rank = jnp.zeros(n, jnp.int32).at[order].set(idx)
    return rank[lab], counts[order]


def clusters(n, edges, active=None):
    """Connected components of a contact graph (the clusters after a collision; Wada et al. 2007 §5.1).

    Arguments:
        n: number of monomers (int), or a positions array (n, dim) whose length is used.
        edges: (E, 2) int array of monomer index pairs (i, j) in contact; entries outside [0, n) are ignored.
        active: optional (E,) bool mask of the edges that are contacts (default: all).

    Returns:
        (labels, sizes): labels (n,) int32 cluster of every monomer, ranked by size (0 = the largest cluster, ties
        broken by the least monomer index); sizes (n,) int32 cluster sizes largest first, zero-padded
        (``sizes[labels[k]]`` is the size of monomer k's cluster; the number of clusters is ``sum(sizes > 0)``).

    jit-able (``n`` static); label propagation with pointer jumping in ``lax.while_loop``. Not differentiable
    (discrete).
    """
    n = _n_of(n)
    i, j, act = _edges_of(edges, active)
    return _components(n, i, j, act)


def gyration_radius(positions, mask=None):
    """Gyration radius r_g = sqrt((1/N) sum_i |x_i - x_M|^2) [cm] (Wada et al. 2007 eq. 50).

    Arguments:
        positions: (n, dim) monomer centres [cm].
        mask: optional (n,) bool, the monomers of the aggregate (e.g. ``labels == 0`` for the largest cluster);
            default all. x_M is the centre of mass of the masked monomers (equal masses).

    Returns:
        r_g [cm] (0 for one monomer or an empty mask). Differentiable in ``positions`` (finite gradient at r_g = 0).
    """
    x = jnp.asarray(positions)
    if x.ndim != 2:
        raise JaxcoagInputError(f"`positions` must have shape (n, dim) [cm]; got {x.shape}.")
    w = jnp.ones(x.shape[0], x.dtype) if mask is None else jnp.asarray(mask).astype(x.dtype)
    if w.shape != (x.shape[0],):
        raise JaxcoagInputError(f"`mask` must have shape ({x.shape[0]},) like positions[:, 0]; got {w.shape}.")
    return _rg(x, w)


@jax.jit
def _rg(x, w):
    N = jnp.sum(w)
    Ns = jnp.where(N > 0, N, 1.0)
    xm = jnp.sum(w[:, None] * x, axis=0) / Ns
    ss = jnp.sum(w * jnp.sum((x - xm[None, :]) ** 2, axis=-1)) / Ns
    pos = ss > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, ss, 1.0)), 0.0)


def contact_number(n_contacts_in_cluster, n_large):
    """Contact number n_con = (contacts inside the largest cluster)/N_large (Wada et al. 2007 §5.3, Fig. 11).

    Arguments:
        n_contacts_in_cluster: number of contacts whose two monomers both belong to the largest cluster.
        n_large: number of monomers of the largest cluster (> 0).

    Returns:
        n_con [-] (float64); (N - 1)/N for an unrestructured BCCA (a tree). 0 where n_large = 0.
    """
    c = jnp.asarray(n_contacts_in_cluster, jnp.float64)
    nl = jnp.asarray(n_large, jnp.float64)
    if not is_traced(nl) and np.any(np.asarray(nl) < 0):
        raise JaxcoagInputError(f"`n_large` must be >= 0 (a number of monomers); got {n_large!r}.")
    return jnp.where(nl > 0, c / jnp.where(nl > 0, nl, 1.0), 0.0)


class LargestCluster(NamedTuple):
    """Summary of the largest cluster of a contact graph (Wada et al. 2007 §5.1-5.3).

    Fields: labels (n,) int32 (0 = largest), sizes (n,) int32 largest first, n_large (int32), r_g [cm] (eq. 50),
    n_contacts (int32, contacts inside the largest cluster), n_con [-] (= n_contacts/n_large).
    """

    labels: jax.Array
    sizes: jax.Array
    n_large: jax.Array
    r_g: jax.Array
    n_contacts: jax.Array
    n_con: jax.Array


def largest_cluster(positions, edges, active=None) -> LargestCluster:
    """Clusters, gyration radius and contact number of the largest cluster (the analysis of Wada et al. 2007 §5).

    Arguments:
        positions: (n, dim) monomer centres [cm].
        edges, active: the contact graph as in :func:`clusters`.

    Returns:
        :class:`LargestCluster`.
    """
    x = jnp.asarray(positions)
    if x.ndim != 2:
        raise JaxcoagInputError(f"`positions` must have shape (n, dim) [cm]; got {x.shape}.")
    i, j, act = _edges_of(edges, active)
    return _largest(x.shape[0], x, i, j, act)


@partial(jax.jit, static_argnums=0)
def _largest(n, x, i, j, act):
    labels, sizes = _components(n, i, j, act)
    big = labels == 0
    ok = act & (i >= 0) & (i < n) & (j >= 0) & (j < n)
    inside = ok & big[jnp.clip(i, 0, n - 1)] & big[jnp.clip(j, 0, n - 1)]
    n_in = jnp.sum(inside).astype(jnp.int32)
    return LargestCluster(labels=labels, sizes=sizes, n_large=sizes[0], r_g=gyration_radius(x, big),
                          n_contacts=n_in, n_con=contact_number(n_in, sizes[0]))


def fractal_fit(n, r_g, r1=1.0):
    """Prefactor k and fractal dimension D of N = k (r_g/r1)^D by least squares in log space (Wada et al. 2007
    eqs. 52-53; 2-D BCCA: k = 1.37, D = 1.57).

    The monomer number N is exact and r_g carries the scatter, so the fit regresses log(r_g/r1) on log N:
    log(r_g/r1) = c + s log N, then D = 1/s and k = exp(-c/s). Pass per-size means (Fig. 10 style) or all samples.

    Arguments:
        n: (p,) monomer numbers N (> 0; at least two distinct values).
        r_g: (p,) gyration radii [cm, or in units of r1 when r1 = 1].
        r1: monomer radius [same unit as r_g] (default 1: r_g already in units of r1).

    Returns:
        (k, D) float64: the prefactor and the exponent.
    """
    N = jnp.asarray(n, jnp.float64).ravel()
    g = jnp.asarray(r_g, jnp.float64).ravel() / r1
    if N.shape != g.shape:
        raise JaxcoagInputError(f"`n` and `r_g` must have the same length; got {N.shape[0]} and {g.shape[0]}.")
    if not (is_traced(N) or is_traced(g)):
        if np.any(np.asarray(N) <= 0) or np.any(np.asarray(g) <= 0) or not np.all(np.isfinite(np.asarray(g))):
            raise JaxcoagInputError("`n` and `r_g` must be positive and finite (log-space fit of N = k (r_g/r1)^D).")
        if np.unique(np.asarray(N)).size < 2:
            raise JaxcoagInputError("`n` needs at least two distinct aggregate sizes to fit a fractal dimension.")
    x, y = jnp.log(N), jnp.log(g)
    xm, ym = jnp.mean(x), jnp.mean(y)
    s = jnp.sum((x - xm) * (y - ym)) / jnp.sum((x - xm) ** 2)
    c = ym - s * xm
    D = 1.0 / s
    return jnp.exp(-c * D), D
