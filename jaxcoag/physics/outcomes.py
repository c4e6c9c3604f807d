"""Collision outcomes shared by the binned and Monte Carlo engines (pure physics, cgs).

One interface (:class:`Outcome`; "Collision-outcome interface" in docs/design_notes.md) describes
what a pair (1, 2) turns into, vectorised over any pair grid:

* with probability ``1 - p_two`` one large remnant of mass M_L = (1 - f_pwl) M_tot and
  enlargement factor ``psi_one``;
* with probability ``p_two`` two remnants (bounce or breakage) of masses split*M_L and
  (1 - split)*M_L with ``psi_a``, ``psi_b``;
* in every case a mass f_pwl M_tot in small fragments, dn/dm ∝ m^q on [m_lo, m_hi], each
  with psi = :func:`psi_fragment` (N);
* the kernel is multiplied by ``eff`` (1 - f_miss).

Recipe functions build it: :func:`o07_outcome` (thesis ch. 2 porosity recipe, optional
energy-threshold fragmentation = the Dominik & Tielens / Wada thresholds, optional bounce
hook), :func:`bounce_outcome`, :func:`sticking_outcome`, :func:`mix_outcomes` (linear mixing
in expected mode). Fragmentation models are small equinox Modules (:class:`NoFragmentation`,
:class:`DTEnergy`, :class:`ShatterAtMass`). Hard switches (``width=0``, static) reproduce the
sources; ``width > 0`` replaces every threshold by a logistic in ln(E/E_thr) so gradients
with respect to material constants exist.

Also here: fragment power-law integrals and a mass-exact sampler (thesis eqs. 6.29-6.30),
the thesis ch. 4 bounce ingredients (lens area, f_comp), and Wada et al. 2007's fitted laws.

References: Ormel 2008 thesis chs. 2, 4, 5, 6 (Tab. 1.1, 6.1); Dominik & Tielens 1997;
Wada et al. 2007 (ApJ 661, 320) §5, eqs. 51-59; Birnstiel, Dullemond & Brauer (2010) (binned
fragment redistribution); errata: docs/design_notes.md.
"""

from __future__ import annotations

import abc
import functools

import equinox as eqx
import jax
import jax.numpy as jnp

from .contact import C_BREAK, Material
from .porosity import _chk, DELTA_CCA, _psi_o07, _reduced_mass, psi_mass_average, smooth_step
from .safe import safe_log, safe_sqrt

__all__ = [
    "Outcome",
    "collision_energy",
    "soft_clip01",
    "psi_fragment",
    "AbstractFragModel",
    "NoFragmentation",
    "DTEnergy",
    "ShatterAtMass",
    "dt_fragment_fraction",
    "dt_thresholds",
    "sticking_outcome",
    "bounce_outcome",
    "mix_outcomes",
    "o07_outcome",
    "BounceWhenCompact",
    "lens_area",
    "Compound",
    "compound_volume",
    "o08_outcome",
    "f_comp_o08",
    "o08_frag_flag",
    "powerlaw_mass_fraction",
    "mean_fragment_mass",
    "sample_fragment_masses",
    "wada_rg_ratio",
    "wada_ncon",
    "wada_rg_slope",
    "wada_ncon_max",
    "wada_bcca_rg",
    "wada_energy_ratio",
]


# ---------------------------------------------------------------------------------------------
class Outcome(eqx.Module):
    """Result of a collision recipe; every field is an array broadcast to the pair-grid shape.

    Fields:
        eff: kernel efficiency 1 - f_miss [-].
        p_two: probability of two large remnants (bounce or breakage) [-].
        split: fraction of M_L in remnant "a" when there are two [-] (m1/M_tot for a bounce).
        f_pwl: fraction of M_tot = m1 + m2 in small power-law fragments [-] (0..1).
        q: number slope of the fragments, dn/dm ∝ m^q [-].
        m_lo, m_hi: mass range of the fragments [g].
        psi_one: enlargement factor of the single remnant [-].
        psi_a, psi_b: enlargement factors of the two remnants [-].
        aux: dict of diagnostics (regime weights, energies), arrays of the same shape.

    Mass bookkeeping (exact for every recipe in this module, see :meth:`expected_mass`):
    (1 - p_two) M_L + p_two (split M_L + (1 - split) M_L) + f_pwl M_tot = M_tot.

    References: the collision-outcome interface in docs/design_notes.md.
    """

    eff: jax.Array
    p_two: jax.Array
    split: jax.Array
    f_pwl: jax.Array
    q: jax.Array
    m_lo: jax.Array
    m_hi: jax.Array
    psi_one: jax.Array
    psi_a: jax.Array
    psi_b: jax.Array
    aux: dict = eqx.field(default_factory=dict)

    @staticmethod
    def build(*, eff=1.0, p_two=0.0, split=0.5, f_pwl=0.0, q=-2.0, m_lo, m_hi, psi_one, psi_a=None,
              psi_b=None, aux=None) -> "Outcome":
        """Broadcast all fields to a common shape and return an :class:`Outcome`."""
        psi_a = psi_one if psi_a is None else psi_a
        psi_b = psi_one if psi_b is None else psi_b
        fields = [jnp.asarray(v, dtype=jnp.result_type(float)) for v in
                  (eff, p_two, split, f_pwl, q, m_lo, m_hi, psi_one, psi_a, psi_b)]
        shape = jnp.broadcast_shapes(*[f.shape for f in fields])
        fields = [jnp.broadcast_to(f, shape) for f in fields]
        aux = {} if aux is None else {k: jnp.broadcast_to(jnp.asarray(v), shape) for k, v in aux.items()}
        return Outcome(*fields, aux=aux)

    def remnant_masses(self, m1, m2):
        """Masses of the products [g].

        Returns a dict: M_tot, M_pwl = f_pwl M_tot, M_L = M_tot - M_pwl (single remnant),
        m_a = split M_L, m_b = M_L - m_a (the two remnants when p_two applies).
        """
        M_tot = m1 + m2
        M_pwl = self.f_pwl * M_tot
        M_L = M_tot - M_pwl
        m_a = self.split * M_L
        return dict(M_tot=M_tot, M_pwl=M_pwl, M_L=M_L, m_a=m_a, m_b=M_L - m_a)

    def expected_mass(self, m1, m2):
        """Expected total product mass [g]; equals m1 + m2 for every outcome (conservation)."""
        r = self.remnant_masses(m1, m2)
        return (1.0 - self.p_two) * r["M_L"] + self.p_two * (r["m_a"] + r["m_b"]) + r["M_pwl"]

    def expected_volume_moment(self, m1, m2, m0, c_f=1.0):
        """Expected sum of m psi over the products [g] (the W = sum m psi moment of a binned
        porosity scheme), with fragments at psi_fragment of their mean mass (approximation)."""
        r = self.remnant_masses(m1, m2)
        one = (1.0 - self.p_two) * r["M_L"] * self.psi_one
        two = self.p_two * (r["m_a"] * self.psi_a + r["m_b"] * self.psi_b)
        mbar = mean_fragment_mass(self.q, self.m_lo, self.m_hi)
        return one + two + r["M_pwl"] * psi_fragment(mbar / m0, c_f)


def collision_energy(m1, m2, dv):
    """Collision energy E = (1/2) m_mu dv^2 in the centre-of-mass frame.

    Arguments: m1, m2: masses [g] (> 0); dv: relative velocity [cm s^-1] (>= 0).
    Returns: E [erg]; m_mu is formed without the overflowing product m1 m2.
    References: Ormel 2008 thesis eqs. 2.9, 6.17; Wada et al. 2007 §5.1.
    """
    m1 = _chk(m1, "m1", positive=True, hint="masses are in grams")
    m2 = _chk(m2, "m2", positive=True, hint="masses are in grams")
    dv = _chk(dv, "dv", nonnegative=True, hint="relative velocity in cm/s")
    return 0.5 * _reduced_mass(m1, m2) * dv**2


def soft_clip01(t, width: float = 0.0):
    """clip(t, 0, 1) for width = 0; for width > 0 the C-infinity version
    width*[softplus(t/width) - softplus((t-1)/width)] (tends to the clip as width -> 0).

    Arguments: t [-]; width: static Python float (in units of t).
    Returns: value in [0, 1].
    References: smooth regime switches in docs/design_notes.md (smooth replacements of clamps).
    """
    t = jnp.asarray(t)
    if width == 0.0:
        return jnp.clip(t, 0.0, 1.0)
    return width * (jnp.logaddexp(0.0, t / width) - jnp.logaddexp(0.0, (t - 1.0) / width))


def _soft_ramp(z, lo, hi, width: float):
    """clip(z, lo, hi) - lo; for width > 0 (static, units of z) the softplus-smoothed version."""
    if width == 0.0:
        return jnp.clip(z, lo, hi) - lo
    return width * (jnp.logaddexp(0.0, (z - lo) / width) - jnp.logaddexp(0.0, (z - hi) / width))


def psi_fragment(n, c_f=1.0):
    """Enlargement factor of a small fragment of n monomers: psi = 1/min(1, c_f n^-0.33).

    Arguments: n: monomer number [-] (> 0); c_f: prefactor [-] (1, [CHOICE]: not printed).
    Returns: psi [-] (>= 1).
    References: Ormel 2008 thesis Fig. 6.2 (phi ∝ N^-0.33); erratum 18 (c_f) in
    docs/design_notes.md.
    """
    n = jnp.asarray(n)
    return 1.0 / jnp.minimum(1.0, c_f * jnp.maximum(n, 1.0) ** -0.33)


# ---------------------------------------------------------------------------------------------
# fragmentation models
class AbstractFragModel(eqx.Module):
    """Fragmentation model: maps a collision to (f_pwl, q, m_lo, m_hi) of the small fragments.

    ``__call__(m1, m2, energy, n_tot, e_break, m0, width)`` with masses [g], energy [erg],
    n_tot = (m1+m2)/m0 [-], e_break [erg] (per contact), m0 [g], width static.

    References: Ormel 2008 thesis §5.3.4, §6.3, Tab. 1.1; Wada et al. 2007 §5.5.
    """

    @abc.abstractmethod
    def __call__(self, m1, m2, energy, n_tot, e_break, m0, width=0.0):
        """Return (f_pwl, q, m_lo, m_hi) arrays of the broadcast pair shape."""


class NoFragmentation(AbstractFragModel):
    """No fragmentation: f_pwl = 0 (fragment range degenerate at m0).

    References: Ormel 2008 thesis §2.2.3 (fragmentation 'avoided by choosing moderate alpha').
    """

    def __call__(self, m1, m2, energy, n_tot, e_break, m0, width=0.0):
        z = jnp.zeros(jnp.broadcast_shapes(jnp.shape(m1), jnp.shape(m2), jnp.shape(energy)))
        return z, z - 2.0, z + m0, z + m0


def dt_fragment_fraction(energy, n_c, e_break, *, eps_ero=3.0, eps_cat=10.0, width=0.0):
    """Mass fraction in small fragments of the Dominik & Tielens / Wada threshold model.

    With e = E/(n_c E_break): 0 below eps_ero (no mass loss); rises linearly in ln E to 0.5
    at eps_cat (Wada's catastrophic-disruption definition N_large/N_tot = 0.5); then linearly
    in ln E to 1 at 3 eps_cat; 1 above (continuous) [CHOICE: a parametric
    bridge between the Dominik & Tielens (1997) / Wada et al. (2007) thresholds].

    Arguments:
        energy: collision energy [erg] (>= 0).
        n_c: number of contacts [-] (N in thesis ch. 2, n_k = N - 2 for Wada's BCCA pairs).
        e_break: breaking energy per contact [erg] (> 0).
        eps_ero, eps_cat: thresholds in units of n_c E_break (3 and 10).
        width: static smoothing in e-folds of energy (0 = hard kinks).

    Returns:
        f_pwl in [0, 1].

    References: Dominik & Tielens 1997; Wada et al. 2007 §5.5, Tab. 1; Ormel 2008 thesis
    Tab. 1.1, 6.1; Wada et al. 2007 §5.5.
    """
    le = safe_log(energy, fill=-1e3) - jnp.log(n_c * e_break)
    l_ero = jnp.log(eps_ero)
    l_cat = jnp.log(eps_cat)
    l_all = l_cat + jnp.log(3.0)
    t1 = _soft_ramp(le, l_ero, l_cat, width) / (l_cat - l_ero)
    t2 = _soft_ramp(le, l_cat, l_all, width) / (l_all - l_cat)
    return 0.5 * t1 + 0.5 * t2


def dt_thresholds(n_c, e_roll, e_break, *, restr_factor=5.0, eps_ero=3.0, eps_cat=10.0):
    """Characteristic collision energies of the Dominik & Tielens recipe [erg].

    Arguments:
        n_c: number of contacts [-] (N, or n_k = N - 2 for Wada's BCCA pairs).
        e_roll, e_break: rolling and breaking energies per contact [erg].
        restr_factor: first visible restructuring in E_roll (5; thesis ch. 2 uses 1).
        eps_ero, eps_cat: erosion onset and catastrophic disruption in n_c E_break (3, 10).

    Returns:
        dict: ``restructuring`` = restr_factor E_roll, ``max_compression`` = n_c E_roll,
        ``erosion`` = eps_ero n_c E_break, ``catastrophic`` = eps_cat n_c E_break.

    References: Dominik & Tielens 1997; Wada et al. 2007 Tab. 1, §5.5; Ormel 2008 thesis
    Tabs. 1.1, 6.1.
    """
    return dict(restructuring=restr_factor * e_roll, max_compression=n_c * e_roll,
                erosion=eps_ero * n_c * e_break, catastrophic=eps_cat * n_c * e_break)


class DTEnergy(AbstractFragModel):
    """Energy-threshold fragmentation (Dominik & Tielens 1997; Wada et al. 2007).

    Erosion from eps_ero n_c E_break, catastrophic disruption (half the mass in fragments)
    at eps_cat n_c E_break, all mass in fragments at 3 eps_cat (see
    :func:`dt_fragment_fraction`). Fragments: dn/dm ∝ m^q_frag on [m0, m_hi_frac M_tot].

    Fields: eps_ero (3), eps_cat (10), q_frag (-2.0), m_hi_frac (0.25) float leaves;
    contacts: static, "N" (n_c = N, thesis ch. 2) or "wada" (n_k = N - 2).

    References: Wada et al. 2007 §5.5; Ormel 2008 thesis Tab. 1.1.
    """

    eps_ero: jax.Array = eqx.field(default=3.0, converter=jnp.asarray)
    eps_cat: jax.Array = eqx.field(default=10.0, converter=jnp.asarray)
    q_frag: jax.Array = eqx.field(default=-2.0, converter=jnp.asarray)
    m_hi_frac: jax.Array = eqx.field(default=0.25, converter=jnp.asarray)
    contacts: str = eqx.field(static=True, default="N")

    def __check_init__(self):
        if self.contacts not in ("N", "wada"):
            raise ValueError(f"DTEnergy(contacts={self.contacts!r}): use 'N' (thesis ch. 2) or 'wada' (N - 2)")

    def __call__(self, m1, m2, energy, n_tot, e_break, m0, width=0.0):
        n_c = n_tot if self.contacts == "N" else jnp.maximum(n_tot - 2.0, 1.0)
        f = dt_fragment_fraction(energy, n_c, e_break, eps_ero=self.eps_ero, eps_cat=self.eps_cat,
                                 width=width)
        m_tot = m1 + m2
        m_hi = jnp.maximum(self.m_hi_frac * m_tot, m0)
        return f, jnp.broadcast_to(self.q_frag, f.shape), jnp.broadcast_to(m0, f.shape), m_hi


class ShatterAtMass(AbstractFragModel):
    """Thesis ch. 5 test problem: a product heavier than m_frag shatters into monomers.

    f_pwl = H(ln(M_tot/m_frag)) (logistic of width ``width`` when smooth), fragments all of
    mass m0 (m_lo = m_hi = m0).

    Fields: m_frag [g] (float leaf).
    References: Ormel 2008 thesis §5.3.4 (Figs. 5.8, 5.9; Ormel & Spaans 2008).
    """

    m_frag: jax.Array = eqx.field(converter=jnp.asarray)

    def __call__(self, m1, m2, energy, n_tot, e_break, m0, width=0.0):
        m_tot = m1 + m2
        f = smooth_step(jnp.log(m_tot) - jnp.log(self.m_frag), width)
        f = f * jnp.ones(jnp.shape(energy))
        mm0 = jnp.broadcast_to(m0, f.shape)
        return f, jnp.full(f.shape, -2.0), mm0, mm0


class BounceWhenCompact(eqx.Module):
    """[CHOICE, not from the sources] bounce when both partners are compact (psi <= psi_max)
    and E > N E_roll (T-Tab1.1 links compaction + bouncing to E ≈ N_c E_roll). Off by default.

    Fields: psi_max [-] (float leaf; e.g. 1/0.33).
    References: Ormel 2008 thesis Tab. 1.1, §6.6.1.
    """

    psi_max: jax.Array = eqx.field(default=1.0 / 0.33, converter=jnp.asarray)

    def weight(self, psi1, psi2, energy, n_tot, e_roll, width=0.0):
        """Bounce weight in [0, 1]."""
        x_e = safe_log(energy, fill=-1e3) - jnp.log(n_tot * e_roll)
        lp = jnp.log(self.psi_max)
        return (smooth_step(x_e, width) * smooth_step(lp - jnp.log(psi1), width)
                * smooth_step(lp - jnp.log(psi2), width))


# ---------------------------------------------------------------------------------------------
# outcome constructors
def sticking_outcome(m1, m2, psi, m0):
    """Perfect sticking: one remnant m1 + m2 with enlargement factor ``psi``.

    Arguments: m1, m2 [g]; psi [-] of the product; m0: monomer mass [g] (fragment range).
    Returns: :class:`Outcome` with p_two = f_pwl = 0, eff = 1.
    References: the collision-outcome interface in docs/design_notes.md.
    """
    return Outcome.build(m_lo=m0, m_hi=m0, psi_one=psi, aux=dict(m_tot=m1 + m2))


def bounce_outcome(m1, psi1, m2, psi2, m0, *, psi1_after=None, psi2_after=None):
    """Bounce: two remnants with the original masses (split = m1/M_tot), no fragments.

    Arguments: m1, m2 [g]; psi1, psi2 [-]; m0 [g]; psi1_after, psi2_after: optional
    post-bounce enlargement factors (e.g. compacted), default unchanged.
    Returns: :class:`Outcome` with p_two = 1, f_pwl = 0.
    References: Ormel 2008 thesis §4.2.3 (the only explicit bounce rule).
    """
    split = 1.0 / (1.0 + m2 / m1)
    pa = psi1 if psi1_after is None else psi1_after
    pb = psi2 if psi2_after is None else psi2_after
    return Outcome.build(p_two=1.0, split=split, m_lo=m0, m_hi=m0, psi_one=psi_mass_average(m1, pa, m2, pb),
                         psi_a=pa, psi_b=pb)


def mix_outcomes(w, a: Outcome, b: Outcome, m1, m2) -> Outcome:
    """Expected-mode mixture: with probability w outcome ``b``, else ``a``.

    Probabilities and masses mix linearly, so the expected products (and mass conservation)
    are exact: p_two, f_pwl and the remnant masses are w-weighted; psi of each remnant slot is
    mass-weighted between the two outcomes; fragment (q, m_lo, m_hi) are taken from the
    outcome carrying more fragment mass (exact when only one fragments).

    Arguments: w: weight of b in [0, 1]; a, b: outcomes; m1, m2: masses [g].
    Returns: :class:`Outcome`.
    References: smooth regime switches in docs/design_notes.md (outcomes mixed linearly in
    expected mode).
    """
    w = jnp.asarray(w)
    ra, rb = a.remnant_masses(m1, m2), b.remnant_masses(m1, m2)
    M_tot = ra["M_tot"]
    f_pwl = (1.0 - w) * a.f_pwl + w * b.f_pwl
    # expected single-remnant / two-remnant masses
    one_a = (1.0 - w) * (1.0 - a.p_two) * ra["M_L"]
    one_b = w * (1.0 - b.p_two) * rb["M_L"]
    two_a = (1.0 - w) * a.p_two * ra["M_L"]
    two_b = w * b.p_two * rb["M_L"]
    M_L = M_tot * (1.0 - f_pwl)
    p_two = jnp.where(M_L > 0, (two_a + two_b) / jnp.where(M_L > 0, M_L, 1.0), 0.0)

    def wavg(x, y, wx, wy):
        s = wx + wy
        return jnp.where(s > 0, (wx * x + wy * y) / jnp.where(s > 0, s, 1.0), 0.5 * (x + y))

    psi_one = wavg(a.psi_one, b.psi_one, one_a, one_b)
    ma = two_a * a.split + two_b * b.split
    split = jnp.where(two_a + two_b > 0, ma / jnp.where(two_a + two_b > 0, two_a + two_b, 1.0), 0.5)
    psi_a = wavg(a.psi_a, b.psi_a, two_a * a.split, two_b * b.split)
    psi_b = wavg(a.psi_b, b.psi_b, two_a * (1 - a.split), two_b * (1 - b.split))
    use_b = w * b.f_pwl > (1.0 - w) * a.f_pwl
    eff = (1.0 - w) * a.eff + w * b.eff
    aux = dict(a.aux)
    return Outcome.build(eff=eff, p_two=p_two, split=split, f_pwl=f_pwl,
                         q=jnp.where(use_b, b.q, a.q), m_lo=jnp.where(use_b, b.m_lo, a.m_lo),
                         m_hi=jnp.where(use_b, b.m_hi, a.m_hi), psi_one=psi_one, psi_a=psi_a,
                         psi_b=psi_b, aux=aux)


def o07_outcome(m1, psi1, m2, psi2, dv, mat: Material, *, delta=DELTA_CCA, B=1.0,
                mF_over_m0=10.0, restr_factor=1.0, psi_min=1.0,
                frag_model: AbstractFragModel | None = None,
                bounce_model: BounceWhenCompact | None = None, width: float = 0.0,
                validate: bool = True) -> Outcome:
    """Thesis ch. 2 collision recipe (O07), optionally with threshold fragmentation / bouncing.

    E = (1/2) m_mu dv^2; below restr_factor E_roll: hit-and-stick psi (eq. 2.15 + psi_add);
    above: compaction (eq. 2.17, f_C = clip(E/(N E_roll), 0, 1)). A fragmentation model adds
    a power-law fragment fraction f_pwl (e.g. :class:`DTEnergy`: erosion at 3 N E_br,
    catastrophic at 10 N E_br, the DT recipe when restr_factor = 5); the large remnant keeps
    psi from the recipe. With ``bounce_model`` a bounce (p_two, split = m1/M) is mixed in.

    Arguments:
        m1, m2: masses [g] (> 0); psi1, psi2: enlargement factors [-] (> 0); dv: relative
            velocity [cm s^-1] (>= 0). Broadcast against each other (e.g. a (n, n) pair grid).
        mat: :class:`Material` (m0, E_roll, E_break in its conventions, monomer pair R = a0/2).
        delta, B, mF_over_m0: hit-and-stick parameters (0.95, 1.0, 10).
        restr_factor: restructuring threshold in E_roll (1 in ch. 2, 5 = DT).
        psi_min: compaction floor (1 = none).
        frag_model: None (no fragmentation) or an :class:`AbstractFragModel`.
        bounce_model: None or :class:`BounceWhenCompact` ([CHOICE], off by default).
        width: static; 0 = hard switches (sources), > 0 = logistic regime switches (e-folds).
        validate: static; False skips input checks (engine hot loops).

    Returns:
        :class:`Outcome`; aux holds ``energy`` [erg], ``w_compact`` (compaction weight),
        ``w_bounce``.

    References: Ormel 2008 thesis eqs. 2.9, 2.13-2.19 and fn. 7, Tab. 1.1; Dominik &
    Tielens 1997; Wada et al. 2007 §5.5; errata 5, 6, 20 in docs/design_notes.md.
    """
    if validate:
        m1 = _chk(m1, "m1", positive=True, hint="masses are in grams")
        m2 = _chk(m2, "m2", positive=True, hint="masses are in grams")
        psi1 = _chk(psi1, "psi1", positive=True, hint="psi = V/V* >= 1 (1 = compact)")
        psi2 = _chk(psi2, "psi2", positive=True, hint="psi = V/V* >= 1 (1 = compact)")
        dv = _chk(dv, "dv", nonnegative=True, hint="relative velocity in cm/s")
    else:  # arrays, so that filter_jit traces them instead of treating floats as static
        m1, psi1, m2, psi2, dv = (jnp.asarray(x, dtype=jnp.result_type(float)) for x in (m1, psi1, m2, psi2, dv))
    # recipe constants as traced leaves: no recompilation when their values change
    delta, B, mF_over_m0, restr_factor, psi_min = (
        jnp.asarray(x, dtype=jnp.result_type(float)) for x in (delta, B, mF_over_m0, restr_factor, psi_min))
    return _o07_jit(m1, psi1, m2, psi2, dv, mat, delta, B, mF_over_m0, restr_factor, psi_min,
                    frag_model, bounce_model, width)


def _o07_impl(m1, psi1, m2, psi2, dv, mat, delta, B, mF_over_m0, restr_factor, psi_min,
              frag_model, bounce_model, width):
    """Unvalidated O07 outcome (see :func:`o07_outcome`); compiled once per shape/config."""
    m0 = mat.m0
    e_roll = mat.e_roll()
    e_br = mat.e_break()
    energy = 0.5 * _reduced_mass(m1, m2) * dv**2
    psi = _psi_o07(m1, psi1, m2, psi2, energy, e_roll, m0, restr_factor, delta, B, mF_over_m0,
                   psi_min, width)
    n_tot = m1 / m0 + m2 / m0
    fm = NoFragmentation() if frag_model is None else frag_model
    f_pwl, q, m_lo, m_hi = fm(m1, m2, energy, n_tot, e_br, m0, width)
    w_c = smooth_step(safe_log(energy, fill=-1e3) - jnp.log(restr_factor * e_roll), width)
    out = Outcome.build(f_pwl=f_pwl, q=q, m_lo=m_lo, m_hi=m_hi, psi_one=psi,
                        aux=dict(energy=energy, w_compact=w_c, w_bounce=jnp.zeros_like(energy)))
    if bounce_model is None:
        return out
    wb = bounce_model.weight(psi1, psi2, energy, n_tot, e_roll, width)
    bo = bounce_outcome(m1, psi1, m2, psi2, m0)
    mixed = mix_outcomes(wb, out, bo, m1, m2)
    aux = dict(energy=out.aux["energy"], w_compact=out.aux["w_compact"], w_bounce=jnp.broadcast_to(wb, out.eff.shape))
    return eqx.tree_at(lambda o: o.aux, mixed, aux)


_o07_jit = eqx.filter_jit(_o07_impl)


# ---------------------------------------------------------------------------------------------
# thesis ch. 4 (O08) ingredients
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


# ---------------------------------------------------------------------------------------------
# fragment power law (thesis eqs. 6.29-6.30)
def _expm1_over_x(x):
    small = jnp.abs(x) < 1e-6
    xs = jnp.where(small, 1.0, x)
    return jnp.where(small, 1.0 + 0.5 * x + x * x / 6.0, jnp.expm1(xs) / xs)


def _int_pow(lo, hi, k):
    """∫_lo^hi m^(k-1) dm = lo^k L expm1(k L)/(k L), L = ln(hi/lo); exact log form at k = 0."""
    L = jnp.log(hi) - jnp.log(lo)
    return jnp.exp(k * jnp.log(lo)) * L * _expm1_over_x(k * L)


@jax.jit
def powerlaw_mass_fraction(q, m_lo, m_hi, m_a, m_b):
    """Fraction of the fragment MASS in [m_a, m_b] for dn/dm ∝ m^q on [m_lo, m_hi].

    f = ∫_{m_a}^{m_b} m^(q+1) dm / ∫_{m_lo}^{m_hi} m^(q+1) dm, with [m_a, m_b] clipped to the
    support; q = -2 handled exactly (log form) with a smooth series around it.

    Arguments: q [-]; m_lo < m_hi [g]; m_a <= m_b [g] (bin edges). All broadcast.
    Returns: mass fraction [-]; e.g. q = -2, [1, 10] of [1, 250] -> 0.41702.
    References: Ormel 2008 thesis eq. 6.29 (the binned equivalent integrates
    m^(q+1) over each bin).
    """
    a = jnp.clip(m_a, m_lo, m_hi)
    b = jnp.clip(m_b, m_lo, m_hi)
    k = q + 2.0
    return _int_pow(a, jnp.maximum(b, a), k) / _int_pow(m_lo, m_hi, k)


@jax.jit
def mean_fragment_mass(q, m_lo, m_hi):
    """Number-mean fragment mass ∫ m^(q+1) dm / ∫ m^q dm over [m_lo, m_hi] [g].

    Arguments: q [-]; m_lo <= m_hi [g] (m_lo = m_hi returns m_lo).
    Returns: mean mass [g]; the number of fragments per unit M_pwl is its inverse.
    References: Ormel 2008 thesis eqs. 6.29-6.30 (q = -2 with m in [1, 250] -> 5.5436).
    """
    m_lo = jnp.asarray(m_lo)
    m_hi = jnp.asarray(m_hi)
    same = m_hi <= m_lo * (1.0 + 1e-12)
    hi = jnp.where(same, m_lo * 2.0, m_hi)
    mean = _int_pow(m_lo, hi, q + 2.0) / _int_pow(m_lo, hi, q + 1.0)
    return jnp.where(same, m_lo, mean)


@functools.partial(jax.jit, static_argnames=("capacity",))
def sample_fragment_masses(key, q, m_lo, m_hi, M_pwl, capacity: int):
    """Draw fragments from dn/dm ∝ m^q on [m_lo, m_hi] until the mass M_pwl is used (MC engine).

    Inverse-CDF draws x = [lo^(1+q) + r (hi^(1+q) - lo^(1+q))]^(1/(1+q)) (x = lo (hi/lo)^r at
    q = -1); fragments are taken in order while the running total is below M_pwl and the
    last one takes the remainder; if ``capacity`` draws do not reach M_pwl, all
    multiplicities are rescaled so the total is exact (the source's eta_dis rule).

    Arguments:
        key: PRNG key. q [-], m_lo, m_hi [g], M_pwl [g] (>= 0): scalars (vmap for batches).
        capacity: static maximum number of distinct fragment masses.

    Returns:
        (masses, mult): arrays (capacity,) [g] and [-]; sum(masses * mult) == M_pwl to
        rounding; unused slots have mult = 0.

    References: Ormel 2008 thesis eqs. 6.29-6.30.
    """
    r = jax.random.uniform(key, (capacity,), dtype=jnp.result_type(float))
    s = q + 1.0
    near = jnp.abs(s) < 1e-9
    s_safe = jnp.where(near, 1.0, s)
    llo, lhi = jnp.log(m_lo), jnp.log(m_hi)
    # log x = llo + log(1 + r (exp(s (lhi - llo)) - 1)) / s
    lx_pow = llo + jnp.log1p(r * jnp.expm1(s_safe * (lhi - llo))) / s_safe
    lx_log = llo + r * (lhi - llo)
    x = jnp.exp(jnp.where(near, lx_log, lx_pow))
    c = jnp.cumsum(x)
    c_prev = c - x
    take = c_prev < M_pwl
    last = take & (c >= M_pwl)
    masses = jnp.where(last, M_pwl - c_prev, x)
    mult = jnp.where(take, 1.0, 0.0)
    total = jnp.sum(masses * mult)
    scale = jnp.where(total > 0, M_pwl / jnp.where(total > 0, total, 1.0), 0.0)
    return masses, mult * scale


# ---------------------------------------------------------------------------------------------
# Wada et al. 2007 fitted laws (2D head-on BCCA collisions)
def wada_rg_ratio(x, fit: str = "W51", *, n_k=None, strict: bool = False):
    """Gyration radius of the largest cluster, r_g/(r1 sqrt(N_large)), vs x = E_imp/(n_k E_roll).

    W51 (N_tot = 256 fit): 0.84 x^-0.12; W58 (large N): x^-0.137 (= 1/2 - 1/d_f, d_f = 1.57).

    Arguments:
        x: E_imp/(n_k E_roll) [-] (> 0), E_roll in Wada's convention.
        fit: static, "W51" or "W58".
        n_k: number of contacts (needed with strict=True for the lower bound x >= 1/n_k).
        strict: static; NaN outside the fit's validity (W51: 1/n_k <= x <= 0.1;
            W58: 1/n_k <= x <= 1).

    Returns: r_g/(r1 sqrt(N_large)) [-] (2D; plays the role of psi^(1/2)).
    References: Wada et al. 2007 eqs. 51, 55, 58.
    """
    x = jnp.asarray(x)
    if fit == "W51":
        val, x_hi = 0.84 * x**-0.12, 0.1
    elif fit == "W58":
        val, x_hi = x**-0.137, 1.0  # printed exponent; = 1/2 - 1/d_f (W55), see wada_rg_slope
    else:
        raise ValueError(f"fit={fit!r}: choose 'W51' or 'W58'")
    if not strict:
        return val
    if n_k is None:
        raise ValueError("strict=True needs n_k (number of contacts) for the lower validity bound x >= 1/n_k")
    ok = (x * n_k >= 1.0) & (x <= x_hi)
    return jnp.where(ok, val, jnp.nan)


def wada_rg_slope(d_f=1.57):
    """Slope of log r_g vs log E_imp between the BCCA and compact states: 1/2 - 1/d_f.

    Arguments: d_f: fractal dimension of the 2D BCCA [-] (1.57).
    Returns: slope [-] (-0.136943 for d_f = 1.57; Wada print -0.137).
    References: Wada et al. 2007 eqs. 52-55.
    """
    return 0.5 - 1.0 / jnp.asarray(d_f)


def wada_ncon_max(N, k=1.35):
    """Maximum contacts per particle of a compressed 2D aggregate: k - (k - 1)/sqrt(N).

    Arguments: N: particles [-] (> 0); k [-] (1.3-1.4 quartz, 1.6 ice).
    Returns: n_con,max [-].
    References: Wada et al. 2007 eq. 57.
    """
    return k - (k - 1.0) / jnp.sqrt(jnp.asarray(N, dtype=jnp.result_type(float)))


def wada_ncon(x, N=None, k=1.35, *, strict: bool = False):
    """Contacts per particle in the largest cluster: n_con = 1 + x^0.75, x = E_imp/(n_k E_roll),
    capped at n_con,max(N, k) when N is given.

    Arguments: x [-] (> 0); N: particles [-] or None (no cap); k [-]; strict: static, NaN
    for x > 0.1 (W56 validity).
    Returns: n_con [-].
    References: Wada et al. 2007 eqs. 56, 57, 59.
    """
    x = jnp.asarray(x)
    val = 1.0 + x**0.75
    if N is not None:
        val = jnp.minimum(val, wada_ncon_max(N, k))
    if strict:
        val = jnp.where(x <= 0.1, val, jnp.nan)
    return val


def wada_bcca_rg(N):
    """Gyration radius of a 2D BCCA in monomer radii: r_g/r1 = (N/1.37)^(1/1.57).

    Arguments: N: particles [-] (> 0).
    Returns: r_g/r1 [-] (N = 8 -> 3.0770; N = 2048 -> 105.21).
    References: Wada et al. 2007 eq. 53.
    """
    N = _chk(N, "N", positive=True)
    return (N / 1.37) ** (1.0 / 1.57)


def wada_energy_ratio(N, v_over_v0, c_break=C_BREAK):
    """E_imp/(n_k E_break) for a head-on collision of two halves of N_tot = N monomers.

    E_imp = N m1 v^2/8 (centre-of-mass frame), n_k = N - 2, E_break = c_break F_c delta_c,
    v0 = sqrt(F_c delta_c/m1): ratio = N (v/v0)^2 / (8 c_break (N - 2)).

    Arguments: N [-] (> 2); v_over_v0 [-]; c_break [-] (1.542585; Wada rounds to 1.54).
    Returns: x_break [-] (N = 1024, 5.7 v0 -> 2.638; 2.642 with c_break = 1.54).
    References: Wada et al. 2007 §5.1, eqs. 45, 48.
    """
    N = _chk(N, "N", positive=True)
    return N * jnp.asarray(v_over_v0) ** 2 / (8.0 * c_break * (N - 2.0))
