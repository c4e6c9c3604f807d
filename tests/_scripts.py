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


def run_quick_figure(path, tmp_path):
    """Run a paper_figs script in --quick mode into ``tmp_path`` and assert its contract: a real PNG (> 10 kB)
    and every counted check ok. Returns the script's result dict."""
    res = load_script(path, "_paper_fig_").main(["--quick", "--out", str(tmp_path)])
    png = pathlib.Path(res["png"])
    assert png.exists() and png.stat().st_size > 10_000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = {k: v for k, v in res["checks"].items() if v["counts"] and not v["ok"]}
    assert not bad, bad
    assert res["all_ok"]
    return res
