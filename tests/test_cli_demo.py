"""The README main job (`jaxcoag demo`) in quick mode: numbers, figure, and refusal of bad input."""

import json
import os

import numpy as np

from jaxcoag import cli, constants as C
from jaxcoag.physics import gas as G


def test_demo_quick_numbers_and_outputs(tmp_path, capsys):
    rc = cli.main(["demo", "--quick", "--out", str(tmp_path)])
    assert rc == 0
    out = capsys.readouterr().out
    assert "N x N kernel matrix" in out
    res = json.load(open(tmp_path / "demo.json"))
    assert os.path.getsize(tmp_path / "demo_velocities.png") > 10_000
    assert res["kernel_finite"]
    gas = G.ch4_disk(3 * C.AU)
    rows = res["rows"]
    # row 1 is a 1 um grain against the 1 um partner: pure Brownian (identical, tightly coupled)
    a, rho_s = rows[1]["a_cm"], 3.0
    m = 4 / 3 * np.pi * rho_s * a ** 3
    dv_bm = np.sqrt(8 * C.k_B * float(gas.T) / np.pi * 2 / m)
    np.testing.assert_allclose(rows[1]["dv_brownian"], dv_bm, rtol=1e-10)
    assert rows[1]["dv_turbulence"] == 0.0 and rows[1]["dv_radial"] == 0.0
    np.testing.assert_allclose(rows[1]["kernel"], np.pi * (2 * a) ** 2 * dv_bm, rtol=1e-10)
    # thesis eqs. 2.1/4.4 at T = 162 K (rho_s = 3, a = 1 um) give 9.5209e-2; the ch4 3 AU temperature is 161.66 K
    np.testing.assert_allclose(rows[1]["dv_brownian"], 9.5209e-2 * np.sqrt(float(gas.T) / 162.0), rtol=1e-4)
    # the Stokes numbers are St = rho_s a / (c_g rho_g) Omega in the Epstein regime
    st0 = rho_s * rows[0]["a_cm"] / (float(gas.c_g) * float(gas.rho_g)) * float(gas.Omega)
    np.testing.assert_allclose(rows[0]["St"], st0, rtol=1e-12)
    # totals are quadrature sums of the components
    for r in rows:
        np.testing.assert_allclose(r["dv_total"] ** 2, r["dv_brownian"] ** 2 + r["dv_turbulence"] ** 2 + r["dv_radial"] ** 2, rtol=1e-10)


def test_demo_refuses_bad_input_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "o"
    rc = cli.main(["demo", "--quick", "--alpha", "-1", "--out", str(out)])
    assert rc == 2
    assert "alpha" in capsys.readouterr().err
    assert not out.exists()
