"""Jitted grouped Monte Carlo coagulation (Ormel & Spaans 2008) — the event loop.

The public entry is ``jaxcoag.evolve(kernel, jaxcoag.MonteCarlo(...), initial, t_out, key=...)``
(:mod:`jaxcoag.mc.engine`); this module holds the loop it advances: :func:`_simulate` runs one
segment of output times from an :class:`~jaxcoag.mc.state.MCState` and returns the end state and
the snapshots.

Structure of one run (all inside ``jax.jit``; batch runs with ``jax.vmap``):

    outer lax.while_loop (until done):
        maintenance: merge (capacity / distribution policy) -> global rezoom -> full rate refresh
        inner lax.while_loop (until done or maintenance due):
            one event: Δt, pair (a, b) [Gillespie full conditioning], snapshots, collision via
            the outcome module, donor fix-up (removal / demagnification), product zoom,
            duplication (const_n / const_ns), incremental update of the rate row sums; all reads
            of the species arrays in one-trip loops (``_opaque_reads``), the writes as one scatter per
            array; without a lax.cond (``COND_FREE_CAPACITY``): no capacity-sized copy per event

The two-level loop keeps the O(S^2) refresh out of the per-event path even under ``vmap``
(where ``lax.cond`` would evaluate both branches).

References: Ormel (2008) thesis §2.3.2, ch. 5 (eqs. 5.6-5.13, 5.31-5.33, App. 5.A/5.B);
Gillespie (1975); Smith & Matsoukas (1998); conventions, defaults and MC hazards in
docs/design_notes.md.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import grouping as G
from .rates import _safe_log_w, log_diag_factor, log_kernel_tile, log_rate_tile, n_eps, pow2, rate_tile
from .state import STATUS, MCState, Snapshots

__all__ = ["CapacityWarning", "min_capacity"]

LN2 = 0.6931471805599453


@dataclasses.dataclass(frozen=True)
class _Cfg:
    """Static (compile-time) configuration of one segment, built from a ``MonteCarlo`` engine and
    the state's shapes (mode: const_v / const_n / const_ns; grouping: None / equal_mass /
    distribution; controller: mass / species)."""

    mode: str
    grouping: str | None
    capacity: int
    n_snap: int
    n_struct: int
    n_prod: int
    rates: str
    n_refresh: int
    rounding: str
    controller: str
    d_max: int
    d_up: int
    n_bins: int
    p_protect: int
    weighting: str
    dedupe: bool
    n_rezoom: int
    leftover: str = "demagnify"
    # > 0: time-resolution cap of the distribution zoom (grouping.zoom_cap_tail): every species is
    # expected to see >= tail_events group events per elapsed time t (runaway kernels, Fig 5.7)
    tail_events: float = 0.0
    # ln G_c of the tail-count refinement of the distribution zoom (grouping.count_nodes); None = off
    count_zoom: float | None = None
    # species per block of the per-event passes over the active prefix [0, hi) (kernel tiles); per-event work is
    # O(hi), independent of the capacity. 128 was fastest of 64/128/256/512 for Ns* = 2000 (~600 live species) on
    # 2 CPU cores; from BIG_BLOCKS_FROM occupied slots on the events use _cfg_big's longer blocks
    block: int = 128
    # block of the cheap passes (sums and searches); None: 4 x block
    cheap_block: int | None = None
    # equal-mass scheduled merge above em_merge x Ns* (None: above 0.9 S only)
    em_merge: float | None = 2.0
    # per-event rate tiles in linear space for kernels with ``cheap_linear`` (see _lin_rows); False: log space always
    linear_rates: bool = True


# ----------------------------------------------------------------------------- helpers

def _log_mp(logm, w, z, valid):
    """ln m_p = ln(M2/M1) of the simulated population."""
    lg = jnp.where(valid, G.log_g(w, z), -jnp.inf)
    return jax.nn.logsumexp(lg + 2 * logm) - jax.nn.logsumexp(lg + logm)


def _zhat(cfg, logm, st_log_mstar, xp, fp):
    if cfg.grouping is None:
        return jnp.zeros(logm.shape, jnp.int32)
    if cfg.grouping == "equal_mass":
        return G.zoom_target_equal_mass(logm, st_log_mstar)
    if cfg.count_zoom is not None:
        nb = cfg.n_bins
        zt = jnp.minimum(jnp.interp(logm, xp[:nb], fp[:nb]), jnp.interp(logm, xp[nb:], fp[nb:]))
        return jnp.maximum(jnp.floor(zt), 0.0).astype(jnp.int32)
    return G.zoom_target_distribution(logm, xp, fp)


def _arrays(st):
    return (st.m, st.logm, st.psi, st.w, st.z, st.valid)


def _write_snap(snaps: Snapshots, k, st):
    return Snapshots(
        m=snaps.m.at[k].set(st.m), logm=snaps.logm.at[k].set(st.logm),
        psi=snaps.psi.at[k].set(st.psi), w=snaps.w.at[k].set(st.w), z=snaps.z.at[k].set(st.z),
        valid=snaps.valid.at[k].set(st.valid), logV=snaps.logV.at[k].set(st.logV),
        M_tot=snaps.M_tot.at[k].set(st.M_tot), n_events=snaps.n_events.at[k].set(st.n_events),
        status=snaps.status.at[k].set(st.status))


def _fill(cfg, p, st, t_new):
    """Record snapshots k with t_out[k] < t_new (t_new = inf fills all remaining)."""
    t_out = p["t_out"]

    def cond(c):
        k, _ = c
        return (k < cfg.n_snap) & (t_out[jnp.minimum(k, cfg.n_snap - 1)] < t_new)

    def body(c):
        k, snaps = c
        return k + 1, _write_snap(snaps, k, st)

    k, snaps = jax.lax.while_loop(cond, body, (st.k_out, st.snaps))
    return st._replace(k_out=k, snaps=snaps)


#: Capacity (slots) from which the event runs without a lax.cond (no S-slot copy per event); 0: always. Below it the
#: event is a cond whose branch copies four species arrays in and out (S slots each). Since stop 45 the cond-free
#: event is the body of a one-trip while loop and faster at every size measured on 2 CPU cores (us per event, cond
#: against cond-free): Ns* = 100 / 400 / 1000 to t = 5 19.8 / 20.8 / 23.3 against 18.9 / 19.5 / 19.6, the issue-17
#: goal run (8 000 slots) 85.3 against 81.0. (Stop 32 had found the cond faster below 16 384 slots: 175 against
#: 215-250 us at 657 species and 8 000 slots; without the while loop the thread pool doubled the cond-free event.)
#: Both forms give the same events bitwise.
COND_FREE_CAPACITY = 0


def _ns_hi_equal_mass(cfg):
    """Capacity part of the equal-mass merge threshold (0.9 S, below the emergency level)."""
    return min(math.floor(0.9 * cfg.capacity), cfg.capacity - cfg.n_prod - 3)


def _ns_hi_em(cfg, ns_target):
    """Species count above which an equal-mass run merges: 2 Ns* (thesis ch. 6: merging at Ns = 2 Ns*),
    or 0.9 S when the capacity is smaller. Without the 2 Ns* rule the demagnification leftovers (MC
    hazard 3) let the count drift to ~7 Ns* (measured: 671 species for Ns* = 100 at t = 10, sum kernel),
    and the cost per event grows with it."""
    if cfg.em_merge is None:
        return jnp.asarray(float(_ns_hi_equal_mass(cfg)))
    return jnp.minimum(_ns_hi_equal_mass(cfg), jnp.floor(cfg.em_merge * ns_target))


def min_capacity(grouping, ns_target, n_products=1):
    """Smallest ``capacity`` S whose merge threshold still holds ``ns_target`` species.

    Grouped runs merge mass neighbours once the species count exceeds a fraction of S
    (distribution: min(0.9 S, Ng*); equal-mass: min(0.9 S, S - n_products - 3), thesis §5.2.1,
    App. 5.B); below this S the run would keep fewer species than ``ns_target`` asks for, i.e.
    a coarser resolution than requested. None for grouping=None (no such threshold).

    Arguments: grouping: None, "equal_mass" or "distribution" (or the engine's grouping object
    ``EqualMass()`` / ``Distribution()``); ns_target: Ns* or Ng*; n_products: the outcome's
    ``n_products``.
    """
    if grouping is not None and not isinstance(grouping, str):
        grouping = "equal_mass" if type(grouping).__name__ == "EqualMass" else "distribution"
    if grouping is None:
        return None
    nt = float(ns_target)
    S = max(int(math.ceil(nt / 0.9)), 1)
    while True:
        hi = math.floor(0.9 * S) if grouping == "distribution" else min(math.floor(0.9 * S), S - n_products - 3)
        if hi >= nt:
            return S
        S += 1


class CapacityWarning(RuntimeWarning):
    """A Monte Carlo run ran out of species slots: an emergency merge of mass neighbours lowered
    its resolution (status ``RESULTS.capacity_exceeded``); rerun with a larger
    ``MonteCarlo(capacity=...)``."""


def _warn_capacity(flags, capacity):
    """Warn (CapacityWarning) when any run in ``flags`` (array of raw STATUS flags) has the CAPACITY flag."""
    import warnings

    st = np.asarray(flags)
    hit = int(np.count_nonzero(st & STATUS.CAPACITY))
    if hit:
        runs = f"{hit} of {st.size} runs" if st.size > 1 else "the run"
        warnings.warn(f"jaxcoag.evolve(MonteCarlo): {runs} ran out of species slots (capacity = {int(capacity)}); an "
                      "emergency merge of mass neighbours lowered the resolution (status capacity_exceeded). Rerun "
                      f"with a larger capacity, e.g. MonteCarlo(capacity={2 * int(capacity)}).", CapacityWarning,
                      stacklevel=4)


def _stop(st, cond, flag):
    """Mark the run done with ``flag`` where ``cond`` holds (snapshots are filled at the end)."""
    return st._replace(done=st.done | cond, status=jnp.where(cond, st.status | flag, st.status))


def _B(cfg, cheap=False):
    """Block length of the passes over the active prefix (cheap passes: ``cfg.cheap_block``, default 4x the kernel-tile
    block)."""
    return min(cfg.capacity, (cfg.cheap_block or 4 * cfg.block) if cheap else cfg.block)


def _nblocks(cfg, cheap=False):
    B = _B(cfg, cheap)
    return -(-cfg.capacity // B)


def _sl(x, start, B):
    return jax.lax.dynamic_slice_in_dim(x, start, B, axis=0)


def _fold(cfg, n, body, init, cheap=False):
    """Fold ``body(k, start, idx, fresh, carry)`` over the blocks k = 0 .. ceil(n/B) - 1 of [0, n).

    The last block's start is clamped to S - B (so that every slice has the static length B);
    ``fresh`` marks the slots of block k proper (k B <= idx < n): slots of the clamped block that an
    earlier block already covered, and slots at or beyond n, are not fresh. Work is O(n), not O(S).
    """
    B = _B(cfg, cheap)
    nb = (jnp.asarray(n, jnp.int32) + (B - 1)) // B

    def f(k, c):
        return body(k, *_block_at(cfg, k, n, cheap), c)

    return jax.lax.fori_loop(jnp.int32(0), nb, f, init)


def _block_at(cfg, k, n, cheap=False):
    """(start, idx, fresh) of block k of [0, n) (see :func:`_fold`)."""
    B, S = _B(cfg, cheap), cfg.capacity
    start = jnp.minimum(k * B, S - B)
    idx = start + jnp.arange(B, dtype=jnp.int32)
    return start, idx, (idx >= k * B) & (idx < n)


def _pick(u, weights):
    c = jnp.cumsum(weights)
    idx = jnp.searchsorted(c, u * c[-1], side="right")
    return jnp.minimum(idx, weights.shape[0] - 1)


def _pick_blocked(cfg, n, wfn, u_blk, u_in, extra=None):
    """Sample a slot in [0, n) with probability ∝ ``wfn(start, idx)`` (non-negative block weights):
    block sums, one block by ``u_blk``, the slot within it by ``u_in``. Returns (slot, total weight), and
    with ``extra`` = (fn, init) also the fold of ``fn(start, fresh, acc)`` over the same blocks (one pass)."""
    def body(k, start, idx, fresh, c):
        bs, acc = c
        acc = acc if extra is None else extra[0](start, fresh, acc)
        return bs.at[k].set(jnp.sum(jnp.where(fresh, wfn(start, idx), 0.0))), acc

    bs, acc = _fold(cfg, n, body, (jnp.zeros((_nblocks(cfg, True),), jnp.float64),
                                   None if extra is None else extra[1]), cheap=True)
    kb = _pick(u_blk, bs).astype(jnp.int32)
    start, idx, fresh = _block_at(cfg, kb, n, cheap=True)
    j = _pick(u_in, jnp.where(fresh, wfn(start, idx), 0.0))
    out = (start + j).astype(jnp.int32), jnp.sum(bs)
    return out if extra is None else out + (acc,)


def _first(cfg, n, pred):
    """Lowest slot in [0, n) where ``pred(start, idx)`` holds, else S (blocked, O(n))."""
    S = cfg.capacity

    def body(k, start, idx, fresh, c):
        return jnp.minimum(c, jnp.min(jnp.where(pred(start, idx) & fresh, idx, S)))

    return _fold(cfg, n, body, jnp.array(S, jnp.int32), cheap=True)


def _active(valid):
    """(hi, ns): one past the highest valid slot, and the number of valid slots (O(S); maintenance only)."""
    S = valid.shape[0]
    hi = jnp.max(jnp.where(valid, jnp.arange(1, S + 1, dtype=jnp.int32), 0))
    return hi.astype(jnp.int32), jnp.sum(valid).astype(jnp.int32)


def _props(arrays, T):
    m, logm, psi, w, z, valid = arrays
    return logm[T], psi[T], w[T], z[T], valid[T]


# ----------------------------------------------------------------------------- linear-space rate tiles

#: Bounds of the linear-space rate tiles (natural log): every partial product r_a w_b 2^k / φ within
#: e^{±_LIN_PART}, an entry below e^{_LIN_TOP}: no overflow, and no entry reaches the e^600 above the scale that
#: makes the incremental update ask for a refresh (``_inc_update``'s "over"), so the linear pass needs no max.
_LIN_PART, _LIN_TOP = 690.0, 600.0


class _Range(NamedTuple):
    """Range (or bounds of it) of the valid slots of [0, hi): max w, min w, max z, max m, min m."""
    w_max: jax.Array
    w_min: jax.Array
    z_max: jax.Array
    m_max: jax.Array
    m_min: jax.Array


def _lin_kernel(cfg, p):
    """The kernel if the rate tiles may be evaluated in linear space (static: ``cheap_linear``), else None."""
    k = p["kernel"]
    return k if (cfg.linear_rates and getattr(type(k), "cheap_linear", False)) else None


def _range_acc(v, w, z, m, c):
    """Fold the slots (valid v, w, z, m) into the accumulator (max w, min w, max z, max m, min m)."""
    inf = jnp.inf
    return (jnp.maximum(c[0], jnp.max(jnp.where(v, w, -inf))), jnp.minimum(c[1], jnp.min(jnp.where(v, w, inf))),
            jnp.maximum(c[2], jnp.max(jnp.where(v, z, 0))).astype(jnp.int32),
            jnp.maximum(c[3], jnp.max(jnp.where(v, m, -inf))), jnp.minimum(c[4], jnp.min(jnp.where(v, m, inf))))


def _range_block(cfg, st):
    """(fn, init) for :func:`_pick_blocked`'s ``extra``: the range of the valid slots, block by block."""
    Bc = _B(cfg, True)

    def fn(start, fresh, c):
        return _range_acc(_sl(st.valid, start, Bc) & fresh, _sl(st.w, start, Bc), _sl(st.z, start, Bc),
                          _sl(st.m, start, Bc), c)

    inf = jnp.array(jnp.inf)
    return fn, (-inf, inf, jnp.int32(0), -inf, inf)   # the range of no slot


def _range(cfg, st):
    """:class:`_Range` of the state's valid slots in [0, hi) (one cheap blocked pass, no transcendental
    function per slot)."""
    fn, init = _range_block(cfg, st)
    return _Range(*_fold(cfg, st.hi, lambda k, start, idx, fresh, c: fn(start, fresh, c), init, cheap=True))


def _range_with(rng, v, w, z, m):
    """Bounds of a state's range after an event that wrote the slots with values (v, w, z, m) (arrays), from
    the range ``rng`` before it: the maxima and minima over the old range and the written slots (a slot that
    died leaves the bounds as they were, still bounds)."""
    return _Range(*_range_acc(v, w, z, m, tuple(rng)))


def _lin_rows(kern, rng, lw, w, z, logm, valid, s_row):
    """Per-row factors (r, d) of :func:`jaxcoag.mc.rates.rate_tile` for rows with ln w ``lw``, w, z, ln m and
    the scale ``s_row`` (scalar or per row), and whether the linear tile is safe for all of them against
    every valid column of the range ``rng`` (:class:`_Range`).

    The bounds: φ >= min(1, w_a, w_min) and 2^{min(z_a, z_b) + N_eps} <= 2^{max(z_a, z_max)}, so every
    partial product r_a w_b 2^k / φ lies in [r_a w_min, r_a w_max 2^{max z} / φ_min]; K(m_a, m_b) <=
    K(m_a, m_max) (``cheap_linear`` kernels are non-decreasing in each mass). With the partial products
    normal, an entry is exact to a few ulp; entries below the smallest normal number are < 1e-308 of the
    largest row sum (the log path underflows there too). Zoom numbers above 1000 take the log path (the tile's
    powers of 2 are exact only up to 2^1023)."""
    dt = jnp.float64
    lr = lw - LN2 - s_row
    ld = log_diag_factor(w, z, lw) - s_row
    zz = jnp.maximum(z, rng.z_max).astype(dt)
    lw_max, lw_min = jnp.log(rng.w_max), jnp.log(rng.w_min)
    lphi = jnp.minimum(0.0, jnp.minimum(lw, lw_min))
    g_hi = lr + lw_max + zz * LN2 - lphi
    g_lo = lr + lw_min
    lk = jnp.log(kern(jnp.exp(logm), rng.m_max))
    ok = ((g_hi < _LIN_PART) & (g_lo > -_LIN_PART) & (g_hi + lk < _LIN_TOP)
          & ((ld == -jnp.inf) | ((ld > -_LIN_PART) & (ld + lk < _LIN_TOP))) & (rng.m_min > 0)
          & (zz <= 1000.0))   # (rates.rate_tile's exact powers of 2)
    return jnp.exp(lr), jnp.exp(ld), jnp.all(ok | ~valid)


def _pick_partner(cfg, p, st, a, u_blk, u_in, rng=None):
    """Partner b of the selected row a, ∝ Λ'_{a,b} over the active prefix (blocked; the row is
    never formed over the capacity): block sums, one block, the slot within it.

    The weights are exp(ln Λ'_ab − s_a) with s_a = ln(R_a e^s), the row's own total (R holds the row
    sums scaled by e^-s), so they sum to ~1: one exponential per entry and no max pass (a block
    log-sum-exp cost a max and a sum pass per block). R_a is the row's sum up to the round-off of the
    incremental updates, far from the e^709 that would overflow a weight.
    """
    B = _B(cfg)
    a1 = jnp.reshape(a, (1,)).astype(jnp.int32)
    la, pa, wa, za, va = _props(_arrays(st), a1)
    Ra = st.R[a]
    s_a = jnp.log(jnp.where((Ra > 0) & jnp.isfinite(Ra), Ra, 1.0)) + st.s

    def wts(start, idx, fresh):   # (no select on the row: see rates.log_rate_tile)
        lm, ps = _sl(st.logm, start, B), _sl(st.psi, start, B)
        logK = log_kernel_tile(p["kernel"], la, pa, lm, ps)
        L = log_rate_tile(logK, a1, la, wa, za, va, idx, lm, _sl(st.w, start, B), _sl(st.z, start, B),
                          _sl(st.valid, start, B) & fresh, p["log2_feps"], cfg.rounding)[0]
        return jnp.exp(L - s_a)

    def pick(wts):
        def body(k, start, idx, fresh, c):
            return c.at[k].set(jnp.sum(wts(start, idx, fresh)))

        bs = _fold(cfg, st.hi, body, jnp.zeros((_nblocks(cfg),), jnp.float64))
        kb = _pick(u_blk, bs).astype(jnp.int32)
        start, idx, fresh = _block_at(cfg, kb, st.hi)
        j = _pick(u_in, wts(start, idx, fresh))
        return (start + j).astype(jnp.int32)

    kern = _lin_kernel(cfg, p)
    if kern is None:
        return pick(wts)
    # linear space where the state's range allows (the same weights to round-off, no exp/log per entry)
    rng = _range(cfg, st) if rng is None else rng
    r_a, d_a, ok = _lin_rows(kern, rng, _safe_log_w(wa), wa, za, la, va, s_a)
    ma = jnp.exp(la)

    def wts_lin(start, idx, fresh):
        lm, m = _sl(st.logm, start, B), _sl(st.m, start, B)
        return rate_tile(kern(ma[:, None], m[None, :]), a1, r_a, d_a, la, wa, za, va, idx, lm, _sl(st.w, start, B),
                         _sl(st.z, start, B), _sl(st.valid, start, B) & fresh, p["log2_feps"], cfg.rounding)[0]

    return jax.lax.cond(ok, lambda: pick(wts_lin), lambda: pick(wts))


class _Old(NamedTuple):
    """Pre-event values (logm, psi, w, z, valid) of the touched slots T, shape (nT,) / (nT, P)."""
    logm: jax.Array
    psi: jax.Array
    w: jax.Array
    z: jax.Array
    valid: jax.Array


def _patch(x_b, idx, slots, values):
    """Block values x_b (B,) or (B, P) of the slots idx with the entries of ``slots`` replaced by ``values``
    (in order, so a later repeat of a slot wins); slots/values: arrays with a leading axis or sequences."""
    for k, v in zip(slots, values):
        hit = idx == k
        x_b = jnp.where(hit[:, None] if x_b.ndim == 2 else hit, v, x_b)
    return x_b


def _inc_update(cfg, p, old, st, T, Tmask, do=True, rng=None):
    """Incremental row-sum update for the touched slots T (rate design B, docs/design_notes.md).

    One blocked pass over the active prefix [0, hi). For every touched slot t and every slot b it
    evaluates one kernel value, one rate formula and one exponential: X_tb = exp(ln Λ'_tb − s) with
    the *effective* row values of t (the new ones where t lives after the event, else the old ones).
    A slot keeps its mass while it lives (donors and deduplicated products keep theirs, new products
    take a slot that was free before the event), and Λ'_tb is proportional to w_t wherever the zoom
    z_t is unchanged and no event fraction phi < 1 involves t (w_t >= 1 before and after,
    rates.log_rate_tile), so off the diagonal

        new rate = X_tb            (t lives after the event; else 0)
        old rate = X_tb w_t^old / w_t^new   (t lived before and after: "exact" rows)
        old rate = X_tb            (t died in the event),  0 (t was free before).

    The rows that lived before and after with a changed zoom or a fractional multiplicity (fragment counts,
    demagnified donors, species merged into fractional multiplicities: ~10% of the updates of a long constant-Ns
    run) get their old rates from the full formula in a second pass that runs only when such a row exists.
    Entries with b in T are overwritten by the new row sums (R[T] = Σ_b new rate), so the b side is the new
    state throughout. (Before, the old rates were a
    second rate formula and exponential per entry on a patched pre-event block: XLA fused that formula
    into R's update as scalar code, ~40% of the update's time at 1666 live species.)

    ``old`` (:class:`_Old`) holds the pre-event values of the slots T only. Where ``do`` is False, R is
    left as it was (the caller discards the scalar results).

    Returns the updated state; also refreshes ``ns`` (valid slots) and, for the maintenance
    triggers, ``extras`` = (ln max m over valid slots, ln M1, ln M2) of the new state (−inf where
    the run's maintenance rules do not use them: ln max m for distribution grouping only, ln M1/M2
    for constant-Ns and non-constant-volume equal-mass runs). On the linear-space path M1 and M2 are linear
    sums of w 2^z m and w 2^z m^2 (no exponential per slot: the log-sum-exps had cost ~40 us of a ~180 us event
    at 3 600 species), taken where the range bounds every term; else the update runs in log space. R's
    round-off check (a row sum below -1e-9 of the sum of |R| asks for a refresh) runs in the next event's row
    pass (:func:`_event`): here it was a pass of its own.
    """
    if cfg.rates == "full":  # the next event refreshes everything: only the trigger figures here
        _, ns = _active(st.valid)
        lg = jnp.where(st.valid, G.log_g(st.w, st.z), -jnp.inf)
        ext = (jnp.max(jnp.where(st.valid, st.logm, -jnp.inf)), jax.nn.logsumexp(lg + st.logm),
               jax.nn.logsumexp(lg + 2.0 * st.logm))
        return st._replace(dirty=jnp.array(True), ns=ns), ext
    B = _B(cfg)
    m_n, logm_n, psi_n, w_n, z_n, valid_n = _arrays(st)
    T = T.astype(jnp.int32)
    vo_t, vn_t = old.valid, valid_n[T]
    lm_t = jnp.where(vn_t, logm_n[T], old.logm)
    ps_t = jnp.where(vn_t[:, None], psi_n[T], old.psi)
    wo_t, wn_t, zo_t, zn_t = old.w, w_n[T], old.z, z_n[T]
    lwo_t, lwn_t = _safe_log_w(wo_t), _safe_log_w(wn_t)
    # effective row values: new where t lives after the event, else old
    w_e, z_e, v_e, lw_e = (jnp.where(vn_t, wn_t, wo_t), jnp.where(vn_t, zn_t, zo_t), vn_t | vo_t,
                           jnp.where(vn_t, lwn_t, lwo_t))
    both = vo_t & vn_t
    exact = (zo_t == zn_t) & (wo_t >= 1.0) & (wn_t >= 1.0)
    # per-row factors of X: f_new (row sums, all rows), f (R's delta: new minus old rate, rows in Tmask)
    f_new = jnp.where(vn_t, 1.0, 0.0)
    f_old = jnp.where(both, jnp.where(exact, wo_t / jnp.where(both, wn_t, 1.0), 0.0), jnp.where(vo_t, 1.0, 0.0))
    f = (jnp.where(Tmask, f_new - f_old, 0.0))[:, None]
    f_new = f_new[:, None]
    kern, l2f = p["kernel"], p["log2_feps"]
    s = st.s
    ninf = jnp.array(-jnp.inf)
    # trigger figures only where the maintenance rules read them (static): not needed in constant-volume runs
    need_mp = cfg.mode == "const_ns" or (cfg.grouping == "equal_mass" and cfg.mode != "const_v")
    need_lmx = cfg.grouping == "distribution"

    def block(start):   # the new state of one block, ln w and the kernel tile against the touched rows
        vn_b, lmn_b, psn_b = _sl(valid_n, start, B), _sl(logm_n, start, B), _sl(psi_n, start, B)
        wn_b, zn_b = _sl(w_n, start, B), _sl(z_n, start, B)
        return vn_b, lmn_b, wn_b, zn_b, _safe_log_w(wn_b), log_kernel_tile(kern, lm_t, ps_t, lmn_b, psn_b)

    def body(k, start, idx, fresh, c):
        R, rowsum, lmax, ns, lmx, l1, l2 = c
        vn_b, lmn_b, wn_b, zn_b, lwn_b, logK = block(start)
        L = log_rate_tile(logK, T, lm_t, w_e, z_e, v_e, idx, lmn_b, wn_b, zn_b, vn_b & fresh, l2f, cfg.rounding,
                          lw_a=lw_e, lw_b=lwn_b)
        # products with per-row factors, no select on a value computed from ln K (it keeps XLA-CPU from
        # vectorising, see rates.log_rate_tile); X = inf (ln Λ' - s > 709) makes R NaN, and sets "over" below
        X = jnp.exp(L - s)
        # R is read here only by its own update (same slots): any other reader of R in this loop (the
        # checks below used to be here) made XLA copy R, all S slots, twice per block
        delta = jnp.where(fresh & do, jnp.sum(X * f, axis=0), 0.0)
        R = jax.lax.dynamic_update_slice_in_dim(R, _sl(R, start, B) + delta, start, axis=0)
        rowsum = rowsum + jnp.sum(X * f_new, axis=1)
        lmax = jnp.maximum(lmax, jnp.max(L))
        return (R, rowsum, lmax) + stats(vn_b & fresh, lmn_b, wn_b, zn_b, ns, lmx, l1, l2, lwn_b)

    def stats(live, lmn_b, wn_b, zn_b, ns, lmx, l1, l2, lwn_b=None):   # the trigger figures of one block
        ns = ns + jnp.sum(live).astype(jnp.int32)
        if need_lmx:
            lmx = jnp.maximum(lmx, jnp.max(jnp.where(live, lmn_b, -jnp.inf)))
        if need_mp:
            lwn_b = _safe_log_w(wn_b) if lwn_b is None else lwn_b
            lg = lwn_b + zn_b.astype(lwn_b.dtype) * LN2
            l1 = jnp.logaddexp(l1, jax.nn.logsumexp(jnp.where(live, lg + lmn_b, -jnp.inf)))
            l2 = jnp.logaddexp(l2, jax.nn.logsumexp(jnp.where(live, lg + 2.0 * lmn_b, -jnp.inf)))
        return ns, lmx, l1, l2

    # rows that lived before and after but are not "exact": their old rates from the full formula (pre-event
    # row values; the b side is the new state, as above), subtracted in a pass that runs only if such a row exists
    gen = Tmask & both & ~exact
    s_g = jnp.where(gen, s, jnp.inf)[:, None]

    def body_old(k, start, idx, fresh, R):
        vn_b, lmn_b, wn_b, zn_b, lwn_b, logK = block(start)
        Lo = log_rate_tile(logK, T, lm_t, wo_t, zo_t, vo_t, idx, lmn_b, wn_b, zn_b, vn_b & fresh, l2f, cfg.rounding,
                           lw_a=lwo_t, lw_b=lwn_b)
        delta = jnp.where(fresh, jnp.sum(jnp.exp(Lo - s_g), axis=0), 0.0)
        return jax.lax.dynamic_update_slice_in_dim(R, _sl(R, start, B) - delta, start, axis=0)

    def passes(body_old, body, R, on=True, init=None):
        # (the old-rate pass before the main pass: the later writes of the species arrays, in the duplication,
        # then depend on every pass that reads them; this pass after the main one made XLA copy w, S slots,
        # twice per event). ``on`` False: zero trips (R and init pass through)
        R = _fold(cfg, jnp.where(on & do & jnp.any(gen), st.hi, 0), body_old, R)
        if init is None:
            init = (jnp.zeros(T.shape, jnp.float64), ninf, jnp.array(0, jnp.int32), ninf, ninf, ninf)
        return _fold(cfg, jnp.where(on, st.hi, 0), body, (R,) + tuple(init))

    kern_lin = _lin_kernel(cfg, p)
    if kern_lin is None:
        out = passes(body_old, body, st.R)
    else:
        # linear space where the state's range allows: X from rates.rate_tile (no exp/log per entry). The range
        # of the new state: bounds from the pre-event range (the event's row pass) and the written slots
        rng = (_range(cfg, st) if rng is None else
               _range_with(rng, vn_t, wn_t, zn_t, jnp.where(vn_t, m_n[T], 1.0)))
        r_e, d_e, ok_e = _lin_rows(kern_lin, rng, lw_e, w_e, z_e, lm_t, v_e, s)
        r_o, d_o, ok_o = _lin_rows(kern_lin, rng, lwo_t, wo_t, zo_t, lm_t, vo_t & gen, s)
        r_o, d_o = jnp.where(gen, r_o, 0.0), jnp.where(gen, d_o, 0.0)
        m_t = jnp.exp(lm_t)[:, None]

        def tile_lin(start, idx, fresh, r, d, w, z, v):
            vn_b, lmn_b, mn_b = _sl(valid_n, start, B), _sl(logm_n, start, B), _sl(m_n, start, B)
            wn_b, zn_b = _sl(w_n, start, B), _sl(z_n, start, B)
            return rate_tile(kern_lin(m_t, mn_b[None, :]), T, r, d, lm_t, w, z, v, idx, lmn_b, wn_b, zn_b,
                             vn_b & fresh, l2f, cfg.rounding)

        def body_old_lin(k, start, idx, fresh, R):
            X = tile_lin(start, idx, fresh, r_o, d_o, wo_t, zo_t, vo_t)
            delta = jnp.where(fresh, jnp.sum(X, axis=0), 0.0)
            return jax.lax.dynamic_update_slice_in_dim(R, _sl(R, start, B) - delta, start, axis=0)

        def body_lin(k, start, idx, fresh, c):   # (lmax: passed through, see below)
            R, rowsum, lmax, ns, lmx, M1, M2 = c
            X = tile_lin(start, idx, fresh, r_e, d_e, w_e, z_e, v_e)
            delta = jnp.where(fresh & do, jnp.sum(X * f, axis=0), 0.0)
            R = jax.lax.dynamic_update_slice_in_dim(R, _sl(R, start, B) + delta, start, axis=0)
            rowsum = rowsum + jnp.sum(X * f_new, axis=1)
            # the trigger figures, M1 and M2 as linear sums (no exponential per slot; guard below)
            live = _sl(valid_n, start, B) & fresh
            ns = ns + jnp.sum(live).astype(jnp.int32)
            if need_lmx:
                lmx = jnp.maximum(lmx, jnp.max(jnp.where(live, _sl(logm_n, start, B), -jnp.inf)))
            if need_mp:
                mn_b = _sl(m_n, start, B)
                gm = jnp.where(live, _sl(w_n, start, B) * pow2(_sl(z_n, start, B)) * mn_b, 0.0)
                M1, M2 = M1 + jnp.sum(gm), M2 + jnp.sum(gm * mn_b)
            return R, rowsum, lmax, ns, lmx, M1, M2

        # the linear passes, then the log-space passes: one of them runs zero trips. (Not a lax.cond: XLA copied R,
        # S slots, into and out of the cond's branches on every event.) The linear path's lmax stays -inf: the
        # guard keeps every linear entry below e^{s + _LIN_TOP}, under the "over" threshold. Its M1 = sum g m and
        # M2 = sum g m^2 (g = w 2^z) are linear sums: every term below e^(_LIN_PART - ln S) by the range, z within
        # pow2's exact range; else the log-space passes run
        lgm_max = jnp.log(rng.w_max) + rng.z_max.astype(jnp.float64) * LN2 + 2.0 * jnp.log(jnp.maximum(rng.m_max, 1.0))
        ok_mp = ((lgm_max < _LIN_PART - math.log(cfg.capacity)) & (rng.z_max <= 1000) & (rng.m_min > 0)
                 if need_mp else True)
        ok = ok_e & ok_o & ok_mp
        zero = jnp.array(0.0)
        R, rowsum, lmax, ns, lmx, M1, M2 = passes(body_old_lin, body_lin, st.R, ok,
                                                  (jnp.zeros(T.shape, jnp.float64), ninf, jnp.array(0, jnp.int32),
                                                   ninf, zero, zero))
        out = passes(body_old, body, R, ~ok, (rowsum, lmax, jnp.array(0, jnp.int32), ninf, ninf, ninf))
        if need_mp:   # ln M1, ln M2 of the linear path (M > 0: there is a live slot; else -inf, as the log sums)
            l1_lin = jnp.where(M1 > 0, jnp.log(jnp.where(M1 > 0, M1, 1.0)), -jnp.inf)
            l2_lin = jnp.where(M2 > 0, jnp.log(jnp.where(M2 > 0, M2, 1.0)), -jnp.inf)
            out = out[:3] + tuple(jnp.where(ok, a_, b_) for a_, b_ in zip((ns, lmx, l1_lin, l2_lin), out[3:]))
        else:
            out = out[:3] + tuple(jnp.where(ok, a_, b_) for a_, b_ in zip((ns, lmx), out[3:5])) + out[5:]
    R, rowsum, lmax, ns, lmx, l1, l2 = out
    R = R.at[jnp.where(do, T, cfg.capacity)].set(rowsum, mode="drop")

    # (the round-off check of R, its negative entries, runs in the next event's row pass: _event)
    over = lmax - s > 600.0
    return st._replace(R=R, dirty=st.dirty | over, ns=ns), (lmx, l1, l2)


# ----------------------------------------------------------------------------- event

class _Folded(NamedTuple):
    products: object      # jaxcoag.outcomes.Products, counts times phi
    folded: jax.Array     # (2,) bool: donor i, donor j emptied into the heaviest product


def _fold_leftovers(p, prods, phi, zp, m, logm, w, z, i, j, same):
    """Partial events: fold a donor's leftover into the heaviest product (MC hazard 15b) [own].

    Returns the products with their counts already scaled by phi, and which donor (i, j) was
    folded (emptied). A partial event (phi < 1, module ``rates``) leaves slivers: a runaway of
    w = 1 meeting a partner that holds w = 1.6e-8 (round-off of merged weights) became a product
    of w = 1.6e-8 at the runaway's mass beside the runaway's w = 1 - 1.6e-8. Such a sliver has the
    rate of a whole particle (rate / phi) but carries almost nothing: it grows as a second runaway,
    past the total mass, and its rate shrinks the time step (the product-kernel gel of thesis
    Fig. 5.6 took > 2e5 events instead of 5.5e4). A donor's leftover is therefore merged into the
    heaviest product (counts add, particle mass the mass-weighted mean: mass and number exact) when
    (a) it is a z = 0 sliver (0 < w < 1) with at most f_eps of the product's mass, or
    (b) the event was partial and the product's particle mass is within a factor 1 + f_eps of the
        donor's (a sticking event of the heavier member: its group grows by phi n_c m_j instead of
        splitting into a product of count phi and a leftover of 1 - phi).
    Either way a particle mass moves by at most the fraction f_eps that the method allows per
    event. Real fragment fractions (products far lighter than the donors) are left as they are.
    """
    dt = logm.dtype
    lfeps = p["log2_feps"] * LN2
    cnt = prods.count * phi
    ok = prods.valid & (cnt > 0)
    lc = jnp.where(ok, jnp.log(jnp.where(ok, cnt, 1.0)), -jnp.inf) + zp.astype(dt) * LN2   # ln(count 2^zp)
    log_tot = lc + prods.logm
    q = jnp.argmax(log_tot)
    lt_q, lc_q, lm_p = log_tot[q], lc[q], prods.logm[q]
    lc_0 = lc_q
    folded, parts = [], []
    for s_, use in ((i, jnp.array(True)), (j, ~same)):
        left = w[s_]
        pos = left > 0
        lcs = jnp.log(jnp.where(pos, left, 1.0)) + z[s_].astype(dt) * LN2                   # ln(w 2^z)
        lL = lcs + logm[s_]
        sliver = (z[s_] == 0) & (left < 1.0) & (lL <= lt_q + lfeps)
        near = (phi < 1.0) & (jnp.abs(lm_p - logm[s_]) <= jnp.log1p(jnp.exp(lfeps)))
        f = use & ok[q] & pos & (sliver | near)
        lt_q = jnp.where(f, jnp.logaddexp(lt_q, lL), lt_q)
        lc_q = jnp.where(f, jnp.logaddexp(lc_q, lcs), lc_q)
        folded.append(f)
        parts.append((f, lcs, s_))
    any_f = folded[0] | folded[1]
    # new particle mass: the count-weighted mean, in linear space where the masses are finite (weights
    # <= 1 summing to 1: round-off ~1e-16, where ln-space sums lose ~ln(m) 1e-16), else in ln space
    mp_lin = jnp.exp(lc_0 - lc_q) * prods.m[q]
    for f, lcs, s_ in parts:
        mp_lin = mp_lin + jnp.where(f, jnp.exp(lcs - lc_q) * m[s_], 0.0)
    lin = jnp.isfinite(mp_lin) & (mp_lin > 0)
    lm_q = jnp.where(lin, jnp.log(jnp.where(lin, mp_lin, 1.0)), lt_q - lc_q)
    lm_q = jnp.where(any_f, lm_q, prods.logm[q])
    cnt = cnt.at[q].set(jnp.where(any_f, jnp.exp(lc_q - zp.astype(dt) * LN2), cnt[q]))
    lmq = prods.logm.at[q].set(lm_q)
    mq = prods.m.at[q].set(jnp.where(any_f, jnp.where(lin, mp_lin, jnp.exp(lm_q)), prods.m[q]))
    return _Folded(prods._replace(m=mq, logm=lmq, count=cnt), jnp.stack(folded))


def _opaque_reads(f, arrays, *args):
    """``(arrays, f(arrays, *args))``, with ``f`` run inside a one-trip ``lax.while_loop`` that passes the
    (large) arrays through unchanged; the trip count is a runtime value, so XLA keeps the loop.

    Why: XLA updates an array in place only if every computation that reads the old array comes before the
    update in data-dependence order. An event reads slots of one species array to compute the new values of
    another (``valid[slot]`` decides the new ``w``; the pre-event values feed the rate update), and XLA fuses
    such a read into each of its consumers, so some reader was always unordered with some update: XLA then
    copied the arrays, S slots each, on every event (7 copies). Neither an optimization barrier nor writing the
    read values back through the same scatter ordered them on CPU. A loop is not fused: here every read of the
    arrays happens inside it, and the scatters update the loop's outputs, of which the loop is the only other
    reader. Returns the arrays as the loop passed them (use these, not the inputs). Measured effect
    (benchmarks/results/mc_scaling.json, Ns* = 100): 54 / 94 / 308 us per event at 150 / 12 800 / 51 200 slots
    before, 52 / 80 / 74 us after (then below ``COND_FREE_CAPACITY`` = 16 384 the event's cond still copied four
    arrays; the event has been cond-free at every capacity since stop 45)."""
    out0 = jax.tree_util.tree_map(lambda sd: jnp.zeros(sd.shape, sd.dtype),
                                  jax.eval_shape(lambda a, x: f(a, *x), arrays, args))
    # args[0] >= 0 (a slot count): XLA cannot prove it, so it can neither unroll the loop (one trip) nor hoist
    # the reads out of it (the scalar arguments are shifted by the trip counter where args[0] < 0, i.e. never)
    neg = args[0] < 0
    n_trips = jnp.int32(1) + neg.astype(jnp.int32)

    def body(c):
        k, arr, _ = c
        x = tuple(v + jnp.where(neg, k, 0).astype(v.dtype) if (jnp.ndim(v) == 0 and jnp.issubdtype(v.dtype, jnp.number))
                  else v for v in args)
        return k + 1, arr, f(arr, *x)

    _, arrays, out = jax.lax.while_loop(lambda c: c[0] < n_trips, body, (jnp.int32(0), arrays, out0))
    return arrays, out


def _stack_writes(idx, val, S):
    """The single-slot writes (idx[k], val[k]), in order, as one (I, V) pair for a scatter: an entry that a later
    write to the same slot overrides gets a distinct out-of-range index (dropped by the scatter)."""
    I, V = jnp.stack(idx), jnp.stack(val)
    ar = jnp.arange(I.shape[0], dtype=jnp.int32)
    later = jnp.any((I[None, :] == I[:, None]) & (ar[None, :] > ar[:, None]), axis=1)   # overwritten later
    return jnp.where(later, S + ar, I), V


def _scatter_writes(base, IV, do=True):
    """``base`` with the writes ``IV`` = (I, V) of :func:`_stack_writes` applied as one scatter; none where
    ``do`` is False."""
    if IV is None:
        return base
    I, V = IV
    S = base.shape[0]
    I = jnp.where(do, I, S + jnp.arange(I.shape[0], dtype=jnp.int32))   # distinct out-of-range indices: dropped
    return base.at[I].set(V, mode="drop", unique_indices=True)


class _Overlay:
    """Pending single-slot writes to one species array (trace-time helper of :func:`_collide_reads`): reads
    (``x[k]``, :meth:`block`) see the writes made so far; :func:`_collide` performs them as one scatter
    (:func:`_scatter_writes`).

    Why: a chain of ``x = x.at[k].set(v)`` with reads of x between the writes made XLA copy the whole array
    (S slots) at every write that followed such a read, ~16 copies per event, so the cost per event grew with
    the capacity (docs/design_notes.md). One scatter after all reads has no such conflict."""

    def __init__(self, base):
        self.base, self.idx, self.val = base, [], []
        self.dtype = base.dtype

    def __getitem__(self, k):
        v = self.base[k]
        for i_, v_ in zip(self.idx, self.val):
            v = jnp.where(k == i_, v_, v)
        return v

    def set(self, k, v):
        self.idx.append(jnp.asarray(k, jnp.int32))
        self.val.append(jnp.broadcast_to(jnp.asarray(v, self.base.dtype), self.base.shape[1:]))

    def block(self, start, B):
        """``_sl(x, start, B)`` of the written array."""
        return _patch(_sl(self.base, start, B), start + jnp.arange(B, dtype=jnp.int32), self.idx, self.val)


def _collide(cfg, p, st, a, b, key, do=True):
    """Execute one (group) event on the species pair {a, b}; returns (state, T, Tmask, old), with ``old``
    (:class:`_Old`) the pre-event values of the touched slots T. All reads run in :func:`_opaque_reads`,
    then one scatter per species array applies the writes (none where ``do`` is False: the caller then
    discards the scalar results)."""
    names = ("m", "logm", "psi", "w", "z", "valid")
    arrays, (writes, T, Tm, old, M_tot, hi) = _opaque_reads(
        lambda arrs, hi_, a_, b_, key_: _collide_reads(cfg, p, st, arrs, a_, b_, key_), _arrays(st), st.hi, a, b, key)
    st = st._replace(**{k: _scatter_writes(x, iv, do) for k, x, iv in zip(names, arrays, writes)},
                     M_tot=M_tot, hi=hi)
    if cfg.leftover == "stochastic" and cfg.mode != "const_v":
        st = st._replace(logV=jnp.log(M_tot) - st.log_rho_d)
    return st, T, Tm, old


def _collide_reads(cfg, p, st, arrays, a, b, key):
    """The read part of :func:`_collide`: from the species ``arrays`` (as passed by :func:`_opaque_reads`; the
    scalar fields of st are read from st) compute the pending writes of every array, T, Tmask, the pre-event
    values at T, M_tot and hi."""
    m, logm, psi, w, z, valid = (_Overlay(x) for x in arrays)
    same = a == b
    za, zb = z[a], z[b]
    a_is_i = (za < zb) | ((za == zb) & ((logm[a] > logm[b]) | ((logm[a] == logm[b]) & (a <= b))))
    i = jnp.where(a_is_i, a, b)
    j = jnp.where(a_is_i, b, a)
    dz = z[j] - z[i]
    ne = n_eps(z[i], z[j], logm[i], logm[j], p["log2_feps"], cfg.rounding)
    ne = jnp.where(same, 0, ne)
    kc = jnp.where(same, 0, dz - ne)
    n_c = jnp.ldexp(1.0, kc)
    log_nc = kc.astype(logm.dtype) * LN2
    zp = jnp.where(same, jnp.maximum(z[a] - 1, 0), z[i])
    prods = p["outcome"].products(m[i], logm[i], psi[i], m[j], logm[j], psi[j], n_c, log_nc, key)

    # donors. Fragment counts are real numbers, so a z = 0 species can hold less than the event
    # removes (0 < w < 1, or 1 < w < 2 for a z = 0 own pair). The event then runs for the fraction
    # phi = min(1, w_i/dw_i, w_j/dw_j) that the donors hold: they lose phi dw, the products get phi
    # times their count (sum phi count m = phi (m_i + n_c m_j) 2^{z_i}: mass exact), and the pair
    # rate is lambda^G / phi (rates.log_rate_row) so that the expected flux is unchanged. Before,
    # w = max(w - dw, 0) clamped such a donor to 0 while the products were those of a whole group:
    # every event of a fractional donor created mass (measured relative drift: 2.4e-2 after 1206 events
    # in tests/test_contact_bridge.py's MC box, 2.6e-6 with EqualMass grouping in
    # tests/test_mc_units.py's VfragShatter run). phi = 1 for whole groups (integer multiplicities).
    dw_i = jnp.where(same, jnp.where(z[a] == 0, 2.0, 1.0), 1.0)
    dw_j = jnp.where(same, 0.0, jnp.ldexp(1.0, -ne))
    phi_i = jnp.where(w[i] >= dw_i, 1.0, w[i] / dw_i)
    phi_j = jnp.where(same | (w[j] >= dw_j), 1.0, w[j] / jnp.where(same, 1.0, dw_j))
    phi = jnp.minimum(phi_i, phi_j)
    # dw is a power of 2, so the donor that sets phi < 1 keeps exactly w - (w/dw) dw = 0 (removed by
    # demagnify below); for same = True, j = i and dw_j = 0 leave the updated w[i] as it is
    w.set(i, jnp.maximum(w[i] - phi * dw_i, 0.0))
    w.set(j, jnp.maximum(w[j] - phi * dw_j, 0.0))
    fold = _fold_leftovers(p, prods, phi, zp, m, logm, w, z, i, j, same)
    w.set(i, jnp.where(fold.folded[0], 0.0, w[i]))
    w.set(j, jnp.where(fold.folded[1], 0.0, w[j]))
    prods = fold.products   # counts already times phi, folded leftovers added
    M_tot = st.M_tot
    for idx, s_ in enumerate((i, j)):
        if cfg.leftover == "stochastic":
            # hazard 3 [own]: a fractional leftover group survives as one whole group with
            # probability w (unbiased in expectation), instead of the demagnify cascade
            wv = w[s_]
            frac = (wv > 0) & (wv < 1) & (z[s_] > 0)
            u = jax.random.uniform(jax.random.fold_in(key, 1000 + idx), dtype=wv.dtype)
            w_new = jnp.where(frac, jnp.where(u < wv, 1.0, 0.0), wv)
            M_tot = M_tot + jnp.where(frac, jnp.ldexp(w_new - wv, z[s_]) * m[s_], 0.0)
            w.set(s_, w_new)
        wn, zn, alive = G.demagnify(w[s_], z[s_])
        w.set(s_, wn)
        z.set(s_, zn)
        valid.set(s_, valid[s_] & alive)
        m.set(s_, jnp.where(alive, m[s_], 1.0))
        logm.set(s_, jnp.where(alive, logm[s_], 0.0))

    # products
    slots = []
    masks = []
    news = []
    Bc = _B(cfg, True)
    hi = st.hi
    for q in range(cfg.n_prod):
        mp = prods.m[q]
        lmp = jnp.where(jnp.isfinite(mp) & (mp > 0), jnp.log(jnp.where(mp > 0, mp, 1.0)), prods.logm[q])
        psip = prods.psi[q]
        cnt = prods.count[q]   # times phi (the fraction of the event the donors held), folds added
        do = prods.valid[q] & (cnt > 0)
        if cfg.dedupe:
            def match(start, idx, lmp=lmp, psip=psip):   # run at once: sees the writes made so far
                ps = psi.block(start, Bc)
                return (valid.block(start, Bc) & (logm.block(start, Bc) == lmp)
                        & jnp.all(ps == jnp.broadcast_to(psip, ps.shape), axis=1))
            kmatch = _first(cfg, hi, match)
            has = kmatch < cfg.capacity
        else:
            kmatch = jnp.array(0, jnp.int32)
            has = jnp.array(False)

        # a new product takes a slot that was free before the event (see _inc_update): not valid now, not
        # a donor emptied by this event (the only slots that can die) and not an earlier product's
        def free(start, idx, news=tuple(news)):
            ok = ~valid.block(start, Bc) & (idx != i) & (idx != j)
            for sl_ in news:
                ok = ok & (idx != sl_)
            return ok
        kfree = _first(cfg, jnp.minimum(hi + 1, cfg.capacity), free)  # without a hole below hi, slot hi
        slot = jnp.where(has, kmatch, jnp.minimum(kfree, cfg.capacity - 1))
        zh = _zhat(cfg, lmp, st.log_mstar, st.zoom_xp, st.zoom_fp)
        wn, zn = G.apply_zoom(cnt, zp, zh)
        w_add = w[slot] + jnp.ldexp(cnt, zp - z[slot])
        new_w = jnp.where(has, w_add, wn)
        new_z = jnp.where(has, z[slot], zn)
        do = do & (has | ((kfree < cfg.capacity) & ~valid[slot]))
        m.set(slot, jnp.where(do & ~has, mp, m[slot]))
        logm.set(slot, jnp.where(do & ~has, lmp, logm[slot]))
        psi.set(slot, jnp.where(do & ~has, psip, psi[slot]))
        w.set(slot, jnp.where(do, new_w, w[slot]))
        z.set(slot, jnp.where(do, new_z, z[slot]))
        valid.set(slot, valid[slot] | do)
        slots.append(slot)
        masks.append(do)
        news.append(jnp.where(do & ~has, slot, -1))
        hi = jnp.where(do & ~has, jnp.maximum(hi, slot + 1), hi).astype(jnp.int32)
    T = jnp.stack([i, j] + slots)
    Tm = jnp.stack([jnp.array(True), ~same] + masks)
    # mask duplicate entries of T (keep the first occurrence)
    nT = T.shape[0]
    dup = jnp.any((T[:, None] == T[None, :]) & (jnp.arange(nT)[None, :] < jnp.arange(nT)[:, None]) & Tm[None, :], axis=1)
    Tm = Tm & ~dup
    old = _Old(logm.base[T], psi.base[T], w.base[T], z.base[T], valid.base[T])   # pre-event values
    # stacked here, inside the loop: the loop's outputs are then a dozen arrays, not a hundred scalars (each
    # output of the loop costs a buffer copy on CPU)
    writes = tuple(_stack_writes(o.idx, o.val, o.base.shape[0]) if o.idx else None
                   for o in (m, logm, psi, w, z, valid))
    return writes, T, Tm, old, M_tot, hi


def _duplicate(cfg, p, st, key, u0, log_mp, do=True):
    """Duplication controller (const_n: one group per event; const_ns: thesis §5.3.1, ch. 6).

    ``u0``: the two uniforms (block, slot) of the first duplication."""
    if cfg.mode == "const_v":
        return st
    Bc = _B(cfg, True)

    def reads(arrs, ns, hi, ub, ui):   # run in _opaque_reads (see there)
        m, logm, psi, w, z, valid = arrs
        k, _ = _pick_blocked(cfg, hi, lambda start, idx: jnp.where(_sl(valid, start, Bc), _sl(w, start, Bc), 0.0),
                             ub, ui)
        return k, _Old(logm[k[None]], psi[k[None]], w[k[None]], z[k[None]], valid[k[None]]), jnp.ldexp(m[k], z[k])

    def dup(st, ub, ui):
        # ns (from the last rate update) first: the reads of that update come before this write of w
        arrs, (k, old, mk) = _opaque_reads(reads, _arrays(st), st.ns, st.hi, ub, ui)
        m, logm, psi, w, z, valid = arrs
        M_new = st.M_tot + mk
        w = w.at[jnp.where(do, k, cfg.capacity)].set(old.w[0] + 1.0, mode="drop")
        st2 = st._replace(m=m, logm=logm, psi=psi, w=w, z=z, valid=valid, M_tot=M_new,
                          logV=jnp.log(M_new) - st.log_rho_d, n_dup=st.n_dup + 1)
        return _inc_update(cfg, p, old, st2, k[None], jnp.ones((1,), bool), do)[0]

    if cfg.mode == "const_n":
        return dup(st, u0[0], u0[1])

    def one(c):
        st, d = c
        ud = jax.random.uniform(jax.random.fold_in(key, d), (2,), dtype=st.w.dtype)
        ud = jnp.where(d == 0, u0, ud)
        return dup(st, ud[0], ud[1]), d + 1

    if cfg.controller == "mass":
        def cond(c):
            st_, d = c
            return do & (st_.M_tot < p["ns_target"] * jnp.exp(log_mp)) & (d < cfg.d_max)
    else:
        nd = jnp.where(do & (st.ns < p["ns_target"]), cfg.d_up, 0)

        def cond(c):
            return c[1] < nd
    st, _ = jax.lax.while_loop(cond, one, (st, 0))
    return st


def _event(cfg, p, st):
    """One iteration of the inner loop: sample, record, collide, update (all passes over the active
    prefix [0, hi), in blocks: the cost per event does not depend on the capacity)."""
    k = jax.random.fold_in(st.key, st.n_events)
    ku, kout = jax.random.split(k, 2)
    # (Δt, row block, row slot, partner block, partner slot, duplication block, duplication slot)
    u = jax.random.uniform(ku, (7,), dtype=st.w.dtype)
    Bc = _B(cfg, True)
    lin = _lin_kernel(cfg, p) is not None
    # The row pass also checks the round-off of the incremental updates (rate design B): the sum of |R| and the
    # smallest entry; an entry below -1e-9 of the sum asks for a refresh before the event (a negative entry
    # within that, round-off of a rate sum near 0, weighs 0 in the pick and stays in R until the refresh). With
    # linear-space tiles it also takes the range of the state that their guard reads.
    rfn, rinit = _range_block(cfg, st) if lin else (None, ())

    def extra(start, fresh, c):
        tot, rmin, *rc = c
        Rb = _sl(st.R, start, Bc)
        live = fresh & _sl(st.valid, start, Bc)
        tot = tot + jnp.sum(jnp.where(live & jnp.isfinite(Rb), jnp.abs(Rb), 0.0))
        rmin = jnp.minimum(rmin, jnp.min(jnp.where(live, Rb, jnp.inf)))
        return (tot, rmin) + (tuple(rfn(start, fresh, tuple(rc))) if lin else ())

    a, total, (tot, rmin, *racc) = _pick_blocked(cfg, st.hi, lambda start, idx: jnp.maximum(_sl(st.R, start, Bc), 0.0),
                                                 u[1], u[2], (extra, (jnp.array(0.0), jnp.array(jnp.inf)) + rinit))
    rng = _Range(*racc) if lin else None
    fresh = st.n_since_refresh == 0
    nonfinite = ~jnp.isfinite(total)
    zero = ~nonfinite & ((total <= 0) | (st.ns == 0))
    tiny = ~nonfinite & (total < 1e-100)
    neg = rmin < -1e-9 * tot

    proceed = ~nonfinite & ~zero & ~(tiny & ~fresh) & ~neg
    log_lam = jnp.log(jnp.where(proceed, total, 1.0)) + st.s - st.logV
    E = -jnp.log1p(-u[0])  # Exp(1)
    t_new = st.t + E * jnp.exp(-log_lam)
    # snapshots first (pre-event state, MC hazard 11); the snapshot buffers (n_snap x S per array) are no
    # operand of the event below (as an operand of a lax.cond, on CPU they were copied on every event:
    # measured 116 -> 271 us/event going from 2 to 64 output times at S = 512)
    st = _fill(cfg, p, st, jnp.where(proceed, t_new, -jnp.inf))
    snaps = st.snaps
    st = st._replace(snaps=None)

    # every output time recorded: the run ends before this event
    finished = proceed & (st.k_out >= cfg.n_snap)
    do = proceed & ~finished

    def go(st, do):   # the event; its writes masked by do (out-of-range scatter indices, zero rate deltas)
        b = _pick_partner(cfg, p, st, a, u[3], u[4], rng)
        st2, T, Tm, old = _collide(cfg, p, st, a, b, kout, do)
        st2, (lmx, l1, l2) = _inc_update(cfg, p, old, st2, T, Tm, do, rng)
        st2 = st2._replace(t=t_new, n_events=st2.n_events + 1, n_since_refresh=st2.n_since_refresh + 1)
        need_mp = cfg.mode == "const_ns" or (cfg.grouping == "equal_mass" and cfg.mode != "const_v")
        log_mp = l2 - l1 if need_mp else jnp.array(0.0)   # ln m_p = ln(M2/M1), read by const-Ns / rezoom
        st2 = _duplicate(cfg, p, st2, kout, u[5:7], log_mp, do)
        # maintenance triggers
        rez = jnp.array(False)
        if cfg.grouping == "equal_mass" and cfg.mode != "const_v":
            rez = jnp.abs(log_mp - st2.zref) > 0.25 * LN2
        elif cfg.grouping == "distribution":
            rez = (jnp.abs(lmx - st2.zref) > 0.25 * LN2) | (st2.n_events % cfg.n_rezoom == 0)
        free = cfg.capacity - st2.ns
        cap = free < cfg.n_prod + 2
        if cfg.grouping == "equal_mass":
            cap = cap | (cfg.capacity - free > _ns_hi_em(cfg, p["ns_target"]))
        dirty = st2.dirty | rez | cap | (st2.n_since_refresh >= cfg.n_refresh)
        st2 = st2._replace(rezoom=st2.rezoom | rez, dirty=dirty)
        return _stop(st2, st2.n_events >= p["max_events"], STATUS.MAX_EVENTS)

    def no_event(st):   # no event: the rate sum was not usable (or the run is finished, see above)
        st = _stop(st, nonfinite & fresh, STATUS.NONFINITE)
        st = _stop(st, zero & fresh, STATUS.ZERO_RATE)
        return st._replace(dirty=st.dirty | (~fresh & ~proceed), done=st.done | finished)

    if cfg.capacity < COND_FREE_CAPACITY:
        return jax.lax.cond(do, lambda s: go(s, True), no_event, st)._replace(snaps=snaps)
    # no lax.cond (the default, COND_FREE_CAPACITY = 0): XLA did not update the species arrays in place inside a
    # cond branch (it copied four of them in and out of the branch, S slots each, on every event); the event runs on
    # every iteration with its writes masked (where do is False, rarely: the next maintenance refreshes) and the
    # scalar fields are selected. The event is the body of a one-trip while loop (its trip count a runtime value):
    # as a part of the event loop's body, XLA-CPU's thread pool ran some of its loops on the other thread, at twice
    # the cost per event on 2 cores (Ns* = 400 to t = 5: 40.3 against 19.5 us; docs/design_notes.md)
    one = jnp.where(st.n_events >= 0, 1, 0).astype(jnp.int32)
    _, st2 = jax.lax.while_loop(lambda c: c[0] < one, lambda c: (c[0] + 1, go(c[1], do)), (jnp.int32(0), st))
    st1 = no_event(st)
    big = ("m", "logm", "psi", "w", "z", "valid", "R")   # already masked by do
    out = {k: (getattr(st2, k) if k in big else jax.tree_util.tree_map(lambda x2, x1: jnp.where(do, x2, x1),
                                                                       getattr(st2, k), getattr(st1, k)))
           for k in st._fields if k != "snaps"}
    return MCState(**out, snaps=snaps)


# ----------------------------------------------------------------------------- maintenance

def _species_block(st, lw, B, start, idx, fresh):
    """The species arrays of one block (slots idx = start + arange(B)) as a dict for the tile functions; valid
    includes ``fresh``."""
    return dict(i=idx, logm=_sl(st.logm, start, B), psi=_sl(st.psi, start, B), w=_sl(st.w, start, B),
                z=_sl(st.z, start, B), valid=_sl(st.valid, start, B) & fresh, lw=_sl(lw, start, B))


def _tiles(cfg, p, st, row_fn):
    """Blocked O(hi^2) pass over the pairs of the active prefix: for every row block, fold
    ``row_fn(rows, cols) -> (B,) ln-sum`` over the column blocks with logaddexp; returns (S,) ln-sums
    (−inf for slots outside the prefix)."""
    B, S = _B(cfg), cfg.capacity
    lw = _safe_log_w(st.w)
    blk = functools.partial(_species_block, st, lw, B)

    def row_body(kr, rstart, ridx, rfresh, out):
        rows = blk(rstart, ridx, rfresh)

        def col_body(kc, cstart, cidx, cfresh, acc):
            return jnp.logaddexp(acc, row_fn(rows, blk(cstart, cidx, cfresh)))

        acc = _fold(cfg, st.hi, col_body, jnp.full((B,), -jnp.inf))
        cur = _sl(out, rstart, B)
        return jax.lax.dynamic_update_slice_in_dim(out, jnp.where(rfresh, acc, cur), rstart, axis=0)

    return _fold(cfg, st.hi, row_body, jnp.full((S,), -jnp.inf))


def _tiles_sym(cfg, st, tile_fn, linear=False, extra=None, on=True):
    """Blocked pass over the pairs of the active prefix for a *symmetric* matrix: ``tile_fn(rows, cols) -> (B, B)``
    ln-entries (−inf outside); returns the (S,) ln row sums (−inf outside the prefix). With ``linear``: linear
    entries (0 outside) and linear row sums (0 outside); ``extra``: more (S,) arrays sliced into the blocks;
    ``on`` False: no tile (zero trips).

    Only the column blocks kc >= kr of row block kr are evaluated: a diagonal tile adds its row sums to its
    rows, an off-diagonal tile its row sums to its rows and its column sums to its columns (entry (a, b) is
    entry (b, a)). nb (nb + 1) / 2 tiles instead of nb^2. Blocks as in :func:`_fold` (the last start clamped to
    S - B, ``fresh`` in the validity masks): a slot outside its block proper adds −inf, which leaves a sum as
    it is.
    """
    B, S = _B(cfg), cfg.capacity
    lw = _safe_log_w(st.w)
    n = jnp.asarray(st.hi, jnp.int32)
    nb = jnp.where(on, (n + (B - 1)) // B, 0)
    zero = 0.0 if linear else -jnp.inf
    add = jnp.add if linear else jnp.logaddexp
    red = jnp.sum if linear else jax.nn.logsumexp

    def blk(k):
        start, idx, fresh = _block_at(cfg, k, n)
        d = _species_block(st, lw, B, start, idx, fresh)
        d.update({key: _sl(x, start, B) for key, x in (extra or {}).items()})
        return start, fresh, d

    def row_body(kr, out):
        rstart, rfresh, rows = blk(kr)

        def col_body(kc, c):
            acc, out = c
            cstart, _, cols = blk(kc)
            L = tile_fn(rows, cols)
            acc = add(acc, red(L, axis=1))
            colsum = jnp.where(kc > kr, red(L, axis=0), zero)
            out = jax.lax.dynamic_update_slice_in_dim(out, add(_sl(out, cstart, B), colsum), cstart, axis=0)
            return acc, out

        acc, out = jax.lax.fori_loop(kr, nb, col_body, (jnp.full((B,), zero), out))
        cur = _sl(out, rstart, B)
        return jax.lax.dynamic_update_slice_in_dim(out, jnp.where(rfresh, add(cur, acc), cur), rstart, axis=0)

    return jax.lax.fori_loop(jnp.int32(0), nb, row_body, jnp.full((S,), zero))


def _refresh(cfg, p, st):
    """Full recomputation of the scaled row sums (R, s) of Λ' over the active prefix (O(hi^2), blocked, the
    upper triangle of tiles only: Λ' is symmetric; the scale keeps the largest row sum at 1, rows below
    exp(s - 745) underflow to 0). For ``cheap_linear`` kernels the tiles are linear (``rates.rate_tile``, scaled
    by the previous s) where the range guard of :func:`_lin_rows` admits every row and the largest sum is
    within e^(+-600), else in log space.

    References: Ormel (2008) eq. (5.31); MC hazard 5 in docs/design_notes.md."""
    def tile_fn(r, c):
        logK = log_kernel_tile(p["kernel"], r["logm"], r["psi"], c["logm"], c["psi"])
        return log_rate_tile(logK, r["i"], r["logm"], r["w"], r["z"], r["valid"], c["i"], c["logm"], c["w"], c["z"],
                             c["valid"], p["log2_feps"], cfg.rounding, lw_a=r["lw"], lw_b=c["lw"])

    def log_space():
        rlog = _tiles_sym(cfg, st, tile_fn)
        rlog = jnp.where(jnp.isnan(rlog), jnp.nan, rlog)
        s = jnp.max(jnp.where(jnp.isfinite(rlog) | jnp.isnan(rlog), rlog, -jnp.inf))
        s = jnp.where(jnp.isfinite(s), s, 0.0)
        R = jnp.exp(rlog - s)
        R = jnp.where(jnp.isnan(rlog) | (rlog == jnp.inf), jnp.nan, R)
        return R, s

    kern = _lin_kernel(cfg, p)
    if kern is None:
        return log_space()
    s0 = st.s
    r, d, ok = _lin_rows(kern, _range(cfg, st), _safe_log_w(st.w), st.w, st.z, st.logm, st.valid, s0)

    def tile_lin(a, b):
        return rate_tile(kern(a["m"][:, None], b["m"][None, :]), a["i"], a["r"], a["d"], a["logm"], a["w"], a["z"],
                         a["valid"], b["i"], b["logm"], b["w"], b["z"], b["valid"], p["log2_feps"], cfg.rounding)

    R = _tiles_sym(cfg, st, tile_lin, linear=True, extra=dict(m=st.m, r=r, d=d), on=ok)
    mx = jnp.max(jnp.where(st.valid, R, 0.0))
    ok = ok & (mx > math.exp(-600.0)) & (mx < math.exp(600.0))
    return jax.lax.cond(ok, lambda: (R / jnp.where(ok, mx, 1.0), s0 + jnp.log(jnp.where(ok, mx, 1.0))), log_space)


def _particle_rates(cfg, p, st):
    """ln Σ_b K(m_a, m_b) g_b per slot a over the active prefix (blocked form of
    :func:`jaxcoag.mc.rates.log_particle_rates`); −inf on invalid slots."""
    def row_fn(r, c):
        logK = log_kernel_tile(p["kernel"], r["logm"], r["psi"], c["logm"], c["psi"])
        lg = jnp.where(c["valid"], c["lw"] + c["z"].astype(logK.dtype) * LN2, -jnp.inf)
        return jax.nn.logsumexp(logK + lg[None, :], axis=1)

    return jnp.where(st.valid, _tiles(cfg, p, st, row_fn), -jnp.inf)


def _rezoom_all(cfg, p, st):
    if cfg.grouping is None:
        return st
    if cfg.grouping == "equal_mass":
        lms = st.log_mstar
        if cfg.mode != "const_v":
            lms = _log_mp(st.logm, st.w, st.z, st.valid)
        zh = G.zoom_target_equal_mass(st.logm, lms)
        w, z = G.apply_zoom(st.w, st.z, zh)
        w = jnp.where(st.valid, w, 0.0)
        return st._replace(w=w, z=jnp.where(st.valid, z, 0), log_mstar=lms, zref=lms)
    xp, fp = G.distribution_nodes(st.logm, st.w, st.z, st.valid, st.log_mlo, jnp.log(p["ns_target"]), cfg.n_bins)
    if cfg.count_zoom is not None:
        xc, fc = G.count_nodes(st.logm, st.w, st.z, st.valid, cfg.count_zoom)
        xp, fp = jnp.concatenate([xp, xc]), jnp.concatenate([fp, fc])
    zh = _zhat(cfg, st.logm, st.log_mstar, xp, fp)
    if cfg.tail_events > 0:
        lr = _particle_rates(cfg, p, st) - st.logV
        lwm = jnp.log(p["tail_wmax"])
        cap = G.zoom_cap_tail(st.w, st.z, st.valid, lr, st.t, lwm, cfg.tail_events)
        zh = jnp.minimum(zh, cap)
    w, z = G.apply_zoom(st.w, st.z, zh)
    w = jnp.where(st.valid, w, 0.0)
    lmax = jnp.max(jnp.where(st.valid, st.logm, -jnp.inf))
    return st._replace(w=w, z=jnp.where(st.valid, z, 0), zoom_xp=xp, zoom_fp=fp, zref=lmax)


#: per-slot arrays of the state (leading axis: the S slots)
_SLOTS = ("m", "logm", "psi", "w", "z", "valid", "R")


def _prefix_sizes(S):
    """Static lengths of the windows of :func:`_on_prefix`: 1024 x 4^k up to S/2, then S."""
    sizes, B = [], 1024
    while 2 * B <= S:
        sizes.append(B)
        B *= 4
    return tuple(sizes) + (S,)


def _on_prefix(cfg, st, fn):
    """``fn(cfg_b, st_b)`` on the shortest window [0, B) of the per-slot arrays that holds every valid slot
    (B from :func:`_prefix_sizes`; ``cfg_b`` = cfg with capacity B, ``st_b`` the state with its per-slot arrays
    cut to B and ``hi`` set to the current prefix end); fn's per-slot arrays are written back into the first B
    slots, R is 0 beyond them (as the refresh leaves the slots past the prefix).

    The maintenance's sorts (the merge), per-slot passes (rezoom, the refresh's ln w and row guard) then cost
    O(B) or O(B log B) instead of O(S log S): a constant-V sum-kernel run holding ~200 species in 51 200 slots
    (Ns* = 100, to t = 20; a maintenance every ~90 events) took 212 us per event against 48 at 3 200 slots.
    The results are those of the full arrays: every valid slot lies in the window, empty slots sort last, the
    per-slot arithmetic does not depend on the window, and the blocks of the passes are the same (B is a
    multiple of the pass blocks, so no block start is clamped inside it)."""
    # only windows that are multiples of both pass blocks (always so for the default block of 128)
    sizes = tuple(B for B in _prefix_sizes(cfg.capacity)
                  if B == cfg.capacity or (B % _B(cfg) == 0 and B % _B(cfg, True) == 0))
    hi0, _ = _active(st.valid)

    def branch(B):
        if B == cfg.capacity:
            return lambda st: fn(cfg, st._replace(hi=hi0))

        def f(st):
            cut = {n: getattr(st, n)[:B] for n in _SLOTS}
            out = fn(dataclasses.replace(cfg, capacity=B), st._replace(hi=hi0, **cut))
            new = {n: getattr(st, n).at[:B].set(getattr(out, n)) for n in _SLOTS if n != "R"}
            return out._replace(R=jnp.zeros_like(st.R).at[:B].set(out.R), **new)

        return f

    if len(sizes) == 1:
        return branch(sizes[0])(st)
    k = jnp.sum(jnp.asarray(sizes[:-1], jnp.int32) < hi0)
    return jax.lax.switch(k, [branch(B) for B in sizes], st)


def _maintenance(cfg, p, st):
    """Scheduled or emergency merge, global rezoom and full rate refresh (thesis §5.2.1, App. 5.B), run on the
    prefix window of the slots that holds the species (:func:`_on_prefix`); the merge thresholds follow the
    capacity S of ``cfg``."""
    return _on_prefix(cfg, st, functools.partial(_maintain, cfg, p))


def _maintain(cfg, p, cfg_b, st):
    """:func:`_maintenance` on the window of ``cfg_b`` (per-slot arrays of length cfg_b.capacity)."""
    S = cfg.capacity
    ns = jnp.sum(st.valid)
    emergency = S - ns < cfg.n_prod + 2
    if cfg.grouping == "distribution":
        ns_hi = jnp.minimum(jnp.floor(0.9 * S), p["ns_target"])
        sched = ns > ns_hi
        ns_lo = jnp.floor(0.75 * ns_hi)
    elif cfg.grouping == "equal_mass":
        # scheduled merge (thesis §5.2.1, ch. 6: Ns_hi = 2 Ns*, here also <= 0.9 S; Ns_lo = 1.5 Ns*,
        # <= 0.7 S): the demagnification leftovers (MC hazard 3, docs/design_notes.md) are merged with
        # mass neighbours, which keeps the species count (and the cost per event) within 2 Ns*
        sched = ns > _ns_hi_em(cfg, p["ns_target"])
        ns_lo = jnp.asarray(float(math.floor(0.7 * S)))
        if cfg.em_merge is not None:
            ns_lo = jnp.minimum(ns_lo, jnp.floor(0.75 * cfg.em_merge * p["ns_target"]))
    else:
        sched = jnp.array(False)
        ns_lo = jnp.array(float(S))
    ns_lo = jnp.where(emergency, jnp.minimum(ns_lo, math.floor(0.7 * S)), ns_lo)
    do_merge = emergency | sched

    def merge(st):
        n_merge = jnp.maximum(ns - ns_lo, 0).astype(jnp.int32)
        m, logm, psi, w, z, valid, nd = G.merge_pairs(st.m, st.logm, st.psi, st.w, st.z, st.valid,
                                                      n_merge, cfg.p_protect, cfg.weighting)
        return st._replace(m=m, logm=logm, psi=psi, w=w, z=z, valid=valid, n_merge=st.n_merge + nd,
                           rezoom=jnp.array(True),
                           status=st.status | jnp.where(emergency, STATUS.CAPACITY, 0))

    st = jax.lax.cond(do_merge, merge, lambda s: s, st)
    if cfg.grouping is not None:
        st = jax.lax.cond(st.rezoom, lambda s: _rezoom_all(cfg_b, p, s), lambda s: s, st)
    hi, ns = _active(st.valid)
    st = st._replace(hi=hi, ns=ns)
    R, s = _refresh(cfg_b, p, st)
    st = st._replace(R=R, s=s, n_since_refresh=jnp.array(0, jnp.int64), dirty=jnp.array(False),
                     rezoom=jnp.array(False))
    still_full = cfg.capacity - ns < cfg.n_prod + 2
    return _stop(st, still_full, STATUS.CAPACITY)


def _monodisperse_state(cfg: _Cfg, N, m0, log_rho_d, ns_target, struct0, key, t0, log_mlo):
    """Initial state: one species of N monomers of mass m0 [g], V = N m0 / rho_d [cm^3] (thesis App. 5.B)."""
    S, P = cfg.capacity, cfg.n_struct
    f = jnp.float64
    valid = jnp.zeros((S,), bool).at[0].set(True)
    m = jnp.ones((S,), f).at[0].set(m0)
    logm = jnp.zeros((S,), f).at[0].set(jnp.log(m0))
    psi = jnp.zeros((S, P), f).at[0].set(struct0)
    w = jnp.zeros((S,), f).at[0].set(N)
    z = jnp.zeros((S,), jnp.int32)
    M_tot = N * m0
    logV = jnp.log(N) + jnp.log(m0) - log_rho_d
    log_mstar = jnp.log(N) + jnp.log(m0) - jnp.log(ns_target)
    if cfg.mode != "const_v":
        log_mstar = jnp.log(m0)
    return _blank_state(cfg, m, logm, psi, w, z, valid, logV, M_tot, log_mstar, key, t0, log_rho_d, log_mlo)


def _species_state(cfg: _Cfg, init, log_rho_d, ns_target, key, t0, log_mlo):
    """Initial state from an ``InitialSpecies`` (slots 0..Ns0-1); V given or M_tot / rho_d."""
    S, P = cfg.capacity, cfg.n_struct
    f = jnp.float64
    n = init.m.shape[0]
    valid = jnp.arange(S) < n
    m = jnp.ones((S,), f).at[:n].set(init.m)
    logm = jnp.zeros((S,), f).at[:n].set(jnp.log(init.m))
    psi = jnp.zeros((S, P), f).at[:n].set(init.psi)
    w = jnp.zeros((S,), f).at[:n].set(init.w)
    z = jnp.zeros((S,), jnp.int32).at[:n].set(init.z)
    lg = jnp.log(init.w) + init.z.astype(f) * LN2
    logM = jax.nn.logsumexp(lg + jnp.log(init.m))
    M_tot = jnp.exp(logM)
    logV = logM - log_rho_d
    log_mstar = logM - jnp.log(ns_target) if cfg.mode == "const_v" else jnp.min(jnp.log(init.m))
    return _blank_state(cfg, m, logm, psi, w, z, valid, logV, M_tot, log_mstar, key, t0, log_rho_d, log_mlo)


def _n_nodes(cfg):
    return cfg.n_bins + (cfg.capacity if cfg.count_zoom is not None else 0)


def _blank_state(cfg, m, logm, psi, w, z, valid, logV, M_tot, log_mstar, key, t0, log_rho_d, log_mlo):
    f = jnp.float64
    S = cfg.capacity
    return MCState(m=m, logm=logm, psi=psi, w=w, z=z, valid=valid, R=jnp.zeros((S,), f), s=jnp.array(0.0),
                   logV=logV, M_tot=M_tot, t=jnp.asarray(t0, f), n_events=jnp.array(0, jnp.int64),
                   n_since_refresh=jnp.array(0, jnp.int64), dirty=jnp.array(True), rezoom=jnp.array(True),
                   log_mstar=log_mstar, zref=log_mstar, zoom_xp=jnp.arange(_n_nodes(cfg), dtype=f),
                   zoom_fp=jnp.zeros((_n_nodes(cfg),), f), key=key, k_out=jnp.array(0, jnp.int32),
                   status=jnp.array(0, jnp.int32), done=jnp.array(False), n_dup=jnp.array(0, jnp.int64),
                   n_merge=jnp.array(0, jnp.int64), log_rho_d=jnp.asarray(log_rho_d, f),
                   log_mlo=jnp.asarray(log_mlo, f), snaps=None, hi=_active(valid)[0], ns=_active(valid)[1])


def _check_stop(cfg, p, before, after):
    """Apply the user stop predicate after an executed event (STATUS.STOPPED)."""
    if p.get("stop") is None:
        return after
    hit = (after.n_events > before.n_events) & jnp.asarray(p["stop"](after), bool)
    return _stop(after, hit, STATUS.STOPPED)


def _start(cfg: _Cfg, p: dict, st: MCState):
    """Fresh snapshot buffers, k_out = 0; a continued state that had halted (event budget spent,
    stopped by the predicate, or out of capacity) stays halted; the stop predicate is also
    checked on the initial state."""
    T, S, P = cfg.n_snap, cfg.capacity, cfg.n_struct
    f = jnp.float64
    snaps = Snapshots(m=jnp.ones((T, S), f), logm=jnp.zeros((T, S), f), psi=jnp.zeros((T, S, P), f),
                      w=jnp.zeros((T, S), f), z=jnp.zeros((T, S), jnp.int32), valid=jnp.zeros((T, S), bool),
                      logV=jnp.zeros((T,), f), M_tot=jnp.zeros((T,), f), n_events=jnp.zeros((T,), jnp.int64),
                      status=jnp.zeros((T,), jnp.int32))
    hi, ns = _active(st.valid)
    st = st._replace(snaps=snaps, k_out=jnp.array(0, jnp.int32), done=jnp.array(False), hi=hi, ns=ns)
    full = (cfg.capacity - jnp.sum(st.valid) < cfg.n_prod + 2) & ((st.status & STATUS.CAPACITY) != 0)
    halted = (st.n_events >= p["max_events"]) | ((st.status & STATUS.STOPPED) != 0) | full
    st = st._replace(done=halted)
    if p.get("stop") is not None:
        st = _stop(st, ~halted & jnp.asarray(p["stop"](st), bool), STATUS.STOPPED)
    return st


#: Occupied slots (hi) from which the events run with longer blocks (``_cfg_big``): 2048-slot kernel tiles and
#: 4096-slot sums and searches instead of 128 and 512. Measured on 2 CPU cores (issue-17 goal run: constant Ns,
#: Ns* = 2000, sum kernel, to t = 20, up to ~4 000 slots in use; docs/design_notes.md): 85.6-86.4 us per event on
#: average against 101.5-102.0 us with 512 / 1024 blocks from 2 048 slots on; at the run's state at t = 12 (4 001
#: slots) one event took 86 against 103 us, at t = 9 (2 984 slots) 82 against 80 us. Runs that hold a few hundred
#: species lose with long blocks (Ns* = 100-1000 to t = 5: 31-43 against 26-34 us per event with 512 / 1024
#: blocks), hence the switch by the occupied prefix.
BIG_BLOCKS_FROM = 2048
#: The kernel-tile block and the cheap-pass block of ``_cfg_big``.
BIG_BLOCK, BIG_CHEAP_BLOCK = 2048, 4096


def _cfg_big(cfg):
    """The configuration of the events from BIG_BLOCKS_FROM occupied slots on (None where the capacity never gets
    there, or the blocks are already at least as long)."""
    if cfg.capacity <= BIG_BLOCKS_FROM or cfg.block >= BIG_BLOCK:
        return None
    return dataclasses.replace(cfg, block=BIG_BLOCK, cheap_block=BIG_CHEAP_BLOCK)


def _simulate(cfg: _Cfg, p: dict, st: MCState):
    """Advance ``st`` (snapshot-free state) over the output times ``p["t_out"]``.

    Returns (end state without snapshot buffers, ``Snapshots`` at every output time). The state
    recorded at t_out[k] is the state after the last event with time <= t_out[k]; remaining
    snapshots of a halted run repeat its final state.
    """
    st = _start(cfg, p, st)
    cfg_big = _cfg_big(cfg)

    def inner_cond(s):
        return ~s.done & ~s.dirty

    def events(cfg_e, cond):
        return lambda s: jax.lax.while_loop(cond, lambda s_: _check_stop(cfg_e, p, s_, _event(cfg_e, p, s_)), s)

    def outer_body(s):
        # maintenance only when due (always true here except right after a continuation, where a
        # refresh would change R and break bitwise equality with the uninterrupted run)
        s = jax.lax.cond(s.dirty, lambda s_: _maintenance(cfg, p, s_), lambda s_: s_, s)
        if cfg_big is None:
            return events(cfg, inner_cond)(s)
        # the events while fewer than BIG_BLOCKS_FROM slots are in use, then (hi only grows between maintenances)
        # with the longer blocks of cfg_big; one of the two loops often runs zero trips. Two loops in sequence, not
        # a lax.cond (that copied the species arrays and snapshot buffers in and out of its branches)
        s = events(cfg, lambda s_: inner_cond(s_) & (s_.hi < BIG_BLOCKS_FROM))(s)
        return events(cfg_big, inner_cond)(s)

    st = jax.lax.while_loop(lambda s: ~s.done, outer_body, st)
    st = _fill(cfg, p, st, jnp.inf)  # remaining snapshots repeat the final state (exact for ZERO_RATE)
    return st._replace(snaps=None), st.snaps


def _config_pairs(cfg: _Cfg, p: dict):
    """Static run configuration as (name, value) pairs (MCResult.config / dataset attributes)."""
    out = [(k, v if isinstance(v, (int, float, str, bool)) else repr(v)) for k, v in dataclasses.asdict(cfg).items()
           if k != "n_snap"]
    out.append(("kernel", type(p["kernel"]).__name__))
    out.append(("outcome", type(p["outcome"]).__name__))
    stop = p.get("stop")
    out.append(("stop", "none" if stop is None else (repr(stop) if isinstance(stop, eqx.Module) else getattr(stop, "__name__", "callable"))))
    return tuple((k, "none" if v is None else v) for k, v in out)

