"""The binned engine carries its step size across solves (checkpoint segments, continued
results) and names the time integrator it used.

Before the carry every segment restarted from dt0 = 1e-3 of the collision time and climbed back
by the controller's factor 10 per step; now a segmented run takes about the steps of one solve.
"""

import numpy as np
import pytest

import jaxcoag
from jaxcoag import checkpoint as CK
from jaxcoag import kernels as K
from jaxcoag._validate import JaxcoagInputError

# constant kernel K = 1 cm^3 s^-1 from monomers m0 = 1 g, N0 = 1 cm^-3: N(t) = N0 / (1 + K N0 t / 2)
# (Smoluchowski 1916); 20 log-spaced outputs over 4 decades of time (t = 0.01 ... 100 s = 50 t_coll).
# The grid and engine are those of tests/test_checkpoint.py, and every solve here has one output
# time (segments, or one solve to t_end): one compiled program, shared with that file's runs.
GRID = jaxcoag.MassGrid.log(10 ** -0.0625, 10 ** 4.9375, 8)
KERN = K.Constant(1.0)
INIT = jaxcoag.Monodisperse(1.0, 1.0)
T_OUT = np.geomspace(1e-2, 1e2, 20)


def _steps(res):
    return int(res.stats["steps"]) + int(res.stats["rejected"])


@pytest.fixture(scope="module")
def runs():
    eng = jaxcoag.Binned(GRID)
    one = jaxcoag.evolve(KERN, eng, INIT, T_OUT[-1:])  # one solve to t_end: the steps of an uninterrupted run
    seg = jaxcoag.evolve(KERN, eng, INIT, T_OUT, max_segments=len(T_OUT))  # one solve per output time
    return one, seg


def test_segmented_run_takes_the_steps_of_one_solve(runs):
    """20 segments (one per output time, as `jaxcoag run` and checkpoints go) vs one solve to the
    end (accepted + rejected steps): with the carried step 57 vs 44, i.e. at most one step more per
    segment (the step an output time cuts in two); before the carry 89 vs 44 (each segment climbed
    back from dt0 = 1e-3 t_coll). The default `jaxcoag run` box: the slow test below. The outputs
    follow N(t) = 1 / (1 + t / 2) to 1e-4, the mass is conserved, and both end in the same state
    to the tolerance."""
    one, seg = runs
    assert _steps(seg) <= _steps(one) + len(T_OUT), (_steps(seg), _steps(one))
    np.testing.assert_allclose(np.asarray(seg.moments(0)), 1.0 / (1.0 + 0.5 * T_OUT), rtol=1e-4)
    for r in (one, seg):
        assert np.max(np.abs(np.asarray(r.mass_drift))) < 1e-12
    rho1, rho2 = np.asarray(one.mass_per_bin())[-1], np.asarray(seg.mass_per_bin())[-1]
    assert np.max(np.abs(rho2 - rho1)) < 1e-5 * rho1.sum()  # rtol 1e-6 per step
    # the step carried out is the controller's step at the end: ~t_end / 10 here, far above dt0 ~ 2e-3 s
    assert 1.0 < float(seg.dt) < 100.0 and np.isclose(float(seg.dt), float(one.dt), rtol=0.5)


def test_continuing_a_result_goes_on_with_its_step(runs):
    """evolve(result, more times) starts from result.dt, so splitting a run in two costs at most
    the step cut at the joint (+1 over the segmented run), and the continuation follows the same
    solution."""
    _, seg = runs
    eng = jaxcoag.Binned(GRID)
    first = jaxcoag.evolve(KERN, eng, INIT, T_OUT[:10], max_segments=10)
    assert float(first.final_state["dt"]) == float(first.dt) > 0
    rest = jaxcoag.evolve(KERN, eng, first, T_OUT[10:], max_segments=10)
    assert _steps(first) + _steps(rest) <= _steps(seg) + 1, (_steps(first), _steps(rest), _steps(seg))
    np.testing.assert_allclose(np.asarray(rest.moments(0)), 1.0 / (1.0 + 0.5 * T_OUT[10:]), rtol=1e-4)
    np.testing.assert_array_equal(np.asarray(rest.y), np.asarray(seg.y)[10:])  # the same steps exactly


def test_checkpoint_stores_the_step_and_an_old_checkpoint_is_refused(runs, tmp_path):
    """The checkpoint's state holds "dt"; resuming after 7 of 20 segments reproduces the
    uninterrupted checkpointed run bit for bit; a checkpoint written before the carry existed
    (state without "dt") is refused with a message naming the missing leaf and what to do."""
    _, seg = runs
    path = tmp_path / "run.npz"
    eng = jaxcoag.Binned(GRID)
    part = jaxcoag.evolve(KERN, eng, INIT, T_OUT, checkpoint=path, max_segments=7)
    assert float(part.dt) > 0
    full = jaxcoag.evolve(KERN, eng, INIT, T_OUT, checkpoint=path)
    np.testing.assert_array_equal(np.asarray(full.y), np.asarray(seg.y))
    assert float(full.dt) == float(seg.dt) and _steps(full) == _steps(seg)
    # an old-format checkpoint: the same run's first 7 outputs, state without "dt"
    st = eng._init(KERN, INIT, 0.0, None, None)
    old_state = {"y": part.y[-1], "t": part.t[-1], "M0": st["M0"]}
    outs = {"y": part.y, "status": np.zeros(7, np.int32), "steps": np.zeros(7, np.int32),
            "rejected": np.zeros(7, np.int32)}
    outs = {k: np.asarray(v, np.asarray(full.stats["steps"]).dtype) if k in ("status", "steps", "rejected") else v
            for k, v in outs.items()}
    old = tmp_path / "old.npz"
    CK.save(old, fingerprint=CK.run_fingerprint(KERN, eng, INIT, T_OUT, t0=0.0, outcome=None, key=None),
            state=old_state, outs=outs)
    with pytest.raises(JaxcoagInputError, match=r"does not fit this run .*state\['dt'\].*start afresh"):
        jaxcoag.evolve(KERN, eng, INIT, T_OUT, checkpoint=old)


def test_solver_is_stated():
    """BinnedResult.solver and the netCDF attribute `solver` name the integrator: Tsit5 for pure
    coagulation, Rodas4 with fragmentation (the automatic choices), the class name of a
    solver given (the fragmentation and user-solver runs: the slow test below)."""
    import diffrax

    from jaxcoag.binned import LinearlyImplicitEuler

    pure = jaxcoag.evolve(KERN, jaxcoag.Binned(GRID), INIT, np.array([2.0]))
    assert pure.solver == "Tsit5" and pure.to_xarray().attrs["solver"] == "Tsit5"
    np.testing.assert_allclose(float(pure.moments(0)[-1]), 1.0 / 2.0, rtol=1e-5)  # N(2 s) = 1 / (1 + 1)
    assert jaxcoag.Binned(GRID).solver_name(jaxcoag.ShatterAbove(10.0, 1.0)) == "Rodas4"
    assert jaxcoag.Binned(GRID).solver_name(jaxcoag.Sticking()) == jaxcoag.Binned(GRID).solver_name() == "Tsit5"
    user = jaxcoag.Binned(GRID, solver=LinearlyImplicitEuler())
    assert user.solver_name(jaxcoag.ShatterAbove(10.0, 1.0)) == user.solver_name() == "LinearlyImplicitEuler"
    assert jaxcoag.Binned(GRID, solver=diffrax.Dopri5()).solver_name() == "Dopri5"


@pytest.mark.slow
def test_fragmentation_and_user_solver_runs_state_their_solver():
    """A fragmentation run states Rodas4 and a run with LinearlyImplicitEuler states that
    name, in the result and its dataset; mass conserved, and the constant-kernel run follows
    N(1 s) = 1 / 1.5 to the first-order scheme's accuracy (~20 s: two more compilations; the
    default test above checks the same names through Binned.solver_name)."""
    from jaxcoag.binned import LinearlyImplicitEuler

    g = jaxcoag.MassGrid.log(10 ** -0.25, 10 ** 1.75, 2)
    t = np.array([0.5, 1.0])
    frag = jaxcoag.evolve(KERN, jaxcoag.Binned(g, rtol=1e-4), INIT, t, outcome=jaxcoag.ShatterAbove(10.0, 1.0))
    assert frag.solver == "Rodas4" and frag.to_xarray().attrs["solver"] == "Rodas4"
    assert np.max(np.abs(np.asarray(frag.mass_drift))) < 1e-10
    lie = jaxcoag.evolve(KERN, jaxcoag.Binned(g, solver=LinearlyImplicitEuler()), INIT, t)
    assert lie.solver == "LinearlyImplicitEuler" and lie.to_xarray().attrs["solver"] == "LinearlyImplicitEuler"
    np.testing.assert_allclose(float(lie.moments(0)[-1]), 1.0 / 1.5, rtol=2e-2)


@pytest.mark.slow
def test_default_run_box_segmented_vs_one_solve():
    """The default `jaxcoag run` box (1 AU MMSN growth + fragmentation, 135 bins, Rodas4,
    17 outputs to 1e4 yr) in its 17 checkpoint segments vs one solve saving every output:
    measured 211 + 3 rejected vs 196 + 3 steps (1.075x; before the carry 223 + 3, 1.14x), the
    outputs agreeing to 1.3e-6 of the total mass (rtol 1e-6). ~2.5 min on 2 cores; the default test
    test_segmented_run_takes_the_steps_of_one_solve covers the same code on a small box."""
    from jaxcoag import config as cfgmod

    b = cfgmod.build(cfgmod.default())
    one = jaxcoag.evolve(b.kernel, b.engine, b.initial, b.t_out, outcome=b.outcome)
    seg = jaxcoag.evolve(b.kernel, b.engine, b.initial, b.t_out, outcome=b.outcome, max_segments=len(b.t_out))
    assert _steps(seg) <= 1.1 * _steps(one), (_steps(seg), _steps(one))
    a, s = np.asarray(one.mass_per_bin()), np.asarray(seg.mass_per_bin())
    assert np.max(np.abs(a - s)) < 1e-5 * a.sum(axis=1).max()
    for r in (one, seg):
        assert np.max(np.abs(np.asarray(r.mass_drift))) < 1e-12
