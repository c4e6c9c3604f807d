"""Bridge from the rigid box to coagulation (jaxcoag.aggregates.rigid.bridge; Richardson 1995 eqs. 29-31).

Default tests (no box engine compilation, a few seconds):

* the kernel estimator on a hand-made log: counts, class assignment, exposures and K exact (both
  quadratures), the path rebuilt from the log equal to the table; the tabulated kernel (ClassKernel,
  rate_table) piecewise constant over the classes, unmeasured pairs from the nearest measured one;
* the estimator on Marcus-Lushnikov (Gillespie) realisations of a known kernel a_ij = a0 (i + j) / 2
  (three seeds, none picked): every class pair with >= 20 expected counts within 4 of its stated Poisson
  sigma (largest |z| of ~10 pairs; P(|z| > 4) ~ 6e-5 each) and chi^2 of the z-scores with p > 1e-3;
* the discrete coagulation equation (R29) with a constant kernel against R30 (N to 1e-8) and R31 (n_k,
  k <= 10, to 1e-7 of N0): deterministic;
* bad input raises JaxcoagInputError.

Slow (they compile the box engine, tens of seconds on 2 cores): model (i), N0 = 300, seeds 1, 2, 3 pooled:
the measured kernel for the class pairs (1,1), (1,2), (2,2) within 3 Poisson sigma of sigma<v> = alpha V
(sigma = alpha V / sqrt(mu), mu = alpha E the expected count over the measured exposure E); the two
exposures (exact path vs trapezoid on 83 outputs) agree within the trapezoid's error bound;
compare_model_i: the binned engine and the k-mer integration reproduce R30 to 1e-6 and R31 for small k;
the quick mode of paper_figs/figR13_bridge.py.
"""

import math
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from jaxcoag._validate import JaxcoagInputError
from jaxcoag.aggregates import rigid
from jaxcoag.aggregates.rigid import bridge

from _scripts import ROOT, load_script  # noqa: E402

EDGES = np.array([0.5, 1.5, 2.5, 4.5])


# ------------------------------------------------------------------------------------------------ exact counting
def test_estimator_on_a_hand_made_log_is_exact():
    # 4 monomers in V = 10: 1+1 at t=1, 1+1 at t=2, 2+2 at t=3 (classes: k=1, k=2, k=3-4)
    t = np.array([0.0, 1.0, 2.0, 3.0])
    N = np.array([[4, 0, 0], [2, 1, 0], [0, 2, 0], [0, 0, 1]])
    tc, ma, mb = np.array([1.0, 2.0, 3.0]), np.array([1.0, 1.0, 2.0]), np.array([1.0, 1.0, 2.0])
    tp, Np = bridge.path_from_log(0.0, N[0], tc, ma, mb, EDGES)
    np.testing.assert_array_equal(tp, t)
    np.testing.assert_array_equal(Np, N)
    np.testing.assert_array_equal(bridge.class_index([0.5, 1.0, 1.49, 2.0, 3.0, 4.49, 4.5, 0.4], EDGES),
                                  [0, 0, 0, 1, 2, 2, -1, -1])
    mk = bridge.kernel_from_arrays(tc, ma, mb, t, N, 10.0, EDGES)
    np.testing.assert_array_equal(mk.counts, [[2, 0, 0], [0, 1, 0], [0, 0, 0]])
    # pairs per interval: (1,1): 6, 1, 0; (1,2): 0, 2, 0; (2,2): 0, 0, 1; class 3 never before t = 3
    np.testing.assert_array_equal(mk.exposure, [[7.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(mk.K[:2, :2], [[20.0 / 7.0, 0.0], [0.0, 10.0]], rtol=1e-15)
    np.testing.assert_allclose(mk.sigma[:2, :2], [[10 * math.sqrt(2) / 7, 5.0], [5.0, 10.0]], rtol=1e-15)
    np.testing.assert_allclose(mk.rate[:2, :2], mk.K[:2, :2] / 10.0, rtol=1e-15)
    assert np.all(np.isnan(mk.K[2])) and np.all(mk.exposure_err == 0)
    tr = bridge.kernel_from_arrays(tc, ma, mb, t, N, 10.0, EDGES, quadrature="trapezoid")
    # (1,1): trapezoid (6+1)/2 + (1+0)/2 + 0 = 4, error bound (5 + 1 + 0)/2 = 3; exact 7 within it
    assert tr.exposure[0, 0] == 4.0 and tr.exposure_err[0, 0] == 3.0
    assert abs(tr.exposure[0, 0] - mk.exposure[0, 0]) <= tr.exposure_err[0, 0]
    # window (t[0], t[-1]]: only the collisions inside count
    part = bridge.kernel_from_arrays(tc, ma, mb, t[:3], N[:3], 10.0, EDGES)
    assert part.counts.sum() == 2 and part.counts[0, 0] == 2


def test_tabulated_kernel_is_piecewise_constant_over_the_classes():
    t = np.array([0.0, 1.0, 2.0, 3.0])
    N = np.array([[4, 0, 0], [2, 1, 0], [0, 2, 0], [0, 0, 1]])
    mk = bridge.kernel_from_arrays([1.0, 2.0, 3.0], [1.0, 1.0, 2.0], [1.0, 1.0, 2.0], t, N, 10.0, EDGES)
    # class 3 (k = 3-4) was never present with anything: its row is the nearest measured pair's value
    kern = bridge.ClassKernel.from_measured(mk)
    tab = np.asarray(kern.table)
    np.testing.assert_allclose(tab[:2, :2], mk.K[:2, :2], rtol=1e-15)
    assert tab[2, 2] == mk.K[1, 1] and tab[0, 2] == mk.K[0, 1] and tab[2, 0] == mk.K[1, 0]
    m1 = np.array([0.7, 1.0, 1.6, 2.0, 3.0, 4.4, 100.0])
    np.testing.assert_allclose(np.asarray(kern(m1, np.ones_like(m1))), tab[[0, 0, 1, 1, 2, 2, 2], 0], rtol=1e-15)
    a = bridge.rate_table(mk, 6)                    # k-mers 1..6 -> classes 0, 1, 2, 2, 2 (top), 2
    np.testing.assert_allclose(a, tab[np.ix_([0, 1, 2, 2, 2, 2], [0, 1, 2, 2, 2, 2])] / 10.0, rtol=1e-15)


# ------------------------------------------------------------------------------------------------ known rates
def _gillespie(a, n0, t_end, rng):
    """Marcus-Lushnikov process with rate a[i-1, j-1] per pair of an i-mer and a j-mer (numbers, by species)."""
    kmax = a.shape[0]
    n = np.zeros(kmax, np.int64)
    n[0] = n0
    t, ts, Ns, log = 0.0, [0.0], [n.copy()], []
    while True:
        occ = np.nonzero(n)[0]                      # occupied species only
        no = n[occ].astype(float)
        P = np.outer(no, no)
        P[np.diag_indices(occ.size)] = 0.5 * no * (no - 1.0)
        iu = np.triu_indices(occ.size)
        r = (a[np.ix_(occ, occ)] * P)[iu]
        R = r.sum()
        if R <= 0:
            break
        t += rng.exponential(1.0 / R)
        if t > t_end:
            break
        e = rng.choice(r.size, p=r / R)
        i, j = occ[iu[0][e]], occ[iu[1][e]]
        if i + j + 1 >= kmax:  # product beyond the table: stop (not reached for these parameters)
            break
        n[i] -= 1
        n[j] -= 1
        n[i + j + 1] += 1
        ts.append(t)
        Ns.append(n.copy())
        log.append((t, i + 1.0, j + 1.0))
    return np.array(ts), np.array(Ns), np.array(log)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_estimator_recovers_a_known_kernel_within_poisson_errors(seed):
    kmax, n0, V, t_end = 128, 2000, 50.0, 6.0
    k = np.arange(1, kmax + 1)
    a0 = 2e-4                                      # N ~ n0 exp(-a0 n0 t / 2): 0.3 n0 at t_end, ~1400 events
    a = a0 * 0.5 * (k[:, None] + k[None, :])       # rate per pair [1/time]: K = a V
    ts, Ns, log = _gillespie(a, n0, t_end, np.random.default_rng(seed))
    assert ts.size > 1000 and Ns[-1, -1] == 0      # the table was never outgrown
    edges = bridge.octave_edges(1.0, kmax)         # classes 1, 2, 3-4, 5-8, ...
    C = edges.size - 1
    cls = bridge.class_index(k, edges)
    Nc = np.stack([np.bincount(cls, weights=row, minlength=C) for row in Ns])
    t_tab = np.concatenate([ts, [t_end]])
    N_tab = np.concatenate([Nc, Nc[-1:]])
    mk = bridge.kernel_from_arrays(log[:, 0], log[:, 1], log[:, 2], t_tab, N_tab, V, edges)
    # counts: every event, by class, exact
    ca, cb = bridge.class_index(log[:, 1], edges), bridge.class_index(log[:, 2], edges)
    ref = np.zeros((C, C), int)
    for i, j in zip(ca, cb):
        ref[i, j] += 1
        if i != j:
            ref[j, i] += 1
    np.testing.assert_array_equal(mk.counts, ref)
    assert np.triu(mk.counts).sum() == len(log)
    # the true class kernel: a_ij averaged over the k-mers of each class, weighted by their exposure
    w = np.diff(np.concatenate([ts, [t_end]]))      # time each state of the path holds
    Nf = Ns.astype(float)
    Ek = (Nf * w[:, None]).T @ Nf - np.diag(w @ Nf)  # ordered pairs of k-mers x time
    num = np.zeros((C, C))
    den = np.zeros((C, C))
    np.add.at(num, (cls[:, None], cls[None, :]), a * Ek)
    np.add.at(den, (cls[:, None], cls[None, :]), Ek)
    K_true = V * num / np.where(den > 0, den, 1.0)
    # class pairs with >= 20 expected counts (selecting on the observed counts would bias upwards)
    mu = K_true * mk.exposure / V
    use = (mu >= 20) & np.triu(np.ones((C, C), bool))
    assert use.sum() >= 5, mk.counts
    z = (mk.K[use] - K_true[use]) / mk.sigma[use]  # the estimator's own (stated) Poisson error
    assert np.max(np.abs(z)) < 4.0, z
    assert stats.chi2.sf(np.sum(z**2), z.size) > 1e-3, z
    # model check of the estimator's own error: sigma = K / sqrt(c)
    np.testing.assert_allclose(mk.sigma[use], mk.K[use] / np.sqrt(mk.counts[use]), rtol=1e-12)


# ------------------------------------------------------------------------------------------------ R29-R31
def test_discrete_smoluchowski_with_constant_kernel_matches_R30_R31():
    n0, alpha, kmax = 100, 0.02, 80
    t = np.array([0.0, 0.3, 1.0, 2.0])            # tau = alpha n0 t / 2 up to 2 (f = 1/3)
    init = np.zeros(kmax)
    init[0] = n0
    s = bridge.smoluchowski(alpha, init, t)
    N30 = n0 / (1.0 + 0.5 * alpha * n0 * t)
    np.testing.assert_allclose(s["N"], N30, rtol=1e-8)
    f = N30 / n0
    k = np.arange(1, 11)
    n31 = n0 * f[:, None] ** 2 * (1.0 - f[:, None]) ** (k - 1)
    np.testing.assert_allclose(s["n"][:, :10], n31, rtol=0, atol=1e-7 * n0)
    assert np.max(np.abs(s["lost"])) < 1e-12
    # the same with the (constant) table form of the rate
    s2 = bridge.smoluchowski(np.full((kmax, kmax), alpha), init, t)
    np.testing.assert_allclose(s2["n"], s["n"], rtol=0, atol=1e-12 * n0)


def test_bad_input_is_refused():
    t = np.array([0.0, 1.0])
    N = np.array([[2, 0], [0, 1]])
    with pytest.raises(JaxcoagInputError, match="increasing"):
        bridge.kernel_from_arrays([0.5], [1.0], [1.0], t, N, 1.0, [0.5, 2.5, 1.5])
    with pytest.raises(JaxcoagInputError, match="no coagulation"):
        bridge.kernel_from_arrays([], [], [], t, N, 1.0, [0.5, 1.5, 2.5])
    with pytest.raises(JaxcoagInputError, match="outside the class edges"):
        bridge.kernel_from_arrays([0.5], [7.0], [1.0], t, N, 1.0, [0.5, 1.5, 2.5])
    with pytest.raises(JaxcoagInputError, match="shape"):
        bridge.kernel_from_arrays([0.5], [1.0], [1.0], t, N[:, :1], 1.0, [0.5, 1.5, 2.5])
    with pytest.raises(JaxcoagInputError, match="quadrature"):
        bridge.kernel_from_arrays([0.5], [1.0], [1.0], t, N, 1.0, [0.5, 1.5, 2.5], quadrature="simpson")
    with pytest.raises(JaxcoagInputError, match="BoxResult"):
        bridge.measured_kernel({"t": t})
    with pytest.raises(JaxcoagInputError, match="rate"):
        bridge.smoluchowski(-1.0, [1.0, 0.0], t)
    with pytest.raises(JaxcoagInputError, match="table"):
        bridge.ClassKernel(np.ones((3, 3)), [0.5, 1.5, 2.5])


# ------------------------------------------------------------------------------------------------ model (i) box
N0_I = 300
T_I = np.linspace(0.0, 8.2, 83)   # v0 = 13: tau = alpha N0 T / 2 = 2.7


@pytest.fixture(scope="module")
def model_i_runs():
    return [rigid.run(rigid.box_model("i", n0=N0_I, v0=13.0, key=jax.random.key(s)), jnp.asarray(T_I))
            for s in (1, 2, 3)]


@pytest.mark.slow
def test_model_i_measured_kernel_is_alpha(model_i_runs):
    alpha = rigid.box_model("i", n0=N0_I, v0=13.0, key=jax.random.key(1)).alpha
    edges = (np.arange(N0_I + 1) + 0.5)
    mks = [bridge.measured_kernel(r, edges) for r in model_i_runs]
    V = mks[0].V
    assert V == 1000.0
    c = sum(m.counts for m in mks)
    E = sum(m.exposure for m in mks)
    for i, j in ((0, 0), (0, 1), (1, 1)):
        mu = alpha * E[i, j]                          # expected coagulations if K = alpha V (R95 §3)
        assert mu >= 15, (mu, c[:3, :3])
        K = V * c[i, j] / E[i, j]
        # Poisson: c ~ mu +- sqrt(mu), i.e. K = alpha V (1 +- 1/sqrt(mu)) (the error of the observed count,
        # K / sqrt(c), is biased small for a downward fluctuation)
        sig = alpha * V / math.sqrt(mu)
        assert abs(K - alpha * V) <= 3.0 * sig, ((i + 1, j + 1), c[i, j], mu, K, alpha * V, sig)
    # every coagulation of the log is counted once; the exact path equals the recorded spectra
    for r, m in zip(model_i_runs, mks):
        assert np.triu(m.counts).sum() == int(np.asarray(r.n_coagulations)[-1])
        # trapezoid on the 83 outputs agrees with the exact exposure within its error bound
        tr = bridge.measured_kernel(r, edges, method="outputs")
        np.testing.assert_array_equal(tr.counts, m.counts)
        d = np.abs(tr.exposure - m.exposure)
        assert np.all(d[:3, :3] <= tr.exposure_err[:3, :3] + 1e-9), (d[:3, :3], tr.exposure_err[:3, :3])


@pytest.mark.slow
def test_model_i_binned_and_discrete_match_R30_R31(model_i_runs):
    c = bridge.compare_model_i(model_i_runs[0], kmax=120)
    np.testing.assert_allclose(c["N_binned"], c["N_R30"], rtol=1e-6)
    np.testing.assert_allclose(c["N_smol"], c["N_R30"], rtol=1e-6)
    np.testing.assert_allclose(c["n_smol"][:, :10], c["n_R31"][:, :10], rtol=0, atol=1e-6 * N0_I)
    assert np.max(np.abs(c["binned"]["mass_drift"])) < 1e-10
    # the box within 3 sigma + 1 % of R30 at T (sigma: Marcus-Lushnikov, spec A9, tau = 2.7: 2 % of N_th
    # for the mean of 3 runs of N0 = 1000, scaled to one run of N0 = 300 by sqrt(3 * 1000 / 300))
    sig = 0.02 * math.sqrt(10.0)
    assert abs(c["N_box"][-1] / c["N_R30"][-1] - 1.0) <= 3 * sig + 0.01
    assert c["N_box"][0] == N0_I and c["n_box"][0, 0] == N0_I


@pytest.mark.slow
def test_figR13_bridge_quick(tmp_path):
    mod = load_script(ROOT / "paper_figs" / "figR13_bridge.py", "_paper_fig_r95_bridge_")
    res = mod.main(["--quick", "--out", str(tmp_path)])
    png = pathlib.Path(res["png"])
    assert png.exists() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = {k: v for k, v in res["checks"].items() if v["counts"] and not v["ok"]}
    assert not bad, bad
    np.testing.assert_allclose(res["N_binned"], res["N_R30"], rtol=1e-6)
