"""Quick mode of the Richardson (1995) figure scripts (paper_figs/figR*.py).

figR03 (model i, R95 Fig. 3): N0 = 200, one seed, v0 = 13 to T = 8.2 (tau = 8.9). The script's checks are
N(1.6) and N(8.2) within 3 sigma + 1 % of (R30) (sigma: the spec's Marcus-Lushnikov spread scaled to
N0 = 200 and one seed), the chi^2 p-value of the spectra against (R31) above 1e-3, N + N_C = N0 and
N_C = N_C1 exactly. It compiles the box engine (tens of seconds on 2 cores), hence ``slow``.
"""

import pathlib

import numpy as np
import pytest

from _scripts import ROOT, load_script  # noqa: E402


@pytest.mark.slow
def test_figR03_model_i_quick(tmp_path):
    mod = load_script(ROOT / "paper_figs" / "figR03_model_i.py", "_paper_fig_r95_")
    res = mod.main(["--quick", "--out", str(tmp_path)])
    png = pathlib.Path(res["png"])
    assert png.exists() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = {k: v for k, v in res["checks"].items() if v["counts"] and not v["ok"]}
    assert not bad, bad
    n, nth = np.asarray(res["n"]), np.asarray(res["n_th"])
    # N(t) decreases and stays within 3 sigma_1 + 1 % of (R30) at every output (sigma_1 <= 12 % at N0 = 200)
    assert np.all(np.diff(n) <= 0)
    assert np.all(np.abs(n / nth - 1) <= 0.35)
    assert n[-1] == pytest.approx(200 / (1 + 0.5 * 200 * 1.6755160819145563e-4 * 13.0 * 8.2), rel=0.35)
