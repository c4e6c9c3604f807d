"""Time stepping of the radial disk: DustPy's monolithic implicit Euler step (parity mode) and a
Strang-split step (fast mode), the step-size rule and the loops to the output times.

Parity mode (:class:`Parity`) reproduces DustPy's discrete system step for step (Stammler &
Birnstiel 2022, §2.5; DustPy 1.0.9 ``std.dust._f_impl_1_direct``, ``std.gas._f_impl_1_direct``):

1. every coefficient (velocities, kernel, fragmentation probability, the coagulation Picard matrix
   J~(Sigma) with S_coag = J~ Sigma, the transport operator) is evaluated at the state at the start of
   the step;
2. the dust takes one implicit Euler step of the whole system (I - dt J) Sigma^(n+1) = Sigma^n,
   J = J_coag + J_hyd, with DustPy's boundary rows (inner "constant gradient", outer fixed value),
   solved exactly by block elimination (:func:`~jaxcoag.disk.blocksolve.block_tridiagonal_solve`);
3. the gas takes its implicit Euler step with the same dt;
4. boundaries and floors are re-imposed;
5. the next dt is 0.1 min(Sigma/|S_tot|) over interior cells with S_tot < 0 and Sigma above the floor,
   dust and gas together, clipped to land on the next output time.

Fast mode (:class:`Split`) replaces step 2 by Strang splitting: half a transport step (one
tridiagonal implicit solve per mass bin), a full coagulation step (one dense implicit solve per cell,
all cells batched), half a transport step. A splitting-error estimate is kept (``split_error``: the
largest disk-integrated, mass-weighted relative difference of one step, sum |Lie - Strang| A / sum
Strang A over the interior cells and mass bins (A the annulus areas), between first-order Lie splitting and Strang splitting of the same step; Lie's leading error term is
the commutator of the two operators, which Strang cancels, so the difference measures how far the
split step is from the unsplit one). It is a local, per-step measure: over a run, n_steps x split_error bounded the
measured mass-weighted difference sum |Sigma_split - Sigma_ref| A / sum Sigma_ref A from the monolithic step in the
three cases measured, loosely (ratio of measured to bound 0.3: Nr = 30, m_max = 1e2 g, alpha = 1.4e-3,
v_frag = 2 m/s, 1e3 and 1e4 yr against :class:`Parity`; 6.5e-3: the same grid at DustPy's defaults, 1e4 yr, against
DustPy; 5e-4: DustPy's default model, 1e5 yr, against DustPy). Compare with :class:`Parity` on your model where it
matters.

References: Stammler & Birnstiel (2022), ApJ 935, 35, §2.5 and §3; Strang (1968), SIAM J. Numer.
Anal. 5, 506.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._status import RESULTS, result_code
from .._validate import JaxcoagInputError, is_traced
from .blocksolve import block_tridiagonal_solve
from .transport import transport_implicit_step

__all__ = ["Parity", "Split", "DiskState", "step", "advance", "replay"]


class Parity(eqx.Module):
    """DustPy's discrete system: one monolithic implicit Euler step of transport + coagulation.

    Fields:
        cfl: the step-size factor of DustPy's rule dt = cfl min(Sigma/|S|) (DustPy: 0.1).

    References: Stammler & Birnstiel (2022) §2.5.
    """

    cfl: float | jax.Array = 0.1


class Split(eqx.Module):
    """Strang splitting: transport (tridiagonal per mass bin) - coagulation (dense per cell) - transport.

    Fields:
        cfl: step-size factor of the same rule as :class:`Parity` (default 0.1).

    Cheaper than :class:`Parity` (batched per-cell solves instead of a sequential block elimination);
    the splitting error scales with dt and persists in steady state.

    References: Strang (1968); Stammler & Birnstiel (2022) §2.5.
    """

    cfl: float | jax.Array = 0.1


class DiskState(eqx.Module):
    """State of a radial disk run (a pytree of arrays; what a checkpoint stores).

    Fields:
        t: time [s].
        sigma_gas: (nr,) gas surface density [g cm^-2].
        sigma_dust: (nr, nm) dust surface density per mass bin [g cm^-2].
        m_acc_gas: gas mass that left through the inner boundary since t = 0 [g] (negative: gained).
        m_out_gas: gas mass that left through the outer boundary since t = 0 [g].
        n_steps: steps taken since t = 0 (int).
        v_rad: (nr, nm) dust radial velocity [cm s^-1] used by the next step. As DustPy 1.0.9 it is set at the
            end of a step from the Stokes numbers and drift speed of the state before the step and the gas
            velocity after it (DustPy refreshes ``dust.v.rad`` only in its finaliser), a lag of one step.
        dt_next: the step the rule proposes for the next step [s] (DustPy's ``t.stepsize``: cfl min(Sigma/|S|)
            with the sources S booked by the finaliser of the previous step).
        split_error: the largest per-step splitting-error estimate so far (:class:`Split`: disk-integrated mass-weighted
            Lie against Strang difference of one step; 0 in parity mode).
        status: int code of :data:`jaxcoag.RESULT_NAMES`.
        dt_log: (K,) the sizes [s] of the first K steps since t = 0, NaN where no step was taken yet (K =
            ``record_steps`` of :class:`~jaxcoag.disk.engine.Disk`, 0 by default: nothing is recorded). Replaying
            these steps with :func:`replay` recomputes the run on the same step sequence (e.g. for finite
            differences with the steps held fixed, as forward- and reverse-mode derivatives hold them).
    """

    t: jax.Array
    sigma_gas: jax.Array
    sigma_dust: jax.Array
    m_acc_gas: jax.Array
    m_out_gas: jax.Array
    n_steps: jax.Array
    v_rad: jax.Array
    dt_next: jax.Array
    split_error: jax.Array
    status: jax.Array
    dt_log: jax.Array


def _dust_implicit(model, phys, sigma, dt):
    """One monolithic implicit Euler step of dust transport + coagulation (DustPy's boundary rows)."""
    nr, nm = sigma.shape
    jc = phys["J_coag"]  # (nr, nm, nm), zero in the first and last cells
    a, b, c = phys["hyd_A"], phys["hyd_B"], phys["hyd_C"]  # (nr, nm)
    eye = jnp.eye(nm, dtype=sigma.dtype)
    diag = eye[None] - dt * (jc + jax.vmap(jnp.diag)(b))
    lower = -dt * a
    upper = -dt * c
    rhs = sigma
    # inner boundary, "constant gradient": Sigma_0 = -K1 Sigma_1 - K2 Sigma_2 (DustPy std.dust.jacobian)
    k1, k2 = phys["bc_in_K1"], phys["bc_in_K2"]
    # substitute Sigma_0 into row 1: lower_1 Sigma_0 = -lower_1 K1 Sigma_1 - lower_1 K2 Sigma_2
    diag = diag.at[1].add(jnp.diag(-lower[1] * k1))
    upper = upper.at[1].add(-lower[1] * k2)
    # outer boundary, fixed value: Sigma_{nr-1} = value
    val = phys["bc_out_value"]
    rhs = rhs.at[nr - 2].add(-upper[nr - 2] * val)
    x = block_tridiagonal_solve(lower[1:-1], diag[1:-1], upper[1:-1], rhs[1:-1])
    s0 = -k1 * x[0] - k2 * x[1]
    return jnp.concatenate([s0[None], x, jnp.broadcast_to(val, (1, nm))], axis=0)


def _tridiag_transport(model, phys, sigma, dt):
    """Implicit Euler transport only (one tridiagonal solve per mass bin, the same boundary rows)."""
    return transport_implicit_step(sigma, phys["hyd_A"], phys["hyd_B"], phys["hyd_C"], dt, model.r, model.ri,
                                   phys["floor_dust"], finalize=False)


def _coag_implicit(phys, sigma, dt):
    """Implicit Euler coagulation only: (I - dt J~_k) Sigma_k^new = Sigma_k in every cell (batched dense solves);
    ``sigma`` (nr, nm) or (nr, nm, k) for k right-hand sides."""
    nm = sigma.shape[1]
    mat = jnp.eye(nm, dtype=sigma.dtype)[None] - dt * phys["J_coag"]
    if sigma.ndim == 2:
        return jnp.linalg.solve(mat, sigma[..., None])[..., 0]
    return jnp.linalg.solve(mat, sigma)


def step(model, mode, state, dt, phys=None):
    """One step of length dt [s] from ``state`` in DustPy's order: coefficients at the start of the step, the
    dust step, the gas step, boundaries and floors, then the finaliser's bookkeeping (the lagged radial dust
    velocity and the sources that size the next step). Returns the new :class:`DiskState`."""
    if phys is None:
        phys = model.physics(state.sigma_gas, state.sigma_dust, state.v_rad)
    sd = state.sigma_dust
    err = state.split_error
    if model.coagulation or model.dust_transport:
        if isinstance(mode, Split) and model.coagulation and model.dust_transport:
            half = _tridiag_transport(model, phys, sd, 0.5 * dt)
            full = _tridiag_transport(model, phys, sd, dt)
            # one batched solve for both coagulation steps (Strang's and the Lie estimate's: the same matrix);
            # two independent batched LAPACK solves in one loop body deadlocked XLA's CPU runtime (jax 0.10.2)
            both = _coag_implicit(phys, jnp.stack([half, full], axis=-1), dt)
            sd = _tridiag_transport(model, phys, both[..., 0], 0.5 * dt)
            # error estimate: Lie splitting (transport dt, then coagulation dt) against Strang
            lie = both[..., 1]
            # disk-integrated, mass-weighted: sum |lie - strang| A / sum strang A over interior cells and bins
            # (nearly empty bins and the floor-filled outer cells do not dominate)
            w = model.area[1:-1, None]
            rel = jnp.sum(jnp.abs(lie - sd)[1:-1] * w) / jnp.sum(sd[1:-1] * w)
            err = jnp.maximum(err, jax.lax.stop_gradient(rel))
        elif isinstance(mode, Split) and model.dust_transport:
            sd = _tridiag_transport(model, phys, sd, dt)
        elif isinstance(mode, Split):
            sd = _coag_implicit(phys, sd, dt)
        else:
            sd = _dust_implicit(model, phys, sd, dt)
    sd = model.dust_finalize(sd)
    sg, m_in, m_out = state.sigma_gas, jnp.zeros(()), jnp.zeros(())
    if model.gas_evolution:
        sg, m_in, m_out = model.gas_step(state.sigma_gas, dt)
    v_rad, dt_next = model.finalize_sources(phys, sg, sd)
    dt_log = state.dt_log
    if dt_log.shape[-1]:  # record the step's size (static: nothing when no record is kept)
        dt_log = dt_log.at[state.n_steps].set(jax.lax.stop_gradient(dt), mode="drop")
    return DiskState(t=state.t + dt, sigma_gas=sg, sigma_dust=sd, m_acc_gas=state.m_acc_gas + m_in,
                     m_out_gas=state.m_out_gas + m_out, n_steps=state.n_steps + 1, v_rad=v_rad,
                     dt_next=jax.lax.stop_gradient(mode.cfl) * dt_next, split_error=err, status=state.status,
                     dt_log=dt_log)


def _fail_code(state):
    ok = jnp.all(jnp.isfinite(state.sigma_dust)) & jnp.all(jnp.isfinite(state.sigma_gas))
    return jnp.where(ok, state.status, result_code(RESULTS.nonfinite))


def _one(model, mode, state, target, dt_max):
    """One guarded step toward ``target``: the rule's dt clipped to the target and to dt_max."""
    phys = model.physics(state.sigma_gas, state.sigma_dust, state.v_rad)
    dt = jnp.minimum(jnp.minimum(state.dt_next, target - state.t), dt_max)
    new = step(model, mode, state, dt, phys)
    # land exactly on the target (no round-off drift of t)
    new = eqx.tree_at(lambda s: s.t, new, jnp.where(target - new.t <= 1e-12 * target, target, new.t))
    return eqx.tree_at(lambda s: s.status, new, _fail_code(new))


def advance(model, mode, state, t_targets, *, max_steps, loop="while", dt_max=jnp.inf):
    """Advance ``state`` through the output times ``t_targets`` [s].

    Arguments:
        max_steps: step budget per output interval (static int); status ``max_steps_reached`` when spent.
        loop: ``"while"`` (``lax.while_loop``: forward-mode derivatives, vmap) or ``"scan"`` (a fixed-length
            ``lax.scan`` of ``max_steps`` guarded steps per interval, checkpointed in two levels (about
            2 sqrt(max_steps) states held): reverse-mode derivatives too, each
            idle step costs a ``lax.cond`` branch).
        dt_max: an upper bound on the step [s] (default none).

    Returns:
        (final state, per-output dict of ``sigma_gas`` (T, nr), ``sigma_dust`` (T, nr, nm), ``n_steps``,
        ``m_acc_gas``, ``m_out_gas``, ``status``).
    """
    ok = result_code(RESULTS.successful)
    budget = result_code(RESULTS.max_steps_reached)

    def running(s, target):
        return (s.t < target) & (s.status == ok)

    def to_target(state, target):
        n0 = state.n_steps
        if loop == "while":
            def cond(s):
                return running(s, target) & (s.n_steps - n0 < max_steps)

            s = jax.lax.while_loop(cond, lambda s: _one(model, mode, s, target, dt_max), state)
        else:
            # two-level checkpointing: reverse mode stores the state at the start of each of the n_outer chunks,
            # then recomputes one chunk at a time storing its chunk states (+1 forward pass; memory
            # ~ 2 sqrt(max_steps) states instead of max_steps: the default model's gradient over 4000 steps
            # needs 3.6 GB of temporaries with one level)
            chunk = max(1, math.isqrt(max_steps))
            n_outer = -(-max_steps // chunk)

            def body(s, _):
                go = running(s, target) & (s.n_steps - n0 < max_steps)
                return jax.lax.cond(go, lambda s: _one(model, mode, s, target, dt_max), lambda s: s, s), None

            def outer(s, _):
                return jax.lax.scan(jax.checkpoint(body), s, None, length=chunk)[0], None

            s, _ = jax.lax.scan(jax.checkpoint(outer), state, None, length=n_outer)
        s = eqx.tree_at(lambda q: q.status, s, jnp.where(running(s, target), budget, s.status))
        out = dict(sigma_gas=s.sigma_gas, sigma_dust=s.sigma_dust, n_steps=s.n_steps, m_acc_gas=s.m_acc_gas,
                   m_out_gas=s.m_out_gas, split_error=s.split_error, status=s.status)
        return s, out

    return jax.lax.scan(to_target, state, jnp.asarray(t_targets, jnp.float64))


def replay(model, mode, state, dts, *, save_at=None):
    """Take the given steps from ``state``: ``step`` scanned over ``dts`` [s], no step-size rule and no landing.

    Uses: finite differences of a run with its step sequence held fixed (the sequence of an adaptive run is
    ``DiskState.dt_log``, recorded with ``Disk(record_steps=K)`` / ``solve(..., record_steps=K)``; the step rule
    is not differentiated, so forward- and reverse-mode derivatives are those of this fixed-step map), and driving
    the parity step with another code's steps (DustPy's, in ``benchmarks/peers/dustpy_disk.py --modes replay``).

    Arguments:
        dts: (n,) step sizes [s], all > 0 (checked when concrete).
        save_at: optional (k,) step counts since ``state`` (ints in 1..n, increasing; concrete) at which to keep
            ``sigma_gas`` and ``sigma_dust``.

    Returns:
        (final :class:`DiskState`, dict of ``sigma_gas`` (k, nr) and ``sigma_dust`` (k, nr, nm) at ``save_at``;
        empty dict when ``save_at`` is None).
    """
    if not is_traced(dts):
        d = np.asarray(dts)
        if d.ndim != 1 or not np.all(np.isfinite(d) & (d > 0)):
            raise JaxcoagInputError("replay(dts=...) takes a 1-D sequence of finite step sizes > 0 [s] (drop the "
                                    "NaN entries of an unused DiskState.dt_log: dt_log[:n_steps]).")
    if save_at is None:
        return jax.lax.scan(lambda s, dt: (step(model, mode, s, dt), None), state, dts)[0], {}
    at = np.asarray(save_at, np.int64)
    n = int(jnp.shape(dts)[0])
    if at.ndim != 1 or at.size == 0 or np.any(np.diff(at) <= 0) or at[0] < 1 or at[-1] > n:
        raise JaxcoagInputError(f"replay(save_at=...) must be increasing step counts in 1..{n}; got {at.tolist()}.")
    keep = np.zeros(n, bool)
    keep[at - 1] = True
    slot = np.maximum(np.cumsum(keep) - 1, 0)  # the output row of step i (used where keep)
    sg = jnp.zeros((at.size,) + state.sigma_gas.shape, state.sigma_gas.dtype)
    sd = jnp.zeros((at.size,) + state.sigma_dust.shape, state.sigma_dust.dtype)

    def body(c, x):
        s, sg, sd = c
        dt, k, hit = x
        s = step(model, mode, s, dt)
        sg = sg.at[k].set(jnp.where(hit, s.sigma_gas, sg[k]))
        sd = sd.at[k].set(jnp.where(hit, s.sigma_dust, sd[k]))
        return (s, sg, sd), None

    (s, sg, sd), _ = jax.lax.scan(body, (state, sg, sd), (dts, jnp.asarray(slot), jnp.asarray(keep)))
    return s, {"sigma_gas": sg, "sigma_dust": sd}
