"""Every script in examples/ runs in quick mode and returns checked numbers."""

import importlib.util
import pathlib

import numpy as np
import pytest

EXAMPLES = sorted((pathlib.Path(__file__).resolve().parents[1] / "examples").glob("[0-9][0-9]_*.py"))


def _load(path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_there_are_examples():
    assert len(EXAMPLES) >= 1


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_quick(path, capsys):
    out = _load(path).main(["--quick"])
    assert isinstance(out, dict) and out
    printed = capsys.readouterr().out
    assert printed.strip()
    if path.stem == "01_velocities_and_kernel":
        np.testing.assert_allclose(out["grad"], out["fd"], rtol=1e-6)
