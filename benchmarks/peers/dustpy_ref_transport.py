"""Reference numbers from DustPy 1.0.9 for the disk grid, gas and dust-transport functions.

Builds DustPy's small CI set-up (``Simulation`` with ``ini.grid.Nr = 30``, ``ini.grid.mmax = 1e2`` g,
every other parameter DustPy's default: 1-1000 au, 7 bins per decade from 1e-12 g, alpha = 1e-3,
M_disk = 0.05 M_sun, r_c = 60 au, v_frag = 1 m/s), records its state at t = 0 and after evolving it to
1e3 yr with DustPy's default integrator, and at each of the two states calls DustPy's own routines
(``dustpy.std.gas_f``, ``dustpy.std.dust_f``, ``dustpy.std.gas``, ``dustpy.std.dust``,
``dustpy.utils.boundary.Boundary``) to produce:

* grid and star: ri, r, A, m, OmegaK, L; gas: Sigma, T, cs, Hp, nu, rho, P, n, mfp, eta, v_visc, v_rad,
  donor-cell fluxes Fi and their sources, the tridiagonal operator (``jac_abc``), the step-size limit;
* one gas implicit step (``std.gas._f_impl_1_direct`` at dt = 0.1 x DustPy's step-size limit, then the
  finaliser's boundary values and floor) ;
* dust: a, St, H, D, v_driftmax, v_rad, SigmaFloor, Sigma, F_adv, F_diff, S_hyd, the transport operator
  (``jacobian_hydrodynamic_generator``), the first and last block rows of DustPy's implicit matrix
  I - dt J (``std.dust.jacobian``) and its right-hand side, a transport-only implicit step (DustPy's J
  minus its coagulation Jacobian, solved with SuperLU as DustPy does, then DustPy's boundary values and
  floor), the step-size limit ``std.dust.dt``; at t = 0 also ``std.dust.MRN_distribution``.

Writes ``tests/data/dustpy_transport_ref.npz`` (compressed, ~0.7 MB), used by
``tests/test_disk_transport.py`` (DustPy is not needed to run the tests).

Regenerate (DustPy 1.0.9 installed; ~30 s on 2 cores):
``python benchmarks/peers/dustpy_ref_transport.py``.

References: Stammler & Birnstiel (2022) ApJ 935, 35 (DustPy).
"""

from __future__ import annotations

import pathlib
import time

import numpy as np

OUT = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "dustpy_transport_ref.npz"


def _state(sim, tag, rec):
    """Record DustPy's inputs and outputs of the current state under the key prefix ``tag``."""
    import scipy.sparse as sp
    import scipy.sparse.linalg  # noqa: F401

    from dustpy import std
    from dustpy.std import dust_f, gas_f
    from dustpy.utils.boundary import Boundary

    # Refresh the derived fields from the current surface densities. DustPy's dust.v.rad is not part of
    # this update: it is set only by the finaliser of the previous step, from the Stokes numbers and
    # v_driftmax of the state *before* that step and the new gas velocity (a lag of one step that the
    # implicit step then uses). It is recorded as is (``dust_v_rad``, the input of the transport
    # operator) and, separately, recomputed by ``dust_f.vrad`` from the current fields (``dust_v_rad_f``).
    sim.update()
    g, d, gr = sim.gas, sim.dust, sim.grid
    Nr, Nm = int(gr.Nr), int(gr.Nm)
    r, ri, area = np.array(gr.r), np.array(gr.ri), np.array(gr.A)

    def put(k, v):
        rec[f"{tag}_{k}"] = np.array(v, dtype=float)

    put("t", sim.t)
    # gas state
    for k in ("Sigma", "T", "cs", "Hp", "nu", "rho", "P", "n", "mfp", "eta", "alpha", "mu"):
        put(f"gas_{k}", getattr(g, k))
    put("gas_v_visc", gas_f.v_visc(g.Sigma, g.nu, r, ri))
    put("gas_v_rad", g.v.rad)
    Fi = gas_f.fi(g.Sigma, g.v.rad, r, ri)
    put("gas_Fi", Fi)
    put("gas_S_hyd", gas_f.s_hyd(Fi, ri))
    Ag, Bg, Cg = gas_f.jac_abc(area, g.nu, r, ri, np.zeros(Nr))
    put("gas_jac_A", Ag), put("gas_jac_B", Bg), put("gas_jac_C", Cg)
    Sg_tot = gas_f.s_tot(np.zeros(Nr), gas_f.s_hyd(Fi, ri))
    put("gas_S_tot_explicit", Sg_tot)
    put("gas_dt", gas_f.timestep(Sg_tot, g.Sigma, g.SigmaFloor))
    # one gas implicit step with DustPy's own scheme and finaliser rules
    dt_gas = 0.1 * float(gas_f.timestep(Sg_tot, g.Sigma, g.SigmaFloor))
    dY = std.gas._f_impl_1_direct(sim.t, g.Sigma, dt_gas)
    solve = np.array(g.Sigma) + np.array(dY)
    fin = solve.copy()
    Boundary(r, ri, fin, condition="const_grad").setboundary()
    Boundary(r[::-1], ri[::-1], fin[::-1], condition="val", value=float(g.SigmaFloor[-1])).setboundary()
    fin = gas_f.enforce_floor(fin, g.SigmaFloor)
    put("gas_step_dt", dt_gas)
    put("gas_step_solve", solve)
    put("gas_step_final", fin)

    # dust state
    for k in ("a", "St", "H", "D", "SigmaFloor", "Sigma"):
        put(f"dust_{k}", getattr(d, k))
    put("dust_rhos", d.rhos)
    put("dust_delta_rad", d.delta.rad)
    put("dust_delta_vert", d.delta.vert)
    put("dust_v_driftmax", d.v.driftmax)
    put("dust_v_rad", d.v.rad)
    put("dust_v_rad_f", dust_f.vrad(d.St, d.v.driftmax, g.v.rad))
    Fadv = dust_f.fi_adv(d.Sigma, d.v.rad, r, ri)
    Fdiff = std.dust.F_diff(sim)
    put("dust_F_adv", Fadv)
    put("dust_F_diff", Fdiff)
    put("dust_S_hyd", dust_f.s_hyd(Fadv + Fdiff, ri))
    A, B, C = dust_f.jacobian_hydrodynamic_generator(area, d.D, r, ri, g.Sigma, d.v.rad)
    put("dust_jac_A", A), put("dust_jac_B", B), put("dust_jac_C", C)
    put("dust_S_tot", d.S.tot)
    dtd = std.dust.dt(sim)
    put("dust_dt", np.inf if dtd is None else dtd)
    # implicit matrix rows and rhs at a given dt
    dt = float(std.sim.dt(sim))  # DustPy's next step (cfl 0.1 included)
    J = std.dust.jacobian(sim, sim.t, dx=dt)
    rhs = np.array(d._rhs).copy()
    M = (sp.identity(Nr * Nm, format="csc") - dt * J).tocsr()
    put("dust_mat_dt", dt)
    put("dust_mat_inner", M[:Nm, : 3 * Nm].toarray())
    put("dust_mat_outer", M[-Nm:, -3 * Nm:].toarray())
    put("dust_rhs", rhs)
    # transport-only step: DustPy's J minus its coagulation Jacobian
    cp = d.coagulation
    dat, row, col = dust_f.jacobian_coagulation_generator(
        cp.A, cp.stick, cp.eps, cp.lf_ind, cp.rm_ind, cp.stick_ind, gr.m, cp.phi,
        d.kernel * d.p.frag, d.kernel * d.p.stick, d.Sigma, d.SigmaFloor)
    Jc = sp.csc_matrix((dat, (row, col)), shape=(Nr * Nm, Nr * Nm))
    Mt = sp.identity(Nr * Nm, format="csc") - dt * (J - Jc)
    lu = sp.linalg.splu(Mt.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                        options=dict(SymmetricMode=True))
    xs = lu.solve(rhs).reshape(Nr, Nm)
    xf = xs.copy()
    Boundary(r, ri, xf, condition="const_grad").setboundary()
    Boundary(r[::-1], ri[::-1], xf[::-1], condition="val", value=0.1 * np.array(d.SigmaFloor[-1])).setboundary()
    xf = np.where(xf > d.SigmaFloor, xf, 0.1 * d.SigmaFloor)
    put("dust_tstep_solve", xs)
    put("dust_tstep_final", xf)


def main():
    import dustpy
    import dustpy.constants as c
    from dustpy import std

    rec = {}
    sim = dustpy.Simulation()
    sim.ini.grid.Nr = 30
    sim.ini.grid.mmax = 1.0e2
    sim.initialize()
    sim.writer = None
    sim.verbosity = 0
    rec["grid_ri"] = np.array(sim.grid.ri)
    rec["grid_r"] = np.array(sim.grid.r)
    rec["grid_A"] = np.array(sim.grid.A)
    rec["grid_m"] = np.array(sim.grid.m)
    rec["grid_OmegaK"] = np.array(sim.grid.OmegaK)
    rec["star_M"] = np.array(float(sim.star.M))
    rec["star_R"] = np.array(float(sim.star.R))
    rec["star_T"] = np.array(float(sim.star.T))
    rec["star_L"] = np.array(float(sim.star.L))
    rec["ini"] = np.array([sim.ini.grid.rmin, sim.ini.grid.rmax, sim.ini.grid.Nr, sim.ini.grid.mmin,
                           sim.ini.grid.mmax, sim.ini.grid.Nmbpd, sim.ini.gas.SigmaRc, sim.ini.gas.Mdisk,
                           sim.ini.gas.SigmaExp, sim.ini.dust.aIniMax, sim.ini.dust.d2gRatio,
                           sim.ini.dust.distExp])
    rec["t0_mrn"] = np.array(std.dust.MRN_distribution(sim))
    _state(sim, "t0", rec)
    sim.t.snapshots = np.array([1.0e3]) * c.year
    t0 = time.perf_counter()
    sim.run()
    print(f"DustPy evolution to 1e3 yr: {time.perf_counter() - t0:.1f} s")
    _state(sim, "t1", rec)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(OUT, **rec)
    print(f"wrote {OUT} ({OUT.stat().st_size / 1e6:.2f} MB)")


if __name__ == "__main__":
    main()
