"""jaxcoag.analytic vs Table 5.1, the post-gel Flory-sol reference values (Ernst, Ziff & Hendriks 1984), and
internal consistency (bin sums vs closed-form moments, Stirling/Euler-Maclaurin branches)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special
from scipy.integrate import quad

from jaxcoag import analytic as A
from jaxcoag._validate import JaxcoagInputError

F2 = 2.0 ** np.arange(0, 120)  # factor-2 bins [2^b, 2^(b+1))
COEFF = {"constant": 1.0, "sum": 0.5, "product": 1.0}  # Table 5.1


@pytest.mark.parametrize("t", [0.0, 0.5, 2.0, 10.0])
def test_table51_constant_sum(t):
    assert A.moments("constant", t, 0) == pytest.approx(1.0 / (1.0 + t / 2.0), rel=1e-14)
    assert A.moments("constant", t, 2) == pytest.approx(1.0 + t, rel=1e-14)
    assert A.moments("sum", t, 0, coeff=0.5) == pytest.approx(np.exp(-t / 2.0), rel=1e-14)
    assert A.moments("sum", t, 2, coeff=0.5) == pytest.approx(np.exp(t), rel=1e-14)
    for kind in ("constant", "sum"):
        assert A.moments(kind, t, 1, coeff=COEFF[kind]) == 1.0


@pytest.mark.parametrize("t,M0,M2", [(0.4, 0.8, 1.6667), (0.7, 0.65, 3.3333), (0.95, 0.525, 20.0)])
def test_product_pregel_reference(t, M0, M2):
    assert A.moments("product", t, 0) == pytest.approx(M0, abs=1e-4)
    assert A.moments("product", t, 2) == pytest.approx(M2, abs=1e-4)
    assert A.gel_fraction(t) == 0.0


@pytest.mark.parametrize("t,beta,M0,M2", [(1.05, 0.09370, 0.47508, 18.730), (1.3, 0.42297, 0.36060, 2.30941),
                                          (2.0, 0.79681, 0.16190, 0.34228)])
def test_product_postgel_reference(t, beta, M0, M2):
    """Post-gel reference values (Flory sol, Lambert W; independent float64 evaluation)."""
    assert A.gel_fraction(t) == pytest.approx(beta, abs=1e-5)
    assert A.moments("product", t, 0) == pytest.approx(M0, abs=1e-5)
    assert A.moments("product", t, 2) == pytest.approx(M2, rel=1e-4)
    b = A.gel_fraction(t)
    assert b == pytest.approx(1.0 - np.exp(-t * b), abs=1e-12)  # beta = 1 - exp(-t beta)
    assert A.moments("product", t, 1) == pytest.approx(1.0 - b, rel=1e-12)


@pytest.mark.parametrize("kind,t", [("constant", 3.0), ("constant", 300.0), ("sum", 4.0), ("sum", 30.0),
                                    ("product", 0.5), ("product", 0.99), ("product", 1.3), ("product", 3.0)])
def test_bin_sums_match_moments(kind, t):
    """Bin sums (exact below 2^16, Euler-Maclaurin beyond) reproduce M0 and M1 (sol mass post-gel)."""
    c = COEFF[kind]
    rho = A.mass_per_bin(kind, F2, t, coeff=c)
    nb = A.number_per_bin(kind, F2, t, coeff=c)
    assert rho.sum() == pytest.approx(A.moments(kind, t, 1, coeff=c), rel=2e-6)
    assert nb.sum() == pytest.approx(A.moments(kind, t, 0, coeff=c), rel=1e-6)
    assert np.all(rho >= 0)


def test_discrete_nk_values():
    # constant: n_k = f^2 (1-f)^(k-1), f = 1/(1+t/2)
    t = 2.0
    f = 1.0 / (1.0 + t / 2)
    k = np.arange(1, 6)
    assert np.allclose(A.number_density("constant", k, t), f * f * (1 - f) ** (k - 1), rtol=1e-14)
    # product: n_k = k^(k-2) t^(k-1) e^(-kt)/k!
    t = 0.7
    ref = k ** (k - 2.0) * t ** (k - 1.0) * np.exp(-k * t) / special.factorial(k)
    assert np.allclose(A.number_density("product", k, t), ref, rtol=1e-13)
    # sum (beta = 1/2): n_k = k^(k-1)/k! (1-T) T^(k-1) e^(-kT), T = 1 - e^(-t/2)
    t = 3.0
    T = 1 - np.exp(-t / 2)
    ref = k ** (k - 1.0) / special.factorial(k) * (1 - T) * T ** (k - 1) * np.exp(-k * T)
    assert np.allclose(A.number_density("sum", k, t, coeff=0.5), ref, rtol=1e-13)


@pytest.mark.parametrize("kind,t", [("sum", 5.0), ("product", 0.8), ("product", 1.5)])
def test_stirling_branch_continuous(kind, t):
    """Stirling branch (k > 100) agrees with the exact lgamma form to 1e-12 (absolute in log)."""
    k = np.array([101.0, 150.0, 400.0])
    got = A.log_nk(kind, k, t, coeff=COEFF[kind])
    tau = t * COEFF[kind]
    if kind == "sum":
        eps = np.exp(-tau)
        T = 1 - eps
        ref = (k - 1) * np.log(k) - special.gammaln(k + 1) + np.log(eps) + (k - 1) * np.log(T) - k * T
    else:
        ref = (k - 2) * np.log(k) - special.gammaln(k + 1) + (k - 1) * np.log(tau) - k * tau
    assert np.allclose(got, ref, atol=1e-10, rtol=0)


def test_exponential_initial_conditions():
    e = np.logspace(-8, 12, 161)
    for kind, t in [("constant", 50.0), ("sum", 3.0), ("product", 0.4)]:
        rho = A.mass_per_bin(kind, e, t, initial="exponential")
        nb = A.number_per_bin(kind, e, t, initial="exponential")
        assert rho.sum() == pytest.approx(1.0, rel=1e-6)
        assert nb.sum() == pytest.approx(A.moments(kind, t, 0, initial="exponential"), rel=1e-6)
    # t = 0 reduces to the initial exponential for every kernel
    m = np.array([0.1, 1.0, 7.0])
    for kind in ("constant", "sum", "product"):
        assert np.allclose(A.number_density(kind, m, 0.0, initial="exponential"), np.exp(-m), rtol=1e-13)
    # second moment of the product solution (series form) vs 2/(1 - 2 tau)
    f = lambda x: A.number_density("product", x, 0.3, initial="exponential")
    M2 = quad(lambda x: x * x * float(f(x)), 0, np.inf, limit=400)[0]
    assert M2 == pytest.approx(2.0 / (1 - 0.6), rel=1e-6)
    # sum kernel (Bessel form): M2 = 2 e^{2 beta t}
    f = lambda x: A.number_density("sum", x, 1.0, coeff=0.5, initial="exponential")
    M2 = quad(lambda x: x * x * float(f(x)), 0, np.inf, limit=400)[0]
    assert M2 == pytest.approx(2 * np.e, rel=1e-6)


def test_units_scaling():
    """n0, m0, coeff enter only through tau and the density/mass scales."""
    e = np.logspace(-3, 12, 100)
    r1 = A.mass_per_bin("sum", e, 4.0, coeff=0.5)
    r2 = A.mass_per_bin("sum", e * 1e-3, 2.0 / (3.0 * 1e-3 * 0.25), coeff=0.25, n0=3.0, m0=1e-3)
    assert np.allclose(r2, r1 * 3.0 * 1e-3, rtol=1e-10, atol=1e-300)


def test_input_errors():
    with pytest.raises(JaxcoagInputError, match="kind"):
        A.moments("linear", 1.0, 0)
    with pytest.raises(JaxcoagInputError, match="t must"):
        A.moments("sum", -1.0, 0)
    with pytest.raises(JaxcoagInputError, match="pre-gel"):
        A.number_density("product", 1.0, 0.6, initial="exponential")
    with pytest.raises(JaxcoagInputError, match="increasing"):
        A.mass_per_bin("sum", [1.0, 0.5, 2.0], 1.0)


def test_sum_kernel_exponential_start_keeps_mass_at_late_times():
    # regression: scipy's ive(1, z) is NaN above z ~ 1e9, which silently dropped mass (0.543 at tau = 10)
    from jaxcoag import analytic
    from jaxcoag.binned import MassGrid

    g = MassGrid.log(1e-6, 1e22, 10)
    for t, tol in ((10.0, 1e-10), (20.0, 1e-6)):
        mb = analytic.mass_per_bin("sum", g.edges, t, coeff=1.0, initial="exponential")
        assert np.all(np.isfinite(mb))
        np.testing.assert_allclose(np.sum(mb), 1.0, rtol=tol)
    z = np.array([1e5, 1e7, 1e12])
    from scipy import special
    np.testing.assert_allclose(analytic._log_ive1(z[:1]), np.log(special.ive(1, z[:1])), rtol=1e-14)
    np.testing.assert_allclose(analytic._log_ive1(z[1:2]), np.log(special.ive(1, z[1:2])), rtol=1e-12)
    assert np.isfinite(analytic._log_ive1(z[2:]))


def test_diagnostics_broadcast_over_leading_time_axis():
    # (nt, nbins) inputs work under jax_numpy_rank_promotion="raise" and equal row-by-row results
    from jaxcoag import diagnostics as D
    from jaxcoag.binned import MassGrid

    g = MassGrid.log(1e-3, 1e6, 5)
    rows = np.stack([A.mass_per_bin("constant", g.edges, t, initial="exponential") for t in (1.0, 10.0, 100.0)])
    for f in (D.m2f, D.mass_peak, lambda r, e: D.moment(r, e, 2)):
        whole = np.asarray(f(rows, g.edges))
        np.testing.assert_allclose(whole, np.stack([np.asarray(f(r, g.edges)) for r in rows]), rtol=1e-14)
    # the mass peak grows with time (constant kernel: m_p ~ 1 + tau)
    mp = np.asarray(D.mass_peak(rows, g.edges))
    assert mp[0] < mp[1] < mp[2]
    # numpy in, numpy out (computed with numpy: no eager XLA compiles); JAX arrays and tracers keep jax.numpy,
    # and both agree to round-off, also under jit
    ref = rows[::-1] * 1.1
    for name, f, args in (("m2f", D.m2f, (g.edges,)), ("mass_peak", D.mass_peak, (g.edges,)),
                          ("moment", D.moment, (g.edges, 2.0)), ("l1_error", D.l1_error, (ref,))):
        out_np = f(rows, *args)
        out_jx = f(jnp.asarray(rows), *args)
        out_jit = jax.jit(lambda r, f=f, args=args: f(r, *args))(jnp.asarray(rows))
        assert isinstance(out_np, np.ndarray) and not isinstance(out_np, jax.Array), name
        assert isinstance(out_jx, jax.Array) and isinstance(out_jit, jax.Array), name
        np.testing.assert_allclose(out_np, np.asarray(out_jx), rtol=1e-14, err_msg=name)
        np.testing.assert_allclose(out_np, np.asarray(out_jit), rtol=1e-14, err_msg=name)
