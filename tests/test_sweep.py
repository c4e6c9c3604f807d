"""jaxcoag.sweep: vmapped sweep == Python loop, failures as per-member status, sharded == unsharded."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import jax.numpy as jnp

import jaxcoag
from jaxcoag import kernels
from jaxcoag._status import RESULT_NAMES, result_code
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.binned import MassGrid, monodisperse
from jaxcoag.sweep import parameter_points, sweep

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
G = MassGrid.log(10 ** (-0.5 / 4), 1e3, 4)
N0 = jnp.asarray(monodisperse(G, 1.0, 1.0))


def box(k0, t_end):
    """Constant kernel k0 [cm^3 s^-1] from t0 = 0, outputs at 0, t_end/2, t_end [s]; t_end = 1e8 s exceeds max_steps."""
    return jaxcoag.evolve(kernels.Constant(k0), jaxcoag.Binned(G, max_steps=60), N0,
                          jnp.stack([0.0, 0.5 * t_end, t_end]), throw=False)


@pytest.fixture(scope="module")
def ds():
    return sweep(box, {"k0": [0.5, 1.0, 2.0], "t_end": [1.0, 10.0, 1e8]}, attrs={"scene": "constant"})


def test_sweep_dataset_round_trips_netcdf(ds, tmp_path):
    from jaxcoag import io
    import xarray as xr

    io.save_netcdf(ds, tmp_path / "sweep.nc")
    xr.testing.assert_identical(io.load_netcdf(tmp_path / "sweep.nc"), ds)


def test_sweep_equals_loop_and_failed_member(ds):
    assert dict(ds.sizes) == {"k0": 3, "t_end": 3, "t": 3, "m": G.nbins, "m_edge": G.nbins + 1}
    np.testing.assert_allclose(ds["m"].values, G.centers, rtol=1e-15)
    np.testing.assert_array_equal(ds["m_edge"].values, G.edges)
    assert "t" not in ds.coords  # the members' output times differ: t_out beside the parameters
    np.testing.assert_array_equal(ds["t_out"].values[0, 0], [0, 0.5, 1.0])
    np.testing.assert_array_equal(ds["t_out"].values[2, 2], [0, 0.5e8, 1e8])
    assert ds["mass_per_bin"].dims == ("k0", "t_end", "t", "m") and ds["gel_mass"].dims == ("k0", "t_end", "t")
    mx = RESULT_NAMES.index("max_steps_reached")
    for i, k0 in enumerate([0.5, 1.0, 2.0]):
        for j, te in enumerate([1.0, 10.0, 1e8]):
            s = box(k0, te)
            st = int(ds["status"][i, j])
            assert st == int(result_code(s.status))
            if te < 1e3:
                assert st == 0
                np.testing.assert_allclose(ds["mass_per_bin"].values[i, j], np.asarray(s.mass_per_bin()),
                                           rtol=1e-10, atol=1e-14)
                assert int(ds["steps"][i, j]) == int(s.stats["steps"])
            else:
                assert st == int(mx)  # the failing member is reported, the others finished
    assert ds.attrs["n_failed"] == 3 and ds.attrs["n_members"] == 9 and ds.attrs["scene"] == "constant"
    assert "max_steps_reached" in ds["status"].attrs["flag_meanings"]
    # mass conservation in the successful members
    ok = ds["status"].values == 0
    assert np.max(np.abs(ds["mass_drift"].values[ok])) < 1e-10


def test_zip_chunk_and_dict_outputs():
    def f(a, b):
        return {"s": a + b, "v": jnp.stack([a, b, a * b]), "bad": jnp.log(a - 1.5)}

    d1 = sweep(f, {"a": [1.0, 2.0, 3.0, 4.0, 5.0], "b": [0.1, 0.2, 0.3, 0.4, 0.5]}, grid="zip")
    d2 = sweep(f, {"a": [1.0, 2.0, 3.0, 4.0, 5.0], "b": [0.1, 0.2, 0.3, 0.4, 0.5]}, grid="zip", chunk=2)
    np.testing.assert_allclose(d1["s"].values, [1.1, 2.2, 3.3, 4.4, 5.5], rtol=1e-15)
    assert d1["v"].dims == ("member", "v_dim0")
    np.testing.assert_array_equal(d1["v"].values, d2["v"].values)
    np.testing.assert_array_equal(d1["a"].values, [1, 2, 3, 4, 5])
    # a = 1 gives log(-0.5) = NaN: that member is 'nonfinite', the rest successful
    assert list(d1["status"].values) == [RESULT_NAMES.index("nonfinite"), 0, 0, 0, 0]
    assert d1.attrs["n_failed"] == 1
    out = sweep(lambda x: x ** 2, {"x": np.arange(1.0, 4.0)})
    np.testing.assert_array_equal(out["value"].values, [1.0, 4.0, 9.0])


def test_parameter_points_outer_order():
    pts, shape = parameter_points({"alpha": [1e-4, 1e-3], "rho_g": [1.0, 2.0, 3.0]})
    assert shape == (2, 3)
    np.testing.assert_array_equal(pts["alpha"], [1e-4] * 3 + [1e-3] * 3)
    np.testing.assert_array_equal(pts["rho_g"], [1.0, 2.0, 3.0] * 2)


@pytest.mark.parametrize("params, kw, match", [
    ({}, {}, "non-empty dict"),
    ({"a": []}, {}, "empty"),
    ({"a": [1.0, np.nan]}, {}, "NaN"),
    ({"a": [[1.0]]}, {}, "1-D"),
    ({"a": [1.0]}, {"grid": "cartesian"}, "grid must be"),
    ({"a": [1.0], "b": [1.0, 2.0]}, {"grid": "zip"}, "equal-length"),
    ({"a": [1.0]}, {"chunk": 0}, "chunk"),
    ({"a": [1.0]}, {"mesh": "cpu"}, "Mesh"),
    ({"a": [1.0]}, {"devices": []}, "empty"),
    ({"a": [1.0]}, {"workers": 0}, "workers must be a positive int"),
    ({"a": [1.0]}, {"workers": True}, "workers must be a positive int"),
    ({"a": [1.0]}, {"workers": 1.5}, "workers must be a positive int"),
])
def test_bad_input(params, kw, match):
    with pytest.raises(JaxcoagInputError, match=match):
        sweep(lambda a, b=0.0: a, params, **kw)


def test_workers_with_devices_refused():
    import jax

    with pytest.raises(JaxcoagInputError, match="not both"):
        sweep(lambda a: a, {"a": [1.0, 2.0]}, workers=2, devices=jax.devices())


def test_workers_give_the_single_thread_results():
    """Blocks run in host threads return exactly what one thread returns with the same chunk, in member order;
    chunk=1 runs each member as its own unbatched program, equal to the loop of single solves."""
    p = {"k0": [0.5, 1.0, 2.0], "t_end": [1.0, 10.0, 1e8]}
    one_thread = sweep(box, p, chunk=2)
    threads = sweep(box, p, chunk=2, workers=3)
    assert threads.attrs["n_workers"] == 3 and one_thread.attrs["n_workers"] == 1
    for k in ("mass_per_bin", "gel_mass", "mass_drift", "steps", "status", "t_out"):
        np.testing.assert_array_equal(threads[k].values, one_thread[k].values)
    singles = sweep(box, p, chunk=1, workers=2)
    np.testing.assert_array_equal(singles["mass_per_bin"].values, sweep(box, p, chunk=1)["mass_per_bin"].values)
    for i, k0 in enumerate(p["k0"]):
        for j, te in enumerate(p["t_end"][:2]):
            np.testing.assert_allclose(singles["mass_per_bin"].values[i, j], np.asarray(box(k0, te).mass_per_bin()),
                                       rtol=1e-12, atol=1e-14)
    assert list(singles["status"].values[:, 2]) == [RESULT_NAMES.index("max_steps_reached")] * 3


def test_workers_run_blocks_at_the_same_time():
    """Two single-member blocks, two workers: each member's program waits (in a host callback) until the other
    one has started. Run one after another, the wait times out and the sweep raises."""
    import threading

    import jax

    barrier = threading.Barrier(2, timeout=60)

    def meet(x):
        barrier.wait()
        return np.asarray(x)

    def f(a):
        return {"y": jax.pure_callback(meet, jax.ShapeDtypeStruct((), jnp.float64), a) * 2.0}

    out = sweep(f, {"a": [1.0, 2.0]}, chunk=1, workers=2)
    np.testing.assert_array_equal(out["y"].values, [2.0, 4.0])


def test_workers_refuse_batched_lapack_blocks():
    """A block of several members whose solves become batched LAPACK calls hangs in several threads: refused
    before it runs; one member per block runs (its solves are unbatched) and gives the loop's values."""
    def f(a):
        A = a * jnp.eye(3) + 1.0
        return {"x": jnp.linalg.solve(A, jnp.ones(3))}

    with pytest.raises(JaxcoagInputError, match="batched LAPACK.*chunk=1"):
        sweep(f, {"a": [1.0, 2.0, 3.0, 4.0]}, chunk=2, workers=2)
    out = sweep(f, {"a": [1.0, 2.0, 3.0, 4.0]}, chunk=1, workers=2)
    for i, a in enumerate([1.0, 2.0, 3.0, 4.0]):
        np.testing.assert_allclose(out["x"].values[i], np.full(3, 1.0 / (a + 3.0)), rtol=1e-14)


SHARD_SCRIPT = textwrap.dedent("""
    import json, os, sys
    os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=4"
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np, jax.numpy as jnp
    sys.path.insert(0, {root!r})
    from jaxcoag import kernels
    import jaxcoag
    from jaxcoag.binned import MassGrid, monodisperse
    from jaxcoag.sweep import sweep
    G = MassGrid.log(10 ** (-0.5 / 4), 1e3, 4)
    N0 = jnp.asarray(monodisperse(G, 1.0, 1.0))
    def box(k0, t_end):
        return jaxcoag.evolve(kernels.Constant(k0), jaxcoag.Binned(G, max_steps=60), N0,
                              jnp.stack([0.0, 0.5 * t_end, t_end]), throw=False)
    p = {{"k0": [0.5, 1.0, 2.0], "t_end": [1.0, 1e8]}}        # 6 members on 4 devices: padded to 8
    a = sweep(box, p)
    b = sweep(box, p, devices=jax.devices())
    mesh = jax.make_mesh((2, 2), ("x", "y"))
    c = sweep(box, p, mesh=mesh, chunk=1)
    out = dict(ndev=len(jax.devices()), nd_b=b.attrs["n_devices"], nd_c=c.attrs["n_devices"],
               status_a=a.status.values.tolist(), status_b=b.status.values.tolist(),
               status_c=c.status.values.tolist(),
               diff_b=float(np.nanmax(np.abs(a.mass_per_bin.values - b.mass_per_bin.values)[a.status.values == 0])),
               diff_c=float(np.nanmax(np.abs(a.mass_per_bin.values - c.mass_per_bin.values)[a.status.values == 0])))
    print("RESULT" + json.dumps(out))
""")


@pytest.mark.slow  # suite budget (25 s); sharding stays in the default run through examples/04_sharded_sweep.py --quick
def test_sharded_equals_unsharded_subprocess():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    r = subprocess.run([sys.executable, "-c", SHARD_SCRIPT.format(root=ROOT)], capture_output=True, text=True,
                       env=env, timeout=240)
    assert r.returncode == 0, r.stderr[-3000:]
    line = [x for x in r.stdout.splitlines() if x.startswith("RESULT")][-1]
    out = json.loads(line[len("RESULT"):])
    assert out["ndev"] == 4 and out["nd_b"] == 4 and out["nd_c"] == 4
    mx = RESULT_NAMES.index("max_steps_reached")
    assert out["status_a"] == [[0, mx]] * 3
    assert out["status_b"] == out["status_a"] and out["status_c"] == out["status_a"]
    assert out["diff_b"] <= 1e-14 and out["diff_c"] <= 1e-14


def _profile(a, b):
    """A (3, 2) 'time x radius' output and a (3,) one, in closed form."""
    return {"x": a * jnp.arange(6.0).reshape(3, 2) + b, "y": a * jnp.arange(3.0)}


def test_dims_name_the_output_axes():
    """dims= names the axes beyond the parameters (values unchanged); outputs not named keep <name>_dim<i>."""
    ds = sweep(_profile, {"a": [1.0, 2.0], "b": [0.0, 5.0, 7.0]}, dims={"x": ("t", "r"), "y": "t"})
    assert ds["x"].dims == ("a", "b", "t", "r") and ds["y"].dims == ("a", "b", "t")
    np.testing.assert_array_equal(ds["x"].values[1, 2], 2.0 * np.arange(6.0).reshape(3, 2) + 7.0)
    np.testing.assert_array_equal(ds["y"].values[1, 0], [0.0, 2.0, 4.0])
    z = sweep(_profile, {"a": [1.0], "b": [0.0]}, grid="zip", dims={"y": ("t",)})
    assert z["y"].dims == ("member", "t") and z["x"].dims == ("member", "x_dim0", "x_dim1")


@pytest.mark.parametrize("dims, match", [
    ({"x": ("t",)}, "names 1 axes but output 'x' has 2"),
    ({"z": ("t",)}, "does not return; its outputs are status, x, y"),
    ({"x": ("a", "r")}, "reuses a parameter"),
    ({"x": ("t", "t")}, "repeats a name"),
    ({"x": ("t", "r"), "y": "r"}, "length 2 in output 'x' but 3 in 'y'"),
    (["x"], "dims must be a dict"),
    ({"x": ("t", "")}, "non-empty strings"),
])
def test_dims_bad_input(dims, match):
    with pytest.raises(JaxcoagInputError, match=match):
        sweep(_profile, {"a": [1.0, 2.0], "b": [0.0]}, dims=dims)
    with pytest.raises(JaxcoagInputError, match="engine result already has named axes|already have named axes"):
        sweep(box, {"k0": [1.0], "t_end": [1.0]}, dims={"mass_per_bin": ("t", "m")})


LAPACK_SCRIPT = textwrap.dedent("""
    import os
    os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=2"
    import jax, jax.numpy as jnp
    jax.config.update("jax_enable_x64", True)
    from jaxcoag.sweep import sweep
    from jaxcoag._validate import JaxcoagInputError

    def f(a):  # one LU per member: jaxlib's batched getrf under vmap
        return jnp.linalg.solve(jnp.eye(120) * a + 0.1, jnp.ones(120))

    ok = sweep(f, {"a": [2.0, 3.0]}, devices=jax.devices()[:1])  # one CPU device: runs
    try:
        sweep(f, {"a": [2.0, 3.0]}, devices=jax.devices())
        print("NOT REFUSED")
    except JaxcoagInputError as e:
        print("REFUSED", e, float(ok["value"].values[0, 0]))
""")


def test_several_cpu_devices_refused_for_lapack_programs():
    """A sweep whose program calls LAPACK factorisations is refused, before it runs, over several CPU devices
    (jaxlib's batched LU deadlocks there: docs/design_notes.md); over one CPU device it runs."""
    env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=ROOT)
    r = subprocess.run([sys.executable, "-c", LAPACK_SCRIPT], capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0, r.stderr[-3000:]
    line = [x for x in r.stdout.splitlines() if x.startswith(("REFUSED", "NOT REFUSED"))][-1]
    assert line.startswith("REFUSED") and "lapack_dgetrf" in line and "2 CPU devices" in line
    assert abs(float(line.split()[-1]) - 1.0 / 14.0) < 1e-14  # (2 I + 0.1 J) x = 1: x = 1 / (2 + 0.1 * 120)


def test_invalid_flag_marks_only_the_bad_members(ds):
    """invalid='flag': a NaN parameter value flags its members; every other member is unchanged."""
    bad = sweep(box, {"k0": [0.5, np.nan, 2.0], "t_end": [1.0, 10.0, 1e8]}, invalid="flag")
    code = RESULT_NAMES.index("invalid_parameters")
    st = bad["status"].values
    assert st[1].tolist() == [code] * 3
    np.testing.assert_array_equal(np.delete(st, 1, axis=0), np.delete(ds["status"].values, 1, axis=0))
    assert np.all(np.isnan(bad["mass_per_bin"].values[1]))
    np.testing.assert_array_equal(np.delete(bad["mass_per_bin"].values, 1, axis=0),
                                  np.delete(ds["mass_per_bin"].values, 1, axis=0))
    assert bad.attrs["n_failed"] == 3 + 2  # the flagged row plus the two max_steps members of good rows
    assert "invalid_parameters" in bad["status"].attrs["flag_meanings"]
    with pytest.raises(JaxcoagInputError, match="index 1"):
        sweep(box, {"k0": [0.5, np.nan], "t_end": [1.0]})
    with pytest.raises(JaxcoagInputError, match="every sweep member"):
        sweep(box, {"k0": [np.nan], "t_end": [1.0]}, invalid="flag")


def test_fn_signature_is_checked():
    with pytest.raises(JaxcoagInputError, match="does not accept the parameter 'c'"):
        sweep(lambda a: a, {"a": [1.0], "c": [2.0]})
    with pytest.raises(JaxcoagInputError, match="needs the argument 'b'"):
        sweep(lambda a, b: a * b, {"a": [1.0]})
    out = sweep(lambda **kw: kw["a"] * 2.0, {"a": [1.0, 2.0]})  # **kwargs accepts anything
    np.testing.assert_array_equal(out["value"].values, [2.0, 4.0])


@pytest.mark.slow
def test_nebula_32x32_sweep_equals_loop():
    """The issue's 32 x 32 alpha x rho_g sweep of the nebula box: all members succeed and equal
    single jitted solves (checked on 16 points spread over the grid)."""
    import diffrax
    import jax
    from jaxcoag import diagnostics, fit

    model = fit.nebula_box(bins_per_decade=4, decades=8, ts=(5e9, 1e10), rtol=1e-6, atol=1e-10)
    adj = diffrax.RecursiveCheckpointAdjoint()

    lc = jnp.asarray(model.grid.log_centers)

    def neb(alpha, rho_g):
        res = model.solve({"alpha": alpha, "rho_g": rho_g}, adjoint=adj)
        rho = res.mass_per_bin()[-1]
        return {"ln_mpeak": jnp.log(diagnostics.mass_peak(rho, model.grid)),
                "mean_ln_m": jnp.sum(rho * lc) / jnp.sum(rho), "result": res.status}

    params = {"alpha": np.logspace(np.log10(3e-5), np.log10(3e-4), 32),
              "rho_g": float(model.rho_g) * np.logspace(-0.3, 0.3, 32)}
    out = sweep(neb, params, chunk=256)
    assert dict(out.sizes) == {"alpha": 32, "rho_g": 32}
    assert out.attrs["n_failed"] == 0 and out.attrs["n_members"] == 1024
    one = jax.jit(neb)
    for i, j in [(i, j) for i in range(0, 32, 9) for j in range(0, 32, 9)]:
        ref = float(one(params["alpha"][i], params["rho_g"][j])["ln_mpeak"])
        assert abs(float(out["ln_mpeak"][i, j]) - ref) < 1e-9
        assert abs(float(out["mean_ln_m"][i, j]) - float(one(params["alpha"][i], params["rho_g"][j])["mean_ln_m"])) \
            < 1e-9
    # physics: growth speeds up with alpha (turbulent relative velocities) and with rho_g (dust density)
    mean = out["mean_ln_m"].values
    assert np.all(np.diff(mean, axis=0) > 0) and np.all(np.diff(mean, axis=1) > 0)


@pytest.mark.slow
def test_monte_carlo_sweep_over_keys():
    """The Monte Carlo engine sweeps like the binned one (vmapped over random keys, fixed bins):
    each member equals its own run, and the number density follows the constant-kernel solution
    n(t) = n0 / (1 + K n0 t / 2) (Smoluchowski 1916) within the sampling noise."""
    from jaxcoag import mc
    import jax

    edges = 2.0 ** np.arange(0, 12)  # [g]: monomers of 1 g up to 2048 g
    t_out = jnp.array([0.0, 1.0, 2.0])

    def run(seed):
        key = jax.random.fold_in(jax.random.key(5), seed.astype(jnp.uint32))
        return jaxcoag.evolve(kernels.Constant(1.0), mc.MonteCarlo(n_particles=400), jaxcoag.Monodisperse(1.0, 1.0),
                              t_out, key=key, throw=False)

    ds = sweep(run, {"seed": np.arange(4.0)}, edges=edges)
    assert dict(ds.sizes) == {"seed": 4, "t": 3, "m": 11, "m_edge": 12}
    np.testing.assert_array_equal(ds["t"].values, [0.0, 1.0, 2.0])
    assert ds["status"].values.tolist() == [0] * 4 and ds.attrs["n_failed"] == 0
    one = run(jnp.asarray(2.0))
    np.testing.assert_array_equal(ds["mass_per_bin"].values[2], np.asarray(one.mass_per_bin(edges)))
    np.testing.assert_array_equal(ds["number_per_bin"].values[2], np.asarray(one.number_per_bin(edges)))
    # every grain is inside the bins: the binned mass is the initial dust density 1 g cm^-3
    np.testing.assert_allclose(ds["mass_per_bin"].values.sum(axis=-1), 1.0, rtol=1e-12)
    n = ds["number_per_bin"].values.sum(axis=-1).mean(axis=0)
    np.testing.assert_allclose(n, 1.0 / (1.0 + 0.5 * np.array([0.0, 1.0, 2.0])), atol=0.05)
    with pytest.raises(JaxcoagInputError, match="edges="):
        sweep(run, {"seed": [0.0]})
