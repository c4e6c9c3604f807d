"""Test-only kernels shared by several test files."""

import jax
import jax.numpy as jnp

from jaxcoag.kernels import AbstractKernel


class SqrtAlphaKernel(AbstractKernel):
    """dv^2 = 1 + alpha 1e10 ((m1/1e6)^2/3 + (m2/1e6)^2/3) (dv ~ sqrt(alpha)); K = pi (a1 + a2)^2 dv."""

    alpha: jax.Array

    def __init__(self, alpha):
        self.alpha = jnp.asarray(alpha, float)

    def relative_velocity2(self, m1, m2, x1=None, x2=None):
        return 1.0 + self.alpha * 1e10 * ((m1 / 1e6) ** (2 / 3) + (m2 / 1e6) ** (2 / 3))

    def __call__(self, m1, m2, x1=None, x2=None):
        a1 = (3 * m1 / (4 * jnp.pi)) ** (1 / 3)
        a2 = (3 * m2 / (4 * jnp.pi)) ** (1 / 3)
        return jnp.pi * (a1 + a2) ** 2 * jnp.sqrt(self.relative_velocity2(m1, m2))
