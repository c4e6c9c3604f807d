"""The shared physics Outcome consumed by the binned engine (Birnstiel, Dullemond & Brauer 2010, eq. 15).

Checks: per-pair mass balance and rhs conservation to round-off for O07 (DT thresholds),
O09 (surrogate tables) and v_frag shattering; exact equivalence of RecipeOutcome with the
fixed-pattern Shattering / ShatterAbove for matching outcomes; the no-fragmentation Outcome reproduces
the two-bin coagulation tensors (merged forms: no cancellation for tiny projectiles); the
thesis eq. 6.29-6.30 fragment bin integrals; a solve that conserves mass; and the end-to-end gradient
d ln<m>/d ln(gamma) through jaxcoag.evolve with a smooth outcome vs central finite differences.
"""

import numpy as np
import pytest
import jax
import jax.numpy as jnp

import jaxcoag
from jaxcoag import Binned, MassGrid, RESULTS, evolve, scenes
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.binned.redistribution import fragment_weights, place_remnant
from jaxcoag.outcomes import O07Recipe, O09Recipe, RecipeOutcome, ShatterAbove, Shattering, VfragShatter
from jaxcoag.physics.dominik_tielens import DTEnergy
from jaxcoag.physics.outcome import Outcome, bounce_outcome
from jaxcoag.binned.twobin import TwoBinScheme, pair_indices, _ext_log_centers
from jaxcoag.kernels import Constant
from jaxcoag.physics import gas as G
from jaxcoag.physics.contact import Material

GRID = MassGrid.log(1e-11, 1e1, 2)  # 24 bins
SCH = TwoBinScheme()


def _kern(alpha=1e-3):
    gas = G.midplane_state(2.4e-11, 162.0, alpha, 3.83e-8)  # thesis ch. 4 gas at 3 AU
    return scenes.nebula_ch4().kernel(gas, rho_s=3.0)


def _state(grid, seed=0):
    rng = np.random.default_rng(seed)
    return jnp.asarray(np.r_[rng.random(grid.nbins) * 1e-13, 0.0])


def _pair_masses(grid):
    iL, _ = pair_indices(grid.nbins)
    return jnp.exp(jnp.asarray(grid.log_centers))[iL]


@pytest.mark.parametrize("recipe,width", [(O07Recipe(frag_model=DTEnergy()), 0.0),
                                          (O07Recipe(frag_model=DTEnergy()), 0.3),
                                          (O07Recipe(frag_model=DTEnergy(), restr_factor=5.0), 0.3), (O09Recipe(), 0.0),
                                          (O09Recipe(), 0.3), (VfragShatter(100.0), 0.0)])
def test_mass_balance_to_round_off(recipe, width):
    kern = _kern(1e-2)
    fr = RecipeOutcome(recipe, Material.ch4_silicate(), width=width)
    data = SCH.precompute(kern, GRID, fr)
    bal = data.frag.mass_balance() / _pair_masses(GRID)
    assert float(jnp.max(jnp.abs(bal))) < 2e-14  # ~100 ulp of the pair mass
    # the setting really fragments (alpha = 1e-2: dv ~ 10 m/s for the largest bins)
    assert float(jnp.max(data.frag.m_pwl / _pair_masses(GRID))) > 0.5
    r = SCH.rhs(0.0, _state(GRID), data)
    assert abs(float(jnp.sum(r))) < 1e-14 * float(jnp.sum(jnp.abs(r)))


@pytest.mark.parametrize("prob", ["maxwellian", "step"])
def test_equivalent_to_engine_shattering(prob):
    """VfragShatter (mixture weight p_f, full shattering, q = 11/6 from the grid bottom to the
    top edge of the larger body's bin) reproduces Shattering without erosion to round-off."""
    kern = _kern(1e-3)
    le = GRID.log_edges
    sh = Shattering(30.0, probability=prob, crater_ratio=1e300)
    rec = VfragShatter(30.0, probability=prob, m_lo=float(np.exp(le[0])), m_hi_factor=float(np.exp((le[1] - le[0]) / 2)))
    of = RecipeOutcome(rec, Material.ch4_silicate())
    y = _state(GRID, 1)
    r1 = SCH.rhs(0.0, y, SCH.precompute(kern, GRID, sh))
    r2 = SCH.rhs(0.0, y, SCH.precompute(kern, GRID, of))
    assert float(jnp.max(jnp.abs(r1 - r2))) < 1e-13 * float(jnp.max(jnp.abs(r1)))
    p = of.probability(kern, jnp.asarray(GRID.centers[-1]), jnp.asarray(GRID.centers[-1]))
    np.testing.assert_allclose(p, sh.probability(kern, GRID.centers[-1], GRID.centers[-1]), rtol=1e-14)


def test_shatter_above_equivalent_to_recipe_outcome():
    """ShatterAbove's fixed-pattern data equal a shared-physics Outcome written independently
    (f_pwl = H(ln(M_tot/m_frag)), all fragments at the monomer mass m0 = 1 g)."""
    g = MassGrid.log(1.0, 1e12, 4)
    mat = Material(a0=(3.0 / (4.0 * np.pi)) ** (1.0 / 3.0), rho_s=1.0, gamma=25.0, E_star=1e11, xi_crit=1e-7)
    np.testing.assert_allclose(mat.m0, 1.0, rtol=1e-14)  # monomer mass 1 g: the thesis ch. 5 units

    def shatter_recipe(m1, psi1, m2, psi2, dv, mat, width=0.0):
        f = jnp.where(jnp.log(m1 + m2) > jnp.log(1e10), 1.0, 0.0)
        return Outcome.build(f_pwl=f, m_lo=mat.m0, m_hi=mat.m0, psi_one=jnp.ones_like(m1))

    of = RecipeOutcome(shatter_recipe, mat, use_velocity=False)
    sa = ShatterAbove(1e10, 1.0)
    assert not of.needs_velocity and not sa.needs_velocity
    y = _state(g, 2)
    r1 = SCH.rhs(0.0, y, SCH.precompute(Constant(1.0), g, sa))
    r2 = SCH.rhs(0.0, y, SCH.precompute(Constant(1.0), g, of))
    assert float(jnp.max(jnp.abs(r1))) > 0  # products above 1e10 g exist on this grid
    assert float(jnp.max(jnp.abs(r1 - r2))) < 1e-13 * float(jnp.max(jnp.abs(r1)))


def test_sticking_outcome_reproduces_coagulation_tensors():
    """O07 without fragmentation = perfect sticking: equals the coagulation operator, including
    projectiles 1e-40 times lighter than the target (merged loss/gain, no cancellation)."""
    g = MassGrid.log(1e-20, 1e20, 1)
    kern = Constant(1.0)
    of = RecipeOutcome(O07Recipe(frag_model=None), Material.ch6_ice(), use_velocity=False)
    y = _state(g, 3)
    r0 = SCH.rhs(0.0, y, TwoBinScheme(gel_sweep=False).precompute(kern, g))
    r2 = SCH.rhs(0.0, y, SCH.precompute(kern, g, of))
    np.testing.assert_allclose(r2, r0, rtol=1e-12, atol=1e-14 * float(jnp.max(jnp.abs(r0))))
    # the largest bin's gain from sweeping up the smallest bin alone is resolved
    lce = jnp.asarray(_ext_log_centers(g))
    idx, coef = place_remnant(lce, jnp.array([g.nbins - 2]), lce[g.nbins - 2:g.nbins - 1],
                              jnp.log1p(jnp.exp(lce[:1] - lce[g.nbins - 2:g.nbins - 1])), jnp.array([1.0]))
    np.testing.assert_allclose(float(jnp.sum(coef)), float(jnp.exp(lce[0])), rtol=1e-12)


def test_bounce_changes_nothing_and_eff_scales_the_kernel():
    """A pure bounce (p_two = 1, split = m1/M_tot: two remnants equal to the parents) leaves the
    distribution unchanged; eff = 1/2 halves the sticking rates."""
    def bounce(m1, psi1, m2, psi2, dv, mat, width=0.0):
        return bounce_outcome(m1, psi1, m2, psi2, mat.m0)

    def half_stick(m1, psi1, m2, psi2, dv, mat, width=0.0):
        return Outcome.build(eff=0.5, m_lo=mat.m0, m_hi=mat.m0, psi_one=jnp.ones_like(m1))

    kern, y = Constant(1.0), _state(GRID, 5)
    mat = Material.ch4_silicate()
    rb = SCH.rhs(0.0, y, SCH.precompute(kern, GRID, RecipeOutcome(bounce, mat, use_velocity=False)))
    r0 = SCH.rhs(0.0, y, TwoBinScheme(gel_sweep=False).precompute(kern, GRID))
    assert float(jnp.max(jnp.abs(rb))) < 1e-13 * float(jnp.max(jnp.abs(r0)))
    rh = SCH.rhs(0.0, y, SCH.precompute(kern, GRID, RecipeOutcome(half_stick, mat, use_velocity=False)))
    np.testing.assert_allclose(rh, 0.5 * r0, rtol=1e-12, atol=1e-14 * float(jnp.max(jnp.abs(r0))))


def test_place_remnant_two_bin_split():
    """A remnant between two centres is split in number and mass exactly; below the grid it
    goes to bin 0, beyond it to the gel accumulator."""
    g = MassGrid.log(1.0, 1e4, 1)  # centres 10^0.5 .. 10^3.5
    lce = jnp.asarray(_ext_log_centers(g))
    mc = np.exp(np.asarray(lce))
    ref = jnp.array([3, 3, 0, 3])
    lr = jnp.log(jnp.array([20.0, 0.5, 5.0, 5e5]))  # general, below, merged-up, beyond
    idx, coef = place_remnant(lce, ref, lce[ref], lr - lce[ref], jnp.full(4, 0.5))
    idx, coef = np.asarray(idx), np.asarray(coef)
    np.testing.assert_allclose(coef.sum(axis=1), 0.5 * (np.exp(np.asarray(lr)) - mc[[3, 3, 0, 3]]), rtol=1e-13)
    # 20 g lies between the centres 10^0.5 and 10^1.5 (far from its parent bin 3)
    e = (20.0 - mc[0]) / (mc[1] - mc[0])
    assert idx[0, 1] == 0 and idx[0, 2] == 1
    np.testing.assert_allclose(coef[0, 1:] / mc[[0, 1]], [0.5 * (1 - e), 0.5 * e], rtol=1e-13)
    assert idx[1, 1] == 0 and abs(coef[1, 1] - 0.25) < 1e-15
    assert idx[3, 1] == g.nbins and abs(coef[3, 1] - 2.5e5) < 1e-9


@pytest.mark.parametrize("q,expect", [(-1.3, 0.08590), (-1.5, 0.14599), (-2.0, 0.41702), (-3.7, 0.98013)])
def test_fragment_bin_integrals_spec_table(q, expect):
    """Thesis eqs. 6.29-6.30 integrated: mass fraction in [1, 10] of dn/dm ∝ m^q on [1, 250]."""
    le = jnp.log(jnp.array([0.1, 1.0, 10.0, 100.0, 1000.0]))
    W = fragment_weights(le, jnp.asarray(q), jnp.asarray(1.0), jnp.asarray(250.0))
    np.testing.assert_allclose(float(W[1]), expect, rtol=2e-4)
    assert float(W[0]) == 0.0 and float(W[-1]) > 0
    np.testing.assert_allclose(float(jnp.sum(W)), 1.0, rtol=1e-14)
    # degenerate range (monomers): all in the bin that holds m_lo
    W0 = fragment_weights(le, jnp.asarray(q), jnp.asarray(3.0), jnp.asarray(3.0))
    np.testing.assert_array_equal(np.asarray(W0), [0, 1, 0, 0])


@pytest.mark.slow  # the fig6 --quick test (tests/test_paper_figs_ch46.py) runs O09 solves in the default suite
def test_o09_cloud_solve_conserves_mass():
    """Ice monomers in an n = 1e7 cm^-3 core with the surrogate O09 recipe: grows, erodes,
    and sum(rho) + gel stays constant."""
    mat = Material.ch6_ice()
    gas = G.molecular_cloud(1e7)
    kern = scenes.molecular_cloud().kernel(gas, rho_s=mat.rho_s)
    grid = MassGrid.log(float(mat.m0) * 0.7, 1e-2, 1)
    n0 = np.zeros(grid.nbins)
    n0[0] = 0.01 * gas.rho_g / grid.centers[0]
    fr = RecipeOutcome(O09Recipe(), mat, width=0.3)
    yr = 3.15576e7
    sol = evolve(kern, Binned(grid), jnp.asarray(n0), jnp.array([0.0, 1e5 * yr, 1e6 * yr]), outcome=fr)
    assert bool(sol.status == RESULTS.successful)
    assert float(jnp.max(jnp.abs(sol.mass_drift))) < 1e-9
    m_mean = jnp.sum(sol.rho * grid.centers[None, :], axis=1) / jnp.sum(sol.rho, axis=1)
    assert float(m_mean[-1]) > 100 * float(mat.m0)


def _log_mean_mass(lp, t_end=1e11):
    """ln <m>_m at t_end for ch. 4 silicate with smooth DT thresholds; lp = ln(gamma, E*)."""
    base = Material.ch4_silicate()
    mat = Material(a0=base.a0, rho_s=base.rho_s, gamma=jnp.exp(lp[0]), E_star=jnp.exp(lp[1]),
                   xi_crit=base.xi_crit, A_br=base.A_br, A_roll=base.A_roll, roll="A")
    fr = RecipeOutcome(O07Recipe(frag_model=DTEnergy()), mat, width=0.3)
    n0 = np.zeros(GRID.nbins)
    n0[0] = 2.4e-13 / GRID.centers[0]
    sol = evolve(_kern(1e-3), Binned(GRID, rtol=1e-8), jnp.asarray(n0), jnp.array([0.0, t_end]), outcome=fr)
    rho = sol.rho[-1]
    return jnp.log(jnp.sum(rho * GRID.centers) / jnp.sum(rho)), sol


@pytest.mark.slow  # suite budget (34 s); binned gradients vs FD stay in the default run: tests/test_binned_gradients.py
def test_gradient_wrt_surface_energy_and_modulus_matches_fd():
    lp = jnp.log(jnp.array([19.0, 3.7e11]))
    val, sol = _log_mean_mass(lp)
    assert bool(sol.status == RESULTS.successful) and abs(float(sol.mass_drift[-1])) < 1e-12
    assert float(val) > np.log(1e-9)  # grew from 1e-11 g
    f = lambda x: _log_mean_mass(x)[0]
    g = jax.grad(f)(lp)
    assert bool(jnp.all(jnp.isfinite(g)))
    h = 1e-4
    for i, name in enumerate(("gamma", "E_star")):
        e = jnp.zeros(2).at[i].set(h)
        fd = (f(lp + e) - f(lp - e)) / (2 * h)
        np.testing.assert_allclose(g[i], fd, rtol=1e-4, err_msg=name)
    # E_br ∝ gamma^5/3 E*^-2/3: stickier grains grow larger, stiffer ones fragment sooner
    assert float(g[0]) > 0 and float(g[1]) < 0
    np.testing.assert_allclose(float(g[1]) / float(g[0]), -2.0 / 5.0, rtol=0.05)


def test_bad_inputs_raise():
    with pytest.raises(JaxcoagInputError, match="recipe"):
        RecipeOutcome(3.0, Material.ch4_silicate())
    with pytest.raises(JaxcoagInputError, match="Material"):
        RecipeOutcome(O07Recipe(), {"gamma": 19.0})
    with pytest.raises(JaxcoagInputError, match="width"):
        RecipeOutcome(O07Recipe(), Material.ch4_silicate(), width=-1.0)
    with pytest.raises(TypeError, match="no relative velocity"):
        SCH.precompute(Constant(1.0), GRID, RecipeOutcome(O07Recipe(), Material.ch4_silicate()))
    # the same refusal from evolve, before any work
    with pytest.raises(TypeError, match="no relative velocity"):
        evolve(Constant(1.0), Binned(GRID), jaxcoag.Monodisperse(GRID.centers[0]), jnp.array([1.0]),
               outcome=RecipeOutcome(O07Recipe(), Material.ch4_silicate()))
    with pytest.raises(JaxcoagInputError, match="probability"):
        VfragShatter(100.0, probability="bogus")


def test_jit_and_vmap_match_eager():
    """The consumer's tensors under jit equal the eager ones; vmap over gamma equals a loop."""
    import equinox as eqx

    kern = _kern(1e-2)
    base = Material.ch4_silicate()

    def frag_mass(lg):
        mat = Material(a0=base.a0, rho_s=base.rho_s, gamma=jnp.exp(lg), E_star=base.E_star, xi_crit=base.xi_crit,
                       A_br=base.A_br, A_roll=base.A_roll, roll="A")
        d = SCH.precompute(kern, GRID, RecipeOutcome(O07Recipe(frag_model=DTEnergy()), mat, width=0.3))
        return SCH.rhs(0.0, _state(GRID, 4), d)

    lgs = jnp.log(jnp.array([5.0, 19.0, 80.0]))
    fj = eqx.filter_jit(frag_mass)
    looped = jnp.stack([fj(x) for x in lgs])
    np.testing.assert_allclose(looped[1], frag_mass(lgs[1]), rtol=1e-12, atol=1e-30)
    np.testing.assert_allclose(jax.vmap(frag_mass)(lgs), looped, rtol=1e-12, atol=1e-30)
    assert float(jnp.max(jnp.abs(looped[0] - looped[2]))) > 0  # gamma matters at alpha = 1e-2


@pytest.mark.slow
def test_steady_state_implicit_gradient_wrt_v_frag():
    """steady_state accepts the Outcome consumer; its implicit-function gradient matches FD
    (measured: 3.874979 vs 3.874979, alpha = 1e-3, v_frag = 1 m/s)."""
    from jaxcoag.binned import steady_state

    n0 = np.zeros(GRID.nbins)
    n0[0] = 2.4e-13 / GRID.centers[0]

    def f(lv):
        fr = RecipeOutcome(VfragShatter(jnp.exp(lv)), Material.ch4_silicate())
        ss = steady_state(_kern(1e-3), Binned(GRID), jnp.asarray(n0), outcome=fr, t_relax=1e12)
        rho = ss.mass_per_bin
        return jnp.log(jnp.sum(rho * GRID.centers) / jnp.sum(rho))

    lv = jnp.log(100.0)
    g = jax.grad(f)(lv)
    h = 1e-4
    np.testing.assert_allclose(g, (f(lv + h) - f(lv - h)) / (2 * h), rtol=1e-4)
    assert float(g) > 0
