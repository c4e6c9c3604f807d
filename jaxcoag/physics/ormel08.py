"""Thesis ch. 4 stick-or-bounce recipe for dust-rimmed chondrules (O08: Ormel, Cuzzi & Tielens 2008) (cgs).

Ingredients: the lens (overlap) area of two spheres' projections (:func:`lens_area`), the
porous mass fraction to compact (:func:`f_comp_o08`), the a-posteriori fragmentation flag
(:func:`o08_frag_flag`), three-phase compounds (:class:`Compound`, :func:`compound_volume`) and
the recipe :func:`o08_outcome` (an :class:`~jaxcoag.physics.outcome.Outcome` plus the product
compounds).

References: Ormel, Cuzzi & Tielens 2008 (ApJ 679, 1588); Ormel 2008 thesis §4.2.3-4.2.4,
eqs. 4.16-4.19, 4.25, Tab. 4.2; errata 10, 19 in docs/design_notes.md.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .contact import Material
from .outcome import Outcome, collision_energy
from .porosity import _chk, DELTA_CCA, _reduced_mass, smooth_step
from .safe import safe_log, safe_sqrt

__all__ = ["lens_area", "f_comp_o08", "o08_frag_flag", "Compound", "compound_volume", "o08_outcome"]


def lens_area(a1, a2, b):
    """Overlap area of two circles of radii a1, a2 whose centres are b apart.

    A = pi min(a1,a2)^2 for b <= |a1-a2|; 0 for b >= a1+a2; otherwise the standard lens
    a1^2 acos(c1) + a2^2 acos(c2) - (1/2) sqrt((-b+a1+a2)(b+a1-a2)(b-a1+a2)(b+a1+a2)).

    Arguments: a1, a2: radii [cm] (> 0); b: impact parameter [cm] (>= 0).
    Returns: A [cm^2] (T4.17 as printed is twice this: erratum 10).
    References: Ormel 2008 thesis eq. 4.17 (corrected: erratum 10 in
    docs/design_notes.md).
    """
    a1 = _chk(a1, "a1", positive=True)
    a2 = _chk(a2, "a2", positive=True)
    b = _chk(b, "b", nonnegative=True, hint="impact parameter in cm")
    inner = b <= jnp.abs(a1 - a2)
    outer = b >= a1 + a2
    mid = ~(inner | outer)
    bs = jnp.where(mid, b, 0.5 * (jnp.abs(a1 - a2) + a1 + a2))
    c1 = jnp.clip((bs**2 + a1**2 - a2**2) / (2 * bs * a1), -1.0, 1.0)
    c2 = jnp.clip((bs**2 + a2**2 - a1**2) / (2 * bs * a2), -1.0, 1.0)
    k = (-bs + a1 + a2) * (bs + a1 - a2) * (bs - a1 + a2) * (bs + a1 + a2)
    lens = a1**2 * jnp.arccos(c1) + a2**2 * jnp.arccos(c2) - 0.5 * safe_sqrt(k)
    return jnp.where(inner, jnp.pi * jnp.minimum(a1, a2) ** 2, jnp.where(outer, 0.0, lens))


def f_comp_o08(m1, m2, dv, mat: Material):
    """Porous mass fraction that must be compacted to dissipate the collision energy.

    f_comp = m0 (E/E_roll)/(m1 + m2), E = (1/2) m_mu dv^2, E_roll of a monomer pair
    (ch. 4: A_roll xi (a0/2) gamma).

    Arguments: m1, m2 [g] (> 0); dv [cm s^-1] (>= 0); mat: :class:`Material` (ch4_silicate).
    Returns: f_comp [-]; equal 1 g masses at 50 cm/s -> 0.22965 (stick if <= F_av, else bounce).
    References: Ormel 2008 thesis eq. 4.16, §4.2.3.
    """
    e = collision_energy(m1, m2, dv)
    return mat.m0 * (e / mat.e_roll()) / (m1 + m2)


def o08_frag_flag(m1, m2, dv, mat: Material, f_cat=8.0):
    """A posteriori fragmentation indicator of thesis ch. 4: f_comp / f_cat (>= 1: catastrophic,
    10 N_c E_br with E_br ≈ E_roll, i.e. f_comp ≈ 8).

    Arguments: m1, m2 [g]; dv [cm s^-1]; mat: :class:`Material`; f_cat [-] (8).
    Returns: ratio [-].
    References: Ormel 2008 thesis §4.2.3, §4.4.3.
    """
    return f_comp_o08(m1, m2, dv, mat) / f_cat


class Compound(eqx.Module):
    """Thesis ch. 4 chondrule-dust compound (three phases); every field an array.

    Fields: m: total mass [g]; f_d: dust mass fraction [-]; f_p: porous fraction of the dust
    [-]; phi_pd: filling factor of the porous dust phase [-].
    References: Ormel 2008 thesis Tab. 4.2, eq. 4.19.
    """

    m: jax.Array = eqx.field(converter=jnp.asarray)
    f_d: jax.Array = eqx.field(converter=jnp.asarray)
    f_p: jax.Array = eqx.field(converter=jnp.asarray)
    phi_pd: jax.Array = eqx.field(converter=jnp.asarray)


def compound_volume(c: Compound, *, rho_c=3.0, rho_d=3.0, phi_cd=0.33):
    """Volume of a compound: chondrule + compact dust (phi_cd) + porous dust (phi_pd) [cm^3].

    V = (1-f_d) m/rho_c + f_d (1-f_p) m/(rho_d phi_cd) + f_d f_p m/(rho_d phi_pd).

    Arguments: c: :class:`Compound`; rho_c, rho_d: chondrule and dust material densities
    [g cm^-3] (3, 3); phi_cd: compact-dust filling factor [-] (0.33).
    Returns: V [cm^3] (1 g, f_d = f_p = 0.5, phi_pd = 0.019114 -> 4.77897).
    References: Ormel 2008 thesis Tab. 4.2, eq. 4.19.
    """
    return ((1.0 - c.f_d) * c.m / rho_c + c.f_d * (1.0 - c.f_p) * c.m / (rho_d * phi_cd)
            + c.f_d * c.f_p * c.m / (rho_d * c.phi_pd))


def o08_outcome(c1: Compound, c2: Compound, dv, b, mat: Material, *, fgeo_mode: str = "geometric",
                fractal_compounds: bool = False, delta=DELTA_CCA, rho_c=3.0, rho_d=3.0,
                phi_cd=0.33, width: float = 0.0):
    """Thesis ch. 4 (O08) stick-or-bounce recipe for dust-rimmed chondrule compounds.

    f_comp = m0 (E/E_roll)/(m1+m2) (eq. 4.16) is the porous mass fraction that must be
    compacted; the available porous fraction is F_av = sum_i m_i f_d,i f_p,i f_geo,i/(m1+m2)
    with f_geo,i = lens(a1, a2, b)/(pi a_i^2) (eq. 4.17 corrected) or 1 (``fgeo_mode="unity"``).
    Stick if f_comp <= F_av (eqs. 4.18a,b: the compacted mass f_comp m moves to the compact
    phase; porous volumes mix additively, the rest keeps the mixed phi [CHOICE]; with
    ``fractal_compounds`` the hit-and-stick void V1((1+V2/V1)^(3 delta/2) - 1) - V2 is added to
    the porous phase before compaction, eq. 4.25). Otherwise bounce: masses and f_d kept,
    f_p,i -> f_p,i (1 - f_geo,i). No fragmentation (checked a posteriori, :func:`o08_frag_flag`).

    Arguments:
        c1, c2: :class:`Compound` (fields broadcast); dv: relative velocity [cm s^-1];
        b: impact parameter [cm] (ignored for fgeo_mode="unity"); mat: :class:`Material`
        (``Material.ch4_silicate()``: a0 = 1 um, gamma = 19, A_roll = 1.8e3, xi = 1e-8).
        fgeo_mode, fractal_compounds: static; delta [-]; rho_c, rho_d [g cm^-3]; phi_cd [-].
        width: static; 0 = hard stick/bounce switch on x = ln(F_av/f_comp), else logistic.

    Returns:
        (outcome, stuck, bounced1, bounced2): an :class:`Outcome` (p_two = bounce weight,
        split = m1/M, f_pwl = 0, psi = V/V* with V* the compact-material volume) and the
        product compounds. aux: f_comp, F_av, V_one [cm^3].

    References: Ormel 2008 thesis §4.2.3-4.2.4, eqs. 4.16-4.18, 4.25 (Ormel,
    Cuzzi & Tielens 2008); erratum 19 in docs/design_notes.md.
    """
    m1, m2 = _chk(c1.m, "c1.m", positive=True), _chk(c2.m, "c2.m", positive=True)
    dv = _chk(dv, "dv", nonnegative=True, hint="relative velocity in cm/s")
    V1 = compound_volume(c1, rho_c=rho_c, rho_d=rho_d, phi_cd=phi_cd)
    V2 = compound_volume(c2, rho_c=rho_c, rho_d=rho_d, phi_cd=phi_cd)
    a1 = (3.0 * V1 / (4.0 * jnp.pi)) ** (1.0 / 3.0)
    a2 = (3.0 * V2 / (4.0 * jnp.pi)) ** (1.0 / 3.0)
    if fgeo_mode == "unity":
        fg1 = fg2 = 1.0
    elif fgeo_mode == "geometric":
        A = lens_area(a1, a2, b)
        fg1, fg2 = A / (jnp.pi * a1**2), A / (jnp.pi * a2**2)
    else:
        raise ValueError(f"fgeo_mode={fgeo_mode!r}: choose 'geometric' or 'unity'")
    M = m1 + m2
    f_comp = mat.m0 * (0.5 * _reduced_mass(m1, m2) * dv**2 / mat.e_roll()) / M
    F_av = (m1 * c1.f_d * c1.f_p * fg1 + m2 * c2.f_d * c2.f_p * fg2) / M
    p_stick = smooth_step(safe_log(F_av, fill=-1e3) - safe_log(f_comp, fill=-1e3), width)
    # sticking update (eqs. 4.18a,b)
    f_d = (c1.f_d * m1 + c2.f_d * m2) / M
    M_pd = c1.f_d * c1.f_p * m1 + c2.f_d * c2.f_p * m2
    V_pd = c1.f_d * c1.f_p * m1 / (rho_d * c1.phi_pd) + c2.f_d * c2.f_p * m2 / (rho_d * c2.phi_pd)
    if fractal_compounds:
        Vb, Vs = jnp.maximum(V1, V2), jnp.minimum(V1, V2)
        V_pd = V_pd + Vb * (1.0 + Vs / Vb) ** (1.5 * delta) - Vb - Vs
    phi_bar = M_pd / (rho_d * V_pd)
    M_pd_left = jnp.maximum(M_pd - f_comp * M, 0.0)
    f_p = jnp.where(f_d > 0, M_pd_left / jnp.where(f_d > 0, f_d * M, 1.0), 0.0)
    stuck = Compound(m=M, f_d=f_d, f_p=f_p, phi_pd=phi_bar)
    b1 = Compound(m=m1, f_d=c1.f_d, f_p=c1.f_p * (1.0 - fg1), phi_pd=c1.phi_pd)
    b2 = Compound(m=m2, f_d=c2.f_d, f_p=c2.f_p * (1.0 - fg2), phi_pd=c2.phi_pd)

    def psi_of(c):
        v_star = (1.0 - c.f_d) * c.m / rho_c + c.f_d * c.m / rho_d
        return compound_volume(c, rho_c=rho_c, rho_d=rho_d, phi_cd=phi_cd) / v_star

    V_one = compound_volume(stuck, rho_c=rho_c, rho_d=rho_d, phi_cd=phi_cd)
    out = Outcome.build(p_two=1.0 - p_stick, split=1.0 / (1.0 + m2 / m1), m_lo=mat.m0, m_hi=mat.m0,
                        psi_one=psi_of(stuck), psi_a=psi_of(b1), psi_b=psi_of(b2),
                        aux=dict(f_comp=f_comp, F_av=F_av, V_one=V_one))
    return out, stuck, b1, b2
