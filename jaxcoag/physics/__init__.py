"""Pure, vectorised physics in cgs units (no engine knowledge, no classes but state records).

Submodules: :mod:`gas` (disk / cloud state), :mod:`drag` (radii, friction time, Stokes number),
:mod:`drift` (Brownian, radial/azimuthal drift, settling), :mod:`turbulence` (Ormel & Cuzzi
2007), :mod:`collision` (cross-sections, focusing, kernel sigma*dv), :mod:`fragmentation`
(fragmentation probabilities), :mod:`safe` (safe math), and the collision-outcome physics:
:mod:`contact` (JKR contact energies), :mod:`porosity` (enlargement factor psi),
:mod:`outcome` (the shared Outcome container, fragment power laws), one module per paper
recipe: :mod:`ormel07` (thesis ch. 2), :mod:`ormel08` (thesis ch. 4), :mod:`recipes` (thesis
ch. 6 tables, O09), :mod:`dominik_tielens` (DT97 energy thresholds), :mod:`wada07` (Wada et
al. 2007 fitted laws). The engine-facing outcome classes are in :mod:`jaxcoag.outcomes`.

The public functions re-exported here validate their inputs; hot paths use the modules'
unvalidated ``_``-prefixed twins.
"""

from . import (collision, contact, dominik_tielens, drag, drift, fragmentation, gas, ormel07, ormel08, outcome, porosity,
               recipes, safe, turbulence, wada07)
from .collision import cross_section, escape_velocity2, focusing_factor, kernel_sigma_dv
from .drag import (
    compact_radius,
    friction_time,
    friction_time_compact,
    particle_scale_height,
    porous_radius,
    projected_area,
    rainout_stokes,
    stokes_number,
)
from .drift import (
    dv2_azimuthal_drift,
    dv2_brownian,
    dv2_radial_drift,
    dv2_settling,
    dv_brownian,
    v_azimuthal_drift,
    v_radial_drift,
    v_radial_drift_collective,
    v_settling,
)
from .fragmentation import p_frag_linear, p_frag_maxwellian, p_frag_sigmoid, p_frag_step
from .gas import GasState, ch4_disk, local_state, midplane_state, mmsn_hayashi81, molecular_cloud
from .turbulence import (
    dv2_terms_oc07,
    dv2_turbulent_oc07,
    dv_turbulent_oc07,
    dv_turbulent_w84,
    st_star,
    vp2_oc07,
    vpg2_oc07,
)
from .contact import Material
from .dominik_tielens import DTEnergy
from .ormel07 import o07_outcome
from .ormel08 import o08_outcome
from .outcome import Outcome
from .porosity import psi_compaction, psi_hit_and_stick
from .recipes import RecipeTables, o09_outcome
