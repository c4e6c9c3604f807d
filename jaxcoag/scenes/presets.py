"""Named scene presets: functions returning :class:`~jaxcoag.Scene` compositions.

Each preset names only the effects its setting needs (like optax's ``adam = chain(...)``).

References: Ormel (2008) thesis ch. 2 (protoplanetary disk: Brownian + turbulence; Ormel, Spaans &
Tielens 2007, porous vs compact with Weidenschilling 1984 turbulence fits), ch. 4 (nebula with
chondrules: Brownian + OC07 turbulence + radial drift, eqs. 4.4, 4.8, 4.10/ch. 3), ch. 6 (molecular
cloud cores: Brownian + OC07 turbulence); DustPy's default relative velocities (Brownian, turbulence,
radial and azimuthal drift, settling; Stammler & Birnstiel 2022).
"""

from __future__ import annotations

from .._validate import JaxcoagInputError
from ..effects import AzimuthalDrift, Brownian, RadialDrift, Settling, TurbulenceOC07
from ..scene import Scene

__all__ = ["brownian_only", "turbulence_only", "protoplanetary_disk", "nebula_ch4", "molecular_cloud",
           "dustpy_like", "ch2_porous", "ch2_compact", "PRESETS", "get"]

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


# ---- chapter 2 (porous vs compact growth until rain-out; thesis ch. 2 = Ormel+2007)
def _ch2_turbulence(method):
    from ..effects import TurbulenceW84
    return TurbulenceW84() if method in (None, "w84") else TurbulenceOC07(method=method)


def ch2_porous(method: str = "w84") -> Scene:
    """Chapter-2 porous disk scene: Brownian + Weidenschilling (1984) turbulence fits (eqs. 2.1,
    2.5a/b; ``method`` = an OC07 method name swaps in OC07) with the enlargement factor psi as
    structural parameter (``porosity="psi"``: a = a* psi^(1/3), tau_f from (m, psi), eq. 2.25).
    Drag: Epstein with the Stokes switch at a = 9 l_mfp/4 (library default; only R1Ta2-P reaches it)."""
    return Scene(velocities=(Brownian(), _ch2_turbulence(method)), porosity="psi", name="ch2_porous")


def ch2_compact(method: str = "w84") -> Scene:
    """Chapter-2 compact disk scene (psi = 1 by definition, thesis 'C' models): Brownian + W84 fits."""
    return Scene(velocities=(Brownian(), _ch2_turbulence(method)), name="ch2_compact")


PRESETS = {f.__name__: f for f in (brownian_only, turbulence_only, protoplanetary_disk, nebula_ch4,
                                   molecular_cloud, dustpy_like, ch2_porous, ch2_compact)}


def get(name: str, **kw) -> Scene:
    """Preset by name, with a clear error for an unknown one."""
    if name not in PRESETS:
        raise JaxcoagInputError(f"unknown scene preset {name!r}; available: {sorted(PRESETS)}")
    return PRESETS[name](**kw)
