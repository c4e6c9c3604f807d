"""Binned consumer of the shared collision :class:`~jaxcoag.physics.outcomes.Outcome` (compact, psi = 1).

The same recipe functions that drive the Monte Carlo engine (O07 with Dominik & Tielens energy
thresholds, the O09 tabulated recipe, ShatterAtMass, ...) are evaluated once per solve on the
bin-centre pair grid (i >= j, i the larger body "L", j the smaller "S"), with the relative
velocity dv = sqrt(``kernel.relative_velocity2``) of the scene kernel, and turned into a
mass-exact redistribution on the two-bin grid (Birnstiel, Dullemond & Brauer 2010, eq. 15)::

    P_ij(m) = (1 - p_two) delta(m - M_L) + p_two [delta(m - s M_L) + delta(m - (1 - s) M_L)]
              + f_pwl M_tot g(m),     M_L = (1 - f_pwl) M_tot,  g ∝ m^q on [m_lo, m_hi]

* each remnant "replaces" a parent (the single remnant and remnant a replace L, remnant b
  replaces S) and is placed by the number- and mass-conserving two-bin split between the
  centres around it; when it lands next to its parent's centre the parent's loss and the
  remnant's gain are merged analytically (ratio m_r/m_parent taken as expm1 of a log-ratio),
  so sweeping up a projectile 1e-20 times lighter than the target is not lost to cancellation
  (the same device as the coagulation tensors of :mod:`jaxcoag.binned.twobin`);
* the fragment mass f_pwl M_tot is spread over the bins by the exact integral of m^(q+1) over
  each bin's overlap with [m_lo, m_hi] (thesis eqs. 6.29-6.30; a degenerate range, m_lo = m_hi, puts it in
  the bin holding m_lo, e.g. monomers); the range is clipped to the grid, mass-exactly;
* the kernel is multiplied by ``eff`` = 1 - f_miss.

Every pair's coefficients sum to zero, so sum(rho) + gel is conserved to round-off. Indices
and coefficients are computed inside the solve from the recipe's (traced) outputs, so
gradients with respect to material constants (gamma, E*, xi_crit, v_frag ...) flow through
the solve; with ``width > 0`` (logistic regime switches, docs/design_notes.md) they are non-zero.

A recipe may also declare a *mixture weight* w (``recipe.weight``): a fraction 1 - w of the
collisions sticks perfectly (handled by the two-bin coagulation tensors) and w follows the
Outcome. This represents "fragment with probability p_f, else stick" exactly (e.g.
:class:`VfragShatter`, the Birnstiel et al. 2010 Maxwellian p_f), which an expected-mode
Outcome alone cannot: its single remnant always has number 1.

Compact particles only (psi = 1): the recipes are called with psi1 = psi2 = 1 and the
remnant/fragment psi fields are not transported (the W = sum m psi moment is the
porosity helper's job).

References: Ormel 2008 thesis §6.5 (eqs. 6.25-6.30), §5.3.4; Brauer et al. (2008) App. A;
Birnstiel, Dullemond & Brauer (2010) eq. 15; collision-outcome interface in docs/design_notes.md.
"""

from __future__ import annotations

from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp

from .._validate import JaxcoagInputError
from ..physics import fragmentation as pfrag
from ..physics.contact import Material
from ..physics.outcomes import DTEnergy, Outcome, ShatterAtMass, o07_outcome
from ..physics.recipes import RecipeTables, o09_outcome
from ..physics.safe import safe_sqrt
from .fragmentation import AbstractFragmentation
from .grid import LOG_TOL
from .twobin import _ext_log_centers

__all__ = ["OutcomeFragmentation", "OutcomeData", "O07Recipe", "O09Recipe", "ShatterAtMassRecipe",
           "VfragShatter", "fragment_weights", "place_remnant"]

_PROB = {"maxwellian": pfrag.p_frag_maxwellian, "sigmoid": pfrag.p_frag_sigmoid,
         "linear": pfrag.p_frag_linear, "step": pfrag.p_frag_step}


# ---------------------------------------------------------------------------------------------
# recipes: (m1, m2, dv, material, width) -> Outcome, with m1 >= m2 (compact)
class O07Recipe(eqx.Module):
    """Thesis ch. 2 recipe (O07) for compact particles, with an energy-threshold fragmentation
    model (default :class:`~jaxcoag.physics.outcomes.DTEnergy`: erosion from 3 N E_br,
    catastrophic at 10 N E_br, fragments dn/dm ∝ m^-2 on [m0, M_tot/4]).

    Fields: frag_model (AbstractFragModel or None), restr_factor (1 = ch. 2; 5 = DT),
    bounce_model (None, or BounceWhenCompact: [CHOICE] not from the sources).
    References: Ormel 2008 thesis §2.2.3, Tab. 1.1; Wada et al. (2007) §5.5.
    """

    frag_model: Any = eqx.field(default_factory=DTEnergy)
    restr_factor: jax.Array = eqx.field(default=1.0, converter=jnp.asarray)
    bounce_model: Any = None

    def __call__(self, m1, m2, dv, material, width=0.0):
        one = jnp.ones_like(m1)
        return o07_outcome(m1, one, m2, one, dv, material, frag_model=self.frag_model,
                           bounce_model=self.bounce_model, restr_factor=self.restr_factor,
                           width=width, validate=False)


class O09Recipe(eqx.Module):
    """Thesis ch. 6 tabulated recipe (O09, expected mode) for compact particles (phi = 1,
    clamped to the tables' highest phi node, 0.25 global / 0.16 local).

    Fields: tables (RecipeTables; ``RecipeTables.surrogate()`` when the CDS set is absent:
    label results as surrogate), b_frac (None = average over p(b) ∝ b), kappa_glob (3).
    References: Ormel 2008 thesis §6.3-6.5 (Ormel et al. 2009).
    """

    tables: RecipeTables = eqx.field(default_factory=RecipeTables.surrogate)
    b_frac: Any = None
    kappa_glob: jax.Array = eqx.field(default=3.0, converter=jnp.asarray)

    def __call__(self, m1, m2, dv, material, width=0.0):
        one = jnp.ones_like(m1)
        return o09_outcome(m1, one, m2, one, dv, self.tables, material, b_frac=self.b_frac,
                           kappa_glob=self.kappa_glob, width=width, validate=False)

    @property
    def is_surrogate(self) -> bool:
        return bool(self.tables.is_surrogate)


class ShatterAtMassRecipe(eqx.Module):
    """Thesis §5.3.4 test: products heavier than m_frag [g] shatter into monomers (mass m0 of
    the material). Velocity-free (works with analytic kernels).

    References: Ormel 2008 thesis §5.3.4, Figs. 5.8-5.9 (Ormel & Spaans 2008).
    """

    m_frag: jax.Array = eqx.field(converter=jnp.asarray)
    needs_velocity = False

    def __call__(self, m1, m2, dv, material, width=0.0):
        one = jnp.ones_like(m1)
        return o07_outcome(m1, one, m2, one, dv, material, frag_model=ShatterAtMass(self.m_frag),
                           width=width, validate=False)


class VfragShatter(eqx.Module):
    """Velocity-threshold shattering (Birnstiel et al. 2010): a fraction p_f(dv; v_frag) of the
    collisions (mixture weight) shatters completely into dn/dm ∝ m^-q on [m_lo, m_hi_factor m_L]
    (q = 11/6, Dohnanyi); the rest stick.

    Fields: v_frag [cm s^-1], q [-] (number exponent, positive), m_lo [g] (None = material m0),
    m_hi_factor [-] (upper fragment mass in units of the larger body's mass), probability
    (static: "maxwellian" | "sigmoid" | "linear" | "step"), p_width (sigmoid/linear width).
    References: Birnstiel, Dullemond & Brauer (2010) eq. 15; Brauer et al. (2008) §2.3.
    """

    v_frag: jax.Array = eqx.field(converter=jnp.asarray)
    q: jax.Array = eqx.field(default=11.0 / 6.0, converter=jnp.asarray)
    m_lo: Any = None
    m_hi_factor: jax.Array = eqx.field(default=1.0, converter=jnp.asarray)
    probability: str = eqx.field(static=True, default="maxwellian")
    p_width: jax.Array = eqx.field(default=0.1, converter=jnp.asarray)

    def __check_init__(self):
        if self.probability not in _PROB:
            raise JaxcoagInputError(f"VfragShatter(probability={self.probability!r}): use one of {sorted(_PROB)}.")

    def weight(self, m1, m2, dv, material, width=0.0):
        """Fraction of collisions that shatter, p_f(dv^2; v_frag) [-]."""
        dv2 = dv ** 2
        if self.probability in ("sigmoid", "linear"):
            return _PROB[self.probability](dv2, self.v_frag, self.p_width)
        return _PROB[self.probability](dv2, self.v_frag)

    def __call__(self, m1, m2, dv, material, width=0.0):
        m_lo = material.m0 if self.m_lo is None else self.m_lo
        return Outcome.build(f_pwl=1.0, q=-self.q, m_lo=m_lo, m_hi=self.m_hi_factor * jnp.maximum(m1, m2),
                             psi_one=jnp.ones_like(m1))


# ---------------------------------------------------------------------------------------------
# redistribution onto the grid
def fragment_weights(log_edges, q, m_lo, m_hi):
    """Mass fractions of a fragment power law dn/dm ∝ m^q on [m_lo, m_hi] per bin.

    W[..., b] = int_{bin b ∩ [m_lo, m_hi]} m^(q+1) dm / int_{[m_lo, m_hi] ∩ grid} m^(q+1) dm
    (exact bin integrals of m^(q+1); q = -2 and any q handled by expm1(x)/x). The range is
    clipped to the grid (mass-exact); a degenerate range (m_hi <= m_lo (1 + 1e-12), e.g.
    monomers, or a range entirely outside the grid) puts all the mass in the bin holding m_lo;
    bins are [m_lo, m_hi), and an m_lo on an interior edge to a relative LOG_TOL = 1e-9
    (:data:`jaxcoag.binned.grid.LOG_TOL`) goes to the bin above the edge, not to the side the
    round-off of ln m_lo happens to fall on (e.g. m_lo = 7 g, edge 7 of
    ``MassGrid.log(0.7, 7e7, 7)``: ln 7 rounds 2.2e-16 below that edge).

    Arguments: log_edges: (N+1,) ln of the bin edges [ln g]; q: number slope [-]; m_lo, m_hi:
    fragment mass range [g] (arrays of a common shape S).
    Returns: (S..., N) weights, each row summing to 1.
    References: Ormel 2008 thesis eqs. 6.29-6.30; Birnstiel, Dullemond & Brauer (2010)
    eq. 15.
    """
    le = jnp.asarray(log_edges)
    N = le.shape[0] - 1
    m_lo, m_hi, q = jnp.broadcast_arrays(jnp.asarray(m_lo), jnp.asarray(m_hi), jnp.asarray(q))
    llo = jnp.clip(jnp.log(m_lo), le[0], le[-1])[..., None]
    lhi = jnp.clip(jnp.log(m_hi), le[0], le[-1])[..., None]
    deg = (lhi - llo) <= 1e-12
    llo_s = jnp.where(deg, le[0], llo)
    lhi_s = jnp.where(deg, le[-1], lhi)
    s = (q + 2.0)[..., None]  # mass per ln m ∝ m^(q+2)
    lead = (1,) * (llo.ndim - 1)
    e_lo, e_hi = le[:-1].reshape(lead + (N,)), le[1:].reshape(lead + (N,))
    a = jnp.clip(llo_s, e_lo, e_hi)
    c = jnp.clip(lhi_s, e_lo, e_hi)
    w = c - a
    pos = w > 0
    w_s = jnp.where(pos, w, 1.0)
    x = s * w_s
    small = jnp.abs(x) < 1e-8
    x_s = jnp.where(small, 1.0, x)
    phi = jnp.where(small, 1.0 + 0.5 * x, jnp.expm1(x_s) / x_s)  # expm1(x)/x > 0
    logI = jnp.where(pos, s * a + jnp.log(w_s) + jnp.log(phi), -jnp.inf)
    W = jax.nn.softmax(logI, axis=-1)
    kb = jnp.clip(jnp.searchsorted(le, llo[..., 0] + LOG_TOL, side="right") - 1, 0, N - 1)
    onehot = jax.nn.one_hot(kb, N, dtype=W.dtype)
    return jnp.where(deg, onehot, W)


def place_remnant(lce, ref, l_ref, delta, nu):
    """Coefficients that replace nu bodies of bin ``ref`` by nu remnants of mass m_ref e^delta.

    Two-bin split (number and mass exact) between the centres around the remnant; merged
    analytic form when the remnant lies between its parent's centre and a neighbouring one
    (no cancellation for tiny delta); below the first centre: mass into bin 0; beyond the last
    (extended) centre: into the gel accumulator (index N).

    Arguments: lce: (N+1,) ln centres with the extrapolated gel centre [ln g]; ref: (P,) int
    parent bins; l_ref: (P,) ln parent mass; delta: (P,) ln(m_r/m_ref); nu: (P,) number of
    remnants per collision.
    Returns: (idx (P, 3) int32, coef (P, 3) [g]) — mass per collision into bins idx.
    References: Kovetz & Olund (1969); Brauer et al. (2008) App. A.
    """
    lce = jnp.asarray(lce)
    N = lce.shape[0] - 1
    lr = l_ref + delta
    k = jnp.searchsorted(lce, lr, side="right") - 1  # -1 .. N
    up = (delta >= 0) & (k == ref)
    dn = (delta < 0) & (k == ref - 1) & (ref >= 1)
    refp = jnp.minimum(ref + 1, N)
    refm = jnp.maximum(ref - 1, 0)
    m_ref = jnp.exp(l_ref)
    dl_up = lce[refp] - lce[ref]
    dl_dn = jnp.where(ref >= 1, lce[ref] - lce[refm], 1.0)
    e_up = jnp.expm1(jnp.where(up, delta, 0.0)) / jnp.expm1(dl_up)
    g_dn = jnp.expm1(jnp.where(dn, delta, 0.0)) / jnp.expm1(-dl_dn)
    below = k < 0
    beyond = k >= N
    kc = jnp.clip(k, 0, N)
    kc1 = jnp.minimum(kc + 1, N)
    m_r = jnp.exp(jnp.minimum(lr, 700.0))
    mk, mk1 = jnp.exp(lce[kc]), jnp.exp(lce[kc1])
    gen = ~(below | beyond)
    den = jnp.where(gen & (mk1 > mk), mk1 - mk, 1.0)
    e = jnp.where(gen, (m_r - mk) / den, 0.0)
    z = jnp.zeros_like(m_ref)
    c0 = jnp.where(up, -nu * m_ref * e_up, jnp.where(dn, -nu * m_ref * g_dn, -nu * m_ref))
    i1 = jnp.where(up, refp, jnp.where(dn, refm, jnp.where(below, 0, jnp.where(beyond, N, kc))))
    c1 = jnp.where(up, nu * jnp.exp(lce[refp]) * e_up, jnp.where(dn, nu * jnp.exp(lce[refm]) * g_dn,
                   jnp.where(gen, nu * (1.0 - e) * mk, nu * m_r)))
    i2 = jnp.where(gen & ~(up | dn), kc1, ref)
    c2 = jnp.where(gen & ~(up | dn), nu * e * mk1, z)
    idx = jnp.stack([ref, i1, i2], axis=-1).astype(jnp.int32)
    return idx, jnp.stack([c0, c1, c2], axis=-1)


class OutcomeData(eqx.Module):
    """Right-hand-side data of :class:`OutcomeFragmentation` on the two-bin pair list (a pytree).

    p: (Np,) fraction of collisions following the Outcome (1 - p stick via the coagulation
    tensors); eff: (Np,) kernel efficiency; coef/idx: (Np, 10) remnant placements and losses
    [g per collision] and their bins (N = gel); m_pwl: (Np,) fragment mass per collision [g];
    W: (Np, N) fragment mass fractions per bin.
    """

    p: jax.Array
    eff: jax.Array
    coef: jax.Array
    idx: jax.Array
    m_pwl: jax.Array
    W: jax.Array
    full: bool = eqx.field(static=True, default=False)

    def rhs(self, rate, nbins):
        """Mass rate [g cm^-3 s^-1] (nbins + 1,) from the Outcome collision number rates ``rate``."""
        r = rate * self.eff
        out = jax.ops.segment_sum((self.coef * r[:, None]).ravel(), self.idx.ravel(), num_segments=nbins + 1)
        gain = (r * self.m_pwl) @ self.W
        return out + jnp.concatenate([gain, jnp.zeros((1,), gain.dtype)])

    def mass_balance(self):
        """Per-pair sum of all mass coefficients [g] (zero up to round-off: conservation)."""
        return jnp.sum(self.coef, axis=1) + self.m_pwl * jnp.sum(self.W, axis=1)


class OutcomeFragmentation(AbstractFragmentation):
    """Binned (two-bin) consumer of a shared-physics collision recipe (module docstring).

    Arguments:
        recipe: callable (m1, m2, dv, material, width) -> :class:`~jaxcoag.physics.outcomes.Outcome`
            with m1 >= m2 [g], dv [cm s^-1]; e.g. :class:`O07Recipe` (DT energy thresholds),
            :class:`O09Recipe` (tabulated ch. 6 recipe), :class:`ShatterAtMassRecipe`,
            :class:`VfragShatter`. Equinox modules: their float fields are differentiable leaves.
            An optional ``recipe.weight(m1, m2, dv, material, width)`` gives the mixture weight.
        material: :class:`~jaxcoag.physics.contact.Material` (m0, E_roll, E_br; leaves).
        width: static regime-switch width in e-folds of energy (0 = the sources' hard
            switches, zero gradient w.r.t. thresholds; > 0 needed for d/d gamma etc.).
        use_velocity: static; dv from ``kernel.relative_velocity2`` (default: True unless the
            recipe sets ``needs_velocity = False``, then dv = 0 and analytic kernels work).

    References: Birnstiel, Dullemond & Brauer (2010) eq. 15 (binned consumer); smooth regime
    switches in docs/design_notes.md.
    """

    recipe: Callable
    material: Material
    width: float = eqx.field(static=True, default=0.0)
    use_velocity: bool = eqx.field(static=True, default=None)

    def __init__(self, recipe, material, width=0.0, use_velocity=None):
        if not callable(recipe):
            raise JaxcoagInputError("recipe must be a callable (m1, m2, dv, material, width) -> Outcome, e.g. "
                                    "jaxcoag.binned.O07Recipe() or O09Recipe().")
        if not isinstance(material, Material):
            raise JaxcoagInputError("material must be a jaxcoag.physics.contact.Material, e.g. "
                                    "Material.ch6_ice() (it supplies m0, E_roll and E_break).")
        if not float(width) >= 0.0:
            raise JaxcoagInputError(f"width must be >= 0 e-folds (got {width}); 0 = hard switches.")
        self.recipe = recipe
        self.material = material
        self.width = float(width)
        if use_velocity is None:
            use_velocity = bool(getattr(recipe, "needs_velocity", True))
        self.use_velocity = bool(use_velocity)

    @property
    def needs_velocity(self):  # instance-level (the base class has a ClassVar)
        return self.use_velocity

    def _pairs(self, kernel, mL, mS):
        if self.use_velocity:
            dv = safe_sqrt(kernel.relative_velocity2(mL, mS))
        else:
            dv = jnp.zeros_like(mL)
        out = self.recipe(mL, mS, dv, self.material, self.width)
        if not isinstance(out, Outcome):
            raise JaxcoagInputError(f"the recipe must return a jaxcoag Outcome, got {type(out).__name__}.")
        w = self.recipe.weight(mL, mS, dv, self.material, self.width) if hasattr(self.recipe, "weight") else None
        return out, w, dv

    def outcome(self, kernel, m_large, m_small):
        """The recipe's Outcome and mixture weight for masses m_large >= m_small [g] (diagnostics)."""
        out, w, _ = self._pairs(kernel, jnp.asarray(m_large), jnp.asarray(m_small))
        return out, (jnp.ones_like(out.eff) if w is None else w)

    def probability(self, kernel, m_large, m_small):
        """Fraction of collisions that do not simply stick: w [1 - (1 - f_pwl)(1 - p_two)] [-]."""
        out, w = self.outcome(kernel, m_large, m_small)
        return w * (1.0 - (1.0 - out.f_pwl) * (1.0 - out.p_two))

    def twobin_data(self, kernel, grid, iL, iS):
        """OutcomeData on the two-bin pair list (iL >= iS)."""
        lce = jnp.asarray(_ext_log_centers(grid))
        iLj, iSj = jnp.asarray(iL), jnp.asarray(iS)
        lL, lS = lce[iLj], lce[iSj]
        mL, mS = jnp.exp(lL), jnp.exp(lS)
        out, w, _ = self._pairs(kernel, mL, mS)
        f = jnp.clip(out.f_pwl, 0.0, 1.0)
        p2 = jnp.clip(out.p_two, 0.0, 1.0)
        s = jnp.clip(out.split, 0.0, 1.0)
        full = w is None
        p = jnp.ones_like(mL) if full else jnp.clip(w, 0.0, 1.0)
        # ln of the remnant masses relative to their parents, without cancellation
        ratio = jnp.exp(lS - lL)
        fs = jnp.where(f < 1.0, f, 0.0)
        l1mf = jnp.where(f < 1.0, jnp.log1p(-fs), -1e3)
        lML_L = jnp.log1p(ratio) + l1mf                       # ln(M_L / m_L)
        ss = jnp.where(s > 0.0, s, 1.0)
        s1 = jnp.where(s < 1.0, 1.0 - s, 1.0)
        la = jnp.where(s > 0.0, jnp.log(ss), -1e3) + lML_L     # ln(s M_L / m_L)
        lb = jnp.where(s < 1.0, jnp.log(s1), -1e3) + lML_L + (lL - lS)  # ln((1-s) M_L / m_S)
        i1, c1 = place_remnant(lce, iLj, lL, lML_L, 1.0 - p2)
        ia, ca = place_remnant(lce, iLj, lL, la, p2)
        ib, cb = place_remnant(lce, iSj, lS, lb, p2)
        iloss = iSj[:, None].astype(jnp.int32)
        closs = (-(1.0 - p2) * mS)[:, None]
        idx = jnp.concatenate([i1, ia, ib, iloss], axis=1)
        coef = jnp.concatenate([c1, ca, cb, closs], axis=1)
        M_tot = mL * (1.0 + ratio)
        W = fragment_weights(grid.log_edges, out.q, out.m_lo, out.m_hi)
        return OutcomeData(p=p, eff=jnp.clip(out.eff, 0.0, 1.0), coef=coef, idx=idx, m_pwl=f * M_tot, W=W,
                           full=full)

