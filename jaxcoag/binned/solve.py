"""Driver: solve the binned coagulation(-fragmentation) equation with diffrax.

``solve_binned(model, grid, n0, ts, ...)`` builds the scheme's state, evaluates the kernel
*inside* the (jit-compiled) solve from the kernel's leaves - so ``jax.grad``/``jax.jvp``/
``jax.vmap`` over kernel parameters (b, alpha, rho_g, T, v_frag ...) work - and integrates with
diffrax. Failures are values: ``BinnedSolution.result`` is a :class:`RESULTS` item; with
``throw=True`` a failed solve raises (``eqx.error_if``) with the item's message.

Time-integration defaults (docs/design_notes.md, traps measured):
* pure coagulation: ``diffrax.Tsit5()`` (not stiff; implicit solvers were 50-100x slower);
* with fragmentation: ``diffrax.Kvaerno5`` with an ``optimistix.Newton`` root finder (stiff
  equilibria; diffrax's default chord iteration rejected most steps near equilibrium); ``LinearlyImplicitEuler``
  (jaxcoag.binned.solvers) is the DustPy-parity alternative (one Jacobian + LU per step);
* error norm: the default ``PIDController`` gets a per-entry absolute tolerance
  ``atol * M_tot / w`` (w = ``scheme.mass_scale``), i.e. tolerances relative to the total mass
  (a single absolute atol over 30 decades of number density fails);
* an explicit ``dt0`` is always passed to diffrax (``dt0=None`` gave NaN gradients): when not
  given it is 1e-3 of the initial collision time M_tot / max|d rho/dt| (capped by the span).

References: Kidger (2021) diffrax; Stammler & Birnstiel (2022, DustPy) §3; docs/design_notes.md (house style, traps).
"""

from __future__ import annotations

import importlib

import numpy as np
import equinox as eqx
import jax
import jax.numpy as jnp
import diffrax
import optimistix as optx

from .._validate import JaxcoagInputError, JaxcoagTypeError, check, is_traced, require_x64
from ..kernels import AbstractKernel
from .grid import MassGrid
from .scheme import AbstractScheme, check_memory
from .twobin import TwoBinScheme

__all__ = ["solve_binned", "BinnedSolution", "RESULTS", "RESULT_NAMES", "result_code", "result_from_code",
           "make_scheme", "steady_state", "SteadyState"]


class RESULTS(eqx.Enumeration):
    """Outcome codes of :func:`solve_binned` (diffrax style)."""

    successful = ""
    max_steps_reached = ("The maximum number of solver steps was reached. Increase `max_steps`, loosen "
                         "rtol/atol, or use an implicit solver (diffrax.Kvaerno5 / LinearlyImplicitEuler) "
                         "for stiff fragmentation problems.")
    nonfinite = ("The solution became non-finite (NaN/inf). Check the kernel parameters, reduce dt0 or "
                 "tighten rtol/atol.")
    negative_density = ("A bin's mass density went negative beyond 10*atol of the total mass. Tighten "
                        "rtol/atol or use an implicit solver.")
    solver_failed = ("The diffrax solver failed (step size underflow, nonlinear solver divergence or "
                     "another internal error). Try a different solver or tighter tolerances.")
    invalid_parameters = ("A parameter of this sweep member is NaN/inf, so it was not run (jaxcoag.sweep.sweep "
                          "with invalid='flag'). Fix that parameter value.")


#: The :class:`RESULTS` items in definition order. The integer code of an item (the ``status`` of sweeps,
#: the ``result_code`` of netCDF files and checkpoints) is its position here; ``len(RESULTS)`` equals
#: ``len(RESULT_NAMES)`` (tested). Only equinox's public Enumeration API is used with it.
RESULT_NAMES = ("successful", "max_steps_reached", "nonfinite", "negative_density", "solver_failed",
                "invalid_parameters")


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


class BinnedSolution(eqx.Module):
    """Result of :func:`solve_binned`.

    Attributes:
        ts: output times [s], (nt,).
        ys: raw scheme states (nt, len(y)).
        mass_per_bin: mass density per bin [g cm^-3], (nt, nbins).
        number_per_bin: number density per bin [cm^-3], (nt, nbins).
        gel_mass: mass density that left through the top of the grid [g cm^-3], (nt,).
        mass_drift: relative change of the total mass incl. gel, (M(t) - M(t0))/M(t0), (nt,).
        result: a :class:`RESULTS` item.
        stats: dict with "steps" (accepted), "rejected", "num_steps" (attempted).
        grid: the MassGrid (static).
    """

    ts: jax.Array
    ys: jax.Array
    mass_per_bin: jax.Array
    number_per_bin: jax.Array
    gel_mass: jax.Array
    mass_drift: jax.Array
    result: RESULTS
    stats: dict
    grid: MassGrid = eqx.field(static=True)

    @property
    def centers(self):
        """Bin center masses [g] (numpy)."""
        return self.grid.centers


def make_scheme(scheme, order=0) -> AbstractScheme:
    """Scheme object from a name ("twobin" | "dg") or an AbstractScheme instance.

    "dg" imports ``jaxcoag.binned.dg.DGScheme(order=order)`` lazily.
    """
    if isinstance(scheme, AbstractScheme):
        return scheme
    if scheme == "twobin":
        if order != 0:
            raise JaxcoagInputError(f"the two-bin scheme is piecewise constant: use order=0 (got {order}); "
                                    "higher orders need scheme='dg'.")
        return TwoBinScheme()
    if scheme == "dg":
        try:
            dg = importlib.import_module("jaxcoag.binned.dg")
        except ImportError as e:  # pragma: no cover - depends on the tree
            raise JaxcoagInputError("scheme='dg' needs jaxcoag/binned/dg.py (DGScheme), which is not "
                                    f"available in this installation ({e}); use scheme='twobin'.") from e
        return dg.DGScheme(order=order)
    raise JaxcoagInputError(f"scheme must be 'twobin', 'dg' or an AbstractScheme instance (got {scheme!r}).")


def _is_implicit(solver, fragmentation):
    """Whether ``solver`` (as passed to solve_binned) builds a dense Jacobian (memory estimate)."""
    from .solvers import LinearlyImplicitEuler

    if solver is None:
        return fragmentation is not None  # Kvaerno5 + Newton with fragmentation
    if isinstance(solver, str):
        return solver == "kvaerno5"
    return isinstance(solver, (diffrax.AbstractImplicitSolver, LinearlyImplicitEuler))


def _validate(model, grid, n0, ts, fragmentation):
    require_x64("jaxcoag.binned.solve_binned")
    if not isinstance(model, AbstractKernel):
        raise JaxcoagInputError(f"model must be a jaxcoag kernel (AbstractKernel subclass), got {type(model).__name__}.")
    if not isinstance(grid, MassGrid):
        raise JaxcoagInputError("grid must be a jaxcoag.binned.MassGrid, e.g. MassGrid.log(1e-12, 1e4, 10).")
    if fragmentation is not None:
        from .fragmentation import AbstractFragmentation
        if not isinstance(fragmentation, AbstractFragmentation):
            raise JaxcoagInputError("fragmentation must be None or a jaxcoag.binned fragmentation model "
                                    "(Shattering(v_frag), ShatterToMonomers(m_frag) or "
                                    "OutcomeFragmentation(recipe, material)).")
    ts = check(ts, "ts", hint="output times in s")
    if ts.ndim != 1 or ts.shape[0] < 2:
        raise JaxcoagInputError("ts must be a 1-D array of at least 2 output times [s] (ts[0] is the initial time).")
    if not is_traced(ts) and not bool(np.all(np.diff(np.asarray(ts)) > 0)):
        raise JaxcoagInputError("ts must be strictly increasing (ts[0] is the time of n0).")
    if not callable(n0):
        n0 = check(n0, "n0", nonnegative=True, hint="number density per bin in cm^-3 (no NaN, no negatives)")
        if n0.shape != (grid.nbins,):
            raise JaxcoagInputError(f"n0 must have shape (nbins,) = ({grid.nbins},); got {n0.shape}. "
                                    "Pass a callable f(m) [cm^-3 g^-1] to project a distribution instead.")
    if fragmentation is not None:
        if bool(getattr(fragmentation, "needs_velocity", False)) and \
                type(model).relative_velocity2 is AbstractKernel.relative_velocity2:
            raise JaxcoagTypeError(
                f"{type(fragmentation).__name__} needs collision velocities, but the {type(model).__name__} kernel has no "
                "relative velocity (analytic kernels). Use a physical kernel from a Scene "
                "(jaxcoag.scenes.nebula_ch4().kernel(gas, rho_s=...)), or a velocity-free fragmentation model "
                "such as ShatterToMonomers(m_frag).")
    return n0, ts


def _check_controls(rtol, atol, max_steps, where="solve_binned"):
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
    tc = jnp.where(rate > 0, M / jnp.where(rate > 0, rate, 1.0), t1 - t0)
    return jax.lax.stop_gradient(jnp.minimum(1e-3 * tc, 1e-2 * (t1 - t0)))


@eqx.filter_jit
def _solve_impl(scheme, grid, model, fragmentation, y0, ts, solver, controller, rtol, atol, dt0,
                adjoint, max_steps, progress_meter):
    data = scheme.precompute(model, grid, fragmentation)
    term = diffrax.ODETerm(lambda t, y, args: scheme.rhs(t, y, args))
    t0, t1 = ts[0], ts[-1]
    w = scheme.mass_scale(y0, grid)
    M0 = scheme.total_mass(y0, grid)
    if solver is None or solver == "kvaerno5":
        # Newton (fresh Jacobian per iteration) instead of diffrax's default chord iteration:
        # measured 125 steps / 0 rejected vs > 3000 steps / 56 % rejected on a 61-bin
        # fragmentation equilibrium (chord diverges on the quadratic coagulation term).
        solver = diffrax.Kvaerno5(root_finder=optx.Newton(rtol=rtol, atol=jax.lax.stop_gradient(1e-3 * atol * M0)))
    if controller is None:
        atol_vec = jax.lax.stop_gradient(atol * M0 / w)
        controller = diffrax.PIDController(rtol=rtol, atol=atol_vec)
    if dt0 is None:
        dt0 = _default_dt0(scheme, grid, data, y0, t0, t1)
    sol = diffrax.diffeqsolve(term, solver, t0, t1, dt0, y0, args=data,
                              saveat=diffrax.SaveAt(ts=ts), stepsize_controller=controller,
                              adjoint=adjoint, max_steps=max_steps, throw=False,
                              progress_meter=progress_meter)
    ys = sol.ys
    rho = jax.vmap(lambda y: scheme.mass_per_bin(y, grid))(ys)
    num = jax.vmap(lambda y: scheme.number_per_bin(y, grid))(ys)
    gel = jax.vmap(lambda y: scheme.gel_mass(y, grid))(ys)
    Mt = jnp.sum(rho, axis=1) + gel
    drift = (Mt - M0) / M0
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
    return ys, rho, num, gel, drift, res, stats


def solve_binned(model, grid, n0, ts, *, scheme="twobin", order=0, fragmentation=None, solver=None,
                 stepsize_controller=None, rtol=1e-6, atol=1e-10, dt0=None, adjoint=None,
                 max_steps=100_000, throw=True, progress_meter=None) -> BinnedSolution:
    """Integrate the binned Smoluchowski (coagulation + optional fragmentation) equation.

    Arguments:
        model: collision kernel, a ``jaxcoag.kernels.AbstractKernel`` [cm^3 s^-1]; evaluated
            inside the solve, so gradients flow to its leaves.
        grid: ``MassGrid`` (structure).
        n0: number density per bin [cm^-3], shape (nbins,), or a callable f(m) number density
            per unit mass [cm^-3 g^-1] projected by the scheme (two-bin: integral of m f(m)
            over the bin by Gauss-Legendre in ln m; DG: its own projection).
        ts: output times [s], strictly increasing; n0 is the state at ts[0].
        scheme: "twobin" (default), "dg" (``order`` = polynomial order) or an AbstractScheme.
        fragmentation: None, or a binned fragmentation model: ``Shattering(v_frag, ...)``,
            ``ShatterToMonomers(m_frag)`` or ``OutcomeFragmentation(recipe, material)`` (the
            shared collision-outcome interface). Models with ``needs_velocity`` (Shattering,
            velocity-dependent recipes) need a kernel with ``relative_velocity2`` (a Scene kernel).
        solver: diffrax solver, or "tsit5" / "kvaerno5"; default Tsit5 (coagulation) /
            "kvaerno5" = Kvaerno5 with an optimistix Newton root finder at 1e-3 atol (fragmentation,
            and stiff post-gel product-kernel runs; its mass drift is at the Newton tolerance,
            not round-off).
        stepsize_controller: diffrax controller; default PIDController(rtol, atol * M_tot / w).
        rtol, atol: relative tolerance, and absolute tolerance *relative to the total mass*
            (arrays inside the compiled solve: changing them does not recompile). Negative bin
            masses below 10 max(rtol, atol) M_tot count as solver noise; with a custom
            ``stepsize_controller`` pass matching rtol/atol here too.
        dt0: initial step [s]; default 1e-3 of the initial collision time (always explicit).
        adjoint: diffrax adjoint; default RecursiveCheckpointAdjoint (reverse mode);
            use ``diffrax.ForwardMode()`` for jax.jvp / jacfwd.
        max_steps: maximum solver steps (static).
        throw: raise (eqx.error_if) if the result is not successful; with False inspect
            ``.result`` (use False inside vmapped sweeps to keep going).
        progress_meter: diffrax progress meter (default none).

    Returns:
        BinnedSolution (ts, mass_per_bin [g cm^-3], number_per_bin [cm^-3], gel_mass, mass_drift,
        result, stats).

    References: Smoluchowski (1916); Brauer et al. (2008) App. A; Stammler & Birnstiel (2022);
    Kidger (2021, diffrax); docs/design_notes.md (solver/tolerance traps).
    """
    n0, ts = _validate(model, grid, n0, ts, fragmentation)
    _check_controls(rtol, atol, max_steps)
    sch = make_scheme(scheme, order)
    # refuse a grid whose pair tensors cannot fit in memory before allocating any of them
    check_memory(sch, grid.nbins, fragmentation=fragmentation, implicit=_is_implicit(solver, fragmentation),
                 fix="use a coarser grid (fewer bins per decade in MassGrid.log)")
    y0 = sch.init(grid, n0)
    if callable(n0) and not is_traced(y0):
        if not bool(jnp.all(jnp.isfinite(y0))):
            raise JaxcoagInputError("n0(m) projected onto the grid gives NaN/inf: the callable must return a finite "
                                    "number density per unit mass [cm^-3 g^-1] over the whole grid (check it at "
                                    "grid.edges).")
        if not float(sch.total_mass(y0, grid)) > 0:
            raise JaxcoagInputError("n0(m) projected onto the grid holds no mass: the distribution lies outside the "
                                    "grid or is zero; widen the grid or fix the callable.")
    if not callable(n0) and not is_traced(y0):
        if not float(jnp.sum(jnp.abs(y0))) > 0:
            raise JaxcoagInputError("n0 is all zeros: there is nothing to coagulate; give a positive number density.")
    if isinstance(solver, str):
        if solver not in ("tsit5", "kvaerno5"):
            raise JaxcoagInputError(f"solver must be a diffrax solver, 'tsit5' or 'kvaerno5' (got {solver!r}).")
        solver = diffrax.Tsit5() if solver == "tsit5" else "kvaerno5"
    if solver is None:
        solver = diffrax.Tsit5() if fragmentation is None else "kvaerno5"  # Kvaerno5 + Newton, built inside
    if adjoint is None:
        adjoint = diffrax.RecursiveCheckpointAdjoint()
    if progress_meter is None:
        progress_meter = diffrax.NoProgressMeter()
    ts = jnp.asarray(ts, dtype=jnp.float64)
    if dt0 is not None:
        dt0 = check(dt0, "dt0", positive=True, hint="initial step in s")
    ys, rho, num, gel, drift, res, stats = _solve_impl(
        # tolerances travel as arrays: changing them does not recompile
        sch, grid, model, fragmentation, y0, ts, solver, stepsize_controller,
        jnp.asarray(float(rtol), jnp.float64), jnp.asarray(float(atol), jnp.float64), dt0,
        adjoint, int(max_steps), progress_meter)
    if throw:
        ys = res.error_if(ys, res != RESULTS.successful)
        rho = res.error_if(rho, res != RESULTS.successful)
    return BinnedSolution(ts=ts, ys=ys, mass_per_bin=rho, number_per_bin=num, gel_mass=gel,
                          mass_drift=drift, result=res, stats=stats, grid=grid)


class SteadyState(eqx.Module):
    """Result of :func:`steady_state`: mass per bin [g cm^-3] (nbins,), number per bin [cm^-3],
    the residual max |F| of the scaled root problem, the optimistix result and the raw state."""

    y: jax.Array
    mass_per_bin: jax.Array
    number_per_bin: jax.Array
    residual: jax.Array
    result: object
    grid: MassGrid = eqx.field(static=True)


def steady_state(model, grid, n0, *, fragmentation, t_relax=None, y_guess=None, scheme="twobin", order=0,
                 solver=None, rtol=1e-6, atol=1e-10, newton_rtol=1e-10, newton_atol=1e-13, max_steps=100_000,
                 newton_steps=50, throw=True) -> SteadyState:
    """Fragmentation-limited steady state with implicit-function gradients.

    1. Relax: integrate :func:`solve_binned` from n0 to ``t_relax`` (gradients stopped here).
    2. Polish: Newton root find (optimistix, ``ImplicitAdjoint``) of the scaled problem
       F(z) = t_c rhs(M0 z)/M0 + (sum(w z) - 1)/n = 0, where z = y/M0, t_c = 1/max|J| and the
       second term fixes the total mass (the rhs conserves mass, so its Jacobian is singular
       without it). The two-bin gel entry is held fixed.
    Gradients of the result w.r.t. the kernel's and the fragmentation model's leaves come
    from the implicit function theorem (one linear solve), not from the relaxation.

    Arguments:
        model: kernel (AbstractKernel); grid: MassGrid; n0: as in :func:`solve_binned`.
        fragmentation: fragmentation model (required: without it there is no steady state).
        t_relax: relaxation time [s] (long enough to be near the steady state), or
        y_guess: a scheme state near the steady state (e.g. ``sol.ys[-1]`` of a previous
            :func:`solve_binned`); then no relaxation is run (n0 is ignored).
        scheme, order, solver, rtol, atol, max_steps: passed to :func:`solve_binned`.
        newton_rtol, newton_atol: Newton tolerances on z (dimensionless); newton_steps: max.
        throw: raise on failure.

    Returns: SteadyState (mass_per_bin [g cm^-3], number_per_bin [cm^-3], residual, result).

    References: Birnstiel, Ormel & Dullemond (2011), A&A 525, A11 (fragmentation-limited steady
    states); Blondel et al. (2022) / optimistix implicit differentiation.
    """
    if fragmentation is None:
        raise JaxcoagInputError("steady_state needs a fragmentation model (coagulation alone never reaches one).")
    newton_rtol = check(newton_rtol, "newton_rtol", positive=True, hint="Newton relative tolerance, e.g. 1e-10")
    newton_atol = check(newton_atol, "newton_atol", positive=True, hint="Newton absolute tolerance on y/M_tot, "
                                                                      "e.g. 1e-13")
    if isinstance(newton_steps, bool) or not isinstance(newton_steps, (int, np.integer)) or newton_steps < 1:
        raise JaxcoagInputError(f"newton_steps must be a positive int (e.g. 50); got {newton_steps!r}.")
    sch = make_scheme(scheme, order)
    if isinstance(grid, MassGrid):  # the Newton polish builds the dense Jacobian (implicit)
        check_memory(sch, grid.nbins, fragmentation=fragmentation, implicit=True,
                     fix="use a coarser grid (fewer bins per decade in MassGrid.log)")
    if y_guess is None:
        if t_relax is None:
            raise JaxcoagInputError("steady_state needs t_relax (relaxation time in s) or y_guess (a state).")
        t_relax = check(t_relax, "t_relax", positive=True, hint="relaxation time in s, long enough to approach "
                                                                "the steady state")
        ts = jnp.array([0.0, float(t_relax)])
        relax = solve_binned(jax.lax.stop_gradient(model), grid, n0, ts, scheme=sch,
                             fragmentation=jax.lax.stop_gradient(fragmentation), solver=solver, rtol=rtol,
                             atol=atol, max_steps=max_steps, throw=throw)
        y_guess = relax.ys[-1]
    else:
        _validate(model, grid, jnp.zeros(grid.nbins), jnp.array([0.0, 1.0]), fragmentation)
        y_guess = check(y_guess, "y_guess", hint="a scheme state, e.g. sol.ys[-1] of a previous solve_binned")
        want = jax.eval_shape(lambda: sch.init(grid, jnp.zeros(grid.nbins))).shape
        if y_guess.shape != want:
            raise JaxcoagInputError(f"y_guess must have shape {want} (the {type(sch).__name__} state, e.g. "
                                    f"sol.ys[-1] of solve_binned on this grid); got {y_guess.shape}.")
    y_guess = jax.lax.stop_gradient(jnp.asarray(y_guess))
    return _steady_impl(sch, grid, model, fragmentation, y_guess, float(newton_rtol), float(newton_atol),
                        int(newton_steps), bool(throw))


@eqx.filter_jit
def _steady_impl(sch, grid, model, fragmentation, y_guess, newton_rtol, newton_atol, newton_steps, throw):
    w = sch.mass_scale(y_guess, grid)
    M0 = jnp.sum(w * y_guess)
    n = y_guess.shape[0]
    free = jnp.ones(n).at[-1].set(0.0) if isinstance(sch, TwoBinScheme) else jnp.ones(n)
    data0 = sch.precompute(jax.lax.stop_gradient(model), grid, jax.lax.stop_gradient(fragmentation))
    J0 = jax.jacfwd(lambda y: sch.rhs(0.0, y, data0))(y_guess)
    tc = jax.lax.stop_gradient(1.0 / jnp.max(jnp.abs(J0)))
    z_fixed = y_guess / M0 * (1.0 - free)

    def F(z, args):
        kern, frag = args
        data = sch.precompute(kern, grid, frag)
        y = (z * free + z_fixed) * M0
        r = tc * sch.rhs(0.0, y, data) / M0 * free
        cons = (jnp.sum(w * y) / M0 - 1.0) / jnp.sum(free)
        return r + cons * free + (z - y_guess / M0) * (1.0 - free)

    sol = optx.root_find(F, optx.Newton(rtol=newton_rtol, atol=newton_atol), y_guess / M0,
                         args=(model, fragmentation), max_steps=newton_steps, throw=throw)
    y = (sol.value * free + z_fixed) * M0
    res = jnp.max(jnp.abs(F(sol.value, (model, fragmentation))))
    return SteadyState(y=y, mass_per_bin=sch.mass_per_bin(y, grid), number_per_bin=sch.number_per_bin(y, grid),
                       residual=res, result=sol.result, grid=grid)
