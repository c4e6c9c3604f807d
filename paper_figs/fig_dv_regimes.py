"""Relative velocity in the default scene against a fixed partner: the OC07 t*_12 = t_s regime boundary.

Issue 12, point 6: in the default scene (``jaxcoag run``: MMSN midplane at 1 AU, alpha = 1e-3,
T = 280 K, rho_s = 1.6; Brownian + OC07 turbulence + radial drift) Delta v_tot against a fixed small
partner rises from ~10-11 to ~15-16 cm/s between the grid bins at 6.70e-6 g and 9.31e-6 g.

Finding: this is not a jump but a slope break (Delta v is continuous, its slope is not). It is the
boundary t_1 = t_s/y* between the tightly coupled and the intermediate regime of Ormel & Cuzzi
(2007) (= Ormel 2008 thesis §3.3.4): the class boundary t*_12 = max(y* tau_f, t_s) is clipped at the
Kolmogorov time t_s (thesis text after eqs. 3.12 and 3.15b, t_s <= t*_12 <= t_L). Below it only
class-I eddies act (Delta v_II = 0, eq. 3.23); above it the class-II integral of eq. 3.14 over
[t_s, t*_12] opens linearly, with an O(1) integrand, so d Delta v^2/d St_1 jumps by
(d St*/d St) [2 - 2 (St_1 K_1^2 + St_2 K_2^2)/(St_1 + St_2)], K_i = St_i/(St_i + Re^-1/2)
(derivative of eq. 3.14 with respect to t*_12 at t*_12 = t_s). The same break is in the exact integral
form eq. 3.13 (evaluated here by quadrature), so the closed form is not at fault. On the default grid
(7 bins per decade, mass ratio 1.39, St ratio 1.116) the break between two bins looks like a jump.

Everything the library computes is compared with an independent numpy/scipy evaluation: the gas state
from the formulas (thesis eqs. 1.13-1.17, 4.7), St of a compact Epstein sphere, y* by bracketing root
of eq. 3.18d (scipy brentq), the thesis form eqs. 3.15a/b, the quadrature of eq. 3.13, Brownian
(eq. 4.4) and radial drift (eq. 4.8).

Panels: (a) Delta v_tot and each contribution (Brownian, turbulence and its class-I / class-II parts,
radial drift; the default scene has no settling or azimuthal drift) against m for the monomer partner
(a = 1 um), with the regime boundary, the default-grid bins and the limiting forms eq. 3.23 and
eq. 3.25 (eps -> 0); (b) the local slope d ln Delta v_tot/d ln m (jax.grad) with the one-sided
analytic slopes at the boundary.

Run: python paper_figs/fig_dv_regimes.py [--quick] [--out DIR]   (docs/velocity_jump.png: --out docs)
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

# cgs constants (CODATA 2018 / IAU 2015 nominal values), typed in independently of jaxcoag.constants
K_B, M_H, G_N, M_SUN, AU = 1.380649e-16, 1.6735575e-24, 6.67430e-8, 1.98847e33, 1.495978707e13
MU, SIGMA_MOL = 2.34, 2.0e-15
PARTNER_ISSUE = 10.0 ** -7.9  # [g] (a = 12.4 um): the partner that gives the issue's 10.1 -> 15.2 cm/s


class Hand:
    """Independent float64 numpy/scipy evaluation of the default scene (no jaxcoag code).

    Hayashi (1981) MMSN midplane at R = 1 AU: Sigma_g = 1700 g cm^-2, T = 280 K; c_g = (k_B T/(mu m_H))^1/2,
    Omega = (G M_sun/R^3)^1/2, H_g = c_g/Omega, rho_g = Sigma_g/((2 pi)^1/2 H_g), l_mfp = mu m_H/(rho_g sigma_mol),
    Re = 2 alpha H_g/l_mfp, v_g = (3 alpha/2)^1/2 c_g, eta = (13/8)(c_g/v_K)^2 (thesis eqs. 1.13-1.18, 4.2, 4.7).
    """

    def __init__(self, alpha, rho_s, T=280.0, Sigma=1700.0):
        self.alpha, self.rho_s, self.T = alpha, rho_s, T
        self.c = math.sqrt(K_B * T / (MU * M_H))
        self.Om = math.sqrt(G_N * M_SUN / AU ** 3)
        H = self.c / self.Om
        self.rho_g = Sigma / (math.sqrt(2.0 * math.pi) * H)
        l_mfp = MU * M_H / (self.rho_g * SIGMA_MOL)
        self.Re = 2.0 * alpha * H / l_mfp
        self.r = self.Re ** -0.5
        self.v_g = math.sqrt(1.5 * alpha) * self.c
        self.v_K = AU * self.Om
        self.eta = 13.0 / 8.0 * (self.c / self.v_K) ** 2
        self.l_mfp = l_mfp

    def radius(self, m):
        return (3.0 * m / (4.0 * math.pi * self.rho_s)) ** (1.0 / 3.0)

    def st(self, m):
        """Epstein Stokes number of a compact sphere, St = rho_s a Omega/(c_g rho_g) (eq. 4.5, t_L = 1/Omega)."""
        a = self.radius(m)
        assert a < 2.25 * self.l_mfp  # Epstein regime
        return self.rho_s * a * self.Om / (self.c * self.rho_g)

    def mass_of_st(self, st):
        a = st * self.c * self.rho_g / (self.rho_s * self.Om)
        return 4.0 / 3.0 * math.pi * self.rho_s * a ** 3

    @staticmethod
    def ystar(st):
        """Root of F(y) = (2/3) y (y - 1)^2 - 1/(1 + y) = -St/(1 + St) (eq. 3.18d), St <= 1, by brentq."""
        from scipy.optimize import brentq

        st = min(st, 1.0)
        return brentq(lambda y: 2.0 / 3.0 * y * (y - 1.0) ** 2 - 1.0 / (1.0 + y) + st / (1.0 + st), 0.9, 1.7,
                      xtol=1e-15, rtol=1e-15)

    def sstar(self, st):
        """St*_i = clip(y* min(St, 1), Re^-1/2, 1) (eq. 3.12 and the text after eq. 3.15b)."""
        return min(max(self.ystar(st) * min(st, 1.0), self.r), 1.0)

    def st_kink(self):
        """St_1 where y*(St_1) St_1 = Re^-1/2, i.e. t*_1 = t_s (thesis §3.3.4: t_1 = t_s/y*)."""
        from scipy.optimize import brentq

        return brentq(lambda s: self.ystar(s) * s - self.r, 0.1 * self.r, self.r, xtol=1e-22, rtol=1e-15)

    def dv2_turb(self, a, b, s=None):
        """(Delta v_I^2, Delta v_II^2)/v_g^2 from the printed eqs. 3.15a/b (s = St*_12 unless given)."""
        r = self.r
        if s is None:
            s = max(self.sstar(a), self.sstar(b))
        dI = (a - b) / (a + b) * (a * a / (s + a) - a * a / (1 + a) - b * b / (s + b) + b * b / (1 + b))
        dII = 2.0 * (s - r) + a * a / (a + s) - a * a / (a + r) + b * b / (b + s) - b * b / (b + r)
        return dI, dII

    def dv2_quad(self, a, b):
        """(Delta v_I^2, Delta v_II^2)/v_g^2 by quadrature of the t-space integrals of eq. 3.13 (t_L = 1):
        class II: sum_i int_r^s [1 - K_i^2] dt, class I: int_s^1 ((a-b)/(a+b)) [K_a^2 - K_b^2] dt, K_x = x/(x+t)."""
        from scipy.integrate import quad

        r = self.r
        s = max(self.sstar(a), self.sstar(b))

        def K2(x, t):
            return (x / (x + t)) ** 2

        dII = quad(lambda t: (1.0 - K2(a, t)) + (1.0 - K2(b, t)), r, s, epsabs=0.0, epsrel=1e-13)[0] if s > r else 0.0
        dI = quad(lambda t: (a - b) / (a + b) * (K2(a, t) - K2(b, t)), s, 1.0, epsabs=0.0, epsrel=1e-13,
                  limit=200, points=[x for x in (a, b) if s < x < 1.0] or None)[0]
        return dI, dII

    def components(self, m1, m2):
        """Delta v [cm/s] per effect and total (quadrature sum, ch. 4 §4.3 text under eq. 4.26)."""
        a, b = self.st(m1), self.st(m2)
        dI, dII = self.dv2_turb(a, b)
        bm2 = 8.0 * K_B * self.T / math.pi * (1.0 / m1 + 1.0 / m2)                         # eq. 4.4
        rd2 = (2.0 * self.eta * self.v_K * (a / (1 + a * a) - b / (1 + b * b))) ** 2     # eq. 4.8
        t2 = self.v_g ** 2 * (dI + dII)
        return dict(total=math.sqrt(bm2 + t2 + rd2), brownian=math.sqrt(bm2), turbulence=math.sqrt(t2),
                    class_I=self.v_g * math.sqrt(dI), class_II=self.v_g * math.sqrt(dII),
                    radial_drift=math.sqrt(rd2))

    def slopes_at_kink(self, b):
        """One-sided d(Delta v_turb^2/v_g^2)/d St_1 at St_1 = St_k for a fixed partner St_2 = b.

        Left (s = r fixed): complex-step derivative of eq. 3.15a. Right: left + D s'(St_k) with
        D = d(eq. 3.14)/d t*_12 at t*_12 = t_s = 2 - 2 (a K_a^2 + b K_b^2)/(a + b), K_x = x/(x + r), and
        s' = d(y* St)/dSt = y* + St RHS'(St)/F'(y*), RHS' = -1/(1+St)^2 (implicit function of eq. 3.18d).
        """
        a, r = self.st_kink(), self.r
        h = 1e-30 * a
        dI, _ = self.dv2_turb(complex(a, h), b, s=r)
        left = dI.imag / h
        Ka, Kb = a / (a + r), b / (b + r)
        D = 2.0 - 2.0 * (a * Ka ** 2 + b * Kb ** 2) / (a + b)
        y = self.ystar(a)
        dF = 2.0 / 3.0 * (y - 1.0) * (3.0 * y - 1.0) + 1.0 / (1.0 + y) ** 2
        ds = y + a * (-1.0 / (1.0 + a) ** 2) / dF
        return left, left + D * ds


def _default_kernel():
    """The default-run scene kernel and grid exactly as ``jaxcoag run`` builds them."""
    from jaxcoag import config

    cfg = config.default()
    g = cfg["gas"]
    assert g["model"] == "mmsn_hayashi81" and g["R_au"] == 1.0 and g["z_H"] == 0.0
    b = config.build(cfg)
    return cfg, b


def main(argv=None):
    args = _common.parse_args(argv, __doc__)
    jax = _common.enable_x64()
    import jax.numpy as jnp
    import numpy as np

    from jaxcoag.physics import turbulence as T

    plt = _common.pyplot()
    cfg, built = _default_kernel()
    K, gas = built.kernel, built.gas
    hand = Hand(cfg["gas"]["alpha"], cfg["dust"]["rho_s"])
    a0 = cfg["dust"]["a0"]
    m0 = 4.0 / 3.0 * math.pi * hand.rho_s * a0 ** 3          # monomer partner [g]
    r = float(gas.Re_eff) ** -0.5
    ck = _common.Checks("velocity regimes of the default scene")
    ck.add("Re (library vs hand)", float(gas.Re), hand.Re, 1e-12)

    # -- locate the boundary in the library: bisection in ln m on St*_1(m) > r --------------------
    @jax.jit
    def excess(lm):
        p = K.particles(jnp.exp(lm))
        return T.st_star(p.st, gas.Re_eff) - r

    lo, hi = math.log(1e-7), math.log(1e-3)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if float(excess(mid)) <= 0.0 else (lo, mid)
        if hi - lo < 1e-13:
            break
    m_k_lib = math.exp(0.5 * (lo + hi))
    st_k = hand.st_kink()
    m_k = hand.mass_of_st(st_k)
    ck.add("boundary mass m_k [g] (t*_1 = t_s)", m_k_lib, m_k, 1e-9)
    ck.add("boundary St_k = Re^-1/2/y*", float(K.particles(jnp.asarray(m_k_lib)).st), st_k, 1e-9)

    # -- Delta v on the default grid around the boundary, vs hand formulas ------------------------
    c = np.asarray(built.grid.centers)
    i = int(np.searchsorted(c, m_k)) - 1
    mA, mB = float(c[i]), float(c[i + 1])
    assert mA < m_k < mB

    @jax.jit
    def dv_tot(m1, m2):
        return jnp.sqrt(K.relative_velocity2(m1, m2))

    steps = {}
    for tag, p in (("monomer", m0), ("issue partner", PARTNER_ISSUE)):
        vA, vB = (float(dv_tot(jnp.asarray(x), jnp.asarray(p))) for x in (mA, mB))
        ck.add(f"dv_tot({mA:.3e} g, {tag}) [cm/s]", vA, hand.components(mA, p)["total"], 1e-10)
        ck.add(f"dv_tot({mB:.3e} g, {tag}) [cm/s]", vB, hand.components(mB, p)["total"], 1e-10)
        steps[tag] = (vA, vB)

    # -- continuity at the boundary (C^0) and the one-sided slopes (not C^1) ----------------------
    h = 1e-9
    vl, vr = (float(dv_tot(jnp.asarray(m_k_lib * (1 + s * h)), jnp.asarray(m0))) for s in (-1, 1))
    ck.add("continuity dv(m_k(1+1e-9))/dv(m_k(1-1e-9))", vr / vl, 1.0, 1e-8)
    st0 = hand.st(m0)
    g_turb = jax.jit(jax.grad(lambda a: T.dv2_turbulent_oc07(a, st0, gas.Re_eff)))
    left, right = hand.slopes_at_kink(st0)
    ck.add("d(dv_turb^2/v_g^2)/dSt_1 left of St_k", float(g_turb(st_k * (1 - 1e-7))), left, 1e-5)
    ck.add("d(dv_turb^2/v_g^2)/dSt_1 right of St_k", float(g_turb(st_k * (1 + 1e-7))), right, 1e-5)

    # -- the exact integral form eq. 3.13 has the same break: quadrature vs library ----------------
    for f in (0.9, 0.999, 1.001, 1.1, 2.0):
        a = f * st_k
        q = sum(hand.dv2_quad(a, st0))
        lib = float(T.dv2_turbulent_oc07(a, st0, gas.Re_eff))
        ck.add(f"eq. 3.13 quadrature vs closed form, St_1 = {f:g} St_k", lib, q, 1e-9)

    # -- curves -----------------------------------------------------------------------------------
    m = np.logspace(-7, -3, 241 if args.quick else 2401)
    mj = jnp.asarray(m)
    p1, p0 = K.particles(mj), K.particles(jnp.full_like(mj, m0))
    comp = {k: np.sqrt(np.asarray(v)) for k, v in _components(K, p1, p0).items()}
    sa, sb = T.st_star(p1.st, gas.Re_eff), T.st_star(p0.st, gas.Re_eff)
    dI, dII = (np.asarray(x) for x in T.dv2_terms_oc07(p1.st, p0.st, sa, sb, gas.Re_eff))
    vg = float(gas.v_g)
    sacc = np.sqrt(np.asarray(T.dv2_turbulent_oc07(p1.st, p0.st, gas.Re_eff, accurate=True))) * vg
    total = np.asarray(dv_tot(mj, jnp.full_like(mj, m0)))
    slope = np.asarray(jax.jit(jax.vmap(jax.grad(
        lambda lm: 0.5 * jnp.log(K.relative_velocity2(jnp.exp(lm), jnp.asarray(m0))))))(jnp.log(mj)))
    st1 = np.asarray(p1.st)
    eq323 = vg * np.sqrt(np.asarray(T.dv2_tightly_coupled_eq323(p1.st, p0.st, gas.Re_eff)))
    eq325 = vg * np.sqrt(np.asarray(T.dv2_intermediate_eq325(p1.st, p0.st / p1.st, 1.6)))

    # slope of ln dv_tot in ln m at the boundary from the analytic one-sided turbulence slopes:
    # d ln dv/d ln m = [v_g^2 (d dv2/dSt_1) St_1/3 + d(bm^2 + rd^2)/d ln m]/(2 dv^2), St ~ m^1/3 (Epstein)
    comps_k = hand.components(m_k, m0)
    eps_m = 1e-6
    rest = lambda mm: hand.components(mm, m0)["brownian"] ** 2 + hand.components(mm, m0)["radial_drift"] ** 2
    d_rest = (rest(m_k * (1 + eps_m)) - rest(m_k * (1 - eps_m))) / (2 * eps_m)
    sl_left = (vg ** 2 * left * st_k / 3.0 + d_rest) / (2 * comps_k["total"] ** 2)
    sl_right = (vg ** 2 * right * st_k / 3.0 + d_rest) / (2 * comps_k["total"] ** 2)
    g_slope = jax.jit(jax.grad(lambda lm: 0.5 * jnp.log(K.relative_velocity2(jnp.exp(lm), jnp.asarray(m0)))))
    ck.add("d ln dv_tot/d ln m left of m_k", float(g_slope(math.log(m_k) - 3e-7)), sl_left, 1e-5)
    ck.add("d ln dv_tot/d ln m right of m_k", float(g_slope(math.log(m_k) + 3e-7)), sl_right, 1e-5)

    fig, (ax, bx) = plt.subplots(2, 1, figsize=(6.4, 7.4), sharex=True, gridspec_kw=dict(height_ratios=[2.2, 1]))
    ax.loglog(m, total, "k-", lw=2.0, label=r"total $\Delta v$")
    ax.loglog(m, comp["turbulence"], "C0-", lw=1.2, label="turbulence (OC07, exact $y^*$)")
    ax.loglog(m, vg * np.sqrt(dI), "C0--", lw=1.0, label=r"  class I part $\Delta v_{\rm I}$ (eq. 3.15a)")
    pos = dII > 0
    ax.loglog(m[pos], vg * np.sqrt(dII[pos]), "C0:", lw=1.4, label=r"  class II part $\Delta v_{\rm II}$ (eq. 3.15b)")
    ax.loglog(m, sacc, "-", color="0.6", lw=0.9, label="turbulence, App. 3.A (accurate=True)")
    ax.loglog(m, comp["brownian"], "C2-", lw=1.0, label="Brownian (eq. 4.4)")
    ax.loglog(m, comp["radial_drift"], "C3-", lw=1.0, label="radial drift (eq. 4.8)")
    below, above = m < m_k * 3, m > m_k / 3
    ax.loglog(m[below], eq323[below], "C1:", lw=1.0, label="tightly coupled, eq. 3.23")
    ax.loglog(m[above], eq325[above], "C4:", lw=1.0, label=r"intermediate, eq. 3.25 ($\epsilon = St_2/St_1$)")
    sel = (c > 1e-7) & (c < 1e-3)
    ax.loglog(c[sel], [hand.components(float(x), m0)["total"] for x in c[sel]], "ks", ms=3.5, mfc="none",
              label="default grid bins (hand formulas)")
    for x in (ax, bx):
        x.axvline(m_k, color="C3", lw=0.8, ls="-.")
    ax.annotate(f"$t^*_1 = t_s$: $m_k$ = {m_k:.4g} g\n(a = {hand.radius(m_k) * 1e4:.1f} $\\mu$m, St = {st_k:.4g})",
                xy=(m_k, 1.5), xytext=(m_k * 1.6, 1.2), fontsize=7.5, color="C3")
    ax.annotate(f"{steps['monomer'][0]:.2f} $\\to$ {steps['monomer'][1]:.2f} cm/s", xy=(mB, steps["monomer"][1]),
                xytext=(1.2e-6, 30), fontsize=7.5, arrowprops=dict(arrowstyle="->", lw=0.6))
    ax.set_ylim(0.03, 150)
    ax.set_ylabel(r"$\Delta v$ against a 1 $\mu$m monomer [cm/s]")
    ax.set_title("default scene (MMSN 1 AU, alpha = 1e-3): a slope break, not a jump", fontsize=9.5)
    ax.legend(fontsize=6.5, loc="lower right", ncol=2)
    bx.semilogx(m, slope, "k-", lw=1.4, label=r"$d\ln\Delta v/d\ln m$ (jax.grad)")
    bx.plot([m_k, m_k], [sl_left, sl_right], "o", color="C3", ms=4, mfc="none",
            label="one-sided slopes at $m_k$ (eq. 3.14)")
    bx.axhline(1.0 / 6.0, color="C4", lw=0.8, ls=":", label="eq. 3.25: 1/6")
    bx.axhline(1.0 / 3.0, color="C1", lw=0.8, ls=":", label="eq. 3.23: 1/3")
    bx.set_xlabel("m [g]")
    bx.set_ylabel("local slope")
    bx.legend(fontsize=6.5, loc="upper right")
    png = _common.savefig(fig, args, "velocity_jump")

    ck.print()
    print(f"gas: Re = {hand.Re:.6e}, Re^-1/2 = {r:.6e}, v_g = {vg:.6f} cm/s")
    print(f"boundary t*_1 = t_s: St_k = {st_k:.10e}, y*(St_k) = {hand.ystar(st_k):.10f}, "
          f"m_k = {m_k:.10e} g, a_k = {hand.radius(m_k) * 1e4:.4f} um; default-grid bins {mA:.6e} | {mB:.6e} g")
    for tag, p in (("monomer", m0), ("issue partner", PARTNER_ISSUE)):
        ca, cb = hand.components(mA, p), hand.components(mB, p)
        print(f"partner {tag} ({p:.4e} g): dv_tot {ca['total']:.4f} -> {cb['total']:.4f} cm/s; "
              f"class I {ca['class_I']:.4f} -> {cb['class_I']:.4f}, "
              f"class II {ca['class_II']:.4f} -> {cb['class_II']:.4f}, "
              f"Brownian {ca['brownian']:.4f}, drift {ca['radial_drift']:.4f} -> {cb['radial_drift']:.4f}")
    print(f"at m_k (monomer partner): dv_tot = {comps_k['total']:.6f} cm/s, continuous "
          f"(relative change across m_k (1 +- 1e-9): {vr / vl - 1:.3e}); "
          f"d ln dv/d ln m = {sl_left:.4f} (left) -> {sl_right:.4f} (right)")
    print(f"d(dv_turb^2/v_g^2)/dSt_1 at St_k: {left:.6f} (left) -> {right:.6f} (right)")
    print(f"wrote {png}")
    return ck.result(png, m_k=m_k, st_k=st_k, bins=(mA, mB), steps=steps, slopes=(sl_left, sl_right))


def _components(K, p1, p2):
    """Per-effect Delta v_k^2 [cm^2 s^-2] of the scene for the pairs (p1, p2) (one root solve per particle)."""
    c1 = [v.per_particle(p1, K.gas) for v in K.scene.velocities]
    c2 = [v.per_particle(p2, K.gas) for v in K.scene.velocities]
    return {v.name: v.dv2(p1, a, p2, b, K.gas) for v, a, b in zip(K.scene.velocities, c1, c2)}


if __name__ == "__main__":
    main()
