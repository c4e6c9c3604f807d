"""jaxcoag.io: labelled datasets, exact netCDF round trip, atomic writes."""

import os

import numpy as np
import pytest
import jax.numpy as jnp
import xarray as xr

from jaxcoag import io, kernels
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.binned import MassGrid, monodisperse, solve_binned

G = MassGrid.log(10 ** (-0.5 / 4), 1e3, 4)


@pytest.fixture(scope="module")
def sol():
    return solve_binned(kernels.Constant(1.0), G, monodisperse(G, 1.0, 1.0), jnp.array([0.0, 0.5, 2.0]))


def test_to_xarray_coords_and_values(sol):
    ds = io.to_xarray(sol, attrs={"scene": "constant", "alpha": 1e-4, "rho_g": np.float64(3e-10), "flag": True})
    assert ds.sizes == {"time": 3, "mass": G.nbins, "mass_edge": G.nbins + 1}
    np.testing.assert_array_equal(ds["time"].values, [0.0, 0.5, 2.0])
    np.testing.assert_array_equal(ds["mass"].values, G.centers)
    np.testing.assert_array_equal(ds["mass_edge"].values, G.edges)
    np.testing.assert_array_equal(ds["mass_per_bin"].values, np.asarray(sol.mass_per_bin))
    np.testing.assert_array_equal(ds["number_per_bin"].values, np.asarray(sol.number_per_bin))
    np.testing.assert_array_equal(ds["gel_mass"].values, np.asarray(sol.gel_mass))
    np.testing.assert_array_equal(ds["mass_drift"].values, np.asarray(sol.mass_drift))
    assert int(ds["result_code"]) == 0 and ds["result_code"].attrs["result_name"] == "successful"
    assert ds.attrs["result"] == "successful"
    assert ds["mass_per_bin"].attrs["units"] == "g cm-3" and ds["time"].attrs["units"] == "s"
    assert ds["mass"].attrs["units"] == "g" and ds["number_per_bin"].attrs["units"] == "cm-3"
    for v in ds.variables.values():
        assert "long_name" in v.attrs and "units" in v.attrs
    assert ds.attrs["scene"] == "constant" and ds.attrs["alpha"] == 1e-4 and ds.attrs["flag"] == 1
    # mass is conserved by the scheme to round-off, recorded in the dataset
    assert float(abs(ds["mass_drift"]).max()) < 1e-10


def test_round_trip_exact(sol, tmp_path):
    p = tmp_path / "run.nc"
    ds = io.to_xarray(sol, attrs={"scene": "constant", "alpha": 1e-4, "vec": np.array([1.0, 2.0])})
    assert io.save_netcdf(ds, p) == str(p)
    back = io.load_netcdf(p)
    xr.testing.assert_identical(back, ds)
    for k in ("mass_per_bin", "number_per_bin", "gel_mass", "mass_drift", "time", "mass", "mass_edge"):
        np.testing.assert_array_equal(back[k].values, ds[k].values)
    # solutions can be saved directly
    p2 = tmp_path / "run2.nc"
    io.save_netcdf(sol, p2, attrs={"scene": "constant"})
    xr.testing.assert_identical(io.load_netcdf(p2), io.to_xarray(sol, attrs={"scene": "constant"}))
    assert sorted(os.listdir(tmp_path)) == ["run.nc", "run2.nc"]


def test_atomic_write_failure_leaves_previous_file(sol, tmp_path, monkeypatch):
    p = tmp_path / "run.nc"
    io.save_netcdf(sol, p, attrs={"version": 1})
    before = p.read_bytes()

    def broken(self, path, *a, **k):
        with open(path, "wb") as fh:  # a partial write, then the disk "fails"
            fh.write(b"CDF\x01 partial")
        raise OSError("simulated failure mid write")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", broken)
    with pytest.raises(OSError, match="simulated"):
        io.save_netcdf(sol, p, attrs={"version": 2})
    assert p.read_bytes() == before
    assert os.listdir(tmp_path) == ["run.nc"]
    # to a new target: nothing at all is left behind
    with pytest.raises(OSError):
        io.save_netcdf(sol, tmp_path / "new.nc")
    assert os.listdir(tmp_path) == ["run.nc"]
    monkeypatch.undo()
    assert io.load_netcdf(p).attrs["version"] == 1


def test_bad_input(sol, tmp_path):
    with pytest.raises(JaxcoagInputError, match="BinnedSolution"):
        io.to_xarray(np.zeros(3))
    with pytest.raises(JaxcoagInputError, match="attrs"):
        io.to_xarray(sol, attrs=[1, 2])
    with pytest.raises(JaxcoagInputError, match="does not exist"):
        io.save_netcdf(sol, tmp_path / "nope" / "x.nc")
    with pytest.raises(FileNotFoundError):
        io.load_netcdf(tmp_path / "missing.nc")


def test_failed_solution_records_result(tmp_path):
    bad = solve_binned(kernels.Constant(1.0), G, monodisperse(G, 1.0, 1.0), jnp.array([0.0, 50.0]),
                       max_steps=2, throw=False)
    ds = io.to_xarray(bad)
    assert ds["result_code"].attrs["result_name"] == "max_steps_reached"
    assert int(ds["result_code"]) != 0 and "max_steps" in ds["result_code"].attrs["result_message"]
