"""Load a runnable script (examples/, paper_figs/) as a module, for tests that call its main()."""

import importlib.util
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]


def load_script(path, prefix="_script_"):
    """Import the file at ``path`` under the module name ``prefix + stem`` and return the module."""
    path = pathlib.Path(path)
    spec = importlib.util.spec_from_file_location(f"{prefix}{path.stem}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
