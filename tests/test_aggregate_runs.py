"""``jaxcoag run`` with the particle-level engines: ``[run] engine = "contact"`` (Wada et al. 2007 DEM) and
``"rigid"`` (Richardson 1995 box), through the one TOML schema, the CLI and the runner."""

import math

import numpy as np
import pytest

from jaxcoag import config
from jaxcoag._validate import JaxcoagInputError


def test_contact_and_rigid_configs_validate_and_fill_defaults():
    c = config.default("contact")
    assert c.engine == "contact" and c["contact"]["n"] == 64 and c["contact"]["v_imp_v0"] == 4.0
    assert c["gas"] is None  # the coagulation sections are neither needed nor invented
    # the shipped TOML round-trips through the writer
    assert config.loads(c.to_toml()) == c
    r = config.from_dict({"run": {"engine": "rigid"}, "rigid": {"model": "v"}})
    assert (r["rigid"]["n0"], r["rigid"]["r0"], r["rigid"]["t_end"]) == (9000, 0.033, 40.8)  # R95 Table I, model (v)
    assert config.default("rigid")["rigid"]["n0"] == 1000
    # the physics hash reads only the engine's own section
    h = c.physics_hash()
    assert c.replace(**{"run.name": "other"}).physics_hash() == h
    assert c.replace(**{"contact.v_imp_v0": 5.0}).physics_hash() != h
    # a binned config switched to the contact engine runs the default collision (its [gas] etc. are ignored)
    sw = config.default().replace(**{"run.engine": "contact"})
    assert sw["contact"]["material"] == "ice"


@pytest.mark.parametrize("raw, match", [
    ({"run": {"engine": "mc"}}, r"missing section \[gas\]"),
    ({"run": {"engine": "contact"}, "contact": {"n": 100}}, r"\[contact\] n = 100 must be a power of 2"),
    ({"run": {"engine": "contact"}, "contact": {"v_imp": 100.0, "v_imp_v0": 2.0}}, r"not both"),
    ({"run": {"engine": "contact"}, "contact": {"dt_tc": 0.5}}, r"stability limit"),
    ({"run": {"engine": "contact"}, "contact": {"material": "iron"}}, r"is not one of \['ice', 'quartz'\]"),
    ({"run": {"engine": "rigid"}, "rigid": {"model": "vi"}}, r"\[rigid\] model = 'vi' is not one of"),
    ({"run": {"engine": "rigid"}, "rigid": {"n0": 0}}, r"\[rigid\] n0 must be > 0"),
])
def test_bad_particle_configs_are_refused_naming_the_key(raw, match):
    with pytest.raises(JaxcoagInputError, match=match):
        config.from_dict(raw)


def test_contact_material_overrides():
    from jaxcoag.aggregates.contact import materials
    from jaxcoag.aggregates.runs import contact_material

    c = dict(config.default("contact")["contact"])
    assert float(contact_material(c).gamma) == float(materials.ice().gamma)
    c.update(material="quartz", gamma=50.0)
    m = contact_material(c)
    q = materials.quartz()
    assert float(m.gamma) == 50.0 and float(m.E) == float(q.E) and float(m.G) == float(q.G)
    # F_c = 3 pi gamma R scales linearly with gamma (Wada et al. 2007 eq. 5)
    assert math.isclose(float(m.F_c) / float(q.F_c), 2.0, rel_tol=1e-14)


@pytest.mark.slow  # suite budget (28 s); the contact engine through evolve stays in tests/test_contact_*.py
def test_contact_run_writes_netcdf_figure_and_summary(tmp_path):
    from jaxcoag import runner
    from jaxcoag.io import load_netcdf

    cfg = config.from_dict({"run": {"engine": "contact", "name": "t"},
                            "contact": {"n": 8, "dt_tc": 0.112, "n_records": 20, "v_imp_v0": 3.0}})
    out = tmp_path / "c.nc"
    res = runner.run(cfg, out=out, progress=False, verbose=False)
    assert res.finished and not res.failed and res.numbers["result"] == "successful"
    n = res.numbers
    # E_imp = (N_total/8) (v/v0)^2 F_c delta_c for two equal aggregates at +-v/2 (Wada et al. 2007 §4)
    mat = res.built["material"]
    e_unit = float(mat.F_c) * float(mat.delta_c)
    assert math.isclose(n["E_imp_erg"], 16 / 8 * 3.0**2 * e_unit, rel_tol=1e-12)
    assert math.isclose(n["x_roll"], n["E_imp_erg"] / (14 * float(mat.E_roll)), rel_tol=1e-12)
    assert n["N_total"] == 16 and 1 <= n["N_large"] <= 16 and int(np.sum(res.result.cluster_sizes)) == 16
    assert n["energy_error"] < 1e-2  # dt = 0.112 t_c: Wada et al. quote < 1e-3 of the total for such steps
    ds = load_netcdf(str(out))
    assert ds.attrs["engine"] == "dem" and ds.sizes["t"] == 20 and ds.attrs["summary_N_total"] == 16
    assert (tmp_path / "c.png").stat().st_size > 10_000
    # the record ends at the default end: the gap closed plus 8 r_g,tot / v_imp, whole steps of dt
    t = ds["t"].values
    assert np.all(np.diff(t) > 0) and math.isclose(t[-1] / (0.112 * float(mat.t_c)), round(t[-1] / (0.112 * float(mat.t_c))),
                                                   abs_tol=1e-6)


@pytest.mark.slow
def test_rigid_cli_run_model_i(tmp_path):
    from jaxcoag.cli import main
    from jaxcoag.io import load_netcdf

    out = tmp_path / "box.nc"
    rc = main(["run", "--engine", "rigid", "--quick", "--out", str(out), "--no-progress"])
    assert rc == 0
    ds = load_netcdf(str(out))
    n = ds["n_aggregates"].values
    assert ds.sizes["t"] == 8 and n[0] <= 200 and np.all(np.diff(n) <= 0)
    # every collision merges two aggregates (model i): N + N_C = N0 exactly
    np.testing.assert_array_equal(n + ds["n_c"].values, 200)
