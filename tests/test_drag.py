"""Friction time, Stokes number and settling utilities (thesis eqs. 1.26, 2.4, 2.25, 4.5-4.6, 4.29)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag import constants as C
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.physics import drag as D
from jaxcoag.physics import gas as G

RHO_S = 3.0


@pytest.fixture(scope="module")
def gas3():
    return G.ch4_disk(3 * C.AU)


def _mass(a, rho_s=RHO_S):
    return 4.0 / 3.0 * math.pi * rho_s * a ** 3


def test_radii_and_area():
    a = jnp.array([1e-5, 1e-2, 10.0, 1e5])
    m = _mass(a)
    np.testing.assert_allclose(D.compact_radius(m, RHO_S), a, rtol=1e-14)
    psi = jnp.array([1.0, 8.0, 27.0, 1e3])
    np.testing.assert_allclose(D.porous_radius(m, RHO_S, psi), a * psi ** (1 / 3), rtol=1e-14)
    np.testing.assert_allclose(D.projected_area(a), math.pi * a ** 2, rtol=1e-15)
    # m up to 1e300 g stays finite
    assert np.isfinite(float(D.compact_radius(1e300, 1.0)))


def test_stokes_epstein_continuity_37(gas3):
    a_sw = 9.0 / 4.0 * gas3.l_mfp
    m = _mass(a_sw)
    t_auto = D.friction_time(m, a_sw, gas3)
    t_ep = D.friction_time(m, a_sw, gas3, regime="epstein")
    t_st = D.friction_time(m, a_sw, gas3, regime="stokes")
    np.testing.assert_allclose(t_auto, t_ep, rtol=1e-12)
    np.testing.assert_allclose(t_st, t_ep, rtol=1e-12)
    # ratio 4a/(9 l_mfp) on both sides of the switch; auto picks the larger
    a = jnp.array([1e-4, 1.0, 50.0, 500.0, 1e4]) * 1.0
    m = _mass(a)
    ep = D.friction_time(m, a, gas3, regime="epstein")
    st = D.friction_time(m, a, gas3, regime="stokes")
    np.testing.assert_allclose(st / ep, 4 * a / (9 * gas3.l_mfp), rtol=1e-12)
    np.testing.assert_allclose(D.friction_time(m, a, gas3), jnp.maximum(ep, st), rtol=1e-15)
    # continuity of 'auto' at the switch: relative jump over +-1e-9 is O(1e-9)
    h = 1e-9
    lo = D.friction_time_compact(_mass(a_sw * (1 - h)), RHO_S, gas3)
    hi = D.friction_time_compact(_mass(a_sw * (1 + h)), RHO_S, gas3)
    assert abs(float(hi / lo) - 1) < 5e-9


def test_closed_forms(gas3):
    a = jnp.array([1e-4, 1e-2, 1.0])  # all Epstein (l_mfp = 82 cm)
    np.testing.assert_allclose(D.friction_time_compact(_mass(a), RHO_S, gas3),
                               RHO_S * a / (gas3.c_g * gas3.rho_g), rtol=1e-13)
    # Stokes law for spheres (requires nu_m = c_g l_mfp/2, gas convention 3 in docs/design_notes.md)
    a = jnp.array([300.0, 1e3, 1e4])
    np.testing.assert_allclose(D.friction_time_compact(_mass(a), RHO_S, gas3),
                               2 * RHO_S * a ** 2 / (9 * gas3.nu_m * gas3.rho_g), rtol=1e-13)
    # porous aggregate, eq. 2.25: tau = rho_s a*/(c_g rho_g psi^(2/3))
    a_star, psi = 1e-3, jnp.array([1.0, 10.0, 1e4])
    m = _mass(a_star)
    ap = D.porous_radius(m, RHO_S, psi)
    np.testing.assert_allclose(D.friction_time(m, ap, gas3),
                               RHO_S * a_star / (gas3.c_g * gas3.rho_g * psi ** (2 / 3)), rtol=1e-13)
    # explicit area == default pi a^2; a fractal area enters as 1/A
    np.testing.assert_allclose(D.friction_time(m, ap, gas3, area=math.pi * ap ** 2), D.friction_time(m, ap, gas3),
                               rtol=1e-15)
    np.testing.assert_allclose(D.friction_time(m, ap, gas3, area=2 * math.pi * ap ** 2),
                               0.5 * D.friction_time(m, ap, gas3), rtol=1e-15)


def test_thesis_grains_38(gas3):
    tau1 = D.friction_time_compact(_mass(1e-4), RHO_S, gas3)
    tau300 = D.friction_time_compact(_mass(3e-2), RHO_S, gas3)
    np.testing.assert_allclose(tau1, 167.0, rtol=1e-2)
    np.testing.assert_allclose(tau300 / 3600.0, 13.9, rtol=1e-2)
    # Stokes numbers St = Omega tau_f (t_L = 1/Omega)
    np.testing.assert_allclose(D.stokes_number(tau1, gas3), tau1 * gas3.Omega, rtol=1e-14)


def test_stokes_number_tl_factor():
    tau = 1e4
    g1 = G.ch4_disk(3 * C.AU)
    g2 = G.ch4_disk(3 * C.AU, tL_factor=2 * math.pi)
    np.testing.assert_allclose(D.stokes_number(tau, g2), D.stokes_number(tau, g1) / (2 * math.pi), rtol=1e-14)
    # scale height and rain-out friction time are convention independent (Omega tau_f)
    st1, st2 = D.stokes_number(tau, g1), D.stokes_number(tau, g2)
    np.testing.assert_allclose(D.particle_scale_height(st2, g2), D.particle_scale_height(st1, g1), rtol=1e-14)
    np.testing.assert_allclose(D.rainout_stokes(g2) * g2.t_L, D.rainout_stokes(g1) * g1.t_L, rtol=1e-14)


@pytest.mark.parametrize("alpha", [1e-6, 1e-4, 1e-2])
def test_scale_height_limits(alpha):
    g = G.ch4_disk(3 * C.AU, alpha=alpha)
    H = g.H_g
    np.testing.assert_allclose(D.rainout_stokes(g), alpha, rtol=1e-14)
    # dubrulle (eq. 4.29)
    np.testing.assert_allclose(D.particle_scale_height(0.0, g), H, rtol=1e-14)
    np.testing.assert_allclose(D.particle_scale_height(alpha, g), H / math.sqrt(2), rtol=1e-13)
    np.testing.assert_allclose(D.particle_scale_height(1e-8 * alpha, g), H, rtol=1e-8)
    big = 1e8 * alpha
    np.testing.assert_allclose(D.particle_scale_height(big, g), H * math.sqrt(alpha / big), rtol=1e-8)
    # ch1 (eq. 1.26): exactly H_g below alpha, H_g sqrt(alpha/St) above
    st = jnp.array([0.0, 0.1, 0.99, 1.01, 10.0, 1e6]) * alpha
    exp = H * jnp.sqrt(jnp.minimum(1.0, alpha / jnp.maximum(st, 1e-300)))
    np.testing.assert_allclose(D.particle_scale_height(st, g, form="ch1"), exp, rtol=1e-13)
    # the two forms share asymptotes and dubrulle <= ch1 everywhere
    grid = jnp.logspace(-6, 6, 49) * alpha
    hd = D.particle_scale_height(grid, g)
    hc = D.particle_scale_height(grid, g, form="ch1")
    assert bool(jnp.all(hd <= hc * (1 + 1e-14)))
    np.testing.assert_allclose(hd[0] / hc[0], 1.0, rtol=1e-6)
    np.testing.assert_allclose(hd[-1] / hc[-1], 1.0, rtol=1e-6)


def test_scale_height_alpha_zero_finite():
    g = G.ch4_disk(3 * C.AU, alpha=0.0)
    assert float(D.particle_scale_height(1e-3, g)) == 0.0
    gr = jax.grad(lambda s: D.particle_scale_height(s, g))(1e-3)
    assert np.isfinite(float(gr))


def test_grad_across_kink(gas3):
    """d ln tau / d ln a for a compact sphere: 1 (Epstein), 2 (Stokes); at the kink the gradient is
    finite: one of the one-sided slopes, or their average 1.5 at an exact tie (JAX's max; velocity hazard 5)."""
    f = lambda la: jnp.log(D.friction_time_compact(_mass(jnp.exp(la)), RHO_S, gas3))
    la_sw = math.log(9 / 4 * float(gas3.l_mfp))
    g = jax.grad(f)
    g_sw = float(g(la_sw))
    assert min(abs(g_sw - v) for v in (1.0, 1.5, 2.0)) < 1e-12, g_sw
    for dla, slope in ((-0.3, 1.0), (0.3, 2.0)):
        x = la_sw + dla
        fd = (f(x + 1e-5) - f(x - 1e-5)) / 2e-5
        np.testing.assert_allclose(g(x), slope, rtol=1e-12)
        np.testing.assert_allclose(g(x), fd, rtol=1e-8)


def test_grad_vs_fd_gas_parameters(gas3):
    """d ln tau / d ln rho_g = -1 (Epstein) and 0 (Stokes: tau ∝ a^2/(nu_m rho_g), nu_m rho_g fixed)."""
    def tau(lr, a):
        g = G.midplane_state(jnp.exp(lr), gas3.T, gas3.alpha, gas3.Omega)
        return jnp.log(D.friction_time_compact(_mass(a), RHO_S, g))
    x = math.log(float(gas3.rho_g))
    for a, want in ((1e-3, -1.0), (1e4, 0.0)):
        gr = jax.grad(tau)(x, a)
        fd = (tau(x + 1e-5, a) - tau(x - 1e-5, a)) / 2e-5
        np.testing.assert_allclose(gr, want, atol=1e-12)
        np.testing.assert_allclose(gr, fd, atol=1e-8)


def test_jit_vmap(gas3):
    a = jnp.logspace(-5, 4, 7)
    m = _mass(a)
    eager = D.friction_time(m, a, gas3)
    f = jax.jit(lambda m, a, g: D.friction_time(m, a, g))
    np.testing.assert_allclose(f(m, a, gas3), eager, rtol=1e-14)
    # concrete material density inside jit
    fc = jax.jit(lambda m: D.friction_time_compact(m, 3.0, gas3))
    np.testing.assert_allclose(fc(m), D.friction_time_compact(m, RHO_S, gas3), rtol=1e-14)
    vm = jax.vmap(lambda mi, ai: D.friction_time(mi, ai, gas3))(m, a)
    stacked = jnp.stack([D.friction_time(mi, ai, gas3) for mi, ai in zip(m, a)])
    np.testing.assert_allclose(vm, stacked, rtol=1e-14)
    # vmap over a batch of gas states (alpha sweep) for the scale height
    alphas = jnp.array([1e-5, 1e-4, 1e-3])
    gs = jax.vmap(lambda al: G.local_state(3 * C.AU * jnp.ones_like(al), C.M_sun * jnp.ones_like(al),
                                           117.83 * jnp.ones_like(al), 162.0 * jnp.ones_like(al), al,
                                           jnp.zeros_like(al)))(alphas)
    hv = jax.vmap(lambda g: D.particle_scale_height(1e-3, g))(gs)
    hl = jnp.stack([D.particle_scale_height(1e-3, G.local_state(3 * C.AU, C.M_sun, 117.83, 162.0, al))
                    for al in alphas])
    np.testing.assert_allclose(hv, hl, rtol=1e-14)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda g: D.friction_time(-1.0, 1e-4, g), "m"),
        (lambda g: D.friction_time(1.0, float("nan"), g), "a"),
        (lambda g: D.friction_time(1.0, 1e-4, g, area=0.0), "area"),
        (lambda g: D.friction_time_compact(1e-12, 0.0, g), "rho_s"),
        (lambda g: D.compact_radius(0.0, 3.0), "m"),
        (lambda g: D.porous_radius(1.0, 3.0, -2.0), "psi"),
        (lambda g: D.projected_area(-1.0), "a"),
        (lambda g: D.stokes_number(-1.0, g), "tau_f"),
        (lambda g: D.particle_scale_height(float("inf"), g), "st"),
    ],
)
def test_bad_inputs(gas3, call, name):
    with pytest.raises(JaxcoagInputError, match=f"`{name}`"):
        call(gas3)


def test_bad_constant_inside_jit_raises_at_trace_time(gas3):
    with pytest.raises(JaxcoagInputError, match="`rho_s`"):
        jax.jit(lambda m: D.friction_time_compact(m, -3.0, gas3))(1e-9)
    # a traced bad value is caught at run time (eqx.error_if) with the same message
    # the equinox runtime check surfaces through XLA's host callback: a JaxRuntimeError on a first
    # dispatch, a ValueError ("INTERNAL: CpuCallback error") from an already-compiled executable
    with pytest.raises((jax.errors.JaxRuntimeError, ValueError), match="`m`") as err:
        jax.block_until_ready(jax.jit(lambda m: D.friction_time_compact(m, 3.0, gas3))(-1e-9))
    assert "EquinoxRuntimeError" in str(err.value)  # the runtime check, not an eager one


def test_bad_structure(gas3):
    with pytest.raises(ValueError, match="regime"):
        D.friction_time(1.0, 1e-4, gas3, regime="newton")
    with pytest.raises(ValueError, match="form"):
        D.particle_scale_height(1e-3, gas3, form="youdin")


def test_internal_twins_match(gas3):
    a = jnp.logspace(-5, 4, 5)
    m = _mass(a)
    np.testing.assert_array_equal(D._friction_time(m, a, gas3), D.friction_time(m, a, gas3))
    np.testing.assert_array_equal(D._friction_time_compact(m, RHO_S, gas3), D.friction_time_compact(m, RHO_S, gas3))
    np.testing.assert_array_equal(D._particle_scale_height(a, gas3), D.particle_scale_height(a, gas3))
    np.testing.assert_array_equal(D._porous_radius(m, RHO_S, 2.0), D.porous_radius(m, RHO_S, 2.0))
