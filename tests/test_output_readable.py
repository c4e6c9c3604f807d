"""Output a person can read: netCDF coordinates t [s], t_yr [yr], a [cm], St with units and the
values of independent formulas; the run figure's time colour bar and fragmentation-limit line;
`jaxcoag --version`; `jaxcoag sweep` progress and figure; example 05's default output directory is
git-ignored (that it writes only there is checked on its quick run in tests/test_examples.py).

References: Ormel (2008) thesis eqs. 2.4 and 4.5 (Epstein friction time tau = rho_s a / (rho_g c_g)
for compact spheres), ch. 4 footnote 5 (St = tau_f / t_L); Birnstiel et al. (2012) eq. 8
(St_frag = v_frag^2 / (3 alpha c_s^2)).
"""

import importlib.metadata
import math
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
import jax.numpy as jnp
from matplotlib import colors

from _configs import SMALL
from _scripts import ROOT, load_script
import jaxcoag
from jaxcoag import cli, config, io, kernels, plot, runner
from jaxcoag.binned import MassGrid
from jaxcoag.physics import drag
from jaxcoag.physics import gas as gasmod

YEAR_S = 365.25 * 86400.0  # Julian year [s]

# 1 AU MMSN, alpha = 1e-3, 1 um grains (rho_s = 1.6); v_frag = 5 cm/s puts the fragmentation
# barrier St_frag = 25 / (3e-3 c_g^2) ~ 8.4e-7 inside this small grid (monomer St ~ 2.4e-7)
FRAG = SMALL.replace('name = "small_growth"', 'name = "readable"') + """
[fragmentation]
model = "shattering"
v_frag = 5.0
"""


@pytest.fixture(scope="module")
def frag_run(tmp_path_factory):
    """The run of FRAG with the Figure that runner.run drew (captured from plot.panel)."""
    d = tmp_path_factory.mktemp("readable")
    figs = []
    orig = plot.panel

    def capture(*a, **kw):
        figs.append(orig(*a, **kw))
        return figs[-1]

    mp = pytest.MonkeyPatch()
    mp.setattr(plot, "panel", capture)
    try:
        res = runner.run(config.loads(FRAG), out=str(d / "run.nc"), progress=False, verbose=False, checkpoint=False)
    finally:
        mp.undo()
    assert len(figs) == 1
    return res, io.load_netcdf(d / "run.nc"), figs[0]


def _gas():
    return gasmod.mmsn_hayashi81(1.0 * 1.495978707e13, alpha=1e-3)


def test_netcdf_time_size_stokes_coordinates(frag_run):
    res, ds, _ = frag_run
    for name, unit in (("t", "s"), ("t_yr", "yr"), ("m", "g"), ("m_edge", "g"), ("a", "cm"), ("St", "1")):
        assert name in ds.coords and ds[name].attrs["units"] == unit, name
    for name in ("t_yr", "a", "St"):
        assert ds[name].dims == (("t",) if name == "t_yr" else ("m",)), name
    t = ds["t"].values
    np.testing.assert_array_equal(t, np.asarray(res.result.t))
    np.testing.assert_allclose(ds["t_yr"].values, t / YEAR_S, rtol=1e-15, atol=0)
    assert ds["t_yr"].values[-1] == pytest.approx(10.0, rel=1e-14)  # t_end_yr = 10
    m = ds["m"].values
    rho_s = 1.6
    np.testing.assert_allclose(ds["a"].values, (3 * m / (4 * math.pi * rho_s)) ** (1 / 3), rtol=1e-14)
    g = _gas()
    st_ref = np.asarray(drag.stokes_number(drag.friction_time_compact(jnp.asarray(m), rho_s, g), g))
    np.testing.assert_allclose(ds["St"].values, st_ref, rtol=1e-13)
    # the grains are far below the mean free path (~1e2 cm): Epstein, tau = rho_s a / (rho_g c_g)
    a = ds["a"].values
    tau_ep = rho_s * a / (float(g.rho_g) * float(g.c_g))
    np.testing.assert_allclose(ds["St"].values, tau_ep / float(g.t_L), rtol=1e-12)


def test_netcdf_fragmentation_barrier_attrs(frag_run):
    _, ds, _ = frag_run
    g = _gas()
    st_frag = 5.0 ** 2 / (3 * 1e-3 * float(g.c_g) ** 2)
    assert ds.attrs["st_frag"] == pytest.approx(st_frag, rel=1e-13)
    m_fr, a_fr = ds.attrs["m_frag_limit_g"], ds.attrs["a_frag_limit_cm"]
    assert a_fr == pytest.approx((3 * m_fr / (4 * math.pi * 1.6)) ** (1 / 3), rel=1e-13)
    # Epstein inversion by hand: St = rho_s a Omega_L / (rho_g c_g) = St_frag
    a_hand = st_frag * float(g.t_L) * float(g.rho_g) * float(g.c_g) / 1.6
    assert a_fr == pytest.approx(a_hand, rel=1e-9)


def test_run_figure_time_colorbar_and_frag_line(frag_run):
    res, ds, fig = frag_run
    ax_f = fig.axes[0]
    nt = ds.sizes["t"]
    # the time colour bar: a colour-bar axes with a log norm over the positive t_yr
    cbars = [a for a in fig.axes[4:] if "t [yr]" in a.get_ylabel()]
    assert len(cbars) == 1
    cb = cbars[0]._colorbar
    assert isinstance(cb.norm, colors.LogNorm)
    ty = ds["t_yr"].values
    assert cb.norm.vmin == pytest.approx(ty[ty > 0].min(), rel=1e-14)
    assert cb.norm.vmax == pytest.approx(ty[-1], rel=1e-14)
    # each m^2 f curve has the colour of its time on that bar
    for i in range(1, nt):
        np.testing.assert_allclose(colors.to_rgba(ax_f.lines[i].get_color()), cb.cmap(cb.norm(ty[i])), atol=1e-12)
    # the fragmentation-limit line at the barrier's mass, labelled with its size
    frag = [ln for ln in ax_f.lines if ln.get_gid() == "frag_limit"]
    assert len(frag) == 1
    x = frag[0].get_xdata()
    assert x[0] == x[1] == pytest.approx(ds.attrs["m_frag_limit_g"], rel=0)
    assert f"a = {ds.attrs['a_frag_limit_cm']:.3g} cm" in frag[0].get_label()
    # independent check of the position: St(m_line) from the drag law equals v_frag^2/(3 alpha c_s^2)
    g = _gas()
    st_line = float(drag.stokes_number(drag.friction_time_compact(jnp.asarray(x[0]), 1.6, g), g))
    assert st_line == pytest.approx(5.0 ** 2 / (3 * 1e-3 * float(g.c_g) ** 2), rel=1e-9)
    assert os.path.getsize(res.figure) > 10_000


def test_frag_limited_size_stokes_regime():
    """In the Stokes regime (a > 9/4 l_mfp) St ~ a^2: the inversion follows the drag law there too."""
    g = gasmod.mmsn_hayashi81(0.3 * 1.495978707e13, alpha=1e-3)  # dense gas: small mean free path
    from jaxcoag import scenes
    K = scenes.nebula_ch4().kernel(g, rho_s=1.6)
    a_switch = 9 / 4 * float(g.l_mfp)
    st_target = float(K.particles(4 / 3 * math.pi * 1.6 * (3 * a_switch) ** 3).st)
    m, a = runner.frag_limited_size(K, st_target)
    assert a == pytest.approx(3 * a_switch, rel=1e-9)
    assert all(math.isnan(v) for v in runner.frag_limited_size(kernels.Constant(1.0), 1e-2))


def test_analytic_kernel_dataset_has_no_size_or_stokes():
    g = MassGrid.log(10 ** -0.1, 1e3, 5)
    res = jaxcoag.evolve(kernels.Constant(1.0), jaxcoag.Binned(g), jaxcoag.Monodisperse(1.0, 1.0),
                         jnp.array([0.0, 1.0, 5.0]))
    ds = res.to_xarray(kernel=kernels.Constant(1.0))
    assert "a" not in ds.variables and "St" not in ds.variables
    np.testing.assert_allclose(ds["t_yr"].values, np.array([0.0, 1.0, 5.0]) / YEAR_S, rtol=1e-15)
    assert ds["t_yr"].attrs["units"] == "yr"
    fig = plot.panel(res)
    cb = [a for a in fig.axes[4:] if a.get_ylabel().startswith("t [s]")]
    assert len(cb) == 1 and not isinstance(cb[0]._colorbar.norm, colors.LogNorm)  # 1..5 s: under a decade


def _mc_result(psi):
    """Two snapshots, three slots (the last one free) of silicate grains [g], structure psi."""
    from jaxcoag import mc

    m = jnp.array([[1e-11, 1e-9, 1.0], [1e-10, 1e-6, 1.0]])
    w = jnp.array([[5.0, 1.0, 0.0], [2.0, 1.0, 0.0]])
    valid = jnp.array([[True, True, False], [True, True, False]])
    V = jnp.array([1.0, 1.0])
    return mc.MCResult(t=jnp.array([0.0, 3.15576e9]), m=m, logm=jnp.log(m), psi=psi, w=w,
                       z=jnp.zeros((2, 3), jnp.int32), valid=valid, V=V, logV=jnp.log(V),
                       M_tot=jnp.sum(jnp.where(valid, m * w, 0.0), axis=1), n_events_snap=jnp.array([0, 3]),
                       status=jaxcoag.RESULTS.successful, flags=jnp.array(0, jnp.int32), n_events=jnp.array(3),
                       n_dup=jnp.array(0), n_merge=jnp.array(0), config=(("mode", "const_v"),))


def test_mc_dataset_t_yr_and_stokes_with_a_physical_kernel():
    import dataclasses
    from jaxcoag import scenes

    g = _gas()
    K = scenes.nebula_ch4().kernel(g, rho_s=1.6)
    r = _mc_result(jnp.zeros((2, 3, 0)))
    ds = r.to_xarray()
    for name in ("a", "St", "a_species", "St_species"):  # no kernel given: nothing invented
        assert name not in ds.variables
    assert "a" not in r.to_xarray(kernel=kernels.Constant(1.0)).variables  # analytic kernel: no rho_s, no gas
    assert "a_species" not in r.to_xarray(kernel=kernels.Constant(1.0)).variables
    np.testing.assert_allclose(ds["t_yr"].values, [0.0, 100.0], rtol=1e-15)
    assert ds["t_yr"].attrs["units"] == "yr" and ds["t"].attrs["units"] == "s"
    ds = r.to_xarray(kernel=K, edges=[1e-12, 1e-8, 1e-4])
    valid = ds["valid"].values.astype(bool)
    m = ds["m_species"].values[valid]
    np.testing.assert_allclose(ds["a_species"].values[valid], (3 * m / (4 * math.pi * 1.6)) ** (1 / 3), rtol=1e-14)
    st_ref = np.asarray(drag.stokes_number(drag.friction_time_compact(jnp.asarray(m), 1.6, g), g))
    np.testing.assert_allclose(ds["St_species"].values[valid], st_ref, rtol=1e-13)
    assert np.all(np.isnan(ds["St_species"].values[~valid])) and np.all(np.isnan(ds["a_species"].values[~valid]))
    assert ds["a_species"].attrs["units"] == "cm" and ds["St_species"].attrs["units"] == "1"
    # the bin centres carry a and St on m, as in a binned run's dataset
    mb = np.sqrt(np.array([1e-12 * 1e-8, 1e-8 * 1e-4]))
    assert ds["a"].dims == ("m",) and ds["St"].dims == ("m",)
    np.testing.assert_allclose(ds["m"].values, mb, rtol=1e-15)
    np.testing.assert_allclose(ds["a"].values, (3 * mb / (4 * math.pi * 1.6)) ** (1 / 3), rtol=1e-14)
    np.testing.assert_allclose(ds["St"].values, np.asarray(drag.stokes_number(
        drag.friction_time_compact(jnp.asarray(mb), 1.6, g), g)), rtol=1e-13)
    # porous grains (enlargement factor psi = 8): a = a* psi^(1/3), Epstein tau = rho_s a* / (rho_g c_g psi^(2/3))
    Kp = dataclasses.replace(scenes.nebula_ch4(), porosity="psi").kernel(g, rho_s=1.6)
    dp = _mc_result(jnp.full((2, 3, 1), 8.0)).to_xarray(kernel=Kp)
    a_star = (3 * m / (4 * math.pi * 1.6)) ** (1 / 3)
    np.testing.assert_allclose(dp["a_species"].values[valid], 2.0 * a_star, rtol=1e-14)
    st_ep = 1.6 * a_star / (float(g.rho_g) * float(g.c_g) * 4.0) / float(g.t_L)
    np.testing.assert_allclose(dp["St_species"].values[valid], st_ep, rtol=1e-12)
    assert "St" not in dp.variables  # a bin-centre mass alone does not fix a porous grain's size


def test_version_flag_prints_the_installed_version():
    want = importlib.metadata.version("jaxcoag")
    p = subprocess.run([sys.executable, "-m", "jaxcoag.cli", "--version"], capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == f"jaxcoag {want}"
    exe = shutil.which("jaxcoag", path=os.path.dirname(sys.executable))
    if exe is not None:  # the console script of the installed package
        q = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=120)
        assert q.returncode == 0 and q.stdout.strip() == f"jaxcoag {want}"


def test_sweep_shows_progress_and_writes_the_figure(tmp_path, capsys):
    cfg = tmp_path / "small.toml"
    cfg.write_text(SMALL)
    out = tmp_path / "res" / "sw.nc"
    assert cli.main(["sweep", str(cfg), "--param", "alpha=1e-4,1e-3", "--out", str(out)]) == 0
    cap = capsys.readouterr()
    assert "2/2" in cap.err and "member" in cap.err  # tqdm bar over the members on stderr
    png = tmp_path / "res" / "sw.png"
    assert png.exists() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and str(png) in cap.out
    ds = io.load_netcdf(out)
    assert ds.attrs["figure"] == str(png)
    np.testing.assert_allclose(ds["t_yr"].values, ds["t"].values / YEAR_S, rtol=1e-15)
    # St per member from its own gas state
    for i, alpha in enumerate((1e-4, 1e-3)):
        g = gasmod.mmsn_hayashi81(1.495978707e13, alpha=alpha)
        m = ds["m"].values
        ref = np.asarray(drag.stokes_number(drag.friction_time_compact(jnp.asarray(m), 1.6, g), g))
        np.testing.assert_allclose(ds["St"].values[i], ref, rtol=1e-13)
    # the figure shows the swept quantity: mass peak against alpha
    fig = plot.sweep_panel(ds)
    np.testing.assert_array_equal(fig.axes[0].lines[0].get_xdata(), [1e-4, 1e-3])
    np.testing.assert_array_equal(fig.axes[0].lines[0].get_ydata(), ds["mass_peak"].values)
    assert fig.axes[0].get_xscale() == "log" and any(a.get_ylabel() == "alpha" for a in fig.axes[2:])
    assert cli.main(["sweep", str(cfg), "--param", "alpha=1e-3", "--out", str(tmp_path / "q.nc"), "--no-figure",
                     "--no-progress"]) == 0
    cap = capsys.readouterr()
    assert "member" not in cap.err and not (tmp_path / "q.png").exists()


def test_example_05_default_output_directory_is_git_ignored():
    # that a run of example 05 writes only into its --out directory (not the working directory, not
    # examples/) is asserted on the quick run of tests/test_examples.py::test_example_quick[05_cli_run]
    # (the example ran twice in the default suite before, ~21 s each on 2 cores)
    # the default output directory is next to the script and git-ignored
    mod = load_script(ROOT / "examples" / "05_cli_run.py", "_readable2_")
    assert mod.DEFAULT_OUT == ROOT / "examples" / "out" / "05_cli_run"
    if shutil.which("git") and (ROOT / ".git").exists():
        p = subprocess.run(["git", "-C", str(ROOT), "check-ignore", "-q", str(mod.DEFAULT_OUT / "x.nc")])
        assert p.returncode == 0
