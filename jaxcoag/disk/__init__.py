"""The 1-D radial disk model: viscous gas, dust radial drift and diffusion, and coagulation plus
fragmentation in every radial cell (the model DustPy users run), differentiable end to end.

* :func:`dustpy_default` builds DustPy's default model (Stammler & Birnstiel 2022 §3), every quantity
  overridable by keyword; effects switch off with ``coagulation=False``, ``dust_transport=False``,
  ``gas_evolution=False``.
* :func:`solve` (or ``jaxcoag.evolve(model, Disk(...), None, t_out)``) evolves it and returns a
  :class:`DiskResult` (``.t`` [s], ``.r`` [cm], ``.m`` [g], ``.sigma_dust`` (t, r, m), ``.sigma_gas``
  (t, r) [g cm^-2], ``.a`` [cm], ``.St``, ``.to_xarray()``).
* :class:`Parity` reproduces DustPy's discrete system (monolithic implicit Euler, its Picard
  coagulation matrix and step rule); :class:`Split` is the faster Strang-split step.

Building blocks: :mod:`~jaxcoag.disk.grid`, :mod:`~jaxcoag.disk.gas`, :mod:`~jaxcoag.disk.transport`,
:mod:`~jaxcoag.disk.velocities`, :mod:`~jaxcoag.disk.coagulation`, :mod:`~jaxcoag.disk.blocksolve`.

References: Stammler & Birnstiel (2022, ApJ 935, 35); Birnstiel, Dullemond & Brauer (2010, A&A 513, A79).
"""

from . import blocksolve, coagulation, gas, grid, transport, velocities
from .engine import Disk, DiskProfile, DiskResult, solve
from .model import DUSTPY_DEFAULTS, DiskModel, dustpy_default
from .solve import DiskState, Parity, Split

__all__ = ["Disk", "DiskModel", "DiskProfile", "DiskResult", "DiskState", "DUSTPY_DEFAULTS", "Parity", "Split",
           "dustpy_default", "solve", "blocksolve", "coagulation", "gas", "grid", "transport",
           "velocities"]
