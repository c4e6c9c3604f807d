"""OC07 turbulent relative velocity (Ormel & Cuzzi 2007 = thesis ch. 3): checks, tables, derivatives.

All reference numbers are hard-coded from a float64 independent reference implementation of the
thesis formulas (not shipped) unless marked "thesis".
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

from jaxcoag.physics import turbulence as T
from jaxcoag.physics.safe import safe_sqrt

RE8 = 1e8


def dv(a, b, re, **kw):
    return float(T.dv_turbulent_oc07(a, b, re, **kw))


def dv2(a, b, re, **kw):
    return float(T.dv2_turbulent_oc07(a, b, re, **kw))


def terms(a, b, re, method="exact", accurate=False):
    sa = T.st_star(a, re, method=method)
    sb = T.st_star(b, re, method=method)
    I, II = T.dv2_terms_oc07(a, b, sa, sb, re, accurate=accurate)
    return float(I), float(II), float(jnp.maximum(sa, sb))


def rel(x, y):
    return abs(x - y) / abs(y)


# ---------------------------------------------------------------- #1-#3: F and the root
def test_01_ya_root():
    ya = float(T.ystar_exact(0.0))
    assert rel(ya, 1.6003688037229952) < 1e-12
    assert rel(ya, 1.6) < 1e-3
    assert abs(float(T.F_ystar(ya))) < 1e-14


def test_02_F_values_and_monotone():
    assert abs(float(T.F_ystar(1.0)) + 0.5) < 1e-12
    assert abs(float(T.F_ystar(0.0)) + 1.0) < 1e-12
    y = jnp.linspace(1e-6, 20.0, 200001)
    dF = T.dF_ystar(y)
    assert abs(float(jnp.min(dF)) - 0.118026) < 1e-6
    assert abs(float(y[jnp.argmin(dF)]) - 0.759) < 1e-3
    # dF_ystar is the derivative of F_ystar; d2F of dF
    g = jax.vmap(jax.grad(T.F_ystar))(y[::1000])
    np.testing.assert_allclose(g, dF[::1000], rtol=1e-13, atol=1e-13)
    g2 = jax.vmap(jax.grad(T.dF_ystar))(y[::1000])
    np.testing.assert_allclose(g2, T.d2F_ystar(y[::1000]), rtol=1e-12, atol=1e-12)


def test_03_st_star_at_and_above_one():
    st = jnp.array([1.0, 1.5, 2.0, 10.0, 1e6, 1e25])
    np.testing.assert_allclose(T.st_star(st, RE8), 1.0, rtol=0, atol=1e-12)
    # the raw root is never used above St = 1 (it would give 0.61 at St = 2)
    np.testing.assert_allclose(T.ystar_exact(2.0), 1.0, atol=1e-12)


# ---------------------------------------------------------------- #4-#7: t* methods
def test_04_exact_ystar():
    st = jnp.array([0.01, 0.1, 0.5, 0.9])
    ref = np.array([1.594399, 1.542336, 1.329160, 1.086965])
    np.testing.assert_allclose(T.ystar_exact(st), ref, atol=1e-6)
    # Re = inf surrogate: St*/St gives the same y*
    np.testing.assert_allclose(T.st_star(st, 1e30) / st, ref, atol=1e-6)


@pytest.mark.parametrize("boa,ref", [(1.0, 0.670440), (0.1, 0.849014), (10.0, 0.453005)])
def test_05_06_eq322(boa, ref):
    st1 = float(T.st_where_star_is_one_eq322(boa))
    assert abs(st1 - ref) < 1e-6
    # solver: y*(St) St = 1 exactly at that St (eq. 3.21 is consistent with eq. 3.22)
    y = float(T.ystar_exact(st1, beta_over_alpha=boa))
    assert abs(y * st1 - 1.0) < 1e-12
    assert float(T.st_star(st1 * (1 - 1e-4), 1e30, beta_over_alpha=boa)) < 1.0
    assert float(T.st_star(st1 * (1 + 1e-4), 1e30, beta_over_alpha=boa)) == 1.0
    assert float(T.st_where_star_is_one_eq322(0.0)) == 1.0


def test_07_ch03():
    st = 1e-12
    assert rel(float(T.st_star(st, 1e30, method="ch03")) / st, 1.587401) < 1e-6
    assert abs(float(T.st_star(1.0, 1e30, method="ch03")) - 0.763143) < 1e-6
    # the two overflow-free branches are the same function (continuous at St = 1)
    lo = float(T.st_star(1 - 1e-12, 1e30, method="ch03"))
    hi = float(T.st_star(1 + 1e-12, 1e30, method="ch03"))
    assert abs(lo - hi) < 1e-11
    # ya: St* reaches 1 at St = 0.625
    assert float(T.st_star(0.625, RE8, method="ya")) == 1.0
    assert abs(float(T.st_star(0.5, RE8, method="ya")) - 0.8) < 1e-15


# ---------------------------------------------------------------- #8-#12: intermediate regime
def test_08_09_eq325():
    for eps, ref in [(0.0, 2.969231), (0.5, 2.292186), (1.0, 1.969231)]:
        assert abs(float(T.dv2_intermediate_eq325(1.0, eps, 1.6)) - ref) < 1e-6
    ya = float(T.ystar_exact(0.0))
    for eps, ref in [(0.0, 2.969859), (1.0, 1.969859)]:
        assert abs(float(T.dv2_intermediate_eq325(1.0, eps, ya)) - ref) < 1e-6


def test_10_full_form_intermediate():
    st1, re = 1e-4, 1e16
    ya = float(T.ystar_exact(0.0))
    for eps, ref in [(0.0, 2.969557), (0.1, 2.800824), (0.5, 2.292706), (1.0, 1.969757)]:
        val = dv2(st1, eps * st1, re) / st1
        assert rel(val, ref) < 1e-6
        assert rel(val, float(T.dv2_intermediate_eq325(1.0, eps, ya))) < 1e-3


def test_11_dv_over_vL():
    # v_L = sqrt(2/3) v_g, so Dv/(v_L sqrt(St1)) = sqrt(1.5 Dv^2/(v_g^2 St1))
    st1, re = 1e-4, 1e16
    for eps, ref in [(0.0, 2.1104), (1.0, 1.7187)]:
        full = np.sqrt(1.5 * dv2(st1, eps * st1, re) / st1)
        approx = np.sqrt(1.5 * float(T.dv2_intermediate_eq325(1.0, eps, 1.6)))
        assert rel(full, ref) < 1e-3
        assert rel(approx, ref) < 1e-3


def test_12_pieces_sum():
    for eps in (0.0, 0.5, 1.0):
        for ya in (1.6, 1.6003688037229952):
            tot = float(T.dv2_intermediate_eq325(1.0, eps, ya))
            parts = float(T.dv2_II_intermediate_eq334(1.0, eps, ya)) + float(T.dv2_I_intermediate_eq335(1.0, eps, ya))
            assert rel(parts, tot) < 1e-12


# ---------------------------------------------------------------- #13-#16: tightly coupled
def test_13_tightly_coupled_ratio():
    a, b = 1e-10, 3e-11
    assert rel(dv2(a, b, RE8) / (a - b) ** 2, 9998.9893) < 1e-6
    assert rel(float(T.dv2_small_eq324(a, b, RE8)) / (a - b) ** 2, 1e4) < 1e-12


def test_14_tightly_coupled_eq323():
    a, b = 1e-7, 3e-8
    full = dv2(a, b, RE8)
    e323 = float(T.dv2_tightly_coupled_eq323(a, b, RE8))
    assert rel(full, 4.894276e-11) < 1e-6
    assert rel(e323, 4.894766e-11) < 1e-6
    assert rel(full, e323) < 2e-4  # they differ by O(r) = 1e-4 (the (1-s), 1/(1+St) factors)
    # class II is exactly zero here
    assert terms(a, b, RE8)[1] == 0.0


def test_15_class_II_threshold():
    thr = 6.248706e-5
    r = 1e-4
    y = float(T.ystar_exact(thr))
    assert rel(y * thr, r) < 1e-6
    assert terms(thr * (1 - 1e-5), 1e-9, RE8)[1] == 0.0
    assert terms(thr * (1 + 1e-5), 1e-9, RE8)[1] > 0.0


def test_16_identical_tightly_coupled_zero_grad():
    f = lambda a, b: T.dv_turbulent_oc07(a, b, RE8)
    assert float(f(1e-6, 1e-6)) == 0.0
    g1, g2 = jax.grad(f, argnums=(0, 1))(1e-6, 1e-6)
    assert float(g1) == 0.0 and float(g2) == 0.0


# ---------------------------------------------------------------- #17-#19: heavy
@pytest.mark.parametrize("a,b", [(1.0, 0.3), (2.0, 1e-6), (10.0, 0.1), (1e6, 1e5), (1e3, 1e3)])
def test_17_heavy_exact(a, b):
    for re in (1e4, 1e8, 1e12):
        I, II, s = terms(a, b, re)
        assert I == 0.0 and s == 1.0
        ref = float(T.dv2_heavy_eq326(a, b, reynolds=re))
        assert rel(II, ref) < 1e-14


@pytest.mark.parametrize("a,b,ref", [(10.0, 0.1, -1.0e-11), (2.0, 1e-6, -3.75e-7), (1e6, 1e5, -1.0e-12)])
def test_18_heavy_vs_eq326(a, b, ref):
    full = dv2(a, b, 1e12)
    approx = float(T.dv2_heavy_eq326(a, b))
    d = (full - approx) / approx
    # 1e-6 relative tolerance on the difference, floored by float64 rounding of the totals
    # the reference prints the difference to 2-3 significant digits
    assert abs(d - ref) <= 2e-2 * abs(ref) + 2e-15


def test_19_unit_points():
    r = 1e-4
    assert rel(dv2(1.0, 1.0, RE8), (1 - r) * (1 + 2 * r) / (1 + r)) < 1e-12
    assert rel(dv2(1.0, 1.0, RE8), 0.99999998000) < 1e-11  # printed to 11 digits
    ref10 = (1 - r) * ((1 + 2 * r) / (2 * (1 + r)) + 1.0)
    assert rel(dv2(1.0, 0.0, RE8), ref10) < 1e-12
    assert rel(dv2(1.0, 0.0, RE8), 1.49989999) < 1e-8


# ---------------------------------------------------------------- #20-#22
@pytest.mark.parametrize("method", T.METHODS)
@pytest.mark.parametrize("accurate", [False, True])
def test_20_symmetry(method, accurate):
    st = jnp.logspace(-9, 3, 49)
    # full-shape arrays, so f(a, b) and f(b, a) run the same compiled program (different broadcast
    # patterns compile to differently fused code, which may differ in the last bits)
    a, b, re = jnp.broadcast_arrays(st[:, None, None], st[None, :, None],
                                    jnp.array([1e4, 1e8, 1e12])[None, None, :])
    f = lambda a, b, re: T.dv_turbulent_oc07(a, b, re, method=method, accurate=accurate)
    d1 = np.asarray(f(a, b, re))
    d2 = np.asarray(f(b, a, re))
    np.testing.assert_array_equal(d1, d2)  # bitwise
    np.testing.assert_array_equal(d1, np.transpose(d1, (1, 0, 2)))
    assert np.all(np.isfinite(d1)) and np.all(d1 >= 0)


def test_21_equal_small():
    assert dv(1e-5, 1e-5, RE8) == 0.0
    assert rel(dv(1e-4, 1e-4, RE8), 9.847625e-3) < 1e-6


@pytest.mark.parametrize("x0_kind", ["lower", "upper"])
@pytest.mark.parametrize("st2_kind", ["zero", "frac"])
def test_22_continuity_at_kinks(x0_kind, st2_kind):
    x0 = 6.248706e-5 if x0_kind == "lower" else 1.0
    if x0_kind == "lower":  # refine the kink St = r/y*(St) by fixed-point iteration
        for _ in range(50):
            x0 = 1e-4 / float(T.ystar_exact(x0))
    st2 = 0.0 if st2_kind == "zero" else 1e-3 * x0
    h = 1e-9 * x0
    lo = np.sqrt(dv2(x0 - h, st2, RE8))
    hi = np.sqrt(dv2(x0 + h, st2, RE8))
    assert abs(hi - lo) / lo < 1e-8


# ---------------------------------------------------------------- #23: peaks
def _peak(f, lo, hi, n=2001, zooms=4):
    g = jax.jit(jax.vmap(f))
    llo, lhi = np.log10(lo), np.log10(hi)
    for _ in range(zooms):
        x = np.linspace(llo, lhi, n)
        v = np.asarray(g(jnp.asarray(10.0 ** x)))
        i = int(np.argmax(v))
        llo, lhi = x[max(i - 2, 0)], x[min(i + 2, n - 1)]
    return 10.0 ** x[i], v[i]


@pytest.mark.parametrize("method,solid,ident", [
    ("exact", (0.964145, 1.226468), (0.915010, 1.009725)),
    ("ya", (0.625, 1.270938), (0.625, 1.109400)),
    ("ch03", (1.843996, 1.105917), (0.931898, 0.813431)),
])
def test_23_peaks(method, solid, ident):
    fs = lambda s: safe_sqrt(T.dv2_turbulent_oc07(s, 0.0, RE8, method=method))
    fi = lambda s: safe_sqrt(T.dv2_turbulent_oc07(s, s, RE8, method=method))
    for f, (x_ref, v_ref) in ((fs, solid), (fi, ident)):
        x, v = _peak(f, 0.05, 20.0)
        assert rel(x, x_ref) < 1e-5
        assert rel(v, v_ref) < 1e-5


def test_23_monotone_exact():
    f = jax.jit(lambda s: T.dv2_turbulent_oc07(s, 0.0, RE8))
    up = np.asarray(f(jnp.logspace(-8, np.log10(0.96), 400)))
    down = np.asarray(f(jnp.logspace(0, 4, 400)))
    assert np.all(np.diff(up) > 0)
    assert np.all(np.diff(down) < 0)


# ---------------------------------------------------------------- #24-#27
def test_24_accurate():
    st = jnp.logspace(-8, 3, 45)
    a, b = st[:, None, None], st[None, :, None]
    re = jnp.array([1e4, 1e8, 1e12, 1e30])[None, None, :]
    for method in T.METHODS:
        sa = T.st_star(a, re, method=method)
        sb = T.st_star(b, re, method=method)
        _, II = T.dv2_terms_oc07(a, b, sa, sb, re)
        _, IIa = T.dv2_terms_oc07(a, b, sa, sb, re, accurate=True)
        assert np.all(np.asarray(IIa) <= np.asarray(II) * (1 + 1e-12) + 1e-300)
        assert np.all(np.asarray(IIa) >= 0)
    _, II, _ = terms(0.1, 0.1, RE8)
    _, IIa, _ = terms(0.1, 0.1, RE8, accurate=True)
    assert abs(IIa / II - 0.6942) < 1e-3


def test_24_accurate_reduces_when_no_class_II():
    # St* = r for both: no fast eddies, accurate == simple == 0 for class II
    I, II, _ = terms(1e-8, 1e-9, RE8)
    Ia, IIa, _ = terms(1e-8, 1e-9, RE8, accurate=True)
    assert II == 0.0 and IIa == 0.0 and I == Ia


def test_25_I_h_I_g():
    assert abs(float(T.I_h(1.6)) - 0.6230808452568) < 1e-12
    assert abs(float(T.I_g(1.6)) - 0.3043617253297) < 1e-12
    for y in (1e-8, 1e-4, 5e-3, 1e-2, 0.02, 0.3, 1.6, 20.0):
        qh = integrate.quad(lambda z: z ** 1.5 / (1 + z), 0, y, epsabs=0, epsrel=2e-14)[0]
        qg = integrate.quad(lambda z: z ** 2 / (1 + z) ** 2, 0, y, epsabs=0, epsrel=2e-14)[0]
        assert rel(float(T.I_h(y)), qh) < 1e-12
        assert rel(float(T.I_g(y)), qg) < 1e-12


def test_26_vp_vpg_sum():
    st = jnp.logspace(-30, 25, 111)[:, None]
    re = jnp.array([0.5, 1.0, 1e4, 1e8, 1e12, 1e30])[None, :]
    tot = T.vp2_oc07(st, re) + T.vpg2_oc07(st, re)
    np.testing.assert_allclose(tot, 1.0, rtol=0, atol=1e-14)
    # eq. 3.5 literal form agrees where it does not cancel
    r = 1e-4
    s = jnp.logspace(-3, 3, 13)
    lit = 1 - s ** 2 * (1 - r) / ((s + 1) * (s + r))
    np.testing.assert_allclose(T.vp2_oc07(s, RE8), lit, rtol=1e-12)


def test_27_vpg_values():
    assert rel(float(jnp.sqrt(T.vpg2_oc07(1e-2, RE8))), 9.900495e-2) < 1e-6
    assert rel(float(jnp.sqrt(T.vpg2_oc07(1.0, RE8))), 7.070361e-1) < 1e-6


def test_vp2_accurate_le_tspace():
    st = jnp.logspace(-8, 3, 60)
    r = 1e-4
    tspace = T.vp2_oc07(st, RE8) - r  # eq. 3.11 = eq. 3.5 - r (typo #4)
    acc = T.vp2_oc07_accurate(st, RE8)
    assert np.all(np.asarray(acc) <= np.asarray(tspace) * (1 + 1e-12))
    # no class II (St* = r): identical
    np.testing.assert_allclose(T.vp2_oc07_accurate(1e-9, RE8), T.vp2_oc07(1e-9, RE8) - r, rtol=1e-12)


# ---------------------------------------------------------------- #28: Newton vs bracketing
def _bisect_root(rhs):
    F = lambda y: (2.0 / 3.0) * y * (y - 1.0) ** 2 - 1.0 / (1.0 + y)
    lo, hi = 1.0, 1.0 + (1.5 * max(rhs, 0.0) + 0.75) ** (1.0 / 3.0)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if F(mid) < rhs:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("boa", [0.0, 1.0, 100.0, 1e4])
def test_28_newton_vs_bisection(boa):
    st = np.logspace(-12, 0, 25)
    y = np.asarray(T.ystar_exact(jnp.asarray(st), beta_over_alpha=boa))
    rhs = (st / (1 + st)) * (boa / (1 + st) - 1)
    ref = np.array([_bisect_root(float(v)) for v in rhs])
    assert np.max(np.abs(y - ref) / ref) <= 1e-15


# ---------------------------------------------------------------- #29: derivatives
def test_29_ystar_derivatives():
    gy = jax.grad(lambda s: T.ystar_exact(s))
    gs = jax.grad(lambda s: T.st_star(s, 1e30))
    for st, dy, ds in [(1e-3, -0.598647436, 1.59917130), (0.1, -0.563708798, 1.48596521),
                       (0.5, -0.529161173, 1.06457896), (0.9, -0.768020290, 0.39574701)]:
        assert rel(float(gy(st)), dy) < 1e-8
        assert rel(float(gs(st)), ds) < 3e-8  # 9 printed digits
    # exact IFT Hessian (custom_jvp), not the one-step value -0.70554823
    h = float(jax.grad(jax.grad(lambda s: T.st_star(s, 1e30)))(0.5))
    assert rel(h, -1.12089449) < 1e-7
    # the IFT gradient matches a central difference of the Newton solution itself
    eps = 1e-6
    fd = (float(T.ystar_exact(0.3 + eps)) - float(T.ystar_exact(0.3 - eps))) / (2 * eps)
    assert rel(float(gy(0.3)), fd) < 1e-7
    # beta/alpha > 0 gradient vs central difference
    g = float(jax.grad(lambda s: T.ystar_exact(s, beta_over_alpha=3.0))(0.2))
    fd = (float(T.ystar_exact(0.2 + eps, beta_over_alpha=3.0)) - float(T.ystar_exact(0.2 - eps, beta_over_alpha=3.0))) / (2 * eps)
    assert rel(g, fd) < 1e-7


DERIV = [
    (1e-6, 3e-7, 1e8, 6.96250420e-5, 9.91381309e1, -9.96059270e1, 1.7224e-5),
    (1e-3, 1e-5, 1e8, 5.33876767e-2, 2.78531169e1, -8.66631870, 5.4567e-4),
    (1e-2, 1e-4, 1e8, 1.71092225e-1, 8.56278791, -4.34189143, 1.1247e-4),
    (0.5, 0.05, 1e8, 1.01768777, 7.65684437e-1, -5.18021603e-1, 1.0780e-7),
    (3.0, 0.3, 1e8, 1.00956958, -3.09537848e-2, -2.93053534e-1, 1.8097e-8),
    (1e-3, 1e-5, 1e12, 5.43153028e-2, 2.73013569e1, -1.60500904e1, 8.0802e-7),
]


@pytest.mark.parametrize("a,b,re,v,da,db,dlnre", DERIV)
def test_29_dv_derivative_table(a, b, re, v, da, db, dlnre):
    f = lambda a, b, lnre: T.dv_turbulent_oc07(a, b, jnp.exp(lnre))
    val, (ga, gb, gr) = jax.value_and_grad(f, argnums=(0, 1, 2))(a, b, jnp.log(re))
    assert rel(float(val), v) < 1e-8
    assert rel(float(ga), da) < 1e-5
    assert rel(float(gb), db) < 1e-5
    # reference: 1e-9 absolute; its d/dlnRe column is printed to 5 digits, so allow half a unit there
    assert abs(float(gr) - dlnre) < max(1e-9, 5e-5 * abs(dlnre))


def test_29_tie_gradient():
    # max(St*_1, St*_2) at a tie: JAX splits the gradient 1/2-1/2 = central difference (velocity hazard 5, item 3)
    ga, gb = jax.grad(lambda a, b: T.dv_turbulent_oc07(a, b, RE8), argnums=(0, 1))(0.1, 0.1)
    assert rel(float(ga), 1.02640450) < 1e-6
    assert rel(float(gb), 1.02640450) < 1e-6


# ---------------------------------------------------------------- #30: float32
def test_30_float32_bounded_form():
    f32 = jnp.float32
    for (a, b), ref in [((1e6, 1e5), 1.099990e-5), ((1e20, 1e19), 1.100000e-19)]:
        v32 = T.dv2_turbulent_oc07(jnp.array(a, f32), jnp.array(b, f32), jnp.array(RE8, f32))
        assert v32.dtype == f32
        v64 = dv2(a, b, RE8)
        assert rel(float(v32), ref) < 1e-6
        assert rel(float(v32), v64) < 1e-6


# ---------------------------------------------------------------- §10.1 table
TABLE = [
    # St1, St2, Re, St*12, dvI2, dvII2, exact, ya, ch03
    (1e-8, 1e-9, 1e8, 1.000000e-4, 8.098373e-13, 0, 8.999096e-7, 8.999096e-7, 8.999096e-7),
    (1e-6, 1e-7, 1e8, 1.000000e-4, 8.018264e-9, 0, 8.954476e-5, 8.954476e-5, 8.954476e-5),
    (1e-5, 1e-5, 1e8, 1.000000e-4, 0, 0, 0, 0, 0),
    (1e-4, 1e-6, 1e8, 1.600309e-4, 3.767956e-5, 1.085151e-4, 1.209110e-2, 1.208892e-2, 1.199969e-2),
    (1e-4, 1e-4, 1e8, 1.600309e-4, 0, 9.697572e-5, 9.847625e-3, 9.844952e-3, 9.735373e-3),
    (1e-3, 1e-5, 1e8, 1.599770e-3, 3.759926e-4, 2.474251e-3, 5.338768e-2, 5.339135e-2, 5.318866e-2),
    (1e-3, 1e-3, 1e8, 1.599770e-3, 0, 1.950657e-3, 4.416624e-2, 4.417068e-2, 4.392588e-2),
    (1e-2, 1e-4, 1e8, 1.594399e-2, 3.680481e-3, 2.559207e-2, 1.710922e-1, 1.713713e-1, 1.706377e-1),
    (1e-2, 1e-2, 1e8, 1.594399e-2, 0, 1.959491e-2, 1.399818e-1, 1.403222e-1, 1.394269e-1),
    (0.1, 1e-3, 1e8, 1.542336e-1, 2.963879e-2, 2.467984e-1, 5.257729e-1, 5.350163e-1, 5.227846e-1),
    (0.1, 0.1, 1e8, 1.542336e-1, 0, 1.871348e-1, 4.325908e-1, 4.437599e-1, 4.289605e-1),
    (0.5, 0.05, 1e8, 6.645798e-1, 3.836081e-2, 9.973276e-1, 1.017688, 1.125064, 9.264170e-1),
    (0.5, 0.5, 1e8, 6.645798e-1, 0, 7.584989e-1, 8.709184e-1, 9.922779e-1, 7.648342e-1),
    (1, 1e-2, 1e8, 1, 0, 1.490098, 1.220696, 1.220696, 1.072097),
    (1, 1, 1e8, 1, 0, 1.000000, 1.000000, 1.000000, 8.127876e-1),
    (10, 1e-3, 1e8, 1, 0, 1.089901, 1.043983, 1.043983, 1.042259),
    (10, 10, 1e8, 1, 0, 1.818182e-1, 4.264014e-1, 4.264014e-1, 4.221649e-1),
    (100, 1, 1e8, 1, 0, 5.099010e-1, 7.140735e-1, 7.140735e-1, 7.140609e-1),
    (1e-8, 1e-9, 1e12, 1.000000e-6, 8.019066e-11, 0, 8.954924e-6, 8.954924e-6, 8.954924e-6),
    (1e-6, 1e-7, 1e12, 1.600368e-6, 3.098282e-7, 1.082088e-6, 1.179795e-3, 1.179525e-3, 1.170254e-3),
    (1e-4, 1e-6, 1e12, 1.600309e-4, 3.767956e-5, 2.570151e-4, 1.716667e-2, 1.716514e-2, 1.710241e-2),
    (1e-2, 1e-2, 1e12, 1.594399e-2, 0, 1.959689e-2, 1.399889e-1, 1.403293e-1, 1.394340e-1),
    (0.5, 0.05, 1e12, 6.645798e-1, 3.836081e-2, 9.973278e-1, 1.017688, 1.125064, 9.264171e-1),
    (1e-4, 1e-6, 1e4, 1.000000e-2, 9.605951e-7, 0, 9.800995e-4, 9.800995e-4, 9.800995e-4),
    (1e-2, 1e-4, 1e4, 1.594399e-2, 3.680481e-3, 1.074207e-2, 1.200939e-1, 1.204912e-1, 1.194455e-1),
    (1, 1, 1e4, 1, 0, 9.998020e-1, 9.999010e-1, 9.999010e-1, 8.126658e-1),
]


def _close(x, ref, rtol=1e-6, atol=1e-15):
    return abs(x - ref) <= rtol * abs(ref) + atol


@pytest.mark.parametrize("row", TABLE, ids=lambda r: f"{r[0]:g}-{r[1]:g}-{r[2]:g}")
def test_table_10_1(row):
    a, b, re, s_ref, I_ref, II_ref, ex, ya, ch = row
    I, II, s = terms(a, b, re)
    assert _close(s, s_ref)
    assert _close(I, I_ref)
    assert _close(II, II_ref)
    if II_ref == 0:
        assert II == 0.0
    if a == b:
        assert I == 0.0
    for method, ref in (("exact", ex), ("ya", ya), ("ch03", ch)):
        assert _close(dv(a, b, re, method=method), ref)


FIG33 = [  # St1, identical, St2 -> 0 (St2 = 0)
    (1e-6, 0.0, 9.949869e-5), (1e-5, 0.0, 9.534101e-4), (1e-4, 9.847625e-3, 1.212294e-2),
    (1e-3, 4.416624e-2, 5.346727e-2), (1e-2, 1.399818e-1, 1.714552e-1), (0.1, 4.325908e-1, 5.272040e-1),
    (0.3, 7.119773e-1, 8.588253e-1), (1, 1.000000, 1.224704), (3, 7.071068e-1, 1.117989),
    (10, 4.264014e-1, 1.044418), (100, 1.407195e-1, 1.004889),
]


@pytest.mark.parametrize("st1,ident,solid", FIG33)
def test_table_10_2(st1, ident, solid):
    assert _close(np.sqrt(dv2(st1, st1, RE8)), ident)
    assert _close(np.sqrt(dv2(st1, 0.0, RE8)), solid)


def test_table_10_2_limits():
    assert rel(float(jnp.sqrt(T.dv2_small_eq324(1e-6, 0.0, RE8))), 1e-4) < 1e-12
    for st1, e0, e1 in [(1e-4, 1.723146e-2, 1.403293e-2), (0.3, 9.438057e-1, 7.686151e-1)]:
        assert rel(float(jnp.sqrt(T.dv2_intermediate_eq325(st1, 0.0, 1.6))), e0) < 1e-6
        assert rel(float(jnp.sqrt(T.dv2_intermediate_eq325(st1, 1.0, 1.6))), e1) < 1e-6
    for st1, solid, ident in [(1, 1.224745, 1.0), (3, 1.118034, 7.071068e-1), (100, 1.004938, 1.407195e-1)]:
        assert rel(float(jnp.sqrt(T.dv2_heavy_eq326(st1, 0.0))), solid) < 1e-6
        assert rel(float(jnp.sqrt(T.dv2_heavy_eq326(st1, st1))), ident) < 1e-6


# ---------------------------------------------------------------- transforms
@pytest.mark.parametrize("method,accurate", [
    ("exact", False), ("exact", True),
    pytest.param("ya", False, marks=pytest.mark.slow), pytest.param("ch03", False, marks=pytest.mark.slow),
    pytest.param("ya", True, marks=pytest.mark.slow), pytest.param("ch03", True, marks=pytest.mark.slow)])
def test_jit_equals_eager_and_vmap_equals_loop(method, accurate):
    a = jnp.array([1e-7, 1e-4, 0.05, 0.5, 3.0, 1e3])
    b = jnp.array([3e-8, 1e-4, 0.5, 0.01, 3.0, 1e-30])
    re = jnp.array([1e8, 1e12, 1e4, 1e8, 1e30, 1e8])
    f = lambda a, b, re: T.dv_turbulent_oc07(a, b, re, method=method, accurate=accurate)
    eager = f(a, b, re)
    np.testing.assert_allclose(jax.jit(f)(a, b, re), eager, rtol=1e-14, atol=0)
    stacked = jnp.stack([f(a[i], b[i], re[i]) for i in range(a.shape[0])])
    np.testing.assert_allclose(jax.vmap(f)(a, b, re), stacked, rtol=1e-14, atol=0)
    np.testing.assert_allclose(eager, stacked, rtol=1e-14, atol=0)
    # gradients too: vmap(grad) == stacked grad
    g = jax.grad(f, argnums=(0, 1))
    gv = jax.vmap(g)(a[:3], b[:3], re[:3])
    for i in range(3):
        gi = g(a[i], b[i], re[i])
        np.testing.assert_allclose([gv[0][i], gv[1][i]], gi, rtol=1e-12, atol=0)


def test_matrix_from_per_particle_st_star():
    # N x N kernel from N root solves (velocity hazard 6) == the pairwise convenience function
    st = jnp.logspace(-7, 2, 40)
    re = 1e8
    s = T.st_star(st, re)
    I, II = T.dv2_terms_oc07(st[:, None], st[None, :], s[:, None], s[None, :], re)
    direct = T.dv2_turbulent_oc07(st[:, None], st[None, :], re)
    np.testing.assert_allclose(I + II, direct, rtol=1e-15, atol=0)


def test_w84_legacy():
    ts, tL, vs, vL = 1.0, 1e4, 1.0, 10.0
    w = lambda a, b: float(T.dv_turbulent_w84(a, b, ts, tL, vs, vL))
    assert w(0.5, 0.2) == pytest.approx(0.3, rel=1e-14)
    assert w(4.0, 4.0) == pytest.approx(1.5 * 2.0, rel=1e-14)   # 3/(1+1) sqrt(4): 1.5 for equal (typo #17)
    assert w(4.0, 1e-9) == pytest.approx(3.0 * 2.0, rel=1e-8)   # 3.0 for t1 >> t2
    assert w(1e3, 1e3) == vL                                     # capped at v_L
    assert w(2e4, 10.0) == vL
    assert w(2e4, 4e4) == pytest.approx(vL * (6e4) * tL / (2 * 2e4 * 4e4), rel=1e-14)
    assert w(0.2, 0.5) == w(0.5, 0.2)


def test_errors():
    from jaxcoag._validate import JaxcoagInputError
    for bad in [(0.0, 0.1, 1e8), (-1.0, 0.1, 1e8), (np.nan, 0.1, 1e8), (0.1, 0.0, 1e8),
                (0.1, 0.1, 0.0), (0.1, 0.1, -5.0), (0.1, 0.1, np.nan)]:
        with pytest.raises(JaxcoagInputError, match="must be"):
            T.dv_turbulent_oc07(*bad)
    with pytest.raises(ValueError, match="valid methods"):
        T.dv_turbulent_oc07(0.1, 0.1, 1e8, method="exactly")
    with pytest.raises(ValueError, match="ya"):
        T.st_star(0.1, 1e8, method="bogus")


def test_vmap_over_beta_over_alpha_and_hessian_of_dv():
    boa = jnp.array([0.0, 0.1, 1.0, 10.0])
    f = lambda b: T.st_star(0.4, 1e8, beta_over_alpha=b)
    np.testing.assert_allclose(jax.vmap(f)(boa), jnp.stack([f(b) for b in boa]), rtol=1e-15)
    np.testing.assert_allclose(jax.vmap(f)(boa), T.st_star(0.4, 1e8, beta_over_alpha=boa), rtol=1e-15)
    # second derivative of Delta v through the root (custom_jvp) vs central FD of jax.grad
    g = jax.grad(lambda a: T.dv_turbulent_oc07(a, 0.05, 1e8))
    h = float(jax.grad(g)(0.3))
    eps = 1e-5
    fd = (float(g(0.3 + eps)) - float(g(0.3 - eps))) / (2 * eps)
    assert rel(h, fd) < 1e-6
