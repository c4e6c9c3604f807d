"""The radial disk as an engine of the one verb: ``jaxcoag.evolve(model, Disk(), None, t_out)``.

:class:`Disk` is the numerical strategy (parity or split mode, loop kind, step budget); the "kernel"
argument of :func:`jaxcoag.evolve` is the :class:`~jaxcoag.disk.model.DiskModel` (every parameter an
array leaf, so gradients and vmap flow to it); the initial condition is ``None`` (the model's own
initial profiles), a :class:`DiskProfile`, or a previous :class:`DiskResult` (continues that run).
:func:`solve` is the short form. Checkpoint / resume / progress come from :func:`jaxcoag.evolve`.

References: Stammler & Birnstiel (2022, ApJ 935, 35); Kidger (2021, diffrax ``diffeqsolve``).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import constants as C
from .._engine import AbstractEngine, AbstractResult, evolve
from .._status import RESULTS, RESULT_NAMES, result_code, result_from_code, result_table
from .._validate import JaxcoagInputError, is_traced
from .solve import DiskState, Parity, Split, advance

__all__ = ["Disk", "DiskProfile", "DiskResult", "solve"]


class DiskProfile(eqx.Module):
    """An initial condition of the radial disk.

    Fields:
        sigma_gas: (nr,) gas surface density [g cm^-2].
        sigma_dust: (nr, nm) dust surface density per mass bin [g cm^-2].
    """

    sigma_gas: jax.Array
    sigma_dust: jax.Array


class Disk(AbstractEngine):
    """The 1-D radial disk engine (viscous gas, dust drift + diffusion, coagulation in every cell).

    Fields:
        mode: :class:`~jaxcoag.disk.solve.Parity` (DustPy's monolithic implicit Euler step; default) or
            :class:`~jaxcoag.disk.solve.Split` (Strang splitting, faster).
        max_steps: step budget per output interval (static; status ``max_steps_reached`` when spent).
        loop: ``"while"`` (default; forward-mode derivatives and vmap) or ``"scan"`` (``max_steps`` guarded
            steps per output interval, checkpointed in two levels; reverse-mode derivatives too: DustPy's default
            model over 4000 steps needs 1.4 GB of temporaries for the gradient, 111 MB forward).
        dt_max: upper bound on the step [s] (default: none, DustPy's rule alone).
        record_steps: record the sizes of the first ``record_steps`` steps since t = 0 (static; default 0, none) in
            ``DiskState.dt_log`` (``DiskResult.step_sizes``), 8 bytes each: the run's own step sequence, to replay it
            with :func:`jaxcoag.disk.solve.replay` (finite differences with the steps held fixed).

    References: Stammler & Birnstiel (2022) §2.5.
    """

    mode: Parity | Split = Parity()
    max_steps: int = eqx.field(static=True, default=100_000)
    loop: str = eqx.field(static=True, default="while")
    dt_max: float | jax.Array = float("inf")
    record_steps: int = eqx.field(static=True, default=0)

    def __check_init__(self):
        if not isinstance(self.mode, (Parity, Split)):
            raise JaxcoagInputError(f"Disk(mode=...) must be jaxcoag.disk.Parity() or jaxcoag.disk.Split(); got "
                                    f"{type(self.mode).__name__}.")
        if isinstance(self.max_steps, bool) or not isinstance(self.max_steps, (int, np.integer)) or self.max_steps < 1:
            raise JaxcoagInputError(f"Disk(max_steps=...) must be a positive int (steps per output interval); got "
                                    f"{self.max_steps!r}.")
        r = self.record_steps
        if isinstance(r, bool) or not isinstance(r, (int, np.integer)) or not 0 <= r <= 10_000_000:
            raise JaxcoagInputError(f"Disk(record_steps=...) must be an int in [0, 1e7] (steps whose sizes are kept, "
                                    f"8 bytes each); got {r!r}.")
        if self.loop not in ("while", "scan"):
            raise JaxcoagInputError(f"Disk(loop=...) must be 'while' or 'scan' (reverse-mode gradients); got "
                                    f"{self.loop!r}.")
        if not is_traced(self.mode.cfl):
            c = float(np.asarray(self.mode.cfl))
            if not (np.isfinite(c) and 0 < c <= 1):
                raise JaxcoagInputError(f"the step factor cfl = {c!r} must be in (0, 1] (DustPy: 0.1).")

    @property
    def name(self) -> str:
        return "disk"

    def _check(self, kernel, initial, t_out, t0, outcome, key):
        from .model import DiskModel

        if not isinstance(kernel, DiskModel):
            raise JaxcoagInputError(f"the disk engine's model is a jaxcoag.disk.DiskModel (e.g. "
                                    f"jaxcoag.disk.dustpy_default()); got {type(kernel).__name__}.")
        if outcome is not None:
            raise JaxcoagInputError("the disk engine's collision outcome is part of the model (v_frag); pass "
                                    "outcome=None.")
        nr, nm = kernel.nr, kernel.nm
        if isinstance(initial, DiskResult):
            shp = initial.final_state.sigma_dust.shape
            k = jnp.shape(initial.final_state.dt_log)[-1]
            if k != self.record_steps:
                raise JaxcoagInputError(f"the run being continued records {k} step sizes; continue it with "
                                        f"record_steps={k} (got {self.record_steps}).")
        elif isinstance(initial, DiskProfile):
            shp = jnp.shape(initial.sigma_dust)
            if jnp.shape(initial.sigma_gas) != (nr,):
                raise JaxcoagInputError(f"DiskProfile.sigma_gas has shape {jnp.shape(initial.sigma_gas)}; the model "
                                        f"has nr = {nr} cells.")
        elif initial is None:
            return
        else:
            raise JaxcoagInputError(f"initial must be None (the model's initial profiles), a jaxcoag.disk.DiskProfile "
                                    f"or a DiskResult to continue; got {type(initial).__name__}.")
        if tuple(shp) != (nr, nm):
            raise JaxcoagInputError(f"the initial dust surface density has shape {tuple(shp)}; the model has "
                                    f"(nr, nm) = ({nr}, {nm}).")
        if isinstance(initial, DiskProfile) and not is_traced(initial.sigma_dust):
            for name in ("sigma_gas", "sigma_dust"):
                v = np.asarray(getattr(initial, name))
                if not np.all(np.isfinite(v)) or np.any(v < 0):
                    raise JaxcoagInputError(f"DiskProfile.{name} must be finite and >= 0 everywhere.")

    def _init(self, kernel, initial, t0, outcome, key):
        if isinstance(initial, DiskResult):
            return initial.final_state
        return _init_jit(kernel, self.mode, initial, jnp.asarray(t0, jnp.float64), self.record_steps)

    def _advance(self, kernel, state, t_seg, outcome):
        return _advance_jit(kernel, self.mode, state, jnp.asarray(t_seg, jnp.float64), self.max_steps, self.loop,
                            self.dt_max)

    def _progress_info(self, state_before, state_after, out, wall_s):
        n = int(state_after.n_steps) - int(state_before.n_steps)
        rate = n / wall_s if wall_s > 0 else float("inf")
        return f"{n} steps ({rate:.3g}/s)"

    def _result(self, kernel, t, outs, state, outcome):
        code = outs["status"]
        last = code[..., -1]
        return DiskResult(t=jnp.asarray(t, jnp.float64), status=result_from_code(last), r=kernel.r, ri=kernel.ri,
                          m=kernel.m, rho_s=kernel.rho_s, sigma_gas=outs["sigma_gas"], sigma_dust=outs["sigma_dust"],
                          n_steps=outs["n_steps"], m_acc_gas=outs["m_acc_gas"], m_out_gas=outs["m_out_gas"],
                          split_error=outs["split_error"],
                          St=_stokes_jit(kernel, outs["sigma_gas"]), status_code=code, final_state=state)


@eqx.filter_jit
def _init_jit(model, mode, initial, t0, record_steps):
    """The engine state at t0 (compiled: the initial profiles, the first radial velocity and step size; an empty
    (NaN) record of ``record_steps`` step sizes)."""
    if initial is None:
        initial = model.initial()
    z = jnp.zeros((), jnp.float64)
    sg = jnp.asarray(initial.sigma_gas, jnp.float64)
    sd = jnp.asarray(initial.sigma_dust, jnp.float64)
    v_rad, rate = model.start(sg, sd)
    return DiskState(t=t0, sigma_gas=sg, sigma_dust=sd, m_acc_gas=z, m_out_gas=z, n_steps=jnp.zeros((), jnp.int64),
                     v_rad=v_rad, dt_next=mode.cfl * rate, split_error=z, status=result_code(RESULTS.successful),
                     dt_log=jnp.full((record_steps,), jnp.nan, jnp.float64))


@eqx.filter_jit
def _stokes_jit(model, sigma_gas):
    """(T, nr, nm) Stokes numbers of the output gas profiles."""
    return jax.vmap(model.stokes_number)(sigma_gas)


@eqx.filter_jit
def _advance_jit(model, mode, state, t_seg, max_steps, loop, dt_max):
    """:func:`~jaxcoag.disk.solve.advance` compiled once per model structure and segment length (checkpointed
    runs call it once per segment)."""
    return advance(model, mode, state, t_seg, max_steps=max_steps, loop=loop, dt_max=dt_max)


class DiskResult(AbstractResult):
    """Result of a radial disk run (one member; a vmapped run adds a leading batch axis).

    Fields:
        t: (T,) output times [s].
        status: :class:`jaxcoag.RESULTS` item of the run (last output).
        r: (nr,) cell centres [cm]; ri: (nr + 1,) interfaces [cm]; m: (nm,) mass grid [g].
        rho_s: material density [g cm^-3].
        sigma_gas: (T, nr) gas surface density [g cm^-2].
        sigma_dust: (T, nr, nm) dust surface density per mass bin [g cm^-2].
        St: (T, nr, nm) Stokes numbers.
        n_steps: (T,) steps taken up to each output.
        m_acc_gas: (T,) gas mass through the inner boundary since t = 0 [g]; m_out_gas: through the outer.
        split_error: (T,) largest per-step splitting-error estimate so far (``Split`` mode: the largest
            disk-integrated mass-weighted difference of one step, sum |Lie - Strang| A / sum Strang A over the
            interior cells and bins; 0 in parity mode).
        status_code: (T,) int status per output.
        final_state: the :class:`~jaxcoag.disk.solve.DiskState` at ``t[-1]`` (pass the result as ``initial``
            to continue).

    The 0-D accessors of :class:`jaxcoag.AbstractResult` (``mass_per_bin``, ``moments``, ...) give the
    disk-integrated totals: mass per bin [g], number per bin, sum of N m^p.
    """

    t: jax.Array
    status: RESULTS
    r: jax.Array
    ri: jax.Array
    m: jax.Array
    rho_s: jax.Array
    sigma_gas: jax.Array
    sigma_dust: jax.Array
    St: jax.Array
    n_steps: jax.Array
    m_acc_gas: jax.Array
    m_out_gas: jax.Array
    split_error: jax.Array
    status_code: jax.Array
    final_state: DiskState

    # ------------------------------------------------------------------ derived
    @property
    def step_sizes(self):
        """(K,) sizes [s] of the run's first K steps since t = 0, NaN past the last step taken (K: the engine's
        ``record_steps``; empty by default). ``step_sizes[:n_steps[-1]]`` is the run's step sequence, for
        :func:`jaxcoag.disk.solve.replay`."""
        return self.final_state.dt_log

    @property
    def area(self):
        """(nr,) annulus areas [cm^2]."""
        return jnp.pi * (self.ri[..., 1:] ** 2 - self.ri[..., :-1] ** 2)

    @property
    def a(self):
        """(nm,) particle radii [cm] of the mass grid (compact spheres of rho_s)."""
        return (3.0 * self.m / (4.0 * jnp.pi * self.rho_s)) ** (1.0 / 3.0)

    @property
    def dust_mass(self):
        """(T,) total dust mass [g]."""
        return jnp.sum(self.sigma_dust.sum(-1) * jnp.expand_dims(self.area, -2), axis=-1)

    @property
    def gas_mass(self):
        """(T,) total gas mass [g]."""
        return jnp.sum(self.sigma_gas * jnp.expand_dims(self.area, -2), axis=-1)

    @property
    def sigma_dust_total(self):
        """(T, nr) total dust surface density [g cm^-2]."""
        return self.sigma_dust.sum(-1)

    def a_peak(self, smooth=False):
        """(T, nr) particle radius [cm] where the dust mass per bin peaks in each cell.

        ``smooth=False``: the radius of the bin holding the most mass (piecewise constant in the parameters, its
        derivative is zero). ``smooth=True``: the vertex of the parabola through ln Sigma_d of that bin and its two
        neighbours, in ln a (exact for a log-normal distribution; differentiable, for fits and gradients of the
        peak size); a peak in the first or last bin returns that bin's radius.
        """
        sd = self.sigma_dust
        a = jnp.broadcast_to(jnp.expand_dims(self.a, (-3, -2)), sd.shape)  # (..., T, nr, nm)

        def at(v, idx):  # v[..., idx] per (t, r); batched results keep their own grids
            return jnp.take_along_axis(v, idx[..., None], axis=-1)[..., 0]

        k = jnp.argmax(sd, axis=-1)
        if not smooth:
            return at(a, k)
        nm = self.m.shape[-1]
        if nm < 3:
            raise JaxcoagInputError("a_peak(smooth=True) needs at least 3 mass bins; use a_peak().")
        kc = jnp.clip(k, 1, nm - 2)
        la = jnp.log(a)
        y = jnp.log(jnp.maximum(sd, jnp.finfo(jnp.float64).tiny))
        ym, y0, yp = (at(y, kc + j) for j in (-1, 0, 1))
        xm, x0, xp = (at(la, kc + j) for j in (-1, 0, 1))
        # vertex of the parabola through (xm, ym), (x0, y0), (xp, yp) (non-uniform spacing allowed)
        num = (x0 - xm) ** 2 * (y0 - yp) - (x0 - xp) ** 2 * (y0 - ym)
        den = (x0 - xm) * (y0 - yp) - (x0 - xp) * (y0 - ym)
        curved = (den != 0.0) & (k == kc)
        off = jnp.clip(0.5 * num / jnp.where(curved, den, 1.0), -(x0 - xm), xp - x0)
        return jnp.where(curved, jnp.exp(x0 - off), at(a, k))

    def a_mean(self):
        """(T, nr) mass-weighted geometric mean particle radius exp(sum_i Sigma_i ln a_i / sum_i Sigma_i) [cm] in
        each cell: a smooth size measure (differentiable everywhere, unlike the peak of a bimodal distribution)."""
        s = self.sigma_dust
        la = jnp.expand_dims(jnp.log(self.a), (-3, -2))
        return jnp.exp(jnp.sum(s * la, axis=-1) / jnp.sum(s, axis=-1))

    def mass_per_bin(self, edges=None):
        """(T, nm) disk-integrated dust mass per mass bin [g] (``edges`` must be None: the model's bins)."""
        self._no_edges(edges)
        return jnp.einsum("...trm,...r->...tm", self.sigma_dust, self.area)

    def number_per_bin(self, edges=None):
        """(T, nm) disk-integrated number of particles per mass bin."""
        return self.mass_per_bin(edges) / self.m[..., None, :]

    def moments(self, p):
        """(T,) disk-integrated sum over bins of N_i m_i^p (p = 1: dust mass [g])."""
        return jnp.sum(self.number_per_bin() * self.m[..., None, :] ** p, axis=-1)

    def bin_edges(self, edges=None):
        """Mass-bin edges [g]: geometric midpoints of the grid, extrapolated at the ends."""
        self._no_edges(edges)
        m = np.asarray(self.m, np.float64)
        lm = np.log(m)
        mid = 0.5 * (lm[1:] + lm[:-1])
        return np.exp(np.concatenate([[lm[0] - (mid[0] - lm[0])], mid, [lm[-1] + (lm[-1] - mid[-1])]]))

    @staticmethod
    def _no_edges(edges):
        if edges is not None:
            raise JaxcoagInputError("the disk result's per-bin accessors use the model's own mass grid; pass "
                                    "edges=None.")

    def to_xarray(self, *, attrs=None, kernel=None, edges=None):
        """Labelled dataset: dims ``t``, ``r``, ``m``; coordinates ``t_yr``, ``r_au``, ``a``; variables
        ``sigma_gas`` (t, r), ``sigma_dust`` (t, r, m), ``St`` (t, r, m), ``dust_mass`` / ``gas_mass`` (t),
        ``a_peak`` (t, r), ``m_acc_gas`` (t), ``n_steps`` (t), ``status`` (t)."""
        import xarray as xr

        if jnp.ndim(self.t) != 1:
            raise JaxcoagInputError("to_xarray takes one run; index a vmapped result first "
                                    "(jax.tree_util.tree_map(lambda x: x[i], result)).")
        f = lambda x: np.asarray(x, np.float64)  # noqa: E731
        t = f(self.t)
        codes = np.asarray(self.status_code, np.int32)
        ds = xr.Dataset(
            {
                "sigma_gas": (("t", "r"), f(self.sigma_gas), {"units": "g cm-2", "long_name": "gas surface density"}),
                "sigma_dust": (("t", "r", "m"), f(self.sigma_dust),
                               {"units": "g cm-2", "long_name": "dust surface density per mass bin"}),
                "St": (("t", "r", "m"), f(self.St), {"units": "1", "long_name": "Stokes number"}),
                "dust_mass": (("t",), f(self.dust_mass), {"units": "g", "long_name": "total dust mass"}),
                "gas_mass": (("t",), f(self.gas_mass), {"units": "g", "long_name": "total gas mass"}),
                "a_peak": (("t", "r"), f(self.a_peak()), {"units": "cm",
                                                          "long_name": "radius of the bin holding most dust mass"}),
                "m_acc_gas": (("t",), f(self.m_acc_gas), {"units": "g",
                                                          "long_name": "gas mass through the inner boundary"}),
                "n_steps": (("t",), np.asarray(self.n_steps, np.int64), {"long_name": "steps taken"}),
                "status": (("t",), codes, {"long_name": "jaxcoag.RESULTS code",
                                           "flag_values": np.arange(len(RESULT_NAMES), dtype=np.int32),
                                           "flag_meanings": " ".join(RESULT_NAMES)}),
            },
            coords={"t": ("t", t, {"units": "s"}), "t_yr": ("t", t / C.yr, {"units": "yr"}),
                    "r": ("r", f(self.r), {"units": "cm", "long_name": "cell centre"}),
                    "r_au": ("r", f(self.r) / C.AU, {"units": "au"}),
                    "r_edge": ("r_edge", f(self.ri), {"units": "cm", "long_name": "cell interfaces"}),
                    "m": ("m", f(self.m), {"units": "g", "long_name": "mass grid"}),
                    "a": ("m", f(self.a), {"units": "cm", "long_name": "particle radius"})},
            attrs={"engine": "disk", "status": RESULT_NAMES[int(codes[-1])],
                   "status_message": result_table()[int(codes[-1])][1]},
        )
        if attrs:
            ds.attrs.update(attrs)
        return ds


def solve(model, t_out, *, mode=None, initial=None, max_steps=100_000, loop="while", checkpoint=None, progress=False,
          throw=True, dt_max=float("inf"), record_steps=0):
    """Evolve a radial disk model to the output times (short form of ``jaxcoag.evolve(model, Disk(...), ...)``).

    Arguments:
        model: :class:`~jaxcoag.disk.model.DiskModel` (e.g. :func:`~jaxcoag.disk.dustpy_default`).
        t_out: output times [s], strictly increasing, >= 0 (t_out[0] = 0 outputs the initial state).
        mode: :class:`~jaxcoag.disk.Parity` (default) or :class:`~jaxcoag.disk.Split`.
        initial: None (the model's initial profiles), a :class:`DiskProfile`, or a :class:`DiskResult` to continue.
        max_steps, loop, dt_max, record_steps: see :class:`Disk`.
        checkpoint, progress, throw: as :func:`jaxcoag.evolve`.

    Returns: :class:`DiskResult` with ``.t`` [s], ``.r`` [cm], ``.m`` [g], ``.sigma_dust`` (t, r, m)
    [g cm^-2], ``.sigma_gas`` (t, r) [g cm^-2], ``.a`` [cm], ``.St`` and ``.to_xarray()``.

    References: Stammler & Birnstiel (2022, ApJ 935, 35).
    """
    engine = Disk(mode=Parity() if mode is None else mode, max_steps=max_steps, loop=loop, dt_max=dt_max,
                  record_steps=record_steps)
    return evolve(model, engine, initial, t_out, checkpoint=checkpoint, progress=progress, throw=throw)
