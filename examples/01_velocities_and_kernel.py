"""Relative velocities and the collision kernel at a disk location, with gradients.

Shows: the Ormel & Cuzzi (2007) turbulent velocity (exact St* root), a Scene kernel
(Brownian + turbulence + radial drift) on a size grid, and d ln K / d ln alpha by jax.grad,
checked against a central finite difference.

    python examples/01_velocities_and_kernel.py [--quick]
"""

import argparse

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np

from jaxcoag import constants as C
from jaxcoag import scenes
from jaxcoag.physics import dv_turbulent_oc07, gas


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    n = 20 if args.quick else 200

    # 1. Delta v / v_g for a heavy-light pair (thesis Fig 3.3 regime)
    for st1 in (1e-4, 1e-2, 1.0):
        print(f"St1 = {st1:7.1e}, St2 -> 0: Delta v / v_g = {float(dv_turbulent_oc07(st1, 1e-12, 1e8)):.6f}")

    # 2. kernel matrix of the chapter-4 nebula scene at 3 AU
    rho_s = 3.0
    a = jnp.logspace(-5, 2, n)
    m = 4 / 3 * jnp.pi * rho_s * a ** 3

    def kernel_matrix(log_alpha):
        g = gas.ch4_disk(3 * C.AU, alpha=jnp.exp(log_alpha))
        return scenes.nebula_ch4().kernel(g, rho_s=rho_s).matrix(m)

    K = jax.jit(kernel_matrix)(jnp.log(1e-4))
    print(f"kernel matrix {K.shape}: min {float(K.min()):.3e}, max {float(K.max()):.3e} cm^3/s")

    # 3. gradient of the total collision rate density with respect to ln alpha
    f = lambda la: jnp.log(jnp.sum(kernel_matrix(la)))
    g = float(jax.grad(f)(jnp.log(1e-4)))
    h = 1e-5
    fd = float((f(jnp.log(1e-4) + h) - f(jnp.log(1e-4) - h)) / (2 * h))
    print(f"d ln(sum K) / d ln alpha = {g:.8f} (grad), {fd:.8f} (central FD), rel diff {abs(g - fd) / abs(fd):.1e}")
    return dict(grad=g, fd=fd)


if __name__ == "__main__":
    main()
