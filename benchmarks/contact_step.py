"""Wall time of one contact-DEM step (Wada et al. 2007 monomer aggregates), this checkout against another one.

The systems of ``contact_throughput.py`` (two ice BCCAs head-on at 5.7 v_0, dt = 0.014 t_c, skin 0.1 r1): 2-D
256 + 256 and 3-D 1024 + 1024 monomers. For each, ``dem.init_state`` and a jitted ``dem._n_steps_loop`` of a fixed
number of steps (inelastic clipping and event-time corrections on, the defaults) are timed after compilation, best
of ``--repeats``; the result is microseconds per step and monomer-steps per second. ``--baseline DIR`` times the
``jaxcoag`` of another checkout (e.g. ``git worktree add /tmp/wt_old <rev>``) on the same positions and velocities in
a subprocess of the same invocation and reports this/baseline ratios. Both use the private step loop so that the
layouts of different revisions are compared on identical work (no records, no stop checks); the public API's
throughput against LAMMPS is ``contact_throughput.py``.

Run: ``python benchmarks/contact_step.py [--baseline DIR] [--rounds 1] [--dims 2,3] [--steps-2d 1000]
[--steps-3d 200] [--repeats 2] [--out PATH]``; ``--rounds R`` alternates the two checkouts R times in fresh
processes and keeps each one's best (the load of a shared machine comes in bursts). Writes ``benchmarks/results/contact_step.json``.
References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007) ApJ 661, 320, §4 (set-up, dt = 0.014 t_c).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from benchmarks import _common as C  # noqa: E402

N_HALF = {2: 256, 3: 1024}


def _time_steps(npz: str, steps: int, repeats: int, root: str | None = None) -> dict:
    """Time ``steps`` DEM steps from the positions/velocities stored in ``npz`` with the ``jaxcoag`` of the checkout
    ``root`` (None: the one this script imports)."""
    if root is not None:
        assert "jaxcoag" not in sys.modules, "the baseline must be imported in a fresh process"
        sys.path.insert(0, str(pathlib.Path(root).resolve()))
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    import jaxcoag
    from jaxcoag.aggregates.contact import dem, materials

    d = np.load(npz)
    dim = int(d["dim"])
    mat = materials.ice(r1=1e-5, xi_crit=2e-8)
    n = d["x"].shape[0]
    st0 = dem.init_state(d["x"], d["v"], np.zeros((n, 3)), mat, dim=dim, skin=0.1)
    cfg = dem._Cfg(dim, True, False, True)
    dt = jnp.asarray(float(d["dt"]))
    f = jax.jit(lambda s: dem._n_steps_loop(s, mat, dt, jnp.asarray(0.1), cfg, steps))
    t0 = time.perf_counter()
    jax.block_until_ready(f(st0).x)
    first = time.perf_counter() - t0
    best = np.inf
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        st = f(st0)
        jax.block_until_ready(st.x)
        best = min(best, time.perf_counter() - t0)
    return dict(jaxcoag=str(pathlib.Path(jaxcoag.__file__).resolve().parents[1]), n=int(n), dim=dim, steps=steps,
                first_call_s=first, run_s=best, us_per_step=1e6 * best / steps,
                monomer_steps_per_s=n * steps / best, n_builds=int(st.n_builds), n_events=int(st.n_events),
                contacts_final=int(jnp.sum(st.active)))


def _revision(path):
    """git HEAD of the checkout at ``path`` (None if it is not a git work tree)."""
    r = subprocess.run(["git", "-C", str(path), "rev-parse", "HEAD"], capture_output=True, text=True)
    return r.stdout.strip() or None


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baseline", default=None, help="checkout directory of the revision to compare against")
    ap.add_argument("--dims", default="2,3")
    ap.add_argument("--steps-2d", type=int, default=1000)
    ap.add_argument("--steps-3d", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=1, help="with --baseline: alternate the two checkouts this many "
                    "times (fresh processes) and keep each one's best (bursts of load on a shared machine)")
    ap.add_argument("--out", default=None)
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--child-steps", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--child-root", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:  # subprocess of --baseline: time the jaxcoag on PYTHONPATH, print one JSON line
        print(json.dumps(_time_steps(a.child, a.child_steps, a.repeats, a.child_root)))
        return None
    if a.baseline and not (pathlib.Path(a.baseline) / "jaxcoag" / "__init__.py").exists():
        raise SystemExit(f"--baseline {a.baseline!r} is not a jaxcoag checkout (no jaxcoag/__init__.py there).")
    import jax

    jax.config.update("jax_enable_x64", True)
    from benchmarks.contact_throughput import DT_TC, V_IMP_V0, _pad3, make_system
    from jaxcoag.aggregates.contact import materials

    mat = materials.ice(r1=1e-5, xi_crit=2e-8)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for dim in (int(s) for s in a.dims.split(",")):
            x, v = make_system(N_HALF[dim], dim, mat, V_IMP_V0 * float(mat.v0))
            npz = os.path.join(tmp, f"sys{dim}.npz")
            np.savez(npz, x=_pad3(x), v=_pad3(v), dim=dim, dt=DT_TC * float(mat.t_c))
            steps = a.steps_2d if dim == 2 else a.steps_3d
            print(f"[{dim}-D {N_HALF[dim]}+{N_HALF[dim]}] {steps} steps ...", flush=True)
            row = dict(system=f"{dim}d {N_HALF[dim]}+{N_HALF[dim]}", ours=_time_steps(npz, steps, a.repeats))
            print(f"  this checkout: {row['ours']['us_per_step']:.1f} us/step", flush=True)
            if a.baseline:
                def child(root):
                    cmd = [sys.executable, __file__, "--child", npz, "--child-steps", str(steps), "--repeats",
                           str(a.repeats)] + (["--child-root", root] if root else [])
                    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
                    return json.loads(out.stdout.strip().splitlines()[-1])

                rounds = {"ours": [row["ours"]["us_per_step"]], "baseline": []}
                for r in range(a.rounds):
                    if r:  # later rounds: this checkout again, in a fresh process like the baseline's
                        o = child(None)
                        rounds["ours"].append(o["us_per_step"])
                        if o["us_per_step"] < row["ours"]["us_per_step"]:
                            row["ours"] = o
                    b = child(a.baseline)
                    rounds["baseline"].append(b["us_per_step"])
                    if "baseline" not in row or b["us_per_step"] < row["baseline"]["us_per_step"]:
                        row["baseline"] = b
                row["rounds_us_per_step"] = rounds
                row["speedup"] = row["baseline"]["us_per_step"] / row["ours"]["us_per_step"]
                print(f"  baseline ({row['baseline']['jaxcoag']}): {row['baseline']['us_per_step']:.1f} us/step; "
                      f"this checkout (best of {a.rounds} rounds) {row['ours']['us_per_step']:.1f} us/step; "
                      f"speed-up {row['speedup']:.2f}x (rounds: {rounds})", flush=True)
            rows.append(row)
    res = dict(description="wall time per contact-DEM step (jitted dem._n_steps_loop, ice BCCAs head-on at 5.7 v_0, "
                           "dt = 0.014 t_c), this checkout vs --baseline in the same invocation",
               baseline=a.baseline, baseline_revision=_revision(a.baseline) if a.baseline else None, results=rows,
               machine=C.machine_info())
    out = pathlib.Path(a.out) if a.out else C.RESULTS / "contact_step.json"
    C.write_json(out, res)
    print(f"wrote {out}")
    return res


if __name__ == "__main__":
    main()
