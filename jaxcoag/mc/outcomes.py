"""Collision-outcome modules for the grouped Monte Carlo engine.

An outcome is an ``equinox.Module`` called once per (group) event with the two colliding
species and the number ``n_c`` of j-particles that hit *one* i-particle (``n_c`` may be as
large as 2^500, so it is passed both linearly and as a log). It returns a fixed-size set of
``n_products`` products, each with a mass, structural parameters and a *count per
i-particle*; the engine multiplies the count by 2^{z_i} (2^{z-1} for an in-group collapse)
to obtain the product multiplicity. New physics (porosity, bouncing, erosion) plugs in by
subclassing :class:`AbstractOutcome`; the event loop never changes.

References: Ormel (2008) thesis §5.2.2 and App. 5.B step 5 (collision module), §5.3.4
(catastrophic fragmentation into monomers above m_frag).
"""

from __future__ import annotations

import abc
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._validate import check

__all__ = ["Products", "AbstractOutcome", "PerfectSticking", "CatastrophicFragmentation"]


class Products(NamedTuple):
    """Fixed-size list of collision products (leading axis ``n_products``).

    Fields:
        m: product mass [g] (may be ``inf`` when it exceeds float64; ``logm`` is then used).
        logm: natural log of the product mass [ln g].
        psi: structural parameters, shape (n_products, n_struct).
        count: number of such products per i-particle (>= 0; float64).
        valid: whether the entry is a real product.
    """

    m: jax.Array
    logm: jax.Array
    psi: jax.Array
    count: jax.Array
    valid: jax.Array


class AbstractOutcome(eqx.Module):
    """Interface of a collision module (Ormel 2008 thesis App. 5.B step 5, ch. 6 §6.4).

    ``__call__(m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key) -> Products``:
    the i-particle (mass ``m_i`` [g], log mass, structural vector ``psi_i`` of shape
    (n_struct,)) accretes ``n_c`` j-particles sequentially (closed form for huge ``n_c``).
    For an in-group collapse or a same-species pair the engine passes i = j and n_c = 1.
    Mass must be conserved: ``sum(count * m) == m_i + n_c m_j``.

    Class attribute ``n_products`` (static) is the maximum number of distinct products.
    """

    n_products: ClassVar[int] = 1

    @abc.abstractmethod
    def __call__(self, m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key):
        """Products of one group event (see class docstring)."""


def _stick(m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc):
    m_new = m_i + n_c * m_j
    logm_new = jnp.logaddexp(logm_i, log_nc + logm_j)
    logm_new = jnp.where(jnp.isfinite(m_new) & (m_new > 0), jnp.log(jnp.where(m_new > 0, m_new, 1.0)), logm_new)
    p_i = jnp.exp(logm_i - logm_new)
    p_j = jnp.exp(log_nc + logm_j - logm_new)
    psi_new = p_i * psi_i + p_j * psi_j
    return m_new, logm_new, psi_new


class PerfectSticking(AbstractOutcome):
    """Perfect sticking: one product of mass m_i + n_c m_j, structure mass-weighted.

    Returns:
        ``Products`` with one entry (count 1 per i-particle).

    References: Ormel (2008) thesis §5.2.2 (sequential accretion of n_c j-particles,
    m_new = m_i + n_c m_j).
    """

    n_products: ClassVar[int] = 1

    def __call__(self, m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key):
        """Sticking product of the i-particle with n_c j-particles (masses in g)."""
        m_new, logm_new, psi_new = _stick(m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc)
        return Products(m=m_new[None], logm=logm_new[None], psi=psi_new[None, :],
                        count=jnp.ones((1,)), valid=jnp.ones((1,), bool))


class CatastrophicFragmentation(AbstractOutcome):
    """Sticking, but a product heavier than ``m_frag`` shatters into monomers of ``m_mono``.

    Arguments:
        m_frag: fragmentation threshold mass [g].
        m_mono: monomer mass [g] (the fragments; count = m_new / m_mono per i-particle).

    The monomers keep the mass-weighted structure of the would-be product. Mass is
    conserved exactly (count is real).

    References: Ormel (2008) thesis §5.3.4 ("particles above m_frag are catastrophically
    fragmented into monomers"), Fig. 5.8/5.9.
    """

    m_frag: jax.Array
    m_mono: jax.Array
    n_products: ClassVar[int] = 1

    def __init__(self, m_frag, m_mono=1.0):
        self.m_frag = check(m_frag, "m_frag", positive=True, hint="give the fragmentation mass threshold in g")
        self.m_mono = check(m_mono, "m_mono", positive=True, hint="give the monomer mass in g")

    def __call__(self, m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key):
        """Sticking product, or m_new/m_mono monomers when m_new > m_frag (masses in g)."""
        m_new, logm_new, psi_new = _stick(m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc)
        frag = logm_new > jnp.log(self.m_frag)
        log_mono = jnp.log(self.m_mono)
        m_out = jnp.where(frag, self.m_mono, m_new)
        logm_out = jnp.where(frag, log_mono, logm_new)
        count = jnp.where(frag, jnp.exp(logm_new - log_mono), 1.0)
        count = jnp.where(frag & jnp.isfinite(m_new), m_new / self.m_mono, count)
        return Products(m=m_out[None], logm=logm_out[None], psi=psi_new[None, :],
                        count=count[None], valid=jnp.ones((1,), bool))
