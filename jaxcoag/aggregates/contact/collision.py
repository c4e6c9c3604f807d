"""Collisions of two monomer aggregates with the contact DEM: ``collide`` and the ``DEM`` engine of ``jaxcoag.evolve``.

``collide(a, b, v_imp, material)`` places two :class:`~jaxcoag.aggregates.contact.aggregate.Aggregate` s head-on
along x in their centre-of-mass frame (Wada et al. 2007 §4: the left one moves at +v_imp n_b/(n_a + n_b), the
right one at -v_imp n_a/(n_a + n_b), i.e. +-v_imp/2 for equal aggregates; the closest pair starts a small gap,
0.05 r1, apart; ``impact_parameter`` offsets the right aggregate along y), integrates the monomer dynamics of
:mod:`~jaxcoag.aggregates.contact.dem` until the outcome settles and returns a :class:`CollisionResult`: the
final clusters (connected components of the contact graph), the gyration radius and contact number of the largest
one (eq. 50, §5.1), and the energy budget over time (kinetic, potential, the four dissipation channels, total;
their Fig. 6).

Default end of a run (the paper does not state one): t_contact + 4 (2 r_g,tot)/v_imp, with t_contact the first
contact event and r_g,tot the gyration radius of the two placed aggregates together, and at least ``quiet_steps``
(1e4) steps after the last contact creation or breaking.

The same run is an engine of the one API: ``jaxcoag.evolve(material, DEM(...), Collision(a, b, v_imp), t_out)``
(``t_out`` [s] are the times of the energy record; checkpoint/resume, Ctrl-C and progress come with
``checkpoint=`` / ``progress=``). ``collide`` runs that engine through the same segment driver
(:func:`jaxcoag.checkpoint.run_segments`), whose adaptive-end hook checks the stop criterion between segments, so
``collide(..., checkpoint=path)`` checkpoints and resumes like ``evolve``.

References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007, ApJ 661, 320) §4 (set-up, dt = 0.014 t_c), §5.1
(eq. 50, n_con, N_large), Fig. 6 (energy budget).
"""

from __future__ import annotations

import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._engine import AbstractEngine
from ..._status import RESULTS, is_failure, result_code, result_from_code
from ..._validate import JaxcoagInputError, is_traced, require_x64
from . import dem as _dem
from .aggregate import Aggregate
from .materials import Material

__all__ = ["Collision", "DEM", "CollisionResult", "collide", "DT_DEFAULT", "DT_MAX"]

#: Default time step in units of t_c (Wada et al. 2007 §4: relative energy error < 1e-4).
DT_DEFAULT = 0.014
#: Largest accepted time step in units of t_c (the paper used up to 0.112 t_c; the pair oscillation at
#: 1.408/t_c and the sliding mode at ~1.9/t_c need omega dt << 2 for the leapfrog).
DT_MAX = 0.2
#: Largest accepted initial overlap 2 r1 - |x_i - x_j| in units of r1 (JKR contacts have delta ~ delta_0 << r1).
OVERLAP_MAX = 0.1


def _is_concrete(*xs):
    return not any(is_traced(x) for x in xs)


class Collision(eqx.Module):
    """Initial condition of a DEM run: two aggregates approaching head-on (Wada et al. 2007 §4).

    Fields:
        a, b: :class:`Aggregate` s of the same dimension (2: planar, 3) and monomer radius r1 [cm]. ``a`` starts
            on the left (-x), ``b`` on the right, each with the orientation it has.
        v_imp: relative impact speed [cm s^-1] (> 0).
        impact_parameter: offset of b's centre of mass along y [cm] (0: head-on).
        gap: initial separation of the closest monomer pair beyond contact [cm]; None: 0.05 r1.

    Placement: the aggregates' centres of mass are put on the x axis (b shifted by ``impact_parameter`` along y),
    b is moved along x until the closest pair (over the pairs that meet on the way) is 2 r1 + gap apart, and the
    system is put in its centre-of-mass frame (positions and velocities).
    """

    a: Aggregate
    b: Aggregate
    v_imp: float | jax.Array
    impact_parameter: float | jax.Array = 0.0
    gap: float | jax.Array | None = None

    def __check_init__(self):
        for name in ("a", "b"):
            if not isinstance(getattr(self, name), Aggregate):
                raise JaxcoagInputError(f"Collision.{name} must be a contact.Aggregate (e.g. contact.bcca(128, key) or "
                                        f"contact.monomer()); got {type(getattr(self, name)).__name__}.")
        if self.a.dim != self.b.dim:
            raise JaxcoagInputError(f"Collision: the aggregates have different dimensions ({self.a.dim} and "
                                    f"{self.b.dim}); build both in 2-D (planar) or both in 3-D.")
        if _is_concrete(self.a.r1, self.b.r1) and not math.isclose(float(self.a.r1), float(self.b.r1), rel_tol=1e-12):
            raise JaxcoagInputError(f"Collision: the aggregates have different monomer radii ({float(self.a.r1):g} "
                                    f"and {float(self.b.r1):g} cm); the contact model needs identical monomers.")
        if _is_concrete(self.v_imp):
            v = np.asarray(self.v_imp, np.float64)
            if v.ndim != 0 or not (np.isfinite(v) and v > 0):
                raise JaxcoagInputError(f"Collision.v_imp must be a finite impact speed > 0 in cm/s; got "
                                        f"{self.v_imp!r}.")
        if _is_concrete(self.impact_parameter):
            p = np.asarray(self.impact_parameter, np.float64)
            if p.ndim != 0 or not np.isfinite(p):
                raise JaxcoagInputError(f"Collision.impact_parameter must be a finite offset in cm; got "
                                        f"{self.impact_parameter!r}.")
        if self.gap is not None and _is_concrete(self.gap):
            g = np.asarray(self.gap, np.float64)
            if g.ndim != 0 or not (np.isfinite(g) and g >= 0):
                raise JaxcoagInputError(f"Collision.gap must be a separation >= 0 in cm (or None); got {self.gap!r}.")
        for name in ("a", "b"):
            _check_overlap(getattr(self, name), name)

    @property
    def dim(self) -> int:
        """2 (planar) or 3."""
        return self.a.dim

    @property
    def n(self) -> int:
        """Total number of monomers."""
        return self.a.n + self.b.n


def _check_overlap(agg, name):
    """Refuse monomers deeper in each other than any JKR contact (2 r1 - |x_i - x_j| > 0.1 r1)."""
    if not _is_concrete(agg.positions, agg.r1) or agg.n < 2:
        return
    from scipy.spatial import cKDTree

    x = np.asarray(agg.positions, np.float64)
    r1 = float(agg.r1)
    pairs = cKDTree(x).query_pairs((2.0 - OVERLAP_MAX) * r1, output_type="ndarray")
    if len(pairs):
        i, j = pairs[0]
        d = float(np.linalg.norm(x[i] - x[j]))
        raise JaxcoagInputError(
            f"Collision.{name}: monomers {i} and {j} overlap by {2 * r1 - d:.3g} cm = {(2 * r1 - d) / r1:.3g} r1 "
            f"({len(pairs)} such pairs); monomers in contact sit at 2 r1 - delta_0 (delta_0 << r1), so an overlap "
            f"beyond {OVERLAP_MAX} r1 is unphysical: check the positions (cm) and r1.")


def _embed3(x):
    """(n, 2) -> (n, 3) with z = 0; (n, 3) unchanged."""
    x = jnp.asarray(x, jnp.float64)
    return x if x.shape[1] == 3 else jnp.concatenate([x, jnp.zeros((x.shape[0], 1))], axis=1)


def _place(coll: Collision, r1):
    """Positions (N, 3) [cm] and velocities (N, 3) [cm s^-1] of the placed pair in the COM frame, and
    r_g,tot [cm] of the placed pair."""
    a = _embed3(coll.a.positions)
    b = _embed3(coll.b.positions)
    ey = jnp.array([[0.0, 1.0, 0.0]])
    a = a - jnp.mean(a, axis=0, keepdims=True)
    b = b - jnp.mean(b, axis=0, keepdims=True) + jnp.asarray(coll.impact_parameter, jnp.float64) * ey
    gap = 0.05 * r1 if coll.gap is None else jnp.asarray(coll.gap, jnp.float64)
    d = 2.0 * r1 + gap
    lat = a[:, None, 1:] - b[None, :, 1:]
    rho2 = jnp.sum(lat * lat, axis=-1)
    hit = rho2 < d * d
    need = a[:, None, 0] - b[None, :, 0] + jnp.sqrt(jnp.where(hit, d * d - rho2, 0.0))
    s_hit = jnp.max(jnp.where(hit, need, -jnp.inf))
    s_miss = jnp.max(a[:, 0]) - jnp.min(b[:, 0]) + d
    s = jnp.where(jnp.any(hit), s_hit, s_miss)
    b = b + s * jnp.array([[1.0, 0.0, 0.0]])
    x = jnp.concatenate([a, b], axis=0)
    x = x - jnp.mean(x, axis=0, keepdims=True)
    na, nb = coll.a.n, coll.b.n
    v = jnp.asarray(coll.v_imp, jnp.float64)
    ex = jnp.array([1.0, 0.0, 0.0])
    vel = jnp.concatenate([jnp.broadcast_to(v * nb / (na + nb) * ex, (na, 3)),
                           jnp.broadcast_to(-v * na / (na + nb) * ex, (nb, 3))], axis=0)
    r_g = jnp.sqrt(jnp.mean(jnp.sum(x * x, axis=-1)))
    return x, vel, r_g


def _random_rotations(a: Aggregate, b: Aggregate, key):
    """``a`` and ``b`` rotated about their centres of mass by independent uniform random rotations (2-D: an angle
    about z; 3-D: uniform on SO(3)), drawn as in :func:`~jaxcoag.aggregates.contact.structures.bcca`."""
    from .structures import _rng_from_key, _rotations

    R = _rotations(_rng_from_key(key), 1, a.dim)[0]
    out = []
    for agg, Rk in zip((a, b), R):
        x = np.asarray(agg.positions, np.float64)
        c = x.mean(axis=0, keepdims=True)
        out.append(Aggregate(jnp.asarray((x - c) @ Rk.T + c), agg.r1))
    return out


class _CollisionState(eqx.Module):
    """Engine state: the DEM state plus the collision's impact speed [cm s^-1], impact energy [erg], r_g,tot [cm]
    of the placed pair and the index of b's first monomer."""

    dem: _dem.DEMState
    v_imp: jax.Array
    E_imp: jax.Array
    r_g0: jax.Array
    n_a: jax.Array


class DEM(AbstractEngine):
    """Monomer contact DEM (Wada et al. 2007) as an engine of ``jaxcoag.evolve``.

    ``jaxcoag.evolve(material, DEM(...), Collision(a, b, v_imp), t_out)``: the "kernel" is the contact
    :class:`~jaxcoag.aggregates.contact.materials.Material`, the initial condition a :class:`Collision` (or a
    :class:`CollisionResult` to continue), ``t_out`` [s] the times of the energy record (each rounded to a whole
    number of steps after t0). Returns a :class:`CollisionResult`.

    Fields:
        dt: time step [s]; None: 0.014 t_c of the material (Wada et al. 2007 §4). Refused above 0.2 t_c.
        capacity: contact slots per monomer (static; the contact list holds capacity x N contacts). None: 2 in 2-D
            and 3 in 3-D (``dem.default_capacity``), or ``dem.max_capacity`` (3, 6) when the aggregates already
            hold more contacts than that.
        neighbours: Verlet-list slots per monomer (static; default 8 in 2-D, 16 in 3-D).
        skin: Verlet skin in units of r1 (default 0.1).
        inelastic: static; inelastic sliding, rolling and twisting (eqs. 39-43). False: elastic springs only.
        freeze_contacts: static; no contact creation or breaking (the dissipationless check).

    Status: ``capacity_exceeded`` when the contact table or the neighbour list overflowed (the run stops there;
    raise ``capacity``/``neighbours``), ``nonfinite`` on NaN/inf. Forward mode only (``lax.while_loop``); for
    reverse-mode gradients use :func:`jaxcoag.aggregates.contact.dem.integrate`.

    References: Wada et al. (2007) §4.
    """

    dt: float | jax.Array | None = None
    capacity: int | None = eqx.field(static=True, default=None)
    neighbours: int | None = eqx.field(static=True, default=None)
    skin: float | jax.Array = 0.1
    inelastic: bool = eqx.field(static=True, default=True)
    freeze_contacts: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        for name in ("capacity", "neighbours"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1):
                raise JaxcoagInputError(f"DEM({name}=...) must be None or a positive int (slots per monomer); "
                                        f"got {v!r}.")
        if self.dt is not None and _is_concrete(self.dt):
            d = np.asarray(self.dt, np.float64)
            if d.ndim != 0 or not (np.isfinite(d) and d > 0):
                raise JaxcoagInputError(f"DEM(dt=...) must be a time step > 0 in s (or None for 0.014 t_c); got "
                                        f"{self.dt!r}.")
        if _is_concrete(self.skin):
            s = np.asarray(self.skin, np.float64)
            if s.ndim != 0 or not (np.isfinite(s) and 0 < s <= 1):
                raise JaxcoagInputError(f"DEM(skin=...) must be in (0, 1] (Verlet skin in units of r1, e.g. 0.1); "
                                        f"got {self.skin!r}.")
        for name in ("inelastic", "freeze_contacts"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise JaxcoagInputError(f"DEM({name}=...) must be True or False; got {getattr(self, name)!r}.")

    @property
    def name(self) -> str:
        return "dem"

    def _dt(self, mat):
        return DT_DEFAULT * mat.t_c if self.dt is None else jnp.asarray(self.dt, jnp.float64)

    def _kw(self):
        return dict(inelastic=self.inelastic, freeze_contacts=self.freeze_contacts, skin=self.skin)

    # ------------------------------------------------------------------ protocol
    def _check(self, kernel, initial, t_out, t0, outcome, key):
        if not isinstance(kernel, Material):
            raise JaxcoagInputError(f"the DEM engine's kernel is the monomer material, a contact.Material (e.g. "
                                    f"contact.materials.ice()); got {type(kernel).__name__}.")
        if outcome is not None:
            raise JaxcoagInputError("the DEM engine resolves collisions itself; pass outcome=None.")
        dt = self._dt(kernel)
        if _is_concrete(dt, kernel.t_c) and float(dt) > DT_MAX * float(kernel.t_c):
            raise JaxcoagInputError(
                f"DEM(dt={float(dt):.4g} s) is {float(dt) / float(kernel.t_c):.3g} t_c, above the stability limit "
                f"{DT_MAX} t_c of the leapfrog (t_c = {float(kernel.t_c):.4g} s for this material); use dt <= "
                f"{DT_MAX * float(kernel.t_c):.4g} s, or None for {DT_DEFAULT} t_c.")
        if isinstance(initial, CollisionResult):
            st = initial.final_state
            if not isinstance(st, _CollisionState):
                raise JaxcoagInputError("initial is a CollisionResult without final_state; continue a result returned "
                                        "by jaxcoag.evolve or contact.collide.")
            K = st.dem.ci.shape[-1] // st.dem.x.shape[-2]
            if self.capacity is not None and int(self.capacity) != K:
                raise JaxcoagInputError(f"the continued run has capacity {K}; use DEM(capacity={K}) or None.")
            return
        if not isinstance(initial, Collision):
            raise JaxcoagInputError(f"the DEM engine starts from a contact.Collision(a, b, v_imp) or continues a "
                                    f"CollisionResult; got {type(initial).__name__}.")
        if _is_concrete(kernel.r1, initial.a.r1) and not math.isclose(float(kernel.r1), float(initial.a.r1),
                                                                      rel_tol=1e-12):
            raise JaxcoagInputError(f"the aggregates' monomer radius r1 = {float(initial.a.r1):g} cm differs from the "
                                    f"material's r1 = {float(kernel.r1):g} cm; build them with the same r1 (e.g. "
                                    f"contact.bcca(n, key, material=mat)).")
        if _is_concrete(initial.a.positions, initial.b.positions, initial.impact_parameter, kernel.r1):
            self._check_capacity(kernel, initial)

    def _capacity(self, mat, coll, have=None):
        """Slots per monomer of a new run: ``capacity``, or for None the default, raised to ``dem.max_capacity``
        when the aggregates already hold more contacts than the default list (concrete positions only; ``have``:
        their contact count if already known)."""
        if self.capacity is not None:
            return int(self.capacity)
        K = _dem.default_capacity(coll.dim)
        if (_initial_contacts(coll, mat) if have is None else have) > K * (coll.a.n + coll.b.n):
            K = _dem.max_capacity(coll.dim)
        return K

    def _check_capacity(self, mat, coll):
        """Refuse capacities whose contact list (capacity x N slots) cannot hold the initial contacts."""
        n_tot = coll.a.n + coll.b.n
        have = _initial_contacts(coll, mat)
        K = self._capacity(mat, coll, have)
        if have > K * n_tot:
            need = -(-have // n_tot)
            raise JaxcoagInputError(f"DEM(capacity={K}) contact slots per monomer ({K * n_tot} in all) cannot hold the "
                                    f"{have} initial contacts of the two aggregates; give capacity >= {need}.")

    def _init(self, kernel, initial, t0, outcome, key):
        if isinstance(initial, CollisionResult):
            return initial.final_state
        r1 = kernel.r1
        x, v, r_g0 = _place(initial, r1)
        st = _dem.init_state(x, v, 0.0, kernel, dim=initial.dim, capacity=self._capacity(kernel, initial),
                             neighbours=self.neighbours, skin=self.skin, t0=t0)
        na, nb = initial.a.n, initial.b.n
        v_imp = jnp.asarray(initial.v_imp, jnp.float64)
        E_imp = 0.5 * kernel.m1 * (na * nb / (na + nb)) * v_imp**2
        return _CollisionState(dem=st, v_imp=v_imp, E_imp=E_imp, r_g0=r_g0, n_a=jnp.asarray(na, jnp.int64))

    def _targets(self, kernel, state, t_seg):
        dt = self._dt(kernel)
        return jnp.round((jnp.asarray(t_seg, jnp.float64) - state.dem.t0) / dt).astype(jnp.int64)

    def _advance(self, kernel, state, t_seg, outcome):
        dt = self._dt(kernel)
        st, rec = _dem.advance_to(state.dem, kernel, self._targets(kernel, state, t_seg), dt=dt, **self._kw())
        rec = dict(rec)
        rec["status"] = _dem.flags_code(rec["flags"])
        return eqx.tree_at(lambda s: s.dem, state, st), rec

    def _progress_time(self, t: float) -> str:
        """Progress-bar time in s (a collision lasts nanoseconds to microseconds, not years)."""
        return f"t = {t:.4g} s"

    def _progress_info(self, state_before, state_after, out, wall_s):
        """Progress-bar figures of one segment: steps per second and contacts."""
        n = int(state_after.dem.step) - int(state_before.dem.step)
        rate = n / wall_s if wall_s > 0 else float("inf")
        return f"{n} steps ({rate:.3g}/s), {int(np.asarray(out['n_contacts'])[-1])} contacts"

    def _result(self, kernel, t, outs, state, outcome):
        st = state.dem
        flags = st.flags
        status = result_from_code(_dem.flags_code(flags))
        if _is_concrete(flags):
            _warn_flags(int(flags))
        dim = st.dim
        x, v = st.x[:, :dim], st.v[:, :dim]
        from .analysis import largest_cluster

        edges = jnp.stack([st.ci, st.cj], axis=-1)
        lc = largest_cluster(st.x, edges, st.active)
        labels, sizes, r_g, n_con = lc.labels, lc.sizes, lc.r_g, lc.n_con
        return CollisionResult(
            t=jnp.asarray(t, jnp.float64), status=status, E_kin=outs["E_kin"], E_kin_rot=outs["E_kin_rot"], U=outs["U"],
            E_dis_n=outs["E_dis_n"], E_dis_s=outs["E_dis_s"], E_dis_r=outs["E_dis_r"], E_dis_t=outs["E_dis_t"],
            E_total=outs["E_total"], P=outs["P"], L=outs["L"], contacts=outs["n_contacts"], positions=x,
            velocities=v, omega=st.w, labels=labels, cluster_sizes=sizes, r_g=r_g, n_contacts=n_con,
            E_imp=state.E_imp, v_imp=state.v_imp, n_steps=st.step, dt=self._dt(kernel), r1=kernel.r1,
            final_state=state)


def _initial_contacts(coll, mat):
    """Number of touching pairs (centre distance <= 2 r1) within the two aggregates of ``coll`` (0 when traced)."""
    from scipy.spatial import cKDTree

    if not _is_concrete(coll.a.positions, coll.b.positions, mat.r1):
        return 0
    n = 0
    for agg in (coll.a, coll.b):
        x = np.asarray(agg.positions, np.float64)
        if x.shape[0] >= 2:
            n += len(cKDTree(x).query_pairs(2.0 * float(mat.r1), output_type="ndarray"))
    return n


def _warn_flags(flags):
    if flags & (_dem.FLAG_CONTACTS | _dem.FLAG_NEIGHBOURS):
        warnings.warn(_capacity_message(flags), RuntimeWarning, stacklevel=3)


def _capacity_message(flags):
    what = []
    if flags & _dem.FLAG_CONTACTS:
        what.append("the contact list (raise DEM(capacity=...) / collide(capacity=...))")
    if flags & _dem.FLAG_NEIGHBOURS:
        what.append("the neighbour list or a cell of the cell list (raise DEM(neighbours=...) / "
                    "collide(neighbours=...); monomers are much closer than 2 r1)")
    return ("DEM run stopped with status capacity_exceeded: the run needed more slots than " + " and ".join(what)
            + "; the state after the overflow is the last one recorded.")


class CollisionResult(eqx.Module):
    """Outcome and energy budget of a DEM collision (``contact.collide`` / ``evolve(material, DEM(), ...)``).

    Fields (T = records of the energy budget, N monomers; float64 cgs):
        t: (T,) record times [s]. status: :class:`jaxcoag.RESULTS` item.
        E_kin, E_kin_rot, U, E_dis_n, E_dis_s, E_dis_r, E_dis_t, E_total: (T,) kinetic (translational +
            rotational), rotational part, potential (U_n + U_s + U_r + U_t), dissipated energies of the normal,
            sliding, rolling and twisting channels, and the total E_kin + U + sum E_dis [erg] (Wada Fig. 6).
        P, L: (T, 3) total momentum [g cm s^-1] and angular momentum sum(m x x v + I w) [g cm^2 s^-1].
        contacts: (T,) number of contacts.
        positions, velocities: (N, dim) final monomer centres [cm] and velocities [cm s^-1] (a's monomers first).
        omega: (N, 3) final angular velocities [rad s^-1].
        labels: (N,) cluster of each monomer (0 = the largest). cluster_sizes: (N,) final cluster sizes, largest
            first, zero-padded (``n_clusters`` non-zero entries).
        r_g: gyration radius of the largest cluster [cm] (Wada eq. 50).
        n_contacts: contacts inside the largest cluster per monomer of it (Wada §5.1 n_con).
        E_imp: impact energy (1/2) mu v_imp^2 [erg] (mu = reduced mass of the aggregates). v_imp [cm s^-1].
        n_steps: steps taken. dt: time step [s]. r1: monomer radius [cm].
        final_state: the engine state at t[-1] (pass the result as ``initial`` to ``evolve`` to continue).
    """

    t: jax.Array
    status: RESULTS
    E_kin: jax.Array
    E_kin_rot: jax.Array
    U: jax.Array
    E_dis_n: jax.Array
    E_dis_s: jax.Array
    E_dis_r: jax.Array
    E_dis_t: jax.Array
    E_total: jax.Array
    P: jax.Array
    L: jax.Array
    contacts: jax.Array
    positions: jax.Array
    velocities: jax.Array
    omega: jax.Array
    labels: jax.Array
    cluster_sizes: jax.Array
    r_g: jax.Array
    n_contacts: jax.Array
    E_imp: jax.Array
    v_imp: jax.Array
    n_steps: jax.Array
    dt: jax.Array
    r1: jax.Array
    final_state: _CollisionState

    @property
    def n_clusters(self):
        """Number of final clusters."""
        return jnp.sum(self.cluster_sizes > 0)

    @property
    def N_large(self):
        """Size of the largest final cluster (Wada §5: N_large)."""
        return self.cluster_sizes[..., 0]

    @property
    def E_dis(self):
        """(T,) total dissipated energy [erg]."""
        return self.E_dis_n + self.E_dis_s + self.E_dis_r + self.E_dis_t

    def to_xarray(self, *, attrs=None):
        """Labelled dataset: dims ``t``, ``monomer``, ``xyz`` (and ``cluster``); coords ``t`` [s], ``t_yr`` [yr];
        the energy budget on t, the final positions/velocities on (monomer, xyz), scalars with units."""
        from ...io import _attr_value, _xr, time_coords

        xr = _xr()
        if jnp.ndim(self.t) != 1:
            raise JaxcoagInputError("to_xarray needs one result; index a vmapped batch first.")
        code = int(np.asarray(result_code(self.status)))
        from ..._status import result_table

        name, message = result_table()[code]
        dim = int(np.shape(self.positions)[-1])
        xyz = ["x", "y", "z"][:dim]
        erg = lambda a, ln: (("t",), np.asarray(a, np.float64), {"units": "erg", "long_name": ln})  # noqa: E731
        data = {
            "E_kin": erg(self.E_kin, "kinetic energy (translational + rotational)"),
            "E_kin_rot": erg(self.E_kin_rot, "rotational kinetic energy"),
            "U": erg(self.U, "potential energy of the contacts (normal + sliding + rolling + twisting)"),
            "E_dis_n": erg(self.E_dis_n, "energy dissipated by contact creation and breaking (normal)"),
            "E_dis_s": erg(self.E_dis_s, "energy dissipated by sliding"),
            "E_dis_r": erg(self.E_dis_r, "energy dissipated by rolling"),
            "E_dis_t": erg(self.E_dis_t, "energy dissipated by twisting"),
            "E_total": erg(self.E_total, "E_kin + U + sum of E_dis"),
            "contacts": (("t",), np.asarray(self.contacts), {"units": "1", "long_name": "number of contacts"}),
            "positions": (("monomer", "xyz"), np.asarray(self.positions, np.float64),
                          {"units": "cm", "long_name": "final monomer centres"}),
            "velocities": (("monomer", "xyz"), np.asarray(self.velocities, np.float64),
                           {"units": "cm s-1", "long_name": "final monomer velocities"}),
            "labels": (("monomer",), np.asarray(self.labels), {"units": "1",
                                                               "long_name": "final cluster (0 = largest)"}),
            "cluster_sizes": (("cluster",), np.asarray(self.cluster_sizes)[: int(self.n_clusters)],
                              {"units": "1", "long_name": "final cluster sizes, largest first"}),
            "r_g": ((), float(self.r_g), {"units": "cm", "long_name": "gyration radius of the largest cluster"}),
            "n_contacts": ((), float(self.n_contacts), {"units": "1", "long_name":
                                                        "contacts per monomer in the largest cluster (n_con)"}),
            "E_imp": ((), float(self.E_imp), {"units": "erg", "long_name": "impact energy"}),
            "v_imp": ((), float(self.v_imp), {"units": "cm s-1", "long_name": "impact speed"}),
            "status": ((), np.int32(code), {"units": "1", "long_name": "jaxcoag.RESULTS code (0 = successful)",
                                            "status_name": name, "status_message": message}),
        }
        coords = {**time_coords(np.asarray(self.t, np.float64)),
                  "monomer": ("monomer", np.arange(np.shape(self.positions)[0])),
                  "xyz": ("xyz", xyz)}
        ds = xr.Dataset(data_vars=data, coords=coords)
        ds.attrs.update(title="jaxcoag contact DEM collision (Wada et al. 2007)", Conventions="CF-1.10", engine="dem",
                        status=name, n_steps=int(self.n_steps), dt_s=float(self.dt), r1_cm=float(self.r1))
        for k, val in (attrs or {}).items():
            ds.attrs[str(k)] = _attr_value(val)
        return ds


#: CollisionResult fields with one entry per record (leading axis = t).
_RECORDS = ("t", "E_kin", "E_kin_rot", "U", "E_dis_n", "E_dis_s", "E_dis_r", "E_dis_t", "E_total", "P", "L", "contacts")


class _CollideEnd(eqx.Module):
    """Adaptive end of :func:`collide` (the ``until`` predicate of :func:`jaxcoag.checkpoint.run_segments`),
    evaluated on the host on the engine state after each segment.

    True when the DEM flags are set (capacity overflow or NaN/inf: the run stops there), or, for the default end
    (``fixed = False``), when t >= t_contact + 8 r_g,tot/v_imp (t_contact = the first contact event, or
    ``t_gap`` = gap/v_imp before any) and at least ``quiet_steps`` steps have passed since the last contact
    creation or breaking. With ``fixed = True`` (``collide(t_end=...)``) only the flags end the run early.

    Fields (Python numbers, so that they enter a checkpoint's run fingerprint exactly): fixed (bool), dt [s],
    t_gap [s], r_g0 (r_g,tot of the placed pair) [cm], v_imp [cm s^-1], quiet_steps [steps].
    """

    fixed: bool
    dt: float
    t_gap: float
    r_g0: float
    v_imp: float
    quiet_steps: int

    def t_stop(self, state) -> float:
        """t_contact + 8 r_g,tot/v_imp [s] of the state's run (Wada et al. 2007 §4 set-up; our default end)."""
        first = int(state.dem.first_event)
        t_contact = first * self.dt if first >= 0 else self.t_gap
        return t_contact + 8.0 * self.r_g0 / self.v_imp

    def __call__(self, state) -> bool:
        st = state.dem
        if int(st.flags):
            return True
        if self.fixed:
            return False
        step = int(st.step)
        return step * self.dt >= self.t_stop(state) and step - int(st.last_event) >= self.quiet_steps


def collide(a, b, v_imp, material, *, impact_parameter=0.0, t_end=None, key=None, dt=None, capacity=None,
            neighbours=None, inelastic=True, record_every=None, quiet_steps=10_000, max_steps=None, gap=None,
            throw=True, checkpoint=None, resume=True, progress=False) -> CollisionResult:
    """Collide two aggregates and run until the outcome settles (Wada et al. 2007 §4).

    The run goes in segments of 25 records through :func:`jaxcoag.checkpoint.run_segments` (the segment driver of
    ``jaxcoag.evolve``), whose adaptive-end predicate checks the default end between segments; with
    ``checkpoint=`` the state is written atomically after every segment, and a run interrupted by Ctrl-C
    (:class:`jaxcoag.checkpoint.RunInterrupted`) or killed resumes from the last segment to a result bit-identical
    to the uninterrupted one (same backend and JAX version).

    Arguments:
        a, b: :class:`Aggregate` s (same dimension and r1 as ``material``); a starts on the left.
        v_imp: relative impact speed [cm s^-1] (> 0).
        material: contact :class:`~jaxcoag.aggregates.contact.materials.Material`.
        impact_parameter: offset of b along y [cm] (0: head-on).
        t_end: run length [s]; None: the default end (module docstring).
        key: ``jax.random`` key: rotate a and b by independent uniform random rotations first; None: as given.
        dt: time step [s]; None: 0.014 t_c. Refused above 0.2 t_c.
        capacity, neighbours: contact and neighbour slots per monomer (see :class:`DEM`). With capacity None the
            run starts with :func:`~jaxcoag.aggregates.contact.dem.default_capacity` (2 in 2-D, 3 in 3-D) or, when
            the aggregates already hold more contacts, :func:`~jaxcoag.aggregates.contact.dem.max_capacity` (3, 6);
            if the list overflows during the run, the collision is rerun from the start with ``max_capacity``
            (a ``RuntimeWarning`` says so; with ``checkpoint=`` the file is restarted).
        inelastic: inelastic sliding/rolling/twisting (default True).
        record_every: steps between records of the energy budget; None: about 200 records over the default run.
        quiet_steps: steps without contact creation or breaking required before the default end (1e4).
        max_steps: step budget of the default end (None: 20x the estimated run + 1e5), rounded up to whole
            segments of 25 records; status ``max_steps_reached`` when spent.
        gap: initial gap of the closest pair [cm] (None: 0.05 r1).
        throw: raise on a failure status (``nonfinite``, ``max_steps_reached``) and on ``capacity_exceeded``.
        checkpoint: path of a checkpoint file (``.npz``; its directory must exist), written atomically after every
            segment (None: no file). The run's fingerprint covers the material, the DEM settings, the placed
            (rotated) aggregates, v_imp, impact parameter, gap, the record times (record_every, t_end or
            max_steps) and the end criterion (quiet_steps); a checkpoint of another collision is refused before
            any work.
        resume: continue from ``checkpoint`` when it exists (True, the default of ``jaxcoag.evolve``); False
            starts afresh and overwrites it.
        progress: a progress bar over the segments (stderr; steps per second and contacts).

    Returns:
        :class:`CollisionResult`.

    Raises:
        :class:`jaxcoag.checkpoint.RunInterrupted` on Ctrl-C (after writing the completed segments).

    References: Wada et al. (2007) §4, §5.1, Fig. 6.
    """
    import os

    from ...checkpoint import run_segments

    require_x64("contact.collide")
    call = dict(impact_parameter=impact_parameter, t_end=t_end, key=key, dt=dt, neighbours=neighbours,
                inelastic=inelastic, record_every=record_every, quiet_steps=quiet_steps, max_steps=max_steps, gap=gap,
                throw=throw, checkpoint=checkpoint, progress=progress)
    coll = Collision(a, b, v_imp, impact_parameter, gap)  # checks a, b before they are rotated
    if key is not None:
        coll = Collision(*_random_rotations(a, b, key), v_imp, impact_parameter, gap)
    auto = capacity is None
    if auto:  # the default list, or max_capacity when the aggregates already need more (DEM._capacity)
        capacity = DEM()._capacity(material, coll)
    engine = DEM(dt=dt, capacity=capacity, neighbours=neighbours, inelastic=bool(inelastic))
    if isinstance(quiet_steps, bool) or not isinstance(quiet_steps, (int, np.integer)) or quiet_steps < 0:
        raise JaxcoagInputError(f"quiet_steps must be an int >= 0; got {quiet_steps!r}.")
    if t_end is not None:
        te = np.asarray(t_end, np.float64)
        if te.ndim != 0 or not (np.isfinite(te) and te > 0):
            raise JaxcoagInputError(f"t_end must be a run length > 0 in s (or None); got {t_end!r}.")
    if checkpoint is not None:
        cp = os.path.abspath(os.fspath(checkpoint))
        if os.path.isdir(cp) or not os.path.isdir(os.path.dirname(cp)):
            raise JaxcoagInputError(f"checkpoint={checkpoint!r} must be a file path in an existing directory (the "
                                    "checkpoint is written there after every segment); create the directory or "
                                    "change the path.")
    engine._check(material, coll, None, 0.0, None, None)
    dt_s = float(engine._dt(material))
    r_g0 = float(_place(coll, material.r1)[2])
    v = float(coll.v_imp)
    t_gap = (0.05 * float(material.r1) if gap is None else float(gap)) / v
    n_est = (t_gap + 8.0 * r_g0 / v) / dt_s if t_end is None else float(t_end) / dt_s
    every = int(record_every) if record_every is not None else max(1, int(round(n_est / 200)))
    if every < 1:
        raise JaxcoagInputError(f"record_every must be a positive int (steps); got {record_every!r}.")
    seg = 25  # records per segment
    if t_end is not None:  # records every `every` steps up to the step of t_end (the last one at t_end), the last
        # segment padded with repeats of t_end (no steps) so that every segment has the same length (one compiled
        # program); the repeats are dropped from the result
        n_end = max(1, int(round(float(t_end) / dt_s)))
        n_rec = -(-n_end // every)
        steps = np.minimum(np.arange(1, seg * -(-n_rec // seg) + 1, dtype=np.int64) * every, n_end)
    else:  # whole segments until the step budget is spent
        budget = int(max_steps) if max_steps is not None else int(20 * n_est + 1e5)
        if budget < 1:
            raise JaxcoagInputError(f"max_steps must be a positive int (steps); got {max_steps!r}.")
        steps = np.arange(1, seg * -(-budget // (seg * every)) + 1, dtype=np.int64) * every
    t_out = steps.astype(np.float64) * dt_s
    end = _CollideEnd(fixed=t_end is not None, dt=dt_s, t_gap=t_gap, r_g0=r_g0, v_imp=v, quiet_steps=int(quiet_steps))
    with warnings.catch_warnings():
        if throw:  # a capacity overflow raises below instead of warning
            warnings.simplefilter("ignore", RuntimeWarning)
        res = run_segments(material, engine, coll, t_out, t0=0.0, outcome=None, key=None, checkpoint=checkpoint,
                           every=seg, resume=resume, progress=progress, desc="contact.collide", until=end)
    if t_end is not None:  # drop the repeated records at t_end
        _, keep = np.unique(np.asarray(res.t), return_index=True)
        if keep.size < res.t.shape[0]:
            res = eqx.tree_at(lambda r: [getattr(r, n) for n in _RECORDS], res,
                              [getattr(res, n)[keep] for n in _RECORDS])
    if t_end is None and not end(res.final_state) and not bool(is_failure(res.status)):
        res = eqx.tree_at(lambda r: r.status, res, RESULTS.max_steps_reached)
    flags = int(res.final_state.dem.flags)
    if auto and flags & _dem.FLAG_CONTACTS and capacity < _dem.max_capacity(coll.dim):
        big = _dem.max_capacity(coll.dim)
        warnings.warn(f"contact.collide: the contact list of {_dem.default_capacity(coll.dim)} slots per monomer "
                      f"overflowed at step {int(res.final_state.dem.step)}; rerunning the collision from the start "
                      f"with capacity={big} (pass capacity={big} to start with it).", RuntimeWarning, stacklevel=2)
        return collide(a, b, v_imp, material, capacity=big, resume=False, **call)
    if throw:
        flags = int(res.final_state.dem.flags)
        if flags & (_dem.FLAG_CONTACTS | _dem.FLAG_NEIGHBOURS):
            raise JaxcoagInputError(_capacity_message(flags))
        if bool(is_failure(res.status)):
            msg = RESULTS[res.status]
            raise RuntimeError(f"contact.collide failed ({msg}); pass throw=False to inspect the result.")
    return res
