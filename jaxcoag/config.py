"""Run configurations: one TOML schema (pydantic v2 models, written with tomli-w) for every engine.

A run configuration names the engine (``[run] engine``), the physics (``[scene]``), the local gas
(``[gas]``), the dust (``[dust]``), the mass grid (``[grid]``: the binned engine's grid, and the
bins every engine's output is written on), an optional collision outcome (``[fragmentation]``),
the engine settings (``[solver]`` for the binned engine, ``[mc]`` for the Monte Carlo engine),
the output times (``[time]``) and the output files (``[output]``). ``jaxcoag run scene.toml``
executes it (:mod:`jaxcoag.runner`); the shipped defaults (:func:`default`) are a protoplanetary
disk run at 1 AU with growth and fragmentation, binned (``jaxcoag config``) or Monte Carlo
(``jaxcoag config --engine mc``).

Schema (units in brackets; "req." = required, otherwise the default is shown)::

    [run]            name = "run", description = "", engine = "binned" | "mc" | "contact" | "rigid"
    [scene]          preset = "nebula_ch4"  (a jaxcoag.scenes.PRESETS name) | effects = [...]
                     (names from "brownian", "turbulence_oc07", "radial_drift",
                     "azimuthal_drift", "settling"; give preset OR effects),
                     turbulence_method = "exact" | "ya" | "ch03" (TurbulenceOC07 St* method; default:
                     the preset's own, "exact" for an effects list),
                     focusing = false, drag_regime = "auto" | "epstein" | "stokes",
                     drag_convention = "ormel" | "dustpy" (Epstein law with c_g and
                     1/(n sigma), thesis eq. 4.5; or DustPy's sqrt(8/pi) c_g and 1/(sqrt2 n sigma))
    [gas]            model (req.) = "mmsn_hayashi81" | "ch4_disk" | "local" | "molecular_cloud"
                     disk models: R_au (req.) [AU], alpha (req.) [-], z_H = 0 [gas scale
                     heights], M_star_msun = 1 [M_sun]; ch4_disk: rho_X = 1;
                     local: also Sigma_g (req.) [g cm^-2], T (req.) [K];
                     molecular_cloud: n (req.) [cm^-3], T = 10 [K]
    [dust]           rho_s (req.) [g cm^-3], a0 [cm] or m0 [g] (exactly one; the monomer /
                     smallest grain), dust_to_gas = 0.01 [-],
                     initial = "monodisperse" | "mrn" (then a_max [cm] req., q_mrn = 3.5)
    [grid]           m_max (req.) [g], bins_per_decade = 7, m_min [g] (default: the monomer
                     mass sits at the centre of the first bin)
    [fragmentation]  absent = pure growth. model = "shattering" (v_frag req. [cm s^-1],
                     q = 11/6, probability = "maxwellian" | "sigmoid" | "linear" | "step",
                     width, crater_ratio = 10, chi = 1; jaxcoag.outcomes.Shattering) |
                     "to_monomers" (m_frag req. [g]; jaxcoag.outcomes.ShatterAbove)
    [solver]         binned engine: scheme = "twobin" | "dg", order = 0, method = "auto" |
                     "rodas4" | "kvaerno5" | "tsit5" | "linearly_implicit_euler", rtol = 1e-6, atol = 1e-10
                     (relative to the total mass), max_steps = 100000 (per output segment)
    [mc]             Monte Carlo engine (jaxcoag.MonteCarlo): seed = 0, grouping = "none" |
                     "equal_mass" | "distribution" (default) with n_bins = 20, m_lo [g],
                     n_rezoom, count_groups, tail_events = 0, tail_wmax (distribution only);
                     volume = "constant_volume" | "constant_number" | "constant_species" (with
                     controller = "mass" | "species"), ns_target = 1000, n_particles (physical
                     particles in the simulated volume at t = 0), f_eps = 1e-3, capacity,
                     max_events = 1e8, rates = "incremental" (n_refresh) | "full",
                     neps_rounding = "ceil" | "floor", p_protect = 16, dedupe = true,
                     merge_weighting = "mass" | "number" | "volume", leftover = "demagnify" |
                     "stochastic"; n_particles is required with engine = "mc" (an MRN start
                     puts n_particles monomer masses of dust in the simulated volume)
    [contact]        engine = "contact" (jaxcoag.aggregates.contact; Wada et al. 2007): material =
                     "ice" | "quartz", r1 = 1e-5 [cm], xi_crit = 2e-8 [cm], gamma [erg cm^-2], E
                     [dyn cm^-2], nu, rho [g cm^-3] (overrides of the material), n = 64 (monomers
                     per BCCA, a power of 2), dim = 2 | 3, seed = 0, v_imp [cm s^-1] or v_imp_v0 = 4
                     [v0], impact_parameter = 0 [cm], dt_tc = 0.014 [t_c], t_end [s] (default: until
                     the outcome settles), n_records = 200
    [rigid]          engine = "rigid" (jaxcoag.aggregates.rigid; Richardson 1995, code units): model =
                     "i" .. "v", n0, r0, t_end (Table I: 1000, 0.1, 8.2; model v 9000, 0.033, 40.8),
                     box = 10, v0 = 1, seed = 0, n_out = 20
    [time]           t_end_yr [yr] (req. unless t_out_yr), n_out = 12, spacing = "log" |
                     "linear", t_first_yr = 1e-4 t_end_yr (log spacing); or t_out_yr = [...]
                     (strictly increasing, > 0). The run starts at t = 0 (1 yr = 3.15576e7 s).
    [output]         path = "jaxcoag_out/run.nc", figure = true (panel PNG next to it),
                     checkpoint = "" (file; "" = none)

``[solver]`` is read by the binned engine only and ``[mc]`` by the Monte Carlo engine only, so
``--set run.engine=mc`` switches an existing configuration between engines. [scene], [gas], [dust],
[grid] and [time] are read (and [gas], [dust], [grid], [time] required) by the coagulation engines
(binned, mc) only; the particle-level engines read [contact] or [rigid] (defaults when absent).

Errors: an unknown section or key (with a "did you mean" suggestion and the allowed keys), a
missing required parameter, a value of the wrong type, a negative / NaN / zero value where a
positive one is needed, a value outside its allowed set (the set is named), a grid with fewer
than 2 bins, output times that do not increase and incompatible settings (a duplicated effect,
drift in a cloud core, a key of another model) all raise :class:`~jaxcoag._validate.JaxcoagInputError`
with one message that starts by naming ``[section] key``. :func:`build` checks everything (gas
state, kernel, grid, initial condition, outcome, engine) before any file is written.

References: Hayashi (1981) MMSN; Ormel (2008) thesis Table 4.1 (ch4 disk), ch. 5 (grouped Monte
Carlo), ch. 6 (clouds); Stammler & Birnstiel (2022, DustPy) default disk run; TOML v1.0.0.
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import json
import math
import os
import typing
from importlib import resources
from typing import Annotated, Literal, Optional

try:  # Python >= 3.11
    import tomllib as _toml
except ImportError:  # pragma: no cover - Python 3.10
    import tomli as _toml

import equinox as eqx
import numpy as np
import pydantic
import tomli_w
from pydantic import BaseModel, ConfigDict, Field, model_validator

from . import constants as C
from ._validate import JaxcoagInputError

__all__ = ["RunConfig", "Built", "load", "loads", "from_dict", "default", "default_path", "build", "to_toml",
           "SECTIONS", "EFFECT_NAMES", "GAS_MODELS", "ENGINES", "SWEEPABLE", "set_value", "n_bins", "check_memory",
           "output_times_s", "make_scene", "make_gas", "make_outcome", "make_grid", "make_engine", "initial_state"]

Pos = Annotated[float, Field(gt=0)]
NonNeg = Annotated[float, Field(ge=0)]
PosInt = Annotated[int, Field(gt=0)]
NonNegInt = Annotated[int, Field(ge=0)]

EFFECT_NAMES = ("brownian", "turbulence_oc07", "radial_drift", "azimuthal_drift", "settling")
ENGINES = ("binned", "mc", "contact", "rigid", "disk")
#: engines of dust populations (they read [scene], [gas], [dust], [grid], [time]); the particle-level engines
#: "contact" and "rigid" read their own section ([contact] / [rigid]) only
COAGULATION_ENGINES = ("binned", "mc")
COAGULATION_SECTIONS = ("gas", "dust", "grid", "time")


class _Section(BaseModel):
    """A TOML table: unknown keys refused, no type coercion (an int is accepted for a float), finite numbers."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


class RunSection(_Section):
    name: str = "run"
    description: str = ""
    engine: Literal["binned", "mc", "contact", "rigid", "disk"] = "binned"


class SceneSection(_Section):
    preset: Optional[str] = None
    effects: Optional[list[str]] = None
    turbulence_method: Optional[Literal["exact", "ya", "ch03"]] = None
    focusing: bool = False
    drag_regime: Literal["auto", "epstein", "stokes"] = "auto"
    drag_convention: Literal["ormel", "dustpy"] = "ormel"

    @model_validator(mode="after")
    def _check(self):
        if self.preset is not None and self.effects is not None:
            raise ValueError("[scene] give either preset or effects, not both.")
        if self.preset is not None:
            from .scenes import PRESETS
            if self.preset not in PRESETS:
                raise ValueError(f"[scene] preset = {self.preset!r} is not a preset; choose one of "
                                 f"{sorted(PRESETS)}.{_suggest(self.preset, PRESETS)}")
        if self.effects is not None:
            if not self.effects:
                raise ValueError(f"[scene] effects is empty; list at least one of {list(EFFECT_NAMES)}.")
            for e in self.effects:
                if e not in EFFECT_NAMES:
                    raise ValueError(f"[scene] effects: unknown effect {e!r}; choose from {list(EFFECT_NAMES)}."
                                     f"{_suggest(e, EFFECT_NAMES)}")
            dup = sorted({e for e in self.effects if self.effects.count(e) > 1})
            if dup:
                raise ValueError(f"[scene] effects lists {dup} more than once; the effects are incompatible (each is "
                                 "added once in quadrature). Keep one of each.")
        return self


#: keys of [gas] per model, and the required ones
_GAS_KEYS = {"mmsn_hayashi81": ("R_au", "alpha", "z_H", "M_star_msun"),
             "ch4_disk": ("R_au", "alpha", "z_H", "M_star_msun", "rho_X"),
             "local": ("R_au", "alpha", "z_H", "M_star_msun", "Sigma_g", "T"),
             "molecular_cloud": ("n", "T")}
_GAS_REQUIRED = {"mmsn_hayashi81": ("R_au", "alpha"), "ch4_disk": ("R_au", "alpha"),
                 "local": ("R_au", "alpha", "Sigma_g", "T"), "molecular_cloud": ("n",)}
GAS_MODELS = tuple(_GAS_KEYS)


class GasSection(_Section):
    model: Literal["mmsn_hayashi81", "ch4_disk", "local", "molecular_cloud"]
    R_au: Optional[Pos] = None
    alpha: Optional[NonNeg] = None
    z_H: NonNeg = 0.0
    M_star_msun: Pos = 1.0
    rho_X: Pos = 1.0
    Sigma_g: Optional[Pos] = None
    T: Optional[Pos] = None
    n: Optional[Pos] = None

    @model_validator(mode="after")
    def _check(self):
        allowed = _GAS_KEYS[self.model]
        for k in sorted(self.model_fields_set - {"model"} - set(allowed), key=list(type(self).model_fields).index):
            raise ValueError(f"[gas] {k} does not apply to model = {self.model!r}; its keys are {list(allowed)}.")
        for k in _GAS_REQUIRED[self.model]:
            if getattr(self, k) is None:
                raise ValueError(f"missing required parameter [gas] {k} for model = {self.model!r}.")
        return self


class DustSection(_Section):
    rho_s: Pos
    a0: Optional[Pos] = None
    m0: Optional[Pos] = None
    dust_to_gas: Pos = 0.01
    initial: Literal["monodisperse", "mrn"] = "monodisperse"
    a_max: Optional[Pos] = None
    q_mrn: float = 3.5

    @model_validator(mode="after")
    def _check(self):
        if self.a0 is None and self.m0 is None:
            raise ValueError("missing required parameter [dust] a0 (monomer radius, cm) or m0 (monomer mass, g).")
        if self.a0 is not None and self.m0 is not None:
            raise ValueError("[dust] give exactly one of a0 (monomer radius, cm) or m0 (monomer mass, g), not both.")
        a0 = self.a0 if self.a0 is not None else (3.0 * self.m0 / (4.0 * math.pi * self.rho_s)) ** (1.0 / 3.0)
        if self.initial == "mrn":
            if self.a_max is None:
                raise ValueError("missing required parameter [dust] a_max (largest MRN grain, cm) for initial = 'mrn'.")
            if not self.a_max > a0:
                raise ValueError(f"[dust] a_max = {self.a_max!r} cm must exceed a0 = {a0:.4g} cm.")
        elif self.a_max is not None:
            raise ValueError("[dust] a_max only applies to initial = 'mrn'.")
        return self


class GridSection(_Section):
    m_min: Optional[Pos] = None
    m_max: Pos
    bins_per_decade: Pos = 7.0


class FragmentationSection(_Section):
    model: Literal["shattering", "to_monomers"] = "shattering"
    v_frag: Optional[Pos] = None
    q: float = 11.0 / 6.0
    probability: Literal["maxwellian", "sigmoid", "linear", "step"] = "maxwellian"
    width: Optional[NonNeg] = None
    crater_ratio: Pos = 10.0
    chi: Pos = 1.0
    m_frag: Optional[Pos] = None

    @model_validator(mode="after")
    def _check(self):
        need, other = ("v_frag", "m_frag") if self.model == "shattering" else ("m_frag", "v_frag")
        unit = "cm/s" if need == "v_frag" else "g"
        if getattr(self, need) is None:
            raise ValueError(f"missing required parameter [fragmentation] {need} ({unit}) for model = {self.model!r}.")
        if getattr(self, other) is not None:
            raise ValueError(f"[fragmentation] {other} applies to model = "
                             f"{'to_monomers' if other == 'm_frag' else 'shattering'!r} only.")
        if self.model == "to_monomers":
            for k in ("q", "probability", "width", "crater_ratio", "chi"):
                if k in self.model_fields_set:
                    raise ValueError(f"[fragmentation] {k} applies to model = 'shattering' only.")
        return self


class SolverSection(_Section):
    scheme: Literal["twobin", "dg"] = "twobin"
    order: NonNegInt = 0
    method: Literal["auto", "rodas4", "kvaerno5", "tsit5", "linearly_implicit_euler"] = "auto"
    rtol: Pos = 1e-6
    atol: Pos = 1e-10
    max_steps: PosInt = 100_000

    @model_validator(mode="after")
    def _check(self):
        if self.scheme == "twobin" and self.order != 0:
            raise ValueError(f"[solver] order = {self.order} needs scheme = 'dg'; the two-bin scheme is order 0.")
        return self


_DISTRIBUTION_KEYS = ("n_bins", "m_lo", "n_rezoom", "count_groups", "tail_events", "tail_wmax")


class MCSection(_Section):
    seed: NonNegInt = 0
    grouping: Literal["none", "equal_mass", "distribution"] = "distribution"
    n_bins: PosInt = 20
    m_lo: Optional[Pos] = None
    n_rezoom: Optional[PosInt] = None
    count_groups: Optional[Annotated[float, Field(ge=1)]] = None
    tail_events: NonNeg = 0.0
    tail_wmax: Optional[Pos] = None
    volume: Literal["constant_volume", "constant_number", "constant_species"] = "constant_volume"
    controller: Optional[Literal["mass", "species"]] = None
    ns_target: PosInt = 1000
    n_particles: Optional[Pos] = None
    f_eps: Pos = 1e-3
    capacity: Optional[PosInt] = None
    max_events: PosInt = 10 ** 8
    rates: Literal["incremental", "full"] = "incremental"
    n_refresh: Optional[PosInt] = None
    neps_rounding: Literal["ceil", "floor"] = "ceil"
    p_protect: NonNegInt = 16
    dedupe: bool = True
    merge_weighting: Literal["mass", "number", "volume"] = "mass"
    leftover: Literal["demagnify", "stochastic"] = "demagnify"

    @model_validator(mode="after")
    def _check(self):
        if self.grouping != "distribution":
            for k in _DISTRIBUTION_KEYS:
                if k in self.model_fields_set:
                    raise ValueError(f"[mc] {k} applies to grouping = 'distribution' only (now {self.grouping!r}).")
        if self.controller is not None and self.volume != "constant_species":
            raise ValueError(f"[mc] controller applies to volume = 'constant_species' only (now {self.volume!r}).")
        if self.n_refresh is not None and self.rates != "incremental":
            raise ValueError("[mc] n_refresh applies to rates = 'incremental' only.")
        if self.f_eps >= 1:
            raise ValueError(f"[mc] f_eps must be < 1 (the largest fractional mass gain per group event), got "
                             f"{self.f_eps!r}.")
        return self


class ContactSection(_Section):
    """[contact]: a head-on collision of two BCCA aggregates of monomers (Wada et al. 2007)."""

    material: Literal["ice", "quartz"] = "ice"
    r1: Pos = 1e-5
    xi_crit: Pos = 2e-8
    gamma: Optional[Pos] = None
    E: Optional[Pos] = None
    nu: Optional[float] = None
    rho: Optional[Pos] = None
    n: PosInt = 64
    dim: Literal[2, 3] = 2
    seed: NonNegInt = 0
    v_imp: Optional[Pos] = None
    v_imp_v0: Optional[Pos] = None
    impact_parameter: NonNeg = 0.0
    dt_tc: Pos = 0.014
    t_end: Optional[Pos] = None
    n_records: PosInt = 200

    @model_validator(mode="after")
    def _check(self):
        if self.n & (self.n - 1) or self.n > 2 ** 17:
            raise ValueError(f"[contact] n = {self.n!r} must be a power of 2 up to 2^17 (monomers per BCCA aggregate, "
                             "e.g. 64 or 128).")
        if self.v_imp is not None and self.v_imp_v0 is not None:
            raise ValueError("[contact] give the impact speed as v_imp [cm/s] or v_imp_v0 [units of v0], not both.")
        if self.nu is not None and not -1.0 < self.nu < 0.5:
            raise ValueError(f"[contact] nu = {self.nu!r} must be a Poisson ratio in (-1, 0.5).")
        if self.dt_tc > 0.2:
            raise ValueError(f"[contact] dt_tc = {self.dt_tc!r} is above the leapfrog's stability limit 0.2 (time step "
                             "in units of t_c; Wada et al. 2007 used 0.014, up to 0.112).")
        return self


#: default impact speed of [contact] in units of v0 (ice 2 A, 64 + 64: E_imp = 256 F_c delta_c, x_roll = 0.68,
#: x_break = 1.3: restructuring, Wada et al. 2007 Table 1)
CONTACT_DEFAULT_V_IMP_V0 = 4.0

RIGID_MODELS = ("i", "ii", "iii", "iv", "v")


class RigidSection(_Section):
    """[rigid]: a periodic box of colliding rigid aggregates (Richardson 1995 Table I; code units)."""

    model: Literal["i", "ii", "iii", "iv", "v"] = "i"
    n0: Optional[PosInt] = None
    r0: Optional[Pos] = None
    box: Pos = 10.0
    v0: Pos = 1.0
    seed: NonNegInt = 0
    t_end: Optional[Pos] = None
    n_out: PosInt = 20


class DiskSection(_Section):
    """[disk]: the 1-D radial disk (DustPy's default model unless overridden; Stammler & Birnstiel 2022).

    Keys mirror :func:`jaxcoag.disk.dustpy_default` (lengths in au, masses of the disk/star in solar
    masses here; cgs everywhere else). Output times come from [time] (default: DustPy's snapshots)."""

    nr: PosInt = 100
    r_min_au: Pos = 1.0
    r_max_au: Pos = 1000.0
    m_min: Pos = 1e-12
    m_max: Pos = 1e5
    bins_per_decade: PosInt = 7
    alpha: Pos = 1e-3
    delta_rad: Optional[Pos] = None
    delta_turb: Optional[Pos] = None
    delta_vert: Optional[Pos] = None
    v_frag: Pos = 100.0
    m_disk_msun: Pos = 0.05
    r_c_au: Pos = 60.0
    rho_s: Pos = 1.67
    dust_to_gas: Pos = 0.01
    a_ini_max: Pos = 1e-4
    m_star_msun: Pos = 1.0
    r_star_rsun: Pos = 2.0
    t_star: Pos = 5772.0
    stokes: Literal["dustpy", "jaxcoag"] = "dustpy"
    coagulation: bool = True
    dust_transport: bool = True
    gas_evolution: bool = True
    mode: Literal["parity", "split"] = "parity"
    cfl: Pos = 0.1
    max_steps: PosInt = 100_000

    @model_validator(mode="after")
    def _check(self):
        if not self.r_max_au > self.r_min_au:
            raise ValueError(f"[disk] r_max_au = {self.r_max_au!r} must exceed r_min_au = {self.r_min_au!r}.")
        if self.nr < 5:
            raise ValueError(f"[disk] nr = {self.nr!r}: the radial grid needs at least 5 cells (DustPy's boundary "
                             "rows use three cells at each end).")
        if not self.m_max > self.m_min:
            raise ValueError(f"[disk] m_max = {self.m_max!r} g must exceed m_min = {self.m_min!r} g.")
        if self.cfl > 1:
            raise ValueError(f"[disk] cfl = {self.cfl!r} must be <= 1 (DustPy uses 0.1).")
        return self


class TimeSection(_Section):
    t_end_yr: Optional[Pos] = None
    n_out: PosInt = 12
    spacing: Literal["log", "linear"] = "log"
    t_first_yr: Optional[Pos] = None
    t_out_yr: Optional[list[float]] = None

    @model_validator(mode="after")
    def _check(self):
        if self.t_out_yr is not None:
            for k in ("t_end_yr", "t_first_yr"):
                if getattr(self, k) is not None:
                    raise ValueError(f"[time] give either t_out_yr or t_end_yr/n_out/t_first_yr, not {k} too.")
            to = self.t_out_yr
            if len(to) < 1:
                raise ValueError("[time] t_out_yr needs at least one output time (yr) after t = 0.")
            if not to[0] > 0:
                raise ValueError(f"[time] t_out_yr must be > 0 (the run starts at t = 0); got {to[0]!r}.")
            if not all(b > a for a, b in zip(to[:-1], to[1:])):
                raise ValueError(f"[time] t_out_yr must be strictly increasing; got {to!r}.")
        else:
            if self.t_end_yr is None:
                raise ValueError("missing required parameter [time] t_end_yr (or t_out_yr).")
            if self.t_first_yr is not None and not self.t_first_yr < self.t_end_yr:
                raise ValueError(f"[time] t_first_yr = {self.t_first_yr!r} must be < t_end_yr = {self.t_end_yr!r}.")
        return self


class OutputSection(_Section):
    path: str = "jaxcoag_out/run.nc"
    figure: bool = True
    checkpoint: str = ""


class _Schema(BaseModel):
    """The whole file: one field per section (the section order is the order written)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    run: RunSection = RunSection()
    scene: SceneSection = SceneSection()
    gas: Optional[GasSection] = None
    dust: Optional[DustSection] = None
    grid: Optional[GridSection] = None
    fragmentation: Optional[FragmentationSection] = None
    solver: SolverSection = SolverSection()
    mc: MCSection = MCSection()
    contact: Optional[ContactSection] = None
    rigid: Optional[RigidSection] = None
    disk: Optional[DiskSection] = None
    time: Optional[TimeSection] = None
    output: OutputSection = OutputSection()

    @model_validator(mode="after")
    def _cross(self):
        if self.run.engine not in COAGULATION_ENGINES:
            return self
        for name in COAGULATION_SECTIONS:
            if getattr(self, name) is None:
                need = [n for n, f in SECTIONS[name].model_fields.items() if f.is_required()]
                raise ValueError(f"missing section [{name}] (needed by [run] engine = {self.run.engine!r}); it needs at "
                                 f"least the keys {need}.")
        du, gr = self.dust, self.grid
        m0 = du.m0 if du.m0 is not None else 4.0 / 3.0 * math.pi * du.rho_s * du.a0 ** 3
        bpd = gr.bins_per_decade
        m_min = gr.m_min if gr.m_min is not None else m0 / 10 ** (0.5 / bpd)
        if not gr.m_max > m_min:
            raise ValueError(f"[grid] m_max = {gr.m_max!r} g must exceed m_min = {m_min:.4g} g.")
        nb = int(round(math.log10(gr.m_max / m_min) * bpd))
        if nb < 2:
            raise ValueError(f"[grid] [m_min, m_max] at bins_per_decade = {bpd:g} gives {nb} bin(s); a grid needs at "
                             "least 2 bins. Increase bins_per_decade or widen [m_min, m_max].")
        if not m_min <= m0 < gr.m_max:
            raise ValueError(f"[dust] monomer mass m0 = {m0:.4g} g lies outside the grid [{m_min:.4g}, "
                             f"{gr.m_max:.4g}] g; change [grid] m_min/m_max.")
        if self.run.engine == "mc" and self.mc.n_particles is None:
            raise ValueError("missing required parameter [mc] n_particles (physical particles in the simulated volume "
                             "at t = 0, e.g. 1e30; up to 1e160 with grouping) for [run] engine = 'mc'.")
        return self


#: section name -> its model class (the schema)
SECTIONS = {name: _section_class for name, _section_class in
            ((n, typing.get_args(f.annotation)[0] if typing.get_args(f.annotation) else f.annotation)
             for n, f in _Schema.model_fields.items())}

#: sections that must be present in a file of a coagulation engine (binned, mc)
REQUIRED_SECTIONS = COAGULATION_SECTIONS

#: scalar parameters a sweep may vary (they enter the compiled solve as array leaves)
SWEEPABLE = ("gas.R_au", "gas.alpha", "gas.z_H", "gas.M_star_msun", "gas.rho_X", "gas.Sigma_g", "gas.T", "gas.n",
             "dust.rho_s", "dust.dust_to_gas", "fragmentation.v_frag", "fragmentation.q", "fragmentation.m_frag")


def _suggest(word, options):
    """" Did you mean 'x'?" for the closest option (difflib ratio >= 0.6, or the only option that
    starts with ``word``), else ""."""
    opts = [str(o) for o in options]
    m = difflib.get_close_matches(str(word), opts, n=1, cutoff=0.6)
    if not m:
        m = [o for o in opts if str(word) and o.startswith(str(word))]
    return f" Did you mean {m[0]!r}?" if len(m) == 1 else ""


def _allowed(section, key):
    """The allowed strings of a Literal-typed key (or None)."""
    ann = SECTIONS[section].model_fields[key].annotation
    for a in (ann, *typing.get_args(ann)):
        if typing.get_origin(a) is Literal:
            return list(typing.get_args(a))
    return None


def _message(err: dict, source: str) -> str:
    """One line for one pydantic error, naming ``[section] key`` first."""
    loc, typ, val = tuple(err["loc"]), err["type"], err.get("input")
    s = str(loc[0]) if loc else None
    k = str(loc[1]) if len(loc) > 1 else None
    w = f"[{s}] {k}"
    if typ == "value_error":
        return str(err["ctx"]["error"])
    if typ == "extra_forbidden":
        if k is None:
            return f"unknown section [{s}] in {source}; allowed sections: {list(SECTIONS)}.{_suggest(s, SECTIONS)}"
        keys = list(SECTIONS[s].model_fields)
        return f"unknown key {k!r} in section [{s}] of {source}; allowed keys: {keys}.{_suggest(k, keys)}"
    if typ == "missing":
        if k is None:
            need = [n for n, f in SECTIONS[s].model_fields.items() if f.is_required()]
            return f"missing section [{s}] in {source}; it needs at least the keys {need}."
        return f"missing required parameter {w} in {source}."
    if typ in ("model_type", "model_attributes_type", "dict_type"):
        return f"[{s}] must be a table of key = value pairs (got {val!r})."
    if len(loc) > 2:  # an element of a list
        kind = "numbers" if _is_float_list(s, k) else "strings"
        if typ == "finite_number":
            return f"{w} must hold finite numbers, got {val!r}."
        return f"{w} must be a list of {kind}, got element {val!r}."
    if typ == "list_type":
        kind = "numbers" if _is_float_list(s, k) else "strings"
        return f"{w} must be a list of {kind}, got {val!r}."
    if typ in ("float_type", "float_parsing"):
        return f"{w} must be a number, got {val!r} ({type(val).__name__})."
    if typ in ("int_type", "int_parsing", "int_from_float"):
        return f"{w} must be an integer, got {val!r} ({type(val).__name__})."
    if typ == "bool_type":
        return f"{w} must be true or false, got {val!r}."
    if typ == "string_type":
        return f"{w} must be a string, got {val!r} ({type(val).__name__})."
    if typ == "finite_number":
        return f"{w} must be finite, got {val!r}."
    if typ == "greater_than":
        return f"{w} must be > {err['ctx']['gt']:g}, got {val!r}."
    if typ == "greater_than_equal":
        return f"{w} must be >= {err['ctx']['ge']:g}, got {val!r}."
    if typ == "literal_error":
        opts = _allowed(s, k) or [err["ctx"].get("expected")]
        return f"{w} = {val!r} is not one of {opts}.{_suggest(val, opts)}"
    return f"{w}: {err['msg']} (got {val!r})."  # pragma: no cover - a pydantic error type not met above


def _is_float_list(section, key):
    return "float" in str(SECTIONS[section].model_fields[key].annotation)


def _first_error(exc: pydantic.ValidationError, source: str) -> str:
    """The message of the most basic error: unknown names first, then a missing section, then a
    missing key, then values (in file order within each kind)."""

    def rank(e):
        if e["type"] == "extra_forbidden":
            return 0
        if e["type"] == "missing":
            return 1 if len(e["loc"]) == 1 else 2
        return 3

    errs = exc.errors(include_url=False)
    return _message(min(errs, key=rank), source)


class RunConfig:
    """A validated run configuration.

    Attributes:
        model: the pydantic schema instance (``model.gas.alpha`` ...; what the user gave plus defaults).
        data: dict section -> dict key -> value, every key present, computed defaults filled in
            (the monomer ``m0``/``a0``, the grid's ``m_min``, the preset, the cloud's T; absent optional
            values are None); ``data["fragmentation"]`` is None for pure growth. ``cfg[section]``
            is ``data[section]``.
        source: where it came from (file path, "<default>" or "<dict>").
    """

    def __init__(self, model: _Schema, source: str = "<dict>"):
        self.model = model
        self.source = source
        self.data = _resolve(model)

    def __getitem__(self, section):
        return self.data[section]

    def __eq__(self, other):
        return isinstance(other, RunConfig) and self.data == other.data

    def __repr__(self):
        return f"RunConfig({self.data['run']['name']!r}, engine={self.engine!r}, source={self.source!r})"

    @property
    def engine(self) -> str:
        """``[run] engine``: "binned" or "mc"."""
        return self.data["run"]["engine"]

    @property
    def has_fragmentation(self) -> bool:
        return self.data["fragmentation"] is not None

    @property
    def explicit(self) -> dict:
        """The values given explicitly (validated): section -> key -> value."""
        return self.model.model_dump(exclude_unset=True, exclude_none=True)

    def raw(self) -> dict:
        """The explicit values as a plain nested dict, suitable for :func:`from_dict`."""
        return copy.deepcopy(self.explicit)

    def to_toml(self) -> str:
        """The configuration as TOML text (the explicit values, written by tomli-w; round-trips
        through :func:`loads`)."""
        return to_toml(self.explicit)

    def physics_hash(self) -> str:
        """sha256 of everything that determines the solution: the engine and the sections it reads
        (all but [run], [output] and the other engine's [solver] / [mc])."""
        if self.engine in COAGULATION_ENGINES:
            skip = ("run", "output", "contact", "rigid", "disk", "mc" if self.engine == "binned" else "solver")
            d = {k: v for k, v in self.data.items() if k not in skip}
        elif self.engine == "disk":
            d = {"disk": self.data["disk"], "time": self.data["time"]}
        else:
            d = {self.engine: self.data[self.engine]}
        d["engine"] = self.engine
        return hashlib.sha256(json.dumps(d, sort_keys=True, default=repr).encode()).hexdigest()

    def replace(self, **dotted) -> "RunConfig":
        """A new validated config with ``"section.key"`` values replaced (e.g. ``{"gas.alpha": 1e-4}``)."""
        raw = self.raw()
        for k, v in dotted.items():
            set_value(raw, k, v)
        return from_dict(raw, source=self.source)


def _resolve(m: _Schema) -> dict:
    """Every section as a dict with the computed defaults filled in."""
    data = {name: (None if getattr(m, name) is None else getattr(m, name).model_dump()) for name in SECTIONS}
    sc = data["scene"]
    if sc["preset"] is None and sc["effects"] is None:
        sc["preset"] = "nebula_ch4"
    g = data["gas"]
    if g is not None and g["model"] == "molecular_cloud" and g["T"] is None:
        g["T"] = 10.0
    du = data["dust"]
    if du is not None:
        if du["m0"] is None:
            du["m0"] = 4.0 / 3.0 * math.pi * du["rho_s"] * du["a0"] ** 3
        else:
            du["a0"] = (3.0 * du["m0"] / (4.0 * math.pi * du["rho_s"])) ** (1.0 / 3.0)
    gr = data["grid"]
    if gr is not None and du is not None and gr["m_min"] is None:
        gr["m_min"] = du["m0"] / 10 ** (0.5 / gr["bins_per_decade"])
    engine = data["run"]["engine"]
    if engine == "contact" and data["contact"] is None:
        data["contact"] = ContactSection().model_dump()
    if engine == "rigid" and data["rigid"] is None:
        data["rigid"] = RigidSection().model_dump()
    if engine == "disk" and data["disk"] is None:
        data["disk"] = DiskSection().model_dump()
    if engine == "disk" and data["time"] is None:  # DustPy's snapshots: 1e3 to 1e5 yr, 21 log-spaced
        data["time"] = TimeSection(t_out_yr=[float(x) for x in np.geomspace(1e3, 1e5, 21)]).model_dump()
    dk = data["disk"]
    if dk is not None:
        for k in ("delta_rad", "delta_turb", "delta_vert"):
            if dk[k] is None:
                dk[k] = dk["alpha"]
    ct = data["contact"]
    if ct is not None and ct["v_imp"] is None and ct["v_imp_v0"] is None:
        ct["v_imp_v0"] = CONTACT_DEFAULT_V_IMP_V0
    rg = data["rigid"]
    if rg is not None:  # Richardson (1995) Table I: models i-iv 1000 spheres of 0.1 to T = 8.2, model v 9000 of 0.033 to 40.8
        big = rg["model"] == "v"
        for k, v in (("n0", 9000 if big else 1000), ("r0", 0.033 if big else 0.1), ("t_end", 40.8 if big else 8.2)):
            if rg[k] is None:
                rg[k] = v
    mc = data["mc"]
    if mc["volume"] == "constant_species" and mc["controller"] is None:
        mc["controller"] = "mass" if mc["grouping"] == "equal_mass" else "species"
    return data


def set_value(raw: dict, dotted: str, value):
    """Set ``raw[section][key] = value`` from a ``"section.key"`` name (checked against the schema)."""
    if "." not in dotted:
        raise JaxcoagInputError(f"parameter {dotted!r} must be written as section.key, e.g. gas.alpha.")
    s, k = dotted.split(".", 1)
    if s not in SECTIONS:
        raise JaxcoagInputError(f"unknown section [{s}] in {dotted!r}; sections: {list(SECTIONS)}."
                                f"{_suggest(s, SECTIONS)}")
    keys = list(SECTIONS[s].model_fields)
    if k not in keys:
        raise JaxcoagInputError(f"unknown key {k!r} in section [{s}]; allowed keys: {keys}.{_suggest(k, keys)}")
    raw.setdefault(s, {})[k] = value


def from_dict(d: dict, *, source: str = "<dict>") -> RunConfig:
    """Validate a nested dict section -> key -> value and fill defaults.

    Raises JaxcoagInputError (one line naming ``[section] key``) for an unknown section/key, a
    missing required section or key, a value of the wrong type or out of range, and inconsistent
    combinations.
    """
    if not isinstance(d, dict):
        raise JaxcoagInputError(f"a run configuration must be a table of sections, got {type(d).__name__}.")
    try:
        model = _Schema.model_validate(d)
    except pydantic.ValidationError as e:
        raise JaxcoagInputError(_first_error(e, source)) from None
    return RunConfig(model, source=source)


def output_times_s(cfg: RunConfig) -> np.ndarray:
    """Output times [s] of a config: 0 followed by the [time] output times (strictly increasing)."""
    t = cfg["time"]
    if t["t_out_yr"] is not None:
        ty = np.asarray(t["t_out_yr"])
    elif t["spacing"] == "log":
        t1 = t["t_first_yr"] if t["t_first_yr"] is not None else 1e-4 * t["t_end_yr"]
        ty = np.logspace(math.log10(t1), math.log10(t["t_end_yr"]), t["n_out"]) if t["n_out"] > 1 else \
            np.array([t["t_end_yr"]])
    else:
        ty = np.linspace(0.0, t["t_end_yr"], t["n_out"] + 1)[1:]
    return np.concatenate([[0.0], ty * C.yr])


def loads(text: str, *, source: str = "<string>") -> RunConfig:
    """Parse TOML text into a validated :class:`RunConfig`."""
    try:
        d = _toml.loads(text)
    except _toml.TOMLDecodeError as e:
        raise JaxcoagInputError(f"{source} is not valid TOML: {e}") from e
    return from_dict(d, source=source)


def load(path) -> RunConfig:
    """Read and validate a TOML run configuration file."""
    p = os.fspath(path)
    if not os.path.isfile(p):
        raise JaxcoagInputError(f"no configuration file at {p!r}.")
    with open(p, "rb") as fh:
        raw = fh.read()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise JaxcoagInputError(f"{p} is not UTF-8 text: {e}") from e
    return loads(text, source=p)


_DEFAULT_FILES = {"binned": "default_run.toml", "mc": "default_mc_run.toml", "contact": "default_contact_run.toml",
                  "rigid": "default_rigid_run.toml", "disk": "default_disk_run.toml"}


def default_path(engine: str = "binned") -> str:
    """Path of a shipped default configuration: ``jaxcoag/data/default_run.toml`` (binned),
    ``default_mc_run.toml`` (Monte Carlo), ``default_contact_run.toml`` (a BCCA collision of the
    contact DEM) or ``default_rigid_run.toml`` (Richardson 1995 model (i) box)."""
    if engine not in _DEFAULT_FILES:
        raise JaxcoagInputError(f"engine = {engine!r} is not one of {list(ENGINES)}.{_suggest(engine, ENGINES)}")
    return str(resources.files("jaxcoag").joinpath("data", _DEFAULT_FILES[engine]))


def default(engine: str = "binned") -> RunConfig:
    """The built-in default run of an engine: the protoplanetary disk at 1 AU with growth and fragmentation
    (binned, mc), a 64 + 64 ice BCCA collision (contact) or Richardson's model (i) box (rigid)."""
    cfg = load(default_path(engine))
    cfg.source = "<default>" if engine == "binned" else f"<default {engine}>"
    return cfg


def to_toml(data: dict) -> str:
    """TOML text (tomli-w) of a section -> key -> value dict (None values and None sections are left out)."""
    clean = {s: {k: v for k, v in sec.items() if v is not None} for s, sec in data.items() if sec is not None}
    return tomli_w.dumps(clean)


# ------------------------------------------------------------------------------------ build
class Built:
    """Everything a run needs, built and checked from a config (see :func:`build`).

    Attributes: cfg, scene (Scene), gas (GasState), kernel (SceneKernel), grid (MassGrid; the
    binned engine's grid and the output bins of every engine), n0 (numpy number density per bin
    [cm^-3]), outcome (a ``jaxcoag.outcomes`` object or None), t_out (output times [s], starting at
    t = 0), engine (``jaxcoag.Binned`` / ``jaxcoag.MonteCarlo``), initial (the initial condition
    passed to :func:`jaxcoag.evolve`), key (PRNG key of the Monte Carlo engine, else None).
    """

    def __init__(self, **kw):
        self.__dict__.update(kw)


def make_scene(cfg: RunConfig):
    """The :class:`~jaxcoag.Scene` of a config."""
    import dataclasses

    from . import effects as E
    from . import scenes
    from .scene import Scene

    sc = cfg["scene"]
    meth = sc["turbulence_method"]
    try:
        if sc["preset"] is not None:
            base = scenes.get(sc["preset"], **({} if meth is None else {"method": meth}))
            # keep the preset's other fields (outcome, porosity, ...); set only what [scene] names
            return dataclasses.replace(base, focusing=sc["focusing"], drag_regime=sc["drag_regime"],
                                       drag_convention=sc["drag_convention"])
        ctor = {"brownian": E.Brownian, "radial_drift": E.RadialDrift, "azimuthal_drift": E.AzimuthalDrift,
                "settling": E.Settling}
        vel = tuple(E.TurbulenceOC07(method=meth or "exact") if e == "turbulence_oc07" else ctor[e]()
                    for e in sc["effects"])
        return Scene(velocities=vel, focusing=sc["focusing"], drag_regime=sc["drag_regime"], name="custom",
                     drag_convention=sc["drag_convention"])
    except (ValueError, TypeError, KeyError) as e:
        raise JaxcoagInputError(f"[scene] {e}") from e


def make_gas(g: dict, **over):
    """GasState from a [gas] section (values in ``over`` replace entries; may be traced)."""
    from .physics import gas as G

    g = dict(g, **over)
    model = g["model"]
    if model == "molecular_cloud":
        return G.molecular_cloud(g["n"], T=g["T"])
    R = g["R_au"] * C.AU
    Ms = g["M_star_msun"] * C.M_sun

    def at(z):
        if model == "mmsn_hayashi81":
            return G.mmsn_hayashi81(R, alpha=g["alpha"], z=z, M_star=Ms)
        if model == "ch4_disk":
            return G.ch4_disk(R, alpha=g["alpha"], z=z, rho_X=g["rho_X"], M_star=Ms)
        return G.local_state(R, Ms, g["Sigma_g"], g["T"], g["alpha"], z)

    if isinstance(g["z_H"], (int, float)) and g["z_H"] == 0.0:
        return at(0.0)
    return at(g["z_H"] * at(0.0).H_g)


def make_outcome(fr: dict | None, m0=None, engine="binned", **over):
    """The collision outcome (``jaxcoag.outcomes``) of a [fragmentation] section; None = pure growth.

    ``model = "shattering"`` -> :class:`jaxcoag.outcomes.Shattering` (Birnstiel et al. 2010 / DustPy
    shattering + cratering; binned: fragments from the grid bottom, Monte Carlo: from the monomer
    mass ``m0`` [g]); ``"to_monomers"`` -> :class:`jaxcoag.outcomes.ShatterAbove` (thesis §5.3.4: a
    product above m_frag shatters into monomers of mass ``m0`` [g])."""
    from . import outcomes as O

    if fr is None:
        return None
    fr = dict(fr, **over)
    if fr["model"] == "to_monomers":
        return O.ShatterAbove(fr["m_frag"], m0)
    return O.Shattering(fr["v_frag"], q=fr["q"], probability=fr["probability"], width=fr["width"],
                        crater_ratio=fr["crater_ratio"], chi=fr["chi"], m_lo=m0 if engine == "mc" else None)


def make_grid(cfg: RunConfig):
    """The :class:`~jaxcoag.MassGrid` of [grid] (log-spaced, ``bins_per_decade``)."""
    from .binned import MassGrid

    gr = cfg["grid"]
    return MassGrid.log(gr["m_min"], gr["m_max"], gr["bins_per_decade"])


def initial_number(cfg: RunConfig, grid, rho_g) -> np.ndarray:
    """Initial number density per bin [cm^-3] (numpy) for gas density rho_g [g cm^-3]."""
    from .binned.grid import monodisperse, mrn

    du = cfg["dust"]
    rho_d = du["dust_to_gas"] * float(rho_g)
    if du["initial"] == "mrn":
        return mrn(grid, du["a0"], du["a_max"], du["rho_s"], rho_d, q=du["q_mrn"])
    return monodisperse(grid, du["m0"], rho_d)


def _binned_solver(cfg: RunConfig, rho_d):
    """diffrax solver of [solver] method (None = the engine's automatic choice: Tsit5 for pure growth,
    Rodas4 with fragmentation); rho_d [g cm^-3] is the total dust mass the root-finder tolerance of an
    explicitly asked Kvaerno5 (+ chord, a Jacobian per stage) refers to (1e-3 atol M_tot)."""
    import diffrax

    from .binned import LinearlyImplicitEuler

    so = cfg["solver"]
    m = so["method"]
    if m == "tsit5":
        return diffrax.Tsit5()
    if m == "linearly_implicit_euler":
        return LinearlyImplicitEuler()
    if m == "rodas4":
        from .binned import Rodas4

        return Rodas4()
    if m == "kvaerno5":
        from .binned.solve import default_implicit_solver

        return default_implicit_solver(so["rtol"], 1e-3 * so["atol"] * rho_d)
    return None


def _mc_engine(cfg: RunConfig):
    """``jaxcoag.MonteCarlo`` of the [mc] section (n_particles only for a monodisperse start; an MRN
    start brings its own multiplicities, :func:`initial_state`)."""
    from . import mc

    s = cfg["mc"]
    if s["grouping"] == "none":
        grouping = None
    elif s["grouping"] == "equal_mass":
        grouping = mc.EqualMass()
    else:
        grouping = mc.Distribution(n_bins=s["n_bins"], m_lo=s["m_lo"], n_rezoom=s["n_rezoom"],
                                   count_groups=s["count_groups"], tail_events=s["tail_events"],
                                   tail_wmax=s["tail_wmax"])
    if s["volume"] == "constant_volume":
        volume = mc.ConstantVolume()
    elif s["volume"] == "constant_number":
        volume = mc.ConstantNumber()
    else:
        volume = mc.ConstantSpecies(controller=mc.MassController() if s["controller"] == "mass" else
                                    mc.SpeciesController())
    rates = mc.IncrementalRates(n_refresh=s["n_refresh"]) if s["rates"] == "incremental" else mc.FullRates()
    n_part = s["n_particles"] if cfg["dust"]["initial"] == "monodisperse" else None
    return mc.MonteCarlo(grouping=grouping, volume=volume, ns_target=float(s["ns_target"]), n_particles=n_part,
                         f_eps=s["f_eps"], capacity=s["capacity"], max_events=s["max_events"], rates=rates,
                         neps_rounding=s["neps_rounding"], p_protect=s["p_protect"], dedupe=s["dedupe"],
                         merge_weighting=s["merge_weighting"], leftover=s["leftover"])


def make_engine(cfg: RunConfig, grid=None, rho_d=None):
    """The engine object of ``[run] engine``: ``jaxcoag.Binned`` from [grid] + [solver], or
    ``jaxcoag.MonteCarlo`` from [mc]. ``rho_d``: dust mass density [g cm^-3] (default from the
    config's gas), the mass scale of an explicit Kvaerno5's Newton tolerance."""
    if cfg.engine == "mc":
        return _mc_engine(cfg)
    from .binned import Binned, DGScheme, TwoBinScheme

    so = cfg["solver"]
    scheme = TwoBinScheme() if so["scheme"] == "twobin" else DGScheme(order=so["order"])
    if rho_d is None:
        rho_d = cfg["dust"]["dust_to_gas"] * float(make_gas(cfg["gas"]).rho_g)
    return Binned(grid if grid is not None else make_grid(cfg), scheme=scheme, solver=_binned_solver(cfg, rho_d),
                  rtol=so["rtol"], atol=so["atol"], max_steps=so["max_steps"])


def initial_state(cfg: RunConfig, grid, rho_g):
    """The initial condition for :func:`jaxcoag.evolve` of the config's engine at gas density rho_g.

    Binned: the number density per bin [cm^-3] (monodisperse in the monomer's bin, or MRN). Monte
    Carlo: ``Monodisperse(m0, rho_d)`` with rho_d = dust_to_gas rho_g, or for an MRN start the
    species of the MRN bins (``jaxcoag.mc.initial_species``, number per bin in the volume of
    ``[mc] n_particles`` monomer masses)."""
    from ._engine import Monodisperse

    du = cfg["dust"]
    rho_d = du["dust_to_gas"] * float(rho_g)
    if cfg.engine == "binned":
        return initial_number(cfg, grid, rho_g)
    if du["initial"] == "monodisperse":
        return Monodisperse(du["m0"], rho_d)
    from . import mc

    n = initial_number(cfg, grid, rho_g)
    keep = n > 0
    V = cfg["mc"]["n_particles"] * du["m0"] / rho_d  # [cm^3]
    return mc.initial_species(np.asarray(grid.centers)[keep], g=n[keep] * V, V=V)


def n_bins(cfg: RunConfig) -> int:
    """Number of bins of the config's grid, round(log10(m_max / m_min) bins_per_decade), without
    building it (as :meth:`jaxcoag.binned.MassGrid.log`)."""
    gr = cfg["grid"]
    return int(round(math.log10(gr["m_max"] / gr["m_min"]) * gr["bins_per_decade"]))


def check_memory(cfg: RunConfig):
    """Refuse (JaxcoagInputError naming [grid] bins_per_decade) a config whose grid and scheme
    tensors would not fit in memory, before any array is allocated: the grid itself against
    :func:`jaxcoag.binned.grid.memory_limit_bytes` and, for the binned engine, the estimate of
    :func:`jaxcoag.binned.scheme.estimate_bytes` for [solver] scheme/order, fragmentation and an
    implicit method ("auto" with fragmentation, "rodas4", "kvaerno5", "linearly_implicit_euler").
    Returns the estimate [bytes]."""
    from .binned.grid import GRID_BYTES_PER_BIN, _gib, memory_limit_bytes
    from .binned.scheme import check_memory as _check

    nb = n_bins(cfg)
    so = cfg["solver"]
    gr = cfg["grid"]
    fix = (f"lower [grid] bins_per_decade (now {gr['bins_per_decade']:g}) or narrow [grid] m_min..m_max "
           f"({gr['m_min']:.3g}..{gr['m_max']:.3g} g)")
    if nb * GRID_BYTES_PER_BIN > memory_limit_bytes():
        raise JaxcoagInputError(f"{nb:.4g} bins would need {_gib(nb * GRID_BYTES_PER_BIN)} for the grid alone, more "
                                f"than the limit of {_gib(memory_limit_bytes())}; {fix}.")
    if cfg.engine != "binned":
        return nb * GRID_BYTES_PER_BIN
    implicit = so["method"] in ("rodas4", "kvaerno5", "linearly_implicit_euler") or (so["method"] == "auto" and
                                                                         cfg.has_fragmentation)
    return _check(so["scheme"], nb, order=so["order"], fragmentation=cfg.has_fragmentation, implicit=implicit,
                  fix=fix)


@eqx.filter_jit
def _kernel_matrix(kernel, m):
    """``kernel.matrix(m)`` in one jitted call."""
    return kernel.matrix(m)


def build(cfg: RunConfig) -> Built:
    """Build and check every object of a run (no files are touched).

    Raises JaxcoagInputError for anything the physics constructors or the engine refuse (e.g.
    drift effects in a molecular-cloud core, a kernel that cannot be evaluated, a non-finite initial
    state, an outcome the engine cannot run), naming the section to change.
    """
    import jax
    import jax.numpy as jnp

    check_memory(cfg)
    scene = make_scene(cfg)
    g = cfg["gas"]
    if g["model"] == "molecular_cloud":
        bad = [n for n in scene.effect_names if n in ("radial_drift", "azimuthal_drift", "settling")]
        if bad:
            raise JaxcoagInputError(f"[scene] effects {bad} are incompatible with [gas] model = 'molecular_cloud' "
                                    "(a cloud core has no Keplerian drift or settling); use preset = "
                                    "'molecular_cloud' or drop them.")
    try:
        gas = make_gas(g)
        kernel = scene.kernel(gas, rho_s=cfg["dust"]["rho_s"])
        grid = make_grid(cfg)
        n0 = initial_number(cfg, grid, gas.rho_g)
    except JaxcoagInputError:
        raise
    except (ValueError, TypeError) as e:
        raise JaxcoagInputError(str(e)) from e
    try:
        outcome = make_outcome(cfg["fragmentation"], m0=cfg["dust"]["m0"], engine=cfg.engine)
    except (ValueError, TypeError) as e:
        raise JaxcoagInputError(f"[fragmentation] {e}") from e
    section = "[mc]" if cfg.engine == "mc" else "[solver]"
    try:
        engine = make_engine(cfg, grid, rho_d=cfg["dust"]["dust_to_gas"] * float(gas.rho_g))
        initial = n0 if cfg.engine == "binned" else initial_state(cfg, grid, gas.rho_g)
    except (ValueError, TypeError) as e:
        raise JaxcoagInputError(f"{section} {e}") from e
    # one compiled call (evaluated eagerly, the scene kernel's matrix compiled its ~100 operations one by one)
    k = np.asarray(_kernel_matrix(kernel, jnp.asarray(grid.centers[:: max(1, grid.nbins // 8)])))
    if not np.all(np.isfinite(k)):
        raise JaxcoagInputError("the collision kernel is not finite on the grid for this [gas]/[dust] setting; "
                                "check the parameters (e.g. z_H, n, T).")
    t_out = output_times_s(cfg)
    key = jax.random.key(cfg["mc"]["seed"]) if cfg.engine == "mc" else None
    if outcome is not None:
        try:
            outcome.check(kernel, cfg.engine)
        except (ValueError, TypeError) as e:
            raise JaxcoagInputError(f"[fragmentation] model = {cfg['fragmentation']['model']!r} with [run] engine = "
                                    f"{cfg.engine!r}: {e}") from None
    try:  # every refusal of the engine itself (Python time, before any work)
        engine._check(kernel, initial, jnp.asarray(t_out), 0.0, outcome, key)
    except (ValueError, TypeError) as e:
        raise JaxcoagInputError(f"{section} {e}") from None
    return Built(cfg=cfg, scene=scene, gas=gas, kernel=kernel, grid=grid, n0=n0, outcome=outcome, t_out=t_out,
                 engine=engine, initial=initial, key=key)
