"""Grouping: zoom methods, (de)magnification and merging of species.

A species of multiplicity g is simulated as w groups of 2^z particles, g = w 2^z (eq. 5.8).
The zoom method only decides z; ``apply_zoom`` caps it so that w ≥ 1 and adjusts w exactly
(``ldexp``), ``demagnify`` restores w ≥ 1 after a donor lost groups, ``merge_pairs`` is the
smoothing safety valve that keeps the species count below the capacity.

References: Ormel (2008) thesis §5.2.1 (limiting Ns: merging), §5.2.3-5.2.4 (zoom methods,
(de)magnification), eq. (5.8), (5.14), App. 5.B; errata of Ormel & Spaans (2008) in docs/design_notes.md.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["zoom_target_equal_mass", "zoom_target_distribution", "distribution_nodes", "count_nodes", "zoom_cap_tail",
           "apply_zoom", "demagnify", "merge_pairs", "log_g"]

LN2 = 0.6931471805599453


def log_g(w, z):
    """ln g = ln w + z ln 2 (−inf for w = 0)."""
    pos = w > 0
    return jnp.where(pos, jnp.log(jnp.where(pos, w, 1.0)), -jnp.inf) + z.astype(w.dtype) * LN2


def zoom_target_equal_mass(logm, log_mstar):
    """Equal-mass zoom target ẑ = max(0, ⌊log2(m*/m)⌋) (group mass in (m*/2, m*]).

    Arguments: logm: ln particle mass [ln g]; log_mstar: ln m* [ln g].
    Returns: int32 target zoom.
    References: Ormel (2008) eq. (5.14) (rounded down: see the Ormel & Spaans (2008)
    errata in docs/design_notes.md).
    """
    return jnp.maximum(jnp.floor((log_mstar - logm) / LN2 + 1e-9), 0.0).astype(jnp.int32)


def distribution_nodes(logm, w, z, valid, log_mlo, log_ng_target, n_bins: int):
    """Nodes (x_p = ln m, f_p = zoom) of the distribution-method zoom function.

    Log-spaced bins between m_lo and the largest mass M_L1 (width ≥ ln 2), particle
    occupancy N_k per bin, target G = Ng*/N_occ groups per occupied bin, bin zoom
    max(0, log2(N_k/G)); the function is the cumulative minimum (non-increasing in m) of the
    occupied-bin values, piecewise linear in ln m, flat outside.

    Returns: (xp, fp), each (n_bins,), for ``jnp.interp``.
    References: Ormel (2008) §5.2.3 (distribution method).
    """
    lmax = jnp.max(jnp.where(valid, logm, -jnp.inf))
    lmax = jnp.where(jnp.isfinite(lmax), lmax, log_mlo)
    width = jnp.maximum((lmax - log_mlo) / n_bins, LN2)
    b = jnp.clip(jnp.floor((logm - log_mlo) / width), 0, n_bins - 1).astype(jnp.int32)
    lg = jnp.where(valid, log_g(w, z), -jnp.inf)
    bmax = jax.ops.segment_max(lg, b, num_segments=n_bins)
    occ = jax.ops.segment_sum(valid.astype(jnp.int32), b, num_segments=n_bins) > 0
    bmax_safe = jnp.where(occ, bmax, 0.0)
    ssum = jax.ops.segment_sum(jnp.where(valid, jnp.exp(lg - bmax_safe[b]), 0.0), b, num_segments=n_bins)
    logN = jnp.where(occ, bmax_safe + jnp.log(jnp.where(occ, ssum, 1.0)), -jnp.inf)
    n_occ = jnp.maximum(jnp.sum(occ), 1)
    logG = log_ng_target - jnp.log(n_occ.astype(logm.dtype))
    zb = jnp.maximum((logN - logG) / LN2, 0.0)
    centres = log_mlo + (jnp.arange(n_bins) + 0.5) * width
    fake = lmax + 1e3 + jnp.arange(n_bins)
    xkey = jnp.where(occ, centres, fake)
    order = jnp.argsort(xkey, stable=True)
    xp = xkey[order]
    fp = jnp.where(occ, zb, 1e4)[order]
    fp = jax.lax.cummin(fp)
    return xp, fp


def zoom_target_distribution(logm, xp, fp):
    """Distribution-method zoom target ⌊z(m)⌋ from the nodes of :func:`distribution_nodes`.

    References: Ormel (2008) §5.2.3 (distribution method), §5.2.4 ((de)magnification); the cap
    z <= floor(log2 g) is ours.
    """
    return jnp.maximum(jnp.floor(jnp.interp(logm, xp, fp)), 0.0).astype(jnp.int32)


def count_nodes(logm, w, z, valid, log_gc):
    """Nodes of the tail-count refinement of the distribution zoom: z_c(m) = log2(C(m) / G_c).

    C(m_i) = Σ_{j: m_j ≥ m_i} g_j is the number of particles at least as heavy as species i
    (a cumulative count from the heavy end), G_c the target number of groups per factor 2 of C.
    Bins equally spaced in ln C instead of ln m: where the count falls steeply with mass (the
    seed tail of a runaway kernel, n_k ∝ e^{-(ν-1) k} at k ≲ ln N) log-mass bins of width ≥ ln 2
    mix counts that differ by e^{k}, so the bin zoom of the lower edge is imposed on the rare heavy
    particles and a whole species moves as one group; z_c gives every species ≈ G_c g_i/C_i ≥
    G_c (1 - e^{-(ν-1)}) groups there and single particles (z = 0) where C ≲ G_c.
    z_c is non-increasing in m by construction; the run uses min(thesis z(m), z_c(m)), which
    only ever refines the thesis zoom.

    Arguments: logm, w, z, valid: species arrays (S,); log_gc: ln G_c.
    Returns: (xp, fp), each (S,): xp = ln m of the species in increasing order (invalid slots
    placed above the heaviest, with the value of the heaviest), fp = max(0, log2(C/G_c)).
    References: Ormel (2008) §5.2.3 (distribution method; "a more flexible bin placement");
    zoom method weakness in docs/design_notes.md **[own]**.
    """
    lg = jnp.where(valid, log_g(w, z), -jnp.inf)
    lmax = jnp.max(jnp.where(valid, logm, -jnp.inf))
    lmax = jnp.where(jnp.isfinite(lmax), lmax, 0.0)
    key = jnp.where(valid, logm, lmax + 1e3 + jnp.arange(logm.shape[0], dtype=logm.dtype))
    order = jnp.argsort(key, stable=True)
    xs = key[order]
    lgs = lg[order]
    # cumulative count from the heavy end: reverse cumulative logsumexp
    logC = jax.lax.cumlogsumexp(lgs[::-1])[::-1]
    zc = jnp.maximum((logC - log_gc) / LN2, 0.0)
    vs = valid[order]
    # invalid (fake) nodes above the heaviest: repeat the heaviest value (flat extrapolation)
    zmin_valid = jnp.min(jnp.where(vs, zc, jnp.inf))
    zc = jnp.where(vs, zc, jnp.where(jnp.isfinite(zmin_valid), zmin_valid, 0.0))
    return xs, zc


def zoom_cap_tail(w, z, valid, log_rate, t, log_wmax, n_events=1.0):
    """Tail cap of the distribution-method zoom: w ≥ n_events / (r t), but w ≤ W_max.

    A group event of species i moves a *quantum* of 2^{z_i} particles at once; the mean flux
    is exact for any zoom (App. 5.A), but where the expected number of particles that leave
    species i in the elapsed time, g_i r_i t, is below one quantum, the rare upward jumps
    that seed a runaway are under-sampled: the high-mass front then advances as if the
    system held ~Ng*/N_b particles per bin instead of N (measured: t_R of (m_i m_j)^2 at
    N = 1e20 was 0.10 with Ng* = 200 and 0.06 with Ng* = 2000, i.e. t_R stopped falling
    with N). Capping z_i ≤ log2(g_i r_i t / n_events) makes every quantum at most the
    expected outflow, so the front advances with the true tail counts and the heaviest
    particles become single (z = 0) where g r t < 1. It costs ≈ n_events group events per
    capped species per elapsed time t. The lower bound z ≥ log2(g_i / W_max) (W_max =
    ``Distribution(tail_wmax=...)``, default Ng*) keeps a bulk species at ≤ W_max groups at t → 0.

    At t = 0 the cap is the floor itself (as many groups as W_max allows).

    Arguments: w, z, valid: species arrays; log_rate: ln r_i, physical collisions per
    particle per unit time [ln s^-1]; t: current time [s]; log_wmax: ln W_max;
    n_events: expected group events per species within t (default 1).
    Returns: int32 cap (a large number on invalid slots).
    References: Ormel (2008) §5.3.3 (demagnify so that t_11 << t_R).
    """
    lg = log_g(jnp.where(valid, w, 1.0), z)
    lt = jnp.log(jnp.maximum(t, 1e-300))
    z_time = (lg + log_rate + lt - jnp.log(n_events)) / LN2
    z_floor = (lg - log_wmax) / LN2
    zc = jnp.maximum(jnp.where(jnp.isfinite(z_time), z_time, -1.0), z_floor)
    # t = 0 (the first rezoom): the time criterion asks for infinitely many groups, i.e. the
    # W_max floor. Without this the first event of a runaway run waited ~1/w_0 = 1/Ng*
    # (measured: no event before t = 2.7e-4 for nu = 3, N = 1e160, where t_R ~ 5e-5).
    zc = jnp.where(t > 0, zc, z_floor)
    zc = jnp.clip(jnp.floor(zc + 1e-9), 0.0, 2000.0)
    return jnp.where(valid, zc, 2000.0).astype(jnp.int32)


def apply_zoom(w, z, zhat):
    """Set z = clip(ẑ, 0, ⌊log2 g⌋) and w = g / 2^z exactly (g = w 2^z unchanged).

    Arguments: w (float), z (int), zhat (int target). Works elementwise; for w < 1 (only
    possible at z = 0 with non-integer multiplicities) the species stays at z = 0.
    Returns: (w_new, z_new).
    References: Ormel (2008) §5.2.4 ((de)magnification; vectorised form [own]).
    """
    _, e = jnp.frexp(jnp.where(w > 0, w, 1.0))
    cap = z + (e - 1)
    z_new = jnp.clip(zhat, 0, jnp.maximum(cap, 0)).astype(jnp.int32)
    z_new = jnp.where(w > 0, z_new, z)
    w_new = jnp.ldexp(w, z - z_new)
    return w_new, z_new


def demagnify(w, z, tol=1e-9):
    """Donor fix-up: remove (w → 0) if g ≤ tol, else halve groups until w ≥ 1 (closed form).

    Returns: (w, z, alive). A species reaching z = 0 with w < 1 (non-integer multiplicity
    from fragmentation or merging) stays alive with that w.
    References: Ormel (2008) §5.2.3-5.2.4, App. 5.B step 5.2 (closed form via frexp);
    MC hazards 2-3 in docs/design_notes.md.
    """
    alive = w > jnp.ldexp(jnp.full_like(w, tol), -z)
    _, e = jnp.frexp(jnp.where(alive, w, 1.0))
    k = jnp.clip(1 - e, 0, z)
    w_new = jnp.where(alive, jnp.ldexp(w, k), 0.0)
    z_new = jnp.where(alive, z - k, 0)
    return w_new, z_new.astype(jnp.int32), alive


def merge_pairs(m, logm, psi, w, z, valid, n_merge, p_protect: int, weighting: str = "mass"):
    """Merge up to ``n_merge`` disjoint pairs of mass-neighbouring species.

    Species are sorted by mass; candidate pairs are (2p, 2p+1) in that order (disjoint by
    construction) among the unprotected species (the ``p_protect`` most massive are never
    merged); the ``n_merge`` pairs closest in ln m (more on exact ties) merge into the lighter slot with
    g = g_a + g_b, m = (g_a m_a + g_b m_b)/g (mass conserved, no rounding) and psi averaged
    with ``weighting`` ∈ {"number" (thesis formula), "mass", "volume" (= mass here, for a
    common material density)}. The merged species keeps the smaller zoom of the two, then w
    is set to g/2^z (the caller rezooms).

    Returns: (m, logm, psi, w, z, valid, n_done).
    References: Ormel (2008) §5.2.1 "Limiting Ns", App. 5.B 6.3; merging errata in docs/design_notes.md.
    """
    S = m.shape[0]
    key = jnp.where(valid, logm, jnp.inf)
    order = jnp.argsort(key, stable=True)
    ns = jnp.sum(valid)
    rank = jnp.arange(S)
    unprot = (rank < ns - p_protect) & valid[order]
    P = S // 2
    A = order[0:2 * P:2]
    B = order[1:2 * P:2]
    okp = unprot[0:2 * P:2] & unprot[1:2 * P:2]
    d = jnp.where(okp, logm[B] - logm[A], jnp.inf)
    thr = jnp.sort(d)[jnp.clip(n_merge - 1, 0, P - 1)]
    sel = okp & (d <= thr) & (n_merge > 0)
    lgA = log_g(w[A], z[A])
    lgB = log_g(w[B], z[B])
    lg = jnp.logaddexp(lgA, lgB)
    pA = jnp.exp(lgA - lg)
    pB = jnp.exp(lgB - lg)
    m_new = pA * m[A] + pB * m[B]
    logm_new = jnp.log(m_new)
    if weighting == "number":
        qA, qB = pA, pB
    elif weighting in ("mass", "volume"):
        qA = pA * m[A] / m_new
        qB = pB * m[B] / m_new
    else:  # pragma: no cover - validated by MonteCarlo(...)
        raise ValueError(f"unknown merge_weighting {weighting!r}")
    psi_new = qA[:, None] * psi[A] + qB[:, None] * psi[B]
    z_new = jnp.minimum(z[A], z[B])
    w_new = jnp.exp(lg - z_new.astype(lg.dtype) * LN2)
    selc = sel[:, None]
    m = m.at[A].set(jnp.where(sel, m_new, m[A]))
    logm = logm.at[A].set(jnp.where(sel, logm_new, logm[A]))
    psi = psi.at[A].set(jnp.where(selc, psi_new, psi[A]))
    w = w.at[A].set(jnp.where(sel, w_new, w[A]))
    z = z.at[A].set(jnp.where(sel, z_new, z[A]))
    valid = valid.at[B].set(jnp.where(sel, False, valid[B]))
    w = w.at[B].set(jnp.where(sel, 0.0, w[B]))
    z = z.at[B].set(jnp.where(sel, 0, z[B]))
    m = m.at[B].set(jnp.where(sel, 1.0, m[B]))
    logm = logm.at[B].set(jnp.where(sel, 0.0, logm[B]))
    return m, logm, psi, w, z, valid, jnp.sum(sel)
