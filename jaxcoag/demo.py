"""Velocity / kernel demo (``jaxcoag demo``); the main job is ``jaxcoag run`` (:mod:`jaxcoag.runner`).

Evaluates the chapter-4 nebula scene (Brownian + Ormel & Cuzzi 2007 turbulence + radial drift,
compact spheres) at a disk location, prints a table of Stokes numbers, the velocity components
and the kernel for a range of sizes against a fixed partner, times the N x N kernel matrix, and
saves a figure (relative-velocity map over both sizes, components vs size, Stokes number).
"""

from __future__ import annotations

import json
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

from . import constants as C
from . import scenes
from .physics import gas as gasmod

__all__ = ["run_demo"]


def _sizes_to_mass(a, rho_s):
    return 4.0 / 3.0 * np.pi * rho_s * a ** 3


def run_demo(*, disk="ch4", R_au=3.0, alpha=1e-4, rho_s=3.0, a_min=1e-5, a_max=1e3, n=200,
             partner=1e-4, out="jaxcoag_out", quick=False, show_table=True):
    """Run the demo; returns a dict of the numbers it printed (also written as JSON).

    Arguments:
        disk: "ch4" (thesis Table 4.1 disk) or "mmsn" (Hayashi 1981).
        R_au: radius [AU]; alpha: turbulence parameter; rho_s: material density [g cm^-3].
        a_min, a_max: size range [cm]; n: grid size of the N x N map; partner: partner radius [cm].
        out: output directory for the figure and JSON; quick: small grid (tests).
    """
    if disk not in ("ch4", "mmsn"):
        raise ValueError(f"unknown disk {disk!r}; use 'ch4' or 'mmsn'")
    if n < 2:
        raise ValueError("n must be >= 2 grid points")
    if quick:
        n = min(n, 40)
    gas = (gasmod.ch4_disk if disk == "ch4" else gasmod.mmsn_hayashi81)(R_au * C.AU, alpha=alpha)
    scene = scenes.nebula_ch4()
    kern = scene.kernel(gas, rho_s=rho_s)

    a_grid = np.logspace(np.log10(a_min), np.log10(a_max), n)
    m_grid = jnp.asarray(_sizes_to_mass(a_grid, rho_s))
    mat = jax.jit(lambda k, m: k.matrix(m))
    comps_fn = jax.jit(lambda k, m: k.components_matrix(m))
    K = mat(kern, m_grid).block_until_ready()
    reps = 3 if quick else 20
    t0 = time.perf_counter()
    for _ in range(reps):
        mat(kern, m_grid).block_until_ready()
    t_mat = (time.perf_counter() - t0) / reps
    comps = {k: np.asarray(v) for k, v in comps_fn(kern, m_grid).items()}
    dv_tot = np.sqrt(sum(comps.values()))

    a_tab = np.logspace(np.log10(a_min), np.log10(a_max), 9)
    m_tab = jnp.asarray(_sizes_to_mass(a_tab, rho_s))
    m_p = jnp.asarray(_sizes_to_mass(np.array(partner), rho_s))
    p = kern.particles(m_tab)
    pp = kern.particles(m_p)
    rows = []
    c_tab = {v.name: np.asarray(v.dv2(p, v.per_particle(p, gas), pp, v.per_particle(pp, gas), gas))
             for v in scene.velocities}
    k_tab = np.asarray(kern(m_tab, m_p))
    for i, a in enumerate(a_tab):
        rows.append(dict(a_cm=float(a), St=float(p.st[i]),
                         dv_brownian=float(np.sqrt(c_tab["brownian"][i])),
                         dv_turbulence=float(np.sqrt(c_tab["turbulence"][i])),
                         dv_radial=float(np.sqrt(c_tab["radial_drift"][i])),
                         dv_total=float(np.sqrt(sum(c[i] for c in c_tab.values()))),
                         kernel=float(k_tab[i])))
    if show_table:
        print(f"jaxcoag demo: scene '{scene.name}' {tuple(scene.effect_names)} in the {disk} disk at "
              f"R = {R_au:g} AU, alpha = {alpha:g}, rho_s = {rho_s:g} g/cm^3")
        print(f"gas: rho_g = {float(gas.rho_g):.4e} g/cm^3, c_g = {float(gas.c_g):.4e} cm/s, "
              f"Re = {float(gas.Re):.4e}, t_s = {float(gas.t_s):.4e} s, eta = {float(gas.eta):.4e}")
        print(f"partner radius a2 = {partner:g} cm")
        hdr = f"{'a1 [cm]':>10} {'St1':>10} {'dv_BM':>10} {'dv_turb':>10} {'dv_drift':>10} {'dv_tot':>10} {'K [cm3/s]':>11}"
        print(hdr)
        for r in rows:
            print(f"{r['a_cm']:10.3e} {r['St']:10.3e} {r['dv_brownian']:10.3e} {r['dv_turbulence']:10.3e} "
                  f"{r['dv_radial']:10.3e} {r['dv_total']:10.3e} {r['kernel']:11.3e}")
        print(f"N x N kernel matrix (N = {n}): {t_mat * 1e3:.3f} ms per evaluation (jit, after warm-up)")

    os.makedirs(out, exist_ok=True)
    fig_path = os.path.join(out, "demo_velocities.png")
    _figure(a_grid, dv_tot, comps, np.asarray(kern.particles(m_grid).st), fig_path, partner_index=int(
        np.argmin(abs(np.log(a_grid / partner)))), title=f"{disk} disk, R = {R_au:g} AU, alpha = {alpha:g}")
    result = dict(disk=disk, R_au=R_au, alpha=alpha, rho_s=rho_s, n=n, matrix_seconds=t_mat, rows=rows,
                  figure=fig_path, kernel_finite=bool(np.all(np.isfinite(np.asarray(K)))))
    tmp = os.path.join(out, ".demo.json.tmp")
    with open(tmp, "w") as fh:
        json.dump(result, fh, indent=1)
    os.replace(tmp, os.path.join(out, "demo.json"))
    if show_table:
        print(f"saved {fig_path}")
    return result


def _figure(a, dv_tot, comps, st, path, partner_index, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.6))
    lv = np.log10(np.maximum(dv_tot, 1e-30))
    cs = ax[0].contourf(a, a, lv, levels=30, cmap="magma")
    ax[0].set_xscale("log"); ax[0].set_yscale("log")
    ax[0].set_xlabel("a1 [cm]"); ax[0].set_ylabel("a2 [cm]")
    ax[0].set_title("log10 Delta v_tot [cm/s]")
    fig.colorbar(cs, ax=ax[0])
    j = partner_index
    for name, v in comps.items():
        ax[1].loglog(a, np.sqrt(np.maximum(v[:, j], 0)) + 1e-30, label=name)
    ax[1].loglog(a, dv_tot[:, j], "k--", label="total")
    ax[1].set_ylim(1e-4, None)
    ax[1].set_xlabel("a1 [cm]"); ax[1].set_ylabel("Delta v [cm/s]")
    ax[1].set_title(f"partner a2 = {a[j]:.2g} cm"); ax[1].legend()
    ax[2].loglog(a, st)
    ax[2].set_xlabel("a [cm]"); ax[2].set_ylabel("Stokes number")
    ax[2].set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
