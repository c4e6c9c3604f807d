"""Jitted grouped Monte Carlo coagulation (Ormel & Spaans 2008) — event loop and ``run``.

Structure of one run (all inside ``jax.jit``; batch runs with ``jax.vmap``):

    outer lax.while_loop (until done):
        maintenance: merge (capacity / distribution policy) -> global rezoom -> full rate refresh
        inner lax.while_loop (until done or maintenance due):
            one event: Δt, pair (a, b) [Gillespie full conditioning], snapshots, collision via
            the outcome module, donor fix-up (removal / demagnification), product zoom,
            duplication (const_n / const_ns), incremental update of the rate row sums

The two-level loop keeps the O(S^2) refresh out of the per-event path even under ``vmap``
(where ``lax.cond`` would evaluate both branches).

References: Ormel (2008) thesis §2.3.2, ch. 5 (eqs. 5.6-5.13, 5.31-5.33, App. 5.A/5.B);
Gillespie (1975); Smith & Matsoukas (1998); conventions, defaults and MC hazards in
docs/design_notes.md.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._validate import JaxcoagInputError, check, is_traced, require_x64
from ..kernels import AbstractKernel
from . import grouping as G
from .outcomes import AbstractOutcome, PerfectSticking
from .rates import log_particle_rates, log_rate_matrix, log_rate_row, n_eps, row_sums
from .results import MCResult
from .state import STATUS, InitialSpecies, MCState, Snapshots

__all__ = ["run", "CapacityWarning", "min_capacity"]

LN2 = 0.6931471805599453
_MODES = ("const_v", "const_n", "const_ns")
_GROUPINGS = (None, "equal_mass", "distribution")


@dataclasses.dataclass(frozen=True)
class _Cfg:
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


def _row(cfg, p, arrays, a):
    m, logm, psi, w, z, valid = arrays
    return log_rate_row(p["kernel"], a, logm, psi, w, z, valid, p["log2_feps"], cfg.rounding)


def _arrays(st):
    return (st.m, st.logm, st.psi, st.w, st.z, st.valid)


def _write_snap(snaps: Snapshots, k, st):
    return Snapshots(
        m=snaps.m.at[k].set(st.m), logm=snaps.logm.at[k].set(st.logm),
        psi=snaps.psi.at[k].set(st.psi), w=snaps.w.at[k].set(st.w), z=snaps.z.at[k].set(st.z),
        valid=snaps.valid.at[k].set(st.valid), logV=snaps.logV.at[k].set(st.logV),
        M_tot=snaps.M_tot.at[k].set(st.M_tot), n_events=snaps.n_events.at[k].set(st.n_events))


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


def _ns_hi_equal_mass(cfg):
    """Species count above which an equal-mass run merges (default 0.9 S, below the emergency level)."""
    return min(math.floor(0.9 * cfg.capacity), cfg.capacity - cfg.n_prod - 3)


def min_capacity(grouping, ns_target, n_products=1):
    """Smallest ``capacity`` S whose merge threshold still holds ``ns_target`` species.

    Grouped runs merge mass neighbours once the species count exceeds a fraction of S
    (distribution: min(0.9 S, Ng*); equal-mass: min(0.9 S, S - n_products - 3), thesis §5.2.1,
    App. 5.B); below this S the run would keep fewer species than ``ns_target`` asks for, i.e.
    a coarser resolution than requested. None for grouping=None (no such threshold).
    """
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
    its resolution (``STATUS.CAPACITY``); rerun with a larger ``capacity``."""


def _warn_capacity(status, capacity):
    """Warn (CapacityWarning) when any run in ``status`` (array of STATUS codes) has the CAPACITY flag."""
    import warnings

    st = np.asarray(status)
    hit = int(np.count_nonzero(st & STATUS.CAPACITY))
    if hit:
        runs = f"{hit} of {st.size} runs" if st.size > 1 else "the run"
        warnings.warn(f"jaxcoag.mc.run: {runs} ran out of species slots (capacity = {int(capacity)}); an emergency "
                      "merge of mass neighbours lowered the resolution (status CAPACITY). Rerun with a larger "
                      f"capacity, e.g. capacity={2 * int(capacity)}.", CapacityWarning, stacklevel=3)


def _stop(st, cond, flag):
    """Mark the run done with ``flag`` where ``cond`` holds (snapshots are filled at the end)."""
    return st._replace(done=st.done | cond, status=jnp.where(cond, st.status | flag, st.status))


def _inc_update(cfg, p, st_old_arrays, st, T, Tmask):
    """Incremental row-sum update for the touched slots T (rate design B, docs/design_notes.md)."""
    if cfg.rates == "full":
        return st._replace(dirty=jnp.array(True))
    Lold = jax.vmap(lambda a: _row(cfg, p, st_old_arrays, a))(T)
    Lnew = jax.vmap(lambda a: _row(cfg, p, _arrays(st), a))(T)
    eo = jnp.where(Tmask[:, None], jnp.exp(Lold - st.s), 0.0)
    en_all = jnp.exp(Lnew - st.s)
    en = jnp.where(Tmask[:, None], en_all, 0.0)
    R = st.R + jnp.sum(en - eo, axis=0)
    R = R.at[T].set(jnp.sum(en_all, axis=1))
    tot = jnp.sum(jnp.where(jnp.isfinite(R), jnp.abs(R), 0.0))
    neg = jnp.any(R < -1e-9 * tot)
    over = jnp.max(Lnew) - st.s > 600.0
    R = jnp.maximum(R, 0.0)
    return st._replace(R=R, dirty=st.dirty | neg | over)


def _pick(u, weights):
    c = jnp.cumsum(weights)
    idx = jnp.searchsorted(c, u * c[-1], side="right")
    return jnp.minimum(idx, weights.shape[0] - 1)


# ----------------------------------------------------------------------------- event

def _collide(cfg, p, st, a, b, key):
    """Execute one (group) event on the species pair {a, b}; returns (state, T, Tmask)."""
    m, logm, psi, w, z, valid = _arrays(st)
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
    prods = p["outcome"](m[i], logm[i], psi[i], m[j], logm[j], psi[j], n_c, log_nc, key)

    # donors
    dw_i = jnp.where(same, jnp.where(z[a] == 0, 2.0, 1.0), 1.0)
    dw_j = jnp.where(same, 0.0, jnp.ldexp(1.0, -ne))
    w = w.at[i].set(jnp.maximum(w[i] - dw_i, 0.0))
    w = w.at[j].set(jnp.maximum(w[j] - dw_j, 0.0))
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
            w = w.at[s_].set(w_new)
        wn, zn, alive = G.demagnify(w[s_], z[s_])
        w = w.at[s_].set(wn)
        z = z.at[s_].set(zn)
        valid = valid.at[s_].set(valid[s_] & alive)
        m = m.at[s_].set(jnp.where(alive, m[s_], 1.0))
        logm = logm.at[s_].set(jnp.where(alive, logm[s_], 0.0))

    # products
    slots = []
    masks = []
    for q in range(cfg.n_prod):
        mp = prods.m[q]
        lmp = jnp.where(jnp.isfinite(mp) & (mp > 0), jnp.log(jnp.where(mp > 0, mp, 1.0)), prods.logm[q])
        psip = prods.psi[q]
        cnt = prods.count[q]
        do = prods.valid[q] & (cnt > 0)
        if cfg.dedupe:
            same_psi = jnp.all(psi == jnp.broadcast_to(psip, psi.shape), axis=1)
            match = valid & (logm == lmp) & same_psi
            has = jnp.any(match)
        else:
            match = jnp.zeros_like(valid)
            has = jnp.array(False)
        kfree = jnp.argmin(valid)
        slot = jnp.where(has, jnp.argmax(match), kfree)
        zh = _zhat(cfg, lmp, st.log_mstar, st.zoom_xp, st.zoom_fp)
        wn, zn = G.apply_zoom(cnt, zp, zh)
        w_add = w[slot] + jnp.ldexp(cnt, zp - z[slot])
        new_w = jnp.where(has, w_add, wn)
        new_z = jnp.where(has, z[slot], zn)
        do = do & (has | ~valid[slot])
        m = m.at[slot].set(jnp.where(do & ~has, mp, m[slot]))
        logm = logm.at[slot].set(jnp.where(do & ~has, lmp, logm[slot]))
        psi = psi.at[slot].set(jnp.where(do & ~has, psip, psi[slot]))
        w = w.at[slot].set(jnp.where(do, new_w, w[slot]))
        z = z.at[slot].set(jnp.where(do, new_z, z[slot]))
        valid = valid.at[slot].set(valid[slot] | do)
        slots.append(slot)
        masks.append(do)
    T = jnp.stack([i, j] + slots)
    Tm = jnp.stack([jnp.array(True), ~same] + masks)
    # mask duplicate entries of T (keep the first occurrence)
    nT = T.shape[0]
    dup = jnp.any((T[:, None] == T[None, :]) & (jnp.arange(nT)[None, :] < jnp.arange(nT)[:, None]) & Tm[None, :], axis=1)
    Tm = Tm & ~dup
    st = st._replace(m=m, logm=logm, psi=psi, w=w, z=z, valid=valid, M_tot=M_tot)
    if cfg.leftover == "stochastic" and cfg.mode != "const_v":
        st = st._replace(logV=jnp.log(M_tot) - jnp.log(p["rho_d"]))
    return st, T, Tm


def _duplicate(cfg, p, st, key, u0, log_mp):
    """Duplication controller (const_n: one group per event; const_ns: thesis §5.3.1, ch. 6)."""
    if cfg.mode == "const_v":
        return st

    def one(c):
        st, d = c
        u = jnp.where(d == 0, u0, jax.random.uniform(jax.random.fold_in(key, d), dtype=st.w.dtype))
        k = _pick(u, jnp.where(st.valid, st.w, 0.0))
        old = _arrays(st)
        M_new = st.M_tot + jnp.ldexp(st.m[k], st.z[k])
        st2 = st._replace(w=st.w.at[k].add(1.0), M_tot=M_new,
                          logV=jnp.log(M_new) - jnp.log(p["rho_d"]), n_dup=st.n_dup + 1)
        st2 = _inc_update(cfg, p, old, st2, k[None], jnp.ones((1,), bool))
        return st2, d + 1

    if cfg.mode == "const_n":
        k = _pick(u0, jnp.where(st.valid, st.w, 0.0))
        old = _arrays(st)
        M_new = st.M_tot + jnp.ldexp(st.m[k], st.z[k])
        st2 = st._replace(w=st.w.at[k].add(1.0), M_tot=M_new,
                          logV=jnp.log(M_new) - jnp.log(p["rho_d"]), n_dup=st.n_dup + 1)
        return _inc_update(cfg, p, old, st2, k[None], jnp.ones((1,), bool))
    ns = jnp.sum(st.valid)
    if cfg.controller == "mass":
        def cond(c):
            st_, d = c
            return (st_.M_tot < p["ns_target"] * jnp.exp(log_mp)) & (d < cfg.d_max)
    else:
        nd = jnp.where(ns < p["ns_target"], cfg.d_up, 0)

        def cond(c):
            return c[1] < nd
    st, _ = jax.lax.while_loop(cond, one, (st, 0))
    return st


def _event(cfg, p, st):
    """One iteration of the inner loop: sample, record, collide, update."""
    k = jax.random.fold_in(st.key, st.n_events)
    ku, kout = jax.random.split(k, 2)
    u = jax.random.uniform(ku, (4,), dtype=st.w.dtype)  # (Δt, a, b, first duplication)
    total = jnp.sum(st.R)
    fresh = st.n_since_refresh == 0
    nonfinite = ~jnp.isfinite(total)
    zero = ~nonfinite & ((total <= 0) | (jnp.sum(st.valid) == 0))
    tiny = ~nonfinite & (total < 1e-100)

    proceed = ~nonfinite & ~zero & ~(tiny & ~fresh)
    log_lam = jnp.log(jnp.where(proceed, total, 1.0)) + st.s - st.logV
    E = -jnp.log1p(-u[0])  # Exp(1)
    t_new = st.t + E * jnp.exp(-log_lam)
    # snapshots first (pre-event state, MC hazard 11), outside the conds below: the snapshot buffers
    # (n_snap x S per array) are then no operand of a lax.cond, which on CPU copied them on every
    # event (measured 116 -> 271 us/event going from 2 to 64 output times at S = 512)
    st = _fill(cfg, p, st, jnp.where(proceed, t_new, -jnp.inf))
    snaps = st.snaps
    st = st._replace(snaps=None)

    def do_event(st):
        def go(st):
            a = _pick(u[1], st.R)
            row = _row(cfg, p, _arrays(st), a)
            rmax = jnp.max(row)
            b = _pick(u[2], jnp.exp(row - rmax))
            old = _arrays(st)
            st2, T, Tm = _collide(cfg, p, st, a, b, kout)
            st2 = _inc_update(cfg, p, old, st2, T, Tm)
            st2 = st2._replace(t=t_new, n_events=st2.n_events + 1, n_since_refresh=st2.n_since_refresh + 1)
            need_mp = cfg.mode == "const_ns" or (cfg.grouping == "equal_mass" and cfg.mode != "const_v")
            log_mp = _log_mp(st2.logm, st2.w, st2.z, st2.valid) if need_mp else jnp.array(0.0)
            st2 = _duplicate(cfg, p, st2, kout, u[3], log_mp)
            # maintenance triggers
            rez = jnp.array(False)
            if cfg.grouping == "equal_mass" and cfg.mode != "const_v":
                rez = jnp.abs(log_mp - st2.zref) > 0.25 * LN2
            elif cfg.grouping == "distribution":
                lmax = jnp.max(jnp.where(st2.valid, st2.logm, -jnp.inf))
                rez = (jnp.abs(lmax - st2.zref) > 0.25 * LN2) | (st2.n_events % cfg.n_rezoom == 0)
            free = cfg.capacity - jnp.sum(st2.valid)
            cap = free < cfg.n_prod + 2
            if cfg.grouping == "equal_mass":
                cap = cap | (cfg.capacity - free > _ns_hi_equal_mass(cfg))
            dirty = st2.dirty | rez | cap | (st2.n_since_refresh >= cfg.n_refresh)
            st2 = st2._replace(rezoom=st2.rezoom | rez, dirty=dirty)
            return _stop(st2, st2.n_events >= p["max_events"], STATUS.MAX_EVENTS)

        return jax.lax.cond(st.k_out >= cfg.n_snap,
                            lambda s: s._replace(done=jnp.array(True)), go, st)

    def no_event(st):
        st = _stop(st, nonfinite & fresh, STATUS.NONFINITE)
        st = _stop(st, zero & fresh, STATUS.ZERO_RATE)
        return st._replace(dirty=st.dirty | ~fresh)

    return jax.lax.cond(proceed, do_event, no_event, st)._replace(snaps=snaps)


# ----------------------------------------------------------------------------- maintenance

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
    xp, fp = G.distribution_nodes(st.logm, st.w, st.z, st.valid, p["log_mlo"], jnp.log(p["ns_target"]), cfg.n_bins)
    if cfg.count_zoom is not None:
        xc, fc = G.count_nodes(st.logm, st.w, st.z, st.valid, cfg.count_zoom)
        xp, fp = jnp.concatenate([xp, xc]), jnp.concatenate([fp, fc])
    zh = _zhat(cfg, st.logm, st.log_mstar, xp, fp)
    if cfg.tail_events > 0:
        lr = log_particle_rates(p["kernel"], st.logm, st.psi, st.w, st.z, st.valid) - st.logV
        lwm = jnp.log(p["tail_wmax"])
        cap = G.zoom_cap_tail(st.w, st.z, st.valid, lr, st.t, lwm, cfg.tail_events)
        zh = jnp.minimum(zh, cap)
    w, z = G.apply_zoom(st.w, st.z, zh)
    w = jnp.where(st.valid, w, 0.0)
    lmax = jnp.max(jnp.where(st.valid, st.logm, -jnp.inf))
    return st._replace(w=w, z=jnp.where(st.valid, z, 0), zoom_xp=xp, zoom_fp=fp, zref=lmax)


def _maintenance(cfg, p, st):
    S = cfg.capacity
    ns = jnp.sum(st.valid)
    emergency = S - ns < cfg.n_prod + 2
    if cfg.grouping == "distribution":
        ns_hi = jnp.minimum(jnp.floor(0.9 * S), p["ns_target"])
        sched = ns > ns_hi
        ns_lo = jnp.floor(0.75 * ns_hi)
    elif cfg.grouping == "equal_mass":
        # scheduled merge (thesis §5.2.1; Ns_hi = 0.9 S, Ns_lo = 0.7 S): the demagnification
        # leftovers (MC hazard 3, docs/design_notes.md) are merged with mass neighbours before the slots run out
        sched = ns > _ns_hi_equal_mass(cfg)
        ns_lo = jnp.array(float(math.floor(0.7 * S)))
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
        st = jax.lax.cond(st.rezoom, lambda s: _rezoom_all(cfg, p, s), lambda s: s, st)
    L = log_rate_matrix(p["kernel"], st.logm, st.psi, st.w, st.z, st.valid, p["log2_feps"], cfg.rounding)
    R, s = row_sums(L)
    st = st._replace(R=R, s=s, n_since_refresh=jnp.array(0, jnp.int64), dirty=jnp.array(False),
                     rezoom=jnp.array(False))
    still_full = cfg.capacity - jnp.sum(st.valid) < cfg.n_prod + 2
    return _stop(st, still_full, STATUS.CAPACITY)


def _monodisperse_state(cfg: _Cfg, p: dict, N, m0, struct0, key):
    """Initial state: one species of N monomers of mass m0, V = N m0 / rho_d (thesis App. 5.B)."""
    S, P = cfg.capacity, cfg.n_struct
    f = jnp.float64
    valid = jnp.zeros((S,), bool).at[0].set(True)
    m = jnp.ones((S,), f).at[0].set(m0)
    logm = jnp.zeros((S,), f).at[0].set(jnp.log(m0))
    psi = jnp.zeros((S, P), f).at[0].set(struct0)
    w = jnp.zeros((S,), f).at[0].set(N)
    z = jnp.zeros((S,), jnp.int32)
    M_tot = N * m0
    logV = jnp.log(N) + jnp.log(m0) - jnp.log(p["rho_d"])
    log_mstar = jnp.log(N) + jnp.log(m0) - jnp.log(p["ns_target"])
    if cfg.mode != "const_v":
        log_mstar = jnp.log(m0)
    return _blank_state(cfg, m, logm, psi, w, z, valid, logV, M_tot, log_mstar, key)


def _species_state(cfg: _Cfg, p: dict, init, key):
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
    logV = logM - jnp.log(p["rho_d"]) if init.V is None else jnp.log(init.V)
    log_mstar = logM - jnp.log(p["ns_target"]) if cfg.mode == "const_v" else jnp.min(jnp.log(init.m))
    return _blank_state(cfg, m, logm, psi, w, z, valid, logV, M_tot, log_mstar, key)


def _n_nodes(cfg):
    return cfg.n_bins + (cfg.capacity if cfg.count_zoom is not None else 0)


def _blank_state(cfg, m, logm, psi, w, z, valid, logV, M_tot, log_mstar, key):
    f = jnp.float64
    S = cfg.capacity
    return MCState(m=m, logm=logm, psi=psi, w=w, z=z, valid=valid, R=jnp.zeros((S,), f), s=jnp.array(0.0),
                   logV=logV, M_tot=M_tot, t=jnp.array(0.0), n_events=jnp.array(0, jnp.int64),
                   n_since_refresh=jnp.array(0, jnp.int64), dirty=jnp.array(True), rezoom=jnp.array(True),
                   log_mstar=log_mstar, zref=log_mstar, zoom_xp=jnp.arange(_n_nodes(cfg), dtype=f),
                   zoom_fp=jnp.zeros((_n_nodes(cfg),), f), key=key, k_out=jnp.array(0, jnp.int32),
                   status=jnp.array(0, jnp.int32), done=jnp.array(False), n_dup=jnp.array(0, jnp.int64),
                   n_merge=jnp.array(0, jnp.int64), snaps=None)


def _check_stop(cfg, p, before, after):
    """Apply the user stop predicate after an executed event (STATUS.STOPPED)."""
    if p.get("stop") is None:
        return after
    hit = (after.n_events > before.n_events) & jnp.asarray(p["stop"](after), bool)
    return _stop(after, hit, STATUS.STOPPED)


def _start(cfg: _Cfg, p: dict, st: MCState):
    """Fresh snapshot buffers, k_out = 0; a resumed state that had halted (event budget spent,
    stopped by the predicate, or out of capacity) stays halted; the stop predicate is also
    checked on the initial state."""
    T, S, P = cfg.n_snap, cfg.capacity, cfg.n_struct
    f = jnp.float64
    snaps = Snapshots(m=jnp.ones((T, S), f), logm=jnp.zeros((T, S), f), psi=jnp.zeros((T, S, P), f),
                      w=jnp.zeros((T, S), f), z=jnp.zeros((T, S), jnp.int32), valid=jnp.zeros((T, S), bool),
                      logV=jnp.zeros((T,), f), M_tot=jnp.zeros((T,), f), n_events=jnp.zeros((T,), jnp.int64))
    st = st._replace(snaps=snaps, k_out=jnp.array(0, jnp.int32), done=jnp.array(False))
    full = (cfg.capacity - jnp.sum(st.valid) < cfg.n_prod + 2) & ((st.status & STATUS.CAPACITY) != 0)
    halted = (st.n_events >= p["max_events"]) | ((st.status & STATUS.STOPPED) != 0) | full
    st = st._replace(done=halted)
    if p.get("stop") is not None:
        st = _stop(st, ~halted & jnp.asarray(p["stop"](st), bool), STATUS.STOPPED)
    return st


def _simulate(cfg: _Cfg, p: dict, init):
    """One run from ``init``: ("mono", N, m0, struct0, key), ("species", InitialSpecies, key)
    or ("resume", MCState)."""
    if init[0] == "mono":
        st = _monodisperse_state(cfg, p, *init[1:])
    elif init[0] == "species":
        st = _species_state(cfg, p, *init[1:])
    else:
        st = init[1]
    st = _start(cfg, p, st)

    def inner_cond(s):
        return ~s.done & ~s.dirty

    def outer_body(s):
        # maintenance only when due (always true here except right after a resume, where a
        # refresh would change R and break bitwise equality with the uninterrupted run)
        s = jax.lax.cond(s.dirty, lambda s_: _maintenance(cfg, p, s_), lambda s_: s_, s)
        return jax.lax.while_loop(inner_cond, lambda s_: _check_stop(cfg, p, s_, _event(cfg, p, s_)), s)

    st = jax.lax.while_loop(lambda s: ~s.done, outer_body, st)
    st = _fill(cfg, p, st, jnp.inf)  # remaining snapshots repeat the final state (exact for ZERO_RATE)
    sn = st.snaps
    t_stop = jnp.where((st.status & STATUS.STOPPED) != 0, st.t, jnp.nan)
    return MCResult(t=p["t_out"], m=sn.m, logm=sn.logm, psi=sn.psi, w=sn.w, z=sn.z, valid=sn.valid,
                    V=jnp.exp(sn.logV), logV=sn.logV, M_tot=sn.M_tot, n_events_snap=sn.n_events,
                    status=st.status, n_events=st.n_events, n_dup=st.n_dup, n_merge=st.n_merge,
                    t_stop=t_stop, final_state=st._replace(snaps=None), config=_config_pairs(cfg, p))


def _config_pairs(cfg: _Cfg, p: dict):
    """Static run configuration as (name, value) pairs (MCResult.config / dataset attributes)."""
    out = [(k, v if isinstance(v, (int, float, str, bool)) else repr(v)) for k, v in dataclasses.asdict(cfg).items()]
    out.append(("kernel", type(p["kernel"]).__name__))
    out.append(("outcome", type(p["outcome"]).__name__))
    stop = p.get("stop")
    out.append(("stop", "none" if stop is None else (repr(stop) if isinstance(stop, eqx.Module) else getattr(stop, "__name__", "callable"))))
    return tuple((k, "none" if v is None else v) for k, v in out)


_simulate_jit = eqx.filter_jit(_simulate)


# ----------------------------------------------------------------------------- public API

def _int_option(name, value, lo, what, allow_none=False):
    """Refuse a non-integer or too-small static integer option with a message naming it."""
    if value is None and allow_none:
        return
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise JaxcoagInputError(f"`{name}` must be an integer >= {lo} ({what}); got {value!r}")
    if int(value) < lo:
        raise JaxcoagInputError(f"`{name}` must be >= {lo} ({what}); got {int(value)}")


def run(kernel, *, n_particles=None, m0=1.0, rho_d=None, t_out, key=None, mode="const_v", grouping=None,
        ns_target=1000, f_eps=1e-3, capacity=None, outcome=None, struct0=None, max_events=10**8,
        rates="incremental", n_refresh=None, neps_rounding="ceil", controller=None, n_bins=20,
        p_protect=16, merge_weighting="mass", dedupe=True, d_max=64, d_up=2, n_rezoom=None,
        m_lo=None, leftover="demagnify", initial=None, resume_from=None, stop=None, tail_events=0.0,
        count_groups=None, tail_wmax=None):
    """Grouped Monte Carlo coagulation (Ormel & Spaans 2008) of a monodisperse or custom start.

    Arguments:
        kernel: ``jaxcoag.kernels.AbstractKernel`` giving K [cm^3 s^-1]; rates use
            ``kernel.log_kernel_from_log_mass`` so masses up to and beyond 1e160 m0 work.
        n_particles: initial number of physical particles of mass m0 (may be 1e160; > 0) for
            the monodisperse start. The simulated volume is V = n_particles m0 / rho_d [cm^3].
            Give either n_particles or ``initial``.
        m0: monomer mass [g] (> 0).
        rho_d: dust mass density [g cm^-3] (> 0; default 1); kept fixed in const_n / const_ns.
            With ``initial`` carrying a volume V, rho_d = M_tot / V instead (do not give both).
        t_out: 1-D non-negative strictly increasing output times [s]; the state recorded at
            t_out[k] is the state after the last event with time ≤ t_out[k].
        key: a ``jax.random`` key (one PRNG key per event is derived with ``fold_in``). Required
            unless ``resume_from`` is given (then it defaults to, and must equal, the state's key).
        mode: "const_v" (fixed volume, exact mass conservation), "const_n" (one group
            duplicated per event, Smith & Matsoukas 1998; V = M_tot/rho_d) or "const_ns"
            (duplication controller keeping the species/group count near ``ns_target``).
        grouping: None (exact species DSMC, eqs. 5.6/5.7), "equal_mass" (eq. 5.14; const_v:
            m* = n_particles m0/ns_target, otherwise m* = m_p = M2/M1) or "distribution"
            (equal number of groups per log-mass bin, ``n_bins`` bins; ns_target = Ng*).
        ns_target: Ns* (equal-mass / const_ns) or Ng* (distribution); default 1000.
        f_eps: maximum fractional mass gain per group event (eq. 5.11); default 1e-3.
        capacity: number of species slots S (static). Default: none: min(n_particles, 2048)+8;
            equal_mass: 8 ns_target; distribution: 2 ns_target. An equal-mass run whose capacity cannot
            hold Ns* species is refused up front (``min_capacity``); a distribution run keeps at most
            min(0.9 S, Ng*) species (scheduled merges of mass neighbours); a run that still runs out of slots
            merges mass neighbours (status CAPACITY) and warns with ``CapacityWarning``; under a
            user's jit/vmap the flag is only in ``status`` (check it there).
        outcome: an ``AbstractOutcome`` (default ``PerfectSticking()``); e.g.
            ``CatastrophicFragmentation(m_frag, m0)``.
        struct0: initial structural vector (shape (P,), P ≥ 0) of the monomers; default empty
            (or zeros of ``kernel.n_struct``). Merged mass-weighted on sticking.
        max_events: event budget; when reached the run stops with STATUS.MAX_EVENTS.
        rates: "incremental" (design B: O(S) per event, full refresh every ``n_refresh``
            events, default S) or "full" (design A: O(S^2) recomputation every event).
        neps_rounding: "ceil" (default) or "floor" (thesis-literal) for N_eps (eq. 5.12).
        controller: const_ns duplication controller: "mass" (default with equal_mass:
            duplicate while M_tot < ns_target m_p, at most ``d_max`` per event) or "species"
            (default otherwise: ``d_up`` duplications after each event while Ns < ns_target).
        n_bins: distribution-method bin count (default 20). m_lo: its lowest mass [g] (m0).
        p_protect: the most massive species never merged (default 16).
        initial: custom initial population from ``jaxcoag.mc.initial_species(m, g | log_g | (w, z),
            psi=..., V=...)`` instead of the monodisperse start; V defaults to M_tot / rho_d.
            Equal-mass const_v then uses m* = M_tot / ns_target, the distribution method
            m_lo = min(m) unless given. With grouping=None the given zooms are kept.
        resume_from: ``result.final_state`` of an earlier run: continue that run over the new
            ``t_out`` (its first time must not precede the state's time). Pass the same other
            arguments as the original call (kernel, mode, grouping, ns_target, f_eps,
            max_events, m_lo, ...; n_particles / initial are then only used for defaults): the
            continuation equals one uninterrupted run over both time ranges bitwise (same
            backend; event keys come from the base key and the event counter, maintenance
            counters live in the state). ``max_events`` counts events of the whole run.
            See also ``jaxcoag.mc.run_checkpointed``.
        stop: optional stop predicate: a ``jaxcoag.mc.AbstractStop`` such as
            ``jaxcoag.mc.Runaway(1e4)`` or any jittable function of the ``MCState``; checked after
            every event; when true the run stops with ``STATUS.STOPPED``, ``result.t_stop`` is
            the event time and later snapshots repeat the stopped state.
        merge_weighting: "mass" (default), "number" (thesis formula) or "volume".
        dedupe: add a product to an existing identical species instead of a new slot (exact).
        n_rezoom: distribution method: global rezoom every n_rezoom events (default
            max(1, ns_target // 16)); also when M_L1 changes by 2^(1/4).
        leftover: "demagnify" (thesis; exact) or "stochastic" (a donor left with 0 < w < 1
            groups keeps one whole group with probability w, else is deleted: unbiased in
            expectation, stops the demagnify cascade of MC hazard 3; in const_v the
            simulated mass then fluctuates, in const_n/const_ns V is rescaled to keep rho_d).
        count_groups: distribution method, runaway kernels (default None = off): G_c > 0 of the
            tail-count refinement (``grouping.count_nodes``). The zoom becomes min(thesis z(m),
            log2(C(m)/G_c)) with C(m) the number of particles at least as heavy as m, i.e. bins
            equally spaced in ln C: where the count falls steeply with mass (the seed tail of a
            runaway kernel) every species keeps >~ G_c groups and the rarest are single particles.
            It only refines (lowers) the thesis zoom. [own; the zoom weakness of docs/design_notes.md]
        tail_events: distribution method (default 0 = off): time-resolution cap of the zoom
            (``grouping.zoom_cap_tail``): every species gets at least ``tail_events`` expected
            group events per elapsed time t, w_i >= tail_events / (r_i t) (r_i = collisions per
            particle per time), at most ``tail_wmax`` groups. This is the thesis' "demagnify the
            monomers so that t_11 << t_R" (§5.3.3) made automatic and applied to every species:
            the rare upward jumps that seed a runaway are sampled with quanta no larger than the
            expected outflow. Costs ~tail_events x Ns events per e-fold of t. Use with
            ``count_groups`` for K = (m_i m_j)^nu, nu > 1 (Fig 5.7); not for non-runaway kernels
            (it over-resolves the bulk and inflates the event count).
        tail_wmax: the largest number of groups per species the time cap may create (default
            ``ns_target``); runaway runs need tail_wmax >> tail_events / t_R.

    Returns:
        ``MCResult`` with per-snapshot species arrays, volume, ``mass_per_bin``, ``moments``,
        M_L1/M_L2, ``to_xarray``, ``status`` (bit flags of ``STATUS``), event counts,
        ``t_stop`` and ``final_state`` (for ``resume_from``). Not differentiable (discrete
        sampling); jit-compiled; batch over keys, kernel parameters or initial states with
        ``jax.vmap``.

    References: Ormel & Spaans (2008) ApJ 684, 1291 = Ormel (2008) thesis ch. 5, eqs.
        (5.6)-(5.14), (5.31)-(5.33), App. 5.B; §2.3.2 (constant-N/Ns); docs/design_notes.md.
    """
    require_x64("jaxcoag.mc.run")
    if not isinstance(kernel, AbstractKernel):
        raise JaxcoagInputError("`kernel` must be a jaxcoag.kernels.AbstractKernel (e.g. jaxcoag.kernels.Constant(1.0))")
    if mode not in _MODES:
        raise JaxcoagInputError(f"unknown mode {mode!r}; use one of {_MODES}")
    if grouping not in _GROUPINGS:
        raise JaxcoagInputError(f"unknown grouping {grouping!r}; use None, 'equal_mass' or 'distribution'")
    if rates not in ("incremental", "full"):
        raise JaxcoagInputError(f"unknown rates {rates!r}; use 'incremental' or 'full'")
    if neps_rounding not in ("ceil", "floor"):
        raise JaxcoagInputError(f"unknown neps_rounding {neps_rounding!r}; use 'ceil' or 'floor'")
    if merge_weighting not in ("mass", "number", "volume"):
        raise JaxcoagInputError(f"unknown merge_weighting {merge_weighting!r}; use 'mass', 'number' or 'volume'")
    if leftover not in ("demagnify", "stochastic"):
        raise JaxcoagInputError(f"unknown leftover {leftover!r}; use 'demagnify' or 'stochastic'")
    if controller is None:
        controller = "mass" if grouping == "equal_mass" else "species"
    if controller not in ("mass", "species"):
        raise JaxcoagInputError(f"unknown controller {controller!r}; use 'mass' or 'species'")
    if outcome is None:
        outcome = PerfectSticking()
    if not isinstance(outcome, AbstractOutcome):
        raise JaxcoagInputError("`outcome` must be a jaxcoag.mc.AbstractOutcome (e.g. PerfectSticking())")
    def _f(x):  # Python/numpy ints -> float before validation (check() casts int arrays lazily)
        return float(x) if isinstance(x, (int, np.integer)) and not isinstance(x, bool) else x

    if resume_from is None and (n_particles is None) == (initial is None):
        raise JaxcoagInputError("give exactly one of n_particles= (monodisperse start) or initial= "
                                "(jaxcoag.mc.initial_species(...)), or resume_from= a result's final_state")
    if n_particles is not None and initial is not None:
        raise JaxcoagInputError("give either n_particles= or initial=, not both")
    if initial is not None and not isinstance(initial, InitialSpecies):
        raise JaxcoagInputError("`initial` must come from jaxcoag.mc.initial_species(m, g=... | log_g=... | w=..., z=...)")
    if resume_from is not None and not (isinstance(resume_from, MCState) and resume_from.snaps is None):
        raise JaxcoagInputError("`resume_from` must be the `final_state` of an MCResult (or a state loaded by run_checkpointed)")
    if resume_from is not None and jnp.ndim(resume_from.t) != 0:
        raise JaxcoagInputError("`resume_from` holds a batch of states (from a vmapped run); resume inside jax.vmap "
                                "or index one member with jax.tree_util.tree_map(lambda x: x[i], state)")
    if resume_from is None and key is None:
        raise JaxcoagInputError("give `key`, a jax.random key (e.g. jax.random.key(0))")
    if stop is not None and not callable(stop):
        raise JaxcoagInputError("`stop` must be a jaxcoag.mc.AbstractStop (e.g. jaxcoag.mc.Runaway(1e4)) or a function of the state")
    if not is_traced(max_events) and int(max_events) < 1:
        raise JaxcoagInputError("`max_events` must be >= 1")
    _int_option("capacity", capacity, 1, "the number of species slots, e.g. 8 * ns_target", allow_none=True)
    _int_option("n_refresh", n_refresh, 1, "events between full rate refreshes (default: capacity)", allow_none=True)
    _int_option("n_rezoom", n_rezoom, 1, "events between global rezooms (default ns_target // 16)", allow_none=True)
    _int_option("n_bins", n_bins, 1, "the number of log-mass bins of the distribution method (default 20)")
    _int_option("p_protect", p_protect, 0, "the number of most massive species never merged (default 16)")
    _int_option("d_max", d_max, 1, "the most duplications per event in const_ns (default 64)")
    _int_option("d_up", d_up, 1, "duplications after each event in const_ns (default 2)")
    if isinstance(tail_events, bool) or not isinstance(tail_events, (int, float, np.integer, np.floating)) \
            or not (float(tail_events) >= 0.0 and math.isfinite(float(tail_events))):
        raise JaxcoagInputError(f"`tail_events` must be a finite number >= 0 (0 = off); got {tail_events!r}")
    if float(tail_events) > 0 and grouping != "distribution":
        raise JaxcoagInputError("`tail_events` > 0 only applies to grouping='distribution'")
    for name, val in (("count_groups", count_groups), ("tail_wmax", tail_wmax)):
        if val is None:
            continue
        if isinstance(val, bool) or not isinstance(val, (int, float, np.integer, np.floating)) \
                or not (math.isfinite(float(val)) and float(val) >= 1.0):
            raise JaxcoagInputError(f"`{name}` must be a finite number >= 1 (groups) or None; got {val!r}")
        if grouping != "distribution":
            raise JaxcoagInputError(f"`{name}` only applies to grouping='distribution'")
    if key is not None and not (isinstance(key, jax.Array) and jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key)):
        if not (isinstance(key, jax.Array) and key.dtype == jnp.uint32 and key.shape[-1:] == (2,)):
            raise JaxcoagInputError(f"`key` must be a jax.random key such as jax.random.key(0); got {type(key).__name__} {key!r}")
    if initial is not None and initial.V is not None and rho_d is not None:
        raise JaxcoagInputError("give either rho_d= or a volume V in initial_species(...), not both (rho_d = M_tot / V)")
    if rho_d is None:
        rho_d = 1.0
    n_particles, m0, rho_d, f_eps, ns_target = map(_f, (n_particles, m0, rho_d, f_eps, ns_target))
    if n_particles is not None:
        n_particles = check(n_particles, "n_particles", positive=True, hint="give the initial number of physical particles (> 0)")
    m0 = check(m0, "m0", positive=True, hint="give the monomer mass in g (> 0)")
    rho_d = check(rho_d, "rho_d", positive=True, hint="give the dust mass density in g cm^-3 (> 0)")
    f_eps = check(f_eps, "f_eps", positive=True, hint="use a small fraction such as 1e-3")
    ns_target = check(ns_target, "ns_target", positive=True, hint="give the target number of species/groups (e.g. 1000)")
    if initial is not None:
        lg0 = jnp.log(initial.w) + initial.z.astype(jnp.float64) * LN2
        logM0 = jax.nn.logsumexp(lg0 + jnp.log(initial.m))
        if initial.V is not None:
            rho_d = jnp.exp(logM0 - jnp.log(initial.V))
        if not is_traced(logM0) and float(logM0) >= math.log(1e300):
            raise JaxcoagInputError("initial: the total mass sum(g m) must stay below 1e300 g (float64 range)")
    if n_particles is not None and not is_traced(n_particles) and not is_traced(m0):
        if float(n_particles) * float(m0) >= 1e300:
            raise JaxcoagInputError("n_particles * m0 must stay below 1e300 g (float64 range); reduce n_particles")
        if grouping is None and float(n_particles) > 2.0 ** 53:
            raise JaxcoagInputError("grouping=None needs n_particles <= 2^53 (integer multiplicities); use grouping='equal_mass' or 'distribution'")
    t_arr = t_out if is_traced(t_out) else jnp.asarray(t_out, jnp.float64)
    if t_arr.ndim != 1 or t_arr.shape[0] < 1:
        raise JaxcoagInputError("`t_out` must be a non-empty 1-D array of output times in s")
    if not is_traced(t_out):
        tv = np.asarray(t_arr)
        if not np.all(np.isfinite(tv)) or np.any(tv < 0):
            raise JaxcoagInputError("`t_out` must be finite and >= 0")
        if np.any(np.diff(tv) <= 0):
            raise JaxcoagInputError("`t_out` must be strictly increasing; sort it and drop duplicates")
    else:
        t_arr = eqx.error_if(t_arr, jnp.any(jnp.diff(t_arr) <= 0) | jnp.any(t_arr < 0),
                             "`t_out` must be >= 0 and strictly increasing")
    if resume_from is not None:
        S_r = int(resume_from.m.shape[-1])
        if capacity is not None and int(capacity) != S_r:
            raise JaxcoagInputError(f"resume_from has capacity {S_r}; drop `capacity` or pass {S_r}")
        capacity = S_r
        if not is_traced(resume_from.t) and not is_traced(t_arr) and float(t_arr[0]) < float(resume_from.t):
            raise JaxcoagInputError(f"t_out[0] = {float(t_arr[0])} precedes the resumed state's time "
                                    f"{float(resume_from.t)}; continue with later output times")
        if key is not None and not is_traced(key) and not is_traced(resume_from.key):
            same = np.array_equal(np.asarray(jax.random.key_data(key)), np.asarray(jax.random.key_data(resume_from.key)))
            if not same:
                raise JaxcoagInputError("`key` differs from the resumed state's key; pass the same key or key=None")
        struct0 = resume_from.psi[0]
    elif initial is not None:
        P0 = int(initial.psi.shape[-1])
        if P0 == 0 and kernel.n_struct > 0:
            initial = eqx.tree_at(lambda x: x.psi, initial, jnp.zeros((initial.m.shape[0], kernel.n_struct), jnp.float64))
        elif P0 < kernel.n_struct:
            raise JaxcoagInputError(f"the kernel reads {kernel.n_struct} structural parameters; give initial psi with that many columns")
        struct0 = initial.psi[0]
    if struct0 is None:
        struct0 = jnp.zeros((kernel.n_struct,), jnp.float64)
    struct0 = check(jnp.atleast_1d(jnp.asarray(struct0, jnp.float64)) if not is_traced(struct0) else struct0,
                    "struct0", hint="give a finite vector of structural parameters")
    if struct0.ndim != 1:
        raise JaxcoagInputError("`struct0` must be a 1-D vector of structural parameters")
    if struct0.shape[0] < kernel.n_struct:
        raise JaxcoagInputError(f"the kernel reads {kernel.n_struct} structural parameters; give struct0 with that many entries")
    n_init = 1 if initial is None else int(initial.m.shape[0])
    if capacity is None:
        if grouping is None:
            n_p = n_particles if initial is None else jnp.exp(jax.nn.logsumexp(lg0))
            if is_traced(n_p):
                raise JaxcoagInputError("give `capacity` when the initial particle numbers are traced (vmapped/jitted)")
            capacity = max(int(min(float(n_p), 2048)) + 8, n_init + outcome.n_products + 4)
        else:
            if is_traced(ns_target):
                raise JaxcoagInputError("give `capacity` when ns_target is traced (vmapped/jitted)")
            capacity = int(8 * float(ns_target)) if grouping == "equal_mass" else int(2 * float(ns_target))
            capacity = max(capacity, 64)
    capacity = int(capacity)
    if capacity < outcome.n_products + 4:
        raise JaxcoagInputError(f"capacity must be at least {outcome.n_products + 4}")
    if resume_from is None and capacity < n_init + outcome.n_products + 2:
        raise JaxcoagInputError(f"capacity {capacity} cannot hold the {n_init} initial species; give capacity >= "
                                f"{n_init + outcome.n_products + 2}")
    if grouping == "equal_mass" and not is_traced(ns_target):
        # Ns* is a species count and the merge threshold a fraction of S: a smaller S would silently
        # cap the species count below ns_target (a coarser run than asked for); refuse instead. (With
        # grouping="distribution" ns_target = Ng* counts groups, not species; there the capacity is the
        # documented species cap min(0.9 S, Ng*), e.g. Fig. 5.7 runs Ng* = 2000 in S = 1024 slots.)
        s_min = min_capacity(grouping, float(ns_target), int(outcome.n_products))
        if capacity < s_min:
            raise JaxcoagInputError(
                f"capacity = {capacity} species slots cannot hold ns_target = {float(ns_target):g} {grouping} species "
                f"(the run merges species above ~0.9 capacity, which would silently lower the resolution); give "
                f"capacity >= {s_min} (the default is {'8' if grouping == 'equal_mass' else '2'} x ns_target) "
                "or lower ns_target")
    cfg = _Cfg(mode=mode, grouping=grouping, capacity=capacity, n_snap=int(t_arr.shape[0]),
               n_struct=int(struct0.shape[0]), n_prod=int(outcome.n_products), rates=rates,
               n_refresh=int(n_refresh if n_refresh is not None else (1 if rates == "full" else capacity)),
               rounding=neps_rounding, controller=controller, d_max=int(d_max), d_up=int(d_up),
               n_bins=int(n_bins), p_protect=int(p_protect), weighting=merge_weighting, dedupe=bool(dedupe),
               n_rezoom=int(n_rezoom if n_rezoom is not None else
                            (max(1, int(float(ns_target)) // 16) if not is_traced(ns_target) else 64)),
               leftover=leftover, tail_events=float(tail_events),
               count_zoom=(math.log(float(count_groups)) if count_groups is not None else None))
    if rates == "full":
        cfg = dataclasses.replace(cfg, n_refresh=1)
    if m_lo is not None:
        log_mlo = jnp.log(check(m_lo, "m_lo", positive=True, hint="give the lowest mass of the distribution bins in g"))
    elif initial is not None:
        log_mlo = jnp.min(jnp.log(initial.m))
    else:
        log_mlo = jnp.log(m0)
    p = dict(kernel=kernel, outcome=outcome, rho_d=rho_d, log2_feps=jnp.log2(f_eps), ns_target=ns_target,
             t_out=t_arr, max_events=jnp.asarray(max_events, jnp.int64), log_mlo=log_mlo, stop=stop,
             tail_wmax=(ns_target if tail_wmax is None else jnp.asarray(float(tail_wmax))))
    if resume_from is not None:
        init = ("resume", resume_from)
    elif initial is not None:
        init = ("species", initial, key)
    else:
        init = ("mono", n_particles, m0, struct0, key)
    res = _simulate_jit(cfg, p, init)
    # out of species slots (emergency merge, STATUS.CAPACITY) lowers the resolution: say so. Inside
    # the user's jit/vmap the flag is in res.status (failures are values): a host callback there
    # would be unrolled once per vmapped lane (a 2e4-lane vmap then never finished compiling).
    if not is_traced(res.status):
        _warn_capacity(res.status, capacity)
    return jax.tree_util.tree_map(lambda x: jax.lax.stop_gradient(x) if eqx.is_inexact_array(x) else x, res)
