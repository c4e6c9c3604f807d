"""One checkpoint/resume module for every engine (jaxcoag.checkpoint).

- a structural run fingerprint: independent of reprs and of the process, different for another
  parameter, class, grid, output time or key;
- checkpoints written atomically after every segment; Ctrl-C -> RunInterrupted with the completed
  segments saved; max_segments; a resumed run equals the uninterrupted checkpointed one bit for bit
  (np.array_equal on every array of the result), for the binned and the Monte Carlo engine;
- refusals, before any work, with one line naming the file and what to do: missing, truncated,
  random bytes, empty, foreign npz, an older format, incomplete, NaN where finite numbers were
  written, checksum, other structure, other configuration.
"""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcoag
from jaxcoag import checkpoint as CK
from jaxcoag import kernels as K
from jaxcoag import mc
from jaxcoag._validate import JaxcoagInputError, is_traced

# ------------------------------------------------------------------------------------------ binned set-up
# constant kernel K = 1 cm^3 s^-1, monodisperse m0 = 1 g (a bin centre), N0 = 1 cm^-3, outputs up to
# t = 20 s (10 collision times 2/(K N0)); 8 bins per decade; one compiled segment solve.
GRID = jaxcoag.MassGrid.log(10 ** -0.0625, 10 ** 4.9375, 8)
KERN = K.Constant(1.0)
INIT = jaxcoag.Monodisperse(1.0, 1.0)
T_OUT = np.array([0.5, 1.0, 2.0, 5.0, 10.0, 20.0])
BINNED = jaxcoag.Binned(GRID)

# ------------------------------------------------------------------------------------------ MC set-up
# grouped equal-mass run of the sum kernel (rezoom, periodic full refresh and merging are exercised),
# 6 outputs in 2 segments of 3 (one compilation for every MC run here).
# Every MC run here has 6 or 3 output times (two compilations); the stop predicate's ratio and the
# event budget are array leaves, so other values reuse them.
MC_KERN = K.Sum(0.5)
NEVER = mc.Runaway(1e300, kind="species")
MC_T = np.array([0.5, 1.0, 1.5, 2.0, 2.5, 3.0])
MC_KEY = jax.random.key(7)
MC_FIELDS = ("m", "logm", "psi", "w", "z", "valid", "V", "logV", "M_tot", "n_events_snap")


def _mc_engine(**kw):
    return jaxcoag.MonteCarlo(**(dict(grouping=mc.EqualMass(), n_particles=1e20, ns_target=48, f_eps=1e-3,
                                      capacity=160, stop=NEVER) | kw))


MC_ENGINE = _mc_engine()


def _binned(path, **kw):
    return jaxcoag.evolve(KERN, BINNED, INIT, T_OUT, checkpoint=path, **kw)


def _mc(path, engine=MC_ENGINE, **kw):
    kw.setdefault("every", 3)
    return jaxcoag.evolve(MC_KERN, engine, INIT, MC_T, key=MC_KEY, checkpoint=path, **kw)


def _leaves(res):
    """Every array of a result (PRNG keys as their data) with its key path."""
    pairs, _ = jax.tree_util.tree_flatten_with_path(res, is_leaf=CK._is_key)
    return [(jax.tree_util.keystr(p), np.asarray(jax.random.key_data(x) if CK._is_key(x) else x)) for p, x in pairs]


def _assert_bitwise(a, b, skip=()):
    la, lb = _leaves(a), _leaves(b)
    assert len(la) > 5 and [p for p, _ in la] == [p for p, _ in lb]
    for (p, x), (_, y) in zip(la, lb):
        if p in skip:
            continue
        assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y, equal_nan=x.dtype.kind in "fc"), p


def _only_traced(monkeypatch, cls):
    """Let ``cls._advance`` be traced (the outputs' template) but never run."""
    real = cls._advance

    def advance(self, kernel, state, *a):
        if not is_traced(state):
            raise AssertionError("a segment ran")
        return real(self, kernel, state, *a)

    monkeypatch.setattr(cls, "_advance", advance)


def _no_tmp(d):
    return [f for f in os.listdir(d) if f.endswith(".tmp")] == []


@pytest.fixture(scope="module")
def binned_full(tmp_path_factory):
    path = tmp_path_factory.mktemp("binned") / "full.npz"
    return _binned(path), path


@pytest.fixture(scope="module")
def mc_plain():
    """The uninterrupted MC run in one advance (no checkpoint)."""
    return jaxcoag.evolve(MC_KERN, MC_ENGINE, INIT, MC_T, key=MC_KEY)


@pytest.fixture(scope="module")
def mc_full(tmp_path_factory):
    path = tmp_path_factory.mktemp("mc") / "full.npz"
    return _mc(path), path


# ------------------------------------------------------------------------------------------ fingerprint
def test_fingerprint_ignores_repr_and_changes_with_every_parameter(monkeypatch):
    fp = lambda kern=KERN, eng=BINNED, init=INIT, t=T_OUT, t0=0.0, key=None, out=None: CK.run_fingerprint(  # noqa: E731
        kern, eng, init, t, t0=t0, outcome=out, key=key)
    base = fp()
    assert len(base) == 64 and base == fp()
    # reprs are not used: addresses or a changed __repr__ leave it unchanged
    monkeypatch.setattr(K.Constant, "__repr__", lambda self: f"<Constant at {id(self):#x}>")
    monkeypatch.setattr(jaxcoag.MassGrid, "__repr__", lambda self: f"<MassGrid at {id(self):#x}>")
    monkeypatch.setattr(jaxcoag.Binned, "__repr__", lambda self: "changed")
    assert fp() == base and fp(kern=K.Constant(1.0), eng=jaxcoag.Binned(jaxcoag.MassGrid(GRID.log_edges))) == base
    monkeypatch.undo()
    # structure and numbers do change it
    others = [fp(kern=K.Constant(float(np.nextafter(1.0, 2.0)))),  # one ulp
              fp(kern=K.Sum(1.0)),  # another class
              fp(eng=jaxcoag.Binned(jaxcoag.MassGrid.log(10 ** -0.0625, 10 ** 4.9375, 9))),  # another grid
              fp(eng=jaxcoag.Binned(GRID, rtol=1e-7)),  # another field value
              fp(eng=jaxcoag.Binned(GRID, scheme=jaxcoag.binned.DGScheme(order=1))),  # another scheme
              fp(init=jaxcoag.Monodisperse(1.0, 2.0)), fp(t=np.r_[T_OUT[:-1], 21.0]), fp(t0=0.1),
              fp(key=jax.random.key(7)), fp(key=jax.random.key(8)), fp(out=jaxcoag.outcomes.Sticking()),
              fp(out=jaxcoag.outcomes.ShatterAbove(100.0, 1.0)), fp(out=jaxcoag.outcomes.ShatterAbove(100.0, 2.0))]
    assert len({base, *others}) == len(others) + 1
    # Python scalars by type and exact value; functions by name and closed-over values
    assert CK.fingerprint(1) != CK.fingerprint(1.0) != CK.fingerprint(True)
    mk = lambda p: (lambda m: m ** p)  # noqa: E731
    assert CK.fingerprint(mk(2.0)) == CK.fingerprint(mk(2.0)) != CK.fingerprint(mk(3.0))


def test_fingerprint_is_the_same_in_another_process(tmp_path):
    code = ("import jax; jax.config.update('jax_enable_x64', True); import numpy as np, jaxcoag; "
            "from jaxcoag import checkpoint as CK, kernels as K, mc; "
            "g = jaxcoag.MassGrid.log(10 ** -0.0625, 10 ** 4.9375, 8); "
            "e = jaxcoag.MonteCarlo(grouping=mc.EqualMass(), n_particles=1e20, ns_target=48, f_eps=1e-3, "
            "capacity=160, stop=mc.Runaway(1e300, kind='species')); "
            "print(CK.fingerprint(jaxcoag.Binned(g), K.Constant(1.0), e, jaxcoag.Monodisperse(1.0, 1.0), "
            "np.array([0.5, 1.0, 2.0, 5.0, 10.0, 20.0]), jax.random.key(7)))")
    env = dict(os.environ, PYTHONHASHSEED="12345")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env,
                       cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split()[-1] == CK.fingerprint(BINNED, KERN, MC_ENGINE, INIT, T_OUT, MC_KEY)


# ------------------------------------------------------------------------------------------ binned
def test_binned_checkpointed_run_is_right_and_the_file_holds_every_output(binned_full):
    res, path = binned_full
    assert bool(res.status == jaxcoag.RESULTS.successful)
    np.testing.assert_array_equal(np.asarray(res.t), T_OUT)
    # the segments' outputs are joined on the host, the result holds JAX arrays as an unsegmented run does
    assert all(isinstance(getattr(res, k), jax.Array) for k in ("y", "rho", "n", "gel_mass", "mass_drift"))
    # Smoluchowski with a constant kernel: N(t) = N0 / (1 + K N0 t / 2); mass conserved
    np.testing.assert_allclose(np.asarray(res.moments(0)), 1.0 / (1.0 + 0.5 * T_OUT), rtol=1e-4)
    assert np.max(np.abs(np.asarray(res.mass_drift))) < 1e-12
    info = CK.read_info(path)
    assert info["n_done"] == 6 and info["meta"]["wall_s"].shape == (6,) and int(info["meta"]["every"]) == 1
    state = BINNED._init(KERN, INIT, 0.0, None, None)
    like = jax.eval_shape(lambda s: BINNED._advance(KERN, s, jnp.asarray(T_OUT[:1]), None)[1], state)
    ck = CK.load(path, fingerprint=CK.run_fingerprint(KERN, BINNED, INIT, T_OUT, t0=0.0, outcome=None, key=None),
                 like_state=state, like_outs=like)
    assert ck["n_done"] == 6
    np.testing.assert_array_equal(np.asarray(ck["outs"]["y"]), np.asarray(res.y))
    np.testing.assert_array_equal(np.asarray(ck["state"]["y"]), np.asarray(res.y[-1]))
    assert float(ck["state"]["t"]) == 20.0
    assert int(np.sum(ck["outs"]["steps"])) == int(res.stats["steps"]) >= 6


def test_binned_max_segments_then_resume_equals_uninterrupted_bitwise(binned_full, tmp_path, capsys, monkeypatch):
    full, _ = binned_full
    path = tmp_path / "run.npz"
    part = _binned(path, max_segments=2)
    np.testing.assert_array_equal(np.asarray(part.t), T_OUT[:2])
    np.testing.assert_array_equal(np.asarray(part.y), np.asarray(full.y)[:2])
    assert CK.read_info(path)["n_done"] == 2
    part = _binned(path, max_segments=1)  # continues with one more segment
    np.testing.assert_array_equal(np.asarray(part.t), T_OUT[:3])
    capsys.readouterr()
    res = _binned(path, progress=True)
    err = capsys.readouterr().err
    assert "jaxcoag run" in err and "6/6" in err and "yr" in err
    _assert_bitwise(res, full)
    _only_traced(monkeypatch, jaxcoag.Binned)
    _assert_bitwise(_binned(path), full)  # every segment done: the result from the file alone
    assert _no_tmp(tmp_path)


def test_binned_ctrl_c_saves_the_completed_segments_and_resume_is_bitwise(binned_full, tmp_path, monkeypatch):
    full, _ = binned_full
    path = tmp_path / "run.npz"
    real = jaxcoag.Binned._advance
    calls = []

    def interrupted(self, *a):
        calls.append(1)
        if len(calls) == 4:
            raise KeyboardInterrupt  # Ctrl-C during the 4th segment
        return real(self, *a)

    monkeypatch.setattr(jaxcoag.Binned, "_advance", interrupted)
    with pytest.raises(CK.RunInterrupted) as ei:
        _binned(path)
    e = ei.value
    assert isinstance(e, KeyboardInterrupt)
    assert (e.checkpoint, e.segments_done, e.n_segments) == (os.fspath(path), 3, 6)
    assert CK.read_info(path)["n_done"] == 3 and _no_tmp(tmp_path)
    monkeypatch.undo()
    _assert_bitwise(_binned(path), full)


def test_save_is_atomic(binned_full, tmp_path, monkeypatch):
    """A write interrupted half-way leaves the previous checkpoint byte for byte and no temporary file."""
    _, good = binned_full
    path = tmp_path / "ck.npz"
    path.write_bytes(good.read_bytes())
    before = path.read_bytes()

    def torn(fh, **arrays):
        fh.write(b"PK\x03\x04 half a zip")
        raise KeyboardInterrupt

    monkeypatch.setattr(CK.np, "savez", torn)
    with pytest.raises(KeyboardInterrupt):
        CK.save(path, fingerprint="x", state={"y": jnp.ones(3)}, outs={"y": jnp.ones((2, 3))})
    monkeypatch.undo()
    assert path.read_bytes() == before and os.listdir(tmp_path) == ["ck.npz"]


def _refused(path, fn, *words):
    """fn() raises one line naming the file and every word; the file is left as it was."""
    raw = path.read_bytes() if path.exists() else None
    with pytest.raises(JaxcoagInputError) as ei:
        fn()
    msg = str(ei.value)
    assert "\n" not in msg and str(path) in msg, msg
    for w in words:
        assert w in msg, msg
    assert (path.read_bytes() if path.exists() else None) == raw
    return msg


def _rewrite(src, dst, **changes):
    d = dict(np.load(src))
    for k, v in changes.items():
        if v is None:
            del d[k]
        else:
            d[k] = v
    np.savez(dst, **d)


def test_other_configuration_refused_before_any_work(binned_full, tmp_path, monkeypatch):
    _, good = binned_full
    path = tmp_path / "ck.npz"
    path.write_bytes(good.read_bytes())

    def no_work(*a, **k):
        raise AssertionError("the run started before refusing")

    monkeypatch.setattr(jaxcoag.Binned, "_init", no_work)
    monkeypatch.setattr(jaxcoag.Binned, "_advance", no_work)
    words = ("different run configuration", "delete it", "without --resume", "resume=False")
    for kw in (dict(kernel=K.Constant(2.0)), dict(engine=jaxcoag.Binned(GRID, rtol=1e-7)),
               dict(initial=jaxcoag.Monodisperse(1.0, 2.0)), dict(t_out=np.r_[T_OUT[:-1], 30.0]),
               dict(t0=0.25)):
        args = dict(kernel=KERN, engine=BINNED, initial=INIT, t_out=T_OUT) | kw
        t0 = args.pop("t0", None)
        _refused(path, lambda: jaxcoag.evolve(args["kernel"], args["engine"], args["initial"], args["t_out"], t0=t0,
                                              checkpoint=path), *words)


@pytest.mark.parametrize("kind", ["truncated", "random_bytes", "empty", "foreign_npz", "old_format", "incomplete",
                                  "nan", "checksum"])
def test_damaged_checkpoint_refused_naming_the_file(binned_full, tmp_path, monkeypatch, kind):
    _, good = binned_full
    raw = good.read_bytes()
    bad = tmp_path / "bad.npz"
    d = dict(np.load(good))
    i_y = [str(p) for p in d["paths"]].index("state['y']")
    y = d[f"leaf_{i_y:05d}"].copy()
    if kind == "truncated":
        bad.write_bytes(raw[: len(raw) // 2])
        words = ("is truncated or not a jaxcoag checkpoint",)
    elif kind == "random_bytes":
        bad.write_bytes(np.random.default_rng(12).bytes(4096))
        words = ("is truncated or not a jaxcoag checkpoint",)
    elif kind == "empty":
        bad.write_bytes(b"")
        words = ("is truncated or not a jaxcoag checkpoint",)
    elif kind == "foreign_npz":
        np.savez(bad, a=np.arange(3))
        words = ("is not a jaxcoag-checkpoint-v2 file",)
    elif kind == "old_format":  # a checkpoint of the former binned-only module
        np.savez(bad, format=np.array("jaxcoag-binned-checkpoint-v1"), ys=np.ones((2, 3)))
        words = ("is not a jaxcoag-checkpoint-v2 file",)
    elif kind == "incomplete":
        _rewrite(good, bad, checksum=None)
        words = ("incomplete or inconsistent", "checksum")
    elif kind == "nan":
        y[3] = np.nan
        _rewrite(good, bad, **{f"leaf_{i_y:05d}": y})
        words = ("NaN/inf in [\"state['y']\"]", "corrupted")
    else:  # a finite number changed
        y[3] *= 1.0 + 1e-12
        _rewrite(good, bad, **{f"leaf_{i_y:05d}": y})
        words = ("fail the sha256 checksum",)
    _only_traced(monkeypatch, jaxcoag.Binned)
    _refused(bad, lambda: _binned(bad), *words, "delete it")
    _refused(bad, lambda: CK.read_info(bad), *words)


def test_load_refuses_another_structure_or_a_missing_file(binned_full, tmp_path):
    _, good = binned_full
    fp = CK.read_info(good)["fingerprint"]
    other = jaxcoag.Binned(jaxcoag.MassGrid.log(1.0, 1e3, 4))
    state = other._init(KERN, INIT, 0.0, None, None)
    like = jax.eval_shape(lambda s: other._advance(KERN, s, jnp.asarray(T_OUT[:1]), None)[1], state)
    _refused(good, lambda: CK.load(good, fingerprint=fp, like_state=state, like_outs=like),
             "does not fit this run", "state['y'] has shape (41,), this run needs (13,)")
    _refused(good, lambda: CK.load(good, fingerprint=fp, like_state={"y": state["y"]}, like_outs=like),
             "does not fit this run", "other pytree leaves")
    _refused(good, lambda: CK.load(good, fingerprint="0" * 64, like_state=state, like_outs=like),
             "different run configuration")
    missing = tmp_path / "missing.npz"
    _refused(missing, lambda: CK.load(missing, fingerprint=None, like_state=state, like_outs=like),
             "no checkpoint file")


def test_resume_false_starts_afresh_over_a_bad_file(binned_full, tmp_path):
    full, _ = binned_full
    path = tmp_path / "ck.npz"
    path.write_bytes(b"garbage")
    part = _binned(path, resume=False, max_segments=1)
    np.testing.assert_array_equal(np.asarray(part.y), np.asarray(full.y)[:1])
    assert CK.read_info(path)["n_done"] == 1


# ------------------------------------------------------------------------------------------ Monte Carlo
K_OUT = (".final_state.k_out",)  # number of outputs of the last advance: 6 in one advance, 3 in segments


def test_mc_segmented_checkpointed_run_equals_one_advance_bitwise(mc_full, mc_plain):
    full, full_path = mc_full
    assert int(full.n_events) > 160 and bool(full.status == jaxcoag.RESULTS.successful)  # > 1 full refresh
    assert CK.read_info(full_path)["n_done"] == 6
    _assert_bitwise(full, mc_plain, skip=K_OUT)
    assert int(mc_plain.final_state.k_out) == 6 and int(full.final_state.k_out) == 3


def test_mc_continuation_equals_uninterrupted(mc_plain):
    """evolve(..., initial=previous MCResult) continues bitwise (event keys from the base key and the
    event counter; every maintenance counter lives in the state)."""
    full = mc_plain
    a = jaxcoag.evolve(MC_KERN, MC_ENGINE, INIT, MC_T[:3], key=MC_KEY)
    b = jaxcoag.evolve(MC_KERN, MC_ENGINE, a, MC_T[3:])
    for f in MC_FIELDS:
        np.testing.assert_array_equal(np.concatenate([np.asarray(getattr(a, f)), np.asarray(getattr(b, f))]),
                                      np.asarray(getattr(full, f)), err_msg=f)
    assert int(b.n_events) == int(full.n_events) and int(a.n_events) < int(full.n_events)
    _assert_bitwise(b.final_state, full.final_state, skip=(".k_out",))
    # a continued state's time precedes the new output times; refusing an earlier time, another key
    # or another capacity
    with pytest.raises(JaxcoagInputError, match="precedes"):
        jaxcoag.evolve(MC_KERN, MC_ENGINE, a, np.array([0.1, 5.0]))
    with pytest.raises(JaxcoagInputError, match="key"):
        jaxcoag.evolve(MC_KERN, MC_ENGINE, a, MC_T[3:], key=jax.random.key(8))
    with pytest.raises(JaxcoagInputError, match="capacity"):
        jaxcoag.evolve(MC_KERN, _mc_engine(capacity=200), a, MC_T[3:])


def test_mc_stop_predicate_and_halts_survive_resume(mc_plain, tmp_path, monkeypatch):
    """Stop predicate semantics (status stopped, t_stop, later outputs repeat the stopped state,
    identical trajectory before the stop), and: a run halted by the predicate or by the event budget
    stays halted when continued, so the continuation equals the uninterrupted run; a checkpointed run
    stops after the segment whose status is a failure (max_steps_reached), and resuming it returns
    that result without running."""
    full = mc_plain
    l1, l2 = full.log_largest_two("species")
    r = float(np.exp(l1[3] - l2[3]))  # the species ratio reached by output 3 (> 1: masses are distinct)
    assert r > 1.0
    eng = _mc_engine(stop=mc.Runaway(r, kind="species"))
    st = jaxcoag.evolve(MC_KERN, eng, INIT, MC_T, key=MC_KEY)
    assert bool(st.status == jaxcoag.RESULTS.stopped) and st.flag_names() == ["STOPPED"]
    ts = float(st.t_stop)
    assert 0.0 < ts <= MC_T[3] and float(st.final_state.t) == ts
    before = MC_T < ts
    assert np.all(~before[3:])
    np.testing.assert_array_equal(np.asarray(st.m)[before], np.asarray(full.m)[before])
    np.testing.assert_array_equal(np.asarray(st.w)[before], np.asarray(full.w)[before])
    a1, a2 = st.log_largest_two("species")
    for k in np.flatnonzero(~before):  # the stopped state repeated; it satisfies the predicate
        np.testing.assert_array_equal(np.asarray(st.w[k]), np.asarray(st.final_state.w))
        assert float(a1[k] - a2[k]) >= np.log(r) - 1e-12
    assert np.isnan(float(full.t_stop))
    # continuation and checkpointed run of a stopped run
    a = jaxcoag.evolve(MC_KERN, eng, INIT, MC_T[:3], key=MC_KEY)
    b = jaxcoag.evolve(MC_KERN, eng, a, MC_T[3:])
    np.testing.assert_array_equal(np.concatenate([a.m, b.m]), np.asarray(st.m))
    assert float(b.t_stop) == ts and int(b.n_events) == int(st.n_events)
    _assert_bitwise(_mc(tmp_path / "stop.npz", engine=eng), st, skip=K_OUT)
    # a run that spent its event budget (max_events counts the whole run, continuations included)
    nmax = int(full.n_events_snap[1]) + 5
    eng = _mc_engine(max_events=nmax)
    fb = jaxcoag.evolve(MC_KERN, eng, INIT, MC_T, key=MC_KEY, throw=False)
    assert bool(fb.status == jaxcoag.RESULTS.max_steps_reached) and int(fb.n_events) == nmax
    a = jaxcoag.evolve(MC_KERN, eng, INIT, MC_T[:3], key=MC_KEY, throw=False)
    b = jaxcoag.evolve(MC_KERN, eng, a, MC_T[3:], throw=False)
    np.testing.assert_array_equal(np.concatenate([a.w, b.w]), np.asarray(fb.w))
    assert int(b.n_events) == nmax and bool(b.status == jaxcoag.RESULTS.max_steps_reached)
    ck = _mc(tmp_path / "budget.npz", engine=eng, throw=False)  # stops after the failing first segment
    np.testing.assert_array_equal(np.asarray(ck.t), MC_T[:3])
    np.testing.assert_array_equal(np.asarray(ck.w), np.asarray(fb.w)[:3])
    assert bool(ck.status == jaxcoag.RESULTS.max_steps_reached) and CK.read_info(tmp_path / "budget.npz")["n_done"] == 3
    with monkeypatch.context() as mp:  # resuming a failed run returns the same result without running
        _only_traced(mp, jaxcoag.MonteCarlo)
        _assert_bitwise(_mc(tmp_path / "budget.npz", engine=eng, throw=False), ck)


@pytest.mark.slow
def test_mc_vmapped_continuation_equals_vmapped_run():
    """A result continues inside jax.vmap (batched final states) and equals the batched full run."""
    keys = jax.random.split(jax.random.key(3), 4)
    eng = jaxcoag.MonteCarlo(n_particles=200, volume=mc.ConstantNumber(), capacity=220)
    kern = K.Constant(1.0)
    t = jnp.array([0.5, 1.0, 2.0, 4.0])
    full = jax.vmap(lambda k: jaxcoag.evolve(kern, eng, INIT, t, key=k, throw=False))(keys)
    a = jax.vmap(lambda k: jaxcoag.evolve(kern, eng, INIT, t[:2], key=k, throw=False))(keys)
    b = jax.vmap(lambda r: jaxcoag.evolve(kern, eng, r, t[2:], throw=False))(a)
    for f in ("m", "w", "z", "valid", "V", "M_tot"):
        np.testing.assert_array_equal(np.concatenate([getattr(a, f), getattr(b, f)], axis=1),
                                      np.asarray(getattr(full, f)), err_msg=f)
    np.testing.assert_array_equal(np.asarray(b.n_dup), np.asarray(full.n_dup))
    with pytest.raises(JaxcoagInputError, match="batch"):
        jaxcoag.evolve(kern, eng, a, t[2:])


def test_mc_ctrl_c_and_resume_equal_the_uninterrupted_run_bitwise(mc_full, tmp_path, monkeypatch, capsys):
    full, _ = mc_full
    path = tmp_path / "run.npz"
    real = jaxcoag.MonteCarlo._advance
    calls = []

    def interrupted(self, *a):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt  # Ctrl-C during the second segment
        return real(self, *a)

    monkeypatch.setattr(jaxcoag.MonteCarlo, "_advance", interrupted)
    with pytest.raises(CK.RunInterrupted) as ei:
        _mc(path)
    assert (ei.value.checkpoint, ei.value.segments_done, ei.value.n_segments) == (os.fspath(path), 1, 2)
    assert CK.read_info(path)["n_done"] == 3 and os.listdir(tmp_path) == ["run.npz"]
    monkeypatch.undo()
    capsys.readouterr()
    res = _mc(path, progress=True)
    assert "2/2" in capsys.readouterr().err
    _assert_bitwise(res, full)
    _only_traced(monkeypatch, jaxcoag.MonteCarlo)
    _assert_bitwise(_mc(path), full)  # all done: from the file alone
    monkeypatch.undo()
    # the first segment alone (max_segments) is the uninterrupted run's first three outputs
    part = _mc(tmp_path / "part.npz", max_segments=1)
    np.testing.assert_array_equal(np.asarray(part.t), MC_T[:3])
    np.testing.assert_array_equal(np.asarray(part.w), np.asarray(full.w)[:3])


def test_mc_refusals(mc_full, tmp_path):
    _, good = mc_full
    path = tmp_path / "ck.npz"
    path.write_bytes(good.read_bytes())
    for kw in (dict(key=jax.random.key(8)), dict(kern=K.Sum(0.25)),
               dict(engine=_mc_engine(f_eps=2e-3))):
        _refused(path, lambda: jaxcoag.evolve(kw.get("kern", MC_KERN), kw.get("engine", MC_ENGINE), INIT, MC_T,
                                              key=kw.get("key", MC_KEY), checkpoint=path, every=3),
                 "different run configuration")
    # NaN in the state's weights (finite when written)
    d = dict(np.load(good))
    i_w = [str(p) for p in d["paths"]].index("state.w")
    w = d[f"leaf_{i_w:05d}"].copy()
    w[0] = np.nan
    bad = tmp_path / "nan.npz"
    np.savez(bad, **(d | {f"leaf_{i_w:05d}": w}))
    _refused(bad, lambda: _mc(bad), "NaN/inf in ['state.w']", "delete it")


def test_nan_written_by_the_run_and_prng_keys_round_trip(tmp_path):
    """A NaN the run itself wrote (e.g. a failed state) is data, not corruption; PRNG keys come back
    as keys of the same implementation; every leaf comes back bit for bit."""
    path = tmp_path / "ck.npz"
    state = {"x": jnp.array([1.0, np.nan, -0.0]), "k": jax.random.key(3), "n": jnp.int32(7)}
    outs = {"status": jnp.array([0, 2], jnp.int32), "y": jnp.array([[1.5, np.inf], [2.5, 3.5]])}
    CK.save(path, fingerprint="abc", state=state, outs=outs, meta={"note": "x", "wall_s": [0.5, 0.25]})
    ck = CK.load(path, fingerprint="abc", like_state=state, like_outs=outs)
    assert ck["n_done"] == 2 and str(ck["meta"]["note"]) == "x" and ck["meta"]["wall_s"].tolist() == [0.5, 0.25]
    for a, b in zip(_leaves((ck["state"], ck["outs"])), _leaves((state, outs))):
        assert a[0] == b[0] and a[1].dtype == b[1].dtype and np.array_equal(a[1], b[1], equal_nan=True), a[0]
    assert np.signbit(np.asarray(ck["state"]["x"])[2])
    assert CK._is_key(ck["state"]["k"]) and str(jax.random.key_impl(ck["state"]["k"])) == "threefry2x32"
    assert float(jax.random.uniform(ck["state"]["k"])) == float(jax.random.uniform(jax.random.key(3)))


class _Clock(jaxcoag._engine.AbstractEngine):
    """A minimal engine (state: the segments done) whose progress time is in its own units."""

    @property
    def name(self):
        return "clock"

    def _check(self, kernel, initial, t_out, t0, outcome, key):
        pass

    def _init(self, kernel, initial, t0, outcome, key):
        return jnp.zeros((), jnp.int32)

    def _advance(self, kernel, state, t_seg, outcome):
        return state + 1, {"status": jnp.zeros(t_seg.shape, jnp.int32), "t": t_seg}

    def _result(self, kernel, t, outs, state, outcome):
        return outs

    def _progress_time(self, t):
        return f"T = {t:.4g}"


def test_progress_bar_time_in_each_engines_units(capsys):
    """The progress bar writes the simulated time through the engine's _progress_time: years for the
    coagulation engines (times in s), seconds for the contact DEM, the box's units for rigid aggregates."""
    from jaxcoag.aggregates import contact, rigid
    from jaxcoag.constants import yr

    out = CK.run_segments(None, _Clock(), None, np.array([1.0, 2.0, 3.5]), t0=0.0, outcome=None, key=None,
                          progress=True, desc="clock")
    np.testing.assert_array_equal(np.asarray(out["t"]), [1.0, 2.0, 3.5])
    err = capsys.readouterr().err
    assert "T = 3.5" in err and " yr" not in err
    assert mc.MonteCarlo(n_particles=10.0)._progress_time(2.0 * yr) == "t = 2 yr"
    assert contact.DEM()._progress_time(3e-9) == "t = 3e-09 s"
    assert rigid.RigidBox()._progress_time(8.2) == "T = 8.2"
