"""Rigid fractal aggregates in a periodic box: Euler rotation, collisions, coagulation, restitution (Richardson 1995).

* :mod:`~.body`: inertia tensors and principal axes (eqs. 1-3), torque-free rotation (eqs. 4-6; a symmetric split
  integrator conserving L exactly), generalised restitution (eqs. 13-28), coagulation at the contact point
  (eqs. 8-12), sphere time of impact and conservative advancement;
* :mod:`~.box`: :func:`box_model` (the five test models of Table I), the engine :class:`RigidBox` of
  ``jaxcoag.evolve`` and :func:`run`, returning a :class:`BoxResult`;
* :mod:`~.diagnostics`: R_max, fractal dimension, density and velocity dispersions as §3 defines them.

References: Richardson (1995, Icarus 115, 320), eqs. 1-33, Table I.
"""

from . import body, box, diagnostics
from .box import Box, BoxResult, RigidBox, box_model, run

__all__ = ["Box", "BoxResult", "RigidBox", "body", "box", "box_model", "diagnostics", "run"]
