"""An aggregate of equal spherical monomers: the initial structure of a contact-mechanics collision.

References: Wada et al. (2007, ApJ 661, 320) §2 (monomers of radius r_1), §4 (aggregates of 2^k monomers).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._validate import JaxcoagInputError, is_traced

__all__ = ["Aggregate", "monomer"]


class Aggregate(eqx.Module):
    """Equal spherical monomers at fixed positions (an initial structure; contacts are found from the geometry).

    Fields:
        positions: monomer centres [cm], shape (n, dim) with dim 2 (planar, the paper's runs) or 3.
        r1: monomer radius [cm] (> 0).

    Two monomers whose centres are closer than 2 r1 (compression delta = 2 r1 - |x_i - x_j| >= 0) start in
    contact (Wada et al. 2007 §2.1: a contact forms at delta >= 0).
    """

    positions: jax.Array
    r1: float | jax.Array = 1e-5

    def __check_init__(self):
        p = self.positions
        if is_traced(p):
            return
        shape = np.shape(p)
        if len(shape) != 2 or shape[1] not in (2, 3) or shape[0] < 1:
            raise JaxcoagInputError(f"Aggregate.positions must have shape (n, 2) or (n, 3) [cm]; got {shape}.")
        if not np.all(np.isfinite(np.asarray(p))):
            raise JaxcoagInputError("Aggregate.positions must be finite [cm].")
        r1 = self.r1
        if not is_traced(r1) and not (np.ndim(r1) == 0 and float(r1) > 0 and np.isfinite(float(r1))):
            raise JaxcoagInputError(f"Aggregate.r1 must be a positive monomer radius in cm; got {r1!r}.")

    @property
    def n(self) -> int:
        """Number of monomers."""
        return int(np.shape(self.positions)[0])

    @property
    def dim(self) -> int:
        """2 (planar) or 3."""
        return int(np.shape(self.positions)[1])

    @property
    def centre_of_mass(self) -> jax.Array:
        """Centre of mass [cm] (equal monomers: the mean position)."""
        return jnp.mean(jnp.asarray(self.positions), axis=0)

    @property
    def r_g(self) -> jax.Array:
        """Gyration radius [cm], r_g = sqrt(<|x_i - x_M|^2>) (Wada et al. 2007 eq. 50)."""
        from .analysis import gyration_radius

        return gyration_radius(self.positions)


def monomer(dim: int = 3, r1: float = 1e-5) -> Aggregate:
    """A single monomer of radius ``r1`` [cm] at the origin, in ``dim`` = 2 or 3 dimensions."""
    if dim not in (2, 3):
        raise JaxcoagInputError(f"dim must be 2 or 3; got {dim!r}.")
    return Aggregate(jnp.zeros((1, dim), jnp.float64), r1)
