"""The collision-outcome container shared by both engines, and fragment power-law helpers (cgs).

One container (:class:`Outcome`) describes what a pair (1, 2) turns into, vectorised over any
pair grid:

* with probability ``1 - p_two`` one large remnant of mass M_L = (1 - f_pwl) M_tot and
  enlargement factor ``psi_one``;
* with probability ``p_two`` two remnants (bounce or breakage) of masses split*M_L and
  (1 - split)*M_L with ``psi_a``, ``psi_b``;
* in every case a mass f_pwl M_tot in small fragments, dn/dm ∝ m^q on [m_lo, m_hi], each
  with psi = :func:`psi_fragment` (N);
* the kernel is multiplied by ``eff`` (1 - f_miss).

Paper recipes build it (:mod:`.ormel07` thesis ch. 2, :mod:`.ormel08` thesis ch. 4,
:mod:`.recipes` thesis ch. 6, with the Dominik & Tielens thresholds of :mod:`.dominik_tielens`);
here are the generic constructors (:func:`sticking_outcome`, :func:`bounce_outcome`,
:func:`mix_outcomes`: linear mixing in expected mode), the collision energy, the smooth clamps,
the fragment psi law, and the fragment power-law integrals and mass-exact sampler (thesis
eqs. 6.29-6.30). Both engines consume an Outcome through :class:`jaxcoag.outcomes.RecipeOutcome`.

References: Ormel 2008 thesis chs. 2, 5, 6 (eqs. 6.25-6.30); Birnstiel, Dullemond & Brauer
(2010) (binned fragment redistribution); errata: docs/design_notes.md.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp

from .porosity import _chk, _reduced_mass, psi_mass_average

__all__ = [
    "Outcome",
    "collision_energy",
    "soft_clip01",
    "psi_fragment",
    "sticking_outcome",
    "bounce_outcome",
    "mix_outcomes",
    "powerlaw_mass_fraction",
    "mean_fragment_mass",
    "sample_fragment_masses",
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


def pair_inputs(m1, psi1, m2, psi2, dv, validate: bool):
    """Masses [g], enlargement factors [-] and relative velocity [cm/s] of a colliding pair, checked
    (``validate``: positive masses and psi, non-negative dv, with messages) or only cast to float
    arrays (hot paths; arrays so that ``filter_jit`` traces them instead of treating floats as static)."""
    if validate:
        return (_chk(m1, "m1", positive=True, hint="masses are in grams"),
                _chk(psi1, "psi1", positive=True, hint="psi = V/V* >= 1 (1 = compact)"),
                _chk(m2, "m2", positive=True, hint="masses are in grams"),
                _chk(psi2, "psi2", positive=True, hint="psi = V/V* >= 1 (1 = compact)"),
                _chk(dv, "dv", nonnegative=True, hint="relative velocity in cm/s"))
    return tuple(jnp.asarray(x, dtype=jnp.result_type(float)) for x in (m1, psi1, m2, psi2, dv))

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
