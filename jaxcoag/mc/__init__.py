"""Grouped Monte Carlo coagulation (Ormel & Spaans 2008) in JAX.

Run it through the one verb of jaxcoag::

    res = jaxcoag.evolve(kernel, jaxcoag.MonteCarlo(grouping=jaxcoag.mc.EqualMass(), n_particles=1e30,
                                                    ns_target=200),
                         jaxcoag.Monodisperse(m0, rho_d), t_out, key=jax.random.key(0))

Public API: the engine :class:`MonteCarlo` and its structure classes (:class:`EqualMass`,
:class:`Distribution`; :class:`ConstantVolume`, :class:`ConstantNumber`, :class:`ConstantSpecies`
with :class:`MassController` / :class:`SpeciesController`; :class:`IncrementalRates`,
:class:`FullRates`), custom starts via :func:`initial_species`, stop predicates
(:class:`AbstractStop`, :class:`Runaway`), the result :class:`MCResult` (snapshots, statistics,
``to_xarray``), the state :class:`MCState`, :func:`min_capacity`, :class:`CapacityWarning`, the
statistics helper :func:`largest_two`, the rate helper :func:`n_eps` and the thesis ch. 2 rain-out
sink (:class:`RainOutKernel`, :func:`rainout_summary`). Collision outcomes live in
:mod:`jaxcoag.outcomes` (shared with the binned engine).

References: Ormel (2008) thesis ch. 5 (Ormel & Spaans 2008, ApJ 684, 1291); conventions, errata and
hazards in docs/design_notes.md.
"""

from .engine import ConstantNumber as ConstantNumber
from .engine import ConstantSpecies as ConstantSpecies
from .engine import ConstantVolume as ConstantVolume
from .engine import Distribution as Distribution
from .engine import EqualMass as EqualMass
from .engine import FullRates as FullRates
from .engine import IncrementalRates as IncrementalRates
from .engine import MassController as MassController
from .engine import MonteCarlo as MonteCarlo
from .engine import SpeciesController as SpeciesController
from .rainout import RainOutKernel as RainOutKernel
from .rainout import rainout_summary as rainout_summary
from .rates import n_eps as n_eps
from .results import MCResult as MCResult
from .run import CapacityWarning as CapacityWarning
from .run import min_capacity as min_capacity
from .state import AbstractStop as AbstractStop
from .state import InitialSpecies as InitialSpecies
from .state import MCState as MCState
from .state import Runaway as Runaway
from .state import initial_species as initial_species
from .state import largest_two as largest_two
