"""Monomer materials of the contact model: elastic constants, surface energy and the derived JKR scales (cgs).

A :class:`Material` holds the seven material numbers of Wada et al. (2007) Table 2 plus the rolling parameter
xi_crit and the shear modulus; every derived quantity of the contact model (equilibrium contact radius, the
simulation units F_c, delta_c, m_1, v_0, t_c, the spring constants of sliding, rolling and twisting and their
critical values, the characteristic energies E_roll and E_break) is a property computed with jnp operations, so a
``Material`` can be traced, vmapped and differentiated (``jax.grad`` with respect to its leaves).

All monomers of one material are identical spheres of radius ``r1``; the reduced quantities of a contact are:
    R = r1/2,   1/E* = 2 (1 - nu^2)/E,   1/G* = 2 (2 - nu)/G,   G_red = (1/G + 1/G)^-1 = G/2,
where G_red is the "G" of Wada et al. eqs. 26, 35, 37 (only this reading makes eq. 36 consistent with eqs. 12, 35).
The shear modulus is not tabulated in the paper; the isotropic value G = E/(2 (1 + nu)) is the default.

References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007, ApJ 661, 320) §2 eqs. 1-45, 48-49, Tables 2-3;
Johnson, Kendall & Roberts (1971) for the JKR theory.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._validate import JaxcoagInputError, is_traced
from ...physics.contact import (
    contact_radius,
    e_break_jkr,
    e_roll_wada,
    jkr_delta0,
    jkr_delta_c,
    monomer_mass,
    pull_off_force,
)
from .jkr import V_STICK_UNITS

__all__ = ["Material", "ice", "quartz", "material"]

_UNITS = {
    "gamma": "surface energy in erg cm^-2 (mJ m^-2 has the same number)",
    "E": "Young's modulus in dyn cm^-2 (1 GPa = 1e10 dyn cm^-2)",
    "nu": "Poisson ratio, dimensionless, in (-1, 0.5)",
    "rho": "material density in g cm^-3 (1000 kg m^-3 = 1 g cm^-3)",
    "r1": "monomer radius in cm (0.1 um = 1e-5 cm)",
    "xi_crit": "critical rolling displacement in cm (2 A = 2e-8 cm)",
    "G": "shear modulus in dyn cm^-2 (default E/(2 (1 + nu)))",
}


def _f64(x):
    """Float64 array leaf (tracers are left alone so the Module can be rebuilt inside jit/grad)."""
    if is_traced(x):
        return x
    return jnp.asarray(x, dtype=jnp.float64)


class Material(eqx.Module):
    """Material of identical spherical monomers for the JKR + sliding/rolling/twisting contact model.

    Fields (float64 array leaves, cgs):
        gamma: surface energy per unit area gamma [erg cm^-2].
        E: Young's modulus [dyn cm^-2].
        nu: Poisson ratio [-], in (-1, 0.5).
        rho: material density [g cm^-3].
        r1: monomer radius [cm].
        xi_crit: critical rolling displacement [cm] (a free parameter: 2 A or 30 A in Wada et al. 2007 §2.2.3).
        G: shear modulus of the monomer material [dyn cm^-2] (the constructors fill E/(2 (1 + nu))).

    Derived properties (all cgs) are listed in the module docstring and on each property.

    References: Wada et al. (2007) §2, Table 2.
    """

    gamma: jax.Array = eqx.field(converter=_f64)
    E: jax.Array = eqx.field(converter=_f64)
    nu: jax.Array = eqx.field(converter=_f64)
    rho: jax.Array = eqx.field(converter=_f64)
    r1: jax.Array = eqx.field(converter=_f64)
    xi_crit: jax.Array = eqx.field(converter=_f64)
    G: jax.Array = eqx.field(converter=_f64)

    def __check_init__(self):
        for name in ("gamma", "E", "nu", "rho", "r1", "xi_crit", "G"):
            v = getattr(self, name)
            if is_traced(v):
                continue
            a = np.asarray(v)
            if not np.all(np.isfinite(a)):
                raise JaxcoagInputError(f"Material.{name} must be finite; give the {_UNITS[name]}. Got {v!r}.")
            if name == "nu":
                if not np.all((a > -1.0) & (a < 0.5)):
                    raise JaxcoagInputError(f"Material.nu must lie in (-1, 0.5) (the {_UNITS[name]}); got {v!r}.")
            elif not np.all(a > 0):
                raise JaxcoagInputError(f"Material.{name} must be > 0; give the {_UNITS[name]}. Got {v!r}.")

    # -- reduced quantities of a contact of two identical monomers ------------------------------------------------
    @property
    def R(self):
        """Reduced radius R = r1 r2/(r1 + r2) = r1/2 [cm] (Wada et al. 2007 §2.1)."""
        return 0.5 * self.r1

    @property
    def E_star(self):
        """Reduced Young's modulus E* = E/(2 (1 - nu^2)) [dyn cm^-2] (Wada et al. 2007 §2.1)."""
        return self.E / (2.0 * (1.0 - self.nu**2))

    @property
    def G_star(self):
        """Reduced shear modulus of the sliding spring, 1/G* = 2 (2 - nu)/G [dyn cm^-2] (Wada et al. 2007 eq. 13)."""
        return self.G / (2.0 * (2.0 - self.nu))

    @property
    def G_red(self):
        """Reduced shear modulus (1/G + 1/G)^-1 = G/2 [dyn cm^-2]: the G of Wada et al. 2007 eqs. 26, 35, 37."""
        return 0.5 * self.G

    # -- JKR scales --------------------------------------------------------------------------------------------
    @property
    def a0(self):
        """Equilibrium contact radius a_0 = (9 pi gamma R^2/E*)^(1/3) [cm] (Wada et al. 2007 eq. 1)."""
        return contact_radius(self.gamma, self.R, self.E_star)

    @property
    def delta0(self):
        """Equilibrium compression delta_0 = a_0^2/(3R) [cm] (Wada et al. 2007 eq. 4)."""
        return jkr_delta0(self.gamma, self.R, self.E_star)

    @property
    def delta_c(self):
        """Critical (separation) compression delta_c = (9/16)^(1/3) delta_0 [cm]; the length unit (Wada §2.1)."""
        return jkr_delta_c(self.gamma, self.R, self.E_star)

    @property
    def F_c(self):
        """Pull-off force F_c = 3 pi gamma R [dyn]; the force unit (Wada et al. 2007 eq. 5)."""
        return pull_off_force(self.gamma, self.R)

    @property
    def m1(self):
        """Monomer mass m_1 = (4/3) pi r1^3 rho [g]; the mass unit (Wada et al. 2007 §3)."""
        return monomer_mass(self.r1, self.rho)

    @property
    def I1(self):
        """Monomer moment of inertia I = (2/5) m_1 r1^2 [g cm^2]."""
        return 0.4 * self.m1 * self.r1**2

    @property
    def v0(self):
        """Velocity unit v_0 = sqrt(F_c delta_c/m_1) [cm s^-1] (Wada et al. 2007 eq. 48)."""
        return jnp.sqrt(self.F_c * self.delta_c / self.m1)

    @property
    def t_c(self):
        """Time unit t_c = delta_c/v_0 = sqrt(m_1 delta_c/F_c) [s] (Wada et al. 2007 eq. 49)."""
        return jnp.sqrt(self.m1 * self.delta_c / self.F_c)

    @property
    def k_n_eq(self):
        """Normal stiffness at equilibrium dF/ddelta(delta_0) = (6/5) F_c/delta_0 [dyn cm^-1] (from eqs. 4-5)."""
        return 1.2 * self.F_c / self.delta0

    # -- tangential springs (Wada et al. 2007 §2.2) -------------------------------------------------------------
    @property
    def k_s(self):
        """Sliding spring constant k_s = 8 a_0 G* [dyn cm^-1] (Wada et al. 2007 eq. 12)."""
        return 8.0 * self.a0 * self.G_star

    @property
    def k_r(self):
        """Rolling spring constant k_r = 4 F_c/R [dyn cm^-1] (Wada et al. 2007 eq. 22)."""
        return 4.0 * self.F_c / self.R

    @property
    def k_t(self):
        """Twisting spring constant k_t = (16/3) G a_0^3 [dyn cm], G = G_red (Wada et al. 2007 eq. 26)."""
        return (16.0 / 3.0) * self.G_red * self.a0**3

    @property
    def F_fric(self):
        """Critical sliding force F_fric = G a_0^2/(2 pi) [dyn], G = G_red (Wada et al. 2007 eq. 35)."""
        return self.G_red * self.a0**2 / (2.0 * jnp.pi)

    @property
    def zeta_crit(self):
        """Critical sliding displacement zeta_crit = (2 - nu) a_0/(16 pi) = F_fric/k_s [cm] (Wada eq. 36)."""
        return (2.0 - self.nu) * self.a0 / (16.0 * jnp.pi)

    @property
    def M_t_fric(self):
        """Critical twisting torque M_t,fric = G a_0^3/(3 pi) [dyn cm], G = G_red (Wada et al. 2007 eq. 37)."""
        return self.G_red * self.a0**3 / (3.0 * jnp.pi)

    @property
    def phi_crit(self):
        """Critical twisting angle phi_crit = M_t,fric/k_t = 1/(16 pi) [rad] (Wada et al. 2007 eq. 38)."""
        return jnp.full(jnp.shape(self.G), 1.0 / (16.0 * math.pi), dtype=jnp.float64)

    # -- characteristic energies and speeds ----------------------------------------------------------------------
    @property
    def E_roll(self):
        """Energy to roll 90 degrees, E_roll = k_r xi_crit pi R = 12 pi^2 gamma R xi_crit [erg] (Wada eq. 44)."""
        return e_roll_wada(self.gamma, self.R, self.xi_crit)

    @property
    def E_break(self):
        """Energy to break a contact, E_break = U_n(-delta_c) - U_n(delta_0) = 1.542585 F_c delta_c [erg] (Wada eq. 45)."""
        return e_break_jkr(self.gamma, self.R, self.E_star)

    @property
    def v_stick(self):
        """Head-on sticking speed of two free monomers, 1.93443 v_0 [cm s^-1] (energy 0.935503 F_c delta_c lost
        between contact creation at delta = 0 and separation at -delta_c; Wada et al. 2007 eq. 6)."""
        return V_STICK_UNITS * self.v0


def material(gamma, E, nu, rho, *, r1=1e-5, xi_crit=2e-8, G=None) -> Material:
    """A material of identical monomers from its constants (cgs).

    Arguments:
        gamma: surface energy [erg cm^-2]. E: Young's modulus [dyn cm^-2]. nu: Poisson ratio [-].
        rho: density [g cm^-3]. r1: monomer radius [cm] (default 0.1 um). xi_crit: critical rolling
        displacement [cm] (default 2 A). G: shear modulus [dyn cm^-2]; None -> isotropic E/(2 (1 + nu)).

    Returns: :class:`Material`.
    References: Wada et al. (2007) §2, Table 2.
    """
    if G is None:
        G = jnp.asarray(E, jnp.float64) / (2.0 * (1.0 + jnp.asarray(nu, jnp.float64)))
    return Material(gamma=gamma, E=E, nu=nu, rho=rho, r1=r1, xi_crit=xi_crit, G=G)


def quartz(r1=1e-5, xi_crit=2e-8) -> Material:
    """Quartz of Wada et al. (2007) Table 2: gamma = 25 mJ m^-2, E = 54 GPa, nu = 0.17, rho = 2600 kg m^-3 (cgs:
    25 erg cm^-2, 5.4e11 dyn cm^-2, 2.6 g cm^-3); r1 [cm], xi_crit [cm] (2 A = 2e-8 cm or 30 A = 3e-7 cm)."""
    return material(25.0, 54.0e10, 0.17, 2.6, r1=r1, xi_crit=xi_crit)


def ice(r1=1e-5, xi_crit=2e-8) -> Material:
    """Ice of Wada et al. (2007) Table 2: gamma = 100 mJ m^-2, E = 7 GPa, nu = 0.25, rho = 1000 kg m^-3 (cgs:
    100 erg cm^-2, 7e10 dyn cm^-2, 1.0 g cm^-3); r1 [cm], xi_crit [cm] (2 A = 2e-8 cm or 30 A = 3e-7 cm)."""
    return material(100.0, 7.0e10, 0.25, 1.0, r1=r1, xi_crit=xi_crit)
