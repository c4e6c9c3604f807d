"""Grouped collision rates in log space (volume-free, symmetric storage).

The symmetric volume-free matrix is ``Λ'_ab = ½ λ^G_ab V`` (a ≠ b) and ``Λ'_aa = λ^G_aa V``
with (eq. 5.31 and the z = 0 correction of eq. 5.10b; errata in docs/design_notes.md)

    λ^G_ab = w_a w_b 2^{min(z_a, z_b) + N_eps(a, b)} C_ab                (a ≠ b)
    λ^G_aa = w_a (w_a 2^{z_a} − 1) C_aa      (z_a ≥ 1, in-group collapse)
    λ^G_aa = ½ w_a (w_a − 1) C_aa            (z_a = 0, species formalism eq. 5.7)

with C = K/V. Everything is evaluated as logs (w up to 1e160, 2^z up to 2^1000, kernels
spanning hundreds of decades): no product m1*m2, g_a*g_b or 2^z_a*2^z_b is ever formed.
The event loop's fast path, :func:`rate_tile`, evaluates the same rates in linear space for the
analytic kernels (``cheap_linear``) where a guard on the state's range (``run._lin_rows``) shows
that every partial product stays within e^(±690); elsewhere it uses the log form.

Fractional multiplicities [own]: fragment counts are real numbers, so a z = 0 species may hold
0 < w < 1 (or 1 < w < 2 for its own pairs), less than one event removes (Δw_i = 1 from the
lower-zoom member i, Δw_j = 2^{−N_eps} from j, Δw = 2 from a z = 0 own pair). Such a pair takes
part with the fraction φ = min(1, w_i/Δw_i, w_j/Δw_j) of the event that it holds (donors lose
φ Δw, products get φ times their count: ``run._collide``), and its rate stored here is λ^G / φ,
so that the expected collision flux (rate × φ) is the formula above. φ = 1 (rates unchanged)
whenever the donors hold whole groups (integer multiplicities: every Sticking run).

References: Ormel (2008) thesis eqs. (5.7), (5.10), (5.12), (5.13), (5.31), (5.32);
rate designs A/B and MC hazards 4-5 in docs/design_notes.md.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["n_eps", "log_kernel_tile", "log_rate_tile", "log_diag_factor", "pow2", "rate_tile", "log_rate_row",
           "log_rate_matrix", "row_sums", "log_particle_rates"]

LN2 = 0.6931471805599453


def _eps_terms(z, logm, log2_feps, rounding: str = "ceil"):
    """Per-slot terms of N_eps: (z as float, log2 m, q = z + log2 m − log2 f_eps ∓ 1e-9) (see :func:`_zoom_exp`)."""
    if rounding not in ("ceil", "floor"):  # pragma: no cover - validated by MonteCarlo(...)
        raise ValueError(f"unknown neps_rounding {rounding!r}")
    zf = z.astype(logm.dtype)
    l2 = logm / LN2
    return zf, l2, ((zf + l2) - log2_feps) + (-1e-9 if rounding == "ceil" else 1e-9)


def _zoom_exp(ta, tb, rounding: str = "ceil"):
    """E = min(z_a, z_b) + N_eps(a, b) as an integer-valued float, from the per-slot terms ta, tb of
    :func:`_eps_terms` (broadcast); also returns min(z_a, z_b) (float) and a_low = z_a <= z_b.

    With i the lower-zoom member, E = clip(⌈q_j − log2 m_i⌉, z_i, z_j) = z_i + clip(⌈x⌉, 0, z_j − z_i), x the
    argument of :func:`n_eps`: one subtraction, one rounding and two clips per pair, all in floating point
    (the int conversions of the pair loop cost ~0.4 ns of a ~1.5 ns linear rate entry). Every user of N_eps (the
    rate tiles and the event, ``run._collide``) takes it from here, so they agree bitwise.
    """
    zfa, l2a, qa = ta
    zfb, l2b, qb = tb
    a_low = zfa <= zfb
    x = jnp.where(a_low, qb, qa) - jnp.where(a_low, l2a, l2b)
    n = jnp.ceil(x) if rounding == "ceil" else jnp.floor(x)
    zmin = jnp.minimum(zfa, zfb)
    return jnp.minimum(jnp.maximum(n, zmin), jnp.maximum(zfa, zfb)), zmin, a_low


def n_eps(z_a, z_b, logm_a, logm_b, log2_feps, rounding: str = "ceil"):
    """Group splitting factor N_eps of a pair (symmetric in a, b).

    Arguments:
        z_a, z_b: zoom numbers (int).
        logm_a, logm_b: ln of the particle masses [ln g].
        log2_feps: log2 of the maximum fractional mass gain f_eps per event.
        rounding: "ceil" (default; Δm/m ≤ f_eps holds) or "floor" (thesis-literal truncation).

    Returns:
        int32 N_eps = clip(round(x), 0, |z_a − z_b|), with x = (z_j − z_i) + log2 m_j − log2 m_i
        − log2 f_eps and i the lower-zoom member (N_eps = 0 for equal zooms); "ceil" rounds x − 1e-9 up,
        "floor" x + 1e-9 down (x within round-off of an integer rounds to it).

    References: Ormel (2008) eq. (5.12)/(5.32) (ceil rounding, capped at z_j - z_i:
    Ormel & Spaans (2008) errata in docs/design_notes.md).
    """
    E, zmin, _ = _zoom_exp(_eps_terms(z_a, logm_a, log2_feps, rounding), _eps_terms(z_b, logm_b, log2_feps, rounding),
                           rounding)
    return (E - zmin).astype(jnp.int32)


def _log_kernel(kernel, logm1, logm2, psi1, psi2):
    if psi1.shape[-1] == 0 and kernel.n_struct == 0:
        return kernel.log_kernel_from_log_mass(logm1, logm2)
    return kernel.log_kernel_from_log_mass(logm1, logm2, psi1, psi2)


def _safe_log_w(w):
    """ln w, −inf for w ≤ 0 (empty slots)."""
    pos = w > 0
    return jnp.where(pos, jnp.log(jnp.where(pos, w, 1.0)), -jnp.inf)


def log_kernel_tile(kernel, logm_a, psi_a, logm_b, psi_b):
    """ln K for every pair of the species sets A and B: shape (nA, nB) [ln(cm^3 s^-1)].

    Arguments: logm_a (nA,), psi_a (nA, P), logm_b (nB,), psi_b (nB, P). The pairs are
    evaluated as one flat batch (any elementwise kernel works, also kernels with per-pair root
    finds).
    """
    nA, nB = logm_a.shape[0], logm_b.shape[0]
    la = jnp.broadcast_to(logm_a[:, None], (nA, nB)).reshape(-1)
    lb = jnp.broadcast_to(logm_b[None, :], (nA, nB)).reshape(-1)
    P = psi_a.shape[-1]
    pa = jnp.broadcast_to(psi_a[:, None, :], (nA, nB, P)).reshape(nA * nB, P)
    pb = jnp.broadcast_to(psi_b[None, :, :], (nA, nB, P)).reshape(nA * nB, P)
    return _log_kernel(kernel, la, lb, pa, pb).reshape(nA, nB)


def log_rate_tile(logK, ia, logm_a, w_a, z_a, valid_a, ib, logm_b, w_b, z_b, valid_b, log2_feps, rounding="ceil",
                  lw_a=None, lw_b=None):
    """ln Λ' for the pairs (a, b) of A x B from their kernel values: shape (nA, nB), −inf = 0.

    Arguments:
        logK: (nA, nB) ln K(m_a, m_b) (:func:`log_kernel_tile`).
        ia, ib: (nA,), (nB,) slot indices (ia == ib marks the diagonal, the own-species pairs).
        logm_*, w_*, z_*, valid_*: species arrays of A (nA,) and B (nB,).
        log2_feps, rounding: as :func:`n_eps`.
        lw_a, lw_b: optional precomputed ln w (saves the logarithms when several tiles share them).

    Per-a quantities (diagonal, ln w_a) are evaluated on (nA, 1) and per-b ones on (1, nB): the
    only per-entry work is arithmetic on ln K (no logarithm or exponential per entry).

    References: Ormel (2008) eqs. (5.7), (5.13), (5.31); see :func:`log_rate_row`.
    """
    ta = tuple(t[:, None] for t in _eps_terms(z_a, logm_a, log2_feps, rounding))
    E, zmin, a_low = _zoom_exp(ta, tuple(t[None, :] for t in _eps_terms(z_b, logm_b, log2_feps, rounding)), rounding)
    lwa = (_safe_log_w(w_a) if lw_a is None else lw_a)[:, None]
    lw = (_safe_log_w(w_b) if lw_b is None else lw_b)[None, :]
    # event fraction phi (see the module docstring and run._collide): the lower-zoom member i gives
    # one group, the other 2^-N_eps groups (N_eps = 0 for equal zooms, so the roles do not matter
    # there); a donor holding less (0 < w < 1 at z = 0) joins with the fraction it has, at a rate
    # divided by that fraction (ln phi = 0 for whole groups, the rate is then unchanged bitwise)
    ne_ln2 = (E - zmin) * LN2
    lphi = jnp.minimum(0.0, jnp.minimum(jnp.where(a_low, lwa, lwa + ne_ln2), jnp.where(a_low, lw + ne_ln2, lw)))
    lphi = jnp.where(jnp.isfinite(lphi), lphi, 0.0)
    a_off = lwa + lw + E * LN2
    # diagonal (per a); the barrier makes XLA compute its log/expm1 once per row, not fused into every entry
    dg = jax.lax.optimization_barrier(log_diag_factor(w_a, z_a, lwa[:, 0])[:, None])
    # ln K enters once, after the selects: a select with ln K (or anything computed from it) as an operand
    # keeps XLA-CPU from vectorising the fused loop (Sum kernel, (3, 4096) tiles: 11.7 against 3.2 + 1.9 ns per
    # entry for the kernel and the rate apart). Subtracting the selected zeros keeps every value bitwise that of
    # ((a_off + ln K) - ln 2) - ln phi off the diagonal and dg + ln K on it.
    on = ia[:, None] == ib[None, :]
    out = (jnp.where(on, dg, a_off) + logK) - jnp.where(on, 0.0, LN2) - jnp.where(on, 0.0, lphi)
    return out + jnp.where(valid_a[:, None] & valid_b[None, :], 0.0, -jnp.inf)


def log_diag_factor(w_a, z_a, lw_a=None):
    """ln(λ^G_aa / C_aa) of the own-species pairs, per row: shape (nA,), −inf where zero.

    ``w_a (w_a 2^{z_a} − 1)`` for z_a ≥ 1 (in-group collapse) and ``½ w_a (w_a − 1)`` for z_a = 0
    (species formalism), divided by the event fraction φ_aa = w_a/2 where 1 < w_a < 2 (module docstring).

    References: Ormel (2008) eqs. (5.7), (5.31).
    """
    dt = w_a.dtype
    lwa = _safe_log_w(w_a) if lw_a is None else lw_a
    lg = lwa + z_a.astype(dt) * LN2
    # z >= 1: w (g - 1), with g >= 2
    gm1_pos = lg > 1e-12
    log_gm1 = jnp.where(gm1_pos, lg + jnp.log(-jnp.expm1(-jnp.where(gm1_pos, lg, 1.0))), -jnp.inf)
    d_grouped = lwa + log_gm1
    wm1 = w_a - 1.0
    # z = 0 own pair: two particles leave (Δw = 2); with 1 < w < 2 the event takes the fraction
    # phi = w/2 (all of it) at the rate ½ w (w - 1) C / phi (= (w - 1) C), see off-diagonal above
    lphi_aa = jnp.where(w_a >= 2.0, 0.0, lwa - LN2)
    d_single = jnp.where(wm1 > 0, lwa + jnp.log(jnp.where(wm1 > 0, wm1, 1.0)) - LN2 - lphi_aa, -jnp.inf)
    return jnp.where(z_a >= 1, d_grouped, d_single)


def pow2(k):
    """2^k as float64, exactly, for integer k in [-1022, 1023] (built from the exponent bits: no
    transcendental function, and XLA-CPU vectorises it)."""
    e = (jnp.clip(k, -1022, 1023).astype(jnp.int64) + 1023) << 52
    return jax.lax.bitcast_convert_type(e, jnp.float64)


def _pow2_float(y):
    """2^y as float64, exactly, for an integer-valued float64 y in [-1022, 1023] (the caller guarantees it): y + 1023
    lands in the low mantissa bits of y + (1023 + 2^52), which a shift moves into the exponent field. No
    float-to-int conversion (that cost more than the rest of the linear rate entry's zoom factor)."""
    b = jax.lax.bitcast_convert_type(y + (1023.0 + 2.0 ** 52), jnp.int64)
    return jax.lax.bitcast_convert_type(b << 52, jnp.float64)


def rate_tile(K, ia, r_a, d_a, logm_a, w_a, z_a, valid_a, ib, logm_b, w_b, z_b, valid_b, log2_feps, rounding="ceil"):
    """Λ'_ab e^{−s} for the pairs of A x B in linear space, from linear kernel values: shape (nA, nB).

    The same rates as ``exp(log_rate_tile(...) - s)`` (to round-off) without a logarithm or
    exponential per entry, for kernels whose linear values are cheap (``cheap_linear``):

        off the diagonal  K_ab · r_a · w_b 2^{min(z_a, z_b) + N_eps} / φ_ab,   r_a = ½ w_a e^{−s}
        on the diagonal   K_aa · d_a,                                           d_a = e^{ln diag_a − s}

    with 1/φ = max(1, 1/w_i, 2^{−N_eps}/w_j) = max(c_i, c_j 2^{−N_eps}), c = max(1, 1/w) per slot (i the
    lower-zoom member): no division per entry.

    Arguments:
        K: (nA, nB) kernel values [cm^3 s^-1] (the kernel's ``__call__`` on the linear masses).
        ia, ib: slot indices (ia == ib marks the diagonal).
        r_a, d_a: (nA,) the per-row factors above (computed from logs, once per row).
        logm_*, w_*, z_*, valid_*: species arrays of A and B (logm for N_eps only).
        log2_feps, rounding: as :func:`n_eps`.

    The caller guarantees the range: every partial product r_a w_b 2^k / φ within [e^{-690}, e^{690}] and
    every zoom number at most 1000 (the Monte Carlo loop checks bounds of the state before it takes this path;
    otherwise it uses :func:`log_rate_tile`).

    References: Ormel (2008) eqs. (5.7), (5.13), (5.31).
    """
    E, zmin, a_low = _zoom_exp(tuple(t[:, None] for t in _eps_terms(z_a, logm_a, log2_feps, rounding)),
                               tuple(t[None, :] for t in _eps_terms(z_b, logm_b, log2_feps, rounding)), rounding)
    ca = jnp.where(w_a > 0, jnp.maximum(1.0, 1.0 / jnp.where(w_a > 0, w_a, 1.0)), 1.0)[:, None]
    cb = jnp.where(w_b > 0, jnp.maximum(1.0, 1.0 / jnp.where(w_b > 0, w_b, 1.0)), 1.0)[None, :]
    inv_phi = jnp.maximum(jnp.where(a_low, ca, cb), jnp.where(a_low, cb, ca) * _pow2_float(zmin - E))
    off = (r_a[:, None] * w_b[None, :]) * _pow2_float(E) * inv_phi
    on = ia[:, None] == ib[None, :]
    f = jnp.where(on, d_a[:, None], off)
    return (f * jnp.where(valid_a[:, None] & valid_b[None, :], 1.0, 0.0)) * K


def log_rate_row(kernel, a, logm, psi, w, z, valid, log2_feps, rounding="ceil"):
    """ln of row ``a`` of the volume-free symmetric rate matrix Λ' (shape (S,), -inf = 0).

    Arguments:
        kernel: an ``AbstractKernel``; a: slot index; logm [ln g], psi, w, z, valid: species
        arrays of shape (S,) / (S, P); log2_feps: log2 f_eps; rounding: N_eps rounding.

    Returns:
        (S,) array ln Λ'_{a,b} [ln(cm^3 s^-1)] (multiply by exp(-ln V) for the event rate).

    References: Ormel (2008) eqs. (5.7), (5.13), (5.31); rate designs in docs/design_notes.md.
    """
    S = logm.shape[0]
    a1 = jnp.reshape(jnp.asarray(a), (1,))
    logK = log_kernel_tile(kernel, logm[a1], psi[a1], logm, psi)
    return log_rate_tile(logK, a1, logm[a1], w[a1], z[a1], valid[a1], jnp.arange(S), logm, w, z, valid, log2_feps,
                         rounding)[0]


def log_rate_matrix(kernel, logm, psi, w, z, valid, log2_feps, rounding="ceil"):
    """Full (S, S) matrix ln Λ' (rows of :func:`log_rate_row`); O(S^2) memory and work.

    References: Ormel (2008) eq. (5.31); rate design A in docs/design_notes.md.
    """
    S = logm.shape[0]
    return jax.vmap(lambda a: log_rate_row(kernel, a, logm, psi, w, z, valid, log2_feps, rounding))(
        jnp.arange(S))


def row_sums(L):
    """Scaled row sums of a log-rate matrix: returns (R, s) with R_a exp(s) = Σ_b exp(L_ab).

    The scale s = max_a ln R_a keeps the largest row sum at 1 (rates of 1e300 and 1e-300 can
    coexist; rows below exp(s - 745) underflow to 0 and are re-derived on the next refresh).

    References: MC hazard 5 in docs/design_notes.md (scale by the max before exponentiating).
    """
    rlog = jax.nn.logsumexp(L, axis=1)
    rlog = jnp.where(jnp.isnan(rlog), jnp.nan, rlog)
    s = jnp.max(jnp.where(jnp.isfinite(rlog) | jnp.isnan(rlog), rlog, -jnp.inf))
    s_ok = jnp.isfinite(s)
    s = jnp.where(s_ok, s, 0.0)
    R = jnp.exp(rlog - s)
    R = jnp.where(jnp.isnan(rlog) | (rlog == jnp.inf), jnp.nan, R)
    return R, s


def log_particle_rates(kernel, logm, psi, w, z, valid):
    """ln of the volume-free physical collision rate of one particle of each species.

    ``ln Σ_b K(m_a, m_b) g_b`` (the rate per particle is this times 1/V [s^-1]); the
    partner sum includes the own species (g_a, not g_a - 1: the difference is irrelevant
    where this is used, the tail zoom cap of the distribution method). O(S^2) kernel
    evaluations, in log space (kernels of 1e300 and multiplicities of 1e160 are fine).

    Returns: (S,) array, -inf on invalid slots.
    References: Ormel (2008) §5.3.3 (runaway kernels: groups must collide on time scales
    short compared to t_R); log-space rates (docs/design_notes.md).
    """
    lg = jnp.where(valid, jnp.log(jnp.where(valid & (w > 0), w, 1.0)) + z.astype(logm.dtype) * LN2, -jnp.inf)

    def one(a):
        S = logm.shape[0]
        la = jnp.broadcast_to(logm[a], (S,))
        pa = jnp.broadcast_to(psi[a], psi.shape)
        return jax.nn.logsumexp(_log_kernel(kernel, la, logm, pa, psi) + lg)

    r = jax.vmap(one)(jnp.arange(logm.shape[0]))
    return jnp.where(valid, r, -jnp.inf)
