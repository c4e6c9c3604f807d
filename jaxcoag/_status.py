"""One status enumeration for every engine (results, sweeps, files, checkpoints).

Failures are values (diffrax style): every result carries ``status``, a :class:`RESULTS` item;
``jaxcoag.evolve(..., throw=True)`` raises for the items in :data:`FAILURES` (with the item's
message, through ``eqx.error_if``, so it also works under ``jax.jit``), while vmapped sweeps use
``throw=False`` and read which member failed. The integer code of an item, written to netCDF files,
sweep datasets and checkpoints, is its position in :data:`RESULT_NAMES` (append new items at the
end so that old files keep their meaning). Only equinox's public ``Enumeration`` API is used.

References: Kidger (2021), diffrax ``RESULTS`` (the failure-as-value pattern).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

__all__ = ["RESULTS", "RESULT_NAMES", "FAILURES", "result_code", "result_from_code", "is_failure", "result_table",
           "status_names"]


class RESULTS(eqx.Enumeration):
    """Outcome of a run of any engine (binned, Monte Carlo, ...)."""

    successful = ""
    max_steps_reached = ("The step budget was spent before the last output time (binned: `max_steps` solver steps; "
                         "Monte Carlo: `max_events` events; later outputs repeat the last state). Raise the budget, "
                         "loosen rtol/atol, or use an implicit solver for stiff fragmentation problems.")
    nonfinite = ("The solution became non-finite (NaN/inf). Check the kernel parameters, reduce dt0 or tighten "
                 "rtol/atol (binned); check that the kernel is finite for every mass pair (Monte Carlo).")
    negative_density = ("A bin's mass density went negative beyond 10*atol of the total mass. Tighten rtol/atol or "
                        "use an implicit solver.")
    solver_failed = ("The solver failed (step size underflow, nonlinear solver divergence or another internal "
                     "error). Try a different solver or tighter tolerances.")
    invalid_parameters = ("A parameter of this sweep member is NaN/inf, so it was not run (jaxcoag.sweep with "
                          "invalid='flag'). Fix that parameter value.")
    capacity_exceeded = ("The Monte Carlo run ran out of species slots and merged mass neighbours to continue "
                         "(consistent but coarser than asked for). Raise MonteCarlo(capacity=...).")
    zero_rate = ("The total collision rate became zero (e.g. a single particle left); later outputs repeat the "
                 "final state, which is exact.")
    stopped = ("The stop predicate of the run (e.g. MonteCarlo(stop=Runaway(...))) fired; later outputs repeat the "
               "stopped state.")


#: The :class:`RESULTS` items in definition order; the integer code of an item is its position here
#: (``len(RESULTS) == len(RESULT_NAMES)`` is tested).
RESULT_NAMES = ("successful", "max_steps_reached", "nonfinite", "negative_density", "solver_failed",
                "invalid_parameters", "capacity_exceeded", "zero_rate", "stopped")

#: Items for which ``evolve(..., throw=True)`` raises. ``capacity_exceeded`` warns instead
#: (the run is consistent, only coarser), ``zero_rate`` and ``stopped`` are legitimate ends.
FAILURES = ("max_steps_reached", "nonfinite", "negative_density", "solver_failed", "invalid_parameters")


def result_code(result):
    """Integer code (int32 array, traceable, batched like ``result``) of a :class:`RESULTS` item."""
    code = jnp.int32(0)
    for i, name in enumerate(RESULT_NAMES[1:], start=1):
        code = jnp.where(result == getattr(RESULTS, name), jnp.int32(i), code)
    return code


def result_from_code(code):
    """The :class:`RESULTS` item of an integer code (inverse of :func:`result_code`; traceable; an
    array of codes gives a batched item)."""
    code = jnp.asarray(code)
    if code.ndim:
        return jax.vmap(result_from_code)(code)
    item = RESULTS.successful
    for i, name in enumerate(RESULT_NAMES[1:], start=1):
        item = RESULTS.where(code == i, getattr(RESULTS, name), item)
    return item


def is_failure(result):
    """Boolean array (batched like ``result``): whether the item is one of :data:`FAILURES`."""
    out = jnp.zeros(jnp.shape(result_code(result)), bool)
    for name in FAILURES:
        out = out | (result == getattr(RESULTS, name))
    return out


def result_table():
    """[(name, message)] of every :class:`RESULTS` item, indexed by its integer code."""
    return [(name, RESULTS[getattr(RESULTS, name)]) for name in RESULT_NAMES]


def status_names(result):
    """Name of a :class:`RESULTS` item: a str for one run, a (nested) list for a vmapped batch
    (e.g. ``["successful", "stopped"]`` for two runs)."""
    import numpy as np

    codes = np.asarray(result_code(result))
    if codes.ndim == 0:
        return RESULT_NAMES[int(codes)]
    return np.vectorize(lambda c: RESULT_NAMES[int(c)], otypes=[object])(codes).tolist()
