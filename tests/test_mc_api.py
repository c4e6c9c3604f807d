"""Monte Carlo API: custom initial states, statistics helpers (M_L1, M_L2 of docs/design_notes.md), the runaway
stop predicate, MCResult.to_xarray and the netCDF round trip."""

import math
import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag import io
from jaxcoag import kernels as K
from jaxcoag import mc
from jaxcoag._validate import JaxcoagInputError

LN2 = math.log(2.0)


def _hand_result():
    """Two snapshots, four slots: known species (g = w 2^z)."""
    m = jnp.array([[1.0, 8.0, 3.0, 1.0], [1.0, 8.0, 20.0, 1.0]])
    w = jnp.array([[6.0, 1.0, 1.5, 0.0], [4.0, 1.0, 1.0, 0.0]])
    z = jnp.array([[2, 0, 1, 0], [2, 1, 0, 0]], jnp.int32)
    valid = jnp.array([[True, True, True, False], [True, True, True, False]])
    V = jnp.array([2.0, 2.0])
    return mc.MCResult(t=jnp.array([0.0, 1.0]), m=m, logm=jnp.log(m), psi=jnp.zeros((2, 4, 0)), w=w, z=z,
                       valid=valid, V=V, logV=jnp.log(V), M_tot=jnp.array([40.0, 52.0]),
                       n_events_snap=jnp.array([0, 7]), status=jnp.array(mc.STATUS.STOPPED, jnp.int32),
                       n_events=jnp.array(7), n_dup=jnp.array(0), n_merge=jnp.array(0), t_stop=jnp.array(0.8),
                       config=(("mode", "const_v"), ("capacity", 4), ("kernel", "Constant")))


def test_statistics_helpers():
    r = _hand_result()
    # snapshot 0: g = (24, 1, 3); snapshot 1: g = (16, 2, 1)
    np.testing.assert_allclose(np.exp(np.asarray(r.log_n_particles)), [28.0, 19.0], rtol=1e-14)
    np.testing.assert_array_equal(np.asarray(r.Ns), [3, 3])
    np.testing.assert_allclose(np.asarray(r.Ng), [8.5, 6.0])
    # particle variant: snapshot 0 largest species (m = 8) has g = 1 -> M_L2 = 3;
    # snapshot 1 largest (m = 20) has g = 1 -> M_L2 = 8 (g = 2 there, but it is the second)
    l1, l2 = r.largest_two("particle")
    np.testing.assert_allclose(np.asarray(l1), [8.0, 20.0])
    np.testing.assert_allclose(np.asarray(l2), [3.0, 8.0])
    np.testing.assert_allclose(np.asarray(r.M_L1), [8.0, 20.0])
    # species variant
    s1, s2 = r.largest_two("species")
    np.testing.assert_allclose(np.asarray(s2), [3.0, 8.0])
    # a largest species holding g >= 2 particles gives M_L2 = M_L1 (particle) but not (species)
    lm = jnp.log(jnp.array([5.0, 2.0]))
    a1, a2 = mc.largest_two(lm, jnp.array([1.0, 3.0]), jnp.array([1, 0], jnp.int32), jnp.array([True, True]))
    assert float(a1) == float(a2) == pytest.approx(math.log(5.0))
    b1, b2 = mc.largest_two(lm, jnp.array([1.0, 3.0]), jnp.array([1, 0], jnp.int32), jnp.array([True, True]), "species")
    assert float(b2) == pytest.approx(math.log(2.0))
    # log moments: M_p = Σ g m^p / V
    g0 = np.array([24.0, 1.0, 3.0])
    m0 = np.array([1.0, 8.0, 3.0])
    for p, lp in ((0, r.log_M0), (1, r.log_M1), (2, r.log_M2)):
        assert float(lp[0]) == pytest.approx(math.log(np.sum(g0 * m0 ** p) / 2.0), rel=1e-14)


def test_runaway_predicate():
    def st(m, w, z):
        m = jnp.asarray(m, float)
        return types.SimpleNamespace(logm=jnp.log(m), w=jnp.asarray(w, float), z=jnp.asarray(z, jnp.int32),
                                     valid=jnp.ones(m.shape, bool))
    run_ = mc.Runaway(1e4)
    assert bool(run_(st([1e5, 1.0], [1.0, 1e6], [0, 0])))        # ratio 1e5 >= 1e4
    assert not bool(run_(st([1e3, 1.0], [1.0, 1e6], [0, 0])))    # ratio 1e3
    assert not bool(run_(st([1e5, 1.0], [2.0, 1e6], [0, 0])))    # two runaway particles: M_L2 = M_L1
    assert bool(mc.Runaway(1e4, kind="species")(st([1e5, 1.0], [2.0, 1e6], [0, 0])))
    assert bool(run_(st([7.0, 1.0], [1.0, 0.0], [0, 0])))        # a single particle left (N = 300 clause)
    assert not bool(run_(st([7.0], [1.0], [1])))                 # one species of 2 particles: ratio 1
    with pytest.raises(JaxcoagInputError, match="ratio"):
        mc.Runaway(0.5)


def test_initial_species_forms_and_errors():
    a = mc.initial_species([1.0, 2.0], g=[10, 3])
    np.testing.assert_array_equal(np.asarray(a.w), [10.0, 3.0])
    np.testing.assert_array_equal(np.asarray(a.z), [0, 0])
    b = mc.initial_species(1.0, log_g=1000 * LN2)  # g = 2^1000 > float64 max
    assert int(b.z[0]) == 948 and float(b.w[0]) == pytest.approx(2.0 ** 52, rel=1e-12)
    c = mc.initial_species([1.0, 3.0], w=[1.5, 4.0], z=[3, 0], psi=[[1.0], [2.0]], V=7.0)
    assert c.psi.shape == (2, 1) and float(c.V) == 7.0
    for kw, msg in ((dict(g=[1.0, 0.5]), ">= 1"), (dict(w=[0.5, 1.0], z=[0, 0]), ">= 1"),
                    (dict(w=[1.0, 1.0], z=[-1, 0]), "integers"), (dict(g=[1, 1], log_g=[0, 0]), "exactly one"),
                    (dict(w=[1.0, 1.0]), "both"), (dict(g=[1, 1], psi=[[1.0]]), "shape")):
        with pytest.raises(JaxcoagInputError, match=msg):
            mc.initial_species([1.0, 2.0], **kw)
    with pytest.raises(JaxcoagInputError, match="m"):
        mc.initial_species([1.0, -2.0], g=[1, 1])
    t = jnp.array([1.0])
    key = jax.random.key(0)
    with pytest.raises(JaxcoagInputError, match="exactly one"):
        mc.run(K.Constant(1.0), t_out=t, key=key)
    with pytest.raises(JaxcoagInputError, match="exactly one"):
        mc.run(K.Constant(1.0), n_particles=5, initial=a, t_out=t, key=key)
    with pytest.raises(JaxcoagInputError, match="rho_d"):
        mc.run(K.Constant(1.0), initial=c, rho_d=2.0, t_out=t, key=key)
    with pytest.raises(JaxcoagInputError, match="key"):
        mc.run(K.Constant(1.0), n_particles=5, t_out=t)
    with pytest.raises(JaxcoagInputError, match="capacity"):
        mc.run(K.Constant(1.0), initial=mc.initial_species([1.0, 2.0, 3.0, 4.0], g=[1, 1, 1, 1]), t_out=t, key=key,
               capacity=6)
    with pytest.raises(JaxcoagInputError, match="stop"):
        mc.run(K.Constant(1.0), n_particles=5, t_out=t, key=key, stop=3.0)
    with pytest.raises(JaxcoagInputError, match="resume_from"):
        mc.run(K.Constant(1.0), n_particles=5, t_out=t, key=key, resume_from=_hand_result())


def test_run_from_custom_initial_state(tmp_path):
    """Three species with a given volume: the t = 0 snapshot is the initial state, V is the given
    one, mass is conserved; the result converts to xarray (species and binned views) and
    round-trips through netCDF."""
    init = mc.initial_species([1.0, 2.0, 5.0], g=[10, 6, 3], V=2.0)
    t = jnp.array([0.0, 0.5, 2.0, 6.0])
    r = mc.run(K.Constant(1.0), initial=init, t_out=t, key=jax.random.key(4), stop=mc.Runaway(1e4))
    M = 10 * 1.0 + 6 * 2.0 + 3 * 5.0
    np.testing.assert_array_equal(np.asarray(r.m[0, :3]), [1.0, 2.0, 5.0])
    np.testing.assert_array_equal(np.asarray(r.g[0, :3]), [10.0, 6.0, 3.0])
    np.testing.assert_allclose(np.asarray(r.V), 2.0, rtol=0)
    np.testing.assert_allclose(np.sum(np.asarray(r.g * r.m), axis=1), M, rtol=1e-13)
    np.testing.assert_allclose(np.asarray(r.M_tot), M, rtol=1e-13)
    ln_np = np.asarray(r.log_n_particles)
    assert ln_np[0] == pytest.approx(math.log(19.0)) and np.all(np.diff(ln_np) <= 0)
    # 19 particles, K = 1, V = 2: a single particle is left long after t = 6 only rarely; either way
    # the run's status is OK or STOPPED (single particle) and t_stop is consistent with it
    assert int(r.status) in (0, mc.STATUS.STOPPED)
    assert np.isnan(float(r.t_stop)) == (int(r.status) == 0)

    edges = 2.0 ** np.arange(0, 7)
    ds = r.to_xarray(attrs={"scene": "three-species box", "seed": 4}, edges=edges)
    assert ds.sizes["time"] == 4 and ds.sizes["species"] == r.m.shape[-1] and ds.sizes["mass"] == 6
    np.testing.assert_allclose(ds["mass_per_bin"].sum("mass").values, M / 2.0, rtol=1e-13)
    np.testing.assert_allclose(ds["mass_per_bin"].values, np.asarray(r.mass_per_bin(edges)), rtol=0)
    assert ds.attrs["run_mode"] == "const_v" and ds.attrs["run_kernel"] == "Constant"
    assert ds.attrs["scene"] == "three-species box" and ds.attrs["status"] in ("OK", "STOPPED")
    assert ds["m"].attrs["units"] == "g" and ds["V"].attrs["units"] == "cm3"
    path = io.save_netcdf(ds, tmp_path / "mc.nc")
    back = io.load_netcdf(path)
    for v in ("m", "log_g", "w", "z", "valid", "V", "M_tot", "n_events", "M_L1", "M_L2", "log_M2", "mass_per_bin"):
        np.testing.assert_array_equal(back[v].values, ds[v].values, err_msg=v)
    assert back.attrs["run_capacity"] == ds.attrs["run_capacity"]
    with pytest.raises(JaxcoagInputError, match="one run"):
        jax.tree_util.tree_map(lambda x: jnp.stack([x, x]), r).to_xarray()
    with pytest.raises(JaxcoagInputError, match="edges"):
        r.to_xarray(edges=[2.0, 1.0])


def test_hand_result_to_xarray():
    r = _hand_result()
    ds = r.to_xarray()
    assert ds.attrs["status"] == "STOPPED" and float(ds["t_stop"]) == 0.8
    np.testing.assert_array_equal(ds["n_species"].values, [3, 3])
    assert ds["log_g"].values[0, 3] == -np.inf
    assert ds.attrs["run_capacity"] == 4


@pytest.mark.slow
def test_const_n_initial_volume_fixes_density():
    """In const_n with a given V the controller keeps the initial mass density M_tot/V."""
    init = mc.initial_species([1.0, 4.0], g=[30, 5], V=5.0)
    r = mc.run(K.Constant(1.0), initial=init, t_out=jnp.array([0.5, 3.0]), key=jax.random.key(1), mode="const_n",
               capacity=80)
    np.testing.assert_allclose(np.asarray(r.M_tot / r.V), 50.0 / 5.0, rtol=1e-12)
    assert int(r.n_dup) > 0
