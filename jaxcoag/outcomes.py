"""Collision outcomes: one class per recipe, consumed by both engines (cgs).

Pass an instance as ``jaxcoag.evolve(kernel, engine, initial, t_out, outcome=...)`` to either the
binned engine (:class:`jaxcoag.Binned`) or the grouped Monte Carlo engine
(:class:`jaxcoag.MonteCarlo`). Each class carries the hooks of both engines:

* binned (two-bin scheme precompute): ``needs_velocity`` (whether the kernel must provide
  ``relative_velocity2``), ``probability(kernel, m_large, m_small)`` (fraction of collisions that
  do not simply stick) and ``twobin_data(kernel, grid, iL, iS)`` (mass-exact redistribution data
  on the pair list i >= j);
* Monte Carlo (event loop): ``n_products`` (static number of product slots),
  ``bind(kernel)`` (called once by the engine before the run; returns the outcome with the
  run's kernel attached where the recipe needs collision velocities) and
  ``products(m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key) -> Products`` (the
  i-particle meets ``n_c`` j-particles);
* both: ``check(kernel, engine)`` (Python-time refusals before any work; ``engine`` is
  ``"binned"`` or ``"mc"``).

References: Ormel (2008) thesis §5.2.2, §5.3.4, App. 5.B step 5, §6.5; Brauer, Dullemond &
Henning (2008) §2.3; Birnstiel, Dullemond & Brauer (2010) eq. 15; Stammler & Birnstiel (2022)
§2.2.
"""

from __future__ import annotations

import abc
from typing import Any, Callable, ClassVar, NamedTuple

import numpy as np
import equinox as eqx
import jax
import jax.numpy as jnp

from ._validate import JaxcoagInputError, JaxcoagTypeError, check
from .physics import fragmentation as pfrag
from .physics.contact import Material
from .physics.dominik_tielens import AbstractFragModel
from .physics.ormel07 import o07_outcome
from .physics.outcome import Outcome, psi_fragment, sample_fragment_masses
from .physics.porosity import DELTA_CCA
from .physics.recipes import RecipeTables, o09_outcome
from .physics.safe import safe_sqrt

__all__ = ["Products", "AbstractOutcome", "Sticking", "ShatterAbove", "Shattering", "RecipeOutcome",
           "AbstractRecipe", "O07Recipe", "O09Recipe", "VfragShatter"]

#: relative tolerance of mass comparisons with a threshold (same as jaxcoag.binned.grid.LOG_TOL):
#: a product exactly at a threshold is decided the same way whatever the round-off of its sum
LOG_TOL = 1e-9

_PROB = {"maxwellian": pfrag.p_frag_maxwellian, "sigmoid": pfrag.p_frag_sigmoid,
         "linear": pfrag.p_frag_linear, "step": pfrag.p_frag_step}


def _p_frag(kind, dv2, v_frag, width):
    """Fragmenting fraction p_f(dv^2; v_frag) of :mod:`jaxcoag.physics.fragmentation`."""
    if kind in ("sigmoid", "linear"):
        return _PROB[kind](dv2, v_frag, width)
    return _PROB[kind](dv2, v_frag)


def _has_velocity(kernel) -> bool:
    from .kernels import AbstractKernel

    return type(kernel).relative_velocity2 is not AbstractKernel.relative_velocity2


def _bind_kernel(outcome, kernel):
    return eqx.tree_at(lambda o: o.kernel, outcome, kernel, is_leaf=lambda x: x is None)


class Products(NamedTuple):
    """Fixed-size list of Monte Carlo collision products (leading axis ``n_products``).

    Fields:
        m: product mass [g] (``logm`` is used where it exceeds float64).
        logm: natural log of the product mass [ln g].
        psi: structural parameters, shape (n_products, n_struct).
        count: number of such products per i-particle (>= 0; float64).
        valid: whether the entry is a real product.
    """

    m: jax.Array
    logm: jax.Array
    psi: jax.Array
    count: jax.Array
    valid: jax.Array


class AbstractOutcome(eqx.Module):
    """Collision outcome accepted by every engine (module docstring lists the hooks).

    Mass conservation is part of the contract: binned redistribution coefficients of every pair
    sum to zero, and Monte Carlo products satisfy sum(count m) = m_i + n_c m_j to rounding.
    """

    n_products: ClassVar[int] = 1
    needs_velocity: ClassVar[bool] = False

    def check(self, kernel, engine: str) -> None:
        """Refuse (JaxcoagInputError) a kernel or engine this outcome cannot run with, before any work.

        Arguments: kernel: the run's kernel; engine: "binned" or "mc".
        """
        if engine not in ("binned", "mc"):
            raise JaxcoagInputError(f"engine must be 'binned' or 'mc' (got {engine!r}).")
        if self.needs_velocity and not _has_velocity(kernel):
            raise JaxcoagTypeError(
                f"{type(self).__name__} needs collision velocities, but the {type(kernel).__name__} kernel has no "
                "relative velocity (analytic kernels). Use a physical kernel from a Scene "
                "(Scene(...).kernel(gas, rho_s=...)), or a velocity-free outcome such as ShatterAbove(m_frag, m_mono).")

    def bind(self, kernel) -> "AbstractOutcome":
        """The outcome the Monte Carlo event loop calls for ``kernel`` (default: itself)."""
        return self

    def probability(self, kernel, m_large, m_small):
        """Binned: fraction of collisions of m_large >= m_small [g] that do not simply stick [-]."""
        raise JaxcoagInputError(f"{type(self).__name__} has no binned-engine form.")

    def twobin_data(self, kernel, grid, iL, iS):
        """Binned: redistribution data on the two-bin pair list (iL >= iS)."""
        raise JaxcoagInputError(f"{type(self).__name__} has no binned-engine form.")

    @abc.abstractmethod
    def products(self, m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key) -> Products:
        """Monte Carlo: products of the i-particle (mass m_i [g], log mass, structure vector psi_i
        (n_struct,)) meeting n_c j-particles sequentially (n_c may be as large as 2^500, so it is also
        passed as log_nc); for an in-group collapse or a same-species pair the engine passes i = j,
        n_c = 1. Counts are per i-particle (the engine multiplies by the group multiplicity)."""


def _stick(m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc):
    """m_i + n_c m_j [g], its log, and the mass-weighted structure vector."""
    m_new = m_i + n_c * m_j
    logm_new = jnp.logaddexp(logm_i, log_nc + logm_j)
    logm_new = jnp.where(jnp.isfinite(m_new) & (m_new > 0), jnp.log(jnp.where(m_new > 0, m_new, 1.0)), logm_new)
    p_i = jnp.exp(logm_i - logm_new)
    p_j = jnp.exp(log_nc + logm_j - logm_new)
    return m_new, logm_new, p_i * psi_i + p_j * psi_j


def _stack_products(ms, xs, cnts, oks):
    dt = jnp.result_type(float)
    m = jnp.stack([jnp.asarray(v, dt) for v in ms])
    m_safe = jnp.where(m > 0, m, 1.0)
    return Products(m=m_safe, logm=jnp.log(m_safe), psi=jnp.stack(xs),
                    count=jnp.stack([jnp.asarray(c, dt) for c in cnts]), valid=jnp.stack(oks) & (m > 0))


# ---------------------------------------------------------------------------------------------
class Sticking(AbstractOutcome):
    """Perfect sticking (the default of every engine): one product of mass m_i + n_c m_j.

    Binned: pure coagulation (the engines treat ``Sticking()`` like ``outcome=None``). Monte
    Carlo: one product per i-particle with the mass-weighted structure vector.

    References: Smoluchowski (1916); Ormel (2008) thesis §5.2.2 (sequential accretion of n_c
    j-particles, m_new = m_i + n_c m_j).
    """

    def probability(self, kernel, m_large, m_small):
        """0: every collision sticks."""
        return jnp.zeros(jnp.broadcast_shapes(jnp.shape(m_large), jnp.shape(m_small)))

    def products(self, m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key) -> Products:
        """Sticking product of the i-particle with n_c j-particles (masses in g)."""
        m_new, logm_new, psi_new = _stick(m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc)
        return Products(m=m_new[None], logm=logm_new[None], psi=psi_new[None, :],
                        count=jnp.ones((1,)), valid=jnp.ones((1,), bool))


# ---------------------------------------------------------------------------------------------
class ShatterAbove(AbstractOutcome):
    """Catastrophic fragmentation into monomers above a mass threshold (thesis §5.3.4).

    A collision whose product mass m_1 + m_2 exceeds ``m_frag`` does not stick: its whole mass
    becomes monomers of mass ``m_mono``. "Exceeds" is decided to a relative LOG_TOL = 1e-9 (ln M >
    ln m_frag + 1e-9), so a product exactly at m_frag sticks in both engines whatever the round-off
    of the sum (e.g. 2 x 4 g on a grid whose centre 4 g is stored as 4.000000000000001).
    Velocity-free: works with analytic kernels. In the steady state f(m) ∝ m^-(3+beta)/2 below
    m_frag (m^-3/2 for the constant kernel).

    Arguments:
        m_frag: threshold mass [g] (> 0, float leaf).
        m_mono: monomer mass [g] (> 0, float leaf). Binned: the fragments go to the bin holding
            m_mono (clipped to the grid); Monte Carlo: count = M / m_mono monomers per i-particle,
            carrying the mass-weighted structure vector of the would-be product.

    References: Ormel (2008) thesis §5.3.4, Figs. 5.8-5.9 (Ormel & Spaans 2008, ApJ 684, 1291).
    """

    m_frag: jax.Array
    m_mono: jax.Array

    def __init__(self, m_frag, m_mono):
        self.m_frag = check(m_frag, "m_frag", positive=True, hint="mass threshold in g above which products shatter")
        self.m_mono = check(m_mono, "m_mono", positive=True, hint="monomer mass in g (the fragments)")

    def _shatters(self, log_m_tot):
        return log_m_tot > jnp.log(self.m_frag) + LOG_TOL

    def probability(self, kernel, m_large, m_small):
        """1 where ln(m_large + m_small) > ln m_frag + LOG_TOL, else 0 (hard threshold)."""
        m_large, m_small = jnp.asarray(m_large), jnp.asarray(m_small)
        return jnp.where(self._shatters(jnp.log(m_large + m_small)), 1.0, 0.0)

    def twobin_data(self, kernel, grid, iL, iS):
        """FragData: -m_S at S, -m_L at L, ejecta m_L + m_S into the bin holding m_mono."""
        from .binned.redistribution import FragData, fragment_weights

        N = grid.nbins
        lc = grid.log_centers
        mL, mS = np.exp(lc[iL]), np.exp(lc[iS])
        idx = np.stack([iS, iL, iL, iL], axis=1).astype(np.int32)
        coef = np.stack([-mS, -mL, np.zeros_like(mL), np.zeros_like(mL)], axis=1)
        w0 = fragment_weights(grid.log_edges, -2.0, self.m_mono, self.m_mono)   # one-hot: the monomer bin
        W = jnp.broadcast_to(w0, (N, N))
        p = self.probability(kernel, jnp.exp(jnp.asarray(lc[iL])), jnp.exp(jnp.asarray(lc[iS])))
        return FragData(p=p, coef=jnp.asarray(coef), idx=idx, ejecta=jnp.asarray(mL + mS),
                        src=np.zeros(iL.size, np.int32), W=W)

    def products(self, m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key) -> Products:
        """Sticking product, or M/m_mono monomers when M = m_i + n_c m_j exceeds m_frag (masses in g)."""
        m_new, logm_new, psi_new = _stick(m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc)
        frag = self._shatters(logm_new)
        log_mono = jnp.log(self.m_mono)
        m_out = jnp.where(frag, self.m_mono, m_new)
        logm_out = jnp.where(frag, log_mono, logm_new)
        count = jnp.where(frag, jnp.exp(logm_new - log_mono), 1.0)
        count = jnp.where(frag & jnp.isfinite(m_new), m_new / self.m_mono, count)
        return Products(m=m_out[None], logm=logm_out[None], psi=psi_new[None, :],
                        count=count[None], valid=jnp.ones((1,), bool))


# ---------------------------------------------------------------------------------------------
class Shattering(AbstractOutcome):
    """Velocity-dependent shattering and erosion (Brauer et al. 2008; Birnstiel et al. 2010; DustPy).

    A fraction p_f(dv^2; v_frag) of the collisions of m_L >= m_S fragments (the rest stick):

    * complete shattering (m_L/m_S < ``crater_ratio``): both bodies are destroyed; the mass
      m_L + m_S becomes fragments n(m) dm ∝ m^-q dm (q = 11/6, Dohnanyi) from m_lo up to m_L;
    * erosion/cratering (m_L/m_S >= ``crater_ratio``, default 10; a pair at exactly the ratio
      erodes, decided to the relative LOG_TOL = 1e-9 so that pairs whose grid centres lie exactly
      crater_ratio apart all erode): the projectile excavates ``chi`` times its own mass from the
      target; the ejecta (1 + chi) m_S become fragments from m_lo up to m_S, the remnant
      m_L - chi m_S keeps the target's structure. Equal masses never erode.

    Binned: fragments from the grid bottom (``m_lo=None``) or m_lo up to the upper edge of the
    larger body's (shattering) or the projectile's (erosion) bin, the remnant by the two-bin split
    (DustPy's scheme). Monte Carlo (needs ``m_lo``): a single collision (n_c = 1) fragments with
    probability p_f (drawn); in a group event (n_c > 1 j-particles, all much lighter than the
    i-particle by the engine's f_eps bound) the expected number n_c p_f of the collisions erode
    the i-particle, or, when the pair is below crater_ratio, the whole group event shatters with
    probability 1 - (1 - p_f)^n_c (at most one breakage per group event, thesis eq. 6.27)
    [CHOICE]; fragments are drawn mass-exactly (:func:`~jaxcoag.physics.outcome.sample_fragment_masses`)
    into ``n_frag`` product species and carry the mass-weighted structure of the two bodies.

    Arguments:
        v_frag: fragmentation threshold velocity [cm s^-1] (leaf, > 0).
        q: fragment number-distribution exponent, n(m) dm ∝ m^-q dm (leaf; 11/6 default).
        probability: "maxwellian" (default) | "sigmoid" | "linear" | "step" (static).
        width: transition width of "sigmoid" (ln units, 0.1) / "linear" (fraction of v_frag, 0.2).
        crater_ratio: mass ratio at and above which collisions erode (static, > 1, default 10).
        chi: eroded target mass in units of the projectile mass (static, in (0, crater_ratio - 1)).
        m_lo: lowest fragment mass [g] (leaf; None = the grid bottom, binned only).
        n_frag: Monte Carlo fragment product species (static int >= 1, default 4).

    References: Brauer, Dullemond & Henning (2008) §2.3; Birnstiel, Dullemond & Brauer (2010)
    eq. 15; Stammler & Birnstiel (2022, DustPy) §2.2 (erosion with chi = 1, mass ratio 10);
    Ormel (2008) thesis eqs. 6.27-6.30 (group events, fragment sampling).
    """

    v_frag: jax.Array
    q: jax.Array
    width: jax.Array
    m_lo: Any
    probability_kind: str = eqx.field(static=True)
    crater_ratio: float = eqx.field(static=True)
    chi: float = eqx.field(static=True)
    n_frag: int = eqx.field(static=True)
    kernel: Any = None
    needs_velocity: ClassVar[bool] = True

    def __init__(self, v_frag, q=11.0 / 6.0, probability="maxwellian", width=None, crater_ratio=10.0, chi=1.0,
                 m_lo=None, n_frag=4, kernel=None):
        self.v_frag = check(v_frag, "v_frag", positive=True, hint="fragmentation velocity in cm/s, e.g. 100.")
        self.q = check(q, "q", hint="fragment exponent n(m) ~ m^-q, typically 11/6")
        if probability not in _PROB:
            raise JaxcoagInputError(f"probability must be one of {sorted(_PROB)} (got {probability!r}).")
        self.probability_kind = probability
        w = {"sigmoid": 0.1, "linear": 0.2}.get(probability, 0.0) if width is None else width
        self.width = check(w, "width", nonnegative=True)
        if not (float(crater_ratio) > 1.0):
            raise JaxcoagInputError("crater_ratio must be > 1 (mass ratio above which collisions erode).")
        if not (0.0 < float(chi) < float(crater_ratio) - 1.0):
            raise JaxcoagInputError("chi must lie in (0, crater_ratio - 1) so that the eroded remnant stays positive.")
        self.crater_ratio = float(crater_ratio)
        self.chi = float(chi)
        self.m_lo = None if m_lo is None else check(m_lo, "m_lo", positive=True, hint="lowest fragment mass in g")
        if isinstance(n_frag, bool) or not isinstance(n_frag, (int, np.integer)) or n_frag < 1:
            raise JaxcoagInputError(f"n_frag must be an int >= 1 (Monte Carlo fragment species); got {n_frag!r}.")
        self.n_frag = int(n_frag)
        self.kernel = kernel

    @property
    def n_products(self) -> int:  # type: ignore[override]
        return 1 + self.n_frag

    def check(self, kernel, engine: str) -> None:
        super().check(kernel, engine)
        if engine == "mc" and self.m_lo is None:
            raise JaxcoagInputError("Shattering in the Monte Carlo engine needs m_lo (the lowest fragment mass in g, "
                                    "e.g. the monomer mass); the binned engine defaults to the grid bottom.")

    def bind(self, kernel) -> "Shattering":
        return _bind_kernel(self, kernel)

    def _pf(self, dv2):
        return _p_frag(self.probability_kind, dv2, self.v_frag, self.width)

    def probability(self, kernel, m_large, m_small):
        """p_f(dv^2(m_large, m_small); v_frag) with dv^2 = ``kernel.relative_velocity2``."""
        return self._pf(kernel.relative_velocity2(m_large, m_small))

    def twobin_data(self, kernel, grid, iL, iS):
        """FragData: shattering (ratio < crater_ratio) / erosion (ratio >= crater_ratio, to LOG_TOL)."""
        from .binned.redistribution import FragData, fragment_weights, place_remnant_np, powerlaw_weights

        lc = grid.log_centers
        mL, mS = np.exp(lc[iL]), np.exp(lc[iS])
        crater = (iL > iS) & ((lc[iL] - lc[iS]) >= np.log(self.crater_ratio) - LOG_TOL)
        # shattering rows: -m_S at S, -m_L at L; ejecta m_L + m_S from source L
        # erosion rows: -m_S at S, remnant placement at (L, k, k+1); ejecta (1+chi) m_S from source S
        chi_mS = self.chi * mS
        mr_log = lc[iL] + np.log1p(-np.where(crater, chi_mS / mL, 0.0))
        ridx, rcoef = place_remnant_np(grid, iL, mr_log, chi_mS)
        idx = np.zeros((iL.size, 4), np.int32)
        coef = np.zeros((iL.size, 4))
        idx[:, 0] = iS
        coef[:, 0] = -mS
        idx[:, 1] = np.where(crater, ridx[:, 0], iL)
        coef[:, 1] = np.where(crater, rcoef[:, 0], -mL)
        idx[:, 2] = np.where(crater, ridx[:, 1], iL)
        coef[:, 2] = np.where(crater, rcoef[:, 1], 0.0)
        idx[:, 3] = np.where(crater, ridx[:, 2], iL)
        coef[:, 3] = np.where(crater, rcoef[:, 2], 0.0)
        ejecta = np.where(crater, (1.0 + self.chi) * mS, mL + mS)
        src = np.where(crater, iS, iL).astype(np.int32)
        p = self.probability(kernel, jnp.exp(jnp.asarray(lc[iL])), jnp.exp(jnp.asarray(lc[iS])))
        if self.m_lo is None:
            W = powerlaw_weights(grid, self.q)
        else:  # the same power law from m_lo to the upper edge of each source bin
            W = fragment_weights(grid.log_edges, -self.q, jnp.broadcast_to(self.m_lo, (grid.nbins,)),
                                 jnp.exp(jnp.asarray(grid.log_edges[1:])))
        return FragData(p=p, coef=jnp.asarray(coef), idx=idx, ejecta=jnp.asarray(ejecta), src=src, W=W)

    def products(self, m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key) -> Products:
        """Sticking, erosion or shattering of the i-particle with n_c j-particles (class docstring)."""
        dt = jnp.result_type(float)
        ku, kf = jax.random.split(key)
        u = jax.random.uniform(ku, (), dtype=dt)
        x_i, x_j = psi_i, psi_j
        dv2 = self.kernel.relative_velocity2(m_i, m_j, x_i, x_j)
        pf = jnp.clip(self._pf(dv2), 0.0, 1.0)
        one = n_c <= 1.0
        i_large = logm_i >= logm_j
        l_big, l_small = jnp.maximum(logm_i, logm_j), jnp.minimum(logm_i, logm_j)
        crater = (l_big > l_small) & (l_big - l_small >= np.log(self.crater_ratio) - LOG_TOL)
        m_new, logm_new, x_mix = _stick(m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc)
        # shattering: everything into fragments up to the larger mass (drawn; group: at least one breakage)
        P_sh = jnp.where(one, pf, -jnp.expm1(n_c * jnp.log1p(-jnp.minimum(pf, 1.0 - 1e-16))))
        shatter = (~crater) & (u < P_sh)
        # erosion: n_f collisions each remove chi m_S from the target and eject (1 + chi) m_S
        n_f = jnp.where(crater, jnp.where(one, jnp.where(u < pf, 1.0, 0.0), n_c * pf), 0.0)
        m_S = jnp.exp(l_small)
        m_ej = n_f * (1.0 + self.chi) * jnp.where(one, m_S, m_j)
        M_rem = jnp.where(shatter, 0.0, jnp.maximum(m_new - m_ej, 0.0))
        M_frag = jnp.where(shatter, m_new, m_new - M_rem)
        m_hi = jnp.where(shatter, jnp.exp(l_big), jnp.where(one, m_S, m_j))
        m_hi = jnp.maximum(m_hi, self.m_lo)
        # structure: remnant of an erosion keeps the target's; sticking and fragments the mixture
        x_target = jnp.where(one & ~i_large, x_j, x_i)
        x_rem = jnp.where(n_f > 0, x_target, x_mix)
        fm, mult = sample_fragment_masses(kf, -self.q, self.m_lo, m_hi, M_frag, self.n_frag)
        ms, xs, cnts, oks = [M_rem], [x_rem], [jnp.ones((), dt)], [M_rem > 0]
        for k in range(self.n_frag):
            ms.append(fm[k])
            xs.append(x_mix)
            cnts.append(mult[k])
            oks.append((mult[k] > 0) & (fm[k] > 0))
        return _stack_products(ms, xs, cnts, oks)


# ---------------------------------------------------------------------------------------------
# shared-physics recipes: (m1, psi1, m2, psi2, dv, material, width) -> Outcome
class AbstractRecipe(eqx.Module):
    """A collision recipe returning the shared :class:`~jaxcoag.physics.outcome.Outcome`.

    ``__call__(m1, psi1, m2, psi2, dv, material, width=0.0) -> Outcome``: masses [g] (binned:
    m1 >= m2), enlargement factors psi [-] (binned: 1, compact), relative velocity dv [cm s^-1],
    a :class:`~jaxcoag.physics.contact.Material`, and the static regime-switch width (e-folds;
    0 = the sources' hard switches). ``weight(...)``: None, or the mixture weight w (a fraction
    1 - w of the collisions sticks perfectly, w follows the Outcome). ``fragments`` /
    ``two_remnants`` tell the Monte Carlo engine which product slots the recipe can fill.
    Float fields are differentiable leaves.

    References: collision-outcome interface in docs/design_notes.md.
    """

    needs_velocity: ClassVar[bool] = True

    @abc.abstractmethod
    def __call__(self, m1, psi1, m2, psi2, dv, material, width=0.0) -> Outcome:
        """The Outcome of the pair (broadcast over any pair grid)."""

    def weight(self, m1, psi1, m2, psi2, dv, material, width=0.0):
        """Mixture weight in [0, 1], or None (every collision follows the Outcome)."""
        return None

    @property
    def fragments(self) -> bool:
        """Whether the recipe can put mass into small fragments (f_pwl > 0)."""
        return True

    @property
    def two_remnants(self) -> bool:
        """Whether the recipe can produce two large remnants or misses (p_two > 0 or eff < 1)."""
        return True


class O07Recipe(AbstractRecipe):
    """Thesis ch. 2 recipe (O07): hit-and-stick / compaction of psi, optional threshold
    fragmentation and bounce (:func:`jaxcoag.physics.ormel07.o07_outcome`).

    Fields: frag_model (None = no fragmentation, as in ch. 2; ``DTEnergy()``: erosion from
    3 N E_br, catastrophic at 10 N E_br, fragments dn/dm ∝ m^-2 on [m0, M_tot/4]); bounce_model
    (None, or ``BounceWhenCompact``: [CHOICE] not from the sources); restr_factor (1 = ch. 2,
    5 = Dominik & Tielens); delta (0.95), B (1), mF_over_m0 (10), psi_min (1): hit-and-stick and
    compaction constants; n_small (None, or e.g. 40: products of at most n_small monomers use the
    pure fractal law B = 0 [CHOICE], erratum 20 — the thesis takes psi from Ossenkopf's tables
    there, which are not available; decided to a relative 1e-9 so that a product of exactly
    n_small monomers counts whatever the round-off of its mass).

    References: Ormel, Spaans & Tielens 2007; Ormel 2008 thesis §2.2.3, eqs. 2.9-2.19,
    Tab. 1.1; Dominik & Tielens 1997; Wada et al. 2007 §5.5; erratum 20 in docs/design_notes.md.
    """

    frag_model: AbstractFragModel | None = None
    bounce_model: Any = None
    restr_factor: jax.Array = eqx.field(default=1.0, converter=jnp.asarray)
    delta: jax.Array = eqx.field(default=DELTA_CCA, converter=jnp.asarray)
    B: jax.Array = eqx.field(default=1.0, converter=jnp.asarray)
    mF_over_m0: jax.Array = eqx.field(default=10.0, converter=jnp.asarray)
    psi_min: jax.Array = eqx.field(default=1.0, converter=jnp.asarray)
    n_small: Any = None

    def __check_init__(self):
        if self.frag_model is not None and not isinstance(self.frag_model, AbstractFragModel):
            raise JaxcoagInputError("O07Recipe(frag_model=...) must be None or a jaxcoag.physics.dominik_tielens "
                                    "fragmentation model, e.g. DTEnergy().")

    @property
    def fragments(self) -> bool:
        return self.frag_model is not None

    @property
    def two_remnants(self) -> bool:
        return self.bounce_model is not None

    def __call__(self, m1, psi1, m2, psi2, dv, material, width=0.0):
        B = self.B
        if self.n_small is not None:
            small = (m1 + m2) / material.m0 <= self.n_small * (1.0 + LOG_TOL)
            B = jnp.where(small, 0.0, B)
        return o07_outcome(m1, psi1, m2, psi2, dv, material, delta=self.delta, B=B, mF_over_m0=self.mF_over_m0,
                           restr_factor=self.restr_factor, psi_min=self.psi_min, frag_model=self.frag_model,
                           bounce_model=self.bounce_model, width=width, validate=False)


class O09Recipe(AbstractRecipe):
    """Thesis ch. 6 tabulated recipe (O09, expected mode; :func:`jaxcoag.physics.recipes.o09_outcome`).

    Fields: tables (RecipeTables; ``RecipeTables.surrogate()`` when the CDS set is absent: label
    results as surrogate), b_frac (None = average over p(b) ∝ b), kappa_glob (3).
    References: Ormel 2008 thesis §6.3-6.5 (Ormel et al. 2009).
    """

    tables: RecipeTables = eqx.field(default_factory=RecipeTables.surrogate)
    b_frac: Any = None
    kappa_glob: jax.Array = eqx.field(default=3.0, converter=jnp.asarray)

    def __call__(self, m1, psi1, m2, psi2, dv, material, width=0.0):
        return o09_outcome(m1, psi1, m2, psi2, dv, self.tables, material, b_frac=self.b_frac,
                           kappa_glob=self.kappa_glob, width=width, validate=False)

    @property
    def is_surrogate(self) -> bool:
        return bool(self.tables.is_surrogate)


class VfragShatter(AbstractRecipe):
    """Velocity-threshold shattering as a shared-physics recipe (Birnstiel et al. 2010): a fraction
    p_f(dv; v_frag) of the collisions (mixture weight) shatters completely into dn/dm ∝ m^-q on
    [m_lo, m_hi_factor max(m1, m2)] (q = 11/6, Dohnanyi); the rest stick.

    Fields: v_frag [cm s^-1], q [-] (number exponent, positive), m_lo [g] (None = material m0),
    m_hi_factor [-], probability (static: "maxwellian" | "sigmoid" | "linear" | "step"), p_width
    (sigmoid/linear width).
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

    @property
    def two_remnants(self) -> bool:
        return False

    def weight(self, m1, psi1, m2, psi2, dv, material, width=0.0):
        """Fraction of collisions that shatter, p_f(dv^2; v_frag) [-]."""
        return _p_frag(self.probability, dv ** 2, self.v_frag, self.p_width)

    def __call__(self, m1, psi1, m2, psi2, dv, material, width=0.0):
        m_lo = material.m0 if self.m_lo is None else self.m_lo
        return Outcome.build(f_pwl=1.0, q=-self.q, m_lo=m_lo, m_hi=self.m_hi_factor * jnp.maximum(m1, m2),
                             psi_one=jnp.ones_like(m1))


def _log1p_neg_pow(n, f):
    """(r^n, (1 - r^n)/(1 - r)) for r = 1 - f, n >= 1 real, 0 <= f <= 1, stable at f -> 0."""
    lr = jnp.log1p(-jnp.minimum(f, 1.0))
    rn = jnp.exp(n * lr)
    small = f < 1e-12
    f_safe = jnp.where(small, 1.0, f)
    geo = jnp.where(small, n * (1.0 - 0.5 * (n - 1.0) * f), -jnp.expm1(n * lr) / f_safe)
    return rn, geo


class RecipeOutcome(AbstractOutcome):
    """Any shared-physics recipe (:class:`AbstractRecipe`) as a collision outcome of both engines.

    Binned (compact particles, psi = 1): the recipe is evaluated once per run on the bin-centre
    pairs (i >= j) with dv = sqrt(``kernel.relative_velocity2``) and turned into a mass-exact
    redistribution (:class:`~jaxcoag.binned.redistribution.OutcomeData`):
    P_ij(m) = (1 - p_two) delta(m - M_L) + p_two [delta(m - s M_L) + delta(m - (1 - s) M_L)]
    + f_pwl M_tot g(m), M_L = (1 - f_pwl) M_tot, g ∝ m^q on [m_lo, m_hi], kernel times eff; with a
    mixture weight w the fraction 1 - w sticks (two-bin coagulation tensors). Gradients with
    respect to the recipe's and material's leaves flow through the solve (non-zero with width > 0).

    Monte Carlo (psi = the structural parameter ``index`` of the kernel, 1 without one): for the
    pair (i, j), dv = sqrt(kernel.relative_velocity2(m_i, m_j, x_i, x_j)) (the velocity field
    that sets the rate), ``out = recipe(m_i, psi_i, m_j, psi_j, dv, material, width)``; a mixture
    weight is drawn for n_c = 1 and applied in expected mode (f_pwl, p_two, 1 - eff times w) for
    group events. Group events (n_c > 1, thesis App. 5.B step 5) [own reading]: the recipe is
    evaluated ONCE for the physical single pair (the regime is decided by the single-collision
    energy), and the n_c sequential accretions are compounded in closed form with the
    per-collision change held fixed (first order in n_c m_j/m_i, bounded by f_eps):

    * mass: a constant fragment fraction f per collision leaves M_L = r^n m_i + r m_j (1-r^n)/(1-r),
      r = 1 - f (exact for f = 0: M_L = m_i + n_c m_j); the rest is fragments;
    * psi: with g = n_c (m_i + m_j)/(m_i + n_c m_j), psi = psi_i + g (psi_one - psi_i) when the
      collision increases psi, and psi - 1 = (psi_i - 1)((psi_one - 1)/(psi_i - 1))^g when it
      compacts (eq. 2.17 compounded n_c times). Both equal psi_one for n_c = 1; psi >= 1;
    * two remnants: at most one two-remnant event per group event, with probability
      1 - (1 - p_two)^n_c (eq. 6.27); misses: n_c (1 - eff) j-particles (the expected number) are
      returned unchanged.

    Fragments: the mass f_pwl M_tot is drawn from dn/dm ∝ m^q on [m_lo, m_hi] (mass-exact, eq.
    6.29) into ``n_frag`` product species with psi = psi_fragment(m/m0, c_f).

    Arguments:
        recipe: an :class:`AbstractRecipe` (:class:`O07Recipe`, :class:`O09Recipe`,
            :class:`VfragShatter`) or a callable with the same signature.
        material: :class:`~jaxcoag.physics.contact.Material` (m0, E_roll, E_br; leaves).
        width: static regime-switch width in e-folds of energy (0 = hard switches).
        use_velocity: static; default the recipe's ``needs_velocity`` (False: dv = 0, analytic
            kernels work).
        remnants: Monte Carlo large-remnant slots, 1 or 2 (default: 2 if the recipe has
            ``two_remnants``, else 1; 1 refuses such a recipe).
        n_frag: Monte Carlo fragment species (default: 4 if the recipe ``fragments``, else 0;
            0 refuses such a recipe). ``n_products = remnants + n_frag``.
        index: static, position of psi in the structure vector (default 0).
        c_f: prefactor of the fragments' psi(N) law (1, [CHOICE], erratum 18).

    References: Ormel (2008) thesis §2.2.3, §6.5 (eqs. 6.25-6.30), App. 5.B step 5; Birnstiel,
    Dullemond & Brauer (2010) eq. 15; Brauer et al. (2008) App. A; errata 5, 6, 18, 20 in
    docs/design_notes.md.
    """

    recipe: Callable
    material: Material
    c_f: jax.Array
    width: float = eqx.field(static=True)
    use_velocity: bool = eqx.field(static=True)
    remnants: int = eqx.field(static=True)
    n_frag: int = eqx.field(static=True)
    index: int = eqx.field(static=True)
    kernel: Any = None

    def __init__(self, recipe, material, *, width=0.0, use_velocity=None, remnants=None, n_frag=None, index=0,
                 c_f=1.0, kernel=None):
        if not callable(recipe):
            raise JaxcoagInputError("recipe must be a collision recipe (m1, psi1, m2, psi2, dv, material, width) -> "
                                    "Outcome, e.g. jaxcoag.O07Recipe() or jaxcoag.O09Recipe().")
        if not isinstance(material, Material):
            raise JaxcoagInputError("material must be a jaxcoag.physics.contact.Material, e.g. Material.ch6_ice() "
                                    "(it supplies m0, E_roll and E_break).")
        if not float(width) >= 0.0:
            raise JaxcoagInputError(f"width must be >= 0 e-folds (got {width}); 0 = hard switches.")
        frag = bool(getattr(recipe, "fragments", True))
        two = bool(getattr(recipe, "two_remnants", True))
        if remnants is None:
            remnants = 2 if two else 1
        if remnants not in (1, 2):
            raise JaxcoagInputError(f"remnants must be 1 or 2 (Monte Carlo slots for large remnants); got {remnants!r}")
        if remnants == 1 and two:
            raise JaxcoagInputError(f"{type(recipe).__name__} can bounce or miss (two large remnants): use remnants=2 "
                                    "(or leave the default).")
        if n_frag is None:
            n_frag = 4 if frag else 0
        if isinstance(n_frag, bool) or not isinstance(n_frag, (int, np.integer)) or n_frag < 0:
            raise JaxcoagInputError(f"n_frag must be a non-negative int (fragment product species); got {n_frag!r}")
        if n_frag == 0 and frag:
            raise JaxcoagInputError(f"{type(recipe).__name__} produces fragments: use n_frag >= 1 (Monte Carlo "
                                    "fragment species, default 4).")
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or index < 0:
            raise JaxcoagInputError(f"index must be a non-negative int (position of psi in x); got {index!r}")
        self.recipe = recipe
        self.material = material
        self.width = float(width)
        self.use_velocity = bool(getattr(recipe, "needs_velocity", True) if use_velocity is None else use_velocity)
        self.remnants = int(remnants)
        self.n_frag = int(n_frag)
        self.index = int(index)
        self.c_f = check(c_f, "c_f", positive=True, hint="fragment psi(N) prefactor, 1 by default")
        self.kernel = kernel

    @property
    def needs_velocity(self) -> bool:  # type: ignore[override]
        return self.use_velocity

    @property
    def n_products(self) -> int:  # type: ignore[override]
        return self.remnants + self.n_frag

    def bind(self, kernel) -> "RecipeOutcome":
        return _bind_kernel(self, kernel)

    # ---------------------------------------------------------------- binned
    def _pairs(self, kernel, mL, mS):
        one = jnp.ones_like(mL)
        dv = safe_sqrt(kernel.relative_velocity2(mL, mS)) if self.use_velocity else jnp.zeros_like(mL)
        out = self.recipe(mL, one, mS, one, dv, self.material, self.width)
        if not isinstance(out, Outcome):
            raise JaxcoagInputError(f"the recipe must return a jaxcoag Outcome, got {type(out).__name__}.")
        w = self.recipe.weight(mL, one, mS, one, dv, self.material, self.width) if hasattr(self.recipe, "weight") \
            else None
        return out, w

    def evaluate(self, kernel, m_large, m_small):
        """(Outcome, mixture weight) of compact masses m_large >= m_small [g] (diagnostics)."""
        out, w = self._pairs(kernel, jnp.asarray(m_large), jnp.asarray(m_small))
        return out, (jnp.ones_like(out.eff) if w is None else w)

    def probability(self, kernel, m_large, m_small):
        """Fraction of collisions that do not simply stick: w [1 - (1 - f_pwl)(1 - p_two)] [-]."""
        out, w = self.evaluate(kernel, m_large, m_small)
        return w * (1.0 - (1.0 - out.f_pwl) * (1.0 - out.p_two))

    def twobin_data(self, kernel, grid, iL, iS):
        """OutcomeData on the two-bin pair list (iL >= iS)."""
        from .binned.redistribution import OutcomeData, fragment_weights, place_remnant
        from .binned.twobin import _ext_log_centers

        lce = jnp.asarray(_ext_log_centers(grid))
        iLj, iSj = jnp.asarray(iL), jnp.asarray(iS)
        lL, lS = lce[iLj], lce[iSj]
        mL, mS = jnp.exp(lL), jnp.exp(lS)
        out, w = self._pairs(kernel, mL, mS)
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
        return OutcomeData(p=p, eff=jnp.clip(out.eff, 0.0, 1.0), coef=coef, idx=idx, m_pwl=f * M_tot, W=W, full=full)

    # ---------------------------------------------------------------- Monte Carlo
    def products(self, m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key) -> Products:
        """Products of the i-particle meeting n_c j-particles (masses in g, structure vectors (P,))."""
        k = self.index
        dt = jnp.result_type(float)
        x_i, x_j = psi_i, psi_j
        has_psi = x_i.shape[-1] > k
        ps_i = x_i[k] if has_psi else jnp.ones((), dt)
        ps_j = x_j[k] if has_psi else jnp.ones((), dt)
        if self.use_velocity:
            dv = safe_sqrt(self.kernel.relative_velocity2(m_i, m_j, x_i, x_j))
        else:
            dv = jnp.zeros((), dt)
        out: Outcome = self.recipe(m_i, ps_i, m_j, ps_j, dv, self.material, self.width)
        w = self.recipe.weight(m_i, ps_i, m_j, ps_j, dv, self.material, self.width) \
            if hasattr(self.recipe, "weight") else None
        ku, kf = jax.random.split(key)
        u = jax.random.uniform(ku, (2,), dtype=dt)
        one = n_c <= 1.0
        eff = jnp.clip(out.eff, 0.0, 1.0)
        p2 = jnp.clip(out.p_two, 0.0, 1.0)
        f = jnp.clip(out.f_pwl, 0.0, 1.0) if self.n_frag > 0 else jnp.zeros((), dt)
        psi_one = out.psi_one
        if w is not None:  # mixture: 1 - w sticks (drawn for one collision, expected mode in a group)
            w = jnp.clip(w, 0.0, 1.0)
            u_w = jax.random.uniform(jax.random.fold_in(ku, 1), (), dtype=dt)
            follow = jnp.where(one, jnp.where(u_w < w, 1.0, 0.0), w)
            M_st = m_i + m_j
            psi_st = (m_i * ps_i + m_j * ps_j) / M_st
            psi_one = follow * psi_one + (1.0 - follow) * psi_st
            eff, p2, f = 1.0 - follow * (1.0 - eff), follow * p2, follow * f

        # misses and two-remnant events (remnants = 2 only): n_c = 1 -> drawn; n_c > 1 -> the
        # expected number of hits n_c eff, and at most one two-remnant event (probability
        # 1 - (1 - p_two)^(n_c eff), eq. 6.27), in which all n_c j-particles take part [CHOICE]
        if self.remnants == 2:
            n_exp = jnp.where(one, jnp.where(u[0] < eff, 1.0, 0.0), n_c * eff)
            P2 = jnp.where(one, p2, -jnp.expm1(n_exp * jnp.log1p(-jnp.minimum(p2, 1.0 - 1e-16))))
            two = (n_exp > 0) & (u[1] < P2)
            n_hit = jnp.where(two, n_c, n_exp)
        else:
            n_hit = n_c
            two = jnp.zeros((), bool)
        n_miss = n_c - n_hit
        hit = n_hit > 0
        n_eff = jnp.where(hit, n_hit, 1.0)

        # large remnant after n_hit sequential collisions with constant fragment fraction f
        rn, geo = _log1p_neg_pow(n_eff, f)
        M_L = rn * m_i + (1.0 - f) * m_j * geo
        M_tot = m_i + n_hit * m_j
        M_pwl = jnp.where(hit, jnp.maximum(M_tot - M_L, 0.0), 0.0)
        M_L = M_tot - M_pwl

        # psi of the large remnant (closed-form compounding, see class docstring)
        g = n_eff * (m_i + m_j) / (m_i + n_eff * m_j)
        e_i = jnp.maximum(ps_i - 1.0, 0.0)
        e_one = jnp.maximum(psi_one - 1.0, 0.0)
        grow = psi_one >= ps_i
        lin = ps_i + g * (psi_one - ps_i)
        ratio = jnp.where(e_i > 0, e_one / jnp.where(e_i > 0, e_i, 1.0), 0.0)
        comp = 1.0 + e_i * jnp.where(ratio > 0, jnp.exp(g * jnp.log(jnp.where(ratio > 0, ratio, 1.0))), 0.0)
        psi_L = jnp.where(n_eff <= 1.0, psi_one, jnp.where(grow, lin, comp))
        psi_L = jnp.maximum(psi_L, 1.0)

        # other structural columns (if any): mass-weighted mix of i and the accreted j's
        wi = m_i / M_tot
        x_mix = wi * x_i + (1.0 - wi) * x_j

        def vec(p):
            return x_mix.at[k].set(p) if has_psi else x_mix

        if self.remnants == 2:
            sp = jnp.clip(out.split, 0.0, 1.0)
            # slot a: the (first) large remnant, or the unchanged i-particle on a miss
            m_a = jnp.where(hit, jnp.where(two, sp * M_L, M_L), m_i)
            x_a = jnp.where(hit, vec(jnp.maximum(jnp.where(two, out.psi_a, psi_L), 1.0)), x_i)
            # slot b: the second remnant, or the missed j-particles (count n_miss)
            m_b = jnp.where(two, (1.0 - sp) * M_L, m_j)
            x_b = jnp.where(two, vec(jnp.maximum(out.psi_b, 1.0)), x_j)
            ms, xs = [m_a, m_b], [x_a, x_b]
            cnts = [jnp.ones((), dt), jnp.where(two, 1.0, n_miss)]
            oks = [m_a > 0, jnp.where(two, m_b > 0, n_miss > 0)]
        else:
            ms, xs, cnts, oks = [M_L], [vec(psi_L)], [jnp.ones((), dt)], [M_L > 0]

        if self.n_frag > 0:
            fm, mult = sample_fragment_masses(kf, out.q, out.m_lo, jnp.maximum(out.m_hi, out.m_lo), M_pwl, self.n_frag)
            psi_fr = psi_fragment(fm / self.material.m0, self.c_f)
            for q in range(self.n_frag):
                ms.append(fm[q])
                xs.append(vec(psi_fr[q]))
                cnts.append(mult[q])
                oks.append((mult[q] > 0) & (fm[q] > 0))
        return _stack_products(ms, xs, cnts, oks)
