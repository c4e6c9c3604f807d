"""Richardson (1995) model (v) (paper_figs/figR09_R12_model_v.py), the rigid box's pair list and its
capacity-overflow message (jaxcoag.aggregates.rigid.box).

Default run (< 0.1 s, no engine compile): the capacity message names the RigidBox argument to raise for each
overflow flag and not the Monte Carlo engine's. Slow (each compiles the box engine, tens of seconds on 2 cores):

* the quick mode of figR09_R12_model_v (N0 = 400 at model v's number density, T = 2): every counted check of
  the script (N + N_coag = N0 and N_coag + N_rest = N_C at every output, mass conservation, per-collision
  |dP| <= 1e-12 P_scale, |dL| <= 1e-10 L_scale, dKE <= 1e-12 KE, no rise of the total kinetic energy, f_D of
  the rendered aggregate = the diagnostics' value), its JSON equal to the returned numbers, and the box's
  pair list of the last neighbour build against scipy's periodic KD tree at the build positions: it holds
  every pair closer than R_s + R_t + skin whose spheres are in different aggregates at the end, only pairs
  closer than that, each once (s < t), and any extra pair is inside one aggregate at the end (a merge after
  the build);
* a model (iv) box with RigidBox(neighbors=1), where scipy's KD tree shows spheres with more than one
  neighbour inside the cutoff: status capacity_exceeded, a RuntimeWarning and to_xarray's status_message
  naming RigidBox(neighbors=...), and the run stopped at the first step.
"""

import json
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial import cKDTree

from _scripts import ROOT, load_script  # noqa: E402
from jaxcoag.aggregates import rigid
from jaxcoag.aggregates.rigid import box as rbox


def test_capacity_message_names_rigid_box_arguments():
    assert rbox.capacity_message(0) == ""
    log_full = rbox.capacity_message(1)
    nb_full = rbox.capacity_message(2)
    both = rbox.capacity_message(3)
    assert "RigidBox(log_capacity=...)" in log_full and "neighbors" not in log_full
    assert "RigidBox(neighbors=...)" in nb_full and "RigidBox(cell_capacity=...)" in nb_full
    assert "log_capacity" not in nb_full
    assert "log_capacity" in both and "RigidBox(neighbors=...)" in both
    for m in (log_full, nb_full, both):
        assert "Monte Carlo" not in m and "MonteCarlo" not in m and "species" not in m
    assert rbox.capacity_message(4) == ""  # bit 2 is the step budget (max_steps_reached), not a capacity


def _pairs_by_kdtree(x, R, agg, L, skin):
    """Pairs (i < j) of spheres in different aggregates with |x_i - x_j| < R_i + R_j + skin (minimum image)."""
    xw = np.mod(x, L)
    xw[xw >= L] = 0.0
    cand = cKDTree(xw, boxsize=L).query_pairs(2 * R.max() + skin, output_type="ndarray")
    d = xw[cand[:, 1]] - xw[cand[:, 0]]
    d -= L * np.round(d / L)
    keep = (np.linalg.norm(d, axis=1) < R[cand[:, 0]] + R[cand[:, 1]] + skin) & (agg[cand[:, 0]] != agg[cand[:, 1]])
    return {(int(min(i, j)), int(max(i, j))) for i, j in cand[keep]}


@pytest.mark.slow
def test_figR09_R12_model_v_quick(tmp_path):
    mod = load_script(ROOT / "paper_figs" / "figR09_R12_model_v.py", "_paper_fig_r95_v_")
    res = mod.main(["--quick", "--out", str(tmp_path)])
    png = res["png"]
    assert png.exists() and png.stat().st_size > 10_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = {k: v for k, v in res["checks"].items() if v["counts"] and not v["ok"]}
    assert not bad, bad
    num = res["numbers"]
    n0 = res["n0"]
    N, nco, nre, nc = (np.array(num[k]) for k in ("N", "n_coag", "n_rest", "N_C"))
    assert np.all(N + nco == n0) and np.all(nco + nre == nc)
    assert nc[-1] > 50 and nre[-1] > 0 and nco[-1] > 0  # both outcomes occur (R95: 62 % / 38 %)
    assert np.all(np.diff(N) <= 0) and np.all(np.diff(nc) >= 0)
    sl = num["second_largest"]
    assert sl["f_D_rendered"] == pytest.approx(sl["f_D"], rel=1e-9)
    on_disk = json.loads(res["json"].read_text())
    assert on_disk["N"] == num["N"] and on_disk["second_largest"] == sl
    # pair list of the last neighbour build vs an independent KD-tree search at the build positions
    st = res["result"].final_state
    n = int(st.n_pairs)
    got = set(zip(np.asarray(st.pair_i)[:n].tolist(), np.asarray(st.pair_j)[:n].tolist()))
    assert len(got) == n and all(i < j for i, j in got)
    x, R, L, skin = np.asarray(st.x_ref), np.asarray(st.sph_R), float(st.par["L"]), float(st.par["skin"])
    agg = np.asarray(st.sph_agg)
    # aggregates only merge after the build: pairs in different aggregates now <= the list <= all close pairs
    want_now = _pairs_by_kdtree(x, R, agg, L, skin)
    close = _pairs_by_kdtree(x, R, np.arange(len(x)), L, skin)
    assert want_now <= got <= close
    assert all(agg[i] == agg[j] for i, j in got - want_now)
    assert len(want_now) > 50  # a sample worth the comparison (95 pairs with the per-body clocks, 2026-11-28)


@pytest.mark.slow
def test_neighbour_overflow_status_message():
    b = rigid.box_model("iv", n0=64, box=10.0 * (64 / 1000) ** (1 / 3), v0=13.0, key=jax.random.key(2))
    eng = rigid.RigidBox(neighbors=1)
    x, R = np.asarray(b.x), np.asarray(b.radius)
    skin = 6.0 * float(b.r0)  # the aggregate models' default skin
    per = np.zeros(64, int)
    for i, j in _pairs_by_kdtree(x, R, np.arange(64), float(b.L), skin):
        per[i] += 1
        per[j] += 1
    assert per.max() > 1  # the reference: some sphere has more neighbours than one slot holds
    with pytest.warns(RuntimeWarning, match=r"RigidBox\(neighbors=\.\.\.\)"):
        res = rigid.run(b, jnp.array([0.05, 0.1]), engine=eng)
    assert res.to_xarray()["status"].attrs["status_name"] == "capacity_exceeded"
    msg = res.to_xarray()["status"].attrs["status_message"]
    assert msg == res.status_message == rbox.capacity_message(2)
    # stopped at the first neighbour build: nothing moved or collided
    assert int(res.outs["n_build"][-1]) == 1 and int(res.outs["n_c"][-1]) == 0
    assert int(res.outs["n_aggregates"][-1]) == 64 and float(res.final_state.t) == 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert rbox.capacity_message(int(res.outs["flags"][-1])) == msg
