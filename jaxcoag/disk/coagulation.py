"""Coagulation and fragmentation in one radial cell of the disk model, as DustPy 1.0.9 discretises them.

* :func:`coagulation_tensors` -- the static collision tensors of a regular logarithmic mass grid
  (DustPy ``coagulation_parameters``): the two-bin sticking split of Brauer, Dullemond & Henning (2008,
  A&A 480, 859, appendices A.1-A.2, the Kovetz & Olund 1969 / Podolak scheme with the A.2 modification
  for very unequal masses) and the mass-conserving fragmentation/erosion model (Stammler & Birnstiel 2022,
  ApJ 935, 35, §2.3.2, after Rafikov et al. 2020).
* :func:`vertical_kernel` -- the vertically integrated kernel (DustPy ``kernel``; Birnstiel et al. 2010,
  A&A 513, A79, eq. 23); :func:`p_frag`, :func:`p_stick` (DustPy ``pfrag``, ``p_stick``).
* :func:`coagulation_source` -- S_coag (nm,) [g cm^-2 s^-1] of one cell (DustPy ``s_coag``).
* :func:`coagulation_jacobian` -- the dense (nm, nm) Picard matrix J~ with S = J~ Sigma of one cell
  (DustPy ``jacobian_coagulation_generator``: each collision pair booked in the column of its larger
  partner; upper triangular plus q = ceil(log10 2 / Delta log10 m) sub-diagonals).

Index conventions follow DustPy's Python view of its Fortran arrays: pair arrays X[..., j, i] are used
for j <= i only (i is the larger partner); the kernel and the rates Rs, Rf are stored there (upper
triangle) and zero below the diagonal. The per-cell functions are pure jnp, jit/vmap-able and
differentiable with respect to the rates and Sigma; the tensors are built once per mass grid on the
host (numpy, vectorised) and enter as constants. J~ is assembled analytically with one segment sum
(plus one matmul for the fragment distribution), never by forward-mode passes.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._validate import JaxcoagInputError

__all__ = ["CoagulationTensors", "coagulation_tensors", "vertical_kernel", "p_frag", "p_stick",
           "coagulation_source", "coagulation_jacobian"]


class CoagulationTensors(eqx.Module):
    """Static collision tensors of a logarithmic mass grid (DustPy 1.0.9 ``coagulation_parameters``).

    DustPy's arrays, in its Python index order (0-based, -1 = none):
        stick (4, nm, nm), stick_ind (4, nm, nm) int: for the pair (j <= i) the fraction stick[l, j, i] of
            one collision's product goes to bin stick_ind[l, j, i] (number units; negative entries remove
            the partners; Brauer et al. 2008 A.1-A.2);
        A (nm, nm) [g]: mass of the fragments of a pair; eps (nm, nm): fraction of the erosion remnant in
            the lower bin rm_ind; lf_ind (nm, nm) int: bin of the largest fragment; rm_ind (nm, nm) int:
            lower bin of the remnant; phi (nm, nm): phi[k, :] the fragment mass distribution with largest
            fragment k (sum 1, ~ m^(2 + fragment_slope)).
    Derived, for the vectorised evaluation (host-built, constant):
        seg_* -- the data layout of one segment sum that yields S (number units) and J~ (see
        :func:`coagulation_jacobian`); p (full fragmentation for j >= i - p), q (sub-diagonals of J~).
    """

    m: jnp.ndarray
    stick: jnp.ndarray
    stick_ind: jnp.ndarray
    A: jnp.ndarray
    eps: jnp.ndarray
    lf_ind: jnp.ndarray
    rm_ind: jnp.ndarray
    phi: jnp.ndarray
    # segment-sum layout: for every term t, pair (j, i) = (pair_j[t], pair_i[t]), target row[t],
    # coefficient coef[t] (number units) and which rate it multiplies (is_frag[t])
    seg_pair: jnp.ndarray
    seg_row: jnp.ndarray
    seg_col: jnp.ndarray
    seg_coef: jnp.ndarray
    seg_coef_j: jnp.ndarray
    seg_frag: jnp.ndarray
    upper: jnp.ndarray
    band: jnp.ndarray
    p: int = eqx.field(static=True)
    q: int = eqx.field(static=True)


def _grid_constants(m):
    """(a, ce, q) of a regular logarithmic grid: m_{i+1} = m_i 10^a (as DustPy 1.0.9; Brauer et al. 2008
    eq. A.6 for ce)."""
    nm = m.size
    a = math.log10(m[0] / m[-1]) / (1.0 - nm)
    ce = int(-1.0 / a * math.log10(1.0 - 10.0 ** (-a))) + 1
    q = int(math.ceil(math.log10(2.0) / a))
    return a, ce, q


def _check_grid(m):
    m = np.asarray(m, dtype=np.float64)
    if m.ndim != 1 or m.size < 3:
        raise JaxcoagInputError(f"coagulation_tensors(m) needs a 1-D mass grid with >= 3 bins; got shape {m.shape}.")
    if not np.all(np.isfinite(m)) or np.any(m <= 0):
        raise JaxcoagInputError("coagulation_tensors(m): masses must be finite and > 0 [g].")
    ratio = m[1:] / m[:-1]
    if np.any(ratio <= 1.0) or np.max(np.abs(ratio / ratio[0] - 1.0)) > 1e-8:
        raise JaxcoagInputError("coagulation_tensors(m): the mass grid must be strictly increasing and regular "
                                "logarithmic (m[i+1]/m[i] constant), as DustPy's sticking scheme assumes; "
                                "build it with jaxcoag.disk.grid.mass_grid or numpy.geomspace.")
    return m


def coagulation_tensors(m, erosion_mass_ratio=10.0, excavated_mass=1.0, fragment_slope=-11.0 / 6.0):
    """Build the collision tensors of DustPy 1.0.9 ``coagulation_parameters`` for the mass grid m.

    Arguments (DustPy's ``sim.ini.dust`` names in brackets):
        m: (nm,) regular logarithmic mass grid [g];
        erosion_mass_ratio [erosionMassRatio]: pairs with m_i/m_j below this (within p = floor(log10(ratio)/a)
            bins) fragment fully, more unequal pairs erode;
        excavated_mass [excavatedMass]: mass excavated from the larger partner in units of the smaller one;
        fragment_slope [fragmentDistribution]: power of the fragment number distribution n(m) dm ~ m^slope,
            so the mass per logarithmic bin scales as m^(2 + slope) (default -11/6, Dohnanyi 1969).
    Returns a :class:`CoagulationTensors` (arrays as DustPy returns them, plus the layout used by
    :func:`coagulation_source` and :func:`coagulation_jacobian`).
    """
    m = _check_grid(m)
    for name, v in (("erosion_mass_ratio", erosion_mass_ratio), ("excavated_mass", excavated_mass),
                    ("fragment_slope", fragment_slope)):
        if not np.isfinite(float(v)):
            raise JaxcoagInputError(f"coagulation_tensors({name}=...) must be finite; got {v!r}.")
    if float(erosion_mass_ratio) < 1.0:
        raise JaxcoagInputError(f"coagulation_tensors(erosion_mass_ratio=...) must be >= 1; got {erosion_mass_ratio}.")
    if float(excavated_mass) < 0.0:
        raise JaxcoagInputError(f"coagulation_tensors(excavated_mass=...) must be >= 0; got {excavated_mass}.")
    crat, fexc, slope = float(erosion_mass_ratio), float(excavated_mass), float(fragment_slope)
    nm = m.size
    a, ce, q = _grid_constants(m)
    p = int(math.floor(math.log10(crat) / a))
    fa, fam = 10.0 ** a, 10.0 ** (-a)
    mi_m_mim1 = m * (1.0 - fam)
    mip1_m_mi = m * (fa - 1.0)
    mip1_m_mim1 = m * (fa - fam)
    idx = np.arange(nm)
    # F[x, y] is DustPy's Fortran array F(x, y); Fortran index = 0-based + 1 (kept 0-based here)
    J, I = np.meshgrid(idx, idx, indexing="ij")  # J[j, i] = j, I[j, i] = i

    # -- Podolak coefficients cpod[k, j, i] (Brauer et al. 2008 A.1)
    mtot = m[:, None] + m[None, :]
    cnt = np.searchsorted(m, mtot, side="right")  # number of bins with m <= mtot
    ok = cnt < nm                                 # some bin is heavier than the product
    k0 = np.clip(cnt - 1, 0, nm - 2)
    epsp = (m[k0 + 1] - mtot) / mip1_m_mi[k0]
    cpod = np.zeros((nm, nm, nm))
    jj, ii = J[ok], I[ok]
    cpod[k0[ok], jj, ii] = epsp[ok]
    cpod[k0[ok] + 1, jj, ii] = 1.0 - epsp[ok]

    # -- D and E matrices (Brauer et al. 2008 A.2), D defaults to -1
    Dm = np.where(J <= I + 1 - ce, -m[J] / mip1_m_mi[I], -1.0)
    theta_e = (mip1_m_mim1[I] - m[J] >= 0.0).astype(float)
    Em = np.where(J <= I - ce, m[J] / mi_m_mim1[I], (1.0 - (m[J] - mi_m_mim1[I]) / mip1_m_mi[I]) * theta_e)

    # -- modified coefficients cpodmod[k, j, i] for i < nm-1 (0-based), j <= jmax(i)
    ifort = np.arange(1, nm + 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        jmax = np.minimum(nm - 1, np.trunc(np.log10(10.0 ** (a * nm) - 10.0 ** (a * ifort)) / a))
    jmax = np.where(ifort <= nm - 1, jmax, 0).astype(int)  # Fortran j limit for Fortran i
    K3 = np.arange(nm)[:, None, None]
    J3 = np.arange(nm)[None, :, None]
    I3 = np.arange(nm)[None, None, :]
    th = lambda x: (x >= 0.0).astype(float)  # noqa: E731  (Heaviside, theta(0) = 1 as DustPy's math.theta)
    term1 = 0.5 * (J3 == I3) * cpod
    term2 = cpod * th((K3 - J3) * 1.0 - 1.5) * th((J3 - I3) * 1.0 - 0.5)
    term3 = (J3 == K3) * Dm.T[None, :, :]                  # d(i, j) = Dm[i, j] -> indexed [j, i] via .T
    e_ik = np.broadcast_to(Em[I3, K3], (nm, nm, nm))      # e(i, k) = Em[i, k] at [k, j, i]
    term4 = (J3 == K3 - 1) * e_ik * th((K3 - I3) * 1.0 - 1.5)
    cpodmod = ((term1 + term2) + term3) + term4
    live = (np.arange(nm)[None, :] + 1 <= jmax[:, None]) & (np.arange(nm)[:, None] + 1 <= nm - 1)  # [i, j]
    cpodmod = cpodmod * live.T[None, :, :]
    # symmetrise: for j <= i keep dum[:, j, i] + dum[:, i, j], zero for j > i
    sym = cpodmod + cpodmod.transpose(0, 2, 1)
    cpodmod = np.where((J <= I)[None, :, :], sym, 0.0)
    nz = cpodmod != 0.0
    if np.any(nz.sum(axis=0) > 4):
        raise JaxcoagInputError("coagulation_tensors: a sticking collision touches more than four bins; the mass "
                                "grid is too fine or not logarithmic for DustPy's scheme.")
    # keep the non-zero entries in ascending k, padded with (0, -1)
    order = np.argsort(~nz, axis=0, kind="stable")[:4]                 # (4, nm, nm) k-indices, non-zeros first
    valid = np.take_along_axis(nz, order, axis=0)
    stick = np.where(valid, np.take_along_axis(cpodmod, order, axis=0), 0.0)
    stick_ind = np.where(valid, order, -1).astype(np.int32)

    # -- fragmentation
    w = m ** (2.0 + slope)
    tri = idx[None, :] <= idx[:, None]     # [i, k]: k <= i
    phi = np.where(tri, w[None, :], 0.0)
    phi = phi / phi.sum(axis=1, keepdims=True)
    ero = J <= I - p - 1                   # erosion pairs (0-based: j <= i - p - 1)
    full = (J >= I - p) & (J <= I)
    klf = np.where(ero, J, np.where(full, I, -1))
    Afrag = np.where(ero, (1.0 + fexc) * m[J], np.where(full, m[I] + m[J], 0.0))
    mrm = m[I] - fexc * m[J]
    f0 = np.searchsorted(m, mrm, side="left")            # first bin with m >= mrm (0-based)
    same = mrm == m[I]
    krm = np.where(same, I - 1, f0 - 1)                  # lower remnant bin (0-based)
    kk = np.clip(krm, 0, nm - 2)
    eps_gen = (m[np.clip(kk + 1, 0, nm - 1)] - mrm) / mip1_m_mi[kk]
    eps_same = fexc * m[J] / mi_m_mim1[I]
    epsf = np.where(ero, np.where(same, eps_same, eps_gen), 0.0)
    krm = np.where(ero, krm, -1)

    tens = dict(m=m, stick=stick, stick_ind=stick_ind, A=Afrag, eps=epsf, lf_ind=klf.astype(np.int32),
                rm_ind=krm.astype(np.int32), phi=phi)
    seg = _segment_layout(m, stick, stick_ind, epsf, krm, ero, full, q)
    return CoagulationTensors(**{k: jnp.asarray(v) for k, v in tens.items()}, **seg, p=p, q=q)


def _segment_layout(m, stick, stick_ind, eps, krm, ero, full, q):
    """Terms of S (number units) and J~ as (pair, row, coef, is_frag) lists, one entry per term.

    For the pair (j <= i) with rates r_s = Rs_ji n_j n_i and r_f = Rf_ji n_j n_i, DustPy's ``s_coag``
    adds coef * r to S_row (number units, before the final factor m); J~[row, i] gets coef * m_row/m_i *
    n_j R_ji (``jacobian_coagulation_generator``). The fragments themselves go through phi separately.
    """
    nm = m.size
    J, I = np.meshgrid(np.arange(nm), np.arange(nm), indexing="ij")
    rows, cols, pairs, coefs, frag = [], [], [], [], []

    def add(mask, row, coef, is_frag):
        rows.append(row[mask]); cols.append(I[mask]); pairs.append((J * nm + I)[mask])  # noqa: E702
        coefs.append(coef[mask]); frag.append(np.full(int(mask.sum()), is_frag))  # noqa: E702

    up = J <= I
    for l in range(4):
        k = stick_ind[l]
        add(up & (k >= 0), k, stick[l], False)
    special = ero & (krm == I - 1)
    general = ero & ~special
    # remnant, lower bin
    add(ero, krm, eps, True)
    # special case (remnant between i-1 and i): -eps at (i, i); general: (1 - eps) at krm + 1 and -1 at i
    add(special, I, -eps, True)
    add(general, krm + 1, 1.0 - eps, True)
    add(general | full, I, -np.ones_like(eps), True)
    # the smaller partner loses one particle in every fragmenting/eroding collision
    add(ero | full, J, -np.ones_like(eps), True)
    row = np.concatenate(rows).astype(np.int32)
    col = np.concatenate(cols).astype(np.int32)
    coef = np.concatenate(coefs)
    coef_j = coef * m[row] / m[col]
    band = (np.arange(nm)[:, None] <= np.arange(nm)[None, :] + q)
    return dict(seg_pair=jnp.asarray(np.concatenate(pairs).astype(np.int32)), seg_row=jnp.asarray(row),
                seg_col=jnp.asarray(col), seg_coef=jnp.asarray(coef), seg_coef_j=jnp.asarray(coef_j),
                seg_frag=jnp.asarray(np.concatenate(frag)), upper=jnp.asarray(up.astype(np.float64)),
                band=jnp.asarray(band.astype(np.float64)))


# ---------------------------------------------------------------------------------------------- kernel, p_frag
def vertical_kernel(a, H, vrel, sigma=None, sigma_floor=None):
    """Vertically integrated collision kernel K[..., j, i] [cm^2 s^-1] for j <= i (zero below the diagonal).

    K_ji = (1 - delta_ij/2) pi (a_i + a_j)^2 dv_ij / sqrt(2 pi (H_i^2 + H_j^2)) (Birnstiel et al. 2010
    eq. 23; DustPy 1.0.9 ``kernel``); it acts on surface densities. As DustPy, only the upper triangle
    (j <= i, i the larger partner) is filled. If ``sigma`` and ``sigma_floor`` (..., nm) are given,
    pairs with a bin below its floor (Sigma < Sigma_floor) get K = 0, as DustPy does; DustPy also sets
    K = 0 in the first and last radial cells (the caller's business).

    Arguments: a (nm,) or (..., nm) radii [cm]; H (..., nm) dust scale heights [cm]; vrel (..., nm, nm)
    [cm s^-1].
    """
    vrel = jnp.asarray(vrel, dtype=jnp.result_type(float))
    nm = vrel.shape[-1]
    batch = vrel.shape[:-2]
    a = jnp.broadcast_to(jnp.asarray(a, dtype=vrel.dtype), batch + (nm,))
    H = jnp.broadcast_to(jnp.asarray(H, dtype=vrel.dtype), batch + (nm,))
    aj, ai = a[..., :, None], a[..., None, :]
    hj, hi = H[..., :, None], H[..., None, :]
    lift = (1,) * len(batch) + (nm, nm)
    diag_fac = (1.0 - 0.5 * jnp.eye(nm)).reshape(lift)
    up = jnp.triu(jnp.ones((nm, nm))).reshape(lift)
    K = diag_fac * jnp.pi * (aj + ai) ** 2 * vrel / jnp.sqrt(2.0 * jnp.pi * (hj ** 2 + hi ** 2))
    K = K * up
    if (sigma is None) != (sigma_floor is None):
        raise JaxcoagInputError("vertical_kernel: give both sigma and sigma_floor, or neither.")
    if sigma is not None:
        above = jnp.asarray(sigma) >= jnp.asarray(sigma_floor)
        K = jnp.where(above[..., :, None] & above[..., None, :], K, 0.0)
    return K


def p_frag(vrel, v_frag):
    """Fragmentation probability (..., nm, nm), DustPy 1.0.9 ``pfrag``: p_f = (1.5 x + 1) exp(-1.5 x) with
    x = (v_frag/dv)^2, the fraction of a Maxwellian relative-speed distribution above v_frag (Stammler &
    Birnstiel 2022 §2.3.2); p_f = 0 where dv = 0. Gradients are finite everywhere (double ``where``).

    Arguments: vrel (..., nm, nm) [cm s^-1]; v_frag scalar or (...,) [cm s^-1].
    """
    vrel = jnp.asarray(vrel, dtype=jnp.result_type(float))
    vf = jnp.broadcast_to(jnp.asarray(v_frag, dtype=vrel.dtype), vrel.shape[:-2])[..., None, None]
    pos = vrel > 0.0
    x = (vf / jnp.where(pos, vrel, 1.0)) ** 2
    return jnp.where(pos, (1.5 * x + 1.0) * jnp.exp(-1.5 * x), 0.0)


def p_stick(vrel, v_frag):
    """Sticking probability 1 - p_frag (DustPy 1.0.9 ``p_stick``, which also sets it to 0 in the first and
    last radial cells: the caller's business)."""
    return 1.0 - p_frag(vrel, v_frag)


# ---------------------------------------------------------------------------------------------- S and J~
def _active_pairs(tensors, Sigma, Sigma_floor):
    """Upper-triangular pair mask (nm, nm) of DustPy's loops: i <= imax, the last bin with Sigma > floor."""
    nm = Sigma.shape[-1]
    idx = jnp.arange(nm)
    imax = jnp.max(jnp.where(Sigma > Sigma_floor, idx, -1))
    return tensors.upper * (idx[None, :] <= imax)


def _check_cell(tensors, Rs, Rf, Sigma):
    nm = tensors.m.shape[0]
    if Sigma.shape != (nm,) or Rs.shape != (nm, nm) or Rf.shape != (nm, nm):
        raise JaxcoagInputError(f"coagulation_source/jacobian work on one cell: Sigma ({nm},), Rs and Rf ({nm}, {nm}); "
                                f"got {Sigma.shape}, {Rs.shape}, {Rf.shape}. Use jax.vmap over radial cells.")


def coagulation_source(tensors, m, Rs, Rf, Sigma, Sigma_floor):
    """Coagulation source S_coag (nm,) [g cm^-2 s^-1] of one cell, DustPy 1.0.9 ``s_coag``.

    With n = Sigma/m and pair rates Rs_ji n_j n_i (sticking), Rf_ji n_j n_i (fragmentation) for j <= i <=
    imax (imax: the largest bin with Sigma > Sigma_floor): sticking products by the Brauer et al. (2008)
    split, fragments with the distribution phi of the largest fragment, erosion remnants split between two
    bins, minus the colliding partners; S = m * (number rate). Sum_i S_i = 0 to round-off (mass
    conservation; Stammler & Birnstiel 2022 §2.3.2).

    Arguments: tensors from :func:`coagulation_tensors`; m (nm,) [g]; Rs, Rf (nm, nm) sticking and
    fragmentation rates K p_stick, K p_frag [cm^2 s^-1] (upper triangle used); Sigma, Sigma_floor (nm,)
    [g cm^-2]. Vmap over cells.
    """
    m = jnp.asarray(m, dtype=jnp.result_type(float))
    Rs, Rf, Sigma = (jnp.asarray(x, dtype=m.dtype) for x in (Rs, Rf, Sigma))
    _check_cell(tensors, Rs, Rf, Sigma)
    nm = m.shape[0]
    P = _active_pairs(tensors, Sigma, Sigma_floor)
    n = Sigma / m
    nn = n[:, None] * n[None, :] * P
    rs = (Rs * nn).reshape(-1)
    rf = (Rf * nn).reshape(-1)
    rate = jnp.where(tensors.seg_frag, rf[tensors.seg_pair], rs[tensors.seg_pair])
    s_num = jax.ops.segment_sum(tensors.seg_coef * rate, tensors.seg_row, num_segments=nm)
    # fragments: As[l] = sum_{pairs with lf_ind = l} A Rf n n, then S_k += sum_l As[l] phi[l, k] / m_k
    lf = tensors.lf_ind.reshape(-1)
    As = jax.ops.segment_sum((tensors.A.reshape(-1) * rf), jnp.where(lf >= 0, lf, nm), num_segments=nm + 1)[:nm]
    return (s_num + (As @ tensors.phi) / m) * m


def coagulation_jacobian(tensors, m, Rs, Rf, Sigma, Sigma_floor):
    """Dense Picard matrix J~ (nm, nm) [s^-1] of one cell with S_coag = J~ Sigma, DustPy 1.0.9
    ``jacobian_coagulation_generator`` (Stammler & Birnstiel 2022 §3, eq. for the implicit coagulation).

    Each pair (j <= i <= imax) is booked in column i (the larger partner), with the rate N_j R_ji:
    J~[k, i] += (m_k/m_i) c_k N_j Rs_ji for the sticking products, J~[:, i] += A_ji phi[lf_ji, :] / m_i
    N_j Rf_ji for the fragments, and the remnant and loss terms (diagonal -1, remnant bins, and
    J~[j, i] -= (m_j/m_i) N_j Rf_ji). Entries below the q-th sub-diagonal are dropped as DustPy's sparse
    output does (they are zero for a correct grid). Every column conserves mass: sum_k J~[k, i] = 0
    to round-off. Assembled with one segment sum and one matmul.

    Arguments as :func:`coagulation_source`. Returns (nm, nm); vmap over cells.
    """
    m = jnp.asarray(m, dtype=jnp.result_type(float))
    Rs, Rf, Sigma = (jnp.asarray(x, dtype=m.dtype) for x in (Rs, Rf, Sigma))
    _check_cell(tensors, Rs, Rf, Sigma)
    nm = m.shape[0]
    P = _active_pairs(tensors, Sigma, Sigma_floor)
    n = Sigma / m
    rs = (n[:, None] * Rs * P).reshape(-1)
    rf = (n[:, None] * Rf * P).reshape(-1)
    rate = jnp.where(tensors.seg_frag, rf[tensors.seg_pair], rs[tensors.seg_pair])
    flat = jax.ops.segment_sum(tensors.seg_coef_j * rate, tensors.seg_row * nm + tensors.seg_col,
                               num_segments=nm * nm)
    # fragments: W[l, i] = sum_{j: lf_ji = l} A_ji N_j Rf_ji / m_i ; J~_frag = phi^T W
    lf = tensors.lf_ind
    w = (tensors.A / m[None, :]).reshape(-1) * rf
    seg = jnp.where(lf >= 0, lf * nm + jnp.arange(nm)[None, :], nm * nm).reshape(-1)
    W = jax.ops.segment_sum(w, seg, num_segments=nm * nm + 1)[:nm * nm].reshape(nm, nm)
    return (flat.reshape(nm, nm) + tensors.phi.T @ W) * tensors.band
