"""Wada et al. (2007) Fig. 6: energy budget of a BCCA-BCCA collision against time.

E_kin (translational + rotational), the potential energy U of the contacts, the energies dissipated by the normal
(contact creation and breaking), sliding and rolling channels (E_dis,n, E_dis,s, E_dis,r; twisting is identically 0
in 2-D) and their total E_kin + U + sum E_dis against t/t_c, and the total's relative error, for the paper's case:
two copies (independently rotated) of one 2-D BCCA of 128 quartz monomers, xi_crit = 2 A, head-on at
v_imp = 5.7 v_0 (the paper does not print v_imp for Fig. 5b/6; 5.7 v_0 is its Fig. 13b "maximum compression" case),
dt = 0.014 t_c (Wada et al. §4). Here E_imp = (1/2) mu v_imp^2 = 1040 F_c delta_c, x_roll = E_imp/(n_k E_roll) = 0.143,
x_break = E_imp/(n_k E_break) = 2.65 (n_k = 254).

Relative error: (E_total(t) - E_total(0))/E_imp. The paper does not define its denominator; E_total(0) = E_imp + U(0)
with U(0) = 254 U_n(delta_0) < 0 (the BCCA bonds) is 0.65 E_imp here, so the error relative to E_total(0) is 1.5x
larger; both are printed.

Run length: the library's default end (t_contact + 8 r_g,tot/v_imp plus 1e4 quiet steps) would be ~2e6 steps here.
The run instead goes in chunks (``collide`` for the first, ``jaxcoag.evolve`` continuing the result for the next ones)
until E_kin has settled: a chunk in which the dissipated energy grows by less than ``settle`` E_imp (full: 25000 steps
= 350 t_c, settle 2e-3) after E_kin has fallen below half of E_imp, or the step cap. The quartz scale
r_1/(v_0 t_c) = 1141 makes the collision slow: the main bodies meet at ~4000 t_c and E_kin settles at ~1.4e4 t_c.
Measured (full mode, 2 shared cores at load ~15): settled after 1.0e6 steps (14000 t_c) in 1612 s (620 steps/s);
max relative error 2.5e-5; at the end E_dis,r = 0.75, E_dis,n = 0.18, E_dis,s = 0.017, E_kin = 0.073 of E_imp
(rolling 0.79 of the dissipation: the two bands below, our reading of "almost all" and "small", are missed: 10
monomers leave the aggregate, N_large = 246, and contact breaking and creation take 0.19).

Checks (the paper's statements, Wada et al. §5.1): max |relative error| < 1e-4; "almost all of the initial kinetic
energy is dissipated by rolling": E_dis,r / (sum E_dis) >= 0.8 at the end [band: our reading of "almost all"];
E_dis,n and E_dis,s "small": each <= 0.1 of the dissipated energy [band]; planar run: E_dis,t = 0 exactly.
Quick mode: 8 + 8 ice monomers (xi_crit = 2 A) at 3 v_0 (x_roll = 0.43), 15000 steps (the compression phase):
the error bound and rolling as the largest channel (counted); the full-mode bands are printed but not counted (in
so small an aggregate rolling takes only ~half: measured 0.49 rolling, 0.22 normal, 0.28 sliding).
Run: python paper_figs/figW06_energy_budget.py [--quick] [--out DIR] [--max-steps N]
"""

import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

#: records per chunk: the same number as ``collide``'s segments, so every chunk reuses one compiled program
RECORDS = 25


def run_chunks(a, b, v_imp, mat, key, *, every, settle, max_steps, min_chunks=1, log=print):
    """Collide ``a`` and ``b`` at ``v_imp`` [cm s^-1] in chunks of ``RECORDS * every`` steps until settled.

    The first chunk is ``contact.collide(..., t_end=...)``, the next ones continue its result with
    ``jaxcoag.evolve(mat, DEM(), result, t_out)``. Settled: after ``min_chunks`` chunks, a chunk in which the total
    dissipated energy grew by less than ``settle`` E_imp while E_kin < E_imp/2. Returns (records dict of numpy
    arrays over the whole run, last CollisionResult, settled bool, wall seconds).
    """
    import jaxcoag
    import numpy as np
    from jaxcoag.aggregates.contact import DEM, collide

    dt = 0.014 * float(mat.t_c)
    chunk = RECORDS * every
    t0 = time.time()
    r = collide(a, b, v_imp, mat, t_end=chunk * dt, key=key, record_every=every)
    names = ("t", "E_kin", "E_kin_rot", "U", "E_dis_n", "E_dis_s", "E_dis_r", "E_dis_t", "E_total", "contacts")
    rec = {k: [np.asarray(getattr(r, k))] for k in names}
    E_imp = float(r.E_imp)
    settled, k = False, 1
    while int(r.n_steps) < max_steps:
        dis0 = float(r.E_dis[-1])
        t_out = float(r.t[-1]) + dt * every * np.arange(1, RECORDS + 1)
        r = jaxcoag.evolve(mat, DEM(), r, t_out)
        k += 1
        for n in names:
            rec[n].append(np.asarray(getattr(r, n)))
        d = (float(r.E_dis[-1]) - dis0) / E_imp
        log(f"  chunk {k}: t = {float(r.t[-1]) / float(mat.t_c):8.0f} t_c, E_kin/E_imp = "
            f"{float(r.E_kin[-1]) / E_imp:.4f}, dE_dis/E_imp = {d:.2e}, contacts {int(r.contacts[-1])}, "
            f"wall {time.time() - t0:.0f} s", flush=True)
        if k >= min_chunks and d < settle and float(r.E_kin[-1]) < 0.5 * E_imp:
            settled = True
            break
    out = {n: np.concatenate(v) for n, v in rec.items()}
    return out, r, settled, time.time() - t0


def _at_least(ck, name, value, bound):
    """A one-sided check row: ``value > bound`` (``_common.Checks.add`` compares two-sided)."""
    ck.add(name, value, bound, float("inf"))
    ck.rows[name]["ok"] = bool(value > bound)


def main(argv=None):
    args = _common.parse_args(argv, __doc__, extra=lambda p: p.add_argument(
        "--max-steps", type=int, default=None, help="step cap of the full run (default 1.5e6)"))
    if args.max_steps is not None and args.max_steps < RECORDS:
        raise SystemExit(f"--max-steps must be >= {RECORDS} steps; got {args.max_steps}.")
    jax = _common.enable_x64()
    import numpy as np

    from jaxcoag.aggregates.contact import bcca, ice, quartz

    plt = _common.pyplot()
    if args.quick:
        mat, n, v_v0, name = ice(xi_crit=2e-8), 8, 3.0, "ice"
        every, settle, max_steps = 200, 0.0, 15_000  # three chunks: the compression phase
    else:
        mat, n, v_v0, name = quartz(xi_crit=2e-8), 128, 5.7, "quartz"
        every, settle = 1000, 2e-3
        max_steps = int(args.max_steps) if args.max_steps is not None else 1_500_000
    tc, ecu = float(mat.t_c), float(mat.F_c * mat.delta_c)
    a = bcca(n, jax.random.key(0), 2, material=mat)
    print(f"W-Fig 6: {n} + {n} {name} monomers (xi_crit = 2 A), v_imp = {v_v0} v_0, dt = 0.014 t_c")
    rec, r, settled, wall = run_chunks(a, a, v_v0 * float(mat.v0), mat, jax.random.key(1), every=every,
                                       settle=settle, max_steps=max_steps)
    E_imp = float(r.E_imp)
    nk = 2 * n - 2
    steps = int(r.n_steps)
    t = rec["t"] / tc
    err = (rec["E_total"] - rec["E_total"][0]) / E_imp
    err0 = (rec["E_total"] - rec["E_total"][0]) / abs(rec["E_total"][0])
    dis = rec["E_dis_n"][-1] + rec["E_dis_s"][-1] + rec["E_dis_r"][-1] + rec["E_dis_t"][-1]
    f_r, f_n, f_s = (rec[k][-1] / dis for k in ("E_dis_r", "E_dis_n", "E_dis_s"))
    print(f"{steps} steps ({t[-1]:.0f} t_c) in {wall:.0f} s = {steps / wall:.0f} steps/s; settled: {settled}")

    ck = _common.Checks("Wada et al. 2007 Fig. 6 (energy budget)")
    ck.add("max |E_total - E_total(0)| / E_imp  (paper: < 1e-4)", np.max(np.abs(err)), 0.0, 1e-4, absolute=True)
    full = not args.quick  # the paper's statements are about 128 + 128 quartz; 8 + 8 ice only has rolling first
    ck.add("E_dis,r / sum E_dis at the end  (paper: almost all; band >= 0.8)", f_r, 1.0, 0.2, absolute=True,
           counts=full)
    ck.add("E_dis,n / sum E_dis  (paper: small; band <= 0.1)", f_n, 0.0, 0.1, absolute=True, counts=full)
    ck.add("E_dis,s / sum E_dis  (paper: small; band <= 0.1)", f_s, 0.0, 0.1, absolute=True, counts=full)
    _at_least(ck, "E_dis,r / max(E_dis,n, E_dis,s): rolling the largest channel (> 1)", f_r / max(f_n, f_s), 1.0)
    ck.add("E_dis,t / E_imp (planar run: exactly 0)", rec["E_dis_t"][-1] / E_imp, 0.0, 0.0, absolute=True)
    if not args.quick:
        ck.add("E_kin settled (1 = dissipation per chunk < 2e-3 E_imp)", float(settled), 1.0, 0.0, absolute=True)
    ck.add("E_imp / (F_c delta_c) = (1/2)(N m_1)(v_imp/2)^2 (paper §5.1)", E_imp / ecu,
           0.5 * 2 * n * (v_v0 / 2) ** 2, 1e-12)
    print(f"fractions of E_imp at t = {t[-1]:.0f} t_c: E_kin {rec['E_kin'][-1] / E_imp:.4f}, U - U(0) "
          f"{(rec['U'][-1] - rec['U'][0]) / E_imp:+.4f}, E_dis,n {rec['E_dis_n'][-1] / E_imp:.4f}, E_dis,s "
          f"{rec['E_dis_s'][-1] / E_imp:.4f}, E_dis,r {rec['E_dis_r'][-1] / E_imp:.4f} (paper: almost all by rolling)")
    print(f"max relative error: {np.max(np.abs(err)):.2e} of E_imp, {np.max(np.abs(err0)):.2e} of |E_total(0)| "
          f"(paper: < 1e-4); x_roll = {E_imp / (nk * float(mat.E_roll)):.3f}, "
          f"x_break = {E_imp / (nk * float(mat.E_break)):.3f}")
    print(f"final: N_large = {int(r.N_large)}, n_con = {float(r.n_contacts):.3f}, r_g/r_1 = "
          f"{float(r.r_g) / float(mat.r1):.2f}, contacts {int(rec['contacts'][-1])} (start {int(rec['contacts'][0])})")

    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(6, 6.5), sharex=True, gridspec_kw=dict(height_ratios=[2.2, 1]))
    for k, lab, st in (("E_kin", r"$E_{\rm kin}$", "k-"), ("U", r"$U$", "C0-"), ("E_dis_n", r"$E_{\rm dis,n}$", "C1--"),
                       ("E_dis_s", r"$E_{\rm dis,s}$", "C2-."), ("E_dis_r", r"$E_{\rm dis,r}$", "C3-"),
                       ("E_total", "total", "k:")):
        ax.plot(t, rec[k] / ecu, st, lw=1.2, label=lab)
    ax.set_ylabel(r"energy $[F_c\delta_c]$")
    ax.legend(fontsize=8, ncol=3)
    ax.set_title(f"Wada et al. 2007 Fig. 6: {n}+{n} {name}, 2 $\\AA$, $v_{{imp}}$ = {v_v0} $v_0$", fontsize=10)
    ax2.plot(t, err, "k-", lw=1)
    ax2.set_ylabel(r"$(E_{\rm tot}-E_{\rm tot}(0))/E_{\rm imp}$")
    ax2.set_xlabel(r"$t/t_c$")
    png = _common.savefig(fig, args, "figW06_energy_budget" + ("_quick" if args.quick else ""))
    stride = max(1, len(t) // 2000)
    data = dict(case=dict(material=name, xi_crit_cm=2e-8, n_per_aggregate=n, v_imp_over_v0=v_v0, dt_over_tc=0.014,
                          steps=steps, wall_s=wall, settled=settled, E_imp_erg=E_imp, F_c_delta_c_erg=ecu),
                t_over_tc=t[::stride].tolist(), relative_error=err[::stride].tolist(),
                **{k + "_over_E_imp": (rec[k][::stride] / E_imp).tolist() for k in
                   ("E_kin", "U", "E_dis_n", "E_dis_s", "E_dis_r", "E_dis_t", "E_total")},
                final=dict(N_large=int(r.N_large), n_con=float(r.n_contacts), r_g_over_r1=float(r.r_g / mat.r1)),
                checks=ck.rows)
    js = args.out / ("figW06_energy_budget" + ("_quick" if args.quick else "") + ".json")
    js.write_text(json.dumps(data, indent=1))
    ck.print()
    print(f"wrote {png} and {js}")
    return ck.result(png, json=js, rolling_fraction=f_r, max_rel_error=float(np.max(np.abs(err))), steps=steps,
                     E_imp=E_imp, E_dis=float(dis), settled=settled)


if __name__ == "__main__":
    main()
