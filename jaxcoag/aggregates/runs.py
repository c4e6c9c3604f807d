"""``jaxcoag run`` for the particle-level engines: ``[run] engine = "contact"`` and ``"rigid"``.

The same job as the coagulation engines (:func:`jaxcoag.runner.run`): validate the configuration,
refuse unwritable outputs before any work, evolve with :func:`jaxcoag.evolve` segment by segment
with an atomic checkpoint after each segment (Ctrl-C saves and resumes bit for bit), write the
result's ``to_xarray()`` dataset as netCDF (atomically), a standard figure next to it, and print a
summary.

* contact: two BCCA aggregates of ``[contact] n`` monomers (independent realisations from
  ``seed``) collide head-on (Wada et al. 2007 §4) with the DEM engine
  (:class:`jaxcoag.aggregates.contact.DEM`); the run length is ``[contact] t_end`` or the default end of
  :func:`jaxcoag.aggregates.contact.collide` without its quiet-time extension (contact + 8 r_g / v_imp).
  Figure: the energy budget over time (Wada Fig. 6) and the final monomers coloured by cluster.
* rigid: a periodic box of Richardson (1995) Table I (:func:`jaxcoag.aggregates.rigid.box_model`),
  outputs evenly spaced to ``[rigid] t_end``. Figure: N(t) against the constant-kernel solution
  (Richardson 1995 eq. 30), the cumulative collisions and the largest mass.

References: Wada et al. (2007, ApJ 661, 320) §4, Fig. 6; Richardson (1995, Icarus 115, 320) §3, eq. 30.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np


__all__ = ["run_particles", "quick_particles"]


def quick_particles(cfg):
    """A smaller, faster version of a contact or rigid config (``--quick``): contact 16 + 16 monomers at
    dt = 0.112 t_c and at most 50 records; rigid at most 200 spheres and 8 outputs (physics unchanged)."""
    from .. import config as cfgmod

    raw = cfg.raw()
    if cfg.engine == "contact":
        c = raw.setdefault("contact", {})
        c["n"] = min(int(cfg["contact"]["n"]), 16)
        c["dt_tc"] = max(float(cfg["contact"]["dt_tc"]), 0.112)
        c["n_records"] = min(int(cfg["contact"]["n_records"]), 50)
    else:
        r = raw.setdefault("rigid", {})
        r["n0"] = min(int(cfg["rigid"]["n0"]), 200)
        r["n_out"] = min(int(cfg["rigid"]["n_out"]), 8)
    return cfgmod.from_dict(raw, source=cfg.source + " (quick)")


def _save(fig, path):
    """Write a figure atomically (temporary file, then rename) and close it."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    tmp = path + ".tmp.png"
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    os.replace(tmp, path)
    return path


# ------------------------------------------------------------------------------------------ contact
def contact_material(c: dict):
    """The contact Material of a [contact] section (the named material with the given overrides)."""
    from .contact import materials

    base = (materials.ice if c["material"] == "ice" else materials.quartz)(r1=c["r1"], xi_crit=c["xi_crit"])
    over = {k: c[k] for k in ("gamma", "E", "nu", "rho") if c.get(k) is not None}
    if not over:
        return base
    kw = {k: float(getattr(base, k)) for k in ("gamma", "E", "nu", "rho")}
    kw.update(over)
    G = None if "E" in over or "nu" in over else float(base.G)
    return materials.material(kw["gamma"], kw["E"], kw["nu"], kw["rho"], r1=c["r1"], xi_crit=c["xi_crit"], G=G)


def _contact_setup(cfg):
    import jax

    from .contact import DEM, Collision, bcca
    from .contact import collision as coll_mod

    c = cfg["contact"]
    mat = contact_material(c)
    ka, kb = jax.random.split(jax.random.key(int(c["seed"])))
    a = bcca(int(c["n"]), ka, dim=int(c["dim"]), material=mat)
    b = bcca(int(c["n"]), kb, dim=int(c["dim"]), material=mat)
    v = float(c["v_imp"]) if c["v_imp"] is not None else float(c["v_imp_v0"]) * float(mat.v0)
    coll = Collision(a, b, v, float(c["impact_parameter"]))
    t_c = float(mat.t_c)
    engine = DEM(dt=float(c["dt_tc"]) * t_c)
    engine._check(mat, coll, None, 0.0, None, None)
    if c["t_end"] is not None:
        t_end = float(c["t_end"])
    else:  # collide's default end: the gap closed + 8 r_g,tot / v_imp
        _, _, r_g0 = coll_mod._place(coll, mat.r1)
        t_end = (0.05 * float(mat.r1) + 8.0 * float(r_g0)) / v
    dt = float(c["dt_tc"]) * t_c
    n_steps = max(1, int(math.ceil(t_end / dt)))
    n_rec = min(int(c["n_records"]), n_steps)
    steps = np.unique(np.round(np.linspace(0, n_steps, n_rec + 1)[1:]).astype(np.int64))
    t_out = steps * dt
    return dict(material=mat, engine=engine, initial=coll, t_out=t_out, v_imp=v, n_total=2 * int(c["n"]))


def _contact_summary(res, setup):

    mat = setup["material"]
    n_tot = setup["n_total"]
    n_k = n_tot - 2
    E_imp = float(res.E_imp)
    E_tot = np.asarray(res.E_total)
    sizes = np.asarray(res.cluster_sizes)
    sizes = sizes[sizes > 0]
    return dict(
        v_imp_cm_s=setup["v_imp"], v_imp_v0=setup["v_imp"] / float(mat.v0), E_imp_erg=E_imp,
        x_roll=E_imp / (n_k * float(mat.E_roll)), x_break=E_imp / (n_k * float(mat.E_break)),
        N_large=int(sizes[0]), N_total=n_tot, n_clusters=int(sizes.size), r_g_over_r1=float(res.r_g) / float(mat.r1),
        n_con=float(res.n_contacts), steps=int(res.n_steps),
        energy_error=float(np.max(np.abs(E_tot - E_tot[0]))) / E_imp)


def _contact_figure(ds, res, setup, path, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mat = setup["material"]
    unit = float(mat.F_c) * float(mat.delta_c)
    t = np.asarray(res.t) / float(mat.t_c)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.8))
    for name, lab, ls in (("E_kin", "kinetic", "-"), ("U", "potential U", "-"), ("E_dis_n", "dissipated: normal", "--"),
                          ("E_dis_s", "sliding", "--"), ("E_dis_r", "rolling", "--"), ("E_dis_t", "twisting", "--"),
                          ("E_total", "total", ":")):
        ax1.plot(t, np.asarray(getattr(res, name)) / unit, ls, label=lab)
    ax1.set_xlabel("t / t_c")
    ax1.set_ylabel("energy / (F_c delta_c)")
    ax1.set_title("energy budget (Wada et al. 2007 Fig. 6)")
    ax1.legend(fontsize=8)
    x = np.asarray(res.positions) / float(mat.r1)
    lab = np.asarray(res.labels)
    r = 1.0
    for i in range(x.shape[0]):
        ax2.add_patch(plt.Circle((x[i, 0], x[i, 1]), r, color=plt.cm.tab10(int(lab[i]) % 10), alpha=0.8, lw=0))
    pad = 2.0
    ax2.set_xlim(x[:, 0].min() - pad, x[:, 0].max() + pad)
    ax2.set_ylim(x[:, 1].min() - pad, x[:, 1].max() + pad)
    ax2.set_aspect("equal")
    ax2.set_xlabel("x / r1")
    ax2.set_ylabel("y / r1")
    ax2.set_title("final monomers by cluster (x-y projection)")
    fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def _format_contact(n, status, wall_s):
    return "\n".join([
        f"jaxcoag run (contact): {n['N_total']} monomers at v_imp = {n['v_imp_v0']:.3g} v0 = {n['v_imp_cm_s']:.4g} cm/s, "
        f"E_imp = {n['x_roll']:.3g} n_k E_roll = {n['x_break']:.3g} n_k E_break",
        f"  outcome: largest cluster {n['N_large']} of {n['N_total']} ({n['n_clusters']} clusters), "
        f"r_g = {n['r_g_over_r1']:.4g} r1, n_con = {n['n_con']:.4g}",
        f"  {n['steps']} steps, energy budget closed to {n['energy_error']:.2e} E_imp (max drift of the total), status {status}, "
        f"{wall_s:.1f} s"])


# ------------------------------------------------------------------------------------------ rigid
def _rigid_setup(cfg):
    import jax

    from .rigid import box as boxmod

    r = cfg["rigid"]
    box = boxmod.box_model(r["model"], n0=int(r["n0"]), r0=float(r["r0"]), box=float(r["box"]), v0=float(r["v0"]),
                           key=jax.random.key(int(r["seed"])))
    t_out = np.linspace(0.0, float(r["t_end"]), int(r["n_out"]) + 1)[1:]
    return dict(box=box, engine=boxmod.RigidBox(), initial=box, t_out=t_out)


def _rigid_summary(res, setup):
    box = setup["box"]
    n_agg = np.asarray(res.n_aggregates)
    n0 = int(np.asarray(box.n0)) if hasattr(box, "n0") else int(n_agg[0])
    t = np.asarray(res.t)
    alpha = float(box.alpha)
    n_th = n0 / (1.0 + 0.5 * alpha * n0 * t[-1])
    nc = np.asarray(res.n_collisions)
    return dict(model=res.model, n0=n0, t_end=float(t[-1]), N=int(n_agg[-1]), N_R30=n_th,
                tau=0.5 * alpha * n0 * float(t[-1]), N_C=int(nc[-1, 0]), N_C1=int(nc[-1, 1]),
                max_mass=float(np.asarray(res.max_mass)[-1]))


def _rigid_figure(res, setup, path, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    box = setup["box"]
    t = np.asarray(res.t)
    n_agg = np.asarray(res.n_aggregates)
    n0 = float(np.asarray(box.n0))
    alpha = float(box.alpha)
    tt = np.linspace(0.0, t[-1], 200)
    nc = np.asarray(res.n_collisions)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    ax1.plot(t, n_agg, "o-", ms=3, label="N(t), this run")
    ax1.plot(tt, n0 / (1 + 0.5 * alpha * n0 * tt), "k-", label="constant kernel (R95 eq. 30)")
    ax1.plot(t, nc[:, 0], ":", label="N_C")
    ax1.plot(t, nc[:, 1], "--", label="N_C1")
    ax1.set_xlabel("t")
    ax1.set_ylabel("number")
    ax1.legend(fontsize=8)
    ax2.plot(t, np.asarray(res.max_mass), "o-", ms=3)
    ax2.set_xlabel("t")
    ax2.set_ylabel("largest mass / m0")
    fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def _format_rigid(n, status, wall_s):
    return (f"jaxcoag run (rigid, Richardson 1995 model ({n['model']})): N(t = {n['t_end']:.4g}) = {n['N']} of "
            f"{n['n0']} (constant kernel eq. 30: {n['N_R30']:.1f}, tau = {n['tau']:.3g}); N_C = {n['N_C']}, "
            f"N_C1 = {n['N_C1']}, largest mass {n['max_mass']:.0f} m0; status {status}, {wall_s:.1f} s")


# ------------------------------------------------------------------------------------------ driver
def run_particles(cfg, *, out, checkpoint, resume, progress, figure, max_segments, verbose, save, t_start):
    """Run a contact or rigid configuration (called by :func:`jaxcoag.runner.run`, which checked the
    output locations). Returns a :class:`jaxcoag.runner.RunResult`."""
    from .._status import FAILURES, RESULT_NAMES, result_code
    from ..io import save_netcdf
    from ..runner import RunResult, _makedirs_for, evolve_saved, figure_path

    setup = _contact_setup(cfg) if cfg.engine == "contact" else _rigid_setup(cfg)
    kernel = setup["material"] if cfg.engine == "contact" else None
    t_out = setup["t_out"]
    n_rec = len(t_out)
    every = max(1, n_rec // 20)  # about 20 checkpoint segments
    result, resumed_from = evolve_saved(kernel, setup["engine"], setup["initial"], t_out, checkpoint=checkpoint,
                                        every=every, resume=resume, progress=progress, max_segments=max_segments,
                                        save=save)
    if not save:
        checkpoint = None
    rname = RESULT_NAMES[int(np.asarray(result_code(result.status)))]
    failed = rname in FAILURES
    finished = int(np.shape(result.t)[0]) == n_rec and not failed
    attrs = {"run_name": cfg["run"]["name"], "run_description": cfg["run"]["description"], "config_source": cfg.source,
             "config_toml": cfg.to_toml(), "physics_hash": cfg.physics_hash()}
    ds = result.to_xarray(attrs=attrs)
    if cfg.engine == "contact":
        numbers = _contact_summary(result, setup)
        text = _format_contact(numbers, rname, time.perf_counter() - t_start)
    else:
        numbers = _rigid_summary(result, setup)
        text = _format_rigid(numbers, rname, time.perf_counter() - t_start)
    numbers["result"] = rname
    for k, v in numbers.items():
        if isinstance(v, (int, float, str)):
            ds.attrs[f"summary_{k}"] = v
    path = fig = None
    if save and (finished or failed):
        ds.attrs["wall_s"] = time.perf_counter() - t_start
        _makedirs_for(out)
        path = save_netcdf(ds, out)
        if figure:
            fig = figure_path(out)
            title = f"{cfg['run']['name']} ({cfg.engine})"
            if cfg.engine == "contact":
                _contact_figure(ds, result, setup, fig, title)
            else:
                _rigid_figure(result, setup, fig, title)
    res = RunResult(result=result, dataset=ds, built=setup, path=path, figure=fig, checkpoint=checkpoint,
                    finished=finished, failed=failed, resumed_from=resumed_from, rows=[], numbers=numbers,
                    wall_s=time.perf_counter() - t_start)
    if verbose:
        print(text)
    return res
