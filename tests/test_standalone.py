"""The repository stands alone: no tracked text file points to the planning notes outside it.

Docstrings and comments cite papers and equation numbers (e.g. "Ormel & Cuzzi (2007), eq. 28",
"Ormel (2008, thesis), eq. 5.12") and, for our own numerical-hazard notes and the errata of the
sources, ``docs/design_notes.md``. A reference to a specification file that is not in the
repository (a spec directory, a shared folder above the checkout, or "spec" followed by a
section sign) is a dangling pointer for every reader of the package; this test lists each one.
"""

import pathlib
import re
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]

# Built from pieces so that this file does not match its own patterns.
_SPEC = "spec"
_SHARED = "shared"
FORBIDDEN = (
    _SPEC + "/",
    _SHARED + "/" + _SPEC,
    "../" + _SHARED,
    _SPEC + " \u00a7",
    "/work/" + _SHARED,
)
# the planning notes' file names (and the shared design guide), mentioned without their folder
FORBIDDEN_RE = re.compile(r"\b(velocities|collisions|montecarlo|particles|disk|DESIGN)\.md\b")


def _tracked_files():
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: the tracked-file list is unavailable")
    out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    return [ROOT / p for p in out.decode("utf-8").split("\0") if p]


def _text(path):
    """File content as text, or None for binary files (a NUL byte or invalid UTF-8)."""
    try:
        raw = path.read_bytes()
    except OSError:  # listed by git but deleted in the work tree
        return None
    if b"\0" in raw:
        return None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return None


def offenders(files, root=ROOT, this=pathlib.Path(__file__).resolve()):
    """(path relative to ``root``, line number, line) of every line with a forbidden reference."""
    found = []
    for path in files:
        if path.resolve() == this:
            continue
        text = _text(path)
        if text is None:
            continue
        for n, line in enumerate(text.splitlines(), start=1):
            if any(s in line for s in FORBIDDEN) or FORBIDDEN_RE.search(line):
                found.append((path.relative_to(root).as_posix(), n, line.strip()))
    return found


def test_detector_flags_each_pattern(tmp_path):
    """The detector finds every pattern (and nothing in clean text): 5 + 1 hits, 0 false ones."""
    bad = tmp_path / "bad.py"
    bad.write_text("\n".join([
        "# see " + _SPEC + "/velocities" + ".md",
        "# see " + _SHARED + "/" + _SPEC,
        "# see ../" + _SHARED + "/x",
        "# see " + _SPEC + " \u00a74.3",
        "# see /work/" + _SHARED + "/seeds",
        "# see montecarlo" + ".md",
        "# Ormel & Cuzzi (2007), eq. 28; docs/design_notes.md; PartitionSpec; specs; spec_from_file",
    ]), encoding="utf-8")
    (tmp_path / "blob.bin").write_bytes(b"\0" + (_SPEC + "/").encode())
    hits = offenders([bad, tmp_path / "blob.bin"], root=tmp_path)
    assert [n for _, n, _ in hits] == [1, 2, 3, 4, 5, 6]


def test_no_references_to_files_outside_the_repository():
    files = _tracked_files()
    assert len(files) > 50  # the listing really covers the repository
    found = offenders(files)
    report = "\n".join(f"{p}:{n}: {line}" for p, n, line in found)
    assert not found, f"{len(found)} references to files outside the repository:\n{report}"
