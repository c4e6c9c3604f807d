"""Fixed-capacity state of the grouped Monte Carlo engine (one run; batch with ``jax.vmap``).

Every species slot carries (m, log m, psi, w, z, valid); invalid slots hold the safe dummy
m = 1, w = 0, z = 0. The multiplicity is g = w 2^z (never formed when it could overflow:
use log g = log w + z ln 2).

The run's raw bit flags (:class:`STATUS`) are an internal detail: results carry one
:class:`jaxcoag.RESULTS` item (:func:`flags_to_code`), and the flags only as ``MCResult.flags``.

References: Ormel (2008) thesis Table 5.4 (state vector per species); snapshots and MC
hazards (status flags) in docs/design_notes.md.
"""

from __future__ import annotations

import abc
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._validate import JaxcoagInputError, check, is_traced

__all__ = ["STATUS", "MCState", "Snapshots", "flag_names", "flags_to_code", "largest_two", "log_n_particles",
           "InitialSpecies", "initial_species", "AbstractStop", "Runaway"]

LN2 = float(jnp.log(2.0))


class STATUS:
    """Raw bit flags of a Monte Carlo run (internal; ``MCResult.flags``). A result reports one
    :class:`jaxcoag.RESULTS` item instead (:func:`flags_to_code`).

    OK: ran to the last output time. CAPACITY: free species slots ran out, an emergency merge
    was done (results remain consistent but are smoothed; raise ``capacity``). ZERO_RATE: the
    total collision rate became zero (e.g. a single particle left); later snapshots repeat
    the final state, which is exact. NONFINITE: a non-finite total rate (kernel returned NaN
    or inf); the run stopped, later snapshots repeat the last good state. MAX_EVENTS: the
    event budget ``max_events`` was spent; later snapshots repeat that state (NOT the true
    state at those times). STOPPED: the stop predicate (``MonteCarlo(stop=...)``, e.g.
    :class:`jaxcoag.mc.Runaway`) became true after an event at time ``MCResult.t_stop``; later
    snapshots repeat the stopped state (deliberately, NOT the true state at those times).
    """

    OK = 0
    CAPACITY = 1
    ZERO_RATE = 2
    NONFINITE = 4
    MAX_EVENTS = 8
    STOPPED = 16


_NAMES = ("CAPACITY", "ZERO_RATE", "NONFINITE", "MAX_EVENTS", "STOPPED")

# flag -> RESULTS item, highest priority first (a run with several flags reports the first)
_PRIORITY = (("NONFINITE", "nonfinite"), ("MAX_EVENTS", "max_steps_reached"), ("CAPACITY", "capacity_exceeded"),
             ("STOPPED", "stopped"), ("ZERO_RATE", "zero_rate"))


def flag_names(flags) -> list[str]:
    """Names of the bit flags set in an integer ``flags`` value (``[]`` means OK)."""
    flags = int(flags)
    return [n for n in _NAMES if flags & getattr(STATUS, n)]


def flags_to_code(flags):
    """Integer :class:`jaxcoag.RESULTS` code (int32, traceable, batched like ``flags``) of raw flags.

    One item by priority: nonfinite > max_steps_reached (MAX_EVENTS) > capacity_exceeded >
    stopped > zero_rate > successful.
    """
    from .._status import RESULT_NAMES

    flags = jnp.asarray(flags, jnp.int32)
    code = jnp.zeros(flags.shape, jnp.int32)
    for flag, item in reversed(_PRIORITY):
        code = jnp.where((flags & getattr(STATUS, flag)) != 0, jnp.int32(RESULT_NAMES.index(item)), code)
    return code


def log_n_particles(w, z, valid):
    """ln Np = ln Σ_i g_i, g_i = w_i 2^{z_i}, over the last axis (overflow-free logsumexp).

    References: Ormel (2008) eq. (5.9).
    """
    pos = valid & (w > 0)
    lg = jnp.where(pos, jnp.log(jnp.where(pos, w, 1.0)) + z.astype(w.dtype) * LN2, -jnp.inf)
    return jax.nn.logsumexp(lg, axis=-1)


def largest_two(logm, w, z, valid, kind: str = "particle"):
    """ln M_L1 and ln M_L2, the masses of the largest and second-largest particle [ln g].

    Arguments:
        logm, w, z, valid: species arrays (any leading axes; species on the last axis).
        kind: "particle" (default; MC hazard 12: if the largest species holds g ≥ 2 particles
            then M_L2 = M_L1) or "species" (largest and second-largest *species* mass, the
            thesis' "largest species/group" reading).

    Returns:
        (log_ML1, log_ML2); −inf where fewer than one (two) particles/species exist.

    References: Ormel (2008) thesis §5.3.2-5.3.3, Figs. 5.6/5.7; MC hazard 12 in docs/design_notes.md.
    """
    if kind not in ("particle", "species"):
        raise ValueError(f"unknown kind {kind!r}; use 'particle' or 'species'")
    lm = jnp.where(valid, logm, -jnp.inf)
    i1 = jnp.argmax(lm, axis=-1)
    l1 = jnp.take_along_axis(lm, i1[..., None], axis=-1)[..., 0]
    slot = jnp.arange(lm.shape[-1]).reshape((1,) * (lm.ndim - 1) + (lm.shape[-1],))
    others = jnp.where(slot == i1[..., None], -jnp.inf, lm)
    l2 = jnp.max(others, axis=-1)
    if kind == "particle":
        w1 = jnp.take_along_axis(w, i1[..., None], axis=-1)[..., 0]
        z1 = jnp.take_along_axis(z, i1[..., None], axis=-1)[..., 0]
        multi = jnp.isfinite(l1) & ((z1 > 0) | (w1 >= 2.0))
        l2 = jnp.where(multi, l1, l2)
    return l1, l2


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
    status: jax.Array  # (T,) int32 raw flags (STATUS) at the snapshot


class MCState(NamedTuple):
    """Complete loop carry of one run (all leaves are arrays; what a checkpoint stores).

    ``snaps`` is None between segments (the output buffers live only inside one advance).
    """

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
    log_rho_d: jax.Array  # ln of the dust mass density rho_d = M_tot / V at t0 [ln(g cm^-3)], kept by const_n/const_ns
    log_mlo: jax.Array    # ln of the lowest mass of the distribution-method bins [ln g]
    snaps: Snapshots | None
    # active prefix: every valid slot has index < hi (per-event work runs over blocks of [0, hi),
    # not over the capacity); ns = number of valid slots. Recomputed from ``valid`` at the start
    # of every segment and after maintenance (None in a hand-built state is filled in there).
    hi: jax.Array | None = None
    ns: jax.Array | None = None


# ----------------------------------------------------------------------------- initial states

class InitialSpecies(eqx.Module):
    """A custom initial population for ``jaxcoag.evolve(kernel, MonteCarlo(...), initial, ...)``;
    build it with :func:`initial_species`.

    Fields (Ns0 = number of initial species, P = structural parameters):
        m: (Ns0,) particle mass of each species [g].
        w: (Ns0,) group number (≥ 1); multiplicity g = w 2^z (eq. 5.8).
        z: (Ns0,) int32 zoom number (≥ 0).
        psi: (Ns0, P) structural parameters (P = 0: filled with the engine's monomer structure).
        V: simulated volume [cm^3], or None: then V = M_tot / rho_d.
        rho_d: dust mass density [g cm^-3] used when V is None (default 1).

    References: Ormel (2008) eq. (5.8), Table 5.4, App. 5.B.
    """

    m: jax.Array
    w: jax.Array
    z: jax.Array
    psi: jax.Array
    V: jax.Array | None = None
    rho_d: jax.Array | None = None


def initial_species(m, g=None, *, log_g=None, w=None, z=None, psi=None, V=None, rho_d=None) -> InitialSpecies:
    """Initial population of several species for ``jaxcoag.evolve(kernel, MonteCarlo(...), initial, t_out)``.

    Give the multiplicities in exactly one of three ways:

    * ``g``: number of physical particles per species (≥ 1); stored as w = g, z = 0 (with
      ``grouping=None`` this is the exact species DSMC, so g should be an integer ≤ 2^53);
    * ``log_g``: natural log of g (for g beyond 1.8e308, e.g. 1e400 monomers): stored as
      z = max(0, ⌊log2 g⌋ − 52), w = g / 2^z;
    * ``w`` and ``z``: the grouped representation g = w 2^z itself (w ≥ 1, integer z ≥ 0).
      With ``grouping=None`` these zooms are kept for the whole run (products get z = 0), which
      is how fixed-zoom tests such as the App. 5.A exactness check are set up; with a
      grouping method the first maintenance rezooms every species (g is kept exactly).

    Arguments:
        m: (Ns0,) particle masses [g] (> 0, finite).
        g, log_g, w, z: multiplicities, see above.
        psi: optional (Ns0, P) structural parameters (default: P = 0, filled in by the engine
            with ``MonteCarlo.struct0`` for a kernel with ``n_struct`` > 0).
        V: simulated volume [cm^3] (> 0). Default None: V = M_tot / rho_d, M_tot = Σ g m. In
            const_n / const_ns the controller keeps the mass density M_tot / V of the initial state.
        rho_d: dust mass density [g cm^-3] (> 0) that sets V when V is not given (default 1);
            give V or rho_d, not both.

    Returns:
        :class:`InitialSpecies`.

    References: Ormel (2008) eqs. (5.8)-(5.9), Table 5.4, App. 5.A.
    """
    if V is not None and rho_d is not None:
        raise JaxcoagInputError("initial_species: give either V= (simulated volume in cm^3) or rho_d= (dust mass "
                                "density in g cm^-3, V = M_tot / rho_d), not both")
    given = [x is not None for x in (g, log_g)] + [w is not None or z is not None]
    if sum(given) != 1:
        raise JaxcoagInputError("initial_species needs exactly one of g=, log_g= or (w=, z=) for the multiplicities")
    m = check(m, "m", positive=True, hint="give the particle mass of each species in g (> 0)")
    m = jnp.atleast_1d(m)
    if m.ndim != 1:
        raise JaxcoagInputError("initial_species: `m` must be a 1-D array (one mass per species)")
    n = m.shape[0]
    if g is not None:
        g = jnp.broadcast_to(check(g, "g", positive=True, hint="give the number of particles per species (>= 1)"), (n,))
        if not is_traced(g) and np.any(np.asarray(g) < 1):
            raise JaxcoagInputError("initial_species: every g must be >= 1 (a species holds at least one particle)")
        w_, z_ = g, jnp.zeros((n,), jnp.int32)
    elif log_g is not None:
        lg = jnp.broadcast_to(check(log_g, "log_g", nonnegative=True, hint="give ln g >= 0 per species"), (n,))
        z_ = jnp.maximum(jnp.floor(lg / LN2 + 1e-9) - 52.0, 0.0).astype(jnp.int32)
        w_ = jnp.exp(lg - z_.astype(lg.dtype) * LN2)
    else:
        if w is None or z is None:
            raise JaxcoagInputError("initial_species: give both w= and z= (g = w 2^z), or use g= / log_g=")
        w_ = jnp.broadcast_to(check(w, "w", positive=True, hint="give group numbers w >= 1"), (n,))
        zc = z if is_traced(z) else np.asarray(z)
        if not is_traced(z):
            if np.any(zc < 0) or np.any(zc != np.round(zc)) or np.any(zc > 1000):
                raise JaxcoagInputError("initial_species: z must be integers in [0, 1000] (zoom numbers)")
        if not is_traced(w_) and np.any(np.asarray(w_) < 1):
            raise JaxcoagInputError("initial_species: every w must be >= 1 (demagnify: use z - 1 and 2 w)")
        z_ = jnp.broadcast_to(jnp.asarray(zc).astype(jnp.int32), (n,))
    if psi is None:
        psi_ = jnp.zeros((n, 0), m.dtype)
    else:
        psi_ = check(psi, "psi", hint="give finite structural parameters, shape (n_species, P)")
        if psi_.ndim == 1:
            psi_ = psi_[:, None]
        if psi_.ndim != 2 or psi_.shape[0] != n:
            raise JaxcoagInputError(f"initial_species: psi must have shape ({n}, P); got {psi_.shape}")
    V_ = None if V is None else check(V, "V", positive=True, hint="give the simulated volume in cm^3 (> 0)")
    rho_ = None if rho_d is None else check(rho_d, "rho_d", positive=True, hint="give the dust mass density in g cm^-3 (> 0)")
    return InitialSpecies(m=m, w=jnp.asarray(w_, m.dtype), z=z_, psi=psi_, V=V_, rho_d=rho_)


# ----------------------------------------------------------------------------- stop predicates

class AbstractStop(eqx.Module):
    """A stop predicate for ``MonteCarlo(stop=...)``: ``__call__(state: MCState) -> bool``.

    It is evaluated on the state after every event (and on the initial state); when it returns
    True the run stops with status ``RESULTS.stopped``, ``MCResult.t_stop`` is the time of that event
    and later snapshots repeat the stopped state. Must be jittable and vmappable (no Python
    control flow on state values). Any plain function of the state works as well.
    """

    @abc.abstractmethod
    def __call__(self, state: MCState):
        """True where the run should stop."""


class Runaway(AbstractStop):
    """Runaway criterion: stop when M_L1/M_L2 ≥ ``ratio`` or a single particle is left.

    Arguments:
        ratio: threshold of the mass ratio of the largest to the second-largest particle
            (default 1e4, thesis §5.3.3). M_L2 is the *particle* statistic: if the largest
            species holds ≥ 2 particles then M_L2 = M_L1 (MC hazard 12).
        kind: "particle" (default) or "species" (second-largest *species*), see
            :func:`largest_two`.

    With it the runaway time t_R of Fig. 5.7 is ``MCResult.t_stop`` directly (for N = 300 the
    ratio is unreachable and the single-particle clause decides).

    References: Ormel (2008) thesis §5.3.3, Fig. 5.7; MC hazard 12 and the §5.3.3
    erratum in docs/design_notes.md.
    """

    log_ratio: jax.Array
    kind: str = eqx.field(static=True)

    def __init__(self, ratio=1e4, kind="particle"):
        if kind not in ("particle", "species"):
            raise JaxcoagInputError(f"Runaway: unknown kind {kind!r}; use 'particle' or 'species'")
        r = check(ratio, "ratio", positive=True, hint="give the runaway mass ratio M_L1/M_L2 (> 1, e.g. 1e4)")
        if not is_traced(r) and not float(r) > 1.0:
            raise JaxcoagInputError("Runaway: ratio must be a finite number > 1 (e.g. 1e4)")
        self.log_ratio = jnp.log(jnp.asarray(r, jnp.float64))  # an array leaf: other ratios (or a vmap over them) reuse the compiled run
        self.kind = kind

    def __call__(self, state: MCState):
        """True when ln M_L1 − ln M_L2 ≥ ln ratio (two or more particles) or Np ≤ 1."""
        l1, l2 = largest_two(state.logm, state.w, state.z, state.valid, self.kind)
        single = log_n_particles(state.w, state.z, state.valid) < 0.5 * LN2  # Np < sqrt(2), i.e. one particle
        return (jnp.isfinite(l2) & (l1 - l2 >= self.log_ratio)) | single
