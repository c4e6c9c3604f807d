"""Velocity effects: thin ``equinox`` Modules that select physics for a :class:`~jaxcoag.Scene`.

Each effect contributes a squared relative velocity Delta v_k^2 [cm^2 s^-2] for pairs of
particles; a scene adds the effects it names in quadrature (Ormel 2008 §4.3, text under eq. 4.26;
as DustPy's ``vrel_tot``) and the kernel takes ONE safe square root of the total
(thesis §4.3; velocity hazard 1 in docs/design_notes.md). An effect that is not named is never traced.

Per-particle work (e.g. the OC07 class boundary St*, a root solve) is done once per particle in
``per_particle`` and passed to ``dv2`` for the pairs, so an N x N kernel matrix costs N root
solves, not N^2 (velocity hazard 6).

Particle properties are passed as a :class:`Particles` record (mass, radius, area, friction time,
Stokes number), broadcast-compatible between the two collision partners.
"""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .physics import drag as _drag
from .physics import drift as _drift
from .physics import turbulence as _turb
from ._validate import JaxcoagInputError
from .physics.gas import GasState

__all__ = [
    "Particles",
    "AbstractVelocity",
    "Brownian",
    "TurbulenceOC07",
    "RadialDrift",
    "AzimuthalDrift",
    "Settling",
    "TurbulenceW84",
    "AbstractPorosity",
    "EnlargementFactor",
]


class Particles(eqx.Module):
    """Per-particle properties [cgs] used by velocity effects (broadcasting arrays).

    Fields: m [g], a [cm] (geometric radius), area [cm^2] (projected), tau_f [s] (friction time),
    st [-] (Stokes number tau_f / t_L).
    """

    m: jax.Array
    a: jax.Array
    area: jax.Array
    tau_f: jax.Array
    st: jax.Array

    def expand(self, axis: int) -> "Particles":
        """Insert a length-1 axis in every field (for outer-product pair broadcasting)."""
        return jax.tree_util.tree_map(lambda v: jnp.expand_dims(v, axis), self)


class AbstractVelocity(eqx.Module):
    """A relative-velocity contribution. Subclasses set ``name`` and implement ``dv2``."""

    name: ClassVar[str] = "abstract"
    extension: ClassVar[bool] = False  # True for [EXT] effects not taken from the thesis

    def per_particle(self, p: Particles, gas: GasState):
        """Per-particle precomputation (default: nothing)."""
        return None

    @abc.abstractmethod
    def dv2(self, p1: Particles, c1, p2: Particles, c2, gas: GasState):
        """Squared relative velocity [cm^2 s^-2] for the pairs (p1, p2) (broadcasting)."""


class Brownian(AbstractVelocity):
    """Brownian motion, Delta v^2 = (8 k_B T/pi)(1/m1 + 1/m2) (thesis eqs. 1.23, 2.1, 4.4)."""

    name: ClassVar[str] = "brownian"

    def dv2(self, p1, c1, p2, c2, gas):
        return _drift._dv2_brownian(p1.m, p2.m, gas.T)


class TurbulenceOC07(AbstractVelocity):
    """Turbulent relative velocity of Ormel & Cuzzi (2007), full closed form (thesis ch. 3,
    eqs. 3.14-3.15 in the bounded-factor form; velocity hazard 3).

    Attributes:
        method: "exact" (root of eq. 3.21), "ya" (t* = 1.6 tau_f) or "ch03" (static).
        accurate: use the App. 3.A power-law variant for class-II eddies (static).
        beta_over_alpha: eddy-crossing correction of eq. 3.21 (array leaf; default 0).
    """

    name: ClassVar[str] = "turbulence"
    method: str = eqx.field(static=True, default="exact")
    accurate: bool = eqx.field(static=True, default=False)
    beta_over_alpha: jax.Array = eqx.field(default_factory=lambda: jnp.asarray(0.0))

    def __check_init__(self):
        if self.method not in ("exact", "ya", "ch03"):
            raise JaxcoagInputError(f"TurbulenceOC07: unknown method {self.method!r}; use 'exact', 'ya' or 'ch03'")

    def per_particle(self, p, gas):
        return _turb.st_star(p.st, gas.Re_eff, method=self.method, beta_over_alpha=self.beta_over_alpha)

    def dv2(self, p1, c1, p2, c2, gas):
        dvI2, dvII2 = _turb.dv2_terms_oc07(p1.st, p2.st, c1, c2, gas.Re_eff, accurate=self.accurate)
        return gas.v_g ** 2 * (dvI2 + dvII2)


class RadialDrift(AbstractVelocity):
    """Differential radial drift, Delta v_r = 2 eta v_K |St1/(1+St1^2) - St2/(1+St2^2)| (thesis eq. 4.8)."""

    name: ClassVar[str] = "radial_drift"

    def dv2(self, p1, c1, p2, c2, gas):
        # drift uses Omega tau_f (eq. 4.8), which equals St only for t_L = 1/Omega
        return _drift._dv2_radial_drift(p1.tau_f * gas.Omega, p2.tau_f * gas.Omega, gas.eta, gas.v_K)


class AzimuthalDrift(AbstractVelocity):
    """[EXT] Differential azimuthal (headwind) drift, eta v_K |1/(1+St1^2) - 1/(1+St2^2)|
    (derived from the same single-particle equations as eq. 4.8; not in the thesis)."""

    name: ClassVar[str] = "azimuthal_drift"
    extension: ClassVar[bool] = True

    def dv2(self, p1, c1, p2, c2, gas):
        return _drift._dv2_azimuthal_drift(p1.tau_f * gas.Omega, p2.tau_f * gas.Omega, gas.eta, gas.v_K)


class Settling(AbstractVelocity):
    """[EXT] Differential vertical settling at the gas state's height z, Delta v_z = |z| Omega
    |St1/(1+St1) - St2/(1+St2)| (ch. 1 §1.2.1 terminal velocity, capped for St >~ 1)."""

    name: ClassVar[str] = "settling"
    extension: ClassVar[bool] = True

    def dv2(self, p1, c1, p2, c2, gas):
        return _drift._dv2_settling(p1.tau_f * gas.Omega, p2.tau_f * gas.Omega, gas.z, gas.Omega)


class TurbulenceW84(AbstractVelocity):
    """Legacy turbulent relative velocity: Weidenschilling (1984) piecewise fits (thesis ch. 2,
    eqs. 2.5a/b), as used in the thesis ch. 2 protoplanetary-disk runs.

    With tau_1 >= tau_2 (friction times, eddy times t_s, t_L and velocities v_s, v_L of the
    gas state): v_s (tau_1 - tau_2)/t_s below t_s; min(v_s 3/(1 + tau_2/tau_1) sqrt(tau_1/t_s),
    v_L) up to t_L; v_L beyond. Piecewise (discontinuous at tau_1 = t_s, see thesis Fig. 2.1):
    gradients exist inside each branch only. Use a gas state built with the ch. 2 conventions
    (t_L = 2 pi/Omega, v_L = alpha^1/2 c_g: ``tL_factor=2*pi``) to reproduce ch. 2.

    References: Weidenschilling (1984) Icarus 60, 553; Ormel (2008) thesis eqs. 2.2-2.5;
    """

    name: ClassVar[str] = "turbulence_w84"

    def dv2(self, p1, c1, p2, c2, gas):
        dv = _turb.dv_turbulent_w84(p1.tau_f, p2.tau_f, gas.t_s, gas.t_L, gas.v_s, gas.v_L)
        return dv * dv


class AbstractPorosity(eqx.Module):
    """A porosity model for :class:`~jaxcoag.Scene` (``Scene(porosity=...)``): how a particle's
    structural parameters (the trailing axis of ``x``) set its geometric radius and area."""

    n_struct: ClassVar[int] = 1

    @abc.abstractmethod
    def radius_area(self, m, x, rho_s):
        """(a [cm], projected area [cm^2]) of particles of mass m [g] with structure x."""


class EnlargementFactor(AbstractPorosity):
    """Structural parameter ``x[..., index]`` is the enlargement factor psi = V/V* >= 1.

    Geometric radius a = a* psi^(1/3) with a* = (3 m/(4 pi rho_s))^(1/3), projected area
    A = pi a^2 = pi a*^2 psi^(2/3) [T2.6]; the Epstein friction time then follows as
    tau_f = 3 m/(4 c_g rho_g A) = rho_s a*/(c_g rho_g psi^(2/3)) [T2.4, T2.25]. psi = 1 is a
    compact sphere. The collision cross-section uses the same geometric radii (ch. 2, ch. 4:
    sigma = pi (a1 + a2)^2, thesis §2.2.2 and ch. 4 footnote 6).

    Attributes:
        index: which structural parameter holds psi (static; default 0).

    References: Ormel (2008) thesis eqs. 2.4, 2.6, 2.25.
    """

    index: int = eqx.field(static=True, default=0)

    def __check_init__(self):
        if not isinstance(self.index, int) or self.index < 0:
            raise JaxcoagInputError(f"EnlargementFactor(index={self.index!r}): index must be a non-negative int")

    @property
    def n_struct(self) -> int:  # type: ignore[override]
        return self.index + 1

    def radius_area(self, m, x, rho_s):
        psi = x[..., self.index]
        a = _drag._compact_radius(m, rho_s) * jnp.cbrt(psi)
        return a, jnp.pi * a ** 2
