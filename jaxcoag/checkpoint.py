"""Checkpoint and resume for every engine: one file format, one segment driver.

A checkpointed run (``jaxcoag.evolve(..., checkpoint=path)``) goes through the output times
segment by segment (``every`` output times per segment) with the engine protocol of
:mod:`jaxcoag._engine`: ``state = engine._init(...)`` once, then
``state, out = engine._advance(kernel, state, t_seg, outcome)`` per segment, and
``engine._result(kernel, t, outs, state, outcome)`` over the concatenated outputs. After every
segment the engine state (the full carry: binned ``{"y", "t"}``, Monte Carlo ``MCState``) and
the outputs so far are written to one ``.npz`` file atomically (temporary file in the same
directory, fsync, ``os.replace``, :func:`jaxcoag.io.atomic_write`), so a killed run leaves the
previous or the new checkpoint, never a torn one. Started again with ``resume=True`` the run
continues from the last completed segment; since the only data crossing a segment boundary is
the state, stored losslessly, the resumed run equals the uninterrupted checkpointed run bit for
bit (same backend and JAX version; the Monte Carlo engine draws every event's random numbers
from the base key and the event counter, so its segmented run also equals one unsegmented run).

File layout (npz, no pickles): ``format``; ``fingerprint`` (sha256 hex of the run, below);
``n_done`` (completed output times); ``leaf_00000`` ... the pytree leaves of ``state`` then of
``outs`` (PRNG keys as their ``key_data``); per leaf its key path (``paths``), dtype
(``dtypes``), PRNG implementation (``key_impls``, "" for arrays) and whether it was finite when
written (``finite``); ``checksum`` (sha256 over the leaves' bytes); ``meta_*`` (wall times,
JAX version, backend). Loading refuses, with a :class:`~jaxcoag._validate.JaxcoagInputError`
naming the file and what to do, a file that is missing, truncated, not a jaxcoag checkpoint, of
another structure (leaf paths, shapes, dtypes against templates), holds NaN/inf where finite
numbers were written or fails its checksum (corruption), or belongs to another run.

The run fingerprint (:func:`fingerprint`) is a sha256 over a *structural description* of the
engine, kernel, initial condition, outcome, output times, t0 and key, built by walking the
objects (class ``__module__.__qualname__`` and dataclass field names of equinox Modules, keys
of containers, dtype/shape/bytes of arrays, type and exact value of Python scalars, qualified
names of functions); it never uses an object's ``repr`` (which may hold memory addresses or
change between versions), so it is the same in every process and changes with every structural
choice and every number.

References: diffrax ``diffeqsolve`` (Kidger 2021) for the state-carry design; DustPy (Stammler &
Birnstiel 2022) writes snapshots per output time and restarts from them in the same way;
Gillespie (1975) (a Monte Carlo state is piecewise constant and the waiting time memoryless, so a
stop at an output time and a restart redraw the crossing event identically).
"""

from __future__ import annotations

import bisect
import dataclasses
import enum
import functools
import hashlib
import os
import struct
import sys
import time
import types

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._validate import JaxcoagInputError
from .io import atomic_write

__all__ = ["fingerprint", "run_fingerprint", "save", "load", "read_info", "run_segments", "RunInterrupted", "FORMAT"]

#: Format tag of the files written by :func:`save` (a file with another tag is refused).
FORMAT = "jaxcoag-checkpoint-v2"

_REMEDY = "delete it or start afresh (jaxcoag run without --resume; evolve(..., resume=False))"


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C during a checkpointed run: raised after the completed segments were written.

    Attributes: checkpoint (the path written, or None when nothing was written), segments_done
    (completed segments of the run), n_segments (all segments of the run).
    """

    def __init__(self, checkpoint=None, segments_done=0, n_segments=0):
        super().__init__(f"interrupted after {segments_done} of {n_segments} segments"
                         + (f"; checkpoint {checkpoint}" if checkpoint else ""))
        self.checkpoint = checkpoint
        self.segments_done = segments_done
        self.n_segments = n_segments


# ---------------------------------------------------------------------------------------- fingerprint
def _qualname(obj) -> str:
    return f"{getattr(obj, '__module__', None)}.{getattr(obj, '__qualname__', type(obj).__qualname__)}"


def _is_key(x) -> bool:
    return hasattr(x, "dtype") and jnp.issubdtype(x.dtype, jax.dtypes.prng_key)


class _Hasher:
    """sha256 over tagged, length-prefixed items (no two descriptions share a byte stream)."""

    def __init__(self):
        self.h = hashlib.sha256()
        self._stack: set[int] = set()

    def item(self, tag: str, data: bytes = b""):
        t = tag.encode()
        self.h.update(struct.pack("<Q", len(t)) + t + struct.pack("<Q", len(data)) + data)

    def feed(self, obj):
        """Describe ``obj`` structurally (see :func:`fingerprint`)."""
        if isinstance(obj, enum.Enum):  # before int/str: IntEnum/StrEnum str() differs between Pythons
            self.item("enum", f"{_qualname(type(obj))}.{obj.name}".encode())
            return
        if obj is None:
            self.item("py:None")
            return
        if isinstance(obj, (bytes, str)):
            self.item(f"py:{type(obj).__name__}", obj if isinstance(obj, bytes) else obj.encode())
            return
        if isinstance(obj, int):  # bool included (its own tag)
            self.item(f"py:{type(obj).__name__}", str(int(obj)).encode())
            return
        if isinstance(obj, float):
            self.item(f"py:{type(obj).__name__}", float(obj).hex().encode())
            return
        if isinstance(obj, complex):
            self.item(f"py:{type(obj).__name__}", f"{obj.real.hex()},{obj.imag.hex()}".encode())
            return
        if isinstance(obj, jax.core.Tracer):
            raise JaxcoagInputError("a checkpointed run needs concrete inputs: call evolve(..., checkpoint=...) "
                                    "outside jax.jit / jax.vmap (or drop checkpoint=).")
        if _is_key(obj):
            self.item("key", str(jax.random.key_impl(obj)).encode())
            obj = jax.random.key_data(obj)
        if isinstance(obj, (np.ndarray, np.generic, jax.Array)):
            a = np.ascontiguousarray(np.asarray(obj))
            self.item("array", f"{a.dtype.str}{a.shape}".encode())
            self.item("bytes", a.tobytes())
            return
        if isinstance(obj, np.dtype):
            self.item("dtype", obj.str.encode())
            return
        if isinstance(obj, type):
            self.item("type", _qualname(obj).encode())
            return
        oid = id(obj)
        if oid in self._stack:  # a reference cycle: name the class, do not recurse
            self.item("cycle", _qualname(type(obj)).encode())
            return
        self._stack.add(oid)
        try:
            self._feed_container(obj)
        finally:
            self._stack.discard(oid)

    def _feed_container(self, obj):
        if isinstance(obj, eqx.Module) or (dataclasses.is_dataclass(obj) and not isinstance(obj, type)):
            skip = set(getattr(type(obj), "__fingerprint_exclude__", ()))
            names = [f.name for f in dataclasses.fields(obj) if f.name not in skip]
            self.item("module", _qualname(type(obj)).encode())
            for n in names:
                self.item("field", n.encode())
                self.feed(getattr(obj, n, None))
            self.item("end")
            return
        if isinstance(obj, tuple) and hasattr(type(obj), "_fields"):  # NamedTuple
            self.item("namedtuple", _qualname(type(obj)).encode())
            for n in obj._fields:
                self.item("field", n.encode())
                self.feed(getattr(obj, n))
            self.item("end")
            return
        if isinstance(obj, (tuple, list)):
            self.item(type(obj).__name__, str(len(obj)).encode())
            for v in obj:
                self.feed(v)
            self.item("end")
            return
        if isinstance(obj, dict):
            items = sorted(((fingerprint(k), k, v) for k, v in obj.items()), key=lambda kv: kv[0])
            self.item("dict", str(len(items)).encode())
            for _, k, v in items:
                self.feed(k)
                self.feed(v)
            self.item("end")
            return
        if isinstance(obj, (set, frozenset)):
            self.item("set", ",".join(sorted(fingerprint(v) for v in obj)).encode())
            return
        if isinstance(obj, functools.partial):
            self.item("partial")
            self.feed(obj.func)
            self.feed(tuple(obj.args))
            self.feed(dict(obj.keywords))
            return
        if isinstance(obj, types.MethodType):
            self.item("method", _qualname(obj.__func__).encode())
            self.feed(obj.__self__)
            return
        if isinstance(obj, types.FunctionType):
            # the name, plus the values it closes over and its defaults (numbers, not reprs)
            self.item("function", _qualname(obj).encode())
            self.feed(obj.__defaults__)
            self.feed(obj.__kwdefaults__)
            cells = obj.__closure__ or ()
            self.feed(tuple(c.cell_contents if _cell_full(c) else None for c in cells))
            return
        d = getattr(obj, "__dict__", None)
        if d is None or callable(obj) and not d:
            self.item("object", _qualname(obj if callable(obj) and d is None else type(obj)).encode())
            return
        # a plain object (e.g. MassGrid): its class and public attributes
        self.item("object", _qualname(type(obj)).encode())
        for n in sorted(k for k in d if not k.startswith("_")):
            self.item("attr", n.encode())
            self.feed(d[n])
        self.item("end")


def _cell_full(cell) -> bool:
    try:
        cell.cell_contents
    except ValueError:  # an empty cell (a name not yet bound)
        return False
    return True


def fingerprint(*objects) -> str:
    """sha256 (hex) of a structural description of ``objects``, never of their ``repr``.

    The walk: an equinox Module or dataclass gives its class ``__module__.__qualname__`` and, per
    dataclass field (static and dynamic; a class may list fields to skip, e.g. progress meters,
    in ``__fingerprint_exclude__``), the field name and its description; tuple/list/dict recurse
    (dict keys sorted by their own fingerprint; NamedTuples with their class and field names);
    arrays (numpy, JAX) give dtype, shape and bytes; PRNG keys their implementation name and
    ``key_data``; Python bool/int/float/complex/str/None their type and exact value (floats as
    ``float.hex``); functions their qualified name, defaults and closed-over values; other
    objects (e.g. :class:`jaxcoag.MassGrid`) their class and public attributes. The result is
    therefore the same in every process and differs for another class, field, shape or number.

    Arguments:
        *objects: anything built from the above (engines, kernels, initial conditions, arrays).

    Returns:
        64-character hexadecimal string.

    Raises:
        JaxcoagInputError: a traced value (under ``jax.jit`` / ``jax.vmap``).
    """
    h = _Hasher()
    h.item("jaxcoag.fingerprint", str(len(objects)).encode())
    for o in objects:
        h.feed(o)
    return h.h.hexdigest()


def run_fingerprint(kernel, engine, initial, t_out, *, t0, outcome, key, until=None) -> str:
    """The fingerprint a checkpoint of this run carries: engine, kernel, initial condition,
    outcome, output times [s] (as float64), t0 [s] and key (structure and numbers), and the
    adaptive-end predicate ``until`` of :func:`run_segments` when there is one (its class and
    fields; without one the fingerprint is that of a run with fixed output times).
    A checkpoint whose fingerprint differs is refused on resume. The engine enters as its
    ``_fingerprint_view()`` (options that only decide how the run is differentiated left out: the binned
    engine's adjoint, which ``jaxcoag run`` sets to forward mode, ``runner.forward_only``)."""
    parts = (FORMAT, engine._fingerprint_view(), kernel, initial, outcome, np.asarray(t_out, np.float64),
             None if t0 is None else float(t0), key)
    return fingerprint(*parts) if until is None else fingerprint(*parts, ("until", until))


# ---------------------------------------------------------------------------------------- file format
def _flat(tree, prefix):
    """[(path string, leaf)] of a pytree; PRNG key arrays are leaves."""
    pairs, _ = jax.tree_util.tree_flatten_with_path(tree, is_leaf=_is_key)
    return [(prefix + jax.tree_util.keystr(p), x) for p, x in pairs]


def _leaf_record(path, x):
    """(numpy data, dtype string, key impl name) of a leaf as it is stored."""
    if _is_key(x):
        return np.asarray(jax.random.key_data(x)), str(x.dtype), str(jax.random.key_impl(x))
    a = np.asarray(x)
    if a.dtype == object:
        raise JaxcoagInputError(f"cannot checkpoint {path}: a checkpoint stores arrays only (got a "
                                f"{type(x).__name__}); make it an array leaf or a static field.")
    return a, a.dtype.str, ""


def _checksum(paths, datas) -> str:
    h = hashlib.sha256()
    for p, a in zip(paths, datas):
        a = np.ascontiguousarray(a)
        h.update(f"{p}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def save(path, *, fingerprint, state, outs, meta=None):
    """Write a checkpoint atomically.

    Arguments:
        path: file path (str or PathLike; ``.npz``); its directory must exist.
        fingerprint: the run fingerprint (:func:`run_fingerprint`), compared on :func:`load`.
        state: the engine state (pytree of arrays / PRNG keys) at the last completed output.
        outs: outputs so far (pytree of arrays, every leaf with leading axis ``n_done``).
        meta: optional dict name -> number, array or str (stored as ``meta_<name>``).

    Returns:
        the path (str).
    """
    path = os.fspath(path)
    recs = _flat(state, "state") + _flat(outs, "outs")
    paths, datas, dtypes, impls = [], [], [], []
    for p, x in recs:
        a, dt, impl = _leaf_record(p, x)
        paths.append(p)
        datas.append(a)
        dtypes.append(dt)
        impls.append(impl)
    lead = {a.shape[0] if a.ndim else -1 for p, a in zip(paths, datas) if p.startswith("outs")}
    if len(lead) > 1 or -1 in lead:
        raise JaxcoagInputError("checkpoint outputs must all have the same leading (output time) axis; got "
                                f"lengths {sorted(lead)}.")
    n_done = lead.pop() if lead else 0
    finite = np.array([a.dtype.kind not in "fc" or bool(np.all(np.isfinite(a))) for a in datas], bool)
    arrays = {"format": np.array(FORMAT), "fingerprint": np.array(str(fingerprint)), "n_done": np.array(n_done),
              "paths": np.array(paths, dtype=str), "dtypes": np.array(dtypes, dtype=str),
              "key_impls": np.array(impls, dtype=str), "finite": finite,
              "checksum": np.array(_checksum(paths, datas)),
              "meta_jax_version": np.array(jax.__version__), "meta_backend": np.array(jax.default_backend())}
    for i, a in enumerate(datas):
        arrays[f"leaf_{i:05d}"] = a
    for k, v in (meta or {}).items():
        arrays[f"meta_{k}"] = np.asarray(v)
        if arrays[f"meta_{k}"].dtype == object:  # would be pickled, and pickles are never loaded
            raise JaxcoagInputError(f"checkpoint meta {k!r} must be a number, array or str; got {type(v).__name__}.")

    def write(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)

    return atomic_write(path, write, what="checkpoint")


def _one_line(e) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def _read(path):
    """Every array of a checkpoint file (format, fields, finiteness and checksum verified)."""
    import zipfile
    import zlib

    if not os.path.isfile(path):
        raise JaxcoagInputError(f"no checkpoint file at {path!r}; check the path (or start without --resume).")
    try:
        with np.load(path, allow_pickle=False) as z:
            if not hasattr(z, "files"):  # a bare .npy array, not an npz archive
                raise ValueError("a single array, not an npz archive")
            d = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as e:
        why = "not an npz archive" if "pickle" in str(e) else _one_line(e)  # numpy: unknown magic = "pickled"
        raise JaxcoagInputError(f"checkpoint {path} is truncated or not a jaxcoag checkpoint ({why}); "
                                f"{_REMEDY}.") from e
    fmt = d.get("format")
    if fmt is None or fmt.ndim != 0 or fmt.dtype.kind != "U" or str(fmt) != FORMAT:
        raise JaxcoagInputError(f"{path} is not a {FORMAT} file (another program's npz or an older jaxcoag "
                                f"checkpoint); {_REMEDY}, or point --checkpoint at another file.")
    scal = ("fingerprint", "n_done", "checksum")
    lists = ("paths", "dtypes", "key_impls", "finite")
    bad = [k for k in scal if k not in d or d[k].ndim != 0] + [k for k in lists if k not in d or d[k].ndim != 1]
    if not bad:
        n = d["paths"].shape[0]
        bad = [k for k in lists if d[k].shape[0] != n] + [f"leaf_{i:05d}" for i in range(n) if f"leaf_{i:05d}" not in d]
    if bad:
        raise JaxcoagInputError(f"checkpoint {path} is incomplete or inconsistent (fields {bad[:4]}); {_REMEDY}.")
    paths = [str(p) for p in d["paths"]]
    datas = [d[f"leaf_{i:05d}"] for i in range(len(paths))]
    nan = [p for p, a, fin in zip(paths, datas, d["finite"])
           if fin and a.dtype.kind in "fc" and not np.all(np.isfinite(a))]
    if nan:
        raise JaxcoagInputError(f"checkpoint {path} holds NaN/inf in {nan[:3]} where the run wrote finite numbers "
                                f"(a corrupted file); {_REMEDY}.")
    if _checksum(paths, datas) != str(d["checksum"]):
        raise JaxcoagInputError(f"checkpoint {path} is corrupted (its data fail the sha256 checksum written with "
                                f"them); {_REMEDY}.")
    return d, paths, datas


def _template(tree, prefix):
    """[(path, dtype string, shape)] of a template pytree (arrays, ShapeDtypeStructs or keys)."""
    out = []
    for p, x in _flat(tree, prefix):
        dt = str(x.dtype) if _is_key(x) else np.dtype(x.dtype).str if hasattr(x, "dtype") else np.asarray(x).dtype.str
        out.append((p, dt, tuple(np.shape(x))))
    return out


def _restore(a, impl, like):
    """A stored leaf as a JAX array like its template: PRNG keys re-wrapped; a weakly typed scalar
    (e.g. ``jnp.asarray(0.0)`` in an engine's initial state) stays weakly typed, so a resumed segment
    reuses the compiled program of the uninterrupted run instead of compiling another one."""
    if impl:
        return jax.random.wrap_key_data(jnp.asarray(a), impl=impl)
    if a.ndim == 0 and getattr(like, "weak_type", False):
        x = jnp.asarray(a.item())  # a Python scalar gives a weakly typed array
        if x.dtype == a.dtype:
            return x
    return jnp.asarray(a)


def _refuse_other_run(path, fp_file, fp_run):
    raise JaxcoagInputError(
        f"checkpoint {path} was written by a different run configuration (engine, kernel, initial condition, "
        f"outcome, output times, t0 or key differ: fingerprint {str(fp_file)[:12]}... vs {str(fp_run)[:12]}...); "
        "refusing to resume. Start afresh without --resume (resume=False), delete it, or point --checkpoint "
        "at another file.")


def load(path, *, fingerprint, like_state, like_outs):
    """Read a checkpoint written by :func:`save` and rebuild its pytrees.

    Arguments:
        path: the file.
        fingerprint: the fingerprint of the run that wants to resume (None: not compared).
        like_state: a state template (same pytree structure, shapes and dtypes; arrays or
            ``jax.ShapeDtypeStruct``).
        like_outs: an outputs template (same structure and dtypes; the leading, output-time
            axis of each leaf may have any length, the others must match).

    Returns:
        dict ``state`` (pytree like ``like_state``, JAX arrays / PRNG keys), ``outs`` (pytree
        like ``like_outs`` with leading axis ``n_done``), ``n_done`` (int), ``fingerprint`` (str),
        ``meta`` (dict of numpy arrays; ``meta_`` stripped).

    Raises:
        JaxcoagInputError naming the file and what to do, for a missing, truncated, foreign,
        incomplete, corrupted (NaN/inf where finite numbers were written, checksum) file, one of
        another run (fingerprint) or of another structure (leaf paths, dtypes, shapes).
    """
    path = os.fspath(path)
    d, paths, datas = _read(path)
    fp = str(d["fingerprint"])
    if fingerprint is not None and fp != str(fingerprint):
        _refuse_other_run(path, fp, fingerprint)
    n_done = int(d["n_done"])
    want = _template(like_state, "state") + _template(like_outs, "outs")
    got_dt = [str(x) for x in d["dtypes"]]
    problem = None
    if [w[0] for w in want] != paths:
        miss = sorted(set(w[0] for w in want) ^ set(paths))
        problem = f"other pytree leaves ({miss[:3] or 'in another order'})"
    else:
        for (p, dt, shp), gdt, a, impl in zip(want, got_dt, datas, d["key_impls"]):
            shape = a.shape
            if str(impl):  # key_data carries the implementation's trailing axes
                try:
                    shape = jax.random.wrap_key_data(jnp.asarray(a), impl=str(impl)).shape
                except Exception as e:  # an unknown implementation name or a malformed key array
                    problem = f"{p} is not a valid {impl} key array ({_one_line(e)})"
                    break
            if dt != gdt:
                problem = f"{p} has dtype {gdt}, this run needs {dt}"
            elif p.startswith("state") and shape != shp:
                problem = f"{p} has shape {shape}, this run needs {shp}"
            elif p.startswith("outs") and (len(shape) != len(shp) or shape[1:] != shp[1:] or shape[0] != n_done):
                problem = f"{p} has shape {shape}, this run needs ({n_done},) + {shp[1:]}"
            if problem:
                break
    if problem:
        raise JaxcoagInputError(f"checkpoint {path} does not fit this run ({problem}); {_REMEDY}.")
    leaves = [_restore(a, str(impl), like) for a, impl, (_, like) in
              zip(datas, d["key_impls"], _flat(like_state, "state") + _flat(like_outs, "outs"))]
    ns = len(_flat(like_state, "state"))
    sdef = jax.tree_util.tree_structure(like_state, is_leaf=_is_key)
    odef = jax.tree_util.tree_structure(like_outs, is_leaf=_is_key)
    return dict(state=jax.tree_util.tree_unflatten(sdef, leaves[:ns]),
                outs=jax.tree_util.tree_unflatten(odef, leaves[ns:]), n_done=n_done, fingerprint=fp,
                meta={k[5:]: v for k, v in d.items() if k.startswith("meta_")})


def read_info(path):
    """Verify a checkpoint file (format, fields, finiteness, checksum) without rebuilding its
    pytrees; returns dict ``n_done`` (completed output times), ``fingerprint`` (str) and ``meta``
    (dict of numpy arrays). For a CLI that reports where a resumed run starts."""
    d, _, _ = _read(os.fspath(path))
    return dict(n_done=int(d["n_done"]), fingerprint=str(d["fingerprint"]),
                meta={k[5:]: v for k, v in d.items() if k.startswith("meta_")})


# ---------------------------------------------------------------------------------------- segment driver
def _codes(out):
    """Integer RESULTS codes (numpy, one per output) of an engine's segment outputs."""
    st = out["status"] if isinstance(out, dict) else getattr(out, "status")
    return np.atleast_1d(np.asarray(st)).astype(np.int64)


def _failure_codes():
    from ._status import FAILURES, RESULT_NAMES

    return {RESULT_NAMES.index(n) for n in FAILURES}


def _concat(a, b):
    """The outputs so far ``a`` followed by a segment's ``b``, concatenated on the host (numpy; PRNG-key
    leaves with jax.numpy): an eager ``jnp.concatenate`` compiles again for every new length, i.e. for every
    segment (0.4 s of the 17 outputs of the default ``jaxcoag run``)."""
    def cat(x, y):
        if _is_key(x):
            return jnp.concatenate([x, y])
        return np.concatenate([np.asarray(x), np.asarray(y)])

    if a is None:
        return jax.tree_util.tree_map(lambda x: x if _is_key(x) else np.asarray(x), b, is_leaf=_is_key)
    return jax.tree_util.tree_map(cat, a, b, is_leaf=_is_key)


def _on_device(outs):
    """The concatenated outputs as JAX arrays again (one transfer per leaf, no compilation)."""
    return jax.tree_util.tree_map(lambda x: x if _is_key(x) else jnp.asarray(x), outs, is_leaf=_is_key)


def run_segments(kernel, engine, initial, t_out, *, t0, outcome, key, checkpoint=None, every=1, resume=True,
                 progress=False, max_segments=None, desc="jaxcoag run", until=None):
    """Advance any engine segment by segment, with an atomic checkpoint after every segment.

    This is what ``jaxcoag.evolve(..., checkpoint=..., progress=..., max_segments=...)`` runs (its
    arguments are checked there, by ``evolve`` and the engine's ``_check``). Segment k covers the
    output times ``t_out[k*every : (k+1)*every]``; the engine's ``_advance`` takes the state from
    the previous segment's end to the last of them, with outputs at each.

    Arguments:
        kernel, engine, initial, t_out [s], t0 [s], outcome, key: as for :func:`jaxcoag.evolve`.
        checkpoint: path of the checkpoint file (None: segments and progress bar only, no file).
        every: output times per segment (int >= 1); the binned result depends on the segmentation
            (each segment restarts the adaptive step control), so resume with the same ``every``
            to reproduce the uninterrupted checkpointed run bit for bit.
        resume: continue from ``checkpoint`` when it exists (refused, before any work, if it belongs
            to another run or is damaged); False starts afresh and overwrites it.
        progress: a tqdm bar over the segments on stderr (simulated time as the engine's ``_progress_time``
            writes it: in yr, in s for the contact DEM, in the box's units for rigid aggregates; engines with a
            ``_progress_info(state_before, state_after, out, wall_s) -> str`` method add their own
            figures, e.g. events per second).
        max_segments: advance at most this many new segments, then return the outputs so far
            (the result's ``.t`` ends at the last completed output; a later call continues).
        desc: label of the progress bar.
        until: adaptive end: a predicate ``until(state) -> bool`` of the engine state, evaluated on
            the host after every completed segment (after its checkpoint is written) and on the
            state read from a checkpoint before resuming; True ends the run there, so ``t_out`` is
            then the longest run allowed (e.g. ``contact.collide``: contact plus 8 r_g,tot/v_imp
            and quiet steps). It must be a function of the state alone (deterministic), and it
            enters the run fingerprint (:func:`run_fingerprint`: make it an equinox Module or a
            dataclass whose fields are its parameters), so a checkpoint written under another end
            criterion is refused. None: run to ``t_out[-1]``.

    Returns:
        the engine's result (``engine._result``) over the completed outputs. The run stops after
        the first segment whose status is a failure (:data:`jaxcoag.FAILURES`); that segment is
        checkpointed too, so resuming returns the same failed result without redoing it. With
        ``until`` it also stops after the first segment whose state satisfies ``until`` (a caller
        tells this end from the end of ``t_out`` by evaluating ``until`` on the final state).

    Raises:
        :class:`RunInterrupted` on Ctrl-C, after writing the completed segments atomically.
        JaxcoagInputError for a checkpoint that cannot be resumed (see :func:`load`).
    """
    from tqdm.auto import tqdm

    t_np = np.asarray(t_out, np.float64)
    T = int(t_np.shape[0])
    every = int(every)
    bounds = list(range(0, T, every)) + [T]
    n_seg = len(bounds) - 1
    path = None if checkpoint is None else os.fspath(checkpoint)
    fp = None if path is None else run_fingerprint(kernel, engine, initial, t_np, t0=t0, outcome=outcome, key=key,
                                                   until=until)
    t_arr = jnp.asarray(t_np)

    resuming = resume and path is not None and os.path.exists(path)
    if resuming:  # refuse a foreign / damaged / other-run file before any work
        info = read_info(path)
        if info["fingerprint"] != fp:
            _refuse_other_run(path, info["fingerprint"], fp)
    state = engine._init(kernel, initial, t0, outcome, key)
    outs, n_done, walls = None, 0, []
    if resuming:
        # the outputs' structure, traced (not run) for the length of the next segment (shares its trace)
        k = min(int(info["n_done"]), T - 1)
        seg = t_arr[k:next(b for b in bounds if b > k)]
        like_outs = jax.eval_shape(lambda s: engine._advance(kernel, s, seg, outcome)[1], state)
        ck = load(path, fingerprint=fp, like_state=state, like_outs=like_outs)
        n_done = ck["n_done"]
        if n_done > T:
            raise JaxcoagInputError(f"checkpoint {path} holds {n_done} outputs, this run has {T}; {_REMEDY}.")
        if n_done:
            state, outs = ck["state"], ck["outs"]
            walls = [float(w) for w in np.atleast_1d(ck["meta"].get("wall_s", []))]
    failures = _failure_codes()
    failed = outs is not None and bool(set(_codes(outs).tolist()) & failures)
    ended = until is not None and outs is not None and bool(until(state))

    def seg_done(n):  # completed segments of this segmentation after n outputs
        return sum(1 for k in range(n_seg) if bounds[k + 1] <= n) if n < T else n_seg

    def write(rec):
        st, o, n, w = rec
        save(path, fingerprint=fp, state=st, outs=o,
             meta={"wall_s": np.asarray(w, np.float64), "every": every, "n_out": T})

    rec = (state, outs, n_done, walls)  # the completed run so far, replaced in one assignment
    bar = tqdm(total=None if until is not None else n_seg, initial=seg_done(n_done), disable=not progress,
               file=sys.stderr, unit="seg", desc=desc, dynamic_ncols=True, leave=True)
    new = 0
    try:
        while n_done < T and not failed and not ended and (max_segments is None or new < max_segments):
            hi = bounds[bisect.bisect_right(bounds, n_done)]
            w0 = time.perf_counter()
            state1, out = engine._advance(kernel, state, t_arr[n_done:hi], outcome)
            state1, out = jax.block_until_ready((state1, out))
            wall = time.perf_counter() - w0
            failed = bool(set(_codes(out).tolist()) & failures)
            prev = state
            rec = (state1, _concat(outs, out), hi, walls + [wall])
            state, outs, n_done, walls = rec
            new += 1
            if path is not None:
                write(rec)
            info_fn = getattr(engine, "_progress_info", None)
            extra = info_fn(prev, state, out, wall) if info_fn is not None else ""
            bar.set_postfix_str(engine._progress_time(float(t_np[hi - 1])) + (f", {extra}" if extra else ""),
                                refresh=False)
            bar.update(1)
            ended = until is not None and bool(until(state))
    except KeyboardInterrupt as e:
        saved = None
        if path is not None and rec[2] > 0:
            write(rec)
            saved = path
        raise RunInterrupted(checkpoint=saved, segments_done=seg_done(rec[2]), n_segments=n_seg) from e
    finally:
        bar.close()
    if outs is None:
        raise JaxcoagInputError("no output time was computed (max_segments stopped the run before its first "
                                "segment); raise max_segments.")
    return engine._result(kernel, t_arr[:n_done], _on_device(outs), state, outcome)
