"""Energy-threshold fragmentation of Dominik & Tielens (1997) and Wada et al. (2007) (cgs).

Fragmentation models map a collision to the small-fragment part (f_pwl, q, m_lo, m_hi) of an
:class:`~jaxcoag.physics.outcome.Outcome`: :class:`NoFragmentation` and :class:`DTEnergy`
(erosion from 3 n_c E_break, catastrophic disruption at 10 n_c E_break, all mass in fragments
at 30 n_c E_break), plus the characteristic energies :func:`dt_thresholds`. Used by the thesis
ch. 2 recipe (:func:`jaxcoag.physics.ormel07.o07_outcome`, ``frag_model=``).

References: Dominik & Tielens 1997 (ApJ 480, 647); Wada et al. 2007 (ApJ 661, 320) §5.5, Tab. 1;
Ormel 2008 thesis Tabs. 1.1, 6.1.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp

from .safe import safe_log

__all__ = ["AbstractFragModel", "NoFragmentation", "DTEnergy", "dt_fragment_fraction", "dt_thresholds"]


def _soft_ramp(z, lo, hi, width: float):
    """clip(z, lo, hi) - lo; for width > 0 (static, units of z) the softplus-smoothed version."""
    if width == 0.0:
        return jnp.clip(z, lo, hi) - lo
    return width * (jnp.logaddexp(0.0, (z - lo) / width) - jnp.logaddexp(0.0, (z - hi) / width))


class AbstractFragModel(eqx.Module):
    """Fragmentation model: maps a collision to (f_pwl, q, m_lo, m_hi) of the small fragments.

    ``__call__(m1, m2, energy, n_tot, e_break, m0, width)`` with masses [g], energy [erg],
    n_tot = (m1+m2)/m0 [-], e_break [erg] (per contact), m0 [g], width static.

    References: Ormel 2008 thesis §5.3.4, §6.3, Tab. 1.1; Wada et al. 2007 §5.5.
    """

    @abc.abstractmethod
    def __call__(self, m1, m2, energy, n_tot, e_break, m0, width=0.0):
        """Return (f_pwl, q, m_lo, m_hi) arrays of the broadcast pair shape."""


class NoFragmentation(AbstractFragModel):
    """No fragmentation: f_pwl = 0 (fragment range degenerate at m0).

    References: Ormel 2008 thesis §2.2.3 (fragmentation 'avoided by choosing moderate alpha').
    """

    def __call__(self, m1, m2, energy, n_tot, e_break, m0, width=0.0):
        z = jnp.zeros(jnp.broadcast_shapes(jnp.shape(m1), jnp.shape(m2), jnp.shape(energy)))
        return z, z - 2.0, z + m0, z + m0


def dt_fragment_fraction(energy, n_c, e_break, *, eps_ero=3.0, eps_cat=10.0, width=0.0):
    """Mass fraction in small fragments of the Dominik & Tielens / Wada threshold model.

    With e = E/(n_c E_break): 0 below eps_ero (no mass loss); rises linearly in ln E to 0.5
    at eps_cat (Wada's catastrophic-disruption definition N_large/N_tot = 0.5); then linearly
    in ln E to 1 at 3 eps_cat; 1 above (continuous) [CHOICE: a parametric
    bridge between the Dominik & Tielens (1997) / Wada et al. (2007) thresholds].

    Arguments:
        energy: collision energy [erg] (>= 0).
        n_c: number of contacts [-] (N in thesis ch. 2, n_k = N - 2 for Wada's BCCA pairs).
        e_break: breaking energy per contact [erg] (> 0).
        eps_ero, eps_cat: thresholds in units of n_c E_break (3 and 10).
        width: static smoothing in e-folds of energy (0 = hard kinks).

    Returns:
        f_pwl in [0, 1].

    References: Dominik & Tielens 1997; Wada et al. 2007 §5.5, Tab. 1; Ormel 2008 thesis
    Tab. 1.1, 6.1; Wada et al. 2007 §5.5.
    """
    le = safe_log(energy, fill=-1e3) - jnp.log(n_c * e_break)
    l_ero = jnp.log(eps_ero)
    l_cat = jnp.log(eps_cat)
    l_all = l_cat + jnp.log(3.0)
    t1 = _soft_ramp(le, l_ero, l_cat, width) / (l_cat - l_ero)
    t2 = _soft_ramp(le, l_cat, l_all, width) / (l_all - l_cat)
    return 0.5 * t1 + 0.5 * t2


def dt_thresholds(n_c, e_roll, e_break, *, restr_factor=5.0, eps_ero=3.0, eps_cat=10.0):
    """Characteristic collision energies of the Dominik & Tielens recipe [erg].

    Arguments:
        n_c: number of contacts [-] (N, or n_k = N - 2 for Wada's BCCA pairs).
        e_roll, e_break: rolling and breaking energies per contact [erg].
        restr_factor: first visible restructuring in E_roll (5; thesis ch. 2 uses 1).
        eps_ero, eps_cat: erosion onset and catastrophic disruption in n_c E_break (3, 10).

    Returns:
        dict: ``restructuring`` = restr_factor E_roll, ``max_compression`` = n_c E_roll,
        ``erosion`` = eps_ero n_c E_break, ``catastrophic`` = eps_cat n_c E_break.

    References: Dominik & Tielens 1997; Wada et al. 2007 Tab. 1, §5.5; Ormel 2008 thesis
    Tabs. 1.1, 6.1.
    """
    return dict(restructuring=restr_factor * e_roll, max_compression=n_c * e_roll,
                erosion=eps_ero * n_c * e_break, catastrophic=eps_cat * n_c * e_break)


class DTEnergy(AbstractFragModel):
    """Energy-threshold fragmentation (Dominik & Tielens 1997; Wada et al. 2007).

    Erosion from eps_ero n_c E_break, catastrophic disruption (half the mass in fragments)
    at eps_cat n_c E_break, all mass in fragments at 3 eps_cat (see
    :func:`dt_fragment_fraction`). Fragments: dn/dm ∝ m^q_frag on [m0, m_hi_frac M_tot].

    Fields: eps_ero (3), eps_cat (10), q_frag (-2.0), m_hi_frac (0.25) float leaves;
    contacts: static, "N" (n_c = N, thesis ch. 2) or "wada" (n_k = N - 2).

    References: Wada et al. 2007 §5.5; Ormel 2008 thesis Tab. 1.1.
    """

    eps_ero: jax.Array = eqx.field(default=3.0, converter=jnp.asarray)
    eps_cat: jax.Array = eqx.field(default=10.0, converter=jnp.asarray)
    q_frag: jax.Array = eqx.field(default=-2.0, converter=jnp.asarray)
    m_hi_frac: jax.Array = eqx.field(default=0.25, converter=jnp.asarray)
    contacts: str = eqx.field(static=True, default="N")

    def __check_init__(self):
        if self.contacts not in ("N", "wada"):
            raise ValueError(f"DTEnergy(contacts={self.contacts!r}): use 'N' (thesis ch. 2) or 'wada' (N - 2)")

    def __call__(self, m1, m2, energy, n_tot, e_break, m0, width=0.0):
        n_c = n_tot if self.contacts == "N" else jnp.maximum(n_tot - 2.0, 1.0)
        f = dt_fragment_fraction(energy, n_c, e_break, eps_ero=self.eps_ero, eps_cat=self.eps_cat,
                                 width=width)
        m_tot = m1 + m2
        m_hi = jnp.maximum(self.m_hi_frac * m_tot, m0)
        return f, jnp.broadcast_to(self.q_frag, f.shape), jnp.broadcast_to(m0, f.shape), m_hi
