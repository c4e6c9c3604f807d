"""Thesis ch. 6 tabulated recipe: thesis §6.3-6.5 (printed Tabs. 6.7/6.9, interpolation, erratum 14,
loader, surrogate, outcome assembly and mass conservation)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag._validate import JaxcoagInputError
from jaxcoag.physics import recipes as RC
from jaxcoag.physics.contact import Material
from jaxcoag.physics.porosity import phi_hit_and_stick_o09

T = RC.RecipeTables.surrogate()


def test_eps_grids_match_velocity_law():
    v_g = np.array([0.05, 0.3, 0.5, 0.75, 1, 2, 4, 6, 8])
    np.testing.assert_allclose(RC.GLOBAL_EPS, 0.228827 * v_g**2, rtol=1e-4)
    v_l = np.array([1, 2, 4, 8, 12, 16])
    np.testing.assert_allclose(RC.LOCAL_EPS, 0.228847 * v_l**2, rtol=1e-4)


def test_interp_weights_S2():
    grid = jnp.array(RC.GLOBAL_EPS)
    e = jnp.array([0.3, 1.0, 5.0])
    i, w = RC.interp_weights(grid, e)
    e1, e2 = grid[i], grid[i + 1]
    # lower-node probability P(eps1) = (eps2 - eps)/(eps2 - eps1) (erratum 14 fixed)
    np.testing.assert_allclose(np.asarray(1 - w), np.asarray((e2 - e) / (e2 - e1)), rtol=1e-14)
    np.testing.assert_array_equal(np.asarray(i), [4, 5, 6])
    # clamping outside the grid
    i, w = RC.interp_weights(grid, jnp.array([1e-6, 1e3]))
    np.testing.assert_array_equal(np.asarray(i), [0, 7])
    np.testing.assert_array_equal(np.asarray(w), [0.0, 1.0])


def test_printed_tables_reproduced_at_nodes():
    E, P = np.meshgrid(RC.GLOBAL_EPS, RC.GLOBAL_PHI, indexing="ij")
    got = RC.interpolate(T.glob, "fpwl", E, P, 0.0)
    np.testing.assert_allclose(np.asarray(got), np.array(RC.TAB6_7), rtol=1e-14, atol=0)
    E, P = np.meshgrid(RC.LOCAL_EPS, RC.LOCAL_PHI, indexing="ij")
    got = RC.interpolate(T.loc, "fpwl", E, P, 0.0)
    np.testing.assert_allclose(np.asarray(got), np.array(RC.TAB6_9), rtol=1e-14, atol=0)


def test_bilinear_midpoints_and_log_option():
    tab = np.array(RC.TAB6_9)
    e1, e2 = RC.LOCAL_EPS[2], RC.LOCAL_EPS[3]
    p1, p2 = RC.LOCAL_PHI[1], RC.LOCAL_PHI[2]
    em, pm = 0.5 * (e1 + e2), 0.5 * (p1 + p2)
    want = 0.25 * (tab[2, 1] + tab[2, 2] + tab[3, 1] + tab[3, 2])
    np.testing.assert_allclose(float(RC.interpolate(T.loc, "fpwl", em, pm, 0.0)), want, rtol=1e-12)
    # log_eps: the geometric midpoint gets weight 1/2
    eg = np.sqrt(e1 * e2)
    np.testing.assert_allclose(float(RC.interpolate(T.loc, "fpwl", eg, p1, 0.0, log_eps=True)),
                               0.5 * (tab[2, 1] + tab[3, 1]), rtol=1e-12)
    # b axis: surrogate scaling at b = 0.75 for the most compact global column is 25 %
    np.testing.assert_allclose(float(RC.interpolate(T.glob, "fpwl", RC.GLOBAL_EPS[5], RC.GLOBAL_PHI[3], 0.75)),
                               0.25 * RC.TAB6_7[5][3], rtol=1e-12)


def test_sample_mode_expectation():
    key = jax.random.PRNGKey(7)
    n = 20000
    e, p, b = 2.0, 0.1, 0.3
    draws = jax.vmap(lambda k: RC.sample_nodes(k, T.loc, "fpwl", e, p, b))(jax.random.split(key, n))
    mean = float(RC.interpolate(T.loc, "fpwl", e, p, b))
    x = np.asarray(draws)
    se = x.std() / np.sqrt(n)
    assert abs(x.mean() - mean) < 4 * se
    # every draw is a table node value
    nodes = np.unique(np.asarray(T.loc.values[RC.QUANTITIES.index("fpwl")]))
    assert np.all(np.isin(np.unique(x), nodes))


def test_b_average_weights():
    w = np.asarray(RC.b_average_weights())
    np.testing.assert_allclose(w.sum(), 1.0, rtol=1e-14)
    # average of the identity quantity f(b) = min(b, 0.95) under p(b) = 2b
    want = 2 / 3 * 0.95**3 + 0.95 * (1 - 0.95**2)
    np.testing.assert_allclose(float(w @ np.array(RC.B_GRID)), want, rtol=1e-6)


def test_loader_round_trip_and_errors(tmp_path):
    (tmp_path / "tables.dat").write_text(T.to_text())
    T2 = RC.RecipeTables.from_cds(tmp_path)
    assert not T2.is_surrogate and T.is_surrogate
    for a, b in ((T.glob, T2.glob), (T.loc, T2.loc)):
        for fa, fb in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
            np.testing.assert_array_equal(np.asarray(fa), np.asarray(fb))
    # missing table -> clear error
    text = T.to_text()
    cut = text.split("# LOCAL, b=0.95, Q=Csig")[0]
    (tmp_path / "tables.dat").write_text(cut)
    with pytest.raises(ValueError, match="missing table LOCAL, b=0.95, Q=Csig"):
        RC.RecipeTables.from_cds(tmp_path / "tables.dat")
    (tmp_path / "bad.dat").write_text("# GLOBAL, b=0.0, Q=foo\n0 1 2\n1 0 0\n")
    with pytest.raises(ValueError, match="unknown quantity"):
        RC.RecipeTables.from_cds(tmp_path / "bad.dat")


# Thesis App. 6.A layout of the published tables, typed from the printed Tabs. 6.7 and 6.9: the
# header, a column-title line, the phi_ini row with an empty corner cell, then tab-separated rows
# of eps and values (digits as printed, e.g. "0.01500").
TAB6_7_PRINTED = """# GLOBAL, b=0.0, Q=fpwl
ε\tφ^ini
\t0.121938\t0.155263\t0.189273\t0.250536
0.000572118\t0.00000\t0.00000\t0.00000\t0.00000
0.0205945\t0.00000\t0.002500\t0.00000\t0.00000
0.0572069\t0.000833\t0.00000\t0.00000\t0.00000
0.128715\t0.092500\t0.030417\t0.008750\t0.0029167
0.228827\t0.388750\t0.094167\t0.030417\t0.01500
0.915310\t0.957500\t0.603333\t0.243750\t0.115833
3.66124\t1.00000\t1.00000\t1.00000\t0.727083
8.23779\t1.00000\t1.00000\t1.00000\t1.00000
14.6450\t1.00000\t1.00000\t1.00000\t1.00000
"""
TAB6_9_PRINTED = """# LOCAL, b=0.0, Q=fpwl
E\tφ^ini
\t0.0700907\t0.0904748\t0.126801\t0.160992
0.228847\t0.00000\t0.00000\t0.00000\t0.00000
0.915388\t1.00100\t0.333667\t0.00000\t0.00000
3.66124\t4.00400\t46.5465\t6.33967\t0.667333
14.6450\t7.00700\t67.0670\t35.2018\t9.00900
32.9511\t7.50750\t148.315\t58.2248\t16.0160
58.5798\t9.50950\t129.129\t62.3957\t30.0300
"""
# the start of a CDS catalogue ReadMe (byte-by-byte description), which lies beside the tables
README = """J/A+A/502/845    Dust coagulation in molecular clouds    (Ormel+, 2009)
================================================================================
Byte-by-byte Description of file: *.dat
--------------------------------------------------------------------------------
   Bytes Format Units   Label     Explanations
--------------------------------------------------------------------------------
   1- 11  F11.6 ---     eps       Dimensionless energy parameter
  13- 22  F10.6 ---     Q         Tabulated quantity at the first phi
--------------------------------------------------------------------------------
"""
FMISS_COL = (1.2, 1.4, 1.7, 2.1)  # a_out/a axis of fmiss (App. 6.A: not phi)


def _code(iq, ib, ie, ic):
    """A distinct exact value per table node, to check where every number lands."""
    return float(iq + 10 * ib + 100 * ie + 1000 * ic)


def _printed_block(recipe, b, q, iq, ib, fixed):
    glob = recipe.upper() == "GLOBAL"
    eps = np.array(RC.GLOBAL_EPS if glob else RC.LOCAL_EPS) * (10.0 if q in ("Csig", "Cphi") else 1.0)
    col = FMISS_COL if q == "fmiss" else (RC.GLOBAL_PHI if glob else RC.LOCAL_PHI)
    if fixed:  # fixed-width columns, blanks as separators, corner cell blank
        lines = [f"# {recipe}, b={b:.3f}, Q={q}", " " * 12 + "".join(f"{c:>11g}" for c in col)]
        lines += [f"{e:>11.6g} " + "".join(f"{_code(iq, ib, ie, ic):>11.1f}" for ic in range(len(col)))
                  for ie, e in enumerate(eps)]
    else:
        lines = [f"# {recipe}, b={b}, Q={q}", "ε\tφ^ini", "\t" + "\t".join(f"{c:g}" for c in col)]
        lines += [f"{e:.6g}\t" + "\t".join(f"{_code(iq, ib, ie, ic):g}" for ic in range(len(col)))
                  for ie, e in enumerate(eps)]
    return "\n".join(lines) + "\n"


def test_loader_reads_the_published_layout(tmp_path):
    """from_cds on the thesis App. 6.A layout (printed Tabs. 6.7/6.9 typed by hand, CDS quantity
    names Nfk/Cphi, mixed-case recipe, fixed-width and tab-separated tables, gzip, a ReadMe beside
    the data): every number lands on its (Q, b, eps, phi) node."""
    import gzip

    cds_name = {"Nf": "Nfk", "Csig": "Cphi"}
    for recipe, printed, fname in (("GLOBAL", TAB6_7_PRINTED, "global.dat"), ("Local", TAB6_9_PRINTED, "local.dat.gz")):
        parts = [printed]
        for iq, q in enumerate(RC.QUANTITIES):
            for ib, b in enumerate(RC.B_GRID):
                if (q, ib) != ("fpwl", 0):
                    parts.append(_printed_block(recipe, b, cds_name.get(q, q), iq, ib, fixed=(ib % 2 == 1)))
        text = "\n".join(parts)
        if fname.endswith(".gz"):
            (tmp_path / fname).write_bytes(gzip.compress(text.encode("utf-8")))
        else:
            (tmp_path / fname).write_text(text, encoding="utf-8")
    (tmp_path / "ReadMe").write_text(README)
    T2 = RC.RecipeTables.from_cds(tmp_path)
    assert not T2.is_surrogate
    iq = RC.QUANTITIES.index
    for t, eps, phi, tab in ((T2.glob, RC.GLOBAL_EPS, RC.GLOBAL_PHI, RC.TAB6_7),
                             (T2.loc, RC.LOCAL_EPS, RC.LOCAL_PHI, RC.TAB6_9)):
        np.testing.assert_array_equal(np.asarray(t.b), RC.B_GRID)
        # the printed b = 0 fpwl tables, at their nodes, through the interpolator
        E, P = np.meshgrid(eps, phi, indexing="ij")
        np.testing.assert_allclose(np.asarray(RC.interpolate(t, "fpwl", E, P, 0.0)), np.array(tab), rtol=1e-12, atol=0)
        np.testing.assert_allclose(np.asarray(t.col[iq("fmiss")]), FMISS_COL, rtol=1e-15)
        np.testing.assert_allclose(np.asarray(t.col[iq("q")]), phi, rtol=1e-15)
        np.testing.assert_allclose(np.asarray(t.eps[iq("Csig")]), 10.0 * np.array(eps), rtol=1e-6)
        np.testing.assert_allclose(np.asarray(t.eps[iq("Sf")]), eps, rtol=1e-6)
        V = np.asarray(t.values)
        for q in RC.QUANTITIES:
            for ib in range(len(RC.B_GRID)):
                if (q, ib) == ("fpwl", 0):
                    continue
                want = [[_code(iq(q), ib, ie, ic) for ic in range(4)] for ie in range(len(eps))]
                np.testing.assert_array_equal(V[iq(q), ib], want, err_msg=f"{q} b={RC.B_GRID[ib]}")
    # bad layouts say what to change
    (tmp_path / "local.dat.gz").unlink()
    (tmp_path / "global.dat").write_text(TAB6_7_PRINTED.replace("\t0.250536\n", "\n"))
    with pytest.raises(JaxcoagInputError, match="axis row has 3 numbers but the data rows have 4"):
        RC.RecipeTables.from_cds(tmp_path)
    (tmp_path / "global.dat").write_text(TAB6_7_PRINTED.replace("0.0205945\t0.00000\t", "0.0205945\t0.0000O\t"))
    with pytest.raises(JaxcoagInputError, match="'0.0000O' is not a number"):
        RC.RecipeTables.from_cds(tmp_path)
    (tmp_path / "global.dat").write_text(TAB6_7_PRINTED.replace("0.0205945\t0.00000\t", "0.0205945\t"))
    with pytest.raises(JaxcoagInputError, match="4 numbers, but the first data row has 5"):
        RC.RecipeTables.from_cds(tmp_path)
    (tmp_path / "global.dat").write_text(TAB6_7_PRINTED + TAB6_7_PRINTED)
    with pytest.raises(JaxcoagInputError, match="appears twice"):
        RC.RecipeTables.from_cds(tmp_path)


def test_surrogate_fpwl_offset_scaling_uses_each_recipe_phi_range():
    """Surrogate fpwl at b = 0.75 is 25 % of the b = 0 value in the most compact phi column and
    6 % in the least compact one, for the local recipe (phi 0.070..0.161) as for the global one
    (phi 0.122..0.251) - not the global phi range applied to the local columns (6-12 %)."""
    iq = RC.QUANTITIES.index("fpwl")
    ib = RC.B_GRID.index(0.75)
    for t, tab in ((T.glob, RC.TAB6_7), (T.loc, RC.TAB6_9)):
        V = np.asarray(t.values[iq])
        tab = np.array(tab)
        big = tab[:, 0] > 0
        np.testing.assert_allclose(V[ib][big, 0] / tab[big, 0], 0.06, rtol=1e-12)
        big = tab[:, -1] > 0
        np.testing.assert_allclose(V[ib][big, -1] / tab[big, -1], 0.25, rtol=1e-12)
        # in between: linear in phi on the recipe's own grid
        phi = np.asarray(t.col[iq])
        big = tab[:, 1] > 0
        np.testing.assert_allclose(V[ib][big, 1] / tab[big, 1],
                                   0.06 + 0.19 * (phi[1] - phi[0]) / (phi[-1] - phi[0]), rtol=1e-12)


def test_surrogate_constraints():
    iq = RC.QUANTITIES.index
    G, L = np.asarray(T.glob.values), np.asarray(T.loc.values)
    assert np.all(G[iq("fmiss")] == 0) and np.all(L[iq("fmiss")] == 0)
    assert np.all(G[iq("Nf"), 0] == 1.0) and np.all(L[iq("Nf"), 0] == 1.0)
    assert np.all((G[iq("Nf")] >= 1) & (G[iq("Nf")] <= 2))
    np.testing.assert_allclose(G[iq("Nf"), 3, -1], 2.0)  # b = 0.75, high eps -> 2 fragments
    qg0 = G[iq("q"), 0, :, 0]
    assert np.all(np.diff(qg0) <= 0) and qg0[0] == -2.0 and qg0[-1] >= -3.7
    assert np.all(G[iq("q"), 1:] >= -2.0)
    assert np.all((L[iq("q")] >= -2.0) & (L[iq("q")] <= -1.3))
    c = G[iq("Csig"), 0]
    assert np.all(c >= 0.95) and np.all(c[RC.GLOBAL_EPS.index(0.915310):] > 1.0)


def _mat():
    return Material.ch6_silicate()


def test_o09_regimes_against_tables():
    M = _mat()
    m0, eb, er = M.m0, M.e_break(), M.e_roll()
    # hit-and-stick: E < 5 E_roll -> eq. 6.24 (form B)
    m1, m2 = 1e3 * m0, 1e2 * m0
    dv = jnp.sqrt(2 * 1.0 * er / (m1 * m2 / (m1 + m2)))
    o = RC.o09_outcome(m1, 5.0, m2, 2.0, dv, T, M, b_frac=0.0)
    np.testing.assert_allclose(float(o.psi_one), 1 / float(phi_hit_and_stick_o09(1e3, 0.2, 1e2, 0.5)), rtol=1e-12)
    assert float(o.f_pwl) == 0.0
    # global (equal masses): eps = E/(N_tot E_br) = 0.228827, <phi> = 0.155263 -> fpwl 0.094167
    m = 500 * m0
    E = 0.228827 * 1000 * eb
    dv = jnp.sqrt(2 * E / (0.5 * m))
    o = RC.o09_outcome(m, 1 / 0.155263, m, 1 / 0.155263, dv, T, M, b_frac=0.0)
    np.testing.assert_allclose(float(o.f_pwl), 0.094167, rtol=1e-6)
    np.testing.assert_allclose(float(o.aux["w_glob"]), 1.0)
    np.testing.assert_allclose(float(o.m_hi), 0.25 * 2 * float(m), rtol=1e-14)
    # local (mass ratio 1e-4): eps = E/(N_mu E_br) = 3.66124, target phi 0.0904748 -> 46.5465 m_mu
    mt, mp = 1e5 * m0, 10 * m0
    m_mu = mt * mp / (mt + mp)
    E = 3.66124 * (m_mu / m0) * eb
    dv = jnp.sqrt(2 * E / m_mu)
    o = RC.o09_outcome(mt, 1 / 0.0904748, mp, 1.0, dv, T, M, b_frac=0.0)
    assert float(o.aux["w_glob"]) == 0.0 and float(o.aux["w_hs"]) == 0.0
    np.testing.assert_allclose(float(o.f_pwl), 46.5465 * float(m_mu / (mt + mp)), rtol=1e-6)


def test_o09_mass_conservation_grid():
    M = _mat()
    m = M.m0 * jnp.logspace(0, 9, 6)
    psi = jnp.array([1.0, 2.0, 5.0, 8.0, 12.0, 20.0])
    m1, p1, m2, p2 = m[None, :, None], psi[None, :, None], m[None, None, :], psi[None, None, :]
    dv = jnp.array([10.0, 300.0, 3e3, 3e4])[:, None, None]  # one compiled call for the whole grid
    o = RC.o09_outcome(m1, p1, m2, p2, dv, T, M)
    assert o.eff.shape == (4, 6, 6)
    M_tot = (m1 + m2) * jnp.ones((4, 1, 1))
    np.testing.assert_allclose(np.asarray(o.expected_mass(m1, m2)), np.asarray(M_tot), rtol=1e-13)
    for fld in ("eff", "p_two", "split", "f_pwl"):
        v = np.asarray(getattr(o, fld))
        assert np.all((v >= 0) & (v <= 1 + 1e-14)), fld
    assert np.all(np.asarray(o.psi_one) >= 1.0)
    assert np.all(np.asarray(o.aux["is_surrogate"]) == 1.0)
    # all three regimes occur on this grid
    assert float(jnp.max(o.aux["w_hs"])) == 1.0 and float(jnp.min(o.aux["w_hs"])) == 0.0
    assert float(jnp.max(o.f_pwl)) > 0.1 and float(jnp.max(o.p_two)) > 0.1


def test_interpolate_jit_vmap():
    f = lambda e, p, b: RC.interpolate(T.glob, "fpwl", e, p, b)
    e = jnp.array([0.01, 0.2, 1.0, 5.0])
    p = jnp.array([0.13, 0.2, 0.24, 0.3])
    np.testing.assert_allclose(np.asarray(jax.jit(f)(e, p, 0.3)), np.asarray(f(e, p, 0.3)), rtol=1e-14)
    vm = jax.vmap(f, in_axes=(0, 0, None))(e, p, 0.3)
    loop = jnp.stack([f(e[i], p[i], 0.3) for i in range(4)])
    np.testing.assert_allclose(np.asarray(vm), np.asarray(loop), rtol=1e-14)


def test_o09_smooth_gradient_vs_fd():
    M = _mat()
    m1, m2 = 2e3 * M.m0, 1e3 * M.m0

    def obj(ldv):
        o = RC.o09_outcome(m1, 4.0, m2, 3.0, jnp.exp(ldv), T, M, width=0.3, validate=False)
        return o.psi_one + o.f_pwl

    h = 1e-5
    x = jnp.log(700.0) + jnp.array([-h, 0.0, h])
    vals, grads = jax.jit(jax.vmap(jax.value_and_grad(obj)))(x)  # one compile
    g = float(grads[1])
    fd = float((vals[2] - vals[0]) / (2 * h))
    assert np.isfinite(g) and abs(g) > 1e-6
    np.testing.assert_allclose(g, fd, rtol=1e-5)
