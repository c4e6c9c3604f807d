"""Dense form of the two-bin pair operators: right-hand side and exact Jacobian without scatters.

The two-bin right-hand side (:mod:`jaxcoag.binned.twobin`, fragmentation data of
:mod:`jaxcoag.binned.redistribution`) is a sum over unordered bin pairs p = (i, j), i >= j, of
coefficients ``coef[p, c]`` times the pair rate ``khat_p rho_i rho_j`` into the bins ``idx[p, c]``.
As a scatter (``segment_sum`` over Np x C entries, Np = N (N + 1)/2) it costs ~0.1 ms per call at
135 bins on one CPU core and its Jacobian (a scatter of 2 Np C entries into an (N+1)^2 matrix)
~0.2 ms; the implicit solvers evaluate both at every stage.

The target bins have a fixed pattern relative to the pair: the smaller partner's bin (losses),
the larger partner's bin plus a small offset (its loss, the product's two-bin split at offsets 0..3
on a regular grid, an eroded remnant at -1 or 0) or a fixed bin (the gel accumulator, a monomer
bin). Each entry (p, c) therefore belongs to one *category* (base, offset):

* ``("L", o)``: target i + o;  ``("S", o)``: target j + o;  ``("F", r)``: the fixed target r.

For each category the coefficients (times khat and any constant weight such as 1 - p_f) are
gathered once per solve into a dense lower-triangular matrix C[i, j]; entries of one pair that
share a category add. Then, with A = C rho (row contraction) and B = rho C (column contraction):

* ``("L", o)``: out[i + o] += rho_i A_i;  J[i + o, l] += rho_i C[i, l] and J[i + o, i] += A_i;
* ``("S", o)``: out[j + o] += rho_j B_j;  J[j + o, l] += C[l, j] rho_j and J[j + o, j] += B_j;
* ``("F", r)``: out[r] += rho . A;  J[r, :] += A + B,

i.e. K matrix-vector products for the right-hand side and K scaled copies of an N x N matrix for
the Jacobian (K ~ 6-8 categories), the same sums as the scatter in another order (agreement to
round-off; every pair's coefficients still sum to zero, so mass is conserved to round-off).
Grids whose pattern needs more than :data:`MAX_CATEGORIES` categories keep the scatter form.

References: Kovetz & Olund (1969); Brauer, Dullemond & Henning (2008) App. A (two-bin operator);
Stammler & Birnstiel (2022, DustPy) §3.2 (implicit steps with the coagulation Jacobian).
"""

from __future__ import annotations

import numpy as np
import equinox as eqx
import jax
import jax.numpy as jnp

__all__ = ["PairOperator", "pair_categories", "MAX_CATEGORIES"]

#: Most categories a dense operator may have; more (an irregular grid) keeps the scatter form.
MAX_CATEGORIES = 32


def pair_categories(targets, iL, iS, n_rows, gel=True):
    """Static category of every entry of a pair operator.

    Arguments: targets (Np, C) int target rows in [0, n_rows); iL, iS (Np,) int partner bins
    (iL >= iS); n_rows: number of output rows (nbins + 1 with the gel accumulator, nbins for the
    fragment sources); gel: whether row n_rows - 1 is the gel accumulator (always a fixed row).
    Returns: (cats, code): ``cats`` a tuple of (base, offset) with base "L", "F" or "S", the S
    categories last (fixed row
    = offset), ``code`` (Np, C) int index into ``cats``. Targets equal to the smaller partner's bin
    are (S, 0), the rest (L, target - iL), except fixed rows: the gel accumulator and any
    column whose targets are all one row. Any assignment is exact (each
    category's formula gives the entry's own target); this one keeps the count small.
    """
    t = np.asarray(targets)
    iL2 = np.broadcast_to(np.asarray(iL)[:, None], t.shape)
    iS2 = np.broadcast_to(np.asarray(iS)[:, None], t.shape)
    base = np.where(t == iS2, 2, 0)                        # codes: 0 = L, 1 = F, 2 = S (sorted: S last)
    off = np.where(base == 2, 0, t - iL2)
    # fixed rows: the gel accumulator (gel=True) and any column that always aims at one row (e.g. every
    # fragment into the monomer bin)
    isf = (t == n_rows - 1) if gel else np.zeros(t.shape, bool)
    for c in range(t.shape[1]):
        if np.unique(t[:, c]).size == 1:
            isf[:, c] = True
    base = np.where(isf, 1, base)
    off = np.where(isf, t, off)
    keys = np.stack([base.ravel(), off.ravel()], axis=1)
    ukeys, code = np.unique(keys, axis=0, return_inverse=True)
    names = ("L", "F", "S")
    cats = tuple((names[int(b)], int(o)) for b, o in ukeys)
    return cats, code.reshape(t.shape).astype(np.int32)


class PairOperator(eqx.Module):
    """Dense pair operator: out = sum_p coef_p rho_iL rho_iS into target rows, and its Jacobian.

    Attributes: mats (K, N, N) per-category coefficient matrices [g x khat units], lower
    triangular in (iL, iS); cats (static tuple of (base, offset)); n_rows (static int).
    Build with :meth:`build`. References: see the module docstring.
    """

    mats: jax.Array
    cats: tuple = eqx.field(static=True)
    n_rows: int = eqx.field(static=True)

    @staticmethod
    def build(terms, iL, iS, nbins, n_rows, gel=True):
        """Gather weighted coefficients into category matrices (once per solve).

        Arguments: terms: list of (targets (Np, C) int numpy, values (Np, C) array) whose values
        already include khat and any per-pair weight; iL, iS (Np,) int numpy; nbins; n_rows; gel:
        row n_rows - 1 is the gel accumulator. Returns: a PairOperator, or None when the pattern needs more than
        :data:`MAX_CATEGORIES` categories.
        """
        targets = np.concatenate([np.asarray(t) for t, _ in terms], axis=1)
        vals = jnp.concatenate([jnp.asarray(v) for _, v in terms], axis=1)
        cats, code = pair_categories(targets, iL, iS, n_rows, gel)
        K = len(cats)
        if K > MAX_CATEGORIES:
            return None
        N = nbins
        flat = (code * (N * N) + (np.asarray(iL) * N + np.asarray(iS))[:, None]).ravel()
        mats = jax.ops.segment_sum(vals.ravel(), jnp.asarray(flat), num_segments=K * N * N).reshape(K, N, N)
        return PairOperator(mats=mats, cats=cats, n_rows=n_rows)

    def _contract(self, rho):
        """A = C rho for the row categories (L, F: a prefix of ``cats``), B = rho C for the S ones."""
        nr = sum(b != "S" for b, _ in self.cats)
        A = jnp.einsum("kij,j->ki", self.mats[:nr], rho)
        B = jnp.einsum("kij,i->kj", self.mats[nr:], rho)
        return nr, A, B

    def apply(self, rho):
        """out (n_rows,) = sum_p coef_p rho_iL rho_iS into the target rows; rho (N,)."""
        R = self.n_rows
        nr, A, B = self._contract(rho)
        out = jnp.zeros((R,), rho.dtype)
        fixed_r, fixed_v = [], []
        for k, (base, o) in enumerate(self.cats):
            if base == "F":
                fixed_r.append(o)
                fixed_v.append(jnp.dot(rho, A[k]))
            elif base == "L":
                out = out + _shift(rho * A[k], o, R)
            else:
                out = out + _shift(rho * B[k - nr], o, R)
        if fixed_r:
            out = out.at[np.array(fixed_r)].add(jnp.stack(fixed_v))
        return out

    def jacobian(self, rho):
        """d out / d rho (n_rows, N) of :meth:`apply`."""
        N, R = rho.shape[0], self.n_rows
        nr, A, B = self._contract(rho)
        J = jnp.zeros((R, N), rho.dtype)
        ar = np.arange(N)
        for k, (base, o) in enumerate(self.cats):
            C = self.mats[k]
            if base == "F":
                J = J.at[o].add(A[k] + jnp.einsum("ij,i->j", C, rho))
            elif base == "L":
                J = J + _shift_rows(rho[:, None] * C, o, R)
                J = _add_diag(J, A[k], o, R, ar)
            else:
                J = J + _shift_rows((C * rho[None, :]).T, o, R)
                J = _add_diag(J, B[k - nr], o, R, ar)
        return J


def _shift(v, o, R):
    """Length-R vector with v[i] at row i + o (entries shifted out of range must be zero)."""
    N = v.shape[0]
    lo, hi = max(0, -o), min(N, R - o)
    return jnp.pad(v[lo:hi], (lo + o, R - hi - o))


def _shift_rows(M, o, R):
    """(R, N) matrix with row i of M (N, N) at row i + o."""
    N = M.shape[0]
    lo, hi = max(0, -o), min(N, R - o)
    return jnp.pad(M[lo:hi], ((lo + o, R - hi - o), (0, 0)))


def _add_diag(J, a, o, R, ar):
    """J[i + o, i] += a[i] for the rows in range."""
    sel = ar[(ar + o >= 0) & (ar + o < R)]
    return J.at[sel + o, sel].add(a[sel])
