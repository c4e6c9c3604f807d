"""Gas of the 1-D disk model: star, passive temperature, midplane structure, viscous evolution (cgs).

Equations and discretisation as DustPy 1.0.9 (``std/gas.py``, ``std/gas.f90``, ``std/star.py``,
``std/grid.py``; Stammler & Birnstiel 2022, ApJ 935, 35, §2.2 and §2.5):

* star: L = 4 pi R^2 sigma_SB T^4; Omega_K = sqrt(G M / r^3);
* passive disk: T^4 = (phi/2) L / (4 pi r^2 sigma_SB) with flaring angle phi = 0.05 (DustPy writes the
  prefactor 0.5 * 0.05 / 4 = 6.25e-3); with T ∝ r^(-1/2) the viscosity nu = alpha c_s H_p is ∝ r;
* midplane: c_s = sqrt(k_B T / mu) (mu in g), H_p = c_s/Omega, rho = Sigma/(sqrt(2 pi) H_p), P = rho c_s^2,
  n = rho/mu, lambda = 1/(sqrt(2) sigma_H2 n); eta = -(1/2) H_p^2/(r P) dP/dr with P interpolated to the
  interfaces (:func:`jaxcoag.disk.grid.interp_to_interfaces`);
* viscous evolution (Lynden-Bell & Pringle 1974): dSigma/dt = (3/r) d/dr [ r^(1/2) d/dr (nu Sigma r^(1/2)) ],
  one implicit Euler step per time step with DustPy's tridiagonal operator (:func:`gas_operator`) and its
  default boundaries (inner "constant gradient", outer fixed value = floor 1e-100 g cm^-2), followed by
  DustPy's finaliser (boundary values re-imposed, floor max(Sigma, 1e-100)).

Constants. DustPy's values (``dustpy.constants``) are in :data:`DUSTPY_CONSTANTS`. The formula constants
used here (k_B, G, sigma_H2, sigma_SB, pi) are the same as ``jaxcoag.constants`` to < 2e-16 relative; the
values that differ are inputs the caller chooses: DustPy's solar mass 1.988409870698051e33 g is 3.02e-5
relatively *smaller* than ``jaxcoag.constants.M_sun`` (1.98847e33 g), and DustPy's mean molecular mass is
mu = 2.3 m_p with the proton mass m_p = 1.67262192369e-24 g (jaxcoag's 0-D engines use 2.34 m_H). For
number-for-number parity pass ``M_star = DUSTPY_CONSTANTS["M_sun"]`` and ``mu = 2.3 * DUSTPY_CONSTANTS["m_p"]``.

All functions are pure, jit/vmap/grad safe, on (nr,) cell arrays and (nr+1,) interface arrays.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

from .. import constants as C
from .grid import const_grad_row, const_grad_value, implicit_tridiagonal_step, interp_to_interfaces

__all__ = [
    "DUSTPY_CONSTANTS",
    "SIGMA_SB",
    "stellar_luminosity",
    "temperature_passive",
    "omega_k",
    "sound_speed",
    "pressure_scale_height",
    "viscosity",
    "rho_midplane",
    "pressure_midplane",
    "n_midplane",
    "mean_free_path",
    "eta_midplane",
    "lbp_profile",
    "lbp_similarity",
    "gas_velocity_visc",
    "gas_radial_velocity",
    "gas_interface_flux",
    "viscous_mass_flow",
    "hydro_source_gas",
    "gas_operator",
    "gas_source",
    "gas_dt",
    "implicit_boundary_fluxes",
    "GasStepInfo",
    "gas_implicit_step",
]

#: Stefan-Boltzmann constant [erg cm^-2 s^-1 K^-4] (CODATA 2018: 2 pi^5 k_B^4/(15 h^3 c^2)), as DustPy.
SIGMA_SB = 5.6703744191844314e-05

#: DustPy 1.0.9's constants (``dustpy/constants/constants.f90``), cgs.
DUSTPY_CONSTANTS = {
    "au": 1.4959787070000e13,
    "G": 6.674299999999999e-08,
    "k_B": 1.380649e-16,
    "m_p": 1.67262192369e-24,
    "M_sun": 1.988409870698051e33,
    "R_sun": 6.9570000000e10,
    "sigma_H2": 2.0e-15,
    "sigma_sb": SIGMA_SB,
    "year": 3.1557600e7,
}


# --------------------------------------------------------------------------------------------
# star and temperature


def stellar_luminosity(R_star, T_star):
    """Stellar luminosity L = 4 pi R^2 sigma_SB T^4 [erg s^-1] (DustPy 1.0.9 ``std.star.luminosity``).

    Arguments:
        R_star: stellar radius [cm] (DustPy default 2 R_sun = 1.3914e11 cm).
        T_star: effective temperature [K] (DustPy default 5772 K).
    """
    return 4.0 * jnp.pi * R_star**2 * SIGMA_SB * T_star**4


def temperature_passive(r, L_star):
    """Passively irradiated disk temperature [K]: T^4 = (phi/2) L/(4 pi r^2 sigma_SB), phi = 0.05.

    DustPy 1.0.9 ``std.gas.T_passive`` / ``gas.f90 t_pass`` (prefactor 0.5 * 0.05/4 = 6.25e-3;
    Chiang & Goldreich 1997 with a constant grazing angle).

    Arguments:
        r: radius [cm].
        L_star: stellar luminosity [erg s^-1].
    """
    return (6.25e-3 * L_star / (jnp.pi * r**2 * SIGMA_SB)) ** 0.25


def omega_k(r, M_star):
    """Keplerian angular frequency Omega_K = sqrt(G M_star / r^3) [s^-1] (DustPy ``std.grid.OmegaK``).

    Arguments:
        r: radius [cm].
        M_star: stellar mass [g] (DustPy's M_sun = DUSTPY_CONSTANTS["M_sun"]).
    """
    return jnp.sqrt(C.G * M_star / r**3)


# --------------------------------------------------------------------------------------------
# midplane structure


def sound_speed(T, mu):
    """Isothermal sound speed c_s = sqrt(k_B T / mu) [cm s^-1] (DustPy ``gas.f90 cs_isothermal``).

    Arguments:
        T: temperature [K].
        mu: mean molecular MASS [g] (DustPy: 2.3 m_p = 3.847e-24 g).
    """
    return jnp.sqrt(C.k_B * T / mu)


def pressure_scale_height(cs, omega):
    """Pressure scale height H_p = c_s / Omega_K [cm] (DustPy ``gas.f90 hp``)."""
    return cs / omega


def viscosity(alpha, cs, Hp):
    """Kinematic viscosity nu = alpha c_s H_p [cm^2 s^-1] (Shakura & Sunyaev 1973; DustPy ``viscosity``)."""
    return alpha * cs * Hp


def rho_midplane(Sigma_g, Hp):
    """Midplane gas density rho = Sigma_g / (sqrt(2 pi) H_p) [g cm^-3] (DustPy ``rho_midplane``)."""
    return Sigma_g / (jnp.sqrt(2.0 * jnp.pi) * Hp)


def pressure_midplane(rho, cs):
    """Midplane pressure P = rho c_s^2 [dyn cm^-2] (DustPy ``p_midplane``)."""
    return rho * cs**2


def n_midplane(rho, mu):
    """Midplane number density n = rho / mu [cm^-3] (mu the molecular mass in g; DustPy ``n_midplane``)."""
    return rho / mu


def mean_free_path(n):
    """Midplane mean free path lambda = 1/(sqrt(2) sigma_H2 n) [cm], sigma_H2 = 2e-15 cm^2.

    DustPy ``mfp_midplane`` (Birnstiel, Dullemond & Brauer 2010, A&A 513, A79, §2). This is the
    "dustpy" mean free path of :func:`jaxcoag.physics.drag.drag_mean_free_path` (l_mfp/sqrt(2)).
    """
    return 1.0 / (jnp.sqrt(2.0) * C.sigma_mol * n)


def eta_midplane(Hp, P, r, ri):
    """Pressure-gradient parameter eta = -(1/2) H_p^2/(r P) dP/dr at the midplane (dimensionless).

    Discretisation as DustPy 1.0.9 ``gas.f90 eta_midplane``: P is interpolated to the interfaces
    (linear, extrapolated at the ends) and dP/dr = (P_i[i+1] - P_i[i])/(ri[i+1] - ri[i]).

    Arguments:
        Hp: (nr,) pressure scale height [cm]; P: (nr,) midplane pressure [dyn cm^-2];
        r: (nr,) centres [cm]; ri: (nr+1,) interfaces [cm].

    References: Nakagawa, Sekiya & Hayashi (1986); Stammler & Birnstiel (2022) §2.3.
    """
    Pi = interp_to_interfaces(P, r, ri)
    grad = (Pi[1:] - Pi[:-1]) / (ri[1:] - ri[:-1])
    return -0.5 * Hp**2 / (r * P) * grad


# --------------------------------------------------------------------------------------------
# Lynden-Bell & Pringle


def lbp_profile(r, r_c, M_disk, p=-1.0):
    """Lynden-Bell & Pringle (1974) initial surface density [g cm^-2] (DustPy ``lyndenbellpringle1974``).

    Sigma = (2 + p) M_disk / (2 pi r_c^2) (r/r_c)^p exp(-(r/r_c)^(2+p)); integrates to M_disk over
    0 < r < inf for p > -2.

    Arguments:
        r: radius [cm]; r_c: characteristic radius [cm] (DustPy default 60 au);
        M_disk: disk mass [g] (DustPy default 0.05 M_sun); p: power-law index (default -1 = gamma).
    """
    x = r / r_c
    return (2.0 + p) * M_disk / (2.0 * jnp.pi * r_c**2) * x**p * jnp.exp(-(x ** (2.0 + p)))


def lbp_similarity(r, t, r_c, nu1, M0):
    """Self-similar viscous solution for nu ∝ r (gamma = 1) [g cm^-2].

    Sigma(r, t) = M0 / (2 pi r_c^2 x) T^(-3/2) exp(-x/T), x = r/r_c, T = 1 + t/t_s, t_s = r_c^2/(3 nu1),
    nu1 = nu(r_c). This is C/(3 pi nu1 x) T^(-3/2) exp(-x/T) with C = 3 nu1 M0/(2 r_c^2) (Lynden-Bell &
    Pringle 1974; Hartmann et al. 1998, ApJ 495, 385, eq. 15 with gamma = 1); at t = 0 it equals
    :func:`lbp_profile` with p = -1. The disk mass is M0 T^(-1/2); the mass accreted by the star by time t
    is M0 (1 - T^(-1/2)).

    Arguments:
        r: radius [cm]; t: time [s]; r_c: [cm]; nu1: viscosity at r_c [cm^2 s^-1]; M0: initial mass [g].
    """
    ts = r_c**2 / (3.0 * nu1)
    T = 1.0 + t / ts
    x = r / r_c
    return M0 / (2.0 * jnp.pi * r_c**2 * x) * T ** (-1.5) * jnp.exp(-x / T)


# --------------------------------------------------------------------------------------------
# velocities and fluxes


def gas_velocity_visc(Sigma_g, nu, r, ri):
    """Viscous radial gas velocity v_visc = -3/(Sigma sqrt(r)) d(Sigma nu sqrt(r))/dr [cm s^-1].

    Discretisation as DustPy 1.0.9 ``gas.f90 v_visc``: Sigma nu sqrt(r) interpolated to the interfaces,
    differenced across each cell; the first and last cell are linearly extrapolated from their two
    neighbours (Lynden-Bell & Pringle 1974; Stammler & Birnstiel 2022, eq. 3).

    Arguments:
        Sigma_g: (nr,) gas surface density [g cm^-2]; nu: (nr,) viscosity [cm^2 s^-1];
        r: (nr,) centres [cm]; ri: (nr+1,) interfaces [cm].
    """
    sr = jnp.sqrt(r)
    argi = interp_to_interfaces(Sigma_g * nu * sr, r, ri)
    grad = (argi[1:] - argi[:-1]) / (ri[1:] - ri[:-1])
    v = -3.0 * grad / (Sigma_g * sr)
    v0 = (v[2] - v[1]) * (r[0] - r[1]) / (r[2] - r[1]) + v[1]
    vn = (v[-2] - v[-3]) * (r[-1] - r[-3]) / (r[-2] - r[-3]) + v[-3]
    return v.at[0].set(v0).at[-1].set(vn)


def gas_radial_velocity(v_visc, eta=0.0, r=1.0, omega=0.0, A=1.0, B=0.0, v_torque=0.0):
    """Radial gas velocity v = A v_visc + B 2 eta r Omega + v_torque [cm s^-1] (DustPy ``gas.f90 v_rad``).

    A, B are the dust back-reaction coefficients (DustPy default A = 1, B = 0: no back-reaction, and then
    v = v_visc); v_torque the velocity of an external torque (default 0).
    """
    return A * v_visc + B * 2.0 * eta * r * omega + v_torque


def gas_interface_flux(Sigma_g, v, r, ri):
    """Donor-cell gas mass flux through the interfaces F_i [g cm^-1 s^-1], shape (nr+1,).

    DustPy 1.0.9 ``gas.f90 fi``: v interpolated to the interfaces with vi[0] = v[0], vi[nr] = v[-1];
    no inflow through either boundary. This is DustPy's diagnostic ``gas.Fi`` (its implicit step uses the
    operator :func:`gas_operator`, whose fluxes are :func:`viscous_mass_flow`).
    """
    vi = interp_to_interfaces(v, r, ri)
    vi = vi.at[0].set(v[0]).at[-1].set(v[-1])
    vip = jnp.maximum(vi, 0.0).at[0].set(0.0)
    vim = jnp.minimum(vi, 0.0).at[-1].set(0.0)
    F_inner = Sigma_g[:-1] * vip[1:-1] + Sigma_g[1:] * vim[1:-1]
    return jnp.concatenate([(Sigma_g[0] * vim[0])[None], F_inner, (Sigma_g[-1] * vip[-1])[None]])


def hydro_source_gas(Fi, ri):
    """Surface-density source of interface fluxes, S = 2 (F_i ri_i - F_{i+1} ri_{i+1})/(ri_{i+1}^2 - ri_i^2).

    DustPy 1.0.9 ``gas.f90 s_hyd`` / ``dust.f90 s_hyd`` [g cm^-2 s^-1]; works on (nr+1,) or (nr+1, nm).
    """
    extra = (1,) * (Fi.ndim - 1)
    rri = ri.reshape(ri.shape + extra)
    Fr = Fi * rri
    return 2.0 * (Fr[:-1] - Fr[1:]) / (rri[1:] ** 2 - rri[:-1] ** 2)


def _operator_flux_coefficients(nu, r, ri, v):
    """Coefficients (a, b) of the operator's interface flux times radius at interfaces 1..nr-1.

    Phi_i = a_i Sigma[i-1] + b_i Sigma[i] = r F at interface i as discretised in DustPy's ``jac_abc``:
    donor-cell advection of r Sigma with v interpolated to the interfaces plus the viscous flux
    -3 sqrt(ri) (nu sqrt(r) Sigma)' with a centred difference.
    """
    vi = interp_to_interfaces(v, r, ri)[1:-1]
    vip = jnp.maximum(vi, 0.0)
    vim = jnp.minimum(vi, 0.0)
    g = nu * jnp.sqrt(r)  # nu/sqrt(r) * r
    w = r[1:] - r[:-1]
    Di = 3.0 * jnp.sqrt(ri[1:-1])
    a = vip * r[:-1] + Di * g[:-1] / w
    b = vim * r[1:] - Di * g[1:] / w
    return a, b


def viscous_mass_flow(Sigma_g, nu, r, ri, v=None):
    """Mass flow outward through the interior interfaces 1..nr-1 [g s^-1], shape (nr-1,).

    2 pi r F as discretised by the implicit operator (:func:`gas_operator`, DustPy ``jac_abc``), so that
    area_i dSigma_i/dt = flow[i-1] - flow[i] holds exactly for the interior cells: the flux used for the
    mass budget of :func:`gas_implicit_step`.

    Arguments:
        Sigma_g: (nr,) [g cm^-2]; nu: (nr,) [cm^2 s^-1]; r, ri: grid [cm];
        v: (nr,) extra advection velocity [cm s^-1] (back-reaction/torque; default 0).
    """
    v = jnp.zeros_like(r) if v is None else v
    a, b = _operator_flux_coefficients(nu, r, ri, v)
    return 2.0 * jnp.pi * (a * Sigma_g[:-1] + b * Sigma_g[1:])


def gas_operator(area, nu, r, ri, v=None):
    """Tridiagonal viscous-evolution operator J (dSigma/dt = A Sigma[i-1] + B Sigma[i] + C Sigma[i+1]).

    DustPy 1.0.9 ``gas.f90 jac_abc`` (and ``std.gas.jacobian`` with nu scaled by the back-reaction
    coefficient A, v = B 2 eta r Omega + v_torque): for interior cells i = 1..nr-2
    dSigma_i/dt = (2 pi/area_i)(Phi_i - Phi_{i+1}) with the interface fluxes of :func:`viscous_mass_flow`;
    rows 0 and nr-1 are zero (they are set by the boundary conditions).

    Arguments:
        area: (nr,) annulus areas [cm^2]; nu: (nr,) [cm^2 s^-1]; r, ri: grid [cm];
        v: (nr,) extra advection velocity [cm s^-1] (default 0).

    Returns:
        (A, B, C): each (nr,) [s^-1].
    """
    v = jnp.zeros_like(r) if v is None else v
    a, b = _operator_flux_coefficients(nu, r, ri, v)  # interfaces 1..nr-1
    vinv = 2.0 * jnp.pi / area
    # cell i (1..nr-2): Phi_i - Phi_{i+1}; Phi_i = a[i-1] S[i-1] + b[i-1] S[i]
    A_in = a[:-1]
    B_in = b[:-1] - a[1:]
    C_in = -b[1:]
    z = jnp.zeros((1,), dtype=A_in.dtype)
    A = jnp.concatenate([z, A_in, z]) * vinv
    B = jnp.concatenate([z, B_in, z]) * vinv
    C = jnp.concatenate([z, C_in, z]) * vinv
    return A, B, C


def gas_source(Sigma_g, nu, r, ri, S_ext=None, v_extra=None):
    """Explicit gas source dSigma/dt [g cm^-2 s^-1] at the current state, shape (nr,).

    As DustPy 1.0.9's ``gas.S.tot`` for its default model: the donor-cell fluxes of DustPy's ``gas.Fi``
    (:func:`gas_interface_flux`) with the radial velocity v = v_visc (+ ``v_extra``), turned into sources
    by :func:`hydro_source_gas`, plus S_ext in the interior cells. (After a step DustPy overwrites the
    two boundary entries with the implicit boundary sources, :func:`implicit_boundary_fluxes`; the step
    size rule :func:`gas_dt` does not use them.)
    """
    v = gas_velocity_visc(Sigma_g, nu, r, ri)
    if v_extra is not None:
        v = v + v_extra
    S = hydro_source_gas(gas_interface_flux(Sigma_g, v, r, ri), ri)
    if S_ext is not None:
        S = S.at[1:-1].add(S_ext[1:-1])
    return S


def gas_dt(S, Sigma_g, floor=1e-100):
    """Step-size limit of the gas [s]: min Sigma/|S| over interior cells with S < 0 and Sigma > floor.

    DustPy 1.0.9 ``gas.f90 timestep`` (before the factor cfl = 0.1 of ``std.sim.dt``). Returns ``inf``
    when no cell limits (DustPy returns 1e100). Use under ``jax.lax.stop_gradient`` in a time loop.
    """
    Si = S[1:-1]
    Sg = Sigma_g[1:-1]
    fl = jnp.broadcast_to(floor, Sigma_g.shape)[1:-1]
    mask = (Si < 0.0) & (Sg > fl)
    rate = jnp.where(mask, Sg / jnp.where(mask, -Si, 1.0), jnp.inf)
    return jnp.min(rate)


def implicit_boundary_fluxes(dt, Fi, ri, Sigma, Sigma_old):
    """DustPy's boundary sources and fluxes after an implicit step (``gas.f90 implicit_boundaries``).

    S_0 = (Sigma_0 - Sigma_old_0)/(dt + 1e-100), S_-1 likewise; F_0 = (S_0 (ri_1^2 - ri_0^2)/2 + ri_1 F_1)/ri_0,
    F_nr = (F_{nr-1} ri_{nr-1} - S_-1 (ri_nr^2 - ri_{nr-1}^2)/2)/ri_nr. Works for the gas (nr,) and, with
    the advective dust fluxes, for the dust (nr, nm) (DustPy ``std.dust.set_implicit_boundaries``).

    Returns:
        (S_inner, S_outer, F_inner, F_outer).
    """
    S0 = (Sigma[0] - Sigma_old[0]) / (dt + 1e-100)
    S1 = (Sigma[-1] - Sigma_old[-1]) / (dt + 1e-100)
    F0 = (0.5 * S0 * (ri[1] ** 2 - ri[0] ** 2) + ri[1] * Fi[1]) / ri[0]
    F1 = (Fi[-2] * ri[-2] - 0.5 * S1 * (ri[-1] ** 2 - ri[-2] ** 2)) / ri[-1]
    return S0, S1, F0, F1


class GasStepInfo(NamedTuple):
    """Mass bookkeeping of one :func:`gas_implicit_step` [g].

    Fields:
        mass_in: mass that left through the inner boundary during the step (accreted by the star; > 0 for
            inflow).
        mass_out: mass that left through the outer boundary.
        mass_ext: mass added by S_ext (interior cells).
        Sigma_solve: (nr,) the solution of the linear system before the finaliser re-imposed the boundary
            values and the floor.

    With M = sum(area Sigma): M_new = M_old - mass_in - mass_out + mass_ext to rounding.
    """

    mass_in: object
    mass_out: object
    mass_ext: object
    Sigma_solve: object


def gas_implicit_step(Sigma_g, nu, r, ri, dt, S_ext=None, floor=1e-100, v=None):
    """One implicit Euler step of the viscous gas, as DustPy 1.0.9 (``std.gas._f_impl_1_direct`` + finaliser).

    (I - dt J) Sigma_new = Sigma_old + dt S_ext (S_ext in the interior cells only), J = :func:`gas_operator`,
    with DustPy's default boundary rows: inner "constant gradient" (:func:`jaxcoag.disk.grid.const_grad_row`),
    outer value = floor (``SigmaFloor[-1]``). Then DustPy's finaliser: inner value re-imposed by
    :func:`jaxcoag.disk.grid.const_grad_value`, outer value = floor, Sigma = max(Sigma, floor).

    The accreted mass is booked exactly: the interior rows are conservative, so the mass crossing the inner
    edge is -area_0 (Sigma_0,new - Sigma_0,old) + dt * flow_1 (the operator's flow out of cell 0 through
    interface 1 evaluated at the solution, :func:`viscous_mass_flow`), and likewise at the outer edge.

    Arguments:
        Sigma_g: (nr,) gas surface density at the start of the step [g cm^-2].
        nu: (nr,) viscosity [cm^2 s^-1] (DustPy multiplies it by the back-reaction coefficient A = 1).
        r, ri: grid [cm]; dt: step [s].
        S_ext: (nr,) external source [g cm^-2 s^-1] or None.
        floor: floor value [g cm^-2] (DustPy 1e-100; also the outer boundary value).
        v: (nr,) extra advection velocity [cm s^-1] (back-reaction B 2 eta r Omega, torque) or None.

    Returns:
        (Sigma_new (nr,), :class:`GasStepInfo`).

    Differentiable in every array argument (the tridiagonal solve has JVP and transpose rules).
    """
    Sigma_g = jnp.asarray(Sigma_g)
    area = jnp.pi * (ri[1:] ** 2 - ri[:-1] ** 2)
    A, B, Cc = gas_operator(area, nu, r, ri, v)
    rhs = Sigma_g
    if S_ext is not None:
        rhs = rhs.at[1:-1].add(dt * S_ext[1:-1])
    K1, K2 = const_grad_row(r, ri)
    fl = jnp.broadcast_to(jnp.asarray(floor, dtype=Sigma_g.dtype), Sigma_g.shape)
    x = implicit_tridiagonal_step(A, B, Cc, dt, rhs, K1, K2, fl[-1])
    # finaliser (DustPy std.gas.finalize): boundaries, then floor
    new = x.at[0].set(const_grad_value(x, r, ri)).at[-1].set(fl[-1])
    new = jnp.maximum(new, fl)
    flow = viscous_mass_flow(x, nu, r, ri, v)  # operator flows of the solved system
    mass_in = -area[0] * (new[0] - Sigma_g[0]) - dt * flow[0]
    mass_out = -area[-1] * (new[-1] - Sigma_g[-1]) + dt * flow[-1]
    # floor additions in the interior are booked as "external" mass (DustPy adds them silently)
    mass_ext = jnp.sum(area[1:-1] * (new[1:-1] - x[1:-1]))
    if S_ext is not None:
        mass_ext = mass_ext + dt * jnp.sum(area[1:-1] * S_ext[1:-1])
    return new, GasStepInfo(mass_in=mass_in, mass_out=mass_out, mass_ext=mass_ext, Sigma_solve=x)
