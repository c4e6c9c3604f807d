"""Quick modes of the Monte Carlo paper figures (thesis Figs 2.8, 2.9, 5.3-5.9; Ormel & Spaans 2008).

Each script's ``main(["--quick", "--out", tmp])`` runs the grouped Monte Carlo engine at reduced size and
returns its check points (simulated vs analytic / published anchor). The tolerances inside the scripts are
statistical (derived from the particle/group numbers and the ensemble spread, see each docstring); here we
assert that every check passed, that the PNG exists, and re-assert the key numbers (the structural
assertions: Fig. 5.3's deterministic t = 30 bound, Fig. 5.7's t_R decreasing with N, ...).

Cost on a 2-core machine: every script compiles at least one engine configuration (~20 s each) and runs
1e4-1e5 events, so only Figs 2.8 and 5.9 (~30 s each) run by default; the others are marked ``slow``
(``pytest -m slow``; each 20 s - 4 min on a 2-core machine, except the large-N Fig 5.7 test, which runs
N = 1e20, 1e80, 1e160 with 2 runs each: up to 2.2e6 events per run, measured 13.5 min).
"""

import math
import pathlib

import pytest

from _scripts import ROOT, load_script  # noqa: E402  (shared script loader)

FIGS = ROOT / "paper_figs"


def _load(name):
    return load_script(FIGS / f"{name}.py", "_paper_fig_mc_")


def _run(name, tmp_path, *extra, quick=True):
    res = _load(name).main((["--quick"] if quick else []) + ["--out", str(tmp_path), *extra])
    png = pathlib.Path(res["png"])
    assert png.exists() and png.stat().st_size > 10_000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = {k: v for k, v in res["checks"].items() if not v["ok"]}
    assert not bad, bad
    assert res["all_ok"]
    return res["checks"], res


def _c(checks, key):
    return checks[key]["computed"]


@pytest.mark.slow  # suite budget (32 s); the constant-kernel MC against the exact solution stays in tests/test_mc_*.py
def test_fig2_8_constant_kernel_const_n(tmp_path):
    """K = 1, const-N, Np = 1000 x 4 runs, t = 1, 1e2, 1e4: moments and E_mass vs the exact solution."""
    ck, _ = _run("fig2_8_constN_constant", tmp_path)
    for t in ("1", "100", "10000"):
        gf = 1 + float(t) / 2
        tol = 4 * math.sqrt((1 + math.log(gf)) / (1000 * 4))
        assert abs(_c(ck, f"mean ln(M0/M0A) t={t}")) < tol
        assert abs(_c(ck, f"mean ln(mp/mpA) t={t}")) < tol
    assert _c(ck, "E_mass/E_floor t=1 (<=1.5)") < 1.5
    assert _c(ck, "E_mass/E_floor t=100 (<=1.5)") < 1.5
    assert _c(ck, "E_mass/E_floor t=10000 (<=2)") < 2.0


@pytest.mark.slow
def test_fig5_3_sum_fixed_np_fails_deterministically(tmp_path):
    """Sum kernel, fixed Np = 1000: fine at t = 1, deterministic failure at t = 30 (M_tot,sim < e^30)."""
    ck, _ = _run("fig5_3_sum_fixedNp", tmp_path)
    assert abs(_c(ck, "mean ln(mp/mpA) t=1")) < 4 * math.sqrt(1.5 / 3000)
    assert _c(ck, "max M_tot,sim / e^30 (<1, deterministic)") < 1.0
    assert _c(ck, "max m_p,sim / M_tot,sim (<=1)") <= 1.0
    assert _c(ck, "mean ln(mp/mpA) t=30 in [-50,-1] (failure)") < -1.0
    # 2 ln Np < 30 involves no simulation: reported, but not part of the pass flag
    assert not ck["one-particle-line crossing 2 ln Np (<30)"]["counts"]
    assert all(v["counts"] for k, v in ck.items() if not k.startswith("one-particle-line"))


@pytest.mark.slow
def test_fig2_9_const_ns_beats_const_n(tmp_path):
    """Sum kernel: const-Ns (species controller) has a smaller E_mass than const-N at t = 20, 30."""
    ck, res = _run("fig2_9_sum_constN_constNs", tmp_path)
    assert _c(ck, "E_mass(b)/E_mass(a) t=20 (<1)") < 1.0
    assert _c(ck, "E_mass(b)/E_mass(a) t=30 (<1)") < 1.0
    assert _c(ck, "(a) max M_tot,sim/e^30 (<1)") < 1.0
    assert _c(ck, "(b) Np(t=30)/Np0 (>1: Np grows)") > 1.0


@pytest.mark.slow
def test_fig5_4_sum_kernel_grouped(tmp_path):
    """Sum kernel with equal-mass (const-Ns) and distribution (const-V, N = 1e100) grouping."""
    ck, _ = _run("fig5_4_sum_grouped", tmp_path)
    for t in ("5", "10"):
        assert abs(_c(ck, f"(a) mean ln(mp/e^t) t={t}")) < 1.0
        assert _c(ck, f"(b) E_mass t={t} (<0.2)") < 0.2
        assert _c(ck, f"(b) E_num t={t} (<0.2)") < 0.2


@pytest.mark.slow
def test_fig5_5_product_kernel_gel(tmp_path):
    """Product kernel, equal-mass: pre-gel M2 and post-gel gel fraction beta(t)."""
    ck, _ = _run("fig5_5_product", tmp_path)
    assert abs(_c(ck, "mean ln(M2/M2A) t=0.4")) < 0.1
    assert abs(_c(ck, "mean ln(M2/M2A) t=0.7")) < 0.1
    # quick size: Ns* = 100 groups, 2 runs -> tolerance 0.05 + 3 sqrt(beta (1 - beta) / 200)
    assert abs(_c(ck, "gel fraction t=1.3") - 0.42297) < 0.05 + 3 * math.sqrt(0.42297 * 0.57703 / 200)
    assert abs(_c(ck, "gel fraction t=2") - 0.79681) < 0.05 + 3 * math.sqrt(0.79681 * 0.20319 / 200)
    assert _c(ck, "output times reached before the event cap") == 7


@pytest.mark.slow
def test_fig5_6_runaway_statistics(tmp_path):
    """Product kernel, distribution method: M_L2 ~ M_L1 early, separation after N^(2/3)."""
    ck, _ = _run("fig5_6_runaway_stats", tmp_path)
    early = [v for k, v in ck.items() if k.startswith("dist: min med M_L2/M_L1")][0]["computed"]
    late = [v for k, v in ck.items() if k.startswith("dist: max M_L2/M_L1")][0]["computed"]
    assert early > 0.1 and late < 0.01
    for t in ("0.5", "0.9"):
        x = _c(ck, f"dist: ln(med M_L1 / estimate) t={t} (in [-ln 20, ln 2])")
        assert -math.log(20) <= x <= math.log(2)


@pytest.mark.slow
def test_fig5_7_runaway_time_decreases_with_n(tmp_path):
    """(m_i m_j)^nu, nu = 2, 3: t_R strictly decreasing in N up to N = 1e20; exact-DSMC anchors at
    N = 300, 1e3, 1e5."""
    ck, res = _run("fig5_7_runaway_time", tmp_path)
    anchors = {2: (0.268, 0.194, 0.1198), 3: (0.0817, 0.0553, 0.0247)}
    for nu in (2, 3):
        mean = res["runaway"][nu]["mean"]
        assert res["runaway"][nu]["N"][-1] == 1e20
        assert all(b < a for a, b in zip(mean, mean[1:])), mean
        assert _c(ck, f"nu={nu}: runs without t_R") == 0
        for n, a in zip((300, 1000, 100000), anchors[nu]):
            row = ck[f"nu={nu}: t_R(N={n:g}) vs exact DSMC"]
            assert row["reference"] == a and abs(row["rel_diff"]) <= row["tol"]


@pytest.mark.slow
def test_fig5_7_runaway_time_large_n_matches_the_chain_model(tmp_path):
    """N = 1e20, 1e80, 1e160 (2 runs): t_R within 5 % + 3 s.e. of the asymptotically exact monomer-bath
    chain (jaxcoag.analytic.runaway_time_chain) at N >= 1e80, below it at 1e20, decreasing, and the last
    local slope d ln t_R / d ln ln N within 15 % of 1 - nu."""
    ck, res = _run("fig5_7_runaway_time", tmp_path, "--grid", "large", "--runs", "2", quick=False)
    for nu in (2, 3):
        mean, chain = res["runaway"][nu]["mean"], res["runaway"][nu]["chain"]
        assert res["runaway"][nu]["N"] == [1e20, 1e80, 1e160]
        assert all(b < a for a, b in zip(mean, mean[1:])), mean
        assert mean[0] < chain[0]
        for n in ("1e+80", "1e+160"):
            row = ck[f"nu={nu}: t_R(N={n}) vs monomer-bath chain"]
            assert abs(row["rel_diff"]) <= row["tol"], row
        x = _c(ck, f"nu={nu}: last slope (N>=1e80) in (1-nu) x [0.85, 1.15]")
        assert 1.15 * (1 - nu) <= x <= 0.85 * (1 - nu)
        # Fig. 5.7: the local slope steepens towards 1 - nu (last slope < first slope of this grid)
        assert _c(ck, f"nu={nu}: last slope - first slope (<0, Fig. 5.7)") < 0.0
        assert ck[f"nu={nu}: last slope - first slope (<0, Fig. 5.7)"]["counts"]


@pytest.mark.slow
def test_fig5_8_sum_fragmentation_bathtub(tmp_path):
    """K = m_i + m_j with catastrophic fragmentation: mass piles up at both ends, comparable amounts."""
    ck, _ = _run("fig5_8_sum_fragmentation", tmp_path)
    assert _c(ck, "low-end mass / max mid bin (>1)") > 1.0
    assert _c(ck, "high-end mass / max mid bin (>1)") > 1.0
    assert _c(ck, "|ln(low/high)| (<ln 3)") < math.log(3.0)


@pytest.mark.slow  # suite budget (32 s); the MC engine with fragmentation stays in tests/test_mc_*.py
def test_fig5_9_constant_fragmentation_power_law(tmp_path):
    """K = 1 with catastrophic fragmentation: steady-state m^2 f ~ m^(1/2) (Camacho 2001)."""
    ck, res = _run("fig5_9_constant_fragmentation", tmp_path)
    assert abs(res["slope"] - 0.5) < 0.2
    assert _c(ck, "snapshots reached before the event cap") == 100
