"""Particle radii, gas drag (friction time), Stokes number and particle scale height (cgs).

Every public function validates its array arguments with :func:`jaxcoag._validate.check`
(concrete input: :class:`~jaxcoag._validate.JaxcoagInputError`; traced input:
``eqx.error_if``). Hot paths (ODE right-hand sides, Monte Carlo loops) should call the
unvalidated internal twins, which have the same signature and a leading underscore:

    _compact_radius, _porous_radius, _projected_area, _friction_time,
    _friction_time_compact, _stokes_number, _particle_scale_height, _rainout_stokes

All functions are pure, broadcasting (numpy rules; under ``jax_numpy_rank_promotion="raise"``
broadcast explicitly, e.g. ``m[:, None]``), and jit/vmap/grad safe.

References (Ormel 2008 PhD thesis; spec/velocities.md §2):
    Epstein   tau_Ep = 3 m / (4 c_g rho_g A)        eqs. 2.4, 3.1, 4.5 (NOT eq. 6.12: typo #13)
    Stokes    tau_St = [4 a / (9 l_mfp)] tau_Ep      eq. 4.6 with Re_p < 1 (C = 1/Re_p)
    switch at a = 9/4 l_mfp (continuous)             ch. 2 footnote 3, eqs. 4.5/4.6 (typo #9)
    porous radius a = a* psi^(1/3)                   ch. 2, eq. 2.25 context (Fig. 2.2)
    St = tau_f / t_L                                 ch. 4 footnote 5
    h_p = H_g / sqrt(1 + St/alpha)                   eq. 4.29 (Dubrulle et al. 1995)
    h_p = H_g sqrt(alpha/St) if St > alpha else H_g  eq. 1.26
    rain-out St = alpha (tau_rain = alpha/Omega)     eq. 2.25
"""

from __future__ import annotations

import jax.numpy as jnp

from .._validate import check
from .safe import clamp_st, safe_sqrt

__all__ = [
    "compact_radius",
    "porous_radius",
    "projected_area",
    "friction_time",
    "friction_time_compact",
    "stokes_number",
    "particle_scale_height",
    "rainout_stokes",
    "REGIMES",
    "SCALE_HEIGHT_FORMS",
]

REGIMES = ("auto", "epstein", "stokes")
SCALE_HEIGHT_FORMS = ("dubrulle", "ch1")


_check = check  # check() validates Python constants eagerly, also inside jit


def _regime_ok(regime):
    if regime not in REGIMES:
        raise ValueError(
            f"unknown drag regime {regime!r}; use one of {REGIMES} ('auto' switches continuously "
            "from Epstein to Stokes drag at a = 9/4 l_mfp; spec/velocities.md §2)"
        )


def _form_ok(form):
    if form not in SCALE_HEIGHT_FORMS:
        raise ValueError(
            f"unknown particle scale-height form {form!r}; use one of {SCALE_HEIGHT_FORMS} "
            "('dubrulle' = thesis eq. 4.29, smooth; 'ch1' = eq. 1.26, kinked)"
        )


# --------------------------------------------------------------------------------------------
# radii and areas


def _compact_radius(m, rho_s):
    """Unvalidated :func:`compact_radius`."""
    return jnp.cbrt(3.0 * m / (4.0 * jnp.pi * rho_s))


def compact_radius(m, rho_s):
    """Radius of a compact (non-porous) sphere of mass ``m``.

    Arguments:
        m: particle mass [g] (> 0).
        rho_s: material (bulk) density [g cm^-3] (> 0).

    Returns:
        a = (3 m / (4 pi rho_s))^(1/3) [cm].

    References: Ormel (2008) thesis ch. 2 (compact size a*, Fig. 2.2); spec/velocities.md §2.1.
    """
    m = _check(m, "m", positive=True, hint="pass the particle mass in g")
    rho_s = _check(rho_s, "rho_s", positive=True, hint="pass the material density in g cm^-3 (e.g. 3.0)")
    return _compact_radius(m, rho_s)


def _porous_radius(m, rho_s, psi):
    """Unvalidated :func:`porous_radius`."""
    return _compact_radius(m, rho_s) * jnp.cbrt(psi)


def porous_radius(m, rho_s, psi):
    """Radius of a porous aggregate with enlargement (volume-filling) parameter ``psi``.

    ``psi`` = V / V* is the ratio of the aggregate's (extended) volume to its compact volume
    (psi = 1/phi with phi the filling factor; psi >= 1 for real aggregates, psi = 1 is compact).

    Arguments:
        m: aggregate mass [g] (> 0).
        rho_s: material (monomer) density [g cm^-3] (> 0).
        psi: enlargement parameter [-] (> 0).

    Returns:
        a = a* psi^(1/3) [cm], with a* = compact_radius(m, rho_s).

    References: Ormel (2008) thesis ch. 2 §2.2 and eq. 2.25 (tau_f = rho_s a*/(c_g rho_g psi^(2/3))).
    """
    m = _check(m, "m", positive=True, hint="pass the particle mass in g")
    rho_s = _check(rho_s, "rho_s", positive=True, hint="pass the material density in g cm^-3 (e.g. 3.0)")
    psi = _check(psi, "psi", positive=True, hint="psi = V/V* is the enlargement parameter (1 = compact, >= 1 for aggregates)")
    return _porous_radius(m, rho_s, psi)


def _projected_area(a):
    """Unvalidated :func:`projected_area`."""
    return jnp.pi * a * a


def projected_area(a):
    """Geometric projected area of a sphere of radius ``a``.

    Arguments:
        a: radius [cm] (> 0).

    Returns:
        A = pi a^2 [cm^2].

    References: Ormel (2008) thesis eqs. 2.4, 4.5 (A = pi a^2); spec/velocities.md §0.1.
    """
    a = _check(a, "a", positive=True, hint="pass the particle radius in cm")
    return _projected_area(a)


# --------------------------------------------------------------------------------------------
# friction time


def _friction_time(m, a, gas, *, area=None, regime="auto"):
    """Unvalidated :func:`friction_time` (``regime`` is still checked: it is static structure)."""
    _regime_ok(regime)
    A = _projected_area(a) if area is None else area
    # (m / A) first: keeps intermediate magnitudes moderate for very large bodies.
    tau_ep = (m / A) * (0.75 / (gas.c_g * gas.rho_g))
    if regime == "epstein":
        return tau_ep
    factor = 4.0 * a / (9.0 * gas.l_mfp)
    if regime == "stokes":
        return tau_ep * factor
    return tau_ep * jnp.maximum(1.0, factor)


def friction_time(m, a, gas, *, area=None, regime="auto"):
    """Friction (stopping) time of a particle in the gas.

    Epstein: tau_Ep = 3 m / (4 c_g rho_g A). Stokes (particle Reynolds number < 1):
    tau_St = tau_Ep * 4 a / (9 l_mfp). ``regime="auto"`` uses tau_Ep * max(1, 4a/(9 l_mfp)),
    which is continuous at a = 9/4 l_mfp (the factor is 1 there) but has a kink; at the kink
    ``jax.grad`` returns the average of the one-sided slopes (spec §8.5 item 5).
    The factor 4a/(9 l_mfp) equals the Stokes law 2 rho_s a^2/(9 nu_m rho_g) only for
    nu_m = c_g l_mfp/2 (the default ``nu_m_divisor``; spec §0.2 item 3).

    Arguments:
        m: particle mass [g] (> 0).
        a: particle geometric radius [cm] (> 0); sets the Epstein/Stokes switch and, if
            ``area`` is None, the projected area pi a^2.
        gas: :class:`jaxcoag.physics.gas.GasState` (uses c_g, rho_g, l_mfp).
        area: projected area A [cm^2] (> 0); default pi a^2.
        regime: "auto" (default), "epstein" or "stokes" (static Python string).

    Returns:
        tau_f [s].

    References: Ormel (2008) thesis eqs. 2.4, 3.1, 4.5 (Epstein; eq. 6.12 has a spurious pi,
    typo #13), eq. 4.6 (Stokes), ch. 2 footnote 3 (switch); spec/velocities.md §2.1-2.2.
    """
    _regime_ok(regime)
    m = _check(m, "m", positive=True, hint="pass the particle mass in g")
    a = _check(a, "a", positive=True, hint="pass the particle radius in cm")
    if area is not None:
        area = _check(area, "area", positive=True, hint="pass the projected area in cm^2 (or None for pi a^2)")
    return _friction_time(m, a, gas, area=area, regime=regime)


def _friction_time_compact(m, rho_s, gas, *, regime="auto"):
    """Unvalidated :func:`friction_time_compact`."""
    return _friction_time(m, _compact_radius(m, rho_s), gas, regime=regime)


def friction_time_compact(m, rho_s, gas, *, regime="auto"):
    """Friction time of a compact sphere: Epstein value rho_s a / (c_g rho_g), Stokes-corrected.

    Arguments:
        m: particle mass [g] (> 0).
        rho_s: material density [g cm^-3] (> 0).
        gas: GasState.
        regime: "auto" (default), "epstein" or "stokes".

    Returns:
        tau_f [s] = friction_time(m, compact_radius(m, rho_s), gas, regime=regime).

    References: Ormel (2008) thesis eqs. 4.5-4.6 and §4.2.2 (1 um grain at 3 AU: tau_f ~ 1e2 s);
    spec/velocities.md §2.1, check #38.
    """
    _regime_ok(regime)
    m = _check(m, "m", positive=True, hint="pass the particle mass in g")
    rho_s = _check(rho_s, "rho_s", positive=True, hint="pass the material density in g cm^-3 (e.g. 3.0)")
    return _friction_time_compact(m, rho_s, gas, regime=regime)


def _stokes_number(tau_f, gas):
    """Unvalidated :func:`stokes_number`."""
    return tau_f / gas.t_L


def stokes_number(tau_f, gas):
    """Stokes number St = tau_f / t_L.

    With the default t_L = 1/Omega this is Omega tau_f (the St of eqs. 4.8, 4.29); with
    ``tL_factor = 2 pi`` (ch. 2 legacy) it is Omega tau_f / (2 pi).

    Arguments:
        tau_f: friction time [s] (>= 0).
        gas: GasState (uses t_L).

    Returns:
        St [-].

    References: Ormel (2008) thesis ch. 4 footnote 5 (St = tau_f/t_L); spec/velocities.md §2.3.
    """
    tau_f = _check(tau_f, "tau_f", nonnegative=True, hint="pass the friction time in s")
    return _stokes_number(tau_f, gas)


# --------------------------------------------------------------------------------------------
# settling utilities


def _particle_scale_height(st, gas, *, form="dubrulle"):
    """Unvalidated :func:`particle_scale_height` (``form`` still checked)."""
    _form_ok(form)
    st_om = clamp_st(st * (gas.Omega * gas.t_L))  # Omega tau_f, floored (spec §8.2)
    alpha = gas.alpha
    if form == "dubrulle":
        # H_g / sqrt(1 + S) = H_g sqrt(alpha/(alpha + St)): finite for alpha = 0 and St -> inf.
        return gas.H_g * safe_sqrt(alpha / (alpha + st_om))
    return gas.H_g * safe_sqrt(jnp.minimum(1.0, alpha / st_om))


def particle_scale_height(st, gas, *, form="dubrulle"):
    """Dust scale height from the balance of settling and turbulent diffusion (Sc = 1).

    ``form="dubrulle"`` (default): h_p = H_g / sqrt(1 + S), S = Omega tau_f / alpha (eq. 4.29),
    smooth. ``form="ch1"``: h_p = H_g sqrt(alpha / (Omega tau_f)) if Omega tau_f > alpha
    else H_g (eq. 1.26), with a kink at Omega tau_f = alpha. Both have the same asymptotes
    (spec typo table #22). The Stokes number ``st`` = tau_f/t_L is converted to Omega tau_f
    with the gas state's t_L (identical for the default t_L = 1/Omega).

    Arguments:
        st: Stokes number tau_f / t_L [-] (>= 0; floored at 1e-30 internally).
        gas: GasState (uses H_g, alpha, Omega, t_L).
        form: "dubrulle" (default) or "ch1" (static Python string).

    Returns:
        h_p [cm] (alpha = 0 gives 0 for any St > 0).

    References: Ormel (2008) thesis eq. 4.29 (Dubrulle et al. 1995) and eq. 1.26;
    spec/velocities.md §2.3.
    """
    _form_ok(form)
    st = _check(st, "st", nonnegative=True, hint="pass the Stokes number tau_f/t_L")
    return _particle_scale_height(st, gas, form=form)


def _rainout_stokes(gas):
    """Unvalidated :func:`rainout_stokes`."""
    return gas.alpha / (gas.Omega * gas.t_L)


def rainout_stokes(gas):
    """Stokes number at which particles rain out: tau_rain = alpha / Omega.

    Arguments:
        gas: GasState (uses alpha, Omega, t_L).

    Returns:
        St_rain = tau_rain / t_L [-]; equals alpha for the default t_L = 1/Omega.

    References: Ormel (2008) thesis eq. 2.25 (tau_rain = alpha/Omega) and eq. 1.26;
    spec/velocities.md §2.3.
    """
    return _rainout_stokes(gas)
