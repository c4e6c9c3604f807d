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
    analytic = pytest.importorskip("jaxcoag.analytic")
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
    pytest.importorskip("jaxcoag.binned")
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
