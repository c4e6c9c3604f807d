"""Quick modes of the Wada et al. (2007) contact-physics figures (W-Fig. 1 JKR potential, W-Fig. 3 hysteresis).

Each script's ``main(["--quick", "--out", tmp])`` returns its check points (computed vs exact JKR constants and
the analytic hysteresis loop); all must pass and the PNG must exist.
"""


import pytest

from _scripts import ROOT, run_quick_figure  # noqa: E402  (shared script loader)

FIGS = ROOT / "paper_figs"

EXPECTED = {
    "figW01_jkr_potential": {"quartz: U(delta_0)": -0.8 * 6.0 ** (1.0 / 3.0), "ice: U(-delta_c)": 4.0 / 45.0,
                             "quartz: F at max pull-off [F_c]": -1.0},
    "figW03_hysteresis": {"shifted equilibrium E: zero force at u/zeta_crit": 2.0,
                          "elastic slope after reversal C-E / k_s": 1.0,
                          "E_dis (eqs. 39-41) / (5 k_s zeta_crit^2)": 1.0,
                          "work / (Delta U + E_dis) (eqs. 39-41)": 1.0},
}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_quick_figure(name, tmp_path):
    res = run_quick_figure(FIGS / f"{name}.py", tmp_path)
    for key, ref in EXPECTED[name].items():
        row = res["checks"][key]
        assert row["reference"] == pytest.approx(ref, rel=1e-15)
        assert abs(row["rel_diff"]) <= row["tol"] <= 1e-4
