"""Fragmentation in the binned engine: ShatterAbove power law (thesis §5.3.4),
velocity-dependent shattering/erosion steady state, mass conservation, steady_state helper."""

import functools

import numpy as np
import pytest
import jax
import jax.numpy as jnp

from jaxcoag import Binned, MassGrid, Monodisperse, RESULTS, evolve, kernels
from jaxcoag.kernels import AbstractKernel
from jaxcoag.binned import monodisperse, steady_state
from jaxcoag.binned.redistribution import powerlaw_weights
from jaxcoag.outcomes import ShatterAbove, Shattering
from jaxcoag.binned.twobin import pair_indices


class TurbKernel(AbstractKernel):
    """Test kernel: geometric cross-section x dv, dv^2 = v_b^2 + alpha c^2 ((m1/ms)^2/3 + (m2/ms)^2/3)."""

    alpha: jax.Array
    rho_s: jax.Array

    def __init__(self, alpha, rho_s=1.0):
        self.alpha = jnp.asarray(alpha, float)
        self.rho_s = jnp.asarray(rho_s, float)

    def relative_velocity2(self, m1, m2, x1=None, x2=None):
        ms = 1e6
        return 1.0 + self.alpha * 1e10 * ((m1 / ms) ** (2 / 3) + (m2 / ms) ** (2 / 3))

    def __call__(self, m1, m2, x1=None, x2=None):
        a1 = (3 * m1 / (4 * jnp.pi * self.rho_s)) ** (1 / 3)
        a2 = (3 * m2 / (4 * jnp.pi * self.rho_s)) ** (1 / 3)
        return jnp.pi * (a1 + a2) ** 2 * jnp.sqrt(self.relative_velocity2(m1, m2))


G_TURB = MassGrid.log(1e-12, 1e8, 2)
N0_TURB = monodisperse(G_TURB, 1.5e-12, 1e-6)
TS_TURB = np.concatenate([[0.0], np.logspace(4, 12, 9)])


@functools.lru_cache(maxsize=None)
def _turb(alpha):
    return evolve(TurbKernel(alpha), Binned(G_TURB, rtol=1e-5, atol=1e-10), N0_TURB, TS_TURB,
                  outcome=Shattering(100.0))


def test_fragment_weights():
    g = MassGrid.log(1e-3, 1e3, 4)
    W = np.asarray(powerlaw_weights(g, 11.0 / 6.0))
    assert np.allclose(W.sum(axis=1), 1.0, atol=1e-14)
    assert np.all(np.triu(W, 1) == 0)
    # mass per ln m ~ m^{2-q} = m^{1/6}: ratio of neighbouring bins = 10^{(1/6)/4}
    row = W[-1]
    assert np.allclose(row[1:] / row[:-1], 10 ** ((1 / 6) / 4), rtol=1e-12)
    W2 = np.asarray(powerlaw_weights(g, 2.0))  # flat in ln m
    assert np.allclose(W2[-1], 1.0 / g.nbins, rtol=1e-10)


def test_frag_tensors_conserve_mass():
    g = MassGrid.log(1e-6, 1e6, 5)
    iL, iS = pair_indices(g.nbins)
    d = Shattering(100.0).twobin_data(TurbKernel(1e-3), g, iL, iS)
    scale = np.exp(g.log_centers[iL])
    # direct coefficients + ejecta (redistributed with rows summing to 1) sum to zero per pair
    assert np.max(np.abs(np.asarray(d.coef).sum(axis=1) + np.asarray(d.ejecta)) / scale) < 1e-13
    crater = (g.log_centers[iL] - g.log_centers[iS]) >= np.log(10.0)
    assert crater.any() and (~crater).any()
    # erosion: ejecta = (1 + chi) m_S from the projectile's bin
    assert np.allclose(np.asarray(d.ejecta)[crater], 2.0 * np.exp(g.log_centers[iS][crater]), rtol=1e-14)
    # random state: rhs conserves mass
    rng = np.random.default_rng(0)
    rate = jnp.asarray(rng.random(iL.size))
    out = d.rhs(rate, g.nbins)
    assert abs(float(jnp.sum(out))) < 1e-13 * float(jnp.sum(jnp.abs(out)))


def test_shatter_above_powerlaw():
    """Constant kernel, disruption into monomers above m_frag = 1e10: steady m^2 f ~ m^{1/2}
    (f ~ m^-3/2, thesis §5.3.4 / eq. 5.22 with beta = 0). Measured slope 0.49984 at 5 bins/decade."""
    bpd = 5
    g = MassGrid.log(10 ** (-0.5 / bpd), 1e11, bpd)  # top above m_frag: nothing reaches the gel
    ts = np.concatenate([[0.0], np.logspace(0, 14, 8)])
    sol = evolve(kernels.Constant(1.0), Binned(g, rtol=1e-4, atol=1e-8), Monodisperse(1.0, 1.0), ts,
                 outcome=ShatterAbove(1e10, 1.0))
    rho = np.asarray(sol.rho)
    lm = np.log10(g.centers)
    assert float(sol.gel_mass[-1]) < 1e-12
    sel = (lm > 1) & (lm < 8)
    slope = np.polyfit(lm[sel], np.log10(rho[-1][sel]), 1)[0]
    assert slope == pytest.approx(0.5, abs=0.01)
    assert np.max(np.abs(np.asarray(sol.mass_drift))) < 1e-8
    # steady: the last two snapshots (1e12, 1e14) agree in the power-law range
    assert np.max(np.abs(rho[-1][sel] / rho[-2][sel] - 1)) < 1e-3


def test_velocity_fragmentation_steady_state():
    """Shattering + erosion with a sqrt(alpha) test kernel reaches a steady state below the
    fragmentation barrier m_b = ms (v_f^2/(alpha c^2))^{3/2} and conserves mass."""
    alpha = 1e-3
    sol = _turb(alpha)
    rho = np.asarray(sol.rho)
    assert sol.status == RESULTS.successful
    assert np.max(np.abs(np.asarray(sol.mass_drift))) < 1e-7  # Newton-limited (Kvaerno5)
    assert float(sol.gel_mass[-1]) < 1e-12 * 1e-6
    change = np.abs(rho[-1] - rho[-2]).sum() / rho[-1].sum()
    assert change < 1e-4
    m_barrier = 1e6 * (1e4 / (alpha * 1e10)) ** 1.5
    m_peak = G_TURB.centers[np.argmax(rho[-1])]
    assert m_barrier / 30 < m_peak < m_barrier
    assert rho[-1].min() >= -1e-12 * 1e-6


def test_steady_state_helper():
    alpha = 1e-3
    ss = steady_state(TurbKernel(alpha), Binned(G_TURB), None, outcome=Shattering(100.0),
                      y_guess=_turb(alpha).y[-3])  # t = 1e10 snapshot as the guess
    long = np.asarray(_turb(alpha).rho[-1])
    assert float(ss.residual) < 1e-12
    assert np.abs(np.asarray(ss.mass_per_bin) - long).sum() / long.sum() < 1e-4
    assert float(jnp.sum(ss.mass_per_bin)) == pytest.approx(1e-6, rel=1e-8)


def test_analytic_kernel_velocity_fragmentation_error():
    g = MassGrid.log(1.0, 1e3, 3)
    with pytest.raises(TypeError, match="relative velocity"):
        evolve(kernels.Constant(1.0), Binned(g), Monodisperse(1.0, 1.0), [0.0, 1.0], outcome=Shattering(100.0))
