"""Local gas / disk state and its derived turbulence quantities (cgs).

Everything a velocity or drag formula needs is precomputed once into a :class:`GasState`
(an ``equinox.Module`` whose fields are all float arrays, so it can be jitted, vmapped and
differentiated with respect to e.g. ``alpha``, ``rho_g`` or ``T``).

References (Ormel 2008 thesis eqs. 1.13-1.18, 2.2-2.3, 4.2-4.3, 4.7, 6.1-6.14; conventions and
thesis typos in docs/design_notes.md):
    c_g = sqrt(k_B T / (mu m_H))                        eq. 1.13
    Omega = sqrt(G M_* / R^3), H_g = c_g / Omega        eq. 1.15
    rho_g(z) = Sigma_g / (sqrt(2 pi) H_g) exp(-z^2/2H^2) eq. 1.14
    l_mfp = mu m_H / (rho_g sigma_mol)                  ch. 1, below eq. 1.17
    nu_m = c_g l_mfp / divisor (2: ch. 2 fn. 2, ch. 4; 3: eq. 6.9)
    nu_T = alpha c_g^2 / Omega, Re = nu_T / nu_m        eqs. 1.18, 2.2, 4.2
    t_L = tL_factor / Omega, v_L = sqrt(alpha) c_g, L = v_L t_L, v_g = sqrt(3/2) v_L
    t_s = Re^-1/2 t_L, v_s = Re^-1/4 v_L, l_s = Re^-3/4 L (eq. 4.3 corrected: typo #1)
    eta = -(1/2)(c_g/v_K)^2 dlnP/dlnR                   eq. 4.7 (sign: typo #11)
    beta = (c_g/v_K)^2                                  ch. 3 §3.3.3
    molecular cloud: eqs. 6.1, 6.5-6.11 (t_L = t_cross, v_L = c_g, nu_m = c_g l_mfp/3)
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .. import constants as C
from .._validate import JaxcoagInputError, check

__all__ = [
    "GasState",
    "local_state",
    "midplane_state",
    "mmsn_hayashi81",
    "ch4_disk",
    "molecular_cloud",
    "VG_CONVENTIONS",
]

VG_CONVENTIONS = ("sqrt(1.5*alpha)*c", "sqrt(alpha)*c")

_Array = jax.Array


class GasState(eqx.Module):
    """Local gas state; every field is a float array [cgs].

    Fields:
        R: heliocentric radius [cm] (inf for a molecular-cloud core).
        z: height above the midplane [cm].
        M_star: stellar mass [g] (0 for a cloud).
        T: temperature [K].
        alpha: Shakura-Sunyaev turbulence parameter [-].
        mu: mean molecular weight [-].
        c_g: isothermal sound speed [cm/s].
        Omega: Keplerian frequency [1/s] (cloud: 1/t_L).
        v_K: Keplerian velocity [cm/s] (cloud: 0).
        H_g: gas scale height [cm] (cloud: Jeans length L_J).
        Sigma_g: gas surface density [g/cm^2] (cloud: rho_g L_J).
        rho_g: gas density at z [g/cm^3].
        P: pressure rho_g c_g^2 [dyn/cm^2].
        l_mfp: molecular mean free path [cm].
        nu_m, nu_T: molecular and turbulent kinematic viscosity [cm^2/s].
        Re: turbulent Reynolds number nu_T/nu_m [-] (the raw value; velocity code uses max(Re, 1)).
        t_L, v_L, L: large-eddy turnover time [s], velocity [cm/s], size [cm].
        v_g: rms turbulent gas velocity [cm/s] (normalisation of the OC07 spectrum).
        t_s, v_s, l_s: Kolmogorov-eddy time [s], velocity [cm/s], size [cm].
        eta: radial pressure-gradient parameter [-] (eq. 4.7).
        beta: (c_g/v_K)^2 [-] (ch. 3 §3.3.3; not the kernel exponent of ch. 5).
    """

    R: _Array
    z: _Array
    M_star: _Array
    T: _Array
    alpha: _Array
    mu: _Array
    c_g: _Array
    Omega: _Array
    v_K: _Array
    H_g: _Array
    Sigma_g: _Array
    rho_g: _Array
    P: _Array
    l_mfp: _Array
    nu_m: _Array
    nu_T: _Array
    Re: _Array
    t_L: _Array
    v_L: _Array
    L: _Array
    v_g: _Array
    t_s: _Array
    v_s: _Array
    l_s: _Array
    eta: _Array
    beta: _Array

    @property
    def Re_eff(self):
        """max(Re, 1): with Re <= 1 there is no inertial range (guard)."""
        return jnp.maximum(self.Re, 1.0)


def _vg_factor(vg_convention: str) -> float:
    if vg_convention == "sqrt(1.5*alpha)*c":
        return 1.5 ** 0.5
    if vg_convention == "sqrt(alpha)*c":
        return 1.0
    raise JaxcoagInputError(
        f"unknown vg_convention {vg_convention!r}; use one of {VG_CONVENTIONS} (Ormel 2008 thesis eq. 2.3b vs §3.3.3)"
    )


def _eddies(*, alpha, c_g, t_L, v_L, L, nu_m, nu_T, vgf):
    Re = nu_T / nu_m
    Re_eff = jnp.maximum(Re, 1.0)
    v_g = vgf * v_L
    t_s = Re_eff ** -0.5 * t_L
    v_s = Re_eff ** -0.25 * v_L
    l_s = Re_eff ** -0.75 * L
    return Re, v_g, t_s, v_s, l_s


def midplane_state(rho_g, T, alpha, Omega, *, R=None, M_star=C.M_sun, dlnP_dlnR=None,
                   mu=C.mu_gas, sigma_mol=C.sigma_mol, tL_factor=1.0, nu_m_divisor=2.0,
                   vg_convention="sqrt(1.5*alpha)*c", z=0.0) -> GasState:
    """Gas state from the local density directly (the parameters users fit: rho_g, alpha, T).

    Arguments:
        rho_g: gas density [g cm^-3] (> 0).
        T: temperature [K] (> 0).
        alpha: turbulence parameter (>= 0).
        Omega: Keplerian frequency [s^-1] (> 0).
        R: radius [cm]; default: from Omega and M_star (R = (G M_*/Omega^2)^(1/3)).
        M_star: stellar mass [g].
        dlnP_dlnR: midplane pressure gradient; None uses the approximation eta = (c_g/v_K)^2.
        mu, sigma_mol, tL_factor, nu_m_divisor, vg_convention: the gas conventions of docs/design_notes.md.
        z: height [cm] (recorded only; rho_g is taken as given at that height).

    Returns:
        GasState. References: thesis eqs. 1.13-1.18, 2.2-2.3, 4.2-4.3, 4.7.
    """
    rho_g = check(rho_g, "rho_g", positive=True, hint="pass the gas density in g cm^-3")
    T = check(T, "T", positive=True, hint="pass the gas temperature in K")
    alpha = check(alpha, "alpha", nonnegative=True, hint="alpha is the Shakura-Sunyaev parameter, e.g. 1e-4")
    Omega = check(Omega, "Omega", positive=True, hint="pass the Keplerian frequency in s^-1")
    M_star = check(M_star, "M_star", positive=True)
    mu = check(mu, "mu", positive=True, hint="mean molecular weight in units of m_H, e.g. 2.34")
    sigma_mol = check(sigma_mol, "sigma_mol", positive=True, hint="molecular cross-section in cm^2, e.g. 2e-15")
    tL_factor = check(tL_factor, "tL_factor", positive=True, hint="t_L = tL_factor / Omega; 1 (ch. 4) or 2 pi")
    nu_m_divisor = check(nu_m_divisor, "nu_m_divisor", positive=True, hint="nu_m = c_g l_mfp / divisor; 2 or 3")
    z = check(z, "z", hint="height above the midplane in cm")
    if dlnP_dlnR is not None:
        dlnP_dlnR = check(dlnP_dlnR, "dlnP_dlnR", hint="midplane pressure gradient, e.g. -11/4; or None")
    vgf = _vg_factor(vg_convention)
    mu = jnp.asarray(mu, rho_g.dtype)
    c_g = jnp.sqrt(C.k_B * T / (mu * C.m_H))
    if R is None:
        R = (C.G * M_star / Omega ** 2) ** (1.0 / 3.0)
    R = check(R, "R", positive=True)
    v_K = R * Omega
    H_g = c_g / Omega
    Sigma_g = jnp.sqrt(2 * jnp.pi) * H_g * rho_g * jnp.exp(0.5 * (jnp.asarray(z) / H_g) ** 2)
    l_mfp = mu * C.m_H / (rho_g * sigma_mol)
    nu_m = c_g * l_mfp / nu_m_divisor
    nu_T = alpha * c_g ** 2 / Omega
    t_L = tL_factor / Omega
    v_L = jnp.sqrt(alpha) * c_g
    L = v_L * t_L
    Re, v_g, t_s, v_s, l_s = _eddies(alpha=alpha, c_g=c_g, t_L=t_L, v_L=v_L, L=L, nu_m=nu_m,
                                     nu_T=nu_T, vgf=vgf)
    beta = (c_g / v_K) ** 2
    eta = beta if dlnP_dlnR is None else -0.5 * beta * jnp.asarray(dlnP_dlnR)
    P = rho_g * c_g ** 2
    f = lambda x: jnp.broadcast_to(jnp.asarray(x, rho_g.dtype), jnp.broadcast_shapes(
        jnp.shape(rho_g), jnp.shape(T), jnp.shape(alpha), jnp.shape(Omega)))
    return GasState(R=f(R), z=f(z), M_star=f(M_star), T=f(T), alpha=f(alpha), mu=f(mu), c_g=f(c_g),
                    Omega=f(Omega), v_K=f(v_K), H_g=f(H_g), Sigma_g=f(Sigma_g), rho_g=f(rho_g), P=f(P),
                    l_mfp=f(l_mfp), nu_m=f(nu_m), nu_T=f(nu_T), Re=f(Re), t_L=f(t_L), v_L=f(v_L), L=f(L),
                    v_g=f(v_g), t_s=f(t_s), v_s=f(v_s), l_s=f(l_s), eta=f(eta), beta=f(beta))


def local_state(R, M_star, Sigma_g, T, alpha, z=0.0, *, dlnP_dlnR=None, mu=C.mu_gas,
                sigma_mol=C.sigma_mol, tL_factor=1.0, nu_m_divisor=2.0,
                vg_convention="sqrt(1.5*alpha)*c") -> GasState:
    """Local disk state from (R, M_*, Sigma_g, T, alpha, z) (thesis eqs. 1.13-1.18, 4.2-4.3).

    Arguments:
        R: heliocentric radius [cm]; M_star: stellar mass [g]; Sigma_g: gas surface density
        [g cm^-2]; T: temperature [K]; alpha: turbulence parameter [-]; z: height [cm].
        dlnP_dlnR: midplane dlnP/dlnR for the exact eta (eq. 4.7); None gives eta ~ (c_g/v_K)^2.
        mu, sigma_mol, tL_factor (1 = t_L = 1/Omega; 2 pi = ch. 2 legacy), nu_m_divisor (2),
        vg_convention: gas convention 2 in docs/design_notes.md.

    Returns:
        GasState with rho_g(z) = Sigma_g/(sqrt(2 pi) H_g) exp(-z^2/(2 H_g^2)) (eq. 1.14).
    """
    R = check(R, "R", positive=True, hint="pass the radius in cm (e.g. jaxcoag.constants.AU)")
    M_star = check(M_star, "M_star", positive=True, hint="pass the stellar mass in g")
    Sigma_g = check(Sigma_g, "Sigma_g", positive=True, hint="pass the gas surface density in g cm^-2")
    T = check(T, "T", positive=True, hint="pass the gas temperature in K")
    z = check(z, "z")
    Omega = jnp.sqrt(C.G * M_star / R ** 3)
    c_g = jnp.sqrt(C.k_B * T / (mu * C.m_H))
    H_g = c_g / Omega
    rho_g = Sigma_g / (jnp.sqrt(2 * jnp.pi) * H_g) * jnp.exp(-0.5 * (z / H_g) ** 2)
    return midplane_state(rho_g, T, alpha, Omega, R=R, M_star=M_star, dlnP_dlnR=dlnP_dlnR, mu=mu,
                          sigma_mol=sigma_mol, tL_factor=tL_factor, nu_m_divisor=nu_m_divisor,
                          vg_convention=vg_convention, z=z)


def _power_law_disk(R, Sigma1, p, T1, q, alpha, z, M_star, **kw) -> GasState:
    R = check(R, "R", positive=True, hint="pass the radius in cm (e.g. 3 * jaxcoag.constants.AU)")
    x = R / C.AU
    return local_state(R, M_star, Sigma1 * x ** p, T1 * x ** q, alpha, z,
                       dlnP_dlnR=p + 0.5 * q - 1.5, **kw)


def mmsn_hayashi81(R, alpha=1e-4, z=0.0, *, M_star=C.M_sun, **kw) -> GasState:
    """Hayashi (1981) minimum-mass solar nebula (thesis ch. 1, ch. 2 §2.2.1).

    Sigma_g = 1700 (R/AU)^-3/2 g cm^-2, T = 280 (R/AU)^-1/2 K, M_* = M_sun, exact eta
    (dlnP/dlnR = -13/4).
    """
    return _power_law_disk(R, 1700.0, -1.5, 280.0, -0.5, alpha, z, M_star, **kw)


def ch4_disk(R, alpha=1e-4, z=0.0, *, rho_X=1.0, M_star=C.M_sun, **kw) -> GasState:
    """Chapter-4 disk (thesis Table 4.1, after Takeuchi & Lin 2002; thesis typo #16).

    Sigma_g = 353.5 rho_X (R/AU)^-1 g cm^-2, T = 280 (R/AU)^-1/2 K, t_L = 1/Omega, exact eta
    (dlnP/dlnR = -11/4). ``rho_X`` is the ch. 4 gas-density enhancement factor.
    """
    rho_X = check(rho_X, "rho_X", positive=True)
    return _power_law_disk(R, 353.5 * rho_X, -1.0, 280.0, -0.5, alpha, z, M_star, **kw)


def molecular_cloud(n, T=10.0, *, mu=C.mu_gas, sigma_mol=C.sigma_mol, nu_m_divisor=3.0) -> GasState:
    """Homogeneous Jeans-mass molecular-cloud core (thesis ch. 6 §6.2, eqs. 6.1-6.14).

    Arguments:
        n: gas number density [cm^-3] (thesis: 1e3..1e7).
        T: temperature [K].

    rho_g = n mu m_H; L_J = (1/2) sqrt(pi c_g^2/(G rho_g)) (eq. 6.5, typo #15); largest eddies
    t_L = t_cross = L_J/c_g (eq. 6.7), v_L = c_g, L = L_J; nu_m = c_g l_mfp/3 (eq. 6.9);
    Re = 3 L_J/l_mfp; v_g = sqrt(3/2) c_g. Omega is set to 1/t_L so that St = Omega tau_f;
    v_K, eta and beta are 0 (no drift in a cloud core); R = inf, Sigma_g = rho_g L_J.
    """
    n = check(n, "n", positive=True, hint="pass the gas number density in cm^-3 (e.g. 1e5)")
    T = check(T, "T", positive=True, hint="pass the gas temperature in K")
    mu = check(mu, "mu", positive=True, hint="mean molecular weight in units of m_H, e.g. 2.34")
    sigma_mol = check(sigma_mol, "sigma_mol", positive=True, hint="molecular cross-section in cm^2, e.g. 2e-15")
    nu_m_divisor = check(nu_m_divisor, "nu_m_divisor", positive=True, hint="nu_m = c_g l_mfp / divisor; 3 (eq. 6.9)")
    rho_g = n * mu * C.m_H
    c_g = jnp.sqrt(C.k_B * T / (mu * C.m_H))
    L_J = 0.5 * jnp.sqrt(jnp.pi * c_g ** 2 / (C.G * rho_g))
    t_L = L_J / c_g
    v_L = c_g
    l_mfp = mu * C.m_H / (rho_g * sigma_mol)
    nu_m = c_g * l_mfp / nu_m_divisor
    nu_T = v_L * L_J
    Re, v_g, t_s, v_s, l_s = _eddies(alpha=1.0, c_g=c_g, t_L=t_L, v_L=v_L, L=L_J, nu_m=nu_m,
                                     nu_T=nu_T, vgf=1.5 ** 0.5)
    z0 = jnp.zeros_like(rho_g)
    f = lambda x: jnp.broadcast_to(jnp.asarray(x, rho_g.dtype), jnp.broadcast_shapes(jnp.shape(n), jnp.shape(T)))
    return GasState(R=f(jnp.inf), z=f(z0), M_star=f(z0), T=f(T), alpha=f(1.0), mu=f(mu), c_g=f(c_g),
                    Omega=f(1.0 / t_L), v_K=f(z0), H_g=f(L_J), Sigma_g=f(rho_g * L_J), rho_g=f(rho_g),
                    P=f(rho_g * c_g ** 2), l_mfp=f(l_mfp), nu_m=f(nu_m), nu_T=f(nu_T), Re=f(Re), t_L=f(t_L),
                    v_L=f(v_L), L=f(L_J), v_g=f(v_g), t_s=f(t_s), v_s=f(v_s), l_s=f(l_s), eta=f(z0), beta=f(z0))


def jeans_quantities(gas: GasState):
    """Cloud diagnostics (thesis eqs. 6.1, 6.5-6.7): dict with L_J [cm], M_J [g], t_cross [s], t_ff [s]."""
    rho = gas.rho_g
    L_J = 0.5 * jnp.sqrt(jnp.pi * gas.c_g ** 2 / (C.G * rho))
    return dict(L_J=L_J, M_J=4 * jnp.pi / 3 * rho * L_J ** 3, t_cross=L_J / gas.c_g,
                t_ff=jnp.sqrt(3 * jnp.pi / (32 * C.G * rho)))
