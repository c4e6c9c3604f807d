"""Abstract interface of a binned Smoluchowski discretisation ("scheme").

A scheme turns the continuous coagulation(-fragmentation) equation on a :class:`MassGrid`
into an ODE ``dy/dt = rhs(t, y, data)`` for a 1-D state vector ``y``. The driver
:func:`jaxcoag.binned.solve_binned` only talks to schemes through this interface, so new
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
  ``jaxcoag.binned.fragmentation.AbstractFragmentation``; a scheme that cannot handle it
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
  usable over 30+ decades (DESIGN.md §5).

References: Smoluchowski (1916); Kovetz & Olund (1969); Brauer, Dullemond & Henning (2008),
A&A 480, 859, App. A (two-bin split); Liu, Gröpler & Warnecke (2019) (DG); DESIGN.md §2.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp

__all__ = ["AbstractScheme"]


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
