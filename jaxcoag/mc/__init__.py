"""Grouped Monte Carlo coagulation (Ormel & Spaans 2008) in JAX.

Public API: :func:`run` (monodisperse or custom start via :func:`initial_species`, resume via
``resume_from=result.final_state``, stop predicates such as :class:`Runaway`),
:func:`run_checkpointed` (segment-wise run with an atomic checkpoint file, resumable, progress
bar), :class:`MCResult` (snapshots, statistics, ``to_xarray``), :class:`MCState`,
:class:`STATUS`, outcome modules (:class:`AbstractOutcome`, :class:`PerfectSticking`,
:class:`CatastrophicFragmentation`, :class:`Products`) and the rate helper :func:`n_eps`.

References: Ormel (2008) thesis ch. 5 (Ormel & Spaans 2008, ApJ 684, 1291); conventions, errata and
hazards in docs/design_notes.md.
"""

from .checkpoint import load_checkpoint as load_checkpoint
from .checkpoint import run_checkpointed as run_checkpointed
from .outcomes import AbstractOutcome as AbstractOutcome
from .outcomes import CatastrophicFragmentation as CatastrophicFragmentation
from .outcomes import PerfectSticking as PerfectSticking
from .outcomes import Products as Products
from .rates import n_eps as n_eps
from .recipe_outcome import RainOutKernel as RainOutKernel, RecipeOutcome as RecipeOutcome, rainout_summary as rainout_summary
from .results import MCResult as MCResult
from .run import run as run
from .run import CapacityWarning as CapacityWarning
from .run import min_capacity as min_capacity
from .state import STATUS as STATUS
from .state import AbstractStop as AbstractStop
from .state import InitialSpecies as InitialSpecies
from .state import MCState as MCState
from .state import Runaway as Runaway
from .state import initial_species as initial_species
from .state import largest_two as largest_two
from .state import status_names as status_names
