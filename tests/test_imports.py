"""A fresh install works: every module imports, and every package the code imports is declared.

The suite runs in the environment that ``pip install -e ".[test]"`` built from ``pyproject.toml``
(``.ci/run`` builds it fresh), so importing every module of the package here fails when a runtime
dependency is missing from the environment. The second check is stricter: it reads the import
statements of the package, the examples, the paper figures, the benchmarks and the tests, maps each
third-party top-level module to the distribution that provides it, and requires that distribution to
be declared in ``pyproject.toml`` (runtime code in ``[project] dependencies``, tests in the ``test``
extra, peer comparisons in the ``peers`` extra). A package that happens to be installed by hand on a
developer's machine therefore cannot hide a missing declaration.
"""

from __future__ import annotations

import ast
import importlib
import importlib.metadata as md
import pkgutil
import re
import sys
from pathlib import Path

import pytest

import jaxcoag

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]


def _all_modules():
    names = [jaxcoag.__name__]
    for info in pkgutil.walk_packages(jaxcoag.__path__, prefix="jaxcoag."):
        names.append(info.name)
    return sorted(names)


MODULES = _all_modules()


def test_module_list_covers_the_package_tree():
    # every .py file under jaxcoag/ is one importable module (no file hidden from walk_packages)
    files = sorted(p for p in (ROOT / "jaxcoag").rglob("*.py") if "__pycache__" not in p.parts)
    expected = set()
    for p in files:
        rel = p.relative_to(ROOT).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        expected.add(".".join(parts))
    assert expected == set(MODULES)
    assert len(MODULES) >= 40


@pytest.mark.parametrize("name", MODULES)
def test_every_module_imports(name):
    mod = importlib.import_module(name)
    assert mod.__name__ == name


def _requirement_names(reqs):
    out = set()
    for r in reqs:
        name = re.split(r"[\s<>=!~;\[(]", r.strip(), maxsplit=1)[0]
        out.add(name.lower().replace("_", "-"))
    return out


def _declared():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    runtime = _requirement_names(meta["dependencies"])
    extras = {k: _requirement_names(v) for k, v in meta.get("optional-dependencies", {}).items()}
    return runtime, extras


def _top_level_imports(path: Path):
    tree = ast.parse(path.read_text(), filename=str(path))
    mods = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                mods.add(a.name.split(".")[0])
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            mods.add(node.module.split(".")[0])
    return mods


_STDLIB = set(sys.stdlib_module_names)
# modules of this repository itself (the package, helper modules of scripts and tests)
_OWN = {"jaxcoag", "benchmarks", "_common", "_scripts", "_testkernels", "conftest"}


def _private_helpers():
    """Helper modules of the scripts and tests (``_name.py`` in paper_figs/, benchmarks/, examples/, tests/), which
    scripts put on sys.path themselves (e.g. paper_figs/_rigid_models.py, imported by benchmarks/rigid_models.py)."""
    return {p.stem for d in ("paper_figs", "benchmarks", "examples", "tests") if (ROOT / d).is_dir()
            for p in (ROOT / d).rglob("_*.py") if p.stem != "__init__"}


def _third_party(paths):
    own_scripts = {p.stem for p in paths} | _private_helpers()
    found = {}
    for p in paths:
        for m in _top_level_imports(p):
            if m in _STDLIB or m in _OWN or m in own_scripts:
                continue
            found.setdefault(m, []).append(str(p.relative_to(ROOT)))
    return found


def _distributions(module: str):
    dists = md.packages_distributions().get(module)
    return {d.lower().replace("_", "-") for d in dists} if dists else set()


# Imports guarded by a version check in the code (tomllib on Python < 3.11)
_CONDITIONAL = {"tomli"}


# Peer codes run side by side in benchmarks (never needed by the package): module -> the distribution
# of the `peers` extra that provides it (simframe is DustPy's framework, installed with it).
_PEER_MODULES = {"dustpy": "dustpy", "simframe": "dustpy", "PySDM": "pysdm"}


def _check(paths, allowed, what, peers=frozenset()):
    problems = []
    for mod, where in sorted(_third_party(paths).items()):
        if mod in _CONDITIONAL and mod in allowed:
            continue
        if mod in _PEER_MODULES:
            if _PEER_MODULES[mod] not in peers:
                problems.append(f"{mod} (imported by {where[0]}) is a peer code, not declared in the peers extra")
            continue
        dists = _distributions(mod)
        if not dists:
            problems.append(f"{mod} (imported by {where[0]}) is not installed by pyproject.toml's {what}")
        elif not dists & allowed:
            problems.append(f"{mod} (distribution {sorted(dists)}, imported by {where[0]}) is not declared in {what}")
    assert not problems, "\n".join(problems)


def _py(folder):
    return sorted(p for p in (ROOT / folder).rglob("*.py") if "__pycache__" not in p.parts)


def test_package_imports_are_declared_runtime_dependencies():
    runtime, _ = _declared()
    _check(_py("jaxcoag"), runtime, "[project] dependencies")


def test_examples_figures_and_benchmarks_need_only_runtime_dependencies():
    runtime, extras = _declared()
    _check(_py("examples") + _py("paper_figs"), runtime, "[project] dependencies")
    # benchmarks may also run the peer codes of the `peers` extra (DustPy, PySDM) side by side
    _check(_py("benchmarks"), runtime, "[project] dependencies", peers=extras.get("peers", set()))


def test_tests_need_only_runtime_and_test_dependencies():
    runtime, extras = _declared()
    _check(_py("tests"), runtime | extras["test"], "dependencies + the test extra")


def test_netcdf_backend_is_usable():
    # h5netcdf imports without h5py; writing needs h5py. A fresh install must write a file.
    import h5py  # noqa: F401
    import xarray as xr
    import numpy as np
    import tempfile, os

    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "x.nc")
        xr.Dataset({"y": ("t", np.arange(3.0))}).to_netcdf(p, engine="h5netcdf")
        with xr.open_dataset(p, engine="h5netcdf") as ds:
            np.testing.assert_array_equal(ds["y"].values, [0.0, 1.0, 2.0])


# Private API of other libraries: a leading-underscore module or attribute of a third-party package,
# or equinox Enumeration internals reached through our own RESULTS.
_PRIVATE = re.compile(
    r"(\b(?:from|import)\s+(?:diffrax|equinox|optax|optimistix|lineax|jax|xarray|numpy|scipy)(?:\.\w+)*\._\w+"
    r"|\b(?:diffrax|equinox|eqx|optax|optx|optimistix|lineax|lx|jax|jnp|xr|xarray)\._[A-Za-z]\w*"
    r"|\._(?:name_to_item|index_to_message|base_offsets|value)\b)")


def test_no_private_api_of_other_libraries():
    files = _py("jaxcoag") + _py("tests") + _py("examples") + _py("paper_figs") + _py("benchmarks")
    me = Path(__file__).resolve()
    hits = []
    for p in files:
        if p.resolve() == me:
            continue
        for n, line in enumerate(p.read_text().splitlines(), start=1):
            if _PRIVATE.search(line):
                hits.append(f"{p.relative_to(ROOT)}:{n}: {line.strip()}")
    assert not hits, "private API of another library:\n" + "\n".join(hits)


def test_private_api_detector_flags_each_form():
    bad = ["from diffrax._local_interpolation import X", "RESULTS._name_to_item", "x = item._value",
           "import jax._src.core", "eqx._enum"]
    good = ["from diffrax import LocalLinearInterpolation", "self._value_cache = 1", "jax.numpy", "_attr_value(v)"]
    assert all(_PRIVATE.search(s) for s in bad)
    assert not any(_PRIVATE.search(s) for s in good)
