"""Collision cross-sections, gravitational focusing and the sigma * Delta v kernel (cgs).

The kernel functions take the SQUARED total relative velocity ``dv2`` (the quadrature sum of
Brownian, turbulent and drift components) and apply ONE double-``where`` safe sqrt, so that
values and gradients stay finite where dv2 = 0 (identical particles in the tightly coupled
regime; velocity hazards 1 and 6 in docs/design_notes.md).

Gravitational focusing floor (documented): v_esc^2/Delta v^2 diverges as Delta v -> 0, so the
focusing branch uses dv2_eff = max(dv2 + dv_floor^2, DV2_MIN) with ``dv_floor`` a user
parameter [cm/s] (default 0, off) and the hard floor DV2_MIN = sqrt(finfo(dtype).tiny)
(1.5e-154 cm^2 s^-2 in float64, i.e. Delta v ~ 1e-77 cm/s; 1.1e-19 in float32). The hard
floor only keeps 1/Delta v finite; any physical Delta v (Brownian motion alone gives
> 1e-30 cm/s for bodies below 1e30 g) is far above it.

Validated public functions have unvalidated internal twins for hot paths, with the same
signature and a leading underscore: ``_cross_section``, ``_v_esc2``, ``_focusing_factor``,
``_kernel_sigma_dv``.

References: Ormel (2008) PhD thesis ch. 4 footnote 6 (sigma = pi (a1 + a2)^2), eq. 4.26
(K = sigma Delta v), eq. 5.5 and eqs. 1.6/1.7 (gravitational focusing).
"""

from __future__ import annotations

import jax.numpy as jnp

from .. import constants as C
from .drag import _check
from .safe import safe_sqrt

__all__ = ["cross_section", "focusing_factor", "kernel_sigma_dv", "escape_velocity2", "dv2_min"]


def dv2_min(dtype) -> float:
    """Hard floor on Delta v^2 in the focusing branch [cm^2 s^-2]: sqrt(finfo(dtype).tiny).

    Arguments:
        dtype: floating dtype of the computation (float64: 1.49e-154; float32: 1.08e-19).

    Returns:
        DV2_MIN as a Python float. References: velocity hazard 6 in
        docs/design_notes.md (focusing floor).
    """
    return float(jnp.finfo(dtype).tiny) ** 0.5


def _cross_section(a1, a2):
    """Unvalidated :func:`cross_section`."""
    rs = a1 + a2
    return jnp.pi * rs * rs


def cross_section(a1, a2):
    """Geometric collision cross-section sigma = pi (a1 + a2)^2.

    Arguments:
        a1, a2: particle radii [cm] (> 0; broadcasting).

    Returns:
        sigma [cm^2].

    References: Ormel (2008) thesis ch. 4 footnote 6, ch. 2 §2.2.
    """
    a1 = _check(a1, "a1", positive=True, hint="pass particle radii in cm")
    a2 = _check(a2, "a2", positive=True, hint="pass particle radii in cm")
    return _cross_section(a1, a2)


def _v_esc2(m1, m2, a1, a2):
    """Unvalidated :func:`escape_velocity2`."""
    return 2.0 * C.G * (m1 + m2) / (a1 + a2)


def escape_velocity2(m1, m2, a1, a2):
    """Squared mutual escape velocity v_esc^2 = 2 G (m1 + m2) / (a1 + a2).

    Arguments:
        m1, m2: masses [g] (> 0); a1, a2: radii [cm] (> 0); broadcasting.

    Returns:
        v_esc^2 [cm^2 s^-2].

    References: Ormel (2008) thesis eq. 5.5 (and eqs. 1.6/1.7).
    """
    m1, m2, a1, a2 = _check_bodies(m1, m2, a1, a2)
    return _v_esc2(m1, m2, a1, a2)


def _check_bodies(m1, m2, a1, a2):
    m1 = _check(m1, "m1", positive=True, hint="pass particle masses in g")
    m2 = _check(m2, "m2", positive=True, hint="pass particle masses in g")
    a1 = _check(a1, "a1", positive=True, hint="pass particle radii in cm")
    a2 = _check(a2, "a2", positive=True, hint="pass particle radii in cm")
    return m1, m2, a1, a2


def _check_dv(dv2, dv_floor):
    dv2 = _check(dv2, "dv2", nonnegative=True,
                hint="pass the SQUARED total relative velocity in cm^2 s^-2 (sum of squares of the components)")
    dv_floor = _check(dv_floor, "dv_floor", nonnegative=True,
                     hint="dv_floor is a velocity floor in cm s^-1 (0 = off)")
    return dv2, dv_floor


def _dv2_eff(dv2, dv_floor):
    e = jnp.asarray(dv2) + jnp.asarray(dv_floor) ** 2
    if not jnp.issubdtype(e.dtype, jnp.floating):
        e = e.astype(jnp.result_type(float))
    # where (a select), not maximum: maximum's JVP multiplies by a 0/1 mask, and 0 * inf = NaN
    # when the (huge) cotangent v_esc^2/dv^2 at the floor overflows (float32).
    floor = dv2_min(e.dtype)
    return jnp.where(e > floor, e, floor)


def _focusing_factor(m1, m2, a1, a2, dv2, *, dv_floor=0.0):
    """Unvalidated :func:`focusing_factor`."""
    return 1.0 + _v_esc2(m1, m2, a1, a2) / _dv2_eff(dv2, dv_floor)


def focusing_factor(m1, m2, a1, a2, dv2, *, dv_floor=0.0):
    """Gravitational focusing factor sigma/sigma_geo = 1 + v_esc^2 / Delta v^2.

    v_esc^2 = 2 G (m1 + m2)/R_s, R_s = a1 + a2. Floor: Delta v^2 -> max(dv2 + dv_floor^2,
    DV2_MIN) with DV2_MIN = sqrt(finfo.tiny) (module docstring), so dv2 = 0 gives a large but
    finite factor and finite gradients. Limits: 1 for Delta v >> v_esc; 2 at Delta v = v_esc.

    Arguments:
        m1, m2: masses [g] (> 0); a1, a2: radii [cm] (> 0); broadcasting.
        dv2: squared relative velocity [cm^2 s^-2] (>= 0).
        dv_floor: optional velocity floor [cm s^-1] (>= 0; default 0 = off).

    Returns:
        1 + v_esc^2/Delta v^2 [-].

    References: Ormel (2008) thesis eq. 5.5 (Safronov focusing; eqs. 1.6/1.7);
    velocity hazard 6 in docs/design_notes.md.
    """
    m1, m2, a1, a2 = _check_bodies(m1, m2, a1, a2)
    dv2, dv_floor = _check_dv(dv2, dv_floor)
    return _focusing_factor(m1, m2, a1, a2, dv2, dv_floor=dv_floor)


def _kernel_sigma_dv(a1, a2, m1, m2, dv2, *, focusing=False, dv_floor=0.0):
    """Unvalidated :func:`kernel_sigma_dv` (``focusing`` still checked: static structure)."""
    _focusing_ok(focusing)
    sig = _cross_section(a1, a2)
    if not focusing:
        return sig * safe_sqrt(jnp.asarray(dv2) + jnp.asarray(dv_floor) ** 2)
    dv = safe_sqrt(_dv2_eff(dv2, dv_floor))  # > 0 always: the one sqrt
    return sig * (dv + _v_esc2(m1, m2, a1, a2) / dv)


def _focusing_ok(focusing):
    if not isinstance(focusing, bool):
        raise TypeError(
            f"`focusing` must be a Python bool (it selects the formula, i.e. static structure), got "
            f"{type(focusing).__name__}; pass focusing=True or focusing=False"
        )


def kernel_sigma_dv(a1, a2, m1, m2, dv2, *, focusing=False, dv_floor=0.0):
    """Collision kernel K = sigma Delta v from the squared total relative velocity.

    Without focusing: K = pi R_s^2 sqrt(dv2 + dv_floor^2) (value 0 and gradient 0 at dv2 = 0,
    via one safe sqrt). With focusing (eq. 5.5): K = pi R_s^2 (Delta v + v_esc^2/Delta v)
    with Delta v = sqrt(max(dv2 + dv_floor^2, DV2_MIN)) (documented floor, module docstring).
    R_s = a1 + a2, v_esc^2 = 2 G (m1 + m2)/R_s.

    Arguments:
        a1, a2: particle radii [cm] (> 0; broadcasting).
        m1, m2: particle masses [g] (> 0; used only when ``focusing``).
        dv2: squared total relative velocity [cm^2 s^-2] (>= 0; the quadrature sum).
        focusing: Python bool (static): include gravitational focusing (default False).
        dv_floor: velocity floor [cm s^-1] (>= 0; default 0 = off), added in quadrature.

    Returns:
        K [cm^3 s^-1].

    References: Ormel (2008) thesis eq. 4.26 (K = sigma Delta v), eq. 5.5 (focusing),
    ch. 4 footnote 6 (sigma); velocity hazards 1, 6 in
    docs/design_notes.md.
    """
    _focusing_ok(focusing)
    a1 = _check(a1, "a1", positive=True, hint="pass particle radii in cm")
    a2 = _check(a2, "a2", positive=True, hint="pass particle radii in cm")
    if focusing:
        m1 = _check(m1, "m1", positive=True, hint="pass particle masses in g")
        m2 = _check(m2, "m2", positive=True, hint="pass particle masses in g")
    dv2, dv_floor = _check_dv(dv2, dv_floor)
    return _kernel_sigma_dv(a1, a2, m1, m2, dv2, focusing=focusing, dv_floor=dv_floor)
