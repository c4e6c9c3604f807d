"""TOML run configurations: defaults, round trip, building, and one refusal per error category."""

import math

import numpy as np
import pytest

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
    assert b.ts[0] == 0.0 and b.ts.size == 17
    np.testing.assert_allclose(b.ts[[1, -1]], [C.yr, 1e4 * C.yr], rtol=1e-12)
    assert b.scene.effect_names == ("brownian", "turbulence", "radial_drift")


def test_minimal_config_fills_defaults_and_round_trips():
    cfg = config.loads(MINIMAL)
    assert not cfg.has_fragmentation
    assert cfg["scene"]["preset"] == "nebula_ch4" and cfg["dust"]["dust_to_gas"] == 0.01
    assert cfg["time"]["n_out"] == 12 and cfg["solver"]["rtol"] == 1e-6
    again = config.loads(cfg.to_toml())
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
