"""Wall time of the Richardson (1995) periodic-box models (i)-(iv) after compilation (compilation apart).

R95's set-up (Table I, §3): N0 = 1000 spheres of radius 0.1 in a box of side 10, T = 8.2, three seeds per
model, rms speed v0 = 13 (R95 does not print it). Goal (the issue): each model under a minute per run after
compilation on 2 cores. Every run goes through ``paper_figs/_rigid_models.run_model`` (the code of
``paper_figs/figR04_R08_models.py``): the compilation is timed on a first call to ``t_out * 1e-6`` (same
shapes and static fields, so the timed runs reuse its program), then each seed's run to T.

``--reuse PATH`` takes the timings of the models already run by the figure's full mode (its
``figR04_R08_runs.json``, which records them with the load average) instead of running them again, and runs
only the models missing there. The JSON records, per model, where its numbers come from.

    python benchmarks/rigid_models.py [--quick] [--models i,ii,iii,iv] [--seeds 1,2,3] [--reuse RUNS_JSON] [--out PATH]

Writes benchmarks/results/rigid_models.json (``--quick``: rigid_models_quick.json: N0 = 100, seed 1, T = 2)
and prints a table. The machine is shared: wall times are upper bounds; the 1-min load average before and
after each model is recorded.

References: Richardson (1995, Icarus 115, 320) §3, Table I.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "paper_figs"))
sys.path.insert(0, str(ROOT))

GOAL_S = 60.0  # seconds per run after compilation on 2 cores (the goal)


def rows_from(data: dict, source: str) -> list[dict]:
    """One table row per model from :func:`run_model` dicts keyed by model."""
    import numpy as np

    rows = []
    for m, d in data.items():
        rs = np.asarray(d["run_s"], float)
        rows.append(dict(model=m, n0=d["n0"], T=d["T"], seeds=d["seeds"], compile_s=d["compile_s"], run_s=rs.tolist(),
                         mean_run_s=float(rs.mean()), max_run_s=float(rs.max()),
                         goal_met=bool(rs.max() < GOAL_S), load_1min=[d["load_before"], d["load_after"]],
                         N_T=[r["N"][-1] for r in d["runs"]], N_C_T=[r["N_C"][-1] for r in d["runs"]],
                         steps=[r["n_steps"] for r in d["runs"]], status=[r["status"] for r in d["runs"]],
                         source=source))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N0 = 100, seed 1, T = 2 (a smoke run)")
    ap.add_argument("--models", default="i,ii,iii,iv", help="comma-separated subset of i,ii,iii,iv")
    ap.add_argument("--seeds", default=None, help="comma-separated seeds (default 1,2,3; --quick: 1)")
    ap.add_argument("--reuse", type=pathlib.Path, default=None,
                    help="runs JSON of paper_figs/figR04_R08_models.py (full mode) whose timings to take")
    ap.add_argument("--out", type=pathlib.Path, default=None, help="output JSON (default benchmarks/results/...)")
    ap.add_argument("--note", default="", help="free text stored in the JSON (e.g. how the reused runs were made)")
    args = ap.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import _rigid_models as RM

    from benchmarks import _common as C

    models = [m.strip() for m in args.models.split(",") if m.strip()]
    n0, seeds, T = (100, [1], 2.0) if args.quick else (1000, [1, 2, 3], 8.2)
    if args.seeds is not None:
        try:
            seeds = [int(x) for x in args.seeds.split(",")]
        except ValueError:
            raise SystemExit(f"--seeds must be comma-separated ints; got {args.seeds!r}.") from None
    RM.check_setup(models, n0, seeds, T)
    reused = {}
    if args.reuse is not None:
        if not args.reuse.exists():
            raise SystemExit(f"--reuse {args.reuse}: no such file (run paper_figs/figR04_R08_models.py first).")
        src = json.loads(args.reuse.read_text())
        for m in models:
            d = src.get(m)
            if d is not None and d["n0"] == n0 and d["seeds"] == seeds and abs(d["T"] - T) < 1e-12:
                reused[m] = d
    out = args.out or C.RESULTS / ("rigid_models_quick.json" if args.quick else "rigid_models.json")
    fresh = {}
    for m in models:
        if m not in reused:
            fresh[m] = RM.run_model(m, n0=n0, seeds=seeds, T=T, t_out=RM.default_t_out(T))
    rows = rows_from(reused, f"reused from {args.reuse}") + rows_from(fresh, "this run")
    rows.sort(key=lambda r: models.index(r["model"]))
    for r in rows:
        r["runs [s]"] = "/".join(f"{x:.0f}" for x in r["run_s"])
        r["load"] = "-".join(f"{x:.1f}" for x in r["load_1min"])
    C.print_table(rows, ["model", "n0", "compile_s", "runs [s]", "mean_run_s", "goal_met", "N_C_T", "load", "source"],
                  title=f"R95 models, N0 = {n0}, T = {T:g}, seeds {seeds}: wall time after compile "
                        f"(goal < {GOAL_S:g} s per run on 2 cores)")
    payload = dict(benchmark="rigid_models", goal_s_per_run=GOAL_S, n0=n0, T=T, seeds=seeds, v0=RM.V0,
                   note=("compile_s: first call to t_out * 1e-6 (compilation + a negligible run); run_s: each seed's "
                         "run to T after it. Machine shared with other jobs: upper bounds; load_1min = 1-min load "
                         "average before/after each model."),
                   run_note=args.note,
                   results=[{k: v for k, v in r.items() if k not in ("runs [s]", "load")} for r in rows],
                   machine=C.machine_info())
    C.write_json(out, payload)
    print(f"wrote {out}")
    return payload


if __name__ == "__main__":
    main()
