"""Particle radii, gas drag (friction time), Stokes number and particle scale height (cgs).

Every public function validates its array arguments with :func:`jaxcoag._validate.check`
(concrete input: :class:`~jaxcoag._validate.JaxcoagInputError`; traced input:
``eqx.error_if``). Hot paths (ODE right-hand sides, Monte Carlo loops) should call the
unvalidated internal twins, which have the same signature and a leading underscore:

    _compact_radius, _porous_radius, _projected_area, _friction_time,
    _friction_time_compact, _stokes_number, _particle_scale_height, _rainout_stokes,
    _thermal_speed

All functions are pure, broadcasting (numpy rules; under ``jax_numpy_rank_promotion="raise"``
broadcast explicitly, e.g. ``m[:, None]``), and jit/vmap/grad safe.

References (Ormel 2008 PhD thesis eqs. 1.20-1.21, 2.4, 3.1, 4.5-4.6):
    Epstein   tau_Ep = 3 m / (4 c_g rho_g A)        eqs. 2.4, 3.1, 4.5 (NOT eq. 6.12: typo #13)
    Stokes    tau_St = [4 a / (9 l_mfp)] tau_Ep      eq. 4.6 with Re_p < 1 (C = 1/Re_p)
    switch at a = 9/4 l_mfp (continuous)             ch. 2 footnote 3, eqs. 4.5/4.6 (typo #9)
    porous radius a = a* psi^(1/3)                   ch. 2, eq. 2.25 context (Fig. 2.2)
    St = tau_f / t_L                                 ch. 4 footnote 5
    h_p = H_g / sqrt(1 + St/alpha)                   eq. 4.29 (Dubrulle et al. 1995)
    h_p = H_g sqrt(alpha/St) if St > alpha else H_g  eq. 1.26
    rain-out St = alpha (tau_rain = alpha/Omega)     eq. 2.25

Drag conventions (``convention=`` of the friction-time functions, static structure). The two
differ in the gas speed of the Epstein law and in the mean free path (which sets the Stokes
switch and the Stokes factor); with c_g = sqrt(k_B T/(mu m_H)) and n = rho_g/(mu m_H):

* ``"ormel"`` (default): tau_Ep = 3 m/(4 rho_g c_g A) with the isothermal sound speed c_g, and
  l_mfp = mu m_H/(rho_g sigma_mol) = 1/(n sigma_mol) (no sqrt 2) - Ormel (2008) thesis eqs. 1.13,
  2.4, 4.5 and ch. 1 below eq. 1.17; Ormel, Spaans & Tielens (2007) A&A 461, 215, footnotes to
  §2 (Epstein limit a < 9/4 l_mfp, Stokes factor 4a/(9 l_mfp) after Weidenschilling 1977, MNRAS
  180, 57; nu_m = c_g l_mfp/2). Compact spheres: tau_Ep = rho_s a/(rho_g c_g).
* ``"dustpy"``: tau_Ep = 3 m/(4 rho_g v_th A) with the mean thermal speed
  v_th = sqrt(8/pi) c_g, and lambda = 1/(sqrt(2) n sigma_mol) = l_mfp/sqrt(2) - Birnstiel,
  Dullemond & Brauer (2010) A&A 513, A79, §2 (Epstein St = pi a rho_s/(2 Sigma_g), which is
  Omega tau_Ep at the midplane density rho_g = Sigma_g/(sqrt(2 pi) H_g), and the Stokes-I law);
  Stammler & Birnstiel (2022) ApJ 935, 35 (DustPy ``St_Epstein_StokesI``, ``mfp_midplane``).
  Stokes: tau_St = [4 a/(9 lambda)] tau_Ep with the switch at a = 9/4 lambda, i.e.
  tau_St = 2 rho_s a^2/(9 nu rho_g) with nu = v_th lambda/2.

For the same grain, St_ormel/St_dustpy = sqrt(8/pi) = 1.596 in the Epstein regime and
sqrt(8/pi)/sqrt(2) = 2/sqrt(pi) = 1.128 in the Stokes regime (both conventions in Stokes).
The turbulent Reynolds number is a separate gas convention: DustPy's Re = alpha Sigma_g
sigma_mol/(2 mu m_H) is ``nu_m_divisor = sqrt(pi/2)`` in :func:`jaxcoag.physics.gas.midplane_state`.
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from .._validate import JaxcoagInputError, check
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
    "thermal_speed",
    "drag_mean_free_path",
    "REGIMES",
    "SCALE_HEIGHT_FORMS",
    "DRAG_CONVENTIONS",
]

REGIMES = ("auto", "epstein", "stokes")
SCALE_HEIGHT_FORMS = ("dubrulle", "ch1")
#: drag conventions (module docstring): "ormel" (c_g, 1/(n sigma)) and "dustpy" (v_th, 1/(sqrt2 n sigma))
DRAG_CONVENTIONS = ("ormel", "dustpy")

_SQRT_8_OVER_PI = math.sqrt(8.0 / math.pi)  # v_th / c_g
_SQRT_2 = math.sqrt(2.0)


_check = check  # check() validates Python constants eagerly, also inside jit


def _regime_ok(regime):
    if regime not in REGIMES:
        raise ValueError(
            f"unknown drag regime {regime!r}; use one of {REGIMES} ('auto' switches continuously "
            "from Epstein to Stokes drag at a = 9/4 l_mfp; Ormel 2008 thesis eqs. 4.5-4.6)"
        )


def _convention_ok(convention):
    if convention not in DRAG_CONVENTIONS:
        raise JaxcoagInputError(
            f"unknown drag convention {convention!r}; use one of {DRAG_CONVENTIONS} ('ormel': Epstein "
            "law with the isothermal sound speed and l_mfp = 1/(n sigma), Ormel 2008 eqs. 2.4/4.5; "
            "'dustpy': mean thermal speed sqrt(8/pi) c_g and 1/(sqrt(2) n sigma), Birnstiel et al. 2010)"
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

    References: Ormel (2008) thesis ch. 2 (compact size a*, Fig. 2.2).
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

    References: Ormel (2008) thesis eqs. 2.4, 4.5 (A = pi a^2).
    """
    a = _check(a, "a", positive=True, hint="pass the particle radius in cm")
    return _projected_area(a)


# --------------------------------------------------------------------------------------------
# friction time


def _thermal_speed(gas):
    """Unvalidated :func:`thermal_speed`."""
    return _SQRT_8_OVER_PI * gas.c_g


def thermal_speed(gas):
    """Mean thermal speed of the gas molecules, v_th = sqrt(8/pi) c_g = sqrt(8 k_B T/(pi mu m_H)).

    Arguments:
        gas: :class:`jaxcoag.physics.gas.GasState` (uses c_g [cm s^-1]).

    Returns:
        v_th [cm s^-1] (the gas speed of the "dustpy" Epstein law).

    References: Birnstiel, Dullemond & Brauer (2010) A&A 513, A79, §2; Stammler & Birnstiel
    (2022) ApJ 935, 35 (DustPy).
    """
    return _thermal_speed(gas)


def _drag_speed_mfp(gas, convention):
    """(gas speed of the Epstein law [cm/s], mean free path [cm]) of a drag convention."""
    _convention_ok(convention)
    if convention == "ormel":
        return gas.c_g, gas.l_mfp
    return _thermal_speed(gas), gas.l_mfp / _SQRT_2


def drag_mean_free_path(gas, *, convention="ormel"):
    """Molecular mean free path used by the Epstein/Stokes switch of a drag convention.

    Arguments:
        gas: GasState (uses l_mfp = mu m_H/(rho_g sigma_mol) [cm]).
        convention: "ormel" (default; l_mfp = 1/(n sigma_mol)) or "dustpy"
            (lambda = 1/(sqrt(2) n sigma_mol) = l_mfp/sqrt(2)) (static Python string).

    Returns:
        mean free path [cm].

    References: Ormel (2008) thesis ch. 1 below eq. 1.17 ("ormel"); Birnstiel et al. (2010) §2,
    DustPy ``mfp_midplane`` ("dustpy").
    """
    return _drag_speed_mfp(gas, convention)[1]


def _friction_time(m, a, gas, *, area=None, regime="auto", convention="ormel"):
    """Unvalidated :func:`friction_time` (``regime``/``convention`` are still checked: structure)."""
    _regime_ok(regime)
    v_gas, mfp = _drag_speed_mfp(gas, convention)
    A = _projected_area(a) if area is None else area
    # (m / A) first: keeps intermediate magnitudes moderate for very large bodies.
    tau_ep = (m / A) * (0.75 / (v_gas * gas.rho_g))
    if regime == "epstein":
        return tau_ep
    factor = 4.0 * a / (9.0 * mfp)
    if regime == "stokes":
        return tau_ep * factor
    return tau_ep * jnp.maximum(1.0, factor)


def friction_time(m, a, gas, *, area=None, regime="auto", convention="ormel"):
    """Friction (stopping) time of a particle in the gas.

    Epstein: tau_Ep = 3 m / (4 v rho_g A). Stokes (particle Reynolds number < 1):
    tau_St = tau_Ep * 4 a / (9 lambda). ``regime="auto"`` uses tau_Ep * max(1, 4a/(9 lambda)),
    which is continuous at a = 9/4 lambda (the factor is 1 there) but has a kink; at the kink
    ``jax.grad`` returns the average of the one-sided slopes (velocity hazard 5, item 5, in
    docs/design_notes.md). The gas speed v and mean free path lambda depend on ``convention``
    (module docstring): "ormel" (default) v = c_g (isothermal sound speed), lambda = l_mfp;
    "dustpy" v = v_th = sqrt(8/pi) c_g, lambda = l_mfp/sqrt(2). The same grain has a
    friction time sqrt(8/pi) = 1.596 times longer in "ormel" than in "dustpy" (Epstein).
    With "ormel" the factor 4a/(9 l_mfp) equals the Stokes law 2 rho_s a^2/(9 nu_m rho_g) only
    for nu_m = c_g l_mfp/2 (the default ``nu_m_divisor``; thesis ch. 2 footnote 2; gas
    convention 3 in docs/design_notes.md); with "dustpy" it is that law for nu = v_th lambda/2.

    Arguments:
        m: particle mass [g] (> 0).
        a: particle geometric radius [cm] (> 0); sets the Epstein/Stokes switch and, if
            ``area`` is None, the projected area pi a^2.
        gas: :class:`jaxcoag.physics.gas.GasState` (uses c_g, rho_g, l_mfp).
        area: projected area A [cm^2] (> 0); default pi a^2.
        regime: "auto" (default), "epstein" or "stokes" (static Python string).
        convention: "ormel" (default) or "dustpy" (static Python string).

    Returns:
        tau_f [s].

    References: Ormel (2008) thesis eqs. 2.4, 3.1, 4.5 (Epstein; eq. 6.12 has a spurious pi,
    typo #13), eq. 4.6 (Stokes), ch. 2 footnote 3 (switch); Birnstiel, Dullemond & Brauer
    (2010) A&A 513, A79, §2 and Stammler & Birnstiel (2022) ApJ 935, 35 ("dustpy").
    """
    _regime_ok(regime)
    _convention_ok(convention)
    m = _check(m, "m", positive=True, hint="pass the particle mass in g")
    a = _check(a, "a", positive=True, hint="pass the particle radius in cm")
    if area is not None:
        area = _check(area, "area", positive=True, hint="pass the projected area in cm^2 (or None for pi a^2)")
    return _friction_time(m, a, gas, area=area, regime=regime, convention=convention)


def _friction_time_compact(m, rho_s, gas, *, regime="auto", convention="ormel"):
    """Unvalidated :func:`friction_time_compact`."""
    return _friction_time(m, _compact_radius(m, rho_s), gas, regime=regime, convention=convention)


def friction_time_compact(m, rho_s, gas, *, regime="auto", convention="ormel"):
    """Friction time of a compact sphere: Epstein value rho_s a / (v rho_g), Stokes-corrected.

    v = c_g for ``convention="ormel"`` (default), v = sqrt(8/pi) c_g for "dustpy" (then
    Omega tau_Ep = pi a rho_s/(2 Sigma_g) at the midplane, DustPy's Epstein Stokes number).

    Arguments:
        m: particle mass [g] (> 0).
        rho_s: material density [g cm^-3] (> 0).
        gas: GasState.
        regime: "auto" (default), "epstein" or "stokes".
        convention: "ormel" (default) or "dustpy" (see :func:`friction_time`).

    Returns:
        tau_f [s] = friction_time(m, compact_radius(m, rho_s), gas, regime=regime,
        convention=convention).

    References: Ormel (2008) thesis eqs. 4.5-4.6 and §4.2.2 (1 um grain at 3 AU: tau_f ~ 1e2 s);
    Birnstiel et al. (2010) §2 ("dustpy").
    """
    _regime_ok(regime)
    _convention_ok(convention)
    m = _check(m, "m", positive=True, hint="pass the particle mass in g")
    rho_s = _check(rho_s, "rho_s", positive=True, hint="pass the material density in g cm^-3 (e.g. 3.0)")
    return _friction_time_compact(m, rho_s, gas, regime=regime, convention=convention)


def _stokes_number(tau_f, gas):
    """Unvalidated :func:`stokes_number`."""
    return tau_f / gas.t_L


def stokes_number(tau_f, gas):
    """Stokes number St = tau_f / t_L.

    With the default t_L = 1/Omega this is Omega tau_f (the St of eqs. 4.8, 4.29); with
    ``tL_factor = 2 pi`` (ch. 2 legacy) it is Omega tau_f / (2 pi). St carries the drag
    convention of ``tau_f`` (module docstring): an Epstein grain has St 1.596 (= sqrt(8/pi))
    times larger with ``friction_time(..., convention="ormel")`` than with "dustpy"
    (DustPy's St = pi a rho_s/(2 Sigma_g)).

    Arguments:
        tau_f: friction time [s] (>= 0).
        gas: GasState (uses t_L).

    Returns:
        St [-].

    References: Ormel (2008) thesis ch. 4 footnote 5 (St = tau_f/t_L).
    """
    tau_f = _check(tau_f, "tau_f", nonnegative=True, hint="pass the friction time in s")
    return _stokes_number(tau_f, gas)


# --------------------------------------------------------------------------------------------
# settling utilities


def _particle_scale_height(st, gas, *, form="dubrulle"):
    """Unvalidated :func:`particle_scale_height` (``form`` still checked)."""
    _form_ok(form)
    st_om = clamp_st(st * (gas.Omega * gas.t_L))  # Omega tau_f, floored (velocity hazard 2)
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
    (thesis typo #22 in docs/design_notes.md). The Stokes number ``st`` = tau_f/t_L is converted to Omega tau_f
    with the gas state's t_L (identical for the default t_L = 1/Omega).

    Arguments:
        st: Stokes number tau_f / t_L [-] (>= 0; floored at 1e-30 internally).
        gas: GasState (uses H_g, alpha, Omega, t_L).
        form: "dubrulle" (default) or "ch1" (static Python string).

    Returns:
        h_p [cm] (alpha = 0 gives 0 for any St > 0).

    References: Ormel (2008) thesis eq. 4.29 (Dubrulle et al. 1995) and eq. 1.26.
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

    References: Ormel (2008) thesis eq. 2.25 (tau_rain = alpha/Omega) and eq. 1.26.
    """
    return _rainout_stokes(gas)
