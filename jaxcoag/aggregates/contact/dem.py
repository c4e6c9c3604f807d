"""Discrete-element integrator of monomer aggregates: contacts, neighbour search and the leapfrog step.

Monomers are identical spheres (radius r1, mass m_1, moment of inertia I = (2/5) m_1 r1^2 of a
:class:`~jaxcoag.aggregates.contact.materials.Material`) that interact only through contacts: the JKR normal
force and the sliding, rolling and twisting springs of Wada et al. (2007) (``interactions.contact_forces``), with
the inelastic clipping of their eqs. 39-43 (``interactions.clip_inelastic``).

State (:class:`DEMState`, fixed capacity, every field an array so that it checkpoints and vmaps):

* positions ``x``, velocities ``v``, angular velocities ``w`` (N, 3) [cm, cm/s, rad/s] and the force ``F`` [dyn] and
  torque ``M`` [dyn cm] of the current configuration; planar (2-D) runs keep z = 0 and w parallel to z by the
  symmetry of the forces (nothing is projected);
* a flat contact list (C-layout of the spec, Part C) of C = capacity x N slots: slot k holds the pair
  ``ci[k] < cj[k]`` (``active[k]``) with the space-frame contact pointers ``n_i``, ``n_j`` (unit vectors fixed in
  the bodies, Wada et al. 2007 eqs. 28-29, rotated exactly at each drift) and the twisting angle ``phi`` (eq. 24:
  phi = phi_s n_c); new contacts take the lowest free slots. Every per-contact pass is O(C) = O(N): a monomer
  aggregate has about one contact per monomer, so a list of 2 (2-D) or 3 (3-D) slots per monomer is 3-4x
  shorter than a table of the largest coordination per monomer (6 / 12 slots, the layout before), and that
  length is what a step costs (docs/design_notes.md, "DEM contact layout"). Since new contacts take the lowest
  free slots, the used slots stay a prefix of the list: each block of steps (256 in the forward loops, a chunk
  of :func:`integrate`) processes the smallest prefix (1.25 N, 1.625 N, 2 N or C) that holds them with room for
  the block's new contacts (:func:`_steps`), so a tree-like aggregate costs ~1.25 N slots per step whatever the
  capacity;
* a Verlet neighbour list ``nbr`` (N, K_nb) of partners j > i within 2 r1 + skin (skin = 0.1 r1 by default),
  rebuilt inside ``lax.cond`` when a monomer has moved more than skin/2 since the last build (under ``jax.vmap``
  the branch runs when any member needs it and is selected per member, so it stays a branch); the build is a
  cell list (cell side = the cutoff, a sort of the cell keys and a ``searchsorted`` per neighbour cell:
  O(N log N), no N^2 step);
* the energy ledger: potential energies ``U`` = (U_n, U_s, U_r, U_t) at the current configuration and the
  dissipated energies ``E_dis`` = (E_dis,n, E_dis,s, E_dis,r, E_dis,t) [erg];
* ``flags`` (bit 1: contact list full, 2: neighbour list or cell full, 4: non-finite state), step counter and
  contact-event counters.

Leapfrog step (Wada et al. 2007 §4, eqs. 46-47; kick-drift-kick): half kick v += dt F/(2 m_1),
w += dt M/(2 I); drift x += dt v, pointers rotated by w dt, phi_s += dt (w_i - w_j).n_c; contact breaking at
delta < -delta_c, creation at delta >= 0 (§2.1), inelastic clipping (eqs. 39-43, the exact potential drop booked
per channel); forces and torques; second half kick. With forces and torques taken at one configuration the step
conserves the total momentum and angular momentum sum(m x x v + I w) to round-off (eqs. 18-19 and the
rolling/twisting pair sums).

Energy ledger of contact events. The paper books the jumps of U_n: E_dis,n += -U_n(delta) at creation and
U_n(-delta_c) at breaking, plus the spring energies of a broken contact (§2.1). In the leapfrog the kinetic energy
changes over a step by (1/2)(F_old + F_new).dx (+ a telescoping O(dt^2) term), so a contact that exists at only
one end of a step also changes E_kin by half its work, (1/2)[F.(dx_i - dx_j) + M_i.dth_i + M_j.dth_j] (an
O(v dt F_c) amount per event: ~0.016 F_c delta_c for two ice monomers meeting at 2.5 v_0). The ledger books that
work too (normal channel): at creation E_dis,n += -U_n(delta) - W_new, at breaking the contact's energies at the
last step (U_n to E_dis,n, U_s, U_r, U_t to their channels) minus the work W_old of its last half kick. So
E_kin + U + sum E_dis is conserved to the integrator's smooth O(dt^2) error, events included, and E_dis is what
the dynamics dissipated.

Event times (``event_times=True``, the default). Events are detected at whole steps, but the JKR force jumps at
both of them (F(0) = -8/9 F_c at creation, F(-delta_c) = -5/9 F_c at breaking, eq. 5), so without a correction
the impulse of a contact would start or stop at the step after the event: an O(F_c dt) error of the momentum
transfer (the rebound speed of two monomers, sqrt(v^2 - 3.742 v_0^2) for exact events, would carry an O(v dt)
error, and the trajectory would jump by ~F_c dt/m_1 whenever a parameter moves an event across a step, leaving
the derivative with respect to the material constants without the event-time term). The leapfrog is a position
Verlet with the impulse dt F(x_k) at each configuration x_k (the two half kicks around it), i.e. the contact's
impulse is credited from t_k - dt/2. In the step from x_{k-1} to x_k where an event is detected, the instant
t_{k-1} + theta dt of the crossing (delta = 0 or -delta_c) is found by linear interpolation of delta between
the two configurations (differentiable in the positions and, through delta_c, in the material), and the normal
force jump F_e gets two correction impulses, at x_k and at x_{k+1}:
    creation:  dt F_e (1 - 3 theta)/2 at x_k,   dt F_e theta/2 at x_{k+1}
    breaking:  dt F_e (3 theta - 1)/2 at x_k,   -dt F_e theta/2 at x_{k+1},
plus at breaking (1 - theta) Z at x_k and theta Z at x_{k+1}, Z = -dt c F_c ((delta_{k-1} - delta_k)/delta_0)^(1/2)
zeta(-1/2, theta) (c = -4 6^(-1/3) (2/9)^(1/2), F - F(-delta_c) = c F_c ((delta + delta_c)/delta_0)^(1/2) + ...,
eqs. 4-5), which removes the sqrt cusp of the samples dt F(delta_j) before the breaking (see Differentiability).
Their sum moves the contact's impulse to start (end) at the event instant, and at the edges (theta = 0, 1) they
cancel the impulse dt F_e of the configuration at which the other event step would have sampled the contact,
so the map from the parameters to the trajectory is continuous when an event moves by a step (positions too,
not only the total impulse). Each impulse acts along the line of centres of the configuration where it is
applied, equal and opposite on the two monomers: P and L are conserved to round-off and no torque is involved.
The tangential springs are zero at creation; at breaking their force and torques (sliding, rolling, twisting) stop
at the same instant and get the same two corrections, F_t and M_1 of the last configuration in contact, with the
torque on the second monomer set to -M_1 - (x_i - x_j) x F_t where it is applied (P and L exact; ``DEMState.Me``,
``ev_t``). The work of the corrections, (1/2) (Fe.dx + Me.dth) in each half kick, is booked in E_dis,n, so the
ledger stays closed. The correction runs inside a ``lax.cond`` taken only on steps with an event or a pending
correction.

Entry points: :func:`init_state` (contacts of every pair with delta >= 0), :func:`step`, :func:`integrate` (a
fixed-length ``lax.scan`` over chunks of steps, each chunk under ``jax.checkpoint``: reverse-mode differentiable
with respect to the material leaves, positions and velocities), :func:`integrate_until` (a ``lax.while_loop``
over chunks with a stop predicate; forward mode only) and :func:`diagnostics`.

Differentiability: forces, torques and the drift are smooth; clipping behaves like ``max``; contact creation and
breaking, and the neighbour list, are discrete (zero gradient through the event masks), but with the event-time
correction the event instants enter through theta, so the derivative of the trajectory includes the motion of
the events (the normal-force jump times d t_event/d parameter) and the discrete map is continuous across event-step
changes: the AD derivative converges to the derivative of the continuous dynamics as dt -> 0. Measured for two ice
monomers head-on at 3 v_0 (tests/test_contact_gradients.py): d v_out/d ln gamma = -1.36089 v_0 at dt = 0.014 t_c and
-1.36037 v_0 at dt/2 against the analytic -1.35992 v_0 (reverse = forward mode; without the correction -0.73 v_0,
and v_out(gamma) jumped by F(-delta_c) dt/(m_1/2) = 0.0156 v_0 at each change of the breaking step, now <= 1 % of
that); v_out itself is 7.6e-5 from sqrt(v^2 - 3.742 v_0^2) (-7.8e-3 without). Both normal-force events are
corrected; so is the sqrt cusp of the force samples just before a breaking (F(delta) - F(-delta_c) ∝ (delta +
delta_c)^(1/2), the vertical tangent: their sum differs from the integral of the force by a Hurwitz-zeta
function of theta, ``_hurwitz_zeta_m_half``, which the breaking correction removes, so the derivative has no
1/theta^(1/2) spikes).

References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007, ApJ 661, 320) eqs. 1-47, §2.1 (contact life cycle),
§4 (integration, dt = 0.014 t_c); Allen & Tildesley (1987) §5.3 (Verlet lists and cell lists).
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._validate import JaxcoagInputError, is_traced
from .interactions import (_cross, _dot, _norm, clip_inelastic, contact_forces, contact_geometry, rotate_by,
                           rotation_coefficients)

__all__ = ["DEMState", "init_state", "step", "integrate", "integrate_until", "diagnostics", "flags_code",
           "FLAG_CONTACTS", "FLAG_NEIGHBOURS", "FLAG_NONFINITE", "default_capacity", "max_capacity",
           "default_neighbours"]

#: ``DEMState.flags`` bit: the contact list (capacity x N slots) was full.
FLAG_CONTACTS = 1
#: ``DEMState.flags`` bit: a neighbour-list row or a cell of the cell list was full (pairs may be missed).
FLAG_NEIGHBOURS = 2
#: ``DEMState.flags`` bit: a position or velocity became NaN/inf.
FLAG_NONFINITE = 4


def default_capacity(dim: int) -> int:
    """Contact slots per monomer (the list holds capacity x N contacts): 2 in 2-D and 3 in 3-D.

    A ballistic aggregate has N - 1 contacts (one per monomer); the densest packings of equal spheres hold 3
    (2-D, hexagonal) and 6 (3-D, fcc) contacts per monomer, random close packing ~3 (coordination ~6). A run
    that needs more stops with status ``capacity_exceeded`` (raise ``capacity``)."""
    return 2 if dim == 2 else 3


def max_capacity(dim: int) -> int:
    """Contact slots per monomer that no packing of equal spheres exceeds: 3 in 2-D (hexagonal) and 6 in 3-D (fcc);
    ``contact.collide`` reruns with it when the default list overflows."""
    return 3 if dim == 2 else 6


def default_neighbours(dim: int) -> int:
    """Neighbour-list slots per monomer (partners j > i within 2 r1 + skin): 8 in 2-D and 16 in 3-D (13 equal
    spheres fit within 2.09 r1 of a sphere in 3-D, 6 within 2.3 r1 in 2-D)."""
    return 8 if dim == 2 else 16


def _cell_occupancy(dim: int) -> int:
    """Slots per cell of the cell list (cell side 2.1 r1): 6 in 2-D and 12 in 3-D (4 and 8 fit without overlap)."""
    return 6 if dim == 2 else 12


class DEMState(eqx.Module):
    """State of a monomer DEM run (fixed capacity; every field an array).

    Fields:
        x, v, w: (N, 3) positions [cm], velocities [cm s^-1], angular velocities [rad s^-1].
        F, M: (N, 3) total contact force [dyn] and torque [dyn cm] at ``x`` (for the next half kick).
        ci, cj: (C,) int32 the two monomers of each contact slot, ci < cj (N = empty slot); C = capacity x N.
        active: (C,) bool, slot holds a contact.
        n_i, n_j: (C, 3) contact pointers of monomers ci and cj (unit vectors, space frame).
        phi: (C,) twisting angle phi_s [rad] (Wada et al. 2007 eq. 24).
        nbr: (N, K_nb) int32 Verlet neighbours j > i of i (N = empty).
        x_ref: (N, 3) positions at the last neighbour-list build [cm].
        U: (4,) potential energies (U_n, U_s, U_r, U_t) of all contacts at ``x`` [erg].
        E_dis: (4,) dissipated energies (normal, sliding, rolling, twisting) since the start [erg].
        Fe: (N, 3) event-time correction at ``x`` [dyn]: the correction impulses due at this configuration over dt
            (module docstring, "Event times"), applied with ``F`` in the two half kicks around ``x``.
        Me: (N, 3) event-time correction of the torques at ``x`` [dyn cm] (tangential springs of broken contacts).
        ev_f, ev_i, ev_j: (2C,) correction due at the next configuration, per slot (breakings, then creations): the
            normal force on monomer ev_i [dyn] (impulse over dt, along n_c of that configuration; -ev_f on ev_j)
            and the pair (N = none).
        ev_t: (C, 6) the tangential part of the correction due at the next configuration, per breaking slot (the
            pairs of ev_i[:C], ev_j[:C]): force on ev_i [dyn] (-it on ev_j) and torque on ev_i [dyn cm] (the torque
            on ev_j is set there so that the angular momentum is exact).
        axes: (dim,) bool, its length is the dimension of the run (2: planar, 3) and so a static shape.
        step: int64, steps taken since the start; t = t0 + step dt.
        t0: float64, time of the start [s].
        flags: int32, ``FLAG_CONTACTS | FLAG_NEIGHBOURS | FLAG_NONFINITE`` bits.
        n_events: int64, contact creations + breakings since the start.
        first_event: int64, step of the first creation or breaking (-1: none yet).
        last_event: int64, step of the latest creation or breaking (-1: none yet).
        n_builds: int64, neighbour-list builds since the start.
        cand_i, cand_j: (K_c,) int32 the neighbour pairs i < j that are not contacts (N = empty), compacted
            (:func:`_candidates`): the pairs that can form a contact, which the step tests for touching.
        cand_full: bool, more such pairs than K_c (the step then runs the creation search on every step until the
            next neighbour-list build).
    """

    x: jax.Array
    v: jax.Array
    w: jax.Array
    F: jax.Array
    M: jax.Array
    ci: jax.Array
    cj: jax.Array
    active: jax.Array
    n_i: jax.Array
    n_j: jax.Array
    phi: jax.Array
    nbr: jax.Array
    x_ref: jax.Array
    U: jax.Array
    E_dis: jax.Array
    Fe: jax.Array
    Me: jax.Array
    ev_f: jax.Array
    ev_i: jax.Array
    ev_j: jax.Array
    ev_t: jax.Array
    axes: jax.Array
    step: jax.Array
    t0: jax.Array
    flags: jax.Array
    n_events: jax.Array
    first_event: jax.Array
    last_event: jax.Array
    n_builds: jax.Array
    cand_i: jax.Array
    cand_j: jax.Array
    cand_full: jax.Array

    @property
    def dim(self) -> int:
        """2 (planar) or 3 (static: the length of ``axes``)."""
        return int(self.axes.shape[-1])


class _Cfg(NamedTuple):
    """Static options of the step."""

    dim: int
    inelastic: bool
    freeze: bool
    events: bool



# ------------------------------------------------------------------------------------------------- batching
@jax.custom_batching.custom_vmap
def _any_member(pred):
    """``pred`` (bool scalar), reduced with ``any`` over every ``jax.vmap`` batch axis: the predicate of a
    ``lax.cond`` that stays a real branch (skipped work) under ``vmap``, where a batched predicate turns the cond
    into a select that evaluates both branches for every member. The branch taken then selects per member."""
    return pred


@_any_member.def_vmap
def _any_member_vmap(axis_size, in_batched, pred):
    (batched,) = in_batched
    return _any_member(jnp.any(pred, axis=0) if batched else pred), False


@jax.custom_batching.custom_vmap
def _max_member(index):
    """``index`` (int scalar), reduced with ``max`` over every ``jax.vmap`` batch axis (the branch index of a
    ``lax.switch`` whose higher branches also serve the lower cases, kept unbatched as in :func:`_any_member`)."""
    return index


@_max_member.def_vmap
def _max_member_vmap(axis_size, in_batched, index):
    (batched,) = in_batched
    return _max_member(jnp.max(index, axis=0) if batched else index), False


def _cond_members(pred, true_fn, false_fn, operand):
    """``lax.cond(pred, true_fn, false_fn, operand)`` with the same result per member under ``jax.vmap``, but
    ``true_fn`` runs only when some member's ``pred`` is True (then selected per member against ``false_fn``: the
    inner ``cond`` on the batched ``pred`` is a select of both branches under ``vmap``, and a plain branch
    without it, where a select of the two branches' results cost a pass over every output)."""
    return jax.lax.cond(_any_member(pred), lambda op: jax.lax.cond(pred, true_fn, false_fn, op), false_fn, operand)


# ------------------------------------------------------------------------------------------------- geometry
def _gather(a, idx):
    """Rows ``a[idx]`` with the empty sentinel (idx = N) clamped to a valid row (masked by the caller)."""
    return a[jnp.minimum(idx, a.shape[0] - 1)]


def _pair_ends(xi, xj, active, r1):
    """(xi, xj) with xj replaced, in empty slots, by a dummy at distance 2 r1 along x from xi (finite contact
    geometry there, so that NaN never enters a masked lane or its gradient)."""
    return xi, jnp.where(active[..., None], xj, xi - 2.0 * r1 * jnp.array([[1.0, 0.0, 0.0]]))


def _safe_pairs(x, ci, cj, active, r1):
    """Positions of the pair ends (C, 3) of the slots (ci, cj), with :func:`_pair_ends`'s dummy in empty slots."""
    return _pair_ends(_gather(x, ci), _gather(x, cj), active, r1)


def _half_work(Fc, Mc1, Mc2, gi, gj):
    """Half the work of each contact's force and torques over a step, (1/2) [F.(dx_i - dx_j) + M_1.dth_i +
    M_2.dth_j] [erg] (C,), from the step rows of its two monomers (columns 3:6 displacement dt v, 6:9 rotation
    angle dt w; :func:`_step`): the leapfrog's half kick with a contact that exists at only one end of the step."""
    return 0.5 * (_dot(Fc, gi[:, 3:6] - gj[:, 3:6]) + _dot(Mc1, gi[:, 6:9]) + _dot(Mc2, gj[:, 6:9]))


def _unit(d):
    """d/|d| and |d| with a safe norm (|d| > 0 in every lane that is used)."""
    r2 = _dot(d, d)
    ok = r2 > 0
    r = jnp.sqrt(jnp.where(ok, r2, 1.0))
    return jnp.where(ok[..., None], d / r[..., None], 0.0), jnp.where(ok, r, 0.0)


def _safe_pointers(n_i, n_j, phi, active):
    """Pointers of empty slots set to the at-rest values of the dummy geometry (n_i = -e_x, n_j = +e_x)."""
    ex = jnp.broadcast_to(jnp.array([1.0, 0.0, 0.0]), n_i.shape)
    a = active[..., None]
    return jnp.where(a, n_i, -ex), jnp.where(a, n_j, ex), jnp.where(active, phi, 0.0)


def _pair_sum(f_i, f_j, ci, cj, active, N):
    """Per-monomer sums (N, k) of per-slot values: f_i (C, k) on monomer ci and f_j (C, k) on cj (one scatter).

    Empty slots get the out-of-range id N, which ``segment_sum`` drops. (Summing them into a dummy row N, as
    before, made every empty slot's update hit one address: on a GPU the atomic adds serialised, 0.32 ms of a
    0.67 ms step at 8192 + 8192 monomers on an H200.)"""
    ids = jnp.concatenate([jnp.where(active, ci, N), jnp.where(active, cj, N)])
    return jax.ops.segment_sum(jnp.concatenate([f_i, f_j], axis=0), ids, num_segments=N)


def _evaluate(x, ci, cj, active, n_i, n_j, phi, mat):
    """Force [dyn] and torque [dyn cm] on every monomer and the four potential energies (U_n, U_s, U_r, U_t) [erg]
    summed over the contacts (the per-slot values: :func:`_slot_forces`)."""
    xi, xj = _safe_pairs(x, ci, cj, active, mat.r1)
    return _evaluate_pairs(xi, xj, ci, cj, active, n_i, n_j, phi, mat, x.shape[0])


def _evaluate_pairs(xi, xj, ci, cj, active, n_i, n_j, phi, mat, N):
    """:func:`_evaluate` from the pair-end positions (C, 3) of :func:`_safe_pairs` (gathered once per step). Every
    slot is evaluated: gathering the occupied ones (about half the list) into a buffer and scattering back cost as
    much as it saved (3-D 1024 + 1024, stop 29)."""
    Uc, F1, M1, M2 = _slot_forces(xi, xj, active, n_i, n_j, phi, mat)
    FM = _pair_sum(jnp.concatenate([F1, M1], axis=-1), jnp.concatenate([-F1, M2], axis=-1), ci, cj, active, N)
    return FM[:, :3], FM[:, 3:], jnp.sum(Uc, axis=0)


def _slot_forces(xi, xj, mask, n_i, n_j, phi, mat):
    """Per slot, zero where ``mask`` is False: the energies (U_n, U_s, U_r, U_t) (C, 4) [erg], the force on monomer ci
    (C, 3) [dyn] and the torques on ci and cj (C, 3) [dyn cm] of the contacts (``interactions.contact_forces``) at
    the pair-end positions ``xi``, ``xj`` of :func:`_safe_pairs` / :func:`_pair_ends` for a mask that covers
    ``mask``.

    The force pass sums them over the active slots (:func:`_evaluate_pairs`); beyond that the step needs them only
    for the slots that break or form in it (the energy ledger and the event-time correction), so they are evaluated
    again there, inside the branches taken on such steps, from the same inputs as the force pass that summed them:
    the state does not carry them (they were four (C, k) fields written every step,
    and XLA copied each of them twice per step to keep the old values alive next to the new ones)."""
    ni, nj, ph = _safe_pointers(n_i, n_j, phi, mask)
    cf = contact_forces(xi, xj, ni, nj, ph, mat)
    a = mask[..., None]
    Uc = jnp.where(a, jnp.stack([cf.U_n, cf.U_s, cf.U_r, cf.U_t], axis=-1), 0.0)
    return Uc, jnp.where(a, cf.F1, 0.0), jnp.where(a, cf.M1, 0.0), jnp.where(a, cf.M2, 0.0)


# ------------------------------------------------------------------------------------------------- neighbours
def _offsets(dim):
    rng = (-1, 0, 1)
    offs = [o + (0,) for o in itertools.product(rng, rng)] if dim == 2 else list(itertools.product(rng, rng, rng))
    return np.asarray(offs, np.int64)


def _build_neighbours(x, cutoff, n_nb, dim):
    """Verlet list (N, n_nb) of partners j > i with |x_i - x_j| < cutoff, by a cell list of side ``cutoff``.

    The monomers are sorted by the integer key of their cell; for each of the 3^dim neighbouring cells the range
    of its members is found with ``searchsorted`` and up to ``occ`` of them are tested. Returns (nbr, overflow):
    overflow is True when a cell held more than ``occ`` monomers or a row more than ``n_nb`` neighbours (then
    pairs may be missing: the run's status becomes ``capacity_exceeded``).
    """
    N = x.shape[0]
    occ = _cell_occupancy(dim)
    lo = jnp.min(x, axis=0)
    c = jnp.floor((x - lo[None, :]) / cutoff).astype(jnp.int64)
    nc = jnp.max(c, axis=0) + 1
    key_of = lambda cc: (cc[..., 0] * nc[1] + cc[..., 1]) * nc[2] + cc[..., 2]  # noqa: E731
    order = jnp.argsort(key_of(c))
    skey = key_of(c)[order]
    offs = jnp.asarray(_offsets(dim))
    S = offs.shape[0]
    cc = c[:, None, :] + offs[None, :, :]  # (N, S, 3) the neighbouring cells
    inside = jnp.all((cc >= 0) & (cc < nc[None, None, :]), axis=-1)
    k = key_of(cc).reshape(-1)
    start = jnp.searchsorted(skey, k, side="left").reshape(N, S)
    stop = jnp.searchsorted(skey, k, side="right").reshape(N, S)
    overflow = jnp.any(inside & (stop - start > occ))
    pos = start[:, :, None] + jnp.arange(occ)[None, None, :]
    j = order[jnp.minimum(pos, N - 1)]
    idx_i = jnp.arange(N)
    ok = inside[:, :, None] & (pos < stop[:, :, None]) & (j > idx_i[:, None, None])
    cand = j.reshape(N, S * occ)
    ok = ok.reshape(N, S * occ)
    d = x[:, None, :] - x[cand]
    ok = ok & (_dot(d, d) < cutoff**2)
    rank = jnp.cumsum(ok, axis=1) - 1
    overflow = overflow | jnp.any(jnp.sum(ok, axis=1) > n_nb)
    rank = jnp.where(ok, rank, n_nb)
    rows = jnp.broadcast_to(idx_i[:, None], cand.shape)
    nbr = jnp.full((N, n_nb), N, jnp.int32).at[rows, rank].set(cand.astype(jnp.int32), mode="drop")
    return nbr, overflow


# ------------------------------------------------------------------------------------------------- contacts
def _cand_capacity(n_mono: int) -> int:
    """Slots of the list of non-contact neighbour pairs (:func:`_candidates`): N/2, at least 64. A colliding pair
    of 2-D 256-monomer BCCAs has 23-29 such pairs (of 4 096 neighbour-table entries) throughout its collision."""
    return max(64, n_mono // 2)


def _candidates(nbr, ci, cj, active, K=None):
    """The neighbour pairs (i, nbr[i, k]) that are not active contacts, compacted into K slots (default
    ``_cand_capacity(N)``; a step keeps the size of its state's list) (N = empty), and whether there were more
    (then the step runs the creation search on every step until the next build).

    A contact can form only between such a pair (every contact is a neighbour pair: it breaks before its centres
    are 2 r1 + delta_c apart, inside the list's cutoff), so a step needs to test only these for touching instead of
    all N x K_nb entries of the neighbour list. Built here (the sorted-key lookup of :func:`_create`) at the start
    and after every neighbour-list build; a step with contact events updates it in place (a breaking adds its pair:
    :func:`_add_candidates`; a creation removes its pairs). Returns (cand_i, cand_j, full)."""
    N, Kn = nbr.shape
    C = ci.shape[0]
    K = _cand_capacity(N) if K is None else K
    n64 = jnp.int64(N)
    keys = jnp.sort(jnp.where(active, ci.astype(jnp.int64) * n64 + cj, n64 * n64))
    flat = nbr.reshape(-1)
    ckey = jnp.repeat(jnp.arange(N, dtype=jnp.int64), Kn) * n64 + flat
    contact = keys[jnp.minimum(jnp.searchsorted(keys, ckey), C - 1)] == ckey
    cand = (flat < N) & ~contact
    idx = jnp.nonzero(cand, size=K, fill_value=N * Kn)[0]
    ok = idx < N * Kn
    cand_i = jnp.where(ok, idx // Kn, N).astype(jnp.int32)
    cand_j = jnp.where(ok, flat[jnp.minimum(idx, N * Kn - 1)], N).astype(jnp.int32)
    return cand_i, cand_j, jnp.sum(cand) > K


def _add_candidates(cand_i, cand_j, cand_full, freed, ci_old, cj_old, N):
    """The list of non-contact neighbour pairs (:func:`_candidates`) after contacts broke, without a new search: the
    broken contacts (``freed``, (C,) mask over the pairs ``ci_old``, ``cj_old``; neighbour pairs, since a contact
    breaks inside the list's cutoff) fill the empty slots (index ``N``) in slot order. O(K + C) and no sort, so that
    under ``jax.vmap``, where every member takes this branch when one has a breaking, it stays cheap. More pairs
    than slots set ``full`` (the step then runs the creation search every step until the next build). The pairs that
    a creation takes leave the list in the creation branch of the step. Returns (cand_i, cand_j, full)."""
    K = cand_i.shape[0]
    empty = cand_i >= N
    slots = jnp.nonzero(empty, size=K, fill_value=K)[0]
    rank = jnp.cumsum(freed) - 1
    tgt = jnp.where(freed & (rank < K), slots[jnp.clip(rank, 0, K - 1)], K)
    cand_i = cand_i.at[tgt].set(ci_old.astype(cand_i.dtype), mode="drop")
    cand_j = cand_j.at[tgt].set(cj_old.astype(cand_j.dtype), mode="drop")
    return cand_i, cand_j, cand_full | (jnp.sum(freed) > jnp.sum(empty))


def _create(x, ci, cj, active, n_i, n_j, phi, nbr, mat):
    """New contacts for the neighbour pairs with delta >= 0 not yet in contact (Wada et al. 2007 §2.1).

    Whether a neighbour pair is already a contact is looked up in the sorted keys ci N + cj of the active slots;
    the r-th new contact (in the order of the neighbour list) takes the r-th free slot. Pointers n_i = -n_c,
    n_j = +n_c (n_c = (x_i - x_j)/|x_i - x_j|), phi = 0. Returns the updated list, the mask of new contacts (C,)
    (the caller books E_dis,n += -U_n(delta) of each, the jump of U_n from 0 to its JKR value, from the force
    evaluation at the same positions) and an overflow flag (more new contacts than free slots).
    """
    N, Kn = nbr.shape
    C = ci.shape[0]
    valid = nbr < N
    xn = _gather(x, nbr)
    nc, dist = _unit(jnp.broadcast_to(x[:, None, :], xn.shape) - xn)
    delta = 2.0 * mat.r1 - dist
    n64 = jnp.int64(N)
    keys = jnp.sort(jnp.where(active, ci.astype(jnp.int64) * n64 + cj, n64 * n64))
    ckey = (jnp.arange(N, dtype=jnp.int64)[:, None] * n64 + nbr).reshape(-1)
    pos = jnp.searchsorted(keys, ckey)
    already = (keys[jnp.minimum(pos, C - 1)] == ckey).reshape(N, Kn)
    cand = (valid & (delta >= 0) & ~already).reshape(-1)
    crank = jnp.cumsum(cand) - 1
    free = jnp.nonzero(~active, size=C, fill_value=C)[0]
    n_free = jnp.sum(~active)
    overflow = jnp.sum(cand) > n_free
    slot = jnp.where(cand & (crank < n_free), free[jnp.clip(crank, 0, C - 1)], C)
    ii = jnp.repeat(jnp.arange(N, dtype=ci.dtype), Kn)
    ncf = nc.reshape(-1, 3)
    ci = ci.at[slot].set(ii, mode="drop")
    cj = cj.at[slot].set(nbr.reshape(-1).astype(cj.dtype), mode="drop")
    new = jnp.zeros((C,), bool).at[slot].set(True, mode="drop")
    n_i = n_i.at[slot].set(-ncf, mode="drop")
    n_j = n_j.at[slot].set(ncf, mode="drop")
    phi = jnp.where(new, 0.0, phi)
    return ci, cj, active | new, n_i, n_j, phi, new, overflow


# JKR normal force at the two events in units of F_c (Wada et al. 2007 eq. 5; ``jkr.normal_force``): F(0) at a/a_0 =
# (2/3)^(2/3) and F(-delta_c) at a/a_0 = 6^(-2/3), both attractive
_F_AT_CREATION = -8.0 / 9.0
_F_AT_BREAKING = -5.0 / 9.0
# F(delta) = F(-delta_c) + _F_SQRT F_c sqrt((delta + delta_c)/delta_0) + O(delta + delta_c) near separation: with
# x = a/a_0 = 6^(-2/3) + e, eq. 4 gives (delta + delta_c)/delta_0 = (9/2) e^2 (d delta/dx = 0 there: the vertical
# tangent) and eq. 5 gives dF/dx = -4 6^(-1/3) F_c, so _F_SQRT = -4 6^(-1/3) (2/9)^(1/2)
_F_SQRT = -4.0 * 6.0 ** (-1.0 / 3.0) * (2.0 / 9.0) ** 0.5


def _hurwitz_zeta_m_half(a):
    """Hurwitz zeta(-1/2, a) = sum_{m>=0} (a + m)^(1/2) (analytically continued) for 0 <= a <= 1: six terms and the
    Euler-Maclaurin tail to B_6 (absolute error < 1e-9); zeta(-1/2, 0) = zeta(-1/2, 1) = zeta(-1/2) = -0.2078862.
    The a^(1/2) term has a zero (not NaN) derivative at a = 0."""
    ok = a > 0
    total = jnp.where(ok, jnp.sqrt(jnp.where(ok, a, 1.0)), 0.0)
    for k in range(1, 6):
        total = total + jnp.sqrt(a + k)
    b = a + 6.0
    return (total - (2.0 / 3.0) * b**1.5 + 0.5 * b**0.5 - b**-0.5 / 24.0 + b**-2.5 / 1920.0
            - (105.0 / (32.0 * 42.0 * 720.0)) * b**-4.5)


def _compression(x, ci, cj, mask, r1):
    """delta = 2 r1 - |x_i - x_j| [cm] of the slots (ci, cj), the dummy value 0 where ``mask`` is False (finite,
    with a finite gradient)."""
    xi, xj = _safe_pairs(x, ci, cj, mask, r1)
    _, dist = _unit(xi - xj)
    return 2.0 * r1 - dist


def _event_impulses(x_old, x, ci_old, cj_old, broken, ci, cj, new, ev_f, ev_i, ev_j, ev_t, Fc_old, Mc1_old, mat):
    """Event-time correction of the leapfrog (module docstring, "Event times").

    A contact created in this step (``new``, delta crossed 0) or broken (``broken``, delta crossed -delta_c)
    crossed at the fraction theta of the step, from the linear interpolation of delta between ``x_old`` and ``x``.
    The normal force jump F_e (F(0) = -8/9 F_c at creation, F(-delta_c) = -5/9 F_c at breaking) gets the
    correction impulses dt F_e (1 - 3 theta)/2 (creation) or dt F_e (3 theta - 1)/2 (breaking) at this
    configuration and dt F_e theta/2 (creation) or -dt F_e theta/2 (breaking) at the next one, each along the
    line of centres of the configuration where it is applied (equal and opposite on the two monomers, no
    torque). A breaking also gets (1 - theta) Z here and theta Z at the next configuration (the sqrt-cusp term
    of the module docstring). The tangential springs of a broken contact (its force minus the normal part, ``Fc_old``
    on ci, and its torque on ci, ``Mc1_old``, at ``x_old``) stop at the same instant and get the same two corrections
    (no cusp term); the torque on cj is -M_1 - (x_i - x_j) x F_t at the configuration where the correction is
    applied, so that P and L stay exact. ``ev_f``, ``ev_i``, ``ev_j``, ``ev_t`` are the corrections due here from
    the previous step.

    Returns (Fe, Me, ev_f_next, ev_i_next, ev_j_next, ev_t_next): the correction force (N, 3) [dyn] and torque (N, 3)
    [dyn cm] at ``x`` (impulses over dt), the per slot normal forces [dyn] and pairs due at the next configuration
    (2C,) and the tangential forces and torques due there (C, 6).
    """
    N = x.shape[0]
    r1 = mat.r1
    # breaking: delta_old >= -delta_c > delta_new, theta = (delta_old + delta_c)/(delta_old - delta_new) in [0, 1)
    # (the line of centres before the step also serves the tangential correction below)
    n_o, dist_o = _unit(jnp.subtract(*_safe_pairs(x_old, ci_old, cj_old, broken, r1)))
    dbo = 2.0 * r1 - dist_o
    dbn = _compression(x, ci_old, cj_old, broken, r1)
    th_b = jnp.clip((dbo + mat.delta_c) / jnp.where(broken, dbo - dbn, 1.0), 0.0, 1.0)
    f_b = _F_AT_BREAKING * mat.F_c
    # the samples dt F(delta_j) of the last steps before a breaking see the sqrt of the vertical tangent: with
    # delta_j + delta_c = (delta_old - delta_new)(theta + m), m = 0, 1, ..., their sum exceeds the integral of the
    # force by dt _F_SQRT F_c ((delta_old - delta_new)/delta_0)^(1/2) zeta(-1/2, theta), a cusp in theta
    z_b = -_F_SQRT * mat.F_c * jnp.sqrt(jnp.maximum(jnp.where(broken, dbo - dbn, mat.delta0), 0.0) / mat.delta0) * (
        _hurwitz_zeta_m_half(th_b))
    # creation: delta_old < 0 <= delta_new, theta = delta_old/(delta_old - delta_new) in (0, 1]
    dco = _compression(x_old, ci, cj, new, r1)
    dcn = _compression(x, ci, cj, new, r1)
    th_c = jnp.clip(dco / jnp.where(new, dco - dcn, 1.0), 0.0, 1.0)
    f_c = _F_AT_CREATION * mat.F_c
    f_now = jnp.concatenate([jnp.where(broken, 0.5 * f_b * (3.0 * th_b - 1.0) + (1.0 - th_b) * z_b, 0.0),
                             jnp.where(new, 0.5 * f_c * (1.0 - 3.0 * th_c), 0.0), ev_f])
    i_now = jnp.concatenate([jnp.where(broken, ci_old, N), jnp.where(new, ci, N), ev_i])
    j_now = jnp.concatenate([jnp.where(broken, cj_old, N), jnp.where(new, cj, N), ev_j])
    occupied = i_now < N
    d_now = jnp.subtract(*_safe_pairs(x, i_now, j_now, occupied, r1))
    nc, _ = _unit(d_now)
    J = jnp.where(occupied, f_now, 0.0)[..., None] * nc
    Fe = _pair_sum(J, -J, i_now, j_now, occupied, N)
    ev_f_next = jnp.concatenate([jnp.where(broken, -0.5 * f_b * th_b + th_b * z_b, 0.0),
                                 jnp.where(new, 0.5 * f_c * th_c, 0.0)])
    ev_i_next = jnp.concatenate([jnp.where(broken, ci_old, N), jnp.where(new, ci, N)]).astype(ev_i.dtype)
    ev_j_next = jnp.concatenate([jnp.where(broken, cj_old, N), jnp.where(new, cj, N)]).astype(ev_j.dtype)
    # tangential springs of the broken contacts (and the previous step's pending ones, pairs ev_i[:C], ev_j[:C])
    C = ci.shape[0]
    F_t = jnp.where(broken[:, None], Fc_old - _dot(Fc_old, n_o)[:, None] * n_o, 0.0)
    M_t = jnp.where(broken[:, None], Mc1_old, 0.0)
    a_now = jnp.where(broken, 0.5 * (3.0 * th_b - 1.0), 0.0)[:, None]
    # these pairs are the entries [0, C) (breakings) and [2C, 3C) (pending breakings) of i_now / j_now above
    t_i = jnp.concatenate([i_now[:C], i_now[2 * C:3 * C]])
    t_j = jnp.concatenate([j_now[:C], j_now[2 * C:3 * C]])
    t_occ = t_i < N
    tF = jnp.where(t_occ[:, None], jnp.concatenate([a_now * F_t, ev_t[:, :3]]), 0.0)
    tM = jnp.where(t_occ[:, None], jnp.concatenate([a_now * M_t, ev_t[:, 3:]]), 0.0)
    tM2 = -tM - _cross(jnp.concatenate([d_now[:C], d_now[2 * C:3 * C]]), tF)
    Fe = Fe + _pair_sum(tF, -tF, t_i, t_j, t_occ, N)
    Me = _pair_sum(tM, tM2, t_i, t_j, t_occ, N)
    a_next = jnp.where(broken, -0.5 * th_b, 0.0)[:, None]
    ev_t_next = jnp.concatenate([a_next * F_t, a_next * M_t], axis=1)
    return Fe, Me, ev_f_next, ev_i_next, ev_j_next, ev_t_next



def _clip_buffers(n_slots: int) -> tuple[int, ...]:
    """Static sizes of the buffers of the compacted inelastic clipping: 1/64 and 1/8 of the list (>= 32 each, only
    the sizes below the list's). A collision clips a few per cent of its contacts at a time (16 of 2045 in the
    3-D 1024 + 1024 benchmark at 5.7 v_0), so the small buffer serves most steps."""
    return tuple(sorted({b for b in (max(32, n_slots // 64), max(32, n_slots // 8)) if b < n_slots}))


def _clip(xi, xj, active, n_i, n_j, phi, mat):
    """Inelastic clipping (Wada et al. 2007 eqs. 39-43, ``interactions.clip_inelastic``) of the contact list.

    Only the contacts past a critical displacement (|zeta| > zeta_crit, |xi| > xi_crit or |phi_s| > phi_crit, the
    test of ``clip_inelastic``) change, so they are gathered into the smallest buffer of :func:`_clip_buffers` that
    holds them, clipped there and scattered back; nothing runs when none is over its limit, and the whole list is
    clipped when more than the largest buffer are (the branch is chosen by the largest count of a ``vmap`` batch).
    The other slots are returned unchanged, as ``clip_inelastic`` itself returns them. Returns (n_i, n_j, phi, dE)
    with dE = (dE_s, dE_r, dE_t) [erg] summed over the contacts. ``xi``, ``xj``: pair-end positions (C, 3) of
    :func:`_safe_pairs`.
    """
    L = active.shape[0]
    bufs = _clip_buffers(L)
    ni0, nj0, ph0 = _safe_pointers(n_i, n_j, phi, active)
    _, _, _, _, zeta, xiv = contact_geometry(xi, xj, ni0, nj0, mat)
    over = active & ((_norm(zeta) > mat.zeta_crit) | (_norm(xiv) > mat.xi_crit) | (jnp.abs(ph0) > mat.phi_crit))
    cnt = jnp.sum(over)
    # branch 0: nothing to clip; 1 .. len(bufs): the smallest buffer that holds cnt; len(bufs) + 1: the whole list
    branch = jnp.where(cnt == 0, 0, 1 + sum((cnt > b).astype(jnp.int32) for b in bufs)).astype(jnp.int32)

    def none(_):
        return n_i, n_j, phi, jnp.zeros(3)

    def compact(nbuf, _):
        idx = jnp.nonzero(over, size=nbuf, fill_value=L)[0]
        take = lambda a: a[jnp.minimum(idx, L - 1)]  # noqa: E731
        ni1, nj1, ph1, dEs, dEr, dEt = clip_inelastic(take(xi), take(xj), take(ni0), take(nj0), take(ph0), mat)
        put = lambda a, b: a.at[idx].set(b, mode="drop")  # noqa: E731
        ok = idx < L
        dE = jnp.stack([jnp.sum(jnp.where(ok, e, 0.0)) for e in (dEs, dEr, dEt)])
        return put(n_i, ni1), put(n_j, nj1), put(phi, ph1), dE

    def full(_):
        ni1, nj1, ph1, dEs, dEr, dEt = clip_inelastic(xi, xj, ni0, nj0, ph0, mat)
        a = active[..., None]
        dE = jnp.stack([jnp.sum(jnp.where(active, e, 0.0)) for e in (dEs, dEr, dEt)])
        return jnp.where(a, ni1, n_i), jnp.where(a, nj1, n_j), jnp.where(active, ph1, phi), dE

    return jax.lax.switch(_max_member(branch), (none, *(functools.partial(compact, b) for b in bufs), full), None)


# ------------------------------------------------------------------------------------------------- state
def init_state(x, v, w, mat, *, dim=3, capacity=None, neighbours=None, skin=0.1, t0=0.0):
    """Initial DEM state: every pair with compression delta = 2 r1 - |x_i - x_j| >= 0 becomes a contact at rest
    (pointers along the line of centres, no sliding, rolling or twisting displacement, phi = 0).

    Arguments:
        x, v, w: (N, 3) positions [cm], velocities [cm s^-1], angular velocities [rad s^-1] (planar runs: z = 0,
            v_z = 0, w along z).
        mat: :class:`~jaxcoag.aggregates.contact.materials.Material`.
        dim: 2 (planar) or 3 (static; sets the neighbour-cell stencil).
        capacity: contact slots per monomer, the list holds capacity x N contacts (default 2 in 2-D, 3 in 3-D,
            :func:`default_capacity`).
        neighbours: neighbour-list slots per monomer (default 8 in 2-D, 16 in 3-D).
        skin: Verlet skin in units of r1 (cutoff 2 r1 + skin r1).
        t0: start time [s].

    Returns:
        :class:`DEMState` (``flags`` has ``FLAG_CONTACTS`` / ``FLAG_NEIGHBOURS`` set if the capacities cannot hold
        the initial contacts).

    References: Wada et al. (2007) §2.1 (a contact forms at delta >= 0), §4.
    """
    if dim not in (2, 3):
        raise JaxcoagInputError(f"dim must be 2 or 3; got {dim!r}.")
    K = int(capacity or default_capacity(dim))
    Kn = int(neighbours or default_neighbours(dim))
    x = jnp.asarray(x, jnp.float64)
    N = x.shape[0]
    f = lambda a: jnp.broadcast_to(jnp.asarray(a, jnp.float64), (N, 3))  # noqa: E731
    return _init_impl(x, f(v), f(w), mat, jnp.asarray(skin, jnp.float64), jnp.asarray(t0, jnp.float64),
                      dim=dim, K=K, Kn=Kn)


@functools.partial(jax.jit, static_argnames=("dim", "K", "Kn"))
def _init_impl(x, v, w, mat, skin, t0, *, dim, K, Kn):
    N = x.shape[0]
    C = K * N
    cutoff = (2.0 + skin) * mat.r1
    nbr, ovf_nb = _build_neighbours(x, cutoff, Kn, dim)
    ci = jnp.full((C,), N, jnp.int32)
    active = jnp.zeros((C,), bool)
    z3 = jnp.zeros((C, 3))
    ci, cj, active, n_i, n_j, phi, _, ovf_c = _create(x, ci, ci, active, z3, z3, jnp.zeros((C,)), nbr, mat)
    F, M, U = _evaluate(x, ci, cj, active, n_i, n_j, phi, mat)
    cand_i, cand_j, cand_full = _candidates(nbr, ci, cj, active)
    flags = jnp.where(ovf_c, FLAG_CONTACTS, 0) | jnp.where(ovf_nb, FLAG_NEIGHBOURS, 0)
    i64 = lambda n: jnp.asarray(n, jnp.int64)  # noqa: E731
    none = jnp.full((2 * C,), N, jnp.int32)
    return DEMState(x=x, v=v, w=w, F=F, M=M, ci=ci, cj=cj, active=active, n_i=n_i, n_j=n_j, phi=phi, nbr=nbr,
                    x_ref=x, U=U, E_dis=jnp.zeros(4), Fe=jnp.zeros((N, 3)),
                    Me=jnp.zeros((N, 3)), ev_f=jnp.zeros((2 * C,)), ev_i=none, ev_j=none, ev_t=jnp.zeros((C, 6)),
                    axes=jnp.ones((dim,), bool),
                    step=i64(0), t0=t0,
                    flags=flags.astype(jnp.int32), n_events=i64(0), first_event=i64(-1), last_event=i64(-1),
                    n_builds=i64(1), cand_i=cand_i, cand_j=cand_j, cand_full=cand_full)


# ------------------------------------------------------------------------------------------------- step
#: per-slot fields of :class:`DEMState` with a leading axis of C slots; ``ev_f``, ``ev_i``, ``ev_j`` have 2C (the
#: breakings' half, then the creations')
_SLOT_FIELDS = ("ci", "cj", "active", "n_i", "n_j", "phi", "ev_t")
_SLOT_FIELDS_2C = ("ev_f", "ev_i", "ev_j")
#: steps of the forward loops (:func:`_n_steps_loop`) per choice of the prefix
_DISPATCH_STEPS = 256
#: prefix sizes in units of N (a tree has N - 1 contacts; a collision compacts it to ~1.5 N in 2-D)
_PREFIX_FRACTIONS = (1.25, 1.625, 2.0)
#: lists shorter than this are always processed whole: each prefix size is another copy of the step to compile
#: (~3-4 s on 2 cores), more than a short list's steps save
_PREFIX_MIN_SLOTS = 1024


def _prefix_slack(n_mono: int) -> int:
    """Free slots kept above the highest used slot when a prefix is chosen for a block of steps (the new contacts
    of up to ``_DISPATCH_STEPS`` steps; a block whose creations need more is taken again on the whole list):
    N/32, at least 8."""
    return max(8, n_mono // 32)


def _prefix_sizes(n_mono: int, n_slots: int) -> tuple[int, ...]:
    """Static slot-prefix sizes of the step: 1.25 N, 1.625 N and 2 N (multiples of 8) below C, then C.

    An aggregate has about one contact per monomer (N - 1 in a tree, up to ~2 N compacted), and new contacts take
    the lowest free slots, so the used slots stay a prefix of the list; a step that processes the prefix that holds
    them instead of all C = capacity x N slots costs what a list of that length costs (3-D, capacity 3, a BCCA pair:
    C = 3 N, the prefix 1.25 N). Lists of fewer than ``_PREFIX_MIN_SLOTS`` slots have the one size C, and so do
    runs on an accelerator (read at trace time), where the slot passes are parallel and each branch of the
    dispatch is a host round trip (the GPU timings of benchmarks/gpu_aggregates.py are of the whole list)."""
    if n_slots < _PREFIX_MIN_SLOTS or jax.default_backend() != "cpu":
        return (n_slots,)
    return tuple(sorted({min(n_slots, 8 * -(-int(np.ceil(f * n_mono)) // 8)) for f in _PREFIX_FRACTIONS} | {n_slots}))


def _take_prefix(st: DEMState, B: int) -> DEMState:
    """The state with its contact list cut to the first B slots (the pending events of those slots kept)."""
    C = st.ci.shape[0]
    upd = {k: getattr(st, k)[:B] for k in _SLOT_FIELDS}
    upd.update({k: jnp.concatenate([getattr(st, k)[:B], getattr(st, k)[C:C + B]]) for k in _SLOT_FIELDS_2C})
    return dataclasses.replace(st, **upd)


def _put_prefix(full: DEMState, part: DEMState, B: int) -> DEMState:
    """``part`` (a step of :func:`_take_prefix`'s state) with its first B slots written back into ``full``'s list."""
    C = full.ci.shape[0]
    upd = {k: getattr(full, k).at[:B].set(getattr(part, k)) for k in _SLOT_FIELDS}
    upd.update({k: getattr(full, k).at[:B].set(getattr(part, k)[:B]).at[C:C + B].set(getattr(part, k)[B:])
                for k in _SLOT_FIELDS_2C})
    return dataclasses.replace(part, **upd)


def _repeat(one, st, n):
    """``n`` applications of ``one`` to ``st``: a ``lax.scan`` for a static int (reverse-mode differentiable), a
    ``fori_loop`` for a traced count."""
    if isinstance(n, int):
        return jax.lax.scan(lambda s, _: (one(s), None), st, None, length=n)[0] if n != 1 else one(st)
    return jax.lax.fori_loop(0, n, lambda _, s: one(s), st)


def _steps(st: DEMState, mat, dt, skin, cfg: _Cfg, n) -> DEMState:
    """``n`` kick-drift-kick steps (module docstring) over one prefix of the contact list that holds every used slot
    (``n``: a static int, or a traced count of at most ``_DISPATCH_STEPS``).

    The used slots are the active contacts and the slots with a correction pending from the previous step; the
    prefix is the smallest of :func:`_prefix_sizes` with :func:`_prefix_slack` free slots above the highest used one
    (chosen by the largest need of a ``jax.vmap`` batch) at the start, and the n steps run on it: slots above it
    are empty before and after every step, so this is :func:`_step_slots` on the prefix, the same contacts in the
    same slots, forces summed in the same order. If the creations of some step need more free slots than the prefix
    has, the n steps are taken again from the start on the whole list (as are steps whose used slots need the whole
    list). The prefix is chosen per block of steps, not per step: cutting the list out and writing it back, and the
    branches around it, cost a whole 2-D 256 + 256 step (142 us per step against 87 us for the step itself on its
    prefix, 2 CPU cores). Returns the state after the n steps."""
    N, C = st.x.shape[0], st.ci.shape[0]
    sizes = _prefix_sizes(N, C)

    def one(s):
        return _step_slots(s, mat, dt, skin, cfg)

    def whole(s):
        return _repeat(one, s, n)

    if len(sizes) == 1:
        return whole(st)
    used = st.active | (st.ev_i[:C] < N) | (st.ev_i[C:] < N)
    top = jnp.max(jnp.where(used, jnp.arange(1, C + 1), 0)) + _prefix_slack(N)
    k = _max_member(jnp.sum((jnp.asarray(sizes[:-1]) < top).astype(jnp.int32)))

    def prefix(B):
        def run(s):
            part = _repeat(one, _take_prefix(s, B), n)
            spilled = ((part.flags & FLAG_CONTACTS) != 0) & ((s.flags & FLAG_CONTACTS) == 0)
            return _put_prefix(s, part, B), spilled

        return run

    def prefixes(s):
        out, spilled = jax.lax.switch(k, [prefix(B) for B in sizes[:-1]], s) if len(sizes) > 2 else prefix(sizes[0])(s)
        return _cond_members(spilled, lambda o: whole(o[0]), lambda o: o[1], (s, out))

    return jax.lax.cond(k == len(sizes) - 1, whole, prefixes, st)


def _step(st: DEMState, mat, dt, skin, cfg: _Cfg) -> DEMState:
    """One step (:func:`_steps` with n = 1)."""
    return _steps(st, mat, dt, skin, cfg, 1)


def _step_slots(st: DEMState, mat, dt, skin, cfg: _Cfg) -> DEMState:
    """One kick-drift-kick step (module docstring) over every slot of ``st``'s contact list.

    Every per-contact quantity of the monomers (position, displacement dt v, rotation angle dt w and its Rodrigues
    coefficients) is gathered once per step for both ends of every slot (two gathers of an (N, 11) array); the
    rare creation branch updates the rows of its new slots."""
    N = st.x.shape[0]
    m1, I1 = mat.m1, mat.I1
    v = st.v + (0.5 * dt / m1) * (st.F + st.Fe)
    w = st.w + (0.5 * dt / I1) * (st.M + st.Me)
    x = st.x + dt * v
    ci, cj, active = st.ci, st.cj, st.active
    # pointers rotate with their monomer (Rodrigues, ``interactions.rotate``): coefficients once per monomer
    th = w * dt
    s_rot, c_rot = rotation_coefficients(th)
    rows = jnp.concatenate([x, dt * v, th, s_rot[:, None], c_rot[:, None]], axis=1)  # (N, 11)
    gi, gj = _gather(rows, ci), _gather(rows, cj)
    n_i = rotate_by(st.n_i, gi[:, 6:9], gi[:, 9], gi[:, 10])
    n_j = rotate_by(st.n_j, gj[:, 6:9], gj[:, 9], gj[:, 10])
    r1 = mat.r1
    xi, xj = _pair_ends(gi[:, :3], gj[:, :3], active, r1)
    nc, dist = _unit(xi - xj)
    phi = jnp.where(active, st.phi + _dot(gi[:, 6:9] - gj[:, 6:9], nc), 0.0)
    E_dis = st.E_dis
    flags = st.flags
    n_ev = jnp.zeros((), jnp.int64)
    nbr, x_ref, n_builds = st.nbr, st.x_ref, st.n_builds
    cand_i, cand_j, cand_full = st.cand_i, st.cand_j, st.cand_full
    new = jnp.zeros_like(active)
    # event times (module docstring): the correction applied at st.x did the work (1/2) Fe.dx in this step's first
    # half kick; corrections are made only by this step's events (else Fe = 0 and nothing is pending)
    E_dis = E_dis.at[0].add(-0.5 * dt * jnp.sum(_dot(st.Fe, v) + _dot(st.Me, w)))
    Fe, Me, ev_f, ev_i, ev_j, ev_t = (jnp.zeros_like(st.Fe), jnp.zeros_like(st.Me), jnp.zeros_like(st.ev_f),
                                      jnp.full_like(st.ev_i, N), jnp.full_like(st.ev_j, N), jnp.zeros_like(st.ev_t))
    if not cfg.freeze:
        # breaking (Wada et al. 2007 §2.1): delta < -delta_c
        ci_old, cj_old = ci, cj
        broken = active & (2.0 * r1 - dist < -mat.delta_c)
        active = active & ~broken
        ci, cj = jnp.where(active, ci, N), jnp.where(active, cj, N)
        # energy ledger of a breaking (module docstring): the energies of the contact at st.x leave U; the
        # work of its last half kick, done in this step's first half kick, is part of the kinetic energy
        n_broken = jnp.sum(broken)

        def broken_forces():
            # the broken contacts' energies, force and torques at st.x, as the previous step's force pass had them
            return _slot_forces(*_safe_pairs(st.x, ci_old, cj_old, broken, r1), broken, st.n_i, st.n_j, st.phi, mat)

        def book_breaking(_):
            Uc_b, Fc_b, Mc1_b, Mc2_b = broken_forces()
            wb = _half_work(Fc_b, Mc1_b, Mc2_b, gi, gj)
            # the broken contacts' pairs go back on the list of non-contact neighbour pairs (a neighbour-list build
            # below, in this step, would list them anyway)
            return (jnp.sum(Uc_b, axis=0).at[0].add(-jnp.sum(wb)),
                    *_add_candidates(st.cand_i, st.cand_j, st.cand_full, broken, ci_old, cj_old, N))

        dE_b, cand_i, cand_j, cand_full = _cond_members(
            n_broken > 0, book_breaking, lambda _: (jnp.zeros(4), st.cand_i, st.cand_j, st.cand_full), None)
        E_dis = E_dis + dE_b
        cutoff = (2.0 + skin) * r1
        disp2 = jnp.max(_dot(x - st.x_ref, x - st.x_ref))
        rebuild = disp2 > (0.5 * skin * r1) ** 2

        def build(_):
            nb, ovf = _build_neighbours(x, cutoff, nbr.shape[1], cfg.dim)
            return (nb, x, ovf, *_candidates(nb, ci, cj, active, cand_i.shape[0]))

        def keep(_):
            return nbr, x_ref, jnp.zeros((), bool), cand_i, cand_j, cand_full

        nbr, x_ref, ovf_nb, cand_i, cand_j, cand_full = _cond_members(rebuild, build, keep, None)
        n_builds = n_builds + rebuild.astype(jnp.int64)
        # creation is rare: the slot assignment runs only when a neighbour pair that is not a contact touches
        # (delta >= 0, computed as _create does, so that the pairs taken off the list are exactly the new contacts).
        # Those pairs are the short list cand_i, cand_j (built with the neighbour list, kept up to date through the
        # contact events; a contact broken in this step cannot touch: its centres are more than 2 r1 + delta_c
        # apart). When the list overflowed (cand_full), the search runs on every step until the next build.
        _, dist_c = _unit(_gather(x, cand_i) - _gather(x, cand_j))
        touch = (cand_i < N) & (2.0 * r1 - dist_c >= 0)

        def create(args):
            *slots, c_i, c_j = args
            c_i, c_j = jnp.where(touch, N, c_i), jnp.where(touch, N, c_j)   # the touching pairs are contacts now
            return (*_create(x, *slots, nbr, mat), c_i, c_j)

        def no_create(args):
            *slots, c_i, c_j = args
            return (*slots, jnp.zeros_like(slots[2]), jnp.zeros((), bool), c_i, c_j)

        ci, cj, active, n_i, n_j, phi, new, ovf_c, cand_i, cand_j = _cond_members(
            jnp.any(touch) | cand_full, create, no_create, (ci, cj, active, n_i, n_j, phi, cand_i, cand_j))
        # pair ends of the new contacts (the rows gi, gj stay those of the slots before the creation: the branch
        # above does not pass them through, which made XLA copy both (C, 11) arrays on every step)
        gi_x = jnp.where(new[:, None], _gather(x, ci), gi[:, :3])
        gj_x = jnp.where(new[:, None], _gather(x, cj), gj[:, :3])
        xi, xj = _pair_ends(gi_x, gj_x, active, r1)
        flags = flags | jnp.where(ovf_c, FLAG_CONTACTS, 0) | jnp.where(ovf_nb, FLAG_NEIGHBOURS, 0)
        n_ev = (jnp.sum(broken) + jnp.sum(new)).astype(jnp.int64)
        if cfg.events:
            # the corrections due here (this step's events and the previous step's pending ones) do the work
            # (1/2) Fe.dx in this step's second half kick
            def correct(_):
                return _event_impulses(st.x, x, ci_old, cj_old, broken, ci, cj, new, st.ev_f, st.ev_i, st.ev_j,
                                       st.ev_t, *broken_forces()[1:3], mat)

            def no_correct(_):
                return Fe, Me, ev_f, ev_i, ev_j, ev_t

            pending = (n_ev > 0) | jnp.any(st.ev_i < N)
            Fe, Me, ev_f, ev_i, ev_j, ev_t = _cond_members(pending, correct, no_correct, None)
            E_dis = E_dis.at[0].add(-0.5 * dt * jnp.sum(_dot(Fe, v) + _dot(Me, w)))
    if cfg.inelastic:
        n_i, n_j, phi, dE = _clip(xi, xj, active, n_i, n_j, phi, mat)
        E_dis = E_dis + jnp.concatenate([jnp.zeros(1), dE])
    F, M, U = _evaluate_pairs(xi, xj, ci, cj, active, n_i, n_j, phi, mat, N)
    if not cfg.freeze:
        # creation: U_n jumps from 0 to U_n(delta), and the second half kick does the new contact's work
        def book_creation(_):
            Uc_n, Fc_n, Mc1_n, Mc2_n = _slot_forces(xi, xj, new, n_i, n_j, phi, mat)
            return -jnp.sum(Uc_n[..., 0] + _half_work(Fc_n, Mc1_n, Mc2_n, _gather(rows, ci), _gather(rows, cj)))

        E_dis = E_dis.at[0].add(_cond_members(jnp.any(new), book_creation, lambda _: jnp.zeros(()), None))
    v = v + (0.5 * dt / m1) * (F + Fe)
    w = w + (0.5 * dt / I1) * (M + Me)
    stp = st.step + 1
    event = n_ev > 0
    return DEMState(x=x, v=v, w=w, F=F, M=M, ci=ci, cj=cj, active=active, n_i=n_i, n_j=n_j, phi=phi, nbr=nbr,
                    x_ref=x_ref, U=U, E_dis=E_dis, Fe=Fe, Me=Me, ev_f=ev_f,
                    ev_i=ev_i, ev_j=ev_j, ev_t=ev_t, axes=st.axes, step=stp, t0=st.t0,
                    flags=flags, n_events=st.n_events + n_ev,
                    first_event=jnp.where(event & (st.first_event < 0), stp, st.first_event),
                    last_event=jnp.where(event, stp, st.last_event), n_builds=n_builds, cand_i=cand_i,
                    cand_j=cand_j, cand_full=cand_full)


def _check_finite(st: DEMState) -> DEMState:
    bad = ~(jnp.all(jnp.isfinite(st.x)) & jnp.all(jnp.isfinite(st.v)) & jnp.all(jnp.isfinite(st.w)))
    return eqx.tree_at(lambda s: s.flags, st, st.flags | jnp.where(bad, FLAG_NONFINITE, 0).astype(jnp.int32))


def step(state: DEMState, mat, dt, *, inelastic=True, freeze_contacts=False, skin=0.1,
         event_times=True) -> DEMState:
    """One leapfrog step of length ``dt`` [s] (module docstring; Wada et al. 2007 §4, eqs. 46-47).

    Arguments:
        state: :class:`DEMState`.
        mat: the material.
        dt: time step [s] (Wada et al. use 0.014 t_c).
        inelastic: static; apply the inelastic clipping of sliding, rolling and twisting (eqs. 39-43).
        freeze_contacts: static; no contact creation or breaking (the dissipationless test of the spec).
        skin: Verlet skin in units of r1 (must match the one of :func:`init_state`).
        event_times: static; correct the impulse of each contact creation and breaking for the instant of the
            event within the step (module docstring, "Event times"): rebound speeds to O(dt^2) instead of O(dt),
            and a trajectory continuous in the material constants and initial conditions across event-step
            changes (derivatives include the motion of the events). False: events act at whole steps.

    Returns: the state after the step.
    """
    cfg = _Cfg(state.dim, bool(inelastic), bool(freeze_contacts), bool(event_times))
    return _step(state, mat, jnp.asarray(dt, jnp.float64), jnp.asarray(skin, jnp.float64), cfg)


def diagnostics(state: DEMState, mat) -> dict:
    """Energies, momenta and counters of a state (all at the synchronous time of the leapfrog).

    Returns a dict of arrays: ``E_kin`` (translational + rotational kinetic energy [erg]), ``E_kin_rot`` [erg],
    ``U`` (U_n + U_s + U_r + U_t [erg]), ``U_n``, ``U_s``, ``U_r``, ``U_t``, ``E_dis_n``, ``E_dis_s``,
    ``E_dis_r``, ``E_dis_t`` [erg], ``E_total`` (E_kin + U + sum E_dis [erg]), ``P`` (3,) total momentum
    [g cm s^-1], ``L`` (3,) total angular momentum sum(m x x v + I w) about the origin [g cm^2 s^-1],
    ``n_contacts`` (int), ``flags`` (int32), ``step`` (int64).

    References: Wada et al. (2007) §4 and Fig. 6 (energy budget).
    """
    m1, I1 = mat.m1, mat.I1
    e_tr = 0.5 * m1 * jnp.sum(state.v**2)
    e_rot = 0.5 * I1 * jnp.sum(state.w**2)
    U = state.U
    out = dict(E_kin=e_tr + e_rot, E_kin_rot=e_rot, U=jnp.sum(U), U_n=U[0], U_s=U[1], U_r=U[2], U_t=U[3],
               E_dis_n=state.E_dis[0], E_dis_s=state.E_dis[1], E_dis_r=state.E_dis[2], E_dis_t=state.E_dis[3],
               E_total=e_tr + e_rot + jnp.sum(U) + jnp.sum(state.E_dis),
               P=m1 * jnp.sum(state.v, axis=0),
               L=m1 * jnp.sum(jnp.cross(state.x, state.v), axis=0) + I1 * jnp.sum(state.w, axis=0),
               n_contacts=jnp.sum(state.active).astype(jnp.int64), flags=state.flags, step=state.step)
    return out


def flags_code(flags):
    """The :data:`jaxcoag.RESULT_NAMES` code (int32, elementwise, traceable) of DEM ``flags`` words:
    ``capacity_exceeded`` (contact or neighbour capacity; pairs may have been missed), ``nonfinite``, else
    ``successful`` (0)."""
    from ..._status import RESULT_NAMES

    flags = jnp.asarray(flags)
    cap = (flags & (FLAG_CONTACTS | FLAG_NEIGHBOURS)) != 0
    nf = (flags & FLAG_NONFINITE) != 0
    code = jnp.where(nf, RESULT_NAMES.index("nonfinite"), 0)
    return jnp.where(cap, RESULT_NAMES.index("capacity_exceeded"), code).astype(jnp.int32)


# ------------------------------------------------------------------------------------------------- loops
def _n_steps_loop(st, mat, dt, skin, cfg, n):
    """``n`` (traced int) steps: a while loop over blocks of at most ``_DISPATCH_STEPS`` (:func:`_steps`)."""

    def body(c):
        s, left = c
        m = jnp.minimum(left, _DISPATCH_STEPS)
        return _steps(s, mat, dt, skin, cfg, m), left - m

    return jax.lax.while_loop(lambda c: c[1] > 0, body, (st, jnp.asarray(n, jnp.int64)))[0]


def integrate(state: DEMState, mat, n_steps: int, *, dt, inelastic=True, freeze_contacts=False, skin=0.1,
              chunk=None, event_times=True):
    """``n_steps`` leapfrog steps as a fixed-length ``lax.scan`` over chunks (reverse-mode differentiable).

    Arguments:
        state: :class:`DEMState`. mat: the material. n_steps: static number of steps.
        dt: time step [s]. inelastic, freeze_contacts, skin, event_times: as for :func:`step`.
        chunk: steps per chunk (static; default min(n_steps, 1000)); must divide n_steps. Each chunk is a
            ``jax.checkpoint``-ed inner scan, so reverse mode stores one state per chunk.

    Returns:
        (state, record): record is :func:`diagnostics` after every chunk (leading axis n_steps/chunk).

    References: Wada et al. (2007) §4; spec Part C (chunked scan).
    """
    n_steps = int(n_steps)
    chunk = int(chunk or min(n_steps, 1000))
    if n_steps < 1 or chunk < 1 or n_steps % chunk:
        raise JaxcoagInputError(f"integrate: n_steps ({n_steps}) must be a positive multiple of chunk ({chunk}).")
    cfg = _Cfg(state.dim, bool(inelastic), bool(freeze_contacts), bool(event_times))
    return _compiled(_integrate_jit, state, mat, dt, skin)(state, mat, jnp.asarray(dt, jnp.float64),
                                                           jnp.asarray(skin, jnp.float64), cfg, n_steps // chunk, chunk)


#: Monomer counts N, ASSIGNER_OFF_FROM <= N < ASSIGNER_FROM, for which the DEM's jitted runs (:func:`integrate`,
#: :func:`integrate_until`, :func:`advance_to`) are compiled without XLA's CPU ``cpu-parallel-task-assigner``. That
#: pass splits large loop fusions over the host threads; in the step of a few thousand monomers it split hundreds of
#: fusions (230 in the 2-D step of N = 2048) too small for the thread hand-offs to pay. ``dem.integrate``, 2 cores,
#: assigner on against off, us per step, two runs of ``benchmarks/cpu_parallelism.py`` (2026-11-28): N = 2048:
#: 320 / 297 and 458 / 284 (2-D), 373 / 317 and 488 / 377 (3-D); N = 512: 85 / 88 and 83 / 83 (2-D), 95 / 98 and
#: 91 / 97 (3-D); N >= 4096: 1030-1110 / 1051-1180 (3-D 4096), 1827-1926 / 1945-2127 and 1787-1821 / 2063-2109 (2-D
#: and 3-D 8192), where the split pays. docs/design_notes.md, "One collision's step and the second CPU core".
ASSIGNER_OFF_FROM = 1024
ASSIGNER_FROM = 4096
_NO_ASSIGNER = {"xla_disable_hlo_passes": "cpu-parallel-task-assigner"}


class _Jitted(NamedTuple):
    """A run function jitted twice: with XLA's default passes (``large``) and without the parallel task assigner
    (``small``)."""
    large: object
    small: object


def _with_small(fn, static_argnums):
    return _Jitted(jax.jit(fn, static_argnums=static_argnums),
                   jax.jit(fn, static_argnums=static_argnums, compiler_options=_NO_ASSIGNER))


def _compiled(jitted: _Jitted, state, *args):
    """The jitted run function for ``state``: from :data:`ASSIGNER_OFF_FROM` to :data:`ASSIGNER_FROM` monomers the
    copy compiled without the parallel task assigner (the same computation). Under any transformation (a caller's
    jit, grad or vmap: a traced ``state`` or ``args``, or a jit trace in progress, where even a new constant is a
    tracer) the plain copy: JAX takes compile options from a top-level jit only, and refuses them on a jit it
    traces through."""
    small = (ASSIGNER_OFF_FROM <= state.x.shape[-2] < ASSIGNER_FROM and not is_traced((state, args))
             and not is_traced(jnp.zeros((), jnp.int32)))
    return jitted.small if small else jitted.large


@functools.partial(_with_small, static_argnums=(4, 5, 6))
def _integrate_jit(state, mat, dt, skin, cfg, n_chunks, chunk):
    @jax.checkpoint
    def one_chunk(st):
        st = _steps(st, mat, dt, skin, cfg, chunk)
        return _check_finite(st)

    def body(st, _):
        st = one_chunk(st)
        return st, diagnostics(st, mat)

    return jax.lax.scan(body, state, None, length=n_chunks)


def integrate_until(state: DEMState, mat, stop, *, dt, max_chunks: int, chunk: int = 1000, inelastic=True,
                    freeze_contacts=False, skin=0.1, event_times=True):
    """Chunks of ``chunk`` steps in a ``lax.while_loop`` until ``stop(state)`` is True (checked after each chunk),
    ``max_chunks`` chunks were taken, or a flag (capacity, non-finite) is raised. Forward mode only.

    Arguments:
        state, mat: as for :func:`integrate`. stop: jittable function of a :class:`DEMState` -> bool scalar.
        dt: time step [s]. max_chunks: static length of the record. chunk: static steps per chunk.
        inelastic, freeze_contacts, skin, event_times: as for :func:`step`.

    Returns:
        (state, record, n_done): record holds :func:`diagnostics` after each chunk (leading axis max_chunks;
        entries at and after n_done repeat the final state's), n_done the chunks taken.
    """
    cfg = _Cfg(state.dim, bool(inelastic), bool(freeze_contacts), bool(event_times))
    return _compiled(_until_jit, state, mat, dt, skin)(state, mat, jnp.asarray(dt, jnp.float64),
                                                       jnp.asarray(skin, jnp.float64), stop, cfg, int(max_chunks),
                                                       int(chunk))


@functools.partial(_with_small, static_argnums=(4, 5, 6, 7))
def _until_jit(state, mat, dt, skin, stop, cfg, max_chunks, chunk):
    rec0 = jax.tree_util.tree_map(lambda a: jnp.zeros((max_chunks,) + jnp.shape(a), jnp.asarray(a).dtype),
                                  diagnostics(state, mat))

    def cond(c):
        st, _, k = c
        return (k < max_chunks) & ~stop(st) & (st.flags == 0)

    def body(c):
        st, rec, k = c
        st = _check_finite(_n_steps_loop(st, mat, dt, skin, cfg, chunk))
        d = diagnostics(st, mat)
        rec = jax.tree_util.tree_map(lambda r, a: r.at[k].set(a), rec, d)
        return st, rec, k + 1

    st, rec, k = jax.lax.while_loop(cond, body, (state, rec0, jnp.zeros((), jnp.int64)))
    last = diagnostics(st, mat)
    idx = jnp.arange(max_chunks)
    rec = jax.tree_util.tree_map(
        lambda r, a: jnp.where((idx >= k).reshape((-1,) + (1,) * jnp.ndim(a)), a, r), rec, last)
    return st, rec, k


def advance_to(state: DEMState, mat, target_steps, *, dt, inelastic=True, freeze_contacts=False, skin=0.1,
               event_times=True):
    """Advance to each absolute step count of ``target_steps`` (1-D int64, non-decreasing) and record
    :func:`diagnostics` there (``lax.scan`` over the targets, a ``while_loop`` of steps within). Forward mode only.
    Options (inelastic, freeze_contacts, skin, event_times) as for :func:`step`.

    Returns: (state, record with leading axis len(target_steps)).
    """
    cfg = _Cfg(state.dim, bool(inelastic), bool(freeze_contacts), bool(event_times))
    return _compiled(_advance_jit, state, mat, dt, skin, target_steps)(
        state, mat, jnp.asarray(dt, jnp.float64), jnp.asarray(skin, jnp.float64), jnp.asarray(target_steps, jnp.int64),
        cfg)


@functools.partial(_with_small, static_argnums=(5,))
def _advance_jit(state, mat, dt, skin, targets, cfg):
    def body(st, target):
        n = jnp.maximum(target - st.step, 0)
        # a raised flag stops the run: later outputs repeat the flagged state
        n = jnp.where(st.flags == 0, n, 0)
        st = _check_finite(_n_steps_loop(st, mat, dt, skin, cfg, n))
        return st, diagnostics(st, mat)

    return jax.lax.scan(body, state, targets)
