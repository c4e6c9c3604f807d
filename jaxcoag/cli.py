"""Command-line interface.

``jaxcoag run [scene.toml | -] [--out FILE]``  the main job: a coagulation(-fragmentation) run of a TOML
                                           configuration (``-``: read it from stdin) with its engine
                                           (``[run] engine = "binned" | "mc" | "contact" | "rigid"``;
                                           default: the binned run of growth and fragmentation at 1 AU in
                                           the MMSN, ``--engine mc`` its Monte Carlo twin, ``--engine
                                           contact`` a BCCA collision of the monomer DEM (Wada et al. 2007),
                                           ``--engine rigid`` Richardson's (1995) box of colliding spheres);
                                           saves netCDF + figure, prints a summary. The coagulation engines
                                           write the same netCDF layout.
``jaxcoag plot FILE [--out PNG]``          re-plot a saved run.
``jaxcoag sweep [scene.toml] --param alpha=1e-4,1e-3 ...``  parameter sweep of a configuration (progress
                                           bar over the members; netCDF + figure of the final mass peak).
``jaxcoag --version``                      the installed version (importlib.metadata).
``jaxcoag config [--engine E] [--resolved]``  print the default configuration (a commented, runnable TOML
                                           template: ``jaxcoag config --engine mc | jaxcoag run -``).
``jaxcoag demo``                           relative velocities and kernel of the ch. 4 nebula scene.

``jaxcoag run`` and ``jaxcoag sweep`` keep JAX's persistent compilation cache
(:func:`jaxcoag.enable_compilation_cache`) in ``$JAXCOAG_CACHE_DIR`` (default ``~/.cache/jaxcoag/jax``),
so a second run of the same configuration loads its compiled solve instead of compiling it again;
``--no-cache`` or ``JAXCOAG_CACHE_DIR=off`` switch it off (an unwritable directory gives a warning and
the run goes on uncached).

``jaxcoag`` with no subcommand runs ``jaxcoag run``. Exit codes: 0 success, 1 the run failed (a
failure status of :data:`jaxcoag.FAILURES`, e.g. the solver's step budget or the Monte Carlo event
budget; the outputs up to the failure are saved) or stopped early (``--max-segments``), 2 refused
input (a one-line reason naming the ``[section] key`` on stderr, no traceback; checked before any
computation, nothing is written: bad configuration, a grid too large for the memory, an output
location that cannot be written, an unreadable / corrupted / foreign checkpoint with ``--resume``),
130 interrupted (Ctrl-C: the completed output times are in the checkpoint and the exact command
that resumes the run is printed on stderr).
"""

from __future__ import annotations

import argparse
import os
import sys

import jax

_COMMANDS = ("run", "plot", "sweep", "config", "demo")


def _enable_x64():
    jax.config.update("jax_enable_x64", True)


def _parse_value(text):
    """A --set / --param value as TOML (number, bool, string, list), falling back to a bare string."""
    from .config import _toml

    try:
        return _toml.loads(f"v = {text}")["v"]
    except _toml.TOMLDecodeError:
        return text


def _version() -> str:
    """The installed distribution's version (importlib.metadata), else ``jaxcoag.__version__``
    (running from a source tree that is not installed)."""
    from importlib import metadata

    try:
        return metadata.version("jaxcoag")
    except metadata.PackageNotFoundError:
        from . import __version__
        return __version__


_NO_CACHE_HELP = ("do not use JAX's persistent compilation cache (default: on, in $JAXCOAG_CACHE_DIR or "
                  "~/.cache/jaxcoag/jax, so a second run loads the compiled solve instead of compiling it; "
                  "JAXCOAG_CACHE_DIR=off also switches it off)")


def _cache(args):
    """Switch on the persistent compilation cache unless --no-cache (jaxcoag.enable_compilation_cache)."""
    if not getattr(args, "no_cache", False):
        from ._cache import enable_compilation_cache

        enable_compilation_cache()


def build_parser() -> argparse.ArgumentParser:
    from .config import ENGINES

    p = argparse.ArgumentParser(prog="jaxcoag", description="Differentiable dust coagulation in JAX. "
                                "With no subcommand: `jaxcoag run` (the default 1 AU disk run).")
    p.add_argument("--version", action="version", version=f"%(prog)s {_version()}",
                   help="print the installed jaxcoag version and exit")
    sub = p.add_subparsers(dest="command")

    r = sub.add_parser("run", help="run a TOML scene with its engine (default: binned 1 AU disk, growth + "
                       "fragmentation); saves netCDF + figure")
    r.add_argument("config", nargs="?", default=None, help="TOML run configuration, or - to read it from stdin "
                   "(default: the built-in 1 AU MMSN run of --engine; `jaxcoag config` prints it)")
    r.add_argument("--engine", choices=list(ENGINES), default=None, help="without a file: the built-in default "
                   "run of this engine (default binned); with a file: override its [run] engine")
    r.add_argument("--out", default=None, help="netCDF output file (default [output] path = jaxcoag_out/run.nc); "
                   "the figure goes next to it (.png)")
    r.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one configuration value, e.g. --set gas.alpha=1e-4 (repeatable)")
    r.add_argument("--checkpoint", default=None, help="checkpoint file (default <out>.ckpt.npz)")
    r.add_argument("--no-checkpoint", action="store_true", help="do not write a checkpoint")
    r.add_argument("--resume", action="store_true", help="continue from the checkpoint (refused if it was "
                   "written by another configuration; starts afresh if there is none)")
    r.add_argument("--max-segments", type=int, default=None, help="stop after this many output intervals "
                   "(continue later with --resume)")
    r.add_argument("--no-figure", action="store_true", help="do not save the figure panel")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    r.add_argument("--quick", action="store_true", help="coarse grid, few outputs (seconds; smoke test)")
    r.add_argument("--no-cache", action="store_true", help=_NO_CACHE_HELP)

    pl = sub.add_parser("plot", help="re-plot a saved run (netCDF) as the standard panel")
    pl.add_argument("file", help="netCDF file written by `jaxcoag run`")
    pl.add_argument("--out", default=None, help="PNG path (default: FILE with .png)")

    s = sub.add_parser("sweep", help="sweep scalar parameters of a configuration (outer product)")
    s.add_argument("config", nargs="?", default=None, help="TOML run configuration (default: built-in)")
    s.add_argument("--param", action="append", default=[], metavar="NAME=V1,V2,...",
                   help="parameter and values, e.g. --param alpha=1e-4,1e-3 (repeatable; names: alpha, R_au, "
                   "T, Sigma_g, n, z_H, rho_X, M_star_msun, rho_s, dust_to_gas, v_frag, q, m_frag)")
    s.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one configuration value (repeatable)")
    s.add_argument("--out", default="jaxcoag_out/sweep.nc", help="netCDF output (default jaxcoag_out/sweep.nc)")
    s.add_argument("--chunk", type=int, default=1, help="members integrated together (default 1: each with its "
                   "own step sizes)")
    s.add_argument("--workers", type=int, default=None, help="members (or chunks) integrated at the same time in "
                   "host threads (default: the number of cores with --chunk 1, else 1)")
    s.add_argument("--quick", action="store_true", help="coarse grid, few outputs")
    s.add_argument("--no-progress", action="store_true", help="no progress bar (the bar counts finished members)")
    s.add_argument("--no-figure", action="store_true", help="do not save the figure of the swept quantity "
                   "(default: next to --out, e.g. sweep.png: final mass peak vs the parameters)")
    s.add_argument("--no-cache", action="store_true", help=_NO_CACHE_HELP)

    c = sub.add_parser("config", help="print the default run configuration (TOML with comments)")
    c.add_argument("--engine", choices=list(ENGINES), default="binned", help="the default run of this engine "
                   "(binned, or mc: a grouped Monte Carlo run of the same scene)")
    c.add_argument("--resolved", action="store_true", help="print every value incl. defaults instead")

    d = sub.add_parser("demo", help="relative velocities and kernel of the ch. 4 nebula scene (table + figure)")
    d.add_argument("--disk", choices=["ch4", "mmsn"], default="ch4", help="disk preset (default ch4 = thesis Table 4.1)")
    d.add_argument("--R", type=float, default=3.0, help="radius in AU (default 3)")
    d.add_argument("--alpha", type=float, default=1e-4, help="turbulence alpha (default 1e-4)")
    d.add_argument("--rho-s", type=float, default=3.0, help="material density g/cm^3 (default 3)")
    d.add_argument("--n", type=int, default=200, help="grid points of the N x N map (default 200)")
    d.add_argument("--out", default="jaxcoag_out", help="output directory (default ./jaxcoag_out)")
    d.add_argument("--quick", action="store_true", help="small grid (seconds)")
    return p


def _load_cfg(path, sets, engine=None):
    from . import config

    if path is None:
        cfg = config.default(engine or "binned")
    elif path == "-":
        cfg = config.loads(sys.stdin.read(), source="<stdin>")
    else:
        cfg = config.load(path)
    if engine is not None and path is not None:
        sets = [f"run.engine={engine!r}"] + list(sets)
    if sets:
        over = {}
        for item in sets:
            if "=" not in item:
                raise config.JaxcoagInputError(f"--set needs SECTION.KEY=VALUE, got {item!r}.")
            k, v = item.split("=", 1)
            over[k.strip()] = _parse_value(v.strip())
        cfg = cfg.replace(**over)
    return cfg


def _cmd_run(args) -> int:
    from . import runner

    cfg = _load_cfg(args.config, args.set, args.engine)
    _cache(args)
    if args.max_segments is not None and args.max_segments < 1:
        raise runner.JaxcoagInputError("--max-segments must be >= 1.")
    ck = False if args.no_checkpoint else args.checkpoint
    if args.no_checkpoint and args.resume:
        raise runner.JaxcoagInputError("--resume needs a checkpoint; drop --no-checkpoint.")
    res = runner.run(cfg, out=args.out, checkpoint=ck, resume=args.resume, progress=not args.no_progress,
                     figure=False if args.no_figure else None, max_segments=args.max_segments, quick=args.quick)
    return 0 if (res.finished and not res.failed) else 1


def _cmd_plot(args) -> int:
    from . import constants as C
    from . import io, runner
    from .plot import panel

    if not os.path.isfile(args.file):
        raise runner.JaxcoagInputError(f"no file at {args.file!r}; give a netCDF file written by `jaxcoag run`.")
    try:
        ds = io.load_netcdf(args.file)
    except (OSError, ValueError) as e:
        raise runner.JaxcoagInputError(f"{args.file} is not a readable netCDF file ({e}).") from e
    kern = runner.kernel_from_dataset(ds)
    out = args.out or runner.figure_path(args.file)
    title = str(ds.attrs.get("run_name", os.path.basename(args.file)))
    d = os.path.dirname(os.path.abspath(out))
    os.makedirs(d, exist_ok=True)
    fl = tuple(float(ds.attrs.get(k, "nan")) for k in ("m_frag_limit_g", "a_frag_limit_cm", "st_frag"))
    panel(ds, kern, path=out, title=title, frag_limit=fl if fl[0] > 0 else None)
    t = ds["t"].values
    print(f"jaxcoag plot: {ds.attrs.get('engine', '?')} run, {ds.sizes['m']} bins, {t.size} outputs up to t = "
          f"{float(t[-1]) / C.yr:.4g} yr ({'with' if kern is not None else 'without'} the run's kernel); saved {out}")
    return 0


def _cmd_sweep(args) -> int:
    from . import runner

    cfg = _load_cfg(args.config, args.set)
    _cache(args)
    params = {}
    for item in args.param:
        if "=" not in item:
            raise runner.JaxcoagInputError(f"--param needs NAME=V1,V2,..., got {item!r}.")
        k, v = item.split("=", 1)
        vals = []
        for x in v.split(","):
            try:
                vals.append(float(x))
            except ValueError:
                raise runner.JaxcoagInputError(f"--param {k}: {x!r} is not a number.") from None
        params[k.strip()] = vals
    if args.chunk < 1:
        raise runner.JaxcoagInputError("--chunk must be >= 1.")
    if args.workers is not None and args.workers < 1:
        raise runner.JaxcoagInputError("--workers must be >= 1.")
    ds, _ = runner.sweep_config(cfg, params, chunk=args.chunk, workers=args.workers, quick=args.quick, out=args.out,
                                progress=not args.no_progress, figure=not args.no_figure)
    return 0 if int(ds.attrs["n_failed"]) == 0 else 1


def _cmd_config(args) -> int:
    from . import config

    if args.resolved:
        sys.stdout.write(config.to_toml(config.default(args.engine).data))
    else:
        with open(config.default_path(args.engine)) as fh:
            sys.stdout.write(fh.read())
    return 0


def main(argv=None) -> int:
    _enable_x64()
    from ._validate import JaxcoagInputError

    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or (argv[0] not in _COMMANDS and argv[0] not in ("-h", "--help", "--version")):
        argv = ["run"] + argv
    parser = build_parser()
    args = parser.parse_args(argv)
    name = args.command
    try:
        if name == "run":
            return _cmd_run(args)
        if name == "plot":
            return _cmd_plot(args)
        if name == "sweep":
            return _cmd_sweep(args)
        if name == "config":
            return _cmd_config(args)
        if name == "demo":
            from .demo import run_demo

            run_demo(disk=args.disk, R_au=args.R, alpha=args.alpha, rho_s=args.rho_s, n=args.n,
                     out=args.out, quick=args.quick)
            return 0
    except (JaxcoagInputError, ValueError, TypeError, OSError) as e:
        msg = " ".join(str(e).split()) or type(e).__name__  # one line, no traceback
        print(f"jaxcoag {name}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:
        _report_interrupt(name, argv, args, e)
        return 130
    parser.print_help()
    return 1


def _report_interrupt(name, argv, args, exc):
    """Ctrl-C: say what was saved and print the exact command that continues the run (stderr)."""
    import shlex

    where = getattr(exc, "checkpoint", None)
    if name != "run":
        print(f"jaxcoag {name}: interrupted; nothing was saved.", file=sys.stderr)
        return
    if where:
        cmd = list(argv) + ([] if "--resume" in argv else ["--resume"])
        print(f"jaxcoag run: interrupted after {exc.segments_done} of {exc.n_segments} output times; "
              f"checkpoint saved to {where}", file=sys.stderr)
        if getattr(args, "config", None) == "-":
            print("(the configuration came from stdin: feed the same configuration again)", file=sys.stderr)
        print("resume with: " + shlex.join(["jaxcoag"] + cmd), file=sys.stderr)
    else:
        why = "--no-checkpoint" if getattr(args, "no_checkpoint", False) else "the run had not started"
        print(f"jaxcoag run: interrupted; no checkpoint was saved ({why}).", file=sys.stderr)
        print("run again with: " + shlex.join(["jaxcoag"] + list(argv)), file=sys.stderr)


def console_main() -> None:
    """The ``jaxcoag`` command (and ``python -m jaxcoag.cli``): :func:`main`, then the exit without the
    interpreter's teardown.

    Everything a command writes is complete when :func:`main` returns (netCDF and checkpoint files are written
    atomically and closed, temporary directories removed, worker threads joined); what is left is freeing JAX's
    backend, the compiled programs and every imported module, which took 0.7-0.8 s of a 5-6 s warm ``jaxcoag
    run`` (0.05 s with this exit; atexit handlers 0.09 s, a final garbage collection 0.14 s, the rest module
    teardown). So stdout and stderr are flushed, the logging handlers shut down, JAX's pending effects awaited,
    and the process ends with :func:`os._exit`. Library use (``cli.main(...)`` from Python) is unaffected.
    """
    exit_now(main())


def exit_now(rc: int) -> None:
    """End the process with exit code ``rc`` the way the ``jaxcoag`` command does (:func:`console_main`):
    JAX's pending effects awaited, logging shut down, stdout and stderr flushed, then :func:`os._exit`."""
    try:
        jax.effects_barrier()
    except Exception:  # pragma: no cover - nothing pending to wait for
        pass
    import logging

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe (e.g. `jaxcoag config | head -1`): nothing left to write
            rc = rc or 1
    os._exit(int(rc))


if __name__ == "__main__":
    console_main()
