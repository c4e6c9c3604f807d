"""The grouped Monte Carlo engine object ``MonteCarlo`` (Ormel & Spaans 2008) for ``jaxcoag.evolve``.

``jaxcoag.evolve(kernel, MonteCarlo(...), initial, t_out, key=key)`` runs the jitted event loop of
:mod:`jaxcoag.mc.run`. The numerical strategy is typed fields with defaults; structural choices are
classes, never strings:

* ``grouping``: ``None`` (exact species DSMC, eqs. 5.6/5.7), :class:`EqualMass` (eq. 5.14) or
  :class:`Distribution` (equal number of groups per log-mass bin, with the runaway refinements);
* ``volume``: :class:`ConstantVolume` (exact mass conservation), :class:`ConstantNumber` (one group
  duplicated per event, Smith & Matsoukas 1998) or :class:`ConstantSpecies` (duplication controller
  :class:`MassController` / :class:`SpeciesController`, thesis §2.3.2, §5.3.1);
* ``rates``: :class:`IncrementalRates` (O(S) per event, full refresh every ``n_refresh`` events) or
  :class:`FullRates` (O(S^2) recomputation every event).

Initial conditions: ``jaxcoag.Monodisperse(m0, rho_d)`` with ``n_particles`` physical particles in
the simulated volume V = n_particles m0 / rho_d; ``jaxcoag.mc.initial_species(...)``; or a previous
``MCResult``, which continues that run bitwise (event keys derive from the base key and the event
counter, all maintenance counters live in the state).

References: Ormel & Spaans (2008) ApJ 684, 1291 = Ormel (2008) thesis ch. 5, eqs. (5.6)-(5.14),
(5.31)-(5.33), App. 5.B; §2.3.2 (constant-N/Ns); Gillespie (1975); Smith & Matsoukas (1998).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._engine import LOOP_XLA_OPTIONS, AbstractEngine, AbstractResult, Monodisperse
from .._status import result_from_code
from .._validate import JaxcoagInputError, is_traced
from ..kernels import AbstractKernel
from . import run as _run
from .results import MCResult
from .state import STATUS, InitialSpecies, MCState, flags_to_code

__all__ = ["MonteCarlo", "EqualMass", "Distribution", "ConstantVolume", "ConstantNumber", "ConstantSpecies",
           "MassController", "SpeciesController", "IncrementalRates", "FullRates"]

LN2 = 0.6931471805599453


def _int_field(where, name, value, lo, what, allow_none=False):
    """Refuse a non-integer or too-small integer field with a message naming it."""
    if value is None and allow_none:
        return
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise JaxcoagInputError(f"{where}({name}=...) must be an integer >= {lo} ({what}); got {value!r}")
    if int(value) < lo:
        raise JaxcoagInputError(f"{where}({name}=...) must be >= {lo} ({what}); got {int(value)}")


def _number_field(where, name, value, *, lo, allow_none=False, inclusive=True, what="", below=None):
    """Refuse a non-finite or too-small number, or one not below ``below`` (traced values pass)."""
    if value is None and allow_none:
        return
    if is_traced(value):
        return
    try:
        v = float(np.asarray(value, np.float64))
        ok = np.ndim(value) == 0 and not isinstance(value, bool) and math.isfinite(v) and (v >= lo if inclusive else v > lo)
        ok = ok and (below is None or v < below)
    except (TypeError, ValueError):
        ok = False
    if not ok:
        rel = ">=" if inclusive else ">"
        upper = "" if below is None else f" and < {below:g}"
        raise JaxcoagInputError(f"{where}({name}=...) must be a finite number {rel} {lo:g}{upper}"
                                f"{' (' + what + ')' if what else ''}; got {value!r}")


# ----------------------------------------------------------------------------- structure classes

class EqualMass(eqx.Module):
    """Equal-mass grouping (thesis eq. 5.14): every species is zoomed so that one group carries
    about the mass m* (const-V: m* = M_tot / ns_target; const-N/Ns: m* = m_p = M2/M1).
    ``MonteCarlo.ns_target`` is the species target Ns*.

    Fields:
        merge_above: merge mass neighbours when the species count exceeds ``merge_above`` x Ns* (down to
            0.75 of that; default 2, thesis ch. 6), or None: only above 0.9 of the capacity (down to 0.7 S,
            the pre-issue-17 rule, with which the count drifts to ~7 Ns* at the default 8 Ns* capacity
            of that rule). Static.

    References: Ormel & Spaans (2008) §3.2, eq. (14) (thesis eq. 5.14); thesis ch. 6 (merging at 2 Ns*).
    """

    merge_above: float | None = eqx.field(static=True, default=2.0)

    def __check_init__(self):
        _number_field("EqualMass", "merge_above", self.merge_above, lo=1.0, inclusive=False, allow_none=True,
                      what="species per Ns* above which mass neighbours merge; None = at 0.9 capacity")


class Distribution(eqx.Module):
    """Distribution-method grouping: the same number of groups per log-mass bin
    (``MonteCarlo.ns_target`` = Ng*, the group target), with optional runaway refinements.

    Fields:
        n_bins: number of log-mass bins (default 20; static).
        m_lo: lowest mass of the bins [g] (default: the smallest initial particle mass).
        n_rezoom: global rezoom every ``n_rezoom`` events (default max(1, ns_target // 16); also
            whenever M_L1 changes by 2^(1/4); static).
        count_groups: G_c >= 1 of the tail-count refinement (``grouping.count_nodes``; None = off;
            static): the zoom becomes min(thesis z(m), log2(C(m)/G_c)), C(m) the number of particles
            at least as heavy as m, so that the steep seed tail of a runaway kernel keeps >~ G_c groups
            per species. It only lowers the thesis zoom. [own; docs/design_notes.md]
        tail_events: time-resolution cap of the zoom (``grouping.zoom_cap_tail``; 0 = off; static):
            every species gets at least ``tail_events`` expected group events per elapsed time t,
            w_i >= tail_events / (r_i t), at most ``tail_wmax`` groups (thesis §5.3.3 "t_11 << t_R" made
            automatic). Use with ``count_groups`` for K = (m_i m_j)^nu, nu > 1 (Fig. 5.7).
        tail_wmax: the largest number of groups per species the time cap may create (default
            ``ns_target``); runaway runs need tail_wmax >> tail_events / t_R.

    References: Ormel & Spaans (2008) §3.2 (distribution method); thesis §5.3.3, Fig. 5.7.
    """

    n_bins: int = eqx.field(static=True, default=20)
    m_lo: float | jax.Array | None = None
    n_rezoom: int | None = eqx.field(static=True, default=None)
    count_groups: float | None = eqx.field(static=True, default=None)
    tail_events: float = eqx.field(static=True, default=0.0)
    tail_wmax: float | jax.Array | None = None

    def __check_init__(self):
        _int_field("Distribution", "n_bins", self.n_bins, 1, "number of log-mass bins")
        _int_field("Distribution", "n_rezoom", self.n_rezoom, 1, "events between global rezooms", allow_none=True)
        _number_field("Distribution", "m_lo", self.m_lo, lo=0.0, inclusive=False, allow_none=True,
                      what="lowest bin mass in g")
        _number_field("Distribution", "count_groups", self.count_groups, lo=1.0, allow_none=True,
                      what="groups per species in the tail; None = off")
        _number_field("Distribution", "tail_events", self.tail_events, lo=0.0, what="0 = off")
        _number_field("Distribution", "tail_wmax", self.tail_wmax, lo=1.0, allow_none=True, what="groups")


class ConstantVolume(eqx.Module):
    """Constant simulated volume V (the default): exact mass conservation; the number of simulated
    particles falls as they coagulate. References: Ormel (2008) thesis §2.3.2, ch. 5."""


class ConstantNumber(eqx.Module):
    """Constant number of simulated particles: one group is duplicated after every event (V grows,
    V = M_tot / rho_d keeps the mass density). References: Smith & Matsoukas (1998); thesis §2.3.2."""


class MassController(eqx.Module):
    """Constant-Ns duplication controller: duplicate groups while M_tot < ns_target m_p (m_p = M2/M1),
    at most ``d_max`` per event (default with equal-mass grouping). References: thesis §5.3.1."""

    d_max: int = eqx.field(static=True, default=64)

    def __check_init__(self):
        _int_field("MassController", "d_max", self.d_max, 1, "the most duplications per event")


class SpeciesController(eqx.Module):
    """Constant-Ns duplication controller: ``d_up`` duplications after each event while the species
    count Ns < ns_target (default without equal-mass grouping). References: thesis §2.3.2, ch. 6."""

    d_up: int = eqx.field(static=True, default=2)

    def __check_init__(self):
        _int_field("SpeciesController", "d_up", self.d_up, 1, "duplications after each event")


class ConstantSpecies(eqx.Module):
    """Constant number of species/groups: a duplication controller keeps the count near
    ``MonteCarlo.ns_target`` (V = M_tot / rho_d keeps the mass density).

    Fields:
        controller: :class:`MassController` or :class:`SpeciesController`; None (default) picks the
            mass controller with ``EqualMass`` grouping, the species controller otherwise.

    References: Ormel (2008) thesis §2.3.2, §5.3.1, ch. 6.
    """

    controller: MassController | SpeciesController | None = None

    def __check_init__(self):
        if self.controller is not None and not isinstance(self.controller, (MassController, SpeciesController)):
            raise JaxcoagInputError(f"ConstantSpecies(controller=...) must be MassController(), SpeciesController() or "
                                    f"None (automatic); got {self.controller!r}")


class IncrementalRates(eqx.Module):
    """Incremental rate rows (design B): O(S) work per event, a full refresh every ``n_refresh``
    events (default: the capacity S; static). References: docs/design_notes.md (MC rate designs)."""

    n_refresh: int | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        _int_field("IncrementalRates", "n_refresh", self.n_refresh, 1, "events between full rate refreshes",
                   allow_none=True)


class FullRates(eqx.Module):
    """Full O(S^2) recomputation of the rate matrix every event (design A; a reference for tests)."""


# ----------------------------------------------------------------------------- helpers

def _default_outcome(outcome):
    from ..outcomes import Sticking

    return Sticking() if outcome is None else outcome


def _is_key(key):
    if isinstance(key, jax.Array) and jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
        return True
    return isinstance(key, jax.Array) and key.dtype == jnp.uint32 and key.shape[-1:] == (2,)


def _f(x):
    """Python/numpy ints -> float (check() casts int arrays lazily)."""
    return float(x) if isinstance(x, (int, np.integer)) and not isinstance(x, bool) else x


class MonteCarlo(AbstractEngine):
    """Grouped Monte Carlo engine (Ormel & Spaans 2008) for ``jaxcoag.evolve``.

    Fields (structure is a class or static field; numbers are leaves, so other values reuse the
    compiled run and may be vmapped):
        grouping: None (exact species DSMC), ``EqualMass()`` or ``Distribution(...)``.
        volume: ``ConstantVolume()`` (default), ``ConstantNumber()`` or ``ConstantSpecies(controller)``.
        ns_target: Ns* (equal-mass / constant-Ns) or Ng* (distribution); default 1000.
        n_particles: physical particles in the simulated volume at t0 for a ``Monodisperse`` start
            (may be 1e160; V = n_particles m0 / rho_d [cm^3]); required there, refused with
            ``initial_species`` (which gives its own multiplicities).
        f_eps: the largest fractional mass gain per group event (eq. 5.11), 0 < f_eps < 1; default 1e-3.
            From 1 on, N_eps = 0 for two groups of equal mass and one event merges whole equal-mass groups
            (refused: on the Golovin box of ``benchmarks/mc_accuracy_vs_time.py`` at Ns* = 256 the species
            count stayed at 13-23 and the L1 error of dm/dlnr was 1.5). There, f_eps = 0.1 was as accurate on
            the bulk of the mass as 1e-3 with ~8x fewer events, while larger values overestimated M2 (M2/M1 at
            3600 s, one run each: 1.3x Golovin's at 0.1, 1.7x at 0.5, 20x at 0.99); tails and runaway bodies
            need 1e-3 to 1e-4 (thesis ch. 5).
        capacity: species slots S (static). Default: grouping None: min(n_particles, 2048) + 8;
            EqualMass: 4 ns_target (the run merges mass neighbours above 2 Ns* species, thesis ch. 6);
            Distribution: 2 ns_target (at least 64). An equal-mass capacity that cannot hold Ns* species
            is refused (:func:`jaxcoag.mc.min_capacity`); a run that runs out of slots merges mass
            neighbours (status ``capacity_exceeded``, ``CapacityWarning``). The cost per event does not
            depend on the capacity (the event passes cover the occupied slots only, in blocks).
        max_events: event budget of the whole run (continuations included); when spent the status is
            ``max_steps_reached``.
        rates: ``IncrementalRates(n_refresh=None)`` (default) or ``FullRates()``.
        neps_rounding: "ceil" (default) or "floor" (thesis-literal) for N_eps (eq. 5.12; static).
        leftover: "demagnify" (thesis; exact) or "stochastic" (a donor left with 0 < w < 1 groups
            keeps one whole group with probability w, else is deleted: unbiased in expectation, stops
            the demagnify cascade of MC hazard 3; static).
        merge_weighting: "mass" (default), "number" (thesis formula) or "volume" (structure merging; static).
        dedupe: add a product to an existing identical species instead of a new slot (exact; static).
        p_protect: the most massive species never merged (default 16; static).
        struct0: (P,) structural vector of the monomers of a ``Monodisperse`` start (and of
            ``initial_species`` without psi); default: ones of ``kernel.n_struct`` (compact monomers,
            enlargement factor psi = V/V* = 1, thesis eq. 2.6; empty for compact kernels).
        stop: None or a stop predicate (``jaxcoag.mc.Runaway(1e4)``, any ``AbstractStop`` or jittable
            function of the ``MCState``), checked after every event: the run then ends with status
            ``stopped``, ``result.t_stop`` is the event time and later outputs repeat that state.

    Real-valued multiplicities (fragment counts of fragmenting outcomes, merged species) can leave a
    z = 0 species with less than one event removes (w < 1; 1 < w < 2 for its own pairs): its
    events are then partial, the fraction phi = w/dw it holds, with products scaled by phi and the
    pair rate divided by phi (mass exact, expected flux unchanged; ``jaxcoag.mc.rates``). Such
    fractional carriers persist, so fragmenting runs without grouping hold more species than
    particles: give such runs a ``capacity`` several times ``n_particles``.

    ``evolve`` result: :class:`jaxcoag.MCResult`. Not differentiable (discrete sampling); jit-compiled;
    batch over keys, kernel parameters or initial states with ``jax.vmap`` (``throw=False``); on a CPU
    backend the members of a vmapped batch run one after another in one compiled program, each as its
    single run would (bit for bit).

    References: Ormel & Spaans (2008) = Ormel (2008) thesis ch. 5, eqs. (5.6)-(5.14), (5.31)-(5.33),
    App. 5.B; §2.3.2; docs/design_notes.md (conventions and MC hazards).
    """

    grouping: EqualMass | Distribution | None = None
    volume: ConstantVolume | ConstantNumber | ConstantSpecies = ConstantVolume()
    ns_target: float | jax.Array = 1000.0
    n_particles: float | jax.Array | None = None
    f_eps: float | jax.Array = 1e-3
    capacity: int | None = eqx.field(static=True, default=None)
    max_events: int | jax.Array = 10**8
    rates: IncrementalRates | FullRates = IncrementalRates()
    neps_rounding: Literal["ceil", "floor"] = eqx.field(static=True, default="ceil")
    leftover: Literal["demagnify", "stochastic"] = eqx.field(static=True, default="demagnify")
    merge_weighting: Literal["mass", "number", "volume"] = eqx.field(static=True, default="mass")
    dedupe: bool = eqx.field(static=True, default=True)
    p_protect: int = eqx.field(static=True, default=16)
    struct0: jax.Array | None = None
    stop: Callable | None = None

    def __check_init__(self):
        w = "MonteCarlo"
        if self.grouping is not None and not isinstance(self.grouping, (EqualMass, Distribution)):
            raise JaxcoagInputError(f"MonteCarlo(grouping=...) must be None (species DSMC), jaxcoag.mc.EqualMass() or "
                                    f"jaxcoag.mc.Distribution(...); got {self.grouping!r}")
        if not isinstance(self.volume, (ConstantVolume, ConstantNumber, ConstantSpecies)):
            raise JaxcoagInputError(f"MonteCarlo(volume=...) must be jaxcoag.mc.ConstantVolume(), ConstantNumber() or "
                                    f"ConstantSpecies(); got {self.volume!r}")
        if not isinstance(self.rates, (IncrementalRates, FullRates)):
            raise JaxcoagInputError(f"MonteCarlo(rates=...) must be jaxcoag.mc.IncrementalRates() or FullRates(); "
                                    f"got {self.rates!r}")
        for name, allowed in (("neps_rounding", ("ceil", "floor")), ("leftover", ("demagnify", "stochastic")),
                              ("merge_weighting", ("mass", "number", "volume"))):
            if getattr(self, name) not in allowed:
                raise JaxcoagInputError(f"MonteCarlo({name}={getattr(self, name)!r}) is unknown; use one of {allowed}")
        if not isinstance(self.dedupe, (bool, np.bool_)):
            raise JaxcoagInputError(f"MonteCarlo(dedupe=...) must be True or False; got {self.dedupe!r}")
        _int_field(w, "p_protect", self.p_protect, 0, "the number of most massive species never merged")
        _int_field(w, "capacity", self.capacity, 1, "species slots, e.g. 4 * ns_target", allow_none=True)
        if not is_traced(self.max_events):
            me = self.max_events
            if isinstance(me, (jax.Array, np.ndarray)) and me.ndim == 0 and jnp.issubdtype(me.dtype, jnp.integer):
                me = int(me)
            _int_field(w, "max_events", me, 1, "the event budget")
        _number_field(w, "ns_target", self.ns_target, lo=0.0, inclusive=False, what="target number of species/groups")
        _number_field(w, "f_eps", self.f_eps, lo=0.0, inclusive=False, below=1.0,
                      what="a small fraction such as 1e-3; from 1 on, one event merges whole equal-mass groups")
        _number_field(w, "n_particles", self.n_particles, lo=0.0, inclusive=False, allow_none=True,
                      what="initial number of physical particles")
        if self.stop is not None and not callable(self.stop):
            raise JaxcoagInputError("MonteCarlo(stop=...) must be a jaxcoag.mc.AbstractStop (e.g. jaxcoag.mc.Runaway(1e4)) "
                                    "or a function of the state")
        if self.struct0 is not None and not is_traced(self.struct0):
            s = np.asarray(self.struct0, np.float64)
            if s.ndim != 1 or not np.all(np.isfinite(s)):
                raise JaxcoagInputError(f"MonteCarlo(struct0=...) must be a finite 1-D vector of structural parameters "
                                        f"(e.g. jnp.ones((1,)) for psi = 1); got shape {s.shape}")

    @property
    def name(self) -> str:
        return "mc"

    # ------------------------------------------------------------------ configuration

    def _grouping_name(self):
        if self.grouping is None:
            return None
        return "equal_mass" if isinstance(self.grouping, EqualMass) else "distribution"

    def _mode(self):
        return {ConstantVolume: "const_v", ConstantNumber: "const_n", ConstantSpecies: "const_ns"}[type(self.volume)]

    def _cfg(self, capacity, n_struct, n_snap, n_prod):
        """Static run configuration (``run._Cfg``) for the state's capacity and structure size."""
        grouping = self._grouping_name()
        ctl = self.volume.controller if isinstance(self.volume, ConstantSpecies) else None
        if ctl is None:
            ctl = MassController() if grouping == "equal_mass" else SpeciesController()
        dist = self.grouping if isinstance(self.grouping, Distribution) else Distribution()
        full = isinstance(self.rates, FullRates)
        if dist.n_rezoom is not None:
            n_rezoom = int(dist.n_rezoom)
        elif is_traced(self.ns_target):
            n_rezoom = 64
        else:
            n_rezoom = max(1, int(float(self.ns_target)) // 16)
        return _run._Cfg(
            mode=self._mode(), grouping=grouping, capacity=int(capacity), n_snap=int(n_snap), n_struct=int(n_struct),
            n_prod=int(n_prod), rates="full" if full else "incremental",
            n_refresh=1 if full else int(self.rates.n_refresh if self.rates.n_refresh is not None else capacity),
            rounding=self.neps_rounding, controller="mass" if isinstance(ctl, MassController) else "species",
            d_max=int(getattr(ctl, "d_max", MassController().d_max)), d_up=int(getattr(ctl, "d_up", SpeciesController().d_up)),
            n_bins=int(dist.n_bins), p_protect=int(self.p_protect), weighting=self.merge_weighting,
            dedupe=bool(self.dedupe), n_rezoom=n_rezoom, leftover=self.leftover, tail_events=float(dist.tail_events),
            count_zoom=math.log(float(dist.count_groups)) if dist.count_groups is not None else None,
            em_merge=float(self.grouping.merge_above) if isinstance(self.grouping, EqualMass)
            and self.grouping.merge_above is not None else None)

    def _params(self, kernel, outcome, t_seg):
        dist = self.grouping if isinstance(self.grouping, Distribution) else None
        ns = jnp.asarray(_f(self.ns_target), jnp.float64)
        tw = None if dist is None else dist.tail_wmax
        return dict(kernel=kernel, outcome=outcome, log2_feps=jnp.log2(jnp.asarray(_f(self.f_eps), jnp.float64)),
                    ns_target=ns, t_out=t_seg, max_events=jnp.asarray(self.max_events, jnp.int64), stop=self.stop,
                    tail_wmax=ns if tw is None else jnp.asarray(_f(tw), jnp.float64))

    def _struct0(self, kernel):
        ns = int(kernel.n_struct)
        if self.struct0 is None:
            return jnp.ones((ns,), jnp.float64)
        s = self.struct0 if is_traced(self.struct0) else jnp.asarray(self.struct0, jnp.float64)
        return s

    def _capacity(self, kernel, initial, n_prod):
        """Species slots S of a fresh run (refusing a capacity that cannot hold the start)."""
        grouping = self._grouping_name()
        n_init = 1 if isinstance(initial, Monodisperse) else int(initial.m.shape[0])
        cap = self.capacity
        if cap is None:
            if grouping is None:
                if isinstance(initial, Monodisperse):
                    n_p = self.n_particles
                else:
                    n_p = jnp.exp(jax.nn.logsumexp(jnp.log(initial.w) + initial.z.astype(jnp.float64) * LN2))
                if is_traced(n_p):
                    raise JaxcoagInputError("give MonteCarlo(capacity=...) when the initial particle numbers are traced "
                                            "(vmapped/jitted)")
                cap = max(int(min(float(n_p), 2048)) + 8, n_init + n_prod + 4)
            else:
                if is_traced(self.ns_target):
                    raise JaxcoagInputError("give MonteCarlo(capacity=...) when ns_target is traced (vmapped/jitted)")
                if grouping == "equal_mass":
                    f = 8.0 if self.grouping.merge_above is None else 2.0 * float(self.grouping.merge_above)
                    cap = int(f * float(self.ns_target))
                else:
                    cap = int(2 * float(self.ns_target))
                cap = max(cap, 64)
        cap = int(cap)
        if cap < n_prod + 4:
            raise JaxcoagInputError(f"MonteCarlo(capacity={cap}) is too small: give capacity >= {n_prod + 4}")
        if cap < n_init + n_prod + 2:
            raise JaxcoagInputError(f"MonteCarlo(capacity={cap}) cannot hold the {n_init} initial species; give "
                                    f"capacity >= {n_init + n_prod + 2}")
        if grouping == "equal_mass" and not is_traced(self.ns_target):
            # Ns* is a species count and the merge threshold a fraction of S: a smaller S would silently
            # cap the species count below ns_target (a coarser run than asked for); refuse instead. (With
            # Distribution ns_target = Ng* counts groups, not species; there the capacity is the documented
            # species cap min(0.9 S, Ng*), e.g. Fig. 5.7 runs Ng* = 2000 in S = 1024 slots.)
            s_min = _run.min_capacity("equal_mass", float(self.ns_target), int(n_prod))
            if cap < s_min:
                raise JaxcoagInputError(
                    f"MonteCarlo(capacity={cap}) species slots cannot hold ns_target = {float(self.ns_target):g} "
                    f"equal-mass species (the run merges species above ~0.9 capacity, which would silently lower the "
                    f"resolution); give capacity >= {s_min} (the default is 4 x ns_target) or lower ns_target")
        return cap

    # ------------------------------------------------------------------ protocol

    def _check(self, kernel, initial, t_out, t0, outcome, key):
        if not isinstance(kernel, AbstractKernel):
            raise JaxcoagInputError("kernel must be a jaxcoag.kernels.AbstractKernel (e.g. jaxcoag.kernels.Constant(1.0))")
        from ..outcomes import AbstractOutcome

        outcome = _default_outcome(outcome)
        if not isinstance(outcome, AbstractOutcome):
            raise JaxcoagInputError(f"outcome must be a collision outcome from jaxcoag.outcomes (e.g. "
                                    f"jaxcoag.outcomes.Sticking()) or None; got {type(outcome).__name__}")
        outcome.check(kernel, "mc")
        n_prod = int(outcome.n_products)
        if key is not None and not _is_key(key):
            raise JaxcoagInputError(f"key must be a jax.random key such as jax.random.key(0); got {type(key).__name__} {key!r}")
        if isinstance(initial, AbstractResult):
            self._check_continuation(initial, key)
            return
        if key is None:
            raise JaxcoagInputError("give key=, a jax.random key (e.g. jax.random.key(0)): the Monte Carlo engine samples "
                                    "its events from it")
        struct0 = self._struct0(kernel)
        if not is_traced(struct0):
            if struct0.ndim != 1 or struct0.shape[0] < int(kernel.n_struct):
                raise JaxcoagInputError(f"the kernel reads {int(kernel.n_struct)} structural parameters; give "
                                        f"MonteCarlo(struct0=...) with that many entries")
        if isinstance(initial, Monodisperse):
            if self.n_particles is None:
                raise JaxcoagInputError("a Monodisperse start needs MonteCarlo(n_particles=...), the number of physical "
                                        "particles in the simulated volume (e.g. 1e4; up to 1e160 with grouping)")
            n_p, m0 = _f(self.n_particles), _f(initial.m0)
            if not is_traced(n_p) and not is_traced(m0):
                if float(n_p) * float(m0) >= 1e300:
                    raise JaxcoagInputError("n_particles * m0 must stay below 1e300 g (float64 range); reduce "
                                            "MonteCarlo(n_particles=...)")
                if self.grouping is None and float(n_p) > 2.0 ** 53:
                    raise JaxcoagInputError("grouping=None needs n_particles <= 2^53 (integer multiplicities); use "
                                            "MonteCarlo(grouping=jaxcoag.mc.EqualMass()) or Distribution()")
        elif isinstance(initial, InitialSpecies):
            if self.n_particles is not None:
                raise JaxcoagInputError("MonteCarlo(n_particles=...) sets a Monodisperse start; initial_species(...) gives "
                                        "its own multiplicities: drop n_particles")
            P0 = int(initial.psi.shape[-1])
            if 0 < P0 < int(kernel.n_struct):
                raise JaxcoagInputError(f"the kernel reads {int(kernel.n_struct)} structural parameters; give "
                                        "initial_species(psi=...) with that many columns")
            lg0 = jnp.log(initial.w) + initial.z.astype(jnp.float64) * LN2
            logM0 = jax.nn.logsumexp(lg0 + jnp.log(initial.m))
            if not is_traced(logM0) and float(logM0) >= math.log(1e300):
                raise JaxcoagInputError("initial_species: the total mass sum(g m) must stay below 1e300 g (float64 range)")
        else:
            raise JaxcoagInputError(f"initial must be jaxcoag.Monodisperse(m0, rho_d), jaxcoag.mc.initial_species(...) or "
                                    f"an MCResult to continue; got {type(initial).__name__}")
        self._capacity(kernel, initial, n_prod)

    def _check_continuation(self, initial, key):
        if not isinstance(initial, MCResult):
            raise JaxcoagInputError(f"initial is a {type(initial).__name__}: a MonteCarlo run continues only an MCResult "
                                    "(or starts from Monodisperse / initial_species)")
        st = initial.final_state
        if not (isinstance(st, MCState) and st.snaps is None):
            raise JaxcoagInputError("initial is an MCResult without final_state (built by hand?): continue a result "
                                    "returned by jaxcoag.evolve")
        if jnp.ndim(st.t) != 0:
            raise JaxcoagInputError("initial holds a batch of results (from a vmapped run); continue inside jax.vmap "
                                    "or index one member with jax.tree_util.tree_map(lambda x: x[i], result)")
        S = int(st.m.shape[-1])
        if self.capacity is not None and int(self.capacity) != S:
            raise JaxcoagInputError(f"the continued run has capacity {S}; use MonteCarlo(capacity={S}) or None")
        if key is not None and not is_traced(key) and not is_traced(st.key):
            kd = lambda k: np.asarray(jax.random.key_data(k) if jax.dtypes.issubdtype(k.dtype, jax.dtypes.prng_key) else k)  # noqa: E731
            if not np.array_equal(kd(key), kd(st.key)):
                raise JaxcoagInputError("key differs from the continued run's key; pass the same key or key=None")

    def _init(self, kernel, initial, t0, outcome, key):
        if isinstance(initial, MCResult):
            return initial.final_state
        outcome = _default_outcome(outcome)
        n_prod = int(outcome.n_products)
        cap = self._capacity(kernel, initial, n_prod)
        struct0 = self._struct0(kernel)
        dist = self.grouping if isinstance(self.grouping, Distribution) else None
        ns_target = jnp.asarray(_f(self.ns_target), jnp.float64)
        if isinstance(initial, Monodisperse):
            m0 = jnp.asarray(_f(initial.m0), jnp.float64)
            log_mlo = jnp.log(m0)
            if dist is not None and dist.m_lo is not None:
                log_mlo = jnp.log(jnp.asarray(_f(dist.m_lo), jnp.float64))
            cfg = self._cfg(cap, struct0.shape[0], 1, n_prod)
            return _run._monodisperse_state(cfg, jnp.asarray(_f(self.n_particles), jnp.float64), m0,
                                            jnp.log(jnp.asarray(_f(initial.rho_d), jnp.float64)), ns_target, struct0,
                                            key, t0, log_mlo)
        init = initial
        P0 = int(init.psi.shape[-1])
        if P0 == 0 and struct0.shape[0] > 0:
            init = eqx.tree_at(lambda x: x.psi, init, jnp.broadcast_to(struct0, (init.m.shape[0], struct0.shape[0])))
        lg0 = jnp.log(init.w) + init.z.astype(jnp.float64) * LN2
        logM = jax.nn.logsumexp(lg0 + jnp.log(init.m))
        if init.V is not None:
            log_rho_d = logM - jnp.log(init.V)
        else:
            log_rho_d = jnp.log(jnp.asarray(1.0 if init.rho_d is None else init.rho_d, jnp.float64))
        log_mlo = jnp.min(jnp.log(init.m))
        if dist is not None and dist.m_lo is not None:
            log_mlo = jnp.log(jnp.asarray(_f(dist.m_lo), jnp.float64))
        cfg = self._cfg(cap, init.psi.shape[-1], 1, n_prod)
        return _run._species_state(cfg, init, log_rho_d, ns_target, key, t0, log_mlo)

    def _advance(self, kernel, state, t_seg, outcome):
        outcome = _default_outcome(outcome).bind(kernel)
        t_seg = t_seg if is_traced(t_seg) else jnp.asarray(t_seg, jnp.float64)
        cfg = self._cfg(state.m.shape[-1], state.psi.shape[-1], t_seg.shape[0], outcome.n_products)
        p = self._params(kernel, outcome, t_seg)
        st, sn = (_advance_jit if is_traced((p, state)) else _advance_top)(cfg, p, state)
        outs = {"m": sn.m, "logm": sn.logm, "psi": sn.psi, "w": sn.w, "z": sn.z, "valid": sn.valid, "logV": sn.logV,
                "M_tot": sn.M_tot, "n_events": sn.n_events, "flags": sn.status, "status": flags_to_code(sn.status)}
        return st, outs

    def _progress_info(self, state_before, state_after, out, wall_s):
        """Progress-bar figures of one segment: events executed, events per second, species count."""
        n_ev = int(state_after.n_events) - int(state_before.n_events)
        rate = n_ev / wall_s if wall_s > 0 else float("inf")
        return f"{n_ev} events ({rate:.3g}/s), Ns = {int(np.sum(np.asarray(state_after.valid)))}"

    def _result(self, kernel, t, outs, state, outcome):
        outcome = _default_outcome(outcome)
        cfg = self._cfg(state.m.shape[-1], state.psi.shape[-1], 1, outcome.n_products)
        flags = state.status
        t_stop = jnp.where((flags & STATUS.STOPPED) != 0, state.t, jnp.nan)
        res = MCResult(t=jnp.asarray(t, jnp.float64), m=outs["m"], logm=outs["logm"], psi=outs["psi"], w=outs["w"],
                       z=outs["z"], valid=outs["valid"], V=jnp.exp(outs["logV"]), logV=outs["logV"], M_tot=outs["M_tot"],
                       n_events_snap=outs["n_events"], status=result_from_code(flags_to_code(flags)), flags=flags,
                       n_events=state.n_events, n_dup=state.n_dup, n_merge=state.n_merge, t_stop=t_stop,
                       rho_d=jnp.exp(state.log_rho_d), final_state=state,
                       config=_run._config_pairs(cfg, dict(kernel=kernel, outcome=outcome, stop=self.stop)))
        # out of species slots (emergency merge) lowers the resolution: say so. Inside the user's
        # jit/vmap the item is in res.status only (failures are values): a host callback there would be
        # unrolled once per vmapped lane (a 2e4-lane vmap then never finished compiling).
        if not is_traced(flags):
            _run._warn_capacity(flags, cfg.capacity)
        return res


def _simulate_members(cfg, p, state):
    """``run._simulate``; under ``jax.vmap`` on a CPU backend the members run one after another (``lax.map``).

    A batched event loop runs every member until the slowest is done and evaluates both branches of every
    ``lax.cond`` its batched predicates reach, with gathers and scatters at per-member slots: an 8-seed ensemble
    ran at ~0.5x the throughput of a loop of single runs on 2 CPU cores. A CPU event is mostly work (rate entries),
    not dispatch, so batching has little to amortise there; the members run as single runs inside one compiled
    program instead (same results as single runs, bit for bit). On GPU/TPU backends the batched loop is kept.
    """
    if jax.default_backend() != "cpu":
        return _run._simulate(cfg, p, state)
    dyn, static = eqx.partition((p, state), eqx.is_array)
    # no derivative flows through the sampling (the outputs are stop_gradient-ed in _advance_impl); stopping it at
    # the inputs as well keeps jax.grad / jax.jvp of a program that contains a run working (zero derivatives)
    dyn = jax.tree_util.tree_map(lambda x: jax.lax.stop_gradient(x) if eqx.is_inexact_array(x) else x, dyn)

    @jax.custom_batching.custom_vmap
    def sim(dyn):
        p_, st_ = eqx.combine(dyn, static)
        return _run._simulate(cfg, p_, st_)

    @sim.def_vmap
    def _members(axis_size, in_batched, dyn):
        (batched,) = in_batched
        leaves, treedef = jax.tree_util.tree_flatten(dyn)
        flags = jax.tree_util.tree_leaves(batched)

        def one(member_leaves):
            it = iter(member_leaves)
            return sim(jax.tree_util.tree_unflatten(treedef, [next(it) if b else x for x, b in zip(leaves, flags)]))

        out = jax.lax.map(one, [x for x, b in zip(leaves, flags) if b])
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return sim(dyn)


def _advance_impl(cfg, p, state):
    st, sn = _simulate_members(cfg, p, state)
    sg = lambda x: jax.lax.stop_gradient(x) if eqx.is_inexact_array(x) else x  # noqa: E731 - discrete sampling
    return jax.tree_util.tree_map(sg, st), jax.tree_util.tree_map(sg, sn)


_advance_jit = eqx.filter_jit(_advance_impl)
#: XLA options of the top-level event loop: LOOP_XLA_OPTIONS (code motion had moved capacity-sized work of the event
#: loop's rarely taken branches into the loop; CPU, Ns* = 100, to t = 5, two probes each: 89-93 against 53-54 us
#: per event at capacity 12 800, 31-65 against 28-39 at 150), and without the CPU parallel-task assigner, which
#: split the event's block fusions (128-512 slots, a few us each) over the threads: their hand-offs cost more than
#: the split work saves (constant-Ns sum kernel, Ns* = 2000, same events: 76 -> 52 us per event to t = 5,
#: 203 -> 153 to t = 12; docs/design_notes.md, "The MC maintenance sorted the empty slots; ...").
MC_XLA_OPTIONS = {"xla_disable_hlo_passes": LOOP_XLA_OPTIONS["xla_disable_hlo_passes"] + ",cpu-parallel-task-assigner"}
_advance_top = eqx.filter_jit(_advance_impl, compiler_options=MC_XLA_OPTIONS)
