"""Drag conventions of the friction time / Stokes number: "ormel" vs "dustpy".

"ormel" (default): Epstein tau = 3 m/(4 rho_g c_g A) with the isothermal sound speed c_g and the
mean free path l = mu m_H/(rho_g sigma) (Ormel 2008 thesis eqs. 2.4, 4.5-4.6). "dustpy": the
mean thermal speed v_th = sqrt(8/pi) c_g and lambda = 1/(sqrt(2) n sigma) (Birnstiel et al. 2010;
Stammler & Birnstiel 2022, DustPy ``St_Epstein_StokesI``). The reference numbers below are
computed from k_B, T, mu, m_H, sigma and Sigma_g directly, not through GasState.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag import config
from jaxcoag import constants as C
from jaxcoag import effects as E
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.physics import drag as D
from jaxcoag.physics import gas as G
from jaxcoag.scene import Scene

RHO_S = 1.6
T1, SIGMA1 = 280.0, 1700.0        # Hayashi (1981) MMSN at 1 AU


def _mass(a, rho_s=RHO_S):
    return 4.0 / 3.0 * math.pi * rho_s * np.asarray(a, dtype=np.float64) ** 3


@pytest.fixture(scope="module")
def gas1():
    return G.mmsn_hayashi81(C.AU, alpha=1e-3)


def _independent(gas):
    """c_g, v_th, rho_g, Omega, l (no sqrt 2), lambda (sqrt 2) from the constants."""
    c_g = math.sqrt(C.k_B * T1 / (C.mu_gas * C.m_H))
    v_th = math.sqrt(8.0 * C.k_B * T1 / (math.pi * C.mu_gas * C.m_H))
    omega = math.sqrt(C.G * C.M_sun / C.AU ** 3)
    rho_g = SIGMA1 / (math.sqrt(2.0 * math.pi) * c_g / omega)
    n = rho_g / (C.mu_gas * C.m_H)
    return dict(c_g=c_g, v_th=v_th, omega=omega, rho_g=rho_g, l=1.0 / (n * C.sigma_mol),
                lam=1.0 / (math.sqrt(2.0) * n * C.sigma_mol))


def test_gas_numbers_are_the_independent_ones(gas1):
    ref = _independent(gas1)
    np.testing.assert_allclose(float(gas1.c_g), ref["c_g"], rtol=1e-14)
    np.testing.assert_allclose(float(gas1.rho_g), ref["rho_g"], rtol=1e-13)
    np.testing.assert_allclose(float(D.thermal_speed(gas1)), ref["v_th"], rtol=1e-14)
    np.testing.assert_allclose(float(D.drag_mean_free_path(gas1)), ref["l"], rtol=1e-13)
    np.testing.assert_allclose(float(D.drag_mean_free_path(gas1, convention="dustpy")), ref["lam"], rtol=1e-13)


def test_epstein_ratio_is_sqrt_8_over_pi_and_dustpy_st_is_pi_a_rhos_over_2sigma(gas1):
    ref = _independent(gas1)
    a = np.array([1e-5, 1e-4, 1e-2, 1.0])          # all below 9/4 lambda = 2.3 cm: Epstein in both
    assert np.all(a < 2.25 * ref["lam"])
    m = _mass(a)
    t_or = np.asarray(D.friction_time_compact(m, RHO_S, gas1))
    t_dp = np.asarray(D.friction_time_compact(m, RHO_S, gas1, convention="dustpy"))
    # ratio = v_th / c_g = sqrt(8/pi) = 1.5957691216057308 (the "1.6x")
    np.testing.assert_allclose(t_or / t_dp, ref["v_th"] / ref["c_g"], rtol=1e-14)
    np.testing.assert_allclose(t_or / t_dp, 1.5957691216057308, rtol=1e-14)
    # DustPy's Epstein Stokes number pi a rho_s / (2 Sigma_g) and ours rho_s a Omega/(rho_g c_g)
    st_dp = np.asarray(D.stokes_number(t_dp, gas1))
    np.testing.assert_allclose(st_dp, math.pi * a * RHO_S / (2.0 * SIGMA1), rtol=1e-12)
    st_or = np.asarray(D.stokes_number(t_or, gas1))
    np.testing.assert_allclose(st_or, RHO_S * a * ref["omega"] / (ref["rho_g"] * ref["c_g"]), rtol=1e-12)


def test_stokes_regime_laws_switch_points_and_ratio(gas1):
    ref = _independent(gas1)
    lam, l_or = ref["lam"], ref["l"]
    # well inside Stokes-I for both conventions
    a = np.array([10.0, 100.0, 1e3])
    m = _mass(a)
    t_dp = np.asarray(D.friction_time_compact(m, RHO_S, gas1, convention="dustpy"))
    nu_dp = 0.5 * ref["v_th"] * lam                  # DustPy's Stokes law: nu = v_th lambda / 2
    np.testing.assert_allclose(t_dp, 2.0 * RHO_S * a ** 2 / (9.0 * nu_dp * ref["rho_g"]), rtol=1e-12)
    st_dp = t_dp * ref["omega"]
    np.testing.assert_allclose(st_dp, 2.0 * math.pi * a ** 2 * RHO_S / (9.0 * lam * SIGMA1), rtol=1e-12)
    t_or = np.asarray(D.friction_time_compact(m, RHO_S, gas1))
    np.testing.assert_allclose(t_or, 2.0 * RHO_S * a ** 2 / (9.0 * (0.5 * ref["c_g"] * l_or) * ref["rho_g"]),
                               rtol=1e-12)
    # Stokes ratio = (v_th/c_g)/sqrt(2) = 2/sqrt(pi)
    np.testing.assert_allclose(t_or / t_dp, 2.0 / math.sqrt(math.pi), rtol=1e-13)
    # between the switch points (9/4 lambda < a < 9/4 l): DustPy in Stokes, ormel still Epstein
    a_mid = np.array([2.4, 3.0])
    assert np.all((a_mid > 2.25 * lam) & (a_mid < 2.25 * l_or))
    r = np.asarray(D.friction_time_compact(_mass(a_mid), RHO_S, gas1)
                   / D.friction_time_compact(_mass(a_mid), RHO_S, gas1, convention="dustpy"))
    np.testing.assert_allclose(r, (ref["v_th"] / ref["c_g"]) * 9.0 * lam / (4.0 * a_mid), rtol=1e-12)
    # the dustpy switch is at 9/4 lambda and continuous; auto = max(Epstein, Stokes)
    a_sw = 2.25 * lam
    lo = float(D.friction_time_compact(_mass(a_sw * (1 - 1e-9)), RHO_S, gas1, convention="dustpy"))
    hi = float(D.friction_time_compact(_mass(a_sw * (1 + 1e-9)), RHO_S, gas1, convention="dustpy"))
    assert abs(hi / lo - 1.0) < 5e-9
    aa = np.array([0.1, 1.0, 2.0, 2.3, 5.0, 50.0])
    mm = _mass(aa)
    ep = np.asarray(D.friction_time(mm, aa, gas1, regime="epstein", convention="dustpy"))
    st = np.asarray(D.friction_time(mm, aa, gas1, regime="stokes", convention="dustpy"))
    np.testing.assert_allclose(st / ep, 4.0 * aa / (9.0 * lam), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(D.friction_time(mm, aa, gas1, convention="dustpy")), np.maximum(ep, st),
                               rtol=1e-15)


def test_porous_area_enters_both_conventions_alike(gas1):
    # tau_Ep = 3 m / (4 rho_g v A): an area 4x larger shortens tau 4x in either convention
    m, a = _mass(1e-3), 1e-3
    for conv in D.DRAG_CONVENTIONS:
        t1 = float(D.friction_time(m, a, gas1, convention=conv))
        t4 = float(D.friction_time(m, a, gas1, area=4.0 * math.pi * a * a, convention=conv))
        np.testing.assert_allclose(t1 / t4, 4.0, rtol=1e-14)


@pytest.mark.parametrize("conv", D.DRAG_CONVENTIONS)
def test_gradients_vs_central_differences_in_log_a_and_log_T(conv):
    gas = G.mmsn_hayashi81(C.AU, alpha=1e-3)

    def ln_tau(ln_a):
        a = jnp.exp(ln_a)
        return jnp.log(D._friction_time_compact(4.0 / 3.0 * jnp.pi * RHO_S * a ** 3, RHO_S, gas, convention=conv))

    h = 1e-5
    for a, slope in ((1e-4, 1.0), (0.3, 1.0), (30.0, 2.0)):      # Epstein: tau ~ a, Stokes: tau ~ a^2
        x = math.log(a)
        g = float(jax.grad(ln_tau)(x))
        fd = (float(ln_tau(x + h)) - float(ln_tau(x - h))) / (2 * h)
        assert abs(g - fd) < 1e-8
        assert abs(g - slope) < 1e-12

    def ln_tau_T(ln_T, a=1e-3):
        g_ = G.midplane_state(1e-9, jnp.exp(ln_T), 1e-3, 2e-7)
        return jnp.log(D._friction_time_compact(_mass(a), RHO_S, g_, convention=conv))

    x = math.log(280.0)
    g = float(jax.grad(ln_tau_T)(x))
    fd = (float(ln_tau_T(x + h)) - float(ln_tau_T(x - h))) / (2 * h)
    assert abs(g - fd) < 1e-8
    assert abs(g + 0.5) < 1e-12                                  # Epstein: tau ~ 1/c_g ~ T^-1/2


def test_jit_and_vmap_equal_eager(gas1):
    m = jnp.asarray(_mass(np.array([1e-5, 1e-3, 1.0, 10.0])))
    for conv in D.DRAG_CONVENTIONS:
        eager = D.friction_time_compact(m, RHO_S, gas1, convention=conv)
        jitted = jax.jit(lambda mm, c=conv: D.friction_time_compact(mm, RHO_S, gas1, convention=c))(m)
        np.testing.assert_array_equal(np.asarray(jitted), np.asarray(eager))
        vm = jax.vmap(lambda mm, c=conv: D._friction_time_compact(mm, RHO_S, gas1, convention=c))(m)
        np.testing.assert_allclose(np.asarray(vm), np.asarray(eager), rtol=1e-15)
    # vmap over gas states (temperatures)
    Ts = jnp.array([50.0, 150.0, 280.0])
    f = lambda T: D._friction_time_compact(1e-6, RHO_S, G.midplane_state(1e-9, T, 1e-3, 2e-7), convention="dustpy")
    np.testing.assert_allclose(np.asarray(jax.vmap(f)(Ts)), np.array([float(f(T)) for T in Ts]), rtol=1e-15)


def test_scene_and_config_carry_the_convention(gas1):
    a = np.array([1e-4, 1e-2])
    m = jnp.asarray(_mass(a))
    vel = (E.Brownian(), E.TurbulenceOC07())
    st_dp = np.asarray(Scene(velocities=vel, drag_convention="dustpy").kernel(gas1, rho_s=RHO_S).particles(m).st)
    np.testing.assert_allclose(st_dp, math.pi * a * RHO_S / (2.0 * SIGMA1), rtol=1e-12)
    st_or = np.asarray(Scene(velocities=vel).kernel(gas1, rho_s=RHO_S).particles(m).st)
    np.testing.assert_allclose(st_or / st_dp, math.sqrt(8.0 / math.pi), rtol=1e-14)
    # a run configuration reaches it: [scene] drag_convention = "dustpy"
    cfg = config.default().replace(**{"scene.drag_convention": "dustpy"})
    scene = config.make_scene(cfg)
    assert scene.drag_convention == "dustpy"
    assert config.make_scene(config.default()).drag_convention == "ormel"
    k = scene.kernel(config.make_gas(cfg["gas"]), rho_s=RHO_S)
    np.testing.assert_allclose(np.asarray(k.particles(m).st), math.pi * a * RHO_S / (2.0 * SIGMA1), rtol=1e-12)
    assert "drag_convention = \"dustpy\"" in cfg.to_toml()


def test_bad_convention_is_refused(gas1):
    with pytest.raises(JaxcoagInputError, match="drag convention"):
        D.friction_time(1e-12, 1e-4, gas1, convention="thermal")
    with pytest.raises(JaxcoagInputError, match="drag convention"):
        D.friction_time_compact(1e-12, RHO_S, gas1, convention="Dustpy")
    with pytest.raises(JaxcoagInputError, match="drag convention"):
        D.drag_mean_free_path(gas1, convention="")
    with pytest.raises(JaxcoagInputError, match="drag_convention"):
        Scene(velocities=(E.Brownian(),), drag_convention="birnstiel")
    with pytest.raises(JaxcoagInputError, match="drag_convention"):
        config.default().replace(**{"scene.drag_convention": "birnstiel"})
