"""Periodic box of spheres / rigid aggregates (Richardson 1995 §3, Table I; jaxcoag.aggregates.rigid.box).

Default run (no compilation of the engine, < 2 s): bad inputs, the initial conditions of box_model
(exact speeds, zero momentum, no overlap) and the A9 diagnostics against independent formulas
(scipy.stats.linregress, R32). The engine itself compiles for tens of seconds on 2 CPU cores, so every
test that runs it is marked ``slow``:

* model (i), N0 = 300, seeds 1, 2, 3 (all of them, none picked): mean N(t) within 3 sigma_3 + 1 % of (R30),
  sigma_3 from the Marcus-Lushnikov table of the spec (2000 realisations, N0 = 1000) scaled by
  sqrt(1000 / 300); N + N_C = N0 exactly; N_C == N_C1; the pooled mass spectrum against (R31) by chi^2;
* model (ii): per-collision |dP| <= 1e-12 P_scale, total momentum drift, dKE <= 0;
* model (iv): per-collision |dP| <= 1e-12 P_scale, |dL| <= 1e-10 L_scale, dKE <= 1e-12 KE, both outcomes;
* fuzz at high speed: no two spheres of different aggregates overlap by more than the tolerance at any
  output of a segmented run (conservative advancement cannot tunnel);
* checkpoint / resume equals the uninterrupted run; to_xarray carries the same numbers.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from jaxcoag import analytic
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.aggregates import rigid
from jaxcoag.aggregates.rigid import diagnostics as diag

KEY = jax.random.key(7)


# ------------------------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize("kwargs, match", [
    (dict(model="vi"), "unknown model"),
    (dict(model="i", n0=1000, r0=0.5), "too small"),
    (dict(model="iv", eps_n=1.2), "eps_n"),
    (dict(model="iv", eps_n=-0.1), "eps_n"),
    (dict(model="iv", mu_t=2.0), "mu_t"),
    (dict(model="iv", mu_p=-0.5), "mu_p"),
    (dict(model="i", v0=-1.0), "v0"),
    (dict(model="i", n0=1), "n0"),
])
def test_bad_inputs(kwargs, match):
    model = kwargs.pop("model")
    with pytest.raises(JaxcoagInputError, match=match):
        rigid.box_model(model, key=KEY, **kwargs)


def test_overlapping_given_spheres_refused():
    x = np.array([[1.0, 1.0, 1.0], [1.15, 1.0, 1.0], [5.0, 5.0, 5.0]])  # 0.15 < 2 r0
    with pytest.raises(JaxcoagInputError, match="overlap"):
        rigid.box_model("i", n0=3, positions=x, key=KEY)
    x[0] = [0.05, 1.0, 1.0]
    x[1] = [9.95, 1.0, 1.0]  # 0.1 apart through the periodic face (minimum image)
    with pytest.raises(JaxcoagInputError, match="overlap"):
        rigid.box_model("i", n0=3, positions=x, key=KEY)


def test_engine_refuses_kernel_and_bad_settings():
    box = rigid.box_model("i", n0=8, key=KEY)
    with pytest.raises(JaxcoagInputError, match="kernel=None"):
        rigid.box.RigidBox()._check(object(), box, jnp.ones(1), 0.0, None, None)
    with pytest.raises(JaxcoagInputError, match="eta"):
        rigid.box.RigidBox(eta=1.5)
    with pytest.raises(JaxcoagInputError, match="neighbors"):
        rigid.box.RigidBox(neighbors=0)
    with pytest.raises(JaxcoagInputError, match='"body"'):
        rigid.box.RigidBox(clock="per-body")


def test_argmin2_and_tau_block_width():
    """box._argmin2 (the per-body clocks' choice of the next pair check: the index of the earliest entry of a block
    and its second smallest value, in one reduction) against numpy, with ties and infinities; box._tau_block is a
    power of two near sqrt(P) in [128, 4096]."""
    from jaxcoag.aggregates.rigid import box as rbox

    rng = np.random.default_rng(5)
    f = jax.jit(rbox._argmin2)
    cases = [rng.uniform(size=512), np.full(256, np.inf), np.r_[np.full(100, np.inf), 3.0, 2.0, 2.0, np.inf],
             np.r_[5.0, np.full(127, np.inf)], rng.integers(0, 4, 128).astype(float)]
    for x in cases:
        i, m2 = f(jnp.asarray(x))
        assert int(i) == int(np.argmin(x))
        rest = np.delete(x, int(np.argmin(x)))
        assert float(m2) == float(np.min(rest))
    assert [rbox._tau_block(P) for P in (1, 1000, 24_000, 240_000, 2_400_000, 10**9)] == [128, 128, 256, 512, 2048,
                                                                                            4096]
    # the numbers of a contact through the state field ev: exact round trip, ids and flags restored
    num = {k: jnp.asarray(rng.normal(size=3)) for k in rbox._EV_VEC}
    num.update({k: jnp.asarray(rng.normal()) for k in rbox._EV_SCAL})
    num.update(a=jnp.int32(123456), b=jnp.int32(7), first=jnp.asarray(True), coag=jnp.asarray(False))
    back = rbox._unpack_event(rbox._pack_event(num))
    assert rbox._pack_event(num).shape == (rbox.EV_SIZE,) and set(back) == set(num)
    for k in num:
        np.testing.assert_array_equal(np.asarray(back[k]), np.asarray(num[k]))
    assert [np.asarray(back[k]).dtype for k in ("a", "b", "first", "coag")] == [np.int32, np.int32, bool, bool]


def _member_lists_ok(st):
    """Every live aggregate's member list (box state mem[mem0[a] : mem0[a] + nmem[a]]) holds exactly its spheres."""
    mem, mem0, nmem, agg = (np.asarray(v) for v in (st.mem, st.mem0, st.nmem, st.sph_agg))
    top = int(st.mem_top)
    for a in np.nonzero(np.asarray(st.alive))[0]:
        assert mem0[a] + nmem[a] <= top
        assert sorted(mem[mem0[a]:mem0[a] + nmem[a]].tolist()) == np.nonzero(agg == a)[0].tolist()
    return True


def test_member_lists_append_and_compact():
    """box._mem_append / _mem_compact (the per-aggregate member lists that make a collision O(members)): a sequence
    of merges whose lists overflow the capacity 2 n0 compacts the live lists to the front, after every merge each
    live aggregate's list holds exactly its spheres, and box._segment_ids reads a's list then b's, padded."""
    from jaxcoag.aggregates.rigid import box as rbox

    n = 8
    b = rigid.box_model("iii", n0=n, r0=0.1, box=5.0, key=KEY)
    st = rigid.RigidBox()._init(None, b, 0.0, None, None)
    assert int(st.mem_top) == n and st.mem.shape == (2 * n,)
    seg = jax.jit(rbox._segment_ids, static_argnums=3)
    app = jax.jit(rbox._mem_append)
    tops = []
    for a, c in [(0, 1), (2, 3), (0, 2), (4, 5), (6, 7), (0, 4), (0, 6)]:
        ids = seg(st, a, c, n)
        want = sorted(np.nonzero((np.asarray(st.sph_agg) == a) | (np.asarray(st.sph_agg) == c))[0].tolist())
        got = np.asarray(ids)
        assert sorted(got[got < n].tolist()) == want and np.all(got[len(want):] == n)
        st = app(st, ids, ids < n, jnp.int32(a))
        st = eqx.tree_at(lambda s: (s.nmem, s.alive, s.sph_agg), st,
                         (st.nmem.at[a].set(st.nmem[a] + st.nmem[c]).at[c].set(0), st.alive.at[c].set(False),
                          jnp.where(st.sph_agg == c, a, st.sph_agg)))
        assert _member_lists_ok(st)
        tops.append(int(st.mem_top))
    # 8 + 2, + 2, + 4 = 16 (full); a list that does not fit compacts the live lists to 8 first: 8 + 2, + 2;
    # 8 + 6; 8 + 8
    assert tops == [10, 12, 16, 10, 12, 14, 16]


# ------------------------------------------------------------------------------------------------ initial state
def test_box_model_initial_conditions():
    b = rigid.box_model("i", n0=400, v0=3.0, key=KEY)
    v = np.asarray(b.v)
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 3.0, rtol=1e-14)  # constant speed (model i)
    assert np.max(np.abs(v.sum(axis=0))) < 1e-12  # antithetic pairs: zero net momentum
    x = np.asarray(b.x)
    assert np.all((x >= 0) & (x < 10.0))
    d = x[:, None, :] - x[None, :, :]
    d -= 10.0 * np.round(d / 10.0)
    r = np.sqrt((d**2).sum(-1)) + np.eye(400) * 100
    assert r.min() > 0.2  # no overlapping or touching pair (minimum image)
    # alpha = pi (2R)^2 (4/3) v0 / L^3 (R95 §3) = 1.6755e-4 v0
    assert b.alpha == pytest.approx(1.6755160819145563e-4 * 3.0, rel=1e-12)
    m = rigid.box_model("iv", n0=600, v0=2.0, key=KEY)
    vm = np.asarray(m.v)
    assert np.max(np.abs(vm.sum(axis=0))) < 1e-11
    # Maxwellian with rms speed v0: <v^2> = v0^2 within 4 sigma (Var(v^2)/<v^2>^2 = 2/3)
    assert abs(np.mean((vm**2).sum(1)) / 4.0 - 1) < 4 * math.sqrt(2 / 3 / 600)
    assert float(m.e_thr) == pytest.approx(0.5 * np.mean((vm**2).sum(1)), rel=1e-12)  # E_thr = mean KE


# ------------------------------------------------------------------------------------------------ neighbour pairs
def _clustered_spheres(rng, L, R):
    """Spheres of radius R: a dilute gas plus compact clumps (one group each; two clumps straddle the periodic
    faces), placed without overlap; returns positions (wrapped) and group ids."""
    pts, grp = [], []

    def free(p):
        if not pts:
            return True
        d = np.asarray(pts) - p
        d -= L * np.round(d / L)
        return np.min(np.linalg.norm(d, axis=1)) >= 2 * R * (1 + 1e-9)

    centres = [rng.uniform(0, L, 3) for _ in range(4)] + [np.array([0.02, 0.5 * L, 0.5 * L]),
                                                          np.array([L - 0.05, L - 0.05, 0.3 * L])]
    for g, c in enumerate(centres):  # clumps: ~25 touching-range spheres each, one group per clump
        for _ in range(400):
            if sum(1 for k in grp if k == g) >= 25:
                break
            p = np.mod(c + rng.normal(scale=2.2 * R, size=3), L)
            if free(p):
                pts.append(p)
                grp.append(g)
    for _ in range(3000):  # gas: one group per sphere
        if len(pts) >= 300:
            break
        p = rng.uniform(0, L, 3)
        if free(p):
            pts.append(p)
            grp.append(len(centres) + len(pts))
    return np.asarray(pts), np.asarray(grp, np.int32)


def test_flat_pair_build_equals_brute_force():
    """box._build_pairs (the aggregate models' list: flat candidates over the 27 cells, blocks up to their
    actual number) against a brute-force minimum-image search: the same pairs (s < t, different groups, gap
    below the skin), in row-major order, per-sphere partner counts against K, and the capacity overflow."""
    from jaxcoag.aggregates.rigid import box as rbox

    rng = np.random.default_rng(3)
    L, R, skin = 4.0, 0.1, 0.3
    x, grp = _clustered_spheres(rng, L, R)
    n = x.shape[0]
    Rs = np.full(n, R)
    d = x[None, :, :] - x[:, None, :]
    d -= L * np.round(d / L)
    dist = np.linalg.norm(d, axis=-1)
    near = (dist < Rs[:, None] + Rs[None, :] + skin) & (grp[:, None] != grp[None, :])
    np.fill_diagonal(near, False)
    ref = sorted((int(s), int(t)) for s, t in zip(*np.nonzero(near)) if s < t)
    deg = near.sum(axis=1)
    nc = int(L // (2 * R + skin))
    assert nc >= 3 and len(ref) > 100 and deg.max() >= 4

    build = jax.jit(rbox._build_pairs, static_argnums=(4, 5, 6, 7, 8))
    P = 4 * len(ref)
    pi, pj, npair, over, rs, rt, nrev = build(jnp.asarray(x), jnp.asarray(Rs), jnp.asarray(grp), L, skin,
                                              int(deg.max()), P, nc, 64)
    k = int(npair)
    got = list(zip(np.asarray(pi)[:k].tolist(), np.asarray(pj)[:k].tolist()))
    assert k == len(ref) and not bool(over)
    assert sorted(got) == ref
    assert np.all(np.diff(np.asarray(pi)[:k]) >= 0)  # row-major: rows in order
    # the reverse entries: every pair once more from its larger sphere, rows in order
    assert int(nrev) == k
    assert sorted(zip(np.asarray(rt)[:k].tolist(), np.asarray(rs)[:k].tolist())) == ref
    assert np.all(np.diff(np.asarray(rs)[:k]) >= 0)
    # the pairs of each sphere (box._adjacency) against the brute-force list: forward and reverse, each pair index
    # exactly once per sphere of the pair
    fwd0, degf, rev0, degr, rev_p, bad = jax.jit(rbox._adjacency, static_argnums=(6, 7))(pi, pj, npair, rs, rt, nrev,
                                                                                         n, 16)
    assert not bool(bad)
    fwd0, degf, rev0, degr, rev_p = (np.asarray(v) for v in (fwd0, degf, rev0, degr, rev_p))
    pin, pjn = np.asarray(pi)[:k], np.asarray(pj)[:k]
    for s_ in range(n):
        mine = list(range(fwd0[s_], fwd0[s_] + degf[s_])) + rev_p[rev0[s_]:rev0[s_] + degr[s_]].tolist()
        assert len(mine) == len(set(mine)) == deg[s_]
        assert {frozenset((int(pin[p]), int(pjn[p]))) for p in mine} == {frozenset((s_, int(t))) for t in
                                                                         np.nonzero(near[s_])[0]}
    # the accelerator's block width (box._lanes: 2^20, one block holds every candidate): the same list
    wide = build(jnp.asarray(x), jnp.asarray(Rs), jnp.asarray(grp), L, skin, int(deg.max()), P, nc, 1 << 20)
    assert int(wide[2]) == k and not bool(wide[3])
    assert np.array_equal(np.asarray(wide[0])[:k], np.asarray(pi)[:k])
    assert np.array_equal(np.asarray(wide[1])[:k], np.asarray(pj)[:k])
    # one partner fewer than the busiest sphere has: overflow; a pair capacity below the count: overflow too
    assert bool(build(jnp.asarray(x), jnp.asarray(Rs), jnp.asarray(grp), L, skin, int(deg.max()) - 1, P, nc, 64)[3])
    short = build(jnp.asarray(x), jnp.asarray(Rs), jnp.asarray(grp), L, skin, int(deg.max()), len(ref) - 1, nc, 64)
    assert bool(short[3]) and int(short[2]) == len(ref) - 1


# ------------------------------------------------------------------------------------------------ diagnostics (A9)
def test_fractal_dimension_matches_linregress():
    rng = np.random.default_rng(3)
    sizes = [3, 5, 17, 60]
    agg = np.concatenate([np.full(s, i) for i, s in enumerate(sizes)])
    r = rng.uniform(0.05, 3.0, agg.size)
    R = np.full(agg.size, 0.1)
    fd, err = diag.fractal_dimension(r, agg, R, include_radius=True)
    for i, s in enumerate(sizes):
        rr = np.sort(r[agg == i] + 0.1)
        lr = stats.linregress(np.log(rr), np.log(np.arange(1, s + 1)))
        assert fd[i] == pytest.approx(lr.slope, rel=1e-12)
        assert err[i] == pytest.approx(lr.stderr, rel=1e-10)
    assert np.all(np.isnan(fd[len(sizes):]))  # slots without members
    # the default reads member-centre distances (spec A9): the same fit without the radius
    fd_c, err_c = diag.fractal_dimension(r, agg, R)
    for i, s in enumerate(sizes):
        lr = stats.linregress(np.log(np.sort(r[agg == i])), np.log(np.arange(1, s + 1)))
        assert fd_c[i] == pytest.approx(lr.slope, rel=1e-12) and err_c[i] == pytest.approx(lr.stderr, rel=1e-10)


def test_fractal_dimension_exact_power_law_and_small_aggregates():
    k = np.arange(1, 41)
    r = 0.3 * k ** (1 / 1.8)  # N(<r) = (r / 0.3)^1.8 exactly
    fd, err = diag.fractal_dimension(r, np.zeros(40, int), np.zeros(40), include_radius=False)
    assert fd[0] == pytest.approx(1.8, rel=1e-12) and err[0] < 1e-12
    fd2, _ = diag.fractal_dimension(np.array([0.1, 0.2, 0.3, 0.4]), np.array([0, 0, 1, 1]), np.full(4, 0.1))
    assert np.all(np.isnan(fd2))  # N_a = 2 is not fitted


def test_weighted_mean_density_power_law_gamma():
    m, e = diag.weighted_mean([1.0, 2.0, np.nan], [1.0, 2.0, 1.0])
    assert m == pytest.approx((1 + 2 / 4) / (1 + 1 / 4), rel=1e-15)
    assert e == pytest.approx(1 / math.sqrt(1.25), rel=1e-15)
    assert diag.density(3.0, 2.0) == pytest.approx(3.0 / (4 / 3 * math.pi * 8), rel=1e-15)
    # R32: gamma = -0.71 gives f_D = 3 / 1.71 = 1.754 (R95 model iii: 1.75)
    assert diag.fd_from_gamma(-0.71) == pytest.approx(1.7543859649122806, rel=1e-15)
    rng = np.random.default_rng(1)
    n = rng.integers(1, 200, 300)
    y = 0.1 * n**0.57 * np.exp(rng.normal(0, 0.05, 300))
    s, se, c = diag.power_law(n, y)
    lr = stats.linregress(np.log(n[n >= 2]), np.log(y[n >= 2]))
    assert s == pytest.approx(lr.slope, rel=1e-12) and se == pytest.approx(lr.stderr, rel=1e-10)
    assert c == pytest.approx(lr.intercept, rel=1e-12)
    rm = diag.r_max(np.array([0.0, 0.5, 0.2, 0.0]), np.array([0, 0, 0, 3]), np.full(4, 0.1))
    np.testing.assert_allclose(rm, [0.6, 0.0, 0.0, 0.1], rtol=1e-15)
    V = jnp.array([[1.0, 0, 0], [-1.0, 2, 0], [100.0, 0, 0]])
    np.testing.assert_allclose(diag.velocity_dispersion(V, jnp.array([True, True, False])), [1.0, 1.0, 0.0])


# ------------------------------------------------------------------------------------------------ engine (slow)
def _tau_times(b, taus):
    return np.asarray(taus) / (0.5 * b.alpha * b.n0)


# sigma/N_th of the mean of 3 runs at N0 = 1000 (spec A9, 2000 Marcus-Lushnikov realisations)
_ML_TAU = np.array([0.25, 0.5, 1.0, 2.0, 4.0, 9.0])
_ML_SIG = np.array([0.008, 0.011, 0.014, 0.018, 0.024, 0.033])


@pytest.fixture(scope="module")
def model_i_runs():
    taus = np.array([0.25, 0.5, 1.0, 2.0, 4.0])
    runs = []
    for seed in (1, 2, 3):
        b = rigid.box_model("i", n0=300, v0=13.0, key=jax.random.key(seed))
        runs.append(rigid.run(b, _tau_times(b, taus)))
    return taus, runs


@pytest.mark.slow
def test_model_i_constant_kernel_statistics(model_i_runs):
    taus, runs = model_i_runs
    n0 = 300
    N = np.array([np.asarray(r.n_aggregates) for r in runs], float)
    for r in runs:
        nc = np.asarray(r.n_collisions)
        np.testing.assert_array_equal(np.asarray(r.n_aggregates) + nc[:, 0], n0)  # N + N_C = N0 exactly
        np.testing.assert_array_equal(nc[:, 0], nc[:, 1])  # N_C == N_C1 under coagulation only
        assert str(r.status) == str(rigid.box.RESULTS.successful)
    Nth = n0 / (1 + taus)  # (R30)
    sig3 = np.interp(taus, _ML_TAU, _ML_SIG) * math.sqrt(1000 / n0) * Nth
    dev = np.abs(N.mean(0) - Nth)
    assert np.all(dev <= 3 * sig3 + 0.01 * Nth), (N.mean(0), Nth, sig3)
    # (R31) pooled spectrum at tau = 1 (f = 0.5) and tau = 4 (f = 0.2): chi^2 over k = 1..8 + tail, p > 1e-3
    for i in (2, 4):
        obs = sum(np.asarray(r.mass_spectrum(kmax=n0))[i] for r in runs).astype(float)
        f = N[:, i].sum() / (3 * n0)
        k = np.arange(1, n0 + 1)
        exp = 3 * n0 * f**2 * (1 - f) ** (k - 1)
        o = np.concatenate([obs[:8], [obs[8:].sum()]])
        e = np.concatenate([exp[:8], [exp[8:].sum()]])
        while e[-1] < 5:  # pool the sparse tail
            o, e = np.concatenate([o[:-2], [o[-2:].sum()]]), np.concatenate([e[:-2], [e[-2:].sum()]])
        e *= o.sum() / e.sum()
        chi2 = np.sum((o - e) ** 2 / e)
        assert stats.chi2.sf(chi2, len(o) - 2) > 1e-3, (i, o, e)
        # (R31) is jaxcoag.analytic's constant-kernel solution with coeff = alpha, n0 = N0
        b = rigid.box_model("i", n0=n0, v0=13.0, key=jax.random.key(1))
        t = taus[i] / (0.5 * b.alpha * n0)
        ref = np.exp(analytic.log_nk("constant", np.arange(1, 9), t, coeff=b.alpha, n0=n0))
        np.testing.assert_allclose(ref, n0 / (1 + taus[i]) ** 2 * (taus[i] / (1 + taus[i])) ** np.arange(8),
                                   rtol=1e-12)


@pytest.mark.slow
def test_model_i_xarray_and_max_mass(model_i_runs):
    taus, runs = model_i_runs
    r = runs[0]
    ds = r.to_xarray()
    np.testing.assert_array_equal(ds["n_aggregates"].values, np.asarray(r.n_aggregates))
    np.testing.assert_allclose(ds["t"].values, np.asarray(r.t))
    spec = ds["mass_spectrum"].values
    np.testing.assert_array_equal((spec * ds["k"].values[None, :]).sum(1), 300)  # mass conserved
    np.testing.assert_array_equal(spec.sum(1), np.asarray(r.n_aggregates))
    assert np.all(np.diff(np.asarray(r.max_mass)) >= 0)
    np.testing.assert_allclose(np.asarray(r.moments(1)), 300 / 1000.0, rtol=1e-13)  # total mass / L^3


@pytest.mark.slow
def test_model_ii_momentum_per_collision():
    b = rigid.box_model("ii", n0=200, box=6.0, v0=5.0, key=jax.random.key(11))
    r = rigid.run(b, jnp.array([1.0, 3.0]))
    log = r.collision_log
    assert len(log["t"]) == int(r.n_collisions[-1, 0]) > 30
    assert np.all(log["dP"] <= 1e-12 * log["P_scale"])
    assert np.all(log["dKE"] <= 1e-12 * log["KE"])  # perfectly inelastic merges lose energy
    st = r.final_state
    P = np.sum(np.asarray(st.M)[:, None] * np.asarray(st.V) * np.asarray(st.alive)[:, None], axis=0)
    assert np.max(np.abs(P)) <= 1e-12 * float(np.sum(np.asarray(b.mass) * np.linalg.norm(np.asarray(b.v), axis=1)))
    # model (ii) radii grow as r0 (m/m0)^(1/3)
    al = np.asarray(st.alive)
    np.testing.assert_allclose(np.asarray(st.sph_R)[al], 0.1 * np.cbrt(np.asarray(st.M)[al]), rtol=1e-13)


@pytest.mark.slow
def test_model_iv_per_collision_invariants():
    b = rigid.box_model("iv", n0=120, box=5.0, v0=5.0, key=jax.random.key(5))
    r = rigid.run(b, jnp.array([0.5, 1.5]))
    log = r.collision_log
    assert len(log["t"]) > 40
    assert {1, 2} <= set(log["outcome"].tolist())  # both coagulation and restitution occur
    assert np.all(log["dP"] <= 1e-12 * log["P_scale"])
    assert np.all(log["dL"] <= 1e-10 * log["L_scale"])
    assert np.all(log["dKE"] <= 1e-12 * log["KE"])
    # outcome rule (A8): coagulation iff E_imp < E_thr
    np.testing.assert_array_equal(log["outcome"] == 1, log["e_imp"] < float(b.e_thr))
    o = r.outs
    np.testing.assert_array_equal(np.asarray(o["n_aggregates"]) + np.asarray(o["n_coag"]), 120)
    assert np.all(np.asarray(o["n_c1"]) <= np.asarray(o["n_c"]))
    assert np.all(np.asarray(o["n_c"]) == np.asarray(o["n_coag"]) + np.asarray(o["n_rest"]))


def _min_gap(st):
    """Smallest gap between spheres of different aggregates (all pairs, minimum image)."""
    from jaxcoag.aggregates.rigid.box import _mimg, _sphere_pos

    x, _, _ = _sphere_pos(st)
    L = st.par["L"]
    d = _mimg(x[:, None, :] - x[None, :, :], L)
    g = jnp.sqrt(jnp.sum(d * d, -1)) - (st.sph_R[:, None] + st.sph_R[None, :])
    other = st.sph_agg[:, None] != st.sph_agg[None, :]
    return float(jnp.min(jnp.where(other, g, jnp.inf)))


@pytest.mark.slow
@pytest.mark.parametrize("clock", ["body", "global"])
def test_fuzz_no_tunnelling_at_high_speed(clock):
    """v0 = 200 box units per time: a sphere crosses its own diameter in 1e-3, the outputs are 5e-3 apart."""
    b = rigid.box_model("iii", n0=60, box=3.0, v0=200.0, key=jax.random.key(2))
    eng = rigid.box.RigidBox(clock=clock)
    res = b
    gaps = []
    for k in range(1, 13):
        res = rigid.run(res, jnp.array([5e-3 * k]), engine=eng)
        gaps.append(_min_gap(res.final_state))
    assert int(res.n_collisions[-1, 0]) > 10
    assert min(gaps) >= -1e-6 * 0.1 - 1e-12, gaps


@pytest.mark.slow
def test_checkpoint_resume_equals_uninterrupted(tmp_path):
    b = rigid.box_model("i", n0=100, box=6.0, v0=13.0, key=jax.random.key(4))
    t = jnp.array([0.2, 0.4, 0.6])
    full = rigid.run(b, t)
    ck = tmp_path / "box.npz"
    part = rigid.run(b, t, checkpoint=ck, max_segments=1)
    assert len(part.t) == 1
    res = rigid.run(b, t, checkpoint=ck)
    np.testing.assert_array_equal(np.asarray(res.n_aggregates), np.asarray(full.n_aggregates))
    np.testing.assert_array_equal(np.asarray(res.outs["M"]), np.asarray(full.outs["M"]))


@pytest.mark.slow
@pytest.mark.parametrize("model", ["iii", "iv", "iv-bound"])
def test_body_and_global_clocks_resolve_the_same_collisions(model, monkeypatch):
    """The per-body clocks (each listed pair checked at its own time, bodies advanced lazily) against the global
    conservative-advancement step, n0 = 300 to T = 0.6: the same collisions (pairs, outcomes, N(t), N_C), contact
    times within 1e-3 (the two clocks detect a contact at different points of the band g <= tol and integrate the
    rotations in different substeps), P, L and KE conserved per collision as the model demands, and every body's
    clock at the output time. "iv-bound": every collision gives the pairs of its two bodies the conservative next
    check in one pass that large aggregates get (box._BIG_EVENT = 0), instead of a check each from now."""
    t = jnp.array([0.2, 0.4, 0.6])
    if model == "iv-bound":
        from jaxcoag.aggregates.rigid import box as rbox

        model = "iv"
        monkeypatch.setattr(rbox, "_BIG_EVENT", 0)
        jax.clear_caches()  # read at trace time
    runs = {}
    for clock in ("global", "body"):
        b = rigid.box_model(model, n0=300, box=6.0, v0=13.0, key=jax.random.key(4))
        runs[clock] = rigid.run(b, t, engine=rigid.RigidBox(neighbors=64, cell_capacity=64, clock=clock))
    g, bd = runs["global"].collision_log, runs["body"].collision_log
    assert len(g["t"]) == len(bd["t"]) > 100
    for k in ("a", "b", "outcome"):
        np.testing.assert_array_equal(bd[k], g[k])
    np.testing.assert_allclose(bd["t"], g["t"], rtol=0, atol=1e-3)
    for k in ("n_aggregates", "n_c", "n_c1", "n_coag"):
        np.testing.assert_array_equal(np.asarray(runs["body"].outs[k]), np.asarray(runs["global"].outs[k]))
    assert np.all(bd["dP"] <= 1e-12 * bd["P_scale"]) and np.all(bd["dL"] <= 1e-10 * bd["L_scale"])
    st = runs["body"].final_state
    assert np.all(np.asarray(st.tb) == 0.6) and float(st.t) == 0.6
    assert _member_lists_ok(st) and _member_lists_ok(runs["global"].final_state)
    # the pair check times are all in the future, and the body clock used several checks per global step's worth
    al = np.asarray(st.tau)[: int(st.n_pairs)]
    assert np.all(al >= 0.6)
    assert int(runs["body"].outs["n_steps"][-1]) > int(runs["global"].outs["n_steps"][-1])


@pytest.mark.slow
def test_body_clock_checkpoint_resume_and_clock_switch(tmp_path):
    """Model (iv) with per-body clocks: a run resumed from its checkpoint equals the uninterrupted run bitwise (the
    state at an output is synchronised and its pair check times stay valid), and a state advanced with the global
    clock continues with per-body clocks (its check times are rebuilt by one scan first) without any overlap."""
    t = jnp.array([0.2, 0.4, 0.6])
    eng = rigid.RigidBox(neighbors=64, cell_capacity=64)

    def box():
        return rigid.box_model("iv", n0=150, box=5.0, v0=13.0, key=jax.random.key(9))

    full = rigid.run(box(), t, engine=eng)
    ck = tmp_path / "iv.npz"
    part = rigid.run(box(), t, engine=eng, checkpoint=ck, max_segments=1)
    assert len(part.t) == 1
    res = rigid.run(box(), t, engine=eng, checkpoint=ck)
    assert int(full.outs["n_c"][-1]) > 20
    for k in ("n_aggregates", "n_c", "n_steps", "n_build"):
        np.testing.assert_array_equal(np.asarray(res.outs[k]), np.asarray(full.outs[k]))
    np.testing.assert_array_equal(np.asarray(res.final_state.X), np.asarray(full.final_state.X))
    np.testing.assert_array_equal(np.asarray(res.final_state.q), np.asarray(full.final_state.q))
    first = rigid.run(box(), t[:1], engine=rigid.RigidBox(neighbors=64, cell_capacity=64, clock="global"))
    assert not np.isfinite(float(first.final_state.t_dsp))  # the global clock leaves no valid check times
    cont = rigid.run(first, t[1:], engine=eng)
    assert int(cont.outs["n_c"][-1]) > int(first.outs["n_c"][-1])
    assert _min_gap(cont.final_state) >= -1e-6 * 0.1 - 1e-12
    log = cont.collision_log
    assert np.all(log["dP"] <= 1e-12 * log["P_scale"])


@pytest.mark.slow
@pytest.mark.parametrize("clock", ["body", "global"])
def test_accelerator_block_widths_give_the_same_run(monkeypatch, clock):
    """The widths a GPU gets from box._lanes (pair build and pair scan 2^20, rotation chunks 16 384: one block
    each) against narrow ones (32, 32, 2: many blocks in every pass of this small box), both on the CPU: the same
    collisions, steps and final state (per-body rotation and the pair order do not depend on the blocking)."""
    from jaxcoag.aggregates.rigid import box as rbox

    eng = rigid.RigidBox(neighbors=64, cell_capacity=64, clock=clock)
    t = jnp.linspace(0.2, 1.0, 5)

    def go():
        b = rigid.box_model("iii", n0=300, box=6.0, v0=13.0, key=jax.random.key(4))
        return rigid.run(b, t, engine=eng)

    monkeypatch.setattr(rbox, "_lanes", lambda cpu_width, accelerator_width: max(2, cpu_width // 64))
    jax.clear_caches()
    cpu = go()
    monkeypatch.setattr(rbox, "_lanes", lambda cpu_width, accelerator_width: accelerator_width)
    jax.clear_caches()  # the widths are read at trace time
    acc = go()
    assert int(cpu.outs["n_c"][-1]) > 20
    for k in ("n_aggregates", "n_c", "n_steps", "n_build"):
        np.testing.assert_array_equal(np.asarray(acc.outs[k]), np.asarray(cpu.outs[k]))
    np.testing.assert_array_equal(np.asarray(acc.final_state.X), np.asarray(cpu.final_state.X))
    np.testing.assert_array_equal(np.asarray(acc.final_state.q), np.asarray(cpu.final_state.q))
