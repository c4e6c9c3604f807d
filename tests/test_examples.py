"""Every script in examples/ runs in quick mode and returns checked numbers."""

import numpy as np
import pytest
from _scripts import ROOT, load_script

EXAMPLES = sorted((ROOT / "examples").glob("[0-9][0-9]_*.py"))


def test_there_are_examples():
    assert len(EXAMPLES) >= 1


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_quick(path, capsys):
    out = load_script(path, "_example_").main(["--quick"])
    assert isinstance(out, dict) and out
    printed = capsys.readouterr().out
    assert printed.strip()
    if path.stem == "01_velocities_and_kernel":
        np.testing.assert_allclose(out["grad"], out["fd"], rtol=1e-6)
