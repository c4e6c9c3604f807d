"""Richardson (1995) Figs. 9-12: model (v), 9000 rigid aggregates of spheres to T = 40.8 (one run).

Model (v) of R95 Table I: 9000 spheres of radius 0.033 in a periodic box of side 10, Maxwellian velocities
(rms speed v0 = 13; R95 does not print it, spec ambiguity A8, the value figR03 uses), aggregates stick rigidly
when the impact energy E_imp = mu |dV|^2 / 2 is below the initial mean kinetic energy per sphere and bounce
with the Bridges et al. (1984) restitution law otherwise (R95 §3). One run (seed 1), as in R95.

Panels: R-Fig 9 (a) N(t) observed with the constant-kernel prediction (R30) for alpha = pi (2 r0)^2 (4/3) v0 / L^3
(dot-dashed), N_C and N_C1; (b) maximum mass / m0; (c, d) mass spectra at t = 1.6 (with R31) and T.
R-Fig 10: aggregates at T: (a) log R_max vs log N_a with its fit, (b) f_D per aggregate and the
inverse-variance weighted mean, (c) rho = M / ((4/3) pi R_max^3) vs N_a with its fit (gamma).
R-Fig 11: (a) sigma_x, sigma_y, sigma_z of the aggregate COM velocities vs t, (b) total (translational +
rotational) kinetic energy vs mass at t = 8.2. R-Fig 12: 3-D rendering (matplotlib) of the second-largest
aggregate at T (R95 text: 1811 spheres, f_D = 2.02 +- 0.01; the caption's "largest" is an erratum).

Counted checks (any N): N + (number of coagulations) = N0 and coagulations + restitutions = N_C at every
output; total mass conserved; every logged collision conserves momentum (|dP| <= 1e-12 P_scale) and angular
momentum (|dL| <= 1e-10 L_scale) and loses kinetic energy (dKE <= 1e-12 KE); the total kinetic energy never
increases between outputs (no energy source; the rotation integrator's relative energy error is < 1e-6);
f_D of the rendered aggregate recomputed from the rendered coordinates equals the diagnostics' value.
Full mode also counts the paper's numbers within the spec's soft bands (A9: exponents +- 0.05, gamma +- 0.1,
mean f_D in [1.5, 2.2], coagulation fraction 0.62 +- 0.1); the rest of the paper's numbers are printed beside
ours as information. Full mode: N0 = 9000, L = 10, T = 40.8, checkpointed (rerun to resume); quick mode:
N0 = 400 at the same number density (L = 10 (400/9000)^(1/3)), T = 2.
Writes figR09_R12_model_v.png and figR09_R12_model_v.json (our numbers and the paper's) into --out.
Run: python paper_figs/figR09_R12_model_v.py [--quick] [--out DIR]
"""

import json
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

#: R95 §3 (model v) and Figs. 9-12
PAPER = dict(t_half=1.7, aggregated_at_8_2=0.90, n_collisions=14420, coag_fraction=0.62, aggregated_at_T=0.9998,
             largest_fraction=0.31, rmax_exponent=(0.52, 0.01), mean_fd=(2.0, 0.2), gamma=(-0.55, 0.04),
             second_largest_members=1811, second_largest_fd=(2.02, 0.01))
V0, SEED = 13.0, 1
#: Verlet-list and cell capacities: the defaults (48, 16) overflow in model (v) near t = 1.8 (compact aggregates of
#: ~20 spheres fill a cell of side ~0.27), which stops the run; the candidate width follows the fullest cell, so a
#: larger capacity costs only where it is used
NEIGHBORS, CELL_CAPACITY = 96, 64
#: the global clock: in this run's later stages large spinning aggregates keep many pairs near contact, which the
#: global step scans at once and the per-body clocks check one by one (2 cores: the whole run to T = 40.8 took 453 s
#: with the global clock on 2026-11-27; with per-body clocks 459 s on 2026-11-28, 195 s of it to T = 16.8 and 264 s
#: for the last ~120 collisions)
CLOCK = "global"


def _ke_slope(M, ke):
    """Least-squares slope of log KE against log M (equipartition: 0)."""
    import numpy as np

    ok = (M > 0) & (ke > 0)
    if ok.sum() < 3 or np.ptp(np.log(M[ok])) == 0:
        return math.nan
    return float(np.polyfit(np.log(M[ok]), np.log(ke[ok]), 1)[0])


def _fd_regression(dist):
    """Sorted-distance regression slope of log k on log r_(k) (R95 §3), written out independently."""
    import numpy as np

    r = np.sort(np.asarray(dist, np.float64))
    k = np.arange(1, len(r) + 1, dtype=np.float64)
    ok = r > 0
    return float(np.polyfit(np.log(r[ok]), np.log(k[ok]), 1)[0])


def _power_law_panel(ax, na, y, slope, ylabel, title):
    """log-log panel of ``y`` over aggregates of N_a >= 2 with its fitted power law (slope from
    ``diag.power_law``; no line when the fit failed)."""
    import numpy as np

    from jaxcoag.aggregates.rigid import diagnostics as diag

    big = na >= 2
    ax.loglog(na[big], y[big], "k.", ms=4)
    if math.isfinite(slope):
        x = np.array([2, na.max()], float)
        ax.loglog(x, np.exp(diag.power_law(na, y)[2]) * x**slope, "k-", lw=0.8, label=f"slope {slope:.3f}")
        ax.legend(fontsize=8)
    ax.set_xlabel("$N_a$")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)


def main(argv=None):
    args = _common.parse_args(argv, __doc__)
    jax = _common.enable_x64()
    import jax.numpy as jnp
    import numpy as np

    from jaxcoag.aggregates import rigid
    from jaxcoag.aggregates.rigid import body
    from jaxcoag.aggregates.rigid import diagnostics as diag

    plt = _common.pyplot()
    if args.quick:
        n0, T = 400, 2.0
        t_out = np.unique(np.concatenate([np.arange(1, 11) * 0.2, [1.6]]))
    else:
        n0, T = 9000, 40.8
        t_out = np.unique(np.round(np.concatenate([np.arange(1, 103) * 0.4, [1.7, 8.2]]), 12))
    L = 10.0 * (n0 / 9000.0) ** (1.0 / 3.0)
    box = rigid.box_model("v", n0=n0, box=L, v0=V0, key=jax.random.key(SEED))
    ckpt = None if args.quick else args.out / "figR09_R12_model_v.ckpt"
    tw = time.time()
    engine = rigid.RigidBox(neighbors=NEIGHBORS, cell_capacity=CELL_CAPACITY, clock=CLOCK)
    res = rigid.run(box, jnp.asarray(t_out), engine=engine, checkpoint=ckpt, every=4, progress=not args.quick)
    wall = time.time() - tw
    o = {k: np.asarray(v) for k, v in res.outs.items()}
    N = o["n_aggregates"].astype(float)
    nc, nc1, ncoag, nrest = o["n_c"], o["n_c1"], o["n_coag"], o["n_rest"]
    mm = np.asarray(res.max_mass)
    alpha = box.alpha
    Nth = n0 / (1 + 0.5 * alpha * n0 * t_out)
    it16 = int(np.argmin(np.abs(t_out - 1.6)))
    i82 = int(np.argmin(np.abs(t_out - 8.2)))
    title = f"R95 Figs. 9-12 (model v, N0 = {n0}, L = {L:.3g}, v0 = {V0:g}, T = {T:g}, seed {SEED})"
    ck = _common.Checks(title)

    # ---- the run reached T (a capacity overflow stops it; later outputs would repeat the stopped state)
    ck.add("run status successful (1 = yes; else see the status message)", float(not res.status_message), 1.0, 0.0,
           absolute=True)
    # ---- conservation and per-collision invariants (hard)
    ck.add("max |N + N_coag - N0| (every output)", np.max(np.abs(N + ncoag - n0)), 0.0, 0.0, absolute=True)
    ck.add("max |N_coag + N_rest - N_C| (every output)", np.max(np.abs(ncoag + nrest - nc)), 0.0, 0.0, absolute=True)
    ck.add("total mass / (N0 m0) at T", float(np.sum(o["M"][-1])) / n0, 1.0, 1e-12)
    log = res.collision_log
    nlog = len(log["t"])
    ck.add("collisions logged = N_C (log not full)", nlog, int(nc[-1]), 0.0, absolute=True)
    if nlog:
        ck.add("max |dP| / P_scale per collision (<= 1e-12)", float(np.max(log["dP"] / log["P_scale"])), 0.0, 1e-12,
               absolute=True)
        ck.add("max |dL| / L_scale per collision (<= 1e-10)", float(np.max(log["dL"] / log["L_scale"])), 0.0, 1e-10,
               absolute=True)
        ck.add("max dKE / KE per collision (<= 1e-12)", max(float(np.max(log["dKE"] / log["KE"])), 0.0), 0.0, 1e-12,
               absolute=True)
    ke = np.asarray(res.kinetic_energy).sum(-1)
    ck.add("max rise of total KE between outputs / KE(0) (<= 1e-6)", max(float(np.max(np.diff(ke))), 0.0)
           / float(np.asarray(box.mass) @ np.sum(np.asarray(box.v) ** 2, -1) * 0.5), 0.0, 1e-6, absolute=True)

    # ---- R-Fig 10: aggregates at T
    ag = res.aggregates(-1)
    na = ag["n_a"]
    s_r, s_r_err, _ = diag.power_law(na, ag["Rmax"])
    gam, gam_err, _ = diag.power_law(na, ag["rho"])
    fd_mean, fd_err = diag.weighted_mean(ag["f_D"], ag["f_D_err"])
    # ---- R-Fig 12: the second-largest aggregate, rendered from the final state's body offsets
    st = res.final_state
    order = np.argsort(-na, kind="stable")
    sec = order[1] if len(order) > 1 else order[0]
    slot = int(ag["slot"][sec])
    members = np.nonzero(np.asarray(st.sph_agg) == slot)[0]
    A = np.asarray(body.matrix_from_quat(st.q[slot]))
    xyz = np.asarray(st.sph_b)[members] @ A.T  # space-frame offsets from the aggregate's COM
    Rs = np.asarray(st.sph_R)[members]
    com = np.average(xyz, axis=0, weights=np.asarray(st.sph_m)[members])
    fd_render = _fd_regression(np.linalg.norm(xyz - com, axis=1))  # member-centre distances (A9)
    ck.add(f"f_D of the rendered aggregate (slot {slot}) = diagnostics' value", fd_render, float(ag["f_D"][sec]), 1e-9)
    ck.add("members of the rendered aggregate = its N_a", len(members), int(na[sec]), 0.0, absolute=True)

    # ---- numbers beside the paper's
    half = np.nonzero(N <= n0 / 2)[0]
    t_half = float(np.interp(n0 / 2, N[::-1], t_out[::-1])) if len(half) else math.nan
    agg_frac = lambda i: 1.0 - float(np.sum((o["nmem"][i] == 1) & o["alive"][i])) / n0  # noqa: E731
    coag_frac = float(ncoag[-1]) / max(int(nc[-1]), 1)
    sig = np.asarray(res.velocity_dispersion)
    M82, ke82 = o["M"][i82][o["alive"][i82]], (o["ke_trans"][i82] + o["ke_rot"][i82])[o["alive"][i82]]
    full = not args.quick
    ck.add("t_1/2 [R95: ~1.7] (info)", t_half, PAPER["t_half"], math.inf, counts=False)
    ck.add(f"aggregated mass fraction at t = {t_out[i82]:g} [R95: ~0.90 at 8.2] (info)", agg_frac(i82),
           PAPER["aggregated_at_8_2"], math.inf, counts=False)
    ck.add("collisions N_C [R95: 14420] (info)", int(nc[-1]), PAPER["n_collisions"], math.inf, counts=False)
    ck.add("coagulation fraction [R95: 0.62; band +- 0.1]", coag_frac, PAPER["coag_fraction"], 0.1, absolute=True,
           counts=full)
    ck.add("aggregated mass fraction at T [R95: 0.9998] (info)", agg_frac(-1), PAPER["aggregated_at_T"], math.inf,
           counts=False)
    ck.add("largest aggregate / total mass at T [R95: 0.31] (info)", float(mm[-1]) / n0, PAPER["largest_fraction"],
           math.inf, counts=False)
    ck.add("R_max exponent [R95: 0.52 +- 0.01; band +- 0.05]", s_r, PAPER["rmax_exponent"][0], 0.05, absolute=True,
           counts=full)
    ck.add("mean f_D [R95: 2.0 +- 0.2; band [1.5, 2.2]]", fd_mean, 1.85, 0.35, absolute=True, counts=full)
    ck.add("gamma (rho ~ N_a^gamma) [R95: -0.55 +- 0.04; band +- 0.1]", gam, PAPER["gamma"][0], 0.1, absolute=True,
           counts=full)
    ck.add("second-largest aggregate: spheres [R95: 1811] (info)", int(na[sec]), PAPER["second_largest_members"],
           math.inf, counts=False)
    ck.add("second-largest aggregate: f_D [R95: 2.02 +- 0.01] (info)", float(ag["f_D"][sec]),
           PAPER["second_largest_fd"][0], math.inf, counts=False)
    ck.add(f"sigma_x / sigma_z at t = {t_out[i82]:g} (isotropy; info)", float(sig[i82, 0] / sig[i82, 2]), 1.0, math.inf,
           counts=False)
    ck.add(f"slope of log KE vs log M at t = {t_out[i82]:g} (equipartition 0; info)", _ke_slope(M82, ke82), 0.0, math.inf,
           absolute=True, counts=False)

    # ---- figure: 3 x 4 panels
    fig = plt.figure(figsize=(17, 12))
    gs = fig.add_gridspec(3, 4)
    a = fig.add_subplot(gs[0, 0])
    t0p = np.concatenate([[0.0], t_out])  # the initial state (N0 spheres, no collision) in front
    a.plot(t0p, np.concatenate([[n0], N]), "k-", label="N (observed)")
    tt = np.linspace(0, T, 300)
    a.plot(tt, n0 / (1 + 0.5 * alpha * n0 * tt), "k-.", label="(R30)")
    a.plot(t0p, np.concatenate([[0], nc]), "k:", label="$N_C$")
    a.plot(t0p, np.concatenate([[0], nc1]), "k--", lw=0.8, label="$N_{C1}$")
    a.axhline(n0 / 2, ls=(0, (8, 4)), color="gray")
    a.set_xlabel("t")
    a.set_ylabel("N")
    a.legend(fontsize=8)
    a.set_title("R-Fig 9a: particles and collisions", fontsize=10)
    b = fig.add_subplot(gs[0, 1])
    b.plot(t_out, mm, "k-")
    b.set_xlabel("t")
    b.set_ylabel("maximum mass / $m_0$")
    b.set_title("R-Fig 9b: maximum mass", fontsize=10)
    spec = np.asarray(res.mass_spectrum(kmax=n0))
    for col, (i, lab) in zip((2, 3), ((it16, "c"), (len(t_out) - 1, "d"))):
        axx = fig.add_subplot(gs[0, col])
        nk = spec[i]
        kk = np.nonzero(nk)[0] + 1
        axx.plot(kk, nk[kk - 1], "ko", ms=3)
        if lab == "c":
            f = N[i] / n0
            k = np.arange(1, max(kk.max(), 10) + 1)
            axx.plot(k, n0 * f**2 * (1 - f) ** (k - 1), "k-", lw=0.8, label=f"(R31), f = {f:.3f}")
            axx.legend(fontsize=8)
        axx.set_xscale("log")
        axx.set_yscale("log")
        axx.set_xlabel("m / $m_0$")
        axx.set_ylabel("$n_k$")
        axx.set_title(f"R-Fig 9{lab}: spectrum at t = {t_out[i]:g}", fontsize=10)
    _power_law_panel(fig.add_subplot(gs[1, 0]), na, ag["Rmax"], s_r, "$R_{max}$", "R-Fig 10a: size (R95: 0.52)")
    d = fig.add_subplot(gs[1, 1])
    okf = np.isfinite(ag["f_D"])
    d.errorbar(na[okf], ag["f_D"][okf], yerr=ag["f_D_err"][okf], fmt="k.", ms=3, lw=0.5)
    if math.isfinite(fd_mean):
        d.axhline(fd_mean, color="gray", label=f"weighted mean {fd_mean:.2f}")
        d.legend(fontsize=8)
    d.set_xscale("log")
    d.set_xlabel("$N_a$")
    d.set_ylabel("$f_D$")
    d.set_title("R-Fig 10b: fractal dimension (R95: 2.0)", fontsize=10)
    _power_law_panel(fig.add_subplot(gs[1, 2]), na, ag["rho"], gam, r"$\rho$",
                     r"R-Fig 10c: density (R95: $\gamma$ = -0.55)")
    g = fig.add_subplot(gs[1, 3])
    for j, (ls, nm) in enumerate(zip(("-", "--", ":"), "xyz")):
        g.plot(t_out, sig[:, j], "k" + ls, label=rf"$\sigma_{nm}$")
    g.set_xlabel("t")
    g.set_ylabel(r"$\sigma$")
    g.legend(fontsize=8)
    g.set_title("R-Fig 11a: velocity dispersion", fontsize=10)
    h = fig.add_subplot(gs[2, 0])
    h.loglog(M82, ke82, "k.", ms=3)
    h.set_xlabel("mass / $m_0$")
    h.set_ylabel("KE (translational + rotational)")
    h.set_title(f"R-Fig 11b: KE vs mass at t = {t_out[i82]:g}", fontsize=10)
    r3 = fig.add_subplot(gs[2, 1:3], projection="3d")
    p = xyz - com
    r3.scatter(p[:, 0], p[:, 1], p[:, 2], s=max(2.0, 3000.0 / len(p)), c=p[:, 2], cmap="gray", depthshade=True)
    ext = float(np.max(np.abs(p))) + float(Rs.max())
    for setl in (r3.set_xlim, r3.set_ylim, r3.set_zlim):
        setl(-ext, ext)
    r3.set_box_aspect((1, 1, 1))
    r3.set_title(f"R-Fig 12: second-largest aggregate, {len(members)} spheres, f_D = {fd_render:.2f} "
                 f"(R95: 1811, 2.02)", fontsize=10)
    txt = fig.add_subplot(gs[2, 3])
    txt.axis("off")
    txt.text(0, 1, "\n".join([
        f"ours (paper)", f"N_C = {int(nc[-1])} ({PAPER['n_collisions']})",
        f"coag. fraction = {coag_frac:.2f} ({PAPER['coag_fraction']})", f"t_1/2 = {t_half:.2f} (1.7)",
        f"largest / total = {float(mm[-1]) / n0:.2f} (0.31)", f"R_max exponent = {s_r:.3f} +- {s_r_err:.3f} (0.52)",
        f"mean f_D = {fd_mean:.2f} +- {fd_err:.2f} (2.0)", f"gamma = {gam:.3f} +- {gam_err:.3f} (-0.55)",
        f"wall time {wall:.0f} s"]), va="top", family="monospace", fontsize=9)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    png = _common.savefig(fig, args, "figR09_R12_model_v")
    ck.print()
    print(f"second-largest aggregate: {len(members)} spheres, f_D = {float(ag['f_D'][sec]):.3f} +- "
          f"{float(ag['f_D_err'][sec]):.3f} (R95: 1811 spheres, f_D = 2.02 +- 0.01)")
    print(f"run: {int(o['n_steps'][-1])} steps, {int(o['n_build'][-1])} neighbour builds, {wall:.1f} s wall "
          f"(compile included), status {res.status_message or 'successful'}")
    numbers = dict(
        case=dict(model="v", n0=n0, L=L, r0=float(box.r0), v0=V0, T=T, seed=SEED, quick=bool(args.quick),
                  neighbors=NEIGHBORS, cell_capacity=CELL_CAPACITY, clock=CLOCK), status=res.status_message or "successful",
        paper=PAPER, wall_s=wall, n_steps=int(o["n_steps"][-1]), n_build=int(o["n_build"][-1]),
        t=t_out.tolist(), N=N.tolist(), N_R30=Nth.tolist(), N_C=nc.tolist(), N_C1=nc1.tolist(),
        n_coag=ncoag.tolist(), n_rest=nrest.tolist(), max_mass=mm.tolist(), sigma_v=sig.tolist(),
        ke_total=ke.tolist(), t_half=t_half, coag_fraction=coag_frac, aggregated_at_8_2=agg_frac(i82),
        aggregated_at_T=agg_frac(-1), largest_fraction=float(mm[-1]) / n0,
        rmax_exponent=[s_r, s_r_err], gamma=[gam, gam_err], fd_from_gamma=float(diag.fd_from_gamma(gam)),
        mean_fd=[fd_mean, fd_err], second_largest=dict(slot=slot, n_a=int(na[sec]), f_D=float(ag["f_D"][sec]),
                                                       f_D_err=float(ag["f_D_err"][sec]), f_D_rendered=fd_render),
        aggregates_T=dict(n_a=na.tolist(), Rmax=ag["Rmax"].tolist(), f_D=np.nan_to_num(ag["f_D"], nan=-1).tolist()),
        ke_vs_mass_8_2=dict(t=float(t_out[i82]), M=M82.tolist(), ke=ke82.tolist()),
        checks={k: dict(v) for k, v in ck.rows.items()}, all_ok=ck.all_ok)
    jpath = args.out / "figR09_R12_model_v.json"
    jpath.write_text(json.dumps(numbers, indent=1, default=float))
    print(f"wrote {png} and {jpath}")
    return ck.result(png, json=jpath, numbers=numbers, n0=n0, result=res)


if __name__ == "__main__":
    main()
