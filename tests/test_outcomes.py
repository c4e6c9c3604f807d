"""Collision outcomes: DT thresholds (thesis Tabs. 1.1, 6.1), O08 (thesis ch. 4), fragment draws (eqs. 6.29-6.30),
Wada et al. (2007) laws (eqs. 51-59), the Outcome interface and smooth switches (docs/design_notes.md)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag._validate import JaxcoagInputError
from jaxcoag.physics import dominik_tielens as DT, ormel07 as O07, ormel08 as O08, outcome as OC, wada07 as W
from jaxcoag.physics.contact import Material, jkr_delta_c
from jaxcoag.physics.porosity import psi_hit_and_stick


# ----------------------------------------------------------------------------- geometry, O08
def test_lens_area_G3():
    a1 = jnp.array([1.0, 1.0, 2.0, 2.0, 2.0])
    a2 = jnp.array([1.0, 1.0, 1.0, 1.0, 1.0])
    b = jnp.array([1.0, 0.5, 2.0, 1.0, 2.9])
    A = np.asarray(O08.lens_area(a1, a2, b))
    np.testing.assert_allclose(A, [1.22837, 2.15211, 1.40307, np.pi, 0.048318], rtol=1e-4)
    np.testing.assert_allclose(A[0] / np.pi, 0.39100, rtol=1e-4)
    np.testing.assert_allclose([A[2] / (4 * np.pi), A[2] / np.pi], [0.11165, 0.44661], rtol=1e-4)
    assert float(O08.lens_area(1.0, 1.0, 2.5)) == 0.0
    # continuity at b = |a1 - a2| and b = a1 + a2
    np.testing.assert_allclose(float(O08.lens_area(2.0, 1.0, 1.0 + 1e-9)), np.pi, rtol=1e-6)
    assert abs(float(O08.lens_area(2.0, 1.0, 3.0 - 1e-9))) < 1e-9


def test_f_comp_o08_M6_R7():
    M = Material.ch4_silicate()
    f = np.asarray(O08.f_comp_o08(1.0, 1.0, jnp.array([10.0, 50.0, 55.0, 295.0]), M))
    np.testing.assert_allclose(f, [0.009186, 0.22965, 0.27787, 7.994], rtol=2e-4)
    # coefficient 3.674e-2 (m_mu^2/(m1 m2)) at 10 cm/s; depends on the mass ratio only
    np.testing.assert_allclose(4 * f[0], 0.036744, rtol=1e-4)
    np.testing.assert_allclose(float(O08.f_comp_o08(1e-3, 1e-3, 10.0, M)), f[0], rtol=1e-12)
    # stick/bounce rule: F_av = 0.25 for two (f_d = f_p = 0.5, f_geo = 1) compounds
    assert f[1] <= 0.25 < f[2]
    np.testing.assert_allclose(float(O08.o08_frag_flag(1.0, 1.0, 295.0, M)), 7.994 / 8, rtol=2e-4)


def test_o08_compounds_R7_R8():
    from jaxcoag.physics.porosity import phi_dust

    M = Material.ch4_silicate()
    phi_pd = 0.15 * float(phi_dust(10 ** (2 / 0.95)))
    np.testing.assert_allclose(phi_pd, 0.019114, rtol=1e-4)
    c = O08.Compound(m=1.0, f_d=0.5, f_p=0.5, phi_pd=phi_pd)
    V = float(O08.compound_volume(c))
    np.testing.assert_allclose([V, (3 * V / (4 * np.pi)) ** (1 / 3)], [4.77897, 1.04492], rtol=1e-5)
    # stick at 50 cm/s (f_comp 0.22965 <= F_av 0.25): conservative merge and fractal compounds
    for fractal, V_want, a_want, phi_want in ((False, 2.01214, 0.78317, phi_pd), (True, 2.27869, 0.81633, 0.013896)):
        o, st, b1, b2 = O08.o08_outcome(c, c, 50.0, 0.0, M, fgeo_mode="unity", fractal_compounds=fractal)
        assert float(o.p_two) == 0.0
        np.testing.assert_allclose([float(st.f_d), float(st.f_p)], [0.5, 0.040703], rtol=1e-4)
        np.testing.assert_allclose(float(o.aux["V_one"]), V_want, rtol=1e-5)
        np.testing.assert_allclose(float((3 * o.aux["V_one"] / (4 * np.pi)) ** (1 / 3)), a_want, rtol=1e-5)
        np.testing.assert_allclose(float(st.phi_pd), phi_want, rtol=1e-4)
        # dust mass conserved: porous + compact dust of the product = dust of the inputs
        np.testing.assert_allclose(float(st.m * st.f_d), 1.0, rtol=1e-14)
        np.testing.assert_allclose(float(o.expected_mass(1.0, 1.0)), 2.0, rtol=1e-14)
    # bounce at 55 cm/s: masses and f_d kept, porous dust compacted (f_geo = 1 -> f_p = 0)
    o, st, b1, b2 = O08.o08_outcome(c, c, 55.0, 0.0, M, fgeo_mode="unity")
    assert float(o.p_two) == 1.0 and float(b1.f_p) == 0.0 and float(b1.m) == 1.0
    np.testing.assert_allclose(float(o.split), 0.5)
    # geometric f_geo with an offset impact lowers F_av and the compacted fraction
    o, st, b1, b2 = O08.o08_outcome(c, c, 50.0, 1.0, M)
    A = float(O08.lens_area(1.0449172, 1.0449172, 1.0)) / (np.pi * 1.0449172**2)
    np.testing.assert_allclose(float(o.aux["F_av"]), 0.25 * A, rtol=1e-6)
    np.testing.assert_allclose(float(b1.f_p), 0.5 * (1 - A), rtol=1e-6)
    # T4.25 void for V2 = V1/10: 0.045472 V1
    np.testing.assert_allclose(1.1 ** (1.5 * 0.95) - 1.1, 0.045472, rtol=1e-4)
    with pytest.raises(ValueError, match="fgeo_mode"):
        O08.o08_outcome(c, c, 50.0, 0.0, M, fgeo_mode="x")


# ----------------------------------------------------------------------------- fragments
@pytest.mark.parametrize("q,frac,mean,per", [
    (-1.3, 0.08590, 24.736, 0.040427), (-1.5, 0.14599, 15.811, 0.063246),
    (-2.0, 0.41702, 5.5436, 0.18039), (-3.7, 0.98013, 1.5881, 0.62968)])
def test_powerlaw_table_66(q, frac, mean, per):
    np.testing.assert_allclose(float(OC.powerlaw_mass_fraction(q, 1.0, 250.0, 1.0, 10.0)), frac, rtol=1e-4)
    np.testing.assert_allclose(float(OC.mean_fragment_mass(q, 1.0, 250.0)), mean, rtol=1e-4)
    np.testing.assert_allclose(1 / float(OC.mean_fragment_mass(q, 1.0, 250.0)), per, rtol=1e-4)


def test_powerlaw_partition_and_q_singularities():
    edges = jnp.logspace(-1, 4, 23)  # covers [1, 250] and beyond: clipped to the support
    for q in (-1.0, -1.3, -2.0, -2.0 + 1e-9, -3.7):
        fr = OC.powerlaw_mass_fraction(q, 1.0, 250.0, edges[:-1], edges[1:])
        np.testing.assert_allclose(float(jnp.sum(fr)), 1.0, rtol=1e-12)
        assert bool(jnp.all(fr >= 0))
    # continuity through q = -2 (log form) and q = -1 (mean mass), and finite q-derivative
    a = float(OC.powerlaw_mass_fraction(-2.0, 1.0, 250.0, 1.0, 10.0))
    b = float(OC.powerlaw_mass_fraction(-2.0 + 1e-7, 1.0, 250.0, 1.0, 10.0))
    np.testing.assert_allclose(a, b, rtol=1e-6)
    np.testing.assert_allclose(float(OC.mean_fragment_mass(-1.0, 1.0, 250.0)),
                               float(OC.mean_fragment_mass(-1.0 + 1e-7, 1.0, 250.0)), rtol=1e-6)
    g = jax.grad(lambda q: OC.powerlaw_mass_fraction(q, 1.0, 250.0, 1.0, 10.0))
    h = 1e-5
    fd = (float(OC.powerlaw_mass_fraction(-2 + h, 1.0, 250.0, 1.0, 10.0))
          - float(OC.powerlaw_mass_fraction(-2 - h, 1.0, 250.0, 1.0, 10.0))) / (2 * h)
    np.testing.assert_allclose(float(g(-2.0)), fd, rtol=1e-6)


def _sampler_means(n, seeds):
    q, lo, hi = -2.0, 1.0, 250.0
    keys = jnp.stack([jax.random.PRNGKey(s) for s in seeds])
    # i.i.d. draws (M_pwl large enough that no draw is truncated except the last)
    draw = jax.vmap(lambda k: OC.sample_fragment_masses(k, q, lo, hi, 1e12, n)[0][:-1])
    x = np.asarray(draw(keys))
    mean = float(OC.mean_fragment_mass(q, lo, hi))
    ex2 = float(OC._int_pow(lo, hi, q + 3.0) / OC._int_pow(lo, hi, q + 1.0))
    se = np.sqrt(ex2 - mean**2) / np.sqrt(n - 1)
    return x, mean, se


@pytest.mark.slow
def test_sampler_mean_rtol_1e2_slow():
    """Fragment sampler (thesis eq. 6.29) mean at rtol 1e-2: 3e6 draws per seed, 4 SE = 0.6 % of the mean."""
    x, mean, se = _sampler_means(3_000_000, (0, 1, 2))
    assert 4 * se < 0.01 * mean
    for row in x:
        assert abs(row.mean() - mean) < 4 * se


def test_sampler_R10():
    q, lo, hi = -2.0, 1.0, 250.0
    seeds = (0, 1, 2)
    x, mean, se = _sampler_means(200_000, seeds)
    for i, s in enumerate(seeds):  # every seed passes; 4 SE ≈ 2.4 % of the mean at n = 2e5
        assert abs(x[i].mean() - mean) < 4 * se, (s, x[i].mean(), mean, se)
    assert x.min() >= lo and x.max() <= hi
    # mass is exact in both regimes: capacity exhausted (rescaled: 64 draws of mean 5.5 < 1000)
    # or not (the last fragment takes the remainder); one compiled call
    M_pwl = jnp.array([1000.0, 100.0, 3.7])
    ks = jnp.stack([jax.random.PRNGKey(s) for s in (11, 12, 13)])
    m, u = jax.vmap(lambda k, Mp: OC.sample_fragment_masses(k, q, lo, hi, Mp, 64))(ks, M_pwl)
    np.testing.assert_allclose(np.asarray(jnp.sum(m * u, axis=1)), np.asarray(M_pwl), rtol=1e-13)
    assert bool(jnp.all(u >= 0))
    assert float(jnp.sum(u[0])) > 64.0 and float(jnp.sum(u[1])) < 64.0  # rescaled vs remainder


# ----------------------------------------------------------------------------- Wada laws
def test_wada_laws_W1_W2():
    x = jnp.array([0.001, 0.01, 0.03, 0.1, 0.3, 1.0])
    np.testing.assert_allclose(np.asarray(W.wada_rg_ratio(x)),
                               [1.92426, 1.45982, 1.27949, 1.10726, 0.97059, 0.84], rtol=1e-4)
    np.testing.assert_allclose(np.asarray(W.wada_rg_ratio(x, "W58")),
                               [2.57630, 1.87931, 1.61674, 1.37088, 1.17928, 1.0], rtol=1e-4)
    np.testing.assert_allclose(np.asarray(W.wada_ncon(x)),
                               [1.00562, 1.03162, 1.07208, 1.17783, 1.40536, 2.0], rtol=1e-5)
    np.testing.assert_allclose(float(W.wada_rg_slope()), -0.136943, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(W.wada_ncon_max(jnp.array([128.0, 2048.0, 1e6]))),
                               [1.31906, 1.34227, 1.34965], rtol=1e-5)
    np.testing.assert_allclose(np.asarray(W.wada_ncon_max(jnp.array([128.0, 2048.0]), 1.6)),
                               [1.54697, 1.58674], rtol=1e-5)
    # capped at n_con,max
    np.testing.assert_allclose(float(W.wada_ncon(1.0, 128.0)), 1.31906, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(W.wada_bcca_rg(jnp.array([8.0, 32.0, 128.0, 512.0, 2048.0]))),
                               [3.0770, 7.4411, 17.992, 43.508, 105.21], rtol=1e-4)
    # W2: with Wada's rounded 1.54 -> 2.6423; with the exact JKR constant 1.542585 -> 2.6379
    np.testing.assert_allclose(float(W.wada_energy_ratio(1024.0, 5.7, 1.54)), 2.6423, rtol=1e-4)
    np.testing.assert_allclose(float(W.wada_energy_ratio(1024.0, 5.7)), 2.6379, rtol=1e-4)
    np.testing.assert_allclose(float(W.wada_energy_ratio(128.0, 18.0, 1.54)), 26.7, rtol=2e-3)
    np.testing.assert_allclose(float(W.wada_energy_ratio(128.0, 11.01, 1.54)), 10.0, rtol=2e-3)
    # strict validity masks
    v = W.wada_rg_ratio(jnp.array([0.001, 0.05, 0.5]), "W51", n_k=254.0, strict=True)
    assert np.isnan(float(v[0])) and np.isfinite(float(v[1])) and np.isnan(float(v[2]))
    with pytest.raises(ValueError, match="n_k"):
        W.wada_rg_ratio(0.05, strict=True)


def test_wada_x_roll_at_tabulated_energies():
    """E/(n_k E_roll) for N = 1024 at 5.7 v0: ice 2 A 1.364 (max compression), quartz 2 A 0.142."""
    for M, want in ((Material.wada_ice(), 1.364), (Material.wada_quartz(), 0.142)):
        Fcdc = M.F_c() * jkr_delta_c(M.gamma, M.R_pair, M.E_star)
        v0 = jnp.sqrt(Fcdc / M.m0)
        N = 1024.0
        E = N * M.m0 * (5.7 * v0) ** 2 / 8.0
        np.testing.assert_allclose(float(E / ((N - 2) * M.e_roll())), want, rtol=3e-3)


# ----------------------------------------------------------------------------- thresholds
def test_dt_thresholds_F3():
    e = jnp.array([0.5, 2.99, 3.0, 5.0, 10.0, 20.0, 30.0, 1e3])
    f = np.asarray(DT.dt_fragment_fraction(e, 1.0, 1.0))
    assert np.all(f[:3] == 0.0)
    np.testing.assert_allclose(f[4], 0.5, rtol=1e-14)  # N_large/N_tot = 0.5 at 10 N_c E_br
    np.testing.assert_allclose(f[6:], 1.0, rtol=1e-14)
    np.testing.assert_allclose(f[3], 0.5 * np.log(5 / 3) / np.log(10 / 3), rtol=1e-12)
    assert np.all(np.diff(f) >= 0)
    # through a Material and o07_outcome: 1 - f_pwl = N_large/N_tot = 0.5 at E = 10 N E_br
    M = Material.ch6_silicate()
    m = 1e3 * M.m0
    dv = jnp.sqrt(2 * 10 * (2e3) * M.e_break() / (0.5 * m))  # E = 1/2 (m/2) dv^2 = 10 N E_br
    o = O07.o07_outcome(m, 3.0, m, 3.0, dv, M, frag_model=DT.DTEnergy())
    np.testing.assert_allclose(float(1 - o.f_pwl), 0.5, rtol=1e-10)
    o = O07.o07_outcome(m, 3.0, m, 3.0, dv * 0.99 * np.sqrt(0.3), M, frag_model=DT.DTEnergy())
    assert float(o.f_pwl) == 0.0
    np.testing.assert_allclose(float(o.m_hi), 0.25 * 2 * float(m), rtol=1e-14)
    # Wada contacts n_k = N - 2 shift the threshold
    ow = O07.o07_outcome(m, 3.0, m, 3.0, dv, M, frag_model=DT.DTEnergy(contacts="wada"))
    np.testing.assert_allclose(float(ow.f_pwl), float(DT.dt_fragment_fraction(10 * 2e3, 2e3 - 2, 1.0)), rtol=1e-10)
    with pytest.raises(ValueError, match="contacts"):
        DT.DTEnergy(contacts="Nc")


def test_dt_threshold_velocities_wada_B10():
    """Impact speeds v/v0 of the DT energies for N_tot = 256 (Wada et al. 2007 §5.1, Tabs. 2-3; E_imp = N m1 v^2/8)."""
    N = 256.0
    for M, want in ((Material.wada_quartz(), (0.947, 2.12, 15.1)), (Material.wada_ice(), (0.305, 0.683, 4.87)),
                    (Material.wada_quartz(3e-7), (3.67, 8.20, 58.4)), (Material.wada_ice(3e-7), (1.18, 2.65, 18.9))):
        fcdc = M.F_c() * jkr_delta_c(M.gamma, M.R_pair, M.E_star)
        th = DT.dt_thresholds(N - 2.0, M.e_roll(), M.e_break())
        v = lambda E: float(jnp.sqrt(8.0 * E / (N * fcdc)))  # E_imp = N m1 v^2/8, v0^2 = F_c delta_c/m1
        np.testing.assert_allclose([v(M.e_roll()), v(th["restructuring"]), v(th["max_compression"])], want, rtol=4e-3)
        np.testing.assert_allclose([v(th["erosion"]), v(th["catastrophic"])], [6.06, 11.07], rtol=2e-3)


def test_shatter_above():
    """Thesis §5.3.4: a product heavier than m_frag becomes M/m_mono monomers (both engines' hooks)."""
    from jaxcoag.kernels import Constant
    from jaxcoag.outcomes import ShatterAbove

    m0 = 3.7e-15
    sa = ShatterAbove(1e10 * m0, m0)
    m1 = jnp.array([1e9, 6e9, 1e9, 5e9]) * m0
    m2 = jnp.array([1e9, 6e9, 1e1, 5e9]) * m0  # the last product sits exactly at m_frag: it sticks
    np.testing.assert_array_equal(np.asarray(sa.probability(Constant(1.0), m1, m2)), [0.0, 1.0, 0.0, 0.0])
    psi = jnp.ones(1)
    key = jax.random.PRNGKey(0)
    for a, b, frag in ((1e9, 1e9, False), (6e9, 6e9, True)):
        mi, mj = a * m0, b * m0
        pr = sa.products(jnp.asarray(mi), jnp.log(mi), psi, jnp.asarray(mj), jnp.log(mj), psi, 1.0, 0.0, key)
        np.testing.assert_allclose(float(jnp.sum(pr.count * pr.m)), mi + mj, rtol=1e-15)
        np.testing.assert_allclose(float(pr.m[0]), m0 if frag else mi + mj, rtol=1e-15)
        np.testing.assert_allclose(float(pr.count[0]), (a + b) if frag else 1.0, rtol=1e-12)
    # a group event: the i-particle sweeps up n_c = 2^40 monomers and crosses m_frag
    n_c = 2.0 ** 40
    pr = sa.products(jnp.asarray(m0), jnp.log(m0), psi, jnp.asarray(m0), jnp.log(m0), psi, n_c, 40 * np.log(2.0), key)
    np.testing.assert_allclose(float(pr.count[0]), n_c + 1.0, rtol=1e-14)


# ----------------------------------------------------------------------------- interface
def _grid(n=6):
    M = Material.ch2_quartz()
    m = M.m0 * jnp.logspace(0, 12, n)
    psi = 1.0 + jnp.linspace(0.0, 40.0, n)
    dv = jnp.logspace(1, 4, n)
    return M, m[:, None], psi[:, None], m[None, :], psi[None, :], dv[:, None] * jnp.ones((1, n))


def _all_outcomes():
    M, m1, p1, m2, p2, dv = _grid()
    outs = {
        "o07": O07.o07_outcome(m1, p1, m2, p2, dv, M),
        "o07_dt": O07.o07_outcome(m1, p1, m2, p2, dv, M, restr_factor=5.0, frag_model=DT.DTEnergy()),
        "o07_dt_smooth": O07.o07_outcome(m1, p1, m2, p2, dv, M, frag_model=DT.DTEnergy(), width=0.3),
        "o07_bounce": O07.o07_outcome(m1, p1, m2, p2, dv, M, frag_model=DT.DTEnergy(),
                                    bounce_model=O07.BounceWhenCompact(psi_max=40.0), width=0.5),
        "shatter": OC.Outcome.build(f_pwl=jnp.where(m1 + m2 > 1e8 * M.m0, 1.0, 0.0), m_lo=M.m0, m_hi=M.m0,
                                    psi_one=psi_hit_and_stick(m1, p1, m2, p2, m0=M.m0)),
        "bounce": OC.bounce_outcome(m1, p1, m2, p2, M.m0),
        "stick": OC.sticking_outcome(m1, m2, psi_hit_and_stick(m1, p1, m2, p2, m0=M.m0), M.m0),
    }
    return M, m1, p1, m2, p2, dv, outs


def test_mass_conservation_and_invariants_every_outcome():
    M, m1, p1, m2, p2, dv, outs = _all_outcomes()
    M_tot = m1 + m2
    for name, o in outs.items():
        assert o.eff.shape == (6, 6), name
        np.testing.assert_allclose(np.asarray(o.expected_mass(m1, m2)), np.asarray(M_tot * jnp.ones((1, 6))),
                                   rtol=1e-14, err_msg=name)
        r = o.remnant_masses(m1, m2)
        np.testing.assert_allclose(np.asarray(r["M_L"] + r["M_pwl"]), np.asarray(M_tot * jnp.ones((1, 6))), rtol=1e-14)
        np.testing.assert_allclose(np.asarray(r["m_a"] + r["m_b"]), np.asarray(r["M_L"]), rtol=1e-14)
        for fld in ("eff", "p_two", "split", "f_pwl"):
            v = np.asarray(getattr(o, fld))
            assert np.all((v >= 0) & (v <= 1)), (name, fld)
        for fld in ("psi_one", "psi_a", "psi_b"):
            assert np.all(np.asarray(getattr(o, fld)) >= 1.0 - 1e-12), (name, fld)
        assert np.all(np.asarray(o.m_hi) >= np.asarray(o.m_lo))
    # W = sum m psi moment: sticking deposits M_tot psi; bounce returns m1 psi1 + m2 psi2
    st = outs["stick"]
    np.testing.assert_allclose(np.asarray(st.expected_volume_moment(m1, m2, M.m0)),
                               np.asarray(M_tot * st.psi_one), rtol=1e-14)
    np.testing.assert_allclose(np.asarray(outs["bounce"].expected_volume_moment(m1, m2, M.m0)),
                               np.asarray(m1 * p1 + m2 * p2), rtol=1e-14)
    # something actually happens in the grid: fragments and bounces both present
    assert float(jnp.max(outs["o07_dt"].f_pwl)) > 0.4
    assert float(jnp.max(outs["o07_bounce"].p_two)) > 0.4
    np.testing.assert_allclose(np.asarray(outs["bounce"].split), np.asarray(m1 / (m1 + m2) * jnp.ones((1, 6))), rtol=1e-14)


def test_o07_symmetry():
    M, m1, p1, m2, p2, dv, _ = _all_outcomes()
    a = O07.o07_outcome(m1, p1, m2, p2, dv, M, frag_model=DT.DTEnergy())
    b = O07.o07_outcome(m2.T, p2.T, m1.T, p1.T, dv, M, frag_model=DT.DTEnergy())
    for fld in ("psi_one", "f_pwl", "p_two", "m_hi"):
        np.testing.assert_allclose(np.asarray(getattr(a, fld)), np.asarray(getattr(b, fld)), rtol=1e-14)


def test_o07_matches_porosity_recipe():
    M = Material.ch2_quartz()
    m0, er = M.m0, M.e_roll()
    m1, m2 = 100 * m0, 10 * m0
    # hit-and-stick (E < E_roll) and compaction (E = 0.5 N E_roll)
    dv_hs = jnp.sqrt(2 * 0.5 * er / (m1 * m2 / (m1 + m2)))
    o = O07.o07_outcome(m1, 10.0, m2, 2.0, dv_hs, M)
    np.testing.assert_allclose(float(o.psi_one), 9.75399, rtol=1e-5)
    dv_c = jnp.sqrt(2 * 0.5 * 110 * er / (m1 * m2 / (m1 + m2)))
    o = O07.o07_outcome(m1, 10.0, m2, 2.0, dv_c, M)
    pm = (100 * 10 + 10 * 2) / 110
    np.testing.assert_allclose(float(o.psi_one), 1 + 0.5 * (pm - 1), rtol=1e-10)
    np.testing.assert_allclose(float(o.aux["energy"]), 0.5 * 110 * float(er), rtol=1e-12)


def test_smooth_mode_S1_and_gradients():
    M = Material.ch6_silicate()
    m1, m2 = 3e3 * M.m0, 1e3 * M.m0

    def outcome(lg, lxi, ldv, width):
        mat = eqx.tree_at(lambda t: (t.gamma, t.xi_crit), M, (jnp.exp(lg), jnp.exp(lxi)))
        return O07.o07_outcome(m1, 5.0, m2, 3.0, jnp.exp(ldv), mat, frag_model=DT.DTEnergy(),
                             restr_factor=5.0, width=width, validate=False)

    x0 = jnp.array([jnp.log(25.0), jnp.log(2e-7)])
    dvs = jnp.log(jnp.array([30.0, 300.0, 3000.0, 2e4]))
    hh = 1e-5
    x = jnp.array([x0[0], x0[1], jnp.log(4e3)])
    pts = jnp.concatenate([x[None], x[None] + hh * jnp.eye(3), x[None] - hh * jnp.eye(3)])

    def obj(z):
        o = outcome(z[0], z[1], z[2], 0.3)
        return o.psi_one + 3.0 * o.f_pwl

    @jax.jit
    def everything():
        hard = jax.vmap(lambda l: outcome(x0[0], x0[1], l, 0.0))(dvs)
        soft = jax.vmap(lambda l: outcome(x0[0], x0[1], l, 1e-3))(dvs)
        vals, grads = jax.vmap(jax.value_and_grad(obj))(pts)
        # gradient at dv = 0 is finite (no sqrt/log singularity)
        g0 = jax.grad(lambda v: O07.o07_outcome(m1, 5.0, m2, 3.0, v, M, width=0.3, validate=False).psi_one)(0.0)
        return hard, soft, vals, grads, g0

    hard, soft, vals, grads, g0 = everything()
    # width -> 0 reproduces the hard switches (away from the thresholds)
    np.testing.assert_allclose(np.asarray(soft.psi_one), np.asarray(hard.psi_one), rtol=2e-3, atol=1e-6)
    np.testing.assert_allclose(np.asarray(soft.f_pwl), np.asarray(hard.f_pwl), atol=2e-3)
    assert float(jnp.max(hard.f_pwl)) > 0.1  # the fragmenting regime is exercised
    g = np.asarray(grads[0])
    fd = np.asarray((vals[1:4] - vals[4:7]) / (2 * hh))
    assert np.all(np.isfinite(g)) and np.all(np.abs(g) > 1e-6)
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-9)
    assert np.isfinite(float(g0))


def test_jit_vmap_equivalence():
    M, m1, p1, m2, p2, dv, _ = _all_outcomes()
    f = lambda a, b, c, d, v: O07.o07_outcome(a, b, c, d, v, M, frag_model=DT.DTEnergy())
    eager = f(m1, p1, m2, p2, dv)
    # jit(vmap(f)) over rows == eager broadcast grid == stacked loop (one compilation)
    rows = jax.jit(jax.vmap(f))(m1[:, 0], p1[:, 0], jnp.broadcast_to(m2, (6, 6)), jnp.broadcast_to(p2, (6, 6)), dv)
    for x, y in zip(jax.tree_util.tree_leaves(rows), jax.tree_util.tree_leaves(eager)):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-13)
    loop = [f(m1[i, 0], p1[i, 0], m2[0], p2[0], dv[i]) for i in (0, 5)]
    for i, o in zip((0, 5), loop):
        np.testing.assert_allclose(np.asarray(o.psi_one), np.asarray(eager.psi_one[i]), rtol=1e-13)
        np.testing.assert_allclose(np.asarray(o.f_pwl), np.asarray(eager.f_pwl[i]), rtol=1e-13)


def test_bad_input_errors():
    M = Material.ch2_quartz()
    with pytest.raises(JaxcoagInputError, match="dv"):
        O07.o07_outcome(1e-12, 1.0, 1e-12, 1.0, -3.0, M)
    with pytest.raises(JaxcoagInputError, match="m1"):
        OC.collision_energy(0.0, 1.0, 1.0)
    with pytest.raises(JaxcoagInputError, match="b"):
        O08.lens_area(1.0, 1.0, -1.0)
    with pytest.raises(ValueError, match="fit"):
        W.wada_rg_ratio(0.1, "W99")
