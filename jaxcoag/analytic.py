"""Exact solutions of the Smoluchowski equation for the constant, sum and product kernels.

Pure numpy/scipy (no JAX, no mpmath), overflow-safe (log space, ``scipy.special.ive``,
``lambertw``). Two initial conditions:

* ``initial="monodisperse"``: n(m, 0) = n0 delta(m - m0); the solution lives on integer
  multiples m = k m0 and :func:`number_density` returns n_k [cm^-3].
* ``initial="exponential"``: f(m, 0) = (n0/m0) exp(-m/m0); :func:`number_density` returns
  f(m, t) [cm^-3 g^-1].

Kernels (``kind``): ``"constant"`` K = coeff; ``"sum"`` K = coeff (m1 + m2); ``"product"``
K = coeff m1 m2 - the same conventions as :mod:`jaxcoag.kernels` (``Constant(k0)``,
``Sum(b)``, ``Product(b)``), with the usual 1/2 for identical pairs inside the equation.
Dimensionless times: constant tau = coeff n0 t; sum eps = exp(-coeff n0 m0 t);
product tau = coeff n0 m0^2 t (gel point tau = 1 monodisperse, 1/2 exponential).
Thesis Table 5.1 units: n0 = m0 = 1 and coeff = 1, 1/2, 1.

References: Ormel (2008) thesis Table 5.1 and eq. 2.24; spec/montecarlo.md §4.2-4.6;
Smoluchowski (1916); Golovin (1963); Trubnikov (1971); Ernst, Ziff & Hendriks (1984) (product
kernel, post-gel Flory sol); Scott (1968) (exponential initial conditions).
"""

from __future__ import annotations

import numpy as np
from scipy import special

from ._validate import JaxcoagInputError

__all__ = ["number_density", "mass_per_bin", "number_per_bin", "moments", "gel_fraction",
           "log_nk", "KINDS"]

KINDS = ("constant", "sum", "product")
_INITIALS = ("monodisperse", "exponential")
_K_EXACT = 2 ** 16          # exact summation of discrete n_k below this k (spec §4.6)
_LOG2PI = np.log(2.0 * np.pi)
_GL_X, _GL_W = np.polynomial.legendre.leggauss(64)


def _args(kind, t, coeff, n0, m0, initial):
    if kind not in KINDS:
        raise JaxcoagInputError(f"kind must be one of {KINDS} (got {kind!r}).")
    if initial not in _INITIALS:
        raise JaxcoagInputError(f"initial must be one of {_INITIALS} (got {initial!r}).")
    t = float(t)
    if not (np.isfinite(t) and t >= 0):
        raise JaxcoagInputError(f"t must be a finite time >= 0 s (got {t!r}).")
    for v, nm in ((coeff, "coeff"), (n0, "n0"), (m0, "m0")):
        if not (np.isfinite(v) and v > 0):
            raise JaxcoagInputError(f"{nm} must be finite and > 0 (got {v!r}).")
    return float(t), float(coeff), float(n0), float(m0)


def _tau(kind, t, coeff, n0, m0):
    if kind == "constant":
        return coeff * n0 * t
    if kind == "sum":
        return coeff * n0 * m0 * t
    return coeff * n0 * m0 * m0 * t


def _stirling_corr(k):
    """lgamma(k+1) - [k log k - k + 0.5 log(2 pi k)] (asymptotic series, k >= 100)."""
    k = np.asarray(k, float)
    return 1.0 / (12.0 * k) - 1.0 / (360.0 * k ** 3)


def _product_I(tau):
    """I(tau) = tau - 1 - log(tau) >= 0, series near tau = 1 (spec §4.4)."""
    d = tau - 1.0
    if abs(d) < 1e-3:
        return d * d / 2.0 - d ** 3 / 3.0 + d ** 4 / 4.0 - d ** 5 / 5.0
    return d - np.log1p(d)


def log_nk(kind, k, t, *, coeff=1.0, n0=1.0, m0=1.0):
    """ln n_k(t) [ln cm^-3] of the monodisperse-start discrete solution, stable for k up to 1e300.

    Arguments:
        kind: "constant" | "sum" | "product".
        k: integer-valued array (k >= 1; float allowed for the Stirling continuation).
        t: time [s]; coeff: kernel coefficient (cm^3 s^-1 [g^-1 | g^-2]); n0 [cm^-3]; m0 [g].

    Returns: array of ln n_k (-inf where n_k = 0, e.g. k > 1 at t = 0).

    References: spec/montecarlo.md §4.2 (constant), §4.3 (sum, Stirling for k > 100), §4.4
    (product; the same formula is the post-gel Flory sol).
    """
    t, coeff, n0, m0 = _args(kind, t, coeff, n0, m0, "monodisperse")
    k = np.asarray(k, dtype=float)
    tau = _tau(kind, t, coeff, n0, m0)
    if tau == 0.0:
        return np.where(k == 1.0, np.log(n0), -np.inf)
    big = k > 100.0
    kb = np.where(big, k, 101.0)
    ks = np.where(big, 1.0, k)
    with np.errstate(divide="ignore", invalid="ignore"):
        if kind == "constant":
            f = 1.0 / (1.0 + 0.5 * tau)
            return np.log(n0) + 2.0 * np.log(f) + (k - 1.0) * np.log1p(-f)
        if kind == "sum":
            eps = np.exp(-tau)
            T = -np.expm1(-tau)
            logT = np.log1p(-eps) if eps < 0.5 else np.log(T)
            small = (np.log(n0) + (ks - 1.0) * np.log(ks) - special.gammaln(ks + 1.0) + np.log(eps)
                     + (ks - 1.0) * logT - ks * T)
            if eps < 0.1:
                j = np.arange(2, 60)
                phi = -np.sum(eps ** j / j)
            else:
                phi = logT + eps
            large = (np.log(n0) + np.log(eps) - logT - 1.5 * np.log(kb) - 0.5 * _LOG2PI
                     - _stirling_corr(kb) + kb * phi)
            return np.where(big, large, small)
        # product
        small = (np.log(n0) + (ks - 2.0) * np.log(ks) - special.gammaln(ks + 1.0)
                 + (ks - 1.0) * np.log(tau) - ks * tau)
        large = (np.log(n0) - _product_I(tau) * kb - 2.5 * np.log(kb) - 0.5 * _LOG2PI - np.log(tau)
                 - _stirling_corr(kb))
        return np.where(big, large, small)


def _log_ive1(z):
    """ln(exp(-z) I_1(z)) for z > 0, finite for every z.

    scipy's ``ive(1, z)`` returns NaN above z ~ 1e9; there the Hankel expansion
    exp(-z) I_1(z) = (1 - 3/(8z) - 15/(128 z^2) + O(z^-3)) / sqrt(2 pi z) is exact to < 1e-18
    (Abramowitz & Stegun 9.7.1).
    """
    z = np.asarray(z, dtype=float)
    big = z > 1e6
    zs = np.where(big, 1.0, z)
    zb = np.where(big, z, 1e6)
    asym = np.log1p(-3.0 / (8.0 * zb) - 15.0 / (128.0 * zb * zb)) - 0.5 * np.log(2.0 * np.pi * zb)
    return np.where(big, asym, np.log(special.ive(1, zs)))


def _log_f_exponential(kind, m, t, coeff, n0, m0):
    """ln f(m, t) [ln cm^-3 g^-1] for f(m, 0) = (n0/m0) exp(-m/m0)."""
    x = np.asarray(m, float) / m0
    tau = _tau(kind, t, coeff, n0, m0)
    base = np.log(n0 / m0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if kind == "constant":
            phi = 1.0 / (1.0 + 0.5 * tau)
            return base + 2.0 * np.log(phi) - phi * x
        if kind == "sum":
            if tau == 0.0:
                return base - x
            eps = np.exp(-tau)
            T = -np.expm1(-tau)
            sT = np.sqrt(T)
            z = 2.0 * sT * x
            # f = n0/m0 (1-T)/(x sqrt T) exp(-(1+T)x) I1(2 sqrt(T) x);  I1(z) = ive(1,z) e^z
            return (base + np.log(eps) - np.log(x * sT) + _log_ive1(z)
                    - (1.0 - sT) ** 2 * x)
        # product, pre-gel (tau < 1/2): f = e^{-(1+tau)x} sum_k tau^{k-1} x^{3k-3} / (k! (2k-1)!)
        if tau >= 0.5:
            raise JaxcoagInputError(
                f"the product-kernel solution from an exponential start is pre-gel only: need "
                f"coeff*n0*m0^2*t < 1/2 (got {tau!r}); use initial='monodisperse' for post-gel.")
        if tau == 0.0:
            return base - x
        xs = np.atleast_1d(x).ravel()
        out = np.empty_like(xs)
        # log-sum-exp of the series around its peak k* = (tau x^3/4)^(1/3); the summand is a
        # smooth bump of width sigma ~ sqrt(k*/3), summed on a stride s <= sigma/4 (Poisson
        # summation: the strided sum times s equals the full sum to ~exp(-2 pi^2 16)).
        offs = np.arange(-150, 151, dtype=float)
        for c in range(0, xs.size, 4096):
            xc = xs[c:c + 4096]
            lx = np.log(xc)
            kpk = np.maximum(1.0, (tau * xc ** 3 / 4.0) ** (1.0 / 3.0))
            stride = np.maximum(1.0, np.floor((np.sqrt(kpk / 3.0) + 1.0) / 4.0))
            kk = np.rint(kpk)[:, None] + stride[:, None] * offs[None, :]
            ok = kk >= 1.0
            kk = np.where(ok, kk, 1.0)
            terms = ((kk - 1.0) * np.log(tau) + (3.0 * kk - 3.0) * lx[:, None]
                     - special.gammaln(kk + 1.0) - special.gammaln(2.0 * kk))
            terms = np.where(ok, terms, -np.inf)
            out[c:c + 4096] = (base - (1.0 + tau) * xc + np.log(stride)
                               + special.logsumexp(terms, axis=1))
        return out.reshape(np.shape(x))


def number_density(kind, m, t, *, coeff=1.0, n0=1.0, m0=1.0, initial="monodisperse"):
    """Exact number density of the constant/sum/product kernel problem.

    Arguments:
        kind: "constant" (K = coeff), "sum" (K = coeff (m1+m2)), "product" (K = coeff m1 m2).
        m: masses [g] (array). Monodisperse: multiples k m0 (k = m/m0 rounded to an integer).
        t: time [s] (>= 0); coeff: kernel coefficient [cm^3 s^-1 (g^-1 | g^-2)];
        n0: initial number density [cm^-3]; m0: monomer / e-folding mass [g].
        initial: "monodisperse" (n0 delta(m - m0)) or "exponential" ((n0/m0) e^{-m/m0}).

    Returns:
        monodisperse: n_k [cm^-3] of k-mers (post-gel product kernel: the Flory sol);
        exponential: f(m, t) [cm^-3 g^-1].

    References: spec/montecarlo.md §4.2-4.4 (eqs. for n_k, Golovin/Bessel form of §4.3);
    Scott (1968); Ernst, Ziff & Hendriks (1984).
    """
    t, coeff, n0, m0 = _args(kind, t, coeff, n0, m0, initial)
    m = np.asarray(m, float)
    if initial == "monodisperse":
        k = np.maximum(np.rint(m / m0), 1.0)
        return np.exp(log_nk(kind, k, t, coeff=coeff, n0=n0, m0=m0))
    return np.exp(_log_f_exponential(kind, m, t, coeff, n0, m0))


def _bin_quad(logf_of_m, lo, hi, weight_power):
    """int_lo^hi m^p f(m) dm per bin by 64-pt Gauss-Legendre in ln m (arrays lo, hi > 0)."""
    a, b = np.log(lo), np.log(hi)
    half = 0.5 * (b - a)
    lm = 0.5 * (a + b)[:, None] + half[:, None] * _GL_X[None, :]
    m = np.exp(lm)
    with np.errstate(over="ignore", invalid="ignore"):
        vals = np.exp(logf_of_m(m) + (weight_power + 1.0) * lm)
    vals = np.where(np.isfinite(vals), vals, 0.0)
    return half * np.sum(vals * _GL_W[None, :], axis=1)


def _discrete_bin_sums(kind, edges, t, coeff, n0, m0, p):
    """sum over integers k in [lo/m0, hi/m0) of (k m0)^p n_k, per bin (exact < 2^16, E-M beyond)."""
    edges = np.asarray(edges, float)
    nb = edges.size - 1
    out = np.zeros(nb)
    # exact part
    kmax = min(_K_EXACT, int(np.ceil(edges[-1] / m0)) + 1)
    k = np.arange(1, kmax, dtype=float)
    if k.size:
        w = np.exp(log_nk(kind, k, t, coeff=coeff, n0=n0, m0=m0)) * (k * m0) ** p
        idx = np.searchsorted(edges, k * m0, side="right") - 1
        ok = (idx >= 0) & (idx < nb)
        out += np.bincount(idx[ok], weights=w[ok], minlength=nb)
    # Euler-Maclaurin beyond 2^16 on the continuous (Stirling) form
    a = np.maximum(np.ceil(edges[:-1] / m0), float(_K_EXACT))
    b = np.maximum(np.ceil(edges[1:] / m0), float(_K_EXACT))
    sel = b > a
    if np.any(sel):
        def g(kk):
            return np.exp(log_nk(kind, kk, t, coeff=coeff, n0=n0, m0=m0)) * (kk * m0) ** p

        def logf(kk):
            with np.errstate(divide="ignore"):
                return log_nk(kind, kk, t, coeff=coeff, n0=n0, m0=m0) + p * np.log(m0)

        integ = _bin_quad(logf, a[sel], b[sel], p)  # int n(k) (k m0)^p dk
        out[sel] += integ + 0.5 * (g(a[sel]) - g(b[sel]))
    return out


def _check_edges(edges):
    e = np.asarray(edges, float)
    if e.ndim != 1 or e.size < 2 or not np.all(np.isfinite(e)) or not np.all(e > 0) or not np.all(np.diff(e) > 0):
        raise JaxcoagInputError("edges must be a 1-D strictly increasing array of finite masses > 0 g (>= 2 edges).")
    return e


def mass_per_bin(kind, edges, t, *, coeff=1.0, n0=1.0, m0=1.0, initial="monodisperse"):
    """Exact mass density per bin [g cm^-3] for arbitrary bin edges [g].

    Monodisperse: sum of n_k k m0 over integers with lo <= k m0 < hi (exact up to k = 2^16,
    Euler-Maclaurin on the Stirling form beyond, spec §4.6). Exponential: the integral of
    m f(m, t) over the bin (64-pt Gauss-Legendre in ln m per bin). Post-gel product kernel:
    the sol only (the gel carries 1 - T/tau of the mass, see :func:`gel_fraction`).

    Arguments: kind, edges (nbins+1,) [g], t [s], coeff, n0 [cm^-3], m0 [g], initial.
    Returns: (nbins,) array [g cm^-3].
    References: spec/montecarlo.md §4.6.
    """
    t, coeff, n0, m0 = _args(kind, t, coeff, n0, m0, initial)
    e = _check_edges(edges)
    if initial == "monodisperse":
        return _discrete_bin_sums(kind, e, t, coeff, n0, m0, 1.0)
    return _continuous_bins(kind, e, t, coeff, n0, m0, 1.0)


def number_per_bin(kind, edges, t, *, coeff=1.0, n0=1.0, m0=1.0, initial="monodisperse"):
    """Exact number density per bin [cm^-3]; as :func:`mass_per_bin` with weight m^0."""
    t, coeff, n0, m0 = _args(kind, t, coeff, n0, m0, initial)
    e = _check_edges(edges)
    if initial == "monodisperse":
        return _discrete_bin_sums(kind, e, t, coeff, n0, m0, 0.0)
    return _continuous_bins(kind, e, t, coeff, n0, m0, 0.0)


def _continuous_bins(kind, e, t, coeff, n0, m0, p):
    lo, hi = e[:-1], e[1:]
    # split each bin in 8 log-sub-intervals for accuracy on wide bins
    nsub = 8
    ls = np.log(lo)[:, None] + (np.log(hi) - np.log(lo))[:, None] * np.arange(nsub + 1)[None, :] / nsub
    slo, shi = np.exp(ls[:, :-1]).ravel(), np.exp(ls[:, 1:]).ravel()
    vals = _bin_quad(lambda m: _log_f_exponential(kind, m, t, coeff, n0, m0), slo, shi, p)
    return vals.reshape(lo.size, nsub).sum(axis=1)


def gel_fraction(t, *, coeff=1.0, n0=1.0, m0=1.0):
    """Mass fraction in the gel for the product kernel from a monodisperse start.

    beta = 1 - T/tau with T = -W0(-tau e^{-tau}) (0 for tau <= 1), tau = coeff n0 m0^2 t.
    Arguments: t [s], coeff [cm^3 s^-1 g^-2], n0 [cm^-3], m0 [g]. Returns: beta in [0, 1).
    References: spec/montecarlo.md §4.4 (Flory; Ernst, Ziff & Hendriks 1984).
    """
    t, coeff, n0, m0 = _args("product", t, coeff, n0, m0, "monodisperse")
    tau = _tau("product", t, coeff, n0, m0)
    return 1.0 - _flory_T(tau) / tau if tau > 1.0 else 0.0


def _flory_T(tau):
    if tau <= 1.0:
        return tau
    return float(np.real(-special.lambertw(-tau * np.exp(-tau), 0)))


def moments(kind, t, p, *, coeff=1.0, n0=1.0, m0=1.0, initial="monodisperse"):
    """Closed-form moments M_p = int m^p f dm (sol only after gelation), p in {0, 1, 2}.

    Arguments: kind, t [s], p (0, 1 or 2), coeff, n0 [cm^-3], m0 [g], initial.
    Returns: M_p [g^p cm^-3].
      monodisperse: Table 5.1 (constant: n0/(1+tau/2), n0 m0, n0 m0^2 (1+tau); sum:
      n0 eps, n0 m0, n0 m0^2/eps^2; product pre-gel: n0 (1 - tau/2), n0 m0, n0 m0^2/(1-tau);
      post-gel sol with T = -W0(-tau e^-tau): n0 (T - T^2/2)/tau, n0 m0 T/tau,
      n0 m0^2 T/(tau (1-T))).
      exponential: constant n0/(1+tau/2), n0 m0, n0 m0^2 (2+tau); sum n0 eps, n0 m0,
      2 n0 m0^2/eps^2; product (tau < 1/2) n0 (1 - tau/2), n0 m0, 2 n0 m0^2/(1 - 2 tau).
    References: thesis Table 5.1; spec/montecarlo.md §4.2-4.5 (moment ODE 5.4).
    """
    t, coeff, n0, m0 = _args(kind, t, coeff, n0, m0, initial)
    if p not in (0, 1, 2):
        raise JaxcoagInputError(f"closed-form moments exist for p = 0, 1, 2 (got p = {p!r}); use "
                                "mass_per_bin/number_per_bin with jaxcoag.diagnostics for other p.")
    tau = _tau(kind, t, coeff, n0, m0)
    expo = initial == "exponential"
    c2 = 2.0 if expo else 1.0
    if kind == "constant":
        return [n0 / (1.0 + 0.5 * tau), n0 * m0, n0 * m0 ** 2 * (c2 + tau)][p]
    if kind == "sum":
        eps = np.exp(-tau)
        return [n0 * eps, n0 * m0, c2 * n0 * m0 ** 2 / eps ** 2][p]
    if expo:
        if tau >= 0.5:
            raise JaxcoagInputError("product kernel from an exponential start: moments are pre-gel only "
                                    f"(coeff*n0*m0^2*t < 1/2; got {tau!r}).")
        return [n0 * (1.0 - 0.5 * tau), n0 * m0, 2.0 * n0 * m0 ** 2 / (1.0 - 2.0 * tau)][p]
    if tau < 1.0:
        return [n0 * (1.0 - 0.5 * tau), n0 * m0, n0 * m0 ** 2 / (1.0 - tau)][p]
    T = _flory_T(tau)
    if T >= 1.0:  # tau == 1 exactly: M2 diverges
        return [n0 * 0.5, n0 * m0, np.inf][p]
    return [n0 * (T - 0.5 * T * T) / tau, n0 * m0 * T / tau, n0 * m0 ** 2 * T / (tau * (1.0 - T))][p]
