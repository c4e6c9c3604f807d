"""Segmented binned integration with atomic checkpoints and exact resume.

A long binned run is integrated one output interval at a time: segment k solves the ODE from
``ts[k]`` to ``ts[k+1]`` starting from the raw scheme state ``y_k`` (mass per bin and the gel
entry for the two-bin scheme, DG coefficients for ``scheme="dg"``), with the same jitted solve
for every segment (the segment's two times are arrays, so nothing recompiles). After each
segment the state history is written atomically to a checkpoint file (``numpy.savez`` to a
temporary file in the same directory, fsync, ``os.replace``), together with a sha256 of the
run configuration and the output times. :func:`integrate` with ``resume=True`` loads the last
complete segment and continues. Ctrl-C (KeyboardInterrupt) during a segment writes the
completed segments and raises :class:`RunInterrupted`; a checkpoint that is truncated, not a
jaxcoag file, inconsistent, holds NaN/inf or belongs to another configuration is refused on
loading with a :class:`~jaxcoag._validate.JaxcoagInputError` naming the file.

Because an uninterrupted run uses exactly the same segmentation (each segment restarts the
adaptive step control from the default ``dt0`` of :func:`jaxcoag.binned.solve_binned`), a
resumed run reproduces the uninterrupted one bit for bit: the only data crossing a segment
boundary is ``y_k``, stored losslessly as float64.

Checkpoint contents (npz): ``format`` (str), ``config_hash`` (str), ``ts`` [s] (nt,),
``ys`` (k+1, ny) raw states of the completed outputs, ``steps``/``rejected`` (k,) per-segment
solver step counts, ``wall_s`` (k,) per-segment wall time [s], ``result_code`` (int).

References: diffrax ``diffeqsolve`` (Kidger 2021); DustPy (Stammler & Birnstiel 2022) writes
snapshots per output time and restarts from them in the same way.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np
import jax
import jax.numpy as jnp
import diffrax

from ._validate import JaxcoagInputError
from .io import atomic_write

__all__ = ["integrate", "SegmentedRun", "RunInterrupted", "save_checkpoint", "load_checkpoint",
           "CHECKPOINT_FORMAT"]

CHECKPOINT_FORMAT = "jaxcoag-binned-checkpoint-v1"


class SegmentedRun:
    """Result of :func:`integrate`.

    Attributes:
        solution: :class:`jaxcoag.binned.BinnedSolution` over the completed outputs
            (all of ``ts`` when finished; mass_drift is relative to the state at ts[0]).
        finished: True when every segment is done.
        n_segments_done: completed segments (of len(ts) - 1).
        resumed_from: segment index the run resumed from (0 = fresh start).
        seg_steps, seg_rejected, seg_wall_s: per-segment accepted / rejected steps and wall time [s].
        checkpoint: the checkpoint path or None.
    """

    def __init__(self, **kw):
        self.__dict__.update(kw)


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`integrate`: raised after the completed segments were checkpointed.

    Attributes: checkpoint (the path written, or None when the run had no checkpoint),
    segments_done (completed segments), n_segments (all segments of the run).
    """

    def __init__(self, checkpoint=None, segments_done=0, n_segments=0):
        super().__init__(f"interrupted after {segments_done} of {n_segments} segments"
                         + (f"; checkpoint {checkpoint}" if checkpoint else ""))
        self.checkpoint = checkpoint
        self.segments_done = segments_done
        self.n_segments = n_segments


def _atomic_savez(path, **arrays):
    def write(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)

    atomic_write(path, write, what="checkpoint")


def save_checkpoint(path, *, config_hash, ts, ys, steps, rejected, wall_s, result_code=0):
    """Write a checkpoint atomically (see the module docstring for the fields)."""
    _atomic_savez(os.fspath(path), format=np.array(CHECKPOINT_FORMAT), config_hash=np.array(str(config_hash)),
                  ts=np.asarray(ts, np.float64), ys=np.asarray(ys, np.float64),
                  steps=np.asarray(steps, np.int64), rejected=np.asarray(rejected, np.int64),
                  wall_s=np.asarray(wall_s, np.float64), result_code=np.array(int(result_code)))


_FIELDS = {"format": 0, "config_hash": 0, "ts": 1, "ys": 2, "steps": 1, "rejected": 1, "wall_s": 1,
           "result_code": 0}  # field -> ndim


def _one_line(e) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def load_checkpoint(path, *, config_hash=None, ts=None, ny=None):
    """Read a checkpoint; refuse (JaxcoagInputError naming the file and what to do) one that is
    truncated or not a jaxcoag binned checkpoint (random bytes, another npz), inconsistent,
    holds NaN/inf states or was written for another configuration.

    Arguments: path; config_hash / ts [s] / ny (state length): when given, must match.
    Returns: dict with the fields of the module docstring (numpy arrays, str hash).
    """
    import zipfile
    import zlib

    path = os.fspath(path)
    todo = "delete it, or run without --resume to start afresh"
    if not os.path.isfile(path):
        raise JaxcoagInputError(f"no checkpoint file at {path!r}.")
    try:
        with np.load(path, allow_pickle=False) as z:
            if not hasattr(z, "files"):  # a bare .npy array, not an npz archive
                raise ValueError("a single array, not an npz archive")
            ck = {k: z[k] for k in z.files if k in _FIELDS}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as e:
        why = "not an npz archive" if "pickle" in str(e) else _one_line(e)  # numpy: unknown magic = "pickled"
        raise JaxcoagInputError(f"checkpoint {path} is truncated or not a jaxcoag checkpoint ({why}); "
                                f"{todo}.") from e
    if "format" not in ck or ck["format"].ndim != 0 or str(ck["format"]) != CHECKPOINT_FORMAT:
        raise JaxcoagInputError(f"{path} is not a {CHECKPOINT_FORMAT} file; {todo}, or pass another --checkpoint.")
    bad = [k for k, nd in _FIELDS.items() if k not in ck or ck[k].ndim != nd]
    if not bad and ck["ys"].dtype.kind != "f":
        bad = ["ys"]
    if not bad:
        n = ck["ys"].shape[0]
        code = int(ck["result_code"])
        nseg = n - 1 + (code != 0)  # a failed segment is recorded without its state
        if n < 1 or not all(ck[k].shape[0] == nseg for k in ("steps", "rejected", "wall_s")) or \
                ck["ts"].shape[0] < n:
            bad = ["ys/steps/ts lengths"]
    if bad:
        raise JaxcoagInputError(f"checkpoint {path} is incomplete or inconsistent (fields {bad}); {todo}.")
    if not np.all(np.isfinite(ck["ys"])) or not np.all(np.isfinite(ck["ts"])):
        raise JaxcoagInputError(f"checkpoint {path} holds NaN/inf states or times (a corrupted file); {todo}.")
    ck["config_hash"] = str(ck["config_hash"])
    ck["result_code"] = int(ck["result_code"])
    if config_hash is not None and ck["config_hash"] != str(config_hash):
        raise JaxcoagInputError(
            f"checkpoint {path} was written by a different run configuration (hash {ck['config_hash'][:12]}... "
            f"vs {str(config_hash)[:12]}...); refusing to resume. Run without --resume to start afresh, delete it, "
            "or point --checkpoint at another file.")
    if ts is not None and (ck["ts"].shape != np.shape(ts) or not np.array_equal(ck["ts"], np.asarray(ts))):
        raise JaxcoagInputError(f"checkpoint {path} has other output times than this run; refusing to resume. "
                                f"Run without --resume to start afresh or delete it.")
    if ny is not None and ck["ys"].shape[1] != ny:
        raise JaxcoagInputError(f"checkpoint {path} holds states of length {ck['ys'].shape[1]}, this run needs {ny}; "
                                f"{todo}.")
    return ck


def _segment_solver(scheme, grid, model, fragmentation, solver, rtol, atol, max_steps):
    """One compiled segment solve y_k -> y_{k+1} (returns state, RESULTS item, stats)."""
    from .binned.solve import _solve_impl

    adjoint = diffrax.RecursiveCheckpointAdjoint()
    meter = diffrax.NoProgressMeter()
    rt = jnp.asarray(float(rtol), jnp.float64)
    at = jnp.asarray(float(atol), jnp.float64)

    def step(y, t0, t1):
        ts = jnp.stack([jnp.asarray(t0, jnp.float64), jnp.asarray(t1, jnp.float64)])
        ys, _, _, _, _, res, stats = _solve_impl(scheme, grid, model, fragmentation, y, ts, solver, None, rt, at,
                                                 None, adjoint, int(max_steps), meter)
        return ys[-1], res, stats

    return step


def integrate(model, grid, y0, ts, *, scheme, fragmentation=None, solver=None, rtol=1e-6, atol=1e-10,
              max_steps=100_000, checkpoint=None, resume=False, config_hash="", progress=False,
              max_segments=None, desc="jaxcoag run", on_segment=None, save=True) -> SegmentedRun:
    """Integrate segment by segment over the output times, checkpointing after each segment.

    Arguments:
        model: collision kernel (AbstractKernel) [cm^3 s^-1].
        grid: MassGrid; y0: raw initial scheme state (``scheme.init(grid, n0)``).
        ts: output times [s] (numpy, strictly increasing, >= 2).
        scheme: an AbstractScheme instance; fragmentation: model or None;
        solver: diffrax solver or "kvaerno5" (None: Tsit5 without / Kvaerno5 with fragmentation);
        rtol, atol, max_steps: as in :func:`jaxcoag.binned.solve_binned` (max_steps per segment).
        checkpoint: path of the checkpoint file written after every segment (None: none).
        resume: continue from ``checkpoint`` if it exists (a mismatched one is refused; a missing
            one starts afresh).
        config_hash: string identifying the configuration (stored and compared on resume).
        progress: show a tqdm bar over the segments (stderr).
        max_segments: integrate at most this many new segments, then return (finished=False);
            a later ``resume=True`` call continues (batch-queue time slices).
        on_segment: optional callback(k, t_k1, y_k1) after each completed segment.
        save: write the checkpoint (False: ``checkpoint`` is only read for ``resume``; nothing
            is written).

    Returns:
        :class:`SegmentedRun`. A segment that fails (max steps, non-finite, negative density)
        stops the run: the solution then holds the outputs up to the last good one and
        ``solution.result`` is the failure.

    Raises:
        :class:`RunInterrupted` (a KeyboardInterrupt) on Ctrl-C: the completed segments are
        written to ``checkpoint`` first (atomically), so ``resume=True`` continues exactly.

    References: module docstring; docs/design_notes.md (solver traps).
    """
    from .binned import BinnedSolution, result_code, result_from_code

    ts = np.asarray(ts, np.float64)
    if ts.ndim != 1 or ts.size < 2 or not np.all(np.diff(ts) > 0):
        raise JaxcoagInputError("ts must be a strictly increasing 1-D array of at least 2 output times [s].")
    y0 = jnp.asarray(y0, jnp.float64)
    ny = int(y0.shape[0])
    if solver is None:
        solver = diffrax.Tsit5() if fragmentation is None else "kvaerno5"
    nseg = ts.size - 1
    ys = [np.asarray(y0)]
    steps, rejected, walls = [], [], []
    k0 = 0
    code = 0
    if resume and checkpoint is not None and os.path.exists(checkpoint):
        ck = load_checkpoint(checkpoint, config_hash=config_hash, ts=ts, ny=ny)
        if not np.array_equal(ck["ys"][0], np.asarray(y0)):
            raise JaxcoagInputError(f"checkpoint {checkpoint} starts from another initial state; refusing to resume.")
        ys = [r for r in ck["ys"]]
        steps, rejected, walls = list(ck["steps"]), list(ck["rejected"]), list(ck["wall_s"])
        k0 = len(ys) - 1
        code = ck["result_code"]
    step = _segment_solver(scheme, grid, model, fragmentation, solver, rtol, atol, max_steps)
    from tqdm.auto import tqdm

    bar = tqdm(total=nseg, initial=k0, disable=not progress, file=sys.stderr, unit="seg", desc=desc,
               dynamic_ncols=True, leave=True)
    done_now = 0
    y = jnp.asarray(ys[-1])
    try:
        for k in range(k0, nseg):
            if code != 0:
                break
            if max_segments is not None and done_now >= max_segments:
                break
            w0 = time.perf_counter()
            y1, res, st = step(y, ts[k], ts[k + 1])
            y1 = jax.block_until_ready(y1)
            c = int(np.asarray(result_code(res)))
            walls.append(time.perf_counter() - w0)
            steps.append(int(st["steps"]))
            rejected.append(int(st["rejected"]))
            if c != 0:
                code = c
            else:
                ys.append(np.asarray(y1))
                y = y1
            done_now += 1
            if checkpoint is not None and save:
                save_checkpoint(checkpoint, config_hash=config_hash, ts=ts, ys=np.stack(ys), steps=steps,
                                rejected=rejected, wall_s=walls, result_code=code)
            bar.set_postfix_str(f"t = {ts[k + 1] / 3.15576e7:.3g} yr, {steps[-1]} steps", refresh=False)
            bar.update(1)
            if on_segment is not None and c == 0:
                on_segment(k + 1, ts[k + 1], y1)
    except KeyboardInterrupt as e:
        # keep the completed segments only (the interrupt may fall between the bookkeeping lines)
        n_ok = len(ys) - 1
        nrec = n_ok + (1 if code != 0 else 0)
        del steps[nrec:], rejected[nrec:], walls[nrec:]
        saved = None
        if checkpoint is not None and save:
            save_checkpoint(checkpoint, config_hash=config_hash, ts=ts, ys=np.stack(ys), steps=steps,
                            rejected=rejected, wall_s=walls, result_code=code)
            saved = checkpoint
        raise RunInterrupted(checkpoint=saved, segments_done=n_ok, n_segments=nseg) from e
    finally:
        bar.close()

    Y = jnp.asarray(np.stack(ys))
    n = Y.shape[0]
    rho = jax.vmap(lambda v: scheme.mass_per_bin(v, grid))(Y)
    num = jax.vmap(lambda v: scheme.number_per_bin(v, grid))(Y)
    gel = jax.vmap(lambda v: scheme.gel_mass(v, grid))(Y)
    M0 = scheme.total_mass(Y[0], grid)
    drift = (jnp.sum(rho, axis=1) + gel - M0) / M0
    result = result_from_code(code)
    stats = {"steps": jnp.asarray(int(np.sum(steps))), "rejected": jnp.asarray(int(np.sum(rejected))),
             "num_steps": jnp.asarray(int(np.sum(steps) + np.sum(rejected)))}
    sol = BinnedSolution(ts=jnp.asarray(ts[:n]), ys=Y, mass_per_bin=rho, number_per_bin=num, gel_mass=gel,
                         mass_drift=drift, result=result, stats=stats, grid=grid)
    return SegmentedRun(solution=sol, finished=(n == ts.size), n_segments_done=n - 1, resumed_from=k0,
                        seg_steps=np.asarray(steps, np.int64), seg_rejected=np.asarray(rejected, np.int64),
                        seg_wall_s=np.asarray(walls, np.float64), checkpoint=checkpoint, failed=code != 0)
