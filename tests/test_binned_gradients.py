"""Gradients through the binned solve: reverse (RecursiveCheckpointAdjoint) and forward
(ForwardMode / jax.jvp) vs central finite differences in log-parameters; jit/vmap consistency;
implicit-function gradients of fragmentation steady states."""

import numpy as np
import pytest
import jax
import jax.numpy as jnp
import diffrax

from jaxcoag import Binned, evolve, kernels
from jaxcoag.binned import MassGrid, monodisperse, steady_state
from jaxcoag.outcomes import Shattering

G = MassGrid.log(10 ** (-0.5 / 5), 1e4, 5)
N0 = monodisperse(G, 1.0, 1.0)
TS = jnp.array([0.0, 5.0, 20.0])
MC = jnp.asarray(G.centers)


def m2_final(logb, adjoint=None):
    """Second moment sum rho_b m_b at t = 20 for the sum kernel K = b (m1 + m2)."""
    sol = evolve(kernels.Sum(jnp.exp(logb)), Binned(G, rtol=1e-10, atol=1e-14, adjoint=adjoint), N0, TS)
    return jnp.sum(sol.mass_per_bin()[-1] * MC)


def _fd(f, x, h=1e-4):
    return (f(x + h) - f(x - h)) / (2 * h)


def test_reverse_and_forward_vs_fd():
    x = jnp.log(0.1)
    g_rev = jax.grad(m2_final)(x)
    _, g_fwd = jax.jvp(lambda v: m2_final(v, diffrax.ForwardMode()), (x,), (jnp.ones(()),))
    g_fd = _fd(m2_final, x)
    assert np.isfinite(float(g_rev)) and float(g_rev) > 0
    assert float(g_rev) == pytest.approx(float(g_fd), rel=1e-5)
    assert float(g_fwd) == pytest.approx(float(g_rev), rel=1e-8)


def test_jit_and_vmap_match():
    bs = jnp.array([0.05, 0.1, 0.2])

    def final_rho(b):
        return evolve(kernels.Sum(b), Binned(G, rtol=1e-10, atol=1e-14), N0, TS, throw=False).mass_per_bin()[-1]

    loop = jnp.stack([final_rho(b) for b in bs])
    vm = jax.vmap(final_rho)(bs)
    jt = jax.jit(final_rho)(bs[1])
    assert np.allclose(np.asarray(vm), np.asarray(loop), rtol=1e-9, atol=1e-15)
    assert np.allclose(np.asarray(jt), np.asarray(loop[1]), rtol=1e-12, atol=1e-16)


from _testkernels import SqrtAlphaKernel as TurbKernel  # noqa: E402  (shared test kernel)


@pytest.mark.slow
def test_steady_state_implicit_gradient():
    """d(mean log mass of the steady state)/d(log v_frag) by the implicit function theorem vs FD."""
    g = MassGrid.log(1e-12, 1e8, 2)
    n0 = monodisperse(g, 1.5e-12, 1e-6)
    lc = jnp.asarray(g.log_centers)
    engine = Binned(g, rtol=1e-5, atol=1e-10)
    guess = steady_state(TurbKernel(1e-3), engine, n0, outcome=Shattering(100.0), t_relax=1e11).y

    def mean_logm(logvf):
        ss = steady_state(TurbKernel(1e-3), engine, None, outcome=Shattering(jnp.exp(logvf)), y_guess=guess)
        rho = ss.mass_per_bin
        return jnp.sum(rho * lc) / jnp.sum(rho)

    x = jnp.log(100.0)
    gr = jax.grad(mean_logm)(x)
    fd = _fd(mean_logm, x, 1e-3)
    # barrier mass ~ v_frag^3 => d<ln m>/d ln v_frag ~ 3
    assert 1.5 < float(gr) < 4.5
    assert float(gr) == pytest.approx(float(fd), rel=1e-4)
