"""Rain-out of the thesis ch. 2 Monte Carlo runs: a settling sink and its accounting.

:class:`RainOutKernel` is the chapter-2 settling sink [T2.25]: a particle whose friction time
exceeds tau_rain = alpha/Omega has left the turbulent layer; the wrapped kernel is zero for
every pair that involves it, so it never collides again, while it stays in the state (with
its mass, psi and multiplicity) so that the rain-out population can be measured afterwards
with :func:`rainout_summary` (rained mass vs time, t_rain, t_99%, <a>, <m>, <psi>, a/a*).

References: Ormel (2008) thesis ch. 2 (§2.4 eq. 2.25 rain-out, Tab. 2.2).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from .._validate import JaxcoagInputError, check
from ..kernels import AbstractKernel

__all__ = ["RainOutKernel", "rainout_summary"]


class RainOutKernel(AbstractKernel):
    """Kernel wrapper: pairs involving a particle with tau_f > tau_rain have zero rate [T2.25].

    In the thesis ch. 2 runs a particle whose friction time exceeds tau_rain = alpha/Omega has a
    scale height below the gas scale height, settles to the midplane and "is removed from the
    simulation" (T§2.4). Here it is parked: it never collides again (log K = -inf), keeps its
    slot, mass, psi and multiplicity, and the spatial density of the colliding population drops
    accordingly; :func:`rainout_summary` measures the parked (rained-out) population.

    Arguments:
        kernel: a physical kernel with ``particles(m, x).tau_f`` (a :class:`~jaxcoag.SceneKernel`).
        tau_rain: rain-out friction time [s]; default alpha/Omega of the kernel's gas (eq. 2.25).

    References: Ormel (2008) thesis eq. 2.25 and §2.4, Tab. 2.2.
    """

    base: AbstractKernel
    tau_rain: jax.Array

    def __init__(self, kernel, tau_rain=None):
        if not hasattr(kernel, "particles") or not hasattr(kernel, "gas"):
            raise JaxcoagInputError("RainOutKernel needs a physical kernel with particles(m, x).tau_f "
                                    "(jaxcoag.Scene(...).kernel(gas, ...))")
        self.base = kernel
        if tau_rain is None:
            tau_rain = kernel.gas.alpha / kernel.gas.Omega
        self.tau_rain = check(tau_rain, "tau_rain", positive=True,
                              hint="rain-out friction time in s, alpha/Omega in thesis eq. 2.25")

    @property
    def n_struct(self) -> int:  # type: ignore[override]
        return self.base.n_struct

    @property
    def gas(self):
        return self.base.gas

    def particles(self, m, x=None):
        return self.base.particles(m, x)

    def rained(self, m, x=None):
        """True where tau_f(m, x) > tau_rain (the particle has rained out)."""
        x = x if self.base.n_struct else None
        return self.base.particles(m, x).tau_f > self.tau_rain

    def __call__(self, m1, m2, x1=None, x2=None):
        gone = self.rained(m1, x1) | self.rained(m2, x2)
        return jnp.where(gone, 0.0, self.base(m1, m2, x1, x2))

    def log_kernel_from_log_mass(self, logm1, logm2, x1=None, x2=None):
        m1, m2 = jnp.exp(logm1), jnp.exp(logm2)
        gone = self.rained(m1, x1) | self.rained(m2, x2)
        return jnp.where(gone, -jnp.inf, self.base.log_kernel_from_log_mass(logm1, logm2, x1, x2))

    def relative_velocity2(self, m1, m2, x1=None, x2=None):
        return self.base.relative_velocity2(m1, m2, x1, x2)


def rainout_summary(res, kernel: RainOutKernel, *, rho_s=None) -> dict[str, Any]:
    """Rain-out accounting of an MC result run with a :class:`RainOutKernel` (thesis Tab. 2.2).

    Arguments:
        res: ``MCResult`` (optionally batched over runs: leading axes before (T, S)).
        kernel: the :class:`RainOutKernel` of the run (tau_f and tau_rain).
        rho_s: material density for a* [g cm^-3]; default the kernel's ``rho_s``.

    Returns:
        dict of arrays (leading batch axes kept): ``t`` [s]; ``M_rain`` (rained mass per
        snapshot [g]) and ``f_rain`` (fraction of the simulated mass); ``t_rain`` = first output
        time with rained mass > 0 and ``t_99`` = first with f_rain >= 0.99 [s] (inf if never:
        resolution = the output grid); number means over the rained population at the last
        snapshot: ``m`` [g], ``a`` [cm] (geometric), ``a_star`` [cm], ``psi``, ``a_over_astar`` =
        <a>/<a*>; and ``n_rain`` (number of rained physical particles).

    References: Ormel (2008) thesis Tab. 2.2 (columns <a>, <m>, <psi>, a/a*, t_rain, t_99%).
    """
    base = kernel.base
    rho_s = base.rho_s if rho_s is None else rho_s
    m, psi, valid = res.m, res.psi, res.valid
    g = res.w * jnp.exp2(res.z.astype(m.dtype))
    x = psi if base.n_struct else None
    gone = valid & kernel.rained(m, x)
    gm = jnp.where(gone, g * m, 0.0)
    M_rain = jnp.sum(gm, axis=-1)
    f_rain = M_rain / res.M_tot
    t = res.t
    big = jnp.inf

    def first(cond):
        idx = jnp.argmax(cond, axis=-1)
        tb = jnp.broadcast_to(t, cond.shape)
        val = jnp.take_along_axis(tb, idx[..., None], axis=-1)[..., 0]
        return jnp.where(jnp.any(cond, axis=-1), val, big)

    t_rain = first(M_rain > 0)
    t_99 = first(f_rain >= 0.99)
    gl = jnp.where(gone[..., -1, :], g[..., -1, :], 0.0)
    ml = m[..., -1, :]
    ps = psi[..., -1, :, base.scene.porosity.index] if base.n_struct else jnp.ones_like(ml)
    a_star = jnp.cbrt(3.0 * ml / (4.0 * jnp.pi * rho_s))
    a = a_star * jnp.cbrt(ps)
    n = jnp.sum(gl, axis=-1)
    n_safe = jnp.where(n > 0, n, 1.0)
    mean = lambda v: jnp.where(n > 0, jnp.sum(gl * v, axis=-1) / n_safe, jnp.nan)
    out = dict(t=t, M_rain=M_rain, f_rain=f_rain, t_rain=t_rain, t_99=t_99, n_rain=n,
               m=mean(ml), a=mean(a), a_star=mean(a_star), psi=mean(ps))
    out["a_over_astar"] = out["a"] / out["a_star"]
    return out
