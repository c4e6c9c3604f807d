"""One verb over engine objects: ``jaxcoag.evolve(kernel, engine, initial, t_out, ...)``.

The numerical strategy is an object (diffrax's ``diffeqsolve(terms, solver, ...)`` is the model):
``jaxcoag.Binned(grid, ...)`` (Smoluchowski on a mass grid, diffrax) or ``jaxcoag.MonteCarlo(...)``
(grouped Monte Carlo, Ormel & Spaans 2008). Every engine takes the same arguments and returns a
result with the same protocol (:class:`AbstractResult`): output times ``.t`` [s], one ``.status``
(:class:`jaxcoag.RESULTS`), the same mass-distribution accessors and diagnostics, and
``.to_xarray()`` with the same coordinate names (``t``, ``t_yr``, ``m``, ``m_edge``, ``a``, ``St``).

Engine protocol (what a new engine implements; all state is a pytree of arrays, which is what a
checkpoint stores):

* ``_check(kernel, initial, t_out, t0, outcome, key)``: every Python-time refusal, before any work;
* ``_init(kernel, initial, t0, outcome, key) -> state``;
* ``_advance(kernel, state, t_seg, outcome) -> (state, outs)``: evolve to ``t_seg[-1]``, with the
  outputs at every time of ``t_seg`` (a pytree with leading axis ``len(t_seg)``, including the
  integer ``"status"`` code of :data:`jaxcoag.RESULT_NAMES` per output);
* ``_result(kernel, t, outs, state, outcome) -> result`` from the outputs of all segments.

``evolve`` without a checkpoint advances once over all output times; with ``checkpoint=`` (or
``progress``/``max_segments``) the one segment driver :func:`jaxcoag.checkpoint.run_segments`
advances segment by segment, writing an atomic checkpoint after each.

References: Kidger (2021), diffrax ``diffeqsolve`` (solver objects, failures as values).
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._status import RESULTS, is_failure
from ._validate import JaxcoagInputError, check, is_traced, require_x64

__all__ = ["AbstractEngine", "AbstractResult", "Monodisperse", "evolve"]


class Monodisperse(eqx.Module):
    """Monodisperse initial condition, understood by every engine.

    Fields:
        m0: monomer mass [g] (> 0).
        rho_d: dust mass density [g cm^-3] (> 0; default 1): number density rho_d / m0.

    Binned engines put all of rho_d into the bin holding m0 (put m0 at a bin centre for analytic
    comparisons); the Monte Carlo engine starts with ``MonteCarlo.n_particles`` particles of mass m0
    in the volume V = n_particles m0 / rho_d.

    References: Ormel (2008) thesis Table 5.1 (monodisperse start, n(m, 0) = rho_d/m0 delta(m - m0)).
    """

    m0: float | jax.Array = 1.0
    rho_d: float | jax.Array = 1.0

    def __check_init__(self):
        for name in ("m0", "rho_d"):
            v = getattr(self, name)
            if not is_traced(v):
                a = np.asarray(v, dtype=np.float64)
                if a.ndim != 0 or not (np.isfinite(a) and a > 0):
                    raise JaxcoagInputError(f"Monodisperse({name}=...) must be a finite scalar > 0 "
                                            f"({'monomer mass in g' if name == 'm0' else 'dust mass density in g cm^-3'}); "
                                            f"got {v!r}.")


class AbstractResult(eqx.Module):
    """Protocol of every engine's result (an equinox Module; add a leading batch axis under vmap).

    Every result has ``t`` (T,) output times [s], ``status`` (a :class:`jaxcoag.RESULTS` item) and
    ``final_state`` (the engine state at ``t[-1]``; pass the result itself as ``initial`` to
    :func:`evolve` to continue the run), and the methods below, with the same names and units for
    every 0-D engine (edges: 1-D increasing mass-bin edges [g]).
    """

    t: eqx.AbstractVar[jax.Array]
    status: eqx.AbstractVar[RESULTS]

    @abc.abstractmethod
    def mass_per_bin(self, edges=None):
        """(T, nbins) dust mass density per mass bin [g cm^-3]."""

    @abc.abstractmethod
    def number_per_bin(self, edges=None):
        """(T, nbins) dust number density per mass bin [cm^-3]."""

    @abc.abstractmethod
    def moments(self, p):
        """(T,) moment M_p = sum over particles of n m^p [g^p cm^-3] (p = 0: number, 1: mass density)."""

    @abc.abstractmethod
    def bin_edges(self, edges=None):
        """The mass-bin edges [g] the binned accessors use for ``edges`` (numpy, (nbins + 1,))."""

    @abc.abstractmethod
    def to_xarray(self, *, attrs=None, kernel=None, edges=None):
        """Labelled dataset with the common layout (dims ``t``, ``m``, ``m_edge``; see the module doc)."""

    def m2f(self, edges=None):
        """(T, nbins) m^2 f(m) = mass density per unit ln m [g cm^-3] (the thesis plots' ordinate)."""
        from .diagnostics import m2f

        return m2f(self.mass_per_bin(edges), self.bin_edges(edges))

    def mass_peak(self, edges=None):
        """(T,) mass [g] of the bin centre holding the most mass per unit ln m."""
        from .diagnostics import mass_peak

        return mass_peak(self.mass_per_bin(edges), self.bin_edges(edges))

    def mean_mass(self):
        """(T,) mass-weighted mean mass M2/M1 [g] (the thesis' m_p)."""
        return self.moments(2) / self.moments(1)


#: XLA options for the compiled loop of an event-driven engine (top-level ``jax.jit`` only: under another trace the
#: options belong to the outermost jit, so the engines call their plain program there). Without while-loop-invariant
#: code motion: rare work runs in gated 0/1-trip loops, and XLA moved the parts of it that read only state those loops
#: do not write out of them into the enclosing loop, where they ran at every event (array-sized work per event in the
#: rigid box's per-body clocks and the Monte Carlo engine; docs/design_notes.md, "A collision in O(members)").
LOOP_XLA_OPTIONS = {"xla_disable_hlo_passes": "while-loop-invariant-code-motion"}


class AbstractEngine(eqx.Module):
    """Numerical strategy of a run (structure as static fields / classes, numbers as leaves).

    Subclasses implement ``_check``, ``_init``, ``_advance`` and ``_result`` (module docstring).
    ``name`` is the engine's name in files and configurations ("binned", "mc", ...).
    """

    @property
    @abc.abstractmethod
    def name(self) -> str:
        """Engine name written to files (``engine`` attribute) and used by ``[run] engine``."""

    @abc.abstractmethod
    def _check(self, kernel, initial, t_out, t0, outcome, key) -> None:
        """Refuse bad input (JaxcoagInputError naming what to change) before any work."""

    @abc.abstractmethod
    def _init(self, kernel, initial, t0, outcome, key):
        """Engine state (pytree of arrays) at ``t0``."""

    @abc.abstractmethod
    def _advance(self, kernel, state, t_seg, outcome):
        """(state at t_seg[-1], outputs at every time of t_seg incl. an int ``status`` code per output)."""

    @abc.abstractmethod
    def _result(self, kernel, t, outs, state, outcome):
        """The engine's result from the concatenated outputs and the final state."""

    def _forward_only(self):
        """The engine for a run that nothing differentiates (``jaxcoag run``, ``jaxcoag sweep``:
        ``runner.forward_only``). Engines whose default serves reverse mode return a faster forward-only form
        with the same steps (the binned engine: ``diffrax.ForwardMode`` for its default adjoint)."""
        return self

    def _fingerprint_view(self):
        """The engine as a checkpoint's fingerprint sees it (``checkpoint.run_fingerprint``): everything that decides
        what a run computes. Engines with options that only decide how a run is differentiated return themselves
        without them (the binned engine's ``adjoint``), so a checkpoint resumes under another such option."""
        return self

    def _progress_time(self, t: float) -> str:
        """Simulated time ``t`` (in the run's time unit) as the progress bar shows it: years for the engines whose
        times are in s and span astrophysical scales; engines with other units or scales override it."""
        from .constants import yr

        return f"t = {t / yr:.4g} yr"


def _check_t_out(t_out, t0):
    """Output times as a float64 array: 1-D, non-empty, finite, strictly increasing, >= t0."""
    t = t_out if is_traced(t_out) else check(t_out, "t_out", hint="output times in s")
    if jnp.ndim(t) != 1 or jnp.shape(t)[0] < 1:
        raise JaxcoagInputError(f"t_out must be a non-empty 1-D array of output times in s; got shape {jnp.shape(t)}.")
    if not is_traced(t):
        tv = np.asarray(t, np.float64)
        if np.any(np.diff(tv) <= 0):
            raise JaxcoagInputError("t_out must be strictly increasing; sort it and drop duplicates.")
        if not is_traced(t0) and tv[0] < float(t0):
            raise JaxcoagInputError(f"t_out[0] = {tv[0]:g} s precedes t0 = {float(t0):g} s (the time of the initial "
                                    "condition); pass t0=t_out[0] or later output times.")
    return jnp.asarray(t, jnp.float64)


def evolve(kernel, engine, initial, t_out, *, t0=None, outcome=None, key=None, checkpoint=None, every=1,
           resume=True, progress=False, max_segments=None, throw=True):
    """Evolve a dust population with any engine: the one verb of jaxcoag.

    Arguments:
        kernel: collision kernel, a ``jaxcoag.kernels.AbstractKernel`` [cm^3 s^-1] (analytic, or
            ``Scene(...).kernel(gas, rho_s)``); evaluated inside the run, so gradients (Binned) and
            vmap flow to its leaves.
        engine: the numerical strategy, ``jaxcoag.Binned(grid, ...)`` or ``jaxcoag.MonteCarlo(...)``.
        initial: the initial condition at ``t0``: ``jaxcoag.Monodisperse(m0, rho_d)`` (every engine);
            Binned also a number density per bin [cm^-3] (nbins,) or a callable f(m) [cm^-3 g^-1];
            MonteCarlo also ``jaxcoag.mc.initial_species(...)``; or a previous result of the same
            engine, which continues that run from its last output (t0 = its last time; a Monte Carlo
            continuation is bitwise one uninterrupted run).
        t_out: output times [s], 1-D, strictly increasing, ``t_out[0] >= t0``; ``result.t`` equals it.
        t0: time of the initial condition [s] (default 0, or the continued result's last time).
        outcome: collision outcome (``jaxcoag.outcomes``; None = perfect sticking).
        key: ``jax.random`` key (stochastic engines; deterministic engines such as Binned ignore it,
            so that the same call runs every engine).
        checkpoint: path of a checkpoint file: the run goes segment by segment (``every`` output
            times per segment) and writes the file atomically after each; with ``resume=True`` an
            existing file of the same configuration is continued (another one is refused). Ctrl-C
            saves the completed segments and raises ``jaxcoag.checkpoint.RunInterrupted``.
        progress: a progress bar over the segments (stderr).
        max_segments: advance at most this many new segments, then return the outputs so far.
        throw: raise (with the :class:`jaxcoag.RESULTS` message) when the status is a failure
            (:data:`jaxcoag.FAILURES`); use ``throw=False`` inside vmapped sweeps and read
            ``result.status``.

    Returns:
        The engine's result (:class:`AbstractResult`): ``.t`` [s], ``.status``, ``mass_per_bin``,
        ``number_per_bin``, ``moments``, ``mass_peak``, ``m2f``, ``to_xarray``, ``final_state``.

    References: Smoluchowski (1916); Ormel & Spaans (2008); Kidger (2021, diffrax).
    """
    require_x64("jaxcoag.evolve")
    if not isinstance(engine, AbstractEngine):
        raise JaxcoagInputError(f"engine must be a jaxcoag engine object such as jaxcoag.Binned(grid) or "
                                f"jaxcoag.MonteCarlo(...); got {type(engine).__name__}.")
    if isinstance(initial, AbstractResult):
        if jnp.ndim(initial.t) != 1:
            raise JaxcoagInputError("initial holds a batch of results (from a vmapped run); continue it inside "
                                    "jax.vmap, or index one member with jax.tree_util.tree_map(lambda x: x[i], result).")
        if t0 is None:
            t0 = initial.t[-1]
    if t0 is None:
        t0 = 0.0
    if not is_traced(t0):
        t0 = float(check(t0, "t0", nonnegative=True, hint="time of the initial condition in s"))
    t_out = _check_t_out(t_out, t0)
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise JaxcoagInputError(f"every must be a positive int (output times per checkpoint segment); got {every!r}.")
    if max_segments is not None and (isinstance(max_segments, bool) or not isinstance(max_segments, (int, np.integer))
                                     or max_segments < 1):
        raise JaxcoagInputError(f"max_segments must be None or a positive int; got {max_segments!r}.")
    engine._check(kernel, initial, t_out, t0, outcome, key)
    if checkpoint is not None or progress or max_segments is not None:
        from .checkpoint import run_segments

        res = run_segments(kernel, engine, initial, t_out, t0=t0, outcome=outcome, key=key, checkpoint=checkpoint,
                           every=int(every), resume=resume, progress=progress, max_segments=max_segments)
    else:
        state = engine._init(kernel, initial, t0, outcome, key)
        state, outs = engine._advance(kernel, state, t_out, outcome)
        res = engine._result(kernel, t_out, outs, state, outcome)
    if throw:
        res = raise_on_failure(res)
    return res


def raise_on_failure(res):
    """``res`` with every float array passed through ``eqx.error_if`` on a failure status (raises with
    the :class:`jaxcoag.RESULTS` item's message; also under ``jax.jit``)."""
    failed = is_failure(res.status)
    if not is_traced(failed) and not bool(np.any(np.asarray(failed))):
        return res
    status = res.status
    dyn, static = eqx.partition(res, eqx.is_inexact_array)
    dyn = jax.tree_util.tree_map(lambda x: status.error_if(x, failed), dyn)
    return eqx.combine(dyn, static)
