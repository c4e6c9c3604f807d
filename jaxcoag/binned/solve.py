"""Internal solve of the binned engine (``jaxcoag.Binned``): the diffrax integration and the
fragmentation-limited steady state.

The compiled solve builds the scheme's data and evaluates the kernel *inside* the (jit-compiled)
solve from the kernel's leaves - so ``jax.grad``/``jax.jvp``/``jax.vmap`` over kernel parameters
(b, alpha, rho_g, T, v_frag ...) work - and integrates with diffrax. Failures are values: the status
is a :class:`jaxcoag.RESULTS` item; ``jaxcoag.evolve(..., throw=True)`` raises with its message.

Time-integration defaults (docs/design_notes.md, traps measured):
* pure coagulation: ``diffrax.Tsit5()`` (not stiff; implicit solvers were 50-100x slower);
* with fragmentation: :class:`~jaxcoag.binned.solvers.Rodas4` (Hairer & Wanner's Rosenbrock method RODAS,
  order 4, L-stable: one Jacobian + one LU per step, linear stages; on the default ``jaxcoag run`` box
  1.8x faster than Kvaerno5 with a Jacobian per stage and 20x more accurate at the same rtol);
  ``default_implicit_solver`` (Kvaerno5 + chord, a Jacobian per stage; diffrax's own chord with one
  Jacobian per step rejected most steps near equilibrium) is the previous default and
  ``LinearlyImplicitEuler`` (jaxcoag.binned.solvers) the DustPy-parity alternative (one Jacobian + LU per step);
* implicit solvers (Rodas4, Kvaerno5's root finder, ``LinearlyImplicitEuler``) and :func:`steady_state` get
  ``scheme.rhs_structured``: for the two-bin scheme a ``custom_jvp`` whose rule is the structured
  Jacobian (``TwoBinScheme.jacobian``, formed once per Jacobian; ~80x cheaper than N + 1 JVPs
  at 135 bins with fragmentation, benchmarks/binned_jacobian.py); explicit solvers keep ``rhs``;
* error norm: the default ``PIDController`` gets a per-entry absolute tolerance
  ``atol * M_tot / w`` (w = ``scheme.mass_scale``), i.e. tolerances relative to the total mass
  (a single absolute atol over 30 decades of number density fails);
* an explicit ``dt0`` is always passed to diffrax (``dt0=None`` gave NaN gradients): when not
  given it is 1e-3 of the initial collision time M_tot / max|d rho/dt| (capped by the span).

References: Kidger (2021) diffrax; Stammler & Birnstiel (2022, DustPy) §3; docs/design_notes.md (house style, traps).
"""

from __future__ import annotations

import numpy as np
import equinox as eqx
import jax
import jax.numpy as jnp
import diffrax
import optimistix as optx

from .._status import RESULTS
from .._validate import JaxcoagInputError, JaxcoagTypeError, check, is_traced
from ..kernels import AbstractKernel
from .grid import MassGrid
from .scheme import AbstractScheme, check_memory
from .twobin import TwoBinScheme

__all__ = ["steady_state", "SteadyState", "CarriedStepController"]


class Kvaerno5Stagewise(diffrax.Kvaerno5):
    """diffrax's Kvaerno5 (ESDIRK 5(4)) with a fresh Jacobian at every implicit stage
    (``diffrax.CalculateJacobian.every_stage``) for a chord root finder: one Jacobian and one LU per
    stage, reused over that stage's iterations.

    The binned engine's default implicit solver (with ``optimistix.Chord``) before :class:`Rodas4`;
    ``[solver] method = "kvaerno5"`` / :func:`default_implicit_solver`. On the default
    ``jaxcoag run`` box (135 bins, fragmentation) it takes the same 196 steps (3 rejected) as Kvaerno5
    with Newton (a Jacobian per iteration), 1.32x faster (1.45 s vs 1.92 s, idle 2-core CPU), and the
    solutions differ by 2.5e-9 of the peak (rtol 1e-6). diffrax's own choice for ESDIRK methods, one
    Jacobian per step reused by all stages, took as many steps but was slower than Newton (2.69 s vs
    2.57 s under load), and diffrax's VeryChord with that Jacobian once diverged on the quadratic
    coagulation term of a 61-bin fragmentation equilibrium (> 3000 steps, 56 % rejected)."""

    calculate_jacobian = diffrax.CalculateJacobian.every_stage


def default_implicit_solver(rtol, root_atol):
    """The binned engine's ESDIRK implicit solver (its default with fragmentation until 2026-11-26, now
    ``[solver] method = "kvaerno5"``): :class:`Kvaerno5Stagewise` with ``optimistix.Chord`` (``rtol``,
    absolute tolerance ``root_atol`` [g cm^-3])."""
    return Kvaerno5Stagewise(root_finder=optx.Chord(rtol=rtol, atol=root_atol))


def _is_implicit(solver, fragmentation):
    """Whether ``solver`` (``Binned.solver``; None = automatic) builds a dense Jacobian (memory estimate)."""
    from .solvers import LinearlyImplicitEuler, Rodas4

    if solver is None:
        return fragmentation is not None  # Rodas4 with fragmentation
    return isinstance(solver, (diffrax.AbstractImplicitSolver, LinearlyImplicitEuler, Rodas4))


def _validate_model(model, grid, n0, fragmentation):
    """Refuse a bad kernel / grid / initial number density / outcome before any work."""
    if not isinstance(model, AbstractKernel):
        raise JaxcoagInputError(f"kernel must be a jaxcoag kernel (AbstractKernel subclass), got {type(model).__name__}.")
    if not isinstance(grid, MassGrid):
        raise JaxcoagInputError("grid must be a jaxcoag.MassGrid, e.g. MassGrid.log(1e-12, 1e4, 10).")
    if fragmentation is not None and not (hasattr(fragmentation, "twobin_data") and hasattr(fragmentation, "probability")):
        raise JaxcoagInputError(f"outcome {type(fragmentation).__name__} has no binned form; use an outcome from "
                                "jaxcoag.outcomes (Sticking, ShatterAbove, Shattering, RecipeOutcome).")
    if not callable(n0):
        n0 = check(n0, "initial", nonnegative=True, hint="number density per bin in cm^-3 (no NaN, no negatives)")
        if n0.shape != (grid.nbins,):
            raise JaxcoagInputError(f"initial number density per bin must have shape (nbins,) = ({grid.nbins},); got "
                                    f"{n0.shape}. Pass jaxcoag.Monodisperse(m0, rho_d) or a callable f(m) "
                                    "[cm^-3 g^-1] to project a distribution instead.")
    if fragmentation is not None:
        if bool(getattr(fragmentation, "needs_velocity", False)) and \
                type(model).relative_velocity2 is AbstractKernel.relative_velocity2:
            raise JaxcoagTypeError(
                f"{type(fragmentation).__name__} needs collision velocities, but the {type(model).__name__} kernel has no "
                "relative velocity (analytic kernels). Use a physical kernel from a Scene "
                "(jaxcoag.scenes.nebula_ch4().kernel(gas, rho_s=...)), or a velocity-free outcome "
                "such as ShatterAbove(m_frag, m_mono).")
    return n0


def _check_controls(rtol, atol, max_steps, where="Binned"):
    """Tolerances (> 0, finite; concrete Python numbers or arrays) and max_steps (positive int)."""
    rtol = check(rtol, "rtol", positive=True, hint=f"{where} relative tolerance, e.g. 1e-6")
    atol = check(atol, "atol", positive=True, hint=f"{where} absolute tolerance relative to the total mass, "
                                                   "e.g. 1e-10")
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or max_steps < 1:
        raise JaxcoagInputError(f"max_steps must be a positive int (a static step budget, e.g. 100_000); "
                                f"got {max_steps!r}.")
    return rtol, atol


def _default_dt0(scheme, grid, data, y0, t0, t1):
    f = scheme.rhs(t0, y0, data)
    w = scheme.mass_scale(y0, grid)
    M = jnp.sum(jnp.abs(w * y0))
    rate = jnp.max(jnp.abs(w * f))
    span = jnp.where(t1 > t0, t1 - t0, 1.0)  # t_out == [t0]: nothing to integrate, any positive step
    tc = jnp.where(rate > 0, M / jnp.where(rate > 0, rate, 1.0), span)
    return jax.lax.stop_gradient(jnp.minimum(1e-3 * tc, 1e-2 * span))


class CarriedStepController(diffrax.AbstractAdaptiveStepSizeController):
    """An adaptive step-size controller that starts from a given step and reports the step to
    continue with, so that consecutive solves (checkpoint segments, continued results) go on
    with the step size reached instead of restarting from a tiny ``dt0``.

    It wraps another adaptive controller (``inner``, e.g. ``diffrax.PIDController``): every
    decision is the inner controller's; ``init`` starts from ``dt_init`` (the ``dt0`` argument of
    ``diffeqsolve`` is ignored and should be None), and the controller state (read with
    ``diffrax.SaveAt(controller_state=True)``) is ``(inner state, next step, end time)``. The
    "next step" is the inner controller's proposal after the last step, except when the last
    accepted step was shortened to land on the end time: then it is the proposal before that
    cut, i.e. the step an uninterrupted solve would have tried there.

    Fields: inner (an ``AbstractAdaptiveStepSizeController``); dt_init (first step, in the
    solve's time units; gradients stopped).

    References: Kidger (2021) diffrax (step-size controller interface: ``init``,
    ``adapt_step_size``, ``SaveAt(controller_state=True)``); Hairer, Norsett & Wanner (1993),
    Solving ODEs I, II.4 (step size selection).
    """

    inner: diffrax.AbstractAdaptiveStepSizeController
    dt_init: jax.Array

    @property
    def rtol(self):
        return self.inner.rtol

    @property
    def atol(self):
        return self.inner.atol

    @property
    def norm(self):
        return self.inner.norm

    def wrap(self, direction):
        return CarriedStepController(self.inner.wrap(direction), self.dt_init)

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        dt = jax.lax.stop_gradient(jnp.asarray(self.dt_init))
        tnext, inner_state = self.inner.init(terms, t0, t1, y0, dt, args, func, error_order)
        t_end = jnp.asarray(t1, jnp.result_type(dt))
        return tnext, (inner_state, jnp.asarray(tnext - t0, jnp.result_type(dt)), t_end)

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order, controller_state):
        inner_state, dt_prev, t_end = controller_state
        keep, next_t0, next_t1, made_jump, inner_state, result = self.inner.adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, inner_state)
        proposal = jax.lax.stop_gradient(next_t1 - next_t0)
        # an accepted step that was cut short to end exactly at t_end: keep the proposal before the cut
        cut = keep & (t1 >= t_end) & (t1 - t0 < dt_prev)
        dt_next = jnp.where(cut, dt_prev, proposal).astype(dt_prev.dtype)
        return keep, next_t0, next_t1, made_jump, (inner_state, dt_next, t_end), result


@eqx.filter_jit
def _solve_impl(scheme, grid, model, fragmentation, y0, t0, ts, solver, controller, rtol, atol, dt0,
                adjoint, max_steps, progress_meter, M0, dt_carry=None):
    """Integrate from (t0, y0) and save at ts (t0 <= ts[0]); M0 [g cm^-3] is the total mass the
    tolerances and the negative-density test refer to. ``dt_carry`` [s]: the step to start from
    (a positive number: the previous segment's ``dt_next``; 0, nan or None: ``dt0``, or the
    default 1e-3 of the collision time). Returns (ys, RESULTS item, stats, dt_next [s]: the step
    to continue with).

    With an adaptive controller (the default ``PIDController``, or one given) the solve runs under
    :class:`CarriedStepController` with ``diffeqsolve(dt0=None)``, and a segment with one output time
    saves with ``SaveAt(t1=True)``: then none of ``diffeqsolve``'s runtime input checks (dt0 sign,
    save times ordered and inside [t0, t1]; equinox ``error_if``) is compiled in. Those checks are
    host callbacks, and a program with host callbacks is never written to JAX's persistent
    compilation cache; jaxcoag checks the same inputs before the solve (``evolve``)."""
    from .solvers import LinearlyImplicitEuler, Rodas4

    data = scheme.precompute(model, grid, fragmentation)
    t1 = ts[-1]
    w = scheme.mass_scale(y0, grid)
    # solvers that form Jacobians (jax.jacfwd / linearize + vmap) get the right-hand side whose
    # JVP rule is the scheme's structured Jacobian (one dense J per Jacobian instead of N + 1
    # JVPs); explicit solvers keep the plain rhs (their JVPs/VJPs need no Jacobian)
    implicit = isinstance(solver, (diffrax.AbstractImplicitSolver, LinearlyImplicitEuler, Rodas4))
    if isinstance(solver, Rodas4) and solver.invariant is None:
        # the total mass is the scheme's linear invariant: Rodas4 projects its stage increments onto it
        c = jax.grad(lambda y: scheme.total_mass(y, grid))(jax.lax.stop_gradient(y0))
        solver = Rodas4(invariant=jax.lax.stop_gradient(c))
    vf = scheme.rhs_structured if implicit else scheme.rhs
    term = diffrax.ODETerm(lambda t, y, args: vf(t, y, args))
    if controller is None:
        atol_vec = jax.lax.stop_gradient(atol * M0 / w)
        controller = diffrax.PIDController(rtol=rtol, atol=atol_vec)
    if dt0 is None:
        dt0 = _default_dt0(scheme, grid, data, y0, t0, t1)
    adaptive = isinstance(controller, diffrax.AbstractAdaptiveStepSizeController)
    if adaptive:
        if dt_carry is not None:
            dt_carry = jax.lax.stop_gradient(jnp.asarray(dt_carry, jnp.float64))
            dt0 = jnp.where(jnp.isfinite(dt_carry) & (dt_carry > 0), dt_carry, dt0)
        one = ts.shape[0] == 1  # ts == [t1]
        saveat = diffrax.SaveAt(t1=True, controller_state=True) if one else \
            diffrax.SaveAt(ts=ts, controller_state=True)
        sol = diffrax.diffeqsolve(term, solver, t0, t1, None, y0, args=data, saveat=saveat,
                                  stepsize_controller=CarriedStepController(controller, dt0), adjoint=adjoint,
                                  max_steps=max_steps, throw=False, progress_meter=progress_meter)
        dt_next = sol.controller_state[1]
    else:
        sol = diffrax.diffeqsolve(term, solver, t0, t1, dt0, y0, args=data,
                                  saveat=diffrax.SaveAt(ts=ts), stepsize_controller=controller,
                                  adjoint=adjoint, max_steps=max_steps, throw=False,
                                  progress_meter=progress_meter)
        dt_next = dt0
    ys = sol.ys
    rho = jax.vmap(lambda y: scheme.mass_per_bin(y, grid))(ys)
    finite = jnp.all(jnp.isfinite(ys))
    # negative mass below the integration tolerance is solver noise, not a failure
    negative = jnp.min(jnp.where(jnp.isfinite(rho), rho, 0.0)) < -10.0 * jnp.maximum(atol, rtol) * M0
    dres = sol.result
    res = RESULTS.where(dres == diffrax.RESULTS.successful, RESULTS.successful, RESULTS.solver_failed)
    res = RESULTS.where(dres == diffrax.RESULTS.max_steps_reached, RESULTS.max_steps_reached, res)
    res = RESULTS.where(res == RESULTS.successful,
                        RESULTS.where(finite, RESULTS.where(negative, RESULTS.negative_density, RESULTS.successful),
                                      RESULTS.nonfinite), res)
    stats = {"steps": sol.stats["num_accepted_steps"], "rejected": sol.stats["num_rejected_steps"],
             "num_steps": sol.stats["num_steps"]}
    return ys, res, stats, jax.lax.stop_gradient(jnp.asarray(dt_next, jnp.float64))


class SteadyState(eqx.Module):
    """Result of :func:`steady_state`: mass per bin [g cm^-3] (nbins,), number per bin [cm^-3],
    the residual max |F| of the scaled root problem, the status (a :class:`jaxcoag.RESULTS` item:
    ``successful`` or ``solver_failed`` when Newton did not converge) and the raw scheme state."""

    y: jax.Array
    mass_per_bin: jax.Array
    number_per_bin: jax.Array
    residual: jax.Array
    status: RESULTS
    grid: MassGrid = eqx.field(static=True)


def steady_state(kernel, engine, initial, *, outcome, t_relax=None, y_guess=None, newton_rtol=1e-10,
                 newton_atol=1e-13, newton_steps=50, throw=True) -> SteadyState:
    """Fragmentation-limited steady state with implicit-function gradients.

    1. Relax: ``jaxcoag.evolve(kernel, engine, initial, [t_relax], outcome=outcome)`` (gradients
       stopped here).
    2. Polish: Newton root find (optimistix, ``ImplicitAdjoint``) of the scaled problem
       F(z) = t_c rhs(M0 z)/M0 + (sum(w z) - 1)/n = 0, where z = y/M0, t_c = 1/max|J| and the
       second term fixes the total mass (the rhs conserves mass, so its Jacobian is singular
       without it). The two-bin gel entry is held fixed.
    Gradients of the result w.r.t. the kernel's and the outcome's leaves come from the implicit
    function theorem (one linear solve), not from the relaxation.

    Arguments:
        kernel: kernel (AbstractKernel) [cm^3 s^-1]; engine: a ``jaxcoag.Binned`` (grid, scheme,
            solver and tolerances of the relaxation); initial: as in :func:`jaxcoag.evolve`.
        outcome: a fragmenting outcome (required: without one there is no steady state).
        t_relax: relaxation time [s] (long enough to be near the steady state), or
        y_guess: a scheme state near the steady state (e.g. ``result.y[-1]`` of a previous run);
            then no relaxation is run (``initial`` is ignored).
        newton_rtol, newton_atol: Newton tolerances on z (dimensionless); newton_steps: max.
        throw: raise on failure.

    Returns: SteadyState (mass_per_bin [g cm^-3], number_per_bin [cm^-3], residual, status).

    References: Birnstiel, Ormel & Dullemond (2011), A&A 525, A11 (fragmentation-limited steady
    states); Blondel et al. (2022) / optimistix implicit differentiation.
    """
    from .._engine import evolve
    from .engine import Binned, _fragmentation

    if not isinstance(engine, Binned):
        raise JaxcoagInputError(f"steady_state needs a jaxcoag.Binned engine; got {type(engine).__name__}.")
    fragmentation = _fragmentation(outcome)
    if fragmentation is None:
        raise JaxcoagInputError("steady_state needs a fragmenting outcome (coagulation alone never reaches one).")
    newton_rtol = check(newton_rtol, "newton_rtol", positive=True, hint="Newton relative tolerance, e.g. 1e-10")
    newton_atol = check(newton_atol, "newton_atol", positive=True, hint="Newton absolute tolerance on y/M_tot, "
                                                                      "e.g. 1e-13")
    if isinstance(newton_steps, bool) or not isinstance(newton_steps, (int, np.integer)) or newton_steps < 1:
        raise JaxcoagInputError(f"newton_steps must be a positive int (e.g. 50); got {newton_steps!r}.")
    sch, grid = engine.scheme, engine.grid
    # the Newton polish builds the dense Jacobian (implicit)
    check_memory(sch, grid.nbins, fragmentation=fragmentation, implicit=True,
                 fix="use a coarser grid (fewer bins per decade in MassGrid.log)")
    if y_guess is None:
        if t_relax is None:
            raise JaxcoagInputError("steady_state needs t_relax (relaxation time in s) or y_guess (a state).")
        t_relax = check(t_relax, "t_relax", positive=True, hint="relaxation time in s, long enough to approach "
                                                                "the steady state")
        relax = evolve(jax.lax.stop_gradient(kernel), engine, initial, jnp.array([float(t_relax)]),
                       outcome=jax.lax.stop_gradient(outcome), throw=throw)
        y_guess = relax.y[-1]
    else:
        _validate_model(kernel, grid, jnp.zeros(grid.nbins), fragmentation)
        y_guess = check(y_guess, "y_guess", hint="a scheme state, e.g. result.y[-1] of a previous run")
        want = jax.eval_shape(lambda: sch.init(grid, jnp.zeros(grid.nbins))).shape
        if y_guess.shape != want:
            raise JaxcoagInputError(f"y_guess must have shape {want} (the {type(sch).__name__} state, e.g. "
                                    f"result.y[-1] of a run on this grid); got {y_guess.shape}.")
    y_guess = jax.lax.stop_gradient(jnp.asarray(y_guess))
    return _steady_impl(sch, grid, kernel, fragmentation, y_guess, float(newton_rtol), float(newton_atol),
                        int(newton_steps), bool(throw))


@eqx.filter_jit
def _steady_impl(sch, grid, model, fragmentation, y_guess, newton_rtol, newton_atol, newton_steps, throw):
    w = sch.mass_scale(y_guess, grid)
    M0 = jnp.sum(w * y_guess)
    n = y_guess.shape[0]
    free = jnp.ones(n).at[-1].set(0.0) if isinstance(sch, TwoBinScheme) else jnp.ones(n)
    data0 = sch.precompute(jax.lax.stop_gradient(model), grid, jax.lax.stop_gradient(fragmentation))
    J0 = jax.jacfwd(lambda y: sch.rhs_structured(0.0, y, data0))(y_guess)
    tc = jax.lax.stop_gradient(1.0 / jnp.max(jnp.abs(J0)))
    z_fixed = y_guess / M0 * (1.0 - free)

    def F(z, args):
        kern, frag = args
        data = sch.precompute(kern, grid, frag)
        y = (z * free + z_fixed) * M0
        r = tc * sch.rhs_structured(0.0, y, data) / M0 * free
        cons = (jnp.sum(w * y) / M0 - 1.0) / jnp.sum(free)
        return r + cons * free + (z - y_guess / M0) * (1.0 - free)

    sol = optx.root_find(F, optx.Newton(rtol=newton_rtol, atol=newton_atol), y_guess / M0,
                         args=(model, fragmentation), max_steps=newton_steps, throw=throw)
    y = (sol.value * free + z_fixed) * M0
    res = jnp.max(jnp.abs(F(sol.value, (model, fragmentation))))
    status = RESULTS.where(sol.result == optx.RESULTS.successful, RESULTS.successful, RESULTS.solver_failed)
    return SteadyState(y=y, mass_per_bin=sch.mass_per_bin(y, grid), number_per_bin=sch.number_per_bin(y, grid),
                       residual=res, status=status, grid=grid)
