"""Bad input at every public entry point: a JaxcoagInputError (or the documented exception)
raised before any work, whose message names the argument and says what to change.

One parametrised case per (entry point, category): negative, zero where > 0 is needed, NaN,
inf, wrong shape, empty / < 2-bin grids, output times not strictly increasing or negative,
unknown names / keys, incompatible combinations (e.g. Shattering with an analytic kernel that
has no relative velocity) and float32 mode. Each case matches a substring of the message that
names the parameter or the fix. Everything here is cheap: no case runs a solve to the end.
"""

import numpy as np
import pytest
import jax
import jax.numpy as jnp

from jaxcoag import diagnostics, fit, io, kernels, scenes
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.binned import (MassGrid, Shattering, ShatterToMonomers, exponential, monodisperse, mrn,
                            solve_binned, steady_state)
from jaxcoag.physics import gas as GAS
from jaxcoag.sweep import parameter_points, sweep

NAN, INF = float("nan"), float("inf")
G = MassGrid.log(10 ** (-0.5 / 4), 1e3, 4)          # 12 bins, monomer 1 g at a bin center
N0 = monodisperse(G, 1.0, 1.0)
K = kernels.Constant(1.0)
TS = np.array([0.0, 1.0, 2.0])


def _gas(**kw):
    p = dict(rho_g=1e-11, T=100.0, alpha=1e-4, Omega=2e-8)
    p.update(kw)
    return GAS.midplane_state(p.pop("rho_g"), p.pop("T"), p.pop("alpha"), p.pop("Omega"), **p)


def _raises(fn, match, exc=JaxcoagInputError):
    with pytest.raises(exc, match=match):
        fn()


# ------------------------------------------------------------------------------ solve_binned
SOLVE_CASES = {
    # model / grid / structure
    "model_not_kernel": (lambda: solve_binned(lambda m1, m2: 1.0, G, N0, TS), "model must be a jaxcoag kernel"),
    "grid_not_massgrid": (lambda: solve_binned(K, np.geomspace(1, 10, 5), N0, TS), "grid must be a jaxcoag.binned.MassGrid"),
    "unknown_scheme": (lambda: solve_binned(K, G, N0, TS, scheme="weno"), "scheme must be 'twobin', 'dg'"),
    "twobin_order": (lambda: solve_binned(K, G, N0, TS, order=2), "use order=0"),
    "unknown_solver": (lambda: solve_binned(K, G, N0, TS, solver="rk4"), "solver must be a diffrax solver"),
    "fragmentation_type": (lambda: solve_binned(K, G, N0, TS, fragmentation=100.0), "fragmentation must be None"),
    # incompatible: velocity-dependent fragmentation with an analytic kernel (no relative velocity)
    "shattering_analytic_kernel": (lambda: solve_binned(K, G, N0, TS, fragmentation=Shattering(100.0)),
                                   "no relative velocity"),
    # n0
    "n0_negative": (lambda: solve_binned(K, G, -N0, TS), "`n0` must be finite and >= 0"),
    "n0_nan": (lambda: solve_binned(K, G, np.where(N0 > 0, NAN, 0.0), TS), "`n0` must be finite"),
    "n0_inf": (lambda: solve_binned(K, G, np.where(N0 > 0, INF, 0.0), TS), "`n0` must be finite"),
    "n0_wrong_shape": (lambda: solve_binned(K, G, N0[:-1], TS), r"n0 must have shape \(nbins,\) = \(12,\)"),
    "n0_zero": (lambda: solve_binned(K, G, 0 * N0, TS), "n0 is all zeros"),
    "n0_callable_nan": (lambda: solve_binned(K, G, lambda m: jnp.sqrt(-m), TS), r"n0\(m\) projected onto the grid gives NaN"),
    "n0_callable_outside": (lambda: solve_binned(K, G, lambda m: 0.0 * m, TS), "holds no mass"),
    # ts
    "ts_not_increasing": (lambda: solve_binned(K, G, N0, np.array([0.0, 2.0, 1.0])), "ts must be strictly increasing"),
    "ts_repeated": (lambda: solve_binned(K, G, N0, np.array([0.0, 1.0, 1.0])), "ts must be strictly increasing"),
    "ts_single": (lambda: solve_binned(K, G, N0, np.array([0.0])), "at least 2 output times"),
    "ts_2d": (lambda: solve_binned(K, G, N0, TS[None, :]), "1-D array"),
    "ts_nan": (lambda: solve_binned(K, G, N0, np.array([0.0, NAN])), "`ts` must be finite"),
    "ts_inf": (lambda: solve_binned(K, G, N0, np.array([0.0, INF])), "`ts` must be finite"),
    # tolerances, steps
    "rtol_negative": (lambda: solve_binned(K, G, N0, TS, rtol=-1e-6), "`rtol` must be finite and > 0"),
    "rtol_zero": (lambda: solve_binned(K, G, N0, TS, rtol=0.0), "`rtol` must be finite and > 0"),
    "rtol_nan": (lambda: solve_binned(K, G, N0, TS, rtol=NAN), "`rtol` must be finite"),
    "atol_negative": (lambda: solve_binned(K, G, N0, TS, atol=-1.0), "`atol` must be finite and > 0"),
    "atol_inf": (lambda: solve_binned(K, G, N0, TS, atol=INF), "`atol` must be finite"),
    "dt0_negative": (lambda: solve_binned(K, G, N0, TS, dt0=-1.0), "`dt0` must be finite and > 0"),
    "dt0_zero": (lambda: solve_binned(K, G, N0, TS, dt0=0.0), "`dt0` must be finite and > 0"),
    "max_steps_zero": (lambda: solve_binned(K, G, N0, TS, max_steps=0), "max_steps must be a positive int"),
    "max_steps_float": (lambda: solve_binned(K, G, N0, TS, max_steps=1e5), "max_steps must be a positive int"),
}


@pytest.mark.parametrize("case", sorted(SOLVE_CASES))
def test_solve_binned(case):
    fn, match = SOLVE_CASES[case]
    _raises(fn, match)


def test_solve_binned_kernel_nan_leaf_under_jit_raises_not_nan():
    """A NaN parameter that only appears at run time (traced) raises with the parameter's name."""
    f = jax.jit(lambda b: solve_binned(kernels.Sum(b), G, N0, TS).mass_per_bin)
    assert bool(jnp.all(jnp.isfinite(f(1e-3))))
    # eqx.error_if under jax.jit surfaces as the runtime error of the compiled program: jax raises a
    # ValueError from the cached (fast-path) executable, a JaxRuntimeError on a first dispatch
    with pytest.raises((ValueError, jax.errors.JaxRuntimeError), match="`b` must be finite and > 0"):
        jax.block_until_ready(f(NAN))


# ------------------------------------------------------------------------------ steady_state
STEADY_CASES = {
    "no_fragmentation": (lambda: steady_state(K, G, N0, fragmentation=None, t_relax=1.0), "needs a fragmentation model"),
    "no_t_relax_no_guess": (lambda: steady_state(K, G, N0, fragmentation=ShatterToMonomers(10.0)),
                            "needs t_relax"),
    "t_relax_negative": (lambda: steady_state(K, G, N0, fragmentation=ShatterToMonomers(10.0), t_relax=-1.0),
                         "`t_relax` must be finite and > 0"),
    "t_relax_nan": (lambda: steady_state(K, G, N0, fragmentation=ShatterToMonomers(10.0), t_relax=NAN),
                    "`t_relax` must be finite"),
    "newton_rtol_zero": (lambda: steady_state(K, G, N0, fragmentation=ShatterToMonomers(10.0), t_relax=1.0,
                                              newton_rtol=0.0), "`newton_rtol` must be finite and > 0"),
    "newton_steps_zero": (lambda: steady_state(K, G, N0, fragmentation=ShatterToMonomers(10.0), t_relax=1.0,
                                               newton_steps=0), "newton_steps must be a positive int"),
    "y_guess_wrong_shape": (lambda: steady_state(K, G, N0, fragmentation=ShatterToMonomers(10.0),
                                                 y_guess=np.ones(3)), "y_guess must have shape"),
    "y_guess_nan": (lambda: steady_state(K, G, N0, fragmentation=ShatterToMonomers(10.0),
                                         y_guess=np.full(G.nbins + 1, NAN)), "`y_guess` must be finite"),
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
    _raises(lambda: ShatterToMonomers(-1.0), "m_frag")


# ------------------------------------------------------------------------------ Monte Carlo
MC_CASES = {
    "kernel_not_kernel": (dict(kernel=1.0), "`kernel` must be a jaxcoag.kernels.AbstractKernel"),
    "n_particles_negative": (dict(n_particles=-10), "`n_particles` must be finite and > 0"),
    "n_particles_nan": (dict(n_particles=NAN), "`n_particles` must be finite"),
    "m0_zero": (dict(m0=0.0), "`m0` must be finite and > 0"),
    "rho_d_inf": (dict(rho_d=INF), "`rho_d` must be finite"),
    "f_eps_negative": (dict(f_eps=-1e-3), "`f_eps` must be finite and > 0"),
    "t_out_not_increasing": (dict(t_out=[1.0, 0.5]), "strictly increasing"),
    "t_out_negative": (dict(t_out=[-1.0, 1.0]), "`t_out` must be finite and >= 0"),
    "t_out_nan": (dict(t_out=[0.0, NAN]), "`t_out` must be finite"),
    "t_out_empty": (dict(t_out=[]), "non-empty 1-D array"),
    "t_out_2d": (dict(t_out=[[1.0]]), "non-empty 1-D array"),
    "unknown_mode": (dict(mode="const_m"), "unknown mode 'const_m'"),
    "unknown_grouping": (dict(grouping="equal_number"), "unknown grouping"),
    "unknown_rates": (dict(rates="lazy"), "unknown rates"),
    "too_many_particles": (dict(n_particles=1e20), "grouping=None needs n_particles <= 2"),
    "outcome_type": (dict(outcome="sticking"), "`outcome` must be a jaxcoag.mc.AbstractOutcome"),
    "capacity_not_int": (dict(capacity=10.5), "`capacity` must be an integer >= 1"),
    "n_bins_zero": (dict(grouping="distribution", n_bins=0), "`n_bins` must be >= 1"),
    "key_not_key": (dict(key=3), "`key` must be a jax.random key"),
    "p_protect_negative": (dict(p_protect=-1), "`p_protect` must be >= 0"),
    "n_refresh_zero": (dict(n_refresh=0), "`n_refresh` must be >= 1"),
    "n_rezoom_zero": (dict(grouping="distribution", n_rezoom=0), "`n_rezoom` must be >= 1"),
    "d_max_zero": (dict(mode="const_ns", d_max=0), "`d_max` must be >= 1"),
    "tail_events_negative": (dict(grouping="distribution", tail_events=-1.0), "`tail_events` must be a finite number >= 0"),
    "tail_events_without_distribution": (dict(tail_events=8.0), "only applies to grouping='distribution'"),
    "count_groups_zero": (dict(grouping="distribution", count_groups=0.0), "`count_groups` must be a finite number >= 1"),
    "count_groups_nan": (dict(grouping="distribution", count_groups=float("nan")), "`count_groups` must be a finite"),
    "count_groups_without_distribution": (dict(grouping="equal_mass", count_groups=10), "`count_groups` only applies"),
    "tail_wmax_small": (dict(grouping="distribution", tail_wmax=0.5), "`tail_wmax` must be a finite number >= 1"),
}


@pytest.mark.parametrize("case", sorted(MC_CASES))
def test_mc_run(case):
    from jaxcoag import mc

    kw, match = MC_CASES[case]
    args = dict(kernel=K, n_particles=100, t_out=[0.5, 1.0], key=jax.random.key(0))
    args.update(kw)
    _raises(lambda: mc.run(args.pop("kernel"), **args), match)


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
def _fake_solution():
    """A BinnedSolution assembled by hand (no solve, no compile): the io checks only read it."""
    from jaxcoag.binned import RESULTS, BinnedSolution

    rho = jnp.tile(jnp.asarray(N0 * G.centers), (TS.size, 1))
    z = jnp.zeros(TS.size)
    return BinnedSolution(ts=jnp.asarray(TS), ys=jnp.concatenate([rho, z[:, None]], axis=1), mass_per_bin=rho,
                          number_per_bin=jnp.tile(jnp.asarray(N0), (TS.size, 1)), gel_mass=z, mass_drift=z,
                          result=RESULTS.successful, stats={"steps": 0, "rejected": 0, "num_steps": 0}, grid=G)


def test_io(tmp_path):
    sol = _fake_solution()
    assert float(io.to_xarray(sol)["mass_per_bin"].sum()) == pytest.approx(TS.size * 1.0)
    _raises(lambda: io.to_xarray({"mass_per_bin": 1}), "needs a jaxcoag.binned.BinnedSolution")
    _raises(lambda: io.to_xarray(sol, attrs=[1]), "attrs must be a dict")
    _raises(lambda: io.to_xarray(sol, attrs={1: "x"}), "attrs keys must be strings")
    _raises(lambda: io.save_netcdf(sol, tmp_path / "missing" / "x.nc"), "does not exist; create it first")
    _raises(lambda: io.save_netcdf(io.to_xarray(sol), tmp_path / "x.nc", attrs={"a": 1}), "attrs is only used")
    _raises(lambda: io.save_netcdf(sol, tmp_path), "is a directory")
    _raises(lambda: io.save_netcdf([1, 2], tmp_path / "x.nc"), "BinnedSolution")
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
        _raises(lambda: solve_binned(K, G, N0, TS), "jax_enable_x64")
        _raises(lambda: sweep(_f, {"a": [1.0]}), "jax_enable_x64")
        _raises(lambda: fit.nebula_box(), "jax_enable_x64")
        from jaxcoag import mc
        _raises(lambda: mc.run(K, n_particles=10, t_out=[1.0], key=jax.random.key(0)), "JAX_ENABLE_X64=1")
    finally:
        jax.config.update("jax_enable_x64", True)
    assert jnp.asarray(1.0).dtype == jnp.float64


def test_incompatible_kernel_error_is_also_a_type_error():
    """Shattering with an analytic kernel: a JaxcoagInputError that is also a TypeError (older
    callers catch TypeError), raised before any compilation."""
    with pytest.raises(TypeError, match="ShatterToMonomers"):
        solve_binned(kernels.Sum(1.0), G, N0, TS, fragmentation=Shattering(100.0))
    with pytest.raises(JaxcoagInputError, match="Scene"):
        steady_state(K, G, N0, fragmentation=Shattering(100.0), y_guess=np.ones(G.nbins + 1))


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


@pytest.fixture
def no_compute(monkeypatch):
    """Make any segment integration fail loudly: a refusal must come before the computation."""
    def boom(*a, **k):
        raise AssertionError("the run started computing before refusing")

    monkeypatch.setattr(ckmod, "integrate", boom)


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
    the process never grew beyond ~1 GiB (a bare import takes ~0.3 GiB; the run asked for ~3e14 GiB)."""
    code = ("import resource, sys; from jaxcoag import cli; rc = cli.main(sys.argv[1:]); "
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss); sys.exit(rc)")
    r = subprocess.run([sys.executable, "-c", code, "run", "--no-progress", "--set", "grid.bins_per_decade=1e6",
                        "--out", str(tmp_path / "o" / "run.nc")], capture_output=True, text=True, timeout=300,
                       cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxcoag run: error: 19173792 bins would need"), r.stderr
    assert int(r.stdout.split()[-1]) < 1024 * 1024  # ru_maxrss [KiB] < 1 GiB
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
    """solve_binned / steady_state / MassGrid refuse an oversized grid up front (no compile, no tensors)."""
    monkeypatch.setenv("JAXCOAG_MEMORY_LIMIT_GB", "0.5")
    g = MassGrid.log(1.0, 1e4, 1000)  # 4000 bins: ~3.7 GiB of two-bin pair tensors (explicit)
    t0 = time.perf_counter()
    _raises(lambda: solve_binned(K, g, monodisperse(g, 1.5, 1.0), TS), "use a coarser grid")
    _raises(lambda: steady_state(K, g, monodisperse(g, 1.5, 1.0), fragmentation=ShatterToMonomers(10.0),
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


def _good_checkpoint(tmp_path, name="ck.npz", **over):
    """A valid binned checkpoint of SMALL_TOML at segment 0 (written with save_checkpoint, no solve)."""
    cfg = config.loads(SMALL_TOML)
    b = config.build(cfg)
    y0 = np.asarray(b.scheme.init(b.grid, jnp.asarray(b.n0)))
    kw = dict(config_hash=cfg.physics_hash(), ts=b.ts, ys=y0[None, :], steps=[], rejected=[], wall_s=[])
    kw.update(over)
    path = tmp_path / name
    ckmod.save_checkpoint(path, **kw)
    return cfg, b, path


@pytest.mark.parametrize("kind", ["truncated", "random_bytes", "other_configuration", "nan_state", "empty_file",
                                  "foreign_npz"])
def test_bad_checkpoint_refused_naming_the_file(tmp_path, capsys, no_compute, kind):
    cfg, b, good = _good_checkpoint(tmp_path, "good.npz")
    # the valid one is accepted (numbers as written)
    ck = ckmod.load_checkpoint(good, config_hash=cfg.physics_hash(), ts=b.ts, ny=b.grid.nbins + 1)
    assert ck["ys"].shape == (1, b.grid.nbins + 1) and ck["steps"].size == 0
    np.testing.assert_allclose(ck["ys"][0].sum(), 0.01 * float(b.gas.rho_g), rtol=1e-12)
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
        words = ("is not a jaxcoag-binned-checkpoint", "delete it")
    elif kind == "other_configuration":
        other = cfg.replace(**{"gas.alpha": 1e-4})
        _good_checkpoint(tmp_path, "bad.npz", config_hash=other.physics_hash())
        words = ("different run configuration", "without --resume")
    else:
        ys = np.asarray(ck["ys"]).copy()
        ys[0, 0] = np.nan
        _good_checkpoint(tmp_path, "bad.npz", ys=ys)
        words = ("NaN", "delete it")
    with pytest.raises(JaxcoagInputError, match="bad.npz") as e:
        ckmod.load_checkpoint(bad, config_hash=cfg.physics_hash(), ts=b.ts, ny=b.grid.nbins + 1)
    for w in words:
        assert w in str(e.value), str(e.value)
    content = bad.read_bytes()
    path = _write_small(tmp_path)
    before = _files(tmp_path)
    msg = _refused(capsys, ["run", path, "--no-progress", "--resume", "--checkpoint", str(bad),
                            "--out", str(tmp_path / "o" / "run.nc")], str(bad), *words)
    assert msg.startswith("jaxcoag run: error:")
    assert _files(tmp_path) == before and bad.read_bytes() == content  # nothing written, checkpoint untouched


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
    rho = np.asarray(res.solution.mass_per_bin)
    assert rho.shape == (4, 11) and np.max(np.abs(np.asarray(res.solution.mass_drift))) < 1e-12
    # the same config with a checkpoint of 1 of 3 segments: resume reads it, writes nothing
    part = runner.run(cfg, out=out, progress=False, verbose=False, figure=False, max_segments=1)
    ck = tmp_path / "sub" / "run.nc.ckpt.npz"
    assert not part.finished and ck.exists() and not out.exists()
    raw, listing = ck.read_bytes(), _files(tmp_path)
    res2 = runner.run(cfg, out=out, save=False, resume=True, progress=False, verbose=False)
    assert res2.resumed_from == 1 and res2.finished
    assert ck.read_bytes() == raw and _files(tmp_path) == listing
    np.testing.assert_array_equal(np.asarray(res2.solution.mass_per_bin), rho)


# ------------------------------------------------------------------------------ Monte Carlo checkpoints / capacity
def test_mc_bad_checkpoint_refused_naming_the_file(tmp_path):
    from jaxcoag import mc

    # the configuration of test_mc_capacity_exhaustion_is_reported_not_silent (one compilation)
    kw = dict(n_particles=2, capacity=24, dedupe=False, key=jax.random.key(4), progress=False, every=4)
    t_out = jnp.array([0.0, 0.5, 2.0, 50.0])
    good = tmp_path / "mc.npz"
    res = mc.run_checkpointed(K, t_out=t_out, checkpoint=good, **kw)
    ck = mc.load_checkpoint(good)
    # two monomers coalesce once (P(no event by t = 50) = e^-25): one particle of mass 2 remains
    assert ck["n_done"] == 4 and int(ck["state"].n_events) == int(res.n_events) == 1
    np.testing.assert_allclose(float(np.sum(np.asarray(ck["state"].w) * np.asarray(ck["state"].m))), 2.0)
    raw = good.read_bytes()
    d = dict(np.load(good))
    d["state_w"] = d["state_w"].copy()
    d["state_w"][0] = np.nan
    cases = {"truncated": (raw[: len(raw) // 3], "is truncated or not a jaxcoag.mc checkpoint"),
             "random": (np.random.default_rng(3).bytes(2048), "is truncated or not a jaxcoag.mc checkpoint"),
             "empty": (b"", "is truncated or not a jaxcoag.mc checkpoint")}
    for name, (content, words) in cases.items():
        p = tmp_path / f"{name}.npz"
        p.write_bytes(content)
        with pytest.raises(JaxcoagInputError, match=f"{name}.npz") as e:
            mc.load_checkpoint(p)
        assert words in str(e.value) and "delete it or use resume=False" in str(e.value)
        # run_checkpointed(resume=True) refuses it before running and leaves it as it was
        with pytest.raises(JaxcoagInputError, match=f"{name}.npz"):
            mc.run_checkpointed(K, t_out=t_out, checkpoint=p, resume=True, **kw)
        assert p.read_bytes() == content
    nanp = tmp_path / "nan.npz"
    np.savez(nanp, **d)
    _raises(lambda: mc.load_checkpoint(nanp), r"holds NaN in \['state_w'\]")
    np.savez(tmp_path / "foreign.npz", a=np.arange(3))
    _raises(lambda: mc.load_checkpoint(tmp_path / "foreign.npz"), "is not a jaxcoag.mc checkpoint")
    # another configuration: refused by the argument fingerprint
    _raises(lambda: mc.run_checkpointed(K, t_out=t_out, checkpoint=good, resume=True,
                                        **dict(kw, n_particles=3)), "different arguments")


def test_mc_capacity_below_the_target_refused():
    """An equal-mass run merges species above min(0.9 S, S - 4), so S must hold Ns* species: Ns* = 16
    needs S >= 20 (S = 19: min(floor(17.1), 19 - 1 - 3) = 15 < 16). (For the distribution method
    min_capacity says which S keeps min(0.9 S, Ng*) = Ng*: 56 for Ng* = 50; there Ng* counts groups,
    not species, and a smaller S is an allowed species cap.)"""
    from jaxcoag import mc

    assert mc.min_capacity("distribution", 50) == 56 and mc.min_capacity("equal_mass", 16) == 20
    assert mc.min_capacity(None, 1000) is None
    base = dict(n_particles=1e6, t_out=[0.5], key=jax.random.key(0))
    _raises(lambda: mc.run(K, grouping="equal_mass", ns_target=16, capacity=19, **base),
            r"cannot hold ns_target = 16 equal_mass species.*capacity >= 20")


def test_mc_capacity_exhaustion_is_reported_not_silent():
    """Ns > S (300 monomers, no grouping, 24 slots): the emergency merge lowers the resolution, so the
    run says so with a CapacityWarning (and STATUS.CAPACITY); a run that fits says nothing."""
    import warnings

    from jaxcoag import mc

    kw = dict(capacity=24, dedupe=False, t_out=jnp.array([0.0, 0.5, 2.0, 50.0]))
    with pytest.warns(mc.CapacityWarning, match=r"ran out of species slots \(capacity = 24\).*capacity=48"):
        res = mc.run(K, n_particles=300, key=jax.random.key(3), **kw)
    assert int(res.status) & mc.STATUS.CAPACITY
    with warnings.catch_warnings():
        warnings.simplefilter("error", mc.CapacityWarning)
        ok = mc.run(K, n_particles=2, key=jax.random.key(4), **kw)
    assert int(ok.status) == mc.STATUS.ZERO_RATE
