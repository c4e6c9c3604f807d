"""jaxcoag.io: labelled datasets of results, exact netCDF round trip, atomic writes."""

import os

import numpy as np
import pytest
import jax.numpy as jnp
import xarray as xr

import jaxcoag
from jaxcoag import io, kernels
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.binned import MassGrid

G = MassGrid.log(10 ** (-0.5 / 4), 1e3, 4)
YEAR_S = 365.25 * 86400.0  # Julian year [s]


@pytest.fixture(scope="module")
def res():
    return jaxcoag.evolve(kernels.Constant(1.0), jaxcoag.Binned(G), jaxcoag.Monodisperse(1.0, 1.0),
                          jnp.array([0.0, 0.5, 2.0]))


def test_to_xarray_coords_and_values(res):
    ds = res.to_xarray(attrs={"scene": "constant", "alpha": 1e-4, "rho_g": np.float64(3e-10), "flag": True})
    assert ds.sizes == {"t": 3, "m": G.nbins, "m_edge": G.nbins + 1}
    np.testing.assert_array_equal(ds["t"].values, [0.0, 0.5, 2.0])
    np.testing.assert_allclose(ds["t_yr"].values, np.array([0.0, 0.5, 2.0]) / YEAR_S, rtol=1e-15, atol=0)
    np.testing.assert_array_equal(ds["m"].values, G.centers)  # the grid's own centres, bit for bit
    np.testing.assert_allclose(ds["m"].values, np.sqrt(G.edges[:-1] * G.edges[1:]), rtol=1e-15)
    np.testing.assert_array_equal(ds["m_edge"].values, G.edges)
    np.testing.assert_array_equal(ds["mass_per_bin"].values, np.asarray(res.mass_per_bin()))
    np.testing.assert_array_equal(ds["number_per_bin"].values, np.asarray(res.number_per_bin()))
    np.testing.assert_array_equal(ds["gel_mass"].values, np.asarray(res.gel_mass))
    np.testing.assert_array_equal(ds["mass_drift"].values, np.asarray(res.mass_drift))
    assert int(ds["status"]) == 0 and ds["status"].attrs["status_name"] == "successful"
    assert ds.attrs["status"] == "successful" and ds.attrs["engine"] == "binned"
    assert ds["mass_per_bin"].attrs["units"] == "g cm-3" and ds["t"].attrs["units"] == "s"
    assert ds["m"].attrs["units"] == "g" and ds["number_per_bin"].attrs["units"] == "cm-3"
    assert ds["t_yr"].attrs["units"] == "yr"
    for v in ds.variables.values():
        assert "long_name" in v.attrs and "units" in v.attrs
    assert ds.attrs["scene"] == "constant" and ds.attrs["alpha"] == 1e-4 and ds.attrs["flag"] == 1
    # mass is conserved by the scheme to round-off, recorded in the dataset
    assert float(abs(ds["mass_drift"]).max()) < 1e-10


def test_time_and_particle_coords():
    """t_yr = t / (365.25 d); a and St from the kernel's drag law (Epstein: St = rho_s a Omega / (rho_g c_g))."""
    import math
    from jaxcoag import constants as C, scenes
    from jaxcoag.physics import gas as gasmod

    tc = io.time_coords([0.0, 3.15576e7, 6.3115200e8])
    assert set(tc) == {"t", "t_yr"} and tc["t"][0] == "t" and tc["t_yr"][0] == "t"
    np.testing.assert_array_equal(tc["t_yr"][1], [0.0, 1.0, 20.0])
    assert tc["t"][2]["units"] == "s" and tc["t_yr"][2]["units"] == "yr"
    g = gasmod.mmsn_hayashi81(1.0 * C.AU, alpha=1e-3)
    K = scenes.nebula_ch4().kernel(g, rho_s=1.6)
    m = np.array([1e-12, 1e-9, 1e-6])
    pc = io.particle_coords(K, m)
    assert pc["a"][0] == "m" and pc["St"][0] == "m" and pc["a"][2]["units"] == "cm" and pc["St"][2]["units"] == "1"
    a = (3 * m / (4 * math.pi * 1.6)) ** (1 / 3)
    np.testing.assert_allclose(pc["a"][1], a, rtol=1e-14)
    np.testing.assert_allclose(pc["St"][1], 1.6 * a / (float(g.rho_g) * float(g.c_g)) / float(g.t_L), rtol=1e-12)
    assert io.particle_coords(kernels.Constant(1.0), m) == {} and io.particle_coords(None, m) == {}
    assert io.particle_coords(K, m, dim="species")["St"][0] == "species"
    # io.grain_size_stokes (one jitted call on masses padded to GRAIN_BATCH) against the eager particles(),
    # for any shape, also longer than one batch
    rng = np.random.default_rng(5)
    for shape in ((), (3,), (2, 3), (io.GRAIN_BATCH + 1,)):
        mm = np.exp(rng.uniform(np.log(1e-12), np.log(1e8), shape))
        ga, gst = io.grain_size_stokes(K, mm)
        p = K.particles(jnp.asarray(mm))
        assert ga.shape == gst.shape == np.shape(mm) and isinstance(ga, np.ndarray) and ga.dtype == np.float64
        np.testing.assert_allclose(ga, np.asarray(p.a), rtol=1e-14)
        np.testing.assert_allclose(gst, np.asarray(p.st), rtol=1e-13)


def test_result_table_is_the_shared_status():
    table = io.result_table()
    assert [table[c][0] for c in sorted(table)] == list(jaxcoag.RESULT_NAMES)
    assert table[0] == ("successful", "")
    assert table[jaxcoag.RESULT_NAMES.index("capacity_exceeded")][0] == "capacity_exceeded"


def test_round_trip_exact(res, tmp_path):
    p = tmp_path / "run.nc"
    ds = res.to_xarray(attrs={"scene": "constant", "alpha": 1e-4, "vec": np.array([1.0, 2.0])})
    assert io.save_netcdf(ds, p) == str(p)
    back = io.load_netcdf(p)
    xr.testing.assert_identical(back, ds)
    for k in ("mass_per_bin", "number_per_bin", "gel_mass", "mass_drift", "t", "t_yr", "m", "m_edge"):
        np.testing.assert_array_equal(back[k].values, ds[k].values)
    # results can be saved directly
    p2 = tmp_path / "run2.nc"
    io.save_netcdf(res, p2, attrs={"scene": "constant"})
    xr.testing.assert_identical(io.load_netcdf(p2), res.to_xarray(attrs={"scene": "constant"}))
    # with other edges: the dataset of to_xarray(edges=...)
    p3 = tmp_path / "run3.nc"
    e = G.edges[::2]
    io.save_netcdf(res, p3, edges=e)
    xr.testing.assert_identical(io.load_netcdf(p3), res.to_xarray(edges=e))
    assert sorted(os.listdir(tmp_path)) == ["run.nc", "run2.nc", "run3.nc"]


def test_atomic_write_failure_leaves_previous_file(res, tmp_path, monkeypatch):
    p = tmp_path / "run.nc"
    io.save_netcdf(res, p, attrs={"version": 1})
    before = p.read_bytes()

    def broken(self, path, *a, **k):
        with open(path, "wb") as fh:  # a partial write, then the disk "fails"
            fh.write(b"CDF\x01 partial")
        raise OSError("simulated failure mid write")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", broken)
    with pytest.raises(OSError, match="simulated"):
        io.save_netcdf(res, p, attrs={"version": 2})
    assert p.read_bytes() == before
    assert os.listdir(tmp_path) == ["run.nc"]
    # to a new target: nothing at all is left behind
    with pytest.raises(OSError):
        io.save_netcdf(res, tmp_path / "new.nc")
    assert os.listdir(tmp_path) == ["run.nc"]
    monkeypatch.undo()
    assert io.load_netcdf(p).attrs["version"] == 1


def test_bad_input(res, tmp_path):
    with pytest.raises(JaxcoagInputError, match=r"xarray.Dataset or a result with .to_xarray\(\)"):
        io.save_netcdf(np.zeros(3), tmp_path / "x.nc")
    with pytest.raises(JaxcoagInputError, match="attrs"):
        res.to_xarray(attrs=[1, 2])
    with pytest.raises(JaxcoagInputError, match=r"save_netcdf\(kernel=...\) is only for saving a result"):
        io.save_netcdf(res.to_xarray(), tmp_path / "x.nc", kernel=kernels.Constant(1.0))
    with pytest.raises(JaxcoagInputError, match="does not exist"):
        io.save_netcdf(res, tmp_path / "nope" / "x.nc")
    with pytest.raises(JaxcoagInputError, match="is a directory"):
        io.save_netcdf(res, tmp_path)
    with pytest.raises(FileNotFoundError):
        io.load_netcdf(tmp_path / "missing.nc")
    assert os.listdir(tmp_path) == []


def test_failed_solution_records_result(tmp_path):
    bad = jaxcoag.evolve(kernels.Constant(1.0), jaxcoag.Binned(G, max_steps=2), jaxcoag.Monodisperse(1.0, 1.0),
                         jnp.array([0.0, 50.0]), throw=False)
    ds = bad.to_xarray()
    assert ds["status"].attrs["status_name"] == "max_steps_reached"
    assert int(ds["status"]) == jaxcoag.RESULT_NAMES.index("max_steps_reached")
    assert "max_steps" in ds["status"].attrs["status_message"] and ds.attrs["status"] == "max_steps_reached"
