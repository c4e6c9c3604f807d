"""Per-contact forces, torques and potentials of the Wada et al. (2007) monomer contact model (cgs).

A contact between monomers 1 and 2 (centres x_1, x_2, radius r1 each) carries two contact pointers n_1, n_2: unit
vectors fixed in each monomer's body, kept here in the space frame (they are rotated with the monomers by
:func:`rotate`, the exact equivalent of Wada et al. eqs. 28-34), and a scalar twist angle phi_s (phi = phi_s n_c,
eq. 24, integrated by the caller as phi_s += dt (omega_1 - omega_2).n_c). At creation n_1 = -n_c, n_2 = +n_c,
phi_s = 0. Vectors are always 3-vectors (planar runs have z = 0 and omega along z). Every function broadcasts over
leading axes.

Interactions (r_1 = r_2 = r1 of the material, R = r1/2, n_c = (x_1 - x_2)/|x_1 - x_2| (eq. 9)):
    normal    (eqs. 3-7):   delta = r_1 + r_2 - |x_1 - x_2|,  F_n,1 = F(delta) n_c,  U_n = U_n(delta)
    sliding   (eqs. 8-19):  zeta_0 = r_1 n_1 - r_2 n_2 + (r_1 + r_2) n_c,  zeta = zeta_0 - (zeta_0.n_c) n_c,
                            U_s = k_s |zeta|^2/2,  F_s,1 = -k_s zeta (r_1 + r_2 - zeta_0.n_c)/|x_1 - x_2|,
                            M_s,1 = -r_1 k_s n_1 x zeta,  M_s,2 = +r_2 k_s n_2 x zeta
    rolling   (eqs. 20-23): xi = R (n_1 + n_2),  U_r = k_r |xi|^2/2,  M_r,i = -R k_r n_i x xi
    twisting  (eqs. 24-27): U_t = k_t phi_s^2/2,  M_t,1 = -k_t phi_s n_c,  M_t,2 = +k_t phi_s n_c
with the torque identity M_1 + M_2 + (x_1 - x_2) x F_1 = 0 (the corrected eq. 19: r x F order), so a leapfrog
with these forces conserves total linear and angular momentum to round-off.

Inelastic regimes (eqs. 35-43, Appendix A): past zeta_crit, xi_crit, phi_crit the displacement is held at the
critical value by moving the pointers (the "initial contact point" is renewed), the force stays at its critical
value and the motion is elastic again about the shifted equilibrium on reversal (Fig. 3). The printed n_2 sliding
correction (eq. 42) has the wrong sign (it would leave zeta unchanged); the general-radius forms used here change
only the targeted displacement: sliding  n_1 -= dzeta/(r_1 + r_2), n_2 += dzeta/(r_1 + r_2); rolling
n_1 -= dxi/r_1, n_2 -= dxi/r_2 (R (1/r_1 + 1/r_2) = 1), each followed by renormalisation; the Appendix's factor
alpha = l'/l is replaced by fixed-point passes (correct, normalise, recompute) that land on the critical values to
round-off.

References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007, ApJ 661, 320) §2 eqs. 3-43 and Appendix A; Dominik &
Tielens (1997) for the rolling/sliding/twisting picture.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from .jkr import normal_force_and_potential

__all__ = ["ContactForces", "contact_geometry", "contact_forces", "clip_inelastic", "rotate", "rotation_coefficients",
           "rotate_by"]

_TINY = 1e-300  # guards norms of zero vectors (masked contact slots) without changing any non-zero value


def _dot(a, b):
    """a.b over the last axis (length 3), written out by component: XLA's CPU backend fuses this with the
    surrounding elementwise work, where a reduction over a length-3 minor axis runs ~4x slower."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]



def _cross(a, b):
    """a x b over the last axis (length 3), written out by component (fuses on XLA's CPU backend)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return jnp.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)

def _norm(a):
    """|a| with a zero (not NaN) gradient at a = 0."""
    s = _dot(a, a)
    safe = jnp.where(s > 0, s, 1.0)
    return jnp.where(s > 0, jnp.sqrt(safe), 0.0)


def _normalize(a):
    n = _norm(a)
    return a / jnp.where(n > 0, n, 1.0)[..., None]


class ContactForces(NamedTuple):
    """Forces, torques and potentials of one contact (broadcast over leading axes).

    Fields:
        F1: total force on monomer 1 (normal eq. 7 + sliding eq. 14) [dyn], shape (..., 3); the force on 2 is -F1.
        M1, M2: torques on monomers 1 and 2 (sliding eqs. 15-17, rolling eq. 23, twisting eq. 27) [dyn cm].
        U_n, U_s, U_r, U_t: normal (eq. 6), sliding (eq. 11), rolling (eq. 21), twisting (eq. 25) energies [erg].
    """

    F1: jax.Array
    M1: jax.Array
    M2: jax.Array
    U_n: jax.Array
    U_s: jax.Array
    U_r: jax.Array
    U_t: jax.Array


def contact_geometry(x1, x2, n1, n2, mat):
    """Geometry of a contact: (dist, n_c, delta, zeta_0, zeta, xi).

    Arguments: x1, x2: centres [cm] (..., 3); n1, n2: contact pointers (..., 3) (unit, space frame); mat: Material.
    Returns: dist = |x_1 - x_2| [cm]; n_c = (x_1 - x_2)/dist (eq. 9; 0 for coincident centres); delta [cm] (eq. 3);
    zeta_0, zeta [cm] (eqs. 8, 10); xi [cm] (eq. 20).
    """
    r_1 = r_2 = mat.r1
    R = mat.R
    d = jnp.asarray(x1) - jnp.asarray(x2)
    dist = _norm(d)
    n_c = d / jnp.where(dist > 0, dist, 1.0)[..., None]
    delta = r_1 + r_2 - dist
    z0 = r_1 * n1 - r_2 * n2 + (r_1 + r_2) * n_c
    zeta = z0 - _dot(z0, n_c)[..., None] * n_c
    xi = R * (n1 + n2)
    return dist, n_c, delta, z0, zeta, xi


def contact_forces(x1, x2, n1, n2, phi_s, mat) -> ContactForces:
    """Forces, torques and potentials of a contact in the Wada et al. (2007) model.

    Arguments:
        x1, x2: monomer centres [cm], shape (..., 3).
        n1, n2: contact pointers of monomers 1 and 2 (unit vectors in the space frame), (..., 3).
        phi_s: twist angle phi.n_c [rad], shape (...).
        mat: :class:`~jaxcoag.aggregates.contact.materials.Material` (r1, k_s, k_r, k_t, JKR scales).

    Returns:
        :class:`ContactForces` (F1, M1, M2 [dyn], [dyn cm]; U_n, U_s, U_r, U_t [erg]). Finite for coincident centres
        (n_c = 0), so masked slots of a fixed-capacity contact list do not poison gradients.

    References: Wada et al. (2007) eqs. 3-27 with the r x F order of eq. 19.
    """
    r_1, r_2 = mat.r1, mat.r1
    R = mat.R
    n1 = jnp.asarray(n1)
    n2 = jnp.asarray(n2)
    phi_s = jnp.asarray(phi_s)
    dist, n_c, delta, z0, zeta, xi = contact_geometry(x1, x2, n1, n2, mat)
    # normal (eqs. 5-7)
    F_n, U_n = normal_force_and_potential(delta, mat)
    # sliding (eqs. 11, 14, 15-17)
    k_s = mat.k_s
    fac = (r_1 + r_2 - _dot(z0, n_c)) / jnp.where(dist > 0, dist, 1.0)
    F_s1 = -k_s * fac[..., None] * zeta
    M_s1 = -r_1 * k_s * _cross(n1, zeta)
    M_s2 = r_2 * k_s * _cross(n2, zeta)
    U_s = 0.5 * k_s * _dot(zeta, zeta)
    # rolling (eqs. 21-23)
    k_r = mat.k_r
    M_r1 = -R * k_r * _cross(n1, xi)
    M_r2 = -R * k_r * _cross(n2, xi)
    U_r = 0.5 * k_r * _dot(xi, xi)
    # twisting (eqs. 25-27)
    k_t = mat.k_t
    M_t1 = -(k_t * phi_s)[..., None] * n_c
    U_t = 0.5 * k_t * phi_s**2
    F1 = F_n[..., None] * n_c + F_s1
    return ContactForces(F1=F1, M1=M_s1 + M_r1 + M_t1, M2=M_s2 + M_r2 - M_t1, U_n=U_n, U_s=U_s, U_r=U_r, U_t=U_t)


def clip_inelastic(x1, x2, n1, n2, phi_s, mat, *, paper_energy: bool = True, passes: int = 3):
    """Inelastic sliding, rolling and twisting: hold each displacement at its critical value (Wada eqs. 39-43).

    If |zeta| > zeta_crit the pointers are moved so that zeta -> zeta zeta_crit/|zeta| (same direction) with |xi|
    and the direction of its tangential part unchanged; if |xi| > xi_crit they are moved so that the tangential
    part of xi shrinks along its direction until |xi| = xi_crit, with zeta unchanged (the normal part of xi, second
    order in the pointer tilts, cannot be steered); if
    |phi_s| > phi_crit, phi_s -> sign(phi_s) phi_crit. The pointer moves use the general-radius forms (module
    docstring; the n_2 sign of the printed eq. 42 is corrected) and ``passes`` fixed-point passes (correct,
    normalise, recompute), after which |zeta| = zeta_crit and |xi| = xi_crit to ~1e-13 relative, and the
    displacement that was not clipped keeps its value to the same accuracy. Below all critical values the inputs
    are returned unchanged (bitwise).

    Arguments:
        x1, x2: centres [cm] (..., 3); n1, n2: contact pointers (..., 3); phi_s: twist angle [rad] (...);
        mat: Material (zeta_crit, xi_crit, phi_crit, k_s, k_r, k_t).
        paper_energy: static. True (default): the paper's eqs. 39-41, dE_s = k_s zeta_crit (|zeta| - zeta_crit),
            dE_r = k_r xi_crit (|xi| - xi_crit), dE_t = k_t phi_crit (|phi_s| - phi_crit): the critical force times
            the overshoot, which is exactly the trapezoid work of the post-clip forces that a kick-drift-kick
            leapfrog does on a plateau, so E_kin + U + sum E_dis is conserved to O(dt^2). False: the potential
            drop dE = U_before - U_after; it exceeds the former by k (overshoot)^2/2 per clipped step, a bias of
            first order in dt in the leapfrog's energy balance (measured on a spinning quartz pair, 200 t_c:
            max |dE|/E_kin,0 = 1.1e-3 at dt = 0.014 t_c and 5.2e-4 at 0.007 t_c, against 1.8e-4 and 4.6e-5
            with the default).
        passes: static number of fixed-point passes (>= 1; 3 reaches round-off for overshoots << r1).

    Returns:
        (n1, n2, phi_s, dE_s, dE_r, dE_t): new pointers and twist angle; energies dissipated by sliding, rolling and
        twisting [erg] (>= 0, zero where the regime is elastic).

    References: Wada et al. (2007) eqs. 35-43, Appendix A (eqs. A1-A8), Fig. 3.
    """
    r_1, r_2 = mat.r1, mat.r1
    n1 = jnp.asarray(n1)
    n2 = jnp.asarray(n2)
    phi_s = jnp.asarray(phi_s)
    _, n_c, _, _, zeta, xi = contact_geometry(x1, x2, n1, n2, mat)
    zc, xc, pc = mat.zeta_crit, mat.xi_crit, mat.phi_crit
    az, ax, ap = _norm(zeta), _norm(xi), jnp.abs(phi_s)
    over_s, over_r, over_t = az > zc, ax > xc, ap > pc
    # targets. zeta (tangential, fully steerable by n_1 - n_2): the clipped vector along its original direction, or
    # the original vector where elastic. xi: only its tangential part can be steered by the pointers (the normal
    # part R (n_1 + n_2).n_c is second order in the pointer tilts), so the tangential part keeps its direction and
    # is sized each pass to give |xi| = min(|xi|, xi_crit).
    zeta_t = zeta * jnp.where(over_s, zc / jnp.where(over_s, az, 1.0), 1.0)[..., None]
    tx = jnp.minimum(ax, xc)
    xT0 = xi - _dot(xi, n_c)[..., None] * n_c
    aT0 = _norm(xT0)
    uT = xT0 / jnp.where(aT0 > 0, aT0, 1.0)[..., None]
    m1, m2 = n1, n2
    for _ in range(passes):
        _, nc_, _, _, z_now, x_now = contact_geometry(x1, x2, m1, m2, mat)
        dz = z_now - zeta_t
        x_n = _dot(x_now, nc_)
        w2 = tx**2 - x_n**2
        want = jnp.where(w2 > 0, jnp.sqrt(jnp.where(w2 > 0, w2, 1.0)), 0.0)  # double where: finite gradient at 0
        dx = x_now - x_n[..., None] * nc_ - want[..., None] * uT
        m1 = _normalize(m1 - dz / (r_1 + r_2) - dx / r_1)
        m2 = _normalize(m2 + dz / (r_1 + r_2) - dx / r_2)
    any_over = (over_s | over_r)[..., None]
    n1_new = jnp.where(any_over, m1, n1)
    n2_new = jnp.where(any_over, m2, n2)
    phi_new = jnp.where(over_t, jnp.sign(phi_s) * pc, phi_s)
    k_s, k_r, k_t = mat.k_s, mat.k_r, mat.k_t
    if paper_energy:
        dE_s = jnp.where(over_s, k_s * zc * (az - zc), 0.0)
        dE_r = jnp.where(over_r, k_r * xc * (ax - xc), 0.0)
        dE_t = jnp.where(over_t, k_t * pc * (ap - pc), 0.0)
    else:
        _, _, _, _, z_new, x_new = contact_geometry(x1, x2, n1_new, n2_new, mat)
        dE_s = jnp.where(over_s, 0.5 * k_s * (az**2 - _dot(z_new, z_new)), 0.0)
        dE_r = jnp.where(over_r, 0.5 * k_r * (ax**2 - _dot(x_new, x_new)), 0.0)
        dE_t = jnp.where(over_t, 0.5 * k_t * (ap**2 - phi_new**2), 0.0)
    return n1_new, n2_new, phi_new, dE_s, dE_r, dE_t


def rotate(n, omega, dt):
    """Rotate vector(s) ``n`` by the angle |omega| dt about omega (exact Rodrigues formula), then renormalise.

    Arguments:
        n: unit vector(s) (..., 3) (contact pointers in the space frame).
        omega: angular velocity [rad s^-1] (..., 3), broadcast against n.
        dt: time step [s] (scalar or broadcastable to n's leading shape).

    Returns:
        The rotated unit vectors (..., 3). At omega = 0 it returns n (renormalised) with finite gradients.

    References: Wada et al. (2007) eqs. 28-34 (pointers fixed in the body frame; the space-frame rotation used here
    is equivalent and avoids the sign erratum of eq. 32).
    """
    n = jnp.asarray(n)
    dt = jnp.asarray(dt)
    th = jnp.asarray(omega) * (dt if dt.ndim == 0 else dt[..., None])  # rotation vector [rad]
    s, c = rotation_coefficients(th)
    return rotate_by(n, th, s, c)


# Taylor coefficients in t = a^2 of sin(a)/a and (1 - cos a)/a^2 through t^7: (-1)^k/(2k+1)! and (-1)^k/(2k+2)!
_SIN_SERIES = tuple((-1.0) ** k / math.factorial(2 * k + 1) for k in range(8))
_COS_SERIES = tuple((-1.0) ** k / math.factorial(2 * k + 2) for k in range(8))
# the series are used when every a^2 of the array is below this: the first omitted terms, a^16/17! and a^16/18!,
# are then below 4.3e-20 (round-off of values ~1 and ~1/2)
_SERIES_T_MAX = 0.25


def _horner(t, coeffs):
    out = coeffs[-1]
    for c in coeffs[-2::-1]:
        out = out * t + c
    return out


def rotation_coefficients(th):
    """Rodrigues coefficients (sin a/a, (1 - cos a)/a^2) of rotation vectors ``th`` (..., 3) [rad], a = |th|
    (computed once per body and shared by all its contact pointers).

    When every a of the array is below 0.5 rad (any DEM step: a = |omega| dt with dt = 0.014 t_c), both come from
    their Taylor series in a^2 through a^14 (exact to round-off there, no sqrt, sin or division: XLA's CPU backend
    calls libm's scalar sin, ~12 ns per element, 48 us of a 3-D 1024 + 1024 step); otherwise from sin, with the
    series below a = 1e-8. The choice is one ``lax.cond`` on the array's largest a (a select under ``vmap``)."""
    t = _dot(th, th)

    def series(t):
        return _horner(t, _SIN_SERIES), _horner(t, _COS_SERIES)

    def trig(t):
        ang = jnp.sqrt(jnp.where(t > 0, t, 1.0))  # double where: finite gradient at a = 0
        small = t < 1e-16
        safe = jnp.where(small, 1.0, ang)
        # sin(a)/a and (1 - cos a)/a^2 = 2 (sin(a/2)/a)^2 (no cancellation), with their series below 1e-8
        s = jnp.where(small, 1.0 - t / 6.0, jnp.sin(safe) / safe)
        c = jnp.where(small, 0.5 - t / 24.0, 2.0 * (jnp.sin(0.5 * safe) / safe) ** 2)
        return s, c

    return jax.lax.cond(jnp.max(t, initial=0.0) < _SERIES_T_MAX, series, trig, t)


def rotate_by(n, th, s, c):
    """Rotate unit vectors ``n`` (..., 3) by the rotation vectors ``th`` (..., 3) [rad] with the coefficients
    ``s, c`` of :func:`rotation_coefficients` (Rodrigues), then renormalise (the body of :func:`rotate`)."""
    txn = _cross(th, n)
    out = n + s[..., None] * txn + c[..., None] * _cross(th, txn)
    return _normalize(out)
