"""Thesis ch. 4 trend: sticking vs bouncing of dust-rimmed chondrules as a function of alpha (O08 recipe).

What is computed: the collision-rate-weighted sticking fraction of the FIRST generation of
compound collisions, right after the dust has been accreted (the thesis: "dust is accreted in a
few 1e2 yr"), for the default ch. 4 setting (``jaxcoag.scenes.binned_setups.setup("ch4_nebula", alpha=...)``:
3 AU, Takeuchi & Lin gas, Brownian + OC07 turbulence + radial drift; chondrules lognormal in
radius, median 300 um, width 0.5, i.e. <a>_m = 720 um). Every chondrule carries a porous rim of
phi_pd = 0.15 phi_dust(10 um/1 um) = 0.0191; the rim mass grows with the chondrule's geometric
cross-section (rim mass ∝ a^2 [CHOICE]: sweep-up of the same dust by every chondrule), normalised
so the total rim mass equals the total chondrule mass (R_cd = 1). For each pair of chondrule-size
nodes the relative velocity comes from the scene kernel (compact chondrule radii), the impact
parameter is averaged uniformly over the cross-section, and the O08 rule (stick if
f_comp <= F_av with the lens-area f_geo, thesis eqs. 4.16-4.18 and erratum 10) decides; pairs are weighted by
K_ij n_i n_j.

Published (thesis §4.4, Tab. 4.5): sticking fraction <~ 50 % at alpha = 1e-4 and nearly 100 % at
alpha = 1e-6, with larger final compounds (T-Tab4.5 <a>_m: 0.7-0.8 cm at alpha <= 1e-6 vs 0.1 cm
at alpha >= 1e-4 for rho_X = 1). Exact checks: the f_comp coefficient 0.036744 (thesis eq. 4.16:
"3.7e-2") and the O08 example (equal 1 g compounds stick at 50 cm/s, f_comp = 0.22965; bounce at 55 cm/s).

Measured (--quick): 0.72 at 1e-6, 0.03 at 1e-4, 0.00 at 1e-2 (full: 0.74, 0.73, 0.59, 0.03, 0, 0
for alpha = 1e-7 .. 1e-2). Where it differs and why: this is the first-generation fraction of a
fixed population, not the
time-integrated fraction of the thesis's MC runs (whose rims are compacted by earlier bounces and
whose compounds grow), and the velocities use compact chondrule radii instead of compound radii;
so only the trend with alpha and the ~50 % / ~100 % levels are compared.

Run:   python paper_figs/fig4_sticking_alpha.py --quick   (alpha = 1e-6, 1e-4, 1e-2; a few s)
Full:  python paper_figs/fig4_sticking_alpha.py           (alpha = 1e-7 .. 1e-2, finer size nodes)
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402


def population(setup, n_nodes):
    """Chondrule size nodes (radii [cm], masses [g], number densities [cm^-3]) and rim fractions."""
    import numpy as np

    p = setup.params
    rho_c = 3.0
    sig = 0.5
    a_med = p["a_m_chondrules"] / math.exp(3.5 * sig ** 2)
    x, w = np.polynomial.hermite_e.hermegauss(n_nodes)  # standard normal nodes/weights
    w = w / w.sum()
    a = a_med * np.exp(sig * x)
    m_c = 4.0 / 3.0 * math.pi * rho_c * a ** 3
    n_c = w * p["rho_chondrules"] / np.sum(w * m_c)     # number densities, total mass rho_chondrules
    rim = a ** 2
    rim_mass = rim * p["rho_dust"] / np.sum(n_c * rim)  # per chondrule, total = rho_dust
    f_d = rim_mass / (m_c + rim_mass)
    return a, m_c + rim_mass, n_c, f_d


def sticking_fraction(alpha, n_nodes=12, n_b=16):
    """Rate-weighted first-generation sticking fraction at ``alpha`` (see module docstring)."""
    import jax.numpy as jnp
    import numpy as np

    from jaxcoag.scenes import binned_setups
    from jaxcoag.physics.ormel08 import Compound, o08_outcome
    from jaxcoag.physics.porosity import phi_dust

    s = binned_setups.setup("ch4_nebula", alpha=alpha)
    mat = s.material
    _, m, n, f_d = population(s, n_nodes)
    phi_pd = 0.15 * float(phi_dust((10.0) ** (2.0 / 0.95)))
    M1, M2 = np.meshgrid(m, m, indexing="ij")
    dv = np.sqrt(np.asarray(s.kernel.relative_velocity2(jnp.asarray(M1), jnp.asarray(M2))))
    K = np.asarray(s.kernel(jnp.asarray(M1), jnp.asarray(M2)))
    full = lambda v: np.full(M1.shape, v)
    c1 = Compound(m=M1, f_d=np.broadcast_to(f_d[:, None], M1.shape), f_p=full(1.0), phi_pd=full(phi_pd))
    c2 = Compound(m=M2, f_d=np.broadcast_to(f_d[None, :], M1.shape), f_p=full(1.0), phi_pd=full(phi_pd))
    # compound radii for the impact parameter
    from jaxcoag.physics.ormel08 import compound_volume
    a1 = (3.0 * np.asarray(compound_volume(c1)) / (4.0 * math.pi)) ** (1.0 / 3.0)
    a2 = (3.0 * np.asarray(compound_volume(c2)) / (4.0 * math.pi)) ** (1.0 / 3.0)
    u = (np.arange(n_b) + 0.5) / n_b                       # b = (a1 + a2) sqrt(u), u ~ U(0, 1)
    p_stick = np.zeros(M1.shape)
    for uu in u:
        out = o08_outcome(c1, c2, jnp.asarray(dv), jnp.asarray((a1 + a2) * math.sqrt(uu) * (1 - 1e-12)), mat)[0]
        p_stick += (1.0 - np.asarray(out.p_two)) / n_b
    rate = K * n[:, None] * n[None, :]
    return float(np.sum(rate * p_stick) / np.sum(rate)), float(np.sum(rate * dv) / np.sum(rate))


def main(argv=None):
    args = _common.parse_args(argv, __doc__)
    _common.enable_x64()
    import numpy as np

    from jaxcoag.physics.contact import Material
    from jaxcoag.physics.ormel08 import Compound, f_comp_o08, o08_outcome

    checks = _common.Checks("thesis ch. 4: sticking fraction vs alpha (O08, first generation)")
    mat = Material.ch4_silicate()
    one = np.array(1.0)
    # f_comp = 3.674e-2 (m_mu^2/(m1 m2)) (dv/10 cm/s)^2: equal masses at 10 cm/s -> 0.009186 (M6)
    checks.add("f_comp, equal 1 g masses at 10 cm/s", float(f_comp_o08(one, one, 10.0, mat)), 0.009186, tol=1e-3)
    c = Compound(m=1.0, f_d=0.5, f_p=0.5, phi_pd=0.019114)
    out50, stuck, _, _ = o08_outcome(c, c, 50.0, 0.0, mat, fgeo_mode="unity")
    out55 = o08_outcome(c, c, 55.0, 0.0, mat, fgeo_mode="unity")[0]
    checks.add("§5 example: f_comp at 50 cm/s", float(out50.aux["f_comp"]), 0.22965, tol=1e-4)
    checks.add("§5 example: sticks at 50 cm/s (p_two)", float(out50.p_two), 0.0, tol=0.0, absolute=True)
    checks.add("§5 example: f_p after sticking", float(stuck.f_p), 0.040703, tol=1e-4)
    checks.add("§5 example: bounces at 55 cm/s (p_two)", float(out55.p_two), 1.0, tol=0.0, absolute=True)

    alphas = [1e-6, 1e-4, 1e-2] if args.quick else [1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2]
    nodes = 8 if args.quick else 16
    fr, dvm = [], []
    for al in alphas:
        f, v = sticking_fraction(al, n_nodes=nodes, n_b=8 if args.quick else 24)
        fr.append(f)
        dvm.append(v)
    print("== first-generation sticking fraction of rimmed chondrules vs alpha "
          "(thesis: <~50 % at 1e-4, ~100 % at 1e-6) ==")
    for al, f, v in zip(alphas, fr, dvm):
        print(f"alpha = {al:7.0e}   sticking fraction = {f:6.3f}   rate-weighted <dv> = {v:8.2f} cm/s")
    i6, i4 = alphas.index(1e-6), alphas.index(1e-4)
    # measured (quick and full): 0.72 at 1e-6 -- a majority, but below the thesis's ~100 % (see below)
    checks.add("alpha = 1e-6: most collisions stick (> 0.5; thesis ~1)", float(fr[i6] > 0.5), 1.0, tol=0.0,
               absolute=True)
    checks.add("alpha = 1e-4: at most about half stick (< 0.6)", float(fr[i4] < 0.6), 1.0, tol=0.0, absolute=True)
    checks.add("trend: sticking fraction falls with alpha", float(np.all(np.diff(fr) <= 1e-12)), 1.0, tol=0.0,
               absolute=True)
    print(f"Differences and why: at alpha = 1e-6 {fr[i6]:.2f} stick (thesis ~1.0); "
          f"at 1e-4 {fr[i4]:.2f} (thesis <~0.5).")
    print(" - first-generation fraction of a fixed, freshly rimmed population; the thesis quotes time-integrated MC")
    print("   fractions of growing compounds whose rims evolve (accretion continues, bounces compact them);")
    print(" - velocities from compact chondrule radii: at low alpha the rate-weighted dv is set by differential radial")
    print("   drift (~30 cm/s at 1e-6, close to the ~50 cm/s sticking limit of 1 g equal compounds with")
    print("   f_p f_d = 0.25);")
    print(" - rim mass ∝ a^2 is a [CHOICE]; the thesis accretes dust with the size-dependent dv of each chondrule.")

    plt = _common.pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.semilogx(alphas, fr, "o-", label="O08, first generation (this work)")
    ax.semilogx([1e-6, 1e-4], [1.0, 0.5], "k*", ms=12, label="thesis §4.4 (~100 %, <~50 %)")
    ax.set_xlabel(r"$\alpha$")
    ax.set_ylabel("sticking fraction")
    ax.set_ylim(0, 1.05)
    ax.legend(fontsize=8)
    ax.set_title("Thesis ch. 4: rimmed chondrules, stick vs bounce", fontsize=9)
    png = _common.savefig(fig, args, "fig4_sticking_alpha")
    checks.print()
    return checks.result(png, alphas=alphas, sticking=fr, dv_mean=dvm)


if __name__ == "__main__":
    main()
