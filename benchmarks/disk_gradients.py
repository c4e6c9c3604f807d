"""Gradients of 1e5-yr radial-disk outcomes, forward and reverse mode, against finite differences.

Model: DustPy's default disk (``jaxcoag.disk.dustpy_default``; Stammler & Birnstiel 2022 §3) on the benchmark's
``ci`` grid (Nr = 30, m_max = 1e2 g; ``--setup default``: Nr = 100, Nm = 120), parity mode (``--mode split``:
the Strang-split step), evolved to ``--t-end-yr`` (default 1e5 yr).

Outcomes y (at t_end): the dust mass left in the disk [M_earth] (interior cells), the dust mass of the ring
10-30 au [M_earth], and ln a_mean at the cell nearest 10 au (mass-weighted geometric mean particle radius,
``DiskResult.a_mean``; ln cm). Parameters x = ln(alpha, v_frag, M_disk, r_c).

* ``forward``: ``jax.jacfwd`` through ``disk.solve`` (``lax.while_loop``, adaptive steps);
* ``reverse``: ``jax.jacrev`` through ``disk.solve(loop="scan")`` (``max_steps`` = the base run's step count
  + 8 guarded steps, each checkpointed);
* ``fd``: central differences with step h in x of the same outcomes computed by replaying the base run's own step
  sequence (``disk.solve(..., record_steps=K)`` records it; ``jaxcoag.disk.solve.replay`` takes those steps). The
  step-size rule (DustPy's: a minimum over cells and bins) is not differentiated, so the derivative is that of the
  map with the steps held fixed; differences of free-running solves would also see the perturbed runs choose
  other steps.

The replay at the base point is checked against the adaptive solve (``pinned_outcome_rel_diff``: round-off of two
compilations of the same steps). Reported: the three Jacobians, the largest relative differences
forward vs fd and reverse vs forward, wall times (compile apart), and XLA's memory analysis of the compiled
forward and reverse programs (temporary buffers: the peak working memory beyond inputs and outputs).

    python benchmarks/disk_gradients.py [--setup ci|default] [--mode parity|split] [--t-end-yr 1e5] [--h 1e-5]
    python benchmarks/disk_gradients.py --t-end-yr 1e5 --directional    # one direction: a quarter of the cost
    python benchmarks/disk_gradients.py --setup default --memory-only 4000   # compile only: peak working memory

Writes ``benchmarks/results/disk_gradients_<setup>_<mode>.json``.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import resource
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np

from benchmarks import _common as C
from jaxcoag import disk
from jaxcoag.disk.solve import replay

K = disk.gas.DUSTPY_CONSTANTS
M_EARTH = 5.9722e27  # g
NAMES = ("alpha", "v_frag", "M_disk", "r_c")
OUTCOMES = ("M_dust [M_earth]", "M_ring 10-30 au [M_earth]", "ln a_mean(10 au) [ln cm]")


def build(setup, x):
    grid = dict(nr=30, m_max=1e2) if setup == "ci" else {}
    a, vf, md, rc = jnp.exp(x)
    return disk.dustpy_default(**grid, alpha=a, v_frag=vf, m_disk=md, r_c=rc)


def timed(timings, name, fn, *a):
    """Compile fn ahead of time, run it once; record compile and run wall times [s] and XLA's temporaries [MiB]."""
    t0 = time.perf_counter()
    c = jax.jit(fn).lower(*a).compile()
    timings[name + "_compile_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    out = jax.block_until_ready(c(*a))
    timings[name + "_s"] = time.perf_counter() - t0
    mem = c.memory_analysis()
    if mem is not None:
        timings[name + "_temp_mib"] = mem.temp_size_in_bytes / 2**20
    return out


def cells(model):
    """Concrete cell selections of a model's grid (which does not depend on x): interior, the 10-30 au ring, and
    the index of the cell nearest 10 au."""
    r_au = np.asarray(model.r) / K["au"]
    interior = np.zeros(r_au.shape, bool)
    interior[1:-1] = True
    return interior, interior & (r_au >= 10.0) & (r_au <= 30.0), int(np.argmin(np.abs(r_au - 10.0)))


def outcomes(model, sigma_dust, sel):
    """(3,) outcomes of a (nr, nm) Sigma_d [g cm^-2] (see the module docstring); ``sel`` from :func:`cells`."""
    interior, ring, i10 = sel
    tot = sigma_dust.sum(-1)
    lna = jnp.sum(sigma_dust[i10] * jnp.log(model.particle_size())) / jnp.sum(sigma_dust[i10])
    return jnp.stack([jnp.sum(jnp.where(interior, tot * model.area, 0.0)) / M_EARTH,
                      jnp.sum(jnp.where(ring, tot * model.area, 0.0)) / M_EARTH, lna])


def memory_only(args, mode, t_out, x0, sel):
    """Compile (do not run) the forward solve and the reverse-mode gradient of the dust mass; report XLA's memory
    analysis (bytes of arguments, outputs and temporaries: the temporaries are the working memory beyond them)."""
    def fwd(x):
        m = build(args.setup, x)
        return outcomes(m, disk.solve(m, t_out, mode=mode, throw=False).sigma_dust[-1], sel)[0]

    def rev(x):
        m = build(args.setup, x)
        res = disk.solve(m, t_out, mode=mode, loop="scan", max_steps=args.memory_only, throw=False)
        return outcomes(m, res.sigma_dust[-1], sel)[0]

    report = {"setup": args.setup, "mode": args.mode, "t_end_yr": args.t_end_yr, "scan_steps": args.memory_only,
              "machine": C.machine_info()}
    for name, fn in (("forward", fwd), ("reverse_grad", jax.grad(rev))):
        t0 = time.perf_counter()
        mem = jax.jit(fn).lower(x0).compile().memory_analysis()
        report[name] = {"compile_s": time.perf_counter() - t0,
                        **{k: getattr(mem, k + "_in_bytes") / 2**20 for k in ("argument_size", "output_size",
                                                                              "temp_size", "generated_code_size")}}
        print(f"{name:13s} compile {report[name]['compile_s']:.1f} s, temporaries {report[name]['temp_size']:.1f} MiB "
              f"(arguments {report[name]['argument_size']:.3f}, outputs {report[name]['output_size']:.3f} MiB)",
              flush=True)
    out = ROOT / "benchmarks" / "results" / f"disk_gradients_memory_{args.setup}_{args.mode}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=1))
    print(f"wrote {out}")
    return report


def directional(args, forward, pinned, x0, y0, n, dts0, t_out, mode, sel, timings):
    """The cheaper check (``--directional``): one direction d through all four ln-parameters. Forward: one
    ``jax.jvp`` (J d, three outcomes); reverse: one ``jax.grad`` of the weighted sum c . y (c = 1/y for the masses,
    1 for ln a_mean), dotted with d; finite differences: two replays of the jvp's own primal steps along d."""
    d = jnp.array([0.3, -0.5, 0.7, 0.4])
    y0 = np.asarray(y0)
    c = jnp.array([1.0 / y0[0], 1.0 / y0[1], 1.0])

    def reverse_c(x):
        m = build(args.setup, x)
        res = disk.solve(m, t_out, mode=mode, loop="scan", max_steps=n + 8, throw=False)
        return jnp.dot(c, outcomes(m, res.sigma_dust[-1], sel))

    def jvp(x):
        (y, _, dts), (ty, _, _) = jax.jvp(lambda z: forward(z, args.record), (x,), (d,))
        return ty, dts

    jv, dts = timed(timings, "jvp", jvp, x0)
    jv = np.asarray(jv)
    dts, seq = steps_used(dts, dts0, args.record)
    print(f"jvp {timings['jvp_s']:.1f} s; its primal steps against the base run's: {seq}", flush=True)
    g = np.asarray(timed(timings, "grad", jax.grad(reverse_c), x0))
    print(f"grad {timings['grad_s']:.1f} s", flush=True)
    pin = jax.jit(pinned).lower(x0, dts).compile()
    t0 = time.perf_counter()
    fd = (np.asarray(pin(x0 + args.h * d, dts)) - np.asarray(pin(x0 - args.h * d, dts))) / (2 * args.h)
    timings["fd_2_runs_s"] = time.perf_counter() - t0
    y_pin = np.asarray(pin(x0, dts))
    rel_fwd_fd = np.abs(jv - fd) / np.abs(fd)
    rev_dir, fwd_dir = float(g @ np.asarray(d)), float(np.asarray(c) @ jv)
    rel_rev_fwd = abs(rev_dir - fwd_dir) / abs(fwd_dir)
    print(f"outcomes at {args.t_end_yr:g} yr: " + ", ".join(f"{o} = {v:.6g}" for o, v in zip(OUTCOMES, y0))
          + f" (replay of the steps differs by {np.max(np.abs(y_pin / y0 - 1)):.1e})")
    for i, o in enumerate(OUTCOMES):
        print(f"d {o:28s} / d ln x . d: forward {jv[i]:.8e}  fd {fd[i]:.8e}  rel. difference {rel_fwd_fd[i]:.1e}")
    print(f"c . J d: reverse {rev_dir:.10e}  forward {fwd_dir:.10e}  rel. difference {rel_rev_fwd:.1e}; reverse "
          f"gradient of c . y: {g.tolist()}")
    print("  ".join(f"{k} {v:.1f}" for k, v in timings.items()))
    report = {"setup": args.setup, "mode": args.mode, "t_end_yr": args.t_end_yr, "h": args.h, "steps": n,
              "direction_ln_params": np.asarray(d).tolist(), "parameters": [f"ln {p}" for p in NAMES],
              "outcomes": list(OUTCOMES), "y": y0.tolist(), "jvp": jv.tolist(), "fd_replayed_steps": fd.tolist(),
              "rel_forward_vs_fd": rel_fwd_fd.tolist(), "weights_c": np.asarray(c).tolist(),
              "grad_reverse_c_dot_y": g.tolist(), "rel_reverse_vs_forward": rel_rev_fwd,
              "jvp_steps_vs_base_run": seq, "replay_outcome_rel_diff": float(np.max(np.abs(y_pin / y0 - 1))),
              "timings": timings, "maxrss_mib_process": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
              "machine": C.machine_info()}
    out = ROOT / "benchmarks" / "results" / f"disk_gradients_{args.setup}_{args.mode}_directional.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=1))
    print(f"wrote {out}")
    return report


def steps_used(dts, dts0, capacity):
    """The steps a run recorded (its finite entries) and how they compare with the base run's ``dts0``: (steps,
    dict of the counts and the largest relative step difference)."""
    dts = np.asarray(dts)
    k = int(np.sum(np.isfinite(dts)))
    if k >= capacity:
        raise SystemExit(f"the run filled the step record (--record {capacity}): rerun with a larger --record")
    dts = dts[:k]
    m = min(k, dts0.size)
    return dts, {"steps": k, "base_steps": int(dts0.size), "identical_steps": int(np.sum(dts[:m] == dts0[:m])),
                 "max_rel_step_difference": float(np.max(np.abs(dts[:m] / dts0[:m] - 1.0))) if m else 0.0}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--setup", choices=("ci", "default"), default="ci")
    ap.add_argument("--mode", choices=("parity", "split"), default="parity")
    ap.add_argument("--t-end-yr", type=float, default=1e5)
    # h = 1e-4 and wider see the map's kinks (floors): on the ci grid at 1e5 yr the ring mass's difference quotient
    # sat 1.5e-5 from the derivative for h = 1e-4 ... 4e-4 and 7e-9 from it at h = 1e-5 (3e-9 at 1e-6)
    ap.add_argument("--h", type=float, default=1e-5, help="finite-difference step in the log parameters")
    ap.add_argument("--memory-only", type=int, default=None, metavar="N_STEPS",
                    help="compile only (nothing runs): XLA's memory analysis of the forward solve and of the "
                         "reverse-mode gradient of the dust mass (jax.grad, loop='scan' with N_STEPS guarded steps)")
    ap.add_argument("--record", type=int, default=1 << 15, metavar="K",
                    help="capacity of the recorded step sequence (the base run must take at most K steps)")
    ap.add_argument("--directional", action="store_true",
                    help="one direction through the four parameters instead of the full Jacobians (one jvp, one "
                         "reverse gradient, two finite-difference runs)")
    args = ap.parse_args(argv)
    mode = disk.Parity() if args.mode == "parity" else disk.Split()
    t_end = args.t_end_yr * K["year"]
    t_out = jnp.array([0.0, t_end])
    x0 = jnp.log(jnp.array([1e-3, 100.0, 0.05 * K["M_sun"], 60.0 * K["au"]]))  # DustPy's defaults
    timings = {}
    sel = cells(build(args.setup, x0))
    if args.memory_only is not None:
        return memory_only(args, mode, t_out, x0, sel)

    def forward(x, record=0):
        m = build(args.setup, x)
        res = disk.solve(m, t_out, mode=mode, throw=False, record_steps=record)
        return outcomes(m, res.sigma_dust[-1], sel), res.n_steps[-1], res.step_sizes

    y0, n_steps, dts0 = timed(timings, "forward", lambda x: forward(x, args.record), x0)
    n = int(n_steps)
    print(f"{args.setup} grid, {args.mode} mode, {args.t_end_yr:g} yr: {n} steps, forward {timings['forward_s']:.1f} s "
          f"(compile {timings['forward_compile_s']:.1f} s)", flush=True)
    dts0, _ = steps_used(dts0, np.zeros(0), args.record)

    def pinned(x, dts):
        m = build(args.setup, x)
        s0 = disk.solve(m, jnp.array([0.0]), mode=mode).final_state
        return outcomes(m, replay(m, mode, s0, dts)[0].sigma_dust, sel)

    if args.directional:
        return directional(args, forward, pinned, x0, y0, n, dts0, t_out, mode, sel, timings)
    def y_and_steps(x):
        y, _, dts = forward(x, args.record)
        return y, dts

    # the Jacobian and the steps of its own primal run (the finite differences replay those)
    J_fwd, dts = timed(timings, "jacfwd", jax.jacfwd(y_and_steps, has_aux=True), x0)
    dts, seq = steps_used(dts, dts0, args.record)
    print(f"jacfwd {timings['jacfwd_s']:.1f} s; its primal steps against the base run's: {seq}", flush=True)

    def reverse_y(x):
        m = build(args.setup, x)
        res = disk.solve(m, t_out, mode=mode, loop="scan", max_steps=n + 8, throw=False)
        return outcomes(m, res.sigma_dust[-1], sel)

    J_rev = timed(timings, "jacrev", jax.jacrev(reverse_y), x0)
    pin = jax.jit(pinned).lower(x0, dts).compile()
    t0 = time.perf_counter()
    J_fd = np.zeros((3, 4))
    for k in range(4):
        e = jnp.zeros(4).at[k].set(args.h)
        J_fd[:, k] = (np.asarray(pin(x0 + e, dts)) - np.asarray(pin(x0 - e, dts))) / (2 * args.h)
    timings["fd_8_runs_s"] = time.perf_counter() - t0
    y_pin = np.asarray(pin(x0, dts))

    J_fwd, J_rev = np.asarray(J_fwd), np.asarray(J_rev)
    scale = np.maximum(np.abs(J_fd), 1e-6 * np.max(np.abs(J_fd), axis=1, keepdims=True))
    rel_fwd_fd = np.abs(J_fwd - J_fd) / scale
    rel_rev_fwd = np.abs(J_rev - J_fwd) / scale
    print(f"outcomes at {args.t_end_yr:g} yr: " + ", ".join(f"{o} = {v:.6g}" for o, v in zip(OUTCOMES, np.asarray(y0)))
          + f" (replay of the steps differs by {np.max(np.abs(y_pin / np.asarray(y0) - 1)):.1e})")
    print(f"{'d y / d ln x':28s} " + " ".join(f"{p:>26s}" for p in NAMES))
    for i, o in enumerate(OUTCOMES):
        print(f"{o:28s} " + " ".join(f"{J_fwd[i, k]:12.5e} ({rel_fwd_fd[i, k]:.0e},{rel_rev_fwd[i, k]:.0e})"
                                     for k in range(4)))
    print("(in brackets: |forward - fd| / |fd| and |reverse - forward| / |fd|)")
    print(f"max rel. difference forward vs fd {rel_fwd_fd.max():.2e}, reverse vs forward {rel_rev_fwd.max():.2e}")
    print("  ".join(f"{k} {v:.1f}" for k, v in timings.items()))
    report = {"setup": args.setup, "mode": args.mode, "t_end_yr": args.t_end_yr, "h": args.h, "steps": n,
              "parameters": [f"ln {p}" for p in NAMES], "outcomes": list(OUTCOMES), "y": np.asarray(y0).tolist(),
              "jac_forward": J_fwd.tolist(), "jac_reverse": J_rev.tolist(), "jac_fd_replayed_steps": J_fd.tolist(),
              "max_rel_forward_vs_fd": float(rel_fwd_fd.max()), "max_rel_reverse_vs_forward": float(rel_rev_fwd.max()),
              "jacfwd_steps_vs_base_run": seq, "replay_outcome_rel_diff": float(np.max(np.abs(y_pin / np.asarray(y0) - 1))),
              "timings": timings,
              "maxrss_mib_process": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
              "machine": C.machine_info()}
    out = ROOT / "benchmarks" / "results" / f"disk_gradients_{args.setup}_{args.mode}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
