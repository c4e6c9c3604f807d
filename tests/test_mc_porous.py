"""Monte Carlo with porosity as structural parameter: RecipeOutcome (shared O07 physics) and rain-out.

Checks: the adapter reproduces the physics recipe for single collisions with the kernel's own
Delta v and conserves mass exactly; group events (n_c > 1) agree with n_c sequential collisions;
the CCA / PCA limits of thesis eqs. 2.13-2.19 (§2.2.4) through the adapter; a porous MC run
(Brownian hit-and-stick, vmapped over keys) conserves mass exactly (active + rained), keeps
1 <= psi <= N^0.425 (the CCA upper bound of the B = 0 recipe) and accounts rain-out
(thesis eq. 2.25) consistently.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcoag as jc
from jaxcoag import Scene, constants as C, effects as E, mc
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.mc import RainOutKernel, rainout_summary
from jaxcoag.outcomes import O07Recipe, RecipeOutcome
from jaxcoag.physics import gas as G
from jaxcoag.physics.contact import Material
from jaxcoag.physics.ormel07 import o07_outcome

MAT = Material.ch2_quartz()
M0 = float(MAT.m0)
GAS = G.mmsn_hayashi81(C.AU, 1e-4, tL_factor=2 * math.pi)
KP = Scene(velocities=(E.Brownian(), E.TurbulenceW84()), porosity="psi").kernel(GAS, material=MAT)
KB = Scene(velocities=(E.Brownian(),), porosity="psi").kernel(GAS, material=MAT)
KEY = jax.random.key(3)


def _call(out, mi, pi, mj, pj, nc=1.0, key=KEY):
    return _jcall(out, jnp.asarray(mi, float), jnp.asarray(pi, float), jnp.asarray(mj, float), jnp.asarray(pj, float),
                  jnp.asarray(float(nc)), key)


@eqx.filter_jit  # the outcome may hold a plain-function recipe (static)
def _jcall(out, mi, pi, mj, pj, nc, key):
    return out.products(mi, jnp.log(mi), pi[None], mj, jnp.log(mj), pj[None], nc, jnp.log(nc), key)


PAIRS = [(1e4 * M0, 30.0, 10 * M0, 5.0), (1e8 * M0, 80.0, 1e3 * M0, 40.0), (1e12 * M0, 80.0, 1e12 * M0, 60.0),
         (1e-2, 86.0, 1e-5, 20.0)]


@pytest.mark.parametrize("mi, pi, mj, pj", PAIRS)
def test_single_collision_is_the_physics_recipe_with_the_kernel_dv(mi, pi, mj, pj):
    out = RecipeOutcome(O07Recipe(), MAT).bind(KP)
    assert out.n_products == 1
    P = _call(out, mi, pi, mj, pj)
    dv = jnp.sqrt(KP.relative_velocity2(mi, mj, jnp.array([pi]), jnp.array([pj])))
    ref = o07_outcome(mi, pi, mj, pj, dv, MAT)
    np.testing.assert_allclose(float(P.psi[0, 0]), float(ref.psi_one), rtol=1e-13)
    np.testing.assert_allclose(float(P.m[0] * P.count[0]), mi + mj, rtol=1e-15)
    assert bool(P.valid[0]) and float(P.psi[0, 0]) >= 1.0


@pytest.mark.parametrize("mi, pi, mj, pj", PAIRS[:2] + [(1e12 * M0, 80.0, 1e6 * M0, 40.0)])
@pytest.mark.parametrize("nc", [8, 64])
def test_group_event_equals_sequential_collisions(mi, pi, mj, pj, nc):
    out = RecipeOutcome(O07Recipe(), MAT).bind(KP)
    P = _call(out, mi, pi, mj, pj, nc)
    m, p = mi, pi
    for _ in range(nc):
        Q = _call(out, m, p, mj, pj)
        m, p = float(Q.m[0]), float(Q.psi[0, 0])
    np.testing.assert_allclose(float(P.m[0]), mi + nc * mj, rtol=1e-14)
    np.testing.assert_allclose(m, mi + nc * mj, rtol=1e-13)
    # closed-form compounding with the per-collision change held fixed: the relative error of the
    # psi change is O(n_c m_j/m_i), which the engine bounds by f_eps
    np.testing.assert_allclose(float(P.psi[0, 0]) - pi, p - pi, rtol=0.5 * nc * mj / mi + 1e-6, atol=1e-9 * pi)


def test_cca_and_pca_limits_through_the_adapter():
    hs = dict(restr_factor=1e250)  # force hit-and-stick (no compaction) whatever Delta v
    cca0 = RecipeOutcome(O07Recipe(B=0.0, **hs), MAT).bind(KB)
    cca1 = RecipeOutcome(O07Recipe(B=1.0, **hs), MAT).bind(KB)
    m, p0, p1 = M0, 1.0, 1.0
    vals = {}
    for k in range(1, 21):
        p0 = float(_call(cca0, m, p0, m, p0).psi[0, 0])
        p1 = float(_call(cca1, m, p1, m, p1).psi[0, 0])
        m = 2 * m
        vals[2 ** k] = p1
    np.testing.assert_allclose(p0, 362.039, rtol=1e-5)                    # R3: psi(2^20) = N^0.425 (B = 0)
    np.testing.assert_allclose([vals[2], vals[64]], [2.29380, 62.068], rtol=1e-4)  # CCA with psi_add (thesis eq. 2.15)
    np.testing.assert_allclose(vals[2 ** 20] / vals[2 ** 19], 1.342573, rtol=2e-4)
    # PCA by group events: one aggregate sweeps n_c = f_eps N monomers per event (closed-form update)
    for B, N_end, f_eps, ref, rtol in [(0.0, 2e5, 1e-2, 1.42501, 2e-3), (1.0, 1e3, 1e-3, 9.0442, 1e-2)]:
        out = RecipeOutcome(O07Recipe(B=B, **hs), MAT).bind(KB)
        N, p = 1.0, 1.0
        while N < N_end - 0.5:
            nc = max(1.0, min(math.floor(f_eps * N), N_end - N))
            p = float(_call(out, N * M0, p, M0, 1.0, nc).psi[0, 0])
            N += nc
        np.testing.assert_allclose(p, ref, rtol=rtol)


def test_two_remnants_misses_and_fragments_conserve_mass():
    # a recipe with bounce probability, misses and a power-law fragment fraction (all from Outcome)
    from jaxcoag.physics.outcome import Outcome

    def recipe(m1, psi1, m2, psi2, dv, mat, width=0.0):
        return Outcome.build(eff=0.7, p_two=0.4, split=m1 / (m1 + m2), f_pwl=0.25, q=-1.8, m_lo=mat.m0,
                             m_hi=0.25 * (m1 + m2), psi_one=0.5 * (psi1 + psi2), psi_a=psi1, psi_b=psi2)

    out = RecipeOutcome(recipe, MAT, remnants=2, n_frag=6).bind(KP)
    assert out.n_products == 8
    kinds = set()
    for s in range(40):
        for nc in (1.0, 16.0):
            mi, mj = 1e6 * M0, 1e4 * M0
            P = _call(out, mi, 20.0, mj, 5.0, nc, jax.random.key(s))
            tot = float(jnp.sum(jnp.where(P.valid, P.m * P.count, 0.0)))
            np.testing.assert_allclose(tot, mi + nc * mj, rtol=1e-12)
            assert np.all(np.asarray(P.psi[:, 0])[np.asarray(P.valid)] >= 1.0)
            assert np.all(np.asarray(P.count) >= 0)
            nv = int(jnp.sum(P.valid))
            kinds.add((nc, nv > 2, bool(P.valid[1])))
    # both single- and two-remnant events and fragment draws occurred
    assert (1.0, True, True) in kinds and (1.0, True, False) in kinds


def test_constructor_errors_say_what_to_change():
    from jaxcoag.kernels import Constant

    with pytest.raises(JaxcoagInputError, match="relative velocity"):
        RecipeOutcome(O07Recipe(), MAT).check(Constant(1.0), "mc")
    with pytest.raises(JaxcoagInputError, match="relative velocity"):  # refused by evolve before any work
        jc.evolve(Constant(1.0), mc.MonteCarlo(n_particles=10), jc.Monodisperse(M0), jnp.array([1.0]), key=KEY,
                  outcome=RecipeOutcome(O07Recipe(), MAT))
    with pytest.raises(JaxcoagInputError, match="remnants must be 1 or 2"):
        RecipeOutcome(O07Recipe(), MAT, remnants=3)
    with pytest.raises(JaxcoagInputError, match="Material"):
        RecipeOutcome(O07Recipe(), 3.0)


@pytest.fixture(scope="module")
def brownian_runs():
    """Two porous Brownian hit-and-stick runs (B = 0), vmapped over keys, with a rain-out sink."""
    N = 256
    rho_d = float(GAS.rho_g) / 240.0
    K0 = float(KB(M0, M0, jnp.array([1.0]), jnp.array([1.0])))
    t_coll = 1.0 / (rho_d / M0 * K0)
    tau_rain = float(KB.particles(jnp.asarray(12 * M0), jnp.array([3.0])).tau_f)
    K = RainOutKernel(KB, tau_rain)
    out = RecipeOutcome(O07Recipe(B=0.0), MAT)
    t_out = jnp.array([0.5, 2.0, 8.0, 32.0, 128.0]) * t_coll
    # struct0 defaults to psi = 1 (compact monomers) for the porous kernel (n_struct = 1)
    eng = mc.MonteCarlo(n_particles=float(N), capacity=N + 8)
    f = jax.vmap(lambda k: jc.evolve(K, eng, jc.Monodisperse(M0, rho_d), t_out, key=k, outcome=out, throw=False))
    keys = jax.random.split(jax.random.key(11), 2)
    return K, N, f(keys), keys, out, t_out, rho_d, eng


def test_porous_mc_run_conserves_mass_and_respects_fractal_bounds(brownian_runs):
    K, N, res, _, _, _, _, _ = brownian_runs
    g = res.w * 2.0 ** res.z
    # a run either reaches the last output or stops with zero_rate because at most one particle is
    # left in the turbulent layer (the others rained out: the rate is then exactly zero)
    ok = np.asarray(res.status == jc.RESULTS.successful)
    zero = np.asarray(res.status == jc.RESULTS.zero_rate)
    tau = np.asarray(K.base.particles(res.m[:, -1], res.psi[:, -1]).tau_f)
    active = np.sum(np.where(np.asarray(res.valid[:, -1]) & (tau <= float(K.tau_rain)), np.asarray(g[:, -1]), 0.0), -1)
    assert np.all(ok | (zero & (active < 2))), (res.status, active)
    tot = jnp.sum(jnp.where(res.valid, g * res.m, 0.0), axis=-1)
    np.testing.assert_allclose(np.asarray(tot), N * M0, rtol=1e-12)    # active + rained, exact
    v = np.asarray(res.valid)
    n_mono = np.asarray(res.m / M0)[v]
    psi = np.asarray(res.psi[..., 0])[v]
    assert np.all(psi >= 1.0)
    # hit-and-stick with B = 0 cannot be fluffier than CCA: psi <= N^0.425 (thesis eq. 2.13; equality for CCA)
    assert np.all(psi <= n_mono ** 0.425 * (1 + 1e-9))
    # growth happened: particles rain out from ~3 monomers on, so the largest aggregate of a run is
    # 6 or 8 monomers (32 runs of this box, each value in about half of them)
    assert n_mono.max() >= 6
    # aggregates above a few monomers are porous (psi grows with N in the hit-and-stick regime)
    assert np.median(psi[n_mono >= 6]) > 1.4
    # the two members used different keys
    assert not np.array_equal(np.asarray(res.m[0]), np.asarray(res.m[1]))


def test_rain_out_accounting(brownian_runs):
    K, N, res, _, _, t_out, _, _ = brownian_runs
    s = rainout_summary(res, K)
    f = np.asarray(s["f_rain"])
    assert np.all(np.diff(f, axis=-1) >= -1e-15) and np.all(f[:, -1] > 0.05)  # rain-out happened
    g = np.asarray(res.w * 2.0 ** res.z)
    v = np.asarray(res.valid)
    tau = np.asarray(K.base.particles(res.m, res.psi).tau_f)
    gone = v & (tau > float(K.tau_rain))
    np.testing.assert_allclose(np.asarray(s["M_rain"]), np.sum(np.where(gone, g * np.asarray(res.m), 0), -1), rtol=1e-13)
    # t_rain = first output time with rained mass; rained particles never collide again: every
    # rained species of snapshot k is still present, unchanged, at snapshot k + 1
    for r in range(2):
        k0 = int(np.argmax(f[r] > 0))
        np.testing.assert_allclose(float(s["t_rain"][r]), float(t_out[k0]), rtol=1e-15)
        for k in range(k0, f.shape[1] - 1):
            a = {(float(mm), float(pp)) for mm, pp, gg in zip(np.asarray(res.m[r, k]), np.asarray(res.psi[r, k, :, 0]), gone[r, k]) if gg}
            b = {(float(mm), float(pp)) for mm, pp, gg in zip(np.asarray(res.m[r, k + 1]), np.asarray(res.psi[r, k + 1, :, 0]), gone[r, k + 1]) if gg}
            assert a <= b
        gl = np.where(gone[r, -1], g[r, -1], 0.0)
        assert float(s["n_rain"][r]) == pytest.approx(gl.sum(), rel=1e-13) and gl.sum() >= 1
        np.testing.assert_allclose(float(s["m"][r]), (gl * np.asarray(res.m[r, -1])).sum() / gl.sum(), rtol=1e-13)
        np.testing.assert_allclose(float(s["psi"][r]), (gl * np.asarray(res.psi[r, -1, :, 0])).sum() / gl.sum(), rtol=1e-13)
        # radii from the particles' own masses and psi (thesis eq. 2.1: a* = (3m / 4 pi rho_s)^(1/3),
        # a = a* psi^(1/3)), with the material's density, number-weighted over the rained particles
        ml, pl = np.asarray(res.m[r, -1]), np.asarray(res.psi[r, -1, :, 0])
        a_star = (3.0 * ml / (4.0 * np.pi * float(MAT.rho_s))) ** (1.0 / 3.0)
        a_geo = a_star * pl ** (1.0 / 3.0)
        np.testing.assert_allclose(float(s["a_star"][r]), (gl * a_star).sum() / gl.sum(), rtol=1e-13)
        np.testing.assert_allclose(float(s["a"][r]), (gl * a_geo).sum() / gl.sum(), rtol=1e-13)
        np.testing.assert_allclose(float(s["a_over_astar"][r]), (gl * a_geo).sum() / (gl * a_star).sum(), rtol=1e-13)
        # psi >= 1 for every rained particle and > 1 for the aggregates: a/a* > 1, below max psi^(1/3)
        assert 1.0 < float(s["a_over_astar"][r]) <= np.max(np.where(gl > 0, pl, 1.0)) ** (1.0 / 3.0) * (1 + 1e-12)


@pytest.mark.slow
def test_vmap_member_equals_single_run(brownian_runs):
    K, N, res, keys, out, t_out, rho_d, eng = brownian_runs
    one = jc.evolve(K, eng, jc.Monodisperse(M0, rho_d), t_out, key=keys[1], outcome=out)
    np.testing.assert_array_equal(np.asarray(one.m), np.asarray(res.m[1]))
    np.testing.assert_array_equal(np.asarray(one.psi), np.asarray(res.psi[1]))
