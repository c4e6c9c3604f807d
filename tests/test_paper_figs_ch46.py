"""Chapter-4 and chapter-6 paper figures in --quick mode (full runs are @slow).

Each script's ``main(["--quick", "--out", tmp])`` returns its check points (exact analytic numbers
of thesis chs. 4 and 6, like-for-like published values, and trend checks); all must pass and
the PNG must exist.
"""

import pathlib

import numpy as np
import pytest

from _scripts import ROOT, load_script  # noqa: E402

FIGS = ROOT / "paper_figs"


def _run(name, tmp_path, quick=True):
    mod = load_script(FIGS / f"{name}.py", "_paper_fig_")
    res = mod.main((["--quick"] if quick else []) + ["--out", str(tmp_path)])
    png = pathlib.Path(res["png"])
    assert png.exists() and png.stat().st_size > 10_000
    bad = {k: v for k, v in res["checks"].items() if not v["ok"]}
    assert not bad, bad
    return res


def test_fig6_cloud_trends_quick(tmp_path):
    res = _run("fig6_5_cloud_trends", tmp_path)
    an = res["analytic"]
    np.testing.assert_allclose(an["N1"], 2.68e3, rtol=5e-3)
    np.testing.assert_allclose(an["N2_over_N1"], 5.29e4, rtol=5e-3)
    np.testing.assert_allclose(an["Q_MRN"], 10.42, rtol=2e-3)
    row = res["table"]["n=1e+05 ice o09"]
    assert row["thesis_row"] == "compact"
    np.testing.assert_allclose(row["a_m"][1], 1.5e-5, rtol=0.1)  # like-for-like early growth
    sil = res["table"]["n=1e+05 silicate o09"]
    assert row["a_m"][3] > 3 * sil["a_m"][3]


@pytest.mark.slow
def test_fig6_cloud_trends_full(tmp_path):
    res = _run("fig6_5_cloud_trends", tmp_path, quick=False)
    assert len(res["table"]) == 11


def test_fig4_sticking_alpha_quick(tmp_path):
    res = _run("fig4_sticking_alpha", tmp_path)
    fr = dict(zip(res["alphas"], res["sticking"]))
    # measured: 0.72 (1e-6), 0.03 (1e-4), 0.00 (1e-2): bouncing takes over as turbulence rises
    assert fr[1e-6] > 0.5 and fr[1e-4] < 0.6 and fr[1e-2] <= fr[1e-4] <= fr[1e-6]
    assert res["checks"]["§5 example: f_p after sticking"]["ok"]


@pytest.mark.slow
def test_fig4_sticking_alpha_full(tmp_path):
    res = _run("fig4_sticking_alpha", tmp_path, quick=False)
    assert len(res["alphas"]) == 6
