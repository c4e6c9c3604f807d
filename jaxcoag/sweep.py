"""Parameter sweeps: vmap a model over a parameter grid, optionally sharded over devices.

``sweep(fn, {"alpha": alphas, "rho_g": rhos})`` evaluates ``fn(alpha=a, rho_g=r)`` for every
point of the outer product (``grid="outer"``) or for matched tuples (``grid="zip"``) in ONE
compiled, vmapped program and returns an ``xarray.Dataset`` labelled by the parameters, with
a ``status`` per member. ``fn`` typically builds a kernel from its arguments and calls
``jaxcoag.evolve(kernel, engine, initial, t_out, throw=False)``; it may return

* a result of ``evolve`` (:class:`jaxcoag.BinnedResult`; any engine's result whose binned view
  has fixed edges, e.g. :class:`jaxcoag.MCResult` with ``sweep(..., edges=...)``) - the dataset
  then has the layout of ``result.to_xarray()`` with the parameters in front: ``mass_per_bin``
  [g cm^-3] and ``number_per_bin`` [cm^-3] (params..., t, m), ``gel_mass`` [g cm^-3] and
  ``mass_drift`` [1] (params..., t) where the result has them (``gel_mass`` as an array: the binned
  engine's mass beyond its grid; as a method ``gel_mass(edges)``: mass above the top edge),
  ``steps`` (binned), coords ``t`` [s], ``t_yr`` [yr], ``m`` [g], ``m_edge`` [g], and
  ``status`` = the member's :class:`jaxcoag.RESULTS` code;
* a dict of arrays (or one array, named ``value``); an optional entry ``"result"`` holding
  a RESULTS item (e.g. ``res.status``) gives the status, otherwise a member's status is
  ``nonfinite`` when any of its outputs is NaN/inf and ``successful`` otherwise.

A Monte Carlo engine sweeps the same way, vmapped over kernel parameters or over random keys
(``key=jax.random.fold_in(base, seed.astype(jnp.uint32))`` from a swept ``seed``); its automatic
bins depend on the data, so give the bins with ``edges=``.

**Failures are values.** Evolve with ``throw=False``: a member that hits ``max_steps`` or goes
non-finite gets that status while the others finish normally. NaN/inf parameter values are
refused up front, or with ``invalid="flag"`` those members are skipped and get the status
``invalid_parameters``. (With ``throw=True`` inside a
vmapped sweep one failure raises for the whole batch, since ``eqx.error_if`` fires on any
member.) All members of one vmapped batch step together until the slowest finishes, so
``chunk=`` (``jax.lax.map`` with ``batch_size``) bounds memory and limits the cost of a slow
member to its chunk. On CPU use chunks: a 32 x 32 nebula-box sweep (32 bins) ran at 140 - 285
points/s with all 1024 members in one batch and 470 - 1550 points/s with chunk=16 - 256 (two
runs of ``benchmarks/sweep_throughput.py`` on a shared, loaded 2-core machine).

**Host threads (one CPU).** A member's step or event loop is sequential: one member keeps one core busy.
Where a member is real work (a fragmentation solve of the default box, a DEM collision), a vmapped batch on a
CPU is no faster than a loop of them (it runs every member until the slowest is done, and both branches of
each batched ``lax.cond``; measured 0.85x and 0.46x of the loop's throughput). ``workers=W`` runs blocks of
``chunk`` members in W host threads at once (XLA releases the GIL while a block runs) with one compiled
program; ``chunk=1`` makes every member its own unbatched program, equal to a single run. Measured on 2 cores,
8 members, against a loop of single runs: the default box's fragmentation solves 2.06x, Monte Carlo seeds
2.84x / 2.49x (Ns* = 100 / 400), contact-DEM impact speeds 2.0x (2000 steps each; benchmarks/README.md). Blocks
whose program calls batched LAPACK routines are refused with ``workers > 1`` (they hang there; ``chunk=1`` keeps
them unbatched).

**Sharding (one host).** With ``mesh=`` (a ``jax.sharding.Mesh``; the member axis is split
over all its axes) or ``devices=`` (a list of devices, one mesh axis ``"members"``) the
flattened members are padded to a multiple of the device count, placed with
``NamedSharding(mesh, PartitionSpec(axes))`` and run with ``jax.shard_map``: every device
integrates its own block (its own adaptive step loop), results are gathered and the padding
dropped. Results equal the unsharded sweep. On a CPU-only machine, emulate devices with
``XLA_FLAGS=--xla_force_host_platform_device_count=4`` set *before* JAX initialises.

**Multi-host (jax.distributed).** On a cluster start every process with the same script and
call, before anything else touches JAX::

    import jax
    jax.distributed.initialize(coordinator_address="host0:1234",   # SLURM/TPU: no arguments needed
                               num_processes=P, process_id=i)
    jax.config.update("jax_enable_x64", True)
    mesh = jax.make_mesh((jax.device_count(),), ("members",))     # spans all hosts' devices
    ds = jaxcoag.sweep.sweep(fn, params, mesh=mesh)

Every process passes the *same* parameter arrays; ``jax.device_count()`` is the global count
and each process's devices integrate their share of the members. The gathered result is
fetched with ``jax.experimental.multihost_utils.process_allgather`` so every process returns
the full dataset; write it from process 0 only
(``if jax.process_index() == 0: jaxcoag.io.save_netcdf(ds, path)``).

A longer guide with the fitting and output steps: ``docs/workflows.md``.

References: JAX docs "Distributed arrays and automatic parallelization", "Manual parallelism
with shard_map", "Multi-host and multi-process environments"; docs/design_notes.md, house style (failures are
values).
"""

from __future__ import annotations

import functools
import math
import re

import numpy as np
import jax
import jax.numpy as jnp

from ._validate import JaxcoagInputError, require_x64

__all__ = ["sweep", "parameter_points"]

_GRIDS = ("outer", "zip")


def _check_params(params, allow_nonfinite=False):
    if not isinstance(params, dict) or not params:
        raise JaxcoagInputError("params must be a non-empty dict name -> 1-D array of values, "
                                "e.g. {'alpha': np.logspace(-5, -3, 32)}.")
    out = {}
    for k, v in params.items():
        if not isinstance(k, str) or not k.isidentifier():
            raise JaxcoagInputError(f"parameter names must be Python identifiers (keyword arguments of fn); got {k!r}.")
        try:
            a = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise JaxcoagInputError(f"parameter {k!r} must be numeric (a 1-D array of floats); got {v!r}.") from e
        if a.ndim != 1:
            raise JaxcoagInputError(f"parameter {k!r} must be a 1-D array of values; got shape {a.shape}.")
        if a.size == 0:
            raise JaxcoagInputError(f"parameter {k!r} is empty: give at least one value.")
        if not allow_nonfinite and not np.all(np.isfinite(a)):
            raise JaxcoagInputError(f"parameter {k!r} contains NaN/inf at index {int(np.argmin(np.isfinite(a)))}; "
                                    "pass finite values (or sweep(..., invalid='flag') to flag those members).")
        out[k] = a
    return out


def _check_signature(fn, names):
    """fn must accept exactly the swept names as keyword arguments (no missing required ones)."""
    import inspect

    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):  # builtins / C callables: nothing to check
        return
    params = sig.parameters
    var_kw = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
    for k in names:
        p = params.get(k)
        if p is None and not var_kw or p is not None and p.kind in (inspect.Parameter.POSITIONAL_ONLY,
                                                                      inspect.Parameter.VAR_POSITIONAL):
            raise JaxcoagInputError(f"fn does not accept the parameter {k!r} as a keyword argument; rename the "
                                    f"sweep parameter to one of fn's arguments {list(params)} or add it to fn.")
    for k, p in params.items():
        if p.default is inspect.Parameter.empty and p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD,
                                                               inspect.Parameter.KEYWORD_ONLY) and k not in names:
            raise JaxcoagInputError(f"fn needs the argument {k!r}, which params does not give; add it to params "
                                    "or give it a default (functools.partial for fixed values).")


def parameter_points(params, grid="outer", *, allow_nonfinite=False):
    """Flattened parameter points of a sweep.

    Arguments: params: dict name -> 1-D array; grid: "outer" (all combinations, first key
    slowest, C order) or "zip" (matched tuples, equal lengths); allow_nonfinite: accept
    NaN/inf values (``sweep(..., invalid="flag")``), otherwise they are refused.
    Returns: (dict name -> 1-D array of length N, shape of the member axes).
    """
    params = _check_params(params, allow_nonfinite)
    if grid not in _GRIDS:
        raise JaxcoagInputError(f"grid must be one of {_GRIDS} (got {grid!r}).")
    if grid == "zip":
        lens = {k: v.size for k, v in params.items()}
        if len(set(lens.values())) != 1:
            raise JaxcoagInputError(f"grid='zip' needs equal-length parameter arrays; got lengths {lens}.")
        return dict(params), (next(iter(lens.values())),)
    shape = tuple(v.size for v in params.values())
    mesh = np.meshgrid(*params.values(), indexing="ij")
    return {k: m.ravel() for k, m in zip(params, mesh)}, shape


def _is_result(x):
    from ._engine import AbstractResult
    return isinstance(x, AbstractResult)


def _is_status(x):
    from ._status import RESULTS
    return isinstance(x, RESULTS)


def _result_outputs(out, edges, meta):
    """Member outputs of an engine result: its binned view on ``edges`` (None: the engine's own,
    which must not depend on the data), the per-time totals it has, and its RESULTS code."""
    from ._status import result_code

    try:
        e = np.asarray(out.bin_edges(edges), np.float64)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError,
            jax.errors.TracerBoolConversionError, jax.errors.TracerIntegerConversionError) as err:
        raise JaxcoagInputError(f"the bins of a {type(out).__name__} depend on the data (automatic edges), which a "
                                "vmapped sweep cannot use: pass fixed bins, sweep(..., edges=np.geomspace(m_lo, m_hi, "
                                "nb + 1)) in g.") from err
    meta["edges"] = e
    rho = out.mass_per_bin(edges)
    flat = {"mass_per_bin": rho, "number_per_bin": out.number_per_bin(edges), "t": out.t}
    gel = getattr(out, "gel_mass", None)
    if callable(gel):  # an engine whose mass beyond the top depends on the bins
        flat["gel_mass"] = gel(edges)
    elif isinstance(gel, jax.Array) and gel.shape == out.t.shape:  # beyond the engine's own grid (binned)
        # on other edges, the mass the re-binned view no longer holds counts as beyond the bins
        # (as result.to_xarray(edges=...))
        flat["gel_mass"] = gel if edges is None else gel + jnp.sum(out.mass_per_bin(), axis=-1) - jnp.sum(rho, axis=-1)
    drift = getattr(out, "mass_drift", None)
    if isinstance(drift, jax.Array) and drift.shape == out.t.shape:
        flat["mass_drift"] = drift
    stats = getattr(out, "stats", None)
    if isinstance(stats, dict) and "steps" in stats:
        flat["steps"] = jnp.asarray(stats["steps"])
    flat["status"] = result_code(out.status)
    return flat


def _member_fn(fn, names, meta, edges):
    """fn of keyword args -> flat dict of arrays (incl. 'status' int32); records the bin edges of
    result outputs in meta."""
    from ._status import RESULT_NAMES, result_code

    def one(*vals):
        out = fn(**dict(zip(names, vals)))
        if _is_result(out):
            return _result_outputs(out, edges, meta)
        if edges is not None:
            raise JaxcoagInputError("edges= applies when fn returns an engine result (jaxcoag.evolve); fn returned "
                                    f"a {type(out).__name__}.")
        if not isinstance(out, dict):
            out = {"value": out}
        flat, res = {}, None
        for k, v in out.items():
            if k == "result" and _is_status(v):
                res = v
                continue
            if not isinstance(k, str) or k == "status":
                raise JaxcoagInputError(f"fn output keys must be strings other than 'status' (got {k!r}); "
                                        "return the jaxcoag.RESULTS item under 'result'.")
            v = jnp.asarray(v)
            if not (jnp.issubdtype(v.dtype, jnp.number) or v.dtype == jnp.bool_):
                raise JaxcoagInputError(f"fn output {k!r} must be numeric arrays.")
            flat[k] = v
        if res is not None:
            status = result_code(res)
        else:
            finite = jnp.array(True)
            for v in flat.values():
                if jnp.issubdtype(v.dtype, jnp.inexact):
                    finite = finite & jnp.all(jnp.isfinite(v))
            status = jnp.where(finite, RESULT_NAMES.index("successful"), RESULT_NAMES.index("nonfinite")).astype(jnp.int32)
        flat["status"] = status
        return flat

    return one


def _check_dims(dims, fn, names, cols, edges):
    """Trace fn once (no run) and check that ``dims`` names existing outputs with the right number of axes."""
    prog, meta = _compiled(fn, tuple(names), None, None, len(cols), edges)
    shapes = jax.eval_shape(prog, *[jax.ShapeDtypeStruct(c[:1].shape, jnp.float64) for c in cols])
    for k, v in dims.items():
        if "edges" in meta:
            raise JaxcoagInputError("dims= is for functions returning a dict or an array; an engine result already "
                                    "has named axes (t, m).")
        if k not in shapes:
            raise JaxcoagInputError(f"dims names {k!r}, which fn does not return; its outputs are "
                                    f"{', '.join(sorted(shapes))}.")
        if len(v) != len(shapes[k].shape) - 1:
            raise JaxcoagInputError(f"dims[{k!r}] names {len(v)} axes but output {k!r} has "
                                    f"{len(shapes[k].shape) - 1} beyond the parameters (shape {shapes[k].shape[1:]}).")
    sizes = {}
    for k, v in dims.items():
        for d, n in zip(v, shapes[k].shape[1:]):
            if sizes.setdefault(d, (n, k))[0] != n:
                raise JaxcoagInputError(f"dimension {d!r} has length {sizes[d][0]} in output {sizes[d][1]!r} but {n} "
                                        f"in {k!r}; give the axes different names.")


def _resolve_mesh(mesh, devices):
    if mesh is not None and devices is not None:
        raise JaxcoagInputError("give either mesh= or devices=, not both.")
    if devices is not None:
        devices = list(devices)
        if not devices:
            raise JaxcoagInputError("devices= is empty; pass e.g. jax.devices().")
        mesh = jax.sharding.Mesh(np.array(devices), ("members",))
    if mesh is not None and not isinstance(mesh, jax.sharding.Mesh):
        raise JaxcoagInputError(f"mesh must be a jax.sharding.Mesh (got {type(mesh).__name__}).")
    return mesh


def _gather(x):
    if isinstance(x, jax.Array) and not x.is_fully_addressable:  # multi-host
        from jax.experimental import multihost_utils
        return np.asarray(multihost_utils.process_allgather(x, tiled=True))
    return np.asarray(x)


@functools.lru_cache(maxsize=32)
def _compiled(fn, names, chunk, mesh, ncols, edges):
    """Jitted (optionally shard_mapped) batched program for fn; cached so repeated sweeps of the
    same function reuse the compilation (``edges``: a tuple of floats or None). Returns (callable,
    meta) - meta['edges'] is filled at trace time when fn returns an engine result."""
    meta = {}
    one = _member_fn(fn, list(names), meta, None if edges is None else np.asarray(edges, np.float64))

    def batched(*cs):
        if chunk is None or chunk >= cs[0].shape[0]:
            return jax.vmap(one)(*cs)
        return jax.lax.map(lambda c: one(*c), cs, batch_size=chunk)

    if mesh is None:
        return jax.jit(batched), meta
    spec = jax.sharding.PartitionSpec(tuple(mesh.axis_names))
    fsh = jax.shard_map(batched, mesh=mesh, in_specs=tuple(spec for _ in range(ncols)), out_specs=spec,
                        check_vma=False)
    return jax.jit(fsh), meta


@functools.lru_cache(maxsize=32)
def _member_program(fn, names, ncols, edges):
    """Jitted program of ONE member (no batch axis: each member's linear solves stay unbatched), its outputs
    given a leading axis of length 1 so that they concatenate like a block's. Cached like :func:`_compiled`."""
    meta = {}
    one = _member_fn(fn, list(names), meta, None if edges is None else np.asarray(edges, np.float64))

    def single(*cs):
        return jax.tree_util.tree_map(lambda x: x[None], one(*[c[0] for c in cs]))

    return jax.jit(single), meta


_LAPACK_BATCHED = re.compile(r"custom_call @(lapack_\w+)\(.*num_batch_dims = \"([1-9][0-9]*)\"")


def _refuse_batched_lapack_in_threads(lowered, workers):
    """Refuse, before anything runs, a block program that calls batched LAPACK routines when the blocks run in
    several host threads: jaxlib fans a batched factorisation out on the host thread pool, and with several
    concurrent executions the program hangs (measured: a (400, 120, 120) ``jnp.linalg.solve`` from two threads
    never returned; one member's unbatched solves ran from two threads at 2.2x the loop's throughput)."""
    found = sorted({m.group(1) for m in _LAPACK_BATCHED.finditer(lowered.as_text())})
    if found:
        raise JaxcoagInputError(
            f"this sweep's blocks call batched LAPACK routines ({', '.join(found)}), which hang when {workers} "
            f"host threads run blocks at once. Give chunk=1 (one member per call: its solves are unbatched) or "
            f"workers=1.")


def _run_blocks(fn, names, cols, chunk, progress, edges, workers=1):
    """Unsharded evaluation block by block (``chunk`` members per compiled call, the last block padded by
    repeating its last member), the blocks run in ``workers`` host threads (in order of their members; one
    compiled program, compiled once before the threads start), with a tqdm bar over the members on stderr when
    ``progress``. A block of one member runs the unbatched member program (:func:`_member_program`)."""
    from concurrent.futures import ThreadPoolExecutor

    n = cols[0].shape[0]
    block = -(-n // workers) if chunk is None else min(chunk, n)
    if block == 1:
        prog, meta = _member_program(fn, tuple(names), len(cols), edges)
    else:
        prog, meta = _compiled(fn, tuple(names), block, None, len(cols), edges)
    blocks = []
    for i in range(0, n, block):
        c = [x[i:i + block] for x in cols]
        k = c[0].shape[0]
        if k < block:
            c = [np.concatenate([x, np.repeat(x[-1:], block - k)]) for x in c]
        blocks.append((k, c))
    first = [jnp.asarray(x) for x in blocks[0][1]]
    if workers > 1:
        lowered = prog.lower(*first)
        _refuse_batched_lapack_in_threads(lowered, workers)
        prog = lowered.compile()   # compiled once, here, not by the first call of every thread

    def run(b):
        k, c = b
        out = prog(*[jnp.asarray(x) for x in c])
        return {key: np.asarray(v)[:k] for key, v in out.items()}

    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=n, desc=progress if isinstance(progress, str) else "sweep", unit="member",
                   dynamic_ncols=True)
    ex = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="jaxcoag-sweep") if workers > 1 else None
    try:
        futs = [ex.submit(run, b) for b in blocks] if ex is not None else None
        parts = []
        for i, b in enumerate(blocks):
            parts.append(futs[i].result() if futs is not None else run(b))
            if bar is not None:
                bar.update(b[0])
    finally:   # Ctrl-C or a failed block: blocks not yet started are dropped
        if ex is not None:
            ex.shutdown(wait=True, cancel_futures=True)
        if bar is not None:
            bar.close()
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}, meta


def _run(fn, names, cols, chunk, mesh, progress=False, edges=None, workers=1):
    """Evaluate fn over flat columns (tuple of (N,) arrays); returns (dict of (N, ...) numpy, meta)."""
    n = cols[0].shape[0]
    if (progress or workers > 1 or chunk == 1) and mesh is None:   # chunk=1: the unbatched member program
        return _run_blocks(fn, names, cols, chunk, progress, edges, workers)
    prog, meta = _compiled(fn, tuple(names), chunk, mesh, len(cols), edges)
    if mesh is None:
        out = prog(*[jnp.asarray(c) for c in cols])
        return {k: np.asarray(v) for k, v in out.items()}, meta
    ndev = math.prod(mesh.devices.shape)
    npad = -n % ndev
    sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec(tuple(mesh.axis_names)))
    padded = [np.concatenate([c, np.repeat(c[-1:], npad)]) if npad else c for c in cols]
    placed = [jax.make_array_from_callback(p.shape, sharding, lambda idx, p=p: p[idx]) for p in padded]
    _refuse_cpu_lapack(prog, placed, mesh)
    out = prog(*placed)
    return {k: _gather(v)[:n] for k, v in out.items()}, meta


_LAPACK_FACTOR = re.compile(r"lapack_[sdcz](getrf|geqrf|potrf|syevd|heevd|gesdd|geev)")


def _refuse_cpu_lapack(prog, args, mesh):
    """Refuse, before anything runs, a program that calls a LAPACK factorisation when the mesh spans several CPU
    devices. jaxlib runs a batched factorisation (e.g. the radial disk's per-cell LU) by fanning it out on the host
    thread pool that the emulated CPU devices themselves occupy; with several devices the device threads wait for
    each other's queued work and the program hangs (measured: 4 devices, (400, 120, 120) ``jnp.linalg.solve``;
    docs/design_notes.md, radial disk). A clear error beats a silent hang."""
    devs = list(mesh.devices.flat)
    if len(devs) < 2 or not all(d.platform == "cpu" for d in devs):
        return
    found = sorted({m.group(0) for m in _LAPACK_FACTOR.finditer(prog.lower(*args).as_text())})
    if found:
        raise JaxcoagInputError(
            f"this sweep calls LAPACK factorisations on the CPU ({', '.join(found)}) and is sharded over "
            f"{len(devs)} CPU devices: jaxlib's batched LAPACK deadlocks across several CPU devices of one host. "
            f"Run it unsharded (drop devices=/mesh=; the vmapped batch already uses the cores) or shard over one "
            f"CPU device (devices=jax.devices()[:1]) or over accelerators.")


def sweep(fn, params, *, grid="outer", chunk=None, mesh=None, devices=None, attrs=None, invalid="raise",
          progress=False, edges=None, dims=None, workers=None):
    """Evaluate ``fn(**point)`` over a parameter grid in one vmapped (optionally sharded) program.

    Arguments:
        fn: function of keyword arguments named as ``params`` (scalar float64 values, in the
            units the caller chooses, e.g. alpha [-], rho_g [g cm^-3]) returning a result of
            ``jaxcoag.evolve`` (BinnedResult, MCResult), a dict of arrays (optionally with
            ``"result"``: a :class:`jaxcoag.RESULTS` item) or an array. Must be traceable
            (jit/vmap); call ``jaxcoag.evolve(..., throw=False)`` inside.
        params: dict name -> 1-D array of finite values (non-empty).
        grid: "outer" (every combination; dims = the parameter names in dict order) or "zip"
            (matched tuples; one dim ``member`` with the parameters as coordinates on it).
        chunk: members per vmapped batch (``jax.lax.map`` batch size); None = all at once
            (per device when sharded, per worker with ``workers``). On CPU, 16 - 256 is 3 - 10x faster than
            one wide batch for cheap members; ``chunk=1`` runs each member as a single, unbatched solve.
        mesh: ``jax.sharding.Mesh`` to shard the members over (split across all mesh axes).
        devices: list of devices; shorthand for ``mesh=Mesh(devices, ("members",))``.
        attrs: dict of global attributes for the dataset (scene, fixed parameters, ...).
        invalid: what to do with NaN/inf parameter values: "raise" (default; a
            JaxcoagInputError naming the parameter and index) or "flag" (those members are not
            evaluated - the program runs them at a valid member's values - their float outputs
            are NaN and their status is ``RESULTS.invalid_parameters``; the rest are unaffected).
            Physically impossible but finite values (e.g. alpha < 0) are refused by the
            model's own checks inside ``fn``; under vmap such a check raises for the whole
            batch, so filter them out of ``params`` first.
        progress: False (default) or True / a description string: show a tqdm bar over the
            members on stderr. The members are then run from Python in blocks of ``chunk``
            (one compiled vmapped program per block, the last block padded) so that the bar
            advances after each block; without ``chunk`` there is one block. Ignored when
            sharded (``mesh``/``devices``), where all members run in one program.
        edges: mass-bin edges [g] (1-D increasing) of the binned view when fn returns an engine
            result; default None = the engine's own bins (the binned grid). Needed for Monte Carlo
            results, whose automatic bins depend on the data.
        workers: host threads that run blocks of ``chunk`` members at once (default None = 1). One compiled
            program serves every block; XLA releases the GIL while a block runs, so on a CPU host each worker
            keeps a core busy: a member's event or step loop is sequential and uses one core, so ``workers=
            os.cpu_count()`` is how a sweep uses the machine (e.g. 8 fragmentation solves of the default box,
            chunk=1, workers=2 on 2 cores: benchmarks/frag_sweep_throughput.py). With an explicit ``chunk`` the
            results equal those of ``workers=1``. Not with ``mesh``/``devices`` (the devices already run in
            parallel). Blocks whose program calls batched LAPACK routines are refused before anything runs
            (they hang in several threads; give ``chunk=1``).
        dims: dict output name -> sequence of dimension names for that output's axes beyond the parameters
            (e.g. ``{"sigma_dust": ("t", "r")}`` for a (T, Nr) output); outputs not named keep the default
            names. A name may be shared by several outputs (their lengths must agree) but not by a parameter.

    Returns:
        xarray.Dataset with the parameters as coordinates, the outputs as variables (extra
        output axes named ``t``/``m`` for results, ``<name>_dim<i>`` otherwise),
        ``status`` (int32 :class:`jaxcoag.RESULTS` code, 0 = successful; attrs
        ``flag_values``/``flag_meanings``) and attrs ``n_members``, ``n_failed`` (members whose
        status is one of :data:`jaxcoag.FAILURES`).

    References: JAX ``vmap``, ``lax.map``, ``shard_map``; docs/design_notes.md, house style ("failures are values").
    """
    require_x64("jaxcoag.sweep.sweep")
    import xarray as xr
    from .io import result_table

    if not callable(fn):
        raise JaxcoagInputError("fn must be a callable taking the parameters as keyword arguments.")
    if chunk is not None:
        if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1:
            raise JaxcoagInputError(f"chunk must be a positive int or None (got {chunk!r}).")
        chunk = int(chunk)
    if attrs is not None and not isinstance(attrs, dict):
        raise JaxcoagInputError("attrs must be a dict.")
    if invalid not in ("raise", "flag"):
        raise JaxcoagInputError(f"invalid must be 'raise' or 'flag' (what to do with NaN/inf parameter values); "
                                f"got {invalid!r}.")
    mesh = _resolve_mesh(mesh, devices)
    if workers is not None:
        if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
            raise JaxcoagInputError(f"workers must be a positive int (host threads) or None; got {workers!r}.")
        if mesh is not None and workers > 1:
            raise JaxcoagInputError("give workers= or mesh=/devices=, not both: sharded members already run in "
                                    "parallel on the devices.")
    workers = 1 if workers is None else int(workers)
    points, shape = parameter_points(params, grid, allow_nonfinite=invalid == "flag")
    names = list(points)
    _check_signature(fn, names)
    cols = tuple(points[k] for k in names)
    bad = np.zeros(cols[0].shape[0], bool)
    for c in cols:
        bad |= ~np.isfinite(c)
    if bad.all():
        raise JaxcoagInputError("every sweep member has a NaN/inf parameter value; nothing to run.")
    if bad.any():  # run flagged members at the first valid member's values, then blank them
        first = int(np.argmin(bad))
        cols = tuple(np.where(bad, c[first], c) for c in cols)
    try:
        hash(fn)
    except TypeError as e:
        raise JaxcoagInputError("fn must be hashable (a function or a hashable callable object).") from e
    if edges is not None:
        e = np.asarray(getattr(edges, "edges", edges), np.float64)
        if e.ndim != 1 or e.size < 2 or not np.all(np.isfinite(e)) or np.any(e <= 0) or np.any(np.diff(e) <= 0):
            raise JaxcoagInputError("edges must be a 1-D, positive, strictly increasing array of >= 2 mass-bin edges "
                                    "in g (or a MassGrid).")
        edges = tuple(float(x) for x in e)
    if dims is not None:
        if not isinstance(dims, dict) or not all(isinstance(k, str) for k in dims):
            raise JaxcoagInputError("dims must be a dict: output name -> sequence of dimension names, e.g. "
                                    "{'sigma_dust': ('t', 'r')}.")
        dims = {k: (v,) if isinstance(v, str) else tuple(v) for k, v in dims.items()}
        for k, v in dims.items():
            if not all(isinstance(d, str) and d for d in v):
                raise JaxcoagInputError(f"dims[{k!r}] must be a sequence of non-empty strings; got {v!r}.")
            if len(set(v)) != len(v) or set(v) & set(names) or (grid == "zip" and "member" in v):
                raise JaxcoagInputError(f"dims[{k!r}] = {v!r} repeats a name or reuses a parameter's dimension "
                                        f"({', '.join(names) if grid == 'outer' else 'member'}); rename it.")
        _check_dims(dims, fn, names, cols, edges)
    out, meta = _run(fn, names, cols, chunk, mesh, progress, edges, workers)
    if bad.any():
        from ._status import RESULT_NAMES
        for k, v in out.items():
            if k == "status":
                out[k] = np.where(bad, np.int32(RESULT_NAMES.index("invalid_parameters")), v).astype(np.int32)
            elif np.issubdtype(v.dtype, np.inexact) and k != "t":
                v = v.copy()
                v[bad] = np.nan
                out[k] = v

    if grid == "outer":
        pdims = tuple(names)
        coords = {k: (k, np.asarray(params[k], np.float64)) for k in names}
    else:
        pdims = ("member",)
        coords = {k: ("member", points[k]) for k in names}
        coords["member"] = ("member", np.arange(shape[0]))
    result = "edges" in meta  # fn returned an engine result (recorded at trace time)
    data = {}
    for k, v in out.items():
        v = v.reshape(shape + v.shape[1:])
        if result and k == "t":
            continue
        extra = v.ndim - len(shape)
        if result and k in ("mass_per_bin", "number_per_bin"):
            d = pdims + ("t", "m")
        elif result and k in ("gel_mass", "mass_drift"):
            d = pdims + ("t",)
        elif dims is not None and k in dims:
            d = pdims + dims[k]
        else:
            d = pdims + tuple(f"{k}_dim{i}" for i in range(extra))
        data[k] = (d, v)
    table = result_table()
    codes = sorted(table)
    status_attrs = {"long_name": "jaxcoag.RESULTS code per member (0 = successful)", "units": "1",
                    "flag_values": np.asarray(codes, np.int32),
                    "flag_meanings": " ".join(table[c][0] for c in codes)}
    if result:
        from .io import time_coords

        t = out["t"]
        units = {"mass_per_bin": ("g cm-3", "dust mass density per mass bin"),
                 "number_per_bin": ("cm-3", "dust number density per mass bin"),
                 "gel_mass": ("g cm-3", "mass density above the top mass-bin edge"),
                 "mass_drift": ("1", "relative total-mass change (M(t) - M(t0)) / M(t0)"),
                 "steps": ("1", "accepted solver steps")}
        if np.all(t == t[:1]):
            coords.update(time_coords(t[0]))  # t [s] and t_yr [yr]
        else:  # the members' output times differ: a variable beside the parameters (dim t has no coordinate)
            data["t_out"] = (pdims + ("t",), t.reshape(shape + t.shape[1:]), {"units": "s", "long_name": "output times"})
        e = meta["edges"]
        coords["m"] = ("m", np.sqrt(e[:-1] * e[1:]), {"units": "g", "long_name": "geometric bin-centre mass sqrt(m_lo m_hi)"})
        coords["m_edge"] = ("m_edge", e, {"units": "g", "long_name": "mass-bin edges"})
        data = {k: (d[0], d[1], dict(zip(("units", "long_name"), units.get(k, ("1", k))))) if len(d) == 2 else d
                for k, d in data.items()}
    data["status"] = (data["status"][0], np.asarray(data["status"][1], np.int32), status_attrs)
    ds = xr.Dataset(data_vars=data, coords=coords)
    from ._status import FAILURES, RESULT_NAMES

    nfail = int(np.sum(np.isin(np.asarray(out["status"]), [RESULT_NAMES.index(n) for n in FAILURES])))
    ds.attrs.update({"n_members": int(math.prod(shape)), "n_failed": nfail, "grid": grid,
                     "n_devices": 1 if mesh is None else int(math.prod(mesh.devices.shape)), "n_workers": workers})
    if attrs:
        from .io import _attr_value
        for k, v in attrs.items():
            ds.attrs[str(k)] = _attr_value(v)
    return ds
