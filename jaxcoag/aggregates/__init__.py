"""Particle-level aggregate dynamics, beneath the coagulation engines.

* :mod:`jaxcoag.aggregates.contact`: monomer contact mechanics (JKR normal force, sliding, rolling and
  twisting; Wada et al. 2007) in a differentiable discrete-element model, 2-D and 3-D.
* :mod:`jaxcoag.aggregates.rigid`: rigid fractal aggregates of spheres that rotate, collide, stick or
  bounce in a periodic box (Richardson 1995).

References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007, ApJ 661, 320); Richardson (1995, Icarus 115, 320).
"""

from . import contact, rigid

__all__ = ["contact", "rigid"]
