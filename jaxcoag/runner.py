"""Run a configuration (:mod:`jaxcoag.config`) with its engine: the ``jaxcoag run`` job.

:func:`run` validates and builds everything first (a refused run writes no file), then calls
``jaxcoag.evolve(kernel, engine, initial, t_out, outcome=..., key=..., checkpoint=...)`` with the
engine of ``[run] engine`` (:class:`jaxcoag.Binned` or :class:`jaxcoag.MonteCarlo`), segment by
segment over the output times with checkpoints (:func:`jaxcoag.checkpoint.run_segments`), saves a
netCDF file of the common layout (``result.to_xarray(kernel=..., edges=<[grid] edges>)``: dims
``t``, ``m``, ``m_edge``, the same for every engine; atomic; global attributes record the
configuration as TOML text, its hash, the scene and the gas state) and the standard figure panel
(:func:`jaxcoag.plot.panel`) next to it, and prints a summary table (time, mass peak, peak radius,
Stokes numbers, mass drift).

:func:`quick_config` shrinks a configuration for smoke tests; :func:`kernel_from_dataset` rebuilds
a saved run's kernel (``jaxcoag plot``); :func:`sweep_config` runs a parameter sweep of a
configuration (``jaxcoag sweep``).

References: Stammler & Birnstiel (2022, DustPy) (run / snapshot / panel workflow);
Birnstiel et al. (2012) fragmentation barrier St_frag = v_frag^2 / (3 alpha c_s^2).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time

import numpy as np
import jax.numpy as jnp

from . import config as cfgmod
from . import constants as C
from . import diagnostics
from . import io
from ._validate import JaxcoagInputError

__all__ = ["run", "RunResult", "forward_only", "quick_config", "kernel_from_dataset", "summary_rows",
           "format_summary", "sweep_config", "figure_path", "checkpoint_path", "st_frag", "frag_limited_size",
           "check_writable", "CompileClock"]


class RunResult:
    """What :func:`run` returns.

    Attributes: result (the engine's result: :class:`jaxcoag.BinnedResult` /
    :class:`jaxcoag.MCResult`), dataset (its common-layout ``xarray.Dataset`` on the [grid] bins,
    as written), built (config.Built), path (netCDF or None), figure (PNG path or None),
    checkpoint (path or None), finished (all output times done), failed (a failure status),
    resumed_from (outputs already in the checkpoint when the run started), wall_s [s], timings (dict
    [s]: setup_s = validation and build, solve_s = the evolve call incl. compilation, of which
    compile_s = XLA compile or persistent-cache load and trace_lower_s = tracing and lowering
    (:class:`CompileClock`), output_s = dataset, netCDF, figure and summary, wall_s; binned and
    Monte Carlo runs), rows (list
    of per-output dicts, see :func:`summary_rows`), numbers (dict of headline numbers: final mass
    peak [g], peak radius [cm], St at the peak, max St, |mass drift|, status name, fragmentation-
    barrier estimate St_frag, and the engine's work: solver steps / Monte Carlo events).
    """

    def __init__(self, **kw):
        self.__dict__.update(kw)


def figure_path(nc_path: str) -> str:
    """PNG path of the panel next to a netCDF file (run.nc -> run.png)."""
    root, ext = os.path.splitext(nc_path)
    return root + ".png" if ext else nc_path + ".png"


def checkpoint_path(nc_path: str) -> str:
    """Default checkpoint path next to the netCDF file (run.nc -> run.nc.ckpt.npz)."""
    return nc_path + ".ckpt.npz"


def quick_config(cfg: cfgmod.RunConfig) -> cfgmod.RunConfig:
    """A smaller, faster version of a config for smoke tests (``--quick``): at most 3 bins per
    decade (m_min recomputed so the monomer sits at a bin centre), at most 8 outputs, and rtol >=
    1e-4 (binned) or [mc] ns_target <= 200 (Ns* / Ng*, Monte Carlo); the physics and the time span
    are unchanged."""
    if cfg.engine == "disk":
        from .disk.runs import quick_disk

        return quick_disk(cfg)
    if cfg.engine not in cfgmod.COAGULATION_ENGINES:
        from .aggregates.runs import quick_particles

        return quick_particles(cfg)
    raw = cfg.raw()
    g = raw.setdefault("grid", {})
    g["bins_per_decade"] = min(float(cfg["grid"]["bins_per_decade"]), 3.0)
    g.pop("m_min", None)  # recentre the monomer in the coarser grid
    t = raw.setdefault("time", {})
    if "t_out_yr" not in t:
        t["n_out"] = min(int(cfg["time"]["n_out"]), 8)
    if cfg.engine == "binned":
        s = raw.setdefault("solver", {})
        s["rtol"] = max(float(cfg["solver"]["rtol"]), 1e-4)
    else:
        s = raw.setdefault("mc", {})
        s["ns_target"] = min(int(cfg["mc"]["ns_target"]), 200)
    return cfgmod.from_dict(raw, source=cfg.source + " (quick)")


def _attrs(cfg, built):
    g = built.gas
    a = {"run_name": cfg["run"]["name"], "description": cfg["run"]["description"],
         "config_toml": cfg.to_toml(), "config_hash": cfg.physics_hash(), "config_source": cfg.source,
         "scene": built.scene.name, "effects": ",".join(built.scene.effect_names),
         "gas_model": cfg["gas"]["model"], "rho_s": cfg["dust"]["rho_s"], "a0_cm": cfg["dust"]["a0"],
         "m0_g": cfg["dust"]["m0"], "dust_to_gas": cfg["dust"]["dust_to_gas"],
         "rho_g": float(g.rho_g), "T": float(g.T), "alpha": float(g.alpha), "c_g": float(g.c_g),
         "Omega": float(g.Omega), "Sigma_g": float(g.Sigma_g), "R_cm": float(g.R)}
    if cfg.engine == "binned":
        so = cfg["solver"]
        a.update(scheme=so["scheme"], solver_method=so["method"], rtol=so["rtol"], atol=so["atol"])
    else:
        s = cfg["mc"]
        a.update(mc_grouping=s["grouping"], mc_volume=s["volume"], mc_ns_target=s["ns_target"], mc_seed=s["seed"],
                 mc_f_eps=s["f_eps"])
    fr = cfg["fragmentation"]
    a["fragmentation"] = "none" if fr is None else fr["model"]
    if fr is not None and fr["v_frag"] is not None:
        a["v_frag"] = fr["v_frag"]
    if fr is not None and fr["m_frag"] is not None:
        a["m_frag"] = fr["m_frag"]
    from . import __version__
    a["jaxcoag_version"] = __version__
    return a


def st_frag(built):
    """Fragmentation-barrier Stokes number v_frag^2 / (3 alpha c_s^2) (Birnstiel et al. 2012), or nan."""
    fr = built.cfg["fragmentation"]
    if fr is None or fr["v_frag"] is None or not float(built.gas.alpha) > 0:
        return float("nan")
    return fr["v_frag"] ** 2 / (3.0 * float(built.gas.alpha) * float(built.gas.c_g) ** 2)


def frag_limited_size(kernel, st_target, *, m_lo=1e-30, m_hi=1e30):
    """Mass [g] and radius [cm] of the grain whose Stokes number equals ``st_target`` in the
    kernel's gas state with its own drag law (Epstein / Stokes switch, Ormel 2008 eqs. 4.5, 4.6),
    e.g. the fragmentation-limited size for St_frag = v_frag^2 / (3 alpha c_s^2) (Birnstiel et al.
    2012, eq. 8). St(m) of compact grains increases monotonically with m, so the root is found by
    bracketing on log-spaced masses and refining (relative precision ~1e-13 in m).

    Returns: (m [g], a [cm]); (nan, nan) when st_target is not finite and positive, the kernel
    has no ``particles`` (analytic kernels) or St(m) never reaches st_target in [m_lo, m_hi].
    """
    nan = (float("nan"), float("nan"))
    if kernel is None or not hasattr(kernel, "particles") or int(getattr(kernel, "n_struct", 0)) != 0:
        return nan
    if not (np.isfinite(st_target) and st_target > 0):
        return nan
    lo, hi = np.log(m_lo), np.log(m_hi)
    for _ in range(4):  # bracket width 138 / 1024^4 ~ 1e-10 in ln m
        lm = np.linspace(lo, hi, 1025)
        _, st = io.grain_size_stokes(kernel, np.exp(lm))
        above = np.nonzero(st >= st_target)[0]
        if above.size == 0 or above[0] == 0:
            return nan
        i = int(above[0])
        lo, hi = lm[i - 1], lm[i]
        s_lo, s_hi = float(np.log(st[i - 1])), float(np.log(st[i]))
    # final step: interpolate ln St linearly in ln m inside the last bracket
    lm = lo + (np.log(st_target) - s_lo) / (s_hi - s_lo) * (hi - lo) if s_hi > s_lo else hi
    m = float(np.exp(lm))
    return m, float(io.grain_size_stokes(kernel, m)[0])


def summary_rows(ds, kernel):
    """Per-output summary of a run dataset (common layout): t [yr], mass peak m_p [g] (of the mass
    per ln m), its radius a_p [cm] and St_p, the largest Stokes number and radius among bins holding
    > 1e-3 of the peak mass per ln m, and the mass drift."""
    rho = np.asarray(ds["mass_per_bin"].values, np.float64)
    edges = np.asarray(ds["m_edge"].values, np.float64)
    m = np.asarray(ds["m"].values, np.float64)
    mp_all = np.asarray(diagnostics.mass_peak(rho, edges), np.float64)
    a_both, st_both = io.grain_size_stokes(kernel, np.concatenate([m, mp_all]))  # one call: bins and peaks
    a_all, st_all, a_mp, st_mp = a_both[:m.size], st_both[:m.size], a_both[m.size:], st_both[m.size:]
    y = rho / np.diff(np.log(edges))
    t = np.asarray(ds["t"].values, np.float64)
    drift = np.asarray(ds["mass_drift"].values, np.float64)
    rows = []
    for i in range(rho.shape[0]):
        mp = float(mp_all[i])
        sig = y[i] > 1e-3 * y[i].max()
        rows.append(dict(t_yr=float(t[i]) / C.yr, m_peak=mp, a_peak=float(a_mp[i]), st_peak=float(st_mp[i]),
                         st_max=float(st_all[sig].max()) if sig.any() else float("nan"),
                         a_max=float(a_all[sig].max()) if sig.any() else float("nan"), mass_drift=float(drift[i])))
    return rows


def format_summary(res) -> str:
    """Text table of a :class:`RunResult`."""
    b = res.built
    cfg = b.cfg
    n = res.numbers
    if cfg.engine == "binned":
        solver = getattr(res.result, "solver", "") or b.engine.solver_name(b.outcome)
        eng = f"binned {cfg['solver']['scheme']} scheme on {b.grid.nbins} bins, solver {solver}"
        work = f"{n['steps']} accepted steps ({n['rejected']} rejected)"
    else:
        s = cfg["mc"]
        eng = (f"Monte Carlo, grouping {s['grouping']}, {s['volume']}, ns_target = {s['ns_target']}, seed = {s['seed']}"
               f"; output on {b.grid.nbins} bins")
        work = f"{n['events']} events"
    fr = cfg["fragmentation"]
    if fr is None:
        frag = "pure growth"
    elif fr["model"] == "shattering":
        frag = f"fragmentation shattering v_frag = {fr['v_frag']:g} cm/s (St_frag = {st_frag(b):.3g})"
    else:
        frag = f"fragmentation to_monomers above m_frag = {fr['m_frag']:g} g"
    lines = [f"jaxcoag run '{cfg['run']['name']}' ({eng}): scene {b.scene.name} {tuple(b.scene.effect_names)}, "
             f"{cfg['gas']['model']} gas, alpha = {float(b.gas.alpha):.3g}, rho_g = {float(b.gas.rho_g):.4g} g/cm^3, "
             f"T = {float(b.gas.T):.4g} K",
             f"  dust: a0 = {cfg['dust']['a0']:.3g} cm, rho_s = {cfg['dust']['rho_s']:g} g/cm^3, "
             f"dust/gas = {cfg['dust']['dust_to_gas']:g}; grid {b.grid.nbins} bins "
             f"({cfg['grid']['bins_per_decade']:g}/decade, {b.grid.edges[0]:.3g}..{b.grid.edges[-1]:.3g} g); {frag}",
             f"{'t [yr]':>10} {'m_peak [g]':>11} {'a_peak [cm]':>11} {'St_peak':>9} {'St_max':>9} {'mass drift':>11}"]
    for r in res.rows:
        lines.append(f"{r['t_yr']:10.4g} {r['m_peak']:11.4g} {r['a_peak']:11.4g} {r['st_peak']:9.3g} "
                     f"{r['st_max']:9.3g} {r['mass_drift']:11.2e}")
    lines.append(f"result: {n['result']}; {work}; {n['outputs_done']} of {len(b.t_out)} outputs; wall "
                 f"{res.wall_s:.1f} s" + (f" (resumed after output {res.resumed_from})" if res.resumed_from else ""))
    tm = getattr(res, "timings", None)
    if tm:
        lines.append(f"time: set-up {tm['setup_s']:.1f} s, solve {tm['solve_s']:.1f} s (XLA compile or cache load "
                     f"{tm['compile_s']:.1f} s, trace + lower {tm['trace_lower_s']:.1f} s), output "
                     f"{tm['output_s']:.1f} s")
    if not res.finished and not res.failed:
        lines.append(f"stopped after {n['outputs_done']} of {len(b.t_out)} outputs; continue with --resume")
    for label, p in (("netCDF", res.path), ("figure", res.figure), ("checkpoint", res.checkpoint)):
        if p:
            lines.append(f"{label}: {p}")
    return "\n".join(lines)


def check_writable(path, what="output file", flag="--out"):
    """Refuse (JaxcoagInputError saying what to change) a file path that cannot be written,
    before any computation, without leaving anything behind: the path must not be a directory;
    its directory must exist and accept a new file (probed with a temporary file that is removed
    at once) or be creatable (the nearest existing ancestor is a writable directory).

    Arguments: path; what: name of the file in the message; flag: the option to change.
    """
    p = os.path.abspath(os.fspath(path))
    if os.path.isdir(p):
        raise JaxcoagInputError(f"the {what} {path!r} is a directory; give a file name with {flag}.")
    if os.path.exists(p) and not os.path.isfile(p):
        raise JaxcoagInputError(f"the {what} {path!r} exists and is not a regular file; change {flag}.")
    d = os.path.dirname(p)
    a = d
    while not os.path.exists(a):
        a = os.path.dirname(a)
    if not os.path.isdir(a):
        raise JaxcoagInputError(f"cannot write the {what} {path!r}: {a!r} is a file, not a directory; change {flag}.")
    if a == d:
        try:
            fd, tmp = tempfile.mkstemp(prefix=".jaxcoag-write-test-", dir=d)
            os.close(fd)
            os.remove(tmp)
        except OSError as e:
            raise JaxcoagInputError(f"cannot write the {what} into {d!r} ({e.strerror}); change {flag} or the "
                                    "directory's permissions.") from None
    elif not os.access(a, os.W_OK | os.X_OK):
        raise JaxcoagInputError(f"cannot create the directory of the {what} {path!r}: {a!r} is not writable; "
                                f"change {flag} or the directory's permissions.")


def _makedirs_for(path):
    """Create the directory of ``path`` (checked by :func:`check_writable` beforehand)."""
    d = os.path.dirname(os.path.abspath(path))
    try:
        os.makedirs(d, exist_ok=True)
    except OSError as e:
        raise JaxcoagInputError(f"cannot create the directory {d!r} ({e.strerror}); choose another "
                                "--out / --checkpoint location.") from e


def _as_config(cfg):
    """A RunConfig from None (the built-in default), a TOML path, a dict or a RunConfig."""
    if cfg is None:
        return cfgmod.default()
    if isinstance(cfg, (str, os.PathLike)):
        return cfgmod.load(cfg)
    if isinstance(cfg, dict):
        return cfgmod.from_dict(cfg)
    if not isinstance(cfg, cfgmod.RunConfig):
        raise JaxcoagInputError(f"cfg must be a RunConfig, a TOML path, a dict or None (got {type(cfg).__name__}).")
    return cfg


def _work(cfg, result):
    """The engine's work counters for the summary."""
    if cfg.engine == "binned":
        return dict(steps=int(result.stats["steps"]), rejected=int(result.stats["rejected"]))
    return dict(events=int(np.asarray(result.n_events)))


def run(cfg=None, *, out=None, checkpoint=None, resume=False, progress=True, figure=None, max_segments=None,
        quick=False, verbose=True, save=True) -> RunResult:
    """Run a configuration with its engine: validate, evolve with checkpoints, save netCDF + panel, summarise.

    The run always goes output time by output time (:func:`jaxcoag.checkpoint.run_segments`, one
    segment per output time), with or without a checkpoint file, so an interrupted and resumed run
    equals an uninterrupted one bit for bit, and a run with a checkpoint equals one without.

    Arguments:
        cfg: RunConfig, a TOML path, a dict or None (the built-in default, :func:`config.default`).
        out: netCDF path (default ``[output] path``); the panel PNG goes next to it (run.png).
        checkpoint: checkpoint path; None = ``[output] checkpoint`` or ``<out>.ckpt.npz``;
            False = no checkpoint.
        resume: continue from the checkpoint (refused if it belongs to another configuration;
            starts afresh if there is none); False overwrites an existing checkpoint.
        progress: tqdm bar over the output times (stderr).
        figure: save the panel (default ``[output] figure``).
        max_segments: stop after this many new output times (resume later).
        quick: shrink the config with :func:`quick_config` (tests, smoke runs).
        verbose: print the summary table; save: write the checkpoint, netCDF and PNG (False:
            write nothing at all, no directory either; a checkpoint is still read for ``resume``,
            the run continuing on a temporary copy).

    Returns: :class:`RunResult`. Raises JaxcoagInputError before computing or writing anything
    for a bad configuration, a grid too large for the memory (:func:`config.check_memory`), an
    output location that cannot be written (:func:`check_writable`) or a checkpoint that is
    unreadable, corrupted or from another configuration (with ``resume``). Ctrl-C raises
    :class:`jaxcoag.checkpoint.RunInterrupted` after checkpointing the completed output times.
    """
    from ._status import FAILURES, RESULT_NAMES, result_code
    from .io import save_netcdf

    t_start = time.perf_counter()
    cfg = _as_config(cfg)
    particles = cfg.engine not in cfgmod.COAGULATION_ENGINES
    if quick:
        cfg = quick_config(cfg)
    if not particles:
        cfgmod.check_memory(cfg)  # a grid too large for the memory: refused before anything else
    out = os.fspath(out) if out is not None else cfg["output"]["path"]
    if not out or out.endswith(os.sep) or os.path.isdir(out):
        raise JaxcoagInputError(f"--out must name a netCDF file (e.g. results/run.nc), got {out!r}.")
    if max_segments is not None and (isinstance(max_segments, bool) or not isinstance(max_segments, int)
                                     or max_segments < 1):
        raise JaxcoagInputError(f"--max-segments must be a positive integer, got {max_segments!r}.")
    if figure is None:
        figure = cfg["output"]["figure"]
    if checkpoint is None:
        checkpoint = cfg["output"]["checkpoint"] or checkpoint_path(out)
    elif checkpoint is False:
        checkpoint = None
    else:
        checkpoint = os.fspath(checkpoint)
    if save:  # every output location must be writable before anything is built or computed
        check_writable(out, "netCDF output", "--out")
        if checkpoint:
            check_writable(checkpoint, "checkpoint", "--checkpoint (or use --no-checkpoint)")
    if cfg.engine == "disk":  # [run] engine = "disk": jaxcoag.disk
        from .disk.runs import run_disk

        return run_disk(cfg, out=out, checkpoint=checkpoint, resume=resume, progress=progress, figure=figure,
                        max_segments=max_segments, verbose=verbose, save=save, t_start=t_start)
    if particles:  # [run] engine = "contact" | "rigid": jaxcoag.aggregates
        from .aggregates.runs import run_particles

        return run_particles(cfg, out=out, checkpoint=checkpoint, resume=resume, progress=progress, figure=figure,
                             max_segments=max_segments, verbose=verbose, save=save, t_start=t_start)
    built = cfgmod.build(cfg)
    n_seg = len(built.t_out)
    t_built = time.perf_counter()
    with CompileClock() as clock:
        result, resumed_from = evolve_saved(built.kernel, forward_only(built.engine), built.initial, built.t_out,
                                            outcome=built.outcome, key=built.key, checkpoint=checkpoint, every=1,
                                            resume=resume, progress=progress, max_segments=max_segments, save=save)
    t_solved = time.perf_counter()
    if not save:
        checkpoint = None  # nothing was written
    rname = RESULT_NAMES[int(np.asarray(result_code(result.status)))]
    failed = rname in FAILURES
    n_done = int(np.shape(result.t)[0])
    finished = n_done == n_seg and not failed
    ds = result.to_xarray(kernel=built.kernel, edges=np.asarray(built.grid.edges), attrs=_attrs(cfg, built))
    if failed:  # keep the outputs before the failure (a failed solve leaves NaN/inf at its own output)
        ok = np.all(np.isfinite(ds["mass_per_bin"].values), axis=1)
        k = int(np.argmin(ok)) if not ok.all() else ok.size
        ds = ds.isel(t=slice(0, max(k, 1)))
    rows = summary_rows(ds, built.kernel)
    sf = st_frag(built)
    numbers = dict(m_peak=rows[-1]["m_peak"], a_peak=rows[-1]["a_peak"], st_peak=rows[-1]["st_peak"],
                   st_max=rows[-1]["st_max"], max_abs_mass_drift=float(np.max(np.abs(ds["mass_drift"].values))),
                   result=rname, outputs_done=int(ds.sizes["t"]), st_frag=sf, t_end_yr=rows[-1]["t_yr"], **_work(cfg, result))
    path = fig = None
    if save and (finished or failed):
        ds.attrs["wall_s"] = time.perf_counter() - t_start
        ds.attrs["outputs_done"] = n_done
        m_fr, a_fr = frag_limited_size(built.kernel, sf)
        if np.isfinite(sf):  # fragmentation barrier (Birnstiel et al. 2012): St, mass [g], radius [cm]
            ds.attrs.update(st_frag=sf, m_frag_limit_g=m_fr, a_frag_limit_cm=a_fr)
        _makedirs_for(out)
        path = save_netcdf(ds, out)
        if figure:
            from .plot import panel
            fig = figure_path(out)
            where = (f"n = {cfg['gas']['n']:.3g} cm^-3 cloud core" if cfg["gas"]["model"] == "molecular_cloud"
                     else f"alpha = {float(built.gas.alpha):.2g}, R = {float(built.gas.R) / C.AU:.3g} AU")
            panel(ds, built.kernel, path=fig, title=f"{cfg['run']['name']} ({built.engine.name}): {built.scene.name}, "
                  f"{where}", frag_limit=(m_fr, a_fr, sf) if np.isfinite(m_fr) else None)
    t_end = time.perf_counter()
    timings = dict(setup_s=t_built - t_start, solve_s=t_solved - t_built, compile_s=clock.compile_s,
                   trace_lower_s=clock.trace_lower_s, output_s=t_end - t_solved, wall_s=t_end - t_start)
    res = RunResult(result=result, dataset=ds, built=built, path=path, figure=fig, checkpoint=checkpoint,
                    finished=finished, failed=failed, resumed_from=resumed_from, rows=rows, numbers=numbers,
                    wall_s=t_end - t_start, timings=timings)
    if verbose:
        print(format_summary(res))
    return res


def forward_only(engine):
    """The engine for a run that nothing differentiates (``jaxcoag run``, ``jaxcoag sweep``): its
    ``_forward_only()`` form (the binned engine with its default adjoint solves with ``diffrax.ForwardMode``:
    faster to trace and compile, the same steps; any other engine, or an adjoint the user chose, unchanged)."""
    return engine._forward_only()


class CompileClock:
    """Context manager summing JAX's compile-time events while it is open (``jax.monitoring``
    duration listeners): ``compile_s`` = XLA backend compilation, or loading the executable from the
    persistent compilation cache ("/jax/core/compile/backend_compile_duration"), ``trace_lower_s`` =
    tracing to a jaxpr and lowering to MLIR ("/jax/core/compile/jaxpr_trace_duration",
    ".../jaxpr_to_mlir_module_duration"; nested jits may count twice) [s]. Both are part of the wall
    time of the code inside the block."""

    BACKEND = "/jax/core/compile/backend_compile_duration"
    TRACE = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration")

    def __init__(self):
        self.compile_s = 0.0
        self.trace_lower_s = 0.0

    def _listen(self, event, duration, **kw):
        if event == self.BACKEND:
            self.compile_s += float(duration)
        elif event in self.TRACE:
            self.trace_lower_s += float(duration)

    def __enter__(self):
        import jax.monitoring

        jax.monitoring.register_event_duration_secs_listener(self._listen)
        return self

    def __exit__(self, *exc):
        import jax.monitoring

        jax.monitoring.unregister_event_duration_listener(self._listen)
        return False


def evolve_saved(kernel, engine, initial, t_out, *, outcome=None, key=None, checkpoint, every, resume, progress,
                 max_segments, save):
    """``jaxcoag.evolve`` from t = 0 as ``jaxcoag run`` does it, for every engine: a damaged checkpoint refused
    (``resume``) before anything is written, the checkpoint's directory made, and with ``save=False`` nothing
    written at all (a resumed run continues on a temporary copy of the checkpoint). Returns (result, outputs
    already in the checkpoint when the run started). Ctrl-C raises :class:`jaxcoag.checkpoint.RunInterrupted`."""
    import jax.numpy as jnp

    from . import checkpoint as ckmod
    from ._engine import evolve

    resumed_from = 0
    if resume and checkpoint and os.path.exists(checkpoint):  # refuse a damaged file before writing anything
        resumed_from = int(ckmod.read_info(checkpoint)["n_done"])
    tmpdir = None
    ck_run = checkpoint
    if not save:
        if resume and checkpoint and os.path.exists(checkpoint):  # continue on a copy: the file stays as it was
            tmpdir = tempfile.mkdtemp(prefix="jaxcoag-run-")
            ck_run = os.path.join(tmpdir, os.path.basename(checkpoint))
            shutil.copyfile(checkpoint, ck_run)
        else:
            ck_run = None
    elif checkpoint:  # the netCDF directory is made when the result is saved (none if interrupted)
        _makedirs_for(checkpoint)
    n_seg = -(-len(t_out) // every)
    try:
        result = evolve(kernel, engine, initial, jnp.asarray(t_out), t0=0.0, outcome=outcome, key=key,
                        checkpoint=ck_run, every=every, resume=bool(resume), progress=progress,
                        max_segments=n_seg if max_segments is None else max_segments, throw=False)
    except ckmod.RunInterrupted as e:
        if not save:
            e.checkpoint = None
        raise
    finally:
        if tmpdir is not None:
            shutil.rmtree(tmpdir, ignore_errors=True)
    return result, resumed_from


# ------------------------------------------------------------------ reading saved runs back
def kernel_from_dataset(ds):
    """The physical kernel recorded in a run file's ``config_toml`` attribute, or None."""
    text = ds.attrs.get("config_toml")
    if not text:
        return None
    cfg = cfgmod.loads(str(text), source="netCDF attribute config_toml")
    scene = cfgmod.make_scene(cfg)
    return scene.kernel(cfgmod.make_gas(cfg["gas"]), rho_s=cfg["dust"]["rho_s"])


# ------------------------------------------------------------------------------ sweeps
def _sweep_name(name):
    """'alpha' or 'gas.alpha' -> ('gas.alpha', 'alpha'); checked against config.SWEEPABLE."""
    by_key = {s.split(".")[1]: s for s in cfgmod.SWEEPABLE}
    dotted = name if "." in name else by_key.get(name)
    if dotted not in cfgmod.SWEEPABLE:
        import difflib
        m = difflib.get_close_matches(name, list(by_key) + list(cfgmod.SWEEPABLE), n=1)
        raise JaxcoagInputError(f"cannot sweep {name!r}; sweepable parameters: {sorted(by_key)} (or section.key)."
                                + (f" Did you mean {m[0]!r}?" if m else ""))
    return dotted, dotted.split(".")[1]


def sweep_config(cfg, params: dict, *, chunk=1, workers=None, quick=False, verbose=True, out=None, progress=None,
                 figure=True):
    """Sweep scalar parameters of a configuration (outer product) in one compiled program (binned engine).

    Arguments:
        cfg: RunConfig / TOML path / dict / None (default run); ``[run] engine`` must be "binned".
        params: dict name -> list of values; names are keys of :data:`config.SWEEPABLE`
            ("alpha", "v_frag", "rho_s", ... or "gas.alpha"). Every member is validated as a
            config first (a bad value is refused before any computation). Sweeping rho_s keeps
            the monomer *mass* (so the grid) fixed.
        chunk: members integrated at once (``jaxcoag.sweep.sweep`` chunk; 1 = one after the
            other, each with its own adaptive steps - implicit solvers batch poorly, docs/design_notes.md).
        workers: members (or chunks) integrated at the same time in host threads (``jaxcoag.sweep.sweep``
            workers); None = the number of cores (``os.cpu_count()``) when ``chunk`` is 1, else 1.
        quick: shrink the config first (:func:`quick_config`); out: netCDF path to save.
        progress: tqdm bar over the members on stderr (default: as ``verbose``); the members
            then run in blocks of ``chunk`` from Python (:func:`jaxcoag.sweep.sweep`).
        figure: with ``out``, also save :func:`jaxcoag.plot.sweep_panel` next to it (sweep.png).

    Returns: (xarray.Dataset, list of row dicts). The dataset holds mass_per_bin (params..., t,
    m), status per member, ``mass_peak`` [g] at the last output time, the grain radius ``a`` [cm]
    and Stokes number ``St`` [1] of the bin centres per member (params..., m; from each member's
    kernel, i.e. its rho_s and gas state), coords ``t`` [s] and ``t_yr`` [yr], and the config.
    The figure path is ``ds.attrs["figure"]`` when one was saved.
    """
    from . import sweep as swmod
    from ._engine import evolve
    from ._status import RESULT_NAMES

    cfg = _as_config(cfg)
    if quick:
        cfg = quick_config(cfg)
    if cfg.engine != "binned":
        raise JaxcoagInputError(f"[run] engine = {cfg.engine!r}: `jaxcoag sweep` runs the binned engine; use "
                                "--set run.engine=binned (or sweep Monte Carlo runs with jaxcoag.sweep over keys).")
    if not params:
        raise JaxcoagInputError("give at least one --param name=v1,v2,... to sweep.")
    if out is not None:  # an unwritable output is refused before the sweep is computed
        check_writable(out, "netCDF output", "--out")
        if figure:
            check_writable(figure_path(os.fspath(out)), "sweep figure", "--out (or use --no-figure)")
    params = dict(params)
    names = {}
    for k, vals in params.items():
        dotted, short = _sweep_name(k)
        if short in names.values():
            raise JaxcoagInputError(f"parameter {short!r} given twice.")
        vals = [float(v) for v in vals]
        if not vals:
            raise JaxcoagInputError(f"parameter {k!r} has no values.")
        for v in vals:  # every member must be a valid config
            cfgmod.build(cfg.replace(**{dotted: v}))
        names[dotted] = short
        params[k] = vals
    built = cfgmod.build(cfg)
    frag0 = cfg["fragmentation"]
    if any(d.startswith("fragmentation.") for d in names) and frag0 is None:
        raise JaxcoagInputError("the config has no [fragmentation] section; nothing to sweep there.")
    rho_g0 = float(built.gas.rho_g)
    n_unit = np.asarray(built.n0) / (cfg["dust"]["dust_to_gas"] * rho_g0)  # per unit dust density
    scene = built.scene
    grid = built.grid
    engine = forward_only(built.engine)  # (the sweep is not differentiated either)
    t_out = jnp.asarray(built.t_out)
    dotted_of = {v: k for k, v in names.items()}
    m0 = cfg["dust"]["m0"]

    def fn(**kw):
        over = {s: {} for s in ("gas", "dust", "fragmentation")}
        for short, v in kw.items():
            s, k = dotted_of[short].split(".")
            over[s][k] = v
        gas = cfgmod.make_gas(cfg["gas"], **over["gas"])
        du = dict(cfg["dust"], **over["dust"])
        kern = scene.kernel(gas, rho_s=du["rho_s"])
        n0 = jnp.asarray(n_unit) * (du["dust_to_gas"] * gas.rho_g)
        outcome = cfgmod.make_outcome(frag0, m0=m0, **over["fragmentation"])
        return evolve(kern, engine, n0, t_out, t0=0.0, outcome=outcome, throw=False)

    sweep_params = {names[_sweep_name(k)[0]]: np.asarray(v) for k, v in params.items()}
    attrs = {"config_toml": cfg.to_toml(), "config_hash": cfg.physics_hash(), "scene": scene.name,
             "swept": ",".join(names[d] for d in names)}
    t0 = time.perf_counter()
    if progress is None:
        progress = verbose
    if workers is None:
        workers = (os.cpu_count() or 1) if chunk == 1 else 1
    ds = swmod.sweep(fn, sweep_params, chunk=chunk, attrs=attrs, workers=workers,
                     progress=f"jaxcoag sweep {cfg['run']['name']}" if progress else False)
    wall = time.perf_counter() - t0
    rho_last = ds["mass_per_bin"].isel(t=-1).values
    flat = rho_last.reshape(-1, rho_last.shape[-1])
    mp = np.array([float(diagnostics.mass_peak(r, grid)) if np.all(np.isfinite(r)) else np.nan for r in flat])
    pdims = tuple(sweep_params)
    ds["mass_peak"] = (pdims, mp.reshape(rho_last.shape[:-1]),
                       {"units": "g", "long_name": "mass peak at the last output time"})
    # grain radius and Stokes number of the bin centres in every member's own gas / material
    a_m = np.empty(rho_last.shape[:-1] + (grid.nbins,))
    st_m = np.empty_like(a_m)
    mesh = np.meshgrid(*[sweep_params[k] for k in pdims], indexing="ij")
    for idx in np.ndindex(*a_m.shape[:-1]):
        over = {s: {} for s in ("gas", "dust")}
        for k, mm in zip(pdims, mesh):
            sec, key = dotted_of[k].split(".")
            if sec in over:
                over[sec][key] = float(mm[idx])
        du = dict(cfg["dust"], **over["dust"])
        pc = io.particle_coords(scene.kernel(cfgmod.make_gas(cfg["gas"], **over["gas"]), rho_s=du["rho_s"]),
                                grid.centers)
        a_m[idx], st_m[idx] = pc["a"][1], pc["St"][1]
    pc = io.particle_coords(built.kernel, grid.centers)  # names and units of the coordinates
    ds["a"] = (pdims + ("m",), a_m, pc["a"][2])
    ds["St"] = (pdims + ("m",), st_m, dict(pc["St"][2], long_name="Stokes number tau_f / t_L of the "
                                                                   "bin-center mass in the member's gas"))
    ds.attrs["wall_s"] = wall
    rows = []
    status = ds["status"].values.ravel()
    drift = ds["mass_drift"].isel(t=-1).values.ravel()
    for i in range(mp.size):
        row = {k: float(m.ravel()[i]) for k, m in zip(pdims, mesh)}
        row.update(status=RESULT_NAMES[int(status[i])], m_peak=float(mp[i]), mass_drift=float(drift[i]))
        rows.append(row)
    path = None
    if out is not None:
        out = os.fspath(out)
        os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
        if figure:
            ds.attrs["figure"] = figure_path(out)
        path = io.save_netcdf(ds, out)
        if figure:
            from .plot import sweep_panel
            sweep_panel(ds, path=ds.attrs["figure"], title=f"jaxcoag sweep of '{cfg['run']['name']}' ({scene.name}), "
                        f"t_end = {float(built.t_out[-1]) / C.yr:.4g} yr")
    if verbose:
        hdr = " ".join(f"{k:>12}" for k in pdims) + f" {'status':>18} {'m_peak [g]':>11} {'mass drift':>11}"
        print(f"jaxcoag sweep of '{cfg['run']['name']}' over {list(pdims)}: {mp.size} members, "
              f"t_end = {float(built.t_out[-1]) / C.yr:.4g} yr, {wall:.1f} s")
        print(hdr)
        for r in rows:
            print(" ".join(f"{r[k]:12.4g}" for k in pdims) + f" {r['status']:>18} "
                  f"{r['m_peak']:11.4g} {r['mass_drift']:11.2e}")
        print(f"{int(ds.attrs['n_failed'])} failed" + (f"; saved {path}" if path else "")
              + (f" and {ds.attrs['figure']}" if path and "figure" in ds.attrs else ""))
    return ds, rows
