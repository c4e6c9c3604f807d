"""Fragmentation probabilities p_f(Delta v; v_frag) shared by both engines.

All functions are pure, broadcasting and differentiable (the hard step excepted), and take the
squared relative velocity ``dv2`` [cm^2 s^-2] so that callers never need a sqrt of a
possibly-zero quadrature total.

References:
    Maxwellian form p_f = (1 + 1.5 x) exp(-1.5 x), x = (v_frag/Delta v)^2: the probability that
    a Maxwell-distributed collision speed with rms Delta v exceeds v_frag (Garaud et al. 2013,
    ApJ 764, 146, eq. 22 with 3D velocities; the form used by DustPy, Stammler & Birnstiel 2022).
    Linear transition: Birnstiel, Dullemond & Brauer (2010), A&A 513, A79, eq. 15 (width 0.2 v_f).
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["p_frag_maxwellian", "p_frag_step", "p_frag_linear", "p_frag_sigmoid"]

_X_MAX = 1.0e3  # (v_frag/dv)^2 above which p_f underflows to 0 anyway


def _ratio2(dv2, v_frag):
    """min((v_frag/dv)^2, _X_MAX) with finite gradients at dv2 = 0 (double-where)."""
    dv2 = jnp.asarray(dv2)
    vf2 = jnp.asarray(v_frag) ** 2
    ok = dv2 * _X_MAX > vf2
    return jnp.where(ok, vf2 / jnp.where(ok, dv2, 1.0), _X_MAX)


def p_frag_maxwellian(dv2, v_frag):
    """Maxwellian fragmentation probability (1 + 1.5 x) exp(-1.5 x), x = v_frag^2 / dv2.

    Arguments:
        dv2: squared rms relative velocity [cm^2 s^-2] (>= 0; 0 gives p_f = 0).
        v_frag: fragmentation threshold velocity [cm s^-1] (> 0).

    Returns:
        p_f in [0, 1]; smooth in both arguments (0 with zero gradient as dv -> 0).

    References: Garaud et al. (2013) eq. 22; DustPy (Stammler & Birnstiel 2022, ApJ 935, 35).
    """
    x = _ratio2(dv2, v_frag)
    return (1.0 + 1.5 * x) * jnp.exp(-1.5 * x)


def p_frag_step(dv2, v_frag):
    """Hard threshold: 1 if dv >= v_frag else 0 (Ormel 2008 ch. 4-5 style switch; not differentiable)."""
    return jnp.where(jnp.asarray(dv2) >= jnp.asarray(v_frag) ** 2, 1.0, 0.0)


def p_frag_linear(dv2, v_frag, width=0.2):
    """Linear ramp from 0 at (1 - width) v_frag to 1 at v_frag (Birnstiel et al. 2010 eq. 15)."""
    dv = jnp.sqrt(jnp.maximum(jnp.asarray(dv2), 0.0))
    return jnp.clip((dv - (1.0 - width) * v_frag) / (width * v_frag), 0.0, 1.0)


def p_frag_sigmoid(dv2, v_frag, width=0.1):
    """Smooth step in log velocity: 1/(1 + (v_frag/dv)^(1/width)), i.e. a logistic in ln dv of
    width ``width`` (in ln units), centred on v_frag. Differentiable surrogate of the hard step.
    """
    x = _ratio2(dv2, v_frag)  # (v_frag/dv)^2, capped: p = 0 exactly at the cap
    # logistic(ln(dv/v_frag)/width) = 1/(1 + exp(-ln(dv/v_f)/width)) = 1/(1 + x^(1/(2 width)))
    return jnp.where(x < _X_MAX, jnp.exp(-jnp.logaddexp(0.0, jnp.log(x) / (2.0 * width))), 0.0)
