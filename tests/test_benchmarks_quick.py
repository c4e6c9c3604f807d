"""Quick smoke of the benchmark scripts (our side only; the peers DustPy/PySDM are not needed).

Runs ``benchmarks/binned_accuracy_vs_time.py`` on one small configuration (constant kernel,
two-bin scheme, 4 bins/decade, one tolerance, no peers), reads the JSON it writes and asserts
numbers: a finite relative L1 error below a bound measured on this configuration (0.135 at
rtol 1e-3 and 1e-6), mass conservation, non-negative timings. Also checks the benchmarks'
independent analytic references against :mod:`jaxcoag.analytic` and the pure-numpy ratio
helpers of the Monte Carlo benchmark. Skips when the binned engine is absent.
"""

import json

import numpy as np
import pytest


def test_reference_constant_kernel_matches_jaxcoag_analytic():
    from jaxcoag import analytic
    from benchmarks import _common as C

    edges = np.geomspace(1e-14, 1e6, 20 * 7 + 1)
    for t in (1e-9, 1.0, 1e3):
        ours = C.mass_per_bin_constant_exp(edges, t, coeff=1.0, n0=1e12, m0=1e-12)
        theirs = np.asarray(analytic.mass_per_bin("constant", edges, t, coeff=1.0, n0=1e12,
                                                  m0=1e-12, initial="exponential"))
        assert C.rel_l1(theirs, ours) < 1e-10
        assert abs(ours.sum() - 1.0) < 1e-9   # mass below 1e-14 g at t = 1e-9: 2e-10


def test_reference_sum_kernel_conserves_mass():
    from benchmarks import _common as C

    edges = np.geomspace(1e-20, 1e10, 30 * 16 + 1)
    for t in (0.0, 0.9, 10.0):
        mass = C.mass_per_bin_sum_exp(edges, t, coeff=1.0, n0=1e12, m0=1e-12)
        assert np.all(np.isfinite(mass))
        assert abs(mass.sum() - 1.0) < 1e-9


def test_mc_ratio_helpers():
    from benchmarks import mc_accuracy_vs_time as M

    front = M.pareto([(1.0, 0.4), (2.0, 0.5), (4.0, 0.1), (8.0, 0.05)])
    assert front == [(1.0, 0.4), (4.0, 0.1), (8.0, 0.05)]
    # log-log interpolation: midway in log between (1, 0.4) and (4, 0.1) -> (2, 0.2)
    assert M.interp_loglog([1.0, 4.0], [0.4, 0.1], 2.0) == pytest.approx(0.2, rel=1e-12)
    assert M.interp_loglog([1.0, 4.0], [0.4, 0.1], 8.0) is None


def test_binned_benchmark_quick_json(tmp_path):
    from benchmarks import binned_accuracy_vs_time as B

    out = tmp_path / "binned.json"
    B.main(["--problems", "constant", "--schemes", "twobin", "--bpd", "4", "--rtol", "1e-4",
            "--no-peers", "--out", str(out)])
    data = json.loads(out.read_text())
    assert data["machine"]["logical_cores"] >= 1
    rows = data["results"]
    assert len(rows) == 1
    r = rows[0]
    assert r["successful"] is True
    assert np.isfinite(r["l1_final"]) and 0.0 < r["l1_final"] < 0.17
    assert abs(r["mass_drift_final"]) < 1e-10
    assert r["wall_s"] > 0.0 and r["compile_s"] >= 0.0
    assert out.with_suffix(".png").exists()


def test_sweep_throughput_quick(tmp_path):
    """4 x 4 nebula-box sweep: vmapped == chunked == looped, throughputs finite and positive."""
    from benchmarks import sweep_throughput as S

    out = S.main(["--quick", "--no-sharded", "--out", str(tmp_path / "st.json")])
    data = json.loads((tmp_path / "st.json").read_text())
    (r,) = data["results"]
    assert r["points"] == 16 and r["failed"] == 0 and r["loop_points_timed"] == 16
    for k in ("vmap_pts_per_s", "chunked_pts_per_s", "loop_pts_per_s", "vmap_over_loop"):
        assert np.isfinite(r[k]) and r[k] > 0.0, k
    assert r["max_abs_diff_vmap_loop"] < 1e-9 and r["max_abs_diff_chunked_vmap"] < 1e-9
    assert r["repeat_identical"] is True
    # ln m_peak [ln g] of 1 micron (4e-12 g) grains after 1e10 s: grown, but far below the grid top
    lo, hi = r["ln_mpeak_range"]
    assert np.log(4e-12) < lo < hi < np.log(4e-12 * 1e8)
    assert out["results"][0]["grid"] == "4x4" and (tmp_path / "st.png").exists()


@pytest.mark.slow
def test_sweep_throughput_sharded_quick(tmp_path):
    """The 4-device subprocess of the throughput benchmark: sharded == unsharded."""
    from benchmarks import sweep_throughput as S

    (r,) = S.run_sharded([3])
    assert r["n_devices"] == 4 and r["points"] == 9 and r["same_status"] is True
    assert r["max_abs_diff_sharded_unsharded"] < 1e-9
    assert r["sharded_pts_per_s"] > 0.0 and r["unsharded_pts_per_s"] > 0.0


@pytest.mark.slow
def test_gradient_cost_quick(tmp_path):
    """Gradient-cost benchmark on the smallest grid: reverse, jvp and jacfwd agree with each
    other and with central differences; cost ratios finite and positive."""
    from benchmarks import gradient_cost as Gc

    Gc.main(["--quick", "--reps", "2", "--out", str(tmp_path / "gc.json")])
    rows = json.loads((tmp_path / "gc.json").read_text())["results"]
    assert [r["fragmentation"] for r in rows] == [False, True]
    for r in rows:
        assert r["result"] == "successful" and r["bins"] == 24
        for k in ("forward_s", "reverse_ratio", "jvp_ratio", "jacfwd_ratio", "compile_reverse_s"):
            assert np.isfinite(r[k]) and r[k] > 0.0, k
        assert r["rev_vs_fwd_max_rel"] < 1e-8 and r["jvp_vs_grad0_rel"] < 1e-8
        assert r["rev_vs_fd_max_rel"] < 1e-4
        # growth speeds up with alpha and with rho_g (collision rate ~ dust density)
        assert r["grad"]["alpha"] > 0.0 and r["grad"]["rho_g"] > 0.0
