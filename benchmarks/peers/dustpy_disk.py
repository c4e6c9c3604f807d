"""DustPy and jaxcoag's radial disk side by side, in one invocation (peer benchmark).

Set-ups (DustPy 1.0.9 defaults unless named; Stammler & Birnstiel 2022 §3):

* ``ci``: ``ini.grid.Nr = 30``, ``ini.grid.mmax = 1e2`` g, snapshots 0, 1e2, 1e3, 1e4 yr;
* ``default``: DustPy's default model (Nr = 100, Nm = 120), snapshots 0 and geomspace(1e3, 1e5, 21) yr
  (``--t-end-yr`` cuts them).

DustPy runs snapshot by snapshot (no writer; its state is copied at each snapshot, its steps counted).
jaxcoag runs ``jaxcoag.disk.solve`` of ``dustpy_default`` with the same parameters in parity mode
(DustPy's discrete system) and in split mode; its compile time is measured apart (first call under
``jax.jit``) from the run (second call). Compared at every snapshot: the dust mass, the gas mass,
Sigma_g(r), Sigma_d(r) (relative differences over cells holding more than 1e-12 of the peak dust
surface density), and a_peak(r) (bin index of the most massive bin per cell; the largest difference
in bins over the interior cells). Speed is reported as the ratio DustPy wall / jaxcoag wall on the
same machine in the same run.

``--modes replay`` runs the parity step with DustPy's own steps (recorded in its run: the time at the start of
every step): the same discrete system with the same step sequence, so that the differences left are round-off and
not the step rule's. Free-running parity takes its steps from DustPy's rule (a minimum over every cell and bin),
so round-off in nearly empty cells can move a step and the two runs' step sequences part after some thousand steps.

``--modes perturbed`` measures that sensitivity on our side alone: one compiled parity solve run from the initial
state and from it with every populated dust bin perturbed by 1e-15 (relative), the two compared as above.

``--write-reference``: writes DustPy's ``ci`` snapshots to ``tests/data/dustpy_disk_ref.npz`` (the
parity test ``tests/test_disk.py`` compares against it; DustPy is not needed there).

Run: ``python benchmarks/peers/dustpy_disk.py [--setup ci|default] [--t-end-yr T] [--modes parity,split,replay,perturbed]
[--write-reference] [--dustpy-cache FILE.npz]``. Writes ``benchmarks/results/dustpy_disk_<setup>.json``
(``dustpy_disk_<setup>_<modes>.json`` for other modes).

References: Stammler & Birnstiel (2022) ApJ 935, 35 (DustPy).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import resource
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
REF = ROOT / "tests" / "data" / "dustpy_disk_ref.npz"
YR = 3.15576e7  # DustPy's year [s]


def snapshots_yr(setup, t_end_yr=None):
    """Snapshot times [yr] (0 first) of a set-up."""
    t = np.array([0.0, 1e2, 1e3, 1e4]) if setup == "ci" else np.concatenate([[0.0], np.geomspace(1e3, 1e5, 21)])
    if t_end_yr is not None:
        t = t[t <= t_end_yr * (1 + 1e-12)]
    return t


def run_dustpy(setup, t_yr):
    """DustPy's run of a set-up: dict of t [s], Sigma_d (T, nr, nm), Sigma_g (T, nr), steps (T,), wall [s]."""
    import dustpy

    sim = dustpy.Simulation()
    if setup == "ci":
        sim.ini.grid.Nr = 30
        sim.ini.grid.mmax = 1e2
    sim.initialize()
    sim.writer = None
    sim.verbosity = 0
    count = {"n": 0}
    step_t = []  # the time at the start of every step [s] (its steps: their differences; the replay mode's input)
    integrate = sim.integrator.integrate

    def counted():
        count["n"] += 1
        step_t.append(float(sim.t))
        return integrate()

    sim.integrator.integrate = counted
    out = {"t": [float(sim.t)], "sigma_dust": [np.array(sim.dust.Sigma)], "sigma_gas": [np.array(sim.gas.Sigma)],
           "steps": [0]}
    wall = 0.0
    for ty in t_yr[1:]:
        sim.t.snapshots = np.array([ty * YR])
        t0 = time.perf_counter()
        sim.run()
        wall += time.perf_counter() - t0
        out["t"].append(float(sim.t))
        out["sigma_dust"].append(np.array(sim.dust.Sigma))
        out["sigma_gas"].append(np.array(sim.gas.Sigma))
        out["steps"].append(count["n"])
    res = {k: np.asarray(v) for k, v in out.items()}
    res.update(wall=wall, step_t=np.asarray(step_t), r=np.array(sim.grid.r), ri=np.array(sim.grid.ri), m=np.array(sim.grid.m),
               area=np.array(sim.grid.A), a=np.array(sim.dust.a[0]))
    return res


def run_jaxcoag(setup, t_yr, mode):
    """jaxcoag's run: dict as :func:`run_dustpy` plus compile [s] and the run's peak RSS [MiB]."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxcoag
    from jaxcoag import disk

    kw = dict(nr=30, m_max=1e2) if setup == "ci" else {}
    model = disk.dustpy_default(**kw)
    m = disk.Parity() if mode == "parity" else disk.Split()
    t_out = np.asarray(t_yr) * YR

    @jax.jit
    def go(model):
        return disk.solve(model, t_out, mode=m, throw=False)

    t0 = time.perf_counter()
    lowered = go.lower(model)
    compiled = lowered.compile()
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = jax.block_until_ready(compiled(model))
    wall = time.perf_counter() - t0
    return {"t": np.asarray(res.t), "sigma_dust": np.asarray(res.sigma_dust), "sigma_gas": np.asarray(res.sigma_gas),
            "steps": np.asarray(res.n_steps), "wall": wall, "compile": t_compile,
            "status": jaxcoag.status_names(res.status), "split_error": np.asarray(res.split_error),
            "maxrss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def run_replay(setup, ref):
    """jaxcoag's parity step driven by DustPy's own step sequence (``jaxcoag.disk.solve.replay``; the steps are the
    differences of ``ref["step_t"]``, DustPy's time at the start of each step, and the last snapshot): the same discrete system
    with the same steps, so what is left is round-off, not the step rule's choices. Snapshots are taken after the
    step counts DustPy had at its snapshots. Returns a dict as :func:`run_jaxcoag`."""
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    from jaxcoag import disk
    from jaxcoag._status import RESULT_NAMES  # DiskState.status holds the code
    from jaxcoag.disk.solve import replay

    if "step_t" not in ref:
        raise SystemExit("replay needs DustPy's step times: this --dustpy-cache was written without them; delete it")
    model = disk.dustpy_default(**(dict(nr=30, m_max=1e2) if setup == "ci" else {}))
    mode = disk.Parity()
    s0 = disk.solve(model, np.asarray([0.0]), mode=mode).final_state
    dts = np.diff(np.append(ref["step_t"], ref["t"][-1]))
    snap = np.asarray(ref["steps"], np.int64)  # steps taken at each snapshot (0 at t = 0)
    if dts.size != snap[-1] or np.any(dts <= 0) or snap[0] != 0:
        raise SystemExit(f"DustPy's step record is inconsistent ({dts.size} steps, {snap[-1]} counted)")

    @jax.jit
    def go(s0, dts):
        s, saved = replay(model, mode, s0, dts, save_at=snap[1:])
        sd = jnp.concatenate([s0.sigma_dust[None], saved["sigma_dust"]])
        sg = jnp.concatenate([s0.sigma_gas[None], saved["sigma_gas"]])
        return s, sd, sg

    t0 = time.perf_counter()
    compiled = go.lower(s0, dts).compile()
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    s, sd, sg = jax.block_until_ready(compiled(s0, dts))
    wall = time.perf_counter() - t0
    return {"t": np.asarray(ref["t"]), "sigma_dust": np.asarray(sd), "sigma_gas": np.asarray(sg), "steps": snap,
            "wall": wall, "compile": t_compile, "status": [RESULT_NAMES[int(s.status)]] * snap.size,
            "split_error": np.zeros(snap.shape),
            "maxrss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def run_perturbed(setup, t_yr, eps=1e-15):
    """The round-off sensitivity of the parity run: one compiled parity solve run twice, from the initial state and
    from it with every populated dust bin multiplied by 1 +- eps (alternating signs). Returns (unperturbed,
    perturbed) dicts as :func:`run_jaxcoag`; comparing them with :func:`compare` shows how far two runs of the
    same discrete system part when only round-off separates them."""
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    from jaxcoag import disk

    model = disk.dustpy_default(**(dict(nr=30, m_max=1e2) if setup == "ci" else {}))
    p = model.initial()
    sd = p.sigma_dust
    sign = jnp.where(jnp.arange(sd.size).reshape(sd.shape) % 2 == 0, 1.0, -1.0)
    sd_p = jnp.where(sd > model.floor_dust(), sd * (1.0 + eps * sign), sd)
    t_out = np.asarray(t_yr) * YR

    @jax.jit
    def go(sd):
        return disk.solve(model, t_out, initial=disk.DiskProfile(p.sigma_gas, sd), throw=False)

    out = []
    for x in (sd, sd_p):
        t0 = time.perf_counter()
        res = jax.block_until_ready(go(x))
        out.append({"t": np.asarray(res.t), "sigma_dust": np.asarray(res.sigma_dust), "r": np.asarray(model.r),
                    "sigma_gas": np.asarray(res.sigma_gas), "steps": np.asarray(res.n_steps),
                    "wall": time.perf_counter() - t0})
    return out


def compare(ours, ref, area, a):
    """Differences of ours against DustPy at every snapshot (see the module docstring)."""
    rows = []
    for k in range(len(ref["t"])):
        sd_o, sd_r = ours["sigma_dust"][k], ref["sigma_dust"][k]
        md_o, md_r = np.sum(sd_o.sum(-1) * area), np.sum(sd_r.sum(-1) * area)
        sg_o, sg_r = ours["sigma_gas"][k], ref["sigma_gas"][k]
        tot_o, tot_r = sd_o.sum(-1), sd_r.sum(-1)
        sel = tot_r > 1e-12 * tot_r.max()
        sel[[0, -1]] = False
        ip_o, ip_r = np.argmax(sd_o, -1), np.argmax(sd_r, -1)
        w = area[1:-1]
        interior = np.zeros_like(sel)
        interior[1:-1] = True
        r_au = ref["r"] / 1.495978707e13
        rows.append({"t_yr": float(ref["t"][k] / YR),
                     "sigma_dust_worst_r_au": float(r_au[sel][np.argmax(np.abs(tot_o[sel] / tot_r[sel] - 1))]),
                     "sigma_gas_worst_r_au": float(r_au[1:-1][np.argmax(np.abs(sg_o[1:-1] / sg_r[1:-1] - 1))]),
                     # mass-weighted L1 differences over the interior cells: sum |d Sigma| A / sum Sigma A
                     "sigma_dust_l1_mass_weighted": float(np.sum(np.abs(tot_o - tot_r)[1:-1] * w)
                                                          / np.sum(tot_r[1:-1] * w)),
                     "sigma_gas_l1_mass_weighted": float(np.sum(np.abs(sg_o - sg_r)[1:-1] * w) / np.sum(sg_r[1:-1] * w)),
                     "sigma_gas_rel_max_dusty_cells": float(np.max(np.abs(sg_o[sel] / sg_r[sel] - 1))),
                     "dust_mass_rel": float(abs(md_o / md_r - 1)),
                     "gas_mass_rel": float(abs(np.sum(sg_o * area) / np.sum(sg_r * area) - 1)),
                     "sigma_gas_rel_max": float(np.max(np.abs(sg_o[1:-1] / sg_r[1:-1] - 1))),
                     "sigma_dust_rel_max": float(np.max(np.abs(tot_o[sel] / tot_r[sel] - 1))),
                     "a_peak_bins_max": int(np.max(np.abs(ip_o[1:-1] - ip_r[1:-1]))),
                     "a_peak_cm_dustpy_mid": float(a[ip_r[len(ip_r) // 2]])})
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--setup", choices=("ci", "default"), default="ci")
    ap.add_argument("--t-end-yr", type=float, default=None)
    ap.add_argument("--modes", default="parity,split", help="comma-separated: parity, split, replay (the parity "
                    "step driven by DustPy's own step sequence), perturbed (the parity run against itself from an "
                    "initial state perturbed by 1e-15)")
    ap.add_argument("--write-reference", action="store_true")
    ap.add_argument("--dustpy-cache", default=None, help="npz file: DustPy's snapshots are read from it when it "
                    "exists (DustPy is not run again) and written to it otherwise")
    args = ap.parse_args(argv)
    t_yr = snapshots_yr(args.setup, args.t_end_yr)
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from _common import machine_info

    cache = pathlib.Path(args.dustpy_cache) if args.dustpy_cache else None
    if cache is not None and cache.exists():
        ref = dict(np.load(cache))
        ref["wall"] = float(ref["wall"])
        if ref["t"].shape != t_yr.shape or not np.allclose(ref["t"], t_yr * YR, rtol=1e-9):
            raise SystemExit(f"{cache} holds other snapshots; delete it or pass another --dustpy-cache")
        print(f"DustPy's run read from {cache} (its wall time {ref['wall']:.1f} s from the run that wrote it)")
    else:
        print(f"DustPy, set-up {args.setup}, snapshots {t_yr} yr ...", flush=True)
        ref = run_dustpy(args.setup, t_yr)
        if cache is not None:
            np.savez_compressed(cache, **ref)
    print(f"  DustPy: {ref['steps'][-1]} steps, {ref['wall']:.2f} s", flush=True)
    if args.write_reference:
        if args.setup != "ci":
            raise SystemExit("--write-reference writes the ci set-up only")
        REF.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(REF, t=ref["t"], sigma_dust=ref["sigma_dust"], sigma_gas=ref["sigma_gas"],
                            steps=ref["steps"], step_t=ref["step_t"], r=ref["r"], ri=ref["ri"], m=ref["m"],
                            a=ref["a"])
        print(f"wrote {REF}")
    report = {"setup": args.setup, "t_yr": t_yr.tolist(), "machine": machine_info(),
              "dustpy": {"steps": ref["steps"].tolist(), "wall_s": ref["wall"],
                         "s_per_step": ref["wall"] / max(int(ref["steps"][-1]), 1)}, "jaxcoag": {}}
    print(f"{'mode':8s} {'compile s':>9s} {'run s':>8s} {'steps':>7s} {'DustPy/ours':>11s} {'dMdust':>9s} "
          f"{'dSigma_d':>9s} {'dSigma_g':>9s} {'a_peak bins':>11s}")
    for mode in [s for s in args.modes.split(",") if s]:
        if mode == "perturbed":
            base, pert = run_perturbed(args.setup, t_yr)
            rows = compare(pert, base, ref["area"], ref["a"])
            rows_dp = compare(base, ref, ref["area"], ref["a"])
            keys = ("dust_mass_rel", "sigma_dust_rel_max", "sigma_gas_rel_max", "a_peak_bins_max",
                    "sigma_gas_rel_max_dusty_cells")
            print(f"perturbed: the parity run from the initial dust x (1 +- 1e-15) against the same program's "
                  f"unperturbed run ({int(pert['steps'][-1])} and {int(base['steps'][-1])} steps; DustPy "
                  f"{int(ref['steps'][-1])}); columns: unperturbed vs DustPy / perturbed vs unperturbed")
            print(f"{'t_yr':>8s} " + " ".join(f"{k[:21]:>21s}" for k in keys))
            for rs, rd in zip(rows, rows_dp):
                print(f"{rs['t_yr']:8.0f} " + " ".join(f"{rd[k]:10.2e}/{rs[k]:10.2e}" for k in keys))
            report["jaxcoag"]["perturbed"] = {"eps": 1e-15, "steps": pert["steps"].tolist(),
                                              "steps_unperturbed": base["steps"].tolist(),
                                              "per_snapshot_vs_unperturbed": rows,
                                              "per_snapshot_unperturbed_vs_dustpy": rows_dp,
                                              "worst_vs_unperturbed": {k: max(r[k] for r in rows) for k in keys},
                                              "worst_unperturbed_vs_dustpy": {k: max(r[k] for r in rows_dp)
                                                                              for k in keys}}
            continue
        ours = run_replay(args.setup, ref) if mode == "replay" else run_jaxcoag(args.setup, t_yr, mode)
        rows = compare(ours, ref, ref["area"], ref["a"])
        worst = {k: max(r[k] for r in rows) for k in ("dust_mass_rel", "sigma_dust_rel_max", "sigma_gas_rel_max",
                                                        "a_peak_bins_max", "sigma_dust_l1_mass_weighted",
                                                        "sigma_gas_l1_mass_weighted", "sigma_gas_rel_max_dusty_cells")}
        ratio = ref["wall"] / ours["wall"]
        print(f"{mode:8s} {ours['compile']:9.2f} {ours['wall']:8.2f} {int(ours['steps'][-1]):7d} {ratio:11.3g} "
              f"{worst['dust_mass_rel']:9.2e} {worst['sigma_dust_rel_max']:9.2e} {worst['sigma_gas_rel_max']:9.2e} "
              f"{worst['a_peak_bins_max']:11d}")
        report["jaxcoag"][mode] = {"compile_s": ours["compile"], "wall_s": ours["wall"],
                                   "steps": ours["steps"].tolist(), "speed_ratio_dustpy_over_ours": ratio,
                                   "status": ours["status"], "split_error_max": float(np.max(ours["split_error"])),
                                   "maxrss_mib_process": ours["maxrss_mib"], "per_snapshot": rows, "worst": worst}
    modes = [s for s in args.modes.split(",") if s]
    tag = "" if modes == ["parity", "split"] else "_" + "_".join(modes)  # other modes do not overwrite the main file
    out = ROOT / "benchmarks" / "results" / f"dustpy_disk_{args.setup}{tag}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
