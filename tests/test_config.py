"""TOML run configurations (pydantic schema, tomli-w writer): defaults, round trip, building for
both engines, and one refusal per error category, each naming its ``[section] key``."""

import math
import tomllib

import jax
import numpy as np
import pytest

import jaxcoag
from jaxcoag import config, constants as C
from jaxcoag._validate import JaxcoagInputError

MINIMAL = """
[gas]
model = "mmsn_hayashi81"
R_au = 1.0
alpha = 1e-3
[dust]
rho_s = 1.6
a0 = 1e-4
[grid]
m_max = 1e3
[time]
t_end_yr = 100.0
"""


def test_default_config_is_the_1au_disk_with_fragmentation():
    cfg = config.default()
    assert cfg["gas"]["model"] == "mmsn_hayashi81" and cfg["gas"]["R_au"] == 1.0
    assert cfg["gas"]["alpha"] == 1e-3 and cfg.has_fragmentation and cfg["fragmentation"]["v_frag"] == 1000.0
    assert cfg["solver"]["scheme"] == "twobin" and cfg["grid"]["bins_per_decade"] == 7.0
    b = config.build(cfg)
    # monomer of 1 um at rho_s = 1.6 sits at the centre of the first bin
    m0 = 4 / 3 * math.pi * 1.6 * 1e-12
    np.testing.assert_allclose(b.grid.centers[0], m0, rtol=1e-12)
    np.testing.assert_allclose(b.n0[0] * b.grid.centers[0], 0.01 * float(b.gas.rho_g), rtol=1e-12)
    assert np.count_nonzero(b.n0) == 1
    # MMSN at 1 AU midplane: rho_g = 1700 / (sqrt(2 pi) H), T = 280 K
    np.testing.assert_allclose(float(b.gas.T), 280.0, rtol=1e-12)
    np.testing.assert_allclose(float(b.gas.rho_g), 1700 / (math.sqrt(2 * math.pi) * float(b.gas.H_g)), rtol=1e-12)
    assert b.t_out[0] == 0.0 and b.t_out.size == 17
    np.testing.assert_allclose(b.t_out[[1, -1]], [C.yr, 1e4 * C.yr], rtol=1e-12)
    assert b.scene.effect_names == ("brownian", "turbulence", "radial_drift")
    # the engine and outcome objects of the default: binned two-bin scheme, DustPy-like shattering
    assert isinstance(b.engine, jaxcoag.Binned) and isinstance(b.engine.scheme, jaxcoag.binned.TwoBinScheme)
    assert b.engine.rtol == 1e-6 and b.engine.atol == 1e-10 and b.engine.grid.nbins == 135 and b.key is None
    assert isinstance(b.outcome, jaxcoag.outcomes.Shattering) and float(b.outcome.v_frag) == 1000.0
    np.testing.assert_allclose(float(b.outcome.q), 11 / 6, rtol=1e-15)
    assert b.initial is b.n0


def test_minimal_config_fills_defaults_and_round_trips():
    cfg = config.loads(MINIMAL)
    assert not cfg.has_fragmentation and cfg.engine == "binned"
    assert cfg["scene"]["preset"] == "nebula_ch4" and cfg["dust"]["dust_to_gas"] == 0.01
    assert cfg["time"]["n_out"] == 12 and cfg["solver"]["rtol"] == 1e-6
    text = cfg.to_toml()
    assert tomllib.loads(text) == cfg.explicit == tomllib.loads(MINIMAL)  # only what was given is written
    again = config.loads(text)
    assert again.data == cfg.data and again.physics_hash() == cfg.physics_hash()
    other = cfg.replace(**{"gas.alpha": 1e-4})
    assert other["gas"]["alpha"] == 1e-4 and other.physics_hash() != cfg.physics_hash()
    # output settings do not change the physics hash
    assert cfg.replace(**{"output.path": "x/y.nc"}).physics_hash() == cfg.physics_hash()
    # linear spacing and explicit times
    lin = cfg.replace(**{"time.spacing": "linear", "time.n_out": 4})
    np.testing.assert_allclose(config.output_times_s(lin) / C.yr, [0, 25, 50, 75, 100], rtol=1e-12)
    raw = cfg.raw()
    del raw["time"]["t_end_yr"]
    raw["time"]["t_out_yr"] = [1, 10, 100]
    np.testing.assert_allclose(config.output_times_s(config.from_dict(raw)) / C.yr, [0, 1, 10, 100], rtol=1e-12)


def test_explicit_effects_other_gas_models_and_mrn():
    raw = config.loads(MINIMAL).raw()
    raw["scene"] = {"effects": ["brownian", "turbulence_oc07"]}
    raw["gas"] = {"model": "molecular_cloud", "n": 1e5, "T": 10.0}
    b = config.build(config.from_dict(raw))
    assert b.scene.effect_names == ("brownian", "turbulence")
    np.testing.assert_allclose(float(b.gas.rho_g), 1e5 * C.mu_gas * C.m_H, rtol=1e-12)
    raw["gas"] = {"model": "local", "R_au": 2.0, "alpha": 1e-4, "Sigma_g": 100.0, "T": 150.0}
    raw["dust"] = {"rho_s": 3.0, "a0": 1e-5, "initial": "mrn", "a_max": 1e-3}
    b = config.build(config.from_dict(raw))
    np.testing.assert_allclose(float(b.gas.Sigma_g), 100.0, rtol=1e-12)
    rho = b.n0 * b.grid.centers
    np.testing.assert_allclose(rho.sum(), 0.01 * float(b.gas.rho_g), rtol=1e-12)
    assert np.count_nonzero(rho) > 3
    # z_H moves the gas density by exp(-z^2/2H^2)
    raw = config.loads(MINIMAL).raw()
    b0 = config.build(config.from_dict(raw))
    raw["gas"]["z_H"] = 1.0
    b1 = config.build(config.from_dict(raw))
    np.testing.assert_allclose(float(b1.gas.rho_g) / float(b0.gas.rho_g), math.exp(-0.5), rtol=1e-12)


@pytest.mark.parametrize("patch, words", [
    ("[gass]\nalpha = 1\n", ["unknown section [gass]", "Did you mean 'gas'"]),
    ("[solver]\nrtoll = 1e-6\n", ["unknown key 'rtoll'", "[solver]", "Did you mean 'rtol'", "allowed keys"]),
    ("[fragmentation]\nq = 1.8\n", ["missing required parameter [fragmentation] v_frag"]),
    ("[solver]\nrtol = \"small\"\n", ["[solver] rtol must be a number"]),
    ("[solver]\nmax_steps = 1.5\n", ["[solver] max_steps must be an integer"]),
    ("[solver]\nscheme = \"twobn\"\n", ["not one of", "Did you mean 'twobin'"]),
    ("[solver]\norder = 2\n", ["needs scheme = 'dg'"]),
    ("[scene]\neffects = [\"brownian\", \"brownian\"]\n", ["more than once", "incompatible"]),
    ("[scene]\npreset = \"nebula\"\n", ["is not a preset"]),
    ("[scene]\npreset = \"nebula_ch4\"\neffects = [\"brownian\"]\n", ["either preset or effects"]),
])
def test_refusals_name_the_problem(patch, words):
    with pytest.raises(JaxcoagInputError) as e:
        config.loads(MINIMAL + patch)
    for w in words:
        assert w in str(e.value), (w, str(e.value))


@pytest.mark.parametrize("section, key, value, words", [
    ("gas", "alpha", -1e-3, ["[gas] alpha must be >= 0"]),
    ("gas", "alpha", float("nan"), ["[gas] alpha must be finite"]),
    ("dust", "rho_s", 0.0, ["[dust] rho_s must be > 0"]),
    ("grid", "bins_per_decade", 0.05, ["at least 2 bins"]),
    ("grid", "m_max", 7e-12, ["at least 2 bins"]),
    ("time", "t_end_yr", -5.0, ["[time] t_end_yr must be > 0"]),
    ("gas", "n", 1e5, ["does not apply to model = 'mmsn_hayashi81'"]),
    ("dust", "m0", 1e-12, ["exactly one of a0", "not both"]),
    ("time", "n_out", 4.0, ["[time] n_out must be an integer, got 4.0"]),
    ("time", "t_out_yr", [1.0, float("inf")], ["[time] t_out_yr must hold finite numbers"]),
    ("gas", "model", "mmsn", ["[gas] model = 'mmsn' is not one of", "Did you mean 'mmsn_hayashi81'"]),
])
def test_bad_values_are_refused(section, key, value, words):
    raw = config.loads(MINIMAL).raw()
    raw[section][key] = value
    with pytest.raises(JaxcoagInputError) as e:
        config.from_dict(raw)
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_missing_parameters_and_times():
    for sec, key in (("gas", "alpha"), ("gas", "R_au"), ("dust", "rho_s"), ("grid", "m_max"), ("time", "t_end_yr")):
        raw = config.loads(MINIMAL).raw()
        del raw[sec][key]
        with pytest.raises(JaxcoagInputError, match=r"missing required parameter \[" + sec + r"\] " + key):
            config.from_dict(raw)
    raw = config.loads(MINIMAL).raw()
    del raw["dust"]
    with pytest.raises(JaxcoagInputError, match=r"missing section \[dust\]"):
        config.from_dict(raw)
    for bad in ([1.0, 10.0, 5.0], [1.0, 1.0], [0.0, 1.0]):
        raw = config.loads(MINIMAL).raw()
        del raw["time"]["t_end_yr"]
        raw["time"]["t_out_yr"] = bad
        with pytest.raises(JaxcoagInputError, match="t_out_yr must be"):
            config.from_dict(raw)
    with pytest.raises(JaxcoagInputError, match="not valid TOML"):
        config.loads("[gas\nmodel = 1")
    with pytest.raises(JaxcoagInputError, match="no configuration file"):
        config.load("/nonexistent/run.toml")


def test_incompatible_effects_for_a_cloud_core_are_refused_at_build():
    raw = config.loads(MINIMAL).raw()
    raw["gas"] = {"model": "molecular_cloud", "n": 1e5}
    cfg = config.from_dict(raw)  # preset nebula_ch4 includes radial drift
    with pytest.raises(JaxcoagInputError, match="incompatible with \\[gas\\] model = 'molecular_cloud'"):
        config.build(cfg)


FULL = MINIMAL.replace("[time]\n", "[time]\nn_out = 5\nspacing = \"linear\"\n") + """
[run]
name = "every_key"
description = "all sections"
engine = "mc"
[scene]
effects = ["brownian", "turbulence_oc07"]
turbulence_method = "ya"
focusing = true
drag_regime = "epstein"
drag_convention = "dustpy"
[fragmentation]
model = "shattering"
v_frag = 300.0
q = 1.5
probability = "sigmoid"
width = 0.2
crater_ratio = 8.0
chi = 2.0
[solver]
scheme = "dg"
order = 1
method = "kvaerno5"
rtol = 1e-5
atol = 1e-9
max_steps = 5000
[mc]
seed = 7
grouping = "distribution"
n_bins = 12
m_lo = 1e-12
n_rezoom = 9
count_groups = 4.0
tail_events = 2.5
tail_wmax = 1000.0
volume = "constant_species"
controller = "species"
ns_target = 300
n_particles = 1e25
f_eps = 0.01
capacity = 900
max_events = 123456
rates = "incremental"
n_refresh = 50
neps_rounding = "floor"
p_protect = 4
dedupe = false
merge_weighting = "number"
leftover = "stochastic"
[output]
path = "x/y.nc"
figure = false
checkpoint = "x/ck.npz"
"""


def test_every_key_round_trips_through_tomli_w_and_maps_onto_the_engine():
    cfg = config.loads(FULL)
    text = cfg.to_toml()
    assert tomllib.loads(text) == tomllib.loads(FULL) == cfg.explicit
    again = config.loads(text)
    assert again.data == cfg.data and again.explicit == cfg.explicit and again.physics_hash() == cfg.physics_hash()
    # every [mc] key lands on the MonteCarlo field of the same meaning
    e = config.make_engine(cfg)
    assert isinstance(e, jaxcoag.MonteCarlo) and isinstance(e.grouping, jaxcoag.mc.Distribution)
    g = e.grouping
    assert (g.n_bins, g.m_lo, g.n_rezoom, g.count_groups, g.tail_events, g.tail_wmax) == (12, 1e-12, 9, 4.0, 2.5, 1e3)
    assert isinstance(e.volume, jaxcoag.mc.ConstantSpecies) and isinstance(e.volume.controller,
                                                                           jaxcoag.mc.SpeciesController)
    assert (e.ns_target, e.n_particles, e.f_eps, e.capacity, e.max_events) == (300.0, 1e25, 0.01, 900, 123456)
    assert isinstance(e.rates, jaxcoag.mc.IncrementalRates) and e.rates.n_refresh == 50
    assert (e.neps_rounding, e.p_protect, e.dedupe, e.merge_weighting, e.leftover) == ("floor", 4, False, "number",
                                                                                         "stochastic")
    # the binned engine of the same file reads [solver] (DG order 1, explicit Kvaerno5)
    eb = config.make_engine(cfg.replace(**{"run.engine": "binned"}))
    assert isinstance(eb, jaxcoag.Binned) and isinstance(eb.scheme, jaxcoag.binned.DGScheme)
    assert eb.scheme.order == 1 and (eb.rtol, eb.atol, eb.max_steps) == (1e-5, 1e-9, 5000)
    # the outcome of [fragmentation]: Monte Carlo fragments start at the monomer mass
    o = config.make_outcome(cfg["fragmentation"], m0=cfg["dust"]["m0"], engine="mc")
    assert isinstance(o, jaxcoag.outcomes.Shattering) and o.probability_kind == "sigmoid"
    assert (float(o.v_frag), float(o.q), float(o.width), o.crater_ratio, o.chi) == (300.0, 1.5, 0.2, 8.0, 2.0)
    np.testing.assert_allclose(float(o.m_lo), 4 / 3 * math.pi * 1.6e-12, rtol=1e-15)


def test_physics_hash_covers_the_engine_and_only_its_own_section():
    b = config.loads(MINIMAL)
    m = b.replace(**{"run.engine": "mc", "mc.n_particles": 1e20})
    assert m.physics_hash() != b.physics_hash()
    # the Monte Carlo settings do not change a binned run, the solver settings not a Monte Carlo run
    assert b.replace(**{"mc.ns_target": 50}).physics_hash() == b.physics_hash()
    assert m.replace(**{"solver.rtol": 1e-3}).physics_hash() == m.physics_hash()
    assert m.replace(**{"mc.seed": 1}).physics_hash() != m.physics_hash()


def test_monte_carlo_build_objects():
    raw = config.loads(MINIMAL).raw()
    raw["run"] = {"engine": "mc"}
    raw["mc"] = {"seed": 5, "grouping": "equal_mass", "ns_target": 100, "n_particles": 1e30}
    b = config.build(config.from_dict(raw))
    assert isinstance(b.engine, jaxcoag.MonteCarlo) and isinstance(b.engine.grouping, jaxcoag.mc.EqualMass)
    assert isinstance(b.engine.volume, jaxcoag.mc.ConstantVolume) and b.engine.n_particles == 1e30
    np.testing.assert_array_equal(jax.random.key_data(b.key), jax.random.key_data(jax.random.key(5)))
    assert isinstance(b.initial, jaxcoag.Monodisperse)
    np.testing.assert_allclose(float(b.initial.m0), 4 / 3 * math.pi * 1.6e-12, rtol=1e-15)
    np.testing.assert_allclose(float(b.initial.rho_d), 0.01 * float(b.gas.rho_g), rtol=1e-15)
    assert b.outcome is None and b.t_out[0] == 0.0 and b.t_out.size == 13
    # an MRN start: the MRN bins as species, n_particles monomer masses of dust in the volume
    raw["dust"] = {"rho_s": 1.6, "a0": 1e-5, "initial": "mrn", "a_max": 1e-3}
    b = config.build(config.from_dict(raw))
    sp = b.initial
    assert isinstance(sp, jaxcoag.mc.InitialSpecies) and b.engine.n_particles is None
    m0 = 4 / 3 * math.pi * 1.6e-15
    V = 1e30 * m0 / (0.01 * float(b.gas.rho_g))
    np.testing.assert_allclose(float(sp.V), V, rtol=1e-14)
    g = np.asarray(sp.w) * 2.0 ** np.asarray(sp.z)
    np.testing.assert_allclose(np.sum(g * np.asarray(sp.m)), 1e30 * m0, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(sp.m), b.grid.centers[b.n0 > 0], rtol=1e-15)


@pytest.mark.parametrize("patch, words", [
    ("[run]\nengine = \"montecarlo\"\n", ["[run] engine = 'montecarlo' is not one of ['binned', 'mc', 'contact', 'rigid', 'disk']"]),
    ("[run]\nengine = \"mc\"\n", ["missing required parameter [mc] n_particles"]),
    ("[mc]\ngrouping = \"equal\"\n", ["[mc] grouping = 'equal' is not one of", "Did you mean 'equal_mass'"]),
    ("[mc]\ngrouping = \"equal_mass\"\nn_bins = 10\n", ["[mc] n_bins applies to grouping = 'distribution' only"]),
    ("[mc]\ncontroller = \"mass\"\n", ["[mc] controller applies to volume = 'constant_species' only"]),
    ("[mc]\nf_eps = 1.5\n", ["[mc] f_eps must be < 1"]),
    ("[mc]\nns_target = 0\n", ["[mc] ns_target must be > 0"]),
    ("[mc]\nns_target = 10.5\n", ["[mc] ns_target must be an integer"]),
    ("[mc]\nseed = -2\n", ["[mc] seed must be >= 0"]),
    ("[mc]\ndedupe = 1\n", ["[mc] dedupe must be true or false"]),
    ("[mc]\ncount_groups = 0.5\n", ["[mc] count_groups must be >= 1"]),
    ("[mc]\nrates = \"full\"\nn_refresh = 3\n", ["[mc] n_refresh applies to rates = 'incremental' only"]),
    ("[mc]\nseeed = 1\n", ["unknown key 'seeed' in section [mc]", "Did you mean 'seed'"]),
    ("[fragmentation]\nmodel = \"to_monomers\"\nm_frag = 1.0\nq = 2.0\n",
     ["[fragmentation] q applies to model = 'shattering' only"]),
    ("[output]\nfigure = \"yes\"\n", ["[output] figure must be true or false"]),
    ("[scene]\neffects = [\"brownian\", 3]\n", ["[scene] effects must be a list of strings"]),
    ("[scene]\nfocusing = true\n[scene]\n", ["not valid TOML"]),
    ("[solver]\n", []),  # an empty table is fine (all defaults)
])
def test_every_refusal_names_its_key(patch, words):
    text = MINIMAL + patch
    if not words:
        assert config.loads(text)["solver"]["rtol"] == 1e-6
        return
    with pytest.raises(JaxcoagInputError) as e:
        config.loads(text)
    for w in words:
        assert w in str(e.value), (w, str(e.value))
    assert "\n" not in str(e.value)  # one line
