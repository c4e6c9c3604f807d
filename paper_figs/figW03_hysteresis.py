"""Wada et al. (2007) Fig. 3: force against displacement in the inelastic sliding regime (hysteresis).

Protocol: two quartz monomers held at the JKR equilibrium distance 2 r1 - delta_0 on the x axis; monomer 1 is
rotated about z in small prescribed steps so that the sliding displacement measured from the initial contact point
(ICP), u = r1 theta, goes 0 -> 3 zeta_crit -> 1 zeta_crit -> -2 zeta_crit. Each step: ``rotate`` the contact
pointer of monomer 1, ``clip_inelastic`` (eqs. 39-43), ``contact_forces`` (eq. 14). Rolling is kept elastic
(xi_crit = 30 A, 34 delta_c, while xi = zeta/2 stays below 2.5 delta_c), so the sliding spring alone dissipates.
Points as in the paper's figure: A elastic (u = zeta_crit/2), B the critical displacement, C the reversal at
3 zeta_crit, D back in the elastic regime after the reversal, E the shifted equilibrium (zero force).
Check points: plateau force = k_s zeta_crit = F_fric (eq. 35-36; times the eq. 14 factor
(r_1 + r_2 - zeta_0.n_c)/|x_1 - x_2| = 1 + delta_0/(2 r1 - delta_0) for the force on the monomer), elastic slope
k_s after the reversal, zero force at u = 2 zeta_crit after the first reversal, dissipated energy = F_fric times
the plateau travel (2 + 3) zeta_crit = 5 k_s zeta_crit^2 (the area swept under the plateaus) with the paper's
eqs. 39-41, and the energy balance work = Delta U + E_dis; the potential-drop bookkeeping (paper_energy=False)
overcounts by k_s h^2/2 per clipped step h (relative h/(2 zeta_crit)).
Run: python paper_figs/figW03_hysteresis.py [--quick] [--out DIR]
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402


def hysteresis(n_per_zc=100, paper_energy=True):
    """Run the protocol; returns a dict of numpy arrays (u, F_spring, F_monomer, torque, energies) and constants."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from jaxcoag.aggregates.contact import interactions as I
    from jaxcoag.aggregates.contact import materials as M

    mat = M.quartz(xi_crit=3e-7)
    r, zc = float(mat.r1), float(mat.zeta_crit)
    x1 = jnp.zeros(3)
    x2 = jnp.array([2.0 * r - float(mat.delta0), 0.0, 0.0])
    n1 = jnp.array([1.0, 0.0, 0.0])  # -n_c: points from 1 to 2
    n2 = -n1
    h = zc / n_per_zc
    # signed steps of the drive u = r theta: +3 zc, -2 zc, -3 zc
    steps = np.concatenate([np.full(3 * n_per_zc, h), np.full(2 * n_per_zc, -h), np.full(3 * n_per_zc, -h)])
    ez = jnp.array([0.0, 0.0, 1.0])

    def body(carry, du):
        m1, m2, phi, e_dis = carry
        m1 = I.rotate(m1, ez * (du / r), 1.0)
        m1, m2, phi, dEs, dEr, dEt = I.clip_inelastic(x1, x2, m1, m2, phi, mat, paper_energy=paper_energy)
        cf = I.contact_forces(x1, x2, m1, m2, phi, mat)
        _, _, _, _, zeta, _ = I.contact_geometry(x1, x2, m1, m2, mat)
        e_dis = e_dis + dEs + dEr + dEt
        out = (mat.k_s * zeta[1], -cf.F1[1], cf.M1[2], cf.U_s + cf.U_r + cf.U_t, e_dis, dEs)
        return (m1, m2, phi, e_dis), out

    init = (n1, n2, jnp.zeros(()), jnp.zeros(()))
    _, out = jax.jit(lambda s: jax.lax.scan(body, init, s))(jnp.asarray(steps))
    Fk, Fm, Mz, U, Ed, dEs = (np.concatenate([[0.0], np.asarray(o)]) for o in out)
    u = np.concatenate([[0.0], np.cumsum(steps)])
    return dict(u=u, F_spring=Fk, F_monomer=Fm, M1z=Mz, U=U, E_dis=Ed, dE_s=dEs, h=h, steps=steps,
                zc=zc, ks=float(mat.k_s), F_fric=float(mat.F_fric), r=r,
                geo=2.0 * r / (2.0 * r - float(mat.delta0)), n=n_per_zc)


def main(argv=None):
    args = _common.parse_args(argv, __doc__)
    _common.enable_x64()
    import numpy as np

    plt = _common.pyplot()
    n = 100 if args.quick else 1000
    res = hysteresis(n)
    u, F, Fm, zc, ks, Ff = res["u"], res["F_spring"], res["F_monomer"], res["zc"], res["ks"], res["F_fric"]
    iB, iC, iE_end = n, 3 * n, 5 * n  # indices: u = zc (B), 3 zc (C), back at 1 zc (end of elastic unloading)
    ck = _common.Checks("Wada 2007 Fig. 3 (sliding hysteresis, eqs. 35-43)")
    ck.add("zeta_crit k_s = F_fric (eq. 36)", zc * ks, Ff, 1e-12)
    ck.add("plateau 1: k_s |zeta| / F_fric (max dev.)", 1.0 + np.max(np.abs(F[iB + 1:iC + 1] / Ff - 1.0)), 1.0, 1e-12)
    ck.add("plateau 2: k_s |zeta| / F_fric (max dev.)", 1.0 + np.max(np.abs(-F[iE_end + 1:] / Ff - 1.0)), 1.0, 1e-12)
    ck.add("force on monomer / (F_fric (1 + delta0/(2r - delta0)))", float(np.mean(Fm[iB + 1:iC + 1])) / Ff,
           res["geo"], 1e-5)
    # elastic loading O -> B and unloading C -> (1 zc): slope k_s (u = r theta vs zeta = r sin theta: ~1e-6)
    s_load = np.polyfit(u[:iB + 1], F[:iB + 1], 1)[0]
    s_unl = np.polyfit(u[iC:iE_end + 1], F[iC:iE_end + 1], 1)
    ck.add("elastic slope O-B / k_s", s_load / ks, 1.0, 1e-5)
    ck.add("elastic slope after reversal C-E / k_s", s_unl[0] / ks, 1.0, 1e-5)
    u0 = -s_unl[1] / s_unl[0]
    ck.add("shifted equilibrium E: zero force at u/zeta_crit", u0 / zc, 2.0, 2e-5, absolute=True)
    ck.add("force at u = zeta_crit after reversal / F_fric", F[iE_end] / Ff, -1.0, 1e-5)
    e_area = 5.0 * ks * zc**2
    ck.add("E_dis (eqs. 39-41) / (5 k_s zeta_crit^2)", res["E_dis"][-1] / e_area, 1.0, 1e-4)
    # energy balance: work of the drive torque (trapezoid in theta over the post-clip torques) = Delta U + E_dis
    dth = res["steps"] / res["r"]

    def balance(r_):
        work = float(np.sum(-0.5 * (r_["M1z"][1:] + r_["M1z"][:-1]) * dth))
        return work / (r_["U"][-1] - r_["U"][0] + r_["E_dis"][-1])

    ck.add("work / (Delta U + E_dis) (eqs. 39-41)", balance(res), 1.0, 1e-4)
    drop = hysteresis(n, paper_energy=False)
    ck.add("E_dis (potential drop) / (5 k_s zeta_crit^2)", drop["E_dis"][-1] / e_area, 1.0 + 0.5 / n, 1e-4)
    ck.add("work / (Delta U + E_dis) (potential drop: k h^2/2 per step)", balance(drop), 1.0, 1.0 / n,
           counts=False)

    fig, ax = plt.subplots(figsize=(5.6, 4.2))
    ax.plot(u / zc, F / Ff, "k-", lw=1.6, label=r"$k_s|\zeta|$ (clip_inelastic + contact_forces)")
    ax.axhline(0.0, color="0.7", lw=0.5)
    ax.axvline(0.0, color="0.7", lw=0.5)
    marks = {"O": 0, "A": n // 2, "B": iB, "C": iC, "D": iC + n // 2, "E": 4 * n}
    for lab, i in marks.items():
        ax.plot([u[i] / zc], [F[i] / Ff], "o", color="C3", ms=4)
        ax.annotate(lab, (u[i] / zc, F[i] / Ff), textcoords="offset points", xytext=(4, 5), fontsize=9)
    ax.plot([2.0], [0.0], "s", mfc="none", color="C0", ms=7, label=r"shifted equilibrium $2\zeta_{\rm crit}$")
    ax.set_xlabel(r"displacement from the initial contact point $u/\zeta_{\rm crit}$")
    ax.set_ylabel(r"force $/F_{\rm fric}$")
    ax.set_title("Wada et al. 2007 Fig. 3: inelastic sliding (quartz)", fontsize=10)
    ax.legend(fontsize=7, loc="upper left")
    png = _common.savefig(fig, args, "figW03_hysteresis")
    ck.print()
    print(f"wrote {png}")
    return ck.result(png)


if __name__ == "__main__":
    main()
