"""jaxcoag.plot.panel: PNG written, plotted m^2 f data equal the solution's numbers."""

import numpy as np
import pytest
import jax.numpy as jnp

from jaxcoag import constants as C
from jaxcoag import diagnostics, kernels, plot, scenes
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.binned import MassGrid, monodisperse, solve_binned
from jaxcoag.physics.gas import ch4_disk


@pytest.fixture(scope="module")
def physical():
    gas = ch4_disk(3 * C.AU)
    K = scenes.nebula_ch4().kernel(gas, rho_s=3.0)
    m0 = 4 / 3 * np.pi * 3.0 * 1e-12
    g = MassGrid.log(m0 / 10 ** 0.1, m0 * 1e6, 5)
    sol = solve_binned(K, g, monodisperse(g, m0, 1e-2 * float(gas.rho_g)), jnp.array([0.0, 1e9, 3e9, 1e10]), dt0=1e4)
    return sol, K


def test_panel_png_and_data(physical, tmp_path):
    sol, K = physical
    p = tmp_path / "panel.png"
    fig = plot.panel(sol, K, p, title="nebula")
    assert p.exists() and p.stat().st_size > 10_000
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    ax_f, ax_p, ax_s, ax_v = fig.axes[:4]
    ref = np.stack([np.asarray(diagnostics.m2f(r, sol.grid)) for r in sol.mass_per_bin])
    assert len(ax_f.lines) == 4
    for i, line in enumerate(ax_f.lines):
        np.testing.assert_array_equal(line.get_xdata(), sol.grid.centers)
        np.testing.assert_array_equal(line.get_ydata(), ref[i])
    # m^2 f integrates (sum over dln m) to the total mass per time
    dl = np.diff(sol.grid.log_edges)
    np.testing.assert_allclose((ax_f.lines[-1].get_ydata() * dl).sum() + float(sol.gel_mass[-1]),
                               float(np.asarray(sol.mass_per_bin[0]).sum()), rtol=1e-9)
    np.testing.assert_array_equal(ax_p.lines[0].get_ydata(),
                                  [float(diagnostics.mass_peak(r, sol.grid)) for r in sol.mass_per_bin])
    np.testing.assert_allclose(ax_s.lines[0].get_ydata(), np.asarray(K.particles(sol.grid.centers).st), rtol=1e-14)
    assert len(ax_v.collections) == 1
    dv = ax_v.collections[0].get_array()
    assert dv.shape == (sol.grid.nbins * sol.grid.nbins,) or dv.shape == (sol.grid.nbins, sol.grid.nbins)
    m = sol.grid.centers
    np.testing.assert_allclose(np.asarray(dv).reshape(len(m), len(m)),
                               np.sqrt(np.asarray(K.relative_velocity2(m[:, None], m[None, :]))).T, rtol=1e-12)


def test_panel_without_kernel(tmp_path):
    g = MassGrid.log(10 ** -0.1, 1e3, 5)
    sol = solve_binned(kernels.Constant(1.0), g, monodisperse(g, 1.0, 1.0), jnp.array([0.0, 1.0, 5.0]))
    fig = plot.panel(sol, path=tmp_path / "p.png")
    assert (tmp_path / "p.png").exists()
    assert len(fig.axes[2].lines) == 0 and len(fig.axes[3].collections) == 0
    with pytest.raises(JaxcoagInputError, match="BinnedSolution"):
        plot.panel(np.ones((2, 3)))
    with pytest.raises(JaxcoagInputError, match="does not exist"):
        plot.panel(sol, path=tmp_path / "no" / "p.png")
