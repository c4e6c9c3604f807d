"""`jaxcoag run / plot / sweep / config` end to end (quick mode) for both engines, and refused runs:
exit code 2, the reason on stderr, no output file - one test per category of bad input."""

import io as _stdio
import os

import numpy as np
import pytest

from jaxcoag import checkpoint as ckmod
from jaxcoag import cli, config, diagnostics, io, runner
from jaxcoag._dataset import COMMON_COORDS, COMMON_VARIABLES

from _configs import SMALL, SMALL_MC  # noqa: E402  (shared test configurations)


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("run")
    out = d / "res" / "run.nc"
    rc = cli.main(["run", "--quick", "--no-progress", "--out", str(out)])
    return rc, out


def test_run_quick_default_end_to_end(quick_run, capsys):
    rc, out = quick_run
    assert rc == 0
    ds = io.load_netcdf(out)
    png = runner.figure_path(str(out))
    assert os.path.getsize(png) > 20_000
    assert os.path.exists(str(out) + ".ckpt.npz")
    cfg = config.loads(ds.attrs["config_toml"])
    assert cfg["gas"]["model"] == "mmsn_hayashi81" and cfg["fragmentation"]["v_frag"] == 1000.0
    assert ds.attrs["status"] == "successful" and int(ds["status"]) == 0 and ds.attrs["engine"] == "binned"
    t = ds["t"].values
    assert t[0] == 0 and np.all(np.diff(t) > 0) and t.size == 9
    np.testing.assert_allclose(t[-1], 1e4 * 3.15576e7, rtol=1e-12)
    # mass conserved through growth and fragmentation
    assert np.max(np.abs(ds["mass_drift"].values)) < 1e-10
    mp = np.asarray(diagnostics.mass_peak(ds["mass_per_bin"].values, ds["m_edge"].values))
    # grows by > 10 decades in mass from the 1 um monomers, then saturates at the fragmentation barrier
    assert mp[-1] > 1e10 * mp[0]
    np.testing.assert_allclose(mp[-1], mp[-2], rtol=1e-3)
    np.testing.assert_allclose(mp[-1], mp[-3], rtol=1e-2)
    kern = runner.kernel_from_dataset(ds)
    st_peak = float(kern.particles(mp[-1]).st)
    st_frag = 1000.0 ** 2 / (3 * 1e-3 * ds.attrs["c_g"] ** 2)
    assert 0.1 * st_frag < st_peak < st_frag  # below the Birnstiel et al. (2012) barrier, same order
    # one checkpoint segment per output time (t = 0 included), all done
    assert ckmod.read_info(str(out) + ".ckpt.npz")["n_done"] == 9


def test_plot_subcommand(quick_run, tmp_path, capsys):
    rc, out = quick_run
    png = tmp_path / "p" / "again.png"
    assert cli.main(["plot", str(out), "--out", str(png)]) == 0
    assert os.path.getsize(png) > 20_000
    assert "with the run's kernel" in capsys.readouterr().out
    assert cli.main(["plot", str(tmp_path / "nope.nc")]) == 2
    assert "no file" in capsys.readouterr().err
    junk = tmp_path / "junk.nc"
    junk.write_text("hello")
    assert cli.main(["plot", str(junk)]) == 2
    assert "not a readable netCDF" in capsys.readouterr().err


def test_resume_of_a_finished_run_rebuilds_the_same_file(quick_run, tmp_path, capsys):
    rc, out = quick_run
    again = tmp_path / "again.nc"
    ck = str(out) + ".ckpt.npz"
    assert cli.main(["run", "--quick", "--no-progress", "--no-figure", "--out", str(again), "--checkpoint", ck,
                     "--resume"]) == 0
    a, b = io.load_netcdf(out), io.load_netcdf(again)
    np.testing.assert_array_equal(a["mass_per_bin"].values, b["mass_per_bin"].values)
    assert "(resumed after output 9)" in capsys.readouterr().out


def _write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


@pytest.mark.parametrize("patch, args, words", [
    ("[gas]\nalpha = 1e-3\n", [], "Cannot declare"),  # duplicate table: invalid TOML
    ("[output]\nfigur = false\n", [], "unknown key 'figur' in section [output]"),
    ("[nebula]\nR_au = 1\n", [], "unknown section [nebula]"),
    ("", ["--set", "gas.alpha=-1e-3"], "[gas] alpha must be >= 0"),
    ("", ["--set", "dust.rho_s=nan"], "[dust] rho_s must be finite"),
    ("", ["--set", "grid.bins_per_decade=0.05"], "at least 2 bins"),
    ("", ["--set", "time.n_out=0"], "[time] n_out must be > 0"),
    ("[scene]\neffects = [\"brownian\", \"turbulence_oc07\", \"brownian\"]\n", [], "incompatible"),
])
def test_refused_run_exits_2_and_writes_nothing(tmp_path, capsys, patch, args, words):
    path = _write(tmp_path, SMALL + patch)
    out = tmp_path / "o" / "run.nc"
    rc = cli.main(["run", path, "--no-progress", "--out", str(out)] + args)
    assert rc == 2
    err = capsys.readouterr().err
    assert words in err, err
    assert not (tmp_path / "o").exists()


def test_time_outputs_not_increasing_refused(tmp_path, capsys):
    text = SMALL.replace("t_end_yr = 10.0\nn_out = 3\n", "t_out_yr = [1.0, 5.0, 2.0]\n")
    out = tmp_path / "o" / "run.nc"
    assert cli.main(["run", _write(tmp_path, text), "--out", str(out)]) == 2
    assert "t_out_yr must be strictly increasing" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_missing_parameter_and_missing_file_refused(tmp_path, capsys):
    out = tmp_path / "o" / "run.nc"
    assert cli.main(["run", _write(tmp_path, SMALL.replace("rho_s = 1.6\n", "")), "--out", str(out)]) == 2
    assert "missing required parameter [dust] rho_s" in capsys.readouterr().err
    assert cli.main(["run", str(tmp_path / "none.toml"), "--out", str(out)]) == 2
    assert "no configuration file" in capsys.readouterr().err
    assert cli.main(["run", "--set", "gas.alpah=1", "--out", str(out)]) == 2
    assert "Did you mean 'alpha'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_small_run_from_toml_and_no_subcommand_means_run(tmp_path, capsys):
    path = _write(tmp_path, SMALL)
    out = tmp_path / "r.nc"
    assert cli.main([path, "--no-progress", "--no-figure", "--no-checkpoint", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "jaxcoag run 'small_growth'" in printed and "result: successful" in printed
    ds = io.load_netcdf(out)
    assert ds["mass_per_bin"].shape == (4, ds.sizes["m"])
    assert not (tmp_path / "r.png").exists() and not (tmp_path / "r.nc.ckpt.npz").exists()
    assert ds["mass_per_bin"].values[-1].argmax() > ds["mass_per_bin"].values[0].argmax()  # it grew
    # a run stopped after one output time writes no netCDF yet (exit 1); --resume finishes it identically
    out2 = tmp_path / "r2.nc"
    assert cli.main([path, "--no-progress", "--no-figure", "--max-segments", "1", "--out", str(out2)]) == 1
    assert "continue with --resume" in capsys.readouterr().out
    assert not out2.exists() and (tmp_path / "r2.nc.ckpt.npz").exists()
    assert cli.main([path, "--no-progress", "--no-figure", "--resume", "--out", str(out2)]) == 0
    np.testing.assert_array_equal(io.load_netcdf(out2)["mass_per_bin"].values, ds["mass_per_bin"].values)


def test_sweep_subcommand_quick(tmp_path, capsys):
    path = _write(tmp_path, SMALL)
    out = tmp_path / "sw.nc"
    rc = cli.main(["sweep", path, "--param", "alpha=1e-4,1e-3", "--param", "rho_s=1.0,1.6", "--out", str(out)])
    assert rc == 0
    ds = io.load_netcdf(out)
    assert ds["mass_per_bin"].shape[:2] == (2, 2) and int(ds.attrs["n_failed"]) == 0
    assert np.all(ds["status"].values == 0)
    mp = ds["mass_peak"].values
    assert np.all(mp[1] >= mp[0]) and np.any(mp[1] > mp[0])  # stronger turbulence grows faster
    # the member alpha = 1e-3, rho_s = 1.6 (SMALL's own values) equals the single run of the same config:
    # the sweep integrates in one go, the run restarts its adaptive steps at every output, so they
    # agree to the solver tolerance (SMALL: rtol = 1e-4; measured max 1.9e-5 on bins above 1e-6 M)
    assert list(ds["alpha"].values) == [1e-4, 1e-3] and list(ds["rho_s"].values) == [1.0, 1.6]
    single = runner.run(config.loads(SMALL), out=str(tmp_path / "one.nc"), progress=False, verbose=False,
                        save=False, checkpoint=False)
    ref = np.asarray(single.result.mass_per_bin())
    member = ds["mass_per_bin"].values[1, 1]
    big = ref > 1e-6 * ref[0].sum()
    np.testing.assert_allclose(member[big], ref[big], rtol=1e-4)
    np.testing.assert_allclose(member, ref, rtol=0, atol=1e-6 * ref[0].sum())
    np.testing.assert_allclose(mp[1, 1], single.numbers["m_peak"], rtol=1e-4)
    printed = capsys.readouterr().out
    assert "4 members" in printed and "0 failed" in printed
    assert cli.main(["plot", str(out)]) == 2
    assert "select one member" in capsys.readouterr().err
    assert cli.main(["sweep", path, "--param", "bins_per_decade=2,3", "--out", str(tmp_path / "x.nc")]) == 2
    assert "cannot sweep 'bins_per_decade'" in capsys.readouterr().err
    assert cli.main(["sweep", path, "--param", "alpha=-1,1e-3", "--out", str(tmp_path / "x.nc")]) == 2
    assert "[gas] alpha must be >= 0" in capsys.readouterr().err
    assert not (tmp_path / "x.nc").exists()


def test_sweep_member_equals_single_run(tmp_path):
    cfg = config.loads(SMALL)
    ds, rows = runner.sweep_config(cfg, {"alpha": [1e-3, 3e-3]}, verbose=False)
    single = runner.run(cfg, out=str(tmp_path / "one.nc"), progress=False, verbose=False, save=False,
                        checkpoint=False)
    # the sweep integrates in one go, the run restarts its adaptive steps at every output segment: equal
    # to the solver tolerance (SMALL: rtol = 1e-4) on every bin above 1e-6 of the mass, at every output
    # (measured: max relative difference 1.9e-5 at the second output, 2.6e-6 at the last)
    ref = np.asarray(single.result.mass_per_bin())
    got = ds["mass_per_bin"].values[0]
    big = ref > 1e-6 * ref[0].sum()
    np.testing.assert_allclose(got[big], ref[big], rtol=1e-4)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6 * ref[0].sum())
    # same initial state, to round-off: the member computes n0 = n_unit (d2g rho_g) inside its compiled program,
    # where XLA may round a product differently (measured: 1 ulp, 3.2e-27 of 1.4e-11 g cm^-3)
    np.testing.assert_allclose(got[0], ref[0], rtol=1e-15, atol=0)
    assert rows[0]["status"] == "successful"
    # the same program with one member instead of two gives the same member (deterministic; measured 2e-16)
    ds1, _ = runner.sweep_config(cfg, {"alpha": [1e-3]}, verbose=False)
    np.testing.assert_allclose(ds1["mass_per_bin"].values[0], got, rtol=1e-12, atol=1e-15 * ref[0].sum())
    # the members ran in one host thread per core (chunk 1); one thread gives the same numbers
    ds_1w, _ = runner.sweep_config(cfg, {"alpha": [1e-3, 3e-3]}, verbose=False, workers=1)
    np.testing.assert_array_equal(ds_1w["mass_per_bin"].values, ds["mass_per_bin"].values)
    assert ds.attrs["n_workers"] == (os.cpu_count() or 1) and ds_1w.attrs["n_workers"] == 1


def test_config_subcommand_prints_the_default(capsys):
    assert cli.main(["config"]) == 0
    text = capsys.readouterr().out
    assert config.loads(text).data == config.default().data
    assert cli.main(["config", "--resolved"]) == 0
    resolved = capsys.readouterr().out
    assert "m_min = " in resolved and "m0 = " in resolved  # computed defaults are shown
    import tomllib
    assert tomllib.loads(resolved)["grid"]["m_min"] == config.default()["grid"]["m_min"]  # written exactly


def test_run_solves_forward_only_with_the_same_numbers():
    """``runner.run`` (``jaxcoag run``) solves the binned box with ``diffrax.ForwardMode`` (``runner.forward_only``:
    a run that nothing differentiates) and gets, to round-off and with the same steps, what the same segments give
    with the engine's default ``RecursiveCheckpointAdjoint``; an adjoint a user set is kept."""
    import diffrax

    cfg = runner.quick_config(config.default())
    b = config.build(cfg)
    assert b.engine.adjoint is None and isinstance(runner.forward_only(b.engine).adjoint, diffrax.ForwardMode)
    mine = b.engine.__class__(b.engine.grid, adjoint=diffrax.DirectAdjoint())
    assert runner.forward_only(mine) is mine
    # a checkpoint's fingerprint leaves the adjoint out (Binned._fingerprint_view): what `jaxcoag run` wrote under
    # ForwardMode resumes under the default adjoint and the other way round; the numbers still count
    fp = lambda e: ckmod.run_fingerprint(b.kernel, e, b.initial, b.t_out, t0=0.0, outcome=b.outcome, key=b.key)
    assert fp(runner.forward_only(b.engine)) == fp(b.engine)
    assert fp(mine) == fp(b.engine.__class__(b.engine.grid)) != fp(b.engine.__class__(b.engine.grid, rtol=1e-3))
    res = runner.run(cfg, save=False, progress=False, verbose=False)
    # the same segments (one per output time, the step size carried) with the default adjoint
    ref, _ = runner.evolve_saved(b.kernel, b.engine, b.initial, b.t_out, outcome=b.outcome, key=b.key,
                                 checkpoint=None, every=1, resume=False, progress=False, max_segments=None, save=False)
    # to round-off: XLA compiles the two loops apart (the default box agreed bit for bit; this quick box has 2 of
    # 522 entries one ulp apart), the step sequences are the same
    np.testing.assert_allclose(res.dataset["mass_per_bin"].values, np.asarray(ref.mass_per_bin()), rtol=1e-13, atol=0)
    assert int(res.result.stats["steps"]) == int(ref.stats["steps"])
    assert int(res.result.stats["rejected"]) == int(ref.stats["rejected"])


def test_the_command_flushes_its_output_and_keeps_exit_codes(tmp_path):
    """The ``jaxcoag`` command (``cli.console_main``, also ``python -m jaxcoag.cli``) ends with ``os._exit``
    after flushing: a piped stdout arrives whole (the default TOML, ~100 lines, parses to the default), a refused
    input still exits with 2 and its one-line message, and argparse's own exits (--version: 0) are unchanged."""
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # block-buffered pipes, as usual

    def cli_run(*args):
        return subprocess.run([sys.executable, "-m", "jaxcoag.cli", *args], capture_output=True, text=True,
                              cwd=tmp_path, timeout=300, env=env)

    r = cli_run("config")
    assert r.returncode == 0, r.stderr
    assert config.loads(r.stdout).data == config.default().data and r.stdout.endswith("\n")
    assert r.stdout == open(config.default_path()).read()
    bad = cli_run("run", str(tmp_path / "missing.toml"), "--no-progress")
    assert bad.returncode == 2 and bad.stderr.startswith("jaxcoag run: error:") and "missing.toml" in bad.stderr
    v = cli_run("--version")
    assert v.returncode == 0 and v.stdout.strip()


def test_config_engine_mc_prints_a_runnable_grouped_default_of_the_same_scene(capsys):
    assert cli.main(["config", "--engine", "mc"]) == 0
    text = capsys.readouterr().out
    mc = config.loads(text)
    binned = config.default()
    assert mc.data == config.default("mc").data and mc.engine == "mc" and binned.engine == "binned"
    assert mc["mc"]["grouping"] in ("equal_mass", "distribution") and mc["mc"]["n_particles"] > 1e20
    # the same physics as the binned default, so that the two figures compare
    for section in ("scene", "gas", "dust", "grid", "fragmentation"):
        assert mc[section] == binned[section], section
    assert mc["output"]["path"] != binned["output"]["path"]  # its own file next to the binned one
    assert "# measured:" in text  # the comment states the measured run time


@pytest.mark.slow
def test_full_default_run_reaches_the_fragmentation_barrier(tmp_path):
    """The README main job at full resolution (135 bins, 16 outputs to 1e4 yr; ~1-4 min on 2 cores)."""
    res = runner.run(out=str(tmp_path / "run.nc"), progress=False, verbose=False)
    assert res.finished and not res.failed and res.numbers["result"] == "successful"
    assert res.numbers["max_abs_mass_drift"] < 1e-12
    mp = np.array([r["m_peak"] for r in res.rows])
    np.testing.assert_allclose(mp[-6:], mp[-1], rtol=1e-4)  # steady for the last ~1e4 yr
    np.testing.assert_allclose(mp[-1], 757.71, rtol=1e-3)  # measured 757.709 g (as the README states)
    assert 0.3 * res.numbers["st_frag"] < res.numbers["st_peak"] < res.numbers["st_frag"]
    assert os.path.getsize(res.figure) > 50_000


def test_solver_failure_exits_1_and_saves_the_outputs_before_it(tmp_path, capsys):
    out = tmp_path / "f.nc"
    rc = cli.main([_write(tmp_path, SMALL), "--no-progress", "--no-figure", "--set", "solver.max_steps=3",
                   "--out", str(out)])
    assert rc == 1
    assert "result: max_steps_reached" in capsys.readouterr().out
    ds = io.load_netcdf(out)
    assert ds.attrs["status"] == "max_steps_reached" and int(ds["status"]) != 0
    assert ds["status"].attrs["status_name"] == "max_steps_reached"
    assert ds.sizes["t"] >= 1 and np.all(np.isfinite(ds["mass_per_bin"].values))


def _interrupt_at(monkeypatch, n):
    """Patch the binned engine's advance so that its n-th call from now (the n-th output time) raises
    KeyboardInterrupt (Ctrl-C); returns the real method."""
    import jaxcoag

    real = _REAL_ADVANCE
    calls = []

    def maybe_interrupted(self, *a, **k):
        calls.append(1)
        if len(calls) == n:
            raise KeyboardInterrupt
        return real(self, *a, **k)

    monkeypatch.setattr(jaxcoag.Binned, "_advance", maybe_interrupted)
    return real


import jaxcoag as _jc  # noqa: E402

_REAL_ADVANCE = _jc.Binned._advance


def test_ctrl_c_checkpoints_prints_the_resume_command_and_exits_130(tmp_path, capsys, monkeypatch):
    """Ctrl-C in the 2nd of 4 output times (t = 0 and 3 outputs): exit 130, the completed output is
    in the checkpoint (no netCDF yet), stderr ends with the exact command that resumes; running that
    command finishes the run bit for bit like an uninterrupted one."""
    import shlex

    import jaxcoag

    path = _write(tmp_path, SMALL)
    out = tmp_path / "int" / "r.nc"
    real = _interrupt_at(monkeypatch, 2)
    argv = ["run", path, "--no-progress", "--no-figure", "--out", str(out)]
    assert cli.main(argv) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-2] == f"jaxcoag run: interrupted after 1 of 4 output times; checkpoint saved to {out}.ckpt.npz"
    assert err[-1] == "resume with: " + shlex.join(["jaxcoag"] + argv + ["--resume"])
    assert ckmod.read_info(str(out) + ".ckpt.npz")["n_done"] == 1 and not out.exists()
    # --no-checkpoint: nothing to save; the message says so and nothing is written
    out2 = tmp_path / "nock" / "r.nc"
    argv2 = ["run", path, "--no-progress", "--no-figure", "--no-checkpoint", "--out", str(out2)]
    _interrupt_at(monkeypatch, 2)
    assert cli.main(argv2) == 130
    err2 = capsys.readouterr().err.strip().splitlines()
    assert err2[-2] == "jaxcoag run: interrupted; no checkpoint was saved (--no-checkpoint)."
    assert not (tmp_path / "nock").exists()
    monkeypatch.setattr(jaxcoag.Binned, "_advance", real)
    cmd = shlex.split(err[-1][len("resume with: "):])
    assert cmd[0] == "jaxcoag" and cli.main(cmd[1:]) == 0
    assert "(resumed after output 1)" in capsys.readouterr().out
    ref = tmp_path / "ref.nc"
    assert cli.main(["run", path, "--no-progress", "--no-figure", "--no-checkpoint", "--out", str(ref)]) == 0
    a, b = io.load_netcdf(out), io.load_netcdf(ref)
    for name in ("mass_per_bin", "number_per_bin", "gel_mass", "mass_drift", "steps", "rejected_steps"):
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)


@pytest.mark.slow
def test_sigint_to_a_running_jaxcoag_run_process(tmp_path):
    """A real SIGINT to `jaxcoag run` once its first checkpoint exists: exit 130, the printed
    command resumes it, and the result equals an uninterrupted run (~1-2 min: two processes)."""
    import shlex
    import signal
    import subprocess
    import sys
    import time

    text = SMALL.replace("n_out = 3\n", "n_out = 300\nspacing = \"linear\"\n")
    path = _write(tmp_path, text)
    out = tmp_path / "r.nc"
    ck = tmp_path / "r.nc.ckpt.npz"
    cmd = [sys.executable, "-m", "jaxcoag.cli", "run", path, "--no-progress", "--no-figure", "--out", str(out)]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    t0 = time.time()
    while not ck.exists() and p.poll() is None and time.time() - t0 < 500:
        time.sleep(0.02)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=300)
    assert p.returncode == 130, err
    lines = err.strip().splitlines()
    assert lines[-1].startswith("resume with: jaxcoag run ") and lines[-1].endswith(" --resume"), err
    n_done = int(lines[-2].split("interrupted after ")[1].split(" of ")[0])
    assert 1 <= n_done < 301 and not out.exists()
    again = shlex.split(lines[-1][len("resume with: "):])
    r = subprocess.run([sys.executable, "-m", "jaxcoag.cli"] + again[1:], capture_output=True, text=True,
                       cwd=tmp_path, timeout=500)
    assert r.returncode == 0, r.stderr
    assert f"(resumed after output {n_done})" in r.stdout
    ref = runner.run(config.loads(text), out=tmp_path / "ref.nc", save=False, progress=False, verbose=False)
    np.testing.assert_array_equal(io.load_netcdf(out)["mass_per_bin"].values, ref.dataset["mass_per_bin"].values)


# ------------------------------------------------------------------------------ the Monte Carlo engine
@pytest.fixture(scope="module")
def small_pair(tmp_path_factory):
    """SMALL with the binned engine (file) and SMALL_MC with the Monte Carlo engine (read from stdin)."""
    d = tmp_path_factory.mktemp("pair")
    b, m = d / "binned.nc", d / "mc.nc"
    mp = pytest.MonkeyPatch()
    try:
        path = d / "small.toml"
        path.write_text(SMALL)
        rc_b = cli.main(["run", str(path), "--no-progress", "--no-figure", "--no-checkpoint", "--out", str(b)])
        mp.setattr("sys.stdin", _stdio.StringIO(SMALL_MC))
        rc_m = cli.main(["run", "-", "--no-progress", "--out", str(m)])
    finally:
        mp.undo()
    return rc_b, rc_m, b, m


def test_mc_run_from_stdin_writes_the_binned_layout(small_pair):
    """`jaxcoag config --engine mc | jaxcoag run -` path: the Monte Carlo file has the coordinates,
    dims and common variables of the binned file, on the same [grid] bins, with the same a / St."""
    rc_b, rc_m, b, m = small_pair
    assert rc_b == 0 and rc_m == 0
    db, dm = io.load_netcdf(b), io.load_netcdf(m)
    assert db.attrs["engine"] == "binned" and dm.attrs["engine"] == "mc"
    assert dm.attrs["status"] == "successful" and int(dm["status"]) == 0
    for name in COMMON_COORDS + ("a", "St"):
        assert name in db.coords and name in dm.coords, name
        assert db[name].dims == dm[name].dims and db[name].attrs["units"] == dm[name].attrs["units"], name
        np.testing.assert_array_equal(db[name].values, dm[name].values, err_msg=name)
    for name in COMMON_VARIABLES:
        assert db[name].dims == dm[name].dims and db[name].attrs["units"] == dm[name].attrs["units"], name
    assert dm["mass_per_bin"].dims == ("t", "m") and dm.sizes["t"] == 4
    np.testing.assert_allclose(dm["t_yr"].values, [0.0, 1e-3, 0.1, 10.0], rtol=1e-12)  # log spacing from 1e-4 t_end
    # constant volume: every output holds the initial dust density 0.01 rho_g, to round-off
    rho_d = 0.01 * float(dm.attrs["rho_g"])
    total = dm["mass_per_bin"].values.sum(axis=1) + dm["gel_mass"].values
    np.testing.assert_allclose(total, rho_d, rtol=1e-12)
    assert np.max(np.abs(dm["mass_drift"].values)) < 1e-12
    # t = 0: all mass in the monomer bin, in both files
    np.testing.assert_allclose(dm["mass_per_bin"].values[0], db["mass_per_bin"].values[0], rtol=1e-12, atol=0)
    # the Monte Carlo species arrays come along
    for name in ("m_species", "log_g", "valid", "n_events"):
        assert name in dm.variables, name
    assert int(dm["n_events"].values[-1]) > 0
    assert os.path.getsize(runner.figure_path(str(m))) > 20_000  # the same panel figure


def test_mc_cli_resume_is_bit_identical(tmp_path, capsys, small_pair):
    """A Monte Carlo run stopped after 2 output times and resumed from its checkpoint writes the same
    file as the uninterrupted run (every array equal, bit for bit)."""
    _, _, _, ref = small_pair
    path = _write(tmp_path, SMALL_MC, "mc.toml")
    out = tmp_path / "r.nc"
    argv = ["run", path, "--no-progress", "--no-figure", "--out", str(out)]
    assert cli.main(argv + ["--max-segments", "2"]) == 1
    assert "continue with --resume" in capsys.readouterr().out and not out.exists()
    assert ckmod.read_info(str(out) + ".ckpt.npz")["n_done"] == 2
    assert cli.main(argv + ["--resume"]) == 0
    assert "(resumed after output 2)" in capsys.readouterr().out
    a, b = io.load_netcdf(out), io.load_netcdf(ref)
    assert set(a.data_vars) == set(b.data_vars)
    for name in a.data_vars:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    # a checkpoint of the binned run of the same physics is refused (another run), nothing written
    bin_out = tmp_path / "b.nc"
    assert cli.main(["run", path, "--engine", "binned", "--no-progress", "--no-figure", "--out", str(bin_out),
                     "--checkpoint", str(out) + ".ckpt.npz", "--resume"]) == 2
    assert "checkpoint" in capsys.readouterr().err and not bin_out.exists()
