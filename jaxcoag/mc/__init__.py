"""Grouped Monte Carlo coagulation (Ormel & Spaans 2008) in JAX.

Public API: :func:`run`, :class:`MCResult`, :class:`STATUS`, outcome modules
(:class:`AbstractOutcome`, :class:`PerfectSticking`, :class:`CatastrophicFragmentation`,
:class:`Products`) and the rate helper :func:`n_eps`.

References: Ormel (2008) thesis ch. 5; spec/montecarlo.md.
"""

from .outcomes import AbstractOutcome as AbstractOutcome
from .outcomes import CatastrophicFragmentation as CatastrophicFragmentation
from .outcomes import PerfectSticking as PerfectSticking
from .outcomes import Products as Products
from .rates import n_eps as n_eps
from .results import MCResult as MCResult
from .run import run as run
from .state import STATUS as STATUS
from .state import status_names as status_names
