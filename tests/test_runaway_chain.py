"""jaxcoag.analytic.runaway_time_chain / log_explosion_cdf: the monomer-bath birth-chain reference
for the runaway time of K = (m_i m_j)^nu (thesis Fig. 5.7; Malyshkin & Goodman 2001).

Checks: the saddlepoint F against brute-force sampling of T = sum_{k>=2} E_k/k^nu and against
its large-deviation asymptote; the outer integrals against a direct Monte Carlo of the model;
t_R(N) monotone with the (ln N)^(1-nu) slope; the exact-DSMC anchors (a known model limitation,
see test_dsmc_anchors); input validation.
"""

import numpy as np
import pytest
from scipy import special

from jaxcoag import analytic as A
from jaxcoag._validate import JaxcoagInputError

NS = [1e3, 1e4, 1e5, 1e10, 1e20, 1e40, 1e80, 1e160]
# exact ungrouped DSMC, mean +- s.e. over 40 runs (t in units of 1/(K(1,1) n_1))
ANCHORS = {2.0: {1e4: (0.143, 0.002), 1e5: (0.1198, 0.0013)},
           3.0: {1e4: (0.0358, 0.0010), 1e5: (0.0247, 0.0006)}}


def _sample_T(nu, n, kmax, rng):
    """T = sum_{k=2}^{kmax} E_k/k^nu + (mean of the remainder), n samples (chunked)."""
    w = np.arange(2.0, kmax + 1.0) ** -nu
    rem = special.zeta(nu, kmax + 1.0)
    out = [rng.standard_exponential((n // 10, w.size)) @ w for _ in range(10)]
    return np.concatenate(out) + rem


@pytest.mark.parametrize("nu,kmax", [(2.0, 100), (3.0, 40)])
def test_log_F_vs_bruteforce(nu, kmax):
    # remainder sd: sqrt(zeta(2 nu, kmax+1)) = 6e-4 (nu=2), 4e-5 (nu=3), << quantile widths
    n = 1_000_000
    T = np.sort(_sample_T(nu, n, kmax, np.random.default_rng(20260101)))
    for p in (1e-1, 1e-2, 1e-3, 1e-4):
        u = T[int(p * n)]
        F_mc = np.mean(T <= u)
        se = np.sqrt(F_mc * (1.0 - F_mc) / n) / F_mc           # relative binomial s.e.
        F_sp = np.exp(A.log_explosion_cdf(u, nu))
        assert abs(F_sp / F_mc - 1.0) < 3.0 * se + 0.04, (p, u, F_mc, F_sp)


@pytest.mark.parametrize("nu", [2.0, 3.0])
def test_log_F_shape_and_asymptote(nu):
    u = np.geomspace(1e-9, 30.0, 400)
    lf = A.log_explosion_cdf(u, nu)
    assert np.all(np.isfinite(lf)) and np.all(lf <= 0.0)
    d = np.diff(lf)
    assert np.all(d >= 0) and np.all(d[lf[1:] < -1e-12] > 0)              # monotone
    assert lf[-1] > -1e-12 and lf[0] < -1e4
    # large deviations: ln F ~ -(1 - 1/nu) C0^(nu/(nu-1)) (nu u)^(-1/(nu-1)), C0 = pi/sin(pi/nu)
    us = np.geomspace(1e-9, 1e-3, 7)
    c0 = np.pi / np.sin(np.pi / nu)
    lead = -(1.0 - 1.0 / nu) * c0 ** (nu / (nu - 1.0)) * (nu * us) ** (-1.0 / (nu - 1.0))
    ratio = A.log_explosion_cdf(us, nu) / lead
    assert np.all(np.diff(ratio) < 0)                       # approaches 1 as u -> 0
    assert abs(ratio[0] - 1.0) < 1e-3
    # vectorised == scalar, and the edges
    assert A.log_explosion_cdf(u[123], nu) == pytest.approx(lf[123], rel=1e-12)
    assert A.log_explosion_cdf(0.0, nu) == -np.inf
    assert A.log_explosion_cdf(np.inf, nu) == 0.0
    assert A.log_explosion_cdf(np.ones((2, 3)), nu).shape == (2, 3)


@pytest.mark.parametrize("nu,N,smax,reps", [(2.0, 1e3, 1.0, 1500), (3.0, 1e3, 0.4, 1500)])
def test_outer_integrals_vs_model_montecarlo(nu, N, smax, reps):
    """Direct Monte Carlo of the model: dimers born at sigma ~ (N/2) e^-sigma, t_R = e^min(sigma+T) - 1."""
    rng = np.random.default_rng(7)
    kmax = 100 if nu == 2.0 else 40
    w = np.arange(2.0, kmax + 1.0) ** -nu
    rem = special.zeta(nu, kmax + 1.0)
    pb = -np.expm1(-smax)
    tau = np.empty(reps)
    for r in range(reps):
        n = rng.poisson(0.5 * N * pb)
        sig = -np.log1p(-rng.random(n) * pb)
        tau[r] = np.min(sig + rng.standard_exponential((n, w.size)) @ w + rem)
    assert tau.max() < smax                        # the cut at sigma <= smax is exact
    t = np.expm1(tau)
    res = A.runaway_time_chain(N, nu)
    se = t.std() / np.sqrt(reps)
    assert abs(res["mean"] - t.mean()) < 4.0 * se + 0.01 * t.mean()
    assert res["std"] == pytest.approx(t.std(), rel=0.1)
    assert res["median"] == pytest.approx(np.median(t), rel=0.03)


@pytest.mark.parametrize("nu", [2.0, 3.0])
def test_mean_decreasing_and_log_slope(nu):
    r = [A.runaway_time_chain(N, nu) for N in NS]
    m = np.array([x["mean"] for x in r])
    assert np.all(np.diff(m) < 0)
    for x in r:
        assert x["std"] > 0 and 0.5 * x["mean"] < x["median"] < 1.5 * x["mean"]
    slope = (np.log(m[-1]) - np.log(m[-2])) / (np.log(np.log(1e160)) - np.log(np.log(1e80)))
    assert abs(slope - (1.0 - nu)) < 0.15 * abs(1.0 - nu), slope


@pytest.mark.parametrize("nu, lo, hi", [(2.0, 1.55, 1.9), (3.0, 1.15, 1.45)])
def test_dsmc_anchors_upper_bound(nu, lo, hi):
    """The monomer-bath chain omits the growing body's accretion of dimers, trimers, ... (rate
    k^nu sum_j j^(nu+1) n_j instead of k^nu n_1: 1.4-2.5x faster at the DSMC t_R of N = 1e4-1e5),
    so it is an upper bound on t_R there: measured ratio model/DSMC 1.77, 1.69 (nu = 2, N = 1e4,
    1e5) and 1.29, 1.29 (nu = 3). The correction is O(t_R) and vanishes as N grows (t_R -> 0)."""
    for N, (mean, se) in ANCHORS[nu].items():
        if N < 1e4:
            continue
        ratio = A.runaway_time_chain(N, nu)["mean"] / mean
        assert lo < ratio < hi, (nu, N, ratio)


def test_no_depletion_and_small_n():
    r = A.runaway_time_chain(1.5, 2.0, depletion=False)
    assert np.isfinite(r["mean"]) and r["mean"] > A.runaway_time_chain(1e3, 2.0, depletion=False)["mean"]
    # constant bath: no e^-sigma and tau = t, so runaway is (slightly) earlier than with depletion
    assert A.runaway_time_chain(1e4, 2.0, depletion=False)["mean"] < A.runaway_time_chain(1e4, 2.0)["mean"]
    assert np.isfinite(A.runaway_time_chain(1e300, 3.0)["mean"])


@pytest.mark.parametrize("kw", [dict(n_particles=1.0, nu=2.0), dict(n_particles=0.5, nu=2.0),
                                dict(n_particles=np.inf, nu=2.0), dict(n_particles=np.nan, nu=2.0),
                                dict(n_particles=-5.0, nu=2.0), dict(n_particles="many", nu=2.0),
                                dict(n_particles=1e4, nu=1.0), dict(n_particles=1e4, nu=0.5),
                                dict(n_particles=1e4, nu=np.nan), dict(n_particles=1e4, nu=np.inf),
                                dict(n_particles=1e4, nu=None), dict(n_particles=50.0, nu=2.0)])
def test_bad_input(kw):
    with pytest.raises(JaxcoagInputError):
        A.runaway_time_chain(**kw)


def test_bad_input_cdf():
    for u, nu in [(-1.0, 2.0), (np.nan, 2.0), (0.1, 1.0), (0.1, -2.0), ([0.1, -0.1], 3.0)]:
        with pytest.raises(JaxcoagInputError):
            A.log_explosion_cdf(u, nu)
