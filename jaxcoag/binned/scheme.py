"""Abstract interface of a binned Smoluchowski discretisation ("scheme").

A scheme turns the continuous coagulation(-fragmentation) equation on a :class:`MassGrid`
into an ODE ``dy/dt = rhs(t, y, data)`` for a 1-D state vector ``y``. The binned
engine (:class:`jaxcoag.Binned`) only talks to schemes through this interface, so new
discretisations (two-bin, discontinuous Galerkin, ...) plug in without touching the driver.

Contract (all methods pure; no Python loops over bins in traced code):

* ``init(grid, n0) -> y0``: build the 1-D float64 initial state. ``n0`` is either an array of
  shape ``(grid.nbins,)`` holding the *number density per bin* [cm^-3], or a callable
  ``f(m)`` giving the number density per unit mass [cm^-3 g^-1] (vectorised over a numpy or
  JAX array of masses in g) which the scheme projects onto its representation. May be called
  outside jit (concrete) - schemes may use numpy here.
* ``precompute(kernel, grid, fragmentation=None) -> data``: everything the right-hand side
  needs that depends on the kernel and grid (kernel matrices, index tensors, fragment
  redistribution weights). The driver calls it *inside* the traced solve, so ``data`` must be a
  JAX pytree whose float leaves are computed from the kernel's leaves (this is what carries
  gradients to alpha, rho_g, v_frag, ...). Index arrays built from the (static) grid may be
  numpy constants. ``fragmentation`` is ``None`` (pure coagulation) or a
  binned-capable ``jaxcoag.outcomes.AbstractOutcome`` (hooks ``probability``/``twobin_data``); a scheme that cannot handle it
  raises a clear ``TypeError`` at Python (trace) time saying which scheme to use instead.
* ``rhs(t, y, data) -> dy/dt``: same shape/dtype as ``y``.
* ``mass_per_bin(y, grid) -> (nbins,)`` mass density per bin [g cm^-3].
* ``number_per_bin(y, grid) -> (nbins,)`` number density per bin [cm^-3].
* ``gel_mass(y, grid) -> scalar`` mass density [g cm^-3] that has left through the top of the
  grid (an explicit state entry, so that ``sum(mass_per_bin) + gel_mass`` is conserved).
  Schemes without an accumulator return 0.
* ``mass_scale(y0, grid) -> (len(y),)``: positive per-entry weights ``w`` such that
  ``w * y`` is "mass per bin"-like [g cm^-3]; the driver builds its error norm from it
  (RMS of ``(w * err) / (rtol * |w*y| + atol * M_tot)``), which is what makes one ``atol``
  usable over 30+ decades (docs/design_notes.md, traps).

References: Smoluchowski (1916); Kovetz & Olund (1969); Brauer, Dullemond & Henning (2008),
A&A 480, 859, App. A (two-bin split); Liu, Gröpler & Warnecke (2019) (DG); house style in docs/design_notes.md.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp

from .._validate import JaxcoagInputError

__all__ = ["AbstractScheme", "estimate_bytes", "check_memory"]

# Peak-memory model of a binned solve [bytes], measured as the growth of the peak resident set
# (ru_maxrss) over a bare `import jaxcoag` on CPU (jax 0.4, float64), default 1 AU config with
# 12 outputs, 5 solver steps; Np = N (N + 1) / 2 bin pairs:
#   twobin, Tsit5, no fragmentation: +400 MB at N = 998, +1107 MB at N = 1995 -> ~480 B per pair;
#   twobin + Shattering with Kvaerno5 (dense Jacobian by forward mode: N + 1 tangents of the
#   pair tensors): +1075 MB at N = 269, +3080 MB at N = 403 -> ~50 B N^3 = ~100 B per pair and
#   tangent;
#   DG order 1: 2.06 cut pieces per pair (N = 57..266), ~1 kB per piece in the geometry build
#   (Python rows) and the (k+1)^3 gain/loss tensors.
#   the dense pair operators (jaxcoag/binned/pairop.py) add K N^2 float64 per operator (K categories,
#   7 at 7 bins per decade; N^2 <= 2 Np): default config with fragmentation, Tsit5, 975 bins, +829 MB
#   before them and +900 MB with them (2026-11-26), charged as 16 B x 8 categories per pair.
_TWOBIN_PAIR = 500.0
_TWOBIN_DENSE_PAIR = 128.0
_TWOBIN_FRAG_PAIR = 400.0
_JAC_PAIR_TANGENT = 100.0
_DG_PIECES_PER_PAIR = 2.1
_DG_PIECE = 600.0
_DG_PIECE_TENSOR = 48.0  # x (k+1)^3: 3 tensors, pieces and groups, float64


def estimate_bytes(scheme, nbins, *, order=0, fragmentation=False, implicit=False):
    """Estimated peak memory [bytes] of a binned solve on ``nbins`` bins (an upper-end estimate
    from the measurements in the comment above this function; within a factor ~2).

    Arguments:
        scheme: "twobin", "dg" or an AbstractScheme instance (TwoBinScheme / DGScheme; another
            scheme returns None: unknown).
        nbins: number of bins N.
        order: DG polynomial degree k (ignored for twobin; taken from a DGScheme instance).
        fragmentation: the fragmentation model, True, or None/False (twobin: its pair tensors and
            N x N weights; a RecipeOutcome also holds (Np, N) fragment weights).
        implicit: an implicit solver (Rodas4, Kvaerno5, LinearlyImplicitEuler) builds the dense Jacobian
            by forward mode: every pair tensor is carried for all len(y) tangents (O(N^3)).

    Returns: float bytes, or None for a scheme this model does not know.

    References: Brauer et al. (2008) App. A (N(N+1)/2 two-bin pairs); Lombart & Laibe (2021)
    (DG flux integrals cut per bin pair).
    """
    name = scheme if isinstance(scheme, str) else type(scheme).__name__
    N = float(nbins)
    pairs = 0.5 * N * (N + 1.0)
    if name in ("twobin", "TwoBinScheme"):
        b = (_TWOBIN_PAIR + _TWOBIN_DENSE_PAIR) * pairs
        if fragmentation is not None and fragmentation is not False:
            b += _TWOBIN_FRAG_PAIR * pairs + 8.0 * N * N
            if type(fragmentation).__name__ == "RecipeOutcome":
                b += 8.0 * pairs * N  # fragment weights W (Np, N)
        if implicit:
            b += _JAC_PAIR_TANGENT * pairs * (N + 1.0)
        return b
    if name in ("dg", "DGScheme"):
        k1 = float(getattr(scheme, "order", order)) + 1.0
        pieces = _DG_PIECES_PER_PAIR * pairs
        b = pieces * (_DG_PIECE + _DG_PIECE_TENSOR * k1 ** 3)
        if implicit:
            b += _JAC_PAIR_TANGENT * pieces * k1 * (N * k1 + 1.0)
        return b
    return None


def check_memory(scheme, nbins, *, order=0, fragmentation=False, implicit=False, fix=""):
    """Refuse (JaxcoagInputError) a solve whose :func:`estimate_bytes` exceeds
    :func:`jaxcoag.binned.grid.memory_limit_bytes`, before anything is allocated.

    Arguments: as :func:`estimate_bytes`; fix: what the user should change (e.g. "lower [grid]
    bins_per_decade"), appended to the message. Returns: the estimate [bytes] (None if unknown).
    """
    from .grid import _gib, memory_limit_bytes

    need = estimate_bytes(scheme, nbins, order=order, fragmentation=fragmentation, implicit=implicit)
    if need is None:
        return None
    limit = memory_limit_bytes()
    if need > limit:
        name = scheme if isinstance(scheme, str) else type(scheme).__name__
        frag = fragmentation is not None and fragmentation is not False
        what = " and ".join(w for w, on in (("fragmentation", frag), ("an implicit solver", implicit)) if on)
        what = f"with {what} " if what else ""
        # the largest N that fits (the estimate grows monotonically with N): bisection
        lo, hi = 2, max(int(nbins), 3)
        while hi - lo > 1:
            mid = (lo + hi) // 2
            ok = estimate_bytes(scheme, mid, order=order, fragmentation=fragmentation, implicit=implicit) <= limit
            lo, hi = (mid, hi) if ok else (lo, mid)
        raise JaxcoagInputError(
            f"{int(nbins)} bins would need ~{_gib(need)} for the {name} scheme {what}(estimate), more than the "
            f"limit of {_gib(limit)} (half the memory; env JAXCOAG_MEMORY_LIMIT_GB overrides); "
            f"{fix or 'use fewer bins (lower bins_per_decade or narrow the mass range)'} (at most ~{lo} bins fit).")
    return need


class AbstractScheme(eqx.Module):
    """Base class of binned discretisations; see the module docstring for the contract.

    Concrete schemes are ``eqx.Module`` s whose fields are *structure* (e.g. the DG
    polynomial ``order``, a static int). They must not store grid- or kernel-dependent arrays:
    those belong in ``data`` from :meth:`precompute`.
    """

    @abc.abstractmethod
    def init(self, grid, n0) -> jax.Array:
        """Initial 1-D state from number density per bin [cm^-3] (array) or f(m) [cm^-3 g^-1]."""

    @abc.abstractmethod
    def precompute(self, kernel, grid, fragmentation=None):
        """Kernel/grid dependent pytree used by :meth:`rhs` (called inside the traced solve)."""

    @abc.abstractmethod
    def rhs(self, t, y, data) -> jax.Array:
        """Time derivative dy/dt [state units s^-1] at time t [s]."""

    def rhs_structured(self, t, y, data) -> jax.Array:
        """:meth:`rhs` for solvers that form Jacobians: a scheme with a structured Jacobian
        overrides it with a ``custom_jvp`` whose rule uses that Jacobian (``TwoBinScheme``);
        default: :meth:`rhs` itself (Jacobians by N + 1 JVPs)."""
        return self.rhs(t, y, data)

    @abc.abstractmethod
    def mass_per_bin(self, y, grid) -> jax.Array:
        """Mass density per bin [g cm^-3], shape (nbins,)."""

    @abc.abstractmethod
    def number_per_bin(self, y, grid) -> jax.Array:
        """Number density per bin [cm^-3], shape (nbins,)."""

    def gel_mass(self, y, grid) -> jax.Array:
        """Mass density [g cm^-3] that left through the top of the grid (default: none, 0)."""
        return jnp.zeros((), y.dtype)

    @abc.abstractmethod
    def mass_scale(self, y0, grid) -> jax.Array:
        """Per-entry positive weights w (len(y)) with w*y ~ mass per bin [g cm^-3] (error norm)."""

    def total_mass(self, y, grid) -> jax.Array:
        """Total mass density incl. gel [g cm^-3] (conserved by coagulation and fragmentation)."""
        return jnp.sum(self.mass_per_bin(y, grid)) + self.gel_mass(y, grid)
