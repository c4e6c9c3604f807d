"""Bad input at every public entry point: a JaxcoagInputError (or the documented exception)
raised before any work, whose message names the argument and says what to change.

Entry points: ``jaxcoag.evolve`` and the engine objects' construction (``Binned``, ``MonteCarlo``
and their structure classes), ``Monodisperse``, outcomes, ``steady_state``, grids, kernels, gas
states, scenes, sweeps, fits, io, checkpoints and the CLI. One parametrised case per (entry point,
category): negative, zero where > 0 is needed, NaN, inf, wrong shape, empty / < 2-bin grids, output
times not strictly increasing or before t0, unknown engine objects / structure given as strings,
a result of another engine as the initial condition, incompatible combinations (e.g. Shattering
with an analytic kernel that has no relative velocity) and float32 mode. Each case matches a
substring of the message that names the parameter or the fix. The refusal cases are cheap: none
runs a solve.
"""

import numpy as np
import pytest
import jax
import jax.numpy as jnp

from jaxcoag import (RESULTS, Binned, BinnedResult, MCResult, Monodisperse, MonteCarlo, diagnostics, evolve, fit, io,
                     kernels, mc, scenes)
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.binned import DGScheme, MassGrid, TwoBinScheme, exponential, monodisperse, mrn, steady_state
from jaxcoag.mc import (ConstantSpecies, Distribution, EqualMass, IncrementalRates, MassController,
                        SpeciesController)
from jaxcoag.outcomes import ShatterAbove, Shattering
from jaxcoag.physics import gas as GAS
from jaxcoag.sweep import parameter_points, sweep

NAN, INF = float("nan"), float("inf")
G = MassGrid.log(10 ** (-0.5 / 4), 1e3, 4)          # 12 bins, monomer 1 g at a bin center
N0 = monodisperse(G, 1.0, 1.0)
K = kernels.Constant(1.0)
TS = np.array([0.0, 1.0, 2.0])
B = Binned(G)


def _gas(**kw):
    p = dict(rho_g=1e-11, T=100.0, alpha=1e-4, Omega=2e-8)
    p.update(kw)
    return GAS.midplane_state(p.pop("rho_g"), p.pop("T"), p.pop("alpha"), p.pop("Omega"), **p)


def _raises(fn, match, exc=JaxcoagInputError):
    with pytest.raises(exc, match=match):
        fn()


def _fake_result(grid=G, ts=TS):
    """A BinnedResult assembled by hand (no solve, no compile): the checks only read it."""
    n = monodisperse(grid, float(grid.centers[0]), 1.0)
    rho = jnp.tile(jnp.asarray(n * grid.centers), (ts.size, 1))
    z = jnp.zeros(ts.size)
    return BinnedResult(t=jnp.asarray(ts), y=jnp.concatenate([rho, z[:, None]], axis=1), rho=rho,
                        n=jnp.tile(jnp.asarray(n), (ts.size, 1)), gel_mass=z, mass_drift=z, status=RESULTS.successful,
                        stats={"steps": 0, "rejected": 0, "num_steps": 0}, M0=jnp.asarray(1.0), grid=grid)


# ------------------------------------------------------------------------------ evolve + Binned
EVOLVE_CASES = {
    # the verb: engine / kernel / initial / key
    "engine_string": (lambda: evolve(K, "binned", N0, TS), "engine must be a jaxcoag engine object"),
    "engine_grid": (lambda: evolve(K, G, N0, TS), "engine must be a jaxcoag engine object"),
    "kernel_not_kernel": (lambda: evolve(lambda m1, m2: 1.0, B, N0, TS), "kernel must be a jaxcoag kernel"),
    "initial_other_grid": (lambda: evolve(K, B, _fake_result(MassGrid.log(1.0, 1e3, 3)), [3.0]),
                           "BinnedResult on another grid"),
    # engine construction: grid / scheme / solver / tolerances / steps
    "grid_not_massgrid": (lambda: Binned((1.0, 10.0, 100.0)), "grid must be a jaxcoag.MassGrid"),
    "scheme_string": (lambda: Binned(G, scheme="dg"), "must be a scheme object"),
    "scheme_class": (lambda: Binned(G, scheme=TwoBinScheme), "must be a scheme object"),
    "dg_order": (lambda: Binned(G, scheme=DGScheme(order=5)), "order"),
    "solver_string": (lambda: Binned(G, solver="kvaerno5"), "must be a diffrax solver"),
    "rtol_negative": (lambda: Binned(G, rtol=-1e-6), "`rtol` must be finite and > 0"),
    "rtol_zero": (lambda: Binned(G, rtol=0.0), "`rtol` must be finite and > 0"),
    "rtol_nan": (lambda: Binned(G, rtol=NAN), "`rtol` must be finite"),
    "atol_negative": (lambda: Binned(G, atol=-1.0), "`atol` must be finite and > 0"),
    "atol_inf": (lambda: Binned(G, atol=INF), "`atol` must be finite"),
    "dt0_negative": (lambda: Binned(G, dt0=-1.0), "`dt0` must be finite and > 0"),
    "dt0_zero": (lambda: Binned(G, dt0=0.0), "`dt0` must be finite and > 0"),
    "max_steps_zero": (lambda: Binned(G, max_steps=0), "max_steps must be a positive int"),
    "max_steps_float": (lambda: Binned(G, max_steps=1e5), "max_steps must be a positive int"),
    # outcome
    "outcome_type": (lambda: evolve(K, B, N0, TS, outcome=100.0), "has no binned form"),
    # incompatible: velocity-dependent fragmentation with an analytic kernel (no relative velocity)
    "shattering_analytic_kernel": (lambda: evolve(K, B, N0, TS, outcome=Shattering(100.0)), "no relative velocity"),
    # initial condition
    "monodisperse_m0_negative": (lambda: Monodisperse(-1.0, 1.0),
                                 r"Monodisperse\(m0=...\) must be a finite scalar > 0"),
    "monodisperse_rho_d_nan": (lambda: Monodisperse(1.0, NAN),
                               r"Monodisperse\(rho_d=...\) must be a finite scalar > 0"),
    "monodisperse_outside_grid": (lambda: evolve(K, B, Monodisperse(1e6, 1.0), TS), "outside the grid"),
    "n0_negative": (lambda: evolve(K, B, -N0, TS), "`initial` must be finite and >= 0"),
    "n0_nan": (lambda: evolve(K, B, np.where(N0 > 0, NAN, 0.0), TS), "`initial` must be finite"),
    "n0_inf": (lambda: evolve(K, B, np.where(N0 > 0, INF, 0.0), TS), "`initial` must be finite"),
    "n0_wrong_shape": (lambda: evolve(K, B, N0[:-1], TS), r"must have shape \(nbins,\) = \(12,\)"),
    "n0_zero": (lambda: evolve(K, B, 0 * N0, TS), "initial number density is all zeros"),
    "n0_callable_nan": (lambda: evolve(K, B, lambda m: jnp.sqrt(-m), TS), r"f\(m\) projected onto the grid gives NaN"),
    "n0_callable_outside": (lambda: evolve(K, B, lambda m: 0.0 * m, TS), "holds no mass"),
    # output times and t0
    "t_out_not_increasing": (lambda: evolve(K, B, N0, np.array([0.0, 2.0, 1.0])), "t_out must be strictly increasing"),
    "t_out_repeated": (lambda: evolve(K, B, N0, np.array([0.0, 1.0, 1.0])), "t_out must be strictly increasing"),
    "t_out_empty": (lambda: evolve(K, B, N0, np.array([])), "non-empty 1-D array"),
    "t_out_2d": (lambda: evolve(K, B, N0, TS[None, :]), "non-empty 1-D array"),
    "t_out_nan": (lambda: evolve(K, B, N0, np.array([0.0, NAN])), "`t_out` must be finite"),
    "t_out_inf": (lambda: evolve(K, B, N0, np.array([0.0, INF])), "`t_out` must be finite"),
    "t_out_before_t0": (lambda: evolve(K, B, N0, TS, t0=0.5), r"t_out\[0\] = 0 s precedes t0 = 0.5 s"),
    "t_out_before_continued_result": (lambda: evolve(K, B, _fake_result(), TS), r"precedes t0 = 2 s"),
    "t0_negative": (lambda: evolve(K, B, N0, TS, t0=-1.0), "`t0` must be finite and >= 0"),
    "t0_nan": (lambda: evolve(K, B, N0, TS, t0=NAN), "`t0` must be finite"),
    # segments
    "every_zero": (lambda: evolve(K, B, N0, TS, every=0), "every must be a positive int"),
    "every_float": (lambda: evolve(K, B, N0, TS, every=1.5), "every must be a positive int"),
    "max_segments_zero": (lambda: evolve(K, B, N0, TS, max_segments=0), "max_segments must be None or a positive int"),
}


@pytest.mark.parametrize("case", sorted(EVOLVE_CASES))
def test_evolve_binned(case):
    fn, match = EVOLVE_CASES[case]
    _raises(fn, match)


def test_evolve_kernel_nan_leaf_under_jit_raises_not_nan():
    """A NaN parameter that only appears at run time (traced) raises with the parameter's name."""
    f = jax.jit(lambda b: evolve(kernels.Sum(b), B, N0, TS).mass_per_bin())
    assert bool(jnp.all(jnp.isfinite(f(1e-3))))
    # eqx.error_if under jax.jit surfaces as the runtime error of the compiled program: jax raises a
    # ValueError from the cached (fast-path) executable, a JaxRuntimeError on a first dispatch
    with pytest.raises((ValueError, jax.errors.JaxRuntimeError), match="`b` must be finite and > 0"):
        jax.block_until_ready(f(NAN))


def test_binned_ignores_a_key():
    """One call runs any engine: the deterministic binned engine ignores key= (bit-identical result)."""
    a = evolve(K, B, N0, TS)
    b = evolve(K, B, N0, TS, key=jax.random.key(0))
    np.testing.assert_array_equal(np.asarray(a.rho), np.asarray(b.rho))
    # constant kernel, monodisperse start: N(t) = N0 / (1 + K N0 t / 2) (Smoluchowski 1916), N0 = 1
    np.testing.assert_allclose(np.asarray(a.n).sum(axis=1), 1.0 / (1.0 + TS / 2.0), rtol=1e-5)


# ------------------------------------------------------------------------------ steady_state
SF = ShatterAbove(10.0, 1.0)
STEADY_CASES = {
    "engine_not_binned": (lambda: steady_state(K, "binned", N0, outcome=SF, t_relax=1.0),
                          "needs a jaxcoag.Binned engine"),
    "no_fragmentation": (lambda: steady_state(K, B, N0, outcome=None, t_relax=1.0), "needs a fragmenting outcome"),
    "no_t_relax_no_guess": (lambda: steady_state(K, B, N0, outcome=SF), "needs t_relax"),
    "t_relax_negative": (lambda: steady_state(K, B, N0, outcome=SF, t_relax=-1.0), "`t_relax` must be finite and > 0"),
    "t_relax_nan": (lambda: steady_state(K, B, N0, outcome=SF, t_relax=NAN), "`t_relax` must be finite"),
    "newton_rtol_zero": (lambda: steady_state(K, B, N0, outcome=SF, t_relax=1.0, newton_rtol=0.0),
                         "`newton_rtol` must be finite and > 0"),
    "newton_steps_zero": (lambda: steady_state(K, B, N0, outcome=SF, t_relax=1.0, newton_steps=0),
                          "newton_steps must be a positive int"),
    "y_guess_wrong_shape": (lambda: steady_state(K, B, N0, outcome=SF, y_guess=np.ones(3)), "y_guess must have shape"),
    "y_guess_nan": (lambda: steady_state(K, B, N0, outcome=SF, y_guess=np.full(G.nbins + 1, NAN)),
                    "`y_guess` must be finite"),
}


@pytest.mark.parametrize("case", sorted(STEADY_CASES))
def test_steady_state(case):
    fn, match = STEADY_CASES[case]
    _raises(fn, match)


# ------------------------------------------------------------------------------ grids and initial conditions
GRID_CASES = {
    "m_min_negative": (lambda: MassGrid.log(-1.0, 1e3, 4), "m_min must be a finite mass > 0"),
    "m_min_zero": (lambda: MassGrid.log(0.0, 1e3, 4), "m_min must be a finite mass > 0"),
    "m_min_nan": (lambda: MassGrid.log(NAN, 1e3, 4), "m_min must be a finite mass > 0"),
    "m_max_inf": (lambda: MassGrid.log(1.0, INF, 4), "m_max must be finite and > m_min"),
    "m_max_below_m_min": (lambda: MassGrid.log(10.0, 1.0, 4), "m_max must be finite and > m_min"),
    "bpd_zero": (lambda: MassGrid.log(1.0, 1e3, 0), "bins_per_decade must be > 0"),
    "bpd_nan": (lambda: MassGrid.log(1.0, 1e3, NAN), "bins_per_decade must be > 0"),
    "one_bin": (lambda: MassGrid.log(1.0, 10.0, 1), "need at least 2"),
    "from_edges_two": (lambda: MassGrid.from_edges([1.0, 2.0]), "at least 3 masses"),
    "from_edges_empty": (lambda: MassGrid.from_edges([]), "at least 3 masses"),
    "from_edges_unsorted": (lambda: MassGrid.from_edges([1.0, 3.0, 2.0]), "strictly increasing"),
    "from_edges_zero": (lambda: MassGrid.from_edges([0.0, 1.0, 2.0]), "finite masses > 0"),
    "from_edges_nan": (lambda: MassGrid.from_edges([1.0, NAN, 3.0]), "finite masses > 0"),
    "log_from_log10_reversed": (lambda: MassGrid.log_from_log10(3.0, 1.0, 4), "log10_max must exceed log10_min"),
    "log_from_log10_nan": (lambda: MassGrid.log_from_log10(NAN, 1.0, 4), "finite"),
    "monodisperse_outside": (lambda: monodisperse(G, 1e6, 1.0), "outside the grid"),
    "monodisperse_rho_negative": (lambda: monodisperse(G, 1.0, -1.0), "rho_d must be a finite dust density > 0"),
    "monodisperse_m0_nan": (lambda: monodisperse(G, NAN, 1.0), "m0 must be a finite mass > 0"),
    "mrn_reversed": (lambda: mrn(G, 1e-1, 1e-2, 3.0, 1.0), "0 < a_min < a_max"),
    "mrn_rho_d_inf": (lambda: mrn(G, 0.3, 0.5, 3.0, INF), "rho_d must be finite and > 0"),
    "mrn_rho_s_nan": (lambda: mrn(G, 0.3, 0.5, NAN, 1.0), "rho_s must be finite and > 0"),
    "mrn_q_nan": (lambda: mrn(G, 0.3, 0.5, 3.0, 1.0, q=NAN), "q must be finite"),
    "mrn_outside": (lambda: mrn(G, 1e-3, 0.5, 3.0, 1.0), "must lie inside the grid"),
    "exponential_negative": (lambda: exponential(-1.0, 1.0), "finite m0 > 0"),
    "exponential_inf": (lambda: exponential(1.0, INF), "n0 > 0"),
}


@pytest.mark.parametrize("case", sorted(GRID_CASES))
def test_grid_and_initial_conditions(case):
    fn, match = GRID_CASES[case]
    _raises(fn, match)


# ------------------------------------------------------------------------------ kernels
KERNEL_CASES = {
    "constant_negative": (lambda: kernels.Constant(-1.0), "`k0` must be finite and > 0"),
    "constant_zero": (lambda: kernels.Constant(0.0), "`k0` must be finite and > 0"),
    "sum_nan": (lambda: kernels.Sum(NAN), "`b` must be finite and > 0"),
    "product_inf": (lambda: kernels.Product(INF), "`b` must be finite and > 0"),
    "powerproduct_nu_nan": (lambda: kernels.PowerProduct(1.0, NAN), "`nu` must be finite"),
    "powerlaw_b_negative": (lambda: kernels.PowerLaw(-1.0, 1.0, 0.0), "`b` must be finite and > 0"),
    "powerlaw_mu_inf": (lambda: kernels.PowerLaw(1.0, INF, 0.0), "`mu` must be finite"),
    "analytic_relative_velocity": (lambda: kernels.Sum(1.0).relative_velocity2(1.0, 2.0), "no relative velocity",
                                   TypeError),
}


@pytest.mark.parametrize("case", sorted(KERNEL_CASES))
def test_kernels(case):
    fn, match, *exc = KERNEL_CASES[case]
    _raises(fn, match, *exc)


# ------------------------------------------------------------------------------ gas states
GAS_CASES = {
    "rho_g_negative": (lambda: _gas(rho_g=-1e-11), "`rho_g` must be finite and > 0; pass the gas density"),
    "rho_g_zero": (lambda: _gas(rho_g=0.0), "`rho_g` must be finite and > 0"),
    "T_nan": (lambda: _gas(T=NAN), "`T` must be finite and > 0"),
    "alpha_negative": (lambda: _gas(alpha=-1e-4), "`alpha` must be finite and >= 0"),
    "alpha_inf": (lambda: _gas(alpha=INF), "`alpha` must be finite"),
    "Omega_zero": (lambda: _gas(Omega=0.0), "`Omega` must be finite and > 0"),
    "R_negative": (lambda: _gas(R=-1.0), "`R` must be finite and > 0"),
    "M_star_nan": (lambda: _gas(M_star=NAN), "`M_star` must be finite and > 0"),
    "mu_zero": (lambda: _gas(mu=0.0), "`mu` must be finite and > 0"),
    "sigma_mol_negative": (lambda: _gas(sigma_mol=-1e-15), "`sigma_mol` must be finite and > 0"),
    "tL_factor_nan": (lambda: _gas(tL_factor=NAN), "`tL_factor` must be finite and > 0"),
    "nu_m_divisor_zero": (lambda: _gas(nu_m_divisor=0.0), "`nu_m_divisor` must be finite and > 0"),
    "dlnP_dlnR_nan": (lambda: _gas(dlnP_dlnR=NAN), "`dlnP_dlnR` must be finite"),
    "z_inf": (lambda: _gas(z=INF), "`z` must be finite"),
    "vg_convention_unknown": (lambda: _gas(vg_convention="sqrt(2*alpha)*c"), "unknown vg_convention"),
    "local_state_sigma_negative": (lambda: GAS.local_state(1.5e13, 2e33, -1.0, 100.0, 1e-4),
                                   "`Sigma_g` must be finite and > 0"),
    "local_state_R_nan": (lambda: GAS.local_state(NAN, 2e33, 100.0, 100.0, 1e-4), "`R` must be finite and > 0"),
    "mmsn_R_zero": (lambda: GAS.mmsn_hayashi81(0.0), "`R` must be finite and > 0"),
    "ch4_alpha_negative": (lambda: GAS.ch4_disk(1.5e13, alpha=-1.0), "`alpha` must be finite and >= 0"),
    "ch4_rho_X_zero": (lambda: GAS.ch4_disk(1.5e13, rho_X=0.0), "`rho_X` must be finite and > 0"),
    "cloud_n_negative": (lambda: GAS.molecular_cloud(-1e5), "`n` must be finite and > 0"),
    "cloud_T_inf": (lambda: GAS.molecular_cloud(1e5, T=INF), "`T` must be finite and > 0"),
}


@pytest.mark.parametrize("case", sorted(GAS_CASES))
def test_gas(case):
    fn, match = GAS_CASES[case]
    _raises(fn, match)


# ------------------------------------------------------------------------------ scenes
def test_scene_and_presets():
    from jaxcoag import Scene, effects

    gas = _gas()
    sc = scenes.nebula_ch4()
    _raises(lambda: sc.kernel(gas, rho_s=-1.0), "`rho_s` must be finite and > 0")
    _raises(lambda: sc.kernel(gas, rho_s=NAN), "`rho_s` must be finite and > 0")
    _raises(lambda: sc.kernel(gas, rho_s=1.0, dv_floor=-1.0), "`dv_floor` must be finite and >= 0")
    _raises(lambda: sc.kernel(gas), "pass rho_s", ValueError)
    _raises(lambda: sc.kernel({"rho_g": 1e-11}, rho_s=1.0), "gas must be a jaxcoag GasState", TypeError)
    _raises(lambda: scenes.get("nebula"), "unknown scene preset 'nebula'; available", JaxcoagInputError)
    _raises(lambda: Scene(velocities=()), "non-empty tuple of velocity effects", ValueError)
    _raises(lambda: Scene(velocities=(effects.Brownian(), effects.Brownian())), "more than once", ValueError)
    _raises(lambda: Scene(velocities=(effects.Brownian(),), drag_regime="newton"), "unknown drag_regime", ValueError)
    _raises(lambda: Scene(velocities=("brownian",)), "velocity modules", TypeError)
    # the physical kernel has a relative velocity, so Shattering is accepted with it (no error here)
    kern = sc.kernel(gas, rho_s=1.0)
    assert float(kern.relative_velocity2(1e-12, 1e-9)) > 0.0


def test_fragmentation_models():
    _raises(lambda: Shattering(-1.0), "`v_frag` must be finite and > 0")
    _raises(lambda: Shattering(NAN), "`v_frag` must be finite and > 0")
    _raises(lambda: Shattering(100.0, probability="gaussian"), "probability must be one of")
    _raises(lambda: ShatterAbove(-1.0, 1.0), "`m_frag` must be finite and > 0")
    _raises(lambda: ShatterAbove(10.0, NAN), "`m_mono` must be finite and > 0")
    _raises(lambda: Shattering(100.0, crater_ratio=1.0), "crater_ratio must be > 1")
    _raises(lambda: Shattering(100.0, chi=9.5), r"chi must lie in \(0, crater_ratio - 1\)")


# ------------------------------------------------------------------------------ Monte Carlo
def _mc(engine=None, initial=None, t_out=(0.5, 1.0), kernel=K, **kw):
    """evolve with the MonteCarlo engine (default: 100 monomers of 1 g, key 0), arguments overridden by kw."""
    args = dict(key=jax.random.key(0))
    args.update(kw)
    engine = MonteCarlo(n_particles=100) if engine is None else engine
    initial = Monodisperse(1.0, 1.0) if initial is None else initial
    return evolve(kernel, engine, initial, t_out, **args)


def _fake_mc_result():
    """An MCResult assembled by hand (T = 1 output, S = 2 slots; no run): a result of another engine."""
    one, two = jnp.ones((1,)), jnp.ones((1, 2))
    return MCResult(t=one, m=two, logm=0 * two, psi=jnp.ones((1, 2, 0)), w=two, z=jnp.zeros((1, 2), jnp.int32),
                    valid=jnp.ones((1, 2), bool), V=one, logV=0 * one, M_tot=2 * one, n_events_snap=jnp.zeros(1),
                    status=RESULTS.successful, flags=jnp.int32(0), n_events=jnp.int32(0), n_dup=jnp.int32(0),
                    n_merge=jnp.int32(0))


MC_CASES = {
    # the engine's fields (refused at construction)
    "n_particles_negative": (lambda: MonteCarlo(n_particles=-10),
                             r"MonteCarlo\(n_particles=...\) must be a finite number > 0"),
    "n_particles_nan": (lambda: MonteCarlo(n_particles=NAN), r"MonteCarlo\(n_particles=...\) must be a finite number"),
    "ns_target_zero": (lambda: MonteCarlo(ns_target=0), r"MonteCarlo\(ns_target=...\) must be a finite number > 0"),
    "f_eps_negative": (lambda: MonteCarlo(f_eps=-1e-3), r"MonteCarlo\(f_eps=...\) must be a finite number > 0"),
    # from 1 on one event merges whole equal-mass groups (Golovin box: L1 1.5, 13-23 species at Ns* = 256)
    "f_eps_one": (lambda: MonteCarlo(f_eps=1.0), r"MonteCarlo\(f_eps=...\) must be a finite number > 0 and < 1 "
                  r"\(a small fraction such as 1e-3; from 1 on, one event merges whole equal-mass groups\)"),
    "capacity_not_int": (lambda: MonteCarlo(capacity=10.5), r"MonteCarlo\(capacity=...\) must be an integer >= 1"),
    "max_events_zero": (lambda: MonteCarlo(max_events=0), r"MonteCarlo\(max_events=...\) must be >= 1"),
    "p_protect_negative": (lambda: MonteCarlo(p_protect=-1), r"MonteCarlo\(p_protect=...\) must be >= 0"),
    "grouping_string": (lambda: MonteCarlo(grouping="equal_mass"), r"MonteCarlo\(grouping=...\) must be None"),
    "grouping_class": (lambda: MonteCarlo(grouping=EqualMass), r"MonteCarlo\(grouping=...\) must be None"),
    "volume_string": (lambda: MonteCarlo(volume="const_m"),
                      r"MonteCarlo\(volume=...\) must be jaxcoag.mc.ConstantVolume"),
    "rates_string": (lambda: MonteCarlo(rates="lazy"), r"MonteCarlo\(rates=...\) must be jaxcoag.mc.IncrementalRates"),
    "neps_rounding_unknown": (lambda: MonteCarlo(neps_rounding="round"),
                              r"MonteCarlo\(neps_rounding='round'\) is unknown"),
    "leftover_unknown": (lambda: MonteCarlo(leftover="keep"), r"MonteCarlo\(leftover='keep'\) is unknown"),
    "merge_weighting_unknown": (lambda: MonteCarlo(merge_weighting="area"), "merge_weighting='area'\\) is unknown"),
    "dedupe_not_bool": (lambda: MonteCarlo(dedupe="yes"), r"MonteCarlo\(dedupe=...\) must be True or False"),
    "stop_not_callable": (lambda: MonteCarlo(stop=1e4), r"MonteCarlo\(stop=...\) must be a jaxcoag.mc.AbstractStop"),
    "struct0_nan": (lambda: MonteCarlo(struct0=jnp.array([NAN])),
                    r"MonteCarlo\(struct0=...\) must be a finite 1-D vector"),
    # the structure classes
    "n_bins_zero": (lambda: Distribution(n_bins=0), r"Distribution\(n_bins=...\) must be >= 1"),
    "n_rezoom_zero": (lambda: Distribution(n_rezoom=0), r"Distribution\(n_rezoom=...\) must be >= 1"),
    "m_lo_zero": (lambda: Distribution(m_lo=0.0), r"Distribution\(m_lo=...\) must be a finite number > 0"),
    "tail_events_negative": (lambda: Distribution(tail_events=-1.0),
                             r"Distribution\(tail_events=...\) must be a finite number >= 0"),
    "count_groups_zero": (lambda: Distribution(count_groups=0.0),
                          r"Distribution\(count_groups=...\) must be a finite number >= 1"),
    "count_groups_nan": (lambda: Distribution(count_groups=NAN), r"Distribution\(count_groups=...\) must be a finite"),
    "tail_wmax_small": (lambda: Distribution(tail_wmax=0.5),
                        r"Distribution\(tail_wmax=...\) must be a finite number >= 1"),
    "controller_string": (lambda: ConstantSpecies(controller="mass"), r"ConstantSpecies\(controller=...\) must be"),
    "d_max_zero": (lambda: MassController(d_max=0), r"MassController\(d_max=...\) must be >= 1"),
    "d_up_float": (lambda: SpeciesController(d_up=1.5), r"SpeciesController\(d_up=...\) must be an integer >= 1"),
    "n_refresh_zero": (lambda: IncrementalRates(n_refresh=0), r"IncrementalRates\(n_refresh=...\) must be >= 1"),
    # evolve: kernel, outcome, key, initial condition, output times
    "kernel_not_kernel": (lambda: _mc(kernel=1.0), "kernel must be a jaxcoag.kernels.AbstractKernel"),
    "outcome_type": (lambda: _mc(outcome="sticking"), "outcome must be a collision outcome from jaxcoag.outcomes"),
    "key_not_key": (lambda: _mc(key=3), "key must be a jax.random key"),
    "key_missing": (lambda: _mc(key=None), "give key=, a jax.random key"),
    "m0_zero": (lambda: _mc(initial=Monodisperse(0.0, 1.0)), r"Monodisperse\(m0=...\) must be a finite scalar > 0"),
    "rho_d_inf": (lambda: _mc(initial=Monodisperse(1.0, INF)), r"Monodisperse\(rho_d=...\) must be a finite scalar"),
    "monodisperse_without_n_particles": (lambda: _mc(engine=MonteCarlo()),
                                         "a Monodisperse start needs MonteCarlo\\(n_particles"),
    "too_many_particles": (lambda: _mc(engine=MonteCarlo(n_particles=1e20)),
                           r"grouping=None needs n_particles <= 2\^53"),
    "mass_beyond_float64": (lambda: _mc(engine=MonteCarlo(n_particles=1e200, grouping=EqualMass()),
                                        initial=Monodisperse(1e120)),
                            "n_particles \\* m0 must stay below 1e300 g"),
    "species_with_n_particles": (lambda: _mc(initial=mc.initial_species(jnp.array([1.0, 2.0]),
                                                                        g=jnp.array([3.0, 4.0]))),
                                 "initial_species\\(...\\) gives its own multiplicities: drop n_particles"),
    "initial_number_array": (lambda: _mc(initial=N0), "initial must be jaxcoag.Monodisperse"),
    "capacity_too_small": (lambda: _mc(engine=MonteCarlo(n_particles=100, capacity=3)),
                           r"MonteCarlo\(capacity=3\) is too small"),
    "t_out_not_increasing": (lambda: _mc(t_out=[1.0, 0.5]), "t_out must be strictly increasing"),
    "t_out_negative": (lambda: _mc(t_out=[-1.0, 1.0]), r"t_out\[0\] = -1 s precedes t0 = 0 s"),
    "t_out_nan": (lambda: _mc(t_out=[0.0, NAN]), "`t_out` must be finite"),
    "t_out_empty": (lambda: _mc(t_out=[]), "non-empty 1-D array"),
    "t_out_2d": (lambda: _mc(t_out=[[1.0]]), "non-empty 1-D array"),
    # a result of another engine as the initial condition (both directions), a hand-made one
    "binned_result_to_mc": (lambda: _mc(initial=_fake_result(), t_out=[3.0]),
                            "initial is a BinnedResult: a MonteCarlo run continues only an MCResult"),
    "mc_result_to_binned": (lambda: evolve(K, B, _fake_mc_result(), [2.0]),
                            "initial is a MCResult: a Binned run continues only a BinnedResult"),
    "mc_result_without_final_state": (lambda: _mc(initial=_fake_mc_result(), t_out=[2.0]),
                                      "MCResult without final_state"),
    # steady_state is a binned-engine tool
    "steady_state_mc": (lambda: steady_state(K, MonteCarlo(n_particles=100), Monodisperse(1.0), outcome=SF,
                                             t_relax=1.0),
                        "steady_state needs a jaxcoag.Binned engine; got MonteCarlo"),
}


@pytest.mark.parametrize("case", sorted(MC_CASES))
def test_monte_carlo(case):
    fn, match = MC_CASES[case]
    _raises(fn, match)


# ------------------------------------------------------------------------------ sweeps
def _f(a, b=1.0):
    return a * b


SWEEP_CASES = {
    "params_not_dict": (lambda: sweep(_f, [1.0, 2.0]), "params must be a non-empty dict"),
    "params_empty": (lambda: sweep(_f, {}), "params must be a non-empty dict"),
    "values_empty": (lambda: sweep(_f, {"a": []}), "parameter 'a' is empty"),
    "values_nan": (lambda: sweep(_f, {"a": [1.0, NAN]}), "parameter 'a' contains NaN/inf at index 1"),
    "values_inf": (lambda: sweep(_f, {"a": [INF, 1.0]}), "parameter 'a' contains NaN/inf at index 0"),
    "values_2d": (lambda: sweep(_f, {"a": [[1.0, 2.0]]}), "must be a 1-D array"),
    "values_strings": (lambda: sweep(_f, {"a": ["x", "y"]}), "parameter 'a' must be numeric"),
    "name_not_identifier": (lambda: sweep(_f, {"a b": [1.0]}), "must be Python identifiers"),
    "name_not_argument": (lambda: sweep(_f, {"c": [1.0]}), "fn does not accept the parameter 'c'"),
    "unknown_grid": (lambda: sweep(_f, {"a": [1.0]}, grid="cartesian"), "grid must be one of"),
    "zip_unequal": (lambda: sweep(_f, {"a": [1.0], "b": [1.0, 2.0]}, grid="zip"), "equal-length"),
    "chunk_zero": (lambda: sweep(_f, {"a": [1.0]}, chunk=0), "chunk must be a positive int"),
    "chunk_bool": (lambda: sweep(_f, {"a": [1.0]}, chunk=True), "chunk must be a positive int"),
    "fn_not_callable": (lambda: sweep(3.0, {"a": [1.0]}), "fn must be a callable"),
    "mesh_and_devices": (lambda: sweep(_f, {"a": [1.0]}, mesh=jax.make_mesh((1,), ("m",)),
                                       devices=jax.devices()), "either mesh= or devices="),
    "mesh_wrong_type": (lambda: sweep(_f, {"a": [1.0]}, mesh="cpu"), "jax.sharding.Mesh"),
    "devices_empty": (lambda: sweep(_f, {"a": [1.0]}, devices=[]), "devices= is empty"),
    "attrs_not_dict": (lambda: sweep(_f, {"a": [1.0]}, attrs=[("scene", "x")]), "attrs must be a dict"),
    "invalid_unknown": (lambda: sweep(_f, {"a": [1.0]}, invalid="skip"), "invalid must be 'raise' or 'flag'"),
    "output_key_status": (lambda: sweep(lambda a: {"status": a}, {"a": [1.0]}), "other than 'status'"),
    "points_unknown_grid": (lambda: parameter_points({"a": [1.0]}, grid="mesh"), "grid must be one of"),
    "points_nan": (lambda: parameter_points({"a": [NAN]}), "contains NaN/inf"),
}


@pytest.mark.parametrize("case", sorted(SWEEP_CASES))
def test_sweep(case):
    fn, match = SWEEP_CASES[case]
    _raises(fn, match)


# ------------------------------------------------------------------------------ fitting
@pytest.fixture(scope="module")
def small_box():
    return fit.nebula_box(bins_per_decade=2, decades=4, ts=(1e9,))


FIT_BOX_CASES = {
    "R_negative": (dict(R=-1.0), "R must be finite and > 0"),
    "alpha_nan": (dict(alpha=NAN), "alpha must be finite and > 0"),
    "rho_g_zero": (dict(rho_g=0.0), "rho_g must be finite and > 0"),
    "v_frag_inf": (dict(v_frag=INF), "v_frag must be finite and > 0"),
    "a0_negative": (dict(a0=-1e-4), "a0 must be finite and > 0"),
    "dust_to_gas_zero": (dict(dust_to_gas=0.0), "dust_to_gas must be finite and > 0"),
    "ts_not_increasing": (dict(ts=(5e9, 2e9)), "ts must be a 1-D increasing array"),
    "ts_negative": (dict(ts=(-1.0, 2e9)), "observation times > 0"),
    "ts_empty": (dict(ts=()), "ts must be a 1-D increasing array"),
    "one_bin": (dict(bins_per_decade=1, decades=1), "need at least 2"),
    "rtol_negative": (dict(rtol=-1.0), "rtol must be finite and > 0"),
    "atol_nan": (dict(atol=NAN), "atol must be finite and > 0"),
}


@pytest.mark.parametrize("case", sorted(FIT_BOX_CASES))
def test_fit_nebula_box(case):
    kw, match = FIT_BOX_CASES[case]
    _raises(lambda: fit.nebula_box(**kw), match)


def test_fit_entry_points(small_box):
    m = small_box
    good = {"alpha": 1e-4}
    target = np.zeros((1, m.grid.nbins))
    _raises(lambda: fit.synthetic_target(m, {"beta": 1.0}), "unknown parameter 'beta' in truth")
    _raises(lambda: fit.synthetic_target(m, {"alpha": -1.0}), r"truth\['alpha'\] must be a finite scalar > 0")
    _raises(lambda: fit.synthetic_target(m, good, noise=-0.1), "noise must be a finite relative level >= 0")
    _raises(lambda: fit.synthetic_target(m, good, noise=NAN), "noise must be a finite")
    _raises(lambda: fit.synthetic_target(m, {"v_frag": 10.0}), "nebula_box\\(fragmentation=True\\)")
    _raises(lambda: fit.synthetic_target("box", good), "model must be a jaxcoag.fit.NebulaBox")
    _raises(lambda: fit.fit_adam("box", target, good), "model must be a jaxcoag.fit.NebulaBox")
    _raises(lambda: fit.fit_adam(m, target, {"alpha": INF}), r"init\['alpha'\] must be a finite scalar > 0")
    _raises(lambda: fit.fit_adam(m, target, {"alpha": [1e-4, 2e-4]}), "finite scalar")
    _raises(lambda: fit.fit_adam(m, target[:, :-1], good), r"target must have shape \(n_obs, nbins\)")
    _raises(lambda: fit.fit_adam(m, target * NAN, good), "target contains NaN/inf")
    _raises(lambda: fit.fit_adam(m, target, good, steps=0), "steps must be a positive int")
    _raises(lambda: fit.fit_adam(m, target, good, learning_rate=-0.1), "learning_rate")
    _raises(lambda: fit.fit_adam(m, target, good, final_learning_rate=NAN), "final_learning_rate")
    _raises(lambda: fit.fit_least_squares(m, target, good, solver="bfgs"), "solver must be 'levenberg_marquardt'")
    _raises(lambda: fit.fit_least_squares(m, target, good, rtol=0.0), "rtol must be finite and > 0")
    _raises(lambda: fit.fit_least_squares(m, target, good, max_steps=-3), "max_steps must be a positive int")


# ------------------------------------------------------------------------------ io and diagnostics
def test_io(tmp_path):
    res = _fake_result()
    assert float(res.to_xarray()["mass_per_bin"].sum()) == pytest.approx(TS.size * 1.0)
    _raises(lambda: res.to_xarray(attrs=[1]), "attrs must be a dict")
    _raises(lambda: res.to_xarray(attrs={1: "x"}), "attrs keys must be strings")
    _raises(lambda: res.to_xarray(edges=[1.0, 0.5, 2.0]), "edges must be a 1-D, positive, strictly increasing")
    _raises(lambda: io.save_netcdf(res, tmp_path / "missing" / "x.nc"), "does not exist; create it first")
    _raises(lambda: io.save_netcdf(res.to_xarray(), tmp_path / "x.nc", attrs={"a": 1}), "is only for saving a result")
    _raises(lambda: io.save_netcdf(res, tmp_path), "is a directory")
    _raises(lambda: io.save_netcdf([1, 2], tmp_path / "x.nc"), "result with .to_xarray()")
    _raises(lambda: io.load_netcdf(tmp_path / "nope.nc"), "no netCDF file", FileNotFoundError)
    assert not any(p.name.endswith(".tmp") for p in tmp_path.iterdir())


def test_diagnostics():
    rho = np.ones(G.nbins)
    _raises(lambda: diagnostics.moment(rho, np.array([1.0, 0.5, 2.0]), 1), "strictly increasing positive masses")
    _raises(lambda: diagnostics.mass_peak(rho, np.array([-1.0, 1.0])), "strictly increasing positive masses")


# ------------------------------------------------------------------------------ float32 mode
def test_float32_mode_is_refused():
    """With x64 off every engine entry point refuses with the switch to turn it on."""
    jax.config.update("jax_enable_x64", False)
    try:
        _raises(lambda: evolve(K, B, N0, TS), "jax_enable_x64")
        _raises(lambda: sweep(_f, {"a": [1.0]}), "jax_enable_x64")
        _raises(lambda: fit.nebula_box(), "jax_enable_x64")
        _raises(lambda: _mc(), "jax_enable_x64")
    finally:
        jax.config.update("jax_enable_x64", True)
    assert jnp.asarray(1.0).dtype == jnp.float64


def test_incompatible_kernel_error_is_also_a_type_error():
    """Shattering with an analytic kernel: a JaxcoagInputError that is also a TypeError (older
    callers catch TypeError), raised before any compilation."""
    with pytest.raises(TypeError, match="ShatterAbove"):
        evolve(kernels.Sum(1.0), B, N0, TS, outcome=Shattering(100.0))
    with pytest.raises(JaxcoagInputError, match="Scene"):
        steady_state(K, B, N0, outcome=Shattering(100.0), y_guess=np.ones(G.nbins + 1))


# ------------------------------------------------------------------------------ refused before the work
# Issue 12 point 3: every refusal is a one-line message saying what to change, exit code 2 from the
# CLI, no traceback, no file written, and it happens before the computation.
import os  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from jaxcoag import checkpoint as ckmod, cli, config, runner  # noqa: E402
from jaxcoag.binned.scheme import check_memory, estimate_bytes  # noqa: E402

from _configs import SMALL as SMALL_TOML  # noqa: E402  (shared test configuration)


def _files(root):
    """Every file and directory below root (relative paths), to prove that nothing was written."""
    out = set()
    for d, dirs, files in os.walk(root):
        for n in dirs + files:
            out.add(os.path.relpath(os.path.join(d, n), root))
    return out


_BINNED_ADVANCE = Binned._advance  # the real one, for building a valid checkpoint under no_compute


@pytest.fixture
def no_compute(monkeypatch):
    """Make every engine's advance fail loudly: a refusal must come before the computation."""
    def boom(*a, **k):
        raise AssertionError("the run started computing before refusing")

    monkeypatch.setattr(Binned, "_advance", boom)
    monkeypatch.setattr(MonteCarlo, "_advance", boom)


def _refused(capsys, argv, *words):
    """cli.main(argv) -> exit 2, one stderr line holding every word, no traceback; returns it."""
    rc = cli.main(argv)
    cap = capsys.readouterr()
    assert rc == 2, (rc, cap.err)
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in cap.err, cap.err
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


def test_grid_too_large_refused_before_any_allocation(tmp_path, capsys, no_compute):
    """bins_per_decade = 1e6 on the default 1 AU grid (6.7e-12..1e8 g, 19.17 decades) means
    1.917e7 bins: the two-bin pair tensors alone would be ~1.8e14 pairs; refused in well under a
    second by the size estimate (nothing is allocated), naming the key to change."""
    before = _files(tmp_path)
    t0 = time.perf_counter()
    msg = _refused(capsys, ["run", "--set", "grid.bins_per_decade=1e6", "--out", str(tmp_path / "o" / "run.nc")],
                   "19173792 bins", "lower [grid] bins_per_decade (now 1e+06)")
    assert time.perf_counter() - t0 < 3.0, msg
    assert _files(tmp_path) == before
    # absurd grids are refused on the grid arrays themselves (before the scheme estimate)
    _refused(capsys, ["run", "--set", "grid.bins_per_decade=1e13", "--out", str(tmp_path / "o" / "run.nc")],
             "for the grid alone", "lower [grid] bins_per_decade")
    assert _files(tmp_path) == before


def test_grid_too_large_refused_in_a_fresh_process_without_a_traceback(tmp_path):
    """The same refusal from a real `jaxcoag run` process: exit 2, exactly one stderr line, and
    the process never grew beyond ~1 GiB (a bare import takes ~0.3 GiB; the run asked for ~3e14 GiB). The peak is
    the process's own VmHWM: Linux carries ru_maxrss over an exec from the forking process (a pytest worker at 2.5
    GiB made this test fail on ru_maxrss)."""
    code = ("import resource, sys; from jaxcoag import cli; rc = cli.main(sys.argv[1:]); "
            "st = open('/proc/self/status').read() if sys.platform.startswith('linux') else ''; "
            "hwm = [int(l.split()[1]) for l in st.splitlines() if l.startswith('VmHWM:')]; "
            "print(hwm[0] if hwm else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss); sys.exit(rc)")
    r = subprocess.run([sys.executable, "-c", code, "run", "--no-progress", "--set", "grid.bins_per_decade=1e6",
                        "--out", str(tmp_path / "o" / "run.nc")], capture_output=True, text=True, timeout=300,
                       cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxcoag run: error: 19173792 bins would need"), r.stderr
    assert int(r.stdout.split()[-1]) < 1024 * 1024  # peak resident memory [KiB] < 1 GiB
    assert os.listdir(tmp_path) == []


def test_memory_estimate_limit_and_suggested_bins(monkeypatch):
    """With JAXCOAG_MEMORY_LIMIT_GB the limit is exactly that; the refusal names the largest bin count
    that fits (estimate(n) <= limit < estimate(n + 1)); the estimate grows as N^2 (explicit) and
    N^3 (implicit solver: the dense Jacobian carries every pair tensor for N + 1 tangents)."""
    import re

    e = [estimate_bytes("twobin", n) for n in (1000, 2000)]
    assert e[1] / e[0] == pytest.approx((2000 * 2001) / (1000 * 1001))
    ei = [estimate_bytes("twobin", n, fragmentation=True, implicit=True) for n in (1000, 2000)]
    assert 7.5 < ei[1] / ei[0] < 8.1
    assert estimate_bytes("dg", 300, order=2) > estimate_bytes("dg", 300, order=1) > estimate_bytes("twobin", 300)
    monkeypatch.setenv("JAXCOAG_MEMORY_LIMIT_GB", "1")
    assert check_memory("twobin", 135, fragmentation=True, implicit=True) < 2 ** 30  # the default run fits
    with pytest.raises(JaxcoagInputError, match=r"more than the limit of 1 GiB") as ei_:
        check_memory("twobin", 400, fragmentation=True, implicit=True, fix="lower [grid] bins_per_decade")
    n = int(re.search(r"at most ~(\d+) bins fit", str(ei_.value)).group(1))
    lim = 2.0 ** 30
    assert estimate_bytes("twobin", n, fragmentation=True, implicit=True) <= lim
    assert estimate_bytes("twobin", n + 1, fragmentation=True, implicit=True) > lim
    monkeypatch.setenv("JAXCOAG_MEMORY_LIMIT_GB", "-3")
    _raises(lambda: check_memory("twobin", 10), "JAXCOAG_MEMORY_LIMIT_GB must be a number of GiB > 0")


def test_grid_too_large_python_api_refused_fast(monkeypatch):
    """evolve(Binned) / steady_state / MassGrid refuse an oversized grid up front (no compile, no tensors)."""
    monkeypatch.setenv("JAXCOAG_MEMORY_LIMIT_GB", "0.5")
    g = MassGrid.log(1.0, 1e4, 1000)  # 4000 bins: ~3.7 GiB of two-bin pair tensors (explicit)
    t0 = time.perf_counter()
    _raises(lambda: evolve(K, Binned(g), Monodisperse(1.5, 1.0), TS), "use a coarser grid")
    _raises(lambda: steady_state(K, Binned(g), Monodisperse(1.5, 1.0), outcome=ShatterAbove(10.0, 1.5),
                                 t_relax=1.0), "use a coarser grid")
    _raises(lambda: MassGrid.log(1.0, 1e4, 1e8), "whose grid arrays alone need")
    assert time.perf_counter() - t0 < 3.0


@pytest.mark.parametrize("how", ["out_under_a_file", "out_under_a_file_no_checkpoint", "checkpoint_under_a_file",
                                 "out_is_a_directory"])
def test_unwritable_output_refused_before_computing(tmp_path, capsys, no_compute, how):
    cfg = tmp_path / "s.toml"
    cfg.write_text(SMALL_TOML)
    blocker = tmp_path / "afile"
    blocker.write_text("not a directory")
    good = str(tmp_path / "res" / "run.nc")
    argv, words = {
        "out_under_a_file": (["--out", str(blocker / "run.nc")], ("netCDF output", "is a file", "change --out")),
        "out_under_a_file_no_checkpoint": (["--out", str(blocker / "run.nc"), "--no-checkpoint"],
                                           ("netCDF output", "is a file", "change --out")),
        "checkpoint_under_a_file": (["--out", good, "--checkpoint", str(blocker / "c.npz")],
                                    ("checkpoint", "is a file", "change --checkpoint")),
        "out_is_a_directory": (["--out", str(tmp_path), "--no-checkpoint"], ("--out must name a netCDF file",)),
    }[how]
    before = _files(tmp_path)
    _refused(capsys, ["run", str(cfg), "--no-progress"] + argv, *words)
    assert _files(tmp_path) == before  # no result, no checkpoint, no directory, no probe file left


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root may write into a 0555 directory")
def test_read_only_directory_refused(tmp_path, capsys, no_compute):
    cfg = tmp_path / "s.toml"
    cfg.write_text(SMALL_TOML)
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        _refused(capsys, ["run", str(cfg), "--no-checkpoint", "--out", str(ro / "run.nc")], "cannot write", "--out")
        _refused(capsys, ["run", str(cfg), "--no-checkpoint", "--out", str(ro / "sub" / "run.nc")], "not writable")
        assert os.listdir(ro) == []
    finally:
        ro.chmod(0o755)


def _good_checkpoint(tmp_path, name="ck.npz", cfg=None):
    """A valid checkpoint of SMALL_TOML (or ``cfg``) after its first output time, as `jaxcoag run` would
    write it: that run's fingerprint, its initial state and zero outputs of the engine's structure (no
    solve). Returns (cfg, built, path, fingerprint, state, outs)."""
    cfg = config.loads(SMALL_TOML) if cfg is None else cfg
    b = config.build(cfg)
    t_out = np.asarray(b.t_out, np.float64)
    fp = ckmod.run_fingerprint(b.kernel, b.engine, b.initial, t_out, t0=0.0, outcome=b.outcome, key=b.key)
    state = b.engine._init(b.kernel, b.initial, 0.0, b.outcome, b.key)
    like = jax.eval_shape(lambda st: _BINNED_ADVANCE(b.engine, b.kernel, st, jnp.asarray(t_out[:1]), b.outcome)[1],
                          state)
    outs = jax.tree_util.tree_map(lambda x: np.zeros(x.shape, x.dtype), like)
    outs["y"] = np.asarray(state["y"])[None, :]
    path = tmp_path / name
    ckmod.save(path, fingerprint=fp, state=state, outs=outs, meta={"every": 1, "n_out": t_out.size})
    return cfg, b, path, fp, state, outs


@pytest.mark.parametrize("kind", ["truncated", "random_bytes", "other_configuration", "nan_state", "empty_file",
                                  "foreign_npz"])
def test_bad_checkpoint_refused_naming_the_file(tmp_path, capsys, no_compute, kind):
    cfg, b, good, fp, state, outs = _good_checkpoint(tmp_path, "good.npz")
    # the valid one is accepted (numbers as written): one output done, the initial dust density 0.01 rho_g
    ck = ckmod.load(good, fingerprint=fp, like_state=state, like_outs=outs)
    assert ck["n_done"] == 1 and ck["outs"]["y"].shape == (1, b.grid.nbins + 1)
    np.testing.assert_allclose(float(ck["state"]["y"].sum()), 0.01 * float(b.gas.rho_g), rtol=1e-12)
    bad = tmp_path / "bad.npz"
    raw = good.read_bytes()
    if kind == "truncated":
        bad.write_bytes(raw[: len(raw) // 2])
        words = ("is truncated or not a jaxcoag checkpoint", "delete it")
    elif kind == "random_bytes":
        bad.write_bytes(np.random.default_rng(12).bytes(4096))
        words = ("is truncated or not a jaxcoag checkpoint", "delete it")
    elif kind == "empty_file":
        bad.write_bytes(b"")
        words = ("is truncated or not a jaxcoag checkpoint", "delete it")
    elif kind == "foreign_npz":
        np.savez(bad, a=np.arange(3))
        words = ("is not a jaxcoag-checkpoint-v2 file", "delete it")
    elif kind == "other_configuration":
        _good_checkpoint(tmp_path, "bad.npz", cfg=cfg.replace(**{"gas.alpha": 1e-4}))
        words = ("different run configuration", "without --resume")
    else:  # a NaN where the run wrote a finite number (the state's bin masses)
        d = dict(np.load(good))
        i_y = [str(q) for q in d["paths"]].index("state['y']")
        leaf = f"leaf_{i_y:05d}"
        d[leaf] = d[leaf].copy()
        d[leaf][0] = np.nan
        np.savez(bad, **d)
        words = ("NaN", "state['y']", "delete it")
    with pytest.raises(JaxcoagInputError, match="bad.npz") as e:
        ckmod.load(bad, fingerprint=fp, like_state=state, like_outs=outs)
    for w in words:
        assert w in str(e.value), str(e.value)
    content = bad.read_bytes()
    path = _write_small(tmp_path)
    before = _files(tmp_path)
    msg = _refused(capsys, ["run", path, "--no-progress", "--resume", "--checkpoint", str(bad),
                            "--out", str(tmp_path / "o" / "run.nc")], str(bad), *words)
    assert msg.startswith("jaxcoag run: error:")
    assert _files(tmp_path) == before and bad.read_bytes() == content  # nothing written, checkpoint untouched
    # the good one passes every check of `jaxcoag run --resume`: the run gets as far as computing
    with pytest.raises(AssertionError, match="started computing"):
        cli.main(["run", path, "--no-progress", "--resume", "--checkpoint", str(good),
                  "--out", str(tmp_path / "o" / "run.nc")])


def _write_small(tmp_path):
    p = tmp_path / "s.toml"
    if not p.exists():
        p.write_text(SMALL_TOML)
    return str(p)


def test_save_false_writes_nothing(tmp_path, monkeypatch):
    """runner.run(save=False): no checkpoint, no netCDF, no figure, no directory; with resume=True a
    checkpoint is read (the run continues from it) but left byte for byte as it was."""
    monkeypatch.chdir(tmp_path)
    cfg = config.loads(SMALL_TOML)
    out = tmp_path / "sub" / "run.nc"
    res = runner.run(cfg, out=out, save=False, progress=False, verbose=False, figure=True)
    assert _files(tmp_path) == set()
    assert res.finished and res.path is None and res.figure is None and res.checkpoint is None
    rho = np.asarray(res.result.mass_per_bin())
    assert rho.shape == (4, 11) and np.max(np.abs(np.asarray(res.result.mass_drift))) < 1e-12
    # the same config with a checkpoint of 1 of 3 segments: resume reads it, writes nothing
    part = runner.run(cfg, out=out, progress=False, verbose=False, figure=False, max_segments=1)
    ck = tmp_path / "sub" / "run.nc.ckpt.npz"
    assert not part.finished and ck.exists() and not out.exists()
    raw, listing = ck.read_bytes(), _files(tmp_path)
    res2 = runner.run(cfg, out=out, save=False, resume=True, progress=False, verbose=False)
    assert res2.resumed_from == 1 and res2.finished
    assert ck.read_bytes() == raw and _files(tmp_path) == listing
    np.testing.assert_array_equal(np.asarray(res2.result.mass_per_bin()), rho)


# ------------------------------------------------------------------------------ Monte Carlo checkpoints / capacity
def test_mc_bad_checkpoint_refused_naming_the_file(tmp_path):
    """evolve(MonteCarlo, checkpoint=...) refuses a damaged file or one of another run, naming the file
    and what to do, before running, and leaves the file as it was."""
    # the configuration of test_mc_capacity_exhaustion_is_reported_not_silent (one compilation)
    engine = MonteCarlo(n_particles=2, capacity=24, dedupe=False)
    t_out = jnp.array([0.0, 0.5, 2.0, 50.0])
    kw = dict(key=jax.random.key(4), every=4)
    good = tmp_path / "mc.npz"
    res = _mc(engine=engine, t_out=t_out, checkpoint=good, **kw)
    state0 = engine._init(K, Monodisperse(1.0, 1.0), 0.0, None, kw["key"])
    like_outs = jax.eval_shape(lambda st: engine._advance(K, st, t_out, None)[1], state0)
    ck = ckmod.load(good, fingerprint=None, like_state=state0, like_outs=like_outs)
    # two monomers coalesce once (P(no event by t = 50) = e^-25): one particle of mass 2 remains
    assert ck["n_done"] == 4 and int(ck["state"].n_events) == int(res.n_events) == 1
    np.testing.assert_allclose(float(np.sum(np.asarray(ck["state"].w) * np.asarray(ck["state"].m))), 2.0)
    raw = good.read_bytes()
    cases = {"truncated": raw[: len(raw) // 3], "random": np.random.default_rng(3).bytes(2048), "empty": b""}
    for name, content in cases.items():
        p = tmp_path / f"{name}.npz"
        p.write_bytes(content)
        with pytest.raises(JaxcoagInputError, match=f"{name}.npz") as e:
            ckmod.read_info(p)
        assert "is truncated or not a jaxcoag checkpoint" in str(e.value)
        assert "delete it or start afresh" in str(e.value)
        # evolve(resume=True) refuses it before running and leaves it as it was
        with pytest.raises(JaxcoagInputError, match=f"{name}.npz"):
            _mc(engine=engine, t_out=t_out, checkpoint=p, resume=True, **kw)
        assert p.read_bytes() == content
    d = dict(np.load(good))
    leaf = f"leaf_{[str(q) for q in d['paths']].index('state.w'):05d}"
    d[leaf] = d[leaf].copy()
    d[leaf][0] = np.nan  # the species weights were finite when written
    nanp = tmp_path / "nan.npz"
    np.savez(nanp, **d)
    _raises(lambda: ckmod.read_info(nanp), r"nan.npz holds NaN/inf in \['state.w'\] where the run wrote finite numbers")
    np.savez(tmp_path / "foreign.npz", a=np.arange(3))
    _raises(lambda: ckmod.read_info(tmp_path / "foreign.npz"), "is not a jaxcoag-checkpoint-v2 file")
    # another configuration (or another key): refused by the run fingerprint
    for other in (dict(engine=MonteCarlo(n_particles=3, capacity=24, dedupe=False)), dict(key=jax.random.key(5))):
        _raises(lambda: _mc(**dict(dict(engine=engine, t_out=t_out, checkpoint=good, resume=True, **kw), **other)),
                "was written by a different run configuration")
    assert good.read_bytes() == raw


def test_mc_capacity_below_the_target_refused():
    """An equal-mass run merges species above min(0.9 S, S - 4), so S must hold Ns* species: Ns* = 16
    needs S >= 20 (S = 19: min(floor(17.1), 19 - 1 - 3) = 15 < 16). (For the distribution method
    min_capacity says which S keeps min(0.9 S, Ng*) = Ng*: 56 for Ng* = 50; there Ng* counts groups,
    not species, and a smaller S is an allowed species cap.)"""
    assert mc.min_capacity("distribution", 50) == 56 and mc.min_capacity("equal_mass", 16) == 20
    assert mc.min_capacity(Distribution(), 50) == 56 and mc.min_capacity(EqualMass(), 16) == 20
    assert mc.min_capacity(None, 1000) is None
    engine = MonteCarlo(grouping=EqualMass(), ns_target=16, capacity=19, n_particles=1e6)
    _raises(lambda: _mc(engine=engine, t_out=[0.5]),
            r"MonteCarlo\(capacity=19\) species slots cannot hold ns_target = 16 equal-mass species.*capacity >= 20")
    # S = 20 holds them (refused only below the bound): no error before the run
    MonteCarlo(grouping=EqualMass(), ns_target=16, capacity=20, n_particles=1e6)._check(
        K, Monodisperse(1.0), jnp.array([0.5]), 0.0, None, jax.random.key(0))


def test_mc_capacity_exhaustion_is_reported_not_silent():
    """Ns > S (300 monomers, no grouping, 24 slots): the emergency merge lowers the resolution, so the
    run says so with a CapacityWarning (and status capacity_exceeded); a run that fits says nothing."""
    import warnings

    t_out = jnp.array([0.0, 0.5, 2.0, 50.0])
    with pytest.warns(mc.CapacityWarning, match=r"ran out of species slots \(capacity = 24\).*capacity=48"):
        res = _mc(engine=MonteCarlo(n_particles=300, capacity=24, dedupe=False), t_out=t_out, key=jax.random.key(3))
    assert res.status == RESULTS.capacity_exceeded
    assert int(res.flags) & mc.state.STATUS.CAPACITY
    with warnings.catch_warnings():
        warnings.simplefilter("error", mc.CapacityWarning)
        ok = _mc(engine=MonteCarlo(n_particles=2, capacity=24, dedupe=False), t_out=t_out, key=jax.random.key(4))
    # two monomers coalesce once (P(no event by t = 50) = e^-25): one particle left, total rate zero
    assert ok.status == RESULTS.zero_rate and int(ok.n_events) == 1
