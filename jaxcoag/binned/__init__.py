"""Binned Smoluchowski coagulation-fragmentation on a mass grid (diffrax time integration).

The engine object :class:`Binned` (run it with ``jaxcoag.evolve``), its result :class:`BinnedResult`,
the grid (:class:`MassGrid`, initial distributions), the schemes (:class:`TwoBinScheme`,
:class:`DGScheme`), the Rosenbrock solver :class:`Rodas4` (the default with fragmentation), the
DustPy-parity solver :class:`LinearlyImplicitEuler` and :func:`steady_state`.

References: Smoluchowski (1916); Brauer, Dullemond & Henning (2008); Birnstiel et al. (2010);
Stammler & Birnstiel (2022, DustPy); Hairer & Wanner (1996) (Rosenbrock methods).
"""

from .grid import MassGrid as MassGrid
from .scheme import AbstractScheme as AbstractScheme
from .twobin import TwoBinScheme as TwoBinScheme
from .engine import Binned as Binned, BinnedResult as BinnedResult
from .solve import steady_state as steady_state, SteadyState as SteadyState
from .solvers import LinearlyImplicitEuler as LinearlyImplicitEuler
from .solvers import Rodas4 as Rodas4
from .grid import monodisperse as monodisperse, mrn as mrn, exponential as exponential
from .dg import DGScheme as DGScheme
