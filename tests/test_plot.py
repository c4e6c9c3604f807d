"""jaxcoag.plot.panel: PNG written, plotted m^2 f data equal the run's numbers (result or dataset)."""

import numpy as np
import pytest
import jax.numpy as jnp

import jaxcoag
from jaxcoag import constants as C
from jaxcoag import diagnostics, io, kernels, plot, scenes
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.binned import MassGrid
from jaxcoag.physics.gas import ch4_disk


@pytest.fixture(scope="module")
def physical():
    gas = ch4_disk(3 * C.AU)
    K = scenes.nebula_ch4().kernel(gas, rho_s=3.0)
    m0 = 4 / 3 * np.pi * 3.0 * 1e-12
    g = MassGrid.log(m0 / 10 ** 0.1, m0 * 1e6, 5)
    res = jaxcoag.evolve(K, jaxcoag.Binned(g, dt0=1e4), jaxcoag.Monodisperse(m0, 1e-2 * float(gas.rho_g)),
                         jnp.array([0.0, 1e9, 3e9, 1e10]))
    return res, K


def test_panel_png_and_data(physical, tmp_path):
    res, K = physical
    p = tmp_path / "panel.png"
    fig = plot.panel(res, K, p, title="nebula")
    assert p.exists() and p.stat().st_size > 10_000
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    ax_f, ax_p, ax_s, ax_v = fig.axes[:4]
    grid = res.grid
    edges = res.bin_edges()
    rho = np.asarray(res.mass_per_bin())
    ref = np.stack([np.asarray(diagnostics.m2f(r, edges)) for r in rho])
    m_ds = res.to_xarray()["m"].values  # geometric centres sqrt(m_lo m_hi) of the grid's edges
    np.testing.assert_allclose(m_ds, grid.centers, rtol=1e-14)
    assert len(ax_f.lines) == 4
    for i, line in enumerate(ax_f.lines):
        np.testing.assert_array_equal(line.get_xdata(), m_ds)
        np.testing.assert_array_equal(line.get_ydata(), ref[i])
    # the same numbers as the result's own m^2 f (mass per unit ln m on its grid)
    np.testing.assert_allclose(ref, np.asarray(res.m2f()), rtol=1e-13)
    # m^2 f integrates (sum over dln m) to the total mass per time
    dl = np.diff(grid.log_edges)
    np.testing.assert_allclose((ax_f.lines[-1].get_ydata() * dl).sum() + float(res.gel_mass[-1]),
                               float(rho[0].sum()), rtol=1e-9)
    np.testing.assert_array_equal(ax_p.lines[0].get_ydata(), [float(diagnostics.mass_peak(r, edges)) for r in rho])
    np.testing.assert_allclose(ax_p.lines[0].get_ydata(), np.asarray(res.mass_peak()), rtol=1e-13)
    np.testing.assert_allclose(ax_s.lines[0].get_ydata(), np.asarray(K.particles(grid.centers).st), rtol=1e-14)
    assert len(ax_v.collections) == 1
    dv = ax_v.collections[0].get_array()
    assert dv.shape == (grid.nbins * grid.nbins,) or dv.shape == (grid.nbins, grid.nbins)
    m = grid.centers
    np.testing.assert_allclose(np.asarray(dv).reshape(len(m), len(m)),
                               np.sqrt(np.asarray(K.relative_velocity2(m[:, None], m[None, :]))).T, rtol=1e-12)


def test_panel_from_a_saved_dataset(physical, tmp_path):
    """A file written with the run's kernel draws the same curves, and St from its coordinate."""
    res, K = physical
    io.save_netcdf(res, tmp_path / "run.nc", kernel=K)
    ds = io.load_netcdf(tmp_path / "run.nc")
    fig_res = plot.panel(res, K)
    fig_ds = plot.panel(ds)  # no kernel: (c) from the file's St, (d) left empty
    for a, b in zip(fig_res.axes[0].lines[:4], fig_ds.axes[0].lines[:4]):
        np.testing.assert_array_equal(a.get_xdata(), b.get_xdata())
        np.testing.assert_array_equal(a.get_ydata(), b.get_ydata())
    np.testing.assert_array_equal(fig_ds.axes[1].lines[0].get_ydata(), fig_res.axes[1].lines[0].get_ydata())
    np.testing.assert_allclose(fig_ds.axes[2].lines[0].get_ydata(), np.asarray(K.particles(res.grid.centers).st),
                               rtol=1e-14)
    assert len(fig_ds.axes[3].collections) == 0
    with pytest.raises(JaxcoagInputError, match="a sweep"):
        plot.panel(ds.expand_dims(alpha=[1e-4]))
    with pytest.raises(JaxcoagInputError, match="missing"):
        plot.panel(ds.drop_vars("m_edge"))


def test_panel_without_kernel(tmp_path):
    g = MassGrid.log(10 ** -0.1, 1e3, 5)
    res = jaxcoag.evolve(kernels.Constant(1.0), jaxcoag.Binned(g), jaxcoag.Monodisperse(1.0, 1.0),
                         jnp.array([0.0, 1.0, 5.0]))
    fig = plot.panel(res, path=tmp_path / "p.png")
    assert (tmp_path / "p.png").exists()
    assert len(fig.axes[2].lines) == 0 and len(fig.axes[3].collections) == 0
    with pytest.raises(JaxcoagInputError, match="result of jaxcoag.evolve"):
        plot.panel(np.ones((2, 3)))
    with pytest.raises(JaxcoagInputError, match="does not exist"):
        plot.panel(res, path=tmp_path / "no" / "p.png")


def test_panel_of_a_monte_carlo_result():
    """An MC result is drawn on its automatic bins (10 per decade): same curves as its m2f, and
    m^2 f summed over d ln m gives the simulated mass density sum(g m) / V."""
    from jaxcoag import mc

    m = jnp.array([[1e-11, 1e-9, 1.0], [1e-10, 1e-6, 1.0]])  # [g]; the last slot is free
    w = jnp.array([[5.0, 1.0, 0.0], [2.0, 1.0, 0.0]])
    valid = jnp.array([[True, True, False], [True, True, False]])
    V = jnp.array([2.0, 2.0])  # [cm^3]
    r = mc.MCResult(t=jnp.array([0.0, 3.15576e9]), m=m, logm=jnp.log(m), psi=jnp.zeros((2, 3, 0)), w=w,
                    z=jnp.zeros((2, 3), jnp.int32), valid=valid, V=V, logV=jnp.log(V),
                    M_tot=jnp.sum(jnp.where(valid, m * w, 0.0), axis=1), n_events_snap=jnp.array([0, 3]),
                    status=jaxcoag.RESULTS.successful, flags=jnp.array(0, jnp.int32), n_events=jnp.array(3),
                    n_dup=jnp.array(0), n_merge=jnp.array(0))
    fig = plot.panel(r)
    e = r.bin_edges()
    np.testing.assert_allclose(np.diff(np.log10(e)), 0.1, rtol=1e-12)  # 10 bins per decade
    lines = fig.axes[0].lines
    assert len(lines) == 2
    for i, line in enumerate(lines):
        np.testing.assert_array_equal(line.get_xdata(), np.sqrt(e[:-1] * e[1:]))
        np.testing.assert_array_equal(line.get_ydata(), np.asarray(diagnostics.m2f(r.mass_per_bin()[i], e)))
        np.testing.assert_allclose((line.get_ydata() * np.diff(np.log(e))).sum(),
                                   float(jnp.sum(jnp.where(valid[i], m[i] * w[i], 0.0))) / 2.0, rtol=1e-13)
    # mass peak of the last snapshot: the 1e-6 g species holds 1e-6 g of the 1.2e-6 g
    assert 10 ** -6.1 < fig.axes[1].lines[0].get_ydata()[-1] < 10 ** -5.9
