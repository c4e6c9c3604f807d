"""Monte Carlo API: the MonteCarlo engine object under jaxcoag.evolve (validation, t0, continuation), custom
initial states, statistics helpers (M_L1, M_L2 of docs/design_notes.md), the runaway stop predicate, the
flags -> RESULTS mapping, MCResult.to_xarray in the common layout of every engine and the netCDF round trip."""

import math
import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcoag as jc
from jaxcoag import io
from jaxcoag import kernels as K
from jaxcoag import mc
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.mc.state import STATUS, flags_to_code

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
                       n_events_snap=jnp.array([0, 7]), status=jc.RESULTS.stopped,
                       flags=jnp.array(STATUS.STOPPED, jnp.int32),
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
    with pytest.raises(JaxcoagInputError, match="V= .* or rho_d="):
        mc.initial_species([1.0, 2.0], g=[1, 1], V=2.0, rho_d=1.0)


def test_engine_validation_before_any_work():
    """Every refusal comes from MonteCarlo(...) or evolve's check, with a message naming what to change."""
    t = jnp.array([1.0])
    key = jax.random.key(0)
    kc = K.Constant(1.0)
    mono = jc.Monodisperse(1.0)
    a = mc.initial_species([1.0, 2.0], g=[10, 3])
    with pytest.raises(JaxcoagInputError, match="n_particles"):
        jc.evolve(kc, mc.MonteCarlo(), mono, t, key=key)
    with pytest.raises(JaxcoagInputError, match="drop n_particles"):
        jc.evolve(kc, mc.MonteCarlo(n_particles=5), a, t, key=key)
    with pytest.raises(JaxcoagInputError, match="key"):
        jc.evolve(kc, mc.MonteCarlo(n_particles=5), mono, t)
    with pytest.raises(JaxcoagInputError, match="key"):
        jc.evolve(kc, mc.MonteCarlo(n_particles=5), mono, t, key=3)
    with pytest.raises(JaxcoagInputError, match="capacity"):
        jc.evolve(kc, mc.MonteCarlo(capacity=6), mc.initial_species([1.0, 2.0, 3.0, 4.0], g=[1, 1, 1, 1]), t, key=key)
    with pytest.raises(JaxcoagInputError, match="stop"):
        mc.MonteCarlo(stop=3.0)
    with pytest.raises(JaxcoagInputError, match="initial"):
        jc.evolve(kc, mc.MonteCarlo(n_particles=5), _hand_result(), t, key=key)  # no final_state
    with pytest.raises(JaxcoagInputError, match="initial"):
        jc.evolve(kc, mc.MonteCarlo(n_particles=5), 3.0, t, key=key)
    with pytest.raises(JaxcoagInputError, match="grouping"):
        mc.MonteCarlo(grouping="equal_mass")
    with pytest.raises(JaxcoagInputError, match="volume"):
        mc.MonteCarlo(volume="const_n")
    with pytest.raises(JaxcoagInputError, match="rates"):
        mc.MonteCarlo(rates="full")
    with pytest.raises(JaxcoagInputError, match="leftover"):
        mc.MonteCarlo(leftover="random")
    with pytest.raises(JaxcoagInputError, match="n_bins"):
        mc.Distribution(n_bins=0)
    with pytest.raises(JaxcoagInputError, match="count_groups"):
        mc.Distribution(count_groups=0.5)
    with pytest.raises(JaxcoagInputError, match="controller"):
        mc.ConstantSpecies(controller="mass")
    with pytest.raises(JaxcoagInputError, match="capacity >= 72"):  # equal-mass Ns* = 64 needs S >= 72
        jc.evolve(kc, mc.MonteCarlo(n_particles=1e10, grouping=mc.EqualMass(), ns_target=64, capacity=70), mono, t,
                  key=key)
    with pytest.raises(JaxcoagInputError, match="t0"):
        jc.evolve(kc, mc.MonteCarlo(n_particles=5), mono, t, key=key, t0=2.0)
    with pytest.raises(JaxcoagInputError, match="outcome"):
        jc.evolve(kc, mc.MonteCarlo(n_particles=5), mono, t, key=key, outcome="sticking")


def test_flags_to_results_priority():
    """Raw flags map to one RESULTS item: nonfinite > max_steps_reached > capacity_exceeded > stopped > zero_rate."""
    names = jc.RESULT_NAMES
    cases = {0: "successful", STATUS.ZERO_RATE: "zero_rate", STATUS.STOPPED | STATUS.ZERO_RATE: "stopped",
             STATUS.CAPACITY | STATUS.STOPPED: "capacity_exceeded", STATUS.MAX_EVENTS | STATUS.CAPACITY: "max_steps_reached",
             STATUS.NONFINITE | STATUS.MAX_EVENTS | STATUS.CAPACITY: "nonfinite", 31: "nonfinite"}
    codes = np.asarray(flags_to_code(jnp.array(list(cases), jnp.int32)))
    assert [names[c] for c in codes] == list(cases.values())


def test_t0_shifts_the_start_and_continuation_is_bitwise():
    """The initial condition sits at t0 (no event before it); a run continued from its result equals one
    uninterrupted run bitwise (event keys from the base key and the event counter)."""
    kc = K.Constant(1.0)
    eng = mc.MonteCarlo(n_particles=19, capacity=27, stop=mc.Runaway(1e4))
    mono = jc.Monodisperse(1.0)
    key = jax.random.key(21)
    # 4 output times, capacity 27 and the Runaway stop as in test_run_from_custom_initial_state: every run of
    # this test (and of the common-layout test) reuses that compilation
    full = jc.evolve(kc, eng, mono, jnp.array([10.25, 10.5, 11.0, 12.0]), key=key, t0=10.0)
    first = jc.evolve(kc, eng, mono, jnp.array([10.0, 10.1, 10.25, 10.5]), key=key, t0=10.0)
    assert int(first.n_events_snap[0]) == 0 and float(np.sum(np.asarray(first.g[0]))) == 19.0  # nothing happened at t0
    # the same key from t0 = 0: the event sequence is the same, shifted by t0 (constant kernel, V fixed)
    base = jc.evolve(kc, eng, mono, jnp.array([0.25, 0.5, 1.0, 2.0]), key=key)
    np.testing.assert_array_equal(np.asarray(full.n_events_snap), np.asarray(base.n_events_snap))
    assert float(full.final_state.t) == pytest.approx(float(base.final_state.t) + 10.0, rel=1e-12)
    second = jc.evolve(kc, eng, first, jnp.array([10.75, 11.0, 11.5, 12.0]))
    assert float(first.t[-1]) == 10.5 and int(full.n_events) > int(first.n_events) > 0
    for f in ("m", "w", "z", "valid", "n_events_snap"):
        x, y, z = (np.asarray(getattr(r, f)) for r in (full, first, second))
        np.testing.assert_array_equal(y[2:], x[:2], err_msg=f)
        np.testing.assert_array_equal(z[[1, 3]], x[2:], err_msg=f)
    assert int(second.n_events) == int(full.n_events) and second.status == full.status
    t_all = jnp.array([10.0, 10.5, 11.0, 12.0])
    with pytest.raises(JaxcoagInputError, match="key differs"):
        jc.evolve(kc, eng, first, t_all[2:], key=jax.random.key(22))
    with pytest.raises(JaxcoagInputError, match="precedes"):
        jc.evolve(kc, eng, first, t_all[:2] + 0.25)  # 10.25 < 10.5, the continued run's last output
    with pytest.raises(JaxcoagInputError, match="capacity 27"):
        jc.evolve(kc, mc.MonteCarlo(n_particles=19, capacity=50), first, t_all[2:])


def test_run_from_custom_initial_state(tmp_path):
    """Three species with a given volume: the t = 0 snapshot is the initial state, V is the given
    one, mass is conserved; the result converts to xarray (species and binned views) and
    round-trips through netCDF."""
    init = mc.initial_species([1.0, 2.0, 5.0], g=[10, 6, 3], V=2.0)
    t = jnp.array([0.0, 0.5, 2.0, 6.0])
    r = jc.evolve(K.Constant(1.0), mc.MonteCarlo(stop=mc.Runaway(1e4)), init, t, key=jax.random.key(4))
    M = 10 * 1.0 + 6 * 2.0 + 3 * 5.0
    np.testing.assert_array_equal(np.asarray(r.m[0, :3]), [1.0, 2.0, 5.0])
    np.testing.assert_array_equal(np.asarray(r.g[0, :3]), [10.0, 6.0, 3.0])
    np.testing.assert_allclose(np.asarray(r.V), 2.0, rtol=0)
    np.testing.assert_allclose(np.sum(np.asarray(r.g * r.m), axis=1), M, rtol=1e-13)
    np.testing.assert_allclose(np.asarray(r.M_tot), M, rtol=1e-13)
    ln_np = np.asarray(r.log_n_particles)
    assert ln_np[0] == pytest.approx(math.log(19.0)) and np.all(np.diff(ln_np) <= 0)
    # 19 particles, K = 1, V = 2: a single particle is left long after t = 6 only rarely; either way
    # the run's status is successful or stopped (single particle) and t_stop is consistent with it
    assert r.status in (jc.RESULTS.successful, jc.RESULTS.stopped)
    assert np.isnan(float(r.t_stop)) == (r.status == jc.RESULTS.successful)

    edges = 2.0 ** np.arange(0, 7)
    ds = r.to_xarray(attrs={"scene": "three-species box", "seed": 4}, edges=edges)
    assert ds.sizes["t"] == 4 and ds.sizes["species"] == r.m.shape[-1] and ds.sizes["m"] == 6
    np.testing.assert_allclose(ds["mass_per_bin"].sum("m").values, M / 2.0, rtol=1e-13)
    np.testing.assert_allclose(ds["mass_per_bin"].values, np.asarray(r.mass_per_bin(edges)), rtol=0)
    np.testing.assert_allclose(ds["m"].values, np.sqrt(edges[:-1] * edges[1:]), rtol=1e-15)
    np.testing.assert_array_equal(ds["gel_mass"].values, 0.0)  # every species below 64 g
    np.testing.assert_allclose(ds["mass_drift"].values, 0.0, atol=1e-14)  # constant V: mass exact
    assert ds.attrs["run_mode"] == "const_v" and ds.attrs["run_kernel"] == "Constant" and ds.attrs["engine"] == "mc"
    assert ds.attrs["scene"] == "three-species box" and ds.attrs["status"] in ("successful", "stopped")
    assert ds["m_species"].attrs["units"] == "g" and ds["V"].attrs["units"] == "cm3"
    # automatic edges: 10 per decade, covering every species (all mass inside, none in gel_mass)
    auto = r.to_xarray()
    e = auto["m_edge"].values
    np.testing.assert_allclose(np.diff(np.log10(e)), 0.1, rtol=1e-9)
    assert e[0] <= 1.0 and e[-1] > float(np.max(np.asarray(r.m)[np.asarray(r.valid)]))
    np.testing.assert_allclose(auto["mass_per_bin"].sum("m").values, M / 2.0, rtol=1e-13)
    path = io.save_netcdf(ds, tmp_path / "mc.nc")
    back = io.load_netcdf(path)
    for v in ("m_species", "log_g", "w", "z", "valid", "V", "M_tot", "n_events", "M_L1", "M_L2", "log_M2", "mass_per_bin"):
        np.testing.assert_array_equal(back[v].values, ds[v].values, err_msg=v)
    assert back.attrs["run_capacity"] == ds.attrs["run_capacity"]
    with pytest.raises(JaxcoagInputError, match="one run"):
        jax.tree_util.tree_map(lambda x: jnp.stack([x, x]), r).to_xarray()
    with pytest.raises(JaxcoagInputError, match="edges"):
        r.to_xarray(edges=[2.0, 1.0])


def test_hand_result_to_xarray():
    r = _hand_result()
    ds = r.to_xarray()
    assert ds.attrs["status"] == "stopped" and int(ds["status"]) == jc.RESULT_NAMES.index("stopped")
    assert ds["status"].attrs["status_name"] == "stopped" and float(ds["t_stop"]) == 0.8
    np.testing.assert_array_equal(ds["n_species"].values, [3, 3])
    assert ds["log_g"].values[0, 3] == -np.inf
    assert ds.attrs["run_capacity"] == 4


@pytest.mark.slow
def test_const_n_initial_volume_fixes_density():
    """In const_n with a given V the controller keeps the initial mass density M_tot/V."""
    init = mc.initial_species([1.0, 4.0], g=[30, 5], V=5.0)
    r = jc.evolve(K.Constant(1.0), mc.MonteCarlo(volume=mc.ConstantNumber(), capacity=80), init, jnp.array([0.5, 3.0]),
                  key=jax.random.key(1))
    np.testing.assert_allclose(np.asarray(r.M_tot / r.V), 50.0 / 5.0, rtol=1e-12)
    assert int(r.n_dup) > 0


def test_mc_and_binned_datasets_share_the_common_layout():
    """to_xarray of a Monte Carlo run and of a binned run of the same problem (constant kernel, monodisperse
    m0 = 1 g, rho_d = 1 g cm^-3) have the same coordinates (t, t_yr, m, m_edge, and a, St with a physical
    kernel), the same common variables with the same dims and units, and both conserve the mass density
    (sum over bins + gel = rho_d)."""
    from jaxcoag._dataset import COMMON_COORDS, COMMON_VARIABLES
    from jaxcoag.physics import gas as G

    kc = K.Constant(1.0)
    mono = jc.Monodisperse(1.0, rho_d=1.0)
    t_out = jnp.array([0.0, 1.0, 2.0, 3.0])
    grid = jc.MassGrid.log(10 ** -0.05, 10 ** 3.95, 10)  # 40 bins, centres 10^(k/10) g
    rb = jc.evolve(kc, jc.Binned(grid), mono, t_out)
    # the engine configuration of test_run_from_custom_initial_state (capacity 27, Runaway stop, 4 outputs):
    # no new compilation
    rm = jc.evolve(kc, mc.MonteCarlo(n_particles=19, capacity=27, stop=mc.Runaway(1e4)), mono, t_out,
                   key=jax.random.key(5))
    gas = G.mmsn_hayashi81(jc.constants.AU, 1e-4)
    phys = jc.Scene(velocities=(jc.effects.Brownian(),)).kernel(gas, rho_s=1.6)
    db = rb.to_xarray(kernel=phys)
    dm = rm.to_xarray(kernel=phys, edges=grid)  # the binned run's grid: its edges and centres
    assert db.attrs["engine"] == "binned" and dm.attrs["engine"] == "mc"
    assert set(COMMON_COORDS) | {"a", "St"} <= set(db.coords)
    assert set(db.coords) == set(dm.coords) - {"species"}
    for c in db.coords:
        assert db[c].dims == dm[c].dims and db[c].attrs.get("units") == dm[c].attrs.get("units"), c
        np.testing.assert_array_equal(db[c].values, dm[c].values, err_msg=c)
    for v in COMMON_VARIABLES:
        assert db[v].dims == dm[v].dims and db[v].attrs["units"] == dm[v].attrs["units"], v
    assert int(db["status"]) == 0 and dm.attrs["status"] in ("successful", "stopped")
    for ds, rtol in ((db, 1e-6), (dm, 1e-13)):
        tot = ds["mass_per_bin"].sum("m").values + ds["gel_mass"].values
        np.testing.assert_allclose(tot, 1.0, rtol=rtol)
        np.testing.assert_allclose(ds["mass_drift"].values, 0.0, atol=rtol)
    # the t_out[0] = t0 snapshot is the initial condition in both: all mass in the bin of m0 = 1 g
    i0 = int(np.argmin(np.abs(np.log(db["m"].values))))
    np.testing.assert_allclose([db["mass_per_bin"].values[0, i0], dm["mass_per_bin"].values[0, i0]], 1.0, rtol=1e-12)
    # the shared accessors of the result protocol: m^2 f = rho_b / dln m_b, and the peak at t0 is m0 = 1 g
    for r in (rb, rm):
        np.testing.assert_allclose(np.asarray(r.m2f(grid.edges)),
                                   np.asarray(r.mass_per_bin(grid.edges)) / np.diff(np.log(grid.edges)), rtol=1e-12)
        assert float(r.mass_peak(grid.edges)[0]) == pytest.approx(1.0, rel=1e-12)
    # automatic MC edges (10 per decade) hold all the mass: M1 from the bins equals the moment M1 = rho_d
    np.testing.assert_allclose(np.asarray(rm.mass_per_bin()).sum(-1), np.asarray(rm.moments(1.0)), rtol=1e-13)


def _scan_lengths(jaxpr):
    """Lengths of every ``scan`` in a (closed) jaxpr, nested ones included."""
    out = []
    for eq in jaxpr.eqns:
        if eq.primitive.name == "scan":
            out.append(int(eq.params["length"]))
        for v in eq.params.values():
            for sub in (v if isinstance(v, (tuple, list)) else (v,)):
                if isinstance(sub, jax.extend.core.ClosedJaxpr):
                    out += _scan_lengths(sub.jaxpr)
                elif isinstance(sub, jax.extend.core.Jaxpr):
                    out += _scan_lengths(sub)
    return out


def _members_case():
    eng = mc.MonteCarlo(grouping=mc.EqualMass(), n_particles=1e30, ns_target=30, f_eps=1e-2)
    t_out = jnp.array([0.0, 1.0, 2.5])

    def run(key, b):
        return jc.evolve(K.Sum(b), eng, jc.Monodisperse(1.0, 1.0), t_out, key=key, throw=False)

    return run, jax.random.split(jax.random.key(11), 3), jnp.array([0.5, 0.8, 1.2])


def _assert_member_equals(res, ix, one):
    for name in ("m", "w", "z", "valid", "M_tot", "logV", "n_events", "flags"):
        np.testing.assert_array_equal(np.asarray(getattr(res, name))[ix], np.asarray(getattr(one, name)),
                                      err_msg=f"{name} member {ix}")


def test_vmapped_members_run_as_single_runs_on_cpu():
    """Under jax.vmap on CPU the members run one after another (a lax.map over the batch, engine
    ``_simulate_members``), each bit for bit its single run (over keys and a kernel parameter at once)."""
    assert jax.default_backend() == "cpu"
    run, keys, bs = _members_case()
    # the batch of 3 becomes a scan of length 3 (the event loop itself has no scan)
    assert 3 in _scan_lengths(jax.make_jaxpr(jax.vmap(run))(keys, bs).jaxpr)
    assert 3 not in _scan_lengths(jax.make_jaxpr(run)(keys[0], bs[0]).jaxpr)
    both = jax.jit(jax.vmap(run))(keys, bs)
    for i in range(3):
        _assert_member_equals(both, (i,), run(keys[i], bs[i]))
    assert len({int(n) for n in np.asarray(both.n_events)}) == 3  # the members did differ


@pytest.mark.slow
def test_nested_vmap_members_equal_single_runs():
    """vmap over keys inside vmap over the kernel parameter: every member (3 x 3) equals its single run."""
    run, keys, bs = _members_case()
    nested = jax.jit(jax.vmap(jax.vmap(run, in_axes=(0, None)), in_axes=(None, 0)))(keys, bs)
    assert nested.m.shape[:2] == (3, 3)
    for i in range(3):
        for j in range(3):
            _assert_member_equals(nested, (j, i), run(keys[i], bs[j]))


def test_derivatives_through_a_run_are_zero_not_errors():
    """The sampling is not differentiable: jax.grad of a program that contains a run gives zero derivatives
    with respect to a kernel parameter (also under vmap, where the members run as single runs), not an error."""
    eng = mc.MonteCarlo(grouping=mc.EqualMass(), n_particles=1e30, ns_target=20, f_eps=1e-2)
    key = jax.random.key(2)

    def f(b):
        r = jc.evolve(K.Sum(b), eng, jc.Monodisperse(1.0, 1.0), jnp.array([0.0, 1.0]), key=key, throw=False)
        return jnp.sum(jnp.where(r.valid[-1], r.m[-1] * r.w[-1], 0.0))

    value, grad = jax.value_and_grad(f)(0.5)
    assert float(grad) == 0.0 and float(value) > 0.0
    np.testing.assert_array_equal(np.asarray(jax.vmap(jax.grad(f))(jnp.array([0.5, 0.7]))), 0.0)
