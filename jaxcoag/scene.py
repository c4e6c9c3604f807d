"""Scenes: which physical effects a simulation includes (structure), and the physical kernel.

A :class:`Scene` names its velocity effects (a tuple of :mod:`jaxcoag.effects` modules), an
outcome model and a porosity model (``porosity="psi"``: the enlargement factor psi is the
structural parameter x[..., 0]; a = a* psi^(1/3), A = pi a^2, tau_f from (m, psi), thesis
eqs. 2.4, 2.6, 2.25; ``None`` = compact spheres, tracing no porosity ops). It holds no
disk numbers: combine it with a :class:`~jaxcoag.physics.gas.GasState` and a material density
to obtain a :class:`SceneKernel`, the collision kernel K = sigma Delta v [cm^3 s^-1] that both
engines evaluate::

    scene = jaxcoag.Scene(velocities=(Brownian(), TurbulenceOC07(), RadialDrift()))
    K = scene.kernel(gas, rho_s=1.6)           # an AbstractKernel
    K(m1, m2); K.matrix(m); K.relative_velocity2(m1, m2)

Only the named effects are traced (an effect that is absent costs nothing), the components
are added in quadrature and one safe square root is taken of the total (velocity hazard 1
in docs/design_notes.md).

References: Ormel (2008) thesis §4.3 (eq. 4.26, quadrature sum), eq. 5.5 (focusing);
velocity hazards in docs/design_notes.md.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from . import effects as _eff
from ._validate import JaxcoagInputError, JaxcoagTypeError, check
from .kernels import AbstractKernel
from .physics import collision as _coll
from .physics import drag as _drag
from .physics.gas import GasState

__all__ = ["Scene", "SceneKernel"]

_DRAG_REGIMES = ("auto", "epstein", "stokes")


_POROSITY_NAMES = {"psi": lambda: _eff.EnlargementFactor()}


def _porosity_model(p):
    """Scene(porosity=...) converter: None, "psi" or an AbstractPorosity instance."""
    if isinstance(p, str):
        if p not in _POROSITY_NAMES:
            raise JaxcoagInputError(f"unknown porosity {p!r}; use None (compact), 'psi' (enlargement factor "
                             "psi as structural parameter x[..., 0]) or jaxcoag.effects.EnlargementFactor(index)")
        return _POROSITY_NAMES[p]()
    return p


class Scene(eqx.Module):
    """A composition of physical effects (structure only; numbers live in GasState/material).

    Attributes:
        velocities: tuple of velocity effects (instances of
            :class:`jaxcoag.effects.AbstractVelocity`), added in quadrature. At least one.
        focusing: include gravitational focusing in the cross-section (eq. 5.5) (static bool).
        drag_regime: "auto" (Epstein/Stokes switch at a = 9/4 l_mfp, eq. 4.6), "epstein", "stokes".
        outcome: collision-outcome model, or None for perfect sticking (outcomes issue).
        porosity: None (compact spheres: traces no porosity ops), ``"psi"`` or
            :class:`jaxcoag.effects.EnlargementFactor` (structural parameter x[..., 0] is the
            enlargement factor psi: a = a* psi^(1/3), A = pi a^2, tau_f from (m, psi); thesis
            eqs. 2.4, 2.6, 2.25). The kernel then has ``n_struct = 1`` and takes ``x``.
        name: label recorded in outputs.
        drag_convention: "ormel" (default: Epstein law with the isothermal sound speed c_g and
            l_mfp = 1/(n sigma_mol), thesis eqs. 2.4, 4.5) or "dustpy" (mean thermal speed
            sqrt(8/pi) c_g and 1/(sqrt(2) n sigma_mol); Birnstiel et al. 2010, DustPy): the same
            grain has a 1.596x larger Epstein St with "ormel" (:mod:`jaxcoag.physics.drag`).
    """

    velocities: tuple = ()
    focusing: bool = eqx.field(static=True, default=False)
    drag_regime: str = eqx.field(static=True, default="auto")
    outcome: Any = None
    porosity: Any = eqx.field(default=None, converter=lambda p: _porosity_model(p))
    name: str = eqx.field(static=True, default="custom")
    drag_convention: str = eqx.field(static=True, default="ormel")

    def __check_init__(self):
        if not isinstance(self.velocities, tuple) or len(self.velocities) == 0:
            raise JaxcoagInputError(
                "Scene(velocities=...) needs a non-empty tuple of velocity effects, e.g. "
                "(jaxcoag.effects.Brownian(), jaxcoag.effects.TurbulenceOC07())"
            )
        names = []
        for v in self.velocities:
            if not isinstance(v, _eff.AbstractVelocity):
                raise JaxcoagTypeError(
                    f"Scene velocities must be jaxcoag.effects velocity modules (Brownian(), "
                    f"TurbulenceOC07(), RadialDrift(), AzimuthalDrift(), Settling()); got {v!r}"
                )
            names.append(v.name)
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise JaxcoagInputError(
                f"Scene lists the velocity effect(s) {dup} more than once; they are incompatible "
                "(each effect is added once in quadrature). Keep one of each."
            )
        if self.drag_regime not in _DRAG_REGIMES:
            raise JaxcoagInputError(f"unknown drag_regime {self.drag_regime!r}; use one of {_DRAG_REGIMES}")
        if self.drag_convention not in _drag.DRAG_CONVENTIONS:
            raise JaxcoagInputError(f"unknown drag_convention {self.drag_convention!r}; use one of "
                                    f"{_drag.DRAG_CONVENTIONS} ('ormel': Epstein with c_g, thesis eq. 4.5; "
                                    "'dustpy': with sqrt(8/pi) c_g and a mean free path 1/(sqrt(2) n sigma))")
        if self.porosity is not None and not isinstance(self.porosity, _eff.AbstractPorosity):
            raise JaxcoagTypeError(
                f"Scene(porosity=...) must be None (compact spheres), 'psi' or a "
                f"jaxcoag.effects porosity model (EnlargementFactor()); got {self.porosity!r}"
            )

    @property
    def effect_names(self) -> tuple:
        return tuple(v.name for v in self.velocities)

    def kernel(self, gas: GasState, rho_s=None, *, material=None, dv_floor=0.0) -> "SceneKernel":
        """The physical kernel of this scene in a given gas with material density rho_s.

        Arguments:
            gas: local gas state (jaxcoag.physics.gas).
            rho_s: material (bulk) density of compact particles [g cm^-3]; or pass
                ``material`` (any object with a ``rho_s`` attribute).
            dv_floor: velocity floor [cm/s] added in quadrature (only needed with focusing and
                no Brownian term; velocity hazard 6). Default 0.
        """
        if not isinstance(gas, GasState):
            raise JaxcoagTypeError("Scene.kernel(gas, ...): gas must be a jaxcoag GasState "
                            "(e.g. jaxcoag.physics.gas.mmsn_hayashi81(jaxcoag.constants.AU))")
        if rho_s is None:
            if material is None or not hasattr(material, "rho_s"):
                raise JaxcoagInputError("Scene.kernel needs the material density: pass rho_s=... [g cm^-3] "
                                 "or material=<object with .rho_s>")
            rho_s = material.rho_s
        rho_s = check(rho_s, "rho_s", positive=True, hint="material density in g cm^-3, e.g. 1.6 or 3.0")
        dv_floor = check(dv_floor, "dv_floor", nonnegative=True)
        return SceneKernel(scene=self, gas=gas, rho_s=rho_s, dv_floor=dv_floor)


class SceneKernel(AbstractKernel):
    """Physical collision kernel K = sigma(a1, a2) Delta v_tot [cm^3 s^-1] of a Scene.

    sigma = pi (a1 + a2)^2, times the focusing factor 1 + v_esc^2/Delta v^2 if the scene asks
    for it (eq. 5.5); Delta v_tot^2 = sum of the scene's effects (eq. 4.26 text) + dv_floor^2.
    Compact spheres: a = (3 m / (4 pi rho_s))^(1/3). Every number (gas state, rho_s) is an array
    leaf, so jax.grad with respect to alpha, rho_g, T, rho_s flows through the kernel.
    """

    scene: Scene
    gas: GasState
    rho_s: jax.Array
    dv_floor: jax.Array

    @property
    def n_struct(self) -> int:  # type: ignore[override]
        """Number of structural parameters read from ``x`` (0 compact, 1 with porosity="psi")."""
        por = self.scene.porosity
        return 0 if por is None else por.n_struct

    def particles(self, m, x=None) -> _eff.Particles:
        """Per-particle properties for masses m [g] and structure x (shape m.shape + (n_struct,)).

        Compact scenes ignore x. Porous scenes need x: a = a* psi^(1/3), A = pi a^2 and the
        friction time from (m, A) (Epstein tau_f = rho_s a*/(c_g rho_g psi^(2/3)), thesis eq. 2.25).
        """
        m = jnp.asarray(m)
        por = self.scene.porosity
        if por is None:
            a = _drag._compact_radius(m, self.rho_s)
            area = jnp.pi * a ** 2
        else:
            if x is None:
                raise JaxcoagTypeError(
                    "this SceneKernel has porosity (n_struct = 1): pass the structural parameters, e.g. "
                    "K(m1, m2, x1, x2) or K.matrix(m, x) with x[..., 0] = psi >= 1 (x = ones((N, 1)) for "
                    "compact particles)")
            x = jnp.asarray(x)
            if x.ndim == 0 or x.shape[-1] < por.n_struct:
                raise JaxcoagTypeError(f"structural parameters x need a trailing axis of length >= {por.n_struct} "
                                f"(x[..., 0] = psi); got shape {x.shape}")
            a, area = por.radius_area(m, x, self.rho_s)
        tau = _drag._friction_time(m, a, self.gas, area=area, regime=self.scene.drag_regime,
                                   convention=self.scene.drag_convention)
        return _eff.Particles(m=m, a=a, area=area, tau_f=tau, st=tau / self.gas.t_L)

    def _caches(self, p):
        return tuple(v.per_particle(p, self.gas) for v in self.scene.velocities)

    def _dv2_pairs(self, p1, c1, p2, c2):
        total = None
        for v, a, b in zip(self.scene.velocities, c1, c2):
            term = v.dv2(p1, a, p2, b, self.gas)
            total = term if total is None else total + term
        return total + self.dv_floor ** 2

    def _pairs(self, m1, m2, x1, x2):
        p1, p2 = self.particles(m1, x1), self.particles(m2, x2)
        return p1, p2, self._dv2_pairs(p1, self._caches(p1), p2, self._caches(p2))

    def _outer(self, m, x):
        p = self.particles(m, x)
        c = self._caches(p)
        exp = lambda tree, ax: jax.tree_util.tree_map(lambda v: jnp.expand_dims(v, ax), tree)
        p1, p2 = p.expand(1), p.expand(0)
        dv2 = self._dv2_pairs(p1, exp(c, 1), p2, exp(c, 0))
        return p1, p2, dv2

    def _k(self, p1, p2, dv2):
        return _coll._kernel_sigma_dv(p1.a, p2.a, p1.m, p2.m, dv2, focusing=self.scene.focusing)

    def __call__(self, m1, m2, x1=None, x2=None):
        p1, p2, dv2 = self._pairs(m1, m2, x1, x2)
        return self._k(p1, p2, dv2)

    def relative_velocity2(self, m1, m2, x1=None, x2=None):
        """Total squared relative velocity Delta v_tot^2 [cm^2 s^-2] (quadrature sum)."""
        return self._pairs(m1, m2, x1, x2)[2]

    def matrix(self, m, x=None):
        p1, p2, dv2 = self._outer(m, x)
        return self._k(p1, p2, dv2)

    def matrix_and_dv2(self, m, x=None):
        p1, p2, dv2 = self._outer(m, x)
        return self._k(p1, p2, dv2), dv2

    def components_matrix(self, m, x=None) -> dict:
        """Per-effect N x N matrices of Delta v_k^2 [cm^2 s^-2], keyed by effect name (diagnostics)."""
        p = self.particles(m, x)
        c = self._caches(p)
        out = {}
        for v, cc in zip(self.scene.velocities, c):
            exp = lambda tree, ax: jax.tree_util.tree_map(lambda u: jnp.expand_dims(u, ax), tree)
            out[v.name] = v.dv2(p.expand(1), exp(cc, 1), p.expand(0), exp(cc, 0), self.gas)
        return out
