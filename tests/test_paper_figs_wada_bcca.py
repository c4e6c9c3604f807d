"""Wada et al. (2007) Figs. 4 and 10 (2-D BCCA gallery and size law, eq. 53) in --quick mode.

Each script's ``main(["--quick", "--out", tmp])`` returns its check points; all counted ones must pass, the PNG must
exist, and the key numbers are asserted here against the paper's law N = 1.37 (r_g/r1)^1.57.
"""

from _scripts import ROOT, run_quick_figure  # noqa: E402  (shared script loader)

FIGS = ROOT / "paper_figs"


def _run(name, tmp_path):
    return run_quick_figure(FIGS / f"{name}.py", tmp_path)


def test_figW04_bcca_gallery(tmp_path):
    res = _run("figW04_bcca_gallery", tmp_path)
    c = res["checks"]
    for N in (8, 32, 128, 512, 2048):
        assert c[f"N={N}: bonds"]["computed"] == N - 1
        assert c[f"N={N}: max |bond - (2 - delta0/r1)|"]["computed"] < 1e-10
    for N in (8, 32, 128, 512):
        assert c[f"N={N}: pairs in contact besides the bonds"]["computed"] == 0
    # ensemble means within 10 % of eq. 53: r_g/r1 = 3.08, 7.44, 17.99, 43.5, 105.2
    for N, ref in [(8, 3.08), (32, 7.44), (128, 17.99), (512, 43.5), (2048, 105.2)]:
        row = next(v for k, v in c.items() if k.startswith(f"N={N}: <r_g/r1>"))
        assert abs(row["computed"] / ref - 1.0) < 0.10


def test_figW10_bcca_size(tmp_path):
    res = _run("figW10_bcca_size", tmp_path)
    assert abs(res["exponent"] - 1.57) < 0.1
    assert abs(res["prefactor"] / 1.37 - 1.0) < 0.25
