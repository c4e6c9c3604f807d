"""Thesis ch. 2 porous vs compact figure (paper_figs/fig2_porous_vs_compact.py; thesis Tab. 2.2).

The quick mode runs 1 AU, alpha = 1e-4, porous (O07, psi as MC structural parameter) and compact, one
small grouped MC run each with the rain-out sink (the porous zoom mass from a pilot run to the first
rain-out, ``jaxcoag.scenes.mc_setups.ch2_pilot``), and checks: a = a* psi^(1/3) exactly for every rained
particle, the §11.1 claims in decades, the rain-out size of eq. 2.25 computed independently from the
gas, the pilot's <psi> against the published one and its rain-out mass against eq. 2.25, and that the
published rows' own consistency checks (no simulation) are reported but not counted.
The full run (all eight T-Tab2.1 models, 2 runs each) is marked slow.
"""

import math
import pathlib

import numpy as np
import pytest

from _scripts import ROOT, load_script  # noqa: E402

FIG = ROOT / "paper_figs" / "fig2_porous_vs_compact.py"


def _check(res):
    png = pathlib.Path(res["png"])
    assert png.exists() and png.stat().st_size > 10_000
    bad = {k: v for k, v in res["checks"].items() if not v["ok"]}
    assert not bad, bad
    assert res["all_ok"]


@pytest.mark.slow  # 84 s in the default run (a porous and a compact Monte Carlo run with a two-pass pilot, compile-bound);
# the default run keeps porous Monte Carlo growth (tests/test_mc_porous.py) and the ch. 2 porosity physics
# (tests/test_scene_porosity.py, tests/test_porosity.py); this figure's numbers run with -m slow
def test_fig2_quick(tmp_path):
    res = load_script(FIG, "_paper_fig_ch2_").main(["--quick", "--out", str(tmp_path)])
    _check(res)
    P, C = res["models"]["R1Ta4-P"], res["models"]["R1Ta4-C"]
    # porous particles rain out much larger and heavier than compact ones (thesis: ~2 and ~4 decades)
    assert P["m"] / C["m"] > 1e3 and P["a"] / C["a"] > 30
    assert C["psi"] == 1.0
    # porous: <psi> and a/a* at rain-out near the published 86 and 4.4 (measured 91.9 and 4.51)
    assert 40 < P["psi"] < 180 and 3.4 < P["a_over_astar"] < 5.6
    # eq. 2.25 from the gas alone: tau_f = rho_s a* / (c_g rho_g psi^(2/3)) = rho_s a / (c_g rho_g psi)
    # reaches tau_rain = alpha/Omega at a/psi = a_rain = alpha c_g rho_g / (Omega rho_s). A rained
    # particle has just crossed it: compact <a> in [1, 3^(1/3)] a_rain (at most an m* group added, m* =
    # 2 m_rain), porous <a>/<psi> (a ratio of means) within [0.9, 1.45] a_rain. Measured 1.04 and 1.05.
    from jaxcoag.physics import gas as G
    from jaxcoag import constants as K

    g = G.mmsn_hayashi81(K.AU, 1e-4)
    gz = G.mmsn_hayashi81(K.AU, 1e-4, z=float(g.H_g))  # the thesis layer z = H_g
    np.testing.assert_allclose(float(gz.rho_g), float(g.rho_g) * math.exp(-0.5), rtol=1e-12)
    omega = math.sqrt(K.G * K.M_sun / K.AU ** 3)
    a_rain = 1e-4 * float(gz.c_g) * float(gz.rho_g) / (omega * 3.0)  # quartz rho_s = 3
    assert 1.0 <= C["a"] / a_rain <= 3 ** (1 / 3)
    assert 0.9 <= (P["a"] / P["psi"]) / a_rain <= 1.45
    # the zoom mass comes from a run, not from the published <psi>: the pilot's <psi>_m at
    # the first rain-out reproduces the published 86 within 0.7-1.4x (measured 80.7 -> 83.0 over its two
    # passes; 9 single runs at Ns* = 16 gave 78-98, sd 7.6 = 9 %, so the band is about +-4 sd)
    pl = res["pilots"]["R1Ta4-P"]
    assert 60.0 < pl["psi"] < 120.0 and len(pl["psi_passes"]) == 2
    # its m_rain_est is the 40-per-decade grid root of eq. 2.25 with that psi: a* = a_rain psi^(2/3)
    m_exact = 4 * math.pi / 3 * 3.0 * (a_rain * pl["psi"] ** (2 / 3)) ** 3
    assert 1.0 < pl["m_rain_est"] / m_exact <= 10 ** (1 / 40) * (1 + 1e-12)
    np.testing.assert_allclose(pl["m_end"], 2.0 * pl["m_rain_est"], rtol=1e-12)  # zoom m* = 2 m_rain
    # the table-only checks are reported but do not count toward the pass flag
    c = res["checks"]
    table_only = [k for k in c if k.startswith("T-Tab2.2")]
    assert len(table_only) == 9 and not any(c[k]["counts"] for k in table_only)
    assert all(c[k]["counts"] for k in c if k not in table_only)
    # compact: t_rain within a factor 2 of the published 2.6e3 yr
    assert 1.3e3 < C["t_rain"] < 5.2e3
    # eq. 2.25 in our gas vs the published rows: the same factor ~1.8 for every Epstein-regime row
    # (R1Ta2-P, a = 7.8 cm, is in the Stokes regime here: 2.19)
    r = res["implied_tau_ratio"]
    assert all(1.7 < r[k] < 1.9 for k in r if k != "R1Ta2-P") and 2.0 < r["R1Ta2-P"] < 2.4


@pytest.mark.slow
def test_fig2_full(tmp_path):
    """All eight T-Tab2.1 models (Ns* = 60, 2 runs each). The alpha = 1e-6 models and R1Ta2-P are known
    to differ (see the script docstring), so the assertions name the checks that must hold."""
    res = load_script(FIG, "_paper_fig_ch2_full_").main(["--out", str(tmp_path)])
    png = pathlib.Path(res["png"])
    assert png.exists() and png.stat().st_size > 10_000
    c = res["checks"]
    must = [k for k in c if "a = a* psi^1/3" in k or k.startswith("1 AU")
            or (k[:5] in ("R1Ta4", "R5Ta4", "R5Ta2") and "log10" in k)]
    bad = {k: c[k] for k in must if not c[k]["ok"]}
    assert len(must) > 15 and not bad, bad
    assert all(c[k]["counts"] for k in must)
    m = res["models"]
    for k, ref in (("R1Ta4-C", 2.6e3), ("R5Ta4-C", 8.1e3), ("R1Ta4-P", 4.7e3), ("R5Ta4-P", 1.9e4)):
        assert 0.5 * ref < m[k]["t_rain"] < 2.0 * ref
