"""One collision-outcome interface for both engines (jaxcoag.outcomes).

Checks: every recipe's Monte Carlo products conserve mass exactly (single collisions and group
events with n_c up to 2^40); Shattering's Monte Carlo products and its binned redistribution data
describe the same collision (remnant m_L - chi m_S and ejecta (1 + chi) m_S for erosion, all of
m_L + m_S for shattering); ShatterAbove decides the same pairs in both engines; Shattering with an
explicit m_lo at the grid bottom equals the grid-bottom default; refusals before any work; and
(slow) ShatterAbove binned vs Monte Carlo on the thesis §5.3.4 constant-kernel box.
"""

import equinox as eqx
import numpy as np
import pytest
import jax
import jax.numpy as jnp

from jaxcoag import Binned, MassGrid, Monodisperse, MonteCarlo, evolve, kernels
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.binned.twobin import TwoBinScheme, pair_indices
from jaxcoag.outcomes import (O07Recipe, O09Recipe, RecipeOutcome, ShatterAbove, Shattering, Sticking,
                              VfragShatter)
from jaxcoag.physics.contact import Material
from jaxcoag.physics.dominik_tielens import DTEnergy


class _VKernel(kernels.AbstractKernel):
    """Test kernel with a relative velocity dv^2 = v2 [cm^2 s^-2] (constant) and K = 1 cm^3 s^-1."""

    v2: jax.Array

    def relative_velocity2(self, m1, m2, x1=None, x2=None):
        return self.v2 * jnp.ones(jnp.broadcast_shapes(jnp.shape(m1), jnp.shape(m2)))

    def __call__(self, m1, m2, x1=None, x2=None):
        return jnp.ones(jnp.broadcast_shapes(jnp.shape(m1), jnp.shape(m2)))


MAT = Material.ch4_silicate()
M0 = float(MAT.m0)
PAIRS = [  # (m_i, m_j, n_c) in units of the monomer mass: equal, 3:1, 1:1e4 single, group events
    (1.0, 1.0, 1.0), (3e4, 1e4, 1.0), (1e4, 1.0, 1.0), (1.0, 1e4, 1.0), (1e8, 10.0, 2.0 ** 10),
    (1e16, 1.0, 2.0 ** 40)]


@eqx.filter_jit
def _products_jit(outcome, mi, mj, nc, psi_i, psi_j, key):
    return outcome.products(mi, jnp.log(mi), psi_i, mj, jnp.log(mj), psi_j, nc, jnp.log(nc), key)


def _products(outcome, mi, mj, nc, psi_i, psi_j, key):
    """Products of one (group) event, compiled once per outcome (float64 scalars)."""
    f = lambda x: jnp.asarray(x, jnp.float64)
    return _products_jit(outcome, f(mi), f(mj), f(nc), psi_i, psi_j, key)


def _outcomes():
    k = _VKernel(jnp.asarray(1e6))  # dv = 10 m/s: O07 + DT fragments the big pairs, p_f(v_frag=1 m/s) ~ 1
    return {
        "sticking": Sticking(),
        "shatter_above": ShatterAbove(5e7 * M0, M0),
        "shattering": Shattering(100.0, m_lo=M0).bind(k),
        "o07_dt": RecipeOutcome(O07Recipe(frag_model=DTEnergy()), MAT, width=0.3).bind(k),
        "o07_nsmall": RecipeOutcome(O07Recipe(n_small=40.0), MAT).bind(k),
        "o09": RecipeOutcome(O09Recipe(), MAT).bind(k),
        "vfrag": RecipeOutcome(VfragShatter(1000.0, probability="linear", p_width=0.5), MAT).bind(k),
    }


@pytest.mark.parametrize("name", list(_outcomes()))
def test_mc_products_conserve_mass(name):
    """sum(count m) = m_i + n_c m_j to rounding, for every recipe, pair and several draws."""
    out = _outcomes()[name]
    psi_i, psi_j = jnp.array([2.0]), jnp.array([5.0])
    keys = jax.random.split(jax.random.PRNGKey(3), 4)
    for mi, mj, nc in PAIRS:
        mi, mj = mi * M0, mj * M0
        for key in keys:
            pr = _products(out, mi, mj, nc, psi_i, psi_j, key)
            assert pr.m.shape == (out.n_products,)
            total = float(jnp.sum(jnp.where(pr.valid, pr.count * pr.m, 0.0)))
            np.testing.assert_allclose(total, mi + nc * mj, rtol=1e-13, err_msg=f"{name} {mi} {mj} {nc}")
            assert bool(jnp.all(jnp.where(pr.valid, pr.count, 0.0) >= 0.0))
            assert bool(jnp.all(jnp.where(pr.valid, pr.psi, 1.0) >= 1.0))


def test_shattering_mc_products_match_binned_data():
    """Shattering at p_f = 1 (dv = 100 v_frag): the Monte Carlo products of one collision are the
    binned FragData's ejecta and remnant (DustPy rules: erosion at mass ratio >= 10, chi = 1)."""
    k = _VKernel(jnp.asarray(1e8))
    sh = Shattering(1.0, m_lo=M0, n_frag=6)
    g = MassGrid.log(M0, 1e6 * M0, 1)   # one bin per decade, centres 10^(k + 1/2) m0
    iL, iS = pair_indices(g.nbins)
    d = sh.twobin_data(k, g, iL, iS)
    np.testing.assert_allclose(np.asarray(d.p), 1.0, rtol=0, atol=1e-12)
    mc = sh.bind(k)
    psi = jnp.ones(0)
    key = jax.random.PRNGKey(0)
    for p in range(iL.size):
        mL, mS = float(g.centers[iL[p]]), float(g.centers[iS[p]])
        pr = _products(mc, mL, mS, 1.0, psi, psi, key)
        frag = np.asarray(pr.valid[1:])
        m_frag = float(jnp.sum(jnp.where(pr.valid[1:], pr.count[1:] * pr.m[1:], 0.0)))
        np.testing.assert_allclose(m_frag, float(d.ejecta[p]), rtol=1e-12)  # same ejecta mass
        erodes = iL[p] > iS[p]  # 10x per bin: every unequal pair is at or above crater_ratio = 10
        if erodes:
            np.testing.assert_allclose(float(pr.m[0]), mL - mS, rtol=1e-13)   # remnant m_L - chi m_S
            assert float(jnp.max(jnp.where(pr.valid[1:], pr.m[1:], 0.0))) <= mS * (1 + 1e-12)
        else:
            assert not bool(pr.valid[0])                                      # nothing survives
            assert float(jnp.max(jnp.where(pr.valid[1:], pr.m[1:], 0.0))) <= mL * (1 + 1e-12)
        # fragments are drawn from [m_lo, m_hi]; only the last one (the remainder) may be lighter
        assert frag.any() and int(jnp.sum(pr.valid[1:] & (pr.m[1:] < M0 * (1 - 1e-12)))) <= 1


def test_shatter_above_same_pairs_in_both_engines():
    """The binned probability and the Monte Carlo products shatter exactly the same pairs, including
    products that land exactly on m_frag (they stick in both)."""
    sa = ShatterAbove(64.0, 1.0)
    g = MassGrid.from_edges(2.0 ** np.arange(-0.5, 10.0))  # centres 1, 2, 4, ..., 512 g
    iL, iS = pair_indices(g.nbins)
    mL, mS = np.round(g.centers[iL]), np.round(g.centers[iS])
    p = np.asarray(sa.probability(kernels.Constant(1.0), jnp.asarray(g.centers[iL]), jnp.asarray(g.centers[iS])))
    np.testing.assert_array_equal(p, (mL + mS > 64.0).astype(float))
    psi = jnp.ones(0)
    key = jax.random.PRNGKey(0)
    for a, b, pp in zip(mL, mS, p):
        pr = _products(sa, a, b, 1.0, psi, psi, key)
        assert (float(pr.m[0]) == 1.0) == (pp == 1.0)
        np.testing.assert_allclose(float(pr.count[0] * pr.m[0]), a + b, rtol=1e-15)
    # binned data: all of m_L + m_S goes to the monomer bin (bin 0)
    d = sa.twobin_data(kernels.Constant(1.0), g, iL, iS)
    np.testing.assert_array_equal(np.asarray(d.W)[:, 0], 1.0)
    np.testing.assert_allclose(np.asarray(d.ejecta), mL + mS, rtol=1e-14)


def test_shattering_explicit_m_lo_equals_grid_bottom():
    """Shattering(m_lo = lowest grid edge) gives the same binned right-hand side as the default."""
    k = _VKernel(jnp.asarray(1e4))
    g = MassGrid.log(1e-6, 1e6, 3)
    sch = TwoBinScheme()
    y = jnp.asarray(np.r_[np.random.default_rng(1).random(g.nbins) * 1e-9, 0.0])
    r0 = sch.rhs(0.0, y, sch.precompute(k, g, Shattering(100.0)))
    r1 = sch.rhs(0.0, y, sch.precompute(k, g, Shattering(100.0, m_lo=1e-6)))
    np.testing.assert_allclose(r1, r0, rtol=1e-12, atol=1e-14 * float(jnp.max(jnp.abs(r0))))
    assert float(jnp.max(jnp.abs(r0))) > 0


def test_refusals_before_work():
    mc = MonteCarlo(n_particles=100)
    t = jnp.array([1.0])
    with pytest.raises(JaxcoagInputError, match="m_lo"):
        evolve(_VKernel(jnp.asarray(1.0)), mc, Monodisperse(1.0), t, outcome=Shattering(100.0),
               key=jax.random.PRNGKey(0))
    with pytest.raises(TypeError, match="relative velocity"):
        evolve(kernels.Constant(1.0), mc, Monodisperse(1.0), t, outcome=Shattering(100.0, m_lo=1.0),
               key=jax.random.PRNGKey(0))
    with pytest.raises(JaxcoagInputError, match="n_frag"):
        RecipeOutcome(O07Recipe(frag_model=DTEnergy()), MAT, n_frag=0)
    with pytest.raises(JaxcoagInputError, match="remnants=2"):
        RecipeOutcome(O09Recipe(), MAT, remnants=1)
    with pytest.raises(JaxcoagInputError, match="m_mono"):
        ShatterAbove(10.0, -1.0)
    with pytest.raises(JaxcoagInputError, match="frag_model"):
        O07Recipe(frag_model="DT")
    # defaults follow the recipe: O07 without fragmentation needs one slot, O09 2 + 4
    assert RecipeOutcome(O07Recipe(), MAT).n_products == 1
    assert RecipeOutcome(O09Recipe(), MAT).n_products == 6


@pytest.mark.slow
def test_shatter_above_binned_vs_mc_steady_state():
    """Thesis §5.3.4 box: K = 1 cm^3/s, monomers of 1 g at 1 cm^-3, products above m_frag = 100 g
    shatter into monomers. Time-averaged (t = 500..3000 s) number density and mass per coarse bin:
    binned (20 bins/decade) vs three exact-DSMC runs of 2000 particles, within 4 standard errors
    of the MC mean (from the run-to-run scatter) plus twice the binned grid error (10 vs 20 per
    decade), which includes the continuous-mass approximation of the monomer region."""
    out = ShatterAbove(100.0, 1.0)
    K = kernels.Constant(1.0)
    t_out = np.linspace(500.0, 3000.0, 26)
    edges = np.array([0.5, 1.5, 4.5, 15.5, 50.5, 200.5])

    def binned(bpd):
        g = MassGrid.log(10 ** (-0.5 / bpd), 1e3, bpd)
        r = evolve(K, Binned(g), Monodisperse(1.0, 1.0), t_out, outcome=out)
        return np.r_[np.asarray(r.moments(0))[-1], np.asarray(r.mass_per_bin(edges))[-1]]

    b20, b10 = binned(20), binned(10)
    runs = []
    for s in range(3):
        r = evolve(K, MonteCarlo(n_particles=2000), Monodisperse(1.0, 1.0), t_out, outcome=out,
                   key=jax.random.PRNGKey(s))
        assert float(jnp.max(jnp.where(r.valid, r.m, 0.0))) <= 100.0
        runs.append(np.r_[np.asarray(r.moments(0)).mean(), np.asarray(r.mass_per_bin(edges)).mean(0)])
    runs = np.array(runs)
    mean, se = runs.mean(0), runs.std(0, ddof=1) / np.sqrt(len(runs))
    tol = 4 * se + 2 * np.abs(b20 - b10)
    assert np.all(np.abs(b20 - mean) < tol), (b20, mean, tol)
