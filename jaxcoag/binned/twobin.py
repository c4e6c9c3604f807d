"""Two-bin (Kovetz & Olund 1969; Brauer et al. 2008) mass-conserving Smoluchowski scheme.

Each bin b holds particles of its geometric center mass m_b. A collision of bins i >= j makes
one particle of mass m = m_i + m_j with m_k <= m < m_{k+1}; it is split between k and k+1 in
number (1 - e, e) with e = (m - m_k)/(m_{k+1} - m_k), which conserves number *and* mass
(DustPy's scheme). The state is the mass density per bin rho_b [g cm^-3] plus one trailing
entry, the gel/outflow accumulator: mass whose target lies beyond the last bin (k+1 >= nbins)
goes there, so sum(rho) + gel is conserved to round-off.

Rates: pair number rate P_ij = s_ij K_ij N_i N_j over unordered pairs i >= j with s_ii = 1/2
(the self-collision factor lives here, not in the kernel), and N_b = rho_b/m_b. Each pair
contributes ``coef[p, :] * P`` [g cm^-3 s^-1] to the 4 bins ``idx[p, :]`` (precomputed numpy
tensors; evaluated as a few dense matrix-vector products per right-hand side, no scatters, by
:mod:`jaxcoag.binned.pairop`, or one ``segment_sum`` on irregular grids). When the product lands in
the larger partner's own bin (k = i, m_j << m_i), the loss of i and the gain of k are merged
analytically (coef_i = -m_j m_i/(m_{i+1}-m_i), coef_{i+1} = m_j m_{i+1}/(m_{i+1}-m_i)) to
avoid the catastrophic cancellation DustPy also removes.

References: Kovetz & Olund (1969), J. Atmos. Sci. 26, 1060; Brauer, Dullemond & Henning
(2008), A&A 480, 859, App. A; Stammler & Birnstiel (2022), ApJ 935, 35 (DustPy), §2.
"""

from __future__ import annotations

import numpy as np
import equinox as eqx
import jax
import jax.numpy as jnp

from .._validate import JaxcoagInputError
from .grid import MassGrid
from .pairop import PairOperator
from .redistribution import FragData, scatter_pair_jacobian
from .scheme import AbstractScheme

__all__ = ["TwoBinScheme", "pair_indices", "coagulation_tensors", "project_callable"]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)


def pair_indices(nbins):
    """Unordered bin pairs (iL >= iS) as two int32 numpy arrays of length nbins (nbins+1)/2."""
    iL, iS = np.tril_indices(nbins)
    return iL.astype(np.int32), iS.astype(np.int32)


def _ext_log_centers(grid):
    lc = grid.log_centers
    return np.concatenate([lc, [2.0 * lc[-1] - lc[-2]]])


def coagulation_tensors(grid: MassGrid):
    """Index/coefficient tensors of the two-bin coagulation operator (numpy, built once).

    Arguments:
        grid: the MassGrid.

    Returns:
        (iL, iS, idx, coef): pair indices (Np,), target bins (Np, 4) int32 in [0, nbins]
        (nbins = gel accumulator) and mass coefficients (Np, 4) [g] such that the mass
        rate is sum_p coef[p, c] * P_p into bin idx[p, c]; each row sums to 0 (mass
        conservation).

    References: Brauer et al. (2008) App. A; Kovetz & Olund (1969).
    """
    N = grid.nbins
    iL, iS = pair_indices(N)
    lce = _ext_log_centers(grid)
    lL, lS = lce[iL], lce[iS]
    with np.errstate(over="ignore"):
        mL, mS = np.exp(lL), np.exp(lS)
        lsum = lL + np.log1p(np.exp(lS - lL))
        msum = mL + mS
        k = np.searchsorted(lce, lsum, side="right") - 1
        k = np.clip(k, iL, N)  # k >= iL by construction; N means "beyond the grid"
        same = k == iL
        # ---- case k == iL: merged loss/gain (no cancellation)
        dl = lce[np.minimum(iL + 1, N)] - lL
        em1 = np.expm1(dl)
        cL_same = -mS / em1
        c1_same = mS * np.exp(dl) / em1
        # ---- case k > iL (k <= N-1 inside; k == N -> all to gel)
        kk = np.minimum(k, N)
        mk = np.exp(lce[kk])
        mk1 = np.exp(lce[np.minimum(kk + 1, N)])
        d = msum - mk
        frac = np.where(k < N, d / np.where(k < N, (mk1 - mk), 1.0), 0.0)
        c1_gen = np.where(k < N, frac * mk1, 0.0)
        ck_gen = msum - c1_gen
    idx = np.zeros((iL.size, 4), np.int32)
    coef = np.zeros((iL.size, 4))
    idx[:, 0] = iS
    coef[:, 0] = -mS
    idx[:, 1] = iL
    coef[:, 1] = np.where(same, cL_same, -mL)
    idx[:, 2] = np.minimum(k, N)
    coef[:, 2] = np.where(same, 0.0, ck_gen)
    idx[:, 3] = np.minimum(k + 1, N)
    coef[:, 3] = np.where(same, c1_same, c1_gen)
    if not np.all(np.isfinite(coef)):
        raise JaxcoagInputError(
            "two-bin coefficients overflow: bin masses beyond ~1e300 g; use a grid with m_max <= 1e300 g.")
    return iL, iS, idx, coef


def project_callable(f, grid: MassGrid, power=1):
    """Integral of m^power f(m) over each bin by 16-pt Gauss-Legendre in ln m.

    Arguments: f callable, number density per unit mass [cm^-3 g^-1] (vectorised);
    grid; power (1: mass per bin [g cm^-3]; 0: number per bin [cm^-3]).
    Returns: jnp array (nbins,). References: standard Gauss-Legendre quadrature.
    """
    le = grid.log_edges
    half = 0.5 * np.diff(le)
    lm = 0.5 * (le[:-1] + le[1:])[:, None] + half[:, None] * _GL_X[None, :]
    m = jnp.asarray(np.exp(lm))
    vals = jnp.asarray(f(m)) * m ** (power + 1)
    return jnp.sum(vals * jnp.asarray(_GL_W)[None, :], axis=1) * jnp.asarray(half)


class TwoBinData(eqx.Module):
    """Precomputed right-hand-side data of :class:`TwoBinScheme` (a pytree)."""

    khat: jax.Array          # K_ij/(m_i m_j) * s_ij on pairs [cm^3 s^-1 g^-2]
    coef: jax.Array          # (Np, 4) [g], possibly (1-p_f)-weighted through frag terms
    frag: object             # None or fragmentation data (see fragmentation.py)
    sweep: object            # None or K(m_b, M_top)/M_top per bin [cm^3 s^-1 g^-1] (gel sweeping)
    iL: jax.Array            # (Np,) larger partner's bin (int32, from the static grid)
    iS: jax.Array            # (Np,) smaller partner's bin
    idx: jax.Array           # (Np, 4) target bins of coef (nbins = gel accumulator)
    op: object = None        # PairOperator of the sticking (+ FragData direct) terms, or None (scatter form)
    ejop: object = None      # PairOperator of the FragData ejecta per source bin, or None
    nbins: int = eqx.field(static=True, default=0)


class TwoBinScheme(AbstractScheme):
    """Two-bin mass-conserving scheme; state = (rho_1..rho_N [g cm^-3], gel [g cm^-3]).

    Arguments:
        gel_sweep: static bool (default True). The gel/outflow accumulator stands for bodies
            of mass >= M_top (the upper grid edge); with ``gel_sweep`` they keep colliding with
            the bins: bin b loses mass at rate K(m_b, M_top)/M_top * rho_b * rho_gel into the
            gel. For the product kernel this is exact (K/M = b m_b independent of M_top) and
            gives the post-gel Flory solution; for kernels with K(m, M)/M -> 0 (constant,
            geometric) it is negligible. Set False for pure outflow (Stockmayer-like sol).
            With a fragmentation model the accumulator is pure outflow (no sweeping): bodies
            beyond the grid would fragment, so letting them sweep the bins drains the
            equilibrium (measured: all mass in 1e13 s for a 1e8 g grid top at alpha = 1e-6).

    References: Kovetz & Olund (1969); Brauer et al. (2008) App. A; DustPy (2022); Flory
    (1941) / Ernst, Ziff & Hendriks (1984) (post-gel sol swept by the gel).
    """

    gel_sweep: bool = eqx.field(static=True, default=True)

    def init(self, grid, n0):
        """State from number per bin [cm^-3] (rho_b = n_b m_b) or callable f(m) [cm^-3 g^-1]
        (rho_b = integral of m f(m) over the bin, so the initial mass is exact)."""
        if callable(n0):
            rho = project_callable(n0, grid, power=1)
        else:
            rho = jnp.asarray(n0) * jnp.asarray(grid.centers)
        return jnp.concatenate([rho, jnp.zeros((1,), rho.dtype)])

    def precompute(self, kernel, grid, fragmentation=None):
        """Kernel on all pairs (log space, overflow-free) + fragmentation tensors.

        Arguments: kernel (AbstractKernel), grid (MassGrid), fragmentation (None or a binned-capable
        ``jaxcoag.outcomes`` outcome: hooks ``probability``/``twobin_data``). Returns: TwoBinData.
        """
        iL, iS, idx, coef = coagulation_tensors(grid)
        lc = jnp.asarray(grid.log_centers)
        lL, lS = lc[iL], lc[iS]
        logk = kernel.log_kernel_from_log_mass(lL, lS)
        s = jnp.where(jnp.asarray(iL == iS), 0.5, 1.0)
        khat = s * jnp.exp(logk - lL - lS)
        sweep = None
        if self.gel_sweep and fragmentation is None:
            ltop = float(grid.log_edges[-1])
            sweep = jnp.exp(kernel.log_kernel_from_log_mass(lc, jnp.full_like(lc, ltop)) - ltop)
        fdata = None
        if fragmentation is not None:
            fdata = fragmentation.twobin_data(kernel, grid, iL, iS)
        op, ejop = self._dense_operators(grid.nbins, iL, iS, idx, coef, khat, fdata)
        return TwoBinData(khat=khat, coef=jnp.asarray(coef), frag=fdata, sweep=sweep, iL=iL, iS=iS, idx=idx,
                          op=op, ejop=ejop, nbins=grid.nbins)

    @staticmethod
    def _dense_operators(N, iL, iS, idx, coef, khat, fdata):
        """Dense pair operators (:mod:`jaxcoag.binned.pairop`) of the terms that are quadratic in rho with
        coefficients fixed during a solve: sticking (weight 1 - p_f with fragmentation), the
        :class:`~jaxcoag.binned.redistribution.FragData` losses/remnants (weight p_f) and its ejecta per
        source bin. Returns (op, ejop); (None, None) keeps the scatter form (an irregular grid, or
        outcome data with per-pair fragment weights in "full" mode)."""
        coef = jnp.asarray(coef)
        if fdata is None:
            return PairOperator.build([(idx, coef * khat[:, None])], iL, iS, N, N + 1), None
        if isinstance(fdata, FragData):
            pf = fdata.p
            op = PairOperator.build([(idx, coef * ((1.0 - pf) * khat)[:, None]),
                                     (np.asarray(fdata.idx), fdata.coef * (pf * khat)[:, None])], iL, iS, N, N + 1)
            ejop = PairOperator.build([(np.asarray(fdata.src)[:, None], (fdata.ejecta * pf * khat)[:, None])],
                                      iL, iS, N, N, gel=False)
            return (op, ejop) if (op is not None and ejop is not None) else (None, None)
        if getattr(fdata, "full", False):
            return None, None
        return PairOperator.build([(idx, coef * ((1.0 - fdata.p) * khat)[:, None])], iL, iS, N, N + 1), None

    def rhs(self, t, y, data):
        """d(rho, gel)/dt [g cm^-3 s^-1]."""
        N = data.nbins
        rho = y[:N]
        if data.op is not None:
            out = data.op.apply(rho)                           # dense form (jaxcoag.binned.pairop)
            if data.ejop is not None:
                out = out + jnp.concatenate([data.ejop.apply(rho) @ data.frag.W, jnp.zeros((1,), y.dtype)])
            elif data.frag is not None:
                P = data.khat * rho[data.iL] * rho[data.iS]
                out = out + data.frag.rhs(data.frag.p * P, N)
        else:
            out = self._rhs_scatter(rho, data)
        if data.sweep is not None:
            swept = data.sweep * rho * y[N]
            out = out + jnp.concatenate([-swept, jnp.sum(swept)[None]])
        return out

    def _rhs_scatter(self, rho, data):
        """Coagulation + fragmentation part of :meth:`rhs` as ``segment_sum`` scatters over the pair list
        (the reference form; used when no dense operator applies)."""
        N = data.nbins
        P = data.khat * rho[data.iL] * rho[data.iS]        # pair rates / (m_i m_j) folded in khat
        if data.frag is None:
            contrib = data.coef * P[:, None]
            return jax.ops.segment_sum(contrib.ravel(), jnp.asarray(data.idx).ravel(), num_segments=N + 1)
        if getattr(data.frag, "full", False):
            # the fragmentation data describe every collision (e.g. RecipeOutcome
            # without a mixture weight): no separate sticking part
            return data.frag.rhs(P, N)
        pf = data.frag.p                                   # fragmenting fraction per pair
        contrib = data.coef * ((1.0 - pf) * P)[:, None]
        out = jax.ops.segment_sum(contrib.ravel(), jnp.asarray(data.idx).ravel(), num_segments=N + 1)
        return out + data.frag.rhs(pf * P, N)

    def jacobian(self, t, y, data):
        """Exact dense Jacobian d rhs/d y (N+1, N+1) [s^-1] from the structure of :meth:`rhs`.

        The right-hand side is linear in the pair rates P_p = khat_p rho_iL rho_iS (the
        coefficients, fragmenting fractions and weights do not depend on y) plus the bilinear
        gel-sweep term, so dP_p/d rho = khat_p (rho_iS e_iL + rho_iL e_iS) has two nonzeros. On
        a regular grid J is a few scaled copies of the dense category matrices
        (:class:`~jaxcoag.binned.pairop.PairOperator`; with fragmentation plus W^T times the
        ejecta's Jacobian); otherwise a scatter of 2 x (coefficient columns) x Np entries
        (:func:`~jaxcoag.binned.redistribution.scatter_pair_jacobian`) plus the fragment weights'
        product (``data.frag.jac_rates``). O(N^2) (O(N^3) for the fragment weights, O(Np N) with
        per-pair weights) work instead of N + 1 Jacobian-vector products of :meth:`rhs`. Equal to
        ``jax.jacfwd(rhs)`` to round-off (summation order differs).

        References: Brauer et al. (2008) App. A; Stammler & Birnstiel (2022) §3.2 (DustPy's
        implicit step with the coagulation Jacobian).
        """
        N = data.nbins
        rho = y[:N]
        if data.op is not None:
            J = data.op.jacobian(rho)                                  # (N + 1, N)
            if data.ejop is not None:
                J = J + jnp.pad(data.frag.W.T @ data.ejop.jacobian(rho), ((0, 1), (0, 0)))
            J = jnp.pad(J, ((0, 0), (0, 1)))                           # the gel column
            if data.ejop is None and data.frag is not None:
                pf = data.frag.p
                J = J + data.frag.jac_rates(pf * data.khat * rho[data.iS], pf * data.khat * rho[data.iL],
                                            data.iL, data.iS, N)
        else:
            J = self._jacobian_scatter(rho, data)
        if data.sweep is not None:
            # swept_b = sweep_b rho_b gel: out_b -= swept_b, out_gel += sum_b swept_b
            g = y[N]
            d_rho = data.sweep * g                             # d swept_b / d rho_b
            d_gel = data.sweep * rho                           # d swept_b / d gel
            b = jnp.arange(N)
            J = J.at[b, b].add(-d_rho)
            J = J.at[:N, N].add(-d_gel)
            J = J.at[N, :N].add(d_rho)
            J = J.at[N, N].add(jnp.sum(d_gel))
        return J

    def _jacobian_scatter(self, rho, data):
        """Coagulation + fragmentation part of :meth:`jacobian` as scatters over the pair list (the
        reference form; used when no dense operator applies)."""
        N = data.nbins
        rL = data.khat * rho[data.iS]                      # d P_p / d rho_iL
        rS = data.khat * rho[data.iL]                      # d P_p / d rho_iS
        if data.frag is None:
            return scatter_pair_jacobian(data.idx, data.coef, rL, rS, data.iL, data.iS, N)
        if getattr(data.frag, "full", False):
            return data.frag.jac_rates(rL, rS, data.iL, data.iS, N)
        pf = data.frag.p
        J = scatter_pair_jacobian(data.idx, data.coef, (1.0 - pf) * rL, (1.0 - pf) * rS, data.iL, data.iS, N)
        return J + data.frag.jac_rates(pf * rL, pf * rS, data.iL, data.iS, N)

    def rhs_structured(self, t, y, data):
        """:meth:`rhs` whose forward-mode derivative in y is ``jacobian(t, y, data) @ y_dot``.

        A ``custom_jvp`` (equinox ``filter_custom_jvp``, symbolic zeros): ``jax.jacfwd`` /
        ``jax.linearize`` + ``vmap`` (diffrax Kvaerno5's Newton through lineax,
        :class:`~jaxcoag.binned.solvers.LinearlyImplicitEuler`, :func:`steady_state`) form
        :meth:`jacobian` once and multiply it by the batch of tangents (one matmul) instead of
        N + 1 JVPs of :meth:`rhs`. Tangents of the data (kernel/outcome parameters) go through
        ``jax.jvp`` of :meth:`rhs` in the data with y fixed; a zero tangent costs nothing.
        Reverse mode transposes the same linear rule. Values equal :meth:`rhs` exactly.
        """
        return _rhs_structured(t, y, data, scheme=self)

    def mass_per_bin(self, y, grid):
        """rho_b [g cm^-3]."""
        return y[..., : grid.nbins]

    def number_per_bin(self, y, grid):
        """rho_b / m_b [cm^-3]."""
        return y[..., : grid.nbins] * jnp.exp(-jnp.asarray(grid.log_centers))

    def gel_mass(self, y, grid):
        """Mass that left through the top of the grid [g cm^-3] (last state entry)."""
        return y[..., grid.nbins]

    def mass_scale(self, y0, grid):
        """All ones: the state already is mass per bin."""
        return jnp.ones(grid.nbins + 1, y0.dtype)


@eqx.filter_custom_jvp
def _rhs_structured(t, y, data, *, scheme):
    return scheme.rhs(t, y, data)


@_rhs_structured.def_jvp
def _rhs_structured_jvp(primals, tangents, *, scheme):
    t, y, data = primals
    _, ty, tdata = tangents                      # None = symbolic zero (rhs does not depend on t)
    out = scheme.rhs(t, y, data)
    tout = None
    if ty is not None:
        tout = scheme.jacobian(t, y, data) @ ty
    if tdata is not None and any(x is not None for x in jax.tree_util.tree_leaves(tdata, is_leaf=lambda x: x is None)):
        spec = jax.tree_util.tree_map(lambda x: x is not None, tdata, is_leaf=lambda x: x is None)
        dyn, static = eqx.partition(data, spec)
        _, td = jax.jvp(lambda d: scheme.rhs(t, y, eqx.combine(d, static)), (dyn,), (tdata,))
        tout = td if tout is None else tout + td
    return out, tout
