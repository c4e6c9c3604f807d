"""jaxcoag: differentiable dust coagulation in JAX (cgs units, float64).

One verb runs every engine (diffrax style: the numerical strategy is an object)::

    import jaxcoag as jc
    res = jc.evolve(kernel, jc.Binned(grid), jc.Monodisperse(m0, rho_d), t_out)          # binned (diffrax)
    res = jc.evolve(kernel, jc.MonteCarlo(...), jc.Monodisperse(m0, rho_d), t_out, key=key)  # grouped MC
    res.t, res.status, res.mass_per_bin(edges), res.moments(2), res.to_xarray()

Public API (flat; the modules behind it are private or namespaces):

    evolve, Binned, MonteCarlo, BinnedResult, MCResult, Monodisperse    the verb, engines, results
    RESULTS, RESULT_NAMES, FAILURES, result_code, status_names          one status for every engine (codes in files)
    MassGrid, Scene, SceneKernel, AbstractKernel                        grid, physical scenes, kernels
    outcomes                     collision outcomes accepted by every engine (Sticking, ShatterAbove, ...)
    kernels, effects, scenes     analytic kernels, velocity effects, scene presets and set-ups
    physics                      pure physics functions (gas, drag, velocities, OC07, porosity, outcomes)
    analytic, diagnostics        exact solutions; moments, L1 errors, mass peak, m^2 f(m)
    io, sweep, fit, checkpoint   netCDF output, vmapped sweeps, gradient fits, checkpoint/resume
    binned, mc                   engine namespaces (schemes, solvers, initial species, stop predicates)
    enable_compilation_cache     JAX's persistent compilation cache (a second process does not compile again)

Enable float64 before use: ``jax.config.update("jax_enable_x64", True)``.
"""

from . import analytic, binned, checkpoint, constants, diagnostics, effects, io, kernels, mc, outcomes, physics, scenes
from ._cache import enable_compilation_cache as enable_compilation_cache
from ._engine import AbstractEngine as AbstractEngine
from ._engine import AbstractResult as AbstractResult
from ._engine import Monodisperse as Monodisperse
from ._engine import evolve as evolve
from ._status import FAILURES as FAILURES
from ._status import RESULT_NAMES as RESULT_NAMES
from ._status import RESULTS as RESULTS
from ._status import result_code as result_code
from ._status import result_from_code as result_from_code
from ._status import status_names as status_names
from .binned import Binned as Binned
from .binned import BinnedResult as BinnedResult
from .binned import MassGrid as MassGrid
from .kernels import AbstractKernel as AbstractKernel
from .mc import MCResult as MCResult
from .mc import MonteCarlo as MonteCarlo
from .outcomes import AbstractOutcome as AbstractOutcome
from .outcomes import O07Recipe as O07Recipe
from .outcomes import O09Recipe as O09Recipe
from .outcomes import RecipeOutcome as RecipeOutcome
from .outcomes import ShatterAbove as ShatterAbove
from .outcomes import Shattering as Shattering
from .outcomes import Sticking as Sticking
from .outcomes import VfragShatter as VfragShatter
from .scene import Scene as Scene
from .scene import SceneKernel as SceneKernel

__version__ = "0.1.0"
