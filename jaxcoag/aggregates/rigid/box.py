"""Periodic-box simulator of colliding spheres and rigid fractal aggregates (Richardson 1995, §3, Table I).

A box of side ``L`` (periodic in x, y, z; free space: straight-line motion between collisions) holds
``n0`` equal spheres. :func:`box_model` builds the initial condition of one of the five test models of
R95 Table I, :class:`RigidBox` is the engine and :func:`run` runs it (through :func:`jaxcoag.evolve`, so
``checkpoint=`` / ``progress=`` / resume work as for every engine)::

    box = rigid.box_model("i", n0=1000, v0=13.0, key=jax.random.key(1))
    res = rigid.run(box, jnp.linspace(0.4, 8.2, 20))
    res.n_aggregates, res.n_collisions, res.max_mass, res.mass_spectrum(), res.fractal_dimension()

Models (R95 Table I, §3): (i) spheres merge into a sphere of fixed radius ``r0`` at the mass-weighted
centre, moving at the constant speed ``v0`` along the summed momentum (a constant coagulation kernel
``α = π(2R)² (4/3) v0 / L³``, eqs. 29-31); (ii) spheres merge into a sphere of radius
``r0 (m/m0)^(1/3)`` with the momentum-conserving velocity; (iii) aggregates stick rigidly at the contact
point (R8-R12); (iv), (v) aggregates stick when the impact energy ``E_imp = ½ μ |V_2 − V_1|²`` is below
``E_thr`` (the initial mean kinetic energy per particle) and bounce otherwise, with the normal coefficient
of restitution of Bridges et al. (1984) (R13-R28). Model (v) has 9000 spheres of radius 0.033.

Numerical scheme (all arrays have the fixed capacity ``n0``):

* Models (i), (ii): exact event-driven dynamics. Every sphere keeps the time and partner of its earliest
  predicted impact over its neighbour list (exact quadratic time of impact, R1's
  :func:`~jaxcoag.aggregates.rigid.body.sphere_toi`); the loop jumps to the earliest of (next impact,
  next neighbour-list rebuild, next output time), so a collision costs O(K²) (the rows of the two
  colliders and of their neighbours) plus O(n0) for the global move, independent of the pair count.
* Models (iii)-(v): conservative advancement at sphere level (spec A4): for a neighbour pair of spheres in
  different aggregates with gap ``g``, gap rate ``ġ`` and the acceleration bound
  ``A = 2(Ω_a² R_max,a + Ω_b² R_max,b)`` of torque-free rotation, the gap cannot close below tol/2 within
  ``η t*``, t* from :func:`~jaxcoag.aggregates.rigid.body.safe_time` for the gap ``g − tol/2`` (η = 1 by
  default): no tunnelling at any speed, and a pair approaching at a nearly constant rate reaches the event
  band in one step. A pair with ``g <= tol`` and ``ġ < 0`` is an event and is resolved alone (coagulation by
  :func:`~jaxcoag.aggregates.rigid.body.merge`, restitution by :func:`~jaxcoag.aggregates.rigid.body.restitute`).
  Rotation uses the symmetric splitting integrator of :func:`~jaxcoag.aggregates.rigid.body.rotate_free` with
  ``|ω| h <= 0.02`` per body (:func:`~jaxcoag.aggregates.rigid.body.rotate_free_batch`).

  - ``RigidBox(clock="body")`` (the default on a CPU), per-body clocks: each body keeps the time ``tb`` at which its
    position and orientation hold and is moved only when one of its pairs is checked (lazy free motion);
    each listed pair keeps its next check time ``τ = t + η t*``. The loop takes the earliest check (a
    blocked minimum over the pairs, O(sqrt P)), brings the two bodies to that time, and either resolves the
    contact or sets the pair's next check. A collision sets the check time of every pair of the two bodies
    to now (their velocities and spins changed). All bodies are brought to a common time only at the output
    times and when some sphere may have moved skin/2 since the list was built (a displacement bound
    updated at each collision from the largest sphere speed bound ``|V| + Ω R_max``; the actual
    displacement is then measured and the list rebuilt above 0.4 skin). A check costs O(sqrt P), a collision
    O(members of the two aggregates + their listed pairs): each aggregate keeps the list of its members
    (:func:`_mem_append`) and each sphere its listed pairs (:func:`_adjacency`, built with the list), so that
    no collision passes over all spheres or pairs, and the work per unit time grows about as n0 instead of
    n0² (the global clock's step shrinks as 1/n0 and each step touches every sphere). This program is compiled
    without XLA's loop-invariant code motion (:data:`jaxcoag._engine.LOOP_XLA_OPTIONS`).
  - ``RigidBox(clock="global")`` (the default on an accelerator): one step ``dt = η min t*`` over all pairs
    for the whole box, every body advanced at every step (the bodies needing more than half the largest
    substep count first).
* Neighbour structure: a Verlet list with cutoff ``R_s + R_t + skin`` (pairs within one aggregate excluded),
  at most ``K`` partners per sphere, built from a uniform cell grid (cells no smaller than the cutoff; the
  27 surrounding cells are searched) in O(n0), or by an all-pairs scan when the cutoff exceeds L/3. It is
  rebuilt when a sphere may have moved (or, in model ii, grown) by skin/2 since the last build, so no
  contact can be missed; a sphere with more than K partners stops the run with status ``capacity_exceeded``
  (raise ``neighbors``; :attr:`BoxResult.status_message` and a warning say which). Models (i)-(ii) keep
  (n0, K) rows whose candidates are the 27 cells padded to the fullest one (2, 4, ... up to
  ``cell_capacity`` spheres per cell, a second overflow). Models (iii)-(v) build the pairs once (s < t)
  directly (:func:`_build_pairs`: candidates enumerated over the occupied cells only, no per-cell capacity)
  and scan only the pairs in use; rotation touches only live aggregates and spinning spheres. With the
  global clock a step costs O(n0) (sphere positions, the global move, the displacement test) plus O(pairs in
  use), and the number of steps per unit time grows with n0 as well, so its cost per unit simulated time
  grows faster than n0; ``benchmarks/rigid_scaling.py`` measures both clocks.
* Periodic images: minimum image per sphere pair (valid because the cutoff is below L/2); contacts of an
  aggregate with its own image are not detected (spec A4.4; R95 is silent).

Every collision is written to a log of fixed capacity (time, slots, outcome, impact energy, normal
speed and, for models ii-v, the changes of linear and angular momentum and kinetic energy of the pair
with their scales); a full log sets the status ``capacity_exceeded`` (the run continues, the counters
stay exact, later collisions are not logged).

Units: any consistent set (R95 uses a box of side 10 "arbitrary units"); cgs when the numbers are cgs.
The Bridges law needs the velocity unit in cm/s (``v_unit``, default 1). The simulator is not
differentiable (the event choice is discrete; ``lax.while_loop``).

References: Richardson (1995, Icarus 115, 320) §§2.3-2.4, 3, Table I, eqs. (7)-(12), (13)-(28), (29)-(31);
Bridges, Hatzes & Lin (1984, Nature 309, 333); Allen & Tildesley (1987) §5.3 (Verlet and cell lists);
Mirtich (1996) (conservative advancement).
"""

from __future__ import annotations

import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._engine import LOOP_XLA_OPTIONS, AbstractEngine, AbstractResult, evolve
from ..._status import RESULTS, result_code, result_from_code, result_table
from ..._validate import JaxcoagInputError, is_traced, require_x64
from . import body
from . import diagnostics as diag

__all__ = ["Box", "BoxState", "RigidBox", "BoxResult", "box_model", "run", "capacity_message", "MODELS"]

#: The five test models of R95 Table I: (n0, r0, T, kind) with kind "fixed" (model i), "grow" (ii),
#: "stick" (iii) or "threshold" (iv, v).
MODELS = {
    "i": (1000, 0.1, 8.2, "fixed"),
    "ii": (1000, 0.1, 8.2, "grow"),
    "iii": (1000, 0.1, 8.2, "stick"),
    "iv": (1000, 0.1, 8.2, "threshold"),
    "v": (9000, 0.033, 40.8, "threshold"),
}
_SPHERE_KINDS = ("fixed", "grow")
#: log outcome codes
COAGULATION, RESTITUTION = 1, 2
_MAX_PACKING = 0.3


# ------------------------------------------------------------------------------------------------ initial
class Box(eqx.Module):
    """Initial condition of a periodic-box run (build it with :func:`box_model`).

    Fields:
        model: "i" ... "v" (static; R95 Table I), which fixes the coagulation kind and outcome rule.
        x: (n0, 3) sphere centres [length], inside [0, L)^3; v: (n0, 3) velocities [length/time].
        radius: (n0,) sphere radii [length]; mass: (n0,) sphere masses [mass].
        L: box side [length]; v0: speed of model (i) [length/time] (also its speed after a merge).
        r0, m0: monomer radius and mass (units of the mass spectrum; model i keeps radius r0).
        eps_n: normal coefficient of restitution in [0, 1], or a negative number for the velocity-dependent
            law of Bridges et al. (1984) (the default of models iv, v).
        mu_t, mu_p: tangential kinetic coefficients (R16, R17) in [0, 1] (R95 used 0).
        e_thr: impact-energy threshold of the outcome rule [energy] (coagulation if E_imp < e_thr).
        v_unit: cm/s per velocity unit (for the Bridges law only).
        key: PRNG key (model i draws a random direction when a merged particle has zero momentum).
    """

    model: str = eqx.field(static=True)
    x: jax.Array
    v: jax.Array
    radius: jax.Array
    mass: jax.Array
    L: jax.Array
    v0: jax.Array
    r0: jax.Array
    m0: jax.Array
    eps_n: jax.Array
    mu_t: jax.Array
    mu_p: jax.Array
    e_thr: jax.Array
    v_unit: jax.Array
    key: jax.Array

    @property
    def kind(self) -> str:
        """"fixed" (i), "grow" (ii), "stick" (iii) or "threshold" (iv, v)."""
        return MODELS[self.model][3]

    @property
    def n0(self) -> int:
        """Number of spheres (the capacity of every array)."""
        return int(np.shape(self.x)[0])

    @property
    def alpha(self) -> float:
        """Constant kernel of model (i), ``α = π (2 r0)² (4/3) v0 / L³`` [1/time] (R95 §3, eq. 29)."""
        return float(math.pi * (2 * float(self.r0)) ** 2 * (4.0 / 3.0) * float(self.v0) / float(self.L) ** 3)


def _key_array(key):
    if key is None:
        raise JaxcoagInputError("box_model needs key=jax.random.key(seed) (initial positions and velocities).")
    if not (hasattr(key, "dtype") and jnp.issubdtype(key.dtype, jax.dtypes.prng_key)):
        key = jax.random.wrap_key_data(jnp.asarray(key, jnp.uint32))
    return key


def _overlapping_pairs(x, radius, L):
    """Index pairs (i < j) of spheres with |d| <= R_i + R_j (minimum image), by scipy's periodic KD tree."""
    from scipy.spatial import cKDTree

    xw = np.mod(x, L)
    xw[xw >= L] = 0.0
    tree = cKDTree(xw, boxsize=L)
    pairs = tree.query_pairs(2.0 * float(np.max(radius)) * (1 + 1e-9), output_type="ndarray")
    if len(pairs) == 0:
        return pairs
    d = xw[pairs[:, 1]] - xw[pairs[:, 0]]
    d -= L * np.round(d / L)
    touch = np.sqrt(np.sum(d * d, axis=1)) <= (radius[pairs[:, 0]] + radius[pairs[:, 1]]) * (1 + 1e-9)
    return pairs[touch]


def box_model(model, *, n0=None, r0=None, box=10.0, v0=1.0, key=None, m0=1.0, positions=None, velocities=None,
              eps_n=None, mu_t=0.0, mu_p=0.0, e_thr=None, v_unit=1.0):
    """Initial condition of one of the five test models of Richardson (1995) Table I.

    Uniform random sphere centres in the cube ``[0, L)^3`` with no overlapping or touching pair (redrawn
    until none), isotropic velocity directions, zero net momentum and zero spin (R95 §3). Model (i): every
    speed equals ``v0`` (directions in antithetic pairs ``±v̂`` so that the net momentum is exactly zero for
    even n0); models (ii)-(v): Maxwellian velocities, each component ``N(0, v0²/3)`` (rms speed v0; R95
    does not print its speeds, spec ambiguity A8), minus the mean.

    Arguments:
        model: "i", "ii", "iii", "iv" or "v".
        n0: number of spheres (default 1000; 9000 for "v").
        r0: sphere radius [length] (default 0.1; 0.033 for "v").
        box: box side L [length] (default 10).
        v0: speed scale [length/time] (model i: the constant speed; others: the rms speed). R95 does not
            print it; its t_1/2 suggests v0 ≈ 13 (spec A8); compare runs in τ = α n0 t / 2.
        key: ``jax.random`` key (required).
        m0: sphere mass [mass] (default 1: masses in units of m0).
        positions, velocities: optional (n0, 3) arrays replacing the random draw (checked for overlaps).
        eps_n: normal coefficient of restitution in [0, 1] (models iv, v); None: Bridges et al. (1984).
        mu_t, mu_p: tangential coefficients (R16, R17) in [0, 1] (default 0, as R95).
        e_thr: outcome threshold [energy]; None: the initial mean kinetic energy per particle (R95 §3).
        v_unit: cm/s per velocity unit for the Bridges law (default 1).

    Returns:
        :class:`Box`.

    Raises:
        JaxcoagInputError: unknown model; non-positive sizes; a packing fraction n0 (4/3)π r0³ / L³ above
        0.3; overlapping given spheres; restitution coefficients outside [0, 1].

    References: Richardson (1995) §3 and Table I; Bridges, Hatzes & Lin (1984).
    """
    require_x64("rigid.box_model")
    if not isinstance(model, str) or model not in MODELS:
        raise JaxcoagInputError(f"unknown model {model!r}; choose one of {sorted(MODELS)} (Richardson 1995 Table I).")
    dn0, dr0, _, kind = MODELS[model]
    n0 = dn0 if n0 is None else n0
    r0 = dr0 if r0 is None else r0
    if isinstance(n0, bool) or not isinstance(n0, (int, np.integer)) or n0 < 2:
        raise JaxcoagInputError(f"n0 must be an int >= 2 (number of spheres); got {n0!r}.")
    n0 = int(n0)
    vals = {}
    for name, val in (("r0", r0), ("box", box), ("v0", v0), ("m0", m0), ("v_unit", v_unit)):
        f = float(val) if np.ndim(val) == 0 else float("nan")
        if not (math.isfinite(f) and f > 0):
            raise JaxcoagInputError(f"{name} must be a finite number > 0; got {val!r}.")
        vals[name] = f
    r0, L, v0, m0, v_unit = vals["r0"], vals["box"], vals["v0"], vals["m0"], vals["v_unit"]
    for name, val in (("eps_n", eps_n), ("mu_t", mu_t), ("mu_p", mu_p)):
        if val is None:
            continue
        f = float(val) if np.ndim(val) == 0 else float("nan")
        if not (0.0 <= f <= 1.0):
            raise JaxcoagInputError(f"{name} must be a restitution coefficient in [0, 1]; got {val!r} "
                                    "(eps_n=None selects the velocity-dependent law of Bridges et al. 1984).")
    phi = n0 * (4.0 / 3.0) * math.pi * r0**3 / L**3
    if phi > _MAX_PACKING:
        raise JaxcoagInputError(f"the box is too small for {n0} spheres of radius {r0:g}: packing fraction "
                                f"{phi:.3f} > {_MAX_PACKING}; enlarge box (L >= {(n0 * 4.19 * r0**3 / 0.3) ** (1 / 3):.3g}), "
                                "or lower n0 or r0.")
    if 2 * r0 >= L / 3:
        raise JaxcoagInputError(f"r0 = {r0:g} is too large for box {L:g}: need 2 r0 < L/3.")
    key = _key_array(key)
    kx, kv, krun = jax.random.split(key, 3)
    radius = np.full(n0, r0)
    if positions is None:
        x = np.array(jax.random.uniform(kx, (n0, 3), jnp.float64, 0.0, L))
        for it in range(1000):
            pairs = _overlapping_pairs(x, radius, L)
            if len(pairs) == 0:
                break
            redo = np.unique(pairs[:, 1])
            x[redo] = np.asarray(jax.random.uniform(jax.random.fold_in(kx, it + 1), (len(redo), 3), jnp.float64,
                                                    0.0, L))
        else:  # pragma: no cover - needs a packing fraction far above the limit
            raise JaxcoagInputError("could not place the spheres without overlap; enlarge the box.")
    else:
        x = np.array(positions, np.float64)
        if x.shape != (n0, 3) or not np.all(np.isfinite(x)):
            raise JaxcoagInputError(f"positions must be a finite ({n0}, 3) array [length]; got shape {x.shape}.")
        x = np.mod(x, L)
        x[x >= L] = 0.0
        pairs = _overlapping_pairs(x, radius, L)
        if len(pairs):
            i, j = pairs[0]
            raise JaxcoagInputError(f"{len(pairs)} pairs of the given spheres overlap or touch (e.g. {i} and {j}); "
                                    "give positions with every centre distance > 2 r0 (minimum image).")
    if velocities is None:
        if kind == "fixed":
            half = (n0 + 1) // 2
            d = np.array(jax.random.normal(kv, (half, 3), jnp.float64))
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            v = v0 * np.concatenate([d, -d])[:n0]
        else:
            v = np.array(jax.random.normal(kv, (n0, 3), jnp.float64)) * (v0 / math.sqrt(3.0))
            v -= v.mean(axis=0, keepdims=True)
    else:
        v = np.array(velocities, np.float64)
        if v.shape != (n0, 3) or not np.all(np.isfinite(v)):
            raise JaxcoagInputError(f"velocities must be a finite ({n0}, 3) array; got shape {v.shape}.")
    mass = np.full(n0, m0)
    if e_thr is None:
        e_thr = float(np.mean(0.5 * mass * np.sum(v * v, axis=1)))
    elif not (np.ndim(e_thr) == 0 and math.isfinite(float(e_thr)) and float(e_thr) >= 0):
        raise JaxcoagInputError(f"e_thr must be a finite energy >= 0; got {e_thr!r}.")
    f = jnp.float64
    return Box(model=model, x=jnp.asarray(x, f), v=jnp.asarray(v, f), radius=jnp.asarray(radius, f),
               mass=jnp.asarray(mass, f), L=jnp.asarray(L, f), v0=jnp.asarray(v0, f), r0=jnp.asarray(r0, f),
               m0=jnp.asarray(m0, f), eps_n=jnp.asarray(-1.0 if eps_n is None else float(eps_n), f),
               mu_t=jnp.asarray(float(mu_t), f), mu_p=jnp.asarray(float(mu_p), f),
               e_thr=jnp.asarray(float(e_thr), f), v_unit=jnp.asarray(v_unit, f), key=krun)


# ------------------------------------------------------------------------------------------------ state
class BoxState(eqx.Module):
    """Engine state (fixed capacity n0; slot a of the aggregate arrays, sphere s of the sphere arrays).

    Aggregate slots: ``alive``, COM ``X`` (wrapped) and ``V``, orientation ``q`` (body -> space), body
    angular momentum ``Pi``, principal moments ``Ip``, mass ``M``, extent ``Rmax`` (R7), member count
    ``nmem``, last collision partner ``last``. Spheres: owner ``sph_agg``, body offset ``sph_b``, radius
    ``sph_R``, mass ``sph_m``. Models (i)-(ii) use slot s = sphere s (``sph_b`` = 0). Neighbour list
    ``nb`` (n0, K) (``n0`` = empty) with reference positions ``x_ref`` and radii ``r_ref`` of its build;
    models (iii)-(v) also keep its pairs s < t once, ``pair_i``/``pair_j`` (capacity n0 K / 2, the first
    ``n_pairs`` in use, in the row order of ``nb``), and the pairs of each sphere (:func:`_adjacency`: ``fwd0``,
    ``degf``, ``rev0``, ``degr``, ``rev_p``); the members of each aggregate slot a are
    ``mem[mem0[a] : mem0[a] + nmem[a]]`` (``mem`` of capacity 2 n0, filled to ``mem_top``: a coagulation appends the
    merged list, :func:`_mem_append`);
    event-driven predictions ``tc``/``partner`` and the rebuild time ``t_rebuild`` (models i-ii; models iii-v
    with per-body clocks: the time at which some sphere may have moved skin/2 since the build). Per-body clocks
    (models iii-v, ``RigidBox(clock="body")``): ``tb`` the time at which each body's ``X``, ``q``, ``Pi`` hold,
    ``tau`` the next check time of each listed pair (blocks of ``tau.size // tau_blk.size``, ``tau_blk`` their
    minima), the displacement bound ``dsp`` of any sphere since the build at time ``t_dsp`` (``-inf``: ``tau``
    not valid, the next run scans every pair first), the speed bound ``vmx`` (max of ``|V| + Ω R_max``) since, and
    ``ev``, the numbers of the last contact found (:func:`_pack_event`), read by the collision that resolves it.
    Counters: collisions ``n_c``, first-time collisions ``n_c1``, coagulations ``n_coag``, restitutions
    ``n_rest``, loop iterations ``n_steps`` (global steps; with per-body clocks pair checks, resynchronisations
    and outputs), rebuilds ``n_build``; ``nc_max`` (static) cells per box side; ``flags`` bit 0 log full, bit 1
    neighbour/cell overflow, bit 2 step budget spent. ``log`` holds the collision log (dict of (E,) arrays)
    and ``n_log`` its fill; ``par`` the physical parameters (dict of scalars).
    """

    model: str = eqx.field(static=True)
    nc_max: int = eqx.field(static=True)
    t: jax.Array
    alive: jax.Array
    X: jax.Array
    V: jax.Array
    q: jax.Array
    Pi: jax.Array
    Ip: jax.Array
    M: jax.Array
    Rmax: jax.Array
    nmem: jax.Array
    last: jax.Array
    sph_agg: jax.Array
    sph_b: jax.Array
    sph_R: jax.Array
    sph_m: jax.Array
    nb: jax.Array
    pair_i: jax.Array
    pair_j: jax.Array
    n_pairs: jax.Array
    fwd0: jax.Array
    degf: jax.Array
    rev0: jax.Array
    degr: jax.Array
    rev_p: jax.Array
    mem: jax.Array
    mem0: jax.Array
    mem_top: jax.Array
    x_ref: jax.Array
    r_ref: jax.Array
    tc: jax.Array
    partner: jax.Array
    t_rebuild: jax.Array
    tb: jax.Array
    tau: jax.Array
    tau_blk: jax.Array
    vmx: jax.Array
    dsp: jax.Array
    t_dsp: jax.Array
    ev: jax.Array
    n_c: jax.Array
    n_c1: jax.Array
    n_coag: jax.Array
    n_rest: jax.Array
    n_steps: jax.Array
    n_build: jax.Array
    flags: jax.Array
    n_log: jax.Array
    log: dict
    par: dict
    key: jax.Array

    @property
    def kind(self) -> str:
        return MODELS[self.model][3]


_LOG_FLOAT = ("t", "e_imp", "u_n", "m_a", "m_b", "dP", "dL", "dKE", "P_scale", "L_scale", "KE")
_LOG_INT = ("a", "b", "outcome")


def _mimg(d, L):
    """Minimum-image separation in a periodic cube of side L."""
    return d - L * jnp.round(d / L)


def _wrap(x, L):
    x = jnp.mod(x, L)
    return jnp.where(x >= L, 0.0, x)


_dot3 = body._dot3


def _lanes(cpu, accelerator):
    """Width of a blocked pass (pair build, pair scan, rotation chunks): ``cpu`` on a CPU, where blocks that fit
    the cache are fastest, ``accelerator`` on a GPU/TPU, where each block costs kernel launches and wide blocks
    fill the chip. Chosen at trace time from ``jax.default_backend()``."""
    return cpu if jax.default_backend() == "cpu" else accelerator


def _slot_table(q, Pi, Ip, X, V):
    """Per body slot: the 9 rotation-matrix entries (row-major), the space spin ω = A diag(1/I_k) Π, X and V,
    as an (slots, 18) array, elementwise on columns (see :func:`_sphere_pos`)."""
    nq2 = q[:, 0] * q[:, 0] + q[:, 1] * q[:, 1] + q[:, 2] * q[:, 2] + q[:, 3] * q[:, 3]
    pos = nq2 > 0
    nq = jnp.where(pos, jnp.sqrt(jnp.where(pos, nq2, 1.0)), 0.0)
    qn = jnp.where(pos[:, None], q / jnp.where(pos, nq, 1.0)[:, None], jnp.asarray([1.0, 0.0, 0.0, 0.0]))
    w, x, y, z = qn[:, 0], qn[:, 1], qn[:, 2], qn[:, 3]
    R = [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]
    v = Pi * body._inv_moments(Ip)
    ws = [R[i][0] * v[:, 0] + R[i][1] * v[:, 1] + R[i][2] * v[:, 2] for i in range(3)]
    return jnp.stack([R[i][k] for i in range(3) for k in range(3)] + ws
                     + [X[:, i] for i in range(3)] + [V[:, i] for i in range(3)], axis=1)


def _from_table(G, b, L):
    """Sphere positions (wrapped), offsets A b and velocities from the gathered rows G (k, 18) of their bodies'
    :func:`_slot_table` and their body-frame offsets b (k, 3)."""
    r = jnp.stack([G[:, 3 * i] * b[:, 0] + G[:, 3 * i + 1] * b[:, 1] + G[:, 3 * i + 2] * b[:, 2] for i in range(3)],
                  axis=1)
    wg, Xg, Vg = G[:, 9:12], G[:, 12:15], G[:, 15:18]
    x = _wrap(Xg + r, L)
    u = Vg + jnp.stack([wg[:, 1] * r[:, 2] - wg[:, 2] * r[:, 1], wg[:, 2] * r[:, 0] - wg[:, 0] * r[:, 2],
                        wg[:, 0] * r[:, 1] - wg[:, 1] * r[:, 0]], axis=1)
    return x, r, u


def _sphere_pos(st):
    """Space positions (wrapped), unwrapped offsets A b and velocities of every sphere.

    Elementwise on columns: the rotation matrix entries of :func:`~jaxcoag.aggregates.rigid.body.matrix_from_quat`
    per slot, then one gather of the 18 slot numbers (matrix, space spin ω = A diag(1/I_k) Π as in
    :func:`~jaxcoag.aggregates.rigid.body.omega_space`, X, V) per sphere (a batched matrix product of n tiny matrices,
    or sums over their axes of 3, is several times slower on CPU, and this runs at every step)."""
    G = _slot_table(st.q, st.Pi, st.Ip, st.X, st.V)[st.sph_agg]
    return _from_table(G, st.sph_b, st.par["L"])


def _sphere_pos_of(st, s):
    """:func:`_sphere_pos` of the spheres ``s`` (k,) only (their bodies' current state; the same arithmetic)."""
    a = st.sph_agg[s]
    G = _slot_table(st.q[a], st.Pi[a], st.Ip[a], st.X[a], st.V[a])
    return _from_table(G, st.sph_b[s], st.par["L"])


def _gap_rate(xi, xj, ui, uj, Ri, Rj, L):
    """Gap g = |d| - (R_i + R_j) and gap rate ġ = d·(u_j - u_i)/|d| of sphere pairs (minimum image d)."""
    d = _mimg(xj - xi, L)
    dist = jnp.sqrt(_dot3(d, d))
    g = dist - (Ri + Rj)
    gdot = _dot3(d, uj - ui) / jnp.where(dist > 0, dist, 1.0)
    return g, gdot


def _tau_block(P):
    """Width of the blocks of the per-pair check times (per-body clocks): about sqrt(P), a power of two in
    [128, 4096], so that finding the earliest check (the minimum over the block minima, then within one block)
    and updating it cost O(sqrt P)."""
    return int(min(max(1 << math.ceil(math.log2(max(P, 1)) / 2), 128), 4096))


# ------------------------------------------------------------------------------------------------ neighbours
def _build_neighbors(x, R, group, active, L, skin, K, C, nc_max, dynamic=True):
    """Verlet list (n, K) with cutoff R_i + R_j + skin, pairs of the same ``group`` excluded.

    Uniform cell grid (side ``L / nc``, nc = floor(L / (2 max R + skin)) <= nc_max, at most C spheres per cell,
    27 cells searched) when nc >= 3, else an all-pairs scan row by row. Returns (nb, overflow) with
    ``n`` marking empty entries.
    """
    n = x.shape[0]
    Rmax_ = jnp.max(jnp.where(active, R, 0.0))
    rc = 2.0 * Rmax_ + skin
    nc = jnp.clip(jnp.floor(L / rc), 1, nc_max).astype(jnp.int32)
    idx = jnp.arange(n)

    def select(i, cand):
        valid = cand < n
        cj = jnp.where(valid, cand, 0)
        d = _mimg(x[cj] - x[i][None, :], L)
        dist = jnp.sqrt(jnp.sum(d * d, axis=-1))
        ok = valid & active[cj] & active[i] & (cj != i) & (group[cj] != group[i]) & (dist < R[i] + R[cj] + skin)
        pos = jnp.cumsum(ok) - 1  # compaction of the accepted candidates into the first K entries
        row = jnp.full(K, n, jnp.int32).at[jnp.where(ok, pos, K)].set(cj.astype(jnp.int32), mode="drop")
        return row, pos[-1] >= K

    def by_cells(_):
        h = L / nc.astype(jnp.float64)
        ci = jnp.clip(jnp.floor(x / h).astype(jnp.int32), 0, nc - 1)
        cid = ci[:, 0] + nc * (ci[:, 1] + nc * ci[:, 2])
        ncell = nc_max**3
        cid = jnp.where(active, cid, ncell)
        order = jnp.argsort(cid)
        sc = cid[order]
        cells = jnp.arange(ncell)
        start = jnp.searchsorted(sc, cells, side="left")
        count = jnp.searchsorted(sc, cells, side="right") - start
        over_cell = jnp.any(count > C)
        off = jnp.stack(jnp.meshgrid(jnp.arange(-1, 2), jnp.arange(-1, 2), jnp.arange(-1, 2), indexing="ij"),
                        -1).reshape(27, 3)

        def rows(Cp):  # candidates: the first Cp occupants of each of the 27 cells (Cp >= the fullest cell)
            def row(i):
                c3 = jnp.mod(ci[i][None, :] + off, nc)
                cc = c3[:, 0] + nc * (c3[:, 1] + nc * c3[:, 2])  # (27,)
                slot = start[cc][:, None] + jnp.arange(Cp)[None, :]
                ok = jnp.arange(Cp)[None, :] < count[cc][:, None]
                cand = jnp.where(ok, order[jnp.clip(slot, 0, n - 1)], n).reshape(-1)
                return select(i, cand)

            return lambda: jax.lax.map(row, idx, batch_size=min(n, 1024))

        # the candidate width follows the fullest cell (2, 4, 8, ... up to C): the same rows as width C (the
        # accepted candidates and their order do not depend on the padding), at a cost proportional to it
        widths = sorted({w for w in (2, 4, 8, 16, 32, 64, 128) if w < C} | {C})
        cmax = jnp.max(count)
        pick = jnp.sum(jnp.asarray(widths[:-1], jnp.int32) < cmax).astype(jnp.int32)
        nb, over = jax.lax.switch(pick, [rows(w) for w in widths])
        return nb, jnp.any(over) | over_cell

    def all_pairs(_):
        nb, over = jax.lax.map(lambda i: select(i, idx), idx, batch_size=min(n, 64))
        return nb, jnp.any(over)

    if nc_max < 3:
        return all_pairs(None)
    if not dynamic:  # radii never grow: nc_max (from the largest radius at the start) is the grid
        nc = jnp.int32(nc_max)
        return by_cells(None)
    return jax.lax.cond(nc >= 3, by_cells, all_pairs, None)


def _build_pairs(x, R, group, L, skin, K, P, nc, block=None):
    """Pair list (each pair once, s < t) of spheres of different ``group`` within R_s + R_t + skin, from a cell
    grid of ``nc`` (static, >= 3) cells per side whose side is at least the largest cutoff.

    The candidates of sphere s are the occupants of its 27 cells, enumerated as one flat sequence over the
    (sphere, cell) pairs (segment k of sphere s holds count(cell) entries) and scanned in blocks up to its
    actual length: the work follows the occupied cells, not the fullest one (padding every sphere's 27 cells to
    the fullest cell's count, as :func:`_build_neighbors` does, made ~20x the candidates in clustered boxes).
    The pairs come in the row-major order of :func:`_build_neighbors`' list (rows s, then the 27 cells, then
    the cell's occupants in sphere order), so both give the same list. ``block``: candidates per scan step
    (default :func:`_lanes`: 2048 on a CPU, 2^20 on an accelerator).

    Returns (pair_i, pair_j, n_pairs, overflow, rev_s, rev_t, n_rev): arrays of capacity P, the number in use,
    whether a sphere has more than K partners (then the list is incomplete: the run must stop, as on an overflowing
    Verlet list), and the reverse entries (s, t) with t < s in the same row-major order (each pair once more, from
    its larger sphere), from which :func:`_adjacency` builds the pairs of each sphere.
    """
    n = x.shape[0]
    block = int(block or _lanes(2048, 1 << 20))
    h = L / nc
    ci = jnp.clip(jnp.floor(x / h).astype(jnp.int32), 0, nc - 1)
    cid = ci[:, 0] + nc * (ci[:, 1] + nc * ci[:, 2])
    ncell = nc**3
    order = jnp.argsort(cid).astype(jnp.int32)  # stable: occupants of a cell in sphere order
    count = jnp.zeros(ncell, jnp.int32).at[cid].add(1)
    start = jnp.cumsum(count) - count
    off = np.stack(np.meshgrid(np.arange(-1, 2), np.arange(-1, 2), np.arange(-1, 2), indexing="ij"), -1).reshape(27, 3)
    c3 = jnp.mod(ci[:, None, :] + off[None, :, :], nc)
    cell = (c3[..., 0] + nc * (c3[..., 1] + nc * c3[..., 2])).reshape(-1)  # (27 n,) segment -> cell
    seg_n = count[cell]
    seg_end = jnp.cumsum(seg_n)  # int32: 27 n * max count, far below 2^31 for any grid that fits in memory
    total = seg_end[-1]
    lane = jnp.arange(block, dtype=jnp.int32)

    def body(b, c):
        pi, pj, npair, deg, rs, rt, nrev = c
        f = b * block + lane
        ok = f < total
        seg = jnp.minimum(jnp.searchsorted(seg_end, f, side="right"), 27 * n - 1).astype(jnp.int32)
        within = f - (seg_end[seg] - seg_n[seg])
        s = seg // 27
        t = order[jnp.clip(start[cell[seg]] + within, 0, n - 1)]
        d = _mimg(x[t] - x[s], L)
        dist = jnp.sqrt(jnp.sum(d * d, axis=-1))
        acc = ok & (t != s) & (group[t] != group[s]) & (dist < R[s] + R[t] + skin)
        deg = deg.at[s].add(acc.astype(jnp.int32))  # partners of s (each pair is met from both ends)
        keep = acc & (t > s)
        pos = npair + jnp.cumsum(keep) - 1
        tgt = jnp.where(keep, pos, P)
        back = acc & (t < s)  # the pair (t, s) met from its larger sphere: the reverse entry of row s
        rtgt = jnp.where(back, nrev + jnp.cumsum(back) - 1, P)
        return (pi.at[tgt].set(s, mode="drop"), pj.at[tgt].set(t, mode="drop"),
                npair + jnp.sum(keep).astype(jnp.int32), deg, rs.at[rtgt].set(s, mode="drop"),
                rt.at[rtgt].set(t, mode="drop"), nrev + jnp.sum(back).astype(jnp.int32))

    z = jnp.zeros(P, jnp.int32)
    init = (z, z, jnp.int32(0), jnp.zeros(n, jnp.int32), z, z, jnp.int32(0))
    pi, pj, npair, deg, rs, rt, nrev = jax.lax.fori_loop(0, (total + block - 1) // block, body, init)
    over = (jnp.max(deg) > K) | (npair > P)
    return pi, pj, jnp.minimum(npair, P), over, rs, rt, jnp.minimum(nrev, P)


# ------------------------------------------------------------------------------------------------ engine
class RigidBox(AbstractEngine):
    """Engine of the periodic box of spheres / rigid aggregates (R95 §3; module docstring for the scheme).

    Fields (static: they fix the compiled program):
        neighbors: Verlet-list capacity K per sphere (default 48).
        cell_capacity: spheres per grid cell C of the sphere models (i), (ii) (default 16; the aggregate models'
            pair build has no per-cell capacity).
        skin: Verlet skin in units of r0 (cutoff R_s + R_t + skin r0); default 12 for the sphere models (i, ii:
            fewer rebuilds of the event predictions) and 6 for the aggregate models.
        log_capacity: collision-log capacity (default 20000).
        max_steps: loop-iteration budget over the whole run (status ``max_steps_reached`` when spent).
        tol: contact gap tolerance of conservative advancement, in units of r0 (default 1e-6).
        eta: fraction of the safe time taken per step, in (0, 1] (default 1: the safe time is that to the gap
            tol/2, so a full step cannot close a gap below tol/2).
        n_rot: maximum rotation substeps per step of ``clock="global"`` (|ω| h <= 0.02 per substep for each body;
            the step is capped so that the fastest spinner needs at most n_rot). With per-body clocks a body takes
            as many substeps of |ω| h <= 0.02 as its own interval needs.
        clock: models (iii)-(v): ``"body"``, per-body clocks, each listed pair checked at its own next check time
            (module docstring), or ``"global"``, one conservative-advancement step for the whole box. Both resolve
            the same contacts to the tolerance ``tol``; ``"body"`` costs O(1) per check instead of O(n0) per global
            step, but each check is a few dozen small kernels, so on a GPU, where a global step's passes over the
            spheres are nearly free and launches are not, the global clock is the faster one. Default ``None``:
            ``"body"`` on a CPU, ``"global"`` on an accelerator (chosen at trace time). Models (i), (ii) are
            event-driven either way.
    """

    neighbors: int = eqx.field(static=True, default=48)
    cell_capacity: int = eqx.field(static=True, default=16)
    skin: float | None = eqx.field(static=True, default=None)
    log_capacity: int = eqx.field(static=True, default=20000)
    max_steps: int = eqx.field(static=True, default=50_000_000)
    tol: float = eqx.field(static=True, default=1e-6)
    eta: float = eqx.field(static=True, default=1.0)
    n_rot: int = eqx.field(static=True, default=64)
    clock: str | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        if self.clock not in (None, "body", "global"):
            raise JaxcoagInputError(f'RigidBox(clock=...) must be "body" (per-body clocks), "global" (one step for '
                                    f'the whole box) or None (body on a CPU, global on an accelerator); got '
                                    f'{self.clock!r}.')
        for name in ("neighbors", "cell_capacity", "log_capacity", "max_steps", "n_rot"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise JaxcoagInputError(f"RigidBox({name}=...) must be an int >= 1; got {v!r}.")
        for name in ("skin", "tol", "eta"):
            v = getattr(self, name)
            if v is None and name == "skin":
                continue
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise JaxcoagInputError(f"RigidBox({name}=...) must be a number > 0; got {v!r}.")
        if self.eta > 1.0:
            raise JaxcoagInputError(f"RigidBox(eta=...) must be in (0, 1] (fraction of the safe time); "
                                    f"got {self.eta}.")

    @property
    def name(self) -> str:
        return "rigid"

    # -------------------------------------------------------------------------------- protocol
    def _progress_time(self, t: float) -> str:
        """Progress-bar time in the box's own units (R95: arbitrary length and time units), not in years."""
        return f"T = {t:.4g}"

    def _check(self, kernel, initial, t_out, t0, outcome, key):
        if kernel is not None:
            raise JaxcoagInputError("the rigid box simulates its collisions explicitly: pass kernel=None.")
        if outcome is not None:
            raise JaxcoagInputError("the rigid box has its own outcome rule (R95 §3, the model): pass outcome=None.")
        if isinstance(initial, BoxResult):
            return
        if not isinstance(initial, Box):
            raise JaxcoagInputError(f"initial must be a rigid.Box (rigid.box_model(...)) or a BoxResult to continue; "
                                    f"got {type(initial).__name__}.")

    def _init(self, kernel, initial, t0, outcome, key):
        if isinstance(initial, BoxResult):
            return initial.final_state
        b = initial
        n = b.n0
        f = jnp.float64
        par = dict(L=b.L, v0=b.v0, r0=b.r0, m0=b.m0, eps_n=b.eps_n, mu_t=b.mu_t, mu_p=b.mu_p, e_thr=b.e_thr,
                   v_unit=b.v_unit)
        skin = self.skin if self.skin is not None else (12.0 if b.kind in _SPHERE_KINDS else 6.0)
        par["skin"] = skin * b.r0
        par = {k: jnp.asarray(v, f) for k, v in par.items()}
        R = jnp.asarray(b.radius, f)
        m = jnp.asarray(b.mass, f)
        Ip1 = 0.4 * m * R * R
        log = {k: jnp.zeros(self.log_capacity, f) for k in _LOG_FLOAT}
        log.update({k: jnp.zeros(self.log_capacity, jnp.int32) for k in _LOG_INT})
        rc = 2 * float(np.max(np.asarray(b.radius))) + float(par["skin"])
        nc_max = int(min(max(math.floor(float(b.L) / rc), 1), 64))
        npair = 1 if b.kind in _SPHERE_KINDS else max(n * self.neighbors // 2, 1)
        tblk = _tau_block(npair)
        nblk = -(-npair // tblk)
        st = BoxState(
            model=b.model, nc_max=nc_max, t=jnp.asarray(t0, f), alive=jnp.ones(n, bool), X=jnp.asarray(b.x, f),
            V=jnp.asarray(b.v, f), q=jnp.tile(jnp.array([1.0, 0, 0, 0], f), (n, 1)), Pi=jnp.zeros((n, 3), f),
            Ip=jnp.stack([Ip1, Ip1, Ip1], -1), M=m, Rmax=R, nmem=jnp.ones(n, jnp.int32),
            last=jnp.full(n, -1, jnp.int32), sph_agg=jnp.arange(n, dtype=jnp.int32), sph_b=jnp.zeros((n, 3), f),
            sph_R=R, sph_m=m, nb=jnp.full((n, self.neighbors), n, jnp.int32),
            pair_i=jnp.zeros(npair, jnp.int32), pair_j=jnp.zeros(npair, jnp.int32), n_pairs=jnp.int32(0),
            fwd0=jnp.zeros(n, jnp.int32), degf=jnp.zeros(n, jnp.int32), rev0=jnp.zeros(n, jnp.int32),
            degr=jnp.zeros(n, jnp.int32), rev_p=jnp.zeros(npair, jnp.int32),
            mem=jnp.concatenate([jnp.arange(n, dtype=jnp.int32), jnp.full(n, n, jnp.int32)]),
            mem0=jnp.arange(n, dtype=jnp.int32), mem_top=jnp.int32(n),
            x_ref=jnp.asarray(b.x, f), r_ref=R,
            tc=jnp.full(n, jnp.inf, f), partner=jnp.full(n, n, jnp.int32), t_rebuild=jnp.asarray(-jnp.inf, f),
            tb=jnp.full(n, t0, f), tau=jnp.full(nblk * tblk, jnp.inf, f), tau_blk=jnp.full(nblk, jnp.inf, f),
            vmx=jnp.asarray(0.0, f), dsp=jnp.asarray(0.0, f), t_dsp=jnp.asarray(-jnp.inf, f), ev=jnp.zeros(EV_SIZE, f),
            n_c=jnp.int32(0), n_c1=jnp.int32(0), n_coag=jnp.int32(0), n_rest=jnp.int32(0), n_steps=jnp.int32(0),
            n_build=jnp.int32(0), flags=jnp.int32(0), n_log=jnp.int32(0), log=log, par=par, key=b.key)
        return st

    def _advance(self, kernel, state, t_seg, outcome):
        # the per-body clocks compile without loop-invariant code motion (LOOP_XLA_OPTIONS); inside another trace
        # (jax.eval_shape of a checkpointed run, a user's jit) XLA options belong to the outer jit
        body_clock = state.kind not in _SPHERE_KINDS and (self.clock or _lanes("body", "global")) == "body"
        f = _advance_body if body_clock and not is_traced((state.t, t_seg)) else _advance_jit
        return f(self, state, jnp.asarray(t_seg, jnp.float64), state.nc_max)

    def _result(self, kernel, t, outs, state, outcome):
        code = outs["status"][-1]
        return BoxResult(t=jnp.asarray(t), status=result_from_code(code), outs=outs, final_state=state,
                         model=state.model)


# ------------------------------------------------------------------------------------------------ outputs
def _outputs(st, code):
    """One output record (module docstring of :class:`BoxResult` for the fields)."""
    x, r, u = _sphere_pos(st)
    w = jax.vmap(body.omega_space)(st.q, st.Pi, st.Ip)
    ke_t = 0.5 * st.M * jnp.sum(st.V * st.V, axis=-1)
    ke_r = jax.vmap(body.kinetic_energy_rot)(st.Pi, st.Ip)
    al = st.alive
    del w, u, x
    return dict(
        alive=al, M=jnp.where(al, st.M, 0.0), nmem=jnp.where(al, st.nmem, 0), Rmax=jnp.where(al, st.Rmax, 0.0),
        V=jnp.where(al[:, None], st.V, 0.0), ke_trans=jnp.where(al, ke_t, 0.0), ke_rot=jnp.where(al, ke_r, 0.0),
        sph_agg=st.sph_agg, sph_r=jnp.sqrt(jnp.sum(r * r, axis=-1)),
        n_aggregates=jnp.sum(al).astype(jnp.int32), n_c=st.n_c, n_c1=st.n_c1, n_coag=st.n_coag, n_rest=st.n_rest,
        n_steps=st.n_steps, n_build=st.n_build, flags=st.flags, status=code)


def capacity_message(flags):
    """What a ``capacity_exceeded`` status of the rigid box means and which :class:`RigidBox` capacity to raise,
    from the run's ``flags`` (bit 0: the collision log is full; bit 1: a sphere had more than ``neighbors``
    neighbours or a grid cell more than ``cell_capacity`` spheres). Empty string if neither bit is set."""
    flags = int(flags)
    what = []
    if flags & 1:
        what.append("the collision log is full (the run went on with exact counters, later collisions are not "
                    "logged): raise RigidBox(log_capacity=...) (default 20000) above the expected number of "
                    "collisions")
    if flags & 2:
        what.append("a sphere had more neighbours within R_s + R_t + skin than the Verlet list holds, or "
                    "(models i, ii) a grid cell more spheres than it holds, so contacts could be missed and the run "
                    "stopped at that step (later outputs repeat it): raise RigidBox(neighbors=...) (default 48) "
                    "and, for models i and ii, RigidBox(cell_capacity=...) (default 16), or lower RigidBox(skin=...)")
    if not what:
        return ""
    return "Rigid box (jaxcoag.aggregates.rigid) status capacity_exceeded: " + "; ".join(what) + "."


def _status_code(st):
    c = jnp.int32(0)
    c = jnp.where((st.flags & 1) != 0, result_code(RESULTS.capacity_exceeded), c)
    c = jnp.where((st.flags & 2) != 0, result_code(RESULTS.capacity_exceeded), c)
    c = jnp.where((st.flags & 4) != 0, result_code(RESULTS.max_steps_reached), c)
    return c


def _record(outs, k, st):
    rec = _outputs(st, _status_code(st))
    return jax.tree_util.tree_map(lambda o, r: o.at[k].set(r), outs, rec)


def _empty_outputs(st, T):
    shapes = jax.eval_shape(lambda s: _outputs(s, jnp.int32(0)), st)
    return jax.tree_util.tree_map(lambda a: jnp.zeros((T,) + a.shape, a.dtype), shapes)


def _stopped(st):
    return (st.flags & 6) != 0


def _write_log(st, rec):
    i = st.n_log
    full = i >= st.log["t"].shape[0]
    log = {k: st.log[k].at[i].set(jnp.asarray(rec[k], st.log[k].dtype), mode="drop") for k in st.log}
    return eqx.tree_at(lambda s: (s.log, s.n_log, s.flags), st,
                       (log, jnp.where(full, i, i + 1), st.flags | jnp.where(full, 1, 0)))


# ------------------------------------------------------------------------------------------------ spheres (i, ii)
def _sphere_row(st, i):
    """Earliest predicted impact (absolute time, partner) of sphere i over its neighbour list."""
    n = st.alive.shape[0]
    j = st.nb[i]
    valid = (j < n)
    jj = jnp.where(valid, j, 0)
    valid = valid & st.alive[jj] & st.alive[i] & (jj != i)
    d = _mimg(st.X[jj] - st.X[i][None, :], st.par["L"])
    uu = st.V[jj] - st.V[i][None, :]
    toi = body.sphere_toi(d, uu, st.sph_R[jj] + st.sph_R[i])
    toi = jnp.where(valid, toi, jnp.inf)
    k = jnp.argmin(toi)
    return st.t + toi[k], jnp.where(jnp.isfinite(toi[k]), jj[k], n).astype(jnp.int32)


def _sphere_horizon(st, i):
    """Time at which sphere i may have used half of the skin (displacement plus radius growth)."""
    disp = _mimg(st.X[i] - st.x_ref[i], st.par["L"])
    used = jnp.sqrt(jnp.sum(disp * disp)) + (st.sph_R[i] - st.r_ref[i])
    spd = jnp.sqrt(jnp.sum(st.V[i] * st.V[i]))
    room = 0.5 * st.par["skin"] - used
    return jnp.where(room <= 0, st.t, jnp.where(spd > 0, st.t + room / jnp.where(spd > 0, spd, 1.0), jnp.inf))


def _sphere_rebuild(engine, st, nc_max):
    n = st.alive.shape[0]
    skin = st.par["skin"]
    nb, over = _build_neighbors(st.X, st.sph_R, jnp.arange(n), st.alive, st.par["L"], skin, engine.neighbors,
                                engine.cell_capacity, nc_max, dynamic=st.kind == "grow")
    st = eqx.tree_at(lambda s: (s.nb, s.x_ref, s.r_ref, s.n_build, s.flags), st,
                     (nb, st.X, st.sph_R, st.n_build + 1, st.flags | jnp.where(over, 2, 0)))
    tc, partner = jax.vmap(lambda i: _sphere_row(st, i))(jnp.arange(n))
    spd = jnp.sqrt(jnp.sum(st.V * st.V, axis=-1))
    vmax = jnp.max(jnp.where(st.alive, spd, 0.0))
    t_rb = jnp.where(vmax > 0, st.t + 0.5 * skin / jnp.where(vmax > 0, vmax, 1.0), jnp.inf)
    return eqx.tree_at(lambda s: (s.tc, s.partner, s.t_rebuild), st, (tc, partner, t_rb))


def _sphere_collide(engine, st, i):
    """Merge sphere i with its predicted partner (R95 §3 models i, ii) and update the predictions."""
    n = st.alive.shape[0]
    p = st.partner[i]
    a, b = jnp.minimum(i, p), jnp.maximum(i, p)
    L = st.par["L"]
    ma, mb = st.M[a], st.M[b]
    Mn = ma + mb
    d = _mimg(st.X[b] - st.X[a], L)
    Xn = st.X[a] + (mb / Mn) * d
    P = ma * st.V[a] + mb * st.V[b]
    Vm = P / Mn
    if st.kind == "fixed":
        key = jax.random.fold_in(st.key, st.n_c)
        rnd = jax.random.normal(key, (3,), jnp.float64)
        pn = jnp.sqrt(jnp.sum(P * P))
        dirn = jnp.where(pn > 0, P / jnp.where(pn > 0, pn, 1.0), rnd / jnp.sqrt(jnp.sum(rnd * rnd)))
        Vn = st.par["v0"] * dirn
        Rn = st.par["r0"]
    else:
        Vn = Vm
        Rn = st.par["r0"] * jnp.cbrt(Mn / st.par["m0"])
    uab = st.V[b] - st.V[a]
    dn = d / jnp.sqrt(jnp.sum(d * d))
    un = jnp.sum(uab * dn)
    e_imp = 0.5 * ma * mb / Mn * jnp.sum(uab * uab)
    ke0 = 0.5 * ma * jnp.sum(st.V[a] ** 2) + 0.5 * mb * jnp.sum(st.V[b] ** 2)
    ke1 = 0.5 * Mn * jnp.sum(Vn * Vn)
    # angular momentum about the new centre (orbital part; spheres carry no spin in models i, ii)
    L0 = ma * jnp.cross(st.X[a] - Xn, st.V[a]) + mb * jnp.cross(st.X[a] + d - Xn, st.V[b])
    rec = dict(t=st.t, e_imp=e_imp, u_n=un, m_a=ma, m_b=mb, dP=jnp.sqrt(jnp.sum((Mn * Vn - P) ** 2)),
               dL=jnp.sqrt(jnp.sum(L0 * L0)), dKE=ke1 - ke0,
               P_scale=ma * jnp.sqrt(jnp.sum(st.V[a] ** 2)) + mb * jnp.sqrt(jnp.sum(st.V[b] ** 2)),
               L_scale=(ma + mb) * jnp.sqrt(jnp.sum(d * d)) * jnp.sqrt(jnp.sum(uab * uab)), KE=ke0, a=a, b=b,
               outcome=COAGULATION)
    first = ~((st.last[a] == b) | (st.last[b] == a))
    st = eqx.tree_at(
        lambda s: (s.X, s.V, s.M, s.sph_R, s.sph_m, s.Rmax, s.nmem, s.alive, s.last, s.n_c, s.n_c1, s.n_coag,
                   s.tc, s.partner, s.Ip),
        st,
        (st.X.at[a].set(_wrap(Xn, L)), st.V.at[a].set(Vn).at[b].set(0.0), st.M.at[a].set(Mn).at[b].set(0.0),
         st.sph_R.at[a].set(Rn), st.sph_m.at[a].set(Mn), st.Rmax.at[a].set(Rn).at[b].set(0.0),
         st.nmem.at[a].add(st.nmem[b]).at[b].set(0), st.alive.at[b].set(False), st.last.at[a].set(b),
         st.n_c + 1, st.n_c1 + first.astype(jnp.int32), st.n_coag + 1, st.tc.at[b].set(jnp.inf),
         st.partner.at[b].set(n), st.Ip.at[a].set(jnp.full(3, 0.4 * Mn * Rn * Rn))))
    st = _write_log(st, rec)
    # predictions: row a in full; neighbours of a or b whose partner was a or b in full; others min with a
    ta, pa = _sphere_row(st, a)
    cand = jnp.concatenate([st.nb[a], st.nb[b]])
    cj = jnp.where(cand < n, cand, 0)
    use = (cand < n) & (cj != a) & st.alive[cj]
    stale = (st.partner[cj] == a) | (st.partner[cj] == b)
    full_t, full_p = jax.vmap(lambda j: _sphere_row(st, j))(cj)
    dj = _mimg(st.X[a][None, :] - st.X[cj], L)
    tj = st.t + body.sphere_toi(dj, st.V[a][None, :] - st.V[cj], st.sph_R[a] + st.sph_R[cj])
    better = tj < st.tc[cj]
    new_t = jnp.where(stale, full_t, jnp.where(better, tj, st.tc[cj]))
    new_p = jnp.where(stale, full_p, jnp.where(better, a, st.partner[cj])).astype(jnp.int32)
    tgt = jnp.where(use, cj, n)
    tc = st.tc.at[tgt].set(new_t, mode="drop").at[a].set(ta)
    partner = st.partner.at[tgt].set(new_p, mode="drop").at[a].set(pa)
    hz = _sphere_horizon(st, a)
    return eqx.tree_at(lambda s: (s.tc, s.partner, s.t_rebuild), st, (tc, partner, jnp.minimum(st.t_rebuild, hz)))


def _sphere_loop(engine, st, t_seg, nc_max):
    T = t_seg.shape[0]
    n = st.alive.shape[0]
    outs0 = _empty_outputs(st, T)

    def cond(c):
        st, k, _ = c
        return k < T

    def body_fn(c):
        st, k, outs = c
        target = t_seg[k]
        i = jnp.argmin(jnp.where(st.alive, st.tc, jnp.inf)).astype(jnp.int32)
        t_col = jnp.where(st.alive[i], st.tc[i], jnp.inf)
        stop = _stopped(st) | (st.n_steps >= engine.max_steps)
        which = jnp.where(stop, 2, jnp.where((st.t_rebuild <= t_col) & (st.t_rebuild <= target), 1,
                                             jnp.where(t_col <= target, 0, 2)))
        t_new = jnp.where(which == 0, t_col, jnp.where(which == 1, jnp.maximum(st.t_rebuild, st.t), target))
        t_new = jnp.where(stop, st.t, jnp.maximum(t_new, st.t))
        dt = t_new - st.t
        st = eqx.tree_at(lambda s: (s.X, s.t, s.n_steps, s.flags), st,
                         (jnp.where(st.alive[:, None], _wrap(st.X + st.V * dt, st.par["L"]), st.X), t_new,
                          st.n_steps + 1,
                          st.flags | jnp.where(st.n_steps + 1 >= engine.max_steps, 4, 0)))
        st, outs = jax.lax.switch(which, [lambda s, o: (_sphere_collide(engine, s, i), o),
                                          lambda s, o: (_sphere_rebuild(engine, s, nc_max), o),
                                          lambda s, o: (s, _record(o, k, s))], st, outs)
        return st, k + jnp.where(which == 2, 1, 0), outs

    st, _, outs = jax.lax.while_loop(cond, body_fn, (st, jnp.int32(0), outs0))
    del n
    return st, outs


# ------------------------------------------------------------------------------------------------ aggregates (iii-v)
def _agg_rebuild(engine, st, x, nc_max):
    n = x.shape[0]
    P = st.pair_i.shape[0]
    if nc_max >= 3:
        pair_i, pair_j, n_pairs, over, rev_s, rev_t, n_rev = _build_pairs(
            x, st.sph_R, st.sph_agg, st.par["L"], st.par["skin"], engine.neighbors, P, nc_max)
        nb = st.nb
    else:
        nb, over = _build_neighbors(x, st.sph_R, st.sph_agg, jnp.ones(n, bool), st.par["L"], st.par["skin"],
                                    engine.neighbors, engine.cell_capacity, nc_max, dynamic=False)
        # each pair once (s < t), in the row-major order of nb: the list is symmetric, so this is every pair; the
        # entries t < s of each row are its reverse entries
        rows = jnp.broadcast_to(jnp.arange(n, dtype=jnp.int32)[:, None], nb.shape).reshape(-1)
        cols = nb.reshape(-1)

        def compact(keep):
            tgt = jnp.where(keep, jnp.cumsum(keep) - 1, P)
            return (jnp.zeros(P, jnp.int32).at[tgt].set(rows, mode="drop"),
                    jnp.zeros(P, jnp.int32).at[tgt].set(cols, mode="drop"),
                    jnp.minimum(jnp.sum(keep), P).astype(jnp.int32))

        pair_i, pair_j, n_pairs = compact((cols < n) & (cols > rows))
        rev_s, rev_t, n_rev = compact((cols < n) & (cols < rows))
    adj = _adjacency(pair_i, pair_j, n_pairs, rev_s, rev_t, n_rev, n)
    over = over | adj[-1]
    return eqx.tree_at(lambda s: (s.nb, s.pair_i, s.pair_j, s.n_pairs, s.fwd0, s.degf, s.rev0, s.degr, s.rev_p,
                                  s.x_ref, s.n_build, s.flags), st,
                       (nb, pair_i, pair_j, n_pairs, *adj[:-1], x, st.n_build + 1, st.flags | jnp.where(over, 2, 0)))


def _adjacency(pair_i, pair_j, n_pairs, rev_s, rev_t, n_rev, n, chunk=2048):
    """The listed pairs of each sphere, so that a collision visits only the pairs of its two bodies' members.

    The pairs of sphere s are its forward pairs p in [fwd0[s], fwd0[s] + degf[s]) (the list is row-major: pair_i
    does not decrease) and its reverse pairs rev_p[rev0[s] : rev0[s] + degr[s]] (those with pair_j = s). The
    reverse entries (s, t), t < s, come from the build in row-major order; the pair index of each is found among
    the forward pairs of row t (at most K of them, looped to the largest forward count). Returns (fwd0, degf, rev0,
    degr, rev_p, bad), ``bad`` when a reverse entry has no forward pair or the counts differ (the pair list was cut
    at its capacity: the run stops with the neighbour overflow anyway)."""
    P = pair_i.shape[0]
    lane_p = jnp.arange(P, dtype=jnp.int32)
    degf = jnp.zeros(n, jnp.int32).at[jnp.where(lane_p < n_pairs, pair_i, n)].add(1, mode="drop")
    degr = jnp.zeros(n, jnp.int32).at[jnp.where(lane_p < n_rev, rev_s, n)].add(1, mode="drop")
    fwd0, rev0 = jnp.cumsum(degf) - degf, jnp.cumsum(degr) - degr
    kmax = jnp.max(degf)
    B = min(P, chunk)
    lane = jnp.arange(B, dtype=jnp.int32)

    def one(c, carry):
        rev_p, missing = carry
        r = c * B + lane
        ok = r < n_rev
        rc = jnp.where(ok, r, 0)
        s, t = rev_s[rc], rev_t[rc]
        base, cnt = fwd0[t], degf[t]

        def look(k, pf):
            p, found = pf
            cand = jnp.minimum(base + k, P - 1)
            m = (k < cnt) & (pair_j[cand] == s)
            return jnp.where(m, cand, p), found | m

        p, found = jax.lax.fori_loop(0, kmax, look, (jnp.zeros(B, jnp.int32), jnp.zeros(B, bool)))
        return rev_p.at[jnp.where(ok, r, P)].set(p, mode="drop"), missing | jnp.any(ok & ~found)

    rev_p, missing = jax.lax.fori_loop(0, (n_rev + B - 1) // B, one, (jnp.zeros(P, jnp.int32), jnp.asarray(False)))
    return fwd0, degf, rev0, degr, rev_p, missing | (n_rev != n_pairs)


def _pair_scan(st, x, u, acc, tol, chunk=None):
    """Gaps of the listed pairs of spheres in different aggregates (conservative advancement, module
    docstring): the smallest safe time t* over them, whether some pair is an event (g <= tol, ġ < 0), and
    the event pair (s, t) with the most negative ġ (the first one in list order on ties). The pairs are
    scanned in chunks up to ``n_pairs``, so the cost follows the pairs in use, not the capacity. ``chunk``: pairs
    per scan step (default :func:`_lanes`: 2048 on a CPU, 2^20 on an accelerator, where each chunk costs kernel
    launches: at 1e6 spheres on a GPU the 2048-pair chunks made ~5 ms of a step)."""
    P = st.pair_i.shape[0]
    B = min(P, int(chunk or _lanes(2048, 1 << 20)))
    L = st.par["L"]
    lane = jnp.arange(B)

    def one(c, carry):
        tmin, gbest, ibest = carry
        p = c * B + lane
        ok = p < st.n_pairs
        pc = jnp.where(ok, p, 0)
        i, j = st.pair_i[pc], st.pair_j[pc]
        ga, gb = st.sph_agg[i], st.sph_agg[j]
        valid = ok & (ga != gb)
        g, gdot = _gap_rate(x[i], x[j], u[i], u[j], st.sph_R[i], st.sph_R[j], L)
        A = 2.0 * (acc[ga] + acc[gb])
        ev = valid & (g <= tol) & (gdot < 0)
        # safe time to the gap tol/2, not to contact: a step of t* lands an approaching pair inside the event
        # band (tol/2, tol] in one step when A t* << |ġ|, instead of closing a fraction eta of the gap per step
        ts = jnp.min(jnp.where(valid, body.safe_time(g - 0.5 * tol, gdot, A), jnp.inf))
        ge = jnp.where(ev, gdot, jnp.inf)
        k = jnp.argmin(ge)
        better = ge[k] < gbest
        return jnp.minimum(tmin, ts), jnp.where(better, ge[k], gbest), jnp.where(better, pc[k], ibest).astype(jnp.int32)

    nchunk = (st.n_pairs + B - 1) // B
    inf = jnp.asarray(jnp.inf, jnp.float64)
    tstar, gbest, ib = jax.lax.fori_loop(0, nchunk, one, (inf, inf, jnp.int32(0)))
    return tstar, jnp.isfinite(gbest), st.pair_i[ib], st.pair_j[ib]


#: the numbers of a contact before it is resolved (:func:`_event_numbers`): 3-vectors, then scalars
_EV_VEC = ("Xa", "Xb", "Va", "Vb", "rc", "c1", "c2", "wa", "wb", "nhat", "P0", "L0")
_EV_SCAL = ("ma", "mb", "u_n", "e_imp", "P_scale", "L_scale", "ke0", "first", "coag", "a", "b")
EV_SIZE = 3 * len(_EV_VEC) + len(_EV_SCAL)


def _pack_event(num):
    """The numbers of :func:`_event_numbers` as one float64 vector of EV_SIZE (the state field ``ev``)."""
    return jnp.concatenate([jnp.asarray(num[k], jnp.float64).reshape(3) for k in _EV_VEC]
                           + [jnp.asarray(num[k], jnp.float64).reshape(1) for k in _EV_SCAL])


def _unpack_event(v):
    """Inverse of :func:`_pack_event` (slot ids back to int32, flags to bool)."""
    num = {k: v[3 * i:3 * i + 3] for i, k in enumerate(_EV_VEC)}
    off = 3 * len(_EV_VEC)
    num.update({k: v[off + i] for i, k in enumerate(_EV_SCAL)})
    num["a"], num["b"] = (jnp.round(num[k]).astype(jnp.int32) for k in ("a", "b"))
    num["first"], num["coag"] = num["first"] > 0.5, num["coag"] > 0.5
    return num


def _agg_event(engine, st, s, t, pos, members):
    """Resolve the contact of sphere s (aggregate a) with sphere t (aggregate b): coagulation (R8-R12) or
    restitution (R13-R28) by the outcome rule of the model (R95 §3): :func:`_event_apply` of
    :func:`_event_numbers`."""
    return _event_apply(engine, st, _event_numbers(st, s, t, pos), members)


def _event_numbers(st, s, t, pos):
    """The numbers of the contact of sphere s (aggregate a) with sphere t (aggregate b) before it is resolved: the
    two bodies' COMs (b's image touching a), velocities, spins, masses, the contact point and its arms, the normal,
    the normal speed, the impact energy, momentum, angular momentum and kinetic energy with their scales, whether it
    is the pair's first collision and whether it coagulates (the model's outcome rule).

    ``pos``: (x_s, x_t, r_s, r_t), the space positions and offsets A b of the two spheres."""
    a, b = st.sph_agg[s], st.sph_agg[t]
    L = st.par["L"]
    xs, xt, rs, rt = pos
    d = _mimg(xt - xs, L)
    dist = jnp.sqrt(jnp.sum(d * d))
    nhat = d / dist
    Xa = st.X[a]
    Xb = Xa + rs + d - rt  # the image of b touching a
    rc = Xa + rs + d * (st.sph_R[s] / (st.sph_R[s] + st.sph_R[t]))
    ma, mb = st.M[a], st.M[b]
    Va, Vb = st.V[a], st.V[b]
    mu = ma * mb / (ma + mb)
    dv = Vb - Va
    e_imp = 0.5 * mu * jnp.sum(dv * dv)
    wa = body.omega_space(st.q[a], st.Pi[a], st.Ip[a])
    wb = body.omega_space(st.q[b], st.Pi[b], st.Ip[b])
    c1, c2 = rc - Xa, rc - Xb
    u_n = jnp.sum(((Vb + jnp.cross(wb, c2)) - (Va + jnp.cross(wa, c1))) * nhat)
    hA = body.angular_momentum_space(st.q[a], st.Pi[a])
    hB = body.angular_momentum_space(st.q[b], st.Pi[b])
    ke0 = (0.5 * ma * jnp.sum(Va * Va) + 0.5 * mb * jnp.sum(Vb * Vb) + body.kinetic_energy_rot(st.Pi[a], st.Ip[a])
           + body.kinetic_energy_rot(st.Pi[b], st.Ip[b]))
    P0 = ma * Va + mb * Vb
    L0 = ma * jnp.cross(Xa - rc, Va) + mb * jnp.cross(Xb - rc, Vb) + hA + hB
    P_scale = ma * jnp.sqrt(jnp.sum(Va * Va)) + mb * jnp.sqrt(jnp.sum(Vb * Vb))
    L_scale = (ma * jnp.sqrt(jnp.sum((Xa - rc) ** 2)) * jnp.sqrt(jnp.sum(Va * Va))
               + mb * jnp.sqrt(jnp.sum((Xb - rc) ** 2)) * jnp.sqrt(jnp.sum(Vb * Vb))
               + jnp.sqrt(jnp.sum(hA * hA)) + jnp.sqrt(jnp.sum(hB * hB)))
    first = ~((st.last[a] == b) | (st.last[b] == a))
    coag = (e_imp < st.par["e_thr"]) if st.kind == "threshold" else jnp.asarray(True)
    return dict(Xa=Xa, Xb=Xb, Va=Va, Vb=Vb, rc=rc, c1=c1, c2=c2, wa=wa, wb=wb, nhat=nhat, P0=P0, L0=L0, ma=ma, mb=mb,
                u_n=u_n, e_imp=e_imp, P_scale=P_scale, L_scale=L_scale, ke0=ke0, first=first, coag=coag, a=a, b=b)


def _event_apply(engine, st, num, members):
    """Resolve a contact from its numbers (:func:`_event_numbers`): coagulation (R8-R12) or restitution (R13-R28),
    the collision log and the counters.

    ``members``: a list of (pred, fn) pairs, fn(state) returning (ids, r): sphere ids that include every member of
    a and b (``n0`` for none) and their offsets; a coagulation works on the rows of the one pair whose pred holds
    (all spheres for the global clock; for the per-body clocks, the members in the smallest of a few fixed
    capacities, :func:`_members`)."""
    n = st.alive.shape[0]
    a, b = num["a"], num["b"]
    lo, hi = jnp.minimum(a, b), jnp.maximum(a, b)
    Xa, Xb, Va, Vb, rc, c1, c2, wa, wb, nhat = (num[k] for k in ("Xa", "Xb", "Va", "Vb", "rc", "c1", "c2", "wa", "wb",
                                                                 "nhat"))
    ma, mb, u_n, P0, L0, ke0, coag = (num[k] for k in ("ma", "mb", "u_n", "P0", "L0", "ke0", "coag"))

    def coagulate(st, ids, r):
        ok = ids < n
        idc = jnp.where(ok, ids, 0)
        g = st.sph_agg[idc]
        in_a = ok & (g == a)
        in_b = ok & (g == b)
        mask = in_a | in_b
        sx = jnp.where(in_b[:, None], Xb[None, :] + r, Xa[None, :] + r)
        X, V, q, Pi, Ip, bnew, Rm = body.merge(Xa, Va, st.q[a], st.Pi[a], st.Ip[a], ma, Xb, Vb, st.q[b], st.Pi[b],
                                               st.Ip[b], mb, sx, st.sph_m[idc], st.sph_R[idc], mask)
        tgt = jnp.where(mask, ids, n)
        st = _mem_append(st, ids, mask, lo)
        P1 = (ma + mb) * V
        L1 = (ma + mb) * jnp.cross(X - rc, V) + body.angular_momentum_space(q, Pi)
        ke1 = 0.5 * (ma + mb) * jnp.sum(V * V) + body.kinetic_energy_rot(Pi, Ip)
        st = eqx.tree_at(
            lambda s: (s.X, s.V, s.q, s.Pi, s.Ip, s.M, s.Rmax, s.nmem, s.alive, s.last, s.sph_b, s.sph_agg,
                       s.n_coag),
            st,
            (st.X.at[lo].set(_wrap(X, st.par["L"])), st.V.at[lo].set(V).at[hi].set(0.0), st.q.at[lo].set(q),
             st.Pi.at[lo].set(Pi).at[hi].set(0.0), st.Ip.at[lo].set(Ip), st.M.at[lo].set(ma + mb).at[hi].set(0.0),
             st.Rmax.at[lo].set(Rm).at[hi].set(0.0), st.nmem.at[lo].set(st.nmem[a] + st.nmem[b]).at[hi].set(0),
             st.alive.at[hi].set(False), st.last.at[lo].set(hi), st.sph_b.at[tgt].set(bnew, mode="drop"),
             st.sph_agg.at[tgt].set(lo, mode="drop"), st.n_coag + 1))
        return st, _changes(P1, L1, ke1), jnp.int32(COAGULATION)

    def restitute(st):
        Ia = body.inertia_inv_space(st.q[a], st.Ip[a])
        Ib = body.inertia_inv_space(st.q[b], st.Ip[b])
        eps = jnp.where(st.par["eps_n"] < 0, body.bridges_epsilon(jnp.abs(u_n), v_unit=st.par["v_unit"]),
                        st.par["eps_n"])
        dV1, dV2, dw1, dw2 = body.restitute(ma, mb, Ia, Ib, c1, c2, Va, Vb, wa, wb, nhat, eps, st.par["mu_t"],
                                            st.par["mu_p"])
        V1, V2 = Va + dV1, Vb + dV2
        Pi1 = body.pi_from_omega_space(st.q[a], wa + dw1, st.Ip[a])
        Pi2 = body.pi_from_omega_space(st.q[b], wb + dw2, st.Ip[b])
        P1 = ma * V1 + mb * V2
        L1 = (ma * jnp.cross(Xa - rc, V1) + mb * jnp.cross(Xb - rc, V2) + body.angular_momentum_space(st.q[a], Pi1)
              + body.angular_momentum_space(st.q[b], Pi2))
        ke1 = (0.5 * ma * jnp.sum(V1 * V1) + 0.5 * mb * jnp.sum(V2 * V2) + body.kinetic_energy_rot(Pi1, st.Ip[a])
               + body.kinetic_energy_rot(Pi2, st.Ip[b]))
        st = eqx.tree_at(lambda s: (s.V, s.Pi, s.last, s.n_rest), st,
                         (st.V.at[a].set(V1).at[b].set(V2), st.Pi.at[a].set(Pi1).at[b].set(Pi2),
                          st.last.at[a].set(b).at[b].set(a), st.n_rest + 1))
        return st, _changes(P1, L1, ke1), jnp.int32(RESTITUTION)

    def _changes(P1, L1, ke1):  # inside the branches: computed after them, XLA re-read the old state there
        return jnp.stack([jnp.sqrt(jnp.sum((P1 - P0) ** 2)), jnp.sqrt(jnp.sum((L1 - L0) ** 2)), ke1 - ke0])

    # the record of the state before the event is written first, and the outcome's numbers after the branches: a
    # log write after them, fused with reads of the state as it was, made XLA copy every written state array
    i_log = st.n_log
    st = _write_log(st, dict(t=st.t, e_imp=num["e_imp"], u_n=u_n, m_a=ma, m_b=mb, dP=0.0, dL=0.0, dKE=0.0,
                             P_scale=num["P_scale"], L_scale=num["L_scale"], KE=ke0, a=a, b=b, outcome=0))
    st = eqx.tree_at(lambda s: (s.n_c, s.n_c1), st, (st.n_c + 1, st.n_c1 + num["first"].astype(jnp.int32)))
    # the branches as gated loops, not a lax.cond: a cond copied the state arrays in and out of them (_gated)
    c0 = (st, jnp.zeros(3, P0.dtype), jnp.int32(0))
    for pred, fn in members:
        c0 = _gated(coag & pred, lambda c, fn=fn: coagulate(c[0], *fn(c[0])), c0)
    st, chg, outcome = _gated(~coag, lambda c: restitute(c[0]), c0)
    log = dict(st.log)
    for k, v in (("dP", chg[0]), ("dL", chg[1]), ("dKE", chg[2]), ("outcome", outcome)):
        log[k] = log[k].at[i_log].set(jnp.asarray(v, log[k].dtype), mode="drop")
    return eqx.tree_at(lambda s: s.log, st, log)


def _mem_append(st, ids, mask, lo):
    """Append the merged member list (``ids`` where ``mask``) of a coagulation into slot ``lo`` at the top of
    ``mem``, compacting ``mem`` first when it would not fit (:func:`_mem_compact`: amortised O(1) per member)."""
    cap = st.mem.shape[0]
    cnt = jnp.sum(mask).astype(jnp.int32)
    # the gated compaction carries only the arrays it writes
    mem, mem0, top = _gated(st.mem_top + cnt > cap, lambda c: _mem_compact(c[0], c[1], st.alive, st.nmem),
                            (st.mem, st.mem0, st.mem_top))
    pos = top + jnp.cumsum(mask).astype(jnp.int32) - 1
    return eqx.tree_at(lambda s: (s.mem, s.mem0, s.mem_top), st,
                       (mem.at[jnp.where(mask, pos, cap)].set(ids, mode="drop"), mem0.at[lo].set(top), top + cnt))


def _mem_compact(mem, mem0, alive, nmem):
    """Move the member lists of the live aggregates to the front of ``mem`` in their order (the lists of merged
    aggregates left behind are dropped). Returns (mem, mem0, mem_top); mem_top becomes n0, so a list of up to n0 more
    members fits."""
    cap = mem.shape[0]
    live = alive & (nmem > 0)
    d = (jnp.zeros(cap + 1, jnp.int32).at[jnp.where(live, mem0, cap)].add(1)
         .at[jnp.where(live, mem0 + nmem, cap)].add(-1))
    inseg = jnp.cumsum(d)[:cap] > 0
    newpos = jnp.cumsum(inseg).astype(jnp.int32) - 1
    new = jnp.full(cap, alive.shape[0], jnp.int32).at[jnp.where(inseg, newpos, cap)].set(mem, mode="drop")
    return new, jnp.where(live, newpos[jnp.clip(mem0, 0, cap - 1)], mem0), jnp.sum(inseg).astype(jnp.int32)


def _segment_ids(st, a, b, c):
    """The sphere ids of aggregates a and b (a's list, then b's) in a capacity c, padded with n0."""
    n = st.alive.shape[0]
    cap = st.mem.shape[0]
    na, nb = st.nmem[a], st.nmem[b]
    k = jnp.arange(c, dtype=jnp.int32)
    src = jnp.where(k < na, st.mem0[a] + k, st.mem0[b] + k - na)
    return jnp.where(k < na + nb, st.mem[jnp.clip(src, 0, cap - 1)], n)


def _spinning(st, ids=None):
    """Bodies (all, or ``ids``) whose orientation moves: live aggregates and spinning spheres (a free sphere with
    Π = 0 keeps q = 1 exactly), so the rotation work follows them."""
    sel = (lambda a: a) if ids is None else (lambda a: a[ids])
    return sel(st.alive) & ((sel(st.nmem) > 1) | jnp.any(sel(st.Pi) != 0, axis=-1))


def _rotate_chunks(st, dt, nsub, spin):
    """Torque-free rotation of the bodies ``spin`` over ``dt`` (scalar or (n,)) in ``nsub`` (n,) substeps each, in
    chunks of spinning bodies (128 on a CPU: :func:`_lanes`), those needing more than half the largest count first,
    so that most chunks hold bodies of similar counts: a chunk loops to its largest count and masks the others
    (:func:`~jaxcoag.aggregates.rigid.body.rotate_free_batch`). (Sorting by ceil log2 n_sub with a cumsum over
    (n0, 7) one-hot classes cost ~0.5 ms per step at 3e4 spheres, more than it saved.) Returns (q, Pi)."""
    n = st.alive.shape[0]
    per_body = jnp.ndim(dt) > 0
    fast = spin & (2 * nsub > jnp.max(nsub))
    cf, cs = jnp.cumsum(fast), jnp.cumsum(spin)
    pos = jnp.where(fast, cf - 1, jnp.where(spin, cf[-1] + (cs - cf) - 1, n))
    ids = jnp.full(n, n, jnp.int32).at[pos].set(jnp.arange(n, dtype=jnp.int32), mode="drop")
    m = jnp.sum(spin).astype(jnp.int32)
    B = min(n, _lanes(128, 16384))
    lane = jnp.arange(B)

    def chunk(c, qp):
        p = c * B + lane
        ok = p < m
        sl = jnp.where(ok, ids[jnp.minimum(p, n - 1)], 0)
        qb, pb = body.rotate_free_batch(qp[0][sl], qp[1][sl], st.Ip[sl], dt[sl] if per_body else dt,
                                        jnp.where(ok, nsub[sl], 1))
        tgt = jnp.where(ok, sl, n)
        return qp[0].at[tgt].set(qb, mode="drop"), qp[1].at[tgt].set(pb, mode="drop")

    return jax.lax.fori_loop(0, (m + B - 1) // B, chunk, (st.q, st.Pi))


def _agg_advance(engine, st, dt, Om):
    # per-body substep counts, |ω| h <= 0.02 for each body (spec A3; Om bounds |ω| over the free motion)
    spin = _spinning(st)
    nsub = jnp.where(spin, jnp.clip(jnp.ceil(Om * dt / 0.02), 1, engine.n_rot), 0).astype(jnp.int32)
    q, Pi = _rotate_chunks(st, dt, nsub, spin)
    X = jnp.where(st.alive[:, None], _wrap(st.X + st.V * dt, st.par["L"]), st.X)
    return eqx.tree_at(lambda s: (s.X, s.q, s.Pi, s.t), st, (X, q, Pi, st.t + dt))


def _agg_loop(engine, st, t_seg, nc_max):
    T = t_seg.shape[0]
    tol = engine.tol * st.par["r0"]
    skin = st.par["skin"]

    def cond(c):
        return c[1] < T

    def body_fn(c):
        st, k, outs = c
        target = t_seg[k]
        # sphere positions once per step: without the barrier XLA fused _sphere_pos into each of its consumers
        # and recomputed it there (at 3e4 spheres ~1 ms per consumer)
        x, r, u = jax.lax.optimization_barrier(_sphere_pos(st))
        dsp = _mimg(x - st.x_ref, st.par["L"])
        # the squared displacements materialised before the max (fused into the reduction, a library kernel on
        # CPU, the pass took 1.65 ms at 3e4 spheres, 0.9 ms with the barrier; one profile each, machine loaded)
        disp = jnp.sqrt(jnp.max(jax.lax.optimization_barrier(_dot3(dsp, dsp))))
        rebuild = (disp > 0.4 * skin) | (st.n_build == 0)
        st = jax.lax.cond(rebuild, lambda s: _agg_rebuild(engine, s, x, nc_max), lambda s: s, st)
        disp = jnp.where(rebuild, 0.0, disp)  # a rebuild sets x_ref = x
        Om = body.max_spin(st.Pi, st.Ip)
        acc = Om * Om * st.Rmax
        tstar, any_ev, s_ev, t_ev = _pair_scan(st, x, u, acc, tol)
        spd = jnp.where(st.alive, jnp.sqrt(_dot3(st.V, st.V)) + Om * st.Rmax, 0.0)
        vmax = jnp.max(spd)
        dt_skin = jnp.where(vmax > 0, (0.5 * skin - disp) / jnp.where(vmax > 0, vmax, 1.0), jnp.inf)
        ommax = jnp.max(jnp.where(st.alive, Om, 0.0))
        dt_rot = jnp.where(ommax > 0, engine.n_rot * 0.02 / jnp.where(ommax > 0, ommax, 1.0), jnp.inf)
        dt_free = jnp.minimum(jnp.minimum(engine.eta * tstar, dt_skin), dt_rot)
        stop = _stopped(st) | (st.n_steps >= engine.max_steps)
        reach = dt_free >= target - st.t
        which = jnp.where(stop, 3, jnp.where(any_ev, 0, jnp.where(reach, 2, 1)))
        st = eqx.tree_at(lambda s: (s.n_steps, s.flags), st,
                         (st.n_steps + 1, st.flags | jnp.where(st.n_steps + 1 >= engine.max_steps, 4, 0)))

        def out_at(s, o):
            s = _agg_advance(engine, s, jnp.maximum(target - s.t, 0.0), Om)
            s = eqx.tree_at(lambda z: z.t, s, target)
            return s, _record(o, k, s)

        ev_pos = (x[s_ev], x[t_ev], r[s_ev], r[t_ev])
        every = [(jnp.asarray(True), lambda _: (jnp.arange(x.shape[0], dtype=jnp.int32), r))]
        st, outs = jax.lax.switch(which, [lambda s, o: (_agg_event(engine, s, s_ev, t_ev, ev_pos, every), o),
                                          lambda s, o: (_agg_advance(engine, s, dt_free, Om), o),
                                          out_at,
                                          lambda s, o: (s, _record(o, k, s))], st, outs)
        return st, k + jnp.where(which >= 2, 1, 0), outs

    st, _, outs = jax.lax.while_loop(cond, body_fn, (st, jnp.int32(0), _empty_outputs(st, T)))
    return st, outs


# ------------------------------------------------------------------------------------------------ per-body clocks
_NSUB_MAX = 1 << 30


def _gated(pred, fn, carry):
    """``fn(carry)`` if ``pred`` else ``carry``, as a loop of 0 or 1 trips. XLA updates a while loop's carry in
    place; a ``lax.cond``/``lax.switch`` over the state made it copy every state array into and out of the
    branches at each iteration (~135 copies, ~250 us per pair check at n0 = 300)."""
    return jax.lax.fori_loop(0, jnp.asarray(pred).astype(jnp.int32), lambda _, c: fn(c), carry)


def _nsub_free(Om, dt):
    """Substeps of |ω| h <= 0.02 (spec A3) for a free rotation over dt with spin bound Om (no cap but 2^30)."""
    return jnp.clip(jnp.ceil(Om * dt / 0.02), 1, _NSUB_MAX).astype(jnp.int32)


def _sync(st, t_new):
    """Every live body from its own clock ``tb`` to ``t_new`` (free translation, torque-free rotation with
    |ω| h <= 0.02 in each body's own substeps); then ``tb = t = t_new``."""
    dt = t_new - st.tb
    spin = _spinning(st) & (dt > 0)
    nsub = jnp.where(spin, _nsub_free(body.max_spin(st.Pi, st.Ip), dt), 0)
    q, Pi = _rotate_chunks(st, dt, nsub, spin)
    X = jnp.where(st.alive[:, None], _wrap(st.X + st.V * dt[:, None], st.par["L"]), st.X)
    return eqx.tree_at(lambda s: (s.X, s.q, s.Pi, s.tb, s.t), st,
                       (X, q, Pi, jnp.full_like(st.tb, t_new), jnp.asarray(t_new, st.t.dtype)))


def _bodies_to(st, ids, t_new):
    """Bodies ``ids`` (k,) from their clocks to ``t_new`` (as :func:`_sync`, for these bodies only)."""
    dt = t_new - st.tb[ids]
    q0, Pi0, Ip = st.q[ids], st.Pi[ids], st.Ip[ids]
    spin = _spinning(st, ids) & (dt > 0)
    nsub = jnp.where(spin, _nsub_free(body.max_spin(Pi0, Ip), dt), 1)
    q, Pi = jax.lax.cond(jnp.any(spin), lambda: body.rotate_free_batch(q0, Pi0, Ip, dt, nsub), lambda: (q0, Pi0))
    q = jnp.where(spin[:, None], q, q0)
    Pi = jnp.where(spin[:, None], Pi, Pi0)
    X = jnp.where(st.alive[ids][:, None], _wrap(st.X[ids] + st.V[ids] * dt[:, None], st.par["L"]), st.X[ids])
    # max(t_new, tb) = t_new (clocks only advance); written so, the write follows the read of tb (a write that did
    # not depend on it made XLA copy tb)
    return eqx.tree_at(lambda s: (s.X, s.q, s.Pi, s.tb), st,
                       (st.X.at[ids].set(X), st.q.at[ids].set(q), st.Pi.at[ids].set(Pi),
                        st.tb.at[ids].set(jnp.maximum(t_new, t_new - dt))))


def _speed_bound(st, ids=None):
    """|V| + Ω R_max of the live bodies (all, or ``ids``): a bound on the speed of each of their spheres."""
    sel = (lambda a: a) if ids is None else (lambda a: a[ids])
    V, Om = sel(st.V), body.max_spin(sel(st.Pi), sel(st.Ip))
    return jnp.max(jnp.where(sel(st.alive), jnp.sqrt(_dot3(V, V)) + Om * sel(st.Rmax), 0.0))


def _deadline(t, dsp, vmx, skin):
    """Time at which a sphere may have moved skin/2 since the build (displacement bound dsp at t, speed <= vmx)."""
    return t + jnp.where(vmx > 0, (0.5 * skin - dsp) / jnp.where(vmx > 0, vmx, 1.0), jnp.inf)


def _argmin2(x):
    """(index of the smallest entry, the second smallest value) of a 1-D array in one reduction (ties: the first
    index, and the second smallest equals the smallest)."""
    idx = jnp.arange(x.shape[0], dtype=jnp.int32)

    def comb(a, b):
        (ma, ia, sa), (mb, ib, sb) = a, b
        first = (ma < mb) | ((ma == mb) & (ia < ib))
        return (jnp.where(first, ma, mb), jnp.where(first, ia, ib),
                jnp.minimum(jnp.minimum(sa, sb), jnp.maximum(ma, mb)))

    inf = jnp.asarray(jnp.inf, x.dtype)
    _, i, s = jax.lax.reduce((x, idx, jnp.full_like(x, jnp.inf)), (inf, jnp.int32(x.shape[0]), inf), comb, (0,))
    return i, s


def _tau_pass(st, n_chunks, fn, carry=None):
    """Apply ``fn(p, ok, tau_chunk) -> new tau chunk`` to the blocks c < n_chunks of the pair check times (those of
    ``carry`` = (tau, tau_blk), default the state's) and keep their block minima."""
    B = st.tau.shape[0] // st.tau_blk.shape[0]
    lane = jnp.arange(B, dtype=jnp.int32)

    def one(c, carry):
        tau, blk = carry
        p = c * B + lane
        ok = p < st.n_pairs
        tc = fn(jnp.where(ok, p, 0), ok, jax.lax.dynamic_slice(tau, (c * B,), (B,)))
        return jax.lax.dynamic_update_slice(tau, tc, (c * B,)), blk.at[c].set(jnp.min(tc))

    return jax.lax.fori_loop(0, n_chunks, one, (st.tau, st.tau_blk) if carry is None else carry)


def _tau_scan(engine, st, x, u, tol, n_old):
    """Next check time of every listed pair from the synchronised state (positions x, velocities u of the
    spheres at ``st.t``): ``t + eta t*`` with t* the safe time to the gap tol/2 (as the global step), ``t`` for a
    pair in the event band, ``inf`` for pairs of one aggregate and for unused slots (up to the larger of the old
    and new pair counts ``n_old``, ``st.n_pairs``)."""
    B = st.tau.shape[0] // st.tau_blk.shape[0]
    Om = body.max_spin(st.Pi, st.Ip)
    acc = Om * Om * st.Rmax
    L = st.par["L"]

    def fn(pc, ok, _):
        i, j = st.pair_i[pc], st.pair_j[pc]
        ga, gb = st.sph_agg[i], st.sph_agg[j]
        valid = ok & (ga != gb)
        g, gdot = _gap_rate(x[i], x[j], u[i], u[j], st.sph_R[i], st.sph_R[j], L)
        ev = (g <= tol) & (gdot < 0)
        ts = jnp.where(ev, 0.0, engine.eta * body.safe_time(g - 0.5 * tol, gdot, 2.0 * (acc[ga] + acc[gb])))
        return jnp.where(valid, st.t + ts, jnp.inf)

    n = jnp.maximum(st.n_pairs, n_old)
    tau, blk = _tau_pass(st, (n + B - 1) // B, fn)
    return eqx.tree_at(lambda s: (s.tau, s.tau_blk), st, (tau, blk))


def _renew(engine, st, t_new, nc_max, tol, force):
    """Synchronise every body at ``t_new``; rebuild the pair list if a sphere moved more than 0.4 skin since the
    last build (or none was built); scan every pair's check time after a rebuild (or if ``force``); restart the
    displacement bound from the measured displacement and the current speed bound."""
    st = _sync(st, t_new)
    x, _, u = _sphere_pos(st)
    dsp_v = _mimg(x - st.x_ref, st.par["L"])
    disp = jnp.sqrt(jnp.max(jax.lax.optimization_barrier(_dot3(dsp_v, dsp_v))))
    rebuild = (disp > 0.4 * st.par["skin"]) | (st.n_build == 0)
    n_old = st.n_pairs
    st = _gated(rebuild, lambda s: _agg_rebuild(engine, s, x, nc_max), st)
    disp = jnp.where(rebuild, 0.0, disp)
    st = _gated(rebuild | force, lambda s: _tau_scan(engine, s, x, u, tol, n_old), st)
    vmx = _speed_bound(st)
    return eqx.tree_at(lambda s: (s.dsp, s.vmx, s.t_dsp, s.t_rebuild), st,
                       (disp, vmx, st.t, _deadline(st.t, disp, vmx, st.par["skin"])))


def _buckets(n):
    """The capacities of the member lists of a collision (per-body clocks): 64, 1024, 8192 below n0, then n0."""
    return [c for c in (64, 1024, 8192) if c < n] + [n]


def _members(st, a, b):
    """The ``members`` argument of :func:`_agg_event` for the per-body clocks: the sphere ids of aggregates a and b
    (and their offsets A b) from their member lists (:func:`_segment_ids`) in the smallest of the capacities of
    :func:`_buckets` that holds nmem[a] + nmem[b], so that a coagulation costs O(members)."""
    n = st.alive.shape[0]
    need = st.nmem[a] + st.nmem[b]
    out, lo = [], 0
    for c in _buckets(n):
        def fill(st, c=c):  # the state the gated loop carries (a captured one would make XLA copy it)
            ids = _segment_ids(st, a, b, c)
            return ids, _sphere_pos_of(st, jnp.where(ids < n, ids, 0))[1]
        out.append(((need > lo) & (need <= c), fill))
        lo = c
    return out


def _check_pair(engine, st, p, blk, te, m2, tol):
    """Check listed pair p at its check time te: bring its two bodies to te and set the pair's next check time
    te + eta t* (inf for a pair inside one aggregate). Returns (state, whether the pair is in contact: g <= tol,
    ġ < 0); for a contact the state's ``ev`` holds its numbers (:func:`_event_numbers`), for :func:`_collide_pair`.
    """
    i, j = st.pair_i[p], st.pair_j[p]
    a, b = st.sph_agg[i], st.sph_agg[j]
    ab = jnp.stack([a, b])
    st = _bodies_to(st, ab, te)
    st = eqx.tree_at(lambda s: s.t, st, te)
    x2, r2, u2 = _sphere_pos_of(st, jnp.stack([i, j]))
    g, gdot = _gap_rate(x2[0], x2[1], u2[0], u2[1], st.sph_R[i], st.sph_R[j], st.par["L"])
    Om = body.max_spin(st.Pi[ab], st.Ip[ab])
    A = 2.0 * jnp.sum(Om * Om * st.Rmax[ab])
    same = a == b
    hit = ~same & (g <= tol) & (gdot < 0)
    ev = _gated(hit, lambda _: _pack_event(_event_numbers(st, i, j, (x2[0], x2[1], r2[0], r2[1]))), st.ev)
    # the next check (after a contact the pass over the pairs of both bodies sets it to te again); the block's new
    # minimum from its second smallest entry m2 (read with the choice of p): a read of the block after the write
    # needed the old tau beside the new one, and XLA copied the whole of tau at every check
    nxt = jnp.where(same, jnp.inf, te + engine.eta * body.safe_time(g - 0.5 * tol, gdot, A))
    st = eqx.tree_at(lambda s: (s.tau, s.tau_blk, s.ev), st,
                     (st.tau.at[p].set(nxt), st.tau_blk.at[blk].set(jnp.minimum(m2, nxt)), ev))
    return st, hit


#: members of a colliding pair above which the pairs of the two bodies get a conservative next check in one pass
_BIG_EVENT = 32


def _pairs_of(st, ids, fn, carry):
    """``carry = fn(p, ok, carry)`` over the listed pairs of the spheres ``ids`` (c,) (padded with n0) in chunks of
    4 c entries: the forward and reverse pairs of each sphere (:func:`_adjacency`), enumerated as one flat sequence
    (a pair of two of the spheres comes twice)."""
    n = st.alive.shape[0]
    P = st.pair_i.shape[0]
    c = ids.shape[0]
    okm = ids < n
    sid = jnp.where(okm, ids, 0)
    df = jnp.where(okm, st.degf[sid], 0)
    deg = df + jnp.where(okm, st.degr[sid], 0)
    cs = jnp.cumsum(deg)
    E = 4 * c
    lane = jnp.arange(E, dtype=jnp.int32)

    def one(k, carry):
        f = k * E + lane
        ok = f < cs[-1]
        m = jnp.minimum(jnp.searchsorted(cs, f, side="right"), c - 1).astype(jnp.int32)
        within = f - (cs[m] - deg[m])
        s_ = sid[m]
        p = jnp.where(within < df[m], st.fwd0[s_] + within,
                      st.rev_p[jnp.clip(st.rev0[s_] + within - df[m], 0, P - 1)])
        return fn(jnp.where(ok, p, 0), ok, carry)

    return jax.lax.fori_loop(0, (cs[-1] + E - 1) // E, one, carry)


def _collide_pair(engine, st, tol):
    """Resolve the contact found by :func:`_check_pair` at the current time from its numbers ``st.ev`` (reading no
    state as it was before the collision's writes: such reads, fused by XLA into code it hoists out of the gated
    branches, made it copy every written state array at each collision), give every listed pair of the two bodies'
    members a new check time (:func:`_pairs_of`: O(members), not a pass over the list), and update the
    displacement bound and the rebuild deadline with their new speeds."""
    n = st.alive.shape[0]
    B = st.tau.shape[0] // st.tau_blk.shape[0]
    nt, nb = st.tau.shape[0], st.tau_blk.shape[0]
    te = st.t
    num = _unpack_event(st.ev)
    a, b = num["a"], num["b"]
    st = _event_apply(engine, st, num, _members(st, a, b))
    need = st.nmem[a] + st.nmem[b]  # after the event (merged into one slot, the other 0): read before, XLA copied nmem
    agg = st.sph_agg

    def flag(pc, ok, carry):
        # check now: the pair's bodies have new velocities and spins (te is below every pending check time)
        tau, tblk = carry
        return (tau.at[jnp.where(ok, pc, nt)].set(te, mode="drop"),
                tblk.at[jnp.where(ok, pc // B, nb)].set(te, mode="drop"))

    def bound(pc, ok, carry):
        # a conservative next check for every pair of the two bodies at once: the partner body is at its own clock
        # tb; its spheres are translated to te and given the slack min(2 R_max, Ω R_max (te - tb)) for the
        # rotation, and the gap cannot close faster than |V_j - V_i| + Ω_i R_max,i + Ω_j R_max,j. The pair keeps
        # its old check time when that is earlier (an early check is safe), so the block minima stay exact.
        tau, tblk = carry
        i, j = st.pair_i[pc], st.pair_j[pc]
        gi, gj = agg[i], agg[j]
        (xi, _, _), (xj, _, _) = _sphere_pos_of(st, i), _sphere_pos_of(st, j)
        dti, dtj = te - st.tb[gi], te - st.tb[gj]
        Oi, Oj = body.max_spin(st.Pi[gi], st.Ip[gi]), body.max_spin(st.Pi[gj], st.Ip[gj])
        Ri, Rj = st.Rmax[gi], st.Rmax[gj]
        slack = jnp.minimum(2.0 * Ri, Oi * Ri * dti) + jnp.minimum(2.0 * Rj, Oj * Rj * dtj)
        d = _mimg(xj + st.V[gj] * dtj[:, None] - xi - st.V[gi] * dti[:, None], st.par["L"])
        g = jnp.sqrt(_dot3(d, d)) - st.sph_R[i] - st.sph_R[j] - slack
        dv = st.V[gj] - st.V[gi]
        w = jnp.sqrt(_dot3(dv, dv)) + Oi * Ri + Oj * Rj
        ts = jnp.where(w > 0, jnp.maximum(g - 0.5 * tol, 0.0) / jnp.where(w > 0, w, 1.0), jnp.inf)
        new = jnp.where(gi == gj, jnp.inf, te + engine.eta * ts)
        return (tau.at[jnp.where(ok, pc, nt)].min(new, mode="drop"),
                tblk.at[jnp.where(ok, pc // B, nb)].min(new, mode="drop"))

    # small aggregates: their few pairs are checked one by one from now; large ones (hundreds of pairs, each a
    # loop iteration) get the conservative bound at once; the member lists in the capacities of _buckets
    sizes = _buckets(n)
    tt = (st.tau, st.tau_blk)
    tt = _gated(need <= _BIG_EVENT, lambda c: _pairs_of(st, _segment_ids(st, a, b, sizes[0]), flag, c), tt)
    lo = _BIG_EVENT
    for c in sizes:
        if c > lo:
            tt = _gated((need > lo) & (need <= c),
                        lambda t, c=c: _pairs_of(st, _segment_ids(st, a, b, c), bound, t), tt)
            lo = c
    tau, tblk = tt
    dsp = st.dsp + st.vmx * (te - st.t_dsp)
    vmx = jnp.maximum(st.vmx, _speed_bound(st, jnp.stack([a, b])))
    return eqx.tree_at(lambda s: (s.tau, s.tau_blk, s.dsp, s.vmx, s.t_dsp, s.t_rebuild), st,
                       (tau, tblk, dsp, vmx, te, _deadline(te, dsp, vmx, st.par["skin"])))


def _agg_loop_body(engine, st, t_seg, nc_max):
    """Models (iii)-(v) with per-body clocks (module docstring). Each iteration of the outer loop runs the pair checks
    in time order (an inner loop) until a contact, the rebuild deadline or the next output time comes first, then
    resolves the contact, resynchronises (and rebuilds the list if due) or records the output."""
    T = t_seg.shape[0]
    tol = engine.tol * st.par["r0"]
    B = st.tau.shape[0] // st.tau_blk.shape[0]
    # a state whose check times are not valid (fresh, or last advanced with the global clock) scans every pair
    st = _gated(~jnp.isfinite(st.t_dsp), lambda s: _renew(engine, s, s.t, nc_max, tol, True), st)

    def earliest(st):
        # the time from the block minima (equal to the slot's entry): a read of tau itself, fused into the
        # consumers after tau's in-place write, made XLA copy the whole of tau at every check
        blk = jnp.argmin(st.tau_blk).astype(jnp.int32)
        l, m2 = _argmin2(jax.lax.dynamic_slice(st.tau, (blk * B,), (B,)))
        return blk * B + l, blk, st.tau_blk[blk], m2

    def halted(st):
        return _stopped(st) | (st.n_steps >= engine.max_steps)

    def count(st):
        return eqx.tree_at(lambda s: (s.n_steps, s.flags), st,
                           (st.n_steps + 1, st.flags | jnp.where(st.n_steps + 1 >= engine.max_steps, 4, 0)))

    def cond(c):
        return c[1] < T

    def body_fn(c):
        st, k, outs = c
        target = t_seg[k]

        # pair checks up to the next contact, resynchronisation or output (the loop's carry is updated in place);
        # the contact is resolved after the loop, from the numbers the check stored
        def due(c):
            return (earliest(c[0])[2] < jnp.minimum(target, c[0].t_rebuild)) & ~halted(c[0]) & ~c[1]

        def check(c):
            p, blk, te, m2 = earliest(c[0])
            return _check_pair(engine, count(c[0]), p, blk, te, m2, tol)

        st, hit = jax.lax.while_loop(due, check, (st, jnp.asarray(False)))
        st = _gated(hit, lambda s: _collide_pair(engine, s, tol), st)
        which = jnp.where(hit, 0, jnp.where(halted(st), 3, jnp.where(st.t_rebuild < target, 1, 2)))
        st = _gated(which > 0, count, st)

        def record(so):
            s = _sync(so[0], jnp.where(which == 2, jnp.maximum(target, so[0].t), so[0].t))
            return s, _record(so[1], k, s)

        st = _gated(which == 1, lambda s: _renew(engine, s, jnp.maximum(s.t_rebuild, s.t), nc_max, tol, False), st)
        st, outs = _gated(which >= 2, record, (st, outs))
        return st, k + jnp.where(which >= 2, 1, 0), outs

    st, _, outs = jax.lax.while_loop(cond, body_fn, (st, jnp.int32(0), _empty_outputs(st, T)))
    return st, outs


def _advance_impl(engine, st, t_seg, nc_max):
    if st.kind in _SPHERE_KINDS:
        return _sphere_loop(engine, st, t_seg, nc_max)
    if (engine.clock or _lanes("body", "global")) == "body":
        return _agg_loop_body(engine, st, t_seg, nc_max)
    st, outs = _agg_loop(engine, st, t_seg, nc_max)
    # every body at the common time; the per-pair check times are not kept by this clock
    st = eqx.tree_at(lambda s: (s.tb, s.t_dsp), st, (jnp.full_like(st.tb, st.t), jnp.asarray(-jnp.inf, st.t.dtype)))
    return st, outs


_advance_jit = jax.jit(_advance_impl, static_argnums=(0, 3))
#: the per-body clocks with LOOP_XLA_OPTIONS: without, a window at 1e5 spheres took 2.6 s instead of 1.25 s (the
#: global clock's passes are not gated and gained nothing)
_advance_body = jax.jit(_advance_impl, static_argnums=(0, 3), compiler_options=LOOP_XLA_OPTIONS)


# ------------------------------------------------------------------------------------------------ result
class BoxResult(AbstractResult):
    """Result of a periodic-box run (R95 §3): per output time ``t`` (T,) the state of every slot.

    Fields: ``t`` (T,) output times; ``status`` (:class:`jaxcoag.RESULTS`); ``outs`` dict of per-output
    arrays: ``alive`` (T, n0), ``M`` aggregate mass, ``nmem`` member spheres, ``Rmax`` (R7), ``V`` (T, n0, 3)
    COM velocity, ``ke_trans``/``ke_rot`` per aggregate, ``sph_agg``/``sph_r`` (T, n0) owner slot and
    distance of each sphere centre from its aggregate's COM, the counters ``n_aggregates``, ``n_c``,
    ``n_c1``, ``n_coag``, ``n_rest``, ``n_steps``, ``n_build``, ``flags``, ``status`` (T,);
    ``final_state`` (:class:`BoxState`, holds the collision log); ``model`` ("i" ... "v").
    Pass the result as ``initial`` to :func:`run` / :func:`jaxcoag.evolve` to continue the run.
    """

    t: jax.Array
    status: RESULTS
    outs: dict
    final_state: BoxState
    model: str = eqx.field(static=True)

    # ---- R95 Fig. 3-5 quantities
    @property
    def n_aggregates(self):
        """(T,) number N(t) of live aggregates, single spheres included (R95 §3)."""
        return self.outs["n_aggregates"]

    @property
    def n_collisions(self):
        """(T, 2) cumulative collisions N_C and first-time collisions N_C1 (a collision of a, b that repeats
        the previous collision of a or of b with the same partner is not first-time; R95 Fig. 3a)."""
        return jnp.stack([self.outs["n_c"], self.outs["n_c1"]], -1)

    @property
    def n_coagulations(self):
        """(T,) cumulative coagulations."""
        return self.outs["n_coag"]

    @property
    def n_restitutions(self):
        """(T,) cumulative restitutions (bounces)."""
        return self.outs["n_rest"]

    @property
    def m0(self):
        return self.final_state.par["m0"]

    @property
    def status_message(self):
        """Text of the final status: for ``capacity_exceeded`` which capacity overflowed and which
        :class:`RigidBox` argument to raise (:func:`capacity_message`), else the :class:`jaxcoag.RESULTS` text."""
        code = int(np.asarray(self.outs["status"])[-1])
        msg = capacity_message(np.asarray(self.outs["flags"])[-1]) if result_table()[code][0] == "capacity_exceeded" \
            else ""
        return msg or result_table()[code][1]

    @property
    def max_mass(self):
        """(T,) largest aggregate mass in units of m0 (R95 Fig. 3b)."""
        return jnp.max(self.outs["M"], axis=-1) / self.m0

    def mass_spectrum(self, kmax=None):
        """(T, kmax) number n_k of aggregates of k member spheres, k = 1..kmax (R95 Fig. 3c,d; eq. 31)."""
        n0 = self.outs["nmem"].shape[-1]
        kmax = n0 if kmax is None else int(kmax)
        k = jnp.where(self.outs["alive"], self.outs["nmem"], 0)
        return jax.vmap(lambda kk: jnp.bincount(kk, length=kmax + 1)[1:])(jnp.minimum(k, kmax + 1) *
                                                                          (k <= kmax))

    def aggregates(self, i=-1, *, include_radius=False, min_members=3):
        """Per-aggregate properties at output i (numpy, live slots only): dict of ``slot``, ``n_a`` (members),
        ``mass``, ``Rmax`` (R7), ``rho`` = M/((4/3)π R_max³), ``f_D`` and ``f_D_err`` (sorted-distance
        regression, NaN for N_a < ``min_members``; ``include_radius``: distances to the sphere centres r
        (False, the default, the spec's A9 reading) or to the edges r + R, the convention R95 leaves open:
        :func:`~jaxcoag.aggregates.rigid.diagnostics.fractal_dimension`), ``ke`` (translational + rotational)."""
        o = {k: np.asarray(v[i]) for k, v in self.outs.items() if np.ndim(v) >= 2}
        fd, err = diag.fractal_dimension(o["sph_r"], o["sph_agg"], np.asarray(self.final_state.sph_R),
                                         include_radius=include_radius, min_members=min_members)
        sl = np.nonzero(o["alive"])[0]
        Rm = o["Rmax"][sl]
        return dict(slot=sl, n_a=o["nmem"][sl], mass=o["M"][sl], Rmax=Rm,
                    rho=diag.density(o["M"][sl], Rm), f_D=np.asarray(fd)[sl], f_D_err=np.asarray(err)[sl],
                    ke=o["ke_trans"][sl] + o["ke_rot"][sl])

    def fractal_dimension(self, i=-1, *, include_radius=False, min_members=3):
        """(f_D per live aggregate, its standard error, weighted mean f_D, its standard error) at output i (R95 §3);
        ``include_radius``, ``min_members``: as in :meth:`aggregates`."""
        ag = self.aggregates(i, include_radius=include_radius, min_members=min_members)
        mean, err = diag.weighted_mean(ag["f_D"], ag["f_D_err"])
        return ag["f_D"], ag["f_D_err"], mean, err

    @property
    def velocity_dispersion(self):
        """(T, 3) number-weighted standard deviation of each COM velocity component over live aggregates."""
        return jax.vmap(diag.velocity_dispersion)(self.outs["V"], self.outs["alive"])

    @property
    def kinetic_energy(self):
        """(T, 2) total translational and rotational kinetic energy."""
        return jnp.stack([jnp.sum(self.outs["ke_trans"], -1), jnp.sum(self.outs["ke_rot"], -1)], -1)

    @property
    def collision_log(self):
        """The filled part of the collision log (numpy dict; see the module docstring)."""
        st = self.final_state
        n = int(st.n_log)
        return {k: np.asarray(v[:n]) for k, v in st.log.items()}

    # ---- common engine protocol (masses in the run's mass unit, volume L^3)
    def bin_edges(self, edges=None):
        if edges is not None:
            return np.asarray(edges, np.float64)
        n0 = self.outs["nmem"].shape[-1]
        return (np.arange(n0 + 1) + 0.5) * float(self.m0)

    def _per_bin(self, edges, mass_weighted):
        """Aggregates (or their mass) per box volume in the mass bins ``edges``, at every output."""
        e = jnp.asarray(self.bin_edges(edges))
        V = self.final_state.par["L"] ** 3
        M = jnp.where(self.outs["alive"], self.outs["M"], -1.0)
        idx = jnp.searchsorted(e, M, side="right") - 1
        ok = (idx >= 0) & (idx < e.shape[0] - 1)
        w = jnp.where(ok, M, 0.0) if mass_weighted else ok.astype(jnp.float64)
        return jax.vmap(lambda ii, ww: jnp.zeros(e.shape[0] - 1).at[ii].add(ww, mode="drop"))(
            jnp.where(ok, idx, e.shape[0]), w) / V

    def number_per_bin(self, edges=None):
        return self._per_bin(edges, False)

    def mass_per_bin(self, edges=None):
        return self._per_bin(edges, True)

    def moments(self, p):
        V = self.final_state.par["L"] ** 3
        M = self.outs["M"]
        al = self.outs["alive"]
        return jnp.sum(jnp.where(al, jnp.where(al, M, 1.0) ** p, 0.0), axis=-1) / V

    def to_xarray(self, *, attrs=None, kernel=None, edges=None):
        """Dataset with coordinate ``t`` (and ``t_yr``), ``m``/``m_edge`` (mass bins of k m0), ``k`` (members),
        ``slot`` and ``axis``: ``n_aggregates``, ``n_c``, ``n_c1``, ``n_coag``, ``n_rest``, ``max_mass`` [m0],
        ``mass_spectrum`` (t, k), ``sigma_v`` (t, axis), ``ke_trans``, ``ke_rot`` (t), per-slot ``M``, ``nmem``,
        ``Rmax``, ``alive`` (t, slot), plus the common ``mass_per_bin``, ``number_per_bin``, ``status``.
        Units are the run's (R95: arbitrary length and time units)."""
        from ..._dataset import common_dataset

        e = self.bin_edges(edges)
        mpb = np.asarray(self.mass_per_bin(edges))
        total = np.asarray(self.moments(1))
        n0 = self.outs["nmem"].shape[-1]
        ke = np.asarray(self.kinetic_energy)
        extra = {
            "n_aggregates": (("t",), np.asarray(self.n_aggregates), {"units": "1", "long_name": "live aggregates N"}),
            "n_c": (("t",), np.asarray(self.outs["n_c"]), {"units": "1", "long_name": "cumulative collisions N_C"}),
            "n_c1": (("t",), np.asarray(self.outs["n_c1"]), {"units": "1", "long_name": "first-time collisions"}),
            "n_coag": (("t",), np.asarray(self.outs["n_coag"]), {"units": "1", "long_name": "coagulations"}),
            "n_rest": (("t",), np.asarray(self.outs["n_rest"]), {"units": "1", "long_name": "restitutions"}),
            "max_mass": (("t",), np.asarray(self.max_mass), {"units": "m0", "long_name": "largest mass"}),
            "mass_spectrum": (("t", "k"), np.asarray(self.mass_spectrum()), {"units": "1",
                                                                             "long_name": "aggregates of k spheres"}),
            "sigma_v": (("t", "axis"), np.asarray(self.velocity_dispersion), {"long_name": "velocity dispersion"}),
            "ke_trans": (("t",), ke[:, 0], {"long_name": "translational kinetic energy"}),
            "ke_rot": (("t",), ke[:, 1], {"long_name": "rotational kinetic energy"}),
            "M": (("t", "slot"), np.asarray(self.outs["M"]), {"long_name": "aggregate mass (0: free slot)"}),
            "nmem": (("t", "slot"), np.asarray(self.outs["nmem"]), {"long_name": "member spheres"}),
            "Rmax": (("t", "slot"), np.asarray(self.outs["Rmax"]), {"long_name": "R_max (R95 eq. 7)"}),
            "alive": (("t", "slot"), np.asarray(self.outs["alive"]), {"long_name": "slot in use"}),
        }
        ds = common_dataset(engine="rigid", title=f"jaxcoag rigid box, Richardson (1995) model ({self.model})",
                            t=np.asarray(self.t), edges=e, mass_per_bin=mpb,
                            number_per_bin=np.asarray(self.number_per_bin(edges)),
                            gel_mass=np.zeros(len(self.t)), mass_drift=total / total[0] - 1.0,
                            code=int(np.asarray(result_code(self.status))), extra=extra, attrs=attrs,
                            extra_coords={"k": ("k", np.arange(1, n0 + 1)), "axis": ("axis", ["x", "y", "z"])})
        ds.attrs["model"] = self.model
        ds["status"].attrs["status_message"] = self.status_message
        return ds


def run(box, t_out, *, engine=None, checkpoint=None, every=1, resume=True, progress=False, max_segments=None,
        throw=True):
    """Run a periodic box (:func:`box_model`) to the output times ``t_out`` (R95 §3).

    Arguments:
        box: :class:`Box`, or a :class:`BoxResult` to continue.
        t_out: 1-D increasing output times (>= 0, or >= the continued result's last time).
        engine: :class:`RigidBox` (default ``RigidBox()``).
        checkpoint, every, resume, progress, max_segments, throw: as for :func:`jaxcoag.evolve`.

    Returns:
        :class:`BoxResult` (a ``capacity_exceeded`` status also warns, with the capacity to raise:
        :attr:`BoxResult.status_message`).

    References: Richardson (1995) §3.
    """
    engine = RigidBox() if engine is None else engine
    if not isinstance(engine, RigidBox):
        raise JaxcoagInputError(f"engine must be a rigid.RigidBox(...); got {type(engine).__name__}.")
    res = evolve(None, engine, box, t_out, checkpoint=checkpoint, every=every, resume=resume, progress=progress,
                 max_segments=max_segments, throw=throw)
    flags = np.asarray(res.outs["flags"])
    if flags.ndim == 1 and flags.size and int(flags[-1]) & 3:
        warnings.warn(capacity_message(flags[-1]), RuntimeWarning, stacklevel=2)
    return res
