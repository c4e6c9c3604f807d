"""Branches decided on grid masses are decided exactly, not by round-off.

Grid log-centres/edges carry a round-off of a few ulp of |ln m|, so masses that coincide
mathematically (two centres exactly a factor 10 apart on a 7-per-decade grid, a monomer mass on a
bin edge, a product of exactly n monomers) fall on either side of a bare ``>=`` by chance. Every
such decision uses the documented tolerance ``jaxcoag.binned.grid.LOG_TOL`` (relative 1e-9).
Each test below fails on the code before the fix (the failing values are given per test).
"""

import functools

import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag import Binned, evolve
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.binned import MassGrid, monodisperse
from jaxcoag.binned.grid import LOG_TOL
from jaxcoag.binned.redistribution import fragment_weights
from jaxcoag.binned.twobin import pair_indices
from jaxcoag.outcomes import O07Recipe, ShatterAbove, Shattering
from jaxcoag.physics.contact import Material
from jaxcoag.physics.ormel07 import o07_outcome

from _testkernels import SqrtAlphaKernel  # noqa: E402  (shared test kernel)

KERNEL = SqrtAlphaKernel(1e-2)  # fragmentation barrier m_b = 1e6 (1e4/(1e-2 1e10))^1.5 = 1 g


def _erodes(frag, grid):
    """Boolean per pair (iL >= iS): erosion (ejecta (1 + chi) m_S from the projectile's bin S)."""
    iL, iS = pair_indices(grid.nbins)
    d = frag.twobin_data(KERNEL, grid, iL, iS)
    ero = (np.asarray(d.src) == iS) & (iL > iS)  # (i = i pairs: source L = S, they shatter)
    mS = np.exp(grid.log_centers[iS])
    # erosion ejecta (1 + chi) m_S, shattering ejecta m_L + m_S: the two branches are distinct
    np.testing.assert_allclose(np.asarray(d.ejecta)[ero], (1.0 + frag.chi) * mS[ero], rtol=1e-14)
    np.testing.assert_allclose(np.asarray(d.ejecta)[~ero], np.exp(grid.log_centers[iL[~ero]]) + mS[~ero],
                               rtol=1e-14)
    return iL, iS, ero


def test_pairs_exactly_a_factor_10_apart_all_erode():
    """7 bins/decade, crater_ratio = 10: every pair 7 bins apart (ratio exactly 10) erodes, every
    pair 6 bins apart (ratio 10^(6/7) = 7.2) shatters. Before the fix only 94 of the 133 pairs
    with offset 7 eroded on this grid (the rest shattered by the sign of a ~1e-15 round-off)."""
    g = MassGrid.log(1e-12, 1e8, 7)
    iL, iS, ero = _erodes(Shattering(100.0), g)
    off = iL - iS
    n7 = int(np.sum(off == 7))
    assert n7 == g.nbins - 7 == 133
    assert int(np.sum(ero & (off == 7))) == n7
    # the rule is integer offset >= 7 on this uniform grid: erosion set == {offset >= 7}
    np.testing.assert_array_equal(ero, off >= 7)
    # the tolerance is far inside the grid spacing and far above the log-centre round-off
    dl = g.log_centers[iL] - g.log_centers[iS]
    assert np.max(np.abs(dl[off == 7] - np.log(10.0))) < 1e-3 * LOG_TOL
    assert np.min(np.abs(dl[off != 7] - np.log(10.0))) > 1e7 * LOG_TOL


def test_pair_a_hair_below_the_ratio_erodes_and_crater_ratio_within_tolerance_is_the_same():
    """Deterministic version of the trap: log spacing ln(10)/7 (1 - 1e-14), so every offset-7 pair
    has ln(m_L/m_S) = ln 10 - 2.3e-14 < ln 10. The bare ``>=`` made all 42 of them shatter; with
    the tolerance they all erode, for crater_ratio 10, 10 (1 - 1e-9) and 10 (1 + 1e-10) alike."""
    n = 49
    g = MassGrid(np.log(1e-4) + np.arange(n + 1) * (np.log(10.0) / 7.0) * (1.0 - 1e-14))
    ref = None
    for cr in (10.0, 10.0 * (1.0 - 1e-9), 10.0 * (1.0 + 1e-10)):
        iL, iS, ero = _erodes(Shattering(100.0, crater_ratio=cr), g)
        assert int(np.sum(ero & (iL - iS == 7))) == n - 7 == 42
        np.testing.assert_array_equal(ero, iL - iS >= 7)
        ref = ero if ref is None else ref
        np.testing.assert_array_equal(ero, ref)
    # a ratio clearly below crater_ratio (10^(6/7) at 1.0001 x 10^(6/7)) still shatters
    _, _, ero = _erodes(Shattering(100.0, crater_ratio=1.0001 * 10 ** (6 / 7)), g)
    np.testing.assert_array_equal(ero, iL - iS >= 7)


@functools.lru_cache(maxsize=None)
def _frag_run(crater_ratio):
    """Shattering + erosion on a 7-per-decade grid 1e-4..1e2 g (42 bins), monomers 1e-4 g, to a
    steady state below the 1 g barrier (measured: gel 2e-20 of 1e-6, mass drift 1.9e-11)."""
    bpd = 7
    g = MassGrid.log(1e-4 * 10 ** (-0.5 / bpd), 1e2, bpd)
    ts = np.concatenate([[0.0], np.logspace(4, 10, 4)])
    sol = evolve(KERNEL, Binned(g, rtol=1e-5, atol=1e-10), monodisperse(g, 1e-4, 1e-6), ts,
                 outcome=Shattering(100.0, crater_ratio=crater_ratio))
    return g, sol


def test_fragmentation_run_identical_for_crater_ratio_10_and_a_hair_below():
    """crater_ratio = 10 and 10 (1 - 1e-9) give bit-identical runs. Before the fix 9 of the 35
    offset-7 pairs shattered for 10 and none for 10 (1 - 1e-9): final mass distributions differed
    by L1 = 1.1e-4 (relative), the mass-weighted mean mass by 8e-4."""
    g, a = _frag_run(10.0)
    _, b = _frag_run(10.0 * (1.0 - 1e-9))
    ra, rb = np.asarray(a.mass_per_bin()), np.asarray(b.mass_per_bin())
    np.testing.assert_array_equal(ra, rb)
    np.testing.assert_array_equal(np.asarray(a.gel_mass), np.asarray(b.gel_mass))
    # it is a fragmentation-limited steady state (the branch matters): mass conserved, steady,
    # peak below the barrier m_b = 1 g, nothing in the gel
    assert np.max(np.abs(np.asarray(a.mass_drift))) < 1e-9
    assert np.abs(ra[-1] - ra[-2]).sum() / ra[-1].sum() < 1e-8
    assert 1.0 / 30 < g.centers[np.argmax(ra[-1])] < 1.0
    assert float(a.gel_mass[-1]) < 1e-12 * 1e-6


def test_shatter_above_product_exactly_at_m_frag_sticks():
    """ShatterAbove: a product exactly at m_frag does not exceed it (sticks), also when the
    sum of two bin centres rounds one ulp above (2 x 4.000000000000001 = 8.000000000000002 on a
    grid with centres 1, 2, 4, ... g: the bare ``>`` shattered that pair)."""
    frag = ShatterAbove(8.0, 1.0)  # monomers of 1 g: the bottom bin of the factor-2 grid below
    m4 = jnp.nextafter(4.0, 5.0)
    assert float(m4 + m4) > 8.0
    assert float(frag.probability(None, m4, m4)) == 0.0
    assert float(frag.probability(None, jnp.asarray(4.0), jnp.asarray(4.0))) == 0.0
    assert float(frag.probability(None, jnp.asarray(4.0), jnp.asarray(4.0 * (1 + 1e-8)))) == 1.0
    # on the factor-2 grid: exactly the pairs whose sum exceeds 8 g shatter (ulp-level sums stick)
    g = MassGrid.from_edges(2.0 ** (np.arange(9) - 0.5))
    iL, iS = pair_indices(g.nbins)
    p = np.asarray(frag.twobin_data(None, g, iL, iS).p)
    exact = 2.0 ** iL + 2.0 ** iS  # the centres are 2^k g up to round-off
    np.testing.assert_array_equal(p, (exact > 8.0).astype(float))


def test_monodisperse_on_a_bin_edge():
    """m0 on an edge belongs to the bin above it ([m_lo, m_hi)). Before the fix
    ``monodisperse(MassGrid.log(2.0, ...), 2.0)`` raised "outside the grid" (ln 10 log10(2)
    rounds 1.1e-16 above ln 2) and m0 = 7 g on edge 7 of MassGrid.log(0.7, 7e7, 7) went to
    bin 6 (ln 7 rounds 2.2e-16 below that edge)."""
    g = MassGrid.log(2.0, 2e6, 7)
    n = monodisperse(g, 2.0, 1.0)
    assert np.flatnonzero(n).tolist() == [0]
    assert n[0] * g.centers[0] == pytest.approx(1.0, rel=1e-15)
    g2 = MassGrid.log(0.7, 7e7, 7)
    assert np.flatnonzero(monodisperse(g2, 7.0, 1.0)).tolist() == [7]
    # clearly outside still raises; just below an edge (1e-6 relative) stays in the lower bin
    with pytest.raises(JaxcoagInputError, match="outside the grid"):
        monodisperse(g, 2.0 * (1 - 1e-6), 1.0)
    assert np.flatnonzero(monodisperse(g2, 7.0 * (1 - 1e-6), 1.0)).tolist() == [6]


def test_degenerate_fragment_range_on_a_bin_edge():
    """Monomer fragments (m_lo = m_hi) on an interior edge go to the bin above it, as in
    ``monodisperse``: 7 g on edge 7 of MassGrid.log(0.7, 7e7, 7) (bin 6 before the fix), also
    0.65 g on edge 14 of MassGrid.log(6.5e-3, 6.5e5, 7) (bin 13 before the fix)."""
    g = MassGrid.log(0.7, 7e7, 7)
    for m, b in ((7.0, 7), (7.0 * (1 - 1e-6), 6), (7.0 * (1 + 1e-6), 7), (0.7, 0), (7e7, g.nbins - 1)):
        W = np.asarray(fragment_weights(g.log_edges, -2.0, jnp.asarray([m]), jnp.asarray([m])))
        np.testing.assert_array_equal(W[0], np.eye(g.nbins)[b])
    g = MassGrid.log(6.5e-3, 6.5e5, 7)
    W = np.asarray(fragment_weights(g.log_edges, -2.0, jnp.asarray([0.65]), jnp.asarray([0.65])))
    np.testing.assert_array_equal(W[0], np.eye(g.nbins)[14])


def test_o07_small_n_branch_for_a_product_of_exactly_n_small_monomers():
    """O07Recipe(n_small=40): a product of exactly 40 monomers uses B = 0 even when its mass,
    summed in float64, is one ulp above 40 m0 (as 2 of 5 distinct float representations of 40 m0
    were when built by random sticking of m0 = 1.26e-15 g); before the fix it took B = 1
    (psi = 3.385 instead of 2.990 here). 41 monomers still use B = 1."""
    mat = Material.ch2_quartz()
    m0 = float(mat.m0)
    m1, m2 = np.nextafter(32 * m0, np.inf), 8 * m0
    assert (m1 + m2) / m0 > 40.0
    rec = O07Recipe(n_small=40)
    dv = 1e-2
    psi = float(rec(jnp.asarray(m1), 3.0, jnp.asarray(m2), 2.0, dv, mat).psi_one)
    b0 = float(o07_outcome(m1, 3.0, m2, 2.0, dv, mat, B=0.0, validate=False).psi_one)
    b1 = float(o07_outcome(m1, 3.0, m2, 2.0, dv, mat, B=1.0, validate=False).psi_one)
    assert psi == b0 and abs(b1 / b0 - 1) > 0.1
    m41 = 33 * m0
    assert float(rec(jnp.asarray(m41), 3.0, jnp.asarray(m2), 2.0, dv, mat).psi_one) == pytest.approx(
        float(o07_outcome(m41, 3.0, m2, 2.0, dv, mat, B=1.0, validate=False).psi_one), rel=1e-15)
