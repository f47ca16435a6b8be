"""The acceptance of C == model on random models: each registered family's draws (its capability
:class:`~codegen.contract.capabilities.RandomModels`, :mod:`codegen.families.random_models`) written into
a folder and taken through the user's commands, ``uiogen design --update``, ``uiogen generate``, ``uiogen
build`` (which installs the extension only when :func:`codegen.extension.conformance.check` passes), then
:func:`~codegen.extension.conformance.check` once more on the installed extension.

``python -m codegen.acceptance.random_models [--family F ...] [--draws N] [--first SEED] --dir DIR`` prints one
line per draw and the acceptance rate per family. A design the family refuses is an acceptable outcome
only as a typed error (exit 2, one line, no traceback); :func:`acceptance` reports how many draws design.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..families.random_models import RandomModel, draw, drawers


@dataclass
class Outcome:
    """What became of one drawn model.

    ``status``: ``"conforms"`` (designed, generated, built: ``uiogen build`` installed it after its
    conformance check, and the direct check passed too), ``"refused"`` (the design was refused with
    a typed error: ``error``, one line), or ``"failed"`` (anything else: a traceback, a conformance
    disagreement, a command that failed after the design passed).
    """

    model: RandomModel
    status: str
    error: str = ""
    seconds: float = 0.0
    report: object = None            # the direct conformance.check Report
    build_line: str = ""             # what `uiogen build` printed about its conformance check
    details: dict = field(default_factory=dict)


def _cli(argv: list) -> tuple:
    """(exit code, stdout, stderr) of ``uiogen ARGV`` in this process (:func:`codegen.acceptance.verbs.run_cli`);
    a traceback, which the console script would print, is the end of stderr."""
    from .verbs import run_cli
    r = run_cli(argv)
    return r["code"], r["stdout"], r["stderr"] + (r["traceback"] or "")


def run(model: RandomModel, folder: Path) -> Outcome:
    """Write ``model`` into ``folder`` and take it through design, generate, build; the outcome carries
    the report of the conformance check that installed the extension (:func:`codegen.extension.conformance.check`,
    recorded by the build for the installed design)."""
    from ..extension import conformance
    from ..extension.build import conformance_record, load
    from ..project import observer_file as observers
    t0 = time.perf_counter()
    path = model.write(folder)
    code, out, err = _cli(["design", path, "--update"])
    if code != 0:
        one_line = err.strip()
        typed = code == 2 and "Traceback" not in err and len(one_line.splitlines()) == 1
        return Outcome(model, "refused" if typed else "failed", one_line, time.perf_counter() - t0)
    for argv in (["generate", path], ["build", path]):
        code, out, err = _cli(argv)
        if code != 0:
            return Outcome(model, "failed", f"uiogen {argv[0]}: {err.strip()}", time.perf_counter() - t0)
    line = next((ln for ln in out.splitlines() if "conformance:" in ln), "")
    config = observers.get(str(path))
    # the check that installed the extension, as `uiogen build` recorded it; it must be of the installed
    # module's design (not a record left by an earlier build)
    record = conformance_record(config)
    installed = load(config).design_sha256
    if record.get("design_sha256") != installed:
        return Outcome(model, "failed", f"uiogen build: no conformance record of the installed design {installed[:12]}",
                       time.perf_counter() - t0)
    return Outcome(model, "conforms", "", time.perf_counter() - t0, conformance.Report.from_record(record), line)


def acceptance(outcomes: list) -> dict:
    """{family: {"draws", "conforms", "refused", "failed", "rate"}}: the fraction of draws designed."""
    out: dict = {}
    for o in outcomes:
        row = out.setdefault(o.model.family, {"draws": 0, "conforms": 0, "refused": 0, "failed": 0})
        row["draws"] += 1
        row[o.status] += 1
    for row in out.values():
        row["rate"] = row["conforms"] / row["draws"]
    return out


def main(argv=None) -> int:
    """``python -m codegen.acceptance.random_models [--family F ...] [--draws N] [--first SEED] --dir DIR``:
    draw, design, build and check; one line per draw and the acceptance rate per family."""
    ap = argparse.ArgumentParser(prog="python -m codegen.acceptance.random_models")
    ap.add_argument("--family", action="append", choices=sorted(drawers()))
    ap.add_argument("--draws", type=int, default=10)
    ap.add_argument("--first", type=int, default=0, help="the first seed (draws first, first + 1, ...)")
    ap.add_argument("--dir", required=True, help="a folder for the drawn projects")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    from .. import families
    for name in families.names():
        if name not in drawers():        # a family that hands in no drawer is said, never left out silently
            print(f"{name}: no random-model drawer (the capability RandomModels): not drawn", file=sys.stderr)
    outcomes = []
    for family in args.family or sorted(drawers()):
        for seed in range(args.first, args.first + args.draws):
            m = draw(family, seed)
            o = run(m, Path(args.dir) / family / f"seed{seed}")
            o.details["seed"] = seed
            outcomes.append(o)
            print(f"{family} seed {seed} {m.name}: {o.status} ({o.seconds:.1f} s) {o.error or o.build_line}",
                  file=sys.stderr, flush=True)
    rates = acceptance(outcomes)
    if args.json:
        print(json.dumps({"acceptance": rates, "draws": [
            {"family": o.model.family, "seed": o.details["seed"], "name": o.model.name, "structure": o.model.structure,
             "status": o.status, "error": o.error, "seconds": o.seconds} for o in outcomes]}, indent=1))
    else:
        for family, row in rates.items():
            print(f"{family}: {row['conforms']} of {row['draws']} designed and conform ({100 * row['rate']:.0f} %), "
                  f"{row['refused']} refused with a typed error, {row['failed']} failed")
    return 1 if any(o.status == "failed" for o in outcomes) else 0


if __name__ == "__main__":
    sys.exit(main())
