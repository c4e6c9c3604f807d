"""Resumable Monte Carlo runs: resume_from and run_checkpointed equal one uninterrupted run bitwise
(snapshots and PRNG in docs/design_notes.md; issue 6 "a resumed run equals an uninterrupted one")."""

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag import kernels as K
from jaxcoag import mc
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.mc import checkpoint as CK

T_OUT = jnp.array([0.5, 1.0, 1.5, 2.0, 2.5, 3.0])
# grouped equal-mass run: maintenance (rezoom, refresh every S events, merging) is exercised.
# Every run in this file uses this configuration with 6 or 3 output times (two compilations);
# the stop predicate's ratio is an array leaf, so other ratios reuse them.
NEVER = mc.Runaway(1e300, kind="species")
KW = dict(n_particles=1e20, grouping="equal_mass", ns_target=48, f_eps=1e-3, capacity=160, stop=NEVER)
KERN = K.Sum(0.5)
KEY = jax.random.key(7)
FIELDS = ("m", "logm", "psi", "w", "z", "valid", "V", "logV", "M_tot", "n_events_snap")


def _leaf(x):
    return np.asarray(jax.random.key_data(x) if jnp.issubdtype(x.dtype, jax.dtypes.prng_key) else x)


def _assert_same(a, b, t_len=None):
    for f in FIELDS:
        np.testing.assert_array_equal(np.asarray(getattr(a, f)), np.asarray(getattr(b, f)), err_msg=f)
    for f in ("status", "n_events", "n_dup", "n_merge"):
        assert int(getattr(a, f)) == int(getattr(b, f)), f
    for f in a.final_state._fields:
        if f in ("snaps", "k_out"):  # k_out = number of snapshots of the last call
            continue
        np.testing.assert_array_equal(_leaf(getattr(a.final_state, f)), _leaf(getattr(b.final_state, f)), err_msg=f)


@pytest.fixture(scope="module")
def full():
    return mc.run(KERN, t_out=T_OUT, key=KEY, **KW)


def test_resume_from_equals_uninterrupted(full):
    assert int(full.n_events) > KW["capacity"] and int(full.status) == 0  # > 1 periodic full refresh
    a = mc.run(KERN, t_out=T_OUT[:3], key=KEY, **KW)
    b = mc.run(KERN, t_out=T_OUT[3:], key=None, resume_from=a.final_state, **KW)
    for f in FIELDS:
        np.testing.assert_array_equal(np.concatenate([np.asarray(getattr(a, f)), np.asarray(getattr(b, f))]),
                                      np.asarray(getattr(full, f)), err_msg=f)
    assert int(b.n_events) == int(full.n_events) and int(a.n_events) < int(full.n_events)
    for f in full.final_state._fields:
        if f not in ("snaps", "k_out"):
            np.testing.assert_array_equal(_leaf(getattr(b.final_state, f)), _leaf(getattr(full.final_state, f)))
    # a resumed state's time precedes the new output times; refusing an earlier time or another key
    with pytest.raises(JaxcoagInputError, match="precedes"):
        mc.run(KERN, t_out=jnp.array([0.1, 5.0]), resume_from=a.final_state, **KW)
    with pytest.raises(JaxcoagInputError, match="key"):
        mc.run(KERN, t_out=T_OUT[3:], key=jax.random.key(8), resume_from=a.final_state, **KW)
    with pytest.raises(JaxcoagInputError, match="capacity"):
        mc.run(KERN, t_out=T_OUT[3:], resume_from=a.final_state, **{**KW, "capacity": 200})


def test_checkpointed_interrupted_and_resumed_equals_uninterrupted(full, tmp_path, monkeypatch, capsys):
    path = tmp_path / "run.npz"
    calls = {"n": 0}
    real_run = CK.run

    def flaky(*args, **kw):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt("simulated kill during segment 2")
        return real_run(*args, **kw)

    monkeypatch.setattr(CK, "run", flaky)
    with pytest.raises(KeyboardInterrupt):
        mc.run_checkpointed(KERN, t_out=T_OUT, key=KEY, checkpoint=path, every=3, progress=False, **KW)
    ck = mc.load_checkpoint(path)
    assert ck["n_done"] == 3 and ck["snaps"]["m"].shape[0] == 3
    assert [p.name for p in tmp_path.iterdir()] == ["run.npz"]  # no temporary file left behind
    monkeypatch.setattr(CK, "run", real_run)

    res = mc.run_checkpointed(KERN, t_out=T_OUT, key=KEY, checkpoint=path, every=3, progress=True, **KW)
    err = capsys.readouterr().err
    assert "ev/s" in err and "Ns=" in err and "mc.run" in err
    _assert_same(res, full)
    assert dict(res.config)["n_snap"] == T_OUT.shape[0] and res.config == full.config
    # a third call finds every segment done and returns the same result from the file
    again = mc.run_checkpointed(KERN, t_out=T_OUT, key=KEY, checkpoint=path, every=3, progress=False, **KW)
    _assert_same(again, full)
    # mismatched arguments are refused (f_eps, key, t_out)
    for bad in (dict(KW, f_eps=2e-3),):
        with pytest.raises(JaxcoagInputError, match="different arguments"):
            mc.run_checkpointed(KERN, t_out=T_OUT, key=KEY, checkpoint=path, every=3, progress=False, **bad)
    with pytest.raises(JaxcoagInputError, match="different arguments"):
        mc.run_checkpointed(KERN, t_out=T_OUT, key=jax.random.key(8), checkpoint=path, progress=False, **KW)
    with pytest.raises(JaxcoagInputError, match="different arguments"):
        mc.run_checkpointed(K.Sum(0.25), t_out=T_OUT, key=KEY, checkpoint=path, progress=False, **KW)
    # no file: a segmented run with a progress bar only, same result
    nofile = mc.run_checkpointed(KERN, t_out=T_OUT, key=KEY, checkpoint=None, every=3, progress=False, **KW)
    _assert_same(nofile, full)
    with pytest.raises(JaxcoagInputError, match="every"):
        mc.run_checkpointed(KERN, t_out=T_OUT, key=KEY, checkpoint=path, every=0, **KW)
    assert os.path.exists(path)


def test_stop_predicate_and_halts_survive_resume(full):
    """Stop predicate semantics (STATUS.STOPPED, t_stop, later snapshots repeat the stopped state,
    identical trajectory before the stop) and: a run halted by the predicate or by the event
    budget stays halted when resumed, so the continuation equals the uninterrupted run."""
    l1, l2 = full.log_largest_two("species")
    r = float(np.exp(l1[3] - l2[3]))  # the species ratio reached by snapshot 3 (> 1: masses are distinct)
    assert r > 1.0
    stop = mc.Runaway(r, kind="species")
    kw = dict(KW, stop=stop)
    st = mc.run(KERN, t_out=T_OUT, key=KEY, **kw)
    assert int(st.status) == mc.STATUS.STOPPED and mc.status_names(st.status) == ["STOPPED"]
    ts = float(st.t_stop)
    assert 0.0 < ts <= float(T_OUT[3]) and float(st.final_state.t) == ts
    before = np.asarray(T_OUT) < ts
    assert np.all(~before[3:])
    np.testing.assert_array_equal(np.asarray(st.m)[before], np.asarray(full.m)[before])
    np.testing.assert_array_equal(np.asarray(st.w)[before], np.asarray(full.w)[before])
    for k in np.flatnonzero(~before):  # stopped state repeated; it satisfies the predicate
        np.testing.assert_array_equal(np.asarray(st.w[k]), np.asarray(st.final_state.w))
        a1, a2 = st.log_largest_two("species")
        assert float(a1[k] - a2[k]) >= np.log(r) - 1e-12
    assert np.isnan(float(full.t_stop))
    # resume of a stopped run
    a = mc.run(KERN, t_out=T_OUT[:3], key=KEY, **kw)
    b = mc.run(KERN, t_out=T_OUT[3:], resume_from=a.final_state, **kw)
    np.testing.assert_array_equal(np.concatenate([a.m, b.m]), np.asarray(st.m))
    assert float(b.t_stop) == ts and int(b.n_events) == int(st.n_events)
    # resume of a run that spent its event budget (max_events counts the whole run)
    nmax = int(full.n_events_snap[1]) + 5
    fb = mc.run(KERN, t_out=T_OUT, key=KEY, max_events=nmax, **KW)
    assert int(fb.status) == mc.STATUS.MAX_EVENTS and int(fb.n_events) == nmax
    a = mc.run(KERN, t_out=T_OUT[:3], key=KEY, max_events=nmax, **KW)
    b = mc.run(KERN, t_out=T_OUT[3:], resume_from=a.final_state, max_events=nmax, **KW)
    np.testing.assert_array_equal(np.concatenate([a.w, b.w]), np.asarray(fb.w))
    assert int(b.n_events) == nmax and int(b.status) == mc.STATUS.MAX_EVENTS


@pytest.mark.slow
def test_vmapped_resume_equals_vmapped_run():
    """resume_from works inside jax.vmap (batched final states) and equals the batched full run."""
    keys = jax.random.split(jax.random.key(3), 4)
    kw = dict(n_particles=200, mode="const_n", capacity=220)
    kern = K.Constant(1.0)
    t = jnp.array([0.5, 1.0, 2.0, 4.0])
    full = jax.vmap(lambda k: mc.run(kern, t_out=t, key=k, **kw))(keys)
    a = jax.vmap(lambda k: mc.run(kern, t_out=t[:2], key=k, **kw))(keys)
    b = jax.vmap(lambda s: mc.run(kern, t_out=t[2:], resume_from=s, **kw))(a.final_state)
    for f in ("m", "w", "z", "valid", "V", "M_tot"):
        np.testing.assert_array_equal(np.concatenate([getattr(a, f), getattr(b, f)], axis=1),
                                      np.asarray(getattr(full, f)), err_msg=f)
    np.testing.assert_array_equal(np.asarray(b.n_dup), np.asarray(full.n_dup))
    with pytest.raises(JaxcoagInputError, match="batch"):
        mc.run(kern, t_out=t[2:], resume_from=a.final_state, **kw)
