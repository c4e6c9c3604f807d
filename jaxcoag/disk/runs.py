"""``jaxcoag run`` for ``[run] engine = "disk"``: the 1-D radial disk from a configuration.

The same job as every engine (:func:`jaxcoag.runner.run`): validate the configuration, refuse
unwritable outputs before any work, evolve with :func:`jaxcoag.evolve` output time by output time
with an atomic checkpoint after each (Ctrl-C saves; a resume is bit-identical), write the result's
``to_xarray()`` dataset as netCDF (atomically), the standard figure next to it and a summary:

* left: Sigma_d per unit ln a over (r, a) at the last output, with the fragmentation limit a_frag
  (f_f = 0.37) and the drift limit a_drift (f_d = 0.55) of Birnstiel, Klahr & Ercolano (2012) eqs.
  (8) and (18) overlaid;
* middle: Sigma_g(r) and Sigma_d(r) at the first, a middle and the last output;
* right: the dust and gas mass against time.

References: Stammler & Birnstiel (2022, ApJ 935, 35); Birnstiel, Klahr & Ercolano (2012, A&A 539, A148).
"""

from __future__ import annotations

import time

import numpy as np

from .. import constants as C

__all__ = ["model_from_config", "run_disk", "quick_disk"]


def model_from_config(cfg):
    """The :class:`~jaxcoag.disk.model.DiskModel`, the :class:`~jaxcoag.disk.engine.Disk` engine and the output
    times [s] (0 first) of a ``[run] engine = "disk"`` configuration."""
    from .. import config as cfgmod
    from .engine import Disk
    from .model import dustpy_default
    from .solve import Parity, Split

    from .gas import DUSTPY_CONSTANTS as DP

    d = cfg["disk"]
    au, msun = DP["au"], DP["M_sun"]  # DustPy's units, so that the default [disk] is dustpy_default() exactly
    model = dustpy_default(
        nr=d["nr"], r_min=d["r_min_au"] * au, r_max=d["r_max_au"] * au, m_min=d["m_min"], m_max=d["m_max"],
        bins_per_decade=d["bins_per_decade"], alpha=d["alpha"], delta_rad=d["delta_rad"], delta_turb=d["delta_turb"],
        delta_vert=d["delta_vert"], v_frag=d["v_frag"], m_disk=d["m_disk_msun"] * msun, r_c=d["r_c_au"] * au,
        rho_s=d["rho_s"], dust_to_gas=d["dust_to_gas"], a_ini_max=d["a_ini_max"], m_star=d["m_star_msun"] * msun,
        r_star=d["r_star_rsun"] * DP["R_sun"], t_star=d["t_star"], stokes=d["stokes"], coagulation=d["coagulation"],
        dust_transport=d["dust_transport"], gas_evolution=d["gas_evolution"])
    mode = Parity(cfl=d["cfl"]) if d["mode"] == "parity" else Split(cfl=d["cfl"])
    engine = Disk(mode=mode, max_steps=d["max_steps"])
    return model, engine, cfgmod.output_times_s(cfg)


def quick_disk(cfg):
    """A smaller, faster version of a disk config (``--quick``): at most 30 cells, m_max <= 1e2 g, at most
    5 bins per decade and output times up to 1e3 yr (at most 4 of them); the physics is unchanged."""
    from .. import config as cfgmod

    raw = cfg.raw()
    d = raw.setdefault("disk", {})
    d["nr"] = min(int(cfg["disk"]["nr"]), 30)
    d["m_max"] = min(float(cfg["disk"]["m_max"]), 1e2)
    d["bins_per_decade"] = min(int(cfg["disk"]["bins_per_decade"]), 5)
    t_all = np.asarray(cfgmod.output_times_s(cfg)[1:]) / C.yr
    keep = [float(x) for x in t_all[t_all <= 1e3 * (1 + 1e-12)]][:4] or [float(min(t_all[0], 1e3))]
    raw["time"] = {"t_out_yr": keep}
    return cfgmod.from_dict(raw, source=cfg.source + " (quick)")


def disk_figure(result, model, path, title=""):
    """The standard disk figure (module docstring) written atomically to ``path`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..aggregates.runs import _save

    r_au = np.asarray(result.r) / C.AU
    a = np.asarray(result.a)
    t_yr = np.asarray(result.t) / C.yr
    sd = np.asarray(result.sigma_dust)
    sg = np.asarray(result.sigma_gas)
    k = len(t_yr) - 1
    dlna = np.log(a[1] / a[0]) if a.size > 1 else 1.0
    per_lna = sd[k] / dlna
    a_frag, a_drift = (np.asarray(x) for x in model.size_limits(result.sigma_gas[k], result.sigma_dust[k]))
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.4))
    floor = max(per_lna.max() * 1e-10, 1e-300)
    lev = np.log10(np.maximum(per_lna.T, floor))
    pc = ax[0].pcolormesh(r_au, a, lev, shading="nearest", vmin=np.log10(floor), vmax=lev.max(), cmap="magma")
    ax[0].plot(r_au, a_frag, "w--", lw=1.2, label="a_frag (f_f = 0.37)")
    ax[0].plot(r_au, a_drift, "c:", lw=1.4, label="a_drift (f_d = 0.55)")
    ax[0].set(xscale="log", yscale="log", xlabel="r [au]", ylabel="a [cm]", ylim=(a[0], a[-1]),
              title=f"log10 Sigma_d per ln a [g cm^-2], t = {t_yr[k]:.3g} yr")
    ax[0].legend(loc="upper right", fontsize=8)
    fig.colorbar(pc, ax=ax[0])
    for j in sorted({0, k // 2, k}):
        ax[1].loglog(r_au, sg[j], "-", label=f"gas, {t_yr[j]:.3g} yr")
        ax[1].loglog(r_au, sd[j].sum(-1), "--", label=f"dust, {t_yr[j]:.3g} yr")
    ax[1].set(xlabel="r [au]", ylabel="Sigma [g cm^-2]", ylim=(max(sd[:, 1:-1].sum(-1).min(), sg.max() * 1e-12), None))
    ax[1].legend(fontsize=7)
    md = np.asarray(result.dust_mass) / C.M_sun
    mg = np.asarray(result.gas_mass) / C.M_sun
    tt = np.maximum(t_yr, t_yr[t_yr > 0].min() / 10 if np.any(t_yr > 0) else 1.0)
    ax[2].loglog(tt, md / md[0], "o-", label=f"dust (M0 = {md[0]:.3g} Msun)")
    ax[2].loglog(tt, mg / mg[0], "s-", label=f"gas (M0 = {mg[0]:.3g} Msun)")
    ax[2].set(xlabel="t [yr]", ylabel="M / M(0)")
    ax[2].legend(fontsize=8)
    fig.suptitle(title)
    return _save(fig, path)


def _summary(result, model):
    t = np.asarray(result.t) / C.yr
    md = np.asarray(result.dust_mass)
    mg = np.asarray(result.gas_mass)
    ap = np.asarray(result.a_peak())[-1]
    r_au = np.asarray(result.r) / C.AU
    j10 = int(np.argmin(np.abs(r_au - 10.0)))
    return {"t_end_yr": float(t[-1]), "steps": int(np.asarray(result.n_steps)[-1]),
            "dust_mass_msun_0": float(md[0] / C.M_sun), "dust_mass_msun_end": float(md[-1] / C.M_sun),
            "gas_mass_msun_end": float(mg[-1] / C.M_sun),
            "gas_accreted_msun": float(np.asarray(result.m_acc_gas)[-1] / C.M_sun),
            "a_peak_cm_at_r": float(ap[j10]), "a_peak_r_au": float(r_au[j10])}


def _format(n, status, wall_s):
    return "\n".join([
        f"disk run: {status}, {n['steps']} steps to {n['t_end_yr']:.4g} yr in {wall_s:.1f} s wall",
        f"  dust mass {n['dust_mass_msun_0']:.4g} -> {n['dust_mass_msun_end']:.4g} Msun; gas {n['gas_mass_msun_end']:.4g}"
        f" Msun ({n['gas_accreted_msun']:.3g} Msun accreted)",
        f"  a_peak at r = {n['a_peak_r_au']:.3g} au: {n['a_peak_cm_at_r']:.3g} cm"])


def run_disk(cfg, *, out, checkpoint, resume, progress, figure, max_segments, verbose, save, t_start):
    """Run a disk configuration (called by :func:`jaxcoag.runner.run`, which checked the output locations).
    Returns a :class:`jaxcoag.runner.RunResult`."""
    from .._status import FAILURES, RESULT_NAMES, result_code
    from ..io import save_netcdf
    from ..runner import RunResult, _makedirs_for, evolve_saved, figure_path

    model, engine, t_out = model_from_config(cfg)
    result, resumed_from = evolve_saved(model, engine, None, t_out, checkpoint=checkpoint, every=1, resume=resume,
                                        progress=progress, max_segments=max_segments, save=save)
    if not save:
        checkpoint = None
    rname = RESULT_NAMES[int(np.asarray(result_code(result.status)))]
    failed = rname in FAILURES
    finished = int(np.shape(result.t)[0]) == len(t_out) and not failed
    attrs = {"run_name": cfg["run"]["name"], "run_description": cfg["run"]["description"], "config_source": cfg.source,
             "config_toml": cfg.to_toml(), "physics_hash": cfg.physics_hash()}
    ds = result.to_xarray(attrs=attrs)
    numbers = _summary(result, model)
    numbers["result"] = rname
    text = _format(numbers, rname, time.perf_counter() - t_start)
    for k, v in numbers.items():
        if isinstance(v, (int, float, str)):
            ds.attrs[f"summary_{k}"] = v
    path = fig = None
    if save and (finished or failed):
        ds.attrs["wall_s"] = time.perf_counter() - t_start
        _makedirs_for(out)
        path = save_netcdf(ds, out)
        if figure:
            fig = disk_figure(result, model, figure_path(out), title=f"{cfg['run']['name']} (disk)")
    res = RunResult(result=result, dataset=ds, built={"model": model, "engine": engine, "t_out": t_out}, path=path,
                    figure=fig, checkpoint=checkpoint, finished=finished, failed=failed, resumed_from=resumed_from,
                    rows=[], numbers=numbers, wall_s=time.perf_counter() - t_start)
    if verbose:
        print(text)
    return res
