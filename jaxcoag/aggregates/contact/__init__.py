"""Monomer contact mechanics: aggregate collisions with JKR, sliding, rolling and twisting (Wada et al. 2007).

A differentiable discrete-element model (DEM) of equal spherical monomers, in 2-D (the paper's planar runs) and 3-D:

* :mod:`~.materials`: :class:`Material` (surface energy, Young's modulus, Poisson ratio, density, monomer radius,
  critical rolling displacement; every constant a float64 leaf, so gradients flow) with ``ice()``, ``quartz()``
  (Wada et al. 2007 Table 2) and ``material(...)``, and the derived scales (v0, t_c, E_roll, E_break, ...);
* :mod:`~.jkr`, :mod:`~.interactions`: the JKR normal force (eqs. 1-7) and the sliding, rolling and twisting springs
  with their inelastic regimes (eqs. 8-43), pure functions;
* :mod:`~.dem`: the fixed-capacity state, neighbour list, contact list and leapfrog step (eqs. 46-47);
* :func:`bcca` (:mod:`~.structures`): ballistic cluster-cluster aggregates of 2^k monomers;
* :func:`collide` / :class:`DEM` + :class:`Collision` (:mod:`~.collision`): a collision run to its outcome, also as
  an engine of ``jaxcoag.evolve`` (checkpoint/resume), returning a :class:`CollisionResult`;
* :mod:`~.analysis`: clusters of the contact graph, gyration radius (eq. 50), contact number;
* :mod:`~.bridge`: a sweep of collisions turned into a collision outcome for the binned and Monte Carlo engines.

References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007, ApJ 661, 320), eqs. 1-59, Tables 1-3.
"""

from . import aggregate, analysis, bridge, collision, dem, interactions, jkr, materials, structures
from .aggregate import Aggregate, monomer
from .analysis import clusters, contact_number, fractal_fit, gyration_radius, largest_cluster
from .bridge import CollisionOutcome, CollisionTable, outcome_from_collisions, sweep_collisions
from .collision import DEM, Collision, CollisionResult, collide
from .materials import Material, ice, material, quartz
from .structures import bcca

__all__ = ["Aggregate", "Collision", "CollisionOutcome", "CollisionResult", "CollisionTable", "DEM", "Material",
           "aggregate", "analysis", "bcca", "bridge", "clusters", "collide", "collision", "contact_number", "dem",
           "fractal_fit", "gyration_radius", "ice", "interactions", "jkr", "largest_cluster", "material", "materials",
           "monomer", "outcome_from_collisions", "quartz", "structures", "sweep_collisions"]
