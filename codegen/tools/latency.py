"""How long a user waits for each verb, beside the floor of its own numeric work (``make bench``).

``python -m codegen.tools.latency [--out docs/data/latency.json] [--only FAMILY ...]`` times, in fresh
processes as a shell would start them (``python -m codegen.cli``), every verb on one built-in
observer of each family and on each family's starter (``uiogen new``, in an empty folder):

* ``design`` (a fresh solve, nothing written), twice: the first run with an empty derived-results
  cache (:mod:`codegen.model.cache`), the second with what the first kept;
* ``generate`` of the one observer into an empty project (a fresh design, its C), then again with
  nothing changed;
* ``validate --scenario`` (the excitation run, or the family's own scenario) and, where the observer
  reads a shared log, ``validate --data``;
* ``fit`` (``--folds 0``) where the family identifies from a log.

Floors, measured in this process in the same run: starting Python and importing the command line
(``import codegen.cli``, the least any verb costs); the Clarabel time of every LMI the design solves;
reading the log; the compiled observer's run over it; the Kalman peers' run over it (what
``validate --data`` runs beside the observer). The record is ``docs/data/latency.json``, rendered on
the performance page by ``uiogen docs``. Figures are wall-clock seconds on whatever machine runs it:
ratios in one run, never asserted in tests.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RECORD = "latency"

def _choice(family) -> tuple:
    """(observer, its shared log or None, scenario observer, scenario) for one family, asked of the
    registries: the family's first built-in that reads a shared log (``validate --data``, and ``fit``
    where the family identifies), and its first built-in with a scenario of its own (the family's first
    demo scenario, else the excitation run)."""
    from ..families.capabilities import Scenarios
    from ..model import load_parameters
    from ..project import observer_file as observers
    from ..validation import demo
    from ..validation.run import reads_the_log
    own = [observers.get(n) for n in observers.names() if observers.get(n).family == family.name]
    if not own:
        return None
    data_obs, data = None, None
    # the observers made for a shared log: the demo's real-data ones and those whose parameter file names
    # their car's log (another reads the log's columns, but its boxes need not hold the log)
    for config in own:
        meta = load_parameters(config.parameter_path).meta
        made_for = config.name in (demo.REAL_DATA_OBSERVER, *demo.REAL_DATA_OTHERS) or "shared_log" in meta
        inputs = json.loads(config.workspace.design_lock(config.name).read_text())["signals"]["input"]
        if made_for and reads_the_log(inputs):
            data_obs, data = config.name, meta.get("shared_log", "stanford")
            break
    if isinstance(family, Scenarios) and family.demo_scenarios:
        scenario = family.demo_scenarios[0]
        others = [c.name for c in own if c.name != data_obs and c.name not in demo.REAL_DATA_ONLY]
        scen_obs = others[0] if others else (data_obs if data_obs not in demo.REAL_DATA_ONLY else None)
    else:                       # no scenarios of the family's own: the excitation run of its own equations
        scenario, scen_obs = "excitation", data_obs or own[0].name
    return (data_obs or own[0].name), data, scen_obs, scenario


def _cli(args: list, env: dict, cwd: Path) -> tuple:
    """(seconds, exit code) of ``uiogen ARGS`` in a fresh interpreter."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", *map(str, args)], capture_output=True, text=True,
                          env=env, cwd=cwd)
    return time.perf_counter() - t0, proc.returncode


def _startup(env: dict, repeats: int = 3) -> float:
    """Seconds to start Python and import the command line (the floor of every verb)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import codegen.cli"], env=env, cwd=ROOT, check=True)
        times.append(time.perf_counter() - t0)
    return min(times)


def _solve_seconds(config) -> float:
    """Clarabel's time over every LMI a fresh design of ``config`` solves."""
    from .. import pipeline
    from ..design.solver import FreshSolver

    class Timed(FreshSolver):
        def __init__(self):
            super().__init__()
            self.seconds = 0.0

        def solve(self, problem, **options):
            sol = super().solve(problem, **options)
            self.seconds += float(getattr(sol, "solve_time_s", 0.0) or 0.0)
            return sol
    solver = Timed()
    pipeline.build(config, solver)
    return solver.seconds


def _log_floors(name: str, data: str) -> dict:
    """Reading the log, the compiled observer's run over it and the Kalman peers' (seconds)."""
    from ..extension.build import load
    from ..project import observer_file as observers
    from ..validation import run as validation_run
    from ..validation import stanford
    config = observers.get(name)
    obs = load(config)
    t0 = time.perf_counter()
    run = stanford.load(data, sample_time=obs.sample_time)
    t1 = time.perf_counter()
    inputs = [getattr(run, validation_run.DATA_COLUMNS[c]) for c in obs.input_names]
    import numpy as np
    X = np.column_stack(inputs)
    t2 = time.perf_counter()
    obs.run(X, obs.initial_state())
    t3 = time.perf_counter()
    validation_run._baselines(config, run)
    t4 = time.perf_counter()
    return {"read_log_s": t1 - t0, "observer_run_s": t3 - t2, "peers_s": t4 - t3, "samples": int(run.n)}


def _builtin_rows(family, env: dict, work: Path) -> list:
    from ..families.capabilities import Identification
    from ..project import observer_file as observers
    name, data, scen_obs, scenario = _choice(family)
    config = observers.get(name)
    rows = []
    solve = _solve_seconds(config)
    for i in (1, 2):
        s, rc = _cli(["design", name], env, ROOT)
        rows.append({"observer": name, "verb": "design", "run": i, "seconds": s, "rc": rc,
                     "floor": "LMI solves", "floor_s": solve})
    project = work / f"gen_{name}"
    for i in (1, 2):
        s, rc = _cli(["generate", name, "--project", project], env, ROOT)
        rows.append({"observer": name, "verb": "generate (empty project)" if i == 1 else "generate (unchanged)",
                     "run": i, "seconds": s, "rc": rc, "floor": "LMI solves" if i == 1 else "",
                     "floor_s": solve if i == 1 else None})
    if scen_obs is not None:
        s, rc = _cli(["validate", scen_obs, "--scenario", scenario, "--json"], env, ROOT)
        rows.append({"observer": scen_obs, "verb": f"validate --scenario {scenario}", "run": 1, "seconds": s,
                     "rc": rc, "floor": "", "floor_s": None})
    if data is not None:
        floors = _log_floors(name, data)
        for i in (1, 2):
            s, rc = _cli(["validate", name, "--data", data, "--json"], env, ROOT)
            rows.append({"observer": name, "verb": f"validate --data {data}", "run": i, "seconds": s, "rc": rc,
                         "floor": f"read {floors['samples']} samples + observer + Kalman peers",
                         "floor_s": floors["read_log_s"] + floors["observer_run_s"] + floors["peers_s"],
                         **{k: v for k, v in floors.items()}})
        if isinstance(family, Identification):
            samples = f"0:{floors['samples']}"
            s, rc = _cli(["fit", name, "--data", data, "--samples", samples, "--folds", "0"], env, ROOT)
            rows.append({"observer": name, "verb": f"fit --samples {samples} --folds 0", "run": 1, "seconds": s,
                         "rc": rc,
                         "floor": f"read {floors['samples']} samples", "floor_s": floors["read_log_s"]})
    return rows


def _starter_rows(family, env: dict, work: Path) -> list:
    from ..project.starter import default_name
    folder = work / f"starter_{family.name}"
    obs = folder / f"{default_name(family)}.toml"
    rows = []
    s, rc = _cli(["new", folder, "--family", family.name], env, work)
    rows.append({"observer": f"starter {family.name}", "verb": "new", "run": 1, "seconds": s, "rc": rc, "floor": "",
                 "floor_s": None})
    from ..project import observer_file as observers
    solve = _solve_seconds(observers.get(str(obs))) if rc == 0 else None
    for verb, args in (("design --update", ["design", obs, "--update"]), ("generate", ["generate", obs]),
                       ("build", ["build", obs]),
                       ("validate --scenario excitation", ["validate", obs, "--scenario", "excitation", "--json"]),
                       ("design", ["design", obs])):
        s, rc = _cli(args, env, work)
        rows.append({"observer": f"starter {family.name}", "verb": verb, "run": 1, "seconds": s, "rc": rc,
                     "floor": "LMI solves" if verb.startswith("design") else "",
                     "floor_s": solve if verb.startswith("design") else None})
    return rows


def measure(families=None) -> dict:
    """Every row (module docstring); the derived-results cache starts empty in a folder of its own."""
    from .. import families as registry
    chosen = [registry.get(f) for f in (families or registry.names())]
    chosen = [f for f in chosen if _choice(f) is not None]
    with tempfile.TemporaryDirectory(prefix="uiogen-latency-") as tmp:
        work = Path(tmp)
        env = dict(os.environ, UIOGEN_CACHE_DIR=str(work / "cache"), PYTHONPATH=str(ROOT))
        os.environ["UIOGEN_CACHE_DIR"] = env["UIOGEN_CACHE_DIR"]      # this process's floors: the same cache
        startup = _startup(env)
        rows = []
        for family in chosen:
            rows += _builtin_rows(family, env, work)
            rows += _starter_rows(family, env, work)
    table_rows = []
    for r in rows:
        floor = (r["floor_s"] or 0.0) + startup
        table_rows.append([f"`{r['observer']}`", r["verb"] + (" (again)" if r["run"] == 2 and
                                                              not r["verb"].startswith("generate") else ""),
                           round(r["seconds"], 2), r["floor"] or "start-up", round(floor, 2),
                           round(r["seconds"] / floor, 1), "ok" if r["rc"] == 0 else f"exit {r['rc']}"])
    return {"startup_s": startup, "rows": rows,
            "table": {"header": ["observer", "verb", "seconds", "floor (+ start-up)", "floor [s]", "ratio", "result"],
                      "rows": table_rows}}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m codegen.tools.latency", description=__doc__.split("\n")[0])
    parser.add_argument("--out", help="write the record here (docs/data/latency.json)")
    parser.add_argument("--only", nargs="*", help="families to time (default: every family with a built-in)")
    args = parser.parse_args(argv)
    record = measure(args.only)
    text = json.dumps(record, indent=1, sort_keys=True) + "\n"
    if args.out:
        tmp = Path(args.out).with_suffix(".json.tmp")
        tmp.write_text(text)
        os.replace(tmp, args.out)
    for row in record["table"]["rows"]:
        print("  ".join(str(c) for c in row))
    print(f"start-up (python + import codegen.cli): {record['startup_s']:.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
