"""One way to run anything: the binned and the Monte Carlo engine through the same calls.

The constant kernel K = 1 cm^3/s from a monodisperse start (m0 = 1 g, rho_d = 1 g cm^-3, so
N0 = 1 cm^-3) has the exact solution n_k(t) = N0 (tau/(1+tau))^(k-1) / (1+tau)^2, tau = K N0 t / 2
(Smoluchowski 1916), with moments M0 = N0/(1+tau) and M2 = rho_d m0 + K rho_d^2 t. Both engines run
with the identical ``jaxcoag.evolve`` call (only the engine object differs) and are compared with it
through the same diagnostics (``moments``, ``mass_per_bin(edges)``, ``mass_peak``), and their
``to_xarray`` datasets have the same coordinates and common variables.

Statistical tolerances of the Monte Carlo run (equal-mass grouping, Ns* species, Ormel & Spaans
2008): the moments of Ns* ~ equally massive species fluctuate by ~1/sqrt(Ns*) (relative); we allow
4/sqrt(Ns*) and check three seeds.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcoag as jc
from jaxcoag import analytic, kernels
from jaxcoag._dataset import COMMON_COORDS, COMMON_VARIABLES

NS = 400
T_OUT = jnp.array([0.0, 2.0, 10.0, 40.0])
EDGES = 10.0 ** (np.arange(0, 61) / 10 - 0.05)        # 10 bins/decade, centres at 10^(k/10) g
KERNEL = kernels.Constant(1.0)
START = jc.Monodisperse(m0=1.0, rho_d=1.0)


def _engines():
    return {"binned": jc.Binned(jc.MassGrid.log(10 ** -0.05, 10 ** 5.95, 10)),
            "mc": jc.MonteCarlo(grouping=jc.mc.EqualMass(), ns_target=NS, n_particles=1e20)}


@pytest.fixture(scope="module")
def runs():
    out = {}
    for name, engine in _engines().items():
        seeds = (0,) if name == "binned" else (0, 1, 2)
        # the same call for every engine (the binned engine ignores the key)
        out[name] = [jc.evolve(KERNEL, engine, START, T_OUT, key=jax.random.key(s)) for s in seeds]
    return out


def _exact_moment(p):
    return np.array([analytic.moments("constant", float(t), p) for t in T_OUT])


def test_both_engines_match_the_constant_kernel_solution(runs):
    ref0, ref2 = _exact_moment(0), _exact_moment(2)
    tau = 0.5 * np.asarray(T_OUT)
    np.testing.assert_allclose(ref0, 1.0 / (1.0 + tau), rtol=1e-12)      # independent closed forms
    np.testing.assert_allclose(ref2, 1.0 + np.asarray(T_OUT), rtol=1e-12)
    rref = analytic.mass_per_bin("constant", EDGES, float(T_OUT[-1]))
    tol_mc = 4.0 / np.sqrt(NS)
    for name, results in runs.items():
        for res in results:
            assert res.status == jc.RESULTS.successful
            np.testing.assert_array_equal(np.asarray(res.t), np.asarray(T_OUT))
            m0 = np.asarray(res.moments(0))
            m2 = np.asarray(res.moments(2))
            rho = np.asarray(res.mass_per_bin(EDGES))
            assert rho.shape == (T_OUT.shape[0], EDGES.size - 1)
            l1 = np.sum(np.abs(rho[-1] - rref)) / np.sum(rref)
            peak = float(res.mass_peak(EDGES)[-1])
            if name == "binned":
                np.testing.assert_allclose(m0, ref0, rtol=1e-6)        # number: integration tolerance
                np.testing.assert_allclose(m2, ref2, rtol=0.04)        # two-bin split at 10 bins/decade
                assert l1 < 0.1
                np.testing.assert_allclose(np.asarray(res.mass_drift), 0.0, atol=1e-13)
            else:
                np.testing.assert_allclose(m0, ref0, rtol=tol_mc)
                np.testing.assert_allclose(m2, ref2, rtol=tol_mc)
                assert l1 < 0.2
                np.testing.assert_allclose(np.asarray(res.moments(1)), 1.0, rtol=1e-12)  # const-V: exact mass
            # the mass peak of m^2 f(m) of the exact solution: m n_k m maximal at k ~ 2/ln(1+1/tau) = 40.5 g
            assert 20.0 < peak < 80.0, (name, peak)


def test_both_engines_write_the_same_dataset_layout(runs):
    ds_b = runs["binned"][0].to_xarray(edges=EDGES)
    ds_m = runs["mc"][0].to_xarray(edges=EDGES)
    for ds, engine in ((ds_b, "binned"), (ds_m, "mc")):
        assert ds.attrs["engine"] == engine
        assert set(COMMON_COORDS) <= set(ds.coords)
        assert set(COMMON_VARIABLES) <= set(ds.data_vars)
        assert ds["mass_per_bin"].dims == ("t", "m")
        assert int(ds["status"]) == 0 and ds["status"].attrs["status_name"] == "successful"
    np.testing.assert_array_equal(ds_b["m"].values, ds_m["m"].values)
    np.testing.assert_array_equal(ds_b["t"].values, ds_m["t"].values)
    np.testing.assert_allclose(ds_b["t_yr"].values, np.asarray(T_OUT) / jc.constants.yr, rtol=1e-15)
    # the binned view of both runs holds the whole mass (inside these edges) at t = 0
    for ds in (ds_b, ds_m):
        np.testing.assert_allclose(ds["mass_per_bin"].isel(t=0).sum().item() + ds["gel_mass"].isel(t=0).item(), 1.0,
                                   rtol=1e-12)


def test_continuing_a_result_equals_the_analytic_continuation():
    """``initial=<previous result>`` continues from its last output (t0 = its last time)."""
    grid = jc.MassGrid.log(10 ** -0.05, 10 ** 5.95, 10)
    engine = jc.Binned(grid)
    first = jc.evolve(KERNEL, engine, START, jnp.array([0.0, 10.0]))
    more = jc.evolve(KERNEL, engine, first, jnp.array([20.0, 40.0]))
    np.testing.assert_allclose(np.asarray(more.moments(0)), 1.0 / (1.0 + 0.5 * np.array([20.0, 40.0])), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(more.mass_drift), 0.0, atol=1e-13)


def test_the_verb_refuses_bad_calls_before_work():
    grid = jc.MassGrid.log(10 ** -0.05, 10 ** 5.95, 10)
    with pytest.raises(jc._validate.JaxcoagInputError, match="engine must be a jaxcoag engine object"):
        jc.evolve(KERNEL, "binned", START, T_OUT)
    with pytest.raises(jc._validate.JaxcoagInputError, match="precedes t0"):
        jc.evolve(KERNEL, jc.Binned(grid), START, T_OUT[1:], t0=5.0)
    with pytest.raises(jc._validate.JaxcoagInputError, match="strictly increasing"):
        jc.evolve(KERNEL, jc.Binned(grid), START, jnp.array([0.0, 2.0, 1.0]))
    with pytest.raises(jc._validate.JaxcoagInputError, match="Monodisperse"):
        jc.Monodisperse(m0=-1.0)
    with pytest.raises(jc._validate.JaxcoagInputError, match="scheme object"):
        jc.Binned(grid, scheme="twobin")
