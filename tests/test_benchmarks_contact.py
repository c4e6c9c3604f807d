"""Contact-DEM throughput benchmark (``benchmarks/contact_throughput.py``) and its LAMMPS peer: our side only.

LAMMPS is not installed in CI; these tests check what the comparison rests on without it:

* the head-on set-up shared by both codes (Wada et al. 2007 §4, the placement of ``contact.collide``): the
  closest pair is exactly 2.05 r1 apart, velocities +-v_imp/2, zero momentum;
* the cgs -> LAMMPS ``units nano`` conversion of the ice material (Wada et al. 2007 Table 2; spec B1 values
  k_s = 79.18 N/m, k_r = 3.7699 N/m, F_fric = 0.7237 F_c) and the input deck (time step in ns);
* the sticking speed of two monomers when contacts break at the pull-off point, 1.3594 v_0 (from the JKR
  potential, Wada et al. 2007 eq. 6), vs Wada's 1.93443 v_0;
* (slow) a quick run of the benchmark's own side, whose JSON must be internally consistent.
"""

import json
import math

import numpy as np
import pytest

from benchmarks import contact_throughput as B
from benchmarks.peers import lammps_contact as L


def _two_chains(r1):
    """Two straight 4-monomer chains along y, centred on their centres of mass (bond length 2 r1)."""
    a = np.stack([np.zeros(4), (np.arange(4) - 1.5) * 2 * r1], axis=1)
    return a, a.copy()


def test_head_on_setup_gap_and_velocities():
    r1 = 1e-5
    a, b = _two_chains(r1)
    v_imp = 1755.0
    x, v = B.head_on_pair(a, b, v_imp, r1)
    # side by side chains: b is placed at x = 2 r1 + 0.05 r1
    assert x[4:, 0] == pytest.approx(np.full(4, 2.05 * r1), rel=1e-14)
    assert B.closest_gap(x, 4, r1) == pytest.approx(0.05 * r1, rel=1e-10)
    assert np.all(v[:4, 0] == 0.5 * v_imp) and np.all(v[4:, 0] == -0.5 * v_imp) and np.all(v[:, 1] == 0.0)
    assert abs(v.sum(axis=0)).max() == 0.0


def test_head_on_setup_offset_pair():
    """A 3-D pair offset laterally by rho = r1 ends sqrt(2.05^2 - 1) r1 apart along x (distance 2.05 r1)."""
    r1 = 1e-5
    a = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -2.0 * r1]])
    b = np.array([[0.0, r1, 0.0], [0.0, 5.0 * r1, 0.0]])   # the second monomer of b misses a (rho > 2.05 r1)
    x, v = B.head_on_pair(a, b, 100.0, r1)
    assert x[2, 0] == pytest.approx(math.sqrt(2.05**2 - 1.0) * r1, rel=1e-14)
    assert B.closest_gap(x, 2, r1) == pytest.approx(0.05 * r1, rel=1e-10)
    assert B.throughput(512, 2000, 4.0) == 256000.0


def test_lammps_nano_units_ice():
    from jaxcoag.aggregates.contact.materials import ice

    c = L.lammps_coefficients(ice())
    # Table 2 of Wada et al. (2007) in units nano: E = 7 GPa = 7e3 x 1e6 Pa, gamma = 0.1 J m^-2 = 100 x 1e-3 J m^-2
    assert c["E"] == pytest.approx(7000.0, rel=1e-12)
    assert c["gamma"] == pytest.approx(100.0, rel=1e-12)
    assert c["nu"] == 0.25
    assert c["diameter"] == pytest.approx(200.0, rel=1e-12)      # nm
    assert c["density"] == pytest.approx(1e-3, rel=1e-12)        # ag nm^-3 = 1e3 g cm^-3
    # spring constants: 1 unit = 1 dyn/cm = 1e-3 N/m; spec B1: k_s = 79.18 N/m, k_r = 3.7699 N/m
    assert c["k_t"] == pytest.approx(79180.0, rel=1e-4)
    assert c["k_roll"] == pytest.approx(3769.9, rel=1e-4)
    # mu_s = F_fric/(2 F_c) = 0.7237/2; mu_roll = k_r xi_crit/(2 F_c) = 2 xi_crit/R = 2 x 2 A / 500 A
    assert c["mu_s"] == pytest.approx(0.7237 / 2.0, rel=1e-4)
    assert c["mu_roll"] == pytest.approx(0.008, rel=1e-12)
    assert L.to_nano(3.831e-12, time=1) == pytest.approx(3.831e-3, rel=1e-12)
    assert L.to_nano(100.0, length=1, time=-1) == pytest.approx(1.0, rel=1e-12)   # 1 m/s = 1 nm/ns


def test_lammps_input_deck_2d():
    from jaxcoag.aggregates.contact.materials import ice

    mat = ice()
    c = L.lammps_coefficients(mat)
    dt = 0.014 * float(mat.t_c)
    deck = L.input_deck("data.agg", c, dim=2, dt=dt, n_steps=123, skin=1e-6)
    lines = deck.splitlines()
    assert "dimension 2" in lines and "fix planar all enforce2d" in lines and "run 123" in lines
    (ts,) = [ln for ln in lines if ln.startswith("timestep")]
    assert float(ts.split()[1]) == pytest.approx(3.8307e-3, rel=1e-4)     # ns (spec B1: dt = 3.831e-12 s)
    (nb,) = [ln for ln in lines if ln.startswith("neighbor")]
    assert float(nb.split()[1]) == pytest.approx(10.0, rel=1e-12)         # 1e-6 cm = 10 nm


def test_stick_speed_pull_off_convention():
    from jaxcoag.aggregates.contact.materials import ice

    mat = ice()
    v0 = float(mat.v0)
    # U_n(2^(-2/3)) - U_n((2/3)^(2/3)) = -0.3846 + 0.846614 = 0.462014 F_c delta_c (Wada et al. 2007 eq. 6 at the
    # pull-off point a/a_0 = 2^(-2/3) and at delta = 0) -> sqrt(4 x 0.462014) v_0 = 1.359432 v_0
    assert L.stick_speed_lammps_units(mat) / v0 == pytest.approx(1.359432, rel=1e-6)
    assert L.stick_speed_lammps_units(mat) == pytest.approx(418.4, rel=1e-3)          # cm/s (ice: 4.18 m/s)
    assert float(mat.v_stick) / v0 == pytest.approx(1.93443, rel=1e-5)


@pytest.mark.slow
def test_quick_run_our_side_json(tmp_path):
    out = tmp_path / "ct.json"
    B.main(["--quick", "--no-peers", "--systems", "2d", "--no-collide", "--out", str(out)])
    data = json.loads(out.read_text())
    (r,) = data["results"]
    ours = r["ours"]
    assert r["n"] == 16 and ours["steps"] == 100 and ours["steps_done"] == 100 and ours["flags"] == 0
    assert ours["monomer_steps_per_s"] == pytest.approx(16 * 100 / ours["run_s"], rel=1e-6)
    assert ours["monomer_steps_per_s"] > 0 and ours["compile_s"] >= 0.0
    # two 8-monomer BCCAs are trees (7 bonds each); no cross contact before the gap is closed
    assert ours["n_contacts_initial"] == 14
    assert r["closest_gap_r1"] == pytest.approx(0.05, rel=1e-9)
    s = data["sweep"]
    assert s["members"] == 8 and s["max_abs_diff_x"] < 1e-12 * 1e-3
    assert s["speedup"] == pytest.approx(s["loop_s"] / s["vmap_s"], rel=1e-6)
    # the threaded sweep runs the same single integration per member: the loop's positions exactly
    assert s["workers"] >= 1 and s["max_abs_diff_x_workers"] == 0.0
    assert s["speedup_workers"] == pytest.approx(s["loop_s"] / s["workers_s"], rel=1e-6)
    assert data["machine"]["logical_cores"] >= 1
    assert out.with_suffix(".png").exists()
