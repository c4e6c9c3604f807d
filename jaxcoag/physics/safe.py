"""Numerically safe primitives (values and gradients finite at singular points).

References: velocity hazards 1-2 in docs/design_notes.md; the double-``where`` pattern of jax-md ``safe_mask``.
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["safe_sqrt", "safe_log", "st_floor", "clamp_st"]


def safe_sqrt(x):
    """sqrt(x) for x >= 0 with gradient 0 (not inf/NaN) at x = 0 (velocity hazard 1).

    ``pos = x > 0; where(pos, sqrt(where(pos, x, 1)), 0)``. Use once on a quadrature total,
    never on individual components.
    """
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def safe_log(x, fill=-jnp.inf):
    """log(x) for x > 0, ``fill`` elsewhere, with finite gradients on the masked branch."""
    pos = x > 0
    return jnp.where(pos, jnp.log(jnp.where(pos, x, 1.0)), fill)


def st_floor(dtype) -> float:
    """Stokes-number floor (velocity hazard 2): 1e-30 in float64, 1e-18 in float32 (floor^2 stays normal)."""
    return 1e-30 if jnp.finfo(dtype).bits >= 64 else 1e-18


def clamp_st(st):
    """max(St, ST_FLOOR) for the dtype of ``st`` (velocity hazard 2)."""
    st = jnp.asarray(st)
    if not jnp.issubdtype(st.dtype, jnp.floating):
        st = st.astype(jnp.result_type(float))
    return jnp.maximum(st, st_floor(st.dtype))
