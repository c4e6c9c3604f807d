"""Smoke run of benchmarks/run_process.py (`jaxcoag run --quick` twice in fresh processes with one
cache directory): the warm run writes nothing to the compilation cache, loads from it, spends
less time compiling, and prints the same numbers as the cold run."""

import json
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.mark.slow
def test_run_process_quick_cold_then_warm(tmp_path):
    """~40 s (two `jaxcoag run --quick` processes); the default suite covers the cache through
    tests/test_cli_cache.py."""
    from benchmarks import run_process as R

    out = tmp_path / "rp.json"
    R.main(["--quick", "--no-peers", "--out", str(out)])
    d = json.loads(out.read_text())
    cold, warm = d["ours_cold"], d["ours_warm"]
    assert cold["rc"] == warm["rc"] == 0 and cold["status"] == warm["status"] == "successful"
    assert cold["cache_writes"] >= 50 and warm["cache_writes"] == 0 and warm["cache_hits"] >= cold["cache_writes"]
    assert warm["compile_s"] < 0.5 * cold["compile_s"]
    assert warm["steps"] == cold["steps"] and warm["m_peak_final"] == cold["m_peak_final"]
    assert cold["solver"] == "Rodas4"
    # the process split adds up to the wall clock (the rest: interpreter start and exit, < 5 s)
    assert 0.0 <= warm["other_s"] < 5.0
