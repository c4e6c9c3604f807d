"""Binned Smoluchowski coagulation-fragmentation on a mass grid (diffrax time integration).

References: Smoluchowski (1916); Brauer, Dullemond & Henning (2008); Birnstiel et al. (2010);
Stammler & Birnstiel (2022, DustPy).
"""

from .grid import MassGrid as MassGrid
from .scheme import AbstractScheme as AbstractScheme
from .twobin import TwoBinScheme as TwoBinScheme
from .solve import (solve_binned as solve_binned, BinnedSolution as BinnedSolution, RESULTS as RESULTS, RESULT_NAMES as RESULT_NAMES,
                    result_code as result_code, result_from_code as result_from_code,
                    steady_state as steady_state, SteadyState as SteadyState)
from .solvers import LinearlyImplicitEuler as LinearlyImplicitEuler
from .fragmentation import (Shattering as Shattering, ShatterToMonomers as ShatterToMonomers,
                            AbstractFragmentation as AbstractFragmentation)
from .grid import monodisperse as monodisperse, mrn as mrn, exponential as exponential
from .dg import DGScheme as DGScheme
from .outcome import (OutcomeFragmentation as OutcomeFragmentation, O07Recipe as O07Recipe,
                      O09Recipe as O09Recipe, ShatterAtMassRecipe as ShatterAtMassRecipe,
                      VfragShatter as VfragShatter)
