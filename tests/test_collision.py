"""Cross-sections, gravitational focusing and the sigma*dv kernel (thesis eq. 5.5, eqs. 1.6/1.7; velocity hazard 6)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag import constants as C
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.physics import collision as K

# two 10 km rocky planetesimals
A1, A2 = 1e6, 2e6
M1, M2 = 4 / 3 * math.pi * 3.0 * A1 ** 3, 4 / 3 * math.pi * 3.0 * A2 ** 3
RS = A1 + A2
VESC2 = 2 * C.G * (M1 + M2) / RS


def test_cross_section_and_escape_velocity():
    np.testing.assert_allclose(K.cross_section(A1, A2), math.pi * RS ** 2, rtol=1e-15)
    a = jnp.array([1e-5, 1.0, 1e8])
    np.testing.assert_allclose(K.cross_section(a[:, None], a[None, :]), math.pi * (a[:, None] + a[None, :]) ** 2,
                               rtol=1e-15)
    np.testing.assert_allclose(K.escape_velocity2(M1, M2, A1, A2), VESC2, rtol=1e-15)


def test_focusing_33():
    # Delta v >> v_esc: sigma -> pi R_s^2
    f_fast = K.focusing_factor(M1, M2, A1, A2, 1e14 * VESC2)
    np.testing.assert_allclose(f_fast, 1.0, rtol=1e-12, atol=0)
    # Delta v = v_esc: sigma = 2 pi R_s^2
    np.testing.assert_allclose(K.focusing_factor(M1, M2, A1, A2, VESC2), 2.0, rtol=1e-12)
    sig = K.cross_section(A1, A2)
    np.testing.assert_allclose(K.kernel_sigma_dv(A1, A2, M1, M2, VESC2, focusing=True),
                               2 * sig * math.sqrt(VESC2), rtol=1e-12)
    big = 1e14 * VESC2
    np.testing.assert_allclose(K.kernel_sigma_dv(A1, A2, M1, M2, big, focusing=True),
                               sig * math.sqrt(big), rtol=1e-12)
    # slow limit: sigma ∝ m^(4/3) scaling, K = pi R_s^2 v_esc^2 / dv
    slow = 1e-6 * VESC2
    np.testing.assert_allclose(K.kernel_sigma_dv(A1, A2, M1, M2, slow, focusing=True),
                               sig * (math.sqrt(slow) + VESC2 / math.sqrt(slow)), rtol=1e-13)
    # focusing=True equals sigma * factor * dv
    dv2 = jnp.array([1e-4, 1.0, 1e4]) * VESC2
    np.testing.assert_allclose(K.kernel_sigma_dv(A1, A2, M1, M2, dv2, focusing=True),
                               sig * K.focusing_factor(M1, M2, A1, A2, dv2) * jnp.sqrt(dv2), rtol=1e-13)


def test_no_focusing_kernel_and_floor():
    dv2 = jnp.array([0.0, 1e-6, 1.0, 1e8])
    sig = K.cross_section(1e-4, 3e-4)
    np.testing.assert_allclose(K.kernel_sigma_dv(1e-4, 3e-4, 1.0, 1.0, dv2), sig * jnp.sqrt(dv2), rtol=1e-15)
    # dv_floor adds in quadrature
    np.testing.assert_allclose(K.kernel_sigma_dv(1e-4, 3e-4, 1.0, 1.0, dv2, dv_floor=2.0),
                               sig * jnp.sqrt(dv2 + 4.0), rtol=1e-15)
    np.testing.assert_allclose(K.focusing_factor(M1, M2, A1, A2, 0.0, dv_floor=1e3), 1 + VESC2 / 1e6, rtol=1e-14)


def test_dv2_zero_finite_value_and_gradient():
    for focusing in (False, True):
        k = lambda d: K.kernel_sigma_dv(A1, A2, M1, M2, d, focusing=focusing)
        v, g = jax.value_and_grad(k)(0.0)
        assert np.isfinite(float(v)) and np.isfinite(float(g)), (focusing, v, g)
    assert float(K.kernel_sigma_dv(A1, A2, M1, M2, 0.0)) == 0.0
    assert float(jax.grad(lambda d: K.kernel_sigma_dv(A1, A2, M1, M2, d))(0.0)) == 0.0
    # focusing at dv2 = 0: the documented floor DV2_MIN = sqrt(tiny) bounds the factor
    ff = K.focusing_factor(M1, M2, A1, A2, 0.0)
    np.testing.assert_allclose(ff, 1 + VESC2 / K.dv2_min(jnp.float64), rtol=1e-14)
    assert np.isfinite(float(ff))
    # gradients wrt every input are finite at dv2 = 0 (a, m too)
    grads = jax.grad(lambda a1, a2, m1, m2, d: K.kernel_sigma_dv(a1, a2, m1, m2, d, focusing=True),
                     argnums=(0, 1, 2, 3, 4))(A1, A2, M1, M2, 0.0)
    assert all(np.isfinite(float(x)) for x in grads)
    # float32 (opt-in): the floor is sqrt(tiny_f32); value and gradient still finite
    f32 = lambda x: jnp.asarray(x, jnp.float32)
    k32 = lambda d: K.kernel_sigma_dv(f32(1e5), f32(1e5), f32(1e16), f32(1e16), d, focusing=True)
    v32, g32 = jax.value_and_grad(k32)(f32(0.0))
    assert v32.dtype == jnp.float32 and np.isfinite(float(v32)) and float(g32) == 0.0
    # and the kernel built from component squares with a zero total (identical particles)
    dv2_tot = lambda x: (x - x) ** 2 + 0.0 * x
    g = jax.grad(lambda x: K.kernel_sigma_dv(1e-4, 1e-4, 1e-11, 1e-11, dv2_tot(x)))(0.3)
    assert float(g) == 0.0


def test_grad_vs_fd_log_params():
    def lk(la1, lm1, ld):
        return jnp.log(K.kernel_sigma_dv(jnp.exp(la1), A2, jnp.exp(lm1), M2, jnp.exp(ld), focusing=True))
    x = (math.log(A1), math.log(M1), math.log(VESC2))
    grads = jax.grad(lk, argnums=(0, 1, 2))(*x)
    for i in range(3):
        xp, xm = list(x), list(x)
        xp[i] += 1e-6
        xm[i] -= 1e-6
        np.testing.assert_allclose(grads[i], (lk(*xp) - lk(*xm)) / 2e-6, rtol=1e-7, atol=1e-9)
    # at dv = v_esc: d ln K / d ln dv2 = (1/2)(dv - v_esc^2/dv)/(dv + v_esc^2/dv) = 0
    np.testing.assert_allclose(grads[2], 0.0, atol=1e-12)


def test_jit_vmap():
    a = jnp.logspace(-4, 6, 6)
    m = 4 / 3 * math.pi * 2.0 * a ** 3
    dv2 = jnp.logspace(-6, 8, 6)[:, None] * jnp.ones((1, 6))
    for focusing in (False, True):
        f = lambda a1, a2, m1, m2, d: K.kernel_sigma_dv(a1, a2, m1, m2, d, focusing=focusing)
        eager = f(a[:, None], a[None, :], m[:, None], m[None, :], dv2)
        jitted = jax.jit(f)(a[:, None], a[None, :], m[:, None], m[None, :], dv2)
        np.testing.assert_allclose(jitted, eager, rtol=1e-14)
        vm = jax.vmap(f, in_axes=(0, None, 0, None, 0))(a, a, m, m, dv2)
        np.testing.assert_allclose(vm, eager, rtol=1e-14)
    # the internal twin (hot path) agrees bitwise
    np.testing.assert_array_equal(
        K._kernel_sigma_dv(a[:, None], a[None, :], m[:, None], m[None, :], dv2, focusing=True),
        K.kernel_sigma_dv(a[:, None], a[None, :], m[:, None], m[None, :], dv2, focusing=True))


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: K.cross_section(-1.0, 1.0), "a1"),
        (lambda: K.kernel_sigma_dv(1.0, 1.0, 1.0, 1.0, -1.0), "dv2"),
        (lambda: K.kernel_sigma_dv(1.0, float("nan"), 1.0, 1.0, 1.0), "a2"),
        (lambda: K.kernel_sigma_dv(1.0, 1.0, 0.0, 1.0, 1.0, focusing=True), "m1"),
        (lambda: K.kernel_sigma_dv(1.0, 1.0, 1.0, 1.0, 1.0, dv_floor=-1.0), "dv_floor"),
        (lambda: K.focusing_factor(1.0, 1.0, 1.0, 1.0, float("inf")), "dv2"),
    ],
)
def test_bad_inputs(call, name):
    with pytest.raises(JaxcoagInputError, match=f"`{name}`"):
        call()


def test_focusing_flag_must_be_python_bool():
    with pytest.raises(TypeError, match="Python bool"):
        K.kernel_sigma_dv(1.0, 1.0, 1.0, 1.0, 1.0, focusing=jnp.array(True))
