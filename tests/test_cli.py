"""`jaxcoag run / plot / sweep / config` end to end (quick mode), and refused runs: exit code 2,
the reason on stderr, no output file - one test per category of bad input."""

import os

import numpy as np
import pytest

from jaxcoag import cli, config, io, runner

from _configs import SMALL  # noqa: E402  (shared test configuration)


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
    assert ds.attrs["result"] == "successful" and int(ds["result_code"]) == 0
    t = ds["time"].values
    assert t[0] == 0 and np.all(np.diff(t) > 0)
    np.testing.assert_allclose(t[-1], 1e4 * 3.15576e7, rtol=1e-12)
    # mass conserved through growth and fragmentation
    assert np.max(np.abs(ds["mass_drift"].values)) < 1e-10
    sol = runner.solution_from_dataset(ds)
    mp = np.array([float(v) for v in __import__("jaxcoag").diagnostics.mass_peak(sol.mass_per_bin, sol.grid)])
    # grows by > 10 decades in mass from the 1 um monomers, then saturates at the fragmentation barrier
    assert mp[-1] > 1e10 * mp[0]
    np.testing.assert_allclose(mp[-1], mp[-2], rtol=1e-3)
    np.testing.assert_allclose(mp[-1], mp[-3], rtol=1e-2)
    kern = runner.kernel_from_dataset(ds)
    st_peak = float(kern.particles(mp[-1]).st)
    st_frag = 1000.0 ** 2 / (3 * 1e-3 * ds.attrs["c_g"] ** 2)
    assert 0.1 * st_frag < st_peak < st_frag  # below the Birnstiel et al. (2012) barrier, same order
    assert int(ds["segment_steps"].sum()) == int(ds["steps"])


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
    assert "resumed from segment 8" in capsys.readouterr().out


def _write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


@pytest.mark.parametrize("patch, args, words", [
    ("[gas]\nalpha = 1e-3\n", [], "Cannot declare"),  # duplicate table: invalid TOML
    ("[output]\nfigur = false\n", [], "unknown key 'figur' in section [output]"),
    ("[disk]\nR_au = 1\n", [], "unknown section [disk]"),
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
    assert ds["mass_per_bin"].shape == (4, ds.sizes["mass"])
    assert not (tmp_path / "r.png").exists() and not (tmp_path / "r.nc.ckpt.npz").exists()
    assert ds["mass_per_bin"].values[-1].argmax() > ds["mass_per_bin"].values[0].argmax()  # it grew
    # a run stopped after one output interval writes no netCDF yet (exit 1); --resume finishes it identically
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
    ref = np.asarray(single.solution.mass_per_bin)
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
    ref = np.asarray(single.solution.mass_per_bin)
    got = ds["mass_per_bin"].values[0]
    big = ref > 1e-6 * ref[0].sum()
    np.testing.assert_allclose(got[big], ref[big], rtol=1e-4)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6 * ref[0].sum())
    np.testing.assert_array_equal(got[0], ref[0])  # same initial state
    assert rows[0]["status"] == "successful"
    # the same program with one member instead of two gives the same member (deterministic; measured 2e-16)
    ds1, _ = runner.sweep_config(cfg, {"alpha": [1e-3]}, verbose=False)
    np.testing.assert_allclose(ds1["mass_per_bin"].values[0], got, rtol=1e-12, atol=1e-15 * ref[0].sum())


def test_config_subcommand_prints_the_default(capsys):
    assert cli.main(["config"]) == 0
    text = capsys.readouterr().out
    assert config.loads(text).data == config.default().data
    assert cli.main(["config", "--resolved"]) == 0
    resolved = capsys.readouterr().out
    assert "m_min = " in resolved and "m0 = " in resolved  # computed defaults are shown


@pytest.mark.slow
def test_full_default_run_reaches_the_fragmentation_barrier(tmp_path):
    """The README main job at full resolution (135 bins, 16 outputs to 1e4 yr; ~1-4 min on 2 cores)."""
    res = runner.run(out=str(tmp_path / "run.nc"), progress=False, verbose=False)
    assert res.finished and not res.failed and res.numbers["result"] == "successful"
    assert res.numbers["max_abs_mass_drift"] < 1e-12
    mp = np.array([r["m_peak"] for r in res.rows])
    np.testing.assert_allclose(mp[-6:], mp[-1], rtol=1e-4)  # steady for the last ~1e4 yr
    np.testing.assert_allclose(mp[-1], 773.07, rtol=1e-3)  # measured 773.07 g (a = 4.87 cm)
    assert 0.3 * res.numbers["st_frag"] < res.numbers["st_peak"] < res.numbers["st_frag"]
    assert os.path.getsize(res.figure) > 50_000


def test_solver_failure_exits_1_and_saves_the_outputs_before_it(tmp_path, capsys):
    out = tmp_path / "f.nc"
    rc = cli.main([_write(tmp_path, SMALL), "--no-progress", "--no-figure", "--set", "solver.max_steps=3",
                   "--out", str(out)])
    assert rc == 1
    assert "result: max_steps_reached" in capsys.readouterr().out
    ds = io.load_netcdf(out)
    assert ds.attrs["result"] == "max_steps_reached" and int(ds["result_code"]) != 0
    assert ds.sizes["time"] >= 1 and np.all(np.isfinite(ds["mass_per_bin"].values))


def _interrupt_at(monkeypatch, n):
    """Patch the segment solver so that the n-th output interval raises KeyboardInterrupt (Ctrl-C)."""
    from jaxcoag import checkpoint as ckmod

    real = ckmod._segment_solver

    def patched(*a, **k):
        step = real(*a, **k)
        calls = []

        def maybe_interrupted(y, t0, t1):
            calls.append(t1)
            if len(calls) == n:
                raise KeyboardInterrupt
            return step(y, t0, t1)

        return maybe_interrupted

    monkeypatch.setattr(ckmod, "_segment_solver", patched)
    return real


def test_ctrl_c_checkpoints_prints_the_resume_command_and_exits_130(tmp_path, capsys, monkeypatch):
    """Ctrl-C in the 2nd of 3 output intervals: exit 130, the completed interval is in the
    checkpoint (no netCDF yet), stderr ends with the exact command that resumes; running that
    command finishes the run bit for bit like an uninterrupted one."""
    import shlex

    from jaxcoag import checkpoint as ckmod

    path = _write(tmp_path, SMALL)
    out = tmp_path / "int" / "r.nc"
    real = _interrupt_at(monkeypatch, 2)
    argv = ["run", path, "--no-progress", "--no-figure", "--out", str(out)]
    assert cli.main(argv) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-2] == f"jaxcoag run: interrupted after 1 of 3 output intervals; checkpoint saved to {out}.ckpt.npz"
    assert err[-1] == "resume with: " + shlex.join(["jaxcoag"] + argv + ["--resume"])
    ck = ckmod.load_checkpoint(str(out) + ".ckpt.npz")
    assert ck["ys"].shape[0] == 2 and ck["steps"].size == 1 and not out.exists()
    # --no-checkpoint: nothing to save; the message says so and nothing is written
    out2 = tmp_path / "nock" / "r.nc"
    argv2 = ["run", path, "--no-progress", "--no-figure", "--no-checkpoint", "--out", str(out2)]
    assert cli.main(argv2) == 130
    err2 = capsys.readouterr().err.strip().splitlines()
    assert err2[-2] == "jaxcoag run: interrupted; no checkpoint was saved (--no-checkpoint)."
    assert not (tmp_path / "nock").exists()
    monkeypatch.setattr(ckmod, "_segment_solver", real)
    cmd = shlex.split(err[-1][len("resume with: "):])
    assert cmd[0] == "jaxcoag" and cli.main(cmd[1:]) == 0
    assert "(resumed from segment 1)" in capsys.readouterr().out
    ref = tmp_path / "ref.nc"
    assert cli.main(["run", path, "--no-progress", "--no-figure", "--no-checkpoint", "--out", str(ref)]) == 0
    a, b = io.load_netcdf(out), io.load_netcdf(ref)
    np.testing.assert_array_equal(a["mass_per_bin"].values, b["mass_per_bin"].values)
    np.testing.assert_array_equal(a["segment_steps"].values, b["segment_steps"].values)


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
    assert 1 <= n_done < 300 and not out.exists()
    again = shlex.split(lines[-1][len("resume with: "):])
    r = subprocess.run([sys.executable, "-m", "jaxcoag.cli"] + again[1:], capture_output=True, text=True,
                       cwd=tmp_path, timeout=500)
    assert r.returncode == 0, r.stderr
    assert f"(resumed from segment {n_done})" in r.stdout
    ref = runner.run(config.loads(text), out=tmp_path / "ref.nc", save=False, progress=False, verbose=False)
    np.testing.assert_array_equal(io.load_netcdf(out)["mass_per_bin"].values,
                                  np.asarray(ref.solution.mass_per_bin))
