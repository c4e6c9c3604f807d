"""Exact small-N statistics of the ungrouped species DSMC (MC hazard 14 in docs/design_notes.md:
master equation, binomial and random-graph targets).

Ensembles of R runs are vmapped over keys (one compilation per kernel); every statistic is a
z-score against the exact finite-N expectation of the Marcus-Lushnikov process, |z| < 4.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxcoag as jc
from jaxcoag import kernels as K
from jaxcoag import mc

N0 = 40
R = 400
T_OUT = jnp.array([0.0, 0.5, 1.5, 3.0])


K0S = np.ones(R)
K0S[:3] = [0.5, 1.0, 2.0]  # members 0-2 check the kernel-parameter vmap; 3.. are the ensemble


MONO = jc.Monodisperse(1.0)


def _const_run(k0, t_out, key):
    return jc.evolve(K.Constant(k0), mc.MonteCarlo(n_particles=N0, capacity=N0 + 8), MONO, t_out, key=key, throw=False)


@pytest.fixture(scope="module")
def const_ensemble():
    keys = jax.random.split(jax.random.key(11), R)
    k0 = jnp.asarray(K0S)
    t = T_OUT[None, :] / k0[:, None]
    return keys, k0, t, jax.vmap(_const_run)(k0, t, keys)


def _ensemble(kernel, seed, n=N0, runs=R, **kw):
    keys = jax.random.split(jax.random.key(seed), runs)
    eng = mc.MonteCarlo(n_particles=n, capacity=n + 8, **kw)
    f = jax.vmap(lambda k: jc.evolve(kernel, eng, MONO, T_OUT, key=k, throw=False))
    return f(keys)


def _counts(res):
    """(R, T, kmax+1) number of particles of integer mass k."""
    g = np.asarray(res.g)
    k = np.rint(np.asarray(res.m)).astype(int)
    out = np.zeros(g.shape[:2] + (N0 + 1,))
    for r in range(g.shape[0]):
        for t in range(g.shape[1]):
            np.add.at(out[r, t], np.where(np.asarray(res.valid[r, t]), k[r, t], 0), g[r, t] * np.asarray(res.valid[r, t]))
    return out


def _z(samples, expect):
    samples = np.asarray(samples, float)
    se = samples.std(ddof=1) / math.sqrt(samples.size)
    return (samples.mean() - expect) / max(se, 1e-12)


def _constant_kernel_exact(t_eval, n0=N0):
    """Master equation of the pure death chain μ_n = α n(n-1)/2, α = K0/V (Kingman coalescent)."""
    alpha = 1.0 / n0
    n = np.arange(1, n0 + 1)
    mu = alpha * n * (n - 1) / 2

    def rhs(_, P):
        d = -mu * P
        d[:-1] += mu[1:] * P[1:]
        return d

    P0 = np.zeros(n0)
    P0[-1] = 1.0
    sol = solve_ivp(rhs, (0, t_eval[-1]), P0, t_eval=t_eval, method="Radau", rtol=1e-10, atol=1e-13)
    P = sol.y.T  # (T, n0), P[:, n-1]
    EN = P @ n
    Enk = np.zeros((len(t_eval), n0 + 1))
    for k in range(1, n0 + 1):
        for nn in range(2, n0 + 1):
            if n0 - k - 1 >= nn - 2 >= 0:
                Enk[:, k] += P[:, nn - 1] * nn * math.comb(n0 - k - 1, nn - 2) / math.comb(n0 - 1, nn - 1)
        if k == n0:
            Enk[:, k] += P[:, 0]
    return EN, Enk


def test_constant_kernel_exact_finite_N(const_ensemble):
    full = const_ensemble[3]
    res = jax.tree_util.tree_map(lambda x: x[3:], full)
    assert np.all(np.asarray(res.status == jc.RESULTS.successful))
    EN, Enk = _constant_kernel_exact(np.asarray(T_OUT)[1:])
    # reference values of the master equation (N0 = 40, t = 1.5; independent evaluation)
    assert EN[1] == pytest.approx(23.131, abs=1e-3) and Enk[1, 1] == pytest.approx(13.284, abs=1e-3)
    Nt = np.asarray(res.moments(0.0) * res.V)  # (R, T)
    np.testing.assert_allclose(Nt[:, 0], N0)
    cnt = _counts(res)
    for it in range(1, 4):
        assert abs(_z(Nt[:, it], EN[it - 1])) < 4
        for k in (1, 2, 3):
            assert abs(_z(cnt[:, it, k], Enk[it - 1, k])) < 4, (it, k)
    # U1: exact mass conservation (integer masses, constant V)
    np.testing.assert_array_equal(np.sum(np.asarray(res.g) * np.asarray(res.m), axis=-1), float(N0))
    np.testing.assert_allclose(np.asarray(res.moments(1.0)), 1.0, rtol=1e-14)


@pytest.mark.slow
@pytest.mark.parametrize("rates", [mc.IncrementalRates(), mc.FullRates()])
def test_sum_kernel_binomial_N(rates):
    """N(t) - 1 ~ Binomial(N0 - 1, e^{-t/2}) for K = (m_i+m_j)/2 (the total rate depends on n only); both
    rate designs."""
    res = _ensemble(K.Sum(0.5), 21, rates=rates)
    Nt = np.asarray(res.moments(0.0) * res.V)
    for it, t in enumerate(np.asarray(T_OUT)):
        p = math.exp(-t / 2)
        EN = 1 + (N0 - 1) * p
        var = (N0 - 1) * p * (1 - p)
        if var == 0:
            np.testing.assert_allclose(Nt[:, it], N0)
            continue
        zz = (Nt[:, it].mean() - EN) / math.sqrt(var / R)
        assert abs(zz) < 4, (it, zz)
        # the spread is binomial too (variance within 25 % for R = 400)
        assert Nt[:, it].var(ddof=1) == pytest.approx(var, rel=0.25)
    np.testing.assert_allclose(np.asarray(res.moments(1.0) * res.V), float(N0), rtol=1e-15)


@pytest.mark.slow
def test_product_kernel_n1_n2():
    """E[n_1] = N0 e^{-(N0-1)t/N0}, E[n_2] = C(N0,2)(1-e^{-t/N0}) e^{-2(N0-2)t/N0} (Erdős-Rényi
    random-graph correspondence)."""
    res = _ensemble(K.Product(1.0), 31)
    cnt = _counts(res)
    for it, t in enumerate(np.asarray(T_OUT)):
        if t == 0:
            continue
        En1 = N0 * math.exp(-(N0 - 1) * t / N0)
        En2 = math.comb(N0, 2) * (1 - math.exp(-t / N0)) * math.exp(-2 * (N0 - 2) * t / N0)
        assert abs(_z(cnt[:, it, 1], En1)) < 4, (t, cnt[:, it, 1].mean(), En1)
        assert abs(_z(cnt[:, it, 2], En2)) < 4, (t, cnt[:, it, 2].mean(), En2)


def test_reproducibility_and_vmap(const_ensemble):
    """U11: same key => identical output; different keys differ; repeated call identical;
    vmap over keys and over the kernel coefficient == single runs."""
    keys, k0, t, ens = const_ensemble
    a = _const_run(k0[5], t[5], keys[5])
    b = _const_run(k0[5], t[5], keys[5])
    c = _const_run(k0[6], t[6], keys[6])
    for x, y in ((a, b), (a, jax.tree_util.tree_map(lambda v: v[5], ens))):
        np.testing.assert_array_equal(np.asarray(x.m), np.asarray(y.m))
        np.testing.assert_array_equal(np.asarray(x.w), np.asarray(y.w))
        assert int(x.n_events) == int(y.n_events)
    assert not (np.array_equal(np.asarray(a.m), np.asarray(c.m)) and np.array_equal(np.asarray(a.w), np.asarray(c.w)))
    # kernel-parameter members 0..2 (K0 = 0.5, 1, 2 with times scaled by 1/K0)
    for r in range(3):
        single = _const_run(k0[r], t[r], keys[r])
        np.testing.assert_array_equal(np.asarray(ens.m[r]), np.asarray(single.m))
        np.testing.assert_array_equal(np.asarray(ens.w[r]), np.asarray(single.w))
        np.testing.assert_array_equal(np.asarray(ens.t[r]), T_OUT / K0S[r])


@pytest.mark.slow
def test_run_under_user_jit():
    """jax.jit(evolve)(key) == evolve(key) (the advance is itself jitted; wrapping it must not change results)."""
    kern = K.Constant(1.0)
    eng = mc.MonteCarlo(n_particles=N0, capacity=N0 + 8)
    key = jax.random.key(3)
    j = jax.jit(lambda k: jc.evolve(kern, eng, MONO, T_OUT, key=k, throw=False))(key)
    a = jc.evolve(kern, eng, MONO, T_OUT, key=key)
    np.testing.assert_array_equal(np.asarray(j.m), np.asarray(a.m))
    np.testing.assert_array_equal(np.asarray(j.w), np.asarray(a.w))
