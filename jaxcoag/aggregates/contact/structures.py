"""Ballistic cluster-cluster aggregates (BCCA) of 2^k equal monomers, in 2-D (the paper) and 3-D.

Construction (Wada et al. 2007 §4, Fig. 4): "random head-on sticking of two identical clusters, successively". Two
clusters A and B of 2^(l-1) monomers, each centred on its centre of mass (COM) at the origin and turned by an
independent uniform random rotation (2-D: an angle in [0, 2 pi); 3-D: a uniform random rotation of SO(3)), are
brought together head-on: B is shot along +x from x = -inf with zero impact parameter (the approach direction is
the COM-COM line). With r1 the monomer radius and rho_ab the distance of a in A and b in B perpendicular to x
(2-D: |y_a - y_b|; 3-D: sqrt((y_a - y_b)^2 + (z_a - z_b)^2)), the pair (a, b) first touches after the shift

    X_ab = x_a - x_b - sqrt(4 r1^2 - rho_ab^2)     for rho_ab < 2 r1,

and the first touching pair is the one with the smallest X_ab, X* = min X_ab. B is moved by (X*, 0, 0), then along
the new bond (a*, b*) by the JKR equilibrium compression delta_0 (Wada et al. 2007 eq. 4) so that the bond sits at
|x_a* - x_b*| = 2 r1 - delta_0 exactly (the paper does not state the bond length; a tree allows any), and the union
is recentred on its COM. Every merge adds one bond, so the result is a tree of n - 1 bonds, all at 2 r1 - delta_0,
and no other pair is in contact (compression delta = 2 r1 - |x_i - x_j| < 0). The rotations of a merge are drawn
again (i) on a tie or near-tie, when the delta_0 shift would bring a second pair into contact (delta >= 0), and
(ii) in 3-D when the projections of A and B on the y-z plane do not overlap (a miss; impossible in 2-D, where a
connected cluster centred on y = 0 always has a disk covering y = 0).

By default the two clusters of every merge are independent realisations; ``copy=True`` merges two copies of one
cluster at every level (the paper's "identical clusters" read literally), each copy independently rotated.

Random numbers and reproducibility: this is a host-side structure generator (not a differentiable path; its
output is an initial condition). It runs in numpy, with a ``numpy.random.Generator`` seeded from 128 bits drawn
from the JAX ``key`` (``jax.random.bits``), so the result is a deterministic function of ``key`` (and of
n, dim, copy and the material's delta_0/r1). All merges of one level are processed together: a cell list in the
plane perpendicular to x finds the pairs that can touch, pruned to the two facing fronts by an upper bound on X*, so a
level costs O(n log n). Measured CPU time per aggregate (shared 2-core machine, upper bounds): N = 2^14, 0.16 s
(2-D) and 0.25 s (3-D); N = 2^17, 1.3 s and 2.3 s.

Measured fractal laws (20 aggregates of the largest size, fit over N >= 8): 2-D, N = 2^3..2^14:
N = 1.37 (r_g/r1)^1.56, against Wada et al. 2007 eq. 53, N = 1.37 (r_g/r1)^1.57; 3-D, N = 2^3..2^13:
N = 1.13 (r_g/r1)^2.04 (at the upper end of the D ~ 1.9-2.0 usually quoted for 3-D BCCAs).

References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007, ApJ 661, 320) §4, Figs. 4 and 10, eqs. 4, 50, 53;
Meakin (1991) for ballistic cluster-cluster aggregation.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._validate import JaxcoagInputError, is_traced, require_x64
from .aggregate import Aggregate

__all__ = ["bcca", "bcca_batch", "bcca_gyration_radii", "MAX_LEVEL"]

MAX_LEVEL = 17  # largest supported aggregate: 2^17 = 131072 monomers
_MAX_TRIES = 10_000  # rotation draws of one level before giving up (~0.3 % of the merges need a redraw)


# ------------------------------------------------------------------------------------------------- input checks
def _level_of(n, name="n") -> int:
    """log2(n) for a power of two 1 <= n <= 2^MAX_LEVEL, else a JaxcoagInputError."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise JaxcoagInputError(f"`{name}` must be a Python int, the number of monomers 2^k; got {n!r}.")
    n = int(n)
    if n < 1 or (n & (n - 1)) != 0:
        lo = 1 << max(n.bit_length() - 1, 0)
        raise JaxcoagInputError(
            f"`{name}` must be a power of two (a BCCA merges two clusters of equal size at every level; Wada et "
            f"al. 2007 §4); got {n}. Use e.g. {lo} or {2 * lo}.")
    level = n.bit_length() - 1
    if level > MAX_LEVEL:
        raise JaxcoagInputError(
            f"`{name}` = {n} exceeds the supported maximum 2^{MAX_LEVEL} = {1 << MAX_LEVEL} monomers.")
    return level


def _dim_of(dim) -> int:
    if isinstance(dim, bool) or dim not in (2, 3):
        raise JaxcoagInputError(f"`dim` must be 2 (planar, the paper's runs) or 3; got {dim!r}.")
    return int(dim)


def _rng_from_key(key) -> np.random.Generator:
    """A numpy Generator seeded deterministically from 128 bits of the JAX PRNG ``key``."""
    if is_traced(key):
        raise JaxcoagInputError("bcca runs on the host (numpy): call it outside jax.jit/vmap with a concrete key.")
    try:
        bits = np.asarray(jax.random.bits(key, (4,), jnp.uint32), dtype=np.uint64)
    except Exception as exc:  # not a key
        raise JaxcoagInputError(
            f"`key` must be a JAX PRNG key, e.g. jax.random.key(0) or jax.random.PRNGKey(0); got {key!r}.") from exc
    return np.random.default_rng([int(b) for b in bits])


@jax.jit
def _delta0_over_r1(mat):
    """delta_0/r1 of a Material (one compiled call instead of a chain of eager ops)."""
    return mat.delta0 / mat.r1


def _bond_lengths(material, r1):
    """(r1 [cm], delta_0/r1) from ``material`` (default ice), with r1 replaced when given."""
    from .materials import Material, ice

    mat = ice() if material is None else material
    if not isinstance(mat, Material):
        raise JaxcoagInputError(
            f"`material` must be a contact.Material (e.g. contact.materials.ice()); got {type(mat).__name__}.")
    if r1 is not None:
        if is_traced(r1) or np.ndim(r1) != 0 or not (np.isfinite(float(r1)) and float(r1) > 0):
            raise JaxcoagInputError(f"`r1` must be a positive monomer radius in cm (e.g. 1e-5); got {r1!r}.")
        mat = eqx.tree_at(lambda m: m.r1, mat, jnp.asarray(float(r1), jnp.float64))
    if is_traced(mat):
        raise JaxcoagInputError("bcca needs a concrete material (call it outside jax.jit/vmap).")
    r1_cm = float(mat.r1)
    d0 = float(_delta0_over_r1(mat))
    if not (0.0 <= d0 < 1.0):
        raise JaxcoagInputError(
            f"the material's equilibrium compression delta_0 = {d0:.3g} r1 is not in [0, r1); check its constants.")
    return r1_cm, d0


# ------------------------------------------------------------------------------------------------- geometry core
def _rotations(rng, k, dim):
    """k pairs of uniform random rotation matrices, shape (k, 2, dim, dim)."""
    if dim == 2:
        th = rng.uniform(0.0, 2.0 * math.pi, size=(k, 2))
        c, s = np.cos(th), np.sin(th)
        return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
    q = rng.standard_normal(size=(k, 2, 4))  # normalised Gaussian 4-vector: uniform on SO(3)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


class _Cells:
    """Cell grid in the plane perpendicular to the approach (x), shared by the merges of one batch.

    2-D: cells of side w/2 in y, a cell's neighbourhood is the 5 cells within two of it; 3-D: cells of side w in
    (y, z) and the 9 cells around. Every pair with |y_a - y_b| <= w (and |z_a - z_b| <= w) lies in neighbouring
    cells. Cell ids are dense integers merge * size + linear cell index (padded so that neighbours stay inside).
    """

    def __init__(self, pts, k, w):
        self.dim = pts.shape[-1]
        if self.dim == 2:
            self.cols, self.side, self.offsets = (1,), 0.5 * w, [(o,) for o in (-2, -1, 0, 1, 2)]
        else:
            self.cols, self.side = (1, 2), w
            self.offsets = [(o, q) for o in (-1, 0, 1) for q in (-1, 0, 1)]
        c = [np.floor(pts[..., col] / self.side).astype(np.int64) for col in self.cols]
        self.lo = [int(x.min()) - 2 for x in c]
        self.ext = [int(x.max()) - lo + 3 for x, lo in zip(c, self.lo)]
        self.size = int(np.prod(self.ext))
        self.n = k * self.size

    def ids(self, x, j, off=None):
        """Cell id of points x (p, dim) [r1] of merges j (p,), shifted by the cell offset ``off``."""
        off = off or (0,) * len(self.cols)
        lin = np.zeros(x.shape[0], np.int64)
        for col, lo, e, o in zip(self.cols, self.lo, self.ext, off):
            lin = lin * e + (np.floor(x[:, col] / self.side).astype(np.int64) - lo + o)
        return j * self.size + lin


def _pairs(cells, xa, ja, xb, jb):
    """Candidate pairs (a, b) of the same merge in neighbouring cells.

    xa (pa, dim), ja (pa,) [merge of each a]; xb, jb the same for B. The rows of B are sorted on their cell id, so the
    partners of every a are contiguous runs. Returns (ia, ib) row indices with ia ascending. Cost O(p log p + pairs).
    """
    kb = cells.ids(xb, jb)
    order = np.argsort(kb, kind="stable")
    kbs = kb[order]
    los, cnts = [], []
    for off in cells.offsets:
        ka = cells.ids(xa, ja, off)
        lo = np.searchsorted(kbs, ka, side="left")
        los.append(lo)
        cnts.append(np.searchsorted(kbs, ka, side="right") - lo)
    lo = np.stack(los, 1).ravel()  # all offsets of a before those of a + 1
    cnt = np.stack(cnts, 1).ravel()
    total = int(cnt.sum())
    ia = np.repeat(np.repeat(np.arange(xa.shape[0]), len(cells.offsets)), cnt)
    pos = np.repeat(lo - (np.cumsum(cnt) - cnt), cnt) + np.arange(total)
    return ia, order[pos]


def _first_contacts(D, ia, k, m):
    """Per merge: X* = min X_ab over the candidate pairs (separations D = x_a - x_b before the shot, (p, dim)
    [r1]; ia the flat A rows, grouped by merge) and the index of the first pair that reaches it (-1: a miss)."""
    j = ia // m
    rho2 = np.sum(D[:, 1:] ** 2, axis=-1)
    hit = rho2 < 4.0
    X = np.where(hit, D[:, 0] - np.sqrt(np.maximum(4.0 - rho2, 0.0)), np.inf)
    Xs = np.full(k, np.inf)
    sel = np.full(k, -1, np.int64)
    if ia.size:
        starts = np.flatnonzero(np.r_[True, j[1:] != j[:-1]])  # j is sorted: one segment per merge
        Xs[j[starts]] = np.minimum.reduceat(X, starts)
        first = np.flatnonzero(hit & (X == Xs[j]))
        jj, at = np.unique(j[first], return_index=True)
        sel[jj] = first[at]
    return Xs, sel


def _candidates(a, b, w, slack):
    """Pairs (a, b) of every merge that can be the first contact or come within 2 r1 after a pull of length
    ``slack`` (= delta_0): |y_a - y_b| <= w (3-D: also in z) and x_a - x_b <= X* + 2 + slack.

    X* is bounded above by the first contact among the cell fronts (per cell, the A monomer of least x and the B
    monomer of largest x); a monomer a is kept only if x_a <= U + w' + max x_b over its neighbouring cells (and b
    symmetrically), which leaves the two facing fronts. a, b: (k, m, dim) [r1]. Returns flat rows (ia, ib), ia
    ascending.
    """
    k, m, dim = a.shape
    af, bf = a.reshape(k * m, dim), b.reshape(k * m, dim)
    jm = np.repeat(np.arange(k, dtype=np.int64), m)
    cells = _Cells(np.concatenate([af, bf]), k, w)
    ka, kb = cells.ids(af, jm), cells.ids(bf, jm)
    # cell fronts: least x of A, largest x of B in every cell
    oa = np.lexsort((af[:, 0], ka))
    fa = oa[np.r_[True, ka[oa][1:] != ka[oa][:-1]]]
    ob = np.lexsort((-bf[:, 0], kb))
    fb = ob[np.r_[True, kb[ob][1:] != kb[ob][:-1]]]
    pa, pb = _pairs(cells, af[fa], jm[fa], bf[fb], jm[fb])
    U, _ = _first_contacts(af[fa][pa] - bf[fb][pb], fa[pa], k, m)  # fa ascending, so fa[pa] is grouped by merge
    reach = U + 2.0 + slack + 1e-9 * (1.0 + np.abs(U))  # x_a - x_b <= reach for every pair that matters
    amin = np.full(cells.n, np.inf)
    amin[ka[fa]] = af[fa, 0]
    bmax = np.full(cells.n, -np.inf)
    bmax[kb[fb]] = bf[fb, 0]
    nb_bmax = np.max([bmax[cells.ids(af, jm, off)] for off in cells.offsets], axis=0)
    nb_amin = np.min([amin[cells.ids(bf, jm, off)] for off in cells.offsets], axis=0)
    keep_a = np.flatnonzero(af[:, 0] - nb_bmax <= reach[jm])
    keep_b = np.flatnonzero(nb_amin - bf[:, 0] <= reach[jm])
    ia, ib = _pairs(cells, af[keep_a], jm[keep_a], bf[keep_b], jm[keep_b])
    return keep_a[ia], keep_b[ib]


def _merge(A, B, rng, d0):
    """Merge clusters B[j] onto A[j] head-on (see the module docstring); A, B: (k, m, dim) COM-centred [r1].

    Returns (merged (k, 2m, dim) COM-centred [r1], bond (k, 2) local indices (a in A, b in B)).
    """
    k, m, dim = A.shape
    L = 2.0 - d0  # bond length [r1]
    out = np.empty((k, 2 * m, dim))
    bond = np.empty((k, 2), np.int64)
    todo = np.arange(k)
    for _ in range(_MAX_TRIES):
        kk = todo.size
        R = _rotations(rng, kk, dim)
        a = np.einsum("kij,kmj->kmi", R[:, 0], A[todo])
        b = np.einsum("kij,kmj->kmi", R[:, 1], B[todo])
        ia, ib = _candidates(a, b, 2.0 + d0, d0)
        D = a.reshape(kk * m, dim)[ia] - b.reshape(kk * m, dim)[ib]  # separations x_a - x_b before the shot
        Xs, sel = _first_contacts(D, ia, kk, m)
        ok = sel >= 0  # False: a miss (3-D only)
        s = np.where(ok, sel, 0)
        shift = np.zeros((kk, dim))
        if ia.size:
            shift[:, 0] = np.where(ok, Xs, 0.0)
            # pull B along the bond so that |x_a - x_b| = 2 r1 - delta_0
            dvec = D[s] - shift
            dist = np.linalg.norm(dvec, axis=-1)
            shift = shift + dvec * (1.0 - L / np.where(ok, dist, 1.0))[:, None]
            # reject a merge if any pair other than the bond now has delta = 2 r1 - |x_a - x_b| >= 0
            dd = D - shift[ia // m]
            touch = np.einsum("pi,pi->p", dd, dd) <= 4.0
            touch[s[ok]] = False
            ok &= np.bincount(ia[touch] // m, minlength=kk) == 0
        bt = b + shift[:, None, :]
        merged = np.concatenate([a, bt], axis=1)
        merged -= merged.mean(axis=1, keepdims=True)
        idx = todo[ok]
        out[idx] = merged[ok]
        bond[idx, 0] = ia[s[ok]] % m
        bond[idx, 1] = ib[s[ok]] % m
        todo = todo[~ok]
        if todo.size == 0:
            return out, bond
    raise RuntimeError(f"bcca: {todo.size} merges found no clean contact after {_MAX_TRIES} rotation draws.")


def _build(count, level, dim, d0, rng, copy, record=None):
    """``count`` BCCAs of 2^level monomers: positions (count, 2^level, dim) [r1] and bonds (count, 2^level - 1, 2).

    ``record(level, clusters)`` is called with the (C, m, dim) clusters after every level when given.
    """
    if copy:
        pos = np.zeros((count, 1, dim))
    else:
        pos = np.zeros((count << level, 1, dim))
    bonds = np.zeros((pos.shape[0], 0, 2), np.int64)
    for lev in range(1, level + 1):
        m = pos.shape[1]
        if copy:
            A, B, bA, bB = pos, pos, bonds, bonds
        else:
            A, B, bA, bB = pos[0::2], pos[1::2], bonds[0::2], bonds[1::2]
        pos, bond = _merge(A, B, rng, d0)
        bond[:, 1] += m
        bonds = np.concatenate([bA, bB + m, bond[:, None, :]], axis=1)
        if record is not None:
            record(lev, pos)
    return pos, bonds


# ------------------------------------------------------------------------------------------------- public API
def bcca(n: int, key, dim: int = 2, *, material=None, r1=None, copy: bool = False, return_bonds: bool = False):
    """A ballistic cluster-cluster aggregate (BCCA) of ``n`` = 2^k equal monomers (Wada et al. 2007 §4, Fig. 4).

    Arguments:
        n: number of monomers, a power of two, 1 <= n <= 2^17.
        key: JAX PRNG key (``jax.random.key(0)``); the structure is a deterministic function of it.
        dim: 2 (planar, in the x-y plane: the paper's aggregates) or 3 (uniform random 3-D rotations).
        material: :class:`~jaxcoag.aggregates.contact.materials.Material` giving the monomer radius and the bond
            length 2 r1 - delta_0 (JKR equilibrium, Wada et al. 2007 eq. 4); default ``materials.ice()``.
        r1: monomer radius [cm]; default the material's ``r1``. When given, delta_0 is that of the material with
            this radius.
        copy: False (default): the two clusters of every merge are independent realisations. True: each level
            merges two copies of one cluster, independently rotated.
        return_bonds: also return the bond list.

    Returns:
        :class:`Aggregate` with positions (n, dim) [cm], centred on the centre of mass, and ``r1`` [cm];
        with ``return_bonds``, the tuple ``(aggregate, bonds)`` where bonds is an (n - 1, 2) int numpy array of the
        monomer index pairs in contact (a tree, every bond at |x_i - x_j| = 2 r1 - delta_0).

    Host-side numpy generator (see the module docstring): not traceable, not differentiable.
    References: Wada et al. (2007) §4, Fig. 4, eqs. 4, 53.
    """
    require_x64("contact.bcca")
    level = _level_of(n)
    dim = _dim_of(dim)
    r1_cm, d0 = _bond_lengths(material, r1)
    rng = _rng_from_key(key)
    pos, bonds = _build(1, level, dim, d0, rng, bool(copy))
    agg = Aggregate(jnp.asarray(pos[0] * r1_cm, jnp.float64), r1_cm)
    return (agg, bonds[0]) if return_bonds else agg


def bcca_batch(n: int, count: int, key, dim: int = 2, *, material=None, r1=None, copy: bool = False):
    """``count`` independent BCCAs of ``n`` = 2^k monomers at once (vectorised over the realisations).

    Arguments: as :func:`bcca`; count: number of realisations (>= 1).

    Returns:
        (positions, bonds): positions a float64 numpy array (count, n, dim) [cm], each aggregate centred on its
        centre of mass; bonds an int numpy array (count, n - 1, 2) of monomer index pairs (per aggregate).

    References: Wada et al. (2007) §4.
    """
    level = _level_of(n)
    dim = _dim_of(dim)
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise JaxcoagInputError(f"`count` must be a positive int (number of realisations); got {count!r}.")
    r1_cm, d0 = _bond_lengths(material, r1)
    rng = _rng_from_key(key)
    pos, bonds = _build(int(count), level, dim, d0, rng, bool(copy))
    return pos * r1_cm, bonds


def bcca_gyration_radii(n_max: int, count: int, key, dim: int = 2, *, material=None):
    """Gyration radii r_g/r1 (Wada et al. 2007 eq. 50) of BCCAs of every size 2, 4, ..., n_max (for Fig. 10).

    One pass builds ``count`` aggregates of ``n_max`` monomers; the 2^l-monomer clusters met on the way are
    themselves independent BCCAs of 2^l monomers (disjoint random draws), so size 2^l gets
    count * n_max / 2^l samples at no extra cost. (Samples of different sizes are correlated, which does not bias
    the per-size means.)

    Arguments:
        n_max: largest size, a power of two <= 2^17. count: number of largest aggregates (>= 1).
        key: JAX PRNG key. dim: 2 or 3. material: bond length 2 r1 - delta_0 (default ice).

    Returns:
        dict {N: numpy array of r_g/r1 [-]} for N = 2, 4, ..., n_max.

    References: Wada et al. (2007) eqs. 50, 53, Fig. 10.
    """
    level = _level_of(n_max, "n_max")
    dim = _dim_of(dim)
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise JaxcoagInputError(f"`count` must be a positive int (number of realisations); got {count!r}.")
    _, d0 = _bond_lengths(material, None)
    rng = _rng_from_key(key)
    out = {}

    def record(lev, clusters):  # clusters are COM-centred
        out[1 << lev] = np.sqrt(np.mean(np.sum(clusters**2, axis=-1), axis=-1))

    _build(int(count), level, dim, d0, rng, False, record)
    return out
