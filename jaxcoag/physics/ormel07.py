"""Thesis ch. 2 collision recipe (O07: Ormel, Spaans & Tielens 2007) as a shared :class:`Outcome` (cgs).

:func:`o07_outcome`: hit-and-stick growth of the enlargement factor psi below the
restructuring energy (eq. 2.15 + psi_add), compaction above it (eq. 2.17), optionally with
energy-threshold fragmentation (:class:`~jaxcoag.physics.dominik_tielens.DTEnergy`) and a bounce
hook (:class:`BounceWhenCompact`, [CHOICE]). Hard switches (``width=0``, static) reproduce the
sources; ``width > 0`` replaces every threshold by a logistic in ln(E/E_thr) so gradients with
respect to material constants exist.

References: Ormel, Spaans & Tielens 2007 (A&A 461, 215); Ormel 2008 thesis §2.2.3, eqs. 2.9,
2.13-2.19, Tab. 1.1; errata 5, 6, 20 in docs/design_notes.md.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .contact import Material
from .dominik_tielens import AbstractFragModel, NoFragmentation
from .outcome import Outcome, pair_inputs, bounce_outcome, mix_outcomes
from .porosity import DELTA_CCA, _psi_o07, _reduced_mass, smooth_step
from .safe import safe_log

__all__ = ["o07_outcome", "BounceWhenCompact"]


class BounceWhenCompact(eqx.Module):
    """[CHOICE, not from the sources] bounce when both partners are compact (psi <= psi_max)
    and E > N E_roll (T-Tab1.1 links compaction + bouncing to E ≈ N_c E_roll). Off by default.

    Fields: psi_max [-] (float leaf; e.g. 1/0.33).
    References: Ormel 2008 thesis Tab. 1.1, §6.6.1.
    """

    psi_max: jax.Array = eqx.field(default=1.0 / 0.33, converter=jnp.asarray)

    def weight(self, psi1, psi2, energy, n_tot, e_roll, width=0.0):
        """Bounce weight in [0, 1]."""
        x_e = safe_log(energy, fill=-1e3) - jnp.log(n_tot * e_roll)
        lp = jnp.log(self.psi_max)
        return (smooth_step(x_e, width) * smooth_step(lp - jnp.log(psi1), width)
                * smooth_step(lp - jnp.log(psi2), width))


def o07_outcome(m1, psi1, m2, psi2, dv, mat: Material, *, delta=DELTA_CCA, B=1.0,
                mF_over_m0=10.0, restr_factor=1.0, psi_min=1.0,
                frag_model: AbstractFragModel | None = None,
                bounce_model: BounceWhenCompact | None = None, width: float = 0.0,
                validate: bool = True) -> Outcome:
    """Thesis ch. 2 collision recipe (O07), optionally with threshold fragmentation / bouncing.

    E = (1/2) m_mu dv^2; below restr_factor E_roll: hit-and-stick psi (eq. 2.15 + psi_add);
    above: compaction (eq. 2.17, f_C = clip(E/(N E_roll), 0, 1)). A fragmentation model adds
    a power-law fragment fraction f_pwl (e.g. :class:`DTEnergy`: erosion at 3 N E_br,
    catastrophic at 10 N E_br, the DT recipe when restr_factor = 5); the large remnant keeps
    psi from the recipe. With ``bounce_model`` a bounce (p_two, split = m1/M) is mixed in.

    Arguments:
        m1, m2: masses [g] (> 0); psi1, psi2: enlargement factors [-] (> 0); dv: relative
            velocity [cm s^-1] (>= 0). Broadcast against each other (e.g. a (n, n) pair grid).
        mat: :class:`Material` (m0, E_roll, E_break in its conventions, monomer pair R = a0/2).
        delta, B, mF_over_m0: hit-and-stick parameters (0.95, 1.0, 10).
        restr_factor: restructuring threshold in E_roll (1 in ch. 2, 5 = DT).
        psi_min: compaction floor (1 = none).
        frag_model: None (no fragmentation) or an :class:`AbstractFragModel`.
        bounce_model: None or :class:`BounceWhenCompact` ([CHOICE], off by default).
        width: static; 0 = hard switches (sources), > 0 = logistic regime switches (e-folds).
        validate: static; False skips input checks (engine hot loops).

    Returns:
        :class:`Outcome`; aux holds ``energy`` [erg], ``w_compact`` (compaction weight),
        ``w_bounce``.

    References: Ormel 2008 thesis eqs. 2.9, 2.13-2.19 and fn. 7, Tab. 1.1; Dominik &
    Tielens 1997; Wada et al. 2007 §5.5; errata 5, 6, 20 in docs/design_notes.md.
    """
    m1, psi1, m2, psi2, dv = pair_inputs(m1, psi1, m2, psi2, dv, validate)
    # recipe constants as traced leaves: no recompilation when their values change
    delta, B, mF_over_m0, restr_factor, psi_min = (
        jnp.asarray(x, dtype=jnp.result_type(float)) for x in (delta, B, mF_over_m0, restr_factor, psi_min))
    return _o07_jit(m1, psi1, m2, psi2, dv, mat, delta, B, mF_over_m0, restr_factor, psi_min,
                    frag_model, bounce_model, width)


def _o07_impl(m1, psi1, m2, psi2, dv, mat, delta, B, mF_over_m0, restr_factor, psi_min,
              frag_model, bounce_model, width):
    """Unvalidated O07 outcome (see :func:`o07_outcome`); compiled once per shape/config."""
    m0 = mat.m0
    e_roll = mat.e_roll()
    e_br = mat.e_break()
    energy = 0.5 * _reduced_mass(m1, m2) * dv**2
    psi = _psi_o07(m1, psi1, m2, psi2, energy, e_roll, m0, restr_factor, delta, B, mF_over_m0,
                   psi_min, width)
    n_tot = m1 / m0 + m2 / m0
    fm = NoFragmentation() if frag_model is None else frag_model
    f_pwl, q, m_lo, m_hi = fm(m1, m2, energy, n_tot, e_br, m0, width)
    w_c = smooth_step(safe_log(energy, fill=-1e3) - jnp.log(restr_factor * e_roll), width)
    out = Outcome.build(f_pwl=f_pwl, q=q, m_lo=m_lo, m_hi=m_hi, psi_one=psi,
                        aux=dict(energy=energy, w_compact=w_c, w_bounce=jnp.zeros_like(energy)))
    if bounce_model is None:
        return out
    wb = bounce_model.weight(psi1, psi2, energy, n_tot, e_roll, width)
    bo = bounce_outcome(m1, psi1, m2, psi2, m0)
    mixed = mix_outcomes(wb, out, bo, m1, m2)
    aux = dict(energy=out.aux["energy"], w_compact=out.aux["w_compact"], w_bounce=jnp.broadcast_to(wb, out.eff.shape))
    return eqx.tree_at(lambda o: o.aux, mixed, aux)


_o07_jit = eqx.filter_jit(_o07_impl)
