"""Issue 12.6: the 'jump' of Delta v in the default scene is the OC07 regime boundary t*_12 = t_s.

Ormel & Cuzzi (2007) (= Ormel 2008 thesis ch. 3) clip the class boundary at the Kolmogorov time,
t_s <= t*_12 (text after eqs. 3.12 and 3.15b), so Delta v_II = 0 up to St_1 = St_k with
y*(St_k) St_k = Re^-1/2 (t_1 = t_s/y*, §3.3.4) and the class-II integral of eq. 3.14 opens linearly
above it: Delta v is continuous but its slope jumps. Every reference below is computed here, in
numpy/scipy, from the thesis formulas (gas eqs. 1.13-1.18, 4.7; St of an Epstein sphere; y* of
eq. 3.18d by brentq; eqs. 3.15a/b as printed; quadrature of eq. 3.13; Brownian eq. 4.4; radial drift
eq. 4.8), never from jaxcoag.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from _scripts import ROOT, load_script  # noqa: E402
from jaxcoag import config
from jaxcoag.physics import turbulence as T

K_B, M_H, G_N, M_SUN, AU = 1.380649e-16, 1.6735575e-24, 6.67430e-8, 1.98847e33, 1.495978707e13
MU, SIGMA_MOL = 2.34, 2.0e-15


# ------------------------------------------------------------------ independent reference (numpy/scipy)
class Ref:
    """Default-run gas (MMSN 1 AU midplane, Sigma = 1700 g cm^-2, T = 280 K) and dust by hand."""

    def __init__(self, alpha=1e-3, rho_s=1.6, a0=1e-4, T=280.0, Sigma=1700.0):
        self.T, self.rho_s = T, rho_s
        c = math.sqrt(K_B * T / (MU * M_H))
        om = math.sqrt(G_N * M_SUN / AU ** 3)
        H = c / om
        self.rho_g = Sigma / (math.sqrt(2 * math.pi) * H)
        l_mfp = MU * M_H / (self.rho_g * SIGMA_MOL)
        self.Re = 2 * alpha * H / l_mfp
        self.r = self.Re ** -0.5
        self.v_g = math.sqrt(1.5 * alpha) * c
        self.v_K = AU * om
        self.eta = 13 / 8 * (c / self.v_K) ** 2
        self.st_per_a = rho_s * om / (c * self.rho_g)       # Epstein: St = rho_s a Omega/(c_g rho_g)
        self.m0 = 4 / 3 * math.pi * rho_s * a0 ** 3

    def st(self, m):
        return self.st_per_a * (3 * m / (4 * math.pi * self.rho_s)) ** (1 / 3)

    def mass(self, st):
        return 4 / 3 * math.pi * self.rho_s * (st / self.st_per_a) ** 3

    def dv_tot(self, m1, m2):
        a, b = self.st(m1), self.st(m2)
        dI, dII = dv2_315(a, b, self.r)
        bm2 = 8 * K_B * self.T / math.pi * (1 / m1 + 1 / m2)
        rd2 = (2 * self.eta * self.v_K * (a / (1 + a * a) - b / (1 + b * b))) ** 2
        return math.sqrt(bm2 + self.v_g ** 2 * (dI + dII) + rd2), dI, dII


def ystar(st):
    """Root of (2/3) y (y-1)^2 - 1/(1+y) = -St/(1+St) (eq. 3.18d), St <= 1."""
    return brentq(lambda y: 2 / 3 * y * (y - 1) ** 2 - 1 / (1 + y) + st / (1 + st), 0.9, 1.7, xtol=1e-15, rtol=1e-15)


def st_kink(r):
    """St_1 where y*(St_1) St_1 = r (t*_1 = t_s)."""
    return brentq(lambda s: ystar(s) * s - r, 0.1 * r, r, xtol=1e-24, rtol=1e-15)


def dv2_315(a, b, r, s=None):
    """(Delta v_I^2, Delta v_II^2)/v_g^2 from the printed eqs. 3.15a/b; s = St*_12 = max(clip(y* St_i, r, 1))."""
    if s is None:
        s = max(min(max(ystar(min(x, 1)) * min(x, 1), r), 1) for x in (a, b))
    dI = (a - b) / (a + b) * (a * a / (s + a) - a * a / (1 + a) - b * b / (s + b) + b * b / (1 + b))
    dII = 2 * (s - r) + a * a / (a + s) - a * a / (a + r) + b * b / (b + s) - b * b / (b + r)
    return dI, dII


def dv2_quad_313(a, b, r):
    """Delta v^2/v_g^2 by quadrature of eq. 3.13 in t-space (t_L = 1), K_x = x/(x + t):
    sum_i int_r^s (1 - K_i^2) dt + int_s^1 ((a - b)/(a + b)) (K_a^2 - K_b^2) dt."""
    s = max(min(max(ystar(x) * x, r), 1) for x in (a, b))
    II = quad(lambda t: 2 - (a / (a + t)) ** 2 - (b / (b + t)) ** 2, r, s, epsabs=0, epsrel=1e-13)[0] if s > r else 0.0
    I = quad(lambda t: (a - b) / (a + b) * ((a / (a + t)) ** 2 - (b / (b + t)) ** 2), s, 1, epsabs=0, epsrel=1e-13,
             limit=200)[0]
    return I + II


def one_sided_slopes(b, r):
    """d(Delta v^2/v_g^2)/dSt_1 at St_k from the left (s = r: complex step of eq. 3.15a) and from the
    right: left + D s', D = 2 - 2 (a K_a^2 + b K_b^2)/(a + b), s' = y* - St/((1 + St)^2 F'(y*))."""
    a = st_kink(r)
    h = 1e-30 * a
    left = dv2_315(complex(a, h), b, r, s=r)[0].imag / h
    Ka, Kb = a / (a + r), b / (b + r)
    D = 2 - 2 * (a * Ka ** 2 + b * Kb ** 2) / (a + b)
    y = ystar(a)
    dF = 2 / 3 * (y - 1) * (3 * y - 1) + 1 / (1 + y) ** 2
    return left, left + D * (y - a / ((1 + a) ** 2 * dF))


# ------------------------------------------------------------------ library side
@pytest.fixture(scope="module")
def built():
    cfg = config.default()
    assert cfg["gas"]["model"] == "mmsn_hayashi81" and cfg["gas"]["R_au"] == 1.0 and cfg["gas"]["alpha"] == 1e-3
    assert cfg["dust"]["rho_s"] == 1.6 and cfg["dust"]["a0"] == 1e-4
    return config.build(cfg)


@pytest.fixture(scope="module")
def ref():
    return Ref()


def _dv_tot(K):
    return jax.jit(lambda m1, m2: jnp.sqrt(K.relative_velocity2(m1, m2)))


def test_boundary_position(built, ref):
    K, gas = built.kernel, built.gas
    assert float(gas.Re) == pytest.approx(ref.Re, rel=1e-12)
    r = float(gas.Re_eff) ** -0.5
    excess = jax.jit(lambda lm: T.st_star(K.particles(jnp.exp(lm)).st, gas.Re_eff) - r)
    lo, hi = math.log(1e-7), math.log(1e-3)
    while hi - lo > 1e-12:                       # bisection on St*_1(m) > r in the library
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if float(excess(mid)) <= 0 else (lo, mid)
    st_k = st_kink(ref.r)
    m_k = ref.mass(st_k)
    assert st_k == pytest.approx(2.3741193145e-5, rel=1e-9)     # y*(St_k) = 1.60035458
    assert math.exp(lo) == pytest.approx(m_k, rel=1e-9)
    assert m_k == pytest.approx(6.8301969882e-6, rel=1e-9)      # a = 100.63 um
    # the default grid is m0 10^(k/7): the boundary lies between the bins k = 42 and 43
    c = np.asarray(built.grid.centers)
    mA, mB = ref.m0 * 10 ** 6, ref.m0 * 10 ** (43 / 7)
    i = int(np.searchsorted(c, m_k)) - 1
    assert c[i] == pytest.approx(mA, rel=1e-12) and c[i + 1] == pytest.approx(mB, rel=1e-12)
    assert mA < m_k < mB


@pytest.mark.parametrize("partner", ["monomer", "issue"])
def test_step_between_bins(built, ref, partner):
    """Delta v_tot at the two bins around m_k equals the hand sum; the left bin is class-I only."""
    K = built.kernel
    p = ref.m0 if partner == "monomer" else 10 ** -7.9
    mA, mB = ref.m0 * 10 ** 6, ref.m0 * 10 ** (43 / 7)
    f = _dv_tot(K)
    (vA, dIA, dIIA), (vB, dIB, dIIB) = ref.dv_tot(mA, p), ref.dv_tot(mB, p)
    assert float(f(jnp.asarray(mA), jnp.asarray(p))) == pytest.approx(vA, rel=1e-10)
    assert float(f(jnp.asarray(mB), jnp.asarray(p))) == pytest.approx(vB, rel=1e-10)
    assert dIIA == 0.0 and dIIB > 0.5 * dIB                     # class II switched on between the bins
    pa, pb = K.particles(jnp.asarray([mA, mB])), K.particles(jnp.asarray([p, p]))
    sa, sb = T.st_star(pa.st, built.gas.Re_eff), T.st_star(pb.st, built.gas.Re_eff)
    lib_I, lib_II = T.dv2_terms_oc07(pa.st, pb.st, sa, sb, built.gas.Re_eff)
    assert float(lib_II[0]) == 0.0
    np.testing.assert_allclose(np.asarray(lib_I), [dIA, dIB], rtol=1e-9)
    np.testing.assert_allclose(float(lib_II[1]), dIIB, rtol=1e-9)
    if partner == "monomer":
        assert (vA, vB) == pytest.approx((11.455004, 16.129359), rel=1e-7)
    else:  # a 12.4 um partner reproduces the numbers of the issue (10.1 -> 15.2 cm/s)
        assert (round(vA, 1), round(vB, 1)) == (10.1, 15.2)


@pytest.mark.parametrize("re, b_frac", [(692727586.1871511, 0.01), (692727586.1871511, 0.5), (1e8, 1e-6), (1e12, 0.3)])
def test_continuous_with_slope_break(re, b_frac):
    """C^0 at St_k (relative change ~ slope x step) and jax.grad equals the one-sided analytic slopes."""
    r = re ** -0.5
    st_k, b = st_kink(r), b_frac * st_kink(r)
    f = jax.jit(lambda a: T.dv2_turbulent_oc07(a, b, re))
    g = jax.grad(lambda a: T.dv2_turbulent_oc07(a, b, re))
    gj = jax.jit(g)
    left, right = one_sided_slopes(b, r)
    v0 = dv2_315(st_k, b, r, s=r)[0]
    h = 1e-9
    assert float(f(st_k * (1 - h))) == pytest.approx(v0 - left * st_k * h, rel=1e-12)
    assert float(f(st_k * (1 + h))) == pytest.approx(v0 + right * st_k * h, rel=1e-12)
    assert float(g(st_k * (1 - 1e-8))) == pytest.approx(left, rel=1e-6)
    assert float(gj(st_k * (1 + 1e-8))) == pytest.approx(right, rel=1e-6)
    assert right / left > 4.0                                  # the break that reads as a 'jump'


def test_default_scene_slope_numbers(built, ref):
    """d ln Delta v_tot/d ln m at m_k: 0.2726 below, 1.4799 above (jax.grad through the scene kernel)."""
    K = built.kernel
    st_k = st_kink(ref.r)
    m_k = ref.mass(st_k)
    b = ref.st(ref.m0)
    left, right = one_sided_slopes(b, ref.r)
    v, _, _ = ref.dv_tot(m_k, ref.m0)
    e = 1e-6

    def rest(m):  # Brownian^2 + radial drift^2 by hand
        a = ref.st(m)
        return (8 * K_B * ref.T / math.pi * (1 / m + 1 / ref.m0)
                + (2 * ref.eta * ref.v_K * (a / (1 + a * a) - b / (1 + b * b))) ** 2)

    d_rest = (rest(m_k * (1 + e)) - rest(m_k * (1 - e))) / (2 * e)
    exp_l = (ref.v_g ** 2 * left * st_k / 3 + d_rest) / (2 * v * v)   # St ~ m^1/3 (Epstein)
    exp_r = (ref.v_g ** 2 * right * st_k / 3 + d_rest) / (2 * v * v)
    g = jax.jit(jax.grad(lambda lm: 0.5 * jnp.log(K.relative_velocity2(jnp.exp(lm), jnp.asarray(ref.m0)))))
    assert float(g(math.log(m_k) - 3e-7)) == pytest.approx(exp_l, rel=1e-5)
    assert float(g(math.log(m_k) + 3e-7)) == pytest.approx(exp_r, rel=1e-5)
    assert (exp_l, exp_r) == pytest.approx((0.272592, 1.479934), rel=1e-5)


def test_break_is_in_the_exact_integral_form(ref):
    """Quadrature of eq. 3.13 (no closed form) equals the library across St_k and has the same one-sided
    slopes; without the t*_12 >= t_s clip the class-II term of eq. 3.15b would be negative."""
    r, b = ref.r, ref.st(ref.m0)
    st_k = st_kink(r)
    for f in (0.5, 0.999, 1.001, 1.5, 10.0):
        assert float(T.dv2_turbulent_oc07(f * st_k, b, ref.Re)) == pytest.approx(dv2_quad_313(f * st_k, b, r),
                                                                               rel=1e-9)
    left, right = one_sided_slopes(b, r)
    d = 1e-4
    q0 = dv2_quad_313(st_k, b, r)
    fd_left = (q0 - dv2_quad_313(st_k * (1 - d), b, r)) / (d * st_k)
    fd_right = (dv2_quad_313(st_k * (1 + d), b, r) - q0) / (d * st_k)
    assert fd_left == pytest.approx(left, rel=2e-3)
    assert fd_right == pytest.approx(right, rel=2e-3)
    a = 0.5 * st_k
    assert dv2_315(a, b, r, s=ystar(a) * a)[1] < 0.0


@pytest.mark.parametrize("method, accurate", [("exact", True), ("ya", False), ("ch03", False)])
def test_break_for_every_tstar_method(method, accurate):
    """The class-II term opens at St*_1 = r for every t* prescription and for App. 3.A (accurate=True):
    at the boundary the App. 3.A power laws equal 1, so the right slope is the g = h = 1 one."""
    re = 1e8
    r = re ** -0.5
    b = 1e-3 * r
    if method == "exact":
        st_k = st_kink(r)
        ds = ystar(st_k) - st_k / ((1 + st_k) ** 2 * (2 / 3 * (ystar(st_k) - 1) * (3 * ystar(st_k) - 1)
                                                    + 1 / (1 + ystar(st_k)) ** 2))
    elif method == "ya":
        st_k, ds = r / 1.6, 1.6
    else:  # ch03: St* = St (St^1.5 + 0.5)^-2/3 = r
        st_k = brentq(lambda s: s * (s ** 1.5 + 0.5) ** (-2 / 3) - r, 0.1 * r, r, xtol=1e-24, rtol=1e-15)
        u = st_k ** 1.5 + 0.5
        ds = u ** (-2 / 3) - st_k * (2 / 3) * u ** (-5 / 3) * 1.5 * st_k ** 0.5
    g = jax.grad(lambda a: T.dv2_turbulent_oc07(a, b, re, method=method, accurate=accurate))
    left = dv2_315(complex(st_k, 1e-30 * st_k), b, r, s=r)[0].imag / (1e-30 * st_k)
    Ka, Kb = st_k / (st_k + r), b / (b + r)
    D = 2 - 2 * (st_k * Ka ** 2 + b * Kb ** 2) / (st_k + b)
    assert float(g(st_k * (1 - 1e-8))) == pytest.approx(left, rel=1e-6)
    assert float(g(st_k * (1 + 1e-8))) == pytest.approx(left + D * ds, rel=1e-6)


def test_figure_script_quick(tmp_path, ref):
    mod = load_script(ROOT / "paper_figs" / "fig_dv_regimes.py", "_paper_fig_")
    res = mod.main(["--quick", "--out", str(tmp_path)])
    bad = {k: v for k, v in res["checks"].items() if not v["ok"]}
    assert not bad, bad
    png = res["png"]
    assert png.exists() and png.stat().st_size > 10_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert res["m_k"] == pytest.approx(ref.mass(st_kink(ref.r)), rel=1e-12)
    assert res["steps"]["monomer"] == pytest.approx((11.455004, 16.129359), rel=1e-7)
    assert res["slopes"] == pytest.approx((0.272592, 1.479934), rel=1e-5)
