"""Analytic kernels: values, log forms beyond float range, symmetry, gradients, jit/vmap."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag import kernels as K
from jaxcoag._validate import JaxcoagInputError


M = jnp.array([1e-12, 1.0, 3.0, 7.5e5, 1e30])


def test_values_match_definitions():
    m1, m2 = M[:, None], M[None, :]
    np.testing.assert_allclose(K.Constant(2.5)(m1, m2), 2.5 * np.ones((5, 5)), rtol=0)
    np.testing.assert_allclose(K.Sum(0.5)(m1, m2), 0.5 * (m1 + m2), rtol=1e-15)
    np.testing.assert_allclose(K.Product(2.0)(m1, m2), 2.0 * m1 * m2, rtol=1e-15)
    np.testing.assert_allclose(K.PowerProduct(3.0, 0.5)(m1, m2), 3.0 * (m1 * m2) ** 0.5, rtol=1e-13)
    np.testing.assert_allclose(K.PowerLaw(0.7, 1.0, 0.3)(m1, m2),
                               0.7 * (m1 * m2 ** 0.3 + m1 ** 0.3 * m2), rtol=1e-13)


def test_special_cases_of_power_law():
    m1, m2 = M[:, None], M[None, :]
    np.testing.assert_allclose(K.PowerLaw(0.5, 1.0, 0.0)(m1, m2), K.Sum(0.5)(m1, m2), rtol=1e-13)
    np.testing.assert_allclose(K.PowerLaw(0.5, 1.0, 1.0)(m1, m2), K.Product(1.0)(m1, m2), rtol=1e-13)
    np.testing.assert_allclose(K.PowerLaw(1.5, 0.0, 0.0)(m1, m2), K.Constant(3.0)(m1, m2), rtol=1e-13)


@pytest.mark.parametrize("kern", [K.Constant(1.3), K.Sum(0.5), K.Product(1.0), K.PowerProduct(1.0, 2.0),
                                  K.PowerLaw(0.2, 0.9, 0.1)])
def test_symmetry_matrix_and_log(kern):
    mat = kern.matrix(M[:3])
    np.testing.assert_array_equal(np.asarray(mat), np.asarray(mat).T)
    np.testing.assert_allclose(kern.log_kernel(M[:3, None], M[None, :3]), np.log(mat), rtol=1e-13)


def test_log_kernel_beyond_float_range():
    # masses of 1e160 m0 (Monte Carlo runaway regime): log K stays finite and exact
    lm = jnp.log(10.0) * 160.0
    assert float(K.Product(1.0).log_kernel_from_log_mass(lm, lm)) == pytest.approx(2 * 160 * np.log(10), rel=1e-14)
    assert float(K.PowerProduct(1.0, 3.0).log_kernel_from_log_mass(lm, lm)) == pytest.approx(960 * np.log(10), rel=1e-14)
    assert float(K.Sum(0.5).log_kernel_from_log_mass(lm, 0.0)) == pytest.approx(np.log(0.5) + 160 * np.log(10), rel=1e-14)
    # 300 orders of magnitude in rate within one evaluation
    lk = K.PowerProduct(1.0, 1.0).log_kernel_from_log_mass(jnp.array([0.0, 345.0]), jnp.array([0.0, 345.0]))
    assert np.all(np.isfinite(lk)) and float(lk[1] - lk[0]) / np.log(10) > 299


def test_gradients_in_log_parameters_vs_fd():
    m1, m2 = 3.0, 11.0

    def f(logb, nu):
        return jnp.log(K.PowerProduct(jnp.exp(logb), nu)(m1, m2))

    g = jax.grad(f, argnums=(0, 1))(jnp.log(2.0), 0.7)
    h = 1e-6
    fd0 = (f(np.log(2.0) + h, 0.7) - f(np.log(2.0) - h, 0.7)) / (2 * h)
    fd1 = (f(np.log(2.0), 0.7 + h) - f(np.log(2.0), 0.7 - h)) / (2 * h)
    np.testing.assert_allclose(g[0], fd0, rtol=1e-8)
    np.testing.assert_allclose(g[1], fd1, rtol=1e-8)
    np.testing.assert_allclose(g[1], np.log(m1 * m2), rtol=1e-12)


def test_jit_and_vmap_over_parameter():
    bs = jnp.array([0.1, 0.5, 2.0])
    f = lambda b: K.Sum(b).matrix(M[:3])
    stacked = jnp.stack([f(b) for b in bs])
    np.testing.assert_allclose(jax.vmap(f)(bs), stacked, rtol=1e-15)
    np.testing.assert_allclose(jax.jit(f)(bs[1]), stacked[1], rtol=1e-15)


def test_bad_parameters_raise():
    with pytest.raises(JaxcoagInputError, match="b"):
        K.Sum(-1.0)
    with pytest.raises(JaxcoagInputError, match="k0"):
        K.Constant(float("nan"))
    with pytest.raises(TypeError, match="analytic kernel"):
        K.Constant(1.0).relative_velocity2(1.0, 2.0)
