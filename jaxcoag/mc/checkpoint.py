"""Checkpointed, resumable Monte Carlo runs with a progress bar.

``run_checkpointed`` runs :func:`jaxcoag.mc.run` segment by segment over the output times
(``every`` output times per segment), continuing each segment from the previous segment's
``final_state``. After every segment the end state and all snapshots so far are written to one
``.npz`` file atomically (temporary file in the same directory, fsync, ``os.replace``), so a
killed run leaves either the previous or the new checkpoint, never a torn one. Started again
with ``resume=True`` it continues from the last completed segment. Because every event's
random numbers derive from the base key and the event counter (``fold_in``) and all
maintenance counters live in the state, the assembled result equals one uninterrupted
``run`` over all output times bitwise (same backend and JAX version).

The checkpoint stores a SHA-256 fingerprint of the arguments (kernel and outcome parameters,
all run keywords, output times, key); resuming with different arguments is refused.

References: Gillespie (1975) (the state is piecewise constant and the waiting time memoryless, so
the crossing event is redrawn identically after a stop at t_out); per-event keys via fold_in
(Monte Carlo conventions in docs/design_notes.md).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import sys
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._validate import JaxcoagInputError
from ..io import atomic_write
from .results import MCResult
from .run import run
from .state import MCState, status_names

__all__ = ["run_checkpointed", "load_checkpoint"]

_SNAP_FIELDS = ("m", "logm", "psi", "w", "z", "valid", "V", "logV", "M_tot", "n_events_snap")
_FORMAT = 1


def _is_key(x):
    return hasattr(x, "dtype") and jnp.issubdtype(x.dtype, jax.dtypes.prng_key)


def _feed(h, obj):
    """Feed a value (pytree, module, array, scalar, str) into the hash deterministically."""
    if isinstance(obj, (str, int, float, bool, type(None))):
        h.update(repr((type(obj).__name__, obj)).encode())
        return
    if _is_key(obj):
        h.update(b"key:" + str(jax.random.key_impl(obj)).encode())
        obj = jax.random.key_data(obj)
    if isinstance(obj, (np.ndarray, jax.Array, np.generic)):
        a = np.asarray(obj)
        h.update(f"arr:{a.dtype.str}:{a.shape}".encode())
        h.update(np.ascontiguousarray(a).tobytes())
        return
    dyn, static = eqx.partition(obj, lambda x: isinstance(x, (jax.Array, np.ndarray)))
    # static structure (class names, static fields, functions by qualified name; no addresses)
    h.update(re.sub(r" at 0x[0-9a-fA-F]+", "", repr(static)).encode())
    for leaf in jax.tree_util.tree_leaves(dyn, is_leaf=_is_key):
        _feed(h, leaf)


def _fingerprint(kernel, t_out, key, kwargs):
    h = hashlib.sha256()
    h.update(f"jaxcoag.mc.run_checkpointed v{_FORMAT}".encode())
    _feed(h, kernel)
    _feed(h, np.asarray(t_out, np.float64))
    _feed(h, key)
    for k in sorted(kwargs):
        h.update(k.encode())
        _feed(h, kwargs[k])
    return h.hexdigest()


def _state_to_arrays(st: MCState):
    out = {}
    for f in st._fields:
        v = getattr(st, f)
        if f == "snaps":
            continue
        if _is_key(v):
            out["state_key_impl"] = np.array(str(jax.random.key_impl(v)))
            v = jax.random.key_data(v)
        out[f"state_{f}"] = np.asarray(v)
    return out


def _state_from_arrays(d):
    vals = {}
    for f in MCState._fields:
        if f == "snaps":
            vals[f] = None
            continue
        v = jnp.asarray(d[f"state_{f}"])
        if f == "key" and "state_key_impl" in d:
            v = jax.random.wrap_key_data(v, impl=str(d["state_key_impl"]))
        vals[f] = v
    return MCState(**vals)


def _save(path, fingerprint, n_done, state, snaps, meta):
    arrays = {"format": np.array(_FORMAT), "fingerprint": np.array(fingerprint), "n_done": np.array(n_done),
              "jax_version": np.array(jax.__version__), "backend": np.array(jax.default_backend())}
    arrays.update(_state_to_arrays(state))
    for f in _SNAP_FIELDS:
        arrays[f"snap_{f}"] = snaps[f]
    for k, v in meta.items():
        arrays[f"meta_{k}"] = np.asarray(v)
    def write(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)

    atomic_write(path, write, what="checkpoint")


_PHYSICAL = ("m", "logm", "psi", "w", "logV", "M_tot")  # never NaN in a run's state or snapshots


def load_checkpoint(path):
    """Read a checkpoint written by :func:`run_checkpointed`.

    A file that is truncated, not a jaxcoag.mc checkpoint (random bytes, another npz), lacks a
    field or holds NaN masses / group numbers / volumes is refused with a
    :class:`JaxcoagInputError` naming the file and what to do (delete it or resume=False).

    Returns:
        dict with ``fingerprint`` (str), ``n_done`` (output times completed), ``state``
        (``MCState`` to resume from), ``snaps`` (dict of the snapshot arrays so far, leading
        axis n_done), ``jax_version``, ``backend`` and ``meta`` (n_events, n_dup, n_merge,
        status, t_stop of the last segment and the run configuration as JSON).
    """
    import zipfile
    import zlib

    path = os.fspath(path)
    todo = "delete it or use resume=False to start over"
    try:
        with np.load(path, allow_pickle=False) as z:
            if not hasattr(z, "files"):
                raise ValueError("a single array, not an npz archive")
            d = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as e:
        why = "not an npz archive" if "pickle" in str(e) else (" ".join(str(e).split()) or type(e).__name__)
        raise JaxcoagInputError(f"checkpoint {path!r} is truncated or not a jaxcoag.mc checkpoint ({why}); "
                                f"{todo}") from e
    fmt = d.get("format")
    if fmt is None or fmt.ndim != 0 or fmt.dtype.kind not in "iu" or int(fmt) != _FORMAT:
        raise JaxcoagInputError(f"{path!r} is not a jaxcoag.mc checkpoint of format {_FORMAT}; {todo}")
    need = ["fingerprint", "n_done", "jax_version", "backend"] + [f"snap_{f}" for f in _SNAP_FIELDS] + \
        [f"state_{f}" for f in MCState._fields if f != "snaps"]
    miss = [k for k in need if k not in d] + [k for k in ("fingerprint", "n_done") if k in d and d[k].ndim != 0]
    if miss:
        raise JaxcoagInputError(f"checkpoint {path!r} is incomplete or inconsistent (fields {miss[:4]}); {todo}")
    bad = [k for k in [f"state_{f}" for f in _PHYSICAL] + [f"snap_{f}" for f in _PHYSICAL]
           if d[k].dtype.kind == "f" and np.isnan(d[k]).any()]
    if bad:
        raise JaxcoagInputError(f"checkpoint {path!r} holds NaN in {bad} (a corrupted file); {todo}")
    return dict(fingerprint=str(d["fingerprint"]), n_done=int(d["n_done"]), state=_state_from_arrays(d),
                snaps={f: d[f"snap_{f}"] for f in _SNAP_FIELDS}, jax_version=str(d["jax_version"]),
                backend=str(d["backend"]), meta={k[5:]: d[k] for k in d if k.startswith("meta_")})


def run_checkpointed(kernel, *, t_out, checkpoint, every=1, resume=True, progress=True, key=None, **kwargs):
    """:func:`jaxcoag.mc.run` in segments with an atomic checkpoint after each; resumable.

    Arguments:
        kernel, key, **kwargs: exactly as for :func:`jaxcoag.mc.run` (n_particles or initial,
            mode, grouping, ns_target, f_eps, capacity, stop, ...; not ``resume_from``).
        t_out: 1-D strictly increasing output times [s] (concrete; not under jit/vmap).
        checkpoint: path of the checkpoint file (``.npz``; its directory must exist), or None
            for a segmented run with a progress bar but no file.
        every: output times per segment (≥ 1). Each segment costs one ``run`` call (one
            compilation per distinct segment length); the checkpoint is rewritten after each.
        resume: if True and ``checkpoint`` exists, continue from it (its argument fingerprint
            must match, else :class:`JaxcoagInputError`); if False, start over and overwrite.
        progress: show a tqdm progress bar over simulated time with events/s and Ns (stderr).

    Returns:
        ``MCResult`` over all of ``t_out``; equal (bitwise, same backend) to
        ``run(kernel, t_out=t_out, key=key, **kwargs)``, also after an interruption and
        resume. ``final_state`` allows a further continuation.

    References: snapshots and PRNG in the Monte Carlo conventions of docs/design_notes.md;
    jaxcoag.io.save_netcdf (same atomic-write pattern).
    """
    if "resume_from" in kwargs:
        raise JaxcoagInputError("run_checkpointed manages resume_from itself; drop it (use resume=True)")
    t = np.asarray(t_out, np.float64)
    if t.ndim != 1 or t.size < 1 or not np.all(np.isfinite(t)) or np.any(t < 0) or np.any(np.diff(t) <= 0):
        raise JaxcoagInputError("`t_out` must be a non-empty, finite, >= 0, strictly increasing 1-D array of times in s")
    if isinstance(every, bool) or int(every) != every or int(every) < 1:
        raise JaxcoagInputError("`every` must be an integer >= 1 (output times per checkpoint segment)")
    every = int(every)
    if key is None:
        raise JaxcoagInputError("give `key`, a jax.random key (e.g. jax.random.key(0))")
    path = None if checkpoint is None else os.fspath(checkpoint)
    if path is not None:
        d = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(d):
            raise JaxcoagInputError(f"directory {d!r} for the checkpoint does not exist; create it first")
    fp = _fingerprint(kernel, t, key, kwargs)
    T = t.size
    n_done, state, snaps, last = 0, None, None, None
    if resume and path is not None and os.path.exists(path):
        ck = load_checkpoint(path)
        if ck["fingerprint"] != fp:
            raise JaxcoagInputError(
                f"checkpoint {path!r} was written by a run with different arguments (kernel, keywords, t_out or "
                "key differ); pass the original arguments, resume=False to start over, or another path")
        n_done, state, snaps = ck["n_done"], ck["state"], ck["snaps"]
        last = ck["meta"]
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=float(t[-1]), initial=float(t[n_done - 1]) if n_done else 0.0, unit="t", file=sys.stderr,
                   desc="mc.run", bar_format="{l_bar}{bar}| t={n:.4g}/{total:.4g} [{elapsed}<{remaining}{postfix}]")
    res = None
    try:
        while n_done < T:
            hi = min(n_done + every, T)
            seg = jnp.asarray(t[n_done:hi])
            n_ev0 = 0 if state is None else int(state.n_events)
            w0 = time.perf_counter()
            res = run(kernel, t_out=seg, key=key, resume_from=state, **kwargs)
            jax.block_until_ready(res.m)
            wall = time.perf_counter() - w0
            new = {f: np.asarray(getattr(res, f)) for f in _SNAP_FIELDS}
            snaps = new if snaps is None else {f: np.concatenate([snaps[f], new[f]]) for f in _SNAP_FIELDS}
            state = res.final_state
            n_done = hi
            last = dict(n_events=np.asarray(res.n_events), n_dup=np.asarray(res.n_dup),
                        n_merge=np.asarray(res.n_merge), status=np.asarray(res.status), t_stop=np.asarray(res.t_stop),
                        config=np.array(json.dumps([(k, T if k == "n_snap" else v) for k, v in res.config])))
            if path is not None:
                _save(path, fp, n_done, state, snaps, last)
            if bar is not None:
                d_ev = int(res.n_events) - n_ev0
                bar.set_postfix_str(f"events={int(res.n_events)}, {d_ev / max(wall, 1e-9):.3g} ev/s, "
                                    f"Ns={int(np.asarray(res.n_species)[-1])}"
                                    + (f", {','.join(status_names(res.status))}" if int(res.status) else ""))
                bar.update(float(t[hi - 1]) - bar.n)
    finally:
        if bar is not None:
            bar.close()
    if res is None:
        # every segment was already done: totals and configuration from the file
        tot = {k: jnp.asarray(last[k]) for k in ("status", "n_events", "n_dup", "n_merge", "t_stop")}
        cfg = tuple((str(k), v) for k, v in json.loads(str(last["config"])))
    else:
        tot = dict(status=res.status, n_events=res.n_events, n_dup=res.n_dup, n_merge=res.n_merge, t_stop=res.t_stop)
        cfg = tuple((k, T if k == "n_snap" else v) for k, v in res.config)
    return MCResult(t=jnp.asarray(t), **{f: jnp.asarray(snaps[f]) for f in _SNAP_FIELDS}, **tot,
                    final_state=state, config=cfg)
