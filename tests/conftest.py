"""Strict test configuration (house style, docs/design_notes.md): float64 and no silent rank promotion."""

import os

os.environ.setdefault("XLA_FLAGS", "")
# `jaxcoag run` / `jaxcoag sweep` turn on JAX's persistent compilation cache (~/.cache/jaxcoag/jax); tests that
# call the CLI in this process must not switch it on for the whole session (every later compile would be
# written to disk). tests/test_cli_cache.py sets its own directories.
os.environ.setdefault("JAXCOAG_CACHE_DIR", "off")
import jax

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
