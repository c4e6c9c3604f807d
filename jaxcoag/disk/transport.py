"""Dust of the 1-D disk model: sizes, Stokes numbers, scale heights, radial velocities, diffusion,
floors, the initial MRN distribution and the radial transport operator (cgs).

Equations and discretisation as DustPy 1.0.9 (``std/dust.py``, ``std/dust.f90``; Stammler &
Birnstiel 2022, ApJ 935, 35, §2.3-2.5; Birnstiel, Dullemond & Brauer 2010, A&A 513, A79, §2):

    dSigma_i/dt + (1/r) d/dr (r Sigma_i v_i) - (1/r) d/dr [ r D_i Sigma_g d/dr (Sigma_i/Sigma_g) ] = S_i

* a = (3 m / (4 pi rho_s))^(1/3);
* St: Epstein (pi/2) a rho_s / Sigma_g for a < 9/4 lambda, Stokes I (2 pi/9) a^2 rho_s/(lambda Sigma_g)
  above (continuous at the switch; DustPy ``st_epstein_stokes1``);
* H_d = min(H_p, H_p / sqrt(1 + St/delta_vert)) (Dubrulle, Morfill & Sterzik 1995, Icarus 114, 237);
* D = delta_rad c_s^2 / (Omega (1 + St^2)) (Youdin & Lithwick 2007), zero in the first and last two cells
  (as DustPy 1.0.9);
* v = (v_g + 2 v_dm St)/(1 + St^2), v_dm = B v_visc/2 - A eta r Omega (A = 1, B = 0 by default:
  no back-reaction; Nakagawa et al. 1986; Takeuchi & Lin 2002);
* transport: donor-cell advection of r Sigma, diffusion written on eps = Sigma/Sigma_g with h = Sigma_g r
  at the interfaces, v and D linearly interpolated (:func:`hydro_coefficients`);
* boundaries: inner "constant gradient", outer value 0.1 Sigma_floor[-1] (:func:`boundary_rows`);
* floor: Sigma_floor = 0.1 m / area (DustPy sets ``0.1 * std.dust.SigmaFloor``); values at or below are
  reset to 0.1 Sigma_floor (:func:`apply_dust_floor`).

Shapes: cells (nr,), interfaces (nr+1,), dust (nr, nm). All functions are pure and jit/vmap/grad safe.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

from .._validate import JaxcoagInputError
from .gas import hydro_source_gas
from .grid import const_grad_row, const_grad_value, implicit_tridiagonal_step, interp_to_interfaces

__all__ = [
    "STOKES_CONVENTIONS",
    "particle_size",
    "stokes_number",
    "dust_scale_height",
    "dust_diffusivity",
    "drift_velocity_max",
    "dust_radial_velocity",
    "sigma_floor",
    "apply_dust_floor",
    "mrn_initial",
    "hydro_coefficients",
    "BoundaryRows",
    "boundary_rows",
    "apply_dust_boundaries",
    "transport_implicit_step",
    "dust_fluxes",
    "hydro_source",
    "dust_dt",
]

#: Stokes-number conventions of :func:`stokes_number`.
STOKES_CONVENTIONS = ("dustpy", "jaxcoag")


def _col(x):
    """(nr,) -> (nr, 1) for broadcasting against (nr, nm); scalars pass through."""
    x = jnp.asarray(x)
    return x[:, None] if x.ndim == 1 else x


def particle_size(m, rho_s):
    """Compact particle radius a = (3 m / (4 pi rho_s))^(1/3) [cm] (DustPy ``dust.f90 a``).

    Arguments:
        m: (nm,) masses [g]; rho_s: material density [g cm^-3], scalar, (nr,) or (nr, nm)
            (DustPy: rho_s times filling factor, default 1.67 g cm^-3).

    Returns:
        (nm,) for a scalar rho_s, else (nr, nm).
    """
    rho = _col(rho_s)
    m = jnp.asarray(m)
    if rho.ndim == 2:
        m = m[None, :]
    return (3.0 * m / (4.0 * jnp.pi * rho)) ** (1.0 / 3.0)


def stokes_number(a, rho_s, Sigma_g, mfp, convention="dustpy"):
    """Midplane Stokes number with the Epstein / Stokes-I switch at a = 9/4 mean free path.

    ``convention="dustpy"`` (DustPy 1.0.9 ``st_epstein_stokes1``; Birnstiel et al. 2010, eqs. 5-6):
    St = (pi/2) a rho_s / Sigma_g for a < 9/4 lambda, St = (2 pi/9) a^2 rho_s / (lambda Sigma_g) else,
    with lambda = ``mfp`` = 1/(sqrt(2) n sigma_H2) (:func:`jaxcoag.disk.gas.mean_free_path`); this is
    Omega tau_f with the mean thermal speed v_th = sqrt(8/pi) c_s in the Epstein law at the midplane.

    ``convention="jaxcoag"``: our 0-D engines' drag (:func:`jaxcoag.physics.drag.friction_time`,
    ``convention="ormel"``; Ormel 2008 thesis eqs. 2.4, 4.5-4.6): Epstein with the isothermal sound speed,
    St = sqrt(2 pi) a rho_s / Sigma_g (sqrt(8/pi) = 1.596 times DustPy's), Stokes factor 4a/(9 l) with
    l = 1/(n sigma_H2) = sqrt(2) lambda and the switch at a = 9/4 l (2/sqrt(pi) = 1.128 times DustPy's in
    the Stokes regime).

    Both are continuous at the switch (the Stokes factor is 1 there), with a kink.

    Arguments:
        a: (nm,) or (nr, nm) radii [cm]; rho_s: scalar, (nr,) or (nr, nm) [g cm^-3];
        Sigma_g: (nr,) [g cm^-2]; mfp: (nr,) DustPy mean free path lambda [cm];
        convention: "dustpy" (default) or "jaxcoag" (static).

    Returns:
        St: (nr, nm).
    """
    if convention not in STOKES_CONVENTIONS:
        raise JaxcoagInputError(
            f"unknown Stokes-number convention {convention!r}; use 'dustpy' (Epstein with the mean thermal "
            "speed, DustPy/Birnstiel et al. 2010) or 'jaxcoag' (Epstein with the sound speed, Ormel 2008)"
        )
    a = jnp.asarray(a)
    if a.ndim == 1:
        a = a[None, :]
    rho = _col(rho_s)
    Sg = _col(Sigma_g)
    lam = _col(mfp)
    if convention == "dustpy":
        ep = 0.5 * jnp.pi * a * rho / Sg
        st = (2.0 / 9.0) * jnp.pi * a**2 * rho / (lam * Sg)
        return jnp.where(a < 2.25 * lam, ep, st)
    l = jnp.sqrt(2.0) * lam
    ep = jnp.sqrt(2.0 * jnp.pi) * a * rho / Sg
    return jnp.where(a < 2.25 * l, ep, ep * (4.0 * a / (9.0 * l)))


def dust_scale_height(Hp, St, delta_vert):
    """Dust scale height H = min(H_p, H_p / sqrt(1 + St/delta_vert)) [cm], (nr, nm).

    Dubrulle, Morfill & Sterzik (1995); DustPy 1.0.9 ``h_dubrulle1995``.

    Arguments:
        Hp: (nr,) gas scale height [cm]; St: (nr, nm); delta_vert: scalar or (nr,) vertical mixing parameter.
    """
    Hp = _col(Hp)
    return jnp.minimum(Hp / jnp.sqrt(1.0 + St / _col(delta_vert)), Hp)


def dust_diffusivity(delta_rad, cs, omega, St):
    """Radial dust diffusivity D = delta_rad c_s^2 / (Omega (1 + St^2)) [cm^2 s^-1], (nr, nm).

    Youdin & Lithwick (2007); DustPy 1.0.9 ``std.dust.D`` which sets D = 0 in the first and last two
    radial cells (to keep the boundary rows free of diffusion).

    Arguments:
        delta_rad: scalar or (nr,); cs: (nr,) [cm s^-1]; omega: (nr,) [s^-1]; St: (nr, nm).
    """
    v2 = _col(delta_rad) * _col(cs) ** 2
    D = v2 / (_col(omega) * (1.0 + St**2))
    D = D.at[:2].set(0.0)
    return D.at[-2:].set(0.0)


def drift_velocity_max(eta, r, omega, v_visc=0.0, A=1.0, B=0.0):
    """Maximum drift velocity v_dm = B v_visc/2 - A eta r Omega [cm s^-1], (nr,).

    DustPy 1.0.9 ``std.dust.vdriftmax`` (back-reaction coefficients A = 1, B = 0 by default;
    Nakagawa, Sekiya & Hayashi 1986; Weidenschilling 1977).
    """
    return 0.5 * B * v_visc - A * eta * r * omega


def dust_radial_velocity(St, v_gas, eta, r, omega, v_visc=None, A=1.0, B=0.0):
    """Radial dust velocity v = (v_g + 2 v_dm St)/(1 + St^2) [cm s^-1], (nr, nm).

    DustPy 1.0.9 ``dust.f90 vrad`` with v_dm = :func:`drift_velocity_max` (Takeuchi & Lin 2002, eq. 23;
    Birnstiel et al. 2010, eq. 17).

    Arguments:
        St: (nr, nm); v_gas: (nr,) radial gas velocity [cm s^-1]; eta: (nr,); r: (nr,) [cm];
        omega: (nr,) [s^-1]; v_visc: (nr,) viscous gas velocity (used only with B != 0; default v_gas,
        which equals v_visc for DustPy's defaults A = 1, B = 0, no torque); A, B: back-reaction coefficients.
    """
    v_visc = v_gas if v_visc is None else v_visc
    vdm = drift_velocity_max(eta, r, omega, v_visc, A, B)
    return (_col(v_gas) + 2.0 * _col(vdm) * St) / (St**2 + 1.0)


def sigma_floor(m, area):
    """DustPy's dust floor Sigma_floor = 0.1 m / area [g cm^-2], (nr, nm).

    ``Simulation._initializedust`` sets ``0.1 * std.dust.SigmaFloor`` where ``std.dust.SigmaFloor`` is one
    particle of mass m per annulus. The outer boundary value is 0.1 * Sigma_floor[-1].

    Arguments:
        m: (nm,) masses [g]; area: (nr,) annulus areas [cm^2].
    """
    return 0.1 * m[None, :] / area[:, None]


def apply_dust_floor(Sigma, floor):
    """DustPy's floor rule: Sigma if Sigma > floor else 0.1 floor (``std.dust.enforce_floor_value``).

    Piecewise: the gradient is 1 above the floor and 0 at or below it.
    """
    return jnp.where(Sigma > floor, Sigma, 0.1 * floor)


def mrn_initial(a, Sigma_g, P, r, ri, omega, cs, rho_s, *, a_max=1e-4, dist_exp=-3.5, d2g=0.01,
                allow_drifting=False, cut="hard"):
    """Initial dust distribution as DustPy 1.0.9 ``std.dust.MRN_distribution`` [g cm^-2], (nr, nm).

    Sigma(r, a_i) ∝ a_i^(dist_exp + 4) for a_i <= a_ini(r), normalised to d2g Sigma_g in every cell
    (n(a) da ∝ a^dist_exp da, Mathis, Rumpl & Nordsieck 1977). With ``allow_drifting=False`` (DustPy's
    default) a_ini = min(a_max, a_d) with the drift limit carrying a safety factor 5e-3,

        a_d = 5e-3 (2/pi) d2g Sigma_g / rho_s (Omega r)^2 / c_s^2 / |dln P/dln r|

    (Birnstiel, Klahr & Ercolano 2012, A&A 539, A148, eq. 18), with dP/dr from P interpolated to the
    interfaces by ``numpy.interp`` (which, unlike the other interpolations, holds the end values constant).

    The cut. ``cut="hard"`` is DustPy's step (a_i <= a_ini): the result is piecewise constant in
    everything that sets a_ini (Sigma_g, P, cs, omega, rho_s, d2g, a_max: e.g. M_disk, r_c) and jumps when
    a_ini crosses a grid size, so its derivative with respect to those is zero almost everywhere and
    undefined at the jumps (alpha does not enter). ``cut="smooth"`` replaces the step by a linear ramp in
    ln a one bin wide, weight = clip(1/2 + (ln a_ini - ln a_i)/dln a, 0, 1), which is continuous and
    piecewise linear in ln a_ini (finite, non-zero derivative in the bin that holds a_ini) and equals the
    hard cut whenever a_ini lies half a bin or more from every grid size.

    Arguments:
        a: (nm,) or (nr, nm) radii [cm] (DustPy's a of the mass grid); Sigma_g: (nr,) [g cm^-2];
        P: (nr,) midplane pressure [dyn cm^-2]; r: (nr,), ri: (nr+1,) [cm]; omega: (nr,) [s^-1];
        cs: (nr,) [cm s^-1]; rho_s: scalar or (nr,) [g cm^-3];
        a_max: largest initial size [cm] (DustPy aIniMax 1e-4); dist_exp: n(a) exponent (-3.5);
        d2g: dust-to-gas ratio (0.01); allow_drifting: static bool; cut: "hard" or "smooth" (static).
    """
    if cut not in ("hard", "smooth"):
        raise JaxcoagInputError(f"unknown cut {cut!r}; use 'hard' (DustPy's step) or 'smooth' (one-bin linear ramp)")
    a2 = jnp.broadcast_to(jnp.asarray(a), (r.shape[0],) + jnp.shape(a)[-1:])
    if allow_drifting:
        aini = jnp.broadcast_to(a_max, r.shape)
    else:
        Pi = jnp.interp(ri, r, P)  # numpy.interp semantics: constant beyond the end points
        gamma = jnp.abs((Pi[1:] - Pi[:-1]) / (ri[1:] - ri[:-1])) * r / P
        rho = jnp.broadcast_to(rho_s, r.shape)
        ad = 5.0e-3 * 2.0 / jnp.pi * d2g * Sigma_g / rho * (omega * r) ** 2.0 / cs**2.0 / gamma
        aini = jnp.minimum(a_max, ad)
    if cut == "hard":
        w = jnp.where(a2 <= aini[:, None], 1.0, 0.0)
    else:
        la = jnp.log(a2)
        dla = la[:, 1:2] - la[:, 0:1]
        w = jnp.clip(0.5 + (jnp.log(aini)[:, None] - la) / dla, 0.0, 1.0)
    ret = w * a2 ** (dist_exp + 4.0)
    s = jnp.sum(ret, axis=1, keepdims=True)
    s = jnp.where(s > 0.0, s, 1.0)
    return ret / s * Sigma_g[:, None] * d2g


# --------------------------------------------------------------------------------------------
# transport operator


def hydro_coefficients(area, D, r, ri, Sigma_g, v):
    """Diagonals of the dust transport operator J_hyd, each (nr, nm) [s^-1].

    DustPy 1.0.9 ``dust.f90 jacobian_hydrodynamic_generator``: the row of cell ir, bin i is
    dSigma[ir, i]/dt = A[ir, i] Sigma[ir-1, i] + B[ir, i] Sigma[ir, i] + C[ir, i] Sigma[ir+1, i],
    for ir = 1..nr-2 (rows 0 and nr-1 are zero; they are boundary rows). Per interface the flux times
    radius is Phi = vip r_{ir-1} Sigma_{ir-1} + vim r_ir Sigma_ir (donor cell of r Sigma) plus
    -D_i h_i (eps_ir - eps_{ir-1})/(r_ir - r_{ir-1}) r-weighted as DustPy (eps = Sigma/Sigma_g,
    h = Sigma_g r, v and D linearly interpolated, h interpolated), and dSigma/dt = (2 pi/area)(Phi_ir - Phi_{ir+1}).

    Arguments:
        area: (nr,) annulus areas [cm^2]; D: (nr, nm) diffusivity [cm^2 s^-1]; r: (nr,), ri: (nr+1,) [cm];
        Sigma_g: (nr,) gas surface density [g cm^-2]; v: (nr, nm) radial dust velocity [cm s^-1].

    Returns:
        (A, B, C): multiply Sigma[ir-1], Sigma[ir], Sigma[ir+1].
    """
    h = Sigma_g * r
    hi = interp_to_interfaces(h, r, ri)[1:-1, None]  # interfaces 1..nr-1
    vi = interp_to_interfaces(v, r, ri)[1:-1]
    Di = interp_to_interfaces(D, r, ri)[1:-1]
    vip = jnp.maximum(vi, 0.0)
    vim = jnp.minimum(vi, 0.0)
    w = (r[1:] - r[:-1])[:, None]
    rl = r[:-1, None]
    rr = r[1:, None]
    hl = h[:-1, None]
    hr = h[1:, None]
    # Phi_i = a_i Sigma[i-1] + b_i Sigma[i] at interfaces i = 1..nr-1
    a_ = vip * rl + Di * hi / (w * hl) * rl
    b_ = vim * rr - Di * hi / (w * hr) * rr
    vinv = (2.0 * jnp.pi / area)[1:-1, None]
    z = jnp.zeros((1,) + a_.shape[1:], dtype=a_.dtype)
    A = jnp.concatenate([z, a_[:-1] * vinv, z])
    B = jnp.concatenate([z, (b_[:-1] - a_[1:]) * vinv, z])
    C = jnp.concatenate([z, -b_[1:] * vinv, z])
    return A, B, C


class BoundaryRows(NamedTuple):
    """DustPy's default dust boundary rows of the implicit matrix (I - dt J) and right-hand side.

    First block row (inner "constant gradient", per mass bin):
        ``inner[0] Sigma[0] + inner[1] Sigma[1] + inner[2] Sigma[2] = inner_rhs``.
    Last block row (outer "val"):
        ``outer[0] Sigma[-1] + outer[1] Sigma[-2] + outer[2] Sigma[-3] = outer_rhs``.

    The coefficients are independent of dt (DustPy writes -K/dt into J, multiplied by -dt in I - dt J),
    and the coagulation Jacobian is zero in both boundary cells (DustPy's generator loops over the interior
    cells only). For a block-tridiagonal solver, fold the inner row into block row 1 by substituting
    Sigma[0] = (inner_rhs - inner[1] Sigma[1] - inner[2] Sigma[2]) / inner[0] (the sub-diagonal block of row
    1 is diagonal: its entries add -lower_1 inner[1]/inner[0] to the diagonal of block (1, 1) and
    -lower_1 inner[2]/inner[0] to the diagonal block (1, 2)), solve cells 1..nr-1, then recover Sigma[0].

    Fields: inner (3,) scalars; inner_rhs (nm,); outer (3,) scalars; outer_rhs (nm,) [g cm^-2].
    """

    inner: object
    inner_rhs: object
    outer: object
    outer_rhs: object


def boundary_rows(r, ri, floor):
    """DustPy 1.0.9's default dust boundary rows (``std.dust.jacobian`` with inner ``const_grad``,
    outer ``val`` = 0.1 SigmaFloor[-1]).

    Arguments:
        r: (nr,), ri: (nr+1,) [cm]; floor: (nr, nm) dust floor (:func:`sigma_floor`) [g cm^-2].

    Returns:
        :class:`BoundaryRows` (inner = (1, K1, K2) with K1, K2 of :func:`jaxcoag.disk.grid.const_grad_row`,
        inner_rhs = 0; outer = (1, 0, 0), outer_rhs = 0.1 floor[-1]).
    """
    K1, K2 = const_grad_row(r, ri)
    one = jnp.ones_like(K1)
    zero = jnp.zeros_like(K1)
    nm = floor.shape[-1]
    return BoundaryRows(
        inner=jnp.stack([one, K1, K2]),
        inner_rhs=jnp.zeros((nm,), dtype=floor.dtype),
        outer=jnp.stack([one, zero, zero]),
        outer_rhs=0.1 * floor[-1],
    )


def apply_dust_boundaries(Sigma, r, ri, floor):
    """DustPy's dust finaliser (``std.dust.finalize_implicit``): boundary values, then the floor.

    Sigma[0] = const_grad value (:func:`jaxcoag.disk.grid.const_grad_value`), Sigma[-1] = 0.1 floor[-1],
    then :func:`apply_dust_floor`.
    """
    Sigma = Sigma.at[0].set(const_grad_value(Sigma, r, ri)).at[-1].set(0.1 * floor[-1])
    return apply_dust_floor(Sigma, floor)


def transport_implicit_step(Sigma, A, B, C, dt, r, ri, floor, S_ext=None, finalize=True):
    """One implicit Euler step of dust transport alone (J = J_hyd), each mass bin a tridiagonal solve.

    DustPy 1.0.9's dust step (``std.dust._f_impl_1_direct``) with the coagulation Jacobian left out:
    (I - dt J_hyd) Sigma_new = Sigma + dt S_ext (interior rows) with :func:`boundary_rows`, then (with
    ``finalize``) :func:`apply_dust_boundaries`. The transport half-steps of a split scheme use it.

    Arguments:
        Sigma: (nr, nm) [g cm^-2]; A, B, C: (nr, nm) from :func:`hydro_coefficients`; dt: [s];
        r, ri: grid [cm]; floor: (nr, nm) [g cm^-2]; S_ext: (nr, nm) or None; finalize: static bool.

    Returns:
        Sigma_new: (nr, nm).
    """
    rhs = Sigma if S_ext is None else Sigma.at[1:-1].add(dt * S_ext[1:-1])
    K1, K2 = const_grad_row(r, ri)
    x = implicit_tridiagonal_step(A, B, C, dt, rhs, K1, K2, 0.1 * floor[-1])
    return apply_dust_boundaries(x, r, ri, floor) if finalize else x


def dust_fluxes(Sigma, v, D, Sigma_g, St, u, r, ri):
    """Explicit advective and diffusive dust fluxes through the interfaces, each (nr+1, nm) [g cm^-1 s^-1].

    Advective (DustPy 1.0.9 ``dust.f90 fi_adv``): donor cell with v interpolated to the interfaces;
    F[0] = Sigma[0] min(v_i[1], 0), F[nr] = Sigma[-1] max(v_i[nr-1], 0) (DustPy uses the neighbouring
    interface's velocity at the two boundaries).

    Diffusive (``dust.f90 fi_diff`` + ``std.dust.F_diff``): F = -D_i Sigma_g,i d(eps)/dr at the interior
    interfaces, limited by lambda = (1 + P)/(1 + P + P^2), P = |F / w|, w = u_i Sigma_i/(1 + St_i^2), so that
    |F| stays below the turbulent velocity times the density (Levermore & Pomraning 1981 type limiter); zero
    at the two boundary interfaces.

    Arguments:
        Sigma: (nr, nm) [g cm^-2]; v: (nr, nm) [cm s^-1]; D: (nr, nm) [cm^2 s^-1]; Sigma_g: (nr,);
        St: (nr, nm); u: (nr,) turbulent rms velocity sqrt(delta_rad) c_s [cm s^-1]; r, ri: grid [cm].

    Returns:
        (F_adv, F_diff).
    """
    vi = interp_to_interfaces(v, r, ri)
    F_in = Sigma[:-1] * jnp.maximum(vi[1:-1], 0.0) + Sigma[1:] * jnp.minimum(vi[1:-1], 0.0)
    F0 = Sigma[0] * jnp.minimum(vi[1], 0.0)
    Fn = Sigma[-1] * jnp.maximum(vi[-2], 0.0)
    F_adv = jnp.concatenate([F0[None], F_in, Fn[None]])

    SigGi = interp_to_interfaces(Sigma_g, r, ri)[1:-1, None]
    ui = interp_to_interfaces(u, r, ri)[1:-1, None]
    Di = interp_to_interfaces(D, r, ri)[1:-1]
    SigDi = interp_to_interfaces(Sigma, r, ri)[1:-1]
    Sti = interp_to_interfaces(St, r, ri)[1:-1]
    eps = Sigma / Sigma_g[:, None]
    grad = (eps[1:] - eps[:-1]) / (r[1:] - r[:-1])[:, None]
    F = -Di * SigGi * grad
    w = ui * SigDi / (1.0 + Sti**2)
    ok = w != 0.0
    P = jnp.abs(F) / jnp.where(ok, jnp.abs(w), 1.0)
    lam = (1.0 + P) / (1.0 + P + P**2)
    F = jnp.where(ok, lam * F, 0.0)
    z = jnp.zeros_like(F[:1])
    F_diff = jnp.concatenate([z, F, z])
    return F_adv, F_diff


def hydro_source(F, ri):
    """Dust transport source S_hyd = 2 (F_i ri_i - F_{i+1} ri_{i+1})/(ri_{i+1}^2 - ri_i^2), (nr, nm).

    DustPy 1.0.9 ``dust.f90 s_hyd`` on the total flux F = F_adv + F_diff (:func:`dust_fluxes`).
    """
    return hydro_source_gas(F, ri)


def dust_dt(S, Sigma, floor):
    """Step-size limit of the dust [s]: min Sigma/|S| over interior cells with S < 0 and Sigma > floor.

    DustPy 1.0.9 ``std.dust.dt`` (before the factor cfl = 0.1 of ``std.sim.dt``); ``inf`` when no cell
    limits (DustPy returns None, which ``std.sim.dt`` turns into 1e100). Use under ``stop_gradient``.
    """
    Si = S[1:-1]
    Sg = Sigma[1:-1]
    mask = (Si < 0.0) & (Sg > floor[1:-1])
    rate = jnp.where(mask, Sg / jnp.where(mask, -Si, 1.0), jnp.inf)
    return jnp.min(rate)
