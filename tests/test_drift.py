"""Brownian and drift velocities (thesis eqs. 1.23-1.25, 2.1, 4.4, 4.8, 4.22a, 4.28)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag import constants as C
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.physics import drift as V
from jaxcoag.physics import gas as G

ETA, VK = 2.65e-3, 1.7196e6  # ch4 3 AU-like values


def _mass(a, rho_s=3.0):
    return 4.0 / 3.0 * math.pi * rho_s * a ** 3


# ------------------------------------------------------------------------------------ Brownian


@pytest.mark.parametrize("a1, a2, want", [(1e-4, 1e-4, 9.5209e-2), (1e-4, 1e-2, 6.7323e-2), (1e-5, 1e-5, 3.0108)])
def test_brownian_reference_32(a1, a2, want):
    dv = V.dv_brownian(_mass(a1), _mass(a2), 162.0)
    np.testing.assert_allclose(dv, want, rtol=1e-4)
    np.testing.assert_allclose(V.dv2_brownian(_mass(a1), _mass(a2), 162.0), dv ** 2, rtol=1e-14)


def test_brownian_equals_eq422a():
    T, rho_s = 162.0, 3.0
    a = jnp.logspace(-6, -1, 6)
    for phi in (1.0, 0.1, 1e-3):
        m = _mass(a, rho_s * phi)  # porous: m = (4 pi/3) rho_s phi a^3
        form = 2 / math.pi * jnp.sqrt(3 * C.k_B * T / rho_s) * a ** -1.5 / math.sqrt(phi)
        np.testing.assert_allclose(V.dv_brownian(m, m, T), form, rtol=1e-13)
    # reduced-mass form sqrt(8 kT/(pi m_mu)) at moderate masses
    m1, m2 = jnp.array([1e-12, 3e-9]), jnp.array([5e-14, 1e-3])
    mu = m1 * m2 / (m1 + m2)
    np.testing.assert_allclose(V.dv_brownian(m1, m2, T), jnp.sqrt(8 * C.k_B * T / (math.pi * mu)), rtol=1e-14)


def test_brownian_overflow_free():
    T = 100.0
    # m1 m2 = 1e600 overflows; the 1/m form does not
    dv = V.dv_brownian(1e300, 1e300, T)
    want = math.sqrt(8 * C.k_B * T / math.pi) * math.sqrt(2.0) * 1e-150
    np.testing.assert_allclose(dv, want, rtol=1e-14)
    dv = V.dv_brownian(jnp.array([1e300, 1e-300]), jnp.array([1e-30, 1e300]), T)
    np.testing.assert_allclose(dv, [math.sqrt(8 * C.k_B * T / math.pi) * 1e15,
                                    math.sqrt(8 * C.k_B * T / math.pi) * 1e150], rtol=1e-14)
    # the square underflows (< 2.2e-308) only for m >~ 1e294 g: harmless, never NaN
    assert float(V.dv2_brownian(1e300, 1e300, T)) >= 0.0
    assert np.all(np.isfinite(np.asarray(V.dv2_brownian(jnp.array([1e300, 1e-300]), 1e-300, T))))
    g = jax.grad(lambda lm: V.dv_brownian(jnp.exp(lm), 1e300, T))(math.log(1e300))
    assert np.isfinite(float(g))


def test_log_brownian_from_log_mass():
    T = 162.0
    lm = jnp.log(jnp.array([1e-15, 1e-3, 1e30]))
    np.testing.assert_allclose(jnp.exp(V._log_dv2_brownian_from_log_mass(lm[:, None], lm[None, :], T)),
                               V.dv2_brownian(jnp.exp(lm)[:, None], jnp.exp(lm)[None, :], T), rtol=1e-13)
    # beyond 1e308 g, and the ln-m gradient stays exact: d ln dv2 / d ln m1 = -m2/(m1 + m2)
    big = 2000.0  # ln m, m = e^2000
    np.testing.assert_allclose(V._log_dv2_brownian_from_log_mass(big, big, T),
                               math.log(8 * C.k_B * T / math.pi) + math.log(2.0) - big, rtol=1e-14)
    g = jax.grad(V._log_dv2_brownian_from_log_mass)(big, big + math.log(3.0), T)
    np.testing.assert_allclose(g, -0.75, rtol=1e-12)


def test_brownian_grad_vs_fd_log_mass():
    T = 162.0
    f = lambda l1, l2, lT: jnp.log(V.dv_brownian(jnp.exp(l1), jnp.exp(l2), jnp.exp(lT)))
    x = (math.log(1e-11), math.log(4e-9), math.log(T))
    grads = jax.grad(f, argnums=(0, 1, 2))(*x)
    h = 1e-5
    for i in range(3):
        xp = list(x); xm = list(x)
        xp[i] += h; xm[i] -= h
        np.testing.assert_allclose(grads[i], (f(*xp) - f(*xm)) / (2 * h), rtol=1e-8, atol=1e-10)
    # analytic: d ln dv/d ln m1 = -(1/2) m2/(m1 + m2); d ln dv / d ln T = 1/2
    np.testing.assert_allclose(grads[0], -0.5 * 4e-9 / (1e-11 + 4e-9), rtol=1e-12)
    np.testing.assert_allclose(grads[2], 0.5, rtol=1e-12)


# ------------------------------------------------------------------------------------ radial drift


def test_radial_drift_31():
    np.testing.assert_allclose(V.v_radial_drift(1.0, ETA, VK), -ETA * VK, rtol=1e-12)
    st = jnp.logspace(-8, 8, 161)  # contains St = 1 (index 80)
    v = V.v_radial_drift(st, ETA, VK)
    assert float(jnp.max(jnp.abs(v))) <= ETA * VK * (1 + 1e-12)
    np.testing.assert_allclose(st[jnp.argmax(jnp.abs(v))], 1.0, rtol=1e-12)
    np.testing.assert_allclose(v, -2 * st / (1 + st ** 2) * ETA * VK, rtol=1e-13)
    # St -> 1/St invariance: Delta v_r(St, 1/St) = 0
    s = jnp.array([1e-6, 0.01, 0.3, 1.0, 7.0, 1e5])
    dv = jnp.sqrt(V.dv2_radial_drift(s, 1.0 / s, ETA, VK))
    assert float(jnp.max(dv)) <= 1e-12 * ETA * VK
    # pairwise equals the squared difference of single-particle velocities
    s1, s2 = jnp.array([1e-3, 0.5, 3.0, 1e3]), jnp.array([1e-5, 2.0, 0.1, 1e3])
    np.testing.assert_allclose(V.dv2_radial_drift(s1, s2, ETA, VK),
                               (V.v_radial_drift(s1, ETA, VK) - V.v_radial_drift(s2, ETA, VK)) ** 2,
                               rtol=1e-12, atol=1e-20)


def test_radial_drift_extremes_and_grad():
    # no St^2 overflow; small-St limit linear
    np.testing.assert_allclose(V.v_radial_drift(1e200, ETA, VK), -2e-200 * ETA * VK, rtol=1e-13)
    np.testing.assert_allclose(V.v_radial_drift(1e-200, ETA, VK), -2e-200 * ETA * VK, rtol=1e-13)
    assert float(V.v_radial_drift(0.0, ETA, VK)) <= 0.0
    v2 = V.dv2_radial_drift(1e300, 1e-300, ETA, VK)
    assert np.isfinite(float(v2))
    # smooth at St1 = St2 (square of a difference, no abs): gradient exactly 0 there
    g = jax.grad(V.dv2_radial_drift, argnums=(0, 1))(0.3, 0.3, ETA, VK)
    assert float(g[0]) == 0.0 and float(g[1]) == 0.0
    # gradient vs FD in ln St
    f = lambda ls: V.v_radial_drift(jnp.exp(ls), ETA, VK)
    for x in (math.log(0.01), 0.7, math.log(50.0)):
        np.testing.assert_allclose(jax.grad(f)(x), (f(x + 1e-6) - f(x - 1e-6)) / 2e-6, rtol=1e-7)


def test_radial_drift_collective():
    st = jnp.array([1e-3, 0.3, 1.0, 30.0])
    np.testing.assert_allclose(V.v_radial_drift_collective(st, ETA, VK, 0.0), V.v_radial_drift(st, ETA, VK),
                               rtol=1e-14)
    np.testing.assert_allclose(V.v_radial_drift_collective(1.0, ETA, VK, 1.0), -0.4 * ETA * VK, rtol=1e-14)
    eps = jnp.array([0.0, 0.1, 1.0, 10.0])
    v = V.v_radial_drift_collective(0.5, ETA, VK, eps)
    np.testing.assert_allclose(v, -2 * 0.5 * ETA * VK / (0.25 + (1 + eps) ** 2), rtol=1e-14)
    assert bool(jnp.all(jnp.diff(jnp.abs(v)) < 0))  # dust loading reduces the drift
    assert np.isfinite(float(V.v_radial_drift_collective(1e300, ETA, VK, 1e3)))


# ------------------------------------------------------------------------------------ [EXT] drifts


def test_azimuthal_drift_limits():
    np.testing.assert_allclose(V.v_azimuthal_drift(0.0, ETA, VK), -ETA * VK, rtol=1e-14)
    np.testing.assert_allclose(V.v_azimuthal_drift(1.0, ETA, VK), -0.5 * ETA * VK, rtol=1e-14)
    np.testing.assert_allclose(V.v_azimuthal_drift(1e100, ETA, VK), -1e-200 * ETA * VK, rtol=1e-13)
    st = jnp.logspace(-4, 4, 33)
    vr = V.v_radial_drift(st, ETA, VK)
    vphi = V.v_azimuthal_drift(st, ETA, VK)
    np.testing.assert_allclose(vphi, -ETA * VK / (1 + st ** 2), rtol=1e-13)
    # single-particle identity of the steady solution: (v_r/2)^2 + v_phi^2 = -eta v_K v_phi
    np.testing.assert_allclose((vr / 2) ** 2 + vphi ** 2, -ETA * VK * vphi, rtol=1e-12)
    s1, s2 = st, st[::-1]
    np.testing.assert_allclose(V.dv2_azimuthal_drift(s1, s2, ETA, VK),
                               (V.v_azimuthal_drift(s1, ETA, VK) - V.v_azimuthal_drift(s2, ETA, VK)) ** 2,
                               rtol=1e-11, atol=1e-24)
    # max pairwise: (eta v_K)^2 between St -> 0 and St -> inf
    np.testing.assert_allclose(V.dv2_azimuthal_drift(1e-30, 1e30, ETA, VK), (ETA * VK) ** 2, rtol=1e-14)


def test_settling_limits():
    z, Om = 1e12, 3.83e-8
    # small St: the thesis terminal velocity -z Omega St (ch. 1)
    np.testing.assert_allclose(V.v_settling(1e-6, z, Om), -z * Om * 1e-6, rtol=1.1e-6)
    # cap: |v_z| -> z Omega for St -> inf, z Omega / 2 at St = 1
    np.testing.assert_allclose(V.v_settling(1.0, z, Om), -0.5 * z * Om, rtol=1e-14)
    np.testing.assert_allclose(V.v_settling(1e300, z, Om), -z * Om, rtol=1e-14)
    assert float(V.v_settling(0.0, 0.0, Om)) == 0.0
    np.testing.assert_allclose(V.v_settling(0.1, -z, Om), -V.v_settling(0.1, z, Om), rtol=1e-15)
    # pairwise: small-St limit (z Omega (St1 - St2))^2; equal to squared difference everywhere
    np.testing.assert_allclose(V.dv2_settling(2e-7, 1e-7, z, Om), (z * Om * 1e-7) ** 2, rtol=1e-6)
    s1, s2 = jnp.array([1e-3, 0.5, 3.0, 1e8]), jnp.array([1e-5, 2.0, 3.0, 1e-8])
    np.testing.assert_allclose(V.dv2_settling(s1, s2, z, Om),
                               (V.v_settling(s1, z, Om) - V.v_settling(s2, z, Om)) ** 2, rtol=1e-10, atol=1e-12)
    assert float(V.dv2_settling(3.0, 3.0, z, Om)) == 0.0
    g = jax.grad(V.dv2_settling, argnums=(0, 1))(3.0, 3.0, z, Om)
    assert float(g[0]) == 0.0 and float(g[1]) == 0.0


def test_drift_with_gas_state_and_transforms():
    g = G.ch4_disk(3 * C.AU)
    st = jnp.logspace(-4, 2, 7)
    eager = V.dv2_radial_drift(st[:, None], st[None, :], g.eta, g.v_K)
    jitted = jax.jit(lambda s1, s2, gg: V.dv2_radial_drift(s1, s2, gg.eta, gg.v_K))(st[:, None], st[None, :], g)
    tol = dict(rtol=1e-14, atol=1e-14 * float(jnp.max(eager)))  # St <-> 1/St pairs are rounding-level zeros
    np.testing.assert_allclose(jitted, eager, **tol)
    np.testing.assert_allclose(jnp.diag(eager), 0.0, atol=0.0)
    vm = jax.vmap(lambda s: V.dv2_radial_drift(s, st, g.eta, g.v_K))(st)
    np.testing.assert_allclose(vm, eager, **tol)
    # Brownian matrix: vmap == stacked loop == jit, with a concrete temperature inside jit
    m = jnp.logspace(-15, -6, 5)
    mat = jax.jit(lambda m: V.dv2_brownian(m[:, None], m[None, :], 162.0))(m)
    loop = jnp.stack([V.dv2_brownian(mi, m, 162.0) for mi in m])
    np.testing.assert_allclose(mat, loop, rtol=1e-14)
    np.testing.assert_allclose(jax.vmap(lambda mi: V.dv2_brownian(mi, m, 162.0))(m), loop, rtol=1e-14)


def test_internal_twins_match():
    m1, m2 = jnp.array([1e-12, 1e3]), jnp.array([1e-9, 1e-14])
    np.testing.assert_array_equal(V._dv2_brownian(m1, m2, 162.0), V.dv2_brownian(m1, m2, 162.0))
    np.testing.assert_array_equal(V._dv_brownian(m1, m2, 162.0), V.dv_brownian(m1, m2, 162.0))
    s1, s2 = jnp.array([1e-3, 5.0]), jnp.array([0.2, 0.2])
    np.testing.assert_array_equal(V._dv2_radial_drift(s1, s2, ETA, VK), V.dv2_radial_drift(s1, s2, ETA, VK))
    np.testing.assert_array_equal(V._dv2_azimuthal_drift(s1, s2, ETA, VK), V.dv2_azimuthal_drift(s1, s2, ETA, VK))
    np.testing.assert_array_equal(V._dv2_settling(s1, s2, 1e12, 4e-8), V.dv2_settling(s1, s2, 1e12, 4e-8))


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: V.dv_brownian(0.0, 1.0, 100.0), "m1"),
        (lambda: V.dv2_brownian(1.0, float("nan"), 100.0), "m2"),
        (lambda: V.dv2_brownian(1.0, 1.0, -3.0), "T"),
        (lambda: V.v_radial_drift(-0.1, ETA, VK), "st"),
        (lambda: V.dv2_radial_drift(0.1, float("nan"), ETA, VK), "st2"),
        (lambda: V.v_radial_drift_collective(0.1, ETA, VK, -1.0), "eps_dust"),
        (lambda: V.dv2_settling(0.1, 0.2, float("inf"), 1e-7), "z"),
        (lambda: V.v_azimuthal_drift(0.1, ETA, -VK), "v_K"),
    ],
)
def test_bad_inputs(call, name):
    with pytest.raises(JaxcoagInputError, match=f"`{name}`"):
        call()
