"""Run configurations: a TOML file (or dict) describing one binned coagulation run.

A run configuration names the physics (``[scene]``), the local gas (``[gas]``), the dust
(``[dust]``), the mass grid (``[grid]``), optional fragmentation (``[fragmentation]``), the
time integration (``[solver]``), the output times (``[time]``) and the output files
(``[output]``). ``jaxcoag run scene.toml`` executes it (:mod:`jaxcoag.runner`); the shipped
default (``jaxcoag/data/default_run.toml``, :func:`default`) is a protoplanetary-disk run at
1 AU with growth and fragmentation.

Schema (units in brackets; "req." = required, otherwise the default is shown)::

    [run]            name = "run", description = ""
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
                     width, crater_ratio = 10, chi = 1) | "to_monomers" (m_frag req. [g])
    [solver]         scheme = "twobin" | "dg", order = 0, method = "auto" | "kvaerno5" |
                     "tsit5" | "linearly_implicit_euler", rtol = 1e-6, atol = 1e-10
                     (relative to the total mass), max_steps = 100000 (per output segment)
    [time]           t_end_yr [yr] (req. unless t_out_yr), n_out = 12, spacing = "log" |
                     "linear", t_first_yr = 1e-4 t_end_yr (log spacing); or t_out_yr = [...]
                     (strictly increasing, > 0). The run starts at t = 0 (1 yr = 3.15576e7 s).
    [output]         path = "jaxcoag_out/run.nc", figure = true (panel PNG next to it),
                     checkpoint = "" (file; "" = none)

Errors: an unknown section or key (with a "did you mean" suggestion and the allowed keys),
a missing required parameter, a value of the wrong type, a negative / NaN / zero value where a
positive one is needed, a grid with fewer than 2 bins, output times that do not increase and
incompatible effects (a duplicated effect, drift in a cloud core) all raise
:class:`~jaxcoag._validate.JaxcoagInputError` naming the section and key. :func:`build` checks
everything (gas state, kernel, grid, initial condition, fragmentation) before any file is
written.

References: Hayashi (1981) MMSN; Ormel (2008) thesis Table 4.1 (ch4 disk), ch. 6 (clouds);
Stammler & Birnstiel (2022, DustPy) default disk run; TOML v1.0.0.
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import hashlib
import json
import math
import os
from importlib import resources

try:  # Python >= 3.11
    import tomllib as _toml
except ImportError:  # pragma: no cover - Python 3.10
    import tomli as _toml

import numpy as np

from . import constants as C
from ._validate import JaxcoagInputError

__all__ = ["RunConfig", "Built", "load", "loads", "from_dict", "default", "default_path", "build", "to_toml",
           "SCHEMA", "EFFECT_NAMES", "GAS_MODELS", "SWEEPABLE", "set_value", "n_bins", "check_memory"]

_REQ = object()  # marker: required key
_AUTO = None  # marker: computed default

# key -> (type, default, check); type in float, int, str, bool, "str_list", "float_list"
# check: "pos" (> 0), "nonneg" (>= 0), None, or a tuple of allowed strings
SCHEMA = {
    "run": {"name": (str, "run", None), "description": (str, "", None)},
    "scene": {
        "preset": (str, _AUTO, None),
        "effects": ("str_list", _AUTO, None),
        "turbulence_method": (str, _AUTO, ("exact", "ya", "ch03")),
        "focusing": (bool, False, None),
        "drag_regime": (str, "auto", ("auto", "epstein", "stokes")),
        "drag_convention": (str, "ormel", ("ormel", "dustpy")),
    },
    "gas": {
        "model": (str, _REQ, ("mmsn_hayashi81", "ch4_disk", "local", "molecular_cloud")),
        "R_au": (float, _AUTO, "pos"),
        "alpha": (float, _AUTO, "nonneg"),
        "z_H": (float, 0.0, "nonneg"),
        "M_star_msun": (float, 1.0, "pos"),
        "rho_X": (float, 1.0, "pos"),
        "Sigma_g": (float, _AUTO, "pos"),
        "T": (float, _AUTO, "pos"),
        "n": (float, _AUTO, "pos"),
    },
    "dust": {
        "rho_s": (float, _REQ, "pos"),
        "a0": (float, _AUTO, "pos"),
        "m0": (float, _AUTO, "pos"),
        "dust_to_gas": (float, 0.01, "pos"),
        "initial": (str, "monodisperse", ("monodisperse", "mrn")),
        "a_max": (float, _AUTO, "pos"),
        "q_mrn": (float, 3.5, None),
    },
    "grid": {
        "m_min": (float, _AUTO, "pos"),
        "m_max": (float, _REQ, "pos"),
        "bins_per_decade": (float, 7.0, "pos"),
    },
    "fragmentation": {
        "model": (str, "shattering", ("shattering", "to_monomers")),
        "v_frag": (float, _AUTO, "pos"),
        "q": (float, 11.0 / 6.0, None),
        "probability": (str, "maxwellian", ("maxwellian", "sigmoid", "linear", "step")),
        "width": (float, _AUTO, "nonneg"),
        "crater_ratio": (float, 10.0, "pos"),
        "chi": (float, 1.0, "pos"),
        "m_frag": (float, _AUTO, "pos"),
    },
    "solver": {
        "scheme": (str, "twobin", ("twobin", "dg")),
        "order": (int, 0, "nonneg"),
        "method": (str, "auto", ("auto", "kvaerno5", "tsit5", "linearly_implicit_euler")),
        "rtol": (float, 1e-6, "pos"),
        "atol": (float, 1e-10, "pos"),
        "max_steps": (int, 100_000, "pos"),
    },
    "time": {
        "t_end_yr": (float, _AUTO, "pos"),
        "n_out": (int, 12, "pos"),
        "spacing": (str, "log", ("log", "linear")),
        "t_first_yr": (float, _AUTO, "pos"),
        "t_out_yr": ("float_list", _AUTO, None),
    },
    "output": {
        "path": (str, "jaxcoag_out/run.nc", None),
        "figure": (bool, True, None),
        "checkpoint": (str, "", None),
    },
}

#: sections that must be present in a file
REQUIRED_SECTIONS = ("gas", "dust", "grid", "time")

EFFECT_NAMES = ("brownian", "turbulence_oc07", "radial_drift", "azimuthal_drift", "settling")
GAS_MODELS = SCHEMA["gas"]["model"][2]
_DISK_KEYS = {"mmsn_hayashi81": ("R_au", "alpha", "z_H", "M_star_msun"),
              "ch4_disk": ("R_au", "alpha", "z_H", "M_star_msun", "rho_X"),
              "local": ("R_au", "alpha", "z_H", "M_star_msun", "Sigma_g", "T"),
              "molecular_cloud": ("n", "T")}
_GAS_REQUIRED = {"mmsn_hayashi81": ("R_au", "alpha"), "ch4_disk": ("R_au", "alpha"),
                 "local": ("R_au", "alpha", "Sigma_g", "T"), "molecular_cloud": ("n",)}

#: scalar parameters a sweep may vary (they enter the compiled solve as array leaves)
SWEEPABLE = ("gas.R_au", "gas.alpha", "gas.z_H", "gas.M_star_msun", "gas.rho_X", "gas.Sigma_g", "gas.T", "gas.n",
             "dust.rho_s", "dust.dust_to_gas", "fragmentation.v_frag", "fragmentation.q", "fragmentation.m_frag")


def _suggest(word, options):
    m = difflib.get_close_matches(word, list(options), n=1, cutoff=0.6)
    return f" Did you mean {m[0]!r}?" if m else ""


def _where(section, key):
    return f"[{section}] {key}"


def _coerce(section, key, value):
    typ, _, chk = SCHEMA[section][key]
    w = _where(section, key)
    if typ is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise JaxcoagInputError(f"{w} must be a number, got {value!r} ({type(value).__name__}).")
        v = float(value)
        if not math.isfinite(v):
            raise JaxcoagInputError(f"{w} must be finite, got {value!r}.")
        if chk == "pos" and not v > 0:
            raise JaxcoagInputError(f"{w} must be > 0, got {value!r}.")
        if chk == "nonneg" and not v >= 0:
            raise JaxcoagInputError(f"{w} must be >= 0, got {value!r}.")
        return v
    if typ is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise JaxcoagInputError(f"{w} must be an integer, got {value!r} ({type(value).__name__}).")
        if chk == "pos" and not value > 0:
            raise JaxcoagInputError(f"{w} must be > 0, got {value!r}.")
        if chk == "nonneg" and not value >= 0:
            raise JaxcoagInputError(f"{w} must be >= 0, got {value!r}.")
        return int(value)
    if typ is bool:
        if not isinstance(value, bool):
            raise JaxcoagInputError(f"{w} must be true or false, got {value!r}.")
        return value
    if typ is str:
        if not isinstance(value, str):
            raise JaxcoagInputError(f"{w} must be a string, got {value!r} ({type(value).__name__}).")
        if isinstance(chk, tuple) and value not in chk:
            raise JaxcoagInputError(f"{w} = {value!r} is not one of {list(chk)}.{_suggest(value, chk)}")
        return value
    if typ == "str_list":
        if not isinstance(value, list) or not all(isinstance(s, str) for s in value):
            raise JaxcoagInputError(f"{w} must be a list of strings, got {value!r}.")
        return list(value)
    if typ == "float_list":
        if not isinstance(value, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                   for x in value):
            raise JaxcoagInputError(f"{w} must be a list of numbers, got {value!r}.")
        out = [float(x) for x in value]
        if not all(math.isfinite(x) for x in out):
            raise JaxcoagInputError(f"{w} must hold finite numbers, got {value!r}.")
        return out
    raise AssertionError(typ)  # pragma: no cover


@dataclasses.dataclass(frozen=True)
class RunConfig:
    """A validated run configuration.

    Attributes:
        data: dict section -> dict key -> value, every key of :data:`SCHEMA` present (computed
            defaults filled in; absent optional values are None); ``data["fragmentation"]`` is
            None for pure growth.
        source: where it came from (file path, "<default>" or "<dict>").
        explicit: the values given explicitly (validated), section -> key -> value; this is what
            :meth:`to_toml` writes, so a saved config round-trips through :func:`loads`.
    """

    data: dict
    source: str = "<dict>"
    explicit: dict = dataclasses.field(default_factory=dict)

    def __getitem__(self, section):
        return self.data[section]

    @property
    def has_fragmentation(self) -> bool:
        return self.data["fragmentation"] is not None

    def to_toml(self) -> str:
        """The configuration as TOML text (the explicit values; round-trips through :func:`loads`)."""
        return to_toml(self.explicit)

    def physics_hash(self) -> str:
        """sha256 of everything that determines the solution (all sections but [run], [output])."""
        d = {k: v for k, v in self.data.items() if k not in ("run", "output")}
        return hashlib.sha256(json.dumps(d, sort_keys=True, default=repr).encode()).hexdigest()

    def replace(self, **dotted) -> "RunConfig":
        """A new validated config with ``"section.key"`` values replaced (e.g. ``{"gas.alpha": 1e-4}``)."""
        raw = self.raw()
        for k, v in dotted.items():
            set_value(raw, k, v)
        return from_dict(raw, source=self.source)

    def raw(self) -> dict:
        """The explicit (non-None) values as a plain nested dict, suitable for :func:`from_dict`."""
        return copy.deepcopy(self.explicit)


def set_value(raw: dict, dotted: str, value):
    """Set ``raw[section][key] = value`` from a ``"section.key"`` name (checked against the schema)."""
    if "." not in dotted:
        raise JaxcoagInputError(f"parameter {dotted!r} must be written as section.key, e.g. gas.alpha.")
    s, k = dotted.split(".", 1)
    if s not in SCHEMA:
        raise JaxcoagInputError(f"unknown section [{s}] in {dotted!r}; sections: {list(SCHEMA)}.{_suggest(s, SCHEMA)}")
    if k not in SCHEMA[s]:
        raise JaxcoagInputError(f"unknown key {k!r} in section [{s}]; allowed keys: {list(SCHEMA[s])}."
                                f"{_suggest(k, SCHEMA[s])}")
    raw.setdefault(s, {})[k] = value


def from_dict(d: dict, *, source: str = "<dict>") -> RunConfig:
    """Validate a nested dict section -> key -> value and fill defaults.

    Raises JaxcoagInputError for an unknown section/key, a missing required section or key,
    a value of the wrong type or out of range, and inconsistent combinations.
    """
    if not isinstance(d, dict):
        raise JaxcoagInputError(f"a run configuration must be a table of sections, got {type(d).__name__}.")
    for s, sec in d.items():
        if s not in SCHEMA:
            raise JaxcoagInputError(f"unknown section [{s}] in {source}; allowed sections: {list(SCHEMA)}."
                                    f"{_suggest(s, SCHEMA)}")
        if not isinstance(sec, dict):
            raise JaxcoagInputError(f"[{s}] must be a table of key = value pairs (got {sec!r}).")
        for k in sec:
            if k not in SCHEMA[s]:
                raise JaxcoagInputError(f"unknown key {k!r} in section [{s}] of {source}; allowed keys: "
                                        f"{list(SCHEMA[s])}.{_suggest(k, SCHEMA[s])}")
    for s in REQUIRED_SECTIONS:
        if s not in d:
            raise JaxcoagInputError(f"missing section [{s}] in {source}; it needs at least the keys "
                                    f"{[k for k, v in SCHEMA[s].items() if v[1] is _REQ] or list(SCHEMA[s])[:3]}.")
    data, explicit = {}, {}
    for s, keys in SCHEMA.items():
        if s == "fragmentation" and s not in d:
            data[s] = None
            continue
        given = d.get(s, {})
        sec = {}
        for k, (typ, dflt, chk) in keys.items():
            if k in given:
                sec[k] = _coerce(s, k, given[k])
                explicit.setdefault(s, {})[k] = copy.deepcopy(sec[k])
            elif dflt is _REQ:
                raise JaxcoagInputError(f"missing required parameter {_where(s, k)} in {source}.")
            else:
                sec[k] = dflt
        data[s] = sec
        if s in d:
            explicit.setdefault(s, {})
    _cross_checks(data, source)
    return RunConfig(data=data, source=source, explicit=explicit)


def _cross_checks(data, source):
    sc = data["scene"]
    if sc["preset"] is not None and sc["effects"] is not None:
        raise JaxcoagInputError("[scene] give either preset or effects, not both.")
    if sc["preset"] is None and sc["effects"] is None:
        sc["preset"] = "nebula_ch4"
    if sc["preset"] is not None:
        from .scenes import PRESETS
        if sc["preset"] not in PRESETS:
            raise JaxcoagInputError(f"[scene] preset = {sc['preset']!r} is not a preset; choose one of "
                                    f"{sorted(PRESETS)}.{_suggest(sc['preset'], PRESETS)}")
    else:
        eff = sc["effects"]
        if not eff:
            raise JaxcoagInputError("[scene] effects is empty; list at least one of " f"{list(EFFECT_NAMES)}.")
        for e in eff:
            if e not in EFFECT_NAMES:
                raise JaxcoagInputError(f"[scene] effects: unknown effect {e!r}; choose from {list(EFFECT_NAMES)}."
                                        f"{_suggest(e, EFFECT_NAMES)}")
        dup = sorted({e for e in eff if eff.count(e) > 1})
        if dup:
            raise JaxcoagInputError(f"[scene] effects lists {dup} more than once; the effects are incompatible "
                                    "(each is added once in quadrature). Keep one of each.")

    g = data["gas"]
    model = g["model"]
    allowed = _DISK_KEYS[model]
    for k in ("R_au", "alpha", "Sigma_g", "T", "n", "rho_X"):
        if g[k] is not None and k not in allowed and not (k == "rho_X" and g[k] == 1.0):
            raise JaxcoagInputError(f"[gas] {k} does not apply to model = {model!r}; its keys are {list(allowed)}.")
    if model == "molecular_cloud":
        for k, dflt in (("z_H", 0.0), ("M_star_msun", 1.0)):
            if g[k] != dflt:
                raise JaxcoagInputError(f"[gas] {k} does not apply to model = 'molecular_cloud' "
                                        f"(a homogeneous core); its keys are {list(allowed)}.")
        if g["T"] is None:
            g["T"] = 10.0
    for k in _GAS_REQUIRED[model]:
        if g[k] is None:
            raise JaxcoagInputError(f"missing required parameter [gas] {k} for model = {model!r} in {source}.")

    du = data["dust"]
    if du["a0"] is None and du["m0"] is None:
        raise JaxcoagInputError(f"missing required parameter [dust] a0 (monomer radius, cm) or m0 (monomer mass, g) "
                                f"in {source}.")
    if du["a0"] is not None and du["m0"] is not None:
        raise JaxcoagInputError("[dust] give exactly one of a0 (monomer radius, cm) or m0 (monomer mass, g), not both.")
    if du["m0"] is None:
        du["m0"] = 4.0 / 3.0 * math.pi * du["rho_s"] * du["a0"] ** 3
    else:
        du["a0"] = (3.0 * du["m0"] / (4.0 * math.pi * du["rho_s"])) ** (1.0 / 3.0)
    if du["initial"] == "mrn":
        if du["a_max"] is None:
            raise JaxcoagInputError("missing required parameter [dust] a_max (largest MRN grain, cm) for "
                                    "initial = 'mrn'.")
        if not du["a_max"] > du["a0"]:
            raise JaxcoagInputError(f"[dust] a_max = {du['a_max']!r} cm must exceed a0 = {du['a0']:.4g} cm.")
    elif du["a_max"] is not None:
        raise JaxcoagInputError("[dust] a_max only applies to initial = 'mrn'.")

    gr = data["grid"]
    bpd = gr["bins_per_decade"]
    if gr["m_min"] is None:
        gr["m_min"] = du["m0"] / 10 ** (0.5 / bpd)
    if not gr["m_max"] > gr["m_min"]:
        raise JaxcoagInputError(f"[grid] m_max = {gr['m_max']!r} g must exceed m_min = {gr['m_min']:.4g} g.")
    nb = int(round(math.log10(gr["m_max"] / gr["m_min"]) * bpd))
    if nb < 2:
        raise JaxcoagInputError(f"[grid] [m_min, m_max] at bins_per_decade = {bpd:g} gives {nb} bin(s); a grid needs "
                                "at least 2 bins. Increase bins_per_decade or widen [m_min, m_max].")
    if not gr["m_min"] <= du["m0"] < gr["m_max"]:
        raise JaxcoagInputError(f"[dust] monomer mass m0 = {du['m0']:.4g} g lies outside the grid "
                                f"[{gr['m_min']:.4g}, {gr['m_max']:.4g}] g; change [grid] m_min/m_max.")

    fr = data["fragmentation"]
    if fr is not None:
        if fr["model"] == "shattering":
            if fr["v_frag"] is None:
                raise JaxcoagInputError("missing required parameter [fragmentation] v_frag (cm/s) for "
                                        "model = 'shattering'.")
            if fr["m_frag"] is not None:
                raise JaxcoagInputError("[fragmentation] m_frag applies to model = 'to_monomers' only.")
        else:
            if fr["m_frag"] is None:
                raise JaxcoagInputError("missing required parameter [fragmentation] m_frag (g) for "
                                        "model = 'to_monomers'.")
            if fr["v_frag"] is not None:
                raise JaxcoagInputError("[fragmentation] v_frag applies to model = 'shattering' only.")

    so = data["solver"]
    if so["scheme"] == "twobin" and so["order"] != 0:
        raise JaxcoagInputError(f"[solver] order = {so['order']} needs scheme = 'dg'; the two-bin scheme is order 0.")

    t = data["time"]
    if t["t_out_yr"] is not None:
        for k in ("t_end_yr", "t_first_yr"):
            if t[k] is not None:
                raise JaxcoagInputError(f"[time] give either t_out_yr or t_end_yr/n_out/t_first_yr, not {k} too.")
        to = t["t_out_yr"]
        if len(to) < 1:
            raise JaxcoagInputError("[time] t_out_yr needs at least one output time (yr) after t = 0.")
        if not to[0] > 0:
            raise JaxcoagInputError(f"[time] t_out_yr must be > 0 (the run starts at t = 0); got {to[0]!r}.")
        if not all(b > a for a, b in zip(to[:-1], to[1:])):
            raise JaxcoagInputError(f"[time] t_out_yr must be strictly increasing; got {to!r}.")
    else:
        if t["t_end_yr"] is None:
            raise JaxcoagInputError(f"missing required parameter [time] t_end_yr (or t_out_yr) in {source}.")
        if t["t_first_yr"] is not None and not t["t_first_yr"] < t["t_end_yr"]:
            raise JaxcoagInputError(f"[time] t_first_yr = {t['t_first_yr']!r} must be < t_end_yr = {t['t_end_yr']!r}.")


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


def default_path() -> str:
    """Path of the shipped default configuration ``jaxcoag/data/default_run.toml``."""
    return str(resources.files("jaxcoag").joinpath("data", "default_run.toml"))


def default() -> RunConfig:
    """The built-in default run (protoplanetary disk at 1 AU, growth + fragmentation)."""
    cfg = load(default_path())
    return dataclasses.replace(cfg, source="<default>")


def _fmt(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    raise TypeError(type(v))  # pragma: no cover


def to_toml(data: dict) -> str:
    """TOML text of a config data dict (None values are left out; a None section is omitted)."""
    lines = []
    for s, sec in data.items():
        if sec is None:
            continue
        lines.append(f"[{s}]")
        for k, v in sec.items():
            if v is not None:
                lines.append(f"{k} = {_fmt(v)}")
        lines.append("")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------ build
class Built:
    """Everything a run needs, built and checked from a config (see :func:`build`).

    Attributes: cfg, scene (Scene), gas (GasState), kernel (SceneKernel), grid (MassGrid),
    n0 (numpy number density per bin [cm^-3]), fragmentation (model or None), ts (output times
    [s]), solver (diffrax solver or the string "kvaerno5"), rtol, atol, max_steps, scheme, order.
    """

    def __init__(self, **kw):
        self.__dict__.update(kw)


def make_scene(cfg: RunConfig):
    """The :class:`~jaxcoag.Scene` of a config."""
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
        else:
            ctor = {"brownian": E.Brownian, "radial_drift": E.RadialDrift, "azimuthal_drift": E.AzimuthalDrift,
                    "settling": E.Settling}
            vel = tuple(E.TurbulenceOC07(method=meth or "exact") if e == "turbulence_oc07" else ctor[e]()
                        for e in sc["effects"])
            name = "custom"
        return Scene(velocities=vel, focusing=sc["focusing"], drag_regime=sc["drag_regime"], name=name,
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


def make_fragmentation(fr: dict | None, **over):
    """Binned fragmentation model of a [fragmentation] section (None = pure growth)."""
    from .binned import Shattering, ShatterToMonomers

    if fr is None:
        return None
    fr = dict(fr, **over)
    if fr["model"] == "to_monomers":
        return ShatterToMonomers(fr["m_frag"])
    return Shattering(fr["v_frag"], q=fr["q"], probability=fr["probability"], width=fr["width"],
                      crater_ratio=fr["crater_ratio"], chi=fr["chi"])


def make_grid(cfg: RunConfig):
    from .binned import MassGrid

    gr = cfg["grid"]
    return MassGrid.log(gr["m_min"], gr["m_max"], gr["bins_per_decade"])


def initial_number(cfg: RunConfig, grid, rho_g) -> np.ndarray:
    """Initial number density per bin [cm^-3] (numpy) for gas density rho_g [g cm^-3]."""
    from .binned import monodisperse, mrn

    du = cfg["dust"]
    rho_d = du["dust_to_gas"] * float(rho_g)
    if du["initial"] == "mrn":
        return mrn(grid, du["a0"], du["a_max"], du["rho_s"], rho_d, q=du["q_mrn"])
    return monodisperse(grid, du["m0"], rho_d)


def make_solver(cfg: RunConfig):
    """diffrax solver (or "kvaerno5", built with a Newton root finder inside solve_binned)."""
    import diffrax
    from .binned import LinearlyImplicitEuler

    m = cfg["solver"]["method"]
    if m == "auto":
        return "kvaerno5" if cfg.has_fragmentation else diffrax.Tsit5()
    if m == "tsit5":
        return diffrax.Tsit5()
    if m == "linearly_implicit_euler":
        return LinearlyImplicitEuler()
    return "kvaerno5"


def n_bins(cfg: RunConfig) -> int:
    """Number of bins of the config's grid, round(log10(m_max / m_min) bins_per_decade), without
    building it (as :meth:`jaxcoag.binned.MassGrid.log`)."""
    gr = cfg["grid"]
    return int(round(math.log10(gr["m_max"] / gr["m_min"]) * gr["bins_per_decade"]))


def check_memory(cfg: RunConfig):
    """Refuse (JaxcoagInputError naming [grid] bins_per_decade) a config whose grid and scheme
    tensors would not fit in memory, before any array is allocated: the estimate of
    :func:`jaxcoag.binned.scheme.estimate_bytes` for [solver] scheme/order, fragmentation and an
    implicit method ("auto" with fragmentation, "kvaerno5", "linearly_implicit_euler") against
    :func:`jaxcoag.binned.grid.memory_limit_bytes`. Returns the estimate [bytes]."""
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
    implicit = so["method"] in ("kvaerno5", "linearly_implicit_euler") or (so["method"] == "auto" and
                                                                         cfg.has_fragmentation)
    return _check(so["scheme"], nb, order=so["order"], fragmentation=cfg.has_fragmentation, implicit=implicit,
                  fix=fix)


def build(cfg: RunConfig) -> Built:
    """Build and check every object of a run (no files are touched).

    Raises JaxcoagInputError for anything the physics constructors refuse (e.g. drift effects in
    a molecular-cloud core, a kernel that cannot be evaluated, a non-finite initial state).
    """
    from .binned.solve import make_scheme

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
        frag = make_fragmentation(cfg["fragmentation"])
        scheme = make_scheme(cfg["solver"]["scheme"], cfg["solver"]["order"])
    except JaxcoagInputError:
        raise
    except (ValueError, TypeError) as e:
        raise JaxcoagInputError(str(e)) from e
    import jax.numpy as jnp

    k = np.asarray(kernel.matrix(jnp.asarray(grid.centers[:: max(1, grid.nbins // 8)])))
    if not np.all(np.isfinite(k)):
        raise JaxcoagInputError("the collision kernel is not finite on the grid for this [gas]/[dust] setting; "
                                "check the parameters (e.g. z_H, n, T).")
    ts = output_times_s(cfg)
    return Built(cfg=cfg, scene=scene, gas=gas, kernel=kernel, grid=grid, n0=n0, fragmentation=frag, ts=ts,
                 solver=make_solver(cfg), scheme=scheme, order=cfg["solver"]["order"],
                 rtol=cfg["solver"]["rtol"], atol=cfg["solver"]["atol"], max_steps=cfg["solver"]["max_steps"])
