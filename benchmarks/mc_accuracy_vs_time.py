"""Monte Carlo accuracy vs wall time: jaxcoag.mc (grouped, Ormel & Spaans 2008) vs PySDM (SDM).

Problem solved by both codes (identical): the Shima et al. (2009) Golovin box with a
*monodisperse* start (our engine starts monodisperse): K = 1500 (m1 + m2) cm^3 s^-1 g^-1
(b = 1500 s^-1 per volume, water 1 g cm^-3), n0 = 2^23 m^-3, every drop with the mean mass
of the Shima spectrum (radius 30.531 um), box 1e6 m^3 (8.39e12 drops), outputs at
1200/2400/3600 s. Metric: relative L1 of dm/dlnr on 128 log radius bins 10 um - 5 mm against
the discrete Golovin solution (``jaxcoag.analytic.mass_per_bin(..., initial="monodisperse")``).

Our side: ``jaxcoag.evolve(Sum(1500), jaxcoag.MonteCarlo(grouping=jaxcoag.mc.EqualMass(), ns_target=Ns,
f_eps=..., n_particles=...), jaxcoag.Monodisperse(m0, rho_d), t_out, key=...)`` (constant volume); sweep over Ns at
the thesis' f_eps = 1e-3 (``--ns``) and at f_eps = 0.1 (``--bulk-feps``, ``--bulk-ns``: on the bulk of the mass as
accurate as 1e-3 at ~8x fewer events), and over f_eps at one Ns (``--feps``); per configuration the first seed's run
includes compilation (``compile_s`` = its time minus the timed run), later seeds are timed;
events per second = events / timed wall time. PySDM: Numba CPU backend, n_sd sweep, same
monodisperse problem (``benchmarks/peers/pysdm_golovin.py``); PySDM on its own exponential
Shima box is run too and reported as a reference of its home accuracy.

A second, less noise-dominated metric ``l1_coarse`` merges every 5 radius bins (~factor-2
mass bins, as in Ormel 2008 thesis §5.3) before taking the L1. Ratios: from our (wall, L1) points (mean over seeds per configuration, log-log
interpolation along our Pareto front): at each PySDM run's wall time, L1(PySDM) / L1(ours)
(> 1: we are more accurate for the same time), and at each PySDM run's error,
wall(PySDM) / wall(ours) (> 1: we are faster). Outside our measured range the value is null
and ``bound`` states the one-sided bound the measurements do support.

Run: ``python benchmarks/mc_accuracy_vs_time.py [--quick] [--ns 64,128] [--feps 1e-3]
[--nsd 11,13] [--seeds 2] [--no-peers]``. Writes benchmarks/results/mc_accuracy_vs_time[_quick].json
and a PNG.
References: Ormel & Spaans (2008) ApJ 684, 1291; Shima et al. (2009) QJRMS 135, 1307;
Golovin (1963); metrics in docs/design_notes.md.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from benchmarks import _common as C  # noqa: E402
from benchmarks.peers import pysdm_golovin as P  # noqa: E402

M0 = P.RHO_W * 4.0 / 3.0 * np.pi * (P.R_MEAN_UM * 1e-4) ** 3   # g
N0 = P.N0_SI * 1e-6                                             # cm^-3
B = P.B_SI / P.RHO_W                                            # cm^3 s^-1 g^-1
VOLUME = P.DV_SI * 1e6                                          # cm^3
M_EDGES = P.RHO_W * 4.0 / 3.0 * np.pi * P.R_EDGES_CM ** 3       # g
DLNR = np.diff(np.log(P.R_EDGES_CM))
COARSE = 5   # radius bins merged for the coarse metric (factor 2.07 in mass per coarse bin)


def coarse_l1(spec, ref):
    """Relative L1 after merging every COARSE radius bins (~factor-2 mass bins)."""
    idx = np.arange(spec.size) // COARSE
    return C.rel_l1(np.bincount(idx, weights=spec), np.bincount(idx, weights=ref))


def run_ours(ns_target, f_eps, seeds, times=P.TIMES, capacity_factor=None):
    """Run our grouped MC for ``seeds`` (list of ints); returns one dict per seed.

    ``capacity`` = ``capacity_factor`` x Ns, or None (the default): the library's default (4 Ns* for
    equal-mass grouping, which merges mass neighbours above 2 Ns*).
    The first seed's time includes compilation (unless this Ns was compiled before: f_eps is
    a traced argument); its ``wall_s`` is None and ``compile_s`` = first time - its events x
    (seconds per event of the timed seeds), when a second seed exists.
    """
    import jax
    import jaxcoag
    from jaxcoag import mc
    from jaxcoag.kernels import Sum

    engine = jaxcoag.MonteCarlo(grouping=mc.EqualMass(), n_particles=N0 * VOLUME, ns_target=ns_target, f_eps=f_eps,
                                capacity=None if capacity_factor is None else int(capacity_factor * ns_target))
    initial = jaxcoag.Monodisperse(M0, N0 * M0)
    refs = np.array([P.golovin_reference_dm_dlnr_monodisperse(t) for t in times])
    out = []
    for i, seed in enumerate(seeds):
        with C.Timer() as tm:
            r = jaxcoag.evolve(Sum(B), engine, initial, np.asarray(times), key=jax.random.PRNGKey(seed), throw=False)
            jax.block_until_ready(r.m)
        spec = np.asarray(r.mass_per_bin(M_EDGES)) / DLNR[None, :]
        l1 = [C.rel_l1(s, ref) for s, ref in zip(spec, refs)]
        l1c = coarse_l1(spec[-1], refs[-1])
        status = jaxcoag.status_names(r.status)
        out.append(dict(code="jaxcoag", ns_target=ns_target, f_eps=f_eps, seed=seed,
                        capacity=int(r.m.shape[-1]),
                        first_call=(i == 0), time_s=tm.seconds, n_events=int(r.n_events),
                        n_merge=int(r.n_merge), n_dup=int(r.n_dup), status=status,
                        l1=l1, l1_final=l1[-1], l1_coarse_final=l1c, dm_dlnr=spec))
    timed = [o for o in out if not o["first_call"]]
    # seconds per event of the timed runs; the first run's events differ (stochastic), so its
    # compile time is its time minus its own events at that rate
    per_event = (sum(o["time_s"] for o in timed) / max(sum(o["n_events"] for o in timed), 1)
                 if timed else None)
    for o in out:
        o["wall_s"] = None if o["first_call"] and timed else o["time_s"]
        o["compile_s"] = None if per_event is None else \
            max(out[0]["time_s"] - out[0]["n_events"] * per_event, 0.0)
    return out


def _as_list(status):
    """A run's status as a list of names (``jaxcoag.status_names`` gives one name for a single run)."""
    if status is None:
        return []
    return [status] if isinstance(status, str) else list(status)


def summarize(rows, key_fields):
    """Mean L1 / wall / events per configuration; ensemble-mean L1 from the averaged spectra."""
    groups = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in key_fields), []).append(r)
    out = []
    for key, rs in groups.items():
        walls = [r["wall_s"] for r in rs if r.get("wall_s") is not None]
        mean_spec = np.mean([r["dm_dlnr"][-1] for r in rs], axis=0)
        ref = rs[0]["reference_final"]
        ev = [r.get("n_events") for r in rs if r.get("n_events") is not None]
        wall = float(np.mean(walls)) if walls else None
        out.append(dict(
            **dict(zip(key_fields, key)), runs=len(rs), wall_s=wall,
            l1_mean=float(np.mean([r["l1_final"] for r in rs])),
            l1_std=float(np.std([r["l1_final"] for r in rs])),
            l1_ensemble=C.rel_l1(mean_spec, ref),
            l1_coarse_mean=float(np.mean([coarse_l1(r["dm_dlnr"][-1], ref) for r in rs])),
            events=float(np.mean(ev)) if ev else None,
            events_per_s=(float(np.mean(ev)) / wall) if (ev and wall) else None,
            compile_s=rs[0].get("compile_s"),
            status=sorted({str(x) for r in rs for x in _as_list(r.get("status"))}) or ["OK"]))
    return out


def pareto(points):
    """Points (wall, err) sorted by wall with strictly decreasing error (the Pareto front)."""
    pts = sorted((w, e) for w, e in points if w is not None and e is not None and w > 0 and e > 0)
    front, best = [], np.inf
    for w, e in pts:
        if e < best:
            front.append((w, e))
            best = e
    return front


def interp_loglog(xs, ys, x):
    """Log-log linear interpolation of y(x) on sorted xs; None outside [xs[0], xs[-1]]."""
    if len(xs) == 0 or x < xs[0] or x > xs[-1]:
        return None
    if len(xs) == 1:
        return float(ys[0])
    return float(np.exp(np.interp(np.log(x), np.log(xs), np.log(ys))))


def ratios(ours_summary, peer_summary):
    """Equal-wall-time error ratios and equal-error wall-time ratios vs each peer point."""
    front = pareto([(o["wall_s"], o["l1_mean"]) for o in ours_summary])
    fw = [w for w, _ in front]
    fe = [e for _, e in front]
    rows = []
    for p in peer_summary:
        e_ours = interp_loglog(fw, fe, p["wall_s"]) if p["wall_s"] else None
        w_ours = interp_loglog(fe[::-1], fw[::-1], p["l1_mean"]) if fe else None
        row = dict(peer_n_sd=p.get("n_sd"), peer_wall_s=p["wall_s"],
                   peer_l1=p["l1_mean"], ours_l1_at_equal_wall=e_ours,
                   error_ratio_equal_wall=None if e_ours is None else p["l1_mean"] / e_ours,
                   ours_wall_at_equal_error=w_ours,
                   speedup_equal_error=None if w_ours is None else p["wall_s"] / w_ours,
                   bound=None)
        if front and (e_ours is None or w_ours is None):
            notes = []
            if e_ours is None and p["wall_s"] < fw[0]:
                notes.append(f"equal-wall error ratio <= {p['l1_mean'] / fe[0]:.3g} "
                             "(peer faster than our fastest run)")
            elif e_ours is None:
                notes.append(f"equal-wall error ratio >= {p['l1_mean'] / fe[-1]:.3g} "
                             "(peer slower than our slowest run)")
            if w_ours is None and p["l1_mean"] < fe[-1]:
                notes.append(f"equal-error speedup <= {p['wall_s'] / fw[-1]:.3g} "
                             "(peer more accurate than our most accurate run)")
            elif w_ours is None:
                notes.append(f"equal-error speedup >= {p['wall_s'] / fw[0]:.3g} "
                             "(peer less accurate than our least accurate run)")
            row["bound"] = "; ".join(notes)
        rows.append(row)
    return rows


def plot(ours_sum, peers_sum, peers_home, path):
    """L1 vs wall time: ours (per f_eps), PySDM same problem, PySDM on its exponential box."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.5))
    for fe in sorted({o["f_eps"] for o in ours_sum}):
        pts = [o for o in ours_sum if o["f_eps"] == fe and o["wall_s"]]
        ax.loglog([o["wall_s"] for o in pts], [o["l1_mean"] for o in pts], "o-",
                  label=f"jaxcoag.mc equal-mass, f_eps={fe:g}")
        for o in pts:
            ax.annotate(f"Ns={o['ns_target']}", (o["wall_s"], o["l1_mean"]), fontsize=6)
    if peers_sum:
        ax.loglog([p["wall_s"] for p in peers_sum], [p["l1_mean"] for p in peers_sum], "ks-",
                  label="PySDM (monodisperse, same problem)")
    if peers_home:
        ax.loglog([p["wall_s"] for p in peers_home], [p["l1_mean"] for p in peers_home], "k^--",
                  label="PySDM (Shima exponential box)")
    ax.set_xlabel("wall time [s] (after compile)")
    ax.set_ylabel("relative L1 of dm/dlnr at 3600 s")
    ax.set_title("Golovin box (Shima et al. 2009 parameters)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="Ns 64,128; n_sd 2^11, 2^13")
    ap.add_argument("--ns", default=None, help="comma list of ns_target")
    ap.add_argument("--feps", default=None, help="comma list of f_eps (at the middle Ns)")
    ap.add_argument("--bulk-feps", type=float, default=0.1,
                    help="f_eps of the second Ns series (default 0.1; 0 skips it)")
    ap.add_argument("--bulk-ns", default=None,
                    help="comma list of ns_target at --bulk-feps (default 128,...,4096; quick 128,256)")
    ap.add_argument("--nsd", default=None, help="comma list of log2(n_sd) for PySDM")
    ap.add_argument("--seeds", type=int, default=2, help="seeds per configuration (>= 2 to "
                    "separate compile time)")
    ap.add_argument("--capacity-factor", type=float, default=None,
                    help="species capacity = factor x Ns (default: the library's, 4 Ns* for equal mass)")
    ap.add_argument("--budget-s", type=float, default=1200.0,
                    help="skip our remaining configurations once this much time has passed")
    ap.add_argument("--no-peers", action="store_true")
    ap.add_argument("--no-ours", action="store_true", help="peer side only")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    C.ensure_x64()
    ns_list = [int(x) for x in args.ns.split(",")] if args.ns else (
        [64, 128] if args.quick else [64, 128, 256, 512])
    feps_main = 1e-3
    feps_sweep = [float(x) for x in args.feps.split(",")] if args.feps else (
        [] if args.quick else [1e-2, 1e-4])
    bulk_ns = [int(x) for x in args.bulk_ns.split(",")] if args.bulk_ns else (
        [128, 256] if args.quick else [128, 256, 512, 1024, 2048, 4096])
    if not args.bulk_feps:
        bulk_ns = []
    nsd = [int(x) for x in args.nsd.split(",")] if args.nsd else (
        [11, 13] if args.quick else [11, 13, 15, 17])
    seeds = list(range(max(args.seeds, 1)))

    t_start = time.perf_counter()
    skipped = []
    peers, home = [], []
    if not args.no_peers:
        cst = P.warm_up()
        print(f"PySDM warm-up {cst:.1f}s", flush=True)
        for k in nsd:
            for seed in seeds:
                r = P.run_pysdm(2 ** k, seed=seed + 1, initial="monodisperse")
                r["reference_final"] = r["reference_dm_dlnr"][-1]
                peers.append(r)
                h = P.run_pysdm(2 ** k, seed=seed + 1, initial="exponential")
                h["reference_final"] = h["reference_dm_dlnr"][-1]
                home.append(h)
                print(f"PySDM n_sd=2^{k} seed={seed + 1}: mono L1={r['l1_final']:.4g} "
                      f"wall={r['wall_s']:.2f}s | exponential L1={h['l1_final']:.4g} "
                      f"wall={h['wall_s']:.2f}s", flush=True)
    ours, ours_error = [], None
    if not args.no_ours:
        configs = [(ns, feps_main) for ns in ns_list]
        mid = ns_list[(len(ns_list) - 1) // 2]
        configs += [(mid, fe) for fe in feps_sweep if fe != feps_main]
        configs += [(ns, args.bulk_feps) for ns in bulk_ns if (ns, args.bulk_feps) not in configs]
        ref_final = P.golovin_reference_dm_dlnr_monodisperse(P.TIMES[-1])
        try:
            for ns, fe in configs:
                if time.perf_counter() - t_start > args.budget_s:
                    skipped.append(dict(ns_target=ns, f_eps=fe))
                    print(f"ours Ns={ns} f_eps={fe:g}: skipped (time budget {args.budget_s} s)")
                    continue
                rs = run_ours(ns, fe, seeds, capacity_factor=args.capacity_factor)
                for r in rs:
                    r["reference_final"] = ref_final
                ours.extend(rs)
                for r in rs:
                    print(f"ours Ns={ns} f_eps={fe:g} seed={r['seed']} L1={r['l1_final']:.4g} "
                          f"time={r['time_s']:.2f}s events={r['n_events']} status={r['status']}",
                          flush=True)
        except ImportError as exc:
            ours_error = f"jaxcoag.mc not importable: {exc}"
            print(ours_error)
    ours_sum = summarize(ours, ["ns_target", "f_eps"]) if ours else []
    peers_sum = summarize(peers, ["n_sd"]) if peers else []
    home_sum = summarize(home, ["n_sd"]) if home else []
    if ours_sum:
        C.print_table(ours_sum, ["ns_target", "f_eps", "runs", "status", "compile_s", "wall_s",
                                 "events",
                                 "events_per_s", "l1_mean", "l1_std", "l1_ensemble", "l1_coarse_mean"],
                      title="jaxcoag.mc on the monodisperse Golovin box (L1 of dm/dlnr, 3600 s)")
    if peers_sum:
        C.print_table(peers_sum, ["n_sd", "runs", "wall_s", "l1_mean", "l1_std", "l1_ensemble",
                                  "l1_coarse_mean"],
                      title="PySDM, same monodisperse problem")
        C.print_table(home_sum, ["n_sd", "runs", "wall_s", "l1_mean", "l1_std", "l1_ensemble",
                                 "l1_coarse_mean"],
                      title="PySDM, Shima exponential box (its home problem)")
    rat = ratios(ours_sum, peers_sum) if (ours_sum and peers_sum) else []
    if rat:
        C.print_table(rat, ["peer_n_sd", "peer_wall_s", "peer_l1", "ours_l1_at_equal_wall",
                            "error_ratio_equal_wall", "ours_wall_at_equal_error",
                            "speedup_equal_error", "bound"],
                      title="Ratios vs PySDM (>1 favours jaxcoag.mc); null = outside our range")
    tag = "_quick" if args.quick else ""
    out = pathlib.Path(args.out) if args.out else C.RESULTS / f"mc_accuracy_vs_time{tag}.json"

    def slim(rs):
        return [{k: v for k, v in r.items() if k not in ("dm_dlnr", "reference_dm_dlnr",
                                                         "reference_final")} for r in rs]

    C.write_json(out, dict(benchmark="mc_accuracy_vs_time", quick=args.quick,
                           machine=C.machine_info(), ours_error=ours_error,
                           ours_skipped_for_time=skipped,
                           problem=dict(kernel="sum", b=B, n0=N0, m0=M0, volume_cm3=VOLUME,
                                        times=P.TIMES, r_edges_cm=P.R_EDGES_CM,
                                        initial="monodisperse"),
                           ours_runs=slim(ours), ours_summary=ours_sum,
                           pysdm_runs=slim(peers), pysdm_summary=peers_sum,
                           pysdm_exponential_runs=slim(home), pysdm_exponential_summary=home_sum,
                           ratios=rat))
    plot(ours_sum, peers_sum, home_sum, out.with_suffix(".png"))
    print(f"wrote {out}")
    return dict(ours=ours_sum, pysdm=peers_sum, pysdm_exponential=home_sum, ratios=rat)


if __name__ == "__main__":
    main()
