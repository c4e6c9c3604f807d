"""Collision kernels K(m_i, m_j) [cm^3 s^-1] shared by the binned and Monte Carlo engines.

A kernel is an ``equinox.Module``: its numbers (``b``, ``nu``, gas state, material constants)
are array leaves that can be differentiated and vmapped; which formula it evaluates is its
type (structure). Every kernel evaluates vectorised on broadcasting pairs:

    K(m1, m2)              # kernel value, same broadcasting as numpy
    K.log_kernel(m1, m2)   # log K, overflow-free for |log K| up to ~1e300 (Monte Carlo rates)
    K.matrix(m)            # the N x N matrix on a vector of masses

Kernels with structural parameters (porosity, ...) accept optional per-particle arrays
``x1, x2`` with a trailing axis of length ``n_struct``; analytic kernels ignore them. The
analytic kernels set ``cheap_linear``: the Monte Carlo engine then evaluates its rate tiles
on the linear masses (``jaxcoag.mc.rates.rate_tile``) where the state's range allows.

References: Ormel (2008) thesis Table 5.1 (constant, sum, product); log kernels
(MC rates in log space, docs/design_notes.md); Smoluchowski (1916), Golovin (1963), Trubnikov (1971).
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp

from ._validate import check
from .physics.safe import safe_log

__all__ = ["AbstractKernel", "Constant", "Sum", "Product", "PowerProduct", "PowerLaw"]


def _logaddexp(a, b):
    """ln(e^a + e^b) for NaN-free inputs (masses' logs), in the form XLA's CPU backend vectorises.

    ``jnp.logaddexp`` guards against NaN with a select on ``a - b != a - b``, which keeps XLA-CPU
    from vectorising the fused loop: 13 ns against 3.6 ns per entry on this form (measured on
    (3, 65536) float64 tiles), and the Monte Carlo rate tiles evaluate one kernel per entry per event.
    Equal arguments (also both -inf or both +inf) take d = 0, so the result is a + ln 2 (or the
    infinity) instead of NaN; the derivative is 1/2 for each argument there, as for ``jnp.logaddexp``.
    """
    d = jnp.where(a == b, 0.0, a - b)
    return jnp.maximum(a, b) + jnp.log1p(jnp.exp(-jnp.abs(d)))


class AbstractKernel(eqx.Module):
    """Base class: a symmetric collision kernel K(m1, m2) [cm^3 s^-1].

    Subclasses implement ``__call__``; they may override ``log_kernel`` with an overflow-free
    form and ``matrix`` with a form that computes per-particle quantities once (N, not N^2).
    """

    n_struct = 0  # number of structural parameters per particle this kernel reads (class attr)
    #: (class attr) True where ``__call__`` is a few arithmetic operations on the linear masses (no
    #: transcendental function) and non-decreasing in each mass: the Monte Carlo event loop then evaluates
    #: its rate tiles in linear space whenever the state's range allows (``jaxcoag.mc.rates.rate_tile``)
    cheap_linear = False

    @abc.abstractmethod
    def __call__(self, m1, m2, x1=None, x2=None):
        """Kernel value [cm^3 s^-1] for masses m1, m2 [g] (broadcasting)."""

    def log_kernel(self, m1, m2, x1=None, x2=None):
        """Natural log of the kernel (default: log of ``__call__``; -inf where K = 0)."""
        return safe_log(self(m1, m2, x1, x2))

    def log_kernel_from_log_mass(self, logm1, logm2, x1=None, x2=None):
        """log K from log-masses; analytic kernels override this so masses beyond 1e308 g work."""
        return self.log_kernel(jnp.exp(logm1), jnp.exp(logm2), x1, x2)

    def matrix(self, m, x=None):
        """N x N kernel matrix on masses ``m`` (shape (N,)) [cm^3 s^-1]."""
        m = jnp.asarray(m)
        x1 = None if x is None else x[:, None, :]
        x2 = None if x is None else x[None, :, :]
        return self(m[:, None], m[None, :], x1, x2)

    def relative_velocity2(self, m1, m2, x1=None, x2=None):
        """Squared relative velocity [cm^2 s^-2] behind the kernel (physical kernels only).

        Velocity-dependent outcomes (fragmentation with v_frag, bouncing) call this. Analytic
        kernels have no velocity and raise a TypeError saying so.
        """
        raise TypeError(
            f"{type(self).__name__} is an analytic kernel with no relative velocity; velocity-dependent "
            "outcomes (fragmentation with v_frag, bouncing) need a physical kernel built from a Scene "
            "(jaxcoag.Scene(...).kernel(gas, material)) or a subclass implementing relative_velocity2."
        )

    def matrix_and_dv2(self, m, x=None):
        """(K, dv^2) N x N matrices on masses ``m``; physical kernels override to share work."""
        m = jnp.asarray(m)
        x1 = None if x is None else x[:, None, :]
        x2 = None if x is None else x[None, :, :]
        return self.matrix(m, x), self.relative_velocity2(m[:, None], m[None, :], x1, x2)


def _leaf(x, name, **kw):
    return check(x, name, **kw)


class Constant(AbstractKernel):
    """K = k0 (Smoluchowski 1916; thesis Table 5.1 with k0 = 1)."""

    k0: jax.Array

    cheap_linear = True

    def __init__(self, k0=1.0):
        self.k0 = _leaf(k0, "k0", positive=True, hint="the constant kernel value in cm^3 s^-1")

    def __call__(self, m1, m2, x1=None, x2=None):
        return self.k0 * jnp.ones(jnp.broadcast_shapes(jnp.shape(m1), jnp.shape(m2)), jnp.result_type(self.k0, m1, m2))

    def log_kernel_from_log_mass(self, logm1, logm2, x1=None, x2=None):
        return jnp.log(self.k0) + jnp.zeros(jnp.broadcast_shapes(jnp.shape(logm1), jnp.shape(logm2)), jnp.result_type(self.k0, logm1))

    def log_kernel(self, m1, m2, x1=None, x2=None):
        return self.log_kernel_from_log_mass(jnp.log(m1), jnp.log(m2))


class Sum(AbstractKernel):
    """K = b (m1 + m2) (Golovin 1963; thesis Table 5.1 with b = 1/2)."""

    b: jax.Array

    cheap_linear = True

    def __init__(self, b=0.5):
        self.b = _leaf(b, "b", positive=True, hint="K = b (m1 + m2), b in cm^3 s^-1 g^-1")

    def __call__(self, m1, m2, x1=None, x2=None):
        return self.b * (m1 + m2)

    def log_kernel_from_log_mass(self, logm1, logm2, x1=None, x2=None):
        return jnp.log(self.b) + _logaddexp(logm1, logm2)

    def log_kernel(self, m1, m2, x1=None, x2=None):
        return self.log_kernel_from_log_mass(jnp.log(m1), jnp.log(m2))


class Product(AbstractKernel):
    """K = b m1 m2 (thesis Table 5.1 with b = 1; gels at t = 1/(b M1) for a monodisperse start)."""

    b: jax.Array

    cheap_linear = True

    def __init__(self, b=1.0):
        self.b = _leaf(b, "b", positive=True, hint="K = b m1 m2, b in cm^3 s^-1 g^-2")

    def __call__(self, m1, m2, x1=None, x2=None):
        return self.b * m1 * m2

    def log_kernel_from_log_mass(self, logm1, logm2, x1=None, x2=None):
        return jnp.log(self.b) + logm1 + logm2

    def log_kernel(self, m1, m2, x1=None, x2=None):
        return self.log_kernel_from_log_mass(jnp.log(m1), jnp.log(m2))


class PowerProduct(AbstractKernel):
    """K = b (m1 m2)^nu (thesis ch. 5 runaway kernels, Fig. 5.7: nu = 2, 3).

    Evaluated as b exp(nu (log m1 + log m2)) so that m1 m2 is never formed.
    """

    b: jax.Array
    nu: jax.Array

    def __init__(self, b=1.0, nu=1.0):
        self.b = _leaf(b, "b", positive=True, hint="K = b (m1 m2)^nu")
        self.nu = _leaf(nu, "nu", hint="K = b (m1 m2)^nu")

    def __call__(self, m1, m2, x1=None, x2=None):
        return jnp.exp(self.log_kernel(m1, m2))

    def log_kernel_from_log_mass(self, logm1, logm2, x1=None, x2=None):
        return jnp.log(self.b) + self.nu * (logm1 + logm2)

    def log_kernel(self, m1, m2, x1=None, x2=None):
        return self.log_kernel_from_log_mass(jnp.log(m1), jnp.log(m2))


class PowerLaw(AbstractKernel):
    """General homogeneous power law K = b (m1^mu m2^nu + m1^nu m2^mu), degree lambda = mu + nu.

    Special cases: Sum(b) = PowerLaw(b, 1, 0); Product(b) = PowerLaw(b/2, 1, 1);
    Constant(k0) = PowerLaw(k0/2, 0, 0). Evaluated in log space (logaddexp), overflow-free.
    """

    b: jax.Array
    mu: jax.Array
    nu: jax.Array

    def __init__(self, b=1.0, mu=1.0, nu=0.0):
        self.b = _leaf(b, "b", positive=True)
        self.mu = _leaf(mu, "mu")
        self.nu = _leaf(nu, "nu")

    def __call__(self, m1, m2, x1=None, x2=None):
        return jnp.exp(self.log_kernel(m1, m2))

    def log_kernel_from_log_mass(self, logm1, logm2, x1=None, x2=None):
        return jnp.log(self.b) + _logaddexp(self.mu * logm1 + self.nu * logm2, self.nu * logm1 + self.mu * logm2)

    def log_kernel(self, m1, m2, x1=None, x2=None):
        return self.log_kernel_from_log_mass(jnp.log(m1), jnp.log(m2))
