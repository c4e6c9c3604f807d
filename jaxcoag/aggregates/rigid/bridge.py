"""Bridge from the rigid-aggregate box to coagulation (Richardson 1995 §3, eqs. 29-31; Smoluchowski 1916).

The periodic box of :mod:`~jaxcoag.aggregates.rigid.box` simulates every collision explicitly; the
coagulation equation (R29, Smoluchowski)::

    dN_k/dt = ½ Σ_{i+j=k} a_ij N_i N_j − N_k Σ_i a_ik N_i            (numbers N_k in the box volume V)

describes the same population through a kernel. Here ``a_ij = K_ij / V`` [1/time] is the rate per pair of
particles in the box and ``K_ij`` [length³/time] the kernel of the number-density form
``dn_k/dt = ½ Σ K_ij n_i n_j − …`` (n = N/V). For model (i) ``K = σ⟨v⟩ = π(2R)² (4/3) v0`` and
``a = α = σ⟨v⟩/V`` (R95 §3), so ``N(t) = N0/(1 + α N0 t/2)`` (R30) and
``N_k = N0 f² (1 − f)^(k−1)``, ``f = N/N0`` (R31).

* :func:`measured_kernel` estimates K_ij from a box run's collision log (coagulations only), with its
  Poisson error; :func:`kernel_from_arrays` is the same estimator on plain arrays;
* :func:`smoluchowski` integrates R29 over k-mers k = 1..kmax (exact discrete masses; diffrax);
* :func:`binned_run` runs the binned engine of this package (``jaxcoag.evolve`` with ``jaxcoag.Binned``)
  in the box's units (number density N/V, kernel K = a V);
* :func:`compare_model_i` puts model (i)'s box, the binned engine and the k-mer integration with the
  constant kernel α side by side with R30/R31; :func:`compare_measured` does the same for any model
  (iii, iv) with the kernel measured from the box's own log (:class:`ClassKernel`: piecewise constant over
  mass classes).

Units: the box's (R95: arbitrary length and time units; masses in the run's mass unit, m0 = 1 by default);
cgs when the box's numbers are cgs. Nothing here is differentiable (the estimator counts events).

References: Richardson (1995, Icarus 115, 320) §3, eqs. (29)-(31); Smoluchowski (1916); Gillespie (1972)
(the estimator count/exposure is the maximum-likelihood rate of a Poisson process with a known exposure).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..._validate import JaxcoagInputError
from ...kernels import AbstractKernel
from .box import COAGULATION, BoxResult

__all__ = ["MeasuredKernel", "ClassKernel", "class_index", "kernel_from_arrays", "path_from_log", "measured_kernel",
           "octave_edges", "rate_table", "smoluchowski", "binned_run", "compare_model_i", "compare_measured"]


# ------------------------------------------------------------------------------------------------ classes
def _check_edges(edges):
    e = np.asarray(edges, np.float64)
    if e.ndim != 1 or e.size < 2 or not np.all(np.isfinite(e)):
        raise JaxcoagInputError(f"edges must be a 1-D array of at least 2 finite masses [mass]; got {edges!r}.")
    if not np.all(np.diff(e) > 0):
        raise JaxcoagInputError("edges must be strictly increasing masses [mass]; sort them and drop duplicates.")
    return e


def class_index(m, edges):
    """Mass class of masses ``m`` [mass]: class c holds edges[c] <= m < edges[c+1]; -1 outside the edges."""
    e = _check_edges(edges)
    m = np.asarray(m, np.float64)
    c = np.searchsorted(e, m, side="right") - 1
    return np.where((c >= 0) & (c < e.size - 1), c, -1)


def octave_edges(m0, kmax):
    """Class edges ``(0.5, 1.5, 2.5, 4.5, 8.5, …) m0`` up to past ``kmax m0``: the classes k = 1, 2, 3-4, 5-8, …
    (one class per factor 2 in mass; the unit of the spectra is the monomer mass m0 [mass])."""
    k = [0.5, 1.5]
    while k[-1] < kmax:
        k.append(2.0 * k[-1] - 0.5)
    return np.asarray(k) * float(m0)


# ------------------------------------------------------------------------------------------------ estimator
class MeasuredKernel(NamedTuple):
    """A kernel measured from collisions (see :func:`kernel_from_arrays`); all (C, C) arrays are symmetric.

    Fields:
        K: kernel estimate [length³/time] (NaN where the exposure is zero: never both present).
        sigma: its Poisson standard error V sqrt(c)/E [length³/time] (for c = 0: that of one count).
        counts: (C, C) int number c_ij of coagulations between classes i and j.
        exposure: (C, C) E_ij = ∫ N_i N_j dt (i ≠ j) or ∫ N_i (N_i − 1)/2 dt [time] (pairs × time).
        exposure_err: (C, C) bound on the quadrature error of E [time] (0 for the exact path).
        edges: (C + 1,) class edges [mass].
        V: box volume [length³].
    """

    K: np.ndarray
    sigma: np.ndarray
    counts: np.ndarray
    exposure: np.ndarray
    exposure_err: np.ndarray
    edges: np.ndarray
    V: float

    @property
    def rate(self):
        """(C, C) rate per pair a_ij = K_ij / V [1/time] (R95's α for model i)."""
        return self.K / self.V

    @property
    def rate_sigma(self):
        """(C, C) Poisson standard error of :attr:`rate` [1/time]."""
        return self.sigma / self.V


def _pairs(N):
    """(T, C, C) number of distinct pairs: N_i N_j off the diagonal, N_i (N_i − 1)/2 on it."""
    N = np.asarray(N, np.float64)
    P = N[:, :, None] * N[:, None, :]
    d = np.arange(N.shape[1])
    P[:, d, d] = 0.5 * N * (N - 1.0)
    return P


def kernel_from_arrays(t_coll, m_a, m_b, t, N, V, edges, *, quadrature="step"):
    """Kernel K_ij = V c_ij / ∫ pairs_ij dt from coagulation times and masses and a class-occupation table.

    For mass classes ``edges`` (class c: edges[c] <= m < edges[c+1]), ``c_ij`` counts the coagulations of a
    class-i with a class-j particle at times ``t[0] < t_coll <= t[-1]``, and the exposure
    ``E_ij = ∫ N_i N_j dt`` (i ≠ j) or ``∫ N_i (N_i − 1)/2 dt`` (i = j) over [t[0], t[-1]]. For a
    Poisson process of rate a_ij per pair, c_ij / E_ij is the maximum-likelihood rate with relative
    standard error 1/sqrt(c_ij), so ``K = V c/E``, ``sigma = V sqrt(c)/E`` (one count where c = 0). To test
    a hypothesised kernel K0, use the expected-count error ``K0 / sqrt(K0 E / V)`` instead: the
    observed-count error is biased small after a downward fluctuation.

    Arguments:
        t_coll, m_a, m_b: (E,) coagulation times [time] and the two masses before the merger [mass].
        t: (T,) increasing times [time] of the occupation table (T >= 2).
        N: (T, C) number of particles of each class at ``t`` (in the volume V).
        V: volume [length³] (box: L³).
        edges: (C + 1,) strictly increasing class edges [mass].
        quadrature: "step" - N[i] holds on [t[i], t[i+1]) (exact for the piecewise-constant path of
            :func:`path_from_log`); "trapezoid" - trapezoidal rule on samples (the box's outputs). Its
            error is bounded by Σ Δt |Δ pairs|/2 per interval when pairs_ij is monotone between samples
            (true when classes i, j only lose or only gain members in the interval; otherwise an
            estimate); it is returned as ``exposure_err`` and falls like 1/T for a fixed run.

    Returns:
        :class:`MeasuredKernel`.

    Raises:
        JaxcoagInputError: bad shapes, edges not increasing, no coagulation in the window, a mass outside
        the edges.

    References: Richardson (1995) eq. (29) (the kernel of the coagulation equation); Gillespie (1972).
    """
    e = _check_edges(edges)
    C = e.size - 1
    t = np.asarray(t, np.float64)
    N = np.asarray(N, np.float64)
    tc, ma, mb = (np.asarray(x, np.float64).reshape(-1) for x in (t_coll, m_a, m_b))
    if t.ndim != 1 or t.size < 2 or not np.all(np.diff(t) > 0):
        raise JaxcoagInputError("t must be at least 2 strictly increasing times [time].")
    if N.shape != (t.size, C):
        raise JaxcoagInputError(f"N must have shape (len(t), n_classes) = ({t.size}, {C}); got {N.shape}.")
    if not (tc.shape == ma.shape == mb.shape):
        raise JaxcoagInputError("t_coll, m_a and m_b must have the same length (one entry per coagulation).")
    if not (np.ndim(V) == 0 and float(V) > 0):
        raise JaxcoagInputError(f"V must be a volume > 0 [length^3]; got {V!r}.")
    if quadrature not in ("step", "trapezoid"):
        raise JaxcoagInputError(f"quadrature must be 'step' or 'trapezoid'; got {quadrature!r}.")
    sel = (tc > t[0]) & (tc <= t[-1])
    if not np.any(sel):
        raise JaxcoagInputError(f"no coagulation in the window ({t[0]:g}, {t[-1]:g}]: nothing to measure a kernel "
                                "from (run longer, or use a model that coagulates).")
    ca, cb = class_index(ma[sel], e), class_index(mb[sel], e)
    if np.any(ca < 0) or np.any(cb < 0):
        bad = np.concatenate([ma[sel][ca < 0], mb[sel][cb < 0]])
        raise JaxcoagInputError(f"coagulating masses outside the class edges [{e[0]:g}, {e[-1]:g}) (e.g. {bad[0]:g}); "
                                "widen edges.")
    counts = np.zeros((C, C), np.int64)
    np.add.at(counts, (np.minimum(ca, cb), np.maximum(ca, cb)), 1)
    counts = counts + np.triu(counts, 1).T
    P = _pairs(N)
    dt = np.diff(t)[:, None, None]
    if quadrature == "step":
        E = np.sum(P[:-1] * dt, axis=0)
        Eerr = np.zeros_like(E)
    else:
        E = np.sum(0.5 * (P[:-1] + P[1:]) * dt, axis=0)
        Eerr = np.sum(0.5 * np.abs(P[1:] - P[:-1]) * dt, axis=0)
    V = float(V)
    with np.errstate(divide="ignore", invalid="ignore"):
        K = np.where(E > 0, V * counts / E, np.nan)
        sig = np.where(E > 0, V * np.sqrt(np.maximum(counts, 1)) / E, np.nan)
    return MeasuredKernel(K=K, sigma=sig, counts=counts, exposure=E, exposure_err=Eerr, edges=e, V=V)


def path_from_log(t0, N0, t_coll, m_a, m_b, edges):
    """Exact piecewise-constant class occupation from a start table and the coagulations after it.

    Arguments:
        t0: start time [time]; N0: (C,) particles per class at t0.
        t_coll, m_a, m_b: coagulation times [time] (increasing, > t0) and masses before the merger [mass].
        edges: (C + 1,) class edges [mass] (the merged masses m_a + m_b must lie inside).

    Returns:
        (t, N): (E + 1,) times [t0, t_coll...] and (E + 1, C) occupation holding on [t[i], t[i+1]).

    References: Richardson (1995) §3 (a coagulation removes particles m_a, m_b and adds m_a + m_b).
    """
    e = _check_edges(edges)
    C = e.size - 1
    tc, ma, mb = (np.asarray(x, np.float64).reshape(-1) for x in (t_coll, m_a, m_b))
    ci, cj, ck = class_index(ma, e), class_index(mb, e), class_index(ma + mb, e)
    if np.any(ci < 0) or np.any(cj < 0) or np.any(ck < 0):
        raise JaxcoagInputError(f"a coagulating or merged mass lies outside the class edges [{e[0]:g}, {e[-1]:g}); "
                                "widen edges.")
    d = np.zeros((tc.size, C), np.int64)
    r = np.arange(tc.size)
    np.add.at(d, (r, ci), -1)
    np.add.at(d, (r, cj), -1)
    np.add.at(d, (r, ck), 1)
    N = np.concatenate([np.asarray(N0, np.int64)[None, :], np.asarray(N0, np.int64)[None, :] + np.cumsum(d, 0)])
    return np.concatenate([[float(t0)], tc]), N


def _class_table(res, e):
    """(T, C) particles per class at the box's outputs."""
    M = np.asarray(res.outs["M"])
    al = np.asarray(res.outs["alive"])
    c = np.where(al, class_index(np.where(al, M, e[0] - 1.0), e), -1)
    if np.any(al & (c < 0)):
        raise JaxcoagInputError("a live aggregate mass lies outside the class edges; widen edges.")
    C = e.size - 1
    return np.stack([np.bincount(ci[ci >= 0], minlength=C) for ci in c])


def measured_kernel(result, edges=None, *, method="log"):
    """The coagulation kernel measured from a box run: rate per pair of mass classes (R95 eq. 29).

    ``K_ij = V c_ij / ∫ N_i N_j dt`` (``N_i (N_i − 1)/2`` for i = j) with V = L³ the box volume, c_ij the
    number of coagulations (log outcome ``COAGULATION``; bounces are not counted) between classes i and j
    in (t[0], t[-1]] of the run's outputs, and the exposure over the same window (see
    :func:`kernel_from_arrays`). Model (i) must give ``K = σ⟨v⟩ = α V`` for every class pair.

    Arguments:
        result: :class:`~jaxcoag.aggregates.rigid.box.BoxResult` with at least 2 outputs and a collision
            log that did not overflow.
        edges: class edges [mass] (strictly increasing); None: one class per number of member spheres,
            ``(k ± 1/2) m0`` for k = 1..kmax, kmax the largest aggregate formed.
        method: "log" (default) - the exposure from the exact piecewise-constant path rebuilt from the log
            (checked to equal the recorded spectrum at every output; no quadrature error); "outputs" -
            the trapezoidal rule on the recorded outputs (error bound in ``exposure_err``; use many
            outputs: it falls like the output spacing).

    Returns:
        :class:`MeasuredKernel` (K [length³/time], sigma, counts, exposure [time], …).

    Raises:
        JaxcoagInputError: not a BoxResult, fewer than 2 outputs, a full log, no coagulation, bad edges, a
        log inconsistent with the outputs.

    References: Richardson (1995) §3, eqs. (29)-(31).
    """
    if not isinstance(result, BoxResult):
        raise JaxcoagInputError(f"measured_kernel needs a rigid.BoxResult (rigid.run(...)); "
                                f"got {type(result).__name__}.")
    if method not in ("log", "outputs"):
        raise JaxcoagInputError(f"method must be 'log' or 'outputs'; got {method!r}.")
    t = np.asarray(result.t, np.float64)
    if t.size < 2:
        raise JaxcoagInputError("the run needs at least 2 output times to measure a kernel.")
    flags = int(np.asarray(result.final_state.flags))
    if flags & 1:
        raise JaxcoagInputError("the collision log overflowed (status capacity_exceeded): rerun with "
                                "rigid.RigidBox(log_capacity=...) large enough for every collision.")
    if flags & 6:
        raise JaxcoagInputError("the box run stopped early (neighbour-list / cell overflow or step budget; status "
                                f"{result.status}): its later outputs hold no collisions; rerun with a larger "
                                "rigid.RigidBox(neighbors=..., cell_capacity=..., max_steps=...).")
    log = result.collision_log
    m0 = float(np.asarray(result.m0))
    coag = log["outcome"] == COAGULATION
    tc, ma, mb = log["t"][coag], log["m_a"][coag], log["m_b"][coag]
    if edges is None:
        kmax = int(np.max(np.asarray(result.outs["nmem"])))
        if coag.any():
            kmax = max(kmax, int(round(float(np.max(ma + mb)) / m0)))
        edges = (np.arange(kmax + 1) + 0.5) * m0
    e = _check_edges(edges)
    N = _class_table(result, e)
    V = float(np.asarray(result.final_state.par["L"])) ** 3
    if method == "outputs":
        return kernel_from_arrays(tc, ma, mb, t, N, V, e, quadrature="trapezoid")
    w = (tc > t[0]) & (tc <= t[-1])
    tp, Np = path_from_log(t[0], N[0], tc[w], ma[w], mb[w], e)
    # the path at every output (state after all events at times <= t_k) must equal the recorded table
    idx = np.searchsorted(tp, t, side="right") - 1
    if not np.array_equal(Np[idx], N):
        raise JaxcoagInputError("the collision log does not reproduce the recorded spectra (an incomplete log?); "
                                "use method='outputs'.")
    # collisions at one instant: keep the last state of each time (zero-length intervals add nothing)
    tp = np.concatenate([tp, [t[-1]]])
    Np = np.concatenate([Np, Np[-1:]])
    keep = np.concatenate([np.diff(tp) > 0, [True]])
    return kernel_from_arrays(tc[w], ma[w], mb[w], tp[keep], Np[keep], V, e, quadrature="step")


# ------------------------------------------------------------------------------------------------ tabulated kernel
def _filled(mk):
    """K of a MeasuredKernel with the unmeasured (NaN) class pairs set to the nearest measured pair."""
    from scipy import ndimage

    K = np.asarray(mk.K, np.float64)
    bad = ~np.isfinite(K)
    if bad.all():
        raise JaxcoagInputError("the measured kernel has no finite entry (no exposure at all).")
    if bad.any():
        _, (ii, jj) = ndimage.distance_transform_edt(bad, return_indices=True)
        K = K[ii, jj]
    return K


def rate_table(mk, kmax, m0=1.0):
    """(kmax, kmax) rate per pair a_ij [1/time] on k-mers k = 1..kmax from a :class:`MeasuredKernel`.

    Piecewise constant over the classes: a_ij = K[c(i m0), c(j m0)] / V. Class pairs without exposure
    (never present together; NaN) take the value of the nearest measured class pair (Euclidean in class
    indices), and k-mers beyond the top edge take the top class. Unmeasured entries are therefore an
    extrapolation; their counts are zero.
    """
    K = _filled(mk)
    e = np.asarray(mk.edges)
    c = np.clip(np.searchsorted(e, np.arange(1, kmax + 1) * float(m0), side="right") - 1, 0, K.shape[0] - 1)
    return K[c[:, None], c[None, :]] / mk.V


class ClassKernel(AbstractKernel):
    """Tabulated kernel K(m1, m2) [length³/time], piecewise constant over mass classes (binned-engine input).

    ``K(m1, m2) = table[c(m1), c(m2)]`` with c the class of ``edges`` (masses below the first edge take
    class 0, above the last the top class). Build it from a :class:`MeasuredKernel` with
    :meth:`from_measured` (NaN entries filled as in :func:`rate_table`).

    References: Richardson (1995) eq. (29) (a kernel per pair of masses).
    """

    table: jax.Array
    edges: jax.Array

    def __init__(self, table, edges):
        e = _check_edges(edges)
        tab = np.asarray(table, np.float64)
        if tab.shape != (e.size - 1, e.size - 1) or not np.all(np.isfinite(tab)) or np.any(tab < 0):
            raise JaxcoagInputError(f"table must be a finite, non-negative ({e.size - 1}, {e.size - 1}) array "
                                    "[length^3/time].")
        self.table = jnp.asarray(tab)
        self.edges = jnp.asarray(e)

    @classmethod
    def from_measured(cls, mk):
        """The :class:`ClassKernel` of a :class:`MeasuredKernel` (unmeasured pairs: nearest measured pair)."""
        return cls(_filled(mk), mk.edges)

    def __call__(self, m1, m2, x1=None, x2=None):
        C = self.table.shape[0]
        c1 = jnp.clip(jnp.searchsorted(self.edges, m1, side="right") - 1, 0, C - 1)
        c2 = jnp.clip(jnp.searchsorted(self.edges, m2, side="right") - 1, 0, C - 1)
        return self.table[c1, c2]


# ------------------------------------------------------------------------------------------------ solvers
@functools.partial(jax.jit, static_argnames=("rtol", "atol"))
def _smol_solve(A, y0, ts, t0, rtol, atol):
    """diffrax solution of R29 on k-mers (compiled once per kmax, number of outputs and tolerances)."""
    import diffrax

    kmax = y0.shape[0]
    k = jnp.arange(1, kmax + 1)
    idx = (k[:, None] + k[None, :] - 1).reshape(-1)  # 0-based slot of the (i+j)-mer; >= kmax: dropped

    def rhs(t, y, args):
        P = (A * y[:, None] * y[None, :]).reshape(-1)
        gain = 0.5 * jnp.zeros(kmax, y.dtype).at[idx].add(P, mode="drop")
        return gain - y * (A @ y)

    sol = diffrax.diffeqsolve(diffrax.ODETerm(rhs), diffrax.Tsit5(), t0, ts[-1], dt0=None, y0=y0,
                              saveat=diffrax.SaveAt(ts=ts),
                              stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
                              max_steps=1_000_000)
    return sol.ys


def smoluchowski(rate, n_init, t_out, *, t0=None, rtol=1e-10, atol=1e-10):
    """Discrete coagulation equation (R29) over k-mers k = 1..kmax, integrated with diffrax (Tsit5, PID).

    ``dN_k/dt = ½ Σ_{i+j=k} a_ij N_i N_j − N_k Σ_{i<=kmax} a_ik N_i``; products with i + j > kmax leave
    the system (their mass is reported as ``lost``). Exact for integer masses (no binning).

    Arguments:
        rate: (kmax, kmax) symmetric rate per pair a_ij [1/time] (kernel / volume), or a scalar (constant).
        n_init: (kmax,) numbers of k-mers at t0 (e.g. N0 monomers: ``[N0, 0, …]``).
        t_out: (T,) increasing output times [time] (>= t0).
        t0: start time [time] (default t_out[0]).
        rtol, atol: tolerances of the PID step controller (atol in numbers of particles).

    Returns:
        dict: ``t`` (T,), ``n`` (T, kmax) numbers of k-mers, ``N`` (T,) total number, ``lost`` (T,) mass
        fraction carried beyond kmax.

    References: Smoluchowski (1916); Richardson (1995) eqs. (29)-(31); Kidger (2021, diffrax).
    """
    n_init = np.asarray(n_init, np.float64)
    if n_init.ndim != 1 or n_init.size < 2 or np.any(n_init < 0) or not np.all(np.isfinite(n_init)):
        raise JaxcoagInputError("n_init must be a 1-D array of finite numbers >= 0 of k-mers (k = 1..kmax).")
    kmax = n_init.size
    a = np.asarray(rate, np.float64)
    a = np.full((kmax, kmax), float(a)) if a.ndim == 0 else a
    if a.shape != (kmax, kmax) or not np.all(np.isfinite(a)) or np.any(a < 0):
        raise JaxcoagInputError(f"rate must be a finite non-negative scalar or ({kmax}, {kmax}) array [1/time].")
    t_out = np.asarray(t_out, np.float64)
    t0 = float(t_out[0]) if t0 is None else float(t0)
    if t_out.ndim != 1 or np.any(np.diff(t_out) <= 0) or t_out[0] < t0:
        raise JaxcoagInputError("t_out must be strictly increasing times >= t0.")
    k = np.arange(1, kmax + 1)
    if t_out[-1] == t0:
        n = np.tile(n_init, (t_out.size, 1))
    else:
        n = np.array(_smol_solve(jnp.asarray(a), jnp.asarray(n_init), jnp.asarray(t_out), jnp.asarray(t0),
                                 float(rtol), float(atol)))
        if t_out[0] == t0:
            n[0] = n_init
    mass0 = float(np.sum(k * n_init))
    return dict(t=t_out, n=n, N=n.sum(-1), lost=1.0 - (n @ k) / mass0)


def binned_run(kernel, initial, t_out, *, V, grid, t0=None, rtol=1e-8, atol=1e-12):
    """Run the binned engine (``jaxcoag.evolve`` with ``jaxcoag.Binned(grid)``) in the box's units.

    Arguments:
        kernel: a ``jaxcoag.kernels`` kernel [length³/time] (``Constant(α V)`` for model i, or a
            :class:`ClassKernel`).
        initial: ``jaxcoag.Monodisperse(m0, rho_d = N0 m0 / V)``, or (nbins,) number density per bin
            [1/length³] on ``grid``.
        t_out: (T,) output times [time]; V: box volume [length³]; grid: ``jaxcoag.MassGrid`` [mass].
        t0: start time (default 0); rtol, atol: the engine's tolerances.

    Returns:
        dict: ``res`` (the BinnedResult), ``N`` (T,) particles in V, ``n_bin`` (T, nbins) particles per bin
        in V, ``mass_drift`` (T,).

    References: Smoluchowski (1916); Kovetz & Olund (1969), Brauer et al. (2008) App. A (two-bin scheme).
    """
    import jaxcoag as jc

    eng = jc.Binned(grid, rtol=rtol, atol=atol)
    res = jc.evolve(kernel, eng, initial, jnp.asarray(t_out, jnp.float64), t0=t0)
    nb = np.asarray(res.number_per_bin()) * float(V)
    return dict(res=res, N=nb.sum(-1), n_bin=nb, mass_drift=np.asarray(res.mass_drift))


def _grid_for(m0, kmax, bpd):
    import jaxcoag as jc

    return jc.MassGrid.log(m0 * 10 ** (-0.5 / bpd), 2.0 * kmax * m0, bpd)


def compare_model_i(result, *, kmax=None, bins_per_decade=5.0):
    """Model (i) box, binned engine, k-mer integration and R30/R31 side by side (constant kernel α).

    The box's α = π(2 r0)² (4/3) v0 / L³ [1/time] (R95 §3) is the kernel per pair; the binned engine runs
    ``Constant(α V)`` [length³/time] from ``Monodisperse(m0, N0 m0 / V)`` on a log grid with m0 at a bin
    centre; :func:`smoluchowski` integrates R29 over k-mers 1..kmax from N0 monomers. All are evaluated at the
    box's output times (the box must start from monomers at t = 0, the default of :func:`run`).

    Arguments:
        result: BoxResult of model (i).
        kmax: k-mers of the spectra and of the discrete integration (default n0).
        bins_per_decade: of the binned engine's grid.

    Returns:
        dict with ``t``; ``N_box``, ``N_binned``, ``N_smol``, ``N_R30`` (T,); ``n_box``, ``n_smol``, ``n_R31``
        (T, kmax) numbers of k-mers; ``edges`` of the binned grid and ``bin_box``, ``bin_binned``,
        ``bin_R31`` (T, nbins) numbers per bin; ``alpha``, ``V``, ``N0``; ``binned`` (its dict), ``smol``.

    References: Richardson (1995) §3, eqs. (29)-(31); Smoluchowski (1916).
    """
    import jaxcoag as jc
    from jaxcoag import analytic, kernels

    if not isinstance(result, BoxResult) or result.model != "i":
        raise JaxcoagInputError("compare_model_i needs the BoxResult of model (i) (constant kernel).")
    st = result.final_state
    L, r0, v0, m0 = (float(np.asarray(st.par[k])) for k in ("L", "r0", "v0", "m0"))
    V = L**3
    alpha = float(np.pi * (2 * r0) ** 2 * (4.0 / 3.0) * v0 / V)
    n0 = int(np.asarray(result.outs["nmem"]).shape[-1])
    kmax = n0 if kmax is None else int(kmax)
    t = np.asarray(result.t, np.float64)
    if t[0] < 0:
        raise JaxcoagInputError("model (i) comparison needs output times >= 0 (the box starts from monomers at 0).")
    N_R30 = n0 / (1.0 + 0.5 * alpha * n0 * t)
    kk = np.arange(1, kmax + 1)
    f = N_R30 / n0
    with np.errstate(divide="ignore"):
        n_R31 = np.exp(np.stack([analytic.log_nk("constant", kk, float(tt), coeff=alpha * V, n0=n0 / V)
                                 for tt in t])) * V
    init = np.zeros(kmax)
    init[0] = n0
    smol = smoluchowski(alpha, init, t, t0=0.0)
    grid = _grid_for(m0, n0, bins_per_decade)
    bn = binned_run(kernels.Constant(alpha * V), jc.Monodisperse(m0=m0, rho_d=n0 * m0 / V), t, V=V, grid=grid)
    edges = np.asarray(grid.edges)
    bin_R31 = np.stack([np.asarray(analytic.number_per_bin("constant", edges, float(tt), coeff=alpha * V, n0=n0 / V,
                                                           m0=m0)) for tt in t]) * V
    return dict(t=t, N_box=np.asarray(result.n_aggregates, np.float64), N_binned=bn["N"], N_smol=smol["N"],
                N_R30=N_R30, f=f, n_box=np.asarray(result.mass_spectrum(kmax), np.float64), n_smol=smol["n"],
                n_R31=n_R31, edges=edges, bin_box=np.asarray(result.number_per_bin(edges)) * V,
                bin_binned=bn["n_bin"], bin_R31=bin_R31, alpha=alpha, V=V, N0=n0, binned=bn, smol=smol)


def compare_measured(result, edges=None, *, kmax=None, bins_per_decade=20.0, binned=True):
    """Any model's box against the coagulation equation with the kernel measured from its own log.

    The kernel is :func:`measured_kernel` (method "log") on ``edges`` (default :func:`octave_edges`: classes
    1, 2, 3-4, 5-8, … m0); the k-mer integration (:func:`smoluchowski`, exact for integer masses) uses
    :func:`rate_table` (piecewise constant over the classes, unmeasured pairs from the nearest measured
    one), and the binned engine the same table as a :class:`ClassKernel`. Both start from the box's
    spectrum at its first output and are evaluated at its output times.

    Arguments:
        result: BoxResult (models iii, iv; any model works).
        edges: class edges [mass] of the kernel; kmax: k-mers of the integration (default n0).
        bins_per_decade: of the binned grid; binned: also run the binned engine.

    Returns:
        dict with ``t``, ``mk`` (:class:`MeasuredKernel`), ``rate`` (kmax, kmax) [1/time], ``N_box``,
        ``N_smol``, ``N_binned`` (T,; NaN if not run), ``N_R30`` (R30 with the measured monomer rate a_11 as a
        constant kernel, for reference), ``n_box``, ``n_smol`` (T, kmax); with ``binned``: ``edges`` of its
        grid, ``bin_box`` and ``bin_binned`` (T, nbins) particles per bin, ``binned`` (its dict).

    References: Richardson (1995) §3, eqs. (29)-(30); Smoluchowski (1916).
    """
    import jaxcoag as jc

    if not isinstance(result, BoxResult):
        raise JaxcoagInputError(f"compare_measured needs a rigid.BoxResult; got {type(result).__name__}.")
    m0 = float(np.asarray(result.m0))
    n0 = int(np.asarray(result.outs["nmem"]).shape[-1])
    kmax = n0 if kmax is None else int(kmax)
    edges = octave_edges(m0, n0) if edges is None else edges
    mk = measured_kernel(result, edges)
    t = np.asarray(result.t, np.float64)
    V = mk.V
    a = rate_table(mk, kmax, m0)
    spec = np.asarray(result.mass_spectrum(kmax), np.float64)
    smol = smoluchowski(a, spec[0], t, t0=float(t[0]))
    N_box = np.asarray(result.n_aggregates, np.float64)
    a11 = float(mk.rate[0, 0])
    N_R30 = N_box[0] / (1.0 + 0.5 * a11 * N_box[0] * (t - t[0]))
    out = dict(t=t, mk=mk, N_box=N_box, N_smol=smol["N"], N_R30=N_R30, n_box=spec, n_smol=smol["n"], smol=smol,
               N_binned=np.full(t.size, np.nan), V=V, rate=a)
    if binned:
        grid = _grid_for(m0, n0, bins_per_decade)
        ge = np.asarray(grid.edges)
        n_init = np.asarray(result.number_per_bin(ge))[0]
        bn = binned_run(ClassKernel.from_measured(mk), jnp.asarray(n_init), t, V=V, grid=grid, t0=float(t[0]))
        out.update(N_binned=bn["N"], edges=ge, bin_box=np.asarray(result.number_per_bin(ge)) * V,
                   bin_binned=bn["n_bin"], binned=bn)
    return out
