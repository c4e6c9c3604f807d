"""The whole `jaxcoag run` process on its built-in default, cold and warm compilation cache, beside
DustPy's own run of the closest box it can express.

Ours: ``python -m jaxcoag.cli run [--quick] --no-progress --out <tmp>/run.nc`` in a fresh process,
twice, with ``JAXCOAG_CACHE_DIR`` pointing at an empty temporary directory: the first run ("cold")
compiles and fills JAX's persistent compilation cache, the second ("warm") loads from it. Wall
clock of the whole process (interpreter start to exit) from outside; the wrapper ends the process as the
``jaxcoag`` command does (``jaxcoag.cli.exit_now``: flushed output, no interpreter teardown); inside, it records
the import time of ``jaxcoag.cli`` and the runner prints its split (``jaxcoag.runner.run``'s
timings: set-up = configuration, kernel and grid build; solve = the evolve call, of which XLA
compile or cache load and trace + lower; output = dataset, netCDF, figure, summary). The
cache's own event counters (``jax.monitoring``: cache hits, cache writes) are recorded too.

The default run (``jaxcoag config``): MMSN (Hayashi 1981) midplane at 1 AU (T = 280 K,
Sigma_g = 1700 g cm^-2, alpha = 1e-3), 1 um grains (rho_s = 1.6), dust-to-gas 0.01, Brownian +
Ormel & Cuzzi (2007) turbulence + radial-drift relative velocities with Ormel's Epstein/Stokes drag
(c_s, 1/(n sigma)), Maxwellian shattering + erosion at v_frag = 10 m/s, two-bin scheme, 7 bins per
decade up to 1e8 g (135 bins), the engine's implicit default (Rodas4) at rtol 1e-6, 17 outputs to 1e4 yr.

DustPy cannot run this box exactly: its Stokes number uses the thermal speed and
1/(sqrt(2) n sigma) (St 1/1.596 of Ormel's convention at equal size, hard-wired), its kernel is
vertically integrated over size-dependent dust scale heights, and its radial-drift relative
velocity comes from the pressure gradient of its own disk model. So DustPy runs the closest box it
can express, its 1-AU growth-fragmentation box of ``peers/dustpy_boxes.py`` (``--problems
frag1au``; a true 0-D box: no gas evolution, no drift, dust scale heights H_p/sqrt(2) so the column
kernel is the midplane kernel), with the default run's v_frag = 10 m/s, mass grid (7 per decade; DustPy
spans whole decades, so 20 decades from the monomer to 6.7e8 g, 141 bins) and end time 1e4 yr, at DustPy's default step control (cfl = 0.1). Its process is timed
the same way (subprocess, wall clock; ``import dustpy``, set-up, integration).

Ratios are DustPy's wall time over ours (> 1: we are faster). Quick mode: ``jaxcoag run --quick``
(3 bins per decade, 8 outputs, rtol 1e-4) beside the same DustPy box (at 3 bins per decade DustPy
lost all its mass by 1e4 yr, so it always runs at 7; its run takes ~3 s).

    python benchmarks/run_process.py [--quick] [--no-peers] [--out FILE]

Writes ``benchmarks/results/run_process[_quick].json``.

References: Stammler & Birnstiel (2022) ApJ 935, 35 (DustPy); JAX persistent compilation cache.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import re
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks import _common as C  # noqa: E402

# the wrapper around `jaxcoag run`: import time, the cache's event counters, then the CLI
_OURS_CHILD = """
import json, sys, time
t0 = time.perf_counter()
import jax.monitoring as mon
ev = {}
mon.register_event_listener(lambda e, **k: ev.__setitem__(e, ev.get(e, 0) + 1))
from jaxcoag import cli
t1 = time.perf_counter()
rc = cli.main(sys.argv[1:])
print("RUN_PROCESS_JSON " + json.dumps(dict(rc=rc, import_s=t1 - t0, main_s=time.perf_counter() - t1,
                                            cache_hits=ev.get("/jax/compilation_cache/cache_hits", 0),
                                            cache_writes=ev.get("/jax/compilation_cache/cache_misses", 0))))
cli.exit_now(rc)  # as the `jaxcoag` command ends (cli.console_main)
"""

_DUSTPY_CHILD = """
import json, sys, time
t0 = time.perf_counter()
sys.path.insert(0, {root!r})
import numpy as np
import dustpy
from benchmarks.peers import dustpy_boxes as D
t1 = time.perf_counter()
box = dict(D.FRAG_BOX, **json.loads(sys.argv[1]))
r = D.run_dustpy_frag(box=box, vertical="box", cfl=0.1)
m = r["m"]
final = r["mass_per_bin"][-1]
y = final / final.sum()
print("RUN_PROCESS_JSON " + json.dumps(dict(import_s=t1 - t0, run_s=time.perf_counter() - t1,
                                            integrate_s=r["wall_s"], steps=r["steps"], nbins=int(m.size),
                                            m_peak=float(m[int(np.argmax(y))]), mass_error=r["mass_error"],
                                            t_end_yr=float(r["t"][-1] / D.DUSTPY_YEAR))))
"""


def _child_json(stdout):
    for line in stdout.splitlines()[::-1]:
        if line.startswith("RUN_PROCESS_JSON "):
            return json.loads(line[len("RUN_PROCESS_JSON "):])
    raise RuntimeError("child printed no result:\n" + stdout[-2000:])


def run_ours(workdir, cache, quick, label):
    """One `jaxcoag run` process; returns its timings (s) and counters."""
    out = pathlib.Path(workdir) / f"{label}.nc"
    args = ["run", "--no-progress", "--out", str(out)] + (["--quick"] if quick else [])
    env = dict(os.environ, JAXCOAG_CACHE_DIR=str(cache),
               PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-c", _OURS_CHILD, *args], capture_output=True, text=True, env=env,
                       cwd=workdir, timeout=3600)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise RuntimeError(f"jaxcoag run failed ({r.returncode}):\n{r.stderr[-3000:]}")
    rec = _child_json(r.stdout)
    tm = re.search(r"time: set-up ([\d.]+) s, solve ([\d.]+) s \(XLA compile or cache load ([\d.]+) s, "
                   r"trace \+ lower ([\d.]+) s\), output ([\d.]+) s", r.stdout)
    res = re.search(r"result: (\w+); (\d+) accepted steps \((\d+) rejected\); (\d+) of (\d+) outputs", r.stdout)
    peak = [ln for ln in r.stdout.splitlines() if re.match(r"\s+[\d.e+]+\s+[\d.e+-]+\s", ln)]
    solver = re.search(r"solver ([\w+]+)", r.stdout)
    rec.update(label=label, process_wall_s=wall, setup_s=float(tm[1]), solve_s=float(tm[2]), compile_s=float(tm[3]),
               trace_lower_s=float(tm[4]), output_s=float(tm[5]), status=res[1], steps=int(res[2]),
               rejected=int(res[3]), outputs=int(res[4]), m_peak_final=float(peak[-1].split()[1]),
               solver=solver[1] if solver else None,
               cache_entries=len([f for f in os.listdir(cache) if not f.startswith(".")]))
    rec["other_s"] = wall - rec["import_s"] - rec["setup_s"] - rec["solve_s"] - rec["output_s"]
    return rec, r.stdout


def run_dustpy(quick):
    """DustPy's closest box in a fresh process (see the module docstring)."""
    # DustPy's mass grids span whole decades: 20 from the monomer (6.7e-12 g) reach 6.7e8 g, the
    # first grid at 7 per decade that covers the default run's 1.1e8 g
    over = dict(v_frag=1000.0, t_end_yr=1.0e4, decades=20)
    del quick  # DustPy at 3 bins per decade lost all its mass by 1e4 yr (mass error 1.0): always 7
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-c", _DUSTPY_CHILD.format(root=str(ROOT)), json.dumps(over)],
                       capture_output=True, text=True, timeout=3600)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise RuntimeError(f"DustPy failed ({r.returncode}):\n{r.stderr[-3000:]}")
    rec = _child_json(r.stdout)
    rec.update(process_wall_s=wall, box_overrides=over, cfl=0.1)
    return rec


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="jaxcoag run --quick (DustPy's box unchanged)")
    ap.add_argument("--no-peers", action="store_true", help="skip DustPy")
    ap.add_argument("--out", default=None, help="JSON path (default benchmarks/results/run_process[_quick].json)")
    args = ap.parse_args(argv)
    machine = C.machine_info()
    with tempfile.TemporaryDirectory(prefix="jaxcoag-run-process-") as tmp:
        cache = pathlib.Path(tmp) / "jaxcache"
        cold, log_cold = run_ours(tmp, cache, args.quick, "cold")
        print(f"jaxcoag run (cold cache): {cold['process_wall_s']:.1f} s", flush=True)
        warm, log_warm = run_ours(tmp, cache, args.quick, "warm")
        print(f"jaxcoag run (warm cache): {warm['process_wall_s']:.1f} s", flush=True)
    print(log_warm)
    dp = None
    if not args.no_peers:
        dp = run_dustpy(args.quick)
        print(f"DustPy closest box: {dp['process_wall_s']:.1f} s", flush=True)
    rows = []
    for rec in (cold, warm):
        rows.append(dict(run=f"jaxcoag run ({rec['label']} cache)", process_s=rec["process_wall_s"],
                         import_s=rec["import_s"], setup_s=rec["setup_s"], solve_s=rec["solve_s"],
                         compile_s=rec["compile_s"], trace_lower_s=rec["trace_lower_s"], output_s=rec["output_s"],
                         steps=rec["steps"] + rec["rejected"], cache_hits=rec["cache_hits"],
                         cache_writes=rec["cache_writes"], m_peak=rec["m_peak_final"]))
    ratios = {}
    if dp is not None:
        rows.append(dict(run="DustPy closest box (cfl 0.1)", process_s=dp["process_wall_s"], import_s=dp["import_s"],
                         setup_s=dp["run_s"] - dp["integrate_s"], solve_s=dp["integrate_s"], steps=dp["steps"],
                         m_peak=dp["m_peak"]))
        ratios = {
            "dustpy_process_over_ours_cold": dp["process_wall_s"] / cold["process_wall_s"],
            "dustpy_process_over_ours_warm": dp["process_wall_s"] / warm["process_wall_s"],
            "dustpy_integration_over_our_warm_solve": dp["integrate_s"] / warm["solve_s"],
            "dustpy_integration_over_our_warm_solve_minus_compile":
                dp["integrate_s"] / max(warm["solve_s"] - warm["compile_s"] - warm["trace_lower_s"], 1e-9),
        }
    C.print_table(rows, ["run", "process_s", "import_s", "setup_s", "solve_s", "compile_s", "trace_lower_s",
                         "output_s", "steps", "cache_hits", "cache_writes", "m_peak"],
                  title="whole `jaxcoag run` process (default box) beside DustPy's closest box"
                        + (" [quick]" if args.quick else ""))
    for k, v in ratios.items():
        print(f"{k:55s} {v:.3g}")
    print(C.NOISE_NOTE)
    payload = dict(benchmark="run_process", quick=args.quick, machine=machine, ours_cold=cold, ours_warm=warm,
                   dustpy=dp, ratios=ratios, rows=rows,
                   dustpy_box="closest DustPy box: peers/dustpy_boxes.py frag1au box (0-D, no drift, H_p/sqrt2 "
                              "scale heights, DustPy's Stokes convention) with the default run's v_frag = 10 m/s, "
                              "grid 7/decade to 6.7e8 g (141 bins) and t_end = 1e4 yr; NOT the same physics as the default "
                              "jaxcoag run (Ormel drag convention, radial-drift relative velocities, midplane box)",
                   notes=C.NOISE_NOTE)
    path = args.out or C.RESULTS / f"run_process{'_quick' if args.quick else ''}.json"
    C.write_json(path, payload)
    print(f"wrote {path}")
    return payload


if __name__ == "__main__":
    main()
