"""Published reference tables the scenes' set-ups and the paper figures compare with.

Numbers typed from Ormel (2008), PhD thesis, Univ. Groningen ("T-" = thesis), with the errata
noted per table. Nothing here is an input of a simulation: a set-up attaches the row that belongs
to it as ``reference`` and scripts print it beside what they compute.

- :data:`CH2_TABLE_2_2`: T-Tab2.2, properties at rain-out of the eight T-Tab2.1 disk models
  (Ormel, Spaans & Tielens 2007, A&A 461, 215); :func:`ch2_model_name` builds the T-Tab2.1 id.
- :data:`CH4_TABLE_4_1_GAS`, :data:`CH4_A_M_CHONDRULES`, :data:`CH4_TABLE_4_5`: the ch. 4 nebula at
  3 AU (Ormel, Cuzzi & Tielens 2008, ApJ 679, 1588): gas numbers (§4.3, T-Tab4.1), the chondrules'
  mass-weighted mean radius and the final <a>_m per (alpha, rho_X) (T-Tab4.5).
- :data:`CH6_TABLE_6_5_6_6`, :data:`CH6_EPOCHS`: T-Tab6.5 (<a>_m) and T-Tab6.6 (geometric opacity)
  of the molecular-cloud cores (Ormel et al. 2009, A&A 502, 845).
"""

from __future__ import annotations

import math

__all__ = ["CH2_TABLE_2_2", "ch2_model_name", "CH4_TABLE_4_1_GAS", "CH4_A_M_CHONDRULES", "CH4_TABLE_4_5",
           "CH6_TABLE_6_5_6_6", "CH6_EPOCHS"]

# T-Tab2.2 (properties at rain-out; averages over 50 runs): <a> [cm], <m> [g], <psi>, <a>/<a*>,
# t_rain and t_99 [yr] (first rain-out, 99 % of the mass rained out). Erratum 8 applied to the alphas.
CH2_TABLE_2_2 = {
    "R1Ta4-P": dict(R_au=1, alpha=1e-4, porous=True, a=2.1, m=1.4, psi=86.0, a_over_astar=4.4, t_rain=4.7e3, t_99=4.5e4),
    "R1Ta4-C": dict(R_au=1, alpha=1e-4, porous=False, a=2.4e-2, m=1.9e-4, psi=1.0, a_over_astar=1.0, t_rain=2.6e3, t_99=4.4e4),
    "R5Ta4-P": dict(R_au=5, alpha=1e-4, porous=True, a=0.72, m=1.4e-2, psi=110.0, a_over_astar=4.8, t_rain=1.9e4, t_99=2.2e5),
    "R5Ta4-C": dict(R_au=5, alpha=1e-4, porous=False, a=6.7e-3, m=1.2e-6, psi=1.0, a_over_astar=1.0, t_rain=8.1e3, t_99=2.1e5),
    "R1Ta2-P": dict(R_au=1, alpha=1e-2, porous=True, a=7.8, m=1.6e3, psi=3.9, a_over_astar=1.6, t_rain=2.6e2, t_99=4.0e5),
    "R5Ta2-P": dict(R_au=5, alpha=1e-2, porous=True, a=24.0, m=1.7e3, psi=36.0, a_over_astar=3.3, t_rain=1.4e3, t_99=4.5e3),
    "R1Ta6-P": dict(R_au=1, alpha=1e-6, porous=True, a=2.1e-2, m=1.3e-6, psi=87.0, a_over_astar=4.4, t_rain=1.3e3, t_99=2.3e6),
    "R5Ta6-P": dict(R_au=5, alpha=1e-6, porous=True, a=1.3e-3, m=4.6e-10, psi=20.0, a_over_astar=2.7, t_rain=61.0, t_99=1.1e5),
}


def ch2_model_name(R_au, alpha, porous) -> str:
    """Thesis Tab. 2.1 model id, e.g. (1, 1e-4, True) -> 'R1Ta4-P'."""
    return f"R{int(R_au)}Ta{int(round(-math.log10(alpha)))}-{'P' if porous else 'C'}"


# Thesis §4.3 / T-Tab4.1: the Takeuchi & Lin disk at 3 AU (rho_X = 1): rho_g [g cm^-3], c_g [cm s^-1],
# l_mfp [cm], T [K], eta = headwind parameter, t_L [yr] (largest-eddy turnover), t_s [s] (smallest eddy).
CH4_TABLE_4_1_GAS = dict(rho_g=2.4e-11, c_g=7.6e4, l_mfp=82.0, T=162.0, eta=2.7e-3, t_L_yr=0.82, t_s=1.2e4)
# mass-weighted mean chondrule radius <a>_m [cm] of the lognormal size distribution (720 um; thesis §4.4)
CH4_A_M_CHONDRULES = 0.072
# T-Tab4.5: final <a>_m [cm] of the compounds per (alpha, rho_X) at 3 AU
CH4_TABLE_4_5 = {(alpha, rho_x): a_m
                 for rho_x, row in ((10.0, (8.5, 8.0, 4.8, 0.6, 0.1, 0.1)), (1.0, (0.8, 0.7, 0.5, 0.1, 0.1, 0.1)))
                 for alpha, a_m in zip((1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2), row)}

# T-Tab6.5 (<a>_m [cm]) and T-Tab6.6 (kappa = sum(pi a^2)/sum(m) [cm^2 g^-1]) at 1e4, 1e5, 1e6,
# 1e7 yr, t_ff, t_ad; keys (n [cm^-3], material, a0 [cm], variant)
CH6_TABLE_6_5_6_6 = {
    (1e3, "ice", 1e-5, "standard"): ((1.0e-5, 1.0e-5, 1.2e-5, 8.3e-5, 1.2e-5, 8.3e-5), (2.8e4, 2.8e4, 2.7e4, 1.5e4, 2.7e4, 1.5e4)),
    (1e4, "silicate", 1e-5, "standard"): ((1.0e-5, 1.1e-5, 1.4e-5, 1.4e-5, 1.2e-5, 1.4e-5), (2.8e4, 2.8e4, 2.7e4, 2.6e4, 2.7e4, 2.6e4)),
    (1e4, "ice", 1e-5, "standard"): ((1.0e-5, 1.1e-5, 4.6e-5, 8.5e-4, 1.5e-5, 8.5e-4), (2.8e4, 2.8e4, 2.0e4, 2.5e3, 2.6e4, 2.5e3)),
    (1e5, "silicate", 1e-5, "standard"): ((1.0e-5, 1.9e-5, 4.0e-5, 4.0e-5, 2.0e-5, 4.0e-5), (2.8e4, 2.5e4, 2.0e4, 2.0e4, 2.5e4, 2.0e4)),
    (1e5, "silicate", 1e-4, "standard"): ((1.0e-4,) * 6, (2.8e3,) * 6),
    (1e5, "ice", 1e-5, "standard"): ((1.0e-5, 2.2e-5, 6.4e-4, 7.4e-3, 2.3e-5, 3.2e-3), (2.8e4, 2.4e4, 5.1e3, 2.3e3, 2.4e4, 8.4e2)),
    (1e5, "ice", 1e-4, "standard"): ((1.0e-4, 1.1e-4, 2.2e-4, 2.3e-4, 1.1e-4, 2.3e-4), (2.8e3, 2.8e3, 2.4e3, 2.4e3, 2.8e3, 2.4e3)),
    (1e5, "ice", 3e-6, "standard"): ((3.2e-6, 1.1e-5, 1.3e-3, 4.3, 1.2e-5, 2.4e-1), (9.3e4, 7.1e4, 1.4e4, 4.4e2, 6.9e4, 1.7e3)),
    (1e5, "ice", 1e-5, "compact"): ((1.0e-5, 1.5e-5, 1.4e-4, 5.8e-3, 1.6e-5, 1.3e-3), (2.8e4, 2.6e4, 8.0e3, 1.9e3, 2.6e4, 1.0e3)),
    (1e5, "ice", 1e-5, "head-on"): ((1.0e-5, 2.2e-5, 3.6e-4, 7.5e-3, 2.4e-5, 3.1e-3), (2.8e4, 2.4e4, 4.9e3, 3.1e3, 2.4e4, 9.3e2)),
    (1e6, "silicate", 1e-5, "standard"): ((1.4e-5, 1.2e-4, 1.3e-4, 1.3e-4, 4.4e-5, 1.3e-4), (2.7e4, 1.4e4, 1.4e4, 1.4e4, 2.0e4, 1.4e4)),
    (1e6, "ice", 1e-5, "standard"): ((1.4e-5, 2.7e-4, 3.7e-2, 2.0e-2, 4.6e-5, 2.9e-2), (2.7e4, 1.2e4, 6.7e2, 2.2e3, 2.0e4, 1.5e3)),
    (1e7, "ice", 1e-5, "standard"): ((7.9e-5, 3.7e-2, 5.2e-2, 6.1e-2, 8.6e-5, 7.8e-1), (1.7e4, 1.8e3, 1.4e3, 1.7e3, 1.6e4, 6.4e2)),
}
CH6_EPOCHS = ("1e4 yr", "1e5 yr", "1e6 yr", "1e7 yr", "t_ff", "t_ad")
