"""Named scene presets: functions returning :class:`~jaxcoag.Scene` compositions.

Each preset names only the effects its setting needs (like optax's ``adam = chain(...)``).

References: Ormel (2008) thesis ch. 2 (protoplanetary disk: Brownian + turbulence), ch. 4
(nebula with chondrules: Brownian + OC07 turbulence + radial drift, eqs. 4.4, 4.8, 4.10/ch. 3),
ch. 6 (molecular cloud cores: Brownian + OC07 turbulence); DustPy's default relative velocities
(Brownian, turbulence, radial and azimuthal drift, settling; Stammler & Birnstiel 2022).
"""

from __future__ import annotations

from .effects import AzimuthalDrift, Brownian, RadialDrift, Settling, TurbulenceOC07
from .scene import Scene

__all__ = ["brownian_only", "turbulence_only", "protoplanetary_disk", "nebula_ch4", "molecular_cloud",
           "dustpy_like", "PRESETS", "get"]


def brownian_only() -> Scene:
    """Brownian motion only (thesis eq. 4.4): the small-grain, laminar limit."""
    return Scene(velocities=(Brownian(),), name="brownian_only")


def turbulence_only(method: str = "exact") -> Scene:
    """OC07 turbulence only (thesis ch. 3)."""
    return Scene(velocities=(TurbulenceOC07(method=method),), name="turbulence_only")


def protoplanetary_disk(method: str = "exact") -> Scene:
    """Chapter-2 style disk scene: Brownian motion + OC07 turbulence (compact variant)."""
    return Scene(velocities=(Brownian(), TurbulenceOC07(method=method)), name="protoplanetary_disk")


def nebula_ch4(method: str = "exact") -> Scene:
    """Chapter-4 nebula: thermal, turbulent and radial-drift velocities in quadrature (§4.3)."""
    return Scene(velocities=(Brownian(), TurbulenceOC07(method=method), RadialDrift()), name="nebula_ch4")


def molecular_cloud(method: str = "exact") -> Scene:
    """Chapter-6 molecular-cloud core: Brownian + OC07 turbulence (use gas.molecular_cloud)."""
    return Scene(velocities=(Brownian(), TurbulenceOC07(method=method)), name="molecular_cloud")


def dustpy_like(method: str = "exact") -> Scene:
    """All five contributions DustPy adds in quadrature (azimuthal drift and settling are [EXT])."""
    return Scene(velocities=(Brownian(), TurbulenceOC07(method=method), RadialDrift(), AzimuthalDrift(),
                             Settling()), name="dustpy_like")


PRESETS = {f.__name__: f for f in (brownian_only, turbulence_only, protoplanetary_disk, nebula_ch4,
                                   molecular_cloud, dustpy_like)}


def get(name: str, **kw) -> Scene:
    """Preset by name, with a clear error for an unknown one."""
    if name not in PRESETS:
        raise KeyError(f"unknown scene preset {name!r}; available: {sorted(PRESETS)}")
    return PRESETS[name](**kw)
