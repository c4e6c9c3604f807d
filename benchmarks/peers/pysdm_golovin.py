"""PySDM (super-droplet method, Numba CPU backend) on the Shima et al. (2009) Golovin box.

Problem (Shima et al. 2009, §5.1; PySDM's own ``Shima_et_al_2009`` example settings):
n0 = 2^23 m^-3, exponential volume spectrum with mean radius 30.531 um (mean volume
X0 = 4/3 pi r^3), Golovin kernel K = b (v1 + v2) with b = 1500 s^-1, box volume 1e6 m^3,
time step 1 s, constant-multiplicity deterministic initial sampling, outputs at 1200, 2400 and
3600 s. Metric: relative L1 of dm/dlnr on 128 logarithmic radius bins from 10 um to 5 mm
against the bin-averaged analytic Golovin solution (water density 1 g cm^-3):
``L1 = sum_b |s_b - a_b| / sum_b a_b`` (bins are uniform in ln r).

Wall time excludes Numba compilation: PySDM compiles per ``Formulae`` instance, so each run
takes its first 1-s step untimed (reported in ``build_s``) and times the remaining 3599 steps;
a small warm-up run first compiles the shared kernels (``compile_s``).

Run: ``python benchmarks/peers/pysdm_golovin.py [--quick] [--nsd 13,15,17] [--seeds 2]``.
Writes ``benchmarks/results/pysdm_golovin[_quick].json`` and a PNG.
References: Shima et al. (2009) QJRMS 135, 1307; Bartman et al. (2022) JOSS 7, 3219 (PySDM);
Golovin (1963).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2]))

from benchmarks import _common as C  # noqa: E402

N0_SI = 2.0 ** 23                  # m^-3
R_MEAN_UM = 30.531                 # um
B_SI = 1500.0                      # s^-1 (per volume)
DV_SI = 1e6                        # m^3 (box volume, as in Shima et al. 2009)
DT_SI = 1.0                        # s
TIMES = (1200.0, 2400.0, 3600.0)   # s
RHO_W = 1.0                        # g cm^-3
R_EDGES_CM = np.logspace(np.log10(10e-4), np.log10(5000e-4), 129)   # 10 um .. 5 mm


def golovin_reference_dm_dlnr(t, r_edges_cm=R_EDGES_CM):
    """Bin-averaged analytic dm/dlnr [g cm^-3] of the Shima Golovin box at time t [s].

    In mass units K = b/rho_w (m1 + m2) = 1500 (m1 + m2) cm^3 s^-1 g^-1 for rho_w = 1 g cm^-3;
    n0 = 2^23 m^-3 = 8.388608 cm^-3; m0 = rho_w 4/3 pi (30.531 um)^3.
    """
    m_edges = RHO_W * 4.0 / 3.0 * np.pi * r_edges_cm ** 3
    m0 = RHO_W * 4.0 / 3.0 * np.pi * (R_MEAN_UM * 1e-4) ** 3
    mass = C.mass_per_bin_sum_exp(m_edges, t, coeff=B_SI / RHO_W, n0=N0_SI * 1e-6, m0=m0)
    return mass / np.diff(np.log(r_edges_cm))


def golovin_reference_dm_dlnr_monodisperse(t, r_edges_cm=R_EDGES_CM):
    """Bin-averaged analytic dm/dlnr [g cm^-3] for the same box started monodisperse.

    All drops start with the mean mass m0 of the Shima spectrum; the discrete Golovin
    solution n_k (k = mass / m0) is summed over each bin by :func:`jaxcoag.analytic.mass_per_bin`.
    """
    from jaxcoag import analytic
    m_edges = RHO_W * 4.0 / 3.0 * np.pi * r_edges_cm ** 3
    m0 = RHO_W * 4.0 / 3.0 * np.pi * (R_MEAN_UM * 1e-4) ** 3
    mass = np.asarray(analytic.mass_per_bin("sum", m_edges, t, coeff=B_SI / RHO_W,
                                            n0=N0_SI * 1e-6, m0=m0, initial="monodisperse"))
    return mass / np.diff(np.log(r_edges_cm))


def _build(n_sd, seed, initial="exponential"):
    from PySDM import Formulae, Particulator
    from PySDM.backends import CPU
    from PySDM.dynamics import Coalescence
    from PySDM.dynamics.collisions.collision_kernels import Golovin
    from PySDM.environments import Box
    from PySDM.initialisation.sampling.spectral_sampling import ConstantMultiplicity
    from PySDM.initialisation.spectra import Exponential
    from PySDM.physics import si
    from PySDM.products import ParticleVolumeVersusRadiusLogarithmSpectrum

    formulae = Formulae(seed=seed)
    backend = CPU(formulae)
    dv = DV_SI * si.m ** 3
    x0 = formulae.trivia.volume(radius=R_MEAN_UM * si.um)
    spectrum = Exponential(norm_factor=N0_SI / si.m ** 3 * dv, scale=x0)
    if initial == "exponential":
        volume, multiplicity = ConstantMultiplicity(spectrum).sample_deterministic(n_sd)
    elif initial == "monodisperse":
        volume = np.full(n_sd, x0)
        multiplicity = np.full(n_sd, N0_SI / si.m ** 3 * dv / n_sd)
    else:
        raise ValueError(f"initial must be 'exponential' or 'monodisperse', got {initial!r}")
    env = Box(dt=DT_SI * si.s, dv=dv, backend=backend)
    return Particulator(
        n_sd, environment=env,
        attributes={"multiplicity": multiplicity, "volume": volume},
        products=(ParticleVolumeVersusRadiusLogarithmSpectrum(R_EDGES_CM * 1e-2 * si.m,
                                                              name="dv/dlnr"),),
        dynamics=(Coalescence(collision_kernel=Golovin(b=B_SI / si.s)),))


def run_pysdm(n_sd, seed=1, times=TIMES, initial="exponential"):
    """Run the box with ``n_sd`` super-droplets; return dict with spectra, L1, wall time.

    ``initial``: "exponential" (Shima et al. 2009) or "monodisperse" (every drop starts with
    the mean mass; identical to the problem our Monte Carlo engine runs).

    ``dm_dlnr`` [g cm^-3] has shape (len(times), 128); ``wall_s`` is the time-stepping wall
    time of steps 2..N; ``build_s`` covers construction plus the first 1-s step, during which
    Numba compiles the kernels of this Formulae instance (PySDM jit-compiles per instance).
    """
    with C.Timer() as tb:
        p = _build(n_sd, seed, initial)
        p.advance(1)               # Numba specialises per Formulae instance: compile here
        p.products["dv/dlnr"].get()
    spectra, t_now = [], DT_SI
    with C.Timer() as tm:
        for t in times:
            steps = int(round((t - t_now) / DT_SI))
            p.advance(steps)
            t_now = t
            spectra.append(np.array(p.products["dv/dlnr"].get(), dtype=np.float64).ravel()
                           * RHO_W)
    spectra = np.array(spectra)
    ref_fn = (golovin_reference_dm_dlnr if initial == "exponential"
              else golovin_reference_dm_dlnr_monodisperse)
    refs = np.array([ref_fn(t) for t in times])
    l1 = [C.rel_l1(s, r) for s, r in zip(spectra, refs)]
    return dict(code="PySDM", initial=initial, n_sd=n_sd, log2_n_sd=int(round(np.log2(n_sd))), seed=seed,
                t_out=list(times), wall_s=tm.seconds, build_s=tb.seconds, l1=l1,
                l1_final=l1[-1], dm_dlnr=spectra, reference_dm_dlnr=refs)


def warm_up():
    """Compile PySDM's Numba kernels (small run); returns its wall time [s]."""
    with C.Timer() as tw:
        p = _build(2 ** 6, 0)
        p.advance(5)
        p.products["dv/dlnr"].get()
    return tw.seconds


def plot(results, path):
    """dm/dlnr at the output times for the largest n_sd, analytic overlaid; L1 vs n_sd."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    big = max(results, key=lambda r: r["n_sd"])
    r_um = np.sqrt(R_EDGES_CM[1:] * R_EDGES_CM[:-1]) * 1e4
    for i, t in enumerate(big["t_out"]):
        a1.semilogx(r_um, big["reference_dm_dlnr"][i] * 1e6, "k-", lw=1.5)
        a1.semilogx(r_um, big["dm_dlnr"][i] * 1e6, ".", ms=3, label=f"t = {t:.0f} s")
    a1.set_xlabel("radius [um]")
    a1.set_ylabel("dm/dlnr [g m^-3]")
    a1.set_title(f"PySDM n_sd = 2^{big['log2_n_sd']} vs Golovin")
    a1.legend(fontsize=8)
    nsd = np.array([r["n_sd"] for r in results])
    a2.loglog(nsd, [r["l1_final"] for r in results], "o")
    a2.set_xlabel("n_sd")
    a2.set_ylabel("relative L1 of dm/dlnr at 3600 s")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="n_sd = 2^11, 2^13, one seed")
    ap.add_argument("--nsd", default=None, help="comma-separated log2(n_sd) list")
    ap.add_argument("--seeds", type=int, default=None, help="seeds per n_sd")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    log2 = [int(x) for x in args.nsd.split(",")] if args.nsd else (
        [11, 13] if args.quick else [13, 15, 17])
    nseeds = args.seeds or (1 if args.quick else 2)
    compile_s = warm_up()
    print(f"PySDM warm-up (Numba compile) {compile_s:.2f} s", flush=True)
    results = []
    for k in log2:
        for seed in range(1, nseeds + 1):
            r = run_pysdm(2 ** k, seed=seed)
            results.append(r)
            print(f"PySDM n_sd=2^{k} seed={seed} L1(t)={np.round(r['l1'], 4).tolist()} "
                  f"wall={r['wall_s']:.2f}s", flush=True)
    C.print_table(results, ["log2_n_sd", "seed", "wall_s", "l1_final"],
                  title="PySDM Shima/Golovin box: relative L1 of dm/dlnr at 3600 s")
    tag = "_quick" if args.quick else ""
    out = pathlib.Path(args.out) if args.out else C.RESULTS / f"pysdm_golovin{tag}.json"
    C.write_json(out, dict(benchmark="pysdm_golovin", quick=args.quick, compile_s=compile_s,
                           machine=C.machine_info(),
                           problem=dict(n0_m3=N0_SI, r_mean_um=R_MEAN_UM, b_s=B_SI, dv_m3=DV_SI,
                                        dt_s=DT_SI, times_s=TIMES,
                                        r_edges_cm=R_EDGES_CM),
                           results=results))
    plot(results, out.with_suffix(".png"))
    print(f"wrote {out}")
    return results


if __name__ == "__main__":
    main()
