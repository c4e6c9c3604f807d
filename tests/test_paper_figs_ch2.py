"""Thesis ch. 2 porous vs compact figure (paper_figs/fig2_porous_vs_compact.py; T-Tab2.2, spec/collisions.md §11.1).

The quick mode runs 1 AU, alpha = 1e-4, porous (O07, psi as MC structural parameter) and compact, one
small grouped MC run each with the rain-out sink, and checks: a = a* psi^(1/3) exactly for every rained
particle, the published rows' own consistency, eq. 2.25 consistency across the published rows, and the
§11.1 claims in decades. The full run (all eight T-Tab2.1 models, 2 runs each) is marked slow.
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


def test_fig2_quick(tmp_path):
    res = load_script(FIG, "_paper_fig_ch2_").main(["--quick", "--out", str(tmp_path)])
    _check(res)
    P, C = res["models"]["R1Ta4-P"], res["models"]["R1Ta4-C"]
    # porous particles rain out much larger and heavier than compact ones (thesis: ~2 and ~4 decades)
    assert P["m"] / C["m"] > 1e3 and P["a"] / C["a"] > 30
    assert C["psi"] == 1.0
    # porous: <psi> and a/a* at rain-out near the published 86 and 4.4 (measured 87 and 4.43)
    assert 40 < P["psi"] < 180 and 3.4 < P["a_over_astar"] < 5.6
    np.testing.assert_allclose(P["a_over_astar"], P["psi"] ** (1 / 3), rtol=0.1)
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
    must = [k for k in c if "a = a* psi^1/3" in k or k.startswith("T-Tab2.2") or k.startswith("1 AU")
            or (k[:5] in ("R1Ta4", "R5Ta4", "R5Ta2") and "log10" in k)]
    bad = {k: c[k] for k in must if not c[k]["ok"]}
    assert len(must) > 15 and not bad, bad
    m = res["models"]
    for k, ref in (("R1Ta4-C", 2.6e3), ("R5Ta4-C", 8.1e3), ("R1Ta4-P", 4.7e3), ("R5Ta4-P", 1.9e4)):
        assert 0.5 * ref < m[k]["t_rain"] < 2.0 * ref
