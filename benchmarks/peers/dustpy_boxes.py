"""DustPy on coagulation-only box problems with analytic solutions (peer runner).

Set-ups follow DustPy's own notebook ``examples/test_analytical_coagulation_kernels.ipynb``: a
3-cell radial grid (one interior cell), gas evolution removed from the integrator, gas sources,
radial dust velocity and fragmentation switched off, sticking probability 1, the kernel array set
by hand, the simulation started at t > 0 from the analytic solution. Problems (cgs; DustPy's
"surface densities" play the role of box mass densities, the equations being identical):

* ``constant``: K = 1, mass 1, exponential start with mean mass m0 = m_min = 1e-12 g,
  t = 1e-9 -> 1e3 (snapshots as the notebook: 1e-7 ... 1e3).
* ``linear``: K = m1 + m2, same start, t = 0.9 -> 10, on [1e-16, 1e5] g: the notebook's
  m_min = 1e-12 g would drop the 8.5 % of the t = 0.9 mass that lies below 1e-12 g, an error
  floor of the set-up rather than of the scheme (it made every code look converged at
  L1 ~ 0.25-0.6).
* ``golovin``: Shima et al. (2009) box: K = 1500 s^-1 (v1 + v2) with water (1 g cm^-3), so
  K = 1500 (m1 + m2) cm^3 s^-1 g^-1; n0 = 2^23 m^-3 = 8.388608 cm^-3, exponential volume
  spectrum with mean radius 30.531 um; t = 0 -> 1200, 2400, 3600 s.

The initial state is the exact mass per bin on DustPy's bins (the notebook samples an
asymptotic point formula instead; with exact bin masses the only error left is DustPy's).

Variants (docs/design_notes.md lists the pitfalls):

* ``notebook``: exactly the notebook's recipe at DustPy defaults: hand-set kernel without
  DustPy's 1/2 on the diagonal, coagulation sources not refreshed after the hand set-up (the
  first implicit step is sized from stale sources and is unbounded), cfl = 0.1.
* ``fixed``: diagonal 1/2 restored and sources refreshed before the run, cfl = 0.1.
* ``fixed_cfl1e-2``, ``fixed_cfl1e-3``: as ``fixed`` with cfl = 0.01 or 0.001 (the constant
  box runs only cfl = 0.01: 0.001 would take ~10^5 steps).

Returns/records mass per bin at the output times on DustPy's grid, wall time of the
integration (DustPy's mass-conservation self-check is excluded), number of steps, and the
relative L1 error against the analytic solution (see :mod:`benchmarks._common`).

``frag1au``: the 1-AU fragmentation box, DustPy and jaxcoag side by side in one invocation
(:func:`run_frag_benchmark`): gas of DustPy's middle cell at 1 AU (T = 280 K, Sigma_g = 1700
g cm^-2, alpha = 1e-3, mu = 2.3 m_p), 1 um monomers (rho_s = 1.6) at dust-to-gas 0.01, 7 bins per
decade, Brownian + Ormel & Cuzzi (2007) turbulent velocities, Maxwellian fragmentation at
v_frag = 1 m/s, fragments n(m) ~ m^-11/6, erosion with one excavated projectile mass. DustPy is
made a true 0-D box (:func:`run_dustpy_frag`): no gas evolution, a dust-only finaliser (DustPy's
default finaliser re-applies the gas boundary conditions every step), no drift, dust scale
heights H_p/sqrt(2) so that its vertically integrated kernel equals the midplane kernel. Ours
uses DustPy's conventions (drag ``convention="dustpy"``, Re = alpha Sigma_g sigma_H2/(2 mu m_p),
DustPy's grid and erosion rule). Controlled variants separate DustPy's step control (cfl),
its relative-velocity formulae (jaxcoag's Delta v imposed on DustPy), the drag convention
(ours with "ormel") and the vertical structure (DustPy's column kernel vs ours at dust-to-gas
/sqrt(2)). Writes ``benchmarks/results/dustpy_boxes_frag1au[_quick].json`` and a PNG.

Run: ``python benchmarks/peers/dustpy_boxes.py [--quick] [--problems constant,linear,golovin,frag1au]``.
Writes ``benchmarks/results/dustpy_boxes[_quick].json`` and a PNG.
References: Stammler & Birnstiel (2022) ApJ 935, 35 (DustPy); Shima et al. (2009) QJRMS 135,
1307; Golovin (1963); Scott (1968); Birnstiel, Dullemond & Brauer (2010) A&A 513, A79;
Ormel & Cuzzi (2007) A&A 466, 413; Dubrulle, Morfill & Sterzik (1995) Icarus 114, 237.
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2]))

from benchmarks import _common as C  # noqa: E402

# Shima et al. (2009) Golovin box in cgs
SHIMA_N0 = 2.0 ** 23 * 1e-6                           # cm^-3
SHIMA_R_MEAN = 30.531e-4                              # cm (mean radius of the volume spectrum)
RHO_WATER = 1.0                                       # g cm^-3
SHIMA_M0 = 4.0 / 3.0 * np.pi * SHIMA_R_MEAN ** 3 * RHO_WATER   # g, mean mass
SHIMA_B = 1500.0                                      # cm^3 s^-1 g^-1 (1500 s^-1 per volume)
SHIMA_TIMES = (1200.0, 2400.0, 3600.0)

VARIANTS = {
    "notebook": dict(diag_half=False, fresh_first_step=False, cfl=0.1),
    "fixed": dict(diag_half=True, fresh_first_step=True, cfl=0.1),
    "fixed_cfl1e-2": dict(diag_half=True, fresh_first_step=True, cfl=1e-2),
    "fixed_cfl1e-3": dict(diag_half=True, fresh_first_step=True, cfl=1e-3),
}


def problem(name):
    """Definition of a box problem: kernel kind/coefficient, initial state, times, grid range.

    Returns a dict with ``kind`` ("constant" or "sum"), ``coeff`` (cm^3 s^-1 or cm^3 s^-1 g^-1),
    ``n0`` [cm^-3] and ``m0`` [g] of the exponential start at t = 0, ``t_start`` [s] (the state
    there is the analytic one), ``t_out`` [s] and the DustPy grid range ``mmin``, ``mmax`` [g].
    """
    if name == "constant":
        return dict(kind="constant", coeff=1.0, n0=1e12, m0=1e-12, t_start=1e-9,
                    t_out=tuple(np.geomspace(1e-7, 1e3, 6)), mmin=1e-12, mmax=1e5)
    if name == "linear":
        return dict(kind="sum", coeff=1.0, n0=1e12, m0=1e-12, t_start=0.9,
                    t_out=(2.0, 4.0, 7.0, 10.0), mmin=1e-16, mmax=1e5)
    if name == "golovin":
        return dict(kind="sum", coeff=SHIMA_B, n0=SHIMA_N0, m0=SHIMA_M0, t_start=0.0,
                    t_out=SHIMA_TIMES, mmin=1e-10, mmax=1e3)
    raise ValueError(f"unknown problem {name!r}")


def _memory_writer():
    """A simframe ``Writer`` that keeps (t, Sigma of the interior cell) in memory, no files."""
    from simframe.io.writer import Writer

    class _MemoryWriter(Writer):
        def __init__(self):
            super().__init__(lambda *a, **k: None, dumping=False, verbosity=0,
                             description="in-memory snapshots (benchmark)")
            self.t, self.sigma = [], []

        def write(self, frame, i=0, forceoverwrite=False, filename=None, **kwargs):
            self.t.append(float(frame.t))
            self.sigma.append(np.array(frame.dust.Sigma[1, :], dtype=np.float64))

    return _MemoryWriter()


def kernel_matrix(kind, coeff, m):
    """K(m_i, m_j) [cm^3 s^-1] on DustPy's mass grid (no diagonal factor)."""
    if kind == "constant":
        return coeff * np.ones((m.size, m.size))
    if kind == "sum":
        return coeff * (m[:, None] + m[None, :])
    raise ValueError(kind)


def run_dustpy(name, *, bins_per_decade, diag_half, fresh_first_step, cfl):
    """Run one DustPy box and return a result dict (see module docstring)."""
    from dustpy import Simulation
    from simframe import Frame

    p = problem(name)
    sim = Simulation()
    sim.verbosity = 0
    sim.ini.grid.Nr = 3
    sim.ini.grid.mmin = p["mmin"]
    sim.ini.grid.mmax = p["mmax"]
    sim.ini.grid.Nmbpd = bins_per_decade
    sim.ini.dust.allowDriftingParticles = False
    sim.initialize()

    # --- the notebook's set_*_kernel recipe ---
    del sim.integrator.instructions[1]                 # no gas evolution
    sim.gas.S.tot[...] = 0.0
    sim.gas.S.tot.updater = None
    sim.dust.v.rad[...] = 0.0                          # no advection
    sim.dust.v.rad.updater = None
    sim.dust.p.frag[...] = 0.0                         # sticking only
    sim.dust.p.frag.updater = None
    sim.dust.p.stick[...] = 1.0
    sim.dust.p.stick.updater = None
    m = np.array(sim.grid.m, dtype=np.float64)
    K = kernel_matrix(p["kind"], p["coeff"], m)
    if diag_half:                                      # DustPy's own kernel has (1 - δ_ij/2)
        K = K * (1.0 - 0.5 * np.eye(m.size))
    sim.dust.kernel[...] = K[None, ...]
    sim.dust.kernel.updater = None
    sim.t = p["t_start"]
    edges = C.dustpy_edges(m)
    sigma0 = C.reference_mass_per_bin(p["kind"], edges, p["t_start"], coeff=p["coeff"],
                                      n0=p["n0"], m0=p["m0"])
    sim.dust.Sigma[...] = sim.dust.SigmaFloor[...]
    sim.dust.Sigma[1, :] = np.maximum(sigma0, sim.dust.SigmaFloor[1, :])
    sim.update()
    if fresh_first_step:
        # In implicit mode S.coag is refreshed only in the integrator's finaliser, so after a
        # hand set-up the first step size comes from stale sources: refresh them here.
        sim.dust.S.coag.update()
        sim.dust.S.tot.update()
    sim.t.cfl = cfl
    sim.t.snapshots = np.asarray(p["t_out"], dtype=np.float64)
    writer = _memory_writer()
    sim.writer = writer

    steps = [0]
    integrate = sim.integrator.integrate

    def counting_integrate():
        steps[0] += 1
        integrate()

    sim.integrator.integrate = counting_integrate
    with C.Timer() as tm:
        Frame.run(sim)                                  # DustPy's run() minus its mass self-check

    sig = np.array(writer.sigma)
    ref = np.array([C.reference_mass_per_bin(p["kind"], edges, t, coeff=p["coeff"], n0=p["n0"],
                                             m0=p["m0"]) for t in writer.t])
    l1 = [C.rel_l1(s, r) for s, r in zip(sig, ref)]
    return dict(problem=name, bins_per_decade=bins_per_decade, diag_half=diag_half,
                fresh_first_step=fresh_first_step, cfl=cfl, t_out=writer.t, wall_s=tm.seconds,
                steps=steps[0], l1=l1, l1_final=l1[-1], mass_final=float(sig[-1].sum()),
                mass_ref=float(ref[-1].sum()), m=m, edges=edges, mass_per_bin=sig,
                reference_mass_per_bin=ref)


def cases(quick):
    """(problem, bins_per_decade, variant) triples of the run."""
    if quick:
        return [("constant", 7, "notebook"), ("constant", 7, "fixed"),
                ("linear", 7, "fixed"), ("golovin", 8, "fixed")]
    return [("constant", 7, "notebook"), ("constant", 7, "fixed"),
            ("constant", 7, "fixed_cfl1e-2"),
            ("linear", 7, "notebook"), ("linear", 7, "fixed"), ("linear", 7, "fixed_cfl1e-3"),
            ("golovin", 16, "notebook"), ("golovin", 16, "fixed"),
            ("golovin", 16, "fixed_cfl1e-3")]


def plot(results, path):
    """Mass per bin (DustPy vs analytic) at the final time, one panel per problem."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(r["problem"] for r in results))
    fig, axes = plt.subplots(1, len(names), figsize=(4.6 * len(names), 3.8), squeeze=False)
    for ax, name in zip(axes[0], names):
        rs = [r for r in results if r["problem"] == name]
        ref_done = False
        for r in rs:
            m = np.asarray(r["m"])
            if not ref_done:
                ax.loglog(m, r["reference_mass_per_bin"][-1], "k-", lw=2, label="analytic")
                ref_done = True
            ax.loglog(m, r["mass_per_bin"][-1], ".-", ms=3,
                      label=f"{r['variant']} L1={r['l1_final']:.3g}")
        top = max(np.max(r["reference_mass_per_bin"][-1]) for r in rs)
        ax.set_ylim(top * 1e-6, top * 3)
        ax.set_title(f"DustPy {name}, t = {rs[0]['t_out'][-1]:.4g} s")
        ax.set_xlabel("m [g]")
        ax.set_ylabel("mass per bin")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ==============================================================================================
# 1-AU fragmentation box: DustPy vs jaxcoag side by side (growth to the fragmentation barrier)
# ==============================================================================================
# DustPy's own constants (dustpy/constants/constants.f90), so both codes see the same gas.
DUSTPY_M_P = 1.67262192369e-24        # g (DustPy's mean molecular mass is mu = 2.3 m_p)
DUSTPY_M_SUN = 1.988409870698051e33   # g
DUSTPY_G = 6.674299999999999e-08      # cm^3 g^-1 s^-2
DUSTPY_K_B = 1.380649e-16             # erg K^-1
DUSTPY_AU = 1.495978707e13            # cm
DUSTPY_YEAR = 3.15576e7               # s
DUSTPY_SIGMA_H2 = 2.0e-15             # cm^2

#: The box (cgs): MMSN-like gas at 1 AU, DustPy's default alpha and v_frag, 1 um monomers.
FRAG_BOX = dict(
    r_in_au=0.99, r_out_au=1.01,        # 3 radial cells spanning [r_in, r_out]; the middle one is the box
    T=280.0, Sigma_g=1700.0, alpha=1e-3, mu_mp=2.3, sigma_H2=DUSTPY_SIGMA_H2,
    rho_s=1.6, a0=1e-4, dust_to_gas=0.01,
    v_frag=100.0, frag_slope=-11.0 / 6.0, crater_ratio=10.0, excavated=1.0,
    bins_per_decade=7, decades=13, t_end_yr=2000.0,
)

#: DustPy variants of the fragmentation box (see :func:`run_dustpy_frag`).
FRAG_DUSTPY_VARIANTS = {
    "box": dict(vertical="box", cfl=0.1, dv=None),
    "box_cfl1e-2": dict(vertical="box", cfl=0.01, dv=None),
    "box_jaxcoag_dv_cfl1e-2": dict(vertical="box", cfl=0.01, dv="jaxcoag"),
    "column": dict(vertical="column", cfl=0.1, dv=None),
}
#: jaxcoag variants: drag convention, OC07 t* method, dust-to-gas factor.
FRAG_OURS_VARIANTS = {
    "dustpy_conv": dict(convention="dustpy", method="ya", d2g_factor=1.0),
    "ormel_conv": dict(convention="ormel", method="ya", d2g_factor=1.0),
    "dustpy_conv_d2g/sqrt2": dict(convention="dustpy", method="ya", d2g_factor=2.0 ** -0.5),
}
#: threshold of the barrier time: <log10 m>_M within this many dex of its final value
BARRIER_DEX = 0.1
#: times [yr] at which <log10 m>_M is tabulated (growth phase)
GROWTH_TIMES_YR = (20.0, 30.0, 40.0, 50.0)


def frag_box_masses(box=FRAG_BOX):
    """DustPy's mass grid for the box [g]: m_i = m0 10^(i/bpd), i = 0 .. decades*bpd (DustPy's
    ``_makemassgrid`` with mmin = m0 and mmax a hair below m0 10^decades, so that its
    ceil(decades) stays exact)."""
    m0 = 4.0 / 3.0 * np.pi * box["rho_s"] * box["a0"] ** 3
    n = int(box["decades"] * box["bins_per_decade"]) + 1
    return np.logspace(np.log10(m0), np.log10(m0 * 10.0 ** (box["decades"] - 1e-9)), num=n, base=10.0)


def frag_box_gas(box=FRAG_BOX):
    """Gas numbers of DustPy's middle cell: r [cm], Omega [s^-1], c_s [cm s^-1], H_p [cm],
    rho_g = Sigma_g/(sqrt(2 pi) H_p) [g cm^-3], computed with DustPy's formulas and constants."""
    ri = np.logspace(np.log10(box["r_in_au"] * DUSTPY_AU), np.log10(box["r_out_au"] * DUSTPY_AU), num=4)
    r = 0.5 * (ri[1] + ri[2])
    omega = np.sqrt(DUSTPY_G * DUSTPY_M_SUN / r ** 3)
    cs = np.sqrt(DUSTPY_K_B * box["T"] / (box["mu_mp"] * DUSTPY_M_P))
    hp = cs / omega
    rho = box["Sigma_g"] / (np.sqrt(2.0 * np.pi) * hp)
    return dict(r=float(r), Omega=float(omega), cs=float(cs), Hp=float(hp), rho_g=float(rho))


def frag_crater_ratio(m, box=FRAG_BOX):
    """Our ``Shattering.crater_ratio`` reproducing DustPy's erosion rule on grid ``m``.

    DustPy erodes when the bin index difference exceeds p = floor(log10(crater_ratio)/a),
    a = log10 of the grid ratio (``coagulation_parameters``), i.e. from p + 1 bins apart; our
    rule is a mass ratio: put it half a bin above p bins.
    """
    a = np.log10(m[0] / m[-1]) / (1.0 - m.size)
    p = np.floor(np.log10(box["crater_ratio"]) / a)
    return float(10.0 ** ((p + 0.5) * a))


def mean_log_mass(mass_per_bin, m):
    """Mass-weighted mean log10 m [log10 g] of mass-per-bin rows (..., nbins)."""
    w = np.asarray(mass_per_bin, dtype=np.float64)
    return np.sum(w * np.log10(m), axis=-1) / np.sum(w, axis=-1)


def barrier_time(t, lmean, dex=BARRIER_DEX):
    """First time [same unit as t] at which <log10 m>_M comes within ``dex`` of its final value
    (linear interpolation between records); None if never."""
    t = np.asarray(t, dtype=np.float64)
    lmean = np.asarray(lmean, dtype=np.float64)
    target = lmean[-1] - dex
    above = np.nonzero(lmean >= target)[0]
    if above.size == 0:
        return None
    k = int(above[0])
    if k == 0:
        return float(t[0])
    f = (target - lmean[k - 1]) / (lmean[k] - lmean[k - 1])
    return float(t[k - 1] + f * (t[k] - t[k - 1]))


def normalised(mass_per_bin):
    """Mass per bin divided by its total: m^2 f(m) on a log grid, up to a constant."""
    x = np.asarray(mass_per_bin, dtype=np.float64)
    return x / np.sum(x)


def frag_compare(mass, mass_ref):
    """(relative L1 of the normalised m^2 f(m), peak offset in bins) of two steady states."""
    a, b = normalised(mass), normalised(mass_ref)
    return float(np.sum(np.abs(a - b))), int(np.argmax(a)) - int(np.argmax(b))


def ours_frag_kernel(m, *, convention="dustpy", method="ya", box=FRAG_BOX):
    """jaxcoag's kernel of the box on grid ``m``: Brownian + OC07 turbulence, gas of DustPy's
    middle cell with DustPy's gas conventions (mu = 2.3 m_p, sigma_H2, Re = alpha Sigma_g
    sigma_H2/(2 mu m_p), i.e. ``nu_m_divisor = sqrt(pi/2)``), drag ``convention``.

    Returns (SceneKernel, gas dict of :func:`frag_box_gas`).
    """
    from jaxcoag import constants as JC
    from jaxcoag import effects as E
    from jaxcoag.physics import gas as G
    from jaxcoag.scene import Scene

    g = frag_box_gas(box)
    gas = G.midplane_state(g["rho_g"], box["T"], box["alpha"], g["Omega"], R=g["r"],
                           mu=box["mu_mp"] * DUSTPY_M_P / JC.m_H, sigma_mol=box["sigma_H2"],
                           nu_m_divisor=float(np.sqrt(np.pi / 2.0)))
    scene = Scene(velocities=(E.Brownian(), E.TurbulenceOC07(method=method)), drag_convention=convention,
                  name="frag1au_box")
    return scene.kernel(gas, rho_s=box["rho_s"]), g


def ours_frag_box(m, *, convention="dustpy", method="ya", d2g_factor=1.0, ts_yr=None, box=FRAG_BOX,
                  rtol=1e-6, atol=1e-10):
    """jaxcoag's two-bin engine on the box (grid centred on DustPy's masses ``m``).

    Fragmentation: ``Shattering`` with DustPy's Maxwellian probability, fragment slope, erosion
    rule (:func:`frag_crater_ratio`) and excavated mass; the engine's implicit default (Rodas4 since
    2026-11-26; the committed frag1au results were taken with Kvaerno5 + Newton). Start: all dust
    (rho_d = dust_to_gas d2g_factor rho_g) in the monomer bin at t = 0.

    Returns a dict: t [s], mass_per_bin (nt, nbins) [g cm^-3], wall_s (first call, includes
    compilation), steps, mass_drift, St (nbins,) and the kernel.
    """
    import jax.numpy as jnp
    import jaxcoag
    from jaxcoag import Binned, MassGrid
    from jaxcoag.binned.grid import monodisperse
    from jaxcoag.outcomes import Shattering

    K, g = ours_frag_kernel(m, convention=convention, method=method, box=box)
    lm = np.log10(m)
    dl = float(np.mean(np.diff(lm)))
    grid = MassGrid.from_edges(10.0 ** np.concatenate([[lm[0] - dl / 2], 0.5 * (lm[1:] + lm[:-1]),
                                                        [lm[-1] + dl / 2]]))
    frag = Shattering(box["v_frag"], q=-box["frag_slope"], probability="maxwellian",
                      crater_ratio=frag_crater_ratio(m, box), chi=box["excavated"])
    n0 = monodisperse(grid, float(m[0]), box["dust_to_gas"] * d2g_factor * g["rho_g"])
    if ts_yr is None:
        ts_yr = np.geomspace(1.0, box["t_end_yr"], 300)
    ts = np.concatenate([[0.0], np.asarray(ts_yr, dtype=np.float64) * DUSTPY_YEAR])
    with C.Timer() as tm:
        # solver=None: the engine's choice with fragmentation (Rodas4)
        sol = jaxcoag.evolve(K, Binned(grid, rtol=rtol, atol=atol), n0, ts, outcome=frag)
        mass = np.asarray(sol.mass_per_bin())
    st = np.asarray(K.particles(jnp.asarray(m)).st)
    return dict(t=ts, mass_per_bin=mass, wall_s=tm.seconds, steps=int(sol.stats["steps"]),
                mass_drift=float(np.max(np.abs(np.asarray(sol.mass_drift)))), St=st, kernel=K)


def run_dustpy_frag(*, vertical="box", cfl=0.1, dv=None, box=FRAG_BOX, snapshots_yr=None):
    """DustPy on the 1-AU fragmentation box.

    Set-up: 3 radial cells in [0.99, 1.01] AU (DustPy integrates only the middle one; its
    diffusivity is zero in the first and last two cells), gas T, Sigma_g and alpha set in all
    cells, the gas instruction removed from the integrator, gas sources and the dust radial
    velocity set to 0, relative velocities from radial and azimuthal drift set to 0 (a box has no
    drift), dust start: all mass in the monomer bin. The integrator's finaliser is DustPy's
    *dust* finaliser only: DustPy's default (``std.sim.finalize_implicit_dust``) also calls the
    gas finaliser, which re-applies the gas boundary conditions after every step (Sigma_g of the
    ghost cells goes 1700 -> 3400 and 1e-100 g cm^-2 here) and so changes the middle cell's
    pressure gradient eta (x50 here), i.e. any drift velocity.

    ``vertical``: "box" makes DustPy's vertically integrated kernel the midplane box kernel:
    dust scale heights fixed at H_p/sqrt(2) for every size (K = sigma dv / (sqrt(2 pi) H_p)) and no
    settling velocity; then Sigma_d/(sqrt(2 pi) H_p) evolves exactly like a midplane box of
    dust density dust_to_gas rho_g. "column" keeps DustPy's own vertical structure (Dubrulle
    et al. 1995 scale heights, K ~ 1/sqrt(2 pi (h_i^2 + h_j^2)), vertical settling velocity).
    ``cfl``: DustPy's step-size factor (default 0.1). ``dv``: None (DustPy's relative
    velocities) or an (Nm, Nm) matrix [cm/s] to impose (e.g. jaxcoag's). ``snapshots_yr``: DustPy's
    snapshot times [yr] (its steps land on them; default: the end time only).

    Returns a dict: t [s] after every step, mass_per_bin (steps, Nm) [g cm^-2] (middle cell),
    m, St, vrel (Nm, Nm) at t = 0, gas numbers, wall_s, steps.
    """
    from dustpy import Simulation, std
    from simframe import Frame

    sim = Simulation()
    sim.verbosity = 0
    sim.ini.grid.Nr = 3
    sim.ini.grid.rmin = box["r_in_au"] * DUSTPY_AU
    sim.ini.grid.rmax = box["r_out_au"] * DUSTPY_AU
    m_expected = frag_box_masses(box)
    sim.ini.grid.mmin = float(m_expected[0])
    sim.ini.grid.mmax = float(m_expected[0] * 10.0 ** (box["decades"] - 1e-9))
    sim.ini.grid.Nmbpd = box["bins_per_decade"]
    sim.ini.gas.alpha = box["alpha"]
    sim.ini.gas.mu = box["mu_mp"] * DUSTPY_M_P
    sim.ini.dust.rhoMonomer = box["rho_s"]
    sim.ini.dust.vFrag = box["v_frag"]
    sim.ini.dust.fragmentDistribution = box["frag_slope"]
    sim.ini.dust.erosionMassRatio = box["crater_ratio"]
    sim.ini.dust.excavatedMass = box["excavated"]
    sim.initialize()
    m = np.array(sim.grid.m, dtype=np.float64)
    if m.size != m_expected.size or np.max(np.abs(m / m_expected - 1.0)) > 1e-12:
        raise RuntimeError("DustPy's mass grid differs from frag_box_masses()")

    sim.gas.T.updater = None
    sim.gas.T[...] = box["T"]
    sim.gas.Sigma[...] = box["Sigma_g"]
    del sim.integrator.instructions[1]                  # no gas evolution
    sim.gas.S.tot[...] = 0.0
    sim.gas.S.tot.updater = None
    sim.dust.v.rad[...] = 0.0                           # no radial transport
    sim.dust.v.rad.updater = None
    zero = ("rad", "azi") + (("vert",) if vertical == "box" else ())
    for name in zero:
        f = getattr(sim.dust.v.rel, name)
        f[...] = 0.0
        f.updater = None
    sim.integrator.finalizer = std.dust.finalize_implicit   # dust only: no gas boundary re-application
    sim.update()
    if vertical == "box":
        sim.dust.H.updater = None
        sim.dust.H[...] = (np.asarray(sim.gas.Hp) / np.sqrt(2.0))[:, None]
    elif vertical != "column":
        raise ValueError(vertical)
    if dv is not None:
        sim.dust.v.rel.tot.updater = None
        sim.dust.v.rel.tot[...] = np.asarray(dv, dtype=np.float64)[None, :, :]
    sim.dust.Sigma[...] = 0.1 * np.asarray(sim.dust.SigmaFloor)
    sim.dust.Sigma[:, 0] = box["dust_to_gas"] * np.asarray(sim.gas.Sigma)
    sim.update()
    sim.dust.S.coag.update()                            # fresh sources for the first step size
    sim.dust.S.tot.update()
    sim.t.cfl = cfl
    snaps = [box["t_end_yr"]] if snapshots_yr is None else list(snapshots_yr)
    sim.t.snapshots = np.array(snaps, dtype=np.float64) * DUSTPY_YEAR
    sim.writer = None
    gas = dict(r=float(sim.grid.r[1]), Omega=float(sim.grid.OmegaK[1]), cs=float(sim.gas.cs[1]),
               Hp=float(sim.gas.Hp[1]), rho_g=float(sim.gas.rho[1]), mfp=float(sim.gas.mfp[1]))
    St = np.array(sim.dust.St[1], dtype=np.float64)
    vrel = np.array(sim.dust.v.rel.tot[1], dtype=np.float64)

    rec_t, rec_s = [], []
    integrate = sim.integrator.integrate

    def recording_integrate():
        integrate()
        rec_t.append(float(sim.t) + float(sim.t._prevstepsize))
        rec_s.append(np.array(sim.dust.Sigma[1, :], dtype=np.float64))

    sim.integrator.integrate = recording_integrate
    s0 = np.array(sim.dust.Sigma[1, :], dtype=np.float64)
    with C.Timer() as tm:
        Frame.run(sim)
    t = np.concatenate([[0.0], rec_t])
    mass = np.vstack([s0[None, :], np.array(rec_s)])
    return dict(t=t, mass_per_bin=mass, m=m, St=St, vrel=vrel, gas=gas, wall_s=tm.seconds,
                steps=len(rec_t), mass_error=float(abs(mass[-1].sum() / mass[0].sum() - 1.0)))


def _frag_summary(name, code, t, mass, m, ref_final):
    yr = DUSTPY_YEAR
    lmean = mean_log_mass(mass, m)
    l1, dpeak = frag_compare(mass[-1], ref_final)
    row = dict(run=name, code=code, t_barrier_yr=barrier_time(t / yr, lmean),
               logm_final=float(lmean[-1]), peak_bin=int(np.argmax(mass[-1])),
               peak_m=float(m[int(np.argmax(mass[-1]))]), L1_vs_dustpy_box=l1, dpeak_bins=dpeak)
    for ty in GROWTH_TIMES_YR:
        row[f"logm_{ty:g}yr"] = float(np.interp(ty * yr, t, lmean))
    return row, lmean


def run_frag_benchmark(quick=False, box=FRAG_BOX):
    """Both codes on the 1-AU fragmentation box; returns (rows, payload) for the table and JSON.

    The reference steady state is DustPy's "box" variant at its default cfl = 0.1.
    Quick mode: the matched pair only (DustPy box, jaxcoag with DustPy's drag convention).
    """
    C.ensure_x64()
    import jax.numpy as jnp

    box = dict(box)
    m = frag_box_masses(box)
    dp_names = ["box"] if quick else list(FRAG_DUSTPY_VARIANTS)
    our_names = ["dustpy_conv"] if quick else list(FRAG_OURS_VARIANTS)

    ours, dps = {}, {}
    for name in our_names:
        ours[name] = ours_frag_box(m, box=box, **FRAG_OURS_VARIANTS[name])
        print(f"jaxcoag {name:24s} steps={ours[name]['steps']} wall={ours[name]['wall_s']:.1f}s "
              "(incl. compile)", flush=True)
    # second call of the matched run: wall time without compilation
    with C.Timer() as tm:
        ours_frag_box(m, box=box, **FRAG_OURS_VARIANTS["dustpy_conv"])
    ours["dustpy_conv"]["wall_s_warm"] = tm.seconds
    K = ours["dustpy_conv"]["kernel"]
    mj = jnp.asarray(m)
    dv_ours = np.sqrt(np.asarray(K.relative_velocity2(mj[:, None], mj[None, :])))
    for name in dp_names:
        v = dict(FRAG_DUSTPY_VARIANTS[name])
        if v["dv"] == "jaxcoag":
            v["dv"] = dv_ours
        dps[name] = run_dustpy_frag(box=box, **v)
        print(f"dustpy  {name:24s} steps={dps[name]['steps']} wall={dps[name]['wall_s']:.1f}s", flush=True)

    ref = dps["box"]["mass_per_bin"][-1]
    rows, series = [], {}
    for name, r in dps.items():
        row, lmean = _frag_summary(name, "dustpy", r["t"], r["mass_per_bin"], m, ref)
        row.update(steps=r["steps"], wall_s=r["wall_s"], cfl=FRAG_DUSTPY_VARIANTS[name]["cfl"])
        rows.append(row)
        series[f"dustpy/{name}"] = dict(t_yr=r["t"] / DUSTPY_YEAR, logm=lmean, final=r["mass_per_bin"][-1])
    for name, r in ours.items():
        row, lmean = _frag_summary(name, "jaxcoag", r["t"], r["mass_per_bin"], m, ref)
        row.update(steps=r["steps"], wall_s=r["wall_s"], wall_warm_s=r.get("wall_s_warm"))
        rows.append(row)
        series[f"jaxcoag/{name}"] = dict(t_yr=r["t"] / DUSTPY_YEAR, logm=lmean, final=r["mass_per_bin"][-1])

    dp0 = dps["box"]
    g_ours = frag_box_gas(box)
    cols = [0, 20, 40, 60, 80, m.size - 1]
    checks = dict(
        gas_rel_diff={k: abs(g_ours[k] / dp0["gas"][k] - 1.0) for k in ("Omega", "cs", "Hp", "rho_g")},
        St_rel_diff_dustpy_conv=float(np.max(np.abs(ours["dustpy_conv"]["St"] / dp0["St"] - 1.0))),
        dv_ratio_jaxcoag_over_dustpy=dict(min=float(np.min(dv_ours / dp0["vrel"])),
                                          max=float(np.max(dv_ours / dp0["vrel"]))),
    )
    if "ormel_conv" in ours:
        checks["St_ratio_ormel_over_dustpy"] = dict(min=float(np.min(ours["ormel_conv"]["St"] / dp0["St"])),
                                                    max=float(np.max(ours["ormel_conv"]["St"] / dp0["St"])))
    payload = dict(
        benchmark="dustpy_boxes_frag1au", quick=quick, box=box, gas=g_ours, m=m,
        crater_ratio_ours=frag_crater_ratio(m, box), barrier_dex=BARRIER_DEX,
        dustpy_variants={k: {kk: (vv if kk != "dv" else (None if vv is None else "jaxcoag dv matrix"))
                             for kk, vv in FRAG_DUSTPY_VARIANTS[k].items()} for k in dp_names},
        ours_variants={k: FRAG_OURS_VARIANTS[k] for k in our_names},
        dustpy_reference=dict(St=dp0["St"], vrel_columns=cols, vrel=dp0["vrel"][:, cols], gas=dp0["gas"],
                              final_mass_per_bin=dp0["mass_per_bin"][-1], mass_error=dp0["mass_error"]),
        checks=checks, rows=rows, series=series)
    return rows, payload


def plot_frag(payload, path):
    """Steady-state m^2 f(m) (normalised mass per bin) and <log10 m>_M(t) of every run."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = np.asarray(payload["m"])
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for key, s in payload["series"].items():
        ls = "-" if key.startswith("dustpy") else "--"
        a1.semilogx(m, normalised(s["final"]), ls, lw=1.3, label=key)
        a2.semilogx(np.maximum(np.asarray(s["t_yr"]), 1e-2), s["logm"], ls, lw=1.3, label=key)
    a1.set_xlabel("m [g]")
    a1.set_ylabel("m^2 f(m) (mass per bin / total)")
    a1.set_xlim(m[0], 1e1)
    a1.set_title(f"steady state, t = {payload['box']['t_end_yr']:g} yr")
    a1.legend(fontsize=7)
    a2.set_xlabel("t [yr]")
    a2.set_ylabel("<log10 m>_M [log10 g]")
    a2.set_xlim(1.0, payload["box"]["t_end_yr"])
    a2.set_title("growth to the fragmentation barrier")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="few cheap cases (about a minute)")
    ap.add_argument("--problems", default="constant,linear,golovin",
                    help="comma list of constant, linear, golovin (analytic boxes, DustPy only) and "
                         "frag1au (1-AU fragmentation box, DustPy and jaxcoag side by side)")
    ap.add_argument("--out", default=None, help="JSON path (default benchmarks/results/...)")
    args = ap.parse_args(argv)
    wanted = set(args.problems.split(","))
    unknown = wanted - {"constant", "linear", "golovin", "frag1au"}
    if unknown:
        ap.error(f"unknown problem(s) {sorted(unknown)}")
    tag = "_quick" if args.quick else ""
    if "frag1au" in wanted:
        wanted.discard("frag1au")
        rows, payload = run_frag_benchmark(quick=args.quick)
        C.print_table(rows, ["code", "run", "cfl", "steps", "wall_s", "wall_warm_s", "t_barrier_yr",
                             *[f"logm_{t:g}yr" for t in GROWTH_TIMES_YR], "logm_final", "peak_bin",
                             "L1_vs_dustpy_box", "dpeak_bins"],
                      title=("1-AU fragmentation box: t_barrier = first time <log10 m>_M is within "
                             f"{BARRIER_DEX} dex of its final value; L1 of normalised m^2 f(m) at "
                             f"{FRAG_BOX['t_end_yr']:g} yr vs DustPy 'box' (cfl 0.1)"))
        print("checks:", payload["checks"])
        payload["machine"] = C.machine_info()
        out = (pathlib.Path(args.out) if args.out and not wanted
               else C.RESULTS / f"dustpy_boxes_frag1au{tag}.json")
        C.write_json(out, payload)
        png = out.with_suffix(".png")
        plot_frag(payload, png)
        print(f"wrote {out} and {png}")
        if not wanted:
            return rows
    results = []
    for name, bpd, variant in cases(args.quick):
        if name not in wanted:
            continue
        r = run_dustpy(name, bins_per_decade=bpd, **VARIANTS[variant])
        r["variant"] = variant
        results.append(r)
        print(f"dustpy {name:8s} {bpd:2d}/dec {variant:14s} L1={r['l1_final']:.4g} "
              f"steps={r['steps']} wall={r['wall_s']:.2f}s", flush=True)
    C.print_table(results, ["problem", "bins_per_decade", "variant", "cfl", "steps", "wall_s",
                            "l1_final"], title="DustPy boxes (relative L1 of mass per bin, final time)")
    out = pathlib.Path(args.out) if args.out else C.RESULTS / f"dustpy_boxes{tag}.json"
    slim = [{k: v for k, v in r.items() if k not in ("m",)} for r in results]
    C.write_json(out, dict(benchmark="dustpy_boxes", quick=args.quick, machine=C.machine_info(),
                           problems={n: problem(n) for n in wanted}, variants=VARIANTS,
                           results=slim))
    png = out.with_suffix(".png")
    plot(results, png)
    print(f"wrote {out} and {png}")
    return results


if __name__ == "__main__":
    main()
