"""Brownian and systematic (drift) relative velocities between two particles (cgs).

Pairwise functions come in two forms: ``dv_*`` (a speed, >= 0) and ``dv2_*`` (its square).
Velocity components add in quadrature (thesis ch. 4 §4.3), so kernels use the ``dv2_*``
forms, sum them, and take ONE safe sqrt of the total (velocity hazard 1 in docs/design_notes.md).
Pairwise drift squares are computed as squares of differences, never with ``abs`` (velocity
hazard 5, item 5).

Thesis physics (on by default in a disk scene): Brownian motion (eqs. 2.1, 4.4, 1.23) and
radial drift (eq. 4.8). Optional: collective-effects radial drift (eq. 4.28; Nakagawa et al.
1986). **[EXT] extensions, not from the thesis and off by default:** azimuthal drift
(headwind; derived from the same single-particle equations as eq. 4.8) and vertical settling
with the St/(1+St) cap.

Stokes numbers in the drift formulas are Omega tau_f (= tau_f/t_L for the default
t_L = 1/Omega; thesis ch. 4 footnote 5). They are never squared directly (no overflow up to
St ~ 1e300) and need no floor: every formula here is finite, with finite gradients, at St = 0.

Validated public functions have unvalidated internal twins for hot paths, with the same
signature and a leading underscore:

    _dv_brownian, _dv2_brownian, _log_dv2_brownian_from_log_mass, _v_radial_drift, _dv2_radial_drift,
    _v_radial_drift_collective, _v_azimuthal_drift, _dv2_azimuthal_drift,
    _v_settling, _dv2_settling

References: Ormel (2008) PhD thesis eqs. 1.23-1.25, 2.1, 4.4, 4.8, 4.28; velocity hazards in
docs/design_notes.md.
"""

from __future__ import annotations

import jax.numpy as jnp

from .. import constants as C
from .drag import _check
from .safe import safe_sqrt

__all__ = [
    "dv_brownian",
    "dv2_brownian",
    "v_radial_drift",
    "dv2_radial_drift",
    "v_radial_drift_collective",
    "v_azimuthal_drift",
    "dv2_azimuthal_drift",
    "v_settling",
    "dv2_settling",
]

_ST_HINT = "pass the Stokes number Omega tau_f (>= 0)"


# --------------------------------------------------------------------------------------------
# bounded building blocks (no St^2, no products of large numbers)


def _as_float(st):
    st = jnp.asarray(st)
    return st if jnp.issubdtype(st.dtype, jnp.floating) else st.astype(jnp.result_type(float))


def _st_over_1_plus_st2(st):
    """St/(1 + St^2) for St >= 0 without forming St^2 for St > 1 (double-where)."""
    st = _as_float(st)
    small = st <= 1.0
    x = jnp.where(small, st, 1.0)  # safe input for the St <= 1 branch
    u = 1.0 / jnp.where(small, 2.0, st)  # 1/St for the St > 1 branch
    return jnp.where(small, x / (1.0 + x * x), u / (1.0 + u * u))


def _one_over_1_plus_st2(st):
    """1/(1 + St^2) for St >= 0 without forming St^2 for St > 1 (double-where)."""
    st = _as_float(st)
    small = st <= 1.0
    x = jnp.where(small, st, 1.0)
    u = 1.0 / jnp.where(small, 2.0, st)
    return jnp.where(small, 1.0 / (1.0 + x * x), (u * u) / (1.0 + u * u))


# --------------------------------------------------------------------------------------------
# Brownian motion


def _dv2_brownian(m1, m2, T):
    """Unvalidated :func:`dv2_brownian`."""
    return (8.0 * C.k_B / jnp.pi) * T * (1.0 / m1 + 1.0 / m2)


def _dv_brownian(m1, m2, T):
    """Unvalidated :func:`dv_brownian`."""
    return safe_sqrt((8.0 * C.k_B / jnp.pi) * T) * safe_sqrt(1.0 / m1 + 1.0 / m2)


def _log_dv2_brownian_from_log_mass(logm1, logm2, T):
    """Unvalidated ln(Delta v_BM^2) from log-masses (hot path for log-space kernels).

    ln(8 k_B T/pi) + logaddexp(-ln m1, -ln m2): overflow-free for any mass (also beyond
    1e308 g) and with exact gradients in ln m (the linear forms lose them to underflow of
    1/m^2 for m >~ 1e154 g). References: thesis eqs. 2.1, 4.4.
    """
    return jnp.log((8.0 * C.k_B / jnp.pi) * T) + jnp.logaddexp(-logm1, -logm2)


def _check_brownian(m1, m2, T):
    m1 = _check(m1, "m1", positive=True, hint="pass particle masses in g")
    m2 = _check(m2, "m2", positive=True, hint="pass particle masses in g")
    T = _check(T, "T", positive=True, hint="pass the gas temperature in K")
    return m1, m2, T


def dv_brownian(m1, m2, T):
    """Mean Brownian relative speed of two particles.

    Delta v_BM = sqrt(8 k_B T / (pi m_mu)), m_mu = m1 m2/(m1 + m2), evaluated as
    sqrt(8 k_B T/pi) * sqrt(1/m1 + 1/m2) so that m1 m2 is never formed (finite for masses up
    to ~1e308 g; velocity hazard 6). For equal porous aggregates it equals the eq. 4.22a form
    (2/pi) sqrt(3 k_B T/rho_s) a^-3/2 phi^-1/2.

    Arguments:
        m1, m2: particle masses [g] (> 0; broadcasting).
        T: gas temperature [K] (> 0).

    Returns:
        Delta v_BM [cm s^-1].

    References: Ormel (2008) thesis eqs. 1.23, 2.1, 4.4, 4.22a.
    """
    return _dv_brownian(*_check_brownian(m1, m2, T))


def dv2_brownian(m1, m2, T):
    """Square of the Brownian relative speed, 8 k_B T (1/m1 + 1/m2) / pi.

    This is the term added in quadrature to the total Delta v^2 (the one kernels use).

    Arguments:
        m1, m2: particle masses [g] (> 0; broadcasting).
        T: gas temperature [K] (> 0).

    Returns:
        Delta v_BM^2 [cm^2 s^-2].

    References: Ormel (2008) thesis eqs. 2.1, 4.4 and §4.3 (quadrature sum).
    """
    return _dv2_brownian(*_check_brownian(m1, m2, T))


# --------------------------------------------------------------------------------------------
# radial drift (thesis eq. 4.8)


def _v_radial_drift(st, eta, v_K):
    """Unvalidated :func:`v_radial_drift`."""
    return -2.0 * eta * v_K * _st_over_1_plus_st2(st)


def v_radial_drift(st, eta, v_K):
    """Radial drift velocity of a single particle (Weidenschilling 1977a).

    v_rd = -2 St eta v_K / (1 + St^2); peaks at |v_rd| = eta v_K for St = 1. Negative is inward.

    Arguments:
        st: Stokes number Omega tau_f [-] (>= 0).
        eta: pressure-gradient parameter [-] (eq. 4.7; GasState.eta).
        v_K: Keplerian velocity [cm s^-1] (GasState.v_K).

    Returns:
        v_rd [cm s^-1] (<= 0 for eta > 0).

    References: Ormel (2008) thesis eq. 4.8 (magnitude eq. 1.25).
    """
    st = _check(st, "st", nonnegative=True, hint=_ST_HINT)
    eta = _check(eta, "eta", hint="eta is the radial pressure-gradient parameter (GasState.eta)")
    v_K = _check(v_K, "v_K", nonnegative=True, hint="pass the Keplerian velocity in cm s^-1")
    return _v_radial_drift(st, eta, v_K)


def _dv2_radial_drift(st1, st2, eta, v_K):
    """Unvalidated :func:`dv2_radial_drift`."""
    d = 2.0 * eta * v_K * (_st_over_1_plus_st2(st1) - _st_over_1_plus_st2(st2))
    return d * d


def dv2_radial_drift(st1, st2, eta, v_K):
    """Squared pairwise radial-drift relative velocity, (v_rd(St1) - v_rd(St2))^2.

    Computed as the square of a difference (no ``abs``: smooth at St1 = St2). Invariant under
    St -> 1/St, so it vanishes for St1 = St2 and for St1 St2 = 1.

    Arguments:
        st1, st2: Stokes numbers Omega tau_f [-] (>= 0; broadcasting).
        eta: pressure-gradient parameter [-].
        v_K: Keplerian velocity [cm s^-1].

    Returns:
        Delta v_r^2 [cm^2 s^-2].

    References: Ormel (2008) thesis eq. 4.8 and §4.3 (quadrature); velocity hazard 5
    (docs/design_notes.md).
    """
    st1 = _check(st1, "st1", nonnegative=True, hint=_ST_HINT)
    st2 = _check(st2, "st2", nonnegative=True, hint=_ST_HINT)
    eta = _check(eta, "eta", hint="eta is the radial pressure-gradient parameter (GasState.eta)")
    v_K = _check(v_K, "v_K", nonnegative=True, hint="pass the Keplerian velocity in cm s^-1")
    return _dv2_radial_drift(st1, st2, eta, v_K)


def _v_radial_drift_collective(st, eta, v_K, eps_dust):
    """Unvalidated :func:`v_radial_drift_collective`."""
    d = 1.0 + eps_dust
    # 2 St/(St^2 + d^2) = (2/d) x/(1 + x^2) with x = St/d (no St^2).
    return -2.0 * eta * v_K * _st_over_1_plus_st2(st / d) / d


def v_radial_drift_collective(st, eta, v_K, eps_dust):
    """Radial drift with collective (dust-loading) effects, single particle size (optional).

    v_rd = -2 St eta v_K / (St^2 + (1 + eps)^2), eps = rho_p/rho_g the local dust-to-gas
    density ratio (Nakagawa et al. 1986). eps = 0 reduces to eq. 4.8. The thesis prints the
    magnitude; the sign here is the inward (negative) one of eq. 4.8. Optional: the thesis
    ch. 4 simulations ignore it (footnote 4) and use it only for Table 4.5 col. (8); keep it
    off by default (``collective=False``).

    Arguments:
        st: Stokes number Omega tau_f [-] (>= 0).
        eta: pressure-gradient parameter [-].
        v_K: Keplerian velocity [cm s^-1].
        eps_dust: midplane dust-to-gas density ratio rho_p/rho_g [-] (>= 0).

    Returns:
        v_rd [cm s^-1].

    References: Ormel (2008) thesis eq. 4.28 (Nakagawa et al. 1986).
    """
    st = _check(st, "st", nonnegative=True, hint=_ST_HINT)
    eta = _check(eta, "eta", hint="eta is the radial pressure-gradient parameter (GasState.eta)")
    v_K = _check(v_K, "v_K", nonnegative=True, hint="pass the Keplerian velocity in cm s^-1")
    eps_dust = _check(eps_dust, "eps_dust", nonnegative=True, hint="eps_dust = rho_p/rho_g, the dust-to-gas density ratio")
    return _v_radial_drift_collective(st, eta, v_K, eps_dust)


# --------------------------------------------------------------------------------------------
# [EXT] azimuthal drift (headwind)


def _v_azimuthal_drift(st, eta, v_K):
    """Unvalidated :func:`v_azimuthal_drift`."""
    return -eta * v_K * _one_over_1_plus_st2(st)


def v_azimuthal_drift(st, eta, v_K):
    """[EXT] Azimuthal velocity of a particle relative to Keplerian, -eta v_K / (1 + St^2).

    NOT from the thesis (which gives only the gas lag eta v_K, eq. 1.24, and mentions the
    headwind qualitatively); derived from the same steady single-particle equations that give
    eq. 4.8 (Weidenschilling 1977a; Nakagawa et al. 1986 with eps = 0). Off by default.
    Limits: -eta v_K (moves with the gas) for St -> 0, 0 (Keplerian) for St -> inf. The
    particle-gas headwind is eta v_K St^2/(1 + St^2).

    Arguments:
        st: Stokes number Omega tau_f [-] (>= 0).
        eta: pressure-gradient parameter [-].
        v_K: Keplerian velocity [cm s^-1].

    Returns:
        v_phi - v_K [cm s^-1].

    References: [EXT] Weidenschilling (1977a); Nakagawa et al. (1986) (steady state of the
    single-particle equations behind thesis eq. 4.8).
    """
    st = _check(st, "st", nonnegative=True, hint=_ST_HINT)
    eta = _check(eta, "eta", hint="eta is the radial pressure-gradient parameter (GasState.eta)")
    v_K = _check(v_K, "v_K", nonnegative=True, hint="pass the Keplerian velocity in cm s^-1")
    return _v_azimuthal_drift(st, eta, v_K)


def _dv2_azimuthal_drift(st1, st2, eta, v_K):
    """Unvalidated :func:`dv2_azimuthal_drift`."""
    d = eta * v_K * (_one_over_1_plus_st2(st1) - _one_over_1_plus_st2(st2))
    return d * d


def dv2_azimuthal_drift(st1, st2, eta, v_K):
    """[EXT] Squared pairwise azimuthal-drift velocity, (eta v_K)^2 (1/(1+St1^2) - 1/(1+St2^2))^2.

    NOT from the thesis; off by default (see :func:`v_azimuthal_drift`). Square of a
    difference, never ``abs``.

    Arguments:
        st1, st2: Stokes numbers Omega tau_f [-] (>= 0; broadcasting).
        eta: pressure-gradient parameter [-].
        v_K: Keplerian velocity [cm s^-1].

    Returns:
        Delta v_phi^2 [cm^2 s^-2].

    References: [EXT] Weidenschilling (1977a); thesis eq. 1.24 (gas lag eta v_K).
    """
    st1 = _check(st1, "st1", nonnegative=True, hint=_ST_HINT)
    st2 = _check(st2, "st2", nonnegative=True, hint=_ST_HINT)
    eta = _check(eta, "eta", hint="eta is the radial pressure-gradient parameter (GasState.eta)")
    v_K = _check(v_K, "v_K", nonnegative=True, hint="pass the Keplerian velocity in cm s^-1")
    return _dv2_azimuthal_drift(st1, st2, eta, v_K)


# --------------------------------------------------------------------------------------------
# [EXT] vertical settling


def _capped(st):
    """St/(1 + St), bounded in [0, 1) and overflow-free."""
    st = _as_float(st)
    return st / (1.0 + st)


def _v_settling(st, z, Omega):
    """Unvalidated :func:`v_settling`."""
    return -z * Omega * _capped(st)


def v_settling(st, z, Omega):
    """[EXT] Vertical settling velocity, capped: v_z = -z Omega St/(1 + St).

    The thesis (ch. 1 §1.2.1) gives the St << 1 terminal velocity v_z = -Omega^2 z tau_f =
    -z Omega St (with g_z = Omega^2 z: typo #10), which is invalid for St >~ 1; the cap
    St/(1 + St) is an extension (NOT from the thesis) that keeps |v_z| <= z Omega. Off by
    default (ch. 4 has no settling; ch. 2 models it as rain-out).

    Arguments:
        st: Stokes number Omega tau_f [-] (>= 0).
        z: height above the midplane [cm].
        Omega: Keplerian frequency [s^-1] (>= 0).

    Returns:
        v_z [cm s^-1] (towards the midplane: negative for z > 0).

    References: Ormel (2008) thesis ch. 1 §1.2.1 (St << 1 limit); [EXT] cap.
    """
    st = _check(st, "st", nonnegative=True, hint=_ST_HINT)
    z = _check(z, "z", hint="pass the height above the midplane in cm")
    Omega = _check(Omega, "Omega", nonnegative=True, hint="pass the Keplerian frequency in s^-1")
    return _v_settling(st, z, Omega)


def _dv2_settling(st1, st2, z, Omega):
    """Unvalidated :func:`dv2_settling`."""
    s1 = _as_float(st1)
    s2 = _as_float(st2)
    # St1/(1+St1) - St2/(1+St2) = ((St1 - St2)/(1 + St1))/(1 + St2): no cancellation, no product overflow.
    d = z * Omega * (((s1 - s2) / (1.0 + s1)) / (1.0 + s2))
    return d * d


def dv2_settling(st1, st2, z, Omega):
    """[EXT] Squared pairwise settling velocity at a common height z (capped form).

    (z Omega)^2 (St1/(1+St1) - St2/(1+St2))^2; reduces to (z Omega (St1 - St2))^2 for St << 1
    (thesis ch. 1). Extension, NOT from the thesis; off by default.

    Arguments:
        st1, st2: Stokes numbers Omega tau_f [-] (>= 0; broadcasting).
        z: height above the midplane [cm].
        Omega: Keplerian frequency [s^-1] (>= 0).

    Returns:
        Delta v_z^2 [cm^2 s^-2].

    References: Ormel (2008) thesis ch. 1 §1.2.1; [EXT] cap.
    """
    st1 = _check(st1, "st1", nonnegative=True, hint=_ST_HINT)
    st2 = _check(st2, "st2", nonnegative=True, hint=_ST_HINT)
    z = _check(z, "z", hint="pass the height above the midplane in cm")
    Omega = _check(Omega, "Omega", nonnegative=True, hint="pass the Keplerian frequency in s^-1")
    return _dv2_settling(st1, st2, z, Omega)
