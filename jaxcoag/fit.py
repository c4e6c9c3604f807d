"""Gradient-based fitting of disk parameters (alpha, rho_g, optionally v_frag) to a size distribution.

The forward model, :class:`NebulaBox`, is a local box of the chapter-4 nebula: the
``scenes.nebula_ch4()`` kernel (Brownian motion + Ormel & Cuzzi 2007 turbulence + radial drift,
added in quadrature) for compact grains of material density ``rho_s`` in a midplane gas of
density ``rho_g`` [g cm^-3], temperature T [K] and turbulence ``alpha`` at radius R, started
monodisperse at radius ``a0`` with dust density ``dust_to_gas * rho_g``, integrated with the
two-bin scheme, observed as mass fractions per bin rho_b / rho_d at a few times.

**Why alpha and rho_g are separately identifiable.** For small grains (Epstein drag,
St << Re^-1/2) the turbulent relative velocity is Delta v ~ v_g Re^(1/4) Delta St, i.e. it
scales as (alpha / rho_g)^(3/4) and the intermediate regime as (alpha / rho_g)^(1/2): from the
turbulent term alone only alpha / rho_g is constrained. Two other terms break the degeneracy:
radial drift Delta v = eta v_K Delta St ~ 1/rho_g (no alpha) and Brownian motion (neither), and
the dust density dust_to_gas * rho_g sets the overall collision rate ~ rho_g. The mass
distributions at 2 - 3 times therefore pin both. Measured on a 46-bin version of the default box (3 AU,
a0 = 1 micron, observation times 2e9, 5e9, 1e10 s): the 2 x 2 Jacobian of the residuals in
(ln alpha, ln rho_g) has singular-value ratio 2.4 and parameter correlation 0.70 - well
conditioned. (With dust density held fixed instead of a fixed dust-to-gas ratio, the rate
would no longer scale with rho_g and the problem gets worse.)

Fits run in log-parameters (positivity, and comparable scales). Residuals are differences of
sqrt(rho_b / rho_d + floor) (a Hellinger-type distance that weights the whole distribution,
not just its peak); the floor (1e-6) keeps gradients finite where bins are empty. The forward
solves use ``diffrax.ForwardMode()``: with two or three parameters, forward-mode Jacobians (as
optimistix's Gauss-Newton / Levenberg-Marquardt use by default) are cheaper than reverse mode.

* :func:`fit_adam` - optax Adam with a cosine-decayed learning rate, the whole loop a single
  jitted ``lax.scan``;
* :func:`fit_least_squares` - optimistix Levenberg-Marquardt (default) or Gauss-Newton.

References: Ormel & Cuzzi (2007) A&A 466, 413 (turbulent velocities); Ormel (2008) thesis ch. 4
(nebula scene, Table 4.1 disk); Kingma & Ba (2015) Adam; More (1978) Levenberg-Marquardt;
Rader et al. (2022, optimistix) / DeepMind optax.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import equinox as eqx
import jax
import jax.numpy as jnp
import diffrax
import optax
import optimistix as optx

from . import constants as C
from . import scenes
from ._validate import JaxcoagInputError, require_x64
from ._engine import evolve
from .binned import MassGrid
from .binned.engine import Binned
from .physics.gas import ch4_disk, midplane_state

__all__ = ["NebulaBox", "nebula_box", "synthetic_target", "residuals", "fit_adam", "fit_least_squares",
           "FitResult", "PARAMETERS"]

PARAMETERS = ("alpha", "rho_g", "v_frag")
_FLOOR = 1e-6


class NebulaBox(eqx.Module):
    """Forward model: local nebula coagulation box (see module docstring); build with :func:`nebula_box`.

    Attributes:
        grid: MassGrid (static).
        t_out: output times [s]; t_out[0] = 0 is the monodisperse start (t0), the rest are observed.
        T: gas temperature [K]; Omega: Keplerian frequency [s^-1]; R: radius [cm].
        rho_s: material density [g cm^-3]; dust_to_gas: dust/gas mass ratio [-].
        alpha, rho_g [g cm^-3], v_frag [cm s^-1]: default values of the parameters (used
            for any parameter not being fitted).
        fragmentation: include the outcome ``jaxcoag.outcomes.Shattering(v_frag)`` (static; stiff,
            solved with Kvaerno5).
        rtol, atol: solver tolerances (static).
    """

    grid: MassGrid = eqx.field(static=True)
    t_out: jax.Array
    T: jax.Array
    Omega: jax.Array
    R: jax.Array
    rho_s: jax.Array
    dust_to_gas: jax.Array
    alpha: jax.Array
    rho_g: jax.Array
    v_frag: jax.Array
    fragmentation: bool = eqx.field(static=True, default=False)
    rtol: float = eqx.field(static=True, default=1e-7)
    atol: float = eqx.field(static=True, default=1e-11)

    def _values(self, params):
        p = {"alpha": self.alpha, "rho_g": self.rho_g, "v_frag": self.v_frag}
        p.update(params)
        return p

    def solve(self, params=None, *, adjoint=None, t_out=None):
        """:class:`jaxcoag.BinnedResult` for parameter values ``params`` (dict, linear values; defaults
        otherwise): ``jaxcoag.evolve`` with ``jaxcoag.Binned(grid)`` from the monodisperse start at
        ``t0 = t_out[0]`` (default ``self.t_out``), ``throw=False`` (read ``.status``)."""
        p = self._values(params or {})
        gas = midplane_state(p["rho_g"], self.T, p["alpha"], self.Omega, R=self.R)
        kern = scenes.nebula_ch4().kernel(gas, rho_s=self.rho_s)
        rho_d = self.dust_to_gas * p["rho_g"]
        n0 = jnp.zeros(self.grid.nbins).at[0].set(rho_d / self.grid.centers[0])
        if self.fragmentation:
            from .outcomes import Shattering

            outcome = Shattering(p["v_frag"])
        else:
            outcome = None
        t_out = self.t_out if t_out is None else jnp.asarray(t_out, jnp.float64)
        engine = Binned(self.grid, rtol=self.rtol, atol=self.atol, dt0=1e-6 * t_out[-1],
                        adjoint=adjoint or diffrax.ForwardMode())
        return evolve(kern, engine, n0, t_out, t0=t_out[0], outcome=outcome, throw=False)

    def __call__(self, params=None, *, adjoint=None):
        """Observed mass fractions rho_b / rho_d, shape (len(t_out) - 1, nbins) [-]."""
        p = self._values(params or {})
        res = self.solve(params, adjoint=adjoint)
        return res.mass_per_bin()[1:] / (self.dust_to_gas * p["rho_g"])


def nebula_box(*, R=3.0 * C.AU, alpha=1e-4, rho_g=None, v_frag=100.0, a0=1e-4, rho_s=3.0, dust_to_gas=0.01,
               bins_per_decade=5, decades=9, ts=(2e9, 5e9, 1e10), fragmentation=False, rtol=1e-7,
               atol=1e-11) -> NebulaBox:
    """Build the default fitting box.

    Arguments:
        R: radius [cm] (default 3 AU); T and Omega come from ``physics.gas.ch4_disk(R)``.
        alpha: turbulence parameter [-]; rho_g: gas density [g cm^-3] (default: ch4_disk's
            midplane value, 2.39e-11 at 3 AU); v_frag: fragmentation velocity [cm s^-1].
        a0: monomer radius [cm]; rho_s: material density [g cm^-3]; dust_to_gas [-].
        bins_per_decade, decades: mass grid from the monomer bin upward (5 x 9 -> 45 bins).
        ts: observation times [s] (> 0, increasing; the start t = 0 is prepended: the model's
            ``t_out`` = (0, *ts)).
        fragmentation: include the outcome Shattering(v_frag) (then v_frag can be fitted).
        rtol, atol: solver tolerances (atol relative to the total mass).
    Returns: NebulaBox.
    """
    require_x64("jaxcoag.fit.nebula_box")
    for name, v in (("R", R), ("alpha", alpha), ("v_frag", v_frag), ("a0", a0), ("rho_s", rho_s),
                    ("dust_to_gas", dust_to_gas), ("bins_per_decade", bins_per_decade), ("decades", decades),
                    ("rtol", rtol), ("atol", atol)):
        if not (np.isfinite(float(v)) and float(v) > 0):
            raise JaxcoagInputError(f"{name} must be finite and > 0 (got {v!r}).")
    ts = np.asarray(ts, np.float64)
    if ts.ndim != 1 or ts.size < 1 or not np.all(np.isfinite(ts)) or not np.all(ts > 0) \
            or not np.all(np.diff(ts) > 0):
        raise JaxcoagInputError(f"ts must be a 1-D increasing array of finite observation times > 0 s "
                                f"(t = 0 is prepended); got {ts.tolist()!r}.")
    gas0 = ch4_disk(R)
    if rho_g is None:
        rho_g = float(gas0.rho_g)
    if not (np.isfinite(float(rho_g)) and float(rho_g) > 0):
        raise JaxcoagInputError(f"rho_g must be finite and > 0 g cm^-3 (got {rho_g!r}).")
    m0 = 4.0 / 3.0 * math.pi * rho_s * a0 ** 3
    half = 10 ** (0.5 / bins_per_decade)
    grid = MassGrid.log(m0 / half, m0 / half * 10 ** decades, bins_per_decade)
    f = lambda x: jnp.asarray(x, jnp.float64)
    return NebulaBox(grid=grid, t_out=f(np.concatenate([[0.0], ts])), T=f(gas0.T), Omega=f(gas0.Omega), R=f(R),
                     rho_s=f(rho_s), dust_to_gas=f(dust_to_gas), alpha=f(alpha), rho_g=f(rho_g), v_frag=f(v_frag),
                     fragmentation=bool(fragmentation), rtol=float(rtol), atol=float(atol))


def _check_params(params, what, model):
    if not isinstance(params, dict) or not params:
        raise JaxcoagInputError(f"{what} must be a non-empty dict with keys among {PARAMETERS}, "
                                "e.g. {'alpha': 3e-4, 'rho_g': 1e-11}.")
    out = {}
    for k, v in params.items():
        if k not in PARAMETERS:
            raise JaxcoagInputError(f"unknown parameter {k!r} in {what}; fit any of {PARAMETERS}.")
        if k == "v_frag" and not model.fragmentation:
            raise JaxcoagInputError("v_frag has no effect without fragmentation: build the model with "
                                    "nebula_box(fragmentation=True).")
        a = np.asarray(v, np.float64)
        if a.shape != () or not np.isfinite(a) or not a > 0:
            raise JaxcoagInputError(f"{what}[{k!r}] must be a finite scalar > 0 (got {v!r}); the fit works in "
                                    "log-parameters.")
        out[k] = jnp.asarray(a)
    return out


def synthetic_target(model: NebulaBox, truth: dict, *, noise=0.01, key=None):
    """Synthetic observation: the model at ``truth`` times (1 + noise * N(0, 1)) per bin.

    Arguments:
        model: NebulaBox; truth: dict of true parameter values (alpha [-], rho_g [g cm^-3],
        v_frag [cm s^-1]); noise: relative Gaussian noise per bin (>= 0); key: jax PRNG key
        (default ``jax.random.key(0)``: fixed, reproducible).
    Returns: array (len(t_out) - 1, nbins) of noisy mass fractions [-].
    """
    if not isinstance(model, NebulaBox):
        raise JaxcoagInputError("model must be a jaxcoag.fit.NebulaBox (build it with nebula_box()).")
    truth = _check_params(truth, "truth", model)
    if not (np.isfinite(noise) and noise >= 0):
        raise JaxcoagInputError(f"noise must be a finite relative level >= 0 (got {noise!r}).")
    key = jax.random.key(0) if key is None else key
    y = model(truth)
    return y * (1.0 + noise * jax.random.normal(key, y.shape))


def residuals(model: NebulaBox, log_params: dict, target):
    """Residual vector sqrt(y_model + floor) - sqrt(y_target + floor), flattened [-]."""
    y = model({k: jnp.exp(v) for k, v in log_params.items()})
    f = lambda x: jnp.sqrt(jnp.maximum(x, 0.0) + _FLOOR)
    return (f(y) - f(target)).ravel()


class FitResult(NamedTuple):
    """Result of a fit: ``params`` (dict, linear values), ``log_params``, final ``loss``
    (0.5 sum r^2), ``steps`` taken, ``history`` (loss per step; Adam) and ``result`` (a string
    "successful" or the optimiser's failure message)."""

    params: dict
    log_params: dict
    loss: float
    steps: int
    history: np.ndarray
    result: str


def _prepare(model, target, init):
    require_x64("jaxcoag.fit")
    if not isinstance(model, NebulaBox):
        raise JaxcoagInputError("model must be a jaxcoag.fit.NebulaBox (build it with nebula_box()).")
    init = _check_params(init, "init", model)
    target = jnp.asarray(target, jnp.float64)
    shape = (model.t_out.shape[0] - 1, model.grid.nbins)
    if target.shape != shape:
        raise JaxcoagInputError(f"target must have shape (n_obs, nbins) = {shape}; got {target.shape}.")
    if not bool(jnp.all(jnp.isfinite(target))):
        raise JaxcoagInputError("target contains NaN/inf.")
    return {k: jnp.log(v) for k, v in init.items()}, target


def fit_adam(model: NebulaBox, target, init: dict, *, steps=150, learning_rate=0.1, final_learning_rate=1e-3):
    """Fit log-parameters by optax Adam on 0.5 sum r^2 (r from :func:`residuals`).

    Arguments:
        model: NebulaBox; target: observed mass fractions (n_obs, nbins);
        init: dict of starting values (linear; keys among alpha, rho_g, v_frag) - the fitted set;
        steps: Adam steps (> 0); learning_rate: initial step in ln-parameter units, cosine-decayed
        to final_learning_rate.
    Returns: FitResult (history = loss per step).
    References: Kingma & Ba (2015); optax.adam, optax.cosine_decay_schedule.
    """
    x0, target = _prepare(model, target, init)
    if not (isinstance(steps, (int, np.integer)) and steps > 0):
        raise JaxcoagInputError(f"steps must be a positive int (got {steps!r}).")
    for name, v in (("learning_rate", learning_rate), ("final_learning_rate", final_learning_rate)):
        if not (np.isfinite(float(v)) and float(v) > 0):
            raise JaxcoagInputError(f"{name} must be finite and > 0 (a step in ln-parameter units, e.g. 0.1 and "
                                    f"1e-3); got {v!r}.")
    sched = optax.cosine_decay_schedule(learning_rate, int(steps), alpha=final_learning_rate / learning_rate)
    opt = optax.adam(sched)

    def loss_fn(x):
        r = residuals(model, x, target)
        return 0.5 * jnp.sum(r ** 2)

    def val_grad(x):
        g, v = jax.jacfwd(lambda z: (loss_fn(z), loss_fn(z)), has_aux=True)(x)
        return v, g

    @jax.jit
    def run(x):
        def step(carry, _):
            x, s = carry
            v, g = val_grad(x)
            upd, s = opt.update(g, s, x)
            return (optax.apply_updates(x, upd), s), v

        (x, _), hist = jax.lax.scan(step, (x, opt.init(x)), None, length=int(steps))
        return x, hist, loss_fn(x)

    x, hist, loss = run(x0)
    ok = bool(jnp.isfinite(loss))
    return FitResult(params={k: float(jnp.exp(v)) for k, v in x.items()}, log_params={k: float(v) for k, v in x.items()},
                     loss=float(loss), steps=int(steps), history=np.asarray(hist),
                     result="successful" if ok else "non-finite loss: lower learning_rate or start closer")


def fit_least_squares(model: NebulaBox, target, init: dict, *, solver="levenberg_marquardt", rtol=1e-8, atol=1e-8,
                      max_steps=100):
    """Fit log-parameters by optimistix nonlinear least squares on the residuals.

    Arguments:
        model, target, init: as :func:`fit_adam`.
        solver: "levenberg_marquardt" (default), "gauss_newton", or an optimistix
            least-squares solver instance.
        rtol, atol: optimistix convergence tolerances on the (log-)parameters / loss.
        max_steps: maximum iterations.
    Returns: FitResult (history = [initial loss, final loss]).
    References: More (1978); optimistix.least_squares (forward-mode Jacobian).
    """
    x0, target = _prepare(model, target, init)
    for name, v in (("rtol", rtol), ("atol", atol)):
        if not (np.isfinite(float(v)) and float(v) > 0):
            raise JaxcoagInputError(f"{name} must be finite and > 0 (optimistix convergence tolerance, e.g. 1e-8); "
                                    f"got {v!r}.")
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or max_steps < 1:
        raise JaxcoagInputError(f"max_steps must be a positive int (optimiser iterations, e.g. 100); got {max_steps!r}.")
    if solver == "levenberg_marquardt":
        solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    elif solver == "gauss_newton":
        solver = optx.GaussNewton(rtol=rtol, atol=atol)
    elif not isinstance(solver, optx.AbstractLeastSquaresSolver):
        raise JaxcoagInputError("solver must be 'levenberg_marquardt', 'gauss_newton' or an optimistix "
                                f"least-squares solver (got {solver!r}).")
    fn = lambda x, args: residuals(model, x, target)

    @jax.jit
    def run(x):
        sol = optx.least_squares(fn, solver, x, max_steps=int(max_steps), throw=False)
        r0, r1 = fn(x, None), fn(sol.value, None)
        return sol.value, sol.result, sol.stats["num_steps"], 0.5 * jnp.sum(r0 ** 2), 0.5 * jnp.sum(r1 ** 2)

    x, res, nsteps, l0, l1 = run(x0)
    msg = "successful" if res == optx.RESULTS.successful else optx.RESULTS[res]
    return FitResult(params={k: float(jnp.exp(v)) for k, v in x.items()}, log_params={k: float(v) for k, v in x.items()},
                     loss=float(l1), steps=int(nsteps), history=np.array([float(l0), float(l1)]), result=str(msg))
