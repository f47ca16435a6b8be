"""Every verb for every family: the starters taken through the whole command line.

For each registered family with an example, in an empty folder (outside any checkout), as a new
user would, through :func:`codegen.cli.main` with the arguments a shell would pass::

    uiogen new DIR --family F --name my_F
    uiogen design DIR/my_F.toml --update
    uiogen generate DIR/my_F.toml
    uiogen build DIR/my_F.toml
    uiogen validate DIR/my_F.toml --scenario excitation --json
    uiogen validate DIR/my_F.toml --data DIR/log.csv --json     (the excitation run written as a CSV
                                                                log, mapped by a [data] table)
    uiogen check-gains DIR/my_F.toml --gains DIR/generated_c/my_F/my_F_design.json
    uiogen export DIR/my_F.toml --format fmu --out DIR/my_F.fmu
    uiogen build DIR/my_F.toml --float32                        (accepted, or refused with its margin)
    uiogen campaign DIR/campaign.toml --workers 1 --json        (the model's own equations, two of
                                                                its parameters dispersed)

A cell passes when the command exits 0 (for ``--float32`` also: exits 2 with a CertificateError
that states the margin) and prints no traceback. ``python -m codegen.acceptance.verbs [--only F ...]
[--out FILE]`` prints the table, or writes the record ``docs/data/families_and_verbs.json`` that
``uiogen docs`` renders into ``docs/families_and_verbs.md``; ``tests/product/test_families_and_verbs.py``
runs every cell and writes it.
"""
from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import re
import sys
import tempfile
import time
import traceback
from pathlib import Path

VERBS = ("new", "design", "generate", "build", "validate excitation", "validate --data", "check-gains",
         "export fmu", "build --float32", "campaign")
RECORD = "families_and_verbs"
LOG_SECONDS = 10.0          # the logged run of the validate --data cell
CAMPAIGN_RUNS = 4


def run_cli(argv: list) -> dict:
    """``uiogen ARGV`` in this process: {"code", "stdout", "stderr", "traceback"}."""
    from .. import cli
    out, err = io.StringIO(), io.StringIO()
    tb = None
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = cli.main([str(a) for a in argv])
        except SystemExit as exc:           # argparse
            code = exc.code if isinstance(exc.code, int) else 2
        except BaseException:               # what the console script would print as a traceback
            code, tb = 1, traceback.format_exc()
    return {"code": code, "stdout": out.getvalue(), "stderr": err.getvalue(), "traceback": tb}


def _cell(result: dict, ok_codes=(0,)) -> dict:
    text = result["stdout"] + result["stderr"]
    if result["traceback"] or "Traceback (most recent call last)" in text:
        tb = result["traceback"] or text
        return {"outcome": "fail", "note": "traceback: " + tb.strip().splitlines()[-1]}
    if result["code"] not in ok_codes:
        lines = [line for line in result["stderr"].splitlines() if line.strip()] or text.splitlines() or [""]
        return {"outcome": "fail", "note": f"exit {result['code']}: {lines[-1][:300]}"}
    return {"outcome": "pass", "note": ""}


def write_log(target: Path, config_path: Path) -> Path:
    """The excitation run of the observer as a CSV log (time, every observer input, the truth of
    every estimate the model has), and a ``[data]`` table mapping it appended to the observer file."""
    import numpy as np
    from ..extension.build import load
    from ..project import observer_file as observers
    from ..validation import excitation
    config = observers.get(str(config_path))
    truth = excitation.simulate(config, duration=LOG_SECONDS)
    obs = load(config)
    refs = [n for n in obs.output_names if n in truth]
    header = ["time", *(f"in_{n}" for n in obs.input_names), *(f"ref_{n}" for n in refs)]
    columns = [truth["t"], *(truth[n] for n in obs.input_names), *(truth[n] for n in refs)]
    with target.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for row in np.column_stack(columns):
            w.writerow([repr(float(v)) for v in row])
    table = ["", "[data]", 'time = "time"', "", "[data.inputs]", *(f'{n} = "in_{n}"' for n in obs.input_names)]
    if refs:
        table += ["", "[data.truth]", *(f'{n} = "ref_{n}"' for n in refs)]
    with config_path.open("a") as fh:
        fh.write("\n".join(table) + "\n")
    return target


def write_campaign(folder: Path, config_path: Path) -> Path:
    """A campaign file of the excitation scenario with two of the model's parameters dispersed (+-5 %)."""
    from ..model import load_parameters
    from ..project import observer_file as observers
    config = observers.get(str(config_path))
    values = load_parameters(config.parameter_path).values
    dispersed = [str(p) for p in config.load_model().parameters if values.get(str(p), 0.0) != 0.0][:2]
    lines = [f'observer = "{config_path.name}"', 'scenarios = ["excitation"]', 'scenario_seed = "per_run"',
             f"runs = {CAMPAIGN_RUNS}", "seed = 2024", "duration = 6.0", "worst = 1", "", "[parameters]",
             *(f'{p} = {{ dist = "uniform", low = 0.95, high = 1.05, relative = true }}' for p in dispersed)]
    path = folder / "campaign.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def family_row(family: str, base: Path, log=None) -> dict:
    """Every verb on the starter of ``family`` in ``base/family``: {verb: {"outcome", "note", "seconds"}}."""
    folder = base / family
    name = f"my_{family}"
    toml = folder / f"{name}.toml"
    lock = folder / "generated_c" / name / f"{name}_design.json"
    row = {}

    def step(verb, make):
        t0 = time.perf_counter()
        try:
            cell = make()
        except Exception:                    # the harness's own preparation: a failure of the cell
            cell = {"outcome": "fail", "note": "traceback: " + traceback.format_exc().strip().splitlines()[-1]}
        cell["seconds"] = round(time.perf_counter() - t0, 1)
        row[verb] = cell
        if log:
            log(f"{family}: {verb}: {cell['outcome']} {cell['note']} ({cell['seconds']} s)")
        return cell["outcome"] != "fail"

    def cli(*argv, ok=(0,)):
        return lambda: _cell(run_cli(list(argv)), ok)

    def float32():
        r = run_cli(["build", toml, "--float32"])
        if r["code"] == 2 and "CertificateError: float32 build refused" in r["stderr"] and not r["traceback"]:
            margin = re.search(r"margin 1-c = ([0-9.eE+-]+)", r["stderr"])
            return {"outcome": "refused", "note": f"margin 1-c = {float(margin.group(1)):.2g}" if margin else ""}
        cell = _cell(r)
        if cell["outcome"] == "pass":
            cell["note"] = "accepted"
        return cell

    def data():
        write_log(folder / "log.csv", toml)
        return _cell(run_cli(["validate", toml, "--data", folder / "log.csv", "--json"]))

    def campaign():
        spec = write_campaign(folder, toml)
        r = run_cli(["campaign", spec, "--workers", "1", "--json"])
        cell = _cell(r)
        if cell["outcome"] == "pass":
            summary = json.loads(r["stdout"])
            if summary["runs_ok"] != summary["runs"]:
                return {"outcome": "fail", "note": f"{summary['runs_ok']} of {summary['runs']} runs ok: "
                                                   f"{summary['runs_failed']}"}
            cell["note"] = f"{summary['runs_ok']}/{summary['runs']} runs"
        return cell

    chain = [("new", cli("new", folder, "--family", family, "--name", name)),
             ("design", cli("design", toml, "--update")),
             ("generate", cli("generate", toml)),
             ("build", cli("build", toml)),
             ("validate excitation", cli("validate", toml, "--scenario", "excitation", "--json")),
             ("validate --data", data),
             ("check-gains", cli("check-gains", toml, "--gains", lock)),
             ("export fmu", cli("export", toml, "--format", "fmu", "--out", folder / f"{name}.fmu")),
             ("build --float32", float32),
             ("campaign", campaign)]
    needed = {"new", "design", "generate", "build"}      # what the later verbs stand on
    for verb, make in chain:
        if not step(verb, make) and verb in needed:
            for later, _ in chain[len(row):]:
                row[later] = {"outcome": "fail", "note": f"not run: {verb} failed", "seconds": 0.0}
            break
    return row


def matrix(families=None, base: Path | None = None, log=None) -> dict:
    """{family: row} for ``families`` (default: every registered family with a starter)."""
    from .. import families as registry
    names = list(families or [f for f in registry.names() if registry.get(f).example])
    with contextlib.ExitStack() as stack:
        if base is None:
            base = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="uiogen-verbs-")))
        return {f: family_row(f, Path(base), log) for f in names}


def _shown(cell: dict) -> str:
    mark = {"pass": "✓", "refused": "refused", "fail": "✗"}[cell["outcome"]]
    return f"{mark} {cell['note']}".strip() if cell["note"] and cell["outcome"] != "fail" else mark


def record(rows: dict) -> dict:
    """The record ``uiogen docs`` renders: the table, and every cell's outcome and note."""
    return {"command": "python -m codegen.acceptance.verbs --out docs/data/families_and_verbs.json "
                       "(tests/product/test_families_and_verbs.py)",
            "verbs": list(VERBS),
            "cells": {f: {v: {"outcome": c["outcome"], "note": c["note"]} for v, c in row.items()}
                      for f, row in rows.items()},
            "table": {"header": ["family", *VERBS],
                      "rows": [[f"`{f}`", *(_shown(row[v]) for v in VERBS)] for f, row in rows.items()]}}


def write_record(rows: dict, path: Path | None = None) -> Path:
    """Write the record (only when it changed, so a re-run leaves the tree clean)."""
    from ..tools.docs import DATA
    path = Path(path or DATA / f"{RECORD}.json")
    text = json.dumps(record(rows), indent=1, ensure_ascii=False) + "\n"
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)
    return path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m codegen.acceptance.verbs", description=__doc__.split("\n")[0])
    p.add_argument("--only", nargs="+", metavar="FAMILY", help="these families only")
    p.add_argument("--out", help="write the record here (docs/data/families_and_verbs.json)")
    p.add_argument("--keep", help="run in this folder and keep it (default: a temporary one)")
    args = p.parse_args(argv)
    if args.out and args.only:
        p.error("--out writes the record of every family; drop --only")
    rows = matrix(args.only, Path(args.keep) if args.keep else None,
                  log=lambda msg: print(msg, file=sys.stderr, flush=True))
    if args.out:
        write_record(rows, Path(args.out))
    rec = record(rows)
    print(" | ".join(rec["table"]["header"]))
    for r in rec["table"]["rows"]:
        print(" | ".join(r))
    return 0 if all(c["outcome"] != "fail" for row in rows.values() for c in row.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
