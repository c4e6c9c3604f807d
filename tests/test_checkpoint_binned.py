"""Binned checkpoint/resume: a resumed run equals the uninterrupted one bit for bit; a checkpoint
of another configuration is refused; checkpoints are written atomically after every segment."""

import os

import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag import checkpoint, config, runner
from jaxcoag.binned import RESULTS
from jaxcoag._validate import JaxcoagInputError

# growth + fragmentation at 1 AU on a coarse grid: same physics as the default run, seconds to solve
TOML = """
[gas]
model = "mmsn_hayashi81"
R_au = 1.0
alpha = 1e-3
[dust]
rho_s = 1.6
a0 = 1e-4
[grid]
m_max = 1e5
bins_per_decade = 3
[fragmentation]
v_frag = 1000.0
[solver]
rtol = 1e-4
[time]
t_end_yr = 1000.0
n_out = 5
t_first_yr = 3.0
"""


@pytest.fixture(scope="module")
def cfg():
    return config.loads(TOML)


@pytest.fixture(scope="module")
def full(cfg, tmp_path_factory):
    d = tmp_path_factory.mktemp("full")
    return runner.run(cfg, out=str(d / "run.nc"), progress=False, verbose=False, figure=False)


def test_uninterrupted_run_reaches_fragmentation_equilibrium(full):
    sol = full.solution
    assert full.finished and not full.failed and bool(sol.result == RESULTS.successful)
    assert np.max(np.abs(np.asarray(sol.mass_drift))) < 1e-10
    mp = np.array([r["m_peak"] for r in full.rows])
    assert mp[-1] > 1e6 * mp[0]  # grew from 1 um monomers ...
    np.testing.assert_allclose(mp[-1], mp[-2], rtol=1e-3)  # ... to a fragmentation-limited steady state
    # the checkpoint holds every output state
    ck = checkpoint.load_checkpoint(full.checkpoint)
    np.testing.assert_array_equal(ck["ys"], np.asarray(sol.ys))
    assert ck["steps"].size == 5 and ck["result_code"] == 0


def test_resume_after_stop_equals_uninterrupted_bitwise(cfg, full, tmp_path):
    out = str(tmp_path / "run.nc")
    part = runner.run(cfg, out=out, progress=False, verbose=False, figure=False, max_segments=2)
    assert not part.finished and part.solution.ys.shape[0] == 3
    np.testing.assert_array_equal(np.asarray(part.solution.ys), np.asarray(full.solution.ys)[:3])
    res = runner.run(cfg, out=out, progress=False, verbose=False, figure=False, resume=True)
    assert res.finished and res.resumed_from == 2
    np.testing.assert_array_equal(np.asarray(res.solution.ys), np.asarray(full.solution.ys))
    np.testing.assert_array_equal(np.asarray(res.solution.mass_per_bin), np.asarray(full.solution.mass_per_bin))
    assert int(res.solution.stats["steps"]) == int(full.solution.stats["steps"])


def test_kill_mid_run_leaves_a_valid_checkpoint_and_resume_matches(cfg, full, tmp_path):
    b = config.build(cfg)
    y0 = b.scheme.init(b.grid, jnp.asarray(b.n0))
    ck = str(tmp_path / "k.npz")
    kw = dict(scheme=b.scheme, fragmentation=b.fragmentation, solver=b.solver, rtol=b.rtol, atol=b.atol,
              max_steps=b.max_steps, checkpoint=ck, config_hash=cfg.physics_hash())

    def killer(k, t, y):
        if k == 3:
            raise KeyboardInterrupt  # simulated kill after the 3rd segment was checkpointed

    with pytest.raises(KeyboardInterrupt):
        checkpoint.integrate(b.kernel, b.grid, y0, b.ts, on_segment=killer, **kw)
    assert checkpoint.load_checkpoint(ck)["ys"].shape[0] == 4
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".tmp")]  # no temporary files left
    seg = checkpoint.integrate(b.kernel, b.grid, y0, b.ts, resume=True, **kw)
    assert seg.finished and seg.resumed_from == 3
    np.testing.assert_array_equal(np.asarray(seg.solution.ys), np.asarray(full.solution.ys))


def test_mismatched_or_broken_checkpoint_is_refused(cfg, full, tmp_path):
    other = cfg.replace(**{"gas.alpha": 2e-3})
    with pytest.raises(JaxcoagInputError, match="different run configuration"):
        runner.run(other, out=str(tmp_path / "x.nc"), checkpoint=full.checkpoint, resume=True, progress=False,
                   verbose=False)
    assert not (tmp_path / "x.nc").exists()
    moved = cfg.replace(**{"time.n_out": 4})
    with pytest.raises(JaxcoagInputError, match="different run configuration"):
        checkpoint.load_checkpoint(full.checkpoint, config_hash=moved.physics_hash())
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(JaxcoagInputError, match="is truncated or not a jaxcoag checkpoint"):
        checkpoint.load_checkpoint(bad)
    with pytest.raises(JaxcoagInputError, match="no checkpoint file"):
        checkpoint.load_checkpoint(tmp_path / "missing.npz")
