"""The Monte Carlo event loop works on the active prefix [0, hi) of the species arrays, in blocks
(``jaxcoag.mc.run``: ``_fold``, ``_refresh``, ``_inc_update``, ``_pick_blocked``, ``_pick_partner``),
so that the cost per event does not depend on the capacity (issue 17).

Checked here against the dense O(S^2) formulas of :mod:`jaxcoag.mc.rates` (Ormel 2008 eqs. 5.7, 5.13,
5.31) on states with holes, several blocks and a clamped last block: the blocked refresh equals the
dense row sums; the blocked incremental update after executed events equals a fresh refresh; the two
blocked samplers draw with the probabilities of the dense weights (chi-square); and a run gives the
same events at two capacities (the capacity no longer enters the per-event computation); the event's
write overlay (``run._Overlay``) behaves like the chain of single-slot updates it replaces; and the compiled
event loop updates the species arrays in place (no S-slot copy per event).
"""

import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

import jaxcoag as jc
from jaxcoag import kernels as K
from jaxcoag import mc
from jaxcoag.mc.rates import log_rate_matrix, row_sums
from jaxcoag.mc.state import MCState

RUN = sys.modules["jaxcoag.mc.run"]
RATES = sys.modules["jaxcoag.mc.rates"]
S = 300          # capacity: with block = 32 the kernel passes use 10 blocks (last start clamped to 268),
BLOCK = 32       # the cheap passes (4 x 32 = 128) 3 blocks (last start clamped to 172)


def _cfg(rates="incremental", linear=True):
    return RUN._Cfg(mode="const_v", grouping=None, capacity=S, n_snap=1, n_struct=0, n_prod=1, rates=rates,
                    n_refresh=10**6, rounding="ceil", controller="species", d_max=1, d_up=1, n_bins=3, p_protect=0,
                    weighting="mass", dedupe=True, n_rezoom=1, block=BLOCK, linear_rates=linear)


def _state(seed=0, n_live=260):
    """A state whose valid slots are spread over [0, 290) with holes: masses over 12 decades, zooms
    0-40, fractional w at z = 0 (the partial-event branch), repeated masses (own-pair branch)."""
    rng = np.random.default_rng(seed)
    hi = 290
    valid = np.zeros(S, bool)
    valid[np.sort(rng.choice(hi - 1, n_live - 1, replace=False))] = True
    valid[hi - 1] = True
    m = np.where(valid, 10.0 ** rng.uniform(0, 12, S), 1.0)
    m[np.flatnonzero(valid)[:5]] = 7.0   # five species of one mass: rows with equal kernel values
    z = np.where(valid, rng.integers(0, 41, S), 0).astype(np.int32)
    w = np.where(valid, rng.uniform(1.0, 50.0, S), 0.0)
    frac = valid & (z == 0) & (rng.uniform(size=S) < 0.3)
    w[frac] = rng.uniform(0.2, 1.9, frac.sum())
    f = jnp.float64
    st = MCState(m=jnp.asarray(m, f), logm=jnp.log(jnp.asarray(m, f)), psi=jnp.zeros((S, 0)), w=jnp.asarray(w, f),
                 z=jnp.asarray(z), valid=jnp.asarray(valid), R=jnp.zeros(S), s=jnp.array(0.0), logV=jnp.array(0.0),
                 M_tot=jnp.asarray(float(np.sum(np.where(valid, w * 2.0 ** z * m, 0.0)))), t=jnp.array(0.0),
                 n_events=jnp.array(0, jnp.int64), n_since_refresh=jnp.array(1, jnp.int64), dirty=jnp.array(False),
                 rezoom=jnp.array(False), log_mstar=jnp.array(0.0), zref=jnp.array(0.0), zoom_xp=jnp.arange(3.0),
                 zoom_fp=jnp.zeros(3), key=jax.random.key(seed), k_out=jnp.array(0, jnp.int32),
                 status=jnp.array(0, jnp.int32), done=jnp.array(False), n_dup=jnp.array(0, jnp.int64),
                 n_merge=jnp.array(0, jnp.int64), log_rho_d=jnp.array(0.0), log_mlo=jnp.array(0.0), snaps=None,
                 hi=jnp.array(hi, jnp.int32), ns=jnp.array(n_live, jnp.int32))
    return st


P = dict(kernel=K.Sum(0.5), outcome=jc.outcomes.Sticking(), log2_feps=jnp.log2(1e-3))


def _dense(st):
    L = log_rate_matrix(P["kernel"], st.logm, st.psi, st.w, st.z, st.valid, P["log2_feps"])
    return row_sums(L)


def _with_dense(st):
    """The state with its dense row sums (R, s)."""
    R, s = _dense(st)
    return st._replace(R=R, s=s)


def _update_event(cfg):
    """Jitted executed event on the pair (a, b): ``run._collide``, then ``run._inc_update`` with the pre-event
    range (as the event loop passes it); returns (state, (ln max m, ln M1, ln M2))."""
    @jax.jit
    def event(st, a, b, key):
        st2, T, Tm, old = RUN._collide(cfg, P, st, a, b, key)
        return RUN._inc_update(cfg, P, old, st2, T, Tm, True, RUN._range(cfg, st))
    return event


@pytest.mark.parametrize("scale", [0.0, 30.0])
def test_blocked_refresh_equals_dense_row_sums(scale):
    """The blocked refresh (upper triangle of tiles) against the dense row sums, with its linear-space tiles
    (the sum kernel's default; they are scaled by the previous scale ``st.s``, here 0 and 30) and with the log-space
    tiles; on the state of :func:`_extreme` the linear form is refused and the result is the log-space one
    bitwise."""
    st = _state()._replace(s=jnp.array(scale))
    Rd, sd = jax.jit(_dense)(st)
    out = {}
    for lin in (True, False):
        R, s = out[lin] = jax.jit(lambda st: RUN._refresh(_cfg(linear=lin), P, st))(st)
        assert float(s) == pytest.approx(float(sd), rel=1e-14, abs=1e-12)
        np.testing.assert_allclose(np.asarray(R), np.asarray(Rd), rtol=1e-12, atol=1e-300)
        assert np.all(np.asarray(R)[~np.asarray(st.valid)] == 0.0)
        assert np.count_nonzero(np.asarray(R)) == int(st.ns)
    assert not np.array_equal(np.asarray(out[True][0]), np.asarray(out[False][0]))   # two ways to the same sums
    ext = _extreme(st)
    Rl, sl = jax.jit(lambda st: RUN._refresh(_cfg(linear=True), P, st))(ext)
    Rg, sg = jax.jit(lambda st: RUN._refresh(_cfg(linear=False), P, st))(ext)
    np.testing.assert_array_equal(np.asarray(Rl), np.asarray(Rg))
    assert float(sl) == float(sg)


def _extreme(st):
    """The state with one multiplicity of 1e300: the scale s of the row sums is then ~e^700, and the linear-space
    factor r_a = ½ w_a e^{-s} of a row with w_a ~ 1 would be subnormal (precision lost): the event loop must take
    the log-space tiles."""
    live = np.flatnonzero(np.asarray(st.valid))
    return st._replace(w=st.w.at[live[7]].set(1e300))


@pytest.mark.slow
@pytest.mark.parametrize("linear", [True, False, "extreme"])
def test_blocked_incremental_update_after_events_equals_refresh(linear):
    """(slow: ~20 s of compile; every default Monte Carlo run goes through the same update, checked
    there against analytic solutions.) Ten executed events (random pairs, own pairs, deduplicated products, dying donors) with the
    blocked incremental update; the row sums then equal a fresh dense computation. Both ways the update takes a
    touched row's old rates are used: the scaled new rate (w_old/w_new) and the full formula (a donor that lived
    before and after with a fractional multiplicity or a new zoom). Both tile forms: linear space (the sum kernel's
    default on this state) and log space; on the state of :func:`_extreme` the range guard must fall back to the
    log-space update (bitwise; mutation-checked: with the guard forced open the R arrays differ).""" 
    cfg = _cfg(linear=bool(linear))
    st = _state(seed=1)
    st = _with_dense(_extreme(st) if linear == "extreme" else st)
    event = _update_event(cfg)
    event_log = _update_event(_cfg(linear=False)) if linear == "extreme" else None

    dense = jax.jit(_dense)
    live = np.flatnonzero(np.asarray(st.valid))
    rng = np.random.default_rng(3)
    pairs = [(live[0], live[0]), (live[-1], live[3])] + [tuple(rng.choice(live, 2)) for _ in range(8)]
    # a donor with 1 < w < 2 as the lower-zoom member (it gives one group): it lives on with w < 1
    w_, z_ = np.asarray(st.w), np.asarray(st.z)
    t = next(x for x in live if 1.0 < w_[x] < 2.0 and np.any(z_[live] > z_[x]))
    pairs.insert(1, (t, next(x for x in live if z_[x] > z_[t])))
    kinds = set()
    for k, (a, b) in enumerate(pairs):
        v = np.asarray(st.valid)
        if not (v[a] and v[b]):
            continue
        w0, z0 = np.asarray(st.w), np.asarray(st.z)
        st_in = st
        st = event(st, jnp.int32(a), jnp.int32(b), jax.random.key(k))[0]
        if event_log is not None:   # the range guard rejects the linear tiles: the log-space update, bitwise
            np.testing.assert_array_equal(np.asarray(st.R), np.asarray(event_log(st_in, jnp.int32(a), jnp.int32(b),
                                                                                 jax.random.key(k))[0].R))
        w1, z1, v1 = np.asarray(st.w), np.asarray(st.z), np.asarray(st.valid)
        for t in {a, b}:   # the donors: which way _inc_update took their old rates
            if v[t] and v1[t]:
                kinds.add("scaled" if (z0[t] == z1[t] and w0[t] >= 1 and w1[t] >= 1) else "full formula")
        assert int(st.ns) == int(np.sum(np.asarray(st.valid)))
        assert int(st.hi) >= int(np.max(np.flatnonzero(np.asarray(st.valid)))) + 1
        # after every event (a wrong old rate of one row shows at once; later events overwrite much of it)
        Rd, sd = dense(st)
        got = np.asarray(st.R) * np.exp(float(st.s) - float(sd))
        np.testing.assert_allclose(got, np.asarray(Rd), rtol=1e-9, atol=1e-12, err_msg=f"event {k}")
    assert not bool(st.dirty)
    assert kinds == {"scaled", "full formula"}, kinds


@pytest.mark.parametrize("which", ["row", "partner", "partner_log"])
def test_blocked_samplers_draw_with_the_dense_probabilities(which):
    """200 000 draws of the two-level (block, slot) samplers; chi-square against the dense weights (the partner
    with the linear-space tiles, the sum kernel's default, and with the log-space tiles)."""
    cfg = _cfg(linear=which != "partner_log")
    st = _state(seed=2, n_live=60)
    R, s = _dense(st)
    st = st._replace(R=R, s=s)
    if which == "row":
        p = np.asarray(R) / np.sum(np.asarray(R))
        draw = jax.jit(jax.vmap(lambda u: RUN._pick_blocked(cfg, st.hi, lambda start, idx: RUN._sl(st.R, start, 128),
                                                            u[0], u[1])[0]))
    else:
        a = int(np.argmax(np.asarray(R)))
        L = np.asarray(log_rate_matrix(P["kernel"], st.logm, st.psi, st.w, st.z, st.valid, P["log2_feps"]))[a]
        p = np.exp(L - np.max(L))
        p /= p.sum()
        draw = jax.jit(jax.vmap(lambda u: RUN._pick_partner(cfg, P, st, jnp.int32(a), u[0], u[1])))
    n = 200_000
    u = jax.random.uniform(jax.random.key(7), (n, 2), dtype=jnp.float64)
    idx = np.asarray(draw(u))
    counts = np.bincount(idx, minlength=S)
    assert counts[p == 0].sum() == 0
    keep = p * n >= 5
    exp_ = p[keep] * n
    chi2 = np.sum((counts[keep] - exp_) ** 2 / exp_) + (counts[~keep].sum() - (p[~keep] * n).sum()) ** 2 / max(
        (p[~keep] * n).sum(), 1.0)
    assert stats.chi2.sf(chi2, keep.sum()) > 1e-6, chi2


@pytest.mark.parametrize("kernel", [K.Constant(2.0), K.Sum(0.5), K.Product(1e-9)], ids=["constant", "sum", "product"])
def test_linear_rate_tiles_equal_the_log_space_rates(kernel):
    """``rates.rate_tile`` (the per-event tiles in linear space, no exp/log per entry) against exp(ln Λ' - s) of
    the dense log-space matrix (Ormel 2008 eqs. 5.7, 5.13, 5.31) on a state with masses over 12 decades, zooms
    0-40, fractional multiplicities and own pairs: every entry to 1e-12, zeros where the log form has zeros; the
    range guard (``run._lin_rows``) admits every row of this state."""
    st = _state(seed=3)
    L = np.asarray(log_rate_matrix(kernel, st.logm, st.psi, st.w, st.z, st.valid, P["log2_feps"]))
    rl = np.asarray(jax.nn.logsumexp(jnp.asarray(L), axis=1))
    s = float(np.max(rl[np.isfinite(rl)]))
    lw = RATES._safe_log_w(st.w)
    r = jnp.exp(lw - np.log(2.0) - s)
    d = jnp.exp(RATES.log_diag_factor(st.w, st.z) - s)
    idx = jnp.arange(S, dtype=jnp.int32)
    X = np.asarray(jax.jit(RATES.rate_tile, static_argnames="rounding")(
        kernel(st.m[:, None], st.m[None, :]), idx, r, d, st.logm, st.w, st.z, st.valid, idx, st.logm, st.w, st.z,
        st.valid, P["log2_feps"]))
    E = np.exp(L - s)
    assert np.all(X[E == 0] == 0) and np.count_nonzero(E) > 0.9 * int(st.ns) ** 2
    big = E > 1e-290
    np.testing.assert_allclose(X[big], E[big], rtol=1e-12)
    rng_ = RUN._range(_cfg(), st)
    ok = RUN._lin_rows(kernel, rng_, lw, st.w, st.z, st.logm, st.valid, s)[2]
    assert bool(ok)


def test_range_of_the_linear_guard_and_its_bounds_after_writes():
    """The range that the linear-tile guard reads (max/min of w and m, max z over the valid slots): the blocked
    pass (``run._range``) and the event's row pass (``_pick_blocked`` with ``extra``) equal numpy's; after writes
    (the slot of the largest w emptied, two new slots) ``run._range_with`` bounds the new state's exact range."""
    cfg = _cfg()
    st = _state(seed=4)
    v = np.asarray(st.valid)
    exact = lambda st: np.array([np.max(np.asarray(st.w)[np.asarray(st.valid)]),
                                 np.min(np.asarray(st.w)[np.asarray(st.valid)]),
                                 np.max(np.asarray(st.z)[np.asarray(st.valid)]),
                                 np.max(np.asarray(st.m)[np.asarray(st.valid)]),
                                 np.min(np.asarray(st.m)[np.asarray(st.valid)])], float)
    np.testing.assert_array_equal(np.array(RUN._range(cfg, st), float), exact(st))
    fn, init = RUN._range_block(cfg, st)
    _, _, acc = RUN._pick_blocked(cfg, st.hi, lambda start, idx: RUN._sl(st.R, start, 128), 0.3, 0.6, (fn, init))
    np.testing.assert_array_equal(np.array(acc, float), exact(st))
    live = np.flatnonzero(v)
    i_max = live[np.argmax(np.asarray(st.w)[live])]
    free = np.flatnonzero(~v)[:2]
    T = jnp.asarray([i_max, free[0], free[1]], jnp.int32)
    st2 = st._replace(valid=st.valid.at[i_max].set(False).at[free].set(True), w=st.w.at[i_max].set(0.0)
                      .at[free].set(jnp.array([20.0, 0.05])), z=st.z.at[free].set(jnp.array([45, 0], jnp.int32)),
                      m=st.m.at[free].set(jnp.array([1e14, 1e-3])))
    bnd = np.array(RUN._range_with(RUN._range(cfg, st), st2.valid[T], st2.w[T], st2.z[T], st2.m[T]), float)
    ex2 = exact(st2)
    assert bnd[0] >= ex2[0] and bnd[2] >= ex2[2] and bnd[3] >= ex2[3]
    assert bnd[1] <= ex2[1] and bnd[4] <= ex2[4]
    # the emptied slot held the largest w: its value stays the bound (above the new state's max)
    assert (bnd[0], bnd[1], bnd[2], bnd[3], bnd[4]) == (exact(st)[0], 0.05, 45, 1e14, 1e-3) and bnd[0] > ex2[0]


def test_partner_pick_linear_and_log_space_agree_and_the_guard_falls_back():
    """The partner sampler draws the same slots with the linear-space tiles as with the log-space ones (400
    uniforms; the weights differ by round-off only); on a state whose range would make a linear factor subnormal
    (:func:`_extreme`) the guard rejects the linear form and the draws are those of the log-space sampler
    bitwise (there every row draws the w = 1e300 slot; the slow incremental-update test checks the rates of that
    state, where the linear form loses the small rows: mutation-checked by forcing the guard)."""
    u = np.asarray(jax.random.uniform(jax.random.key(11), (400, 2), dtype=jnp.float64))
    for st, extreme in ((_state(seed=2), False), (_extreme(_state(seed=2)), True)):
        R, s = _dense(st)
        st = st._replace(R=R, s=s)
        live = np.flatnonzero(np.asarray(st.valid))
        rows = jnp.asarray(live[::len(live) // 20][:20], jnp.int32)
        a = jnp.repeat(rows, 20)   # 20 rows, 20 draws each
        draws = {}
        for lin in (True, False):
            cfg = _cfg(linear=lin)
            draws[lin] = np.asarray(jax.jit(jax.vmap(
                lambda a, u: RUN._pick_partner(cfg, P, st, a, u[0], u[1])))(a, jnp.asarray(u)))
        np.testing.assert_array_equal(draws[True], draws[False])
        pairs = set(zip(np.asarray(a).tolist(), draws[True].tolist()))
        assert len(pairs) > (19 if extreme else 25)   # concentrated rows: 32 distinct pairs (20 with w = 1e300)
        wa, za = st.w[rows], st.z[rows]
        ok = RUN._lin_rows(P["kernel"], RUN._range(_cfg(), st), RATES._safe_log_w(wa), wa, za, st.logm[rows],
                           st.valid[rows], jnp.log(st.R[rows]) + st.s)[2]
        assert bool(ok) is not extreme


@pytest.mark.slow
def test_run_is_the_same_at_two_capacities():
    """(slow: two engine compiles, ~40 s.) Equal-mass grouped run (sum kernel, Ns* = 50, ~85 species): capacity 600 and 4000 give the same
    events bitwise (the per-event passes cover [0, hi) only; n_refresh is fixed so that the refresh
    schedule does not follow the capacity)."""
    out = []
    for cap in (600, 4000):
        eng = jc.MonteCarlo(grouping=mc.EqualMass(), n_particles=1e30, ns_target=50, f_eps=1e-3, capacity=cap,
                            rates=mc.IncrementalRates(n_refresh=400))
        r = jc.evolve(K.Sum(0.5), eng, jc.Monodisperse(1.0, 1.0), jnp.array([0.0, 2.0, 5.0]), key=jax.random.key(4))
        out.append(r)
    a, b = out
    assert int(a.n_events) == int(b.n_events) > 500
    for f in ("m", "w", "z", "valid"):
        np.testing.assert_array_equal(np.asarray(getattr(a, f)), np.asarray(getattr(b, f))[:, :600], err_msg=f)
    assert not np.any(np.asarray(b.valid)[:, 600:])


@pytest.mark.parametrize("grouping", ["equal_mass", "distribution"])
def test_maintenance_on_the_prefix_window_equals_the_full_arrays(grouping):
    """The maintenance (scheduled merge, global rezoom, full refresh) runs on the shortest window [0, B) of the
    slots that holds the species (``run._on_prefix``): on the 260 species of :func:`_state` in 4 096 slots it
    takes the 1 024-slot window, and gives bit for bit what the same steps give on all 4 096 slots, with the
    merge (Ns* = 60 asks for ~100 merged pairs) and each grouping's rezoom; R stays 0 past the window."""
    S4 = 4096
    assert RUN._prefix_sizes(S4) == (1024, S4) and RUN._prefix_sizes(2047) == (2047,)
    st0 = _state(3)
    pad = S4 - S

    def grow(x, fill):
        return jnp.concatenate([x, jnp.full((pad,) + x.shape[1:], fill, x.dtype)])

    st = st0._replace(m=grow(st0.m, 1.0), logm=grow(st0.logm, 0.0), psi=jnp.zeros((S4, 0)), w=grow(st0.w, 0.0),
                      z=grow(st0.z, 0), valid=grow(st0.valid, False), R=jnp.full((S4,), 0.5), dirty=jnp.array(True),
                      rezoom=jnp.array(True), log_mstar=jnp.array(20.0), hi=jnp.array(7, jnp.int32))
    cfg = RUN._Cfg(mode="const_v", grouping=grouping, capacity=S4, n_snap=1, n_struct=0, n_prod=1,
                   rates="incremental", n_refresh=10**6, rounding="ceil", controller="species", d_max=1, d_up=1,
                   n_bins=3, p_protect=2, weighting="mass", dedupe=True, n_rezoom=1)
    p = dict(P, ns_target=jnp.asarray(60.0), tail_wmax=jnp.asarray(60.0))
    win = jax.jit(lambda st: RUN._maintenance(cfg, p, st))(st)
    full = jax.jit(lambda st: RUN._maintain(cfg, p, cfg, st._replace(hi=RUN._active(st.valid)[0])))(st)
    assert int(RUN._active(st.valid)[0]) == 290
    assert int(win.n_merge) - int(st.n_merge) >= 90 and int(win.ns) == int(jnp.sum(win.valid)) < 170
    for f in ("m", "logm", "w", "z", "valid", "R", "s", "hi", "ns", "n_merge", "zoom_xp", "zoom_fp", "zref"):
        np.testing.assert_array_equal(np.asarray(getattr(win, f)), np.asarray(getattr(full, f)), err_msg=f)
    assert not np.any(np.asarray(win.R)[1024:]) and np.count_nonzero(np.asarray(win.R)) == int(win.ns)
    assert not bool(win.dirty) and not bool(win.rezoom)


@pytest.mark.slow
@pytest.mark.parametrize("volume", [mc.ConstantVolume(), mc.ConstantSpecies()])
def test_equal_mass_species_count_stays_within_2x_of_target(volume):
    """(slow: ~15 s each, compile-dominated.) Sum kernel, equal-mass grouping, Ns* = 40, f_eps = 1e-2, 16
    outputs to t = 12: the species count never exceeds 2 Ns* (merging at 2 Ns*, thesis ch. 6). Before the
    2 Ns* rule it drifted to 281 = 7 Ns* (const-V) and 99 = 2.5 Ns* (const-Ns) in these runs. The count
    starts at one species (monodisperse) and rises: const-V (1e30 monomers) reaches Ns*/2 by t = 4,
    const-Ns (Fig. 5.4a set-up, n_particles = Ns*, mass controller) only late in the run (11 species at
    t = 4, 78 at t = 12), so the lower bound is asserted where it holds."""
    ns = 40
    const_v = isinstance(volume, mc.ConstantVolume)
    eng = jc.MonteCarlo(grouping=mc.EqualMass(), volume=volume, n_particles=1e30 if const_v else float(ns),
                        ns_target=ns, f_eps=1e-2)
    t_out = jnp.linspace(0.0, 12.0, 16)
    r = jc.evolve(K.Sum(0.5), eng, jc.Monodisperse(1.0, 1.0), t_out, key=jax.random.key(2))
    nsp = np.asarray(r.n_species)
    assert r.status == jc.RESULTS.successful
    assert nsp.max() <= 2 * ns, nsp
    late = np.asarray(t_out) >= (4.0 if const_v else 11.0)
    assert nsp[late].min() >= ns / 2, nsp
    if const_v:   # merging conserves mass exactly
        g = np.asarray(r.w * 2.0 ** r.z)
        M = np.sum(np.where(np.asarray(r.valid), g * np.asarray(r.m), 0.0), axis=-1)
        np.testing.assert_allclose(M, 1e30, rtol=1e-12)


def test_overlay_writes_equal_sequential_updates():
    """``run._Overlay`` (the event's writes collected per array and applied as one scatter, so that XLA does not
    copy the S-slot arrays) reads and writes like the chain of ``x = x.at[k].set(v)`` it replaces: reads see the
    earlier writes, block reads too, repeated slots keep the last write; for float, int, bool and (S, P) arrays."""
    rng = np.random.default_rng(7)
    n_slots, P = 40, 2
    bases = dict(f=rng.normal(size=n_slots), i=rng.integers(-5, 5, n_slots).astype(np.int32),
                 b=rng.uniform(size=n_slots) < 0.5, p=rng.normal(size=(n_slots, P)))
    slots = np.array([3, 17, 3, 39, 0, 17, 17, 25], np.int32)   # repeats, first and last slot

    def new_value(name, v, q):
        return ~v if name == "b" else v * 2 + q

    @jax.jit
    def with_overlay(bases, slots):
        out, reads = {}, {}
        for name, base in bases.items():
            ov = RUN._Overlay(base)
            rs = []
            for q in range(slots.shape[0]):
                v = ov[slots[q]]
                rs.append(v)
                ov.set(slots[q], new_value(name, v, q))
            rs.append(ov.block(jnp.int32(0), n_slots))
            reads[name] = rs
            iv = RUN._stack_writes(ov.idx, ov.val, n_slots)
            out[name] = RUN._scatter_writes(ov.base, iv)
            out[name + "_masked"] = RUN._scatter_writes(ov.base, iv, jnp.array(False))
        return out, reads

    out, reads = with_overlay({k: jnp.asarray(v) for k, v in bases.items()}, jnp.asarray(slots))
    for name, base in bases.items():
        x = np.array(base)
        for q, k in enumerate(slots):
            np.testing.assert_array_equal(np.asarray(reads[name][q]), x[k])
            x[k] = new_value(name, x[k], q)
        np.testing.assert_array_equal(np.asarray(reads[name][-1]), x)
        np.testing.assert_array_equal(np.asarray(out[name]), x)
        np.testing.assert_array_equal(np.asarray(out[name + "_masked"]), base)   # do = False: no write


@pytest.mark.parametrize("volume,grouping", [("const_v", "equal_mass"), ("const_ns", "equal_mass"),
                                             pytest.param("const_n", "none", marks=pytest.mark.slow),
                                             pytest.param("const_v", "distribution", marks=pytest.mark.slow)])
def test_event_loop_updates_species_arrays_in_place(volume, grouping):
    """No whole-array copy per event: in the compiled event loop (``run._event`` in a ``fori_loop``) XLA updates
    the species arrays and R in place. A copy of an S-slot array there made the cost per event follow the
    capacity (7 copies per event before stop 32; Ns* = 100: 94 us per event at S = 12 800, 308 us at 51 200,
    54 us at 150: benchmarks/results/mc_scaling.json); the reads of one array that feed another's update run in
    ``run._opaque_reads``, and the event has no lax.cond (``run.COND_FREE_CAPACITY``, 0). Checked on the
    optimised HLO for the four volume/grouping paths (duplication loops included), and in the constant-Ns case also
    the loop with the longer blocks of ``run._cfg_big``; the capacity 16411 appears in no other shape. (~20 s of
    compile each: the default run checks the default grouping with and without duplication, ``-m slow`` the other
    two.)"""
    import re

    from jaxcoag.mc.engine import _default_outcome

    cap = 16411
    assert cap >= RUN.COND_FREE_CAPACITY
    vol = dict(const_v=mc.ConstantVolume(), const_ns=mc.ConstantSpecies(), const_n=mc.ConstantNumber())[volume]
    grp = dict(equal_mass=mc.EqualMass(), none=None, distribution=mc.Distribution())[grouping]
    n_part = 1e30 if volume == "const_v" else 100.0
    eng = jc.MonteCarlo(grouping=grp, volume=vol, n_particles=n_part, ns_target=100, f_eps=1e-3, capacity=cap)
    kern = K.Sum(0.5)
    r = jc.evolve(kern, eng, jc.Monodisperse(1.0, 1.0), jnp.array([0.0, 0.3]), key=jax.random.key(1))
    outcome = _default_outcome(None).bind(kern)
    st = r.final_state
    cfg = eng._cfg(cap, st.psi.shape[-1], 2, outcome.n_products)
    p = eng._params(kern, outcome, jnp.array([0.3, 0.6]))
    st = RUN._start(cfg, p, st)
    cfg_big = RUN._cfg_big(cfg)   # the longer blocks from BIG_BLOCKS_FROM occupied slots on
    assert cfg_big is not None and cfg_big.block > cfg.block
    loop = jax.jit(lambda s: jax.lax.fori_loop(0, 3, lambda i, s_: RUN._event(cfg, p, s_), s))
    loop_big = jax.jit(lambda s: jax.lax.fori_loop(0, 3, lambda i, s_: RUN._event(cfg_big, p, s_), s))
    # (the big-block loop in the constant-Ns case only, which has every pass of the other; ~15 s of compile each)
    for lp in (loop, loop_big) if volume == "const_ns" else (loop,):
        hlo = lp.lower(st).compile().as_text()
        comp, copies = None, []
        for line in hlo.splitlines():
            if line and not line.startswith(" ") and "(" in line and "{" in line:
                comp = line.split("(")[0]
            if re.search(rf"\[{cap}(,\d+)?\]", line) and " copy(" in line and not comp.startswith("ENTRY"):
                copies.append(line.strip()[:100])
        assert copies == [], copies
    # and the loop runs: 3 events (or fewer if the rate sum asked for maintenance), mass conserved in const_v
    out = loop(st)
    assert 1 <= int(out.n_events - st.n_events) <= 3
    if volume == "const_v":
        M = float(jnp.sum(jnp.where(out.valid, jnp.ldexp(out.w, out.z) * out.m, 0.0)))
        np.testing.assert_allclose(M, float(out.M_tot), rtol=1e-12)


@pytest.mark.parametrize("state", ["linear", "heavy", "extreme"])
def test_update_trigger_figures_equal_the_population_moments(state):
    """The incremental update returns the maintenance triggers of the new state: ns (valid slots), ln M1 and ln M2
    (M_k = sum over species of g m^k, g = w 2^z; their ratio is the mass m_p that the constant-Ns controller and
    the equal-mass rezoom read). On the linear-space path they are linear sums (no exponential per slot), taken
    only where the state's range bounds every g m^2 below e^(690 - ln S); else the update runs in log space.
    Checked after each of six events against log-sum-exps of the numpy arrays, on the linear path ("linear"),
    on a state whose g m^2 would overflow the linear sums although its rate tiles are linear-safe ("heavy": masses
    near e^340; the whole update then takes the log path, its R bitwise that of the log-space update), and on the
    state of :func:`_extreme` (log path)."""
    import dataclasses

    from scipy.special import logsumexp

    cfg = dataclasses.replace(_cfg(), mode="const_ns")
    cfg_log = dataclasses.replace(cfg, linear_rates=False)
    st = _state(seed=2)
    if state == "heavy":
        st = st._replace(m=st.m * np.exp(320.0), logm=st.logm + 320.0)
    elif state == "extreme":
        st = _extreme(st)
    st = _with_dense(st)
    event, event_log = _update_event(cfg), _update_event(cfg_log)
    rng_ = RUN._range(cfg, st)
    lgm = np.log(float(rng_.w_max)) + int(rng_.z_max) * np.log(2.0) + 2 * np.log(float(rng_.m_max))
    assert (lgm < 690 - np.log(S)) == (state == "linear")
    live = np.flatnonzero(np.asarray(st.valid))
    rng = np.random.default_rng(4)
    for k in range(6):
        a, b = (int(x) for x in rng.choice(live, 2))
        st_in = st
        st, (_, l1, l2) = event(st, jnp.int32(a), jnp.int32(b), jax.random.key(k))
        v, w, z, lm = (np.asarray(getattr(st, n)) for n in ("valid", "w", "z", "logm"))
        lg = np.log(w[v]) + z[v] * np.log(2.0)
        assert int(st.ns) == int(v.sum())
        np.testing.assert_allclose(float(l1), logsumexp(lg + lm[v]), rtol=1e-13, err_msg=f"event {k}")
        np.testing.assert_allclose(float(l2), logsumexp(lg + 2 * lm[v]), rtol=1e-13, err_msg=f"event {k}")
        if state != "linear":   # the range guard sends the whole update to the log-space passes
            st_log, (_, l1_log, l2_log) = event_log(st_in, jnp.int32(a), jnp.int32(b), jax.random.key(k))
            np.testing.assert_array_equal(np.asarray(st.R), np.asarray(st_log.R))
            assert (float(l1), float(l2)) == (float(l1_log), float(l2_log))
        live = np.flatnonzero(v)


def test_row_pass_checks_the_round_off_of_the_incremental_rates():
    """The round-off check of the incremental row sums runs in the event's row pass (rate design B): a row sum
    below -1e-9 of the sum of |R| stops the event before it happens and asks for a refresh (the next maintenance
    recomputes R); a smaller negative entry, round-off of a rate sum near 0, weighs 0 in the row pick and the event
    goes on."""
    eng = jc.MonteCarlo(grouping=mc.EqualMass(), n_particles=1e30, ns_target=40, f_eps=1e-3, capacity=300)
    kern = K.Sum(0.5)
    r = jc.evolve(kern, eng, jc.Monodisperse(1.0, 1.0), jnp.array([0.0, 0.5]), key=jax.random.key(1))
    outcome = jc.outcomes.Sticking().bind(kern)
    cfg = eng._cfg(300, 0, 2, outcome.n_products)
    p = eng._params(kern, outcome, jnp.array([0.5, 5.0]))
    st = RUN._start(cfg, p, r.final_state)
    st = jax.jit(lambda s: RUN._maintenance(cfg, p, s))(st)
    st = st._replace(n_since_refresh=jnp.array(3, jnp.int64))
    x = int(np.flatnonzero(np.asarray(st.valid))[0])
    tot = float(jnp.sum(jnp.where(st.valid, jnp.abs(st.R), 0.0)))
    event = jax.jit(lambda s: RUN._event(cfg, p, s))
    big = event(st._replace(R=st.R.at[x].set(-1e-6 * tot)))
    assert int(big.n_events) == int(st.n_events) and bool(big.dirty)
    small = event(st._replace(R=st.R.at[x].set(-1e-12 * tot)))
    assert int(small.n_events) == int(st.n_events) + 1 and not bool(small.dirty)


@pytest.mark.parametrize("volume", [pytest.param("const_v", marks=pytest.mark.slow), "const_ns"])
def test_cond_and_cond_free_events_are_the_same(volume, monkeypatch):
    """The event as a lax.cond (below ``run.COND_FREE_CAPACITY`` slots; since stop 45 only where that constant is
    raised) and the masked cond-free event in a one-trip while loop (the default, no S-slot copy) give the same
    events bit for bit, with duplication (constant Ns) and without. The cond run has a capacity (307) that no other
    test compiles, so no cached cond-free program is reused (~25 s of compile each: the run without duplication is
    ``-m slow``)."""
    vol = mc.ConstantSpecies() if volume == "const_ns" else mc.ConstantVolume()
    out = []
    for cap, cond_free_from in ((307, 1 << 20), (313, RUN.COND_FREE_CAPACITY)):
        monkeypatch.setattr(RUN, "COND_FREE_CAPACITY", cond_free_from)
        eng = jc.MonteCarlo(grouping=mc.EqualMass(), volume=vol, n_particles=40.0 if volume == "const_ns" else 1e30,
                            ns_target=40, f_eps=1e-3, capacity=cap, rates=mc.IncrementalRates(n_refresh=200))
        out.append(jc.evolve(K.Sum(0.5), eng, jc.Monodisperse(1.0, 1.0), jnp.array([0.0, 1.0, 3.0]),
                             key=jax.random.key(5)))
    a, b = out
    assert int(a.n_events) == int(b.n_events) > 50
    if volume == "const_ns":
        assert int(a.n_dup) == int(b.n_dup) > 0
    for f in ("m", "w", "z", "valid", "M_tot", "logV"):
        x, y = np.asarray(getattr(a, f)), np.asarray(getattr(b, f))
        if x.ndim == 2:
            y = y[:, :307]
        np.testing.assert_array_equal(x, y, err_msg=f)
    assert not np.any(np.asarray(b.valid)[:, 307:])
