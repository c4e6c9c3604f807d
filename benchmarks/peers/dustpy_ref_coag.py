"""Reference numbers from DustPy 1.0.9 for the per-cell coagulation: velocities, kernel, p_frag, S_coag, J~.

Builds DustPy's small CI set-up (``Simulation`` with ``ini.grid.Nr = 30``, ``ini.grid.mmax = 1e2`` g,
every other parameter DustPy's default: 1-1000 au, 7 bins per decade from 1e-12 g, alpha = 1e-3,
v_frag = 1 m/s, erosionMassRatio = 10, excavatedMass = 1, fragmentDistribution = -11/6), records its state
at t = 0 (MRN) and after evolving it to 1e3 yr with DustPy's default integrator (size distribution no
longer MRN, with bins below the floor), and calls DustPy's own Fortran routines (``dustpy.std.dust_f``):

* ``coagulation_parameters`` (the collision tensors: stick, stick_ind, A, eps, lf_ind, rm_ind, phi);
* per state, the inputs of every cell (gas T, cs, mu, delta_turb, Omega_K, Sigma_g, v_frag; dust a, St, H,
  v_rad, v_driftmax, Sigma, SigmaFloor) and ``s_coag`` for all cells;
* for two interior cells per state (``{tag}_cells``): the five velocity components and their total
  (``vrel_azimuthal_drift``, ``vrel_brownian_motion``, ``vrel_radial_drift``, ``vrel_ormel_cuzzi_2007``,
  ``vrel_vertical_settling``, ``vrel_tot``), ``kernel``, ``pfrag`` (upper triangles j <= i, flattened by
  numpy.triu_indices, to keep the file small) and the dense (Nm, Nm) block of that cell of the sparse
  matrix of ``jacobian_coagulation_generator`` (its (dat, row, col) output summed into a dense array).

Writes ``tests/data/dustpy_coag_ref.npz`` (compressed, < 1.5 MB) for ``tests/test_disk_coagulation.py``
(DustPy is not needed to run the tests).

Regenerate (DustPy 1.0.9 installed; ~20 s on 2 cores): ``python benchmarks/peers/dustpy_ref_coag.py``.

References: Stammler & Birnstiel (2022) ApJ 935, 35 (DustPy); Brauer, Dullemond & Henning (2008) A&A 480,
859 (sticking scheme); Ormel & Cuzzi (2007) A&A 466, 413 (turbulent velocities).
"""

from __future__ import annotations

import pathlib
import time

import numpy as np

OUT = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "dustpy_coag_ref.npz"
CELLS = {"t0": (3, 20), "t1": (3, 12)}


def _state(sim, tag, rec):
    """Record DustPy's inputs and outputs of the current state under the key prefix ``tag``."""
    import scipy.sparse as sp

    from dustpy.std import dust_f

    sim.update()
    g, d, gr = sim.gas, sim.dust, sim.grid
    Nr, Nm = int(gr.Nr), int(gr.Nm)
    m = np.array(gr.m)

    def put(k, v, dtype=float):
        rec[f"{tag}_{k}"] = np.array(v, dtype=dtype)

    put("t", sim.t)
    for k in ("T", "cs", "mu", "Sigma"):
        put(f"gas_{k}", getattr(g, k))
    put("OmegaK", gr.OmegaK)
    put("delta_turb", d.delta.turb)
    put("v_frag", d.v.frag)
    for k in ("a", "St", "H", "Sigma", "SigmaFloor"):
        put(f"dust_{k}", getattr(d, k))
    put("dust_v_rad", d.v.rad)
    put("dust_v_driftmax", d.v.driftmax)

    comps = {
        "azi": dust_f.vrel_azimuthal_drift(d.v.driftmax, d.St),
        "brown": dust_f.vrel_brownian_motion(g.cs, m, g.T),
        "rad": dust_f.vrel_radial_drift(d.v.rad),
        "turb": dust_f.vrel_ormel_cuzzi_2007(d.delta.turb, g.cs, g.mu, gr.OmegaK, g.Sigma, d.St),
        "vert": dust_f.vrel_vertical_settling(d.H, gr.OmegaK, d.St),
    }
    tot = np.sqrt(sum(v ** 2 for v in comps.values()))
    assert np.allclose(tot, np.array(d.v.rel.tot), rtol=1e-14, atol=0.0)
    K = dust_f.kernel(d.a, d.H, d.Sigma, d.SigmaFloor, tot)
    pf = dust_f.pfrag(tot, d.v.frag)
    pf[0] = 0.0
    pf[-1] = 0.0
    ps = 1.0 - pf
    ps[0] = 0.0
    ps[-1] = 0.0
    Rf, Rs = K * pf, K * ps
    cp = d.coagulation
    put("S_coag", dust_f.s_coag(cp.stick, cp.stick_ind, cp.A, cp.eps, cp.lf_ind, cp.rm_ind, cp.phi, Rf, Rs, m,
                                d.Sigma, d.SigmaFloor))
    dat, row, col = dust_f.jacobian_coagulation_generator(cp.A, cp.stick, cp.eps, cp.lf_ind, cp.rm_ind,
                                                          cp.stick_ind, m, cp.phi, Rf, Rs, d.Sigma, d.SigmaFloor)
    Jc = sp.csr_matrix((dat, (row, col)), shape=(Nr * Nm, Nr * Nm))
    iu = np.triu_indices(Nm)  # (row j, column i) with j <= i: DustPy's X[ir, j, i] storage
    cells = CELLS[tag]
    put("cells", cells, dtype=np.int64)
    for c in cells:
        for k, v in comps.items():
            put(f"c{c}_vrel_{k}", v[c][iu])
        put(f"c{c}_vrel_tot", tot[c][iu])
        put(f"c{c}_kernel", K[c][iu])
        put(f"c{c}_pfrag", pf[c][iu])
        put(f"c{c}_jac", Jc[c * Nm:(c + 1) * Nm, c * Nm:(c + 1) * Nm].toarray())
    imax = [int(np.max(np.nonzero(d.Sigma[c] > d.SigmaFloor[c])[0])) for c in cells]
    print(f"{tag}: t = {float(sim.t):.3e} s, cells {cells}, largest bin above floor {imax} of {Nm - 1}")


def main():
    import dustpy
    import dustpy.constants as c
    from dustpy.std import dust_f

    rec = {}
    sim = dustpy.Simulation()
    sim.ini.grid.Nr = 30
    sim.ini.grid.mmax = 1.0e2
    sim.initialize()
    sim.writer = None
    sim.verbosity = 0
    m = np.array(sim.grid.m)
    rec["grid_m"] = m
    rec["grid_r"] = np.array(sim.grid.r)
    ini = sim.ini.dust
    rec["coag_args"] = np.array([ini.erosionMassRatio, ini.excavatedMass, ini.fragmentDistribution])
    names = ("stick", "stick_ind", "A", "eps", "lf_ind", "rm_ind", "phi")
    out = dust_f.coagulation_parameters(ini.erosionMassRatio, ini.excavatedMass, ini.fragmentDistribution, m)
    for k, v in zip(names, out):
        rec[f"coag_{k}"] = np.array(v)
        assert np.array_equal(np.array(v), np.array(getattr(sim.dust.coagulation, k)))
    # DustPy's own mass-conservation diagnostics of these tensors
    rec["coag_masserr_stick"] = np.array(dust_f.check_mass_conservation_sticking(out[0], out[1], m)[0])
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
