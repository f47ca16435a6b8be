"""How long a user waits for each verb, beside the floor of its own numeric work (``make bench``).

``python -m codegen.tools.latency [--out docs/data/latency.json] [--quick] [--repeats N] [--only FAMILY ...]
[--cases built-in starter] [--verbs VERB ...]`` times, in fresh processes as a shell would start them
(``python -m codegen.cli``), every verb on one built-in observer of each family and on each family's
starter (``uiogen new``, in an empty folder):

* built-in: ``design`` (a fresh solve, nothing written); ``generate`` into an empty project (a fresh
  design, its C); ``build`` of that project; ``validate --scenario`` (the family's own scenario, else
  the excitation run); where the observer reads a shared log, ``validate --data``, and ``fit``
  (``--folds 0``) where the family identifies from a log; ``analyze`` of the observer's model (with
  its trial designs);
* starter: ``new``, then ``design --update``, ``generate``, ``build`` and ``validate --scenario
  excitation`` of the starter's observer file (its model is the family's example's: ``analyze`` runs
  on the built-in's).

Each command runs twice in a row: "first", the first time in its project with an empty
derived-results cache (:mod:`codegen.model.cache`, a folder of its own per case and repeat: it holds
only what the earlier verbs of the same case kept), and "again", the same command at once on the
unchanged project. The whole sequence is repeated ``--repeats`` times, each time in new folders;
the table gives medians.

Floors, measured in this process in the same run (medians over the repeats too): starting Python
and importing the command line (``import codegen.cli``, the least any verb costs, added to every
floor); the Clarabel time of the LMIs a fresh design solves; the compiler on the observer's generated C
(its two translation units, the build's flags); reading the log, the compiled observer's run over it
and the Kalman peers' run (what ``validate --data`` runs beside the observer). The machine's load
(``uptime``) is recorded before and after. The record is ``docs/data/latency.json``, rendered on the
performance page by ``uiogen docs``. Figures are wall-clock seconds on whatever machine runs it: ratios
in one run, never asserted in tests (``tests/product/test_latency.py`` checks the table's form).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RECORD = "latency"
CASES = ("built-in", "starter")
FULL_REPEATS = 2
HEADER = ["family", "observer", "verb", "first [s]", "again [s]", "floor (+ start-up)", "floor [s]",
          "first ÷ floor", "again ÷ floor", "result"]

def _choice(family) -> tuple:
    """(observer, its shared log or None, scenario observer, scenario) for one family, asked of the
    registries: the family's first built-in that reads a shared log (``validate --data``, and ``fit``
    where the family identifies), and its first built-in with a scenario of its own (the family's first
    demo scenario, else the excitation run)."""
    from ..contract.capabilities import Scenarios
    from ..model import load_parameters
    from ..project import observer_file as observers
    from ..validation import demo
    from ..validation.logs import reads_the_log
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



def _cli(args: list, env: dict, cwd: Path) -> dict:
    """``uiogen ARGS`` in a fresh interpreter: {"seconds", "rc", "error" (stderr's last line on a failure)}."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", *map(str, args)], capture_output=True, text=True,
                          env=env, cwd=cwd)
    seconds = time.perf_counter() - t0
    error = ""
    if proc.returncode != 0:
        lines = [line for line in proc.stderr.splitlines() if line.strip()]
        error = (lines[-1] if lines else "")[:300]
    return {"seconds": seconds, "rc": proc.returncode, "error": error}


def _startup(env: dict, repeats: int = 3) -> float:
    """Seconds to start Python and import the command line (the floor of every verb; the least of
    ``repeats``)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import codegen.cli"], env=env, cwd=ROOT, check=True)
        times.append(time.perf_counter() - t0)
    return min(times)


def _solve_floor(config) -> dict:
    """Clarabel's time over every LMI a fresh design of ``config`` solves, and how many it solves."""
    from .. import pipeline
    from ..design.solver import FreshSolver

    class Timed(FreshSolver):
        def __init__(self):
            super().__init__()
            self.seconds = 0.0
            self.count = 0

        def solve(self, problem, **options):
            sol = super().solve(problem, **options)
            self.seconds += float(getattr(sol, "solve_time_s", 0.0) or 0.0)
            self.count += 1
            return sol
    solver = Timed()
    pipeline.build(config, solver)
    return {"lmi_s": solver.seconds, "lmi_solves": solver.count}


def _compile_floor(config) -> dict:
    """The C compiler alone on the observer's generated C (its two translation units, the flags
    ``build`` gives them), into a scratch folder: what ``build`` cannot do without."""
    from ..emit.toolchain import compile_and_link
    from ..extension import build
    src = build.generated_dir(config)
    name = config.name
    extra = build.SPEED_FLAGS + (build.LTO_FLAGS if build.lto_supported() else [])    # the probe before the clock
    with tempfile.TemporaryDirectory(prefix="uiogen-latency-cc-") as tmp:
        t0 = time.perf_counter()
        compile_and_link([src / f"{name}_kernel.c", src / f"{name}.c"], Path(tmp) / f"{name}_floor.so",
                         include=[src], flags=build.STRICT_FLAGS, extra_flags=extra, shared=True, object_dir=tmp)
        return {"compile_s": time.perf_counter() - t0}


def _log_floors(name: str, data: str) -> dict:
    """Reading the log, the compiled observer's run over it and the Kalman peers' (seconds)."""
    import numpy as np
    from ..extension.build import load
    from ..project import observer_file as observers
    from ..validation import logs, stanford
    config = observers.get(name)
    obs = load(config)
    t0 = time.perf_counter()
    run = stanford.load(data, sample_time=obs.sample_time)
    t1 = time.perf_counter()
    X = np.column_stack([getattr(run, logs.DATA_COLUMNS[c]) for c in obs.input_names])
    t2 = time.perf_counter()
    obs.run(X, obs.initial_state())
    t3 = time.perf_counter()
    logs._baselines(config, run)
    t4 = time.perf_counter()
    return {"read_log_s": t1 - t0, "observer_run_s": t3 - t2, "peers_s": t4 - t3, "samples": int(run.n)}


# --- the cases: the commands of one built-in or one starter, in order ---------------------------------
# A step: (key, verb as shown, observer as shown, argv, floor kind, run again). The keys are what
# ``--verbs`` selects; a step's prerequisites (``new`` for a starter, ``generate`` before ``build``)
# run whatever it selects.
VERBS = ("new", "design", "generate", "build", "validate --scenario", "validate --data", "fit", "analyze")
PREREQUISITES = {"build": ("generate",)}


def _builtin_case(family, work: Path) -> dict:
    from ..contract.capabilities import Identification
    from ..project import observer_file as observers
    name, data, scen_obs, scenario = _choice(family)
    project = work / f"gen_{name}"
    steps = [("design", "design", name, ["design", name], "lmi", True),
             ("generate", "generate (empty project)", name, ["generate", name, "--project", project], "lmi", True),
             ("build", "build", name, ["build", name, "--project", project], "compile", True)]
    if scen_obs is not None:
        steps.append(("validate --scenario", f"validate --scenario {scenario}", scen_obs,
                      ["validate", scen_obs, "--scenario", scenario, "--json"], "start-up", True))
    if data is not None:
        steps.append(("validate --data", f"validate --data {data}", name, ["validate", name, "--data", data, "--json"],
                      "log", True))
        if isinstance(family, Identification):
            steps.append(("fit", "fit --folds 0", name, ["fit", name, "--data", data, "--samples", "{samples}",
                                                         "--folds", "0"], "read", True))
    steps.append(("analyze", "analyze", name, ["analyze", name, "--json"], "start-up", True))

    def before() -> dict:
        return _log_floors(name, data) if data is not None else {}

    def after(ran: set) -> dict:
        out = _solve_floor(observers.get(name)) if ran & {"design", "generate"} else {}
        if "build" in ran and (project / "generated_c" / name).is_dir():
            out.update(_compile_floor(observers.get(name, project=project)))
        return out
    return {"cwd": ROOT, "steps": steps, "before": before, "after": after}


def _starter_case(family, work: Path) -> dict:
    from ..project import observer_file as observers
    from ..project.starter import default_name
    folder = work / f"starter_{family.name}"
    obs = folder / f"{default_name(family)}.toml"
    who = f"starter {family.name}"
    steps = [("new", "new", who, ["new", folder, "--family", family.name], "start-up", False),
             ("design", "design --update", who, ["design", obs, "--update"], "lmi", True),
             ("generate", "generate", who, ["generate", obs], "start-up", True),
             ("build", "build", who, ["build", obs], "compile", True),
             ("validate --scenario", "validate --scenario excitation", who,
              ["validate", obs, "--scenario", "excitation", "--json"], "start-up", True)]

    def after(ran: set) -> dict:
        if not obs.is_file():
            return {}
        config = observers.get(str(obs))
        out = _solve_floor(config) if "design" in ran else {}
        if "build" in ran and (folder / "generated_c" / config.name).is_dir():
            out.update(_compile_floor(config))
        return out
    return {"cwd": work, "steps": steps, "before": dict, "after": after}


def _selected(steps: list, verbs) -> list:
    if verbs is None:
        return steps
    unknown = sorted(set(verbs) - set(VERBS))
    if unknown:
        raise SystemExit(f"latency: unknown verb(s) {', '.join(unknown)} (among: {', '.join(VERBS)})")
    wanted = set(verbs) | {"new"} | {p for v in verbs for p in PREREQUISITES.get(v, ())}
    return [s for s in steps if s[0] in wanted]


def _floor(kind: str, floors: dict) -> tuple:
    """(what the floor is, its seconds without start-up or None where it was not measured)."""
    if kind == "start-up":
        return "start-up", 0.0
    if kind == "lmi" and "lmi_s" in floors:
        return f"{floors['lmi_solves']} LMI solve(s)", floors["lmi_s"]
    if kind == "compile" and "compile_s" in floors:
        return "compiling the generated C", floors["compile_s"]
    if kind == "log" and "read_log_s" in floors:
        return (f"read {floors['samples']} samples {floors['read_log_s']:.2f} + observer {floors['observer_run_s']:.3f}"
                f" + Kalman peers {floors['peers_s']:.2f}",
                floors["read_log_s"] + floors["observer_run_s"] + floors["peers_s"])
    if kind == "read" and "read_log_s" in floors:
        return f"read {floors['samples']} samples", floors["read_log_s"]
    return kind, None


def _median_floors(runs: list) -> dict:
    keys = set().union(*runs) if runs else set()
    def median(values):         # a count (solves, samples) stays a whole number
        return statistics.median_low(values) if all(isinstance(v, int) for v in values) else statistics.median(values)
    return {k: median([r[k] for r in runs if k in r]) for k in keys}


def _uptime() -> dict:
    text = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    return {"uptime": text, "loadavg": [round(x, 2) for x in os.getloadavg()]}


def _ratio(seconds, floor):
    return None if seconds is None or floor is None or floor <= 0 else seconds / floor


def measure(families=None, cases=CASES, verbs=None, repeats: int = FULL_REPEATS, progress=None,
            each_repeat=None) -> dict:
    """Every row (module docstring): ``families`` (names; default every family with a built-in),
    ``cases`` (built-in, starter), ``verbs`` (among :data:`VERBS`; default all), ``repeats`` times;
    ``each_repeat(record)`` is given the record of the repeats done so far after each."""
    from .. import families as registry
    from ..project.starter import default_name      # noqa: F401  (the starters' names, imported before timing)
    chosen = [registry.get(f) for f in (families or registry.names())]
    chosen = [f for f in chosen if _choice(f) is not None]
    t_start = time.perf_counter()
    load_before = _uptime()
    startups, results, order = [], {}, []
    saved_cache = os.environ.get("UIOGEN_CACHE_DIR")
    try:
        for r in range(repeats):
            with tempfile.TemporaryDirectory(prefix="uiogen-latency-") as tmp:
                work = Path(tmp)
                env = dict(os.environ, UIOGEN_CACHE_DIR=str(work / "cache_startup"), PYTHONPATH=str(ROOT))
                startups.append(_startup(env))
                for family in chosen:
                    for kind in cases:
                        case = (_builtin_case if kind == "built-in" else _starter_case)(family, work)
                        key = (family.name, kind)
                        # the case's own derived-results cache, empty at its first command; this
                        # process's floors use it too
                        cache = str(work / f"cache_{kind}_{family.name}")
                        env = dict(os.environ, UIOGEN_CACHE_DIR=cache, PYTHONPATH=str(ROOT))
                        os.environ["UIOGEN_CACHE_DIR"] = cache
                        entry = results.setdefault(key, {"steps": {}, "floors": []})
                        if key not in order:
                            order.append(key)
                        floors = case["before"]()
                        ran = set()
                        for step_key, verb, who, argv, floor_kind, again in _selected(case["steps"], verbs):
                            argv = [str(a).replace("{samples}", f"0:{floors.get('samples', 0)}") for a in argv]
                            runs = [_cli(argv, env, case["cwd"])]
                            if again:
                                runs.append(_cli(argv, env, case["cwd"]))
                            ran.add(step_key)
                            step = entry["steps"].setdefault(verb, {
                                "observer": who, "verb": verb, "key": step_key, "floor_kind": floor_kind,
                                "command": ["uiogen", *[a.replace(str(work), "DIR") for a in argv]],
                                "first": [], "again": [], "rc": [], "errors": []})
                            step["first"].append(runs[0]["seconds"])
                            if again:
                                step["again"].append(runs[1]["seconds"])
                            step["rc"] += [x["rc"] for x in runs]
                            step["errors"] += [x["error"] for x in runs if x["error"]]
                            if progress is not None:
                                progress(f"{family.name} {kind}: {verb}: "
                                         + ", ".join(f"{x['seconds']:.2f} s" for x in runs)
                                         + ("" if all(x["rc"] == 0 for x in runs) else " (failed)"))
                        floors.update(case["after"](ran))
                        entry["floors"].append(floors)
            if each_repeat is not None and r + 1 < repeats:
                each_repeat(_summary(results, order, startups, r + 1, t_start, load_before, chosen, cases, verbs))
    finally:
        if saved_cache is None:
            os.environ.pop("UIOGEN_CACHE_DIR", None)
        else:
            os.environ["UIOGEN_CACHE_DIR"] = saved_cache
    return _summary(results, order, startups, repeats, t_start, load_before, chosen, cases, verbs)


def _summary(results: dict, order: list, startups: list, repeats: int, t_start: float, load_before: dict,
             chosen: list, cases, verbs) -> dict:
    """The record of the runs so far: medians, floors, ratios, the table."""
    startup = statistics.median(startups)
    rows, table_rows = [], []
    for family_name, kind in order:
        entry = results[(family_name, kind)]
        floors = _median_floors(entry["floors"])
        for step in entry["steps"].values():
            what, floor_s = _floor(step["floor_kind"], floors)
            floor = None if floor_s is None else floor_s + startup
            first = statistics.median(step["first"])
            again = statistics.median(step["again"]) if step["again"] else None
            bad = [rc for rc in step["rc"] if rc != 0]
            result = "ok" if not bad else f"exit {bad[0]}: {step['errors'][0][:80] if step['errors'] else ''}"
            rows.append({"family": family_name, "case": kind, "observer": step["observer"], "verb": step["verb"],
                         "command": step["command"], "first_s": first, "again_s": again,
                         "first_runs_s": step["first"], "again_runs_s": step["again"], "floor": what,
                         "floor_s": floor, "floors": floors, "startup_s": startup,
                         "first_ratio": _ratio(first, floor), "again_ratio": _ratio(again, floor),
                         "rc": step["rc"], "errors": step["errors"]})
            r = rows[-1]
            table_rows.append([family_name, f"`{step['observer']}`", step["verb"], round(first, 2),
                               "–" if again is None else round(again, 2), what,
                               "–" if floor is None else round(floor, 2),
                               "–" if r["first_ratio"] is None else round(r["first_ratio"], 1),
                               "–" if r["again_ratio"] is None else round(r["again_ratio"], 1), result])
    total = time.perf_counter() - t_start
    load_after = _uptime()
    note = (f"Medians of {repeats} run(s) of each command (first: empty cache and project; again: at once, "
            f"unchanged). Start-up (python + import codegen.cli) {startup:.2f} s, in every floor. Load average "
            f"{' / '.join(map(str, load_before['loadavg']))} before, "
            f"{' / '.join(map(str, load_after['loadavg']))} after (1 / 5 / 15 min), on {os.cpu_count()} CPUs "
            f"shared with other jobs; the whole run {total / 60:.1f} min.")
    return {"generated_by": "python -m codegen.tools.latency", "repeats": repeats,
            "families": [f.name for f in chosen], "cases": list(cases), "verbs": list(verbs or VERBS),
            "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version()},
            "load_before": load_before, "load_after": load_after, "total_s": total, "startup_s": startup,
            "startup_runs_s": startups, "rows": rows,
            "table": {"header": HEADER, "rows": table_rows, "note": note}}


def check_record(record: dict) -> list:
    """What is wrong with a record's form (empty when none): every row has each column, a floor of
    at least the start-up, finite positive seconds and ratios. Speed is not judged."""
    problems = []
    table = record.get("table", {})
    if table.get("header") != HEADER:
        problems.append(f"header {table.get('header')!r}, expected {HEADER!r}")
    if not table.get("rows"):
        problems.append("no rows")
    for row in table.get("rows", []):
        if len(row) != len(HEADER):
            problems.append(f"row {row!r}: {len(row)} cells, expected {len(HEADER)}")
    startup = record.get("startup_s")
    if not (isinstance(startup, float) and math.isfinite(startup) and startup > 0):
        problems.append(f"start-up {startup!r} is not a positive number of seconds")
    for row in record.get("rows", []):
        where = f"{row.get('observer')} {row.get('verb')}"
        for k in ("first_s", "floor_s", "first_ratio") + (("again_s", "again_ratio") if row.get("again_s") is not None
                                                           else ()):
            v = row.get(k)
            if not (isinstance(v, float) and math.isfinite(v) and v > 0):
                problems.append(f"{where}: {k} {v!r} is not a finite positive number")
        if isinstance(row.get("floor_s"), float) and isinstance(startup, float) and row["floor_s"] < startup:
            problems.append(f"{where}: floor {row['floor_s']} below the start-up {startup}")
        rcs = row.get("rc")
        if not isinstance(rcs, list) or not rcs or any(rc != 0 for rc in rcs):
            problems.append(f"{where}: exit {row.get('rc')}: {'; '.join(row.get('errors', []))[:200]}")
    return problems


def markdown(record: dict) -> str:
    from .docs import _table
    return _table(record["table"]["header"], record["table"]["rows"]) + "\n" + record["table"]["note"] + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m codegen.tools.latency", description=__doc__.split("\n")[0])
    parser.add_argument("--out", help="write the record here (docs/data/latency.json)")
    parser.add_argument("--only", nargs="*", help="families to time (default: every family with a built-in)")
    parser.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES))
    parser.add_argument("--verbs", nargs="+", metavar="VERB", help=f"among: {', '.join(VERBS)} (default: all)")
    parser.add_argument("--repeats", type=int, default=None, help=f"runs of each command (default {FULL_REPEATS}; "
                                                                  f"--quick: 1)")
    parser.add_argument("--quick", action="store_true",
                        help="one run of each command, the built-ins only, no analyze (a few minutes)")
    args = parser.parse_args(argv)
    repeats = args.repeats or (1 if args.quick else FULL_REPEATS)
    cases, verbs = args.cases, args.verbs
    if args.quick:
        cases = [c for c in cases if c == "built-in"] or cases
        verbs = verbs or [v for v in VERBS if v != "analyze"]

    def write(record: dict) -> None:
        if args.out:
            tmp = Path(args.out).with_suffix(".json.tmp")
            tmp.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
            os.replace(tmp, args.out)
    # the record after each repeat too: a run stopped in a later repeat leaves the earlier ones whole
    record = measure(args.only, cases, verbs, repeats,
                     progress=lambda line: print(f"  ... {line}", file=sys.stderr, flush=True), each_repeat=write)
    write(record)
    print(markdown(record), end="")
    problems = check_record(record)
    for p in problems:
        print(f"latency: {p}", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    raise SystemExit(main())
