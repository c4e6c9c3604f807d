"""Binned engine with the physical Scene kernel: gradients reach the disk and material parameters.

Issue "binned engine": the kernel is built from the physics core inside the solve, so
d(outcome)/d(alpha, rho_g, T, rho_s, v_frag) flow through diffrax; checked against central
finite differences in log-parameters.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcoag
from jaxcoag import scenes
from jaxcoag.outcomes import Shattering
from jaxcoag.physics import gas as G

GRID = jaxcoag.MassGrid.log(1e-12, 1e0, 3)  # 1e-12 g (~0.5 um) to 1 g, 36 bins
OMEGA = 3.83e-8  # 3 AU


def _n0(rho_d=1e-13, m0=1e-12):
    n = np.zeros(GRID.nbins)
    n[0] = rho_d / GRID.centers[0]
    return jnp.asarray(n)


def _log_peak(lp, t_end=3e10, frag=False):
    alpha, rho_g, T, rho_s, v_frag = (jnp.exp(v) for v in lp)
    gas = G.midplane_state(rho_g, T, alpha, OMEGA)
    kern = scenes.nebula_ch4().kernel(gas, rho_s=rho_s)
    fr = Shattering(v_frag, probability="maxwellian") if frag else None
    sol = jaxcoag.evolve(kern, jaxcoag.Binned(GRID, rtol=1e-8), _n0(), jnp.array([0.0, t_end]), outcome=fr)
    rho = sol.mass_per_bin()[-1]
    # smooth outcome: log of the mass-weighted mean mass (M2/M1 from the bins)
    return jnp.log(jnp.sum(rho * GRID.centers) / jnp.sum(rho)), sol


LP0 = jnp.log(jnp.array([1e-4, 2.4e-11, 162.0, 3.0, 100.0]))
NAMES = ("alpha", "rho_g", "T", "rho_s", "v_frag")


@pytest.mark.slow  # suite budget (34 s); binned gradients vs FD stay in the default run: tests/test_binned_gradients.py
def test_growth_gradients_wrt_disk_and_material_parameters_match_fd():
    f = lambda lp: _log_peak(lp)[0]
    val, sol = _log_peak(LP0)
    assert bool(sol.status == jaxcoag.RESULTS.successful) and abs(float(sol.mass_drift[-1])) < 1e-12
    assert float(val) > np.log(1e-10)  # it grew by > 100x in mass
    g = jax.grad(f)(LP0)
    h = 1e-4
    for i, name in enumerate(NAMES[:4]):
        e = jnp.zeros(5).at[i].set(h)
        fd = (f(LP0 + e) - f(LP0 - e)) / (2 * h)
        np.testing.assert_allclose(g[i], fd, rtol=2e-4, atol=1e-6, err_msg=name)
    assert float(g[4]) == 0.0  # no fragmentation: v_frag does not enter
    assert float(g[0]) > 0  # stronger turbulence, faster growth


@pytest.mark.slow  # the default run keeps the same check on the same solve type (nebula_ch4 kernel, fragmentation
# outcome, implicit Kvaerno5 solve, reverse mode vs central FD in a log outcome parameter, rtol 1e-4) in
# tests/test_binned_outcome.py::test_gradient_wrt_surface_energy_and_modulus_matches_fd; the engine's
# Shattering (no erosion) equals RecipeOutcome(VfragShatter) to round-off (test_binned_outcome.py::
# test_equivalent_to_engine_shattering): ~30 s on 2 cores saved
def test_fragmentation_gradient_wrt_v_frag_matches_fd():
    f = lambda lp: _log_peak(lp, t_end=3e11, frag=True)[0]
    lp = LP0.at[4].set(jnp.log(30.0))  # low v_frag: fragmentation matters by the end
    val, sol = _log_peak(lp, t_end=3e11, frag=True)
    assert bool(sol.status == jaxcoag.RESULTS.successful) and abs(float(sol.mass_drift[-1])) < 1e-6
    g = jax.grad(f)(lp)
    h = 1e-4
    e = jnp.zeros(5).at[4].set(h)
    fd = (f(lp + e) - f(lp - e)) / (2 * h)
    np.testing.assert_allclose(g[4], fd, rtol=2e-3, atol=1e-6)
    assert float(g[4]) > 0  # a higher fragmentation threshold lets grains grow larger
