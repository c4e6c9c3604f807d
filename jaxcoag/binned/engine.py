"""The binned engine object ``Binned`` and its result ``BinnedResult`` (Smoluchowski on a mass grid).

``jaxcoag.evolve(kernel, Binned(grid, ...), initial, t_out)`` integrates the binned
coagulation(-fragmentation) equation with diffrax (defaults and traps in
:mod:`jaxcoag.binned.solve`): the kernel is evaluated inside the compiled solve, so ``jax.grad``,
``jax.jvp`` and ``jax.vmap`` over kernel and outcome parameters (alpha, rho_g, T, v_frag, ...) work.

References: Smoluchowski (1916); Brauer, Dullemond & Henning (2008) App. A; Stammler & Birnstiel
(2022, DustPy); Kidger (2021, diffrax).
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._engine import AbstractEngine, AbstractResult, Monodisperse
from .._status import RESULTS, result_code, result_from_code
from .._validate import JaxcoagInputError, check, is_traced
from .grid import MassGrid, monodisperse
from .scheme import AbstractScheme, check_memory
from .solve import _check_controls, _is_implicit, _solve_impl, _validate_model
from .solvers import Rodas4
from .twobin import TwoBinScheme

__all__ = ["Binned", "BinnedResult", "rebin_matrix"]


def rebin_matrix(log_edges_from, log_edges_to):
    """(n_from, n_to) fractions of each source bin that fall into each target bin, by overlap in ln m
    (mass in a source bin is taken uniform in ln m; rows sum to the fraction inside the target range)."""
    a = np.asarray(log_edges_from, np.float64)
    b = np.asarray(log_edges_to, np.float64)
    lo = np.maximum(a[:-1, None], b[None, :-1])
    hi = np.minimum(a[1:, None], b[None, 1:])
    return np.clip(hi - lo, 0.0, None) / np.diff(a)[:, None]


def _fragmentation(outcome):
    """The binned fragmentation hook object of ``outcome`` (None for pure sticking)."""
    from ..outcomes import Sticking  # lazy: jaxcoag.outcomes imports the binned redistribution

    return None if outcome is None or isinstance(outcome, Sticking) else outcome


class Binned(AbstractEngine):
    """Binned Smoluchowski engine (diffrax time integration on a ``MassGrid``).

    Fields:
        grid: the :class:`~jaxcoag.binned.MassGrid` (structure).
        scheme: the discretisation, ``TwoBinScheme()`` (default; Kovetz & Olund 1969 / Brauer et al.
            2008 two-bin split, exact mass conservation) or ``DGScheme(order=k)`` (Lombart & Laibe 2021).
        solver: a diffrax solver, or None: ``diffrax.Tsit5()`` for pure coagulation and
            :class:`jaxcoag.binned.Rodas4` (Rosenbrock, order 4, L-stable) with fragmentation (stiff);
            ``jaxcoag.binned.solve.default_implicit_solver`` (Kvaerno5, a Jacobian per stage) is the
            previous default and ``jaxcoag.binned.LinearlyImplicitEuler`` the DustPy-parity alternative. The result
            states the one used (``BinnedResult.solver``, :meth:`solver_name`).
        stepsize_controller: diffrax controller; default ``PIDController(rtol, atol * M_tot / w)``
            (absolute tolerance relative to the total mass, per bin).
        rtol, atol: relative tolerance, and absolute tolerance relative to the total mass.
        dt0: initial step [s]; default 1e-3 of the initial collision time (always explicit: dt0=None
            in diffrax gave NaN gradients). Only the first solve of a run starts from it: with an
            adaptive controller the step size reached is carried on (engine state ``"dt"``, stored
            in checkpoints, and ``BinnedResult.dt`` for continuing a result), so checkpoint
            segments and continuations do not climb back from a tiny step
            (:class:`jaxcoag.binned.solve.CarriedStepController`).
        adjoint: diffrax adjoint; default ``RecursiveCheckpointAdjoint`` (reverse mode); use
            ``diffrax.ForwardMode()`` for ``jax.jvp``/``jacfwd``.
        max_steps: solver step budget per advance (static).
        progress_meter: diffrax progress meter of one solve (default none).

    References: Smoluchowski (1916); Brauer et al. (2008) App. A; Stammler & Birnstiel (2022);
    Kidger (2021, diffrax).
    """

    grid: MassGrid = eqx.field(static=True)
    scheme: AbstractScheme = TwoBinScheme()
    solver: object = None
    stepsize_controller: object = None
    rtol: float = 1e-6
    atol: float = 1e-10
    dt0: float | None = None
    adjoint: object = None
    max_steps: int = eqx.field(static=True, default=100_000)
    progress_meter: object = None

    # how progress is shown does not change the run: a checkpoint resumes under another meter
    __fingerprint_exclude__ = ("progress_meter",)

    def __check_init__(self):
        if not isinstance(self.grid, MassGrid):
            raise JaxcoagInputError("Binned(grid): grid must be a jaxcoag.MassGrid, e.g. MassGrid.log(1e-12, 1e4, 10).")
        if not isinstance(self.scheme, AbstractScheme):
            raise JaxcoagInputError(f"Binned(scheme=...) must be a scheme object, jaxcoag.binned.TwoBinScheme() or "
                                    f"jaxcoag.binned.DGScheme(order=k); got {self.scheme!r}.")
        if self.solver is not None and not isinstance(self.solver, diffrax.AbstractSolver):
            raise JaxcoagInputError(f"Binned(solver=...) must be a diffrax solver (e.g. diffrax.Tsit5(), diffrax.Kvaerno5()) "
                                    f"or None for the automatic choice; got {self.solver!r}.")
        _check_controls(self.rtol, self.atol, self.max_steps, where="Binned")
        if self.dt0 is not None and not is_traced(self.dt0):
            check(self.dt0, "dt0", positive=True, hint="initial step in s")

    @property
    def name(self) -> str:
        return "binned"

    # ------------------------------------------------------------------ protocol
    def _forward_only(self):
        """With the default adjoint (``diffrax.RecursiveCheckpointAdjoint``, there for ``jax.grad``): the engine
        with ``diffrax.ForwardMode``, whose plain ``lax.while_loop`` traces, lowers and compiles faster (default
        ``jaxcoag run`` box, warm cache: trace + lower 0.8-1.0 s against 1.2-1.6 s, cold XLA compile 3.2 against
        3.8 s), with the same steps and the same numbers to round-off (bit for bit on that box; the two loops are
        compiled apart). An adjoint the user chose is kept."""
        if self.adjoint is not None:
            return self
        return eqx.tree_at(lambda e: e.adjoint, self, diffrax.ForwardMode(), is_leaf=lambda x: x is None)

    def _fingerprint_view(self):
        """Without the adjoint: it decides how a solve is differentiated, not its steps (checkpoints written by
        ``jaxcoag run``, which solves forward-only, resume under the default adjoint and the other way round; the
        numbers then agree to round-off)."""
        if self.adjoint is None:
            return self
        return eqx.tree_at(lambda e: e.adjoint, self, None)

    def _n0(self, initial):
        if isinstance(initial, Monodisperse):
            if is_traced(initial.m0) or is_traced(initial.rho_d):
                raise JaxcoagInputError("Binned: Monodisperse(m0, rho_d) must be concrete numbers (the bin holding m0 "
                                        "is structure); vmap over a number-density array instead.")
            return monodisperse(self.grid, initial.m0, initial.rho_d)
        return initial

    def _check(self, kernel, initial, t_out, t0, outcome, key):
        # key: the binned engine is deterministic and ignores it (so one call runs any engine)
        frag = _fragmentation(outcome)
        if outcome is not None and hasattr(outcome, "check"):
            outcome.check(kernel, "binned")
        if isinstance(initial, AbstractResult):
            if not isinstance(initial, BinnedResult):
                raise JaxcoagInputError(f"initial is a {type(initial).__name__}: a Binned run continues only a "
                                        "BinnedResult (or starts from Monodisperse / a number density per bin).")
            if initial.grid != self.grid:
                raise JaxcoagInputError("initial is a BinnedResult on another grid: continue with the same MassGrid.")
            if jnp.ndim(initial.t) != 1:
                raise JaxcoagInputError("initial is a batch of results (vmapped); continue one member at a time or "
                                        "inside jax.vmap.")
            n0 = jnp.zeros(self.grid.nbins)
        else:
            n0 = self._n0(initial)
        _validate_model(kernel, self.grid, n0, frag)
        check_memory(self.scheme, self.grid.nbins, fragmentation=frag, implicit=_is_implicit(self.solver, frag),
                     fix="use a coarser grid (fewer bins per decade in MassGrid.log)")
        if isinstance(initial, AbstractResult):
            return
        y0 = self.scheme.init(self.grid, n0)
        if callable(n0) and not is_traced(y0):
            if not bool(jnp.all(jnp.isfinite(y0))):
                raise JaxcoagInputError("initial f(m) projected onto the grid gives NaN/inf: the callable must return a "
                                        "finite number density per unit mass [cm^-3 g^-1] over the whole grid (check it "
                                        "at grid.edges).")
            if not float(self.scheme.total_mass(y0, self.grid)) > 0:
                raise JaxcoagInputError("initial f(m) projected onto the grid holds no mass: the distribution lies "
                                        "outside the grid or is zero; widen the grid or fix the callable.")
        if not callable(n0) and not is_traced(y0):
            if not float(jnp.sum(jnp.abs(y0))) > 0:
                raise JaxcoagInputError("the initial number density is all zeros: there is nothing to coagulate; give a "
                                        "positive number density.")

    def _init(self, kernel, initial, t0, outcome, key):
        # "dt" [s]: the step size to continue with (0 = none yet: the first solve starts from dt0)
        if isinstance(initial, BinnedResult):
            return {"y": jnp.asarray(initial.y[-1]), "t": jnp.asarray(initial.t[-1], jnp.float64),
                    "M0": jnp.asarray(initial.M0, jnp.float64), "dt": jnp.asarray(initial.dt, jnp.float64)}
        y0 = jnp.asarray(self.scheme.init(self.grid, self._n0(initial)), jnp.float64)
        return {"y": y0, "t": jnp.asarray(t0, jnp.float64), "M0": self.scheme.total_mass(y0, self.grid),
                "dt": jnp.zeros((), jnp.float64)}

    def solver_name(self, outcome=None) -> str:
        """Name of the time integrator this engine uses with ``outcome``: "Tsit5" (pure coagulation)
        or "Rodas4" (with fragmentation: Hairer & Wanner's Rosenbrock method RODAS,
        :class:`jaxcoag.binned.Rodas4`) for the automatic choice, else the class name of the given
        diffrax solver (e.g. "LinearlyImplicitEuler", "Kvaerno5Stagewise")."""
        if self.solver is None:
            return "Tsit5" if _fragmentation(outcome) is None else "Rodas4"
        return type(self.solver).__name__

    def _advance(self, kernel, state, t_seg, outcome):
        solver = self.solver
        frag = _fragmentation(outcome)
        if solver is None:
            solver = diffrax.Tsit5() if frag is None else Rodas4()
        adjoint = diffrax.RecursiveCheckpointAdjoint() if self.adjoint is None else self.adjoint
        meter = diffrax.NoProgressMeter() if self.progress_meter is None else self.progress_meter
        t_seg = jnp.asarray(t_seg, jnp.float64)
        dt0 = None if self.dt0 is None else jnp.asarray(self.dt0, jnp.float64)
        ys, res, stats, dt_next = _solve_impl(
            # tolerances travel as arrays: changing them does not recompile
            self.scheme, self.grid, kernel, frag, state["y"], state["t"], t_seg, solver, self.stepsize_controller,
            jnp.asarray(self.rtol, jnp.float64), jnp.asarray(self.atol, jnp.float64), dt0, adjoint,
            int(self.max_steps), meter, state["M0"], state.get("dt"))
        n = t_seg.shape[0]
        code = jnp.broadcast_to(result_code(res), (n,))
        last = jnp.arange(n) == n - 1
        outs = {"y": ys, "status": code,
                "steps": jnp.where(last, stats["steps"], 0), "rejected": jnp.where(last, stats["rejected"], 0)}
        return {"y": ys[-1], "t": t_seg[-1], "M0": state["M0"], "dt": dt_next}, outs

    def _result(self, kernel, t, outs, state, outcome):
        sch, grid = self.scheme, self.grid
        Y = outs["y"]
        rho = jax.vmap(lambda y: sch.mass_per_bin(y, grid))(Y)
        num = jax.vmap(lambda y: sch.number_per_bin(y, grid))(Y)
        gel = jax.vmap(lambda y: sch.gel_mass(y, grid))(Y)
        M0 = state["M0"]
        drift = (jnp.sum(rho, axis=1) + gel - M0) / M0
        status = result_from_code(outs["status"][-1])
        stats = {"steps": jnp.sum(outs["steps"]), "rejected": jnp.sum(outs["rejected"]),
                 "num_steps": jnp.sum(outs["steps"]) + jnp.sum(outs["rejected"])}
        return BinnedResult(t=jnp.asarray(t, jnp.float64), y=Y, rho=rho, n=num, gel_mass=gel, mass_drift=drift,
                            status=status, stats=stats, M0=M0, grid=grid, dt=jnp.asarray(state["dt"], jnp.float64),
                            solver=self.solver_name(outcome))


class BinnedResult(AbstractResult):
    """Result of the binned engine (add a leading batch axis under ``jax.vmap``).

    Fields:
        t: (T,) output times [s].
        y: (T, ny) raw scheme states (two-bin: mass per bin and the gel entry; DG: moments).
        rho: (T, nbins) mass density per bin [g cm^-3] on the engine's grid (``mass_per_bin()``).
        n: (T, nbins) number density per bin [cm^-3] (``number_per_bin()``).
        gel_mass: (T,) mass density that left through the top of the grid [g cm^-3].
        mass_drift: (T,) relative change of the total mass incl. gel since the run's start.
        status: a :class:`jaxcoag.RESULTS` item.
        stats: {"steps", "rejected", "num_steps"} solver step counts.
        M0: total mass density at the run's start [g cm^-3].
        grid: the MassGrid (static).
        dt: step size [s] the solve would continue with after ``t[-1]`` (passing the result as
            ``initial`` continues from it instead of restarting from a tiny ``dt0``).
        solver: name of the time integrator used (static str): "Tsit5" (automatic, pure
            coagulation), "Rodas4" (automatic, with fragmentation) or the class name of
            the diffrax solver given to ``Binned(solver=...)``.
    """

    t: jax.Array
    y: jax.Array
    rho: jax.Array
    n: jax.Array
    gel_mass: jax.Array
    mass_drift: jax.Array
    status: RESULTS
    stats: dict
    M0: jax.Array
    grid: MassGrid = eqx.field(static=True)
    dt: jax.Array = 0.0
    solver: str = eqx.field(static=True, default="")

    @property
    def centers(self):
        """Bin-centre masses [g] of the engine's grid (numpy)."""
        return self.grid.centers

    @property
    def final_state(self):
        """Engine state at ``t[-1]`` ({"y", "t", "M0", "dt"}); pass the result as ``initial`` to continue."""
        return {"y": self.y[..., -1, :], "t": self.t[..., -1], "M0": self.M0, "dt": self.dt}

    def bin_edges(self, edges=None):
        """Mass-bin edges [g]: the engine's grid for ``edges=None``, else ``edges`` (checked)."""
        if edges is None:
            return np.asarray(self.grid.edges, np.float64)
        e = np.asarray(getattr(edges, "edges", edges), np.float64)
        if e.ndim != 1 or e.size < 2 or not np.all(np.isfinite(e)) or np.any(e <= 0) or np.any(np.diff(e) <= 0):
            raise JaxcoagInputError("edges must be a 1-D, positive, strictly increasing array of >= 2 mass-bin edges in g.")
        return e

    def _rebin(self, x, edges):
        if edges is None:
            return x
        W = rebin_matrix(self.grid.log_edges, np.log(self.bin_edges(edges)))
        return x @ jnp.asarray(W)

    def mass_per_bin(self, edges=None):
        """(T, nbins) mass density per bin [g cm^-3]; other ``edges`` [g] re-bin conservatively by overlap
        in ln m (mass taken uniform in ln m within a grid bin)."""
        return self._rebin(self.rho, edges)

    def number_per_bin(self, edges=None):
        """(T, nbins) number density per bin [cm^-3] (re-binned like :meth:`mass_per_bin`)."""
        return self._rebin(self.n, edges)

    def moments(self, p):
        """(T,) M_p = sum_b n_b mbar_b^p [g^p cm^-3], mbar_b = rho_b / n_b the mean mass of bin b."""
        pos = self.n > 0
        nb = jnp.where(pos, self.n, 1.0)
        mbar = jnp.where(pos, self.rho / nb, 1.0)
        return jnp.sum(jnp.where(pos, self.n * mbar ** p, 0.0), axis=-1)

    def to_xarray(self, *, attrs=None, kernel=None, edges=None):
        """Labelled dataset of one run (common layout of every engine).

        Arguments:
            attrs: optional dict of global attributes (scene, parameters); values netCDF cannot hold
                are stored as their ``repr``.
            kernel: optional physical kernel the run used (compact grains): adds ``a`` [cm] and ``St``
                [1] on ``m``. Analytic kernels add nothing.
            edges: optional mass-bin edges [g] for the binned view (default: the engine's grid).

        Returns:
            xarray.Dataset with coords ``t`` [s], ``t_yr`` [yr] (dim t), ``m`` [g] (bin centres),
            ``m_edge`` [g] (and ``a``, ``St``); variables ``mass_per_bin`` [g cm^-3] and ``number_per_bin``
            [cm^-3] on (t, m), ``gel_mass`` [g cm^-3] and ``mass_drift`` [1] on t, ``status`` (RESULTS
            code, attributes ``status_name``/``status_message``), ``steps``, ``rejected_steps``;
            attributes ``title``, ``Conventions``, ``engine`` = "binned", ``status``, ``solver`` (the time
            integrator used, :attr:`solver`).

        References: CF conventions 1.10 (units, long_name).
        """
        from .._dataset import common_dataset

        if np.ndim(self.rho) != 2:
            raise JaxcoagInputError(
                f"to_xarray takes one result with rho of shape (T, nbins); got shape {np.shape(self.rho)} (a vmapped "
                "batch?). Index one member first, or build the dataset with jaxcoag.sweep.")
        e = self.bin_edges(edges)
        rho = np.asarray(self.mass_per_bin(edges), np.float64)
        gel = np.asarray(self.gel_mass, np.float64)
        if edges is not None:  # mass above the new top edge counts as "beyond the grid"
            gel = gel + np.asarray(self.rho, np.float64).sum(axis=1) - rho.sum(axis=1)
        extra = {
            "steps": ((), np.int64(np.asarray(self.stats["steps"])), {"units": "1", "long_name": "accepted solver steps"}),
            "rejected_steps": ((), np.int64(np.asarray(self.stats["rejected"])),
                               {"units": "1", "long_name": "rejected solver steps"}),
        }
        ds = common_dataset(engine="binned", title="jaxcoag binned coagulation solution", t=np.asarray(self.t),
                            edges=e, mass_per_bin=rho, number_per_bin=np.asarray(self.number_per_bin(edges)),
                            gel_mass=gel, mass_drift=np.asarray(self.mass_drift), code=int(np.asarray(result_code(self.status))),
                            extra=extra, extra_coords={}, kernel=kernel, attrs=attrs,
                            centres=np.asarray(self.grid.centers, np.float64) if edges is None else None)
        if self.solver:
            ds.attrs["solver"] = self.solver
        return ds
