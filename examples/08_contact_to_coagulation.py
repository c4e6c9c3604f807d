"""From monomer-contact collisions to a coagulation box: a DEM-measured collision outcome in both engines.

Shows: a real sweep of head-on collisions of ice BCCA pairs with the contact DEM (Wada et al. 2007 §4:
``contact.bridge.sweep_collisions`` runs ``contact.collide`` over sizes x impact speeds), the collision table it
measures (x_break = E_imp/(n_k E_break), N_large/N_total, r_g change), the outcome built from it
(``outcome_from_collisions``, usable by the binned and the Monte Carlo engines), and one coagulation box run with
it in both engines through ``jaxcoag.evolve``, side by side with the fitted recipe users hand-copy today: the
Dominik & Tielens (1997) / Wada et al. (2007) energy thresholds (erosion from 3 n_k E_break, catastrophic
disruption, N_large/N_total = 1/2, at 10 n_k E_break; ``O07Recipe(frag_model=DTEnergy(contacts="wada"))``).

The box: monomers of the DEM material (0.1 micron ice) at n0 = 1e3 cm^-3 with a constant kernel K0 = 1e-3
cm^3 s^-1 (K0 n0 = 1 collision per monomer per second) and a prescribed relative-velocity law [CHOICE, not a disk
velocity: Brownian and turbulent speeds of such small aggregates are ~cm/s, far below fragmentation]
dv^2 = v_c^2 (m_1 + m_2)/M_c, with M_c = the largest measured N_total times m_1 and v_c the speed at which two
halves of M_c have x_break = 3, the onset of disruption (Wada et al. 2007 §5.1: x_break = N (v/v0)^2 /
(8 c_break (N - 2))). Pairs of a few monomers stick (x_break < 2 up to 8 + 8 monomers), pairs of M_c and more
fragment: growth becomes fragmentation-limited, at a mass-weighted mean mass <m>_m = M_2/M_1 that depends on the
outcome. The binned engine tracks no porosity, so only the masses of the
outcome matter here (the r_g change is printed, not used).

    python examples/08_contact_to_coagulation.py [--quick]

--quick: one size (8 + 8 monomers, planar), one structure, six speeds, dt = 0.112 t_c (the largest step of
Wada et al. 2007 §4), 2000 quiet steps; the box on a 10 bins/decade grid and 1000 Monte Carlo particles
(equal-mass grouping, Ns* = 1000) up to 100 s (minutes on 2 CPU cores, mostly compilation). Full: sizes 4, 8,
16, 32 per aggregate, 3 structures, ten speeds, dt = 0.014 t_c and the default end of ``collide``; 20
bins/decade and 4000 particles up to 300 s (hours on a laptop CPU; not run by the tests).

References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007, ApJ 661, 320) §4-5 (eqs. 44-45, 48; Fig. 14);
Dominik & Tielens (1997, ApJ 480, 647); Ormel (2008) thesis §6.5 (tabulated recipes in coagulation).
"""

import argparse
import os
import time

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np

from jaxcoag import Binned, MassGrid, Monodisperse, MonteCarlo, evolve, kernels, status_names
from jaxcoag.aggregates import contact
from jaxcoag.aggregates.contact import bridge
from jaxcoag.mc import EqualMass
from jaxcoag.outcomes import O07Recipe, RecipeOutcome
from jaxcoag.physics.dominik_tielens import DTEnergy, dt_fragment_fraction

X_C = 3.0  # x_break of two halves of M_c at v_c: the onset of disruption (Wada et al. 2007 §5.5, D&T 1997)
X_CAT = 10.0  # catastrophic disruption, N_large/N_total = 1/2 (Wada et al. 2007 §5.5; the D&T recipe's value)
K0 = 1e-3  # constant kernel [cm^3 s^-1]
N0 = 1e3  # monomers per cm^3 at t = 0


class SpeedLawKernel(kernels.AbstractKernel):
    """Constant kernel K0 [cm^3 s^-1] with the relative velocity dv^2 = v_c^2 (m_1 + m_2)/M_c [cm^2 s^-2]
    ([CHOICE] a prescribed velocity law that grows with the pair mass, putting the fragmentation regime of the
    measured table inside the box's mass range; not a disk velocity)."""

    k0: jax.Array
    v_c: jax.Array
    m_c: jax.Array
    n_struct = 0

    def __call__(self, m1, m2, x1=None, x2=None):
        return self.k0 * jnp.ones(jnp.broadcast_shapes(jnp.shape(m1), jnp.shape(m2)))

    def relative_velocity2(self, m1, m2, x1=None, x2=None):
        return self.v_c**2 * (m1 + m2) / self.m_c


def speed_for(x_break, n_total, material):
    """Relative speed [cm s^-1] at which two halves of n_total monomers collide with E_imp = x_break n_k E_break
    (inverse of Wada et al. 2007 §5.1: E_imp = N m_1 v^2/8, n_k = N - 2)."""
    return float(np.sqrt(x_break * 8.0 * (n_total - 2.0) * float(material.E_break) / (n_total * float(material.m1))))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="one size, one structure, six speeds, small box")
    args = ap.parse_args(argv)
    mat = contact.materials.ice()
    v0, tc, m1 = float(mat.v0), float(mat.t_c), float(mat.m1)
    if args.quick:
        sizes, n_struct, v_over_v0 = [8], 1, np.array([1.0, 3.0, 6.0, 10.0, 16.0, 25.0])
        sweep_kw = dict(dt=0.112 * tc, quiet_steps=2000)
        bins_per_decade, n_particles, t_out = 10, 1000, np.array([1.0, 3.0, 10.0, 30.0, 100.0])
    else:
        sizes, n_struct, v_over_v0 = [4, 8, 16, 32], 3, np.geomspace(1.0, 30.0, 10)
        sweep_kw = dict()
        bins_per_decade, n_particles, t_out = 20, 4000, np.array([1.0, 3.0, 10.0, 30.0, 100.0, 300.0])

    # 1. the DEM sweep: ice BCCAs (planar), each colliding with a rotated copy of itself (Wada et al. 2007 §4),
    #    one collision per core at a time (host threads; the table does not depend on the number of workers)
    w0 = time.perf_counter()
    table = bridge.sweep_collisions(sizes, v_over_v0 * v0, mat, jax.random.key(8), n_structures=n_struct,
                                    workers=os.cpu_count(), **sweep_kw)
    wall_sweep = time.perf_counter() - w0
    n_tot = np.asarray(table.n_total)
    x = np.asarray(table.x_break)
    f_large = np.asarray(table.f_large)
    print(f"DEM sweep: {len(sizes)} size(s) x {v_over_v0.size} speeds x {n_struct} structure(s) of ice BCCAs "
          f"({wall_sweep:.1f} s wall)")
    print(" N_total  v/v0    x_break   N_large/N_tot  r_g change  N_2nd/N_tot | fragment fraction: DEM  D&T")
    dem_out = bridge.outcome_from_collisions(table, mat)
    f_frag_dem = 1.0 - np.asarray(dem_out.recipe.f_large)  # the outcome's table (running minimum of f_large)
    n_k = np.maximum(n_tot - 2.0, 1.0)[:, None]
    e_break = float(mat.E_break)
    f_frag_dt = np.asarray(dt_fragment_fraction(x * n_k * e_break, n_k, e_break))
    for i, n in enumerate(n_tot):
        for j, v in enumerate(v_over_v0):
            print(f" {n:6.0f} {v:6.2f} {x[i, j]:9.3g}   {f_large[i, j]:10.3f}   {float(table.rg_ratio[i, j]):9.3f}  "
                  f"{float(table.f_second[i, j]):10.3f}  |  {f_frag_dem[i, j]:22.3f} {f_frag_dt[i, j]:5.3f}")

    # 2. the box: both outcomes, both engines
    n_c = float(n_tot[-1])
    v_c = speed_for(X_C, n_c, mat)
    kern = SpeedLawKernel(jnp.asarray(K0), jnp.asarray(v_c), jnp.asarray(n_c * m1))
    dt_out = RecipeOutcome(O07Recipe(frag_model=DTEnergy(contacts="wada")), dem_out.material)
    outcomes = {"DEM table": dem_out, "D&T thresholds": dt_out}
    grid = MassGrid.log(10 ** (-0.5 / bins_per_decade) * m1, 3e3 * m1, bins_per_decade)
    ic = Monodisperse(m1, N0 * m1)
    t = jnp.asarray(t_out)
    # equal-mass grouping with Ns* = the particle number (thesis ch. 6): the DEM table's fragments have real-valued
    # masses, so exact species DSMC (grouping=None) gained a species with almost every fragmenting event and ran out
    # of slots (capacity_exceeded at 4 x n_particles); here mass neighbours merge above 2 Ns*
    mc = MonteCarlo(grouping=EqualMass(), n_particles=n_particles, ns_target=n_particles, max_events=200 * n_particles)
    res = {}
    print(f"\nbox: K0 = {K0:g} cm^3/s, n0 = {N0:g} cm^-3, dv^2 = v_c^2 (m1 + m2)/M_c with M_c = {n_c:.0f} m_1, "
          f"v_c = {v_c:.4g} cm/s = {v_c / v0:.3g} v0 (x_break = {X_C:g} for two halves of M_c)")
    print(" outcome          engine       wall [s]  max|mass drift|  status             <m>_m/m_1 at t = " +
          "  ".join(f"{s:g}" for s in t_out) + " s")
    for name, out in outcomes.items():
        for eng_name, eng in (("binned", Binned(grid)), ("Monte Carlo", mc)):
            w0 = time.perf_counter()
            r = evolve(kern, eng, ic, t, outcome=out, key=jax.random.key(0))
            mm = np.asarray(r.mean_mass()) / m1
            drift = float(jnp.max(jnp.abs(r.mass_drift)))
            wall = time.perf_counter() - w0
            res[(name, eng_name)] = dict(mean_mass=mm, drift=drift, status=status_names(r.status), wall=wall)
            print(f" {name:16s} {eng_name:12s} {wall:8.1f}  {drift:14.2e}   {status_names(r.status):17s}  "
                  + "  ".join(f"{v:8.3f}" for v in mm))

    # 3. summary: conservation, engine agreement, DEM vs hand-copied thresholds
    agree = {name: float(res[(name, "Monte Carlo")]["mean_mass"][-1] / res[(name, "binned")]["mean_mass"][-1] - 1.0)
             for name in outcomes}
    dem_vs_dt = {e: float(res[("DEM table", e)]["mean_mass"][-1] / res[("D&T thresholds", e)]["mean_mass"][-1])
                 for e in ("binned", "Monte Carlo")}
    print(f"\nMonte Carlo / binned - 1 of <m>_m at {t_out[-1]:g} s: " +
          ", ".join(f"{k}: {v:+.3f}" for k, v in agree.items()))
    print(f"<m>_m with the DEM table / with the D&T thresholds at {t_out[-1]:g} s: " +
          ", ".join(f"{k}: {v:.3f}" for k, v in dem_vs_dt.items()))
    fl_mono = np.asarray(dem_out.recipe.f_large)  # f_large as the outcome uses it (non-increasing with energy)
    half = [float(np.interp(-0.5, -fl_mono[i], np.log(x[i]))) if fl_mono[i, -1] <= 0.5 < fl_mono[i, 0] else np.nan
            for i in range(len(n_tot))]  # linear in ln x_break, as the outcome interpolates; NaN: not bracketed
    print("x_break where N_large/N_total falls to 1/2 (catastrophic disruption): DEM " +
          ", ".join(f"N = {n:.0f}: {np.exp(h):.3g}" for n, h in zip(n_tot, half)) + f"; D&T: {X_CAT:g}")
    return dict(
        v_over_v0=v_over_v0.tolist(), n_total=n_tot.tolist(), e_imp=np.asarray(table.e_imp).tolist(),
        x_break=x.tolist(), f_large=f_large.tolist(), rg_ratio=np.asarray(table.rg_ratio).tolist(),
        n_runs=np.asarray(table.n_runs).tolist(), e_break=e_break, e_roll=float(mat.E_roll), m1=m1, v0=v0,
        f_frag_dem=f_frag_dem.tolist(), f_frag_dt=f_frag_dt.tolist(), v_c=v_c, m_c=n_c * m1,
        x_half_dem=[float(np.exp(h)) for h in half], t_out=t_out.tolist(), k0=K0, n0=N0, n_particles=n_particles,
        box={f"{a}|{b}": dict(mean_mass=v["mean_mass"].tolist(), drift=v["drift"], status=v["status"])
             for (a, b), v in res.items()},
        mc_over_binned_minus_1=agree, dem_over_dt=dem_vs_dt, wall_sweep_s=wall_sweep)


if __name__ == "__main__":
    main()
