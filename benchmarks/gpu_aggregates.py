"""The aggregate engines on a GPU: Richardson's rigid box at 1e5 and 1e6 spheres (issue 15) and Wada's contact DEM
on 3-D 1024 + 1024 and 8192 + 8192 collisions with a vmapped speed sweep (issue 14).

Runs on whatever device JAX finds first (a GPU when one is there; the CPU otherwise, for a check of the script
at small sizes with ``--quick``). Every number is float64 and cgs / the box's units, as on the CPU.

(a) Rigid box, model (v) (R95 Table I: spheres of radius 0.033, rms speed v0 = 13, bouncing above the energy
    threshold) at the number density of model (v) (box side L = 10 (N / 9000)^(1/3)), as
    ``benchmarks/rigid_scaling.py`` does on the CPU: a first call to t_a = 100 / N (about 110 collisions;
    compile plus run) and a timed continuation over dt = ``--window`` / N with the compiled program. Reported:
    wall per unit simulated time, per loop step and per collision, steps, collisions, rebuilds, final status.
(b) Contact DEM: the head-on BCCA set-ups of ``benchmarks/contact_throughput.py`` (ice, r1 = 0.1 um, v_imp =
    5.7 v_0, dt = 0.014 t_c, skin 0.1 r1): monomer-steps per second of ``dem.integrate`` after compilation, and
    the number of steps the run to the outcome needs at least (``contact.collide``'s default end
    t_contact + 8 r_g,tot / v_imp) with the projected wall time to it; a vmapped sweep of 8 impact speeds of the
    2-D 256 + 256 collision against a Python loop of the same 8.

The JSON is written after each part (a run stopped at a time limit keeps what it finished).

The rigid sizes' wall per unit time is fitted as ~N^b (least squares on the logs, as rigid_scaling.py).

    python benchmarks/gpu_aggregates.py [--quick] [--rigid-sizes 10000,100000,1000000] [--out PATH]
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import traceback

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402

from benchmarks import _common as C  # noqa: E402
from benchmarks import contact_throughput as CT  # noqa: E402


def device_record():
    d = jax.devices()[0]
    return dict(backend=jax.default_backend(), device=str(getattr(d, "device_kind", d)), jax=jax.__version__,
                n_devices=len(jax.devices()))


def rigid_one(n0, window_collisions, seed=1):
    """Model (v) at N = n0: first call to t_a = 100 / n0, timed continuation over window_collisions / n0
    (``rigid_scaling.timed``)."""
    from benchmarks import rigid_scaling

    return rigid_scaling.timed(n0, seed, t_a=100.0 / n0, dt=window_collisions / n0)


def contact_one(n_half, dim, steps, material, v_imp):
    """Throughput of ``dem.integrate`` on the head-on BCCA pair, and the projected time to the outcome."""
    x, v = CT.make_system(n_half, dim, material, v_imp)
    r1 = float(np.asarray(material.r1))
    dt = CT.DT_TC * float(np.asarray(material.t_c))
    row = CT.run_ours(x, v, material, dim=dim, dt=dt, n_steps=steps)
    r_g0 = float(np.sqrt(np.mean(np.sum((x - x.mean(axis=0)) ** 2, axis=-1))))
    n_min = (CT.GAP * r1 / v_imp + 8.0 * r_g0 / v_imp) / dt
    row.update(system=f"{dim}d {n_half}+{n_half}", dim=dim, dt_s=dt, v_imp=v_imp, r_g0_r1=r_g0 / r1,
               n_steps_outcome_min=n_min, projected_outcome_s=n_min * row["run_s"] / steps)
    return row


def profile_rigid(n0, window_collisions, outdir, seed=1):
    """A ``jax.profiler`` trace (with a Perfetto JSON) of a model (v) window at N = n0, after a compiling call."""
    from jaxcoag.aggregates import rigid

    L = 10.0 * (n0 / 9000.0) ** (1.0 / 3.0)
    box = rigid.box_model("v", n0=n0, box=L, v0=13.0, key=jax.random.key(seed))
    r1 = rigid.run(box, jnp.array([100.0 / n0]))
    jax.block_until_ready(r1.outs)
    with jax.profiler.trace(os.path.join(outdir, "rigid"), create_perfetto_trace=True):
        r2 = rigid.run(r1, jnp.array([(100.0 + window_collisions) / n0]))
        jax.block_until_ready(r2.outs)
    return int(np.asarray(r2.outs["n_steps"])[-1]) - int(np.asarray(r1.outs["n_steps"])[-1])


def profile_contact(n_half, dim, steps, material, v_imp, outdir):
    """A ``jax.profiler`` trace of ``steps`` DEM steps of the head-on BCCA pair, after a compiling call."""
    from jaxcoag.aggregates.contact import dem

    x, v = CT.make_system(n_half, dim, material, v_imp)
    dt = CT.DT_TC * float(np.asarray(material.t_c))
    n = x.shape[0]
    st0 = dem.init_state(CT._pad3(x), CT._pad3(v), np.zeros((n, 3)), material, dim=dim, skin=CT.SKIN)
    st, _ = dem.integrate(st0, material, steps, dt=dt, skin=CT.SKIN, chunk=steps)
    jax.block_until_ready(st.x)
    with jax.profiler.trace(os.path.join(outdir, "contact"), create_perfetto_trace=True):
        st, _ = dem.integrate(st0, material, steps, dt=dt, skin=CT.SKIN, chunk=steps)
        jax.block_until_ready(st.x)
    return steps


def outcome(n_half, dim, v_imp_v0, material):
    """``contact.collide`` of two independent BCCAs to its default end (the outcome), timed; with the timing of a
    1000-step run of the same collide (``contact_throughput.run_collide``)."""
    v0 = float(np.asarray(material.v0))
    row = CT.run_collide(n_half, dim, material, v_imp_v0 * v0, n_steps=1000, full=True)
    row.update(system=f"{dim}d {n_half}+{n_half}", v_imp_v0=v_imp_v0)
    return row


def sweep(n_half, dim, steps, material, v0):
    speeds = np.linspace(3.0, 10.0, 8) * v0
    xs, vs = [], []
    for vi in speeds:
        xi, vv = CT.make_system(n_half, dim, material, vi)
        xs.append(xi)
        vs.append(vv)
    dt = CT.DT_TC * float(np.asarray(material.t_c))
    out = CT.run_sweep(xs, vs, material, dim=dim, dt=dt, n_steps=steps)
    out.update(system=f"{dim}d {n_half}+{n_half}", v_imp_v0=[float(s / v0) for s in speeds])
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (a check of the script on a CPU)")
    ap.add_argument("--rigid-sizes", default=None, help="comma-separated N (default 10000,100000,1000000)")
    ap.add_argument("--window", type=float, default=2000.0, help="timed rigid window, in collisions (~1.1 per "
                    "sphere and unit time): dt = window / N")
    ap.add_argument("--contact", default=None, help="comma list dim:n_half:steps (default 2:256:2000,"
                    "3:1024:1000,3:8192:1000)")
    ap.add_argument("--sweep-steps", type=int, default=None, help="steps per sweep member (default 500)")
    ap.add_argument("--parts", default="rigid,contact,sweep", help="which parts, in this order (also: profile, "
                    "traces of the largest rigid size's window and of the last contact system into --profile-dir; "
                    "outcome, --outcome's collision run to its outcome)")
    ap.add_argument("--outcome", default="3:8192:12.5", help="collision of the outcome part, dim:n_half:v_imp/v_0")
    ap.add_argument("--profile-dir", default="jax_profile", help="directory of the profile part's traces")
    ap.add_argument("--out", default=None, help="JSON path (default benchmarks/results/gpu_aggregates.json)")
    a = ap.parse_args(argv)
    from jaxcoag.aggregates.contact import materials

    q = a.quick
    sizes = [int(float(s)) for s in (a.rigid_sizes or ("1000,3000" if q else "10000,100000,1000000")).split(",")]
    contact = [tuple(int(v) for v in s.split(":")) for s in
               (a.contact or ("3:8:100,3:64:100" if q else "2:256:2000,3:1024:1000,3:8192:1000")).split(",")]
    sweep_steps = a.sweep_steps or (50 if q else 500)
    out = pathlib.Path(a.out or C.RESULTS / ("gpu_aggregates_quick.json" if q else "gpu_aggregates.json"))
    mat = materials.ice(r1=1e-5, xi_crit=2e-8)
    v0 = float(np.asarray(mat.v0))
    machine = C.machine_info()
    machine.pop("timing_note", None)  # the 2-core note of the CPU benchmarks
    rec = dict(benchmark="gpu_aggregates", quick=q, device=device_record(), machine=machine,
               note="wall-clock times on the device named in 'device' (machine: its host); compile time apart "
                    "(first_call_s includes it)", rigid=[], contact=[], sweep=None, errors=[])
    print("device:", rec["device"], flush=True)

    def save():
        C.write_json(out, rec)

    for part in a.parts.split(","):
        try:
            if part == "contact":
                for dim, nh, steps in contact:
                    row = contact_one(nh, dim, steps, mat, 5.7 * v0)
                    rec["contact"].append(row)
                    save()
                    print(f"contact {row['system']}: {row['monomer_steps_per_s']:.3e} monomer-steps/s "
                          f"({row['run_s']:.3f} s for {steps} steps; first call {row['first_call_s']:.1f} s), "
                          f"outcome >= {row['n_steps_outcome_min']:.3g} steps, projected "
                          f"{row['projected_outcome_s']:.1f} s, flags {row['flags']}", flush=True)
            elif part == "sweep":
                s = sweep(8 if q else 256, 2, sweep_steps, mat, v0)
                rec["sweep"] = s
                save()
                print(f"sweep {s['system']} x{s['members']}: loop {s['loop_s']:.3f} s, vmap {s['vmap_s']:.3f} s, "
                      f"speedup {s['speedup']:.2f}, max|dx| {s['max_abs_diff_x']:.2e} cm", flush=True)
            elif part == "rigid":
                for n0 in sizes:
                    row = rigid_one(n0, a.window)
                    rec["rigid"].append(row)
                    if len(rec["rigid"]) >= 2:
                        from benchmarks import rigid_scaling
                        b, e = rigid_scaling.fit(rec["rigid"])
                        rec["exponent_wall_per_time"] = dict(b=b, stderr=e)
                        rec["exponent_wall_per_step"] = dict(zip(("b", "stderr"),
                                                                 rigid_scaling.fit(rec["rigid"], "wall_per_step_ms")))
                    save()
                    print(f"rigid N={n0}: setup {row['setup_s']:.1f} s, first call {row['first_call_s']:.1f} s, "
                          f"window {row['window']:.3g}: {row['wall_s']:.2f} s, {row['steps']} steps "
                          f"({row['wall_per_step_ms']:.3f} ms/step), {row['collisions']} collisions, "
                          f"{row['rebuilds']} rebuilds, {row['wall_per_time']:.4g} s per unit time, "
                          f"{row['status']}", flush=True)
            elif part == "outcome":
                dim, nh, vv = a.outcome.split(":")
                row = outcome(int(nh), int(dim), float(vv), mat)
                rec["outcome"] = row
                save()
                print(f"outcome {row['system']} at {vv} v0: {row['outcome_s']:.1f} s, {row['outcome_steps']} steps, "
                      f"clusters {row['outcome_cluster_sizes']}, r_g {row['outcome_r_g_r1']:.2f} r1, n_con "
                      f"{row['outcome_n_contacts']:.3f}, {row['outcome_status']}", flush=True)
            elif part == "profile":
                nr = profile_rigid(max(sizes), min(a.window, 200.0), a.profile_dir)
                dim, nh, _ = contact[-1]
                nc = profile_contact(nh, dim, 200, mat, 5.7 * v0, a.profile_dir)
                rec["profile"] = dict(dir=a.profile_dir, rigid_n0=max(sizes), rigid_steps=nr,
                                      contact=f"{dim}d {nh}+{nh}", contact_steps=nc)
                save()
                print(f"profile: traces in {a.profile_dir} (rigid {nr} steps, contact {nc} steps)", flush=True)
            else:
                raise SystemExit(f"--parts: unknown part {part!r} (contact, sweep, rigid)")
        except Exception as e:  # keep the other parts' numbers; the error goes into the JSON
            rec["errors"].append(dict(part=part, error=repr(e), traceback=traceback.format_exc()))
            save()
            print(f"{part}: FAILED {e!r}", flush=True)
            traceback.print_exc()
    if "exponent_wall_per_time" in rec:
        print("rigid wall per unit time ~ N^{b:.3f} +- {stderr:.3f}".format(**rec["exponent_wall_per_time"]))
    print("wrote", out, flush=True)
    return 1 if rec["errors"] else 0


if __name__ == "__main__":
    sys.exit(main())
