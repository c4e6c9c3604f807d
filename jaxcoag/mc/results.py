"""Result container of the Monte Carlo engine with binned and moment diagnostics.

References: spec/montecarlo.md §3.8 (snapshot payload), §4.1 (densities from a simulation:
n_b = Σ_{i∈b} g_i/V, ρ_b = Σ_{i∈b} g_i m_i/V), §3.1 (log-moments).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .state import status_names

__all__ = ["MCResult"]

LN2 = 0.6931471805599453


class MCResult(eqx.Module):
    """Snapshots of one Monte Carlo run (add a leading batch axis under ``jax.vmap``).

    Fields (T = number of output times, S = capacity, P = structural parameters):
        t: (T,) output times [s].
        m, logm: (T, S) species particle masses [g] and their natural logs.
        psi: (T, S, P) structural parameters.
        w, z: (T, S) group number (float) and zoom number (int); multiplicity g = w 2^z.
        valid: (T, S) which slots hold a species.
        V, logV: (T,) simulated volume [cm^3] and its log.
        M_tot: (T,) total simulated mass [g].
        n_events_snap: (T,) events executed before each snapshot.
        status: int bit flags (``jaxcoag.mc.STATUS``); n_events, n_dup, n_merge: totals.

    References: Ormel (2008) thesis Table 5.4; spec/montecarlo.md §3.8.
    """

    t: jax.Array
    m: jax.Array
    logm: jax.Array
    psi: jax.Array
    w: jax.Array
    z: jax.Array
    valid: jax.Array
    V: jax.Array
    logV: jax.Array
    M_tot: jax.Array
    n_events_snap: jax.Array
    status: jax.Array
    n_events: jax.Array
    n_dup: jax.Array
    n_merge: jax.Array

    @property
    def log_g(self):
        """(T, S) ln multiplicity ln g = ln w + z ln 2 (−inf on invalid slots)."""
        pos = self.valid & (self.w > 0)
        return jnp.where(pos, jnp.log(jnp.where(pos, self.w, 1.0)) + self.z * LN2, -jnp.inf)

    @property
    def g(self):
        """(T, S) multiplicity g = w 2^z (number of physical particles per species; may be inf
        beyond 1.8e308, use ``log_g``)."""
        return jnp.where(self.valid, jnp.ldexp(self.w, self.z), 0.0)

    @property
    def n_species(self):
        """(T,) number of valid species Ns."""
        return jnp.sum(self.valid, axis=-1)

    @property
    def n_groups(self):
        """(T,) number of groups Ng = Σ w."""
        return jnp.sum(jnp.where(self.valid, self.w, 0.0), axis=-1)

    def status_names(self):
        """Flag names set in ``status`` (only for a single, concrete run)."""
        return status_names(self.status)

    def log_moments(self, p):
        """(T,) ln M_p = ln(Σ_i g_i m_i^p / V) [ln(g^p cm^-3)] via logsumexp (overflow-free).

        References: spec/montecarlo.md §3.1 (log-moments), §4.5 (Table 5.1 moments).
        """
        x = jnp.where(self.valid, self.log_g + p * self.logm, -jnp.inf)
        return jax.nn.logsumexp(x, axis=-1) - self.logV

    def moments(self, p):
        """(T,) moments M_p = Σ_i g_i m_i^p / V [g^p cm^-3] (M0 number, M1 mass density).

        References: Ormel (2008) eq. (5.4) and Table 5.1; spec/montecarlo.md §4.5.
        """
        return jnp.exp(self.log_moments(p))

    def _per_bin(self, edges, p):
        edges = jnp.asarray(edges, jnp.float64)
        le = jnp.log(edges)
        nb = edges.shape[-1] - 1
        b = jnp.searchsorted(le, self.logm, side="right") - 1
        inside = self.valid & (b >= 0) & (b < nb)
        bc = jnp.clip(b, 0, nb - 1)
        val = jnp.where(inside, jnp.exp(self.log_g + p * self.logm - self.logV[..., None]), 0.0)
        onehot = (bc[..., None] == jnp.arange(nb).reshape((1,) * bc.ndim + (nb,))) & inside[..., None]
        return jnp.sum(jnp.where(onehot, val[..., None], 0.0), axis=-2)

    def mass_per_bin(self, edges):
        """(T, nbins) mass density per mass bin [g cm^-3]: Σ_{edges[b] ≤ m_i < edges[b+1]} g_i m_i / V.

        Arguments: edges: (nbins+1,) increasing bin edges [g] (e.g. 2.0**arange(...)).
        References: spec/montecarlo.md §4.1, §4.6 (factor-2 bins).
        """
        return self._per_bin(edges, 1.0)

    def number_per_bin(self, edges):
        """(T, nbins) number density per mass bin [cm^-3]: Σ_{i in bin} g_i / V.

        References: spec/montecarlo.md §4.1.
        """
        return self._per_bin(edges, 0.0)

    def largest_mass(self):
        """(T,) mass of the largest particle M_L1 [g].

        References: spec/montecarlo.md §0 (M_L1), §4.4.
        """
        return jnp.exp(jnp.max(jnp.where(self.valid, self.logm, -jnp.inf), axis=-1))
