"""Scenes: named presets (``jaxcoag.scenes.nebula_ch4()`` ...: functions returning a
:class:`~jaxcoag.Scene`), and in separate modules

- :mod:`jaxcoag.scenes.tables`: published reference tables (thesis T-Tab2.2, T-Tab4.1/4.5, T-Tab6.5/6.6);
- :mod:`jaxcoag.scenes.binned_setups`: complete binned-engine settings of the seeds
  (``binned_setups.setup("ch6_cloud", n=1e5)``);
- :mod:`jaxcoag.scenes.mc_setups`: the Monte Carlo set-ups of the paper figures (thesis ch. 2:
  ``ch2_setup``, ``ch2_mc_run``, ``ch2_pilot``, ``RainedFraction``).

References: Ormel (2008) thesis chs. 2-6; Stammler & Birnstiel (2022) for :func:`dustpy_like`.
"""

from . import binned_setups, mc_setups, tables
from .presets import (PRESETS, brownian_only, ch2_compact, ch2_porous, dustpy_like, get, molecular_cloud,
                      nebula_ch4, protoplanetary_disk, turbulence_only)

__all__ = ["brownian_only", "turbulence_only", "protoplanetary_disk", "nebula_ch4", "molecular_cloud",
           "dustpy_like", "ch2_porous", "ch2_compact", "PRESETS", "get", "tables", "binned_setups", "mc_setups"]
