"""Wada et al. (2007) Figs. 7, 11 and 14 from one sweep of head-on BCCA collisions.

Fig. 7: r_g/(r_1 sqrt(N_large)) (a) and r_g/(r_1 sqrt(N_total)) (b) of the largest cluster against
x_roll = E_imp/(n_k E_roll) with the paper's fit 0.84 x_roll^-0.12 (eq. 51, fit over E_roll < E_imp < 0.1 n_k E_roll);
Fig. 11: n_con against E_imp (a) and log(n_con - 1) against log x_roll (b) with n_con - 1 = x_roll^0.75 (eq. 56,
E_imp <~ 0.1 n_k E_roll); Fig. 14: N_large/N_total against x_break = E_imp/(n_k E_break) (disruption from x_break ~ 3,
catastrophic, N_large/N_total <= 1/2, from ~ 10). n_k = N_total - 2, E_imp = (1/2) N_total m_1 (v_imp/2)^2 (§5.1).
Each collision: one 2-D BCCA per structure (``contact.bcca``, key = structure) against an independently rotated copy
of itself (the paper's "same BCCA", §4), head-on, in the centre-of-mass frame.

The paper's sweep (Wada et al. §4-5, Table 3): N_total = 256, four material sets (quartz and ice, xi_crit = 2 and
30 A), 3 structures, v_imp from 0.14 to 18 v_0 (~16 speeds), dt = 0.014 t_c. Not runnable here. A collision lasts
until the aggregates have passed through each other, a relative displacement D ~ 8 r_g,a (r_g,a = 18 r_1 for a
128-BCCA), i.e. D/(v_imp dt) = 8 x 18 x (r_1/(v_0 t_c)) / (0.014 v_imp/v_0) steps with r_1/(v_0 t_c) = 119 (ice) or
1141 (quartz); over 16 log-spaced speeds 0.14-18 v_0 (sum v_0/v_imp = 22.6) that is 2.8e7 steps per ice structure
and 2.6e8 per quartz structure, x 2 xi_crit x 3 structures = 1.8e9 steps of 256 monomers. Measured on this machine
(2 cores shared by 5 jobs, load 13-18): 1.5e5 monomer-steps/s over the reduced sweep (0.95e5 at N_total = 64,
~1.9e5 at 256; ~90 s of compilation per size), so the paper's sweep would take ~35 days here (the script prints
this projection from the rate it measured). A ``jax.vmap`` of ``dem.advance_to`` over 4 structures of 32 + 32
monomers (same run length) measured 2.6 s of CPU against 3.2 s for the loop, after an extra ~20 s compilation: not
used (``collide`` takes one scalar v_imp, and runs at different speeds have different lengths).

Reduced sweep (full mode of this script; measured 2015 s of runs for its 28 collisions, 1.9e6 steps, plus ~90 s
of compilation per size, under load with the first contact layout; 301 s in all, compilation included, on idle
cores with the flat contact list of stop 29; one collision after another: the script now runs ``--workers``
collisions at a time in host threads, default one per core):
* N_total = 64 (32 + 32): ice 30 A, 2 structures, v_imp = 1-18 v_0 (8 speeds, 7 for the second structure;
  x_roll 0.003-0.93, x_break 0.08-27); ice 2 A, 1 structure, v_imp = 1, 2, 3, 4.9, 8 v_0 (x_roll 0.04-2.8);
* N_total = 256 (128 + 128): ice 30 A, 2 structures, v_imp = 1.5, 2.3, 3.5, 5.3 v_0 (x_roll 0.006-0.08: the range
  E_roll < E_imp < 0.1 n_k E_roll of eq. 51 and eq. 56, x_break <= 2.3: no disruption);
* quartz is left out (10x the steps of ice at equal v_imp/v_0).
dt = 0.056 t_c (the paper went up to 0.112 t_c for its large runs, with energy errors < 1e-3, §4; rerun at 0.014 t_c,
ice 30 A, N_total = 64, structure 0: at 3.44 v_0 n_con 1.141 and r_g 10.25 r_1 both times, at 5.2 v_0 n_con 1.234
vs 1.238, r_g 8.94 vs 8.79 r_1, N_large 64 vs 63; energy errors 3.7e-6 vs 7e-5, the dt^2 scaling); each run lasts
t_gap + 8 r_g,a/v_imp, split in two halves whose outcomes are compared (a run is "settled" when N_large is
unchanged, n_con changed by < 0.03 and r_g by < 3 % over the second half; the fraction is printed); the energy
error max|E_total - E_total(0)|/E_imp of every run is kept (printed, not counted: 2.2e-3 at most, in the shattering
runs at 18 v_0).
What each size can test (Wada et al. §5.2-5.3): at N_total = 64 the r_g slope is only required to be shallower than
eq. 51's (small BCCAs start more compact, Fig. 8), eq. 56 and "n_con ~ 1 below E_roll" are printed but not counted
(n_con is lower for N_total = 16 and 64, eq. 57), the disruption thresholds in x_break are counted (brackets between
grid speeds) and so is r_g ~ r_1 sqrt(N_large) at x_roll ~ 1 (ice 2 A); at N_total = 256 the spec's bands of eqs. 51
and 56 are counted. Measured at N_total = 256 (ice 30 A, 2 structures x 4 speeds): r_g/(r_1 sqrt(N_large)) =
0.924 x_roll^-0.077 (paper 0.84 x_roll^-0.12; band [-0.16, -0.09] missed: at E_imp = 1.6 E_roll the merger is
already ~20 % smaller than the BCCA pair) and n_con - 1 = 0.673 x_roll^0.42 (paper x_roll^0.75 +- 0.15, missed:
n_con - 1 lies above the law for x_roll < 0.05); with one structure the r_g exponent was -0.094.
Results are cached in ``<out>/figW07_W11_W14_sweep.json`` (per collision, written as they finish; a rerun skips the
done ones), so the figures are redrawn without rerunning.

Quick mode (the default test): N_total = 16 (8 + 8), dt = 0.112 t_c, runs of t_gap + 4 r_g,a/v_imp, three
collisions: ice 30 A at 1 v_0 (E_imp = 0.045 E_roll: n_con ~ 1, within 0.2 since one contact is 1/16 here, and r_g
within 3 % of the unrestructured merger), ice 2 A at 2 v_0 (x_roll = 0.19: r_g compacted to 0.55-0.95 of the merger)
and at 18 v_0 (x_break = 30: catastrophic disruption, N_large/N_total <= 1/2).
Run: python paper_figs/figW07_W11_W14_sweep.py [--quick] [--out DIR] [--budget-s S]
"""

import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

#: records per half run (the same as ``collide``'s segments: one compiled program per size)
RECORDS = 25
DT_TC = 0.056
#: (label, material constructor name, xi_crit [cm]); the paper's symbols of Fig. 7
SETS = {"quartz 2 A": ("quartz", 2e-8, "s", "k"), "quartz 30 A": ("quartz", 3e-7, "s", "none"),
        "ice 2 A": ("ice", 2e-8, "o", "k"), "ice 30 A": ("ice", 3e-7, "o", "none")}
FULL_PLAN = [("ice 30 A", 32, (0,), (1.0, 1.51, 2.28, 3.44, 5.2, 7.86, 11.9, 18.0)),
             ("ice 2 A", 32, (0,), (1.0, 2.0, 3.0, 4.9, 8.0)),
             ("ice 30 A", 32, (1,), (18.0, 11.9, 7.86, 5.2, 3.44, 2.28, 1.51)),
             ("ice 30 A", 128, (0, 1), (5.3, 3.5, 2.3, 1.5))]
QUICK_PLAN = [("ice 30 A", 8, (0,), (1.0,)), ("ice 2 A", 8, (0,), (2.0, 18.0))]
#: full sweep (paper): for the projected cost in the output
PAPER_SPEEDS = 16


def _material(label):
    from jaxcoag.aggregates import contact

    name, xi, _, _ = SETS[label]
    return getattr(contact, name)(xi_crit=xi)


def run_one(label, n, structure, v_v0, *, dt_tc=DT_TC, span=8.0, log=print):
    """One collision: BCCA(n, key=structure) against a rotated copy at v_v0 v_0, dt = dt_tc t_c, run for
    t_gap + span r_g,a/v_imp in two halves; returns a dict of its outcome."""
    import jax
    import jaxcoag
    import numpy as np
    from jaxcoag.aggregates.contact import DEM, analysis, bcca, collide

    mat = _material(label)
    r1, v0, tc = float(mat.r1), float(mat.v0), float(mat.t_c)
    dt = dt_tc * tc
    a = bcca(n, jax.random.key(structure), 2, material=mat)
    rga = float(analysis.gyration_radius(a.positions))
    v = v_v0 * v0
    t_end = 0.05 * r1 / v + span * rga / v
    every = max(1, int(round(t_end / dt / (2 * RECORDS))))
    t0 = time.time()
    key = jax.random.fold_in(jax.random.key(1000 + structure), int(round(v_v0 * 1000)))
    half = collide(a, a, v, mat, t_end=RECORDS * every * dt, key=key, dt=dt, record_every=every)
    res = jaxcoag.evolve(mat, DEM(dt=dt), half, float(half.t[-1]) + dt * every * np.arange(1, RECORDS + 1))
    wall = time.time() - t0
    N = 2 * n
    E_imp = float(res.E_imp)
    e_tot = np.concatenate([np.asarray(half.E_total), np.asarray(res.E_total)])
    out = dict(set=label, n=n, N_total=N, structure=structure, v_over_v0=v_v0, E_imp_erg=E_imp,
               x_roll=E_imp / ((N - 2) * float(mat.E_roll)), x_break=E_imp / ((N - 2) * float(mat.E_break)),
               N_large=int(res.N_large), N_second=int(res.cluster_sizes[1]), r_g_over_r1=float(res.r_g) / r1,
               r_g0_over_r1=float(res.final_state.r_g0) / r1, n_con=float(res.n_contacts),
               half=dict(N_large=int(half.N_large), r_g_over_r1=float(half.r_g) / r1, n_con=float(half.n_contacts)),
               E_kin_end_over_E_imp=float(res.E_kin[-1]) / E_imp,
               energy_error=float(np.max(np.abs(e_tot - e_tot[0]))) / E_imp,
               steps=int(res.n_steps), dt_over_tc=dt_tc, span=span, t_end_over_tc=float(res.t[-1]) / tc, wall_s=wall,
               status=str(res.status))
    out["settled"] = bool(out["half"]["N_large"] == out["N_large"] and abs(out["half"]["n_con"] - out["n_con"]) < 0.03
                          and abs(out["half"]["r_g_over_r1"] / out["r_g_over_r1"] - 1.0) < 0.03)
    log(f"  {label:11s} N={N:4d} s{structure} v={v_v0:6.2f} v0: x_roll {out['x_roll']:.3g} x_break "
        f"{out['x_break']:.3g} N_large {out['N_large']:3d} n_con {out['n_con']:.3f} r_g/r1 {out['r_g_over_r1']:.2f} "
        f"(r_g0 {out['r_g0_over_r1']:.2f}) settled {out['settled']} dE {out['energy_error']:.1e} "
        f"{out['steps']} steps {wall:.0f} s", flush=True)
    return out


def _key(label, n, s, v):
    return f"{label}|{n}|{s}|{v:g}"


def run_sweep(plan, cache, budget_s=None, *, dt_tc=DT_TC, span=8.0, log=print, workers=None):
    """Run the plan's collisions not yet in ``cache`` (a JSON path; written after each), within ``budget_s``, and
    ``workers`` of them at a time in host threads (default: the core count; a collision keeps one core busy).
    The returned dict (and the cache) lists the collisions in the plan's order."""
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    data = json.loads(cache.read_text()) if cache.exists() else {}
    jobs = [(label, n, s, v) for label, n, structures, speeds in plan for s in structures for v in speeds]
    todo = iter([j for j in jobs if _key(*j) not in data])
    workers = workers or os.cpu_count() or 1
    t0 = time.time()
    running = {}
    stopped = False

    def ordered(d):
        return {_key(*j): d[_key(*j)] for j in jobs if _key(*j) in d}

    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="figW07-sweep") as ex:
        def submit():
            nonlocal stopped
            job = None if stopped else next(todo, None)
            if job is None:
                return
            if budget_s is not None and time.time() - t0 > budget_s:
                log(f"  budget of {budget_s:.0f} s spent: {_key(*job)} and later ones not run")
                stopped = True
                return
            running[ex.submit(run_one, *job, dt_tc=dt_tc, span=span, log=log)] = _key(*job)

        for _ in range(workers):
            submit()
        while running:
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for f in done:
                data[running.pop(f)] = f.result()
                cache.write_text(json.dumps(ordered(data), indent=1))
                submit()
    return ordered(data)


def fit_power(x, y):
    """Least squares of log y on log x: (prefactor, exponent)."""
    import numpy as np

    b, a = np.polyfit(np.log(x), np.log(y), 1)
    return float(np.exp(a)), float(b)


def _interval(pts, pred):
    """(last x before the first point with pred, first x with pred) of sorted (x, f) points; None if none has pred."""
    for i, (x, f) in enumerate(pts):
        if pred(f):
            return (pts[i - 1][0] if i else 0.0, x)
    return None


def _overlaps(ck, name, iv, lo, hi):
    """Counted check: the bracket ``iv`` = (x_before, x_at) of a threshold intersects the band [lo, hi]."""
    ck.add(name, iv[1], 0.5 * (lo + hi), 0.5 * (hi - lo), absolute=True)
    ck.rows[name]["ok"] = bool(iv[0] <= hi and iv[1] >= lo)


def analyse(rows, ck, quick):
    """Fits and thresholds of the sweep rows (list of dicts), added to ``ck``; returns a dict of the numbers.

    Full mode, per N_total: the paper's bands (Wada et al. §5, for N_total = 256) are counted where they hold at that
    size; at N_total < 256 the r_g slope is only required to be shallower than eq. 51 (small BCCAs start more compact,
    Wada et al. Fig. 8) and the eq. 56 fit and the n_con ~ 1 rows are printed, not counted (n_con is lower for
    N_total = 16 and 64, §5.3). Thresholds of Fig. 14 are brackets (last intact speed, first disrupted speed) of the
    structure-averaged N_large/N_total, counted when the bracket meets the band.
    """
    import numpy as np

    out = {}
    if quick:
        lo = [r for r in rows if r["x_roll"] < 1.0 / (r["N_total"] - 2)]
        for r in lo:
            ck.add(f"{r['set']} {r['v_over_v0']} v0 (E_imp/E_roll = {r['x_roll'] * (r['N_total'] - 2):.3f}): n_con "
                   "(~1; one contact is 1/16 here)", r["n_con"], 1.0, 0.2)
            ck.add(f"{r['set']} {r['v_over_v0']} v0: r_g / r_g(unrestructured merger)",
                   r["r_g_over_r1"] / r["r_g0_over_r1"], 1.0, 0.03)
            ck.add(f"{r['set']} {r['v_over_v0']} v0: N_large/N_total", r["N_large"] / r["N_total"], 1.0, 0.0)
        for r in rows:
            if r["x_break"] > 10:
                ck.add(f"{r['set']} {r['v_over_v0']} v0 (x_break = {r['x_break']:.1f}): N_large/N_total <= 1/2 "
                       "(paper: catastrophic from ~10)", r["N_large"] / r["N_total"], 0.25, 0.25, absolute=True)
            elif r["x_roll"] > 0.05:
                ck.add(f"{r['set']} {r['v_over_v0']} v0 (x_roll = {r['x_roll']:.2f}): r_g / r_g(merger) in "
                       "[0.55, 0.95] (compacted)", r["r_g_over_r1"] / r["r_g0_over_r1"], 0.75, 0.2, absolute=True)
        return out
    for NT in sorted({r["N_total"] for r in rows}):
        rs = [r for r in rows if r["N_total"] == NT]
        full = NT >= 256
        tag = f"N={NT}"
        # eq. 51 over E_roll < E_imp < 0.1 n_k E_roll
        sel = [r for r in rs if 1.0 / (NT - 2) < r["x_roll"] < 0.1]
        if len(sel) >= 3:
            A, s = fit_power([r["x_roll"] for r in sel], [r["r_g_over_r1"] / np.sqrt(r["N_large"]) for r in sel])
            out[f"W51 {tag}"] = dict(prefactor=A, exponent=s, points=len(sel), N_total=NT)
            if full:
                ck.add(f"{tag}: eq. 51 exponent ({len(sel)} runs, 1/n_k < x_roll < 0.1; band [-0.16, -0.09])", s,
                       -0.125, 0.035, absolute=True)
            else:
                ck.add(f"{tag}: eq. 51 exponent ({len(sel)} runs) in (-0.12, 0): shallower than at 256 (Fig. 8)", s,
                       -0.06, 0.06, absolute=True)
            ck.add(f"{tag}: eq. 51 prefactor (paper 0.84; band +- 0.15)", A, 0.84, 0.15, absolute=True, counts=full)
        # eq. 56 over x_roll <= 0.1 (n_con > 1)
        sel = [r for r in rs if r["x_roll"] <= 0.1 and r["n_con"] > 1.0 + 1e-9 and r["N_large"] == NT]
        if len(sel) >= 3:
            A, s = fit_power([r["x_roll"] for r in sel], [r["n_con"] - 1.0 for r in sel])
            out[f"W56 {tag}"] = dict(prefactor=A, exponent=s, points=len(sel), N_total=NT)
            ck.add(f"{tag}: eq. 56 exponent ({len(sel)} runs, x_roll <= 0.1; paper 0.75, band +- 0.15)", s, 0.75,
                   0.15, absolute=True, counts=full)
            ck.add(f"{tag}: eq. 56 prefactor (paper 1)", A, 1.0, 0.5, counts=False)
        # below E_roll: no restructuring
        for r in rs:
            if r["x_roll"] * (NT - 2) < 1.0:
                ck.add(f"{tag} {r['set']} s{r['structure']} {r['v_over_v0']} v0 (E_imp = "
                       f"{r['x_roll'] * (NT - 2):.2f} E_roll): n_con (paper ~1)", r["n_con"], 1.0, 0.05, counts=full)
        # Fig. 14 thresholds, per set, structure-averaged
        by = {}
        for r in rs:
            by.setdefault((r["set"], r["v_over_v0"]), []).append(r)
        for label in sorted({r["set"] for r in rs}):
            pts = sorted(((float(np.mean([q["x_break"] for q in v])),
                           float(np.mean([q["N_large"] / q["N_total"] for q in v])))
                          for (lab, _), v in by.items() if lab == label))
            onset = _interval(pts, lambda f: f < 1.0)
            cat = _interval(pts, lambda f: f <= 0.5)
            out[f"fig14 {label} {tag}"] = dict(points=pts, onset=onset, catastrophic=cat, N_total=NT)
            if onset is not None:
                _overlaps(ck, f"{tag} {label}: N_large < N_total first between x_break {onset[0]:.3g} and "
                          f"{onset[1]:.3g} (band [1.5, 5])", onset, 1.5, 5.0)
            if cat is not None:
                _overlaps(ck, f"{tag} {label}: N_large/N_total <= 1/2 first between x_break {cat[0]:.3g} and "
                          f"{cat[1]:.3g} (band [5, 20])", cat, 5.0, 20.0)
            mc = [r for r in rs if r["set"] == label and 0.6 < r["x_roll"] < 1.7]
            if label == "ice 2 A" and mc:
                r = min(mc, key=lambda q: abs(np.log(q["x_roll"])))
                ck.add(f"{tag} ice 2 A: r_g/(r_1 sqrt(N_large)) at x_roll = {r['x_roll']:.2f} (band 1 +- 0.15)",
                       r["r_g_over_r1"] / np.sqrt(r["N_large"]), 1.0, 0.15, absolute=True)
    ck.add("runs settled (fraction)", np.mean([r["settled"] for r in rows]), 1.0, 1.0, counts=False)
    ck.add("max energy error / E_imp, x_roll > 0.01 (paper: < 1e-4 at 0.014 t_c, < 1e-3 at <= 0.112 t_c)",
           max([r["energy_error"] for r in rows if r["x_roll"] > 0.01] or [0.0]), 0.0, 1e-3, absolute=True,
           counts=False)
    return out


def draw(rows, plt, fits):
    """Figs. 7a, 7b, 11a, 11b, 14 in one figure."""
    import numpy as np

    fig, ax = plt.subplots(2, 3, figsize=(14, 8))
    ax = ax.ravel()
    sizes = sorted({r["N_total"] for r in rows})
    for label, NT in [(lab, n) for n in sizes for lab in SETS]:
        rr = [r for r in rows if r["set"] == label and r["N_total"] == NT]
        if not rr:
            continue
        _, _, mk, fc = SETS[label]
        c = f"C{sizes.index(NT)}" if len(sizes) > 1 else "k"
        kw = dict(marker=mk, ls="none", mec=c, mfc=c if fc == "k" else "none", ms=5, label=f"{label}, N={NT}")
        x = np.array([r["x_roll"] for r in rr])
        NL = np.array([r["N_large"] for r in rr], float)
        NT = np.array([r["N_total"] for r in rr], float)
        rg = np.array([r["r_g_over_r1"] for r in rr])
        nc = np.array([r["n_con"] for r in rr])
        ax[0].plot(x, rg / np.sqrt(NL), **kw)
        ax[1].plot(x, rg / np.sqrt(NT), **kw)
        ax[2].plot([r["E_imp_erg"] for r in rr], nc, **kw)
        m = nc > 1.0 + 1e-9
        ax[3].plot(x[m], nc[m] - 1.0, **kw)
        ax[4].plot([r["x_break"] for r in rr], NL / NT, **kw)
    g = np.geomspace(1e-3, 3, 50)
    ax[0].plot(g, 0.84 * g**-0.12, color="0.6", lw=2, label=r"eq. 51: $0.84\,x^{-0.12}$")
    for i, (k, f) in enumerate(sorted((k, f) for k, f in fits.items() if k.startswith("W51"))):
        ax[0].plot(g, f["prefactor"] * g ** f["exponent"], f"C{3 + i}--", lw=1,
                   label=rf"fit N={f['N_total']}: ${f['prefactor']:.2f}\,x^{{{f['exponent']:.3f}}}$")
    ax[3].plot(g, g**0.75, color="0.6", lw=2, label=r"eq. 56: $x^{0.75}$")
    for i, (k, f) in enumerate(sorted((k, f) for k, f in fits.items() if k.startswith("W56"))):
        ax[3].plot(g, f["prefactor"] * g ** f["exponent"], f"C{3 + i}--", lw=1,
                   label=rf"fit N={f['N_total']}: ${f['prefactor']:.2f}\,x^{{{f['exponent']:.3f}}}$")
    for i, NT in enumerate(sizes):
        for a in ax[:2]:
            for xv in (0.1 / (NT - 2), 0.1):  # E_imp = 0.1 E_roll and 0.1 n_k E_roll (the paper's dotted lines)
                a.axvline(xv, color=f"C{i}" if len(sizes) > 1 else "k", ls=":", lw=0.8)
    for a, xl, yl, t in ((ax[0], r"$x_{\rm roll}=E_{\rm imp}/(n_kE_{\rm roll})$", r"$r_g/(r_1N_{\rm large}^{1/2})$",
                          "Fig. 7a"),
                         (ax[1], r"$x_{\rm roll}$", r"$r_g/(r_1N_{\rm total}^{1/2})$", "Fig. 7b"),
                         (ax[2], r"$E_{\rm imp}$ [erg]", r"$n_{\rm con}$", "Fig. 11a"),
                         (ax[3], r"$x_{\rm roll}$", r"$n_{\rm con}-1$", "Fig. 11b"),
                         (ax[4], r"$x_{\rm break}=E_{\rm imp}/(n_kE_{\rm break})$", r"$N_{\rm large}/N_{\rm total}$",
                          "Fig. 14")):
        a.set_xscale("log")
        a.set_xlabel(xl)
        a.set_ylabel(yl)
        a.set_title(t, fontsize=10)
        a.legend(fontsize=7)
    ax[3].set_yscale("log")
    ax[5].axis("off")
    ax[5].text(0, 0.5, f"N_total = {sizes} (paper: 256)\n{len(rows)} collisions\n"
               f"dt = {DT_TC} t_c", fontsize=10)
    fig.tight_layout()
    return fig


def main(argv=None):
    def extra(p):
        p.add_argument("--budget-s", type=float, default=None, help="stop starting new collisions after this many "
                       "seconds")
        p.add_argument("--workers", type=int, default=None, help="collisions run at a time in host threads (default: "
                       "the core count)")

    args = _common.parse_args(argv, __doc__, extra=extra)
    if args.workers is not None and args.workers < 1:
        raise SystemExit(f"--workers must be >= 1; got {args.workers}.")
    if args.budget_s is not None and not args.budget_s > 0:
        raise SystemExit(f"--budget-s must be > 0 seconds; got {args.budget_s}.")
    _common.enable_x64()
    plt = _common.pyplot()
    plan = QUICK_PLAN if args.quick else FULL_PLAN
    name = "figW07_W11_W14_sweep" + ("_quick" if args.quick else "")
    cache = args.out / f"{name}.json"
    if args.quick and cache.exists():
        cache.unlink()  # the quick run always reruns (it is the test)
    t0 = time.time()
    data = run_sweep(plan, cache, args.budget_s, dt_tc=0.112 if args.quick else DT_TC,
                     span=4.0 if args.quick else 8.0, workers=args.workers)
    rows = list(data.values())
    ran = sum(r["wall_s"] for r in rows)
    steps = sum(r["steps"] for r in rows)
    print(f"{len(rows)} collisions, {steps} steps, {ran:.0f} s of runs ({time.time() - t0:.0f} s this call, "
          f"including compilation)")
    big = [r for r in rows if r["N_total"] >= 64]
    if big:  # projected cost of the paper's sweep from the measured speed (steps per second x monomers)
        rate = sum(r["steps"] * r["N_total"] for r in big) / sum(r["wall_s"] for r in big)
        steps_paper = 0.0
        for mat_r1 in (119.0, 1141.0):
            steps_paper += 2 * 3 * 8 * 18.0 * mat_r1 * 22.6 / 0.014  # 2 xi_crit x 3 structures
        print(f"measured {rate:.3g} monomer-steps/s; the paper's sweep (N_total = 256, 4 sets x 3 structures x 16 "
              f"speeds, dt = 0.014 t_c) is ~{steps_paper:.2g} steps = {steps_paper * 256 / rate / 86400:.1f} days here")
    ck = _common.Checks("Wada et al. 2007 Figs. 7, 11, 14 (reduced sweep)" if not args.quick else
                        "Wada et al. 2007 Figs. 7, 11, 14 (quick)")
    fits = analyse(rows, ck, args.quick)
    for k, v in fits.items():
        if k.startswith("W"):
            law = "0.84 x_roll^-0.12" if k.startswith("W51") else "x_roll^0.75"
            print(f"eq. {k[1:3]} (N_total = {v['N_total']}): fit {v['prefactor']:.3f} x_roll^{v['exponent']:.3f} "
                  f"over {v['points']} runs "
                  f"(paper: {law})")
        else:
            print(f"{k}: onset x_break in {v['onset']}, catastrophic in {v['catastrophic']} (paper: ~3, ~10)")
    fig = draw(rows, plt, fits)
    png = _common.savefig(fig, args, name)
    ck.print()
    print(f"wrote {png} and {cache}")
    return ck.result(png, json=cache, rows=rows, fits=fits)


if __name__ == "__main__":
    main()
