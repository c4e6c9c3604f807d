"""jaxcoag: differentiable dust coagulation in JAX (cgs units, float64).

Flat public API (the modules stay importable on their own)::

    jaxcoag.physics        pure physics functions (gas, drag, velocities, OC07, outcomes)
    jaxcoag.kernels        analytic kernels; jaxcoag.Scene(...).kernel(gas, rho_s) physical ones
    jaxcoag.effects        velocity effects a Scene composes; jaxcoag.scenes presets
    jaxcoag.MassGrid, jaxcoag.solve_binned    binned Smoluchowski engine (diffrax)
    jaxcoag.mc.run         grouped Monte Carlo engine (Ormel & Spaans 2008)
    jaxcoag.analytic       exact constant / sum / product kernel solutions
    jaxcoag.diagnostics    moments, L1 errors, mass peak, m^2 f(m)

Enable float64 before use: ``jax.config.update("jax_enable_x64", True)``.
"""

from . import analytic, binned, constants, diagnostics, effects, kernels, mc, physics, scenes
from .binned import BinnedSolution as BinnedSolution
from .binned import MassGrid as MassGrid
from .binned import solve_binned as solve_binned
from .binned import steady_state as steady_state
from .kernels import AbstractKernel as AbstractKernel
from .scene import Scene as Scene
from .scene import SceneKernel as SceneKernel

__version__ = "0.1.0"
