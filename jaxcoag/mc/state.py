"""Fixed-capacity state of the grouped Monte Carlo engine (one run; batch with ``jax.vmap``).

Every species slot carries (m, log m, psi, w, z, valid); invalid slots hold the safe dummy
m = 1, w = 0, z = 0. The multiplicity is g = w 2^z (never formed when it could overflow:
use log g = log w + z ln 2).

References: Ormel (2008) thesis Table 5.4 (state vector per species); spec/montecarlo.md
§3.2 (state layout), §3.8 (snapshots), §6 (status flags).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

__all__ = ["STATUS", "MCState", "Snapshots", "status_names"]

LN2 = float(jnp.log(2.0))


class STATUS:
    """Bit flags of ``MCResult.status`` (failures are values, so vmapped sweeps keep going).

    OK: ran to the last output time. CAPACITY: free species slots ran out, an emergency merge
    was done (results remain consistent but are smoothed; raise ``capacity``). ZERO_RATE: the
    total collision rate became zero (e.g. a single particle left); later snapshots repeat
    the final state, which is exact. NONFINITE: a non-finite total rate (kernel returned NaN
    or inf); the run stopped, later snapshots repeat the last good state. MAX_EVENTS: the
    event budget ``max_events`` was spent; later snapshots repeat that state (NOT the true
    state at those times).
    """

    OK = 0
    CAPACITY = 1
    ZERO_RATE = 2
    NONFINITE = 4
    MAX_EVENTS = 8


def status_names(code) -> list[str]:
    """Names of the flags set in an integer status code (``[]`` means OK)."""
    code = int(code)
    return [n for n in ("CAPACITY", "ZERO_RATE", "NONFINITE", "MAX_EVENTS") if code & getattr(STATUS, n)]


class Snapshots(NamedTuple):
    """Per output time (leading axis n_snap): species arrays and scalars."""

    m: jax.Array       # (T, S) mass [g]
    logm: jax.Array    # (T, S) ln mass
    psi: jax.Array     # (T, S, P) structural parameters
    w: jax.Array       # (T, S) group number
    z: jax.Array       # (T, S) zoom number (int32)
    valid: jax.Array   # (T, S) bool
    logV: jax.Array    # (T,) ln simulated volume [ln cm^3]
    M_tot: jax.Array   # (T,) total simulated mass [g]
    n_events: jax.Array  # (T,) events executed before the snapshot


class MCState(NamedTuple):
    """Complete loop carry of one run (all leaves are arrays)."""

    m: jax.Array
    logm: jax.Array
    psi: jax.Array
    w: jax.Array
    z: jax.Array
    valid: jax.Array
    R: jax.Array          # (S,) volume-free row sums of the symmetric rate matrix, scaled by exp(-s)
    s: jax.Array          # log scale of R
    logV: jax.Array
    M_tot: jax.Array
    t: jax.Array
    n_events: jax.Array
    n_since_refresh: jax.Array
    dirty: jax.Array      # bool: maintenance (refresh/merge/rezoom) needed before the next event
    rezoom: jax.Array     # bool: a global rezoom is due
    log_mstar: jax.Array  # equal-mass characteristic mass (ln g)
    zref: jax.Array       # reference log quantity for the rezoom trigger
    zoom_xp: jax.Array    # (N_b,) distribution-method nodes (ln m)
    zoom_fp: jax.Array    # (N_b,) distribution-method zoom values at the nodes
    key: jax.Array
    k_out: jax.Array
    status: jax.Array
    done: jax.Array
    n_dup: jax.Array
    n_merge: jax.Array
    snaps: Snapshots
