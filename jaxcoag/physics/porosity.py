"""Porosity (enlargement factor psi = V/V*) recipes and porous-particle geometry (cgs).

Pure broadcasting functions, differentiable almost everywhere (kinks only where the sources
switch regime: the volume/mass ordering at V1 = V2 / m1 = m2, the compaction clip, the a_out
branch junction). Public functions validate their inputs (clear error, never a silent NaN);
the ``_underscore`` twins skip validation for engine hot loops.

Contents (Ormel 2008 thesis ch. 2 §2.2, eqs. 2.4-2.25; ch. 6 eqs. 6.22, 6.24):
    geometry      a* = (3m/4 pi rho_s)^(1/3), a = a* psi^(1/3), A = pi a^2        [T2.6, T2.25]
    ch. 2 (O07)   hit-and-stick psi with psi_add (eqs. 2.13-2.15, 2.19),
                  compaction (eq. 2.17), the combined O07 switch, PCA/CCA limits   [T§2.2.3-4]
    ch. 4         dust filling factor phi_dust = N^(1-3 delta/2)                   [T4.20]
    ch. 6 (O09)   hit-and-stick filling factor (eq. 6.24, forms A/B), outer radius
                  a_out from the empirical fit (eq. 6.22) and its inversion          [T§6.3]

References: Ormel 2008 PhD thesis (Leiden) chs. 2, 4, 6; Ormel, Spaans & Tielens 2007
(A&A 461, 215); Ormel et al. 2009 (A&A 502, 845).
"""

from __future__ import annotations

import jax.numpy as jnp

import jax

from .._validate import check
from .safe import safe_log

__all__ = [
    "DELTA_CCA",
    "compact_radius_of",
    "geometric_radius",
    "geometric_area",
    "enlargement_factor",
    "filling_factor",
    "psi_mass_average",
    "psi_hit_and_stick",
    "psi_add",
    "compaction_fraction",
    "psi_compaction",
    "psi_o07",
    "psi_fractal",
    "psi_pca_limit",
    "psi_cca_ratio",
    "phi_dust",
    "void_volume_o09",
    "phi_hit_and_stick_o09",
    "outer_radius_ratio",
    "outer_radius",
    "smooth_step",
]

_chk = check  # check() validates Python constants eagerly, also inside jit


DELTA_CCA = 0.95  # A ∝ m^delta for cluster-cluster aggregation (Ossenkopf; Kempf+99; Paszun & Dominik)


def smooth_step(x, width: float = 0.0):
    """Regime switch in a log-ratio x: Heaviside(x) for width = 0, logistic(x/width) otherwise.

    Arguments:
        x: log-ratio, e.g. ln(E/E_thr) [-].
        width: static Python float (e-folds); 0 reproduces the sources' hard switches exactly
            and builds no sigmoid (no 0*inf gradient hazard).

    Returns:
        weight in [0, 1] (H(0) = 1: the threshold itself belongs to the upper regime).

    References: smooth regime switches in docs/design_notes.md.
    """
    x = jnp.asarray(x)
    if width == 0.0:
        return jnp.where(x >= 0.0, 1.0, 0.0)
    if width < 0.0:
        raise ValueError(f"width must be >= 0 (got {width}); use 0 for the sources' hard switches")
    return 1.0 / (1.0 + jnp.exp(-x / width))


# ---------------------------------------------------------------------------------------------
# geometry (the radius formulas live in drag.py; this module adds the psi bookkeeping)
from .drag import _compact_radius, _porous_radius  # noqa: E402


def compact_radius_of(m, rho_s):
    """Compact radius a* = (3 m / (4 pi rho_s))^(1/3).

    Arguments: m: mass [g] (> 0); rho_s: material density [g cm^-3] (> 0).
    Returns: a* [cm].
    References: Ormel 2008 thesis eq. 2.6 (V* = m/rho_s).
    """
    m = _chk(m, "m", positive=True)
    rho_s = _chk(rho_s, "rho_s", positive=True)
    return _compact_radius(m, rho_s)


def _geometric_radius(m, psi, rho_s):
    return _porous_radius(m, rho_s, psi)


def geometric_radius(m, psi, rho_s):
    """Geometric radius a = a* psi^(1/3) of a porous particle (used for gas drag and sigma).

    Arguments:
        m: mass [g] (> 0).
        psi: enlargement factor V/V* [-] (>= 1 physically; > 0 accepted).
        rho_s: material density [g cm^-3] (> 0).

    Returns:
        a [cm]; e.g. (1.4 g, psi 86, rho_s 3) -> 2.12392 cm (T-Tab2.2 R1Ta4-P: 2.1 cm).

    References: Ormel 2008 thesis eqs. 2.6, 2.25.
    """
    m = _chk(m, "m", positive=True)
    psi = _chk(psi, "psi", positive=True, hint="psi = V/V* is >= 1 (1 = compact)")
    rho_s = _chk(rho_s, "rho_s", positive=True)
    return _geometric_radius(m, psi, rho_s)


def _geometric_area(m, psi, rho_s):
    return jnp.pi * _compact_radius(m, rho_s) ** 2 * psi ** (2.0 / 3.0)


def geometric_area(m, psi, rho_s):
    """Orientation-averaged projected area A = pi a*^2 psi^(2/3).

    Arguments: m [g] (> 0); psi [-] (> 0); rho_s [g cm^-3] (> 0).
    Returns: A [cm^2].
    References: Ormel 2008 thesis eqs. 2.4, 2.6, 2.25.
    """
    m = _chk(m, "m", positive=True)
    psi = _chk(psi, "psi", positive=True, hint="psi = V/V* is >= 1 (1 = compact)")
    rho_s = _chk(rho_s, "rho_s", positive=True)
    return _geometric_area(m, psi, rho_s)


def enlargement_factor(m, a, rho_s):
    """Enlargement factor psi = (a/a*)^3 from mass and geometric radius.

    Arguments: m [g] (> 0); a: geometric radius [cm] (> 0); rho_s [g cm^-3] (> 0).
    Returns: psi [-].
    References: Ormel 2008 thesis eq. 2.6.
    """
    m = _chk(m, "m", positive=True)
    a = _chk(a, "a", positive=True)
    rho_s = _chk(rho_s, "rho_s", positive=True)
    return (a / _compact_radius(m, rho_s)) ** 3


def filling_factor(psi):
    """Geometric filling factor phi = 1/psi [-] (thesis ch. 6 structural parameter).

    Arguments: psi: enlargement factor [-] (> 0).
    Returns: phi [-].
    References: Ormel 2008 thesis §6.3.1.
    """
    psi = _chk(psi, "psi", positive=True)
    return 1.0 / psi


# ---------------------------------------------------------------------------------------------
# chapter 2 recipe (O07)
def psi_mass_average(m1, psi1, m2, psi2):
    """Mass-averaged enlargement factor <psi>_m = (m1 psi1 + m2 psi2)/(m1 + m2).

    Arguments: m1, m2 [g] (any common unit); psi1, psi2 [-].
    Returns: <psi>_m [-] (written as a weighted mean, no overflow for huge masses).
    References: Ormel 2008 thesis eq. 2.14.
    """
    w1 = 1.0 / (1.0 + m2 / m1)
    return w1 * psi1 + (1.0 - w1) * psi2


def _reduced_mass(m1, m2):
    """m1 m2/(m1 + m2) without forming the product (no overflow)."""
    ms = jnp.minimum(m1, m2)
    mb = jnp.maximum(m1, m2)
    return ms / (1.0 + ms / mb)


def _order(m1, psi1, m2, psi2):
    """Canonical order (b = heavier; ties: larger psi) so that results are bitwise symmetric."""
    first = (m1 > m2) | ((m1 == m2) & (psi1 >= psi2))
    return (jnp.where(first, m1, m2), jnp.where(first, psi1, psi2),
            jnp.where(first, m2, m1), jnp.where(first, psi2, psi1))


def _psi_add_ordered(mb, psib, ms, m0, B, mF_over_m0):
    r = ms / mb
    m_red = ms / (1.0 + r)
    return B * r * psib * jnp.exp(-m_red / (mF_over_m0 * m0))


def _psi_add(m1, psi1, m2, psi2, m0, B, mF_over_m0):
    mb, pb, ms, ps = _order(m1, psi1, m2, psi2)
    return _psi_add_ordered(mb, pb, ms, m0, B, mF_over_m0)


def psi_add(m1, psi1, m2, psi2, *, m0, B=1.0, mF_over_m0=10.0):
    """PCA correction psi_add = B (m_s/m_b) psi_b exp(-m_mu/m_F), labels ordered by MASS.

    Arguments:
        m1, m2: masses [g] (> 0); psi1, psi2: enlargement factors [-] (> 0).
        m0: monomer mass [g] (> 0); B: amplitude [-] (1.0); mF_over_m0: m_F/m0 [-] (10).

    Returns:
        psi_add [-]; symmetric under swapping the particles. Ordering by mass (b = heavier)
        is our resolution of the thesis eq. 2.11/2.12 ambiguity (volume ordering can blow up).

    References: Ormel 2008 thesis eq. 2.19; erratum 5 in docs/design_notes.md.
    """
    m1, psi1, m2, psi2, m0 = _check_pair(m1, psi1, m2, psi2, m0)
    return _psi_add(m1, psi1, m2, psi2, m0, B, mF_over_m0)


def _psi_hit_and_stick(m1, psi1, m2, psi2, m0, delta=DELTA_CCA, B=1.0, mF_over_m0=10.0):
    """Unvalidated twin of :func:`psi_hit_and_stick` (engine hot paths)."""
    mb, pb, ms, ps = _order(m1, psi1, m2, psi2)
    r = ms / mb
    t = ps / pb
    # volume ratio small/large in (0, 1] (V ∝ m psi), without forming m*psi products
    x = jnp.where(r * t <= 1.0, r * t, 1.0 / (r * t))
    pm = (pb + r * ps) / (1.0 + r)  # <psi>_m
    psi_hs = pm * (1.0 + x) ** (1.5 * delta - 1.0)
    return psi_hs + _psi_add_ordered(mb, pb, ms, m0, B, mF_over_m0)


def _check_pair(m1, psi1, m2, psi2, m0):
    m1 = _chk(m1, "m1", positive=True, hint="masses are in grams")
    m2 = _chk(m2, "m2", positive=True, hint="masses are in grams")
    psi1 = _chk(psi1, "psi1", positive=True, hint="psi = V/V* >= 1 (1 = compact)")
    psi2 = _chk(psi2, "psi2", positive=True, hint="psi = V/V* >= 1 (1 = compact)")
    m0 = _chk(m0, "m0", positive=True, hint="m0 is the monomer mass (4/3) pi a0^3 rho_s in grams")
    return m1, psi1, m2, psi2, m0


def psi_hit_and_stick(m1, psi1, m2, psi2, *, m0, delta=DELTA_CCA, B=1.0, mF_over_m0=10.0):
    """Enlargement factor of the product of a hit-and-stick collision (thesis ch. 2 recipe).

    psi = <psi>_m (1 + x)^(3 delta/2 - 1) + psi_add, where x = V_s/V_b in (0, 1] is the volume
    ratio (V_i ∝ m_i psi_i, bracket ordered by VOLUME, eq. 2.12-2.13) and psi_add (eq. 2.19)
    is ordered by MASS ([CHOICE], erratum 5 in docs/design_notes.md).

    Arguments:
        m1, m2: masses [g] (> 0), broadcasting.
        psi1, psi2: enlargement factors [-] (> 0; 1 = compact).
        m0: monomer mass [g] (> 0).
        delta: fractal area exponent A ∝ m^delta [-] (0.95 = CCA).
        B: psi_add amplitude [-] (1.0; 0 switches the PCA correction off).
        mF_over_m0: m_F/m0 [-] (10).

    Returns:
        psi of the product [-], symmetric in (1, 2); product mass is m1 + m2.
        Limits: monomer PCA -> 1.425 (B = 0) / 14.974 (B = 1); CCA psi ∝ m^(3 delta/2 - 1).

    References: Ormel 2008 thesis eqs. 2.13-2.15, 2.19; Ormel, Spaans & Tielens 2007.
    """
    m1, psi1, m2, psi2, m0 = _check_pair(m1, psi1, m2, psi2, m0)
    return _psi_hs_jit(m1, psi1, m2, psi2, m0, delta, B, mF_over_m0)


def _compaction_fraction(energy, n, e_roll, width=0.0):
    x = energy / (n * e_roll)
    if width == 0.0:
        return jnp.clip(x, 0.0, 1.0)
    # smooth min(x, 1): x/(1 + x^p)^(1/p), p = 1/width (smooth switches, docs/design_notes.md); computed in log space
    p = 1.0 / width
    lx = safe_log(x, fill=-1e3)
    return jnp.where(x > 0, jnp.exp(lx - jnp.logaddexp(0.0, p * lx) / p), 0.0)


def compaction_fraction(energy, n, e_roll, *, width=0.0):
    """Compaction fraction f_C = clip(E/(N E_roll), 0, 1) (smooth min for width > 0).

    Arguments:
        energy: collision energy [erg] (>= 0).
        n: number of monomers (contacts) N = (m1 + m2)/m0 [-] (> 0).
        e_roll: rolling energy [erg] (> 0).
        width: static; 0 = hard clip; > 0 uses x/(1 + x^p)^(1/p), p = 1/width.

    Returns:
        f_C in [0, 1].

    References: Ormel 2008 thesis §2.2.3 (Delta V_p/V_p = -E/(N E_roll)); smooth switches in
    docs/design_notes.md.
    """
    energy = _chk(energy, "energy", nonnegative=True, hint="collision energy in erg")
    n = _chk(n, "n", positive=True)
    e_roll = _chk(e_roll, "e_roll", positive=True)
    return _compaction_fraction(energy, n, e_roll, width)


def _psi_compaction(m1, psi1, m2, psi2, energy, e_roll, m0, psi_min=1.0, width=0.0):
    mb, pb, ms, ps = _order(m1, psi1, m2, psi2)
    n = mb / m0 + ms / m0
    f_c = _compaction_fraction(energy, n, e_roll, width)
    pm = psi_mass_average(mb, pb, ms, ps)
    psi = 1.0 + (1.0 - f_c) * (pm - 1.0)
    if isinstance(psi_min, (int, float)) and psi_min == 1.0:
        return psi
    return jnp.maximum(psi, jnp.minimum(psi_min, pm))


def psi_compaction(m1, psi1, m2, psi2, energy, *, e_roll, m0, psi_min=1.0, width=0.0):
    """Enlargement factor after a compacting collision: psi - 1 = (1 - f_C)(<psi>_m - 1).

    f_C = clip(E/(N E_roll), 0, 1) with N = (m1 + m2)/m0; the porous volume of both partners
    shrinks by the factor (1 - f_C) (eq. 2.16).

    Arguments:
        m1, m2: masses [g] (> 0); psi1, psi2: enlargement factors [-] (> 0).
        energy: collision energy (1/2) m_mu dv^2 [erg] (>= 0).
        e_roll: rolling energy [erg] (> 0).
        m0: monomer mass [g] (> 0).
        psi_min: floor psi = max(psi, min(psi_min, <psi>_m)) (1 = thesis ch. 2, no floor;
            1/0.33 for the rolling-compaction limit of chs. 4 and 6) [CHOICE].
        width: static smoothing of the clip (0 = sources).

    Returns:
        psi of the product [-] (1, or the floor, when E >= N E_roll).

    References: Ormel 2008 thesis eqs. 2.16-2.17.
    """
    m1, psi1, m2, psi2, m0 = _check_pair(m1, psi1, m2, psi2, m0)
    energy = _chk(energy, "energy", nonnegative=True, hint="collision energy in erg")
    e_roll = _chk(e_roll, "e_roll", positive=True, hint="rolling energy in erg")
    return _psi_compaction_jit(m1, psi1, m2, psi2, energy, e_roll, m0, psi_min, width)


def _psi_o07(m1, psi1, m2, psi2, energy, e_roll, m0, restr_factor=1.0, delta=DELTA_CCA, B=1.0,
             mF_over_m0=10.0, psi_min=1.0, width=0.0):
    psi_hs = _psi_hit_and_stick(m1, psi1, m2, psi2, m0, delta, B, mF_over_m0)
    psi_c = _psi_compaction(m1, psi1, m2, psi2, energy, e_roll, m0, psi_min, width)
    e_thr = restr_factor * e_roll
    s = smooth_step(safe_log(energy, fill=-1e3) - jnp.log(e_thr), width)
    return (1.0 - s) * psi_hs + s * psi_c


def psi_o07(m1, psi1, m2, psi2, energy, *, e_roll, m0, restr_factor=1.0, delta=DELTA_CCA,
            B=1.0, mF_over_m0=10.0, psi_min=1.0, width=0.0):
    """Thesis ch. 2 (O07) porosity recipe: hit-and-stick below restr_factor E_roll, else compaction.

    Arguments:
        m1, m2 [g], psi1, psi2 [-]: the colliding particles (> 0).
        energy: collision energy [erg] (>= 0).
        e_roll: rolling energy [erg]; m0: monomer mass [g].
        restr_factor: compaction starts at restr_factor E_roll (1 in ch. 2, T fn. 7; 5 = DT).
        delta, B, mF_over_m0: hit-and-stick parameters (see :func:`psi_hit_and_stick`).
        psi_min: compaction floor (see :func:`psi_compaction`).
        width: static; 0 = hard switch, > 0 = logistic blend in ln E (e-folds) and smooth clip.

    Returns:
        psi of the product [-].

    References: Ormel 2008 thesis eqs. 2.13-2.19 and fn. 7; errata 5, 6, 20 in
    docs/design_notes.md.
    """
    m1, psi1, m2, psi2, m0 = _check_pair(m1, psi1, m2, psi2, m0)
    energy = _chk(energy, "energy", nonnegative=True, hint="collision energy in erg")
    e_roll = _chk(e_roll, "e_roll", positive=True, hint="rolling energy in erg")
    return _psi_o07_jit(m1, psi1, m2, psi2, energy, e_roll, m0, restr_factor, delta, B, mF_over_m0,
                    psi_min, width)


def psi_fractal(m, m0, delta=DELTA_CCA):
    """Pure fractal (CCA-like) scaling psi = (m/m0)^(3 delta/2 - 1).

    Arguments: m [g] (> 0); m0: monomer mass [g] (> 0); delta: area exponent [-].
    Returns: psi [-] (psi ∝ m^0.425 for delta = 0.95).
    References: Ormel 2008 thesis eq. 2.8.
    """
    m = _chk(m, "m", positive=True)
    m0 = _chk(m0, "m0", positive=True)
    return (m / m0) ** (1.5 * delta - 1.0)


def psi_pca_limit(delta=DELTA_CCA, psi2=1.0, B=1.0, mF_over_m0=10.0):
    """Asymptotic psi of monomer (PCA) growth with the O07 recipe.

    psi* = (3/2) delta psi2 / (1 - B exp(-1/mF_over_m0)); B = 0 gives (3/2) delta psi2 = 1.425.

    Arguments: delta [-]; psi2: monomer psi [-] (1); B [-]; mF_over_m0 [-].
    Returns: psi* [-] (14.974 for the ch. 2 defaults).
    References: Ormel 2008 thesis eq. 2.18 and §2.2.4 (PCA/CCA limits).
    """
    return 1.5 * delta * psi2 / (1.0 - B * jnp.exp(-1.0 / jnp.asarray(mF_over_m0)))


def psi_cca_ratio(delta=DELTA_CCA):
    """Growth factor of psi per equal-mass (CCA) doubling without psi_add: 2^(3 delta/2 - 1).

    Arguments: delta [-]. Returns: ratio [-] (1.342573 for delta = 0.95).
    References: Ormel 2008 thesis eqs. 2.8, 2.13.
    """
    return 2.0 ** (1.5 * jnp.asarray(delta) - 1.0)


def phi_dust(n, delta=DELTA_CCA):
    """Filling factor of a fractal dust aggregate of n monomers: phi = n^(1 - 3 delta/2).

    Arguments: n: number of monomers [-] (> 0); delta [-].
    Returns: phi [-]; with n = (a_dust/a0)^(2/delta): a/a0 = 10 -> 0.12743, 100 -> 0.016238.
    References: Ormel 2008 thesis eq. 4.20.
    """
    n = _chk(n, "n", positive=True)
    return n ** (1.0 - 1.5 * delta)


# ---------------------------------------------------------------------------------------------
# chapter 6 recipe (O09)
def _void_volume_o09(V1, V2, N2, phi2, delta=DELTA_CCA, form="B"):
    Vb = jnp.maximum(V1, V2)
    Vs = jnp.minimum(V1, V2)
    r = Vs / Vb
    cca = (Vb + Vs) * ((1.0 + r) ** (1.5 * delta - 1.0) - 1.0)
    if form == "B":
        X = jnp.exp(-15.0 * r**0.25)
    elif form == "A":
        X = jnp.exp(-((15.0 * r) ** 0.25))
    else:
        raise ValueError(f"form={form!r}: choose 'B' (default, satisfies both stated limits) or 'A' (as printed)")
    pca = N2 / (0.087 * phi2) * X
    return jnp.maximum(cca, pca)


def void_volume_o09(V1, V2, N2, phi2, *, delta=DELTA_CCA, form="B"):
    """Void volume created by a hit-and-stick collision, thesis ch. 6 (eq. 6.24).

    V_void = max[(V1+V2)((1+V_s/V_b)^(3 delta/2 - 1) - 1), N_s/(0.087 phi_s) X], with
    X_B = exp(-15 (V_s/V_b)^(1/4)) (default; both stated limits hold) or X_A = exp(-(15 V_s/V_b)^(1/4))
    (as printed; erratum 12). Label s = the smaller-VOLUME partner.

    Arguments:
        V1, V2: volumes in monomer volumes, V = N/phi [-] (> 0). The smaller one is the
            projectile; N2, phi2 are its monomer number and filling factor.
        N2: monomer number of the smaller-volume partner [-] (> 0).
        phi2: its filling factor [-] (> 0).
        delta: area exponent [-]; form: static "B" or "A".

    Returns:
        V_void in monomer volumes [-].

    References: Ormel 2008 thesis eq. 6.24 (erratum 12 in docs/design_notes.md).
    """
    V1 = _chk(V1, "V1", positive=True)
    V2 = _chk(V2, "V2", positive=True)
    N2 = _chk(N2, "N2", positive=True)
    phi2 = _chk(phi2, "phi2", positive=True)
    return _void_volume_o09(V1, V2, N2, phi2, delta, form)


def _phi_hit_and_stick_o09(N1, phi1, N2, phi2, delta=DELTA_CCA, form="B"):
    V1 = N1 / phi1
    V2 = N2 / phi2
    small2 = V2 <= V1
    Ns = jnp.where(small2, N2, N1)
    phis = jnp.where(small2, phi2, phi1)
    V_new = V1 + V2 + _void_volume_o09(V1, V2, Ns, phis, delta, form)
    return (N1 + N2) / V_new


def phi_hit_and_stick_o09(N1, phi1, N2, phi2, *, delta=DELTA_CCA, form="B"):
    """Filling factor of the product of a hit-and-stick collision, thesis ch. 6 recipe.

    phi_new = (N1 + N2)/(V1 + V2 + V_void), V_i = N_i/phi_i (monomer volumes), V_void from
    :func:`void_volume_o09` (the smaller-volume partner acts as projectile).

    Arguments:
        N1, N2: monomer numbers [-] (> 0); phi1, phi2: filling factors [-] (> 0).
        delta [-]; form: static "B" (default) or "A".

    Returns:
        phi of the product [-]; symmetric. Form B: CCA slope d ln phi/d ln N = -0.425,
        monomer PCA phi(1e5) = 0.152.

    References: Ormel 2008 thesis eq. 6.24 (erratum 12 in docs/design_notes.md).
    """
    N1 = _chk(N1, "N1", positive=True)
    N2 = _chk(N2, "N2", positive=True)
    phi1 = _chk(phi1, "phi1", positive=True)
    phi2 = _chk(phi2, "phi2", positive=True)
    return _phi_hs_o09_jit(N1, phi1, N2, phi2, delta, form)


_LOG_PHI_B0 = jnp.log(1.21) - 0.3 * jnp.log(1.2)  # phi_b(N) = 1.14663 N^-0.33


def _outer_radius_ratio(N, phi, width=0.0):
    lN = jnp.log(N)
    lphi = jnp.log(phi)
    expo = 0.75 - 4.21 * lN / jnp.log(10.0)  # compact branch exponent (< 0 for N > 1.6)
    ok = N >= 1.6
    expo_s = jnp.where(ok, expo, -1.0)
    l_compact = lphi / expo_s
    l_fluffy = -(10.0 / 3.0) * (lphi + 0.33 * lN - jnp.log(1.21))
    l_b = _LOG_PHI_B0 - 0.33 * lN  # ln phi_b
    if width == 0.0:
        l_ratio = jnp.where(lphi >= l_b, l_compact, l_fluffy)
    else:
        # logistic blend of the two branches in ln phi (~ +-5 % of phi_b <-> width 0.02) [CHOICE]
        s = 1.0 / (1.0 + jnp.exp(-(lphi - l_b) / width))
        l_ratio = s * l_compact + (1.0 - s) * l_fluffy
    l_ratio = jnp.maximum(l_ratio, 0.0)
    return jnp.where(ok, jnp.exp(l_ratio), 1.0)


def outer_radius_ratio(N, phi, *, width=0.0):
    """Outer-to-geometric radius ratio a_out/a from the thesis ch. 6 empirical fit (inverted).

    Fit: compact (a_out/a < 1.2): phi = (a_out/a)^(0.75 - 4.21 log10 N);
    fluffy (>= 1.2): phi = 1.21 (a_out/a)^(-0.3) N^(-0.33). Branch chosen by phi vs
    phi_b(N) = 1.14663 N^-0.33. Guards [CHOICE]: a_out = a for N < 1.6; a_out >= a.

    Arguments:
        N: number of monomers [-] (> 0).
        phi: filling factor 1/psi [-] (> 0).
        width: static; 0 = hard branch switch; > 0 blends the branches with a logistic in
            ln(phi/phi_b) of this width (0.02 spans about +-5 % of phi_b).

    Returns:
        a_out/a [-]; e.g. (1000, 0.05) -> 20.546, (1e6, 0.01) -> 2.20099.

    References: Ormel 2008 thesis eq. 6.22 (log10, DER; §6.4.1).
    """
    N = _chk(N, "N", positive=True)
    phi = _chk(phi, "phi", positive=True, hint="phi = 1/psi is the filling factor, 0 < phi <= 1")
    return _outer_radius_ratio_jit(N, phi, width)


def outer_radius(m, psi, rho_s, m0, *, width=0.0):
    """Outer radius a_out (smallest sphere around the centre of mass enclosing the aggregate).

    Arguments: m [g], psi [-], rho_s [g cm^-3], m0: monomer mass [g] (all > 0); width: static.
    Returns: a_out [cm] = a(m, psi) * outer_radius_ratio(m/m0, 1/psi).
    References: Ormel 2008 thesis eqs. 6.21-6.22.
    """
    m = _chk(m, "m", positive=True)
    psi = _chk(psi, "psi", positive=True)
    rho_s = _chk(rho_s, "rho_s", positive=True)
    m0 = _chk(m0, "m0", positive=True)
    return _geometric_radius(m, psi, rho_s) * _outer_radius_ratio(m / m0, 1.0 / psi, width)


# Compiled twins used by the validated public functions: one XLA executable per input shape
# instead of one per primitive in eager mode (numbers stay traced; only switches are static).
_psi_hs_jit = jax.jit(_psi_hit_and_stick)
_psi_compaction_jit = jax.jit(_psi_compaction, static_argnames=("width",))
_psi_o07_jit = jax.jit(_psi_o07, static_argnames=("width",))
_phi_hs_o09_jit = jax.jit(_phi_hit_and_stick_o09, static_argnames=("form",))
_outer_radius_ratio_jit = jax.jit(_outer_radius_ratio, static_argnames=("width",))
