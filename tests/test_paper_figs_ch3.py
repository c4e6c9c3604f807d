"""Smoke-and-numbers test of the chapter-3 paper figures (thesis Figs 3.1-3.4) in --quick mode.

Each script's ``main(["--quick", "--out", tmp])`` returns its check points (computed vs reference,
thesis ch. 3 and independent float64 values); all must be within tolerance and the PNG must exist.
"""

import pathlib

import pytest

from _scripts import ROOT, load_script  # noqa: E402  (shared script loader)

FIGS = ROOT / "paper_figs"


def _load(name):
    return load_script(FIGS / f"{name}.py", "_paper_fig_")


EXPECTED = {
    "fig3_1_ystar": {"root y_a (RHS=0)": 1.6003688037229952, "F(1) (root at St=1)": -0.5,
                     "eq3.22 St(St*=1), b/a=1": 0.670440},
    "fig3_2_tstar": {"St*(0.3) exact": 0.4302, "St*(0.3) ya=1.6": 0.48, "St*(0.3) ch03": 0.3940},
    "fig3_3_dv": {"St2->0, St1=0.3": 8.588253e-1, "identical, St1=0.3": 7.119773e-1,
                  "peak value (St2->0)": 1.226468, "peak St1 (St2->0)": 0.964145},
    "fig3_4_contours": {"max along St2->0, exact: value": 1.226468, "max along St2->0, ya: St1": 0.625,
                        "max along St2->0, ch03: value": 1.105917},
}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_quick_figure(name, tmp_path):
    res = _load(name).main(["--quick", "--out", str(tmp_path)])
    png = pathlib.Path(res["png"])
    assert png.exists() and png.stat().st_size > 10_000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = {k: v for k, v in res["checks"].items() if not v["ok"]}
    assert not bad, bad
    assert res["all_ok"]
    for key, ref in EXPECTED[name].items():
        row = res["checks"][key]
        assert row["reference"] == ref
        assert abs(row["rel_diff"]) <= row["tol"]
        assert abs(row["computed"] - ref) <= 1e-3 * abs(ref)
