"""Rigid fractal aggregates in a periodic box: Euler rotation, collisions, coagulation, restitution (Richardson 1995).

* :mod:`~.body`: inertia tensors and principal axes (eqs. 1-3), torque-free rotation (eqs. 4-6; a symmetric split
  integrator conserving L exactly), generalised restitution (eqs. 13-28), coagulation at the contact point
  (eqs. 8-12), sphere time of impact and conservative advancement;
* :mod:`~.box`: :func:`box_model` (the five test models of Table I), the engine :class:`RigidBox` of
  ``jaxcoag.evolve`` and :func:`run`, returning a :class:`BoxResult`;
* :mod:`~.diagnostics`: R_max, fractal dimension, density and velocity dispersions as §3 defines them;
* :mod:`~.bridge`: the bridge to coagulation: the kernel measured from a box's collision log
  (:func:`measured_kernel`), the discrete coagulation equation (R29) and the binned engine side by side
  with the box (:func:`compare_model_i` with the constant kernel α, R30/R31; :func:`compare_measured`).

References: Richardson (1995, Icarus 115, 320), eqs. 1-33, Table I.
"""

from . import body, box, bridge, diagnostics
from .box import Box, BoxResult, RigidBox, box_model, run
from .bridge import ClassKernel, MeasuredKernel, compare_measured, compare_model_i, measured_kernel, smoluchowski

__all__ = ["Box", "BoxResult", "ClassKernel", "MeasuredKernel", "RigidBox", "body", "box", "box_model", "bridge",
           "compare_measured", "compare_model_i", "diagnostics", "measured_kernel", "run", "smoluchowski"]
