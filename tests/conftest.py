"""Strict test configuration (house style, docs/design_notes.md): float64 and no silent rank promotion."""

import os

os.environ.setdefault("XLA_FLAGS", "")
import jax

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
