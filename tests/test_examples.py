"""Every script in examples/ runs in quick mode, and the numbers it returns are checked against
independent references (a finite difference, the true parameters of a synthetic fit, the unsharded
or looped computation, exact mass conservation, the monomer mass, Birnstiel et al. 2012 scaling)."""

import math
import os

import numpy as np
import pytest
from _scripts import ROOT, load_script

from jaxcoag import config

EXAMPLES = sorted((ROOT / "examples").glob("[0-9][0-9]_*.py"))


def _check_01(out):
    # jax.grad of ln(sum K) w.r.t. ln alpha against a central difference (h = 1e-5: truncation and
    # round-off ~1e-10 relative; measured 5e-10)
    np.testing.assert_allclose(out["grad"], out["fd"], rtol=1e-8)
    # Delta v^2 = Delta v_BM^2 + Delta v_turb^2 + Delta v_drift^2 with Delta v_turb ∝ alpha^(1/2) ... alpha^(3/4)
    # (OC07 regimes; Re ∝ alpha), the other terms alpha-free: 0 < d ln K / d ln alpha < 3/4
    assert 0.0 < out["grad"] < 0.75


def _check_02(out):
    # Levenberg-Marquardt from a factor 3 away recovers the synthetic truth (1 % noise; measured
    # rel. errors 2.9e-4 (alpha) and 3.2e-4 (rho_g))
    assert out["true_alpha"] == 1e-4
    assert out["rel_err"] < 5e-3 and out["rel_err_rho_g"] < 5e-3
    lm = out["levenberg_marquardt"]
    np.testing.assert_allclose(lm["alpha"], 1e-4, rtol=5e-3)
    assert abs(lm["alpha"] / out["true_alpha"] - 1.0) == pytest.approx(out["rel_err"], rel=1e-12)
    # what tests/test_fit.py::test_levenberg_marquardt_recovers (the same quick nebula_box and fit, now
    # slow) asserts: the optimiser succeeds, the first step cuts the loss 1000x, and the final loss is
    # the noise floor (1 % noise on sqrt(y): r ~ 0.005 sqrt(y))
    assert lm["result"] == "successful"
    assert lm["history"][1] < 1e-3 * lm["history"][0]
    target = np.asarray(out["target"])
    assert lm["loss"] < 0.5 * np.sum((0.005 * 3 * np.sqrt(np.maximum(target, 0))) ** 2)


def _check_03(out):
    # 4 x 4 grid, no failed member; the vmapped sweep equals the Python loop of jitted solves (the
    # same compiled solve per member: measured 0.0)
    assert out["n_points"] == 16 and out["n_failed"] == 0
    assert out["max_rel_diff"] <= 1e-12
    # stronger turbulence grows the mass peak faster (turbulence-dominated relative velocities)
    assert out["dlnmp_dlnalpha"] > 0.5


def _check_04(out):
    # the sharded sweep (over however many devices exist) equals the unsharded one
    assert out["n_members"] == 9 and out["n_devices"] >= 1
    assert out["same_status"] is True
    assert out["rel_diff"] <= 1e-12


def _check_05(out):
    cfg = config.load(ROOT / "examples" / "scenes" / "ch4_disk_3au.toml")
    assert out["rc_run"] == 0 and out["rc_plot"] == 0
    # the first output's mass peak is the monomer bin: m0 = 4/3 pi a0^3 rho_s of the scene file
    m0 = 4.0 / 3.0 * math.pi * cfg["dust"]["a0"] ** 3 * cfg["dust"]["rho_s"]
    np.testing.assert_allclose(out["m_peak_first"], m0, rtol=1e-10)
    # mass is conserved to round-off by the coagulation-fragmentation solve (measured 2.5e-15)
    assert out["max_abs_mass_drift"] < 1e-12
    # fragmentation barrier (Birnstiel et al. 2012): the peak sits below St_frag = v_frag^2 / (3 alpha c_s^2)
    # (measured 0.54 St_frag), and m_peak ∝ alpha^-3 for turbulence-dominated Epstein fragmentation
    # (measured slope -2.82 between alpha = 1e-4 and 4e-4)
    assert 0.2 * out["st_frag"] < out["st_peak"] < out["st_frag"]
    assert -3.5 < out["dlnm_dlnalpha"] < -2.5
    assert out["m_peak"] > 1e6 * m0


def _check_06(out):
    # Levenberg-Marquardt from alpha x 3, v_frag / 3 recovers DustPy's defaults from the 1 %-noise profile; the errors
    # are the noise's (measured 1.4e-3 and 3.5e-4, within 1 Fisher sigma 1.9e-3 and 2.4e-3)
    lm = out["levenberg_marquardt"]
    assert lm["successful"]
    sig = out["sigma_ln_params"]
    assert abs(lm["rel_err_alpha"]) < max(3 * sig[0], 1e-3) and abs(lm["rel_err_v_frag"]) < max(3 * sig[1], 1e-3)
    assert abs(lm["rel_err_alpha"]) < 1e-2 and abs(lm["rel_err_v_frag"]) < 1e-2
    # chi^2/2 falls from the start to the noise floor (expected n_data/2 = 16 for the residuals in noise units)
    assert lm["loss0"] > 1e3 * lm["loss"]
    assert lm["loss"] < out["n_data"]
    # alpha and v_frag are constrained separately, not only through v_frag^2 / alpha (measured correlation 0.22)
    assert out["jacobian_column_correlation"] < 0.9


def _check_07(out):
    # 2 x 2 disks; the vmapped sweep equals the loop of jitted solves (measured 8.8e-15) and the sharded sweep the
    # unsharded one (measured 0.0, one device)
    assert out["n_members"] == 4 and out["n_failed"] == 0
    assert out["rel_diff_loop"] < 1e-10 and out["rel_diff_sharded"] < 1e-10
    assert out["dims"] == ["alpha", "v_frag", "t", "r"]
    # stronger turbulence at v_frag = 2 m/s grows the innermost grains faster within 1000 yr (measured a_mean
    # 1.7e-3 cm at alpha = 3e-4 and 1.4e-2 cm at 3e-3)
    a = np.asarray(out["a_mean_last_inner"])
    assert a[1, 1] > 3 * a[0, 1]


def _check_08(out):
    from jaxcoag.physics.wada07 import wada_energy_ratio

    m1, v0 = out["m1"], out["v0"]
    n = np.asarray(out["n_total"])[:, None]
    v = np.asarray(out["v_over_v0"])[None, :]
    x = np.asarray(out["x_break"])
    fl = np.asarray(out["f_large"])
    # the measured table's energies against Wada et al. (2007) §5.1: E_imp = N m_1 v^2/8 and
    # x_break = N (v/v0)^2 / (8 c_break (N - 2)) (physics.wada07, independent of the bridge)
    np.testing.assert_allclose(out["e_imp"], n * m1 * (v * v0) ** 2 / 8.0, rtol=1e-12)
    np.testing.assert_allclose(x, np.asarray(wada_energy_ratio(n, v)), rtol=1e-12)
    assert np.all(np.asarray(out["n_runs"]) >= 1)  # no failed DEM run left out
    # Wada et al. (2007) §5.5, Fig. 14: no monomer is lost below ~3 n_k E_break (checked where x_break < 1, a factor
    # 3 below) and disruption is catastrophic (N_large/N_total <= 1/2) above ~10 n_k E_break (checked where
    # x_break >= 20, a factor 2 above); the sweep reaches both regimes
    assert np.any(x < 1.0) and np.all(fl[x < 1.0] == 1.0)
    assert np.any(x >= 20.0) and np.all(fl[x >= 20.0] <= 0.5)
    # the outcome uses the running minimum of the table's N_large/N_total along energy (the table itself) ...
    fl_mono = np.minimum.accumulate(fl, axis=1)
    np.testing.assert_allclose(out["f_frag_dem"], 1.0 - fl_mono, rtol=0, atol=1e-15)
    for i in range(fl.shape[0]):  # ... and loses half the mass where that falls to 1/2 (linear in ln x_break)
        if fl_mono[i, 0] > 0.5 >= fl_mono[i, -1]:
            j = int(np.argmax(fl_mono[i] <= 0.5))
            lx = np.log(x[i, j - 1]) + (fl_mono[i, j - 1] - 0.5) / (fl_mono[i, j - 1] - fl_mono[i, j]) * np.log(
                x[i, j] / x[i, j - 1])
            np.testing.assert_allclose(out["x_half_dem"][i], np.exp(lx), rtol=1e-12)
    # the hand-copied recipe: Dominik & Tielens (1997) / Wada et al. (2007) thresholds as bridged in Ormel (2008)
    # Tab. 1.1: no loss below 3 n_k E_break, linear in ln E to 1/2 at 10 n_k E_break and to 1 at 30
    ref = np.clip(0.5 * np.log(x / 3.0) / np.log(10.0 / 3.0), 0.0, 0.5) + np.clip(0.5 * np.log(x / 10.0) / np.log(3.0),
                                                                                   0.0, 0.5)
    np.testing.assert_allclose(out["f_frag_dt"], ref, rtol=1e-12, atol=1e-15)
    # the coagulation boxes: successful (the Monte Carlo runs group equal masses with Ns* = 1000; with exact species
    # DSMC the DEM table's real-valued fragment masses exhausted 4000 slots) and mass conserved to round-off
    # (measured <= 1.2e-15 binned, 0 Monte Carlo)
    t = np.asarray(out["t_out"])
    stick = 1.0 + out["k0"] * out["n0"] * t  # constant kernel from monomers: <m>_m/m_1 = 1 + K0 n0 t (Smoluchowski)
    assert len(out["box"]) == 4
    for name, b in out["box"].items():
        assert b["status"] == "successful", name
        assert b["drift"] < 1e-12, name
        mm = np.asarray(b["mean_mass"])
        # t = 1 s: the pairs present have x_break < 2 (their fragment mass stays below one monomer in both
        # recipes), so the box still follows pure sticking; band 8 %: ~330 Monte Carlo events by then, so
        # <m>_m - 1 fluctuates by ~1/sqrt(330) ~ 5 % of itself, 3 sigma ~ 8 % of <m>_m = 2 (measured -1.5 %
        # Monte Carlo, +0.6 % binned)
        np.testing.assert_allclose(mm[0], stick[0], rtol=0.08, err_msg=name)
        assert mm[-1] < 0.5 * stick[-1], name  # fragmentation-limited: far below the sticking value at the end
    # the two engines agree on <m>_m at the last output for both outcomes (measured -4.3 % and -1.5 %; band 15 %:
    # Monte Carlo noise of the mass-weighted mean over the ~1000/<m>_m particles that carry the mass, and the
    # binned grid's resolution)
    for name, d in out["mc_over_binned_minus_1"].items():
        assert abs(d) < 0.15, (name, d)


CHECKS = {"01_velocities_and_kernel": _check_01, "02_fit_nebula_parameters": _check_02,
          "03_parameter_sweep": _check_03, "04_sharded_sweep": _check_04, "05_cli_run": _check_05,
          "06_fit_disk_alpha_vfrag": _check_06, "07_disk_ensemble": _check_07, "08_contact_to_coagulation": _check_08}
# the disk examples compile the radial disk's time loop (and its Jacobian): 40 s each on 2 cores, over the default
# suite's budget; they run with -m slow. Example 08 runs a DEM sweep and four coagulation boxes (minutes on 2 cores);
# its parts run by default in tests/test_contact_collide.py (collide, the default end, checkpoints) and
# tests/test_contact_bridge.py (outcome_from_collisions: interpolation, sticking limit, binned box mass
# conservation, Monte Carlo products).
SLOW = {"06_fit_disk_alpha_vfrag", "07_disk_ensemble", "08_contact_to_coagulation"}


def test_every_example_has_checks():
    assert {p.stem for p in EXAMPLES} == set(CHECKS)


def _tree(d):
    return sorted(os.path.relpath(os.path.join(r, f), d) for r, _, fs in os.walk(d) for f in fs)


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.stem in SLOW else p for p in EXAMPLES],
                         ids=[p.stem for p in EXAMPLES])
def test_example_quick(path, capsys, tmp_path, monkeypatch):
    argv = ["--quick"]
    if path.stem == "05_cli_run":
        # the same run also checks where example 05 writes (one run of the example instead of two; the
        # default output directory is checked in tests/test_output_readable.py): from an empty working
        # directory with --out, every file goes into --out, nothing into the working directory or examples/
        cwd = tmp_path / "cwd"
        cwd.mkdir()
        monkeypatch.chdir(cwd)
        before = _tree(ROOT / "examples")
        argv += ["--out", str(tmp_path / "out")]
    out = load_script(path, "_example_").main(argv)
    assert capsys.readouterr().out.strip()
    CHECKS[path.stem](out)
    if path.stem == "05_cli_run":
        assert _tree(cwd) == []
        assert _tree(ROOT / "examples") == before
        assert {"ch4_3au.nc", "ch4_3au.png", "ch4_3au_replot.png"} <= set(_tree(tmp_path / "out"))
