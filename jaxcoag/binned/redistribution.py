"""Mass-exact redistribution of collision products on the two-bin grid (binned engine numerics).

The outcome classes of :mod:`jaxcoag.outcomes` turn their physics into right-hand-side data on
the two-bin pair list (i >= j; i the larger body "L", j the smaller "S") with these helpers:

* :class:`FragData` (fixed-pattern recipes: :class:`~jaxcoag.outcomes.Shattering`,
  :class:`~jaxcoag.outcomes.ShatterAbove`): per-pair losses and remnant placements plus ejecta
  redistributed by fragment weights per source bin;
* :class:`OutcomeData` (:class:`~jaxcoag.outcomes.RecipeOutcome`: any shared
  :class:`~jaxcoag.physics.outcome.Outcome`): one large remnant or two, and power-law fragments,
  each placed by the number- and mass-conserving two-bin split, with the parent's loss and the
  remnant's gain merged analytically when the remnant lands next to its parent's centre (no
  cancellation when a projectile 1e-20 times lighter than the target is swept up);
* :func:`powerlaw_weights` / :func:`fragment_weights`: exact bin integrals of the fragment mass
  power law.

Every pair's coefficients sum to zero (rows of the weights sum to 1), so sum(rho) + gel is
conserved to round-off.

References: Brauer, Dullemond & Henning (2008) §2.3, App. A; Birnstiel, Dullemond & Brauer
(2010) eq. 15; Stammler & Birnstiel (2022, DustPy) §2.2; Ormel 2008 thesis eqs. 6.29-6.30;
Kovetz & Olund (1969).
"""

from __future__ import annotations

import numpy as np
import equinox as eqx
import jax
import jax.numpy as jnp

from .grid import LOG_TOL

__all__ = ["FragData", "OutcomeData", "powerlaw_weights", "fragment_weights", "place_remnant", "place_remnant_np",
           "scatter_pair_jacobian"]


def scatter_pair_jacobian(idx, coef, rL, rS, iL, iS, nbins):
    """Dense Jacobian (nbins + 1, nbins + 1) of ``segment_sum(coef * rate[:, None], idx)`` [s^-1].

    The pair number rates depend on the state only through the two partners' densities:
    d rate_p / d rho_{iL[p]} = rL[p], d rate_p / d rho_{iS[p]} = rS[p] (for rate_p =
    khat_p rho_iL rho_iS: rL = khat rho_iS, rS = khat rho_iL; a self pair iL = iS gets both,
    i.e. 2 khat rho). Hence J[idx[p, c], iL[p]] += coef[p, c] rL[p] and
    J[idx[p, c], iS[p]] += coef[p, c] rS[p]: one scatter of 2 x C x Np entries (C coefficient
    columns), O(N^2) work instead of N + 1 Jacobian-vector products.

    Arguments: idx (Np, C) int target bins (nbins = gel accumulator); coef (Np, C) [g];
    rL, rS (Np,) [cm^-3 s^-1 per (g cm^-3)]; iL, iS (Np,) int partner bins; nbins (static int).
    Returns: (nbins + 1, nbins + 1) jnp array; column nbins (the gel entry) is zero.
    References: Brauer et al. (2008) App. A (two-bin operator); Hairer & Wanner (1996) §IV.7
    (Jacobians of implicit steps).
    """
    n = nbins + 1
    idx = jnp.asarray(idx)
    cols = jnp.stack([jnp.broadcast_to(jnp.asarray(iL)[:, None], idx.shape),
                      jnp.broadcast_to(jnp.asarray(iS)[:, None], idx.shape)])
    vals = jnp.stack([coef * rL[:, None], coef * rS[:, None]])
    flat = (idx[None] * n + cols).ravel()
    return jax.ops.segment_sum(vals.ravel(), flat, num_segments=n * n).reshape(n, n)


class FragData(eqx.Module):
    """Fragmentation right-hand-side data on the two-bin pair list (a pytree).

    p: (Np,) fragmenting fraction per pair; coef/idx: (Np, 4) direct mass coefficients [g]
    (losses, remnant placement) and target bins; ejecta: (Np,) mass [g] redistributed by the
    fragment weights W[src] (rows of W sum to 1).
    """

    p: jax.Array
    coef: jax.Array
    idx: np.ndarray
    ejecta: jax.Array
    src: np.ndarray
    W: jax.Array

    def rhs(self, rate, nbins):
        """Mass rate [g cm^-3 s^-1] (nbins + 1,) from fragmenting pair number rates ``rate``."""
        out = jax.ops.segment_sum((self.coef * rate[:, None]).ravel(), jnp.asarray(self.idx).ravel(),
                                  num_segments=nbins + 1)
        G = jax.ops.segment_sum(self.ejecta * rate, jnp.asarray(self.src), num_segments=nbins)
        gain = G @ self.W
        return out + jnp.concatenate([gain, jnp.zeros((1,), gain.dtype)])

    def jac_rates(self, rL, rS, iL, iS, nbins):
        """Jacobian (nbins + 1, nbins + 1) [s^-1] of :meth:`rhs` composed with pair rates whose
        state derivatives are d rate_p/d rho_iL = rL[p], d rate_p/d rho_iS = rS[p].

        Direct part: :func:`scatter_pair_jacobian`; ejecta: dG[s, j] = sum_{p: src_p = s}
        ejecta_p d rate_p/d rho_j (a scatter), then d gain/d rho = W^T dG (one N x N x (N+1)
        product). References: Brauer et al. (2008) §2.3 (fragment redistribution).
        """
        n = nbins + 1
        J = scatter_pair_jacobian(self.idx, self.coef, rL, rS, iL, iS, nbins)
        src = jnp.asarray(self.src)
        flat = jnp.concatenate([src * n + jnp.asarray(iL), src * n + jnp.asarray(iS)])
        dG = jax.ops.segment_sum(jnp.concatenate([self.ejecta * rL, self.ejecta * rS]), flat,
                                 num_segments=nbins * n).reshape(nbins, n)
        gain = self.W.T @ dG
        return J + jnp.concatenate([gain, jnp.zeros((1, n), gain.dtype)])


class OutcomeData(eqx.Module):
    """Right-hand-side data of :class:`~jaxcoag.outcomes.RecipeOutcome` on the two-bin pair list (a pytree).

    p: (Np,) fraction of collisions following the Outcome (1 - p stick via the coagulation
    tensors); eff: (Np,) kernel efficiency; coef/idx: (Np, 10) remnant placements and losses
    [g per collision] and their bins (N = gel); m_pwl: (Np,) fragment mass per collision [g];
    W: (Np, N) fragment mass fractions per bin.
    """

    p: jax.Array
    eff: jax.Array
    coef: jax.Array
    idx: jax.Array
    m_pwl: jax.Array
    W: jax.Array
    full: bool = eqx.field(static=True, default=False)

    def rhs(self, rate, nbins):
        """Mass rate [g cm^-3 s^-1] (nbins + 1,) from the Outcome collision number rates ``rate``."""
        r = rate * self.eff
        out = jax.ops.segment_sum((self.coef * r[:, None]).ravel(), self.idx.ravel(), num_segments=nbins + 1)
        gain = (r * self.m_pwl) @ self.W
        return out + jnp.concatenate([gain, jnp.zeros((1,), gain.dtype)])

    def jac_rates(self, rL, rS, iL, iS, nbins):
        """Jacobian (nbins + 1, nbins + 1) [s^-1] of :meth:`rhs` composed with pair rates whose
        state derivatives are d rate_p/d rho_iL = rL[p], d rate_p/d rho_iS = rS[p].

        Placements: :func:`scatter_pair_jacobian` (10 columns); fragments: d gain_b/d rho_j =
        sum_p W[p, b] m_pwl_p eff_p (rL_p [j = iL_p] + rS_p [j = iS_p]), i.e. two segment sums of
        the scaled rows of W over the partner bins (O(Np N), like one right-hand side) instead of
        a dense (N x Np) (Np x N) product. References: Birnstiel, Dullemond & Brauer (2010) eq. 15.
        """
        n = nbins + 1
        aL, aS = rL * self.eff, rS * self.eff
        J = scatter_pair_jacobian(self.idx, self.coef, aL, aS, iL, iS, nbins)
        GT = (jax.ops.segment_sum(self.W * (aL * self.m_pwl)[:, None], jnp.asarray(iL), num_segments=n)
              + jax.ops.segment_sum(self.W * (aS * self.m_pwl)[:, None], jnp.asarray(iS), num_segments=n))
        return J + jnp.concatenate([GT.T, jnp.zeros((1, n), GT.dtype)])

    def mass_balance(self):
        """Per-pair sum of all mass coefficients [g] (zero up to round-off: conservation)."""
        return jnp.sum(self.coef, axis=1) + self.m_pwl * jnp.sum(self.W, axis=1)


def powerlaw_weights(grid, q):
    """Mass fractions W[L, b] of a fragment power law n(m) ~ m^-q from the grid bottom to bin L.

    Arguments: grid (MassGrid); q (float leaf, the number-distribution exponent).
    Returns: (nbins, nbins) jnp array, lower triangular, rows sum to 1.
    References: Brauer et al. (2008) eq. 13 (fragment distribution).
    """
    le = jnp.asarray(grid.log_edges)
    lhi, dl = le[1:], le[1:] - le[:-1]
    s = 2.0 - q  # mass per ln m ~ m^{2-q}
    small = jnp.abs(s) < 1e-8
    s_safe = jnp.where(small, 1.0, s)
    # int_bin m^s dln m = exp(s lhi) (1 - exp(-s dl))/s, in log form
    logfac = jnp.where(small, jnp.log(dl), jnp.log(-jnp.expm1(-s_safe * dl) / s_safe))
    logw = s * lhi + logfac
    N = grid.nbins
    mask = jnp.asarray(np.tril(np.ones((N, N), bool)))
    lw = jnp.where(mask, logw[None, :], -jnp.inf)
    return jax.nn.softmax(lw, axis=1)


def fragment_weights(log_edges, q, m_lo, m_hi):
    """Mass fractions of a fragment power law dn/dm ∝ m^q on [m_lo, m_hi] per bin.

    W[..., b] = int_{bin b ∩ [m_lo, m_hi]} m^(q+1) dm / int_{[m_lo, m_hi] ∩ grid} m^(q+1) dm
    (exact bin integrals of m^(q+1); q = -2 and any q handled by expm1(x)/x). The range is
    clipped to the grid (mass-exact); a degenerate range (m_hi <= m_lo (1 + 1e-12), e.g.
    monomers, or a range entirely outside the grid) puts all the mass in the bin holding m_lo;
    bins are [m_lo, m_hi), and an m_lo on an interior edge to a relative LOG_TOL = 1e-9
    (:data:`jaxcoag.binned.grid.LOG_TOL`) goes to the bin above the edge, not to the side the
    round-off of ln m_lo happens to fall on (e.g. m_lo = 7 g, edge 7 of
    ``MassGrid.log(0.7, 7e7, 7)``: ln 7 rounds 2.2e-16 below that edge).

    Arguments: log_edges: (N+1,) ln of the bin edges [ln g]; q: number slope [-]; m_lo, m_hi:
    fragment mass range [g] (arrays of a common shape S).
    Returns: (S..., N) weights, each row summing to 1.
    References: Ormel 2008 thesis eqs. 6.29-6.30; Birnstiel, Dullemond & Brauer (2010)
    eq. 15.
    """
    le = jnp.asarray(log_edges)
    N = le.shape[0] - 1
    m_lo, m_hi, q = jnp.broadcast_arrays(jnp.asarray(m_lo), jnp.asarray(m_hi), jnp.asarray(q))
    llo = jnp.clip(jnp.log(m_lo), le[0], le[-1])[..., None]
    lhi = jnp.clip(jnp.log(m_hi), le[0], le[-1])[..., None]
    deg = (lhi - llo) <= 1e-12
    llo_s = jnp.where(deg, le[0], llo)
    lhi_s = jnp.where(deg, le[-1], lhi)
    s = (q + 2.0)[..., None]  # mass per ln m ∝ m^(q+2)
    lead = (1,) * (llo.ndim - 1)
    e_lo, e_hi = le[:-1].reshape(lead + (N,)), le[1:].reshape(lead + (N,))
    a = jnp.clip(llo_s, e_lo, e_hi)
    c = jnp.clip(lhi_s, e_lo, e_hi)
    w = c - a
    pos = w > 0
    w_s = jnp.where(pos, w, 1.0)
    x = s * w_s
    small = jnp.abs(x) < 1e-8
    x_s = jnp.where(small, 1.0, x)
    phi = jnp.where(small, 1.0 + 0.5 * x, jnp.expm1(x_s) / x_s)  # expm1(x)/x > 0
    logI = jnp.where(pos, s * a + jnp.log(w_s) + jnp.log(phi), -jnp.inf)
    W = jax.nn.softmax(logI, axis=-1)
    kb = jnp.clip(jnp.searchsorted(le, llo[..., 0] + LOG_TOL, side="right") - 1, 0, N - 1)
    onehot = jax.nn.one_hot(kb, N, dtype=W.dtype)
    return jnp.where(deg, onehot, W)


def place_remnant(lce, ref, l_ref, delta, nu):
    """Coefficients that replace nu bodies of bin ``ref`` by nu remnants of mass m_ref e^delta.

    Two-bin split (number and mass exact) between the centres around the remnant; merged
    analytic form when the remnant lies between its parent's centre and a neighbouring one
    (no cancellation for tiny delta); below the first centre: mass into bin 0; beyond the last
    (extended) centre: into the gel accumulator (index N).

    Arguments: lce: (N+1,) ln centres with the extrapolated gel centre [ln g]; ref: (P,) int
    parent bins; l_ref: (P,) ln parent mass; delta: (P,) ln(m_r/m_ref); nu: (P,) number of
    remnants per collision.
    Returns: (idx (P, 3) int32, coef (P, 3) [g]) — mass per collision into bins idx.
    References: Kovetz & Olund (1969); Brauer et al. (2008) App. A.
    """
    lce = jnp.asarray(lce)
    N = lce.shape[0] - 1
    lr = l_ref + delta
    k = jnp.searchsorted(lce, lr, side="right") - 1  # -1 .. N
    up = (delta >= 0) & (k == ref)
    dn = (delta < 0) & (k == ref - 1) & (ref >= 1)
    refp = jnp.minimum(ref + 1, N)
    refm = jnp.maximum(ref - 1, 0)
    m_ref = jnp.exp(l_ref)
    dl_up = lce[refp] - lce[ref]
    dl_dn = jnp.where(ref >= 1, lce[ref] - lce[refm], 1.0)
    e_up = jnp.expm1(jnp.where(up, delta, 0.0)) / jnp.expm1(dl_up)
    g_dn = jnp.expm1(jnp.where(dn, delta, 0.0)) / jnp.expm1(-dl_dn)
    below = k < 0
    beyond = k >= N
    kc = jnp.clip(k, 0, N)
    kc1 = jnp.minimum(kc + 1, N)
    m_r = jnp.exp(jnp.minimum(lr, 700.0))
    mk, mk1 = jnp.exp(lce[kc]), jnp.exp(lce[kc1])
    gen = ~(below | beyond)
    den = jnp.where(gen & (mk1 > mk), mk1 - mk, 1.0)
    e = jnp.where(gen, (m_r - mk) / den, 0.0)
    z = jnp.zeros_like(m_ref)
    c0 = jnp.where(up, -nu * m_ref * e_up, jnp.where(dn, -nu * m_ref * g_dn, -nu * m_ref))
    i1 = jnp.where(up, refp, jnp.where(dn, refm, jnp.where(below, 0, jnp.where(beyond, N, kc))))
    c1 = jnp.where(up, nu * jnp.exp(lce[refp]) * e_up, jnp.where(dn, nu * jnp.exp(lce[refm]) * g_dn,
                   jnp.where(gen, nu * (1.0 - e) * mk, nu * m_r)))
    i2 = jnp.where(gen & ~(up | dn), kc1, ref)
    c2 = jnp.where(gen & ~(up | dn), nu * e * mk1, z)
    idx = jnp.stack([ref, i1, i2], axis=-1).astype(jnp.int32)
    return idx, jnp.stack([c0, c1, c2], axis=-1)


def place_remnant_np(grid, iL, mr_log, chi_mS):
    """Coefficients placing an eroded remnant of mass m_r = m_L - chi m_S < m_L (replacing body L)
    by the two-bin split (numpy, fixed pattern; merged form when it lands in [m_{L-1}, m_L]).

    Arguments: grid (MassGrid); iL (P,) int target bins; mr_log (P,) ln m_r [ln g]; chi_mS (P,)
    eroded mass [g]. Returns: (idx (P, 3) int32, coef (P, 3) [g]).
    References: Stammler & Birnstiel (2022) §2.2 (erosion); Brauer et al. (2008) App. A.
    """
    N = grid.nbins
    lc = grid.log_centers
    mL = np.exp(lc[iL])
    k = np.searchsorted(lc, mr_log, side="right") - 1
    k = np.clip(k, 0, np.maximum(iL - 1, 0))
    mk = np.exp(lc[k])
    mk1 = np.exp(lc[np.minimum(k + 1, N - 1)])
    mr = np.exp(mr_log)
    adj = (k == iL - 1)
    dm = np.where(iL >= 1, mL - np.exp(lc[np.maximum(iL - 1, 0)]), 1.0)
    # merged form for k = L-1 (number a = chi m_S/(m_L - m_{L-1}) moves from L to L-1)
    cL_adj = -chi_mS * mL / dm
    cK_adj = chi_mS * np.exp(lc[np.maximum(iL - 1, 0)]) / dm
    # general form
    c1 = (mr - mk) * mk1 / np.where(mk1 > mk, mk1 - mk, 1.0)
    ck = mr - c1
    idx = np.stack([iL, k, np.minimum(k + 1, N - 1)], axis=1).astype(np.int32)
    coef = np.stack([np.where(adj, cL_adj, -mL), np.where(adj, cK_adj, ck), np.where(adj, 0.0, c1)], axis=1)
    return idx, coef
