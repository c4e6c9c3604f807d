"""Input validation for public entry points.

Concrete inputs are checked eagerly in Python and rejected with a :class:`ValueError` whose
message says which argument is wrong and what to change. Inside ``jax.jit``/``vmap`` (traced
inputs) the same condition is attached with :func:`equinox.error_if`, so a bad value raises a
runtime error carrying the same message instead of propagating a silent NaN. Engines that
must keep going in sweeps report failures as values instead (see their ``result`` fields).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import equinox as eqx

__all__ = ["check", "is_traced", "require_x64", "JaxcoagInputError", "JaxcoagTypeError"]


class JaxcoagInputError(ValueError):
    """Raised for a bad argument at a public entry point; the message says what to change."""


class JaxcoagTypeError(JaxcoagInputError, TypeError):
    """A JaxcoagInputError for an argument of the wrong kind (also a TypeError, so code that
    catches TypeError - e.g. for a kernel without relative velocities - keeps working)."""


def is_traced(x) -> bool:
    """True if ``x`` (or any leaf of it) is a JAX tracer (we are inside jit/vmap/grad)."""
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(x))


def require_x64(where: str) -> None:
    """Raise unless float64 is enabled (cgs magnitudes span 1e-20..1e40)."""
    if not jax.config.jax_enable_x64:
        raise JaxcoagInputError(
            f"{where} needs 64-bit floats (cgs quantities span ~60 decades). Enable them before "
            "creating any array: `jax.config.update('jax_enable_x64', True)` or set the "
            "environment variable JAX_ENABLE_X64=1."
        )


def check(x, name: str, *, positive: bool = False, nonnegative: bool = False,
          finite: bool = True, hint: str = ""):
    """Validate an array argument; return it as a JAX array (float dtype preserved).

    Arguments:
        x: the value (scalar or array, concrete or traced).
        name: argument name used in the message.
        positive: require x > 0.
        nonnegative: require x >= 0.
        finite: require no NaN/inf.
        hint: extra sentence telling the user what to change.
    """
    if is_traced(x):
        arr = x
        if not jnp.issubdtype(arr.dtype, jnp.floating):
            arr = arr.astype(jnp.result_type(float))
    else:
        # inside jit, jnp ops on Python constants are staged out as tracers: keep constants concrete
        with jax.ensure_compile_time_eval():
            arr = jnp.asarray(x)
            if not jnp.issubdtype(arr.dtype, jnp.floating):
                arr = arr.astype(jnp.result_type(float))
    traced = is_traced(arr)
    what = []
    if finite:
        what.append("finite")
    if positive:
        what.append("> 0")
    elif nonnegative:
        what.append(">= 0")
    req = " and ".join(what)
    msg = f"argument `{name}` must be {req}" + (f"; {hint}" if hint else "")
    if traced:
        bad = jnp.zeros(arr.shape, bool)
        if finite:
            bad = bad | ~jnp.isfinite(arr)
        if positive:
            bad = bad | ~(arr > 0)
        elif nonnegative:
            bad = bad | ~(arr >= 0)
        return eqx.error_if(arr, bad, msg)
    v = np.asarray(arr)
    bad = np.zeros(v.shape, bool)
    if finite:
        bad |= ~np.isfinite(v)
    if positive:
        bad |= ~(v > 0)
    elif nonnegative:
        bad |= ~(v >= 0)
    if bad.any():
        first = v[bad].ravel()[0] if v.ndim else v
        raise JaxcoagInputError(f"{msg} (got {first!r}" + (f" at {int(bad.sum())} of {v.size} entries)" if v.ndim else ")"))
    return arr
