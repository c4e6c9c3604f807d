"""Mass-conserving fragmentation outcomes for the binned engine.

A fragmentation model is an ``eqx.Module``: which recipe (class, static options) is structure,
the numbers (``v_frag``, ``q``, ``m_frag``) are float leaves, so d(outcome)/d(v_frag) works.
For every unordered bin pair (i >= j; i the larger body "L", j the projectile "S") the model
gives the fraction p_f of collisions that fragment instead of sticking; the two-bin scheme
uses (1 - p_f) for coagulation and p_f for the outcome below.

Recipes (``Shattering``):

* complete shattering (m_L/m_S < ``crater_ratio``): both bodies are destroyed; the mass
  m_L + m_S is redistributed as a power law n(m) dm ~ m^-q dm (q = 11/6 default, Dohnanyi)
  from the bottom of the grid up to the upper edge of the larger body's bin, i.e. bin b <= L
  receives the fraction int_b m^{1-q} dm / int_{m_min}^{m_L,hi} m^{1-q} dm.
* erosion/cratering (m_L/m_S >= ``crater_ratio``, default 10; a pair at exactly the ratio
  erodes, decided with the grid tolerance :data:`~jaxcoag.binned.grid.LOG_TOL`, see
  :class:`Shattering`): the projectile excavates
  ``chi`` times its own mass (default 1) from the target; the ejecta (1 + chi) m_S are
  redistributed as the power law up to the projectile's bin, the remnant m_L - chi m_S is
  placed by the two-bin split between its neighbouring bins (merged with the loss of L when
  it lands in [m_{L-1}, m_L], avoiding cancellation).

Probability p_f(dv^2; v_frag) from :mod:`jaxcoag.physics.fragmentation` ("maxwellian"
default, "sigmoid", "linear", "step"), with dv^2 = ``kernel.relative_velocity2`` on the bin
centers (physical kernels only).

``ShatterToMonomers(m_frag)``: the thesis §5.3.4 test - a collision whose product would exceed
m_frag is catastrophically disrupted into monomers (all its mass goes to the lowest bin). No
velocity needed: works with analytic kernels.

Every recipe conserves mass exactly in the coefficients (rows sum to 0 and fragment weights
sum to 1), so sum(rho) + gel is conserved to round-off.

References: Brauer, Dullemond & Henning (2008) §2.3 (shattering, cratering, q = 11/6);
Birnstiel, Dullemond & Brauer (2010) §3; Stammler & Birnstiel (2022, DustPy) §2.2 (erosion with
chi = 1, mass ratio 10); Ormel (2008) thesis §5.3.4 (shatter into monomers above m_frag).
"""

from __future__ import annotations

import abc
from typing import ClassVar

import numpy as np
import equinox as eqx
import jax
import jax.numpy as jnp

from .._validate import JaxcoagInputError, check
from ..physics import fragmentation as pfrag
from .grid import LOG_TOL

__all__ = ["AbstractFragmentation", "Shattering", "ShatterToMonomers", "FragData",
           "powerlaw_weights"]

_PROB = {"maxwellian": pfrag.p_frag_maxwellian, "sigmoid": pfrag.p_frag_sigmoid,
         "linear": pfrag.p_frag_linear, "step": pfrag.p_frag_step}


class FragData(eqx.Module):
    """Fragmentation right-hand-side data on the two-bin pair list (a pytree).

    p: (Np,) fragmenting fraction per pair; coef/idx: (Np, 4) direct mass coefficients [g]
    (losses, remnant placement) and target bins; ejecta: (Np,) mass [g] redistributed by the
    fragment weights W[src] (rows of W sum to 1).
    """

    p: jax.Array
    coef: jax.Array
    idx: np.ndarray
    ejecta: jax.Array
    src: np.ndarray
    W: jax.Array

    def rhs(self, rate, nbins):
        """Mass rate [g cm^-3 s^-1] (nbins + 1,) from fragmenting pair number rates ``rate``."""
        out = jax.ops.segment_sum((self.coef * rate[:, None]).ravel(), jnp.asarray(self.idx).ravel(),
                                  num_segments=nbins + 1)
        G = jax.ops.segment_sum(self.ejecta * rate, jnp.asarray(self.src), num_segments=nbins)
        gain = G @ self.W
        return out + jnp.concatenate([gain, jnp.zeros((1,), gain.dtype)])


def powerlaw_weights(grid, q):
    """Mass fractions W[L, b] of a fragment power law n(m) ~ m^-q from the grid bottom to bin L.

    Arguments: grid (MassGrid); q (float leaf, the number-distribution exponent).
    Returns: (nbins, nbins) jnp array, lower triangular, rows sum to 1.
    References: Brauer et al. (2008) eq. 13 (fragment distribution).
    """
    le = jnp.asarray(grid.log_edges)
    lhi, dl = le[1:], le[1:] - le[:-1]
    s = 2.0 - q  # mass per ln m ~ m^{2-q}
    small = jnp.abs(s) < 1e-8
    s_safe = jnp.where(small, 1.0, s)
    # int_bin m^s dln m = exp(s lhi) (1 - exp(-s dl))/s, in log form
    logfac = jnp.where(small, jnp.log(dl), jnp.log(-jnp.expm1(-s_safe * dl) / s_safe))
    logw = s * lhi + logfac
    N = grid.nbins
    mask = jnp.asarray(np.tril(np.ones((N, N), bool)))
    lw = jnp.where(mask, logw[None, :], -jnp.inf)
    return jax.nn.softmax(lw, axis=1)


def _place_remnant(grid, iL, mr_log, chi_mS):
    """Coefficients placing a remnant of mass m_r < m_L (replacing body L) by the two-bin split."""
    N = grid.nbins
    lc = grid.log_centers
    mL = np.exp(lc[iL])
    k = np.searchsorted(lc, mr_log, side="right") - 1
    k = np.clip(k, 0, np.maximum(iL - 1, 0))
    mk = np.exp(lc[k])
    mk1 = np.exp(lc[np.minimum(k + 1, N - 1)])
    mr = np.exp(mr_log)
    adj = (k == iL - 1)
    dm = np.where(iL >= 1, mL - np.exp(lc[np.maximum(iL - 1, 0)]), 1.0)
    # merged form for k = L-1 (number a = chi m_S/(m_L - m_{L-1}) moves from L to L-1)
    cL_adj = -chi_mS * mL / dm
    cK_adj = chi_mS * np.exp(lc[np.maximum(iL - 1, 0)]) / dm
    # general form
    c1 = (mr - mk) * mk1 / np.where(mk1 > mk, mk1 - mk, 1.0)
    ck = mr - c1
    idx = np.stack([iL, k, np.minimum(k + 1, N - 1)], axis=1).astype(np.int32)
    coef = np.stack([np.where(adj, cL_adj, -mL), np.where(adj, cK_adj, ck), np.where(adj, 0.0, c1)], axis=1)
    return idx, coef


class AbstractFragmentation(eqx.Module):
    """Base class of binned fragmentation recipes (see module docstring)."""

    needs_velocity: ClassVar[bool] = True

    @abc.abstractmethod
    def probability(self, kernel, m_large, m_small):
        """Fragmenting fraction p_f in [0, 1] of collisions between masses m_large >= m_small [g]."""

    @abc.abstractmethod
    def twobin_data(self, kernel, grid, iL, iS) -> FragData:
        """FragData on the two-bin pair list (iL >= iS)."""


class Shattering(AbstractFragmentation):
    """Velocity-dependent shattering + erosion (module docstring), p_f from v_frag.

    Arguments:
        v_frag: fragmentation threshold velocity [cm s^-1] (leaf, > 0).
        q: fragment number-distribution exponent, n(m) dm ~ m^-q dm (leaf; 11/6 default).
        probability: "maxwellian" (default) | "sigmoid" | "linear" | "step" (static).
        width: transition width of "sigmoid" (ln units) / "linear" (fraction of v_frag).
        crater_ratio: mass ratio m_L/m_S at and above which collisions erode instead of
            shattering (static, default 10). A pair at exactly the ratio erodes: the branch
            is ln(m_L/m_S) >= ln(crater_ratio) - LOG_TOL (LOG_TOL = 1e-9, i.e. a relative 1e-9,
            :data:`jaxcoag.binned.grid.LOG_TOL`), so pairs whose centres lie exactly
            crater_ratio apart (7 bins apart on a 7-per-decade grid with crater_ratio = 10)
            all erode instead of choosing by the round-off of the log-centres (which made 39 of
            133 such pairs of a 1e-12..1e8 g grid shatter), and crater_ratio = 10 and
            10 (1 - 1e-9) give the same run. Equal-mass pairs (i = j) never erode.
        chi: eroded target mass in units of the projectile mass (static, default 1).

    References: Brauer et al. (2008) §2.3; Birnstiel et al. (2010) eq. 15; DustPy (2022) §2.2.
    """

    v_frag: jax.Array
    q: jax.Array
    width: jax.Array
    probability_kind: str = eqx.field(static=True)
    crater_ratio: float = eqx.field(static=True)
    chi: float = eqx.field(static=True)

    def __init__(self, v_frag, q=11.0 / 6.0, probability="maxwellian", width=None, crater_ratio=10.0, chi=1.0):
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

    def probability(self, kernel, m_large, m_small):
        """p_f(dv^2(m_large, m_small); v_frag); dv^2 from ``kernel.relative_velocity2``."""
        dv2 = kernel.relative_velocity2(m_large, m_small)
        if self.probability_kind in ("sigmoid", "linear"):
            return _PROB[self.probability_kind](dv2, self.v_frag, self.width)
        return _PROB[self.probability_kind](dv2, self.v_frag)

    def twobin_data(self, kernel, grid, iL, iS):
        """FragData: shattering (ratio < crater_ratio) / erosion (ratio >= crater_ratio, to LOG_TOL)."""
        lc = grid.log_centers
        mL, mS = np.exp(lc[iL]), np.exp(lc[iS])
        crater = (iL > iS) & ((lc[iL] - lc[iS]) >= np.log(self.crater_ratio) - LOG_TOL)
        # shattering rows: -m_S at S, -m_L at L; ejecta m_L + m_S from source L
        # erosion rows: -m_S at S, remnant placement at (L, k, k+1); ejecta (1+chi) m_S from source S
        chi_mS = self.chi * mS
        mr_log = lc[iL] + np.log1p(-np.where(crater, chi_mS / mL, 0.0))
        ridx, rcoef = _place_remnant(grid, iL, mr_log, chi_mS)
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
        return FragData(p=p, coef=jnp.asarray(coef), idx=idx, ejecta=jnp.asarray(ejecta), src=src,
                        W=powerlaw_weights(grid, self.q))


class ShatterToMonomers(AbstractFragmentation):
    """Catastrophic disruption into monomers above a mass threshold (thesis §5.3.4).

    A collision whose product mass m_L + m_S exceeds ``m_frag`` [g] does not stick: all its
    mass goes to the lowest bin (the monomers). Velocity-free; works with analytic kernels.
    "Exceeds" is decided to a relative tolerance LOG_TOL = 1e-9
    (:data:`jaxcoag.binned.grid.LOG_TOL`): a product exactly at m_frag sticks (as in the Monte
    Carlo :class:`jaxcoag.mc.CatastrophicFragmentation`) even when the sum of the two bin
    centres rounds above it (e.g. 2 m_2 = 8.000000000000002 g = m_frag (1 + 2e-16) on a grid
    with centres 1, 2, 4, ... g).

    References: Ormel (2008) thesis §5.3.4, Figs. 5.8-5.9 (steady state f ~ m^-(3+beta)/2,
    i.e. m^-3/2 for the constant kernel).
    """

    m_frag: jax.Array
    needs_velocity: ClassVar[bool] = False

    def __init__(self, m_frag):
        self.m_frag = check(m_frag, "m_frag", positive=True, hint="mass threshold in g above which products shatter")

    def probability(self, kernel, m_large, m_small):
        """1 where m_large + m_small > m_frag (1 + LOG_TOL), else 0 (hard threshold)."""
        return jnp.where(m_large + m_small > self.m_frag * (1.0 + LOG_TOL), 1.0, 0.0)

    def twobin_data(self, kernel, grid, iL, iS):
        """FragData: -m_S at S, -m_L at L, ejecta m_L + m_S all into bin 0."""
        N = grid.nbins
        lc = grid.log_centers
        mL, mS = np.exp(lc[iL]), np.exp(lc[iS])
        idx = np.stack([iS, iL, iL, iL], axis=1).astype(np.int32)
        coef = np.stack([-mS, -mL, np.zeros_like(mL), np.zeros_like(mL)], axis=1)
        W = jnp.zeros((N, N)).at[:, 0].set(1.0)
        p = self.probability(kernel, jnp.exp(jnp.asarray(lc[iL])), jnp.exp(jnp.asarray(lc[iS])))
        return FragData(p=p, coef=jnp.asarray(coef), idx=idx, ejecta=jnp.asarray(mL + mS),
                        src=np.zeros(iL.size, np.int32), W=W)
