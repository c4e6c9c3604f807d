"""JAX's persistent compilation cache (``jaxcoag.enable_compilation_cache``, on by default in
``jaxcoag run`` / ``jaxcoag sweep``): a second process loads the compiled programs instead of
compiling them again; an unwritable directory or ``JAXCOAG_CACHE_DIR=off`` leaves the run uncached.

The cache's own counters are read with ``jax.monitoring`` event listeners in the child processes:
"/jax/compilation_cache/cache_hits" (an executable loaded from disk) and
"/jax/compilation_cache/cache_misses" (recorded when an executable is *written* to the cache,
jax/_src/compilation_cache.py ``put_executable_and_time``).
"""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import jaxcoag
from jaxcoag import _cache

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

_SOLVE = textwrap.dedent("""
    def solve(jc, np):
        # a grid no other test uses (bins_per_decade 2.5): the parent compiles it afresh
        grid = jc.MassGrid.log(10 ** -0.2, 1e6, 2.5)
        res = jc.evolve(jc.kernels.Constant(1.0), jc.Binned(grid, rtol=1e-8, atol=1e-12), jc.Monodisperse(1.0, 1.0),
                        np.array([4.0]))
        return np.asarray(res.moments(0)).tolist(), np.asarray(res.moments(1)).tolist()
""")

_CHILD = _SOLVE + textwrap.dedent("""
    import json, sys
    import jax
    import jax.monitoring as mon
    jax.config.update("jax_enable_x64", True)
    ev = {}
    mon.register_event_listener(lambda e, **k: ev.__setitem__(e, ev.get(e, 0) + 1))
    import numpy as np
    import jaxcoag as jc
    import time
    from jaxcoag.runner import CompileClock
    used = jc.enable_compilation_cache(sys.argv[1])
    t0 = time.perf_counter()
    with CompileClock() as clock:
        m0, m1 = solve(jc, np)
    wall = time.perf_counter() - t0
    print(json.dumps(dict(used=used, hits=ev.get("/jax/compilation_cache/cache_hits", 0),
                          writes=ev.get("/jax/compilation_cache/cache_misses", 0), m0=m0, m1=m1, wall=wall,
                          compile_s=clock.compile_s, trace_lower_s=clock.trace_lower_s)))
""")


class _Events:
    """Counts of jax.monitoring events while open."""

    def __init__(self):
        self.n = {}

    def _on(self, event, **kw):
        self.n[event] = self.n.get(event, 0) + 1

    def __enter__(self):
        import jax.monitoring

        jax.monitoring.register_event_listener(self._on)
        return self

    def __exit__(self, *exc):
        import jax.monitoring

        jax.monitoring.unregister_event_listener(self._on)


@pytest.mark.slow
def test_second_process_loads_the_compiled_solve_from_the_cache(tmp_path):
    """(slow: two child processes, ~10 s; the slow CLI test below covers the same path through `jaxcoag
    run`.) A fresh process compiles a binned solve (constant kernel, 15 bins, one output time as in a
    `jaxcoag run` segment) with an empty cache directory and writes it there, the solve program
    included; a second process running the same solve with that directory loads the programs (hits,
    no writes: nothing compiled again) and gets bit-identical numbers, which follow Smoluchowski's
    constant-kernel law N(t) = N0 / (1 + K N0 t / 2) with the mass conserved. Both sides are child
    processes with the same environment: a pytest worker that already ran other tests compiled this
    solve under another cache key (measured in CI: 32 writes and no hits in the reader)."""
    cache = tmp_path / "jaxcache"
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("JAXCOAG_CACHE_DIR", None)

    def child():
        r = subprocess.run([sys.executable, "-c", _CHILD, str(cache)], capture_output=True, text=True, env=env,
                           timeout=300)
        assert r.returncode == 0, r.stderr
        return json.loads(r.stdout.strip().splitlines()[-1])

    a = child()
    entries = [f for f in os.listdir(cache) if not f.startswith(".")]
    assert a["used"] == str(cache) and a["writes"] >= 5 and len(entries) >= a["writes"]
    assert any(f.startswith("jit__solve_impl-") for f in entries)  # the solve itself (no host callbacks in it)
    # the runner's compile clock saw the XLA compilations, which are part of the wall time
    assert 0.0 < a["compile_s"] < a["wall"] and 0.0 < a["trace_lower_s"] < a["wall"]
    b = child()
    assert b["used"] == str(cache) and b["writes"] == 0 and b["hits"] >= 1
    np.testing.assert_allclose(a["m0"], [1.0 / (1.0 + 0.5 * 4.0)], rtol=1e-6)
    np.testing.assert_allclose(a["m1"], 1.0, rtol=1e-12)
    assert b["m0"] == a["m0"] and b["m1"] == a["m1"]  # a loaded executable computes what the compiled one did


def test_unwritable_or_switched_off_cache_runs_uncached(tmp_path, monkeypatch):
    """A directory that cannot be created gives a RuntimeWarning naming it and returns None (no
    error, JAX's config untouched); JAXCOAG_CACHE_DIR=off returns None; the default directory is
    $JAXCOAG_CACHE_DIR, else ~/.cache/jaxcoag/jax."""
    import jax

    before = jax.config.jax_compilation_cache_dir
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    with pytest.warns(RuntimeWarning, match="cannot be written"):
        assert jaxcoag.enable_compilation_cache(blocker / "cache") is None
    monkeypatch.setenv("JAXCOAG_CACHE_DIR", "off")
    assert jaxcoag.enable_compilation_cache() is None and _cache.default_cache_dir() is None
    assert jax.config.jax_compilation_cache_dir == before
    monkeypatch.setenv("JAXCOAG_CACHE_DIR", str(tmp_path / "c"))
    assert _cache.default_cache_dir() == str(tmp_path / "c")
    monkeypatch.delenv("JAXCOAG_CACHE_DIR")
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    assert _cache.default_cache_dir() == os.path.join(os.path.expanduser("~"), ".cache", "jaxcoag", "jax")


@pytest.mark.slow
def test_jaxcoag_run_twice_compiles_once(tmp_path):
    """`jaxcoag run` (the CLI, cache on by default via JAXCOAG_CACHE_DIR) twice on a small
    config in two processes: the second writes nothing to the cache, loads from it, and reports
    less compile-or-load time; with --no-cache nothing is read or written. (~30 s; the default
    test above covers the same cache path through jaxcoag.evolve.)"""
    from _configs import SMALL

    cfg = tmp_path / "small.toml"
    cfg.write_text(SMALL)
    cache = tmp_path / "jaxcache"
    code = textwrap.dedent("""
        import json, sys
        import jax.monitoring as mon
        ev = {}
        mon.register_event_listener(lambda e, **k: ev.__setitem__(e, ev.get(e, 0) + 1))
        from jaxcoag import cli
        rc = cli.main(sys.argv[1:])
        print(json.dumps(dict(rc=rc, hits=ev.get("/jax/compilation_cache/cache_hits", 0),
                              writes=ev.get("/jax/compilation_cache/cache_misses", 0))))
    """)
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""),
               JAXCOAG_CACHE_DIR=str(cache))

    def run(*extra):
        r = subprocess.run([sys.executable, "-c", code, "run", str(cfg), "--no-progress", "--no-figure",
                            "--no-checkpoint", "--out", str(tmp_path / "r.nc"), *extra], capture_output=True,
                           text=True, env=env, timeout=600)
        assert r.returncode == 0, r.stderr
        lines = r.stdout.strip().splitlines()
        t = [ln for ln in lines if ln.startswith("time: set-up")][0]
        return json.loads(lines[-1]), float(t.split("XLA compile or cache load ")[1].split(" s")[0])

    a, ca = run()
    b, cb = run()
    assert a["rc"] == b["rc"] == 0 and a["writes"] >= 50 and b["writes"] == 0 and b["hits"] >= a["writes"]
    assert cb < ca
    n = len(os.listdir(cache))
    c, _ = run("--no-cache")
    assert c["hits"] == c["writes"] == 0 and len(os.listdir(cache)) == n
