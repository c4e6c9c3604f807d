"""Monomer contact physics: JKR contact, breaking and rolling energies, material presets (cgs).

All functions are pure and broadcasting; every material constant enters as a power law, so
they are smooth in (gamma, E*, R, xi_crit) and safe under ``jit``/``vmap``/``grad``.

Conventions (Wada et al. 2007 eqs. 1-6, 22, 44-45; Ormel 2008 thesis eqs. 1.27-1.31, 2.10, 4.12,
6.18; T = thesis, W = Wada, errata in docs/design_notes.md):
    R        = r1 r2/(r1+r2)                     reduced monomer radius (= a0/2 identical)
    1/E*     = (1-nu1^2)/E1 + (1-nu2^2)/E2       reduced modulus        [W, T§1.2.2 erratum]
    r_contact= (9 pi gamma R^2/E*)^(1/3)         JKR equilibrium contact radius [W1, T1.29]
    delta0   = r_contact^2/(3R), delta_c = (9/16)^(1/3) delta0
    F_c      = 3 pi gamma R                      pull-off force [W5]
    E_break  = A_br gamma^(5/3) R^(4/3) E*^(-2/3)     [T4.12a, T6.18a; W45 with A_br = 37.066]
    rolling energy: four named conventions (``e_roll_dt``, ``e_roll_wada``, ``e_roll_force``,
    ``e_roll_a``): thesis eqs. 2.10, 4.12b, 6.18b, Tab. 4.3; Wada eqs. 22, 44.

The thesis errata are applied: E*^2 (not E*^4) inside T1.30's cube root; the missing pi of
T1.31; (1-nu^2) instead of (1-nu)^2 in T§1.2.2; A_br(DT) = 43, not T-Tab4.3's 9.6.

References: Wada et al. 2007 (ApJ 661, 320) eqs. 1-6, 22, 44, 45, Tabs. 2-3;
Ormel 2008 thesis eqs. 1.27-1.31, 2.10, 4.12-4.14, 6.18-6.20, Tabs. 2.1, 4.3.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp

from .._validate import check, is_traced

__all__ = [
    "C_BREAK",
    "A_BR_WADA",
    "A_BR_CHOKSHI",
    "A_BR_EMPIRICAL",
    "A_ROLL_CH4",
    "F_ROLL_HEIM",
    "ROLL_CONVENTIONS",
    "BREAK_CONVENTIONS",
    "reduced_radius",
    "reduced_modulus",
    "contact_radius",
    "jkr_delta0",
    "jkr_delta_c",
    "pull_off_force",
    "jkr_potential",
    "e_break_jkr",
    "e_break",
    "e_roll_dt",
    "e_roll_wada",
    "e_roll_force",
    "e_roll_a",
    "monomer_mass",
    "v_break",
    "v_hit_and_stick",
    "Material",
]

_chk = check  # check() validates Python constants eagerly, also inside jit


# ---------------------------------------------------------------------------------------------
# Material-independent JKR constants [W6, W45; DER]
# U_n/(F_c delta_c) = 4 6^(1/3) [(4/5)x^5 - (4/3)x^(7/2) + (1/3)x^2], x = a/r_contact.
# U_n(x_sep = 6^(-2/3)) = 4/45 and U_n(x = 1) = -(4/5) 6^(1/3), so
C_BREAK = 4.0 / 45.0 + 0.8 * 6.0 ** (1.0 / 3.0)  # = 1.542585 (E_break / (F_c delta_c))
# E_break = C_BREAK F_c delta_c = A_br gamma^(5/3) R^(4/3) E*^(-2/3) with
A_BR_WADA = C_BREAK * math.pi * (9.0 / 16.0) ** (1.0 / 3.0) * (9.0 * math.pi) ** (2.0 / 3.0)  # 37.066
A_BR_CHOKSHI = 43.0  # Chokshi et al. 1993 (1.8 F_c delta_c -> 43.32), as quoted in T1.30, T6.18a
A_BR_EMPIRICAL = 2.8e3  # Blum & Wurm 2000 calibration used in thesis ch. 4 and ch. 6 (default)
A_ROLL_CH4 = 1.8e3  # T-Tab4.3 rolling prefactor (with xi = 1e-8 cm)
F_ROLL_HEIM = 8.5e-5  # dyn, Heim et al. 1999 rolling force for gamma = 14 erg/cm^2 [T2.10 text]
_GAMMA_HEIM = 14.0  # erg cm^-2

ROLL_CONVENTIONS = ("DT", "Wada", "force", "A")
BREAK_CONVENTIONS = ("A_br", "equal_roll")


# ---------------------------------------------------------------------------------------------
def reduced_radius(r1, r2):
    """Reduced monomer radius R = r1 r2/(r1 + r2).

    Arguments:
        r1, r2: monomer radii [cm] (> 0).

    Returns:
        R [cm]; equals r1/2 for identical monomers.

    References: Wada et al. 2007 §2.1 (R); Ormel 2008 thesis §1.2.2 (a_mu).
    """
    r1 = _chk(r1, "r1", positive=True)
    r2 = _chk(r2, "r2", positive=True)
    return r1 / (1.0 + r1 / r2)


def reduced_modulus(young1, poisson1, young2=None, poisson2=None):
    """Reduced Young's modulus E* with 1/E* = (1-nu1^2)/E1 + (1-nu2^2)/E2.

    Arguments:
        young1: Young's modulus of monomer 1 [dyn cm^-2] (> 0).
        poisson1: Poisson ratio of monomer 1 [-] (in [0, 0.5]).
        young2, poisson2: the same for monomer 2; default = monomer 1 (identical material),
            giving E* = E/(2(1-nu^2)).

    Returns:
        E* [dyn cm^-2].

    References: Wada et al. 2007 §2.1; Ormel 2008 thesis §1.2.2 with the (1-nu)^2 -> (1-nu^2)
    erratum (erratum 3 in docs/design_notes.md).
    """
    young1 = _chk(young1, "young1", positive=True, hint="Young's modulus is in dyn/cm^2 (1 GPa = 1e10)")
    poisson1 = _chk(poisson1, "poisson1", nonnegative=True)
    young2 = young1 if young2 is None else _chk(young2, "young2", positive=True)
    poisson2 = poisson1 if poisson2 is None else _chk(poisson2, "poisson2", nonnegative=True)
    return 1.0 / ((1.0 - poisson1**2) / young1 + (1.0 - poisson2**2) / young2)


def contact_radius(gamma, R, E_star):
    """JKR equilibrium contact radius r_contact = (9 pi gamma R^2 / E*)^(1/3).

    Arguments:
        gamma: surface energy [erg cm^-2].
        R: reduced monomer radius [cm].
        E_star: reduced modulus [dyn cm^-2].

    Returns:
        r_contact [cm] (Wada's a_0).

    References: Wada et al. 2007 eq. 1; Ormel 2008 thesis eq. 1.29.
    """
    return (9.0 * jnp.pi * gamma * R**2 / E_star) ** (1.0 / 3.0)


def jkr_delta0(gamma, R, E_star):
    """Equilibrium compression length delta0 = r_contact^2/(3R) [cm].

    Arguments: gamma [erg cm^-2], R [cm], E_star [dyn cm^-2].
    Returns: delta0 [cm].
    References: Wada et al. 2007 eq. 4.
    """
    return contact_radius(gamma, R, E_star) ** 2 / (3.0 * R)


def jkr_delta_c(gamma, R, E_star):
    """Critical (separation) displacement delta_c = (9/16)^(1/3) delta0 [cm].

    Arguments: gamma [erg cm^-2], R [cm], E_star [dyn cm^-2].
    Returns: delta_c [cm].
    References: Wada et al. 2007 §2.1 (below eq. 6).
    """
    return (9.0 / 16.0) ** (1.0 / 3.0) * jkr_delta0(gamma, R, E_star)


def pull_off_force(gamma, R):
    """JKR pull-off force F_c = 3 pi gamma R.

    Arguments: gamma [erg cm^-2], R: reduced radius [cm].
    Returns: F_c [dyn].
    References: Wada et al. 2007 eq. 5; Ormel 2008 thesis eq. 1.28.
    """
    return 3.0 * jnp.pi * gamma * R


def jkr_potential(x):
    """Normal JKR potential in units of F_c delta_c as a function of x = a/r_contact.

    U_n/(F_c delta_c) = 4 6^(1/3) [(4/5) x^5 - (4/3) x^(7/2) + (1/3) x^2].

    Arguments:
        x: contact radius over the equilibrium contact radius [-] (>= 0).

    Returns:
        U_n / (F_c delta_c) [-]; U(1) = -1.453696, U(6^(-2/3)) = 4/45, U((2/3)^(2/3)) = -0.846614.

    References: Wada et al. 2007 eq. 6.
    """
    x = jnp.asarray(x)
    return 4.0 * 6.0 ** (1.0 / 3.0) * (0.8 * x**5 - (4.0 / 3.0) * x**3.5 + x**2 / 3.0)


def e_break_jkr(gamma, R, E_star):
    """Energy to break a monomer contact, JKR: E_break = 1.542585 F_c delta_c.

    Arguments: gamma [erg cm^-2], R: reduced radius [cm], E_star [dyn cm^-2].
    Returns: E_break [erg]; identical to ``e_break(..., A_br=A_BR_WADA)``.
    References: Wada et al. 2007 eq. 45 (constant derived from eq. 6).
    """
    return C_BREAK * pull_off_force(gamma, R) * jkr_delta_c(gamma, R, E_star)


def e_break(gamma, R, E_star, A_br=A_BR_EMPIRICAL):
    """Breaking energy E_br = A_br gamma^(5/3) R^(4/3) E*^(-2/3).

    Arguments:
        gamma: surface energy [erg cm^-2].
        R: reduced monomer radius a_mu [cm] (a0/2 for a monomer pair).
        E_star: reduced modulus [dyn cm^-2].
        A_br: prefactor [-]: ``A_BR_EMPIRICAL`` = 2.8e3 (Blum & Wurm 2000; thesis ch. 4, 6),
            ``A_BR_CHOKSHI`` = 43, ``A_BR_WADA`` = 37.066 (= 1.5426 F_c delta_c).

    Returns:
        E_br [erg].

    References: Ormel 2008 thesis eqs. 1.30 (E*^4 -> E*^2 erratum), 4.12a, 6.18a.
    """
    return A_br * gamma ** (5.0 / 3.0) * R ** (4.0 / 3.0) * E_star ** (-2.0 / 3.0)


def e_roll_dt(gamma, R, xi_crit):
    """Rolling energy, Dominik & Tielens convention: E_roll = 6 pi^2 gamma R xi_crit.

    Arguments: gamma [erg cm^-2]; R: reduced radius [cm] (a0/2 for identical monomers, giving
    3 pi^2 gamma a0 xi); xi_crit: critical rolling displacement [cm] (2e-7 in thesis ch. 6).
    Returns: E_roll [erg].
    References: Ormel 2008 thesis eqs. 2.10, 4.12b, 6.18b (T1.31 lacks a factor pi: erratum).
    """
    return 6.0 * jnp.pi**2 * gamma * R * xi_crit


def e_roll_wada(gamma, R, xi_crit):
    """Rolling energy, Wada convention: E_roll = k_r xi_crit pi R = 12 pi^2 gamma R xi_crit.

    Twice the DT value because the torque is held at its maximum over the 90 degree roll.

    Arguments: gamma [erg cm^-2]; R: reduced radius [cm]; xi_crit [cm] (Wada: 2 A or 30 A).
    Returns: E_roll [erg].
    References: Wada et al. 2007 eqs. 22 (k_r = 4 F_c/R), 44.
    """
    return 12.0 * jnp.pi**2 * gamma * R * xi_crit


def e_roll_force(a0, gamma, F_roll=F_ROLL_HEIM):
    """Rolling energy from a measured rolling force: E_roll = (1/2) pi a0 F_roll (gamma/14).

    Arguments:
        a0: monomer radius [cm].
        gamma: surface energy [erg cm^-2]; the force scales linearly with gamma.
        F_roll: rolling force at gamma = 14 erg cm^-2 [dyn] (Heim et al. 1999: 8.5e-5).

    Returns:
        E_roll [erg] (thesis ch. 2: quartz gamma=25 -> 2.3842e-9, ice gamma=370 -> 3.5287e-8).

    References: Ormel 2008 thesis eq. 2.10 and text; Heim et al. 1999.
    """
    return 0.5 * jnp.pi * a0 * F_roll * (gamma / _GAMMA_HEIM)


def e_roll_a(gamma, R, xi_crit, A_roll=A_ROLL_CH4):
    """Rolling energy with a free prefactor: E_roll = A_roll xi a_mu gamma.

    Arguments: gamma [erg cm^-2]; R: reduced radius a_mu [cm]; xi_crit [cm] (ch. 4: 1e-8);
    A_roll: prefactor [-] (ch. 4: 1.8e3; DT corresponds to 6 pi^2 = 59.2).
    Returns: E_roll [erg].
    References: Ormel 2008 thesis Tab. 4.3.
    """
    return A_roll * xi_crit * R * gamma


def monomer_mass(a0, rho_s):
    """Monomer mass m0 = (4/3) pi a0^3 rho_s.

    Arguments: a0: monomer radius [cm]; rho_s: material density [g cm^-3].
    Returns: m0 [g].
    References: Ormel 2008 thesis §2.2.1; Wada et al. 2007 (m_1).
    """
    return 4.0 / 3.0 * jnp.pi * a0**3 * rho_s


def v_break(e_br, m_red):
    """Breaking velocity v_br = sqrt(2 E_br / m_mu).

    Arguments: e_br: breaking energy [erg]; m_red: reduced mass [g].
    Returns: v_br [cm s^-1].
    References: Ormel 2008 thesis eq. 6.19.
    """
    return jnp.sqrt(2.0 * e_br / m_red)


def v_hit_and_stick(e_roll, m_red, factor=10.0):
    """Hit-and-stick threshold velocity v_hs = sqrt(factor E_roll / m_mu) (factor 10 = 2 x 5 E_roll).

    Arguments: e_roll: rolling energy [erg]; m_red: reduced mass [g]; factor: 10 (T6.20, T4.14).
    Returns: v_hs [cm s^-1].
    References: Ormel 2008 thesis eqs. 6.20, 4.14.
    """
    return jnp.sqrt(factor * e_roll / m_red)


# ---------------------------------------------------------------------------------------------
def _f(x):
    return x if is_traced(x) else jnp.asarray(x, dtype=jnp.result_type(float))


class Material(eqx.Module):
    """Monomer material; every number is a float array leaf (differentiable, vmappable).

    Fields (cgs):
        a0: monomer radius [cm].
        rho_s: material (bulk) density [g cm^-3].
        gamma: surface energy [erg cm^-2].
        E_star: reduced Young's modulus of a monomer pair [dyn cm^-2].
        xi_crit: critical rolling displacement [cm] (``xi`` for the "A" convention).
        A_br: breaking-energy prefactor [-] (see :func:`e_break`).
        A_roll: rolling prefactor [-] (only for ``roll="A"``).
        F_roll: rolling force at gamma = 14 erg cm^-2 [dyn] (only for ``roll="force"``).
        roll: static; which rolling convention: "DT" (6 pi^2 gamma R xi), "Wada" (12 pi^2 gamma
            R xi), "force" (pi a0 F_roll gamma/28, thesis ch. 2), "A" (A_roll xi R gamma, ch. 4).
        breaking: static; "A_br" (E_br = A_br gamma^5/3 R^4/3 E*^-2/3) or "equal_roll"
            (E_br = E_roll, the thesis ch. 2 assumption of Fig. 2.3).

    Methods ``m0``, ``R_pair``, ``e_roll(R)``, ``e_break(R)``, ``F_c(R)`` give derived
    quantities; R defaults to a0/2 (a pair of identical monomers).

    Presets: ``wada_quartz``, ``wada_ice`` (W-Tab2, Wada conventions), ``ch2_quartz``,
    ``ch2_ice``, ``ch4_silicate``, ``ch6_silicate``, ``ch6_ice`` (thesis).

    References: Wada et al. 2007 Tabs. 2-3; Ormel 2008 thesis Tabs. 2.1, 4.3 and §6.2.3.
    """

    a0: jax.Array = eqx.field(converter=_f)
    rho_s: jax.Array = eqx.field(converter=_f)
    gamma: jax.Array = eqx.field(converter=_f)
    E_star: jax.Array = eqx.field(converter=_f)
    xi_crit: jax.Array = eqx.field(converter=_f)
    A_br: jax.Array = eqx.field(converter=_f, default=A_BR_EMPIRICAL)
    A_roll: jax.Array = eqx.field(converter=_f, default=A_ROLL_CH4)
    F_roll: jax.Array = eqx.field(converter=_f, default=F_ROLL_HEIM)
    roll: str = eqx.field(static=True, default="DT")
    breaking: str = eqx.field(static=True, default="A_br")

    def __check_init__(self):
        if self.roll not in ROLL_CONVENTIONS:
            raise ValueError(f"Material(roll={self.roll!r}): choose one of {ROLL_CONVENTIONS}")
        if self.breaking not in BREAK_CONVENTIONS:
            raise ValueError(f"Material(breaking={self.breaking!r}): choose one of {BREAK_CONVENTIONS}")
        for name in ("a0", "rho_s", "gamma", "E_star", "xi_crit", "A_br", "A_roll", "F_roll"):
            v = getattr(self, name)
            if not is_traced(v):
                _chk(v, f"Material.{name}", positive=True,
                      hint="material constants are positive cgs numbers (e.g. a0 = 1e-5 cm, "
                           "gamma = 25 erg/cm^2, E_star = 2.8e11 dyn/cm^2)")

    # -- derived quantities ------------------------------------------------------------------
    @property
    def m0(self):
        """Monomer mass (4/3) pi a0^3 rho_s [g]."""
        return monomer_mass(self.a0, self.rho_s)

    @property
    def R_pair(self):
        """Reduced radius of two identical monomers, a0/2 [cm]."""
        return 0.5 * self.a0

    def F_c(self, R=None):
        """Pull-off force 3 pi gamma R [dyn] (R default a0/2)."""
        return pull_off_force(self.gamma, self.R_pair if R is None else R)

    def e_roll(self, R=None):
        """Rolling energy [erg] in this material's convention (R: reduced radius [cm], default a0/2).

        For ``roll="force"`` E_roll = (1/2) pi (2R) F_roll gamma/14, i.e. a0 -> 2R.
        """
        R = self.R_pair if R is None else R
        if self.roll == "DT":
            return e_roll_dt(self.gamma, R, self.xi_crit)
        if self.roll == "Wada":
            return e_roll_wada(self.gamma, R, self.xi_crit)
        if self.roll == "force":
            return e_roll_force(2.0 * R, self.gamma, self.F_roll)
        return e_roll_a(self.gamma, R, self.xi_crit, self.A_roll)

    def e_break(self, R=None):
        """Breaking energy [erg] (R: reduced radius [cm], default a0/2)."""
        if self.breaking == "equal_roll":
            return self.e_roll(R)
        R = self.R_pair if R is None else R
        return e_break(self.gamma, R, self.E_star, self.A_br)

    # -- presets -----------------------------------------------------------------------------
    @classmethod
    def from_young(cls, a0, rho_s, gamma, young, poisson, xi_crit, **kw):
        """Build from Young's modulus [dyn cm^-2] and Poisson ratio (identical monomers)."""
        return cls(a0=a0, rho_s=rho_s, gamma=gamma, E_star=reduced_modulus(young, poisson),
                   xi_crit=xi_crit, **kw)

    @classmethod
    def wada_quartz(cls, xi_crit=2e-8):
        """Wada et al. 2007 quartz: r1 = 0.1 um, gamma = 25, E = 54 GPa, nu = 0.17, rho = 2.6;
        Wada rolling convention, JKR breaking (A_br = 37.066). xi_crit 2 A (or 30 A = 3e-7 cm)."""
        return cls.from_young(1e-5, 2.6, 25.0, 54e10, 0.17, xi_crit, A_br=A_BR_WADA, roll="Wada")

    @classmethod
    def wada_ice(cls, xi_crit=2e-8):
        """Wada et al. 2007 ice: r1 = 0.1 um, gamma = 100, E = 7 GPa, nu = 0.25, rho = 1.0;
        Wada rolling convention, JKR breaking. xi_crit 2 A (or 30 A = 3e-7 cm)."""
        return cls.from_young(1e-5, 1.0, 100.0, 7e10, 0.25, xi_crit, A_br=A_BR_WADA, roll="Wada")

    @classmethod
    def ch2_quartz(cls):
        """Thesis ch. 2 quartz (1 AU): a0 = 0.1 um, rho_s = 3, gamma = 25; rolling force law,
        E_br = E_roll. E_star (2.8e11, ch. 6 value) and xi_crit are unused by this preset."""
        return cls(a0=1e-5, rho_s=3.0, gamma=25.0, E_star=2.8e11, xi_crit=2e-7,
                   roll="force", breaking="equal_roll")

    @classmethod
    def ch2_ice(cls, gamma=370.0):
        """Thesis ch. 2 ice (5 AU): a0 = 0.1 um, rho_s = 1, gamma = 370 (T-Tab2.1; the text's 300
        is erratum 7, pass gamma=300 to use it); rolling force law, E_br = E_roll."""
        return cls(a0=1e-5, rho_s=1.0, gamma=gamma, E_star=3.7e10, xi_crit=2e-7,
                   roll="force", breaking="equal_roll")

    @classmethod
    def ch4_silicate(cls):
        """Thesis ch. 4 silicate: a0 = 1 um, rho = 3, gamma = 19, E* = 3.7e11, A_br = 2.8e3,
        A_roll = 1.8e3, xi = 1e-8 cm (T-Tab4.3)."""
        return cls(a0=1e-4, rho_s=3.0, gamma=19.0, E_star=3.7e11, xi_crit=1e-8,
                   A_br=A_BR_EMPIRICAL, A_roll=A_ROLL_CH4, roll="A")

    @classmethod
    def ch6_silicate(cls, a0=1e-5):
        """Thesis ch. 6 silicate: a0 = 0.1 um, rho0 = 2.65, gamma = 25, E* = 2.8e11,
        xi = 2e-7 cm, A_br = 2.8e3, DT rolling (§6.2.3)."""
        return cls(a0=a0, rho_s=2.65, gamma=25.0, E_star=2.8e11, xi_crit=2e-7,
                   A_br=A_BR_EMPIRICAL, roll="DT")

    @classmethod
    def ch6_ice(cls, a0=1e-5):
        """Thesis ch. 6 ice-coated silicate: as ``ch6_silicate`` with gamma = 370, E* = 3.7e10
        (bulk density stays 2.65)."""
        return cls(a0=a0, rho_s=2.65, gamma=370.0, E_star=3.7e10, xi_crit=2e-7,
                   A_br=A_BR_EMPIRICAL, roll="DT")
