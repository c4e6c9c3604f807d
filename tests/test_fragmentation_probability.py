"""Fragmentation probabilities p_f(Delta v; v_frag): limits, values, gradients."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxcoag.physics import fragmentation as F


def test_maxwellian_values_and_limits():
    vf = 100.0
    # x = (vf/v)^2; p = (1 + 1.5 x) exp(-1.5 x)
    for v in [30.0, 100.0, 250.0, 1e4]:
        x = (vf / v) ** 2
        np.testing.assert_allclose(F.p_frag_maxwellian(v ** 2, vf), (1 + 1.5 * x) * np.exp(-1.5 * x), rtol=1e-14)
    assert float(F.p_frag_maxwellian(0.0, vf)) == 0.0
    assert float(F.p_frag_maxwellian(1e16, vf)) > 1 - 1e-10
    # at v = v_f: 2.5 e^-1.5
    np.testing.assert_allclose(F.p_frag_maxwellian(vf ** 2, vf), 2.5 * np.exp(-1.5), rtol=1e-14)


def test_monotone_and_bounded():
    v2 = jnp.logspace(-2, 8, 400)
    for f in (F.p_frag_maxwellian, F.p_frag_sigmoid, F.p_frag_linear, F.p_frag_step):
        p = np.asarray(f(v2, 100.0))
        assert np.all((p >= 0) & (p <= 1))
        assert np.all(np.diff(p) >= -1e-15)


def test_sigmoid_centre_and_width():
    np.testing.assert_allclose(F.p_frag_sigmoid(100.0 ** 2, 100.0, 0.1), 0.5, rtol=1e-14)
    # one width above the threshold in ln v: logistic(1) = 0.7310585786
    v = 100.0 * np.exp(0.1)
    np.testing.assert_allclose(F.p_frag_sigmoid(v ** 2, 100.0, 0.1), 1 / (1 + np.exp(-1.0)), rtol=1e-12)


def test_gradients_finite_and_match_fd():
    for f in (F.p_frag_maxwellian, F.p_frag_sigmoid):
        g0 = jax.grad(f, argnums=(0, 1))(0.0, 100.0)
        assert all(np.isfinite(np.asarray(x)) for x in g0)

        def lf(lnv, lnvf):
            return f(jnp.exp(2 * lnv), jnp.exp(lnvf))

        lnv, lnvf, h = np.log(120.0), np.log(100.0), 1e-6
        g = jax.grad(lf, argnums=(0, 1))(lnv, lnvf)
        fd0 = (lf(lnv + h, lnvf) - lf(lnv - h, lnvf)) / (2 * h)
        fd1 = (lf(lnv, lnvf + h) - lf(lnv, lnvf - h)) / (2 * h)
        np.testing.assert_allclose(g[0], fd0, rtol=1e-6)
        np.testing.assert_allclose(g[1], fd1, rtol=1e-6)
        # depends on v/v_f only
        np.testing.assert_allclose(g[0], -g[1], rtol=1e-10)


def test_jit_vmap():
    v2 = jnp.array([1.0, 1e4, 1e6])
    np.testing.assert_allclose(jax.jit(F.p_frag_maxwellian)(v2, 100.0), F.p_frag_maxwellian(v2, 100.0), rtol=1e-15)
    vfs = jnp.array([10.0, 100.0])
    np.testing.assert_allclose(jax.vmap(lambda vf: F.p_frag_maxwellian(v2, vf))(vfs),
                               jnp.stack([F.p_frag_maxwellian(v2, vf) for vf in vfs]), rtol=1e-15)
