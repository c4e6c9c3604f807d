"""Timed runs of the Richardson (1995) box models and their compact summaries (shared helper).

Used by ``paper_figs/figR04_R08_models.py`` (R95 Figs. 4-8, models ii-iv) and by
``benchmarks/rigid_models.py`` (wall time of models i-iv): one code path runs a model over several seeds,
times the compilation apart (a first run to ``t_out * 1e-6``, the same shapes and static fields as the real
runs, so the real runs reuse its compiled program) and the runs after it, and keeps per run only the
numbers the figures need, as plain lists (JSON-ready):

* per output time: N (live aggregates), N_C, N_C1, coagulations, restitutions, largest and second-largest
  mass / m0 (R95 Figs. 3-5, 7: panels a, b);
* the mass spectrum n_k at the spectrum times (panels c, d; stored sparse as [k, n_k] pairs);
* per live aggregate at the last output: N_a, mass, R_max (R7), density M / ((4/3) pi R_max^3), f_D and its
  regression error (R95 §3; Figs. 6, 8), and f_D from the centre distances (``f_D_centre``: R95 does not say
  whether its sorted distances reach the sphere centres or edges).

Set-up (R95 §3, Table I): spheres of radius r0 = 0.1, box side 10 (N0 / 1000)^(1/3) (R95's number density for
any N0), rms speed v0 = 13 (R95 does not print it; its t_1/2 suggests ~13), seeds = ``jax.random.key(s)``.
Engine: ``RigidBox()`` for the sphere models (i, ii); ``RigidBox(cell_capacity=64, neighbors=64)`` for the
aggregate models (iii, iv: an aggregate packs many spheres into one cell).

References: Richardson (1995, Icarus 115, 320) §3, Table I, eqs. (7), (29)-(32).
"""

from __future__ import annotations

import math
import os
import time

V0 = 13.0
R0 = 0.1


def box_side(n0: int) -> float:
    """Box side [length] keeping R95's number density of 1000 spheres in a box of side 10."""
    return 10.0 * (n0 / 1000.0) ** (1.0 / 3.0)


def default_t_out(T: float, n: int = 20):
    """Output times: n regular intervals up to T plus t = 1.6 T / 8.2 (R95's first spectrum time, Figs. 3-5, 7c)."""
    import numpy as np

    return np.unique(np.concatenate([np.linspace(T / n, T, n), [1.6 * T / 8.2, T]]))


def engine_for(model: str):
    """The engine used for ``model`` (see the module docstring)."""
    from jaxcoag.aggregates import rigid

    if model in ("i", "ii"):
        return rigid.RigidBox()
    return rigid.RigidBox(cell_capacity=64, neighbors=64)


def check_setup(models, n0, seeds, T, spectrum_times=()):
    """Refuse bad input before any work: unknown models, n0 < 2, no seeds, T <= 0, spectrum times outside (0, T]."""
    from jaxcoag._validate import JaxcoagInputError

    bad = [m for m in models if m not in ("i", "ii", "iii", "iv")]
    if bad or not models:
        raise JaxcoagInputError(f"models must be a non-empty subset of i, ii, iii, iv (R95 Table I); got {models!r}.")
    if isinstance(n0, bool) or not isinstance(n0, int) or n0 < 2:
        raise JaxcoagInputError(f"n0 must be an int >= 2; got {n0!r}.")
    if not seeds or any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds):
        raise JaxcoagInputError(f"seeds must be a non-empty list of ints >= 0; got {seeds!r}.")
    if not (math.isfinite(T) and T > 0):
        raise JaxcoagInputError(f"T must be a finite time > 0; got {T!r}.")
    if any(not (0 < s <= T) for s in spectrum_times):
        raise JaxcoagInputError(f"spectrum times must lie in (0, T = {T:g}]; got {list(spectrum_times)!r}.")


def summarize(res, spectrum_idx) -> dict:
    """Compact, JSON-ready numbers of one :class:`BoxResult` (module docstring)."""
    import numpy as np

    from jaxcoag._status import RESULT_NAMES, result_code

    o = res.outs
    M = np.where(np.asarray(o["alive"]), np.asarray(o["M"]), 0.0) / float(res.m0)
    Ms = np.sort(M, axis=-1)
    spec = np.asarray(res.mass_spectrum())
    ag = res.aggregates(-1, include_radius=True)      # edge distances r + R (stored as f_D)
    ag_c = res.aggregates(-1, include_radius=False)   # centre distances (the library default, spec A9)
    out = dict(
        t=np.asarray(res.t).tolist(),
        N=np.asarray(res.n_aggregates).astype(int).tolist(),
        N_C=np.asarray(o["n_c"]).astype(int).tolist(),
        N_C1=np.asarray(o["n_c1"]).astype(int).tolist(),
        n_coag=np.asarray(o["n_coag"]).astype(int).tolist(),
        n_rest=np.asarray(o["n_rest"]).astype(int).tolist(),
        max_mass=Ms[:, -1].tolist(),
        second_mass=Ms[:, -2].tolist(),
        n_steps=int(np.asarray(o["n_steps"])[-1]),
        status=RESULT_NAMES[int(np.asarray(result_code(res.status)))],
        spectra={},
        aggregates=dict({k: np.asarray(ag[k]).tolist() for k in ("n_a", "mass", "Rmax", "rho", "f_D", "f_D_err")},
                        f_D_centre=np.asarray(ag_c["f_D"]).tolist(), f_D_centre_err=np.asarray(ag_c["f_D_err"]).tolist()),
    )
    for i in spectrum_idx:
        nz = np.nonzero(spec[i])[0]
        out["spectra"][f"{float(res.t[i]):.6g}"] = [[int(k + 1), int(spec[i][k])] for k in nz]
    return out


def run_model(model: str, *, n0: int, seeds, T: float, t_out, spectrum_times=(), v0: float = V0,
              verbose: bool = True) -> dict:
    """Run ``model`` for every seed to the outputs ``t_out`` (ending at T) and time it.

    Returns:
        dict with ``model``, ``n0``, ``L``, ``v0``, ``alpha`` (the constant kernel of model i at this v0,
        R95 eq. 29: pi (2 r0)^2 (4/3) v0 / L^3), ``compile_s`` (first call to t_out * 1e-6: compilation plus a
        negligible run), ``run_s`` (list, wall time per seed after compilation), ``load_before``/``load_after``
        (1-min load averages) and ``runs`` (list of :func:`summarize` dicts, one per seed).
    """
    import jax
    import jax.numpy as jnp
    import numpy as np

    from jaxcoag.aggregates import rigid

    check_setup([model], n0, list(seeds), T, spectrum_times)
    t_out = np.asarray(t_out, np.float64)
    sidx = [int(np.argmin(np.abs(t_out - s))) for s in spectrum_times]
    L = box_side(n0)
    eng = engine_for(model)
    load0 = os.getloadavg()[0]
    b = rigid.box_model(model, n0=n0, r0=R0, box=L, v0=v0, key=jax.random.key(int(seeds[0])))
    w = time.perf_counter()
    r = rigid.run(b, jnp.asarray(t_out * 1e-6), engine=eng)
    jax.block_until_ready(r.outs)
    compile_s = time.perf_counter() - w
    if verbose:
        print(f"model {model}: N0 = {n0}, compile (first call to t_out * 1e-6) {compile_s:.1f} s", flush=True)
    runs, run_s = [], []
    for s in seeds:
        b = rigid.box_model(model, n0=n0, r0=R0, box=L, v0=v0, key=jax.random.key(int(s)))
        w = time.perf_counter()
        r = rigid.run(b, jnp.asarray(t_out), engine=eng)
        jax.block_until_ready(r.outs)
        run_s.append(time.perf_counter() - w)
        runs.append(summarize(r, sidx))
        if verbose:
            print(f"model {model}: seed {s}: {run_s[-1]:.1f} s, N(T) = {runs[-1]['N'][-1]}, "
                  f"N_C = {runs[-1]['N_C'][-1]}, steps {runs[-1]['n_steps']}, status {runs[-1]['status']!r}, "
                  f"load {os.getloadavg()[0]:.2f}", flush=True)
    return dict(model=model, n0=n0, L=L, v0=v0, r0=R0, T=float(T), seeds=[int(s) for s in seeds],
                alpha=float(b.alpha), compile_s=compile_s, run_s=run_s, load_before=load0,
                load_after=os.getloadavg()[0], runs=runs)


__all__ = ["V0", "R0", "box_side", "default_t_out", "engine_for", "check_setup", "summarize", "run_model"]
