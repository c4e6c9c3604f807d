"""Binned-engine set-ups of the seeds' settings: :func:`setup` (by name, see :data:`SETUPS`) returns a
:class:`Setup` bundling scene, gas, material, kernel, collision outcome, grid, initial state, output
times, the numbers used and the published ones to compare with.

Names: ``ch2_compact_1au``/``_5au`` (thesis ch. 2 compact models), ``ch4_nebula`` (chondrules + dust at
3 AU, thesis ch. 4), ``ch6_cloud`` (molecular-cloud core, thesis ch. 6), ``ch5_constant``/``_sum``/
``_product`` (thesis ch. 5 test kernels, T-Tab5.1). References: Ormel (2008) thesis chs. 2, 4, 5, 6.
"""

from __future__ import annotations

import equinox as _eqx

from .._validate import JaxcoagInputError as _JIE
from . import tables as _tables
from .mc_setups import ch2_setup
from .presets import molecular_cloud, nebula_ch4

__all__ = ["Setup", "setup", "SETUPS"]


# A Scene holds structure only; a Setup bundles everything one run of a seed's setting needs
# (scene, gas, material, kernel, outcome, grid, initial state, output times, the numbers used and
# the published ones to compare with). ``setup(name, **overrides)``.
class Setup(_eqx.Module):
    """A complete binned-engine setting, run with the one verb::

        s = setup("ch6_cloud")
        res = jaxcoag.evolve(s.kernel, jaxcoag.Binned(s.grid), s.n0, s.t_out, outcome=s.outcome)

    Attributes:
        name: setup name. kernel: collision kernel [cm^3 s^-1]. grid: MassGrid. n0: number
        density per bin [cm^-3] (numpy) at t = 0. t_out: output times [s] (numpy, t_out[0] = 0).
        scene: the Scene (None for the ch. 5 analytic test kernels). gas: GasState or None.
        material: contact.Material or None. outcome: collision outcome (:mod:`jaxcoag.outcomes`)
        or None (perfect sticking). params: dict of the numbers used and derived [cgs; times also
        in yr]. reference: dict of published numbers (empty if none; the tables are in
        :mod:`jaxcoag.scenes.tables`). notes: what differs from the source.
    """

    name: str = _eqx.field(static=True)
    kernel: object
    grid: object = _eqx.field(static=True)
    n0: object
    t_out: object
    scene: object = None
    gas: object = None
    material: object = None
    outcome: object = None
    params: dict = _eqx.field(default_factory=dict)
    reference: dict = _eqx.field(default_factory=dict)
    notes: str = _eqx.field(static=True, default="")

    @property
    def effect_names(self) -> tuple:
        """Names of the velocity effects the setting simulates (() for analytic kernels)."""
        return () if self.scene is None else self.scene.effect_names


_YR = 3.15576e7


def _log_grid(m_first, decades, bins_per_decade):
    """Log grid whose first bin centre is m_first [g]."""
    from ..binned.grid import MassGrid
    lo = float(m_first) * 10.0 ** (-0.5 / bins_per_decade)
    return MassGrid.log(lo, lo * 10.0 ** decades, bins_per_decade)


def _setup_ch6(n=1e5, material="ice", T=10.0, a0=1e-5, R_gd=100.0, bins_per_decade=2, decades=16,
               outcome="o09", width=0.3, method="exact", t_end_yr=1e7):
    """Thesis ch. 6 molecular-cloud core (thesis §6.2, eqs. 6.1-6.16; Ormel et al. 2009):
    homogeneous Jeans core of density n [cm^-3] (1e3..1e7) at T [K]; ice-coated (gamma = 370,
    E* = 3.7e10) or bare silicate (gamma = 25, E* = 2.8e11) monomers of radius a0 (rho0 = 2.65,
    xi = 2e-7, A_br = 2.8e3); R_gd = 100; Brownian + OC07 turbulence with v_L = c_g,
    t_L = L_J/c_g. Compact particles (psi = 1: the thesis's 'compact' run 9 is the like-for-like
    row). Outcome: "o09" (tabulated recipe with the SURROGATE tables unless CDS tables are
    loaded; smooth regime switches of ``width``), "o07_dt" (DT thresholds, restr_factor 5) or
    "sticking". Outputs at 1e4..1e7 yr, t_ff and t_ad = 3.7e6 yr (n/1e5)^-1/2 (T-Tab6.5)."""
    import numpy as np

    from ..binned.grid import monodisperse
    from .. import outcomes as _oc
    from ..physics import gas as _gas
    from ..physics.contact import Material

    if material not in ("ice", "silicate"):
        raise _JIE(f"ch6_cloud: material must be 'ice' (ice-coated silicate) or 'silicate'; got {material!r}")
    if not (float(n) > 0):
        raise _JIE(f"ch6_cloud: n must be a gas number density > 0 cm^-3 (thesis 1e3..1e7); got {n!r}")
    if outcome not in ("o09", "o07_dt", "sticking"):
        raise _JIE(f"ch6_cloud: outcome must be 'o09', 'o07_dt' or 'sticking'; got {outcome!r}")
    mat = Material.ch6_ice(a0) if material == "ice" else Material.ch6_silicate(a0)
    gas = _gas.molecular_cloud(n, T)
    scene = molecular_cloud(method)
    kernel = scene.kernel(gas, material=mat)
    m0 = float(mat.m0)
    rho_g = float(gas.rho_g)
    rho_d = rho_g / float(R_gd)
    grid = _log_grid(m0, decades, bins_per_decade)
    n0 = monodisperse(grid, m0, rho_d)
    jq = _gas.jeans_quantities(gas)
    t_ff = float(jq["t_ff"])
    t_ad = 3.7e6 * _YR * (float(n) / 1e5) ** -0.5
    epochs = np.array([1e4 * _YR, 1e5 * _YR, 1e6 * _YR, 1e7 * _YR, t_ff, t_ad])
    t_out = np.unique(np.concatenate([[0.0], epochs[epochs <= t_end_yr * _YR * (1 + 1e-12)], [t_end_yr * _YR]]))
    if outcome == "o09":
        oc = _oc.RecipeOutcome(_oc.O09Recipe(), mat, width=width)
    elif outcome == "o07_dt":
        from ..physics.dominik_tielens import DTEnergy

        oc = _oc.RecipeOutcome(_oc.O07Recipe(frag_model=DTEnergy(), restr_factor=5.0), mat, width=width)
    else:
        oc = None
    # monomer numbers of §11.4 (eqs. 6.13-6.16)
    rho0, a0f = float(mat.rho_s), float(mat.a0)
    c_g = float(gas.c_g)
    tau0 = rho0 * a0f / (c_g * rho_g)                                  # eq. 6.13
    St_s = tau0 / float(gas.t_s)
    dv0 = 3.0 ** 0.5 * float(gas.v_s) * St_s ** 0.5                    # eq. 6.15
    t_coll0 = rho0 * a0f * float(R_gd) / (3.0 * rho_g * dv0)           # eq. 6.16
    e_roll, e_br = float(mat.e_roll()), float(mat.e_break())
    params = dict(n=float(n), T=float(T), material=material, a0=a0f, rho0=rho0, R_gd=float(R_gd), rho_g=rho_g,
                  rho_d=rho_d, m0=m0, f_monomer0=rho_d / m0, c_g=c_g, Re=float(gas.Re), t_s=float(gas.t_s),
                  v_s=float(gas.v_s), tau0=tau0, tau0_yr=tau0 / _YR, St_s=St_s, dv0=dv0, t_coll0=t_coll0,
                  t_coll0_yr=t_coll0 / _YR, t_ff=t_ff, t_ad=t_ad, e_roll=e_roll, e_break=e_br,
                  kappa0=3.0 / (4.0 * rho0 * a0f), outcome=outcome, width=float(width))
    variant = "compact"
    ref = _tables.CH6_TABLE_6_5_6_6.get((float(n), material, a0f, variant)) or _tables.CH6_TABLE_6_5_6_6.get(
        (float(n), material, a0f, "standard"))
    reference = {}
    if ref is not None:
        row = "compact" if (float(n), material, a0f, "compact") in _tables.CH6_TABLE_6_5_6_6 else "standard (porous)"
        reference = dict(row=row, epochs=_tables.CH6_EPOCHS, a_m=ref[0], kappa=ref[1],
                         source="Ormel 2008 thesis Tabs. 6.5, 6.6")
    notes = ("compact particles (psi = 1); " + ("O09 recipe with SURROGATE tables (thesis prints only Tabs. 6.7/6.9) "
             if outcome == "o09" else "") + "homogeneous static core, no collapse (as the thesis).")
    return Setup(name="ch6_cloud", kernel=kernel, grid=grid, n0=n0, t_out=t_out, scene=scene, gas=gas, material=mat,
                 outcome=oc, params=params, reference=reference, notes=notes)


def _setup_ch4(alpha=1e-4, rho_X=1.0, R_au=3.0, R_gc=100.0, R_cd=1.0, a_dust=1e-3, a_chondrule=3e-2,
               sigma_chondrule=0.5, bins_per_decade=4, decades=12, t_end_yr=1e4, method="exact"):
    """Thesis ch. 4 nebula with chondrules and dust (thesis §4.4; Ormel, Cuzzi & Tielens 2008): Takeuchi & Lin
    disk (T-Tab4.1) at R_au = 3 AU with gas enhancement rho_X; Brownian + OC07 turbulence +
    radial drift (eqs. 4.4, 4.8, ch. 3); chondrules lognormal in radius (median a_chondrule =
    300 um, width sigma = 0.5: <a>_m = 720 um) with density rho_g/R_gc, dust of radius a_dust =
    10 um with rho_chondrules/R_cd; ch4-silicate material (rho = 3). The binned engine treats
    compounds as compact spheres that stick (the O08 stick/bounce rule needs the compound
    phases: use the MC engine); this bundle gives the gas/velocity setting and initial state."""
    import numpy as np

    from .. import constants as _C
    from ..physics import gas as _gas
    from ..physics.contact import Material

    for nm, v in (("alpha", alpha), ("rho_X", rho_X), ("R_au", R_au), ("R_gc", R_gc), ("R_cd", R_cd),
                  ("a_dust", a_dust), ("a_chondrule", a_chondrule), ("sigma_chondrule", sigma_chondrule)):
        if not (float(v) > 0):
            raise _JIE(f"ch4_nebula: {nm} must be > 0 (got {v!r})")
    mat = Material.ch4_silicate()
    gas = _gas.ch4_disk(float(R_au) * _C.AU, alpha, rho_X=rho_X)
    scene = nebula_ch4(method)
    kernel = scene.kernel(gas, material=mat)
    rho_s = float(mat.rho_s)
    mass = lambda a: 4.0 / 3.0 * np.pi * rho_s * a ** 3
    m_dust = mass(a_dust)
    grid = _log_grid(m_dust, decades, bins_per_decade)  # 1.3e-8 g .. 1.3e4 g (a ~ 10 cm)
    rho_g = float(gas.rho_g)
    rho_c = rho_g / float(R_gc)
    rho_dd = rho_c / float(R_cd)
    # chondrule mass per bin: n(a) ∝ lognormal(ln a; ln a_ch, sigma); mass weight ∝ a^3 n(a)
    le = np.asarray(grid.log_edges)
    la_edges = (le - np.log(4.0 / 3.0 * np.pi * rho_s)) / 3.0
    from math import erf, sqrt
    mu3 = np.log(a_chondrule) + 3.0 * sigma_chondrule ** 2   # mass-weighted lognormal shifts by 3 sigma^2
    cdf = np.array([0.5 * (1.0 + erf((x - mu3) / (sqrt(2.0) * sigma_chondrule))) for x in la_edges])
    w = np.diff(cdf)
    w = w / w.sum()
    n0 = rho_c * w / grid.centers
    kd = int(np.searchsorted(le, np.log(m_dust), side="right") - 1)
    n0[kd] += rho_dd / grid.centers[kd]
    t_out = np.concatenate([[0.0], np.logspace(0, np.log10(t_end_yr), 9) * _YR])
    a_m0 = float(a_chondrule * np.exp(3.5 * sigma_chondrule ** 2))
    params = dict(alpha=float(alpha), rho_X=float(rho_X), R_au=float(R_au), rho_g=rho_g, T=float(gas.T),
                  c_g=float(gas.c_g), l_mfp=float(gas.l_mfp), eta=float(gas.eta), t_L=float(gas.t_L),
                  t_L_yr=float(gas.t_L) / _YR, t_s=float(gas.t_s), rho_chondrules=rho_c, rho_dust=rho_dd,
                  m_dust=m_dust, a_m_chondrules=a_m0)
    reference = dict(gas=dict(_tables.CH4_TABLE_4_1_GAS), a_m_chondrules=_tables.CH4_A_M_CHONDRULES,
                     source="Ormel 2008 thesis §4.3, Tab. 4.1, Tab. 4.5")
    a_m_final = _tables.CH4_TABLE_4_5.get((float(alpha), float(rho_X)))
    if a_m_final is not None and float(R_au) == 3.0:
        reference["a_m_final"] = a_m_final
    notes = "compact sticking spheres (no O08 stick/bounce, no porous dust phase) in the binned engine."
    return Setup(name="ch4_nebula", kernel=kernel, grid=grid, n0=n0, t_out=t_out, scene=scene, gas=gas, material=mat,
                 outcome=None, params=params, reference=reference, notes=notes)


def _setup_ch2_compact(R_au=1, alpha=1e-4, bins_per_decade=4, decades=14, t_end_yr=None, method="w84"):
    """Thesis ch. 2 compact model ('C' rows of T-Tab2.2) for the binned engine: the setting of
    :func:`ch2_setup` (MMSN at z = H_g, t_L = 2 pi/Omega, quartz at 1 AU / ice at 5 AU,
    Brownian + W84 turbulence) with perfect sticking of compact spheres; rain-out (removal at
    tau_f > alpha/Omega) is an MC-engine feature and is not applied here."""
    import numpy as np

    from ..binned.grid import monodisperse

    if R_au not in (1, 5):
        raise _JIE(f"ch2_compact: R_au must be 1 or 5; got {R_au!r}")
    base = ch2_setup(R_au, alpha, porous=False, method=method, rain_out=False)
    mat, gas, kernel = base["material"], base["gas"], base["kernel"]
    m0 = float(mat.m0)
    grid = _log_grid(m0, decades, bins_per_decade)
    n0 = monodisperse(grid, m0, base["rho_d"])
    ref = base["reference"] or {}
    if t_end_yr is None:
        t_end_yr = float(ref.get("t_99", 1e5))
    t_out = np.concatenate([[0.0], np.logspace(1, np.log10(t_end_yr), 9) * _YR])
    params = dict(R_au=R_au, alpha=float(alpha), rho_g=float(gas.rho_g), rho_d=float(base["rho_d"]), m0=m0,
                  tau_rain=float(base["tau_rain"]), m_rain_est=float(base["m_rain_est"]))
    reference = dict(ref, model=base["name"], source="Ormel 2008 thesis Tab. 2.2") if ref else {}
    return Setup(name=f"ch2_compact_{R_au}au", kernel=kernel, grid=grid, n0=n0, t_out=t_out, scene=base["scene"],
                 gas=gas, material=mat, outcome=None, params=params, reference=reference,
                 notes="no rain-out sink in the binned engine (the MC engine's RainOutKernel does it).")


def _setup_ch5(kind, bins_per_decade=8, m_frag=None):
    """Thesis ch. 5 test kernels (Tab. 5.1): K = 1, K = (m_i + m_j)/2, K = m_i m_j as analytic kernels,
    monodisperse start m0 = 1, n0 = 1 (dimensionless units); ``m_frag``: shatter products
    heavier than m_frag into monomers (thesis §5.3.4; constant and sum kernels)."""
    import numpy as np

    from .. import outcomes as _oc
    from ..binned.grid import monodisperse
    from .. import kernels as _k

    kern = {"constant": _k.Constant(1.0), "sum": _k.Sum(0.5), "product": _k.Product(1.0)}[kind]
    t_end = {"constant": 1e4, "sum": 10.0, "product": 0.9}[kind]
    decades = {"constant": 7, "sum": 8, "product": 6}[kind] if m_frag is None else int(np.ceil(np.log10(m_frag))) + 1
    grid = _log_grid(1.0, decades, bins_per_decade)
    n0 = monodisperse(grid, 1.0, 1.0)
    t_out = np.concatenate([[0.0], np.logspace(-1 if kind != "constant" else 0, np.log10(t_end), 7)])
    outcome = None if m_frag is None else _oc.ShatterAbove(m_frag, 1.0)
    reference = dict(analytic=f"jaxcoag.analytic.number_density('{kind}', m, t)") if m_frag is None else dict(
        steady_state="m^2 f ∝ m^(1/2) (constant) / bath tub n0 m0 = n_f m_f (sum) [T§5.3.4]")
    return Setup(name=f"ch5_{kind}", kernel=kern, grid=grid, n0=n0, t_out=t_out, outcome=outcome,
                 params=dict(m0=1.0, n0=1.0, t_end=t_end, m_frag=m_frag), reference=reference,
                 notes="dimensionless units (m0 = n0 = 1).")


# name -> (builder, fixed arguments that are not overridable)
SETUPS = {
    "ch2_compact_1au": (_setup_ch2_compact, dict(R_au=1)),
    "ch2_compact_5au": (_setup_ch2_compact, dict(R_au=5)),
    "ch4_nebula": (_setup_ch4, {}),
    "ch6_cloud": (_setup_ch6, {}),
    "ch5_constant": (_setup_ch5, dict(kind="constant")),
    "ch5_sum": (_setup_ch5, dict(kind="sum")),
    "ch5_product": (_setup_ch5, dict(kind="product")),
}


def setup(name: str, **overrides) -> Setup:
    """A complete setting of the seeds by name (see :data:`SETUPS`), with keyword overrides.

    Names: ``ch2_compact_1au``/``_5au`` (thesis ch. 2 compact), ``ch4_nebula`` (chondrules +
    dust at 3 AU), ``ch6_cloud`` (molecular-cloud core; n, material = "ice"|"silicate", a0,
    outcome ...), ``ch5_constant``/``ch5_sum``/``ch5_product`` (test kernels; m_frag).
    Raises JaxcoagInputError for an unknown name or override (listing the valid ones).
    """
    import inspect

    if name not in SETUPS:
        raise _JIE(f"unknown setup {name!r}; available: {sorted(SETUPS)}")
    builder, fixed = SETUPS[name]
    allowed = [p for p in inspect.signature(builder).parameters if p not in fixed]
    bad = sorted(set(overrides) - set(allowed))
    if bad:
        raise _JIE(f"setup {name!r} has no parameter(s) {bad}; valid overrides: {allowed}")
    return builder(**fixed, **overrides)
