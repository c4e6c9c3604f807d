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

Variants (DESIGN.md §5 lists the pitfalls):

* ``notebook``: exactly the notebook's recipe at DustPy defaults: hand-set kernel without
  DustPy's 1/2 on the diagonal, coagulation sources not refreshed after the hand set-up (the
  first implicit step is sized from stale sources and is unbounded), cfl = 0.1.
* ``fixed``: diagonal 1/2 restored and sources refreshed before the run, cfl = 0.1.
* ``fixed_cfl1e-2``, ``fixed_cfl1e-3``: as ``fixed`` with cfl = 0.01 or 0.001 (the constant
  box runs only cfl = 0.01: 0.001 would take ~10^5 steps).

Returns/records mass per bin at the output times on DustPy's grid, wall time of the
integration (DustPy's mass-conservation self-check is excluded), number of steps, and the
relative L1 error against the analytic solution (see :mod:`benchmarks._common`).

Run: ``python benchmarks/peers/dustpy_boxes.py [--quick] [--problems constant,linear,golovin]``.
Writes ``benchmarks/results/dustpy_boxes[_quick].json`` and a PNG.
References: Stammler & Birnstiel (2022) ApJ 935, 35 (DustPy); Shima et al. (2009) QJRMS 135,
1307; Golovin (1963); Scott (1968).
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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="few cheap cases (about a minute)")
    ap.add_argument("--problems", default="constant,linear,golovin")
    ap.add_argument("--out", default=None, help="JSON path (default benchmarks/results/...)")
    args = ap.parse_args(argv)
    wanted = set(args.problems.split(","))
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
    tag = "_quick" if args.quick else ""
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
