"""How much a re-solve of the committed designs moves, measured two ways (docs: Performance).

* **Another CPU**: every design re-solved under QEMU's user-mode emulation of another x86-64
  CPU model (``qemu-x86_64 -cpu CPU``, Debian's qemu-user): numpy takes other code paths and
  OpenBLAS another kernel, without touching any ``OPENBLAS_*`` variable; the fresh objectives and
  decision variables against the committed ones (``uiogen design NAME --json`` compares them).
* **A perturbation**: every LMI problem solved again with its coefficients perturbed by 1e-13
  relative (seeded), natively: the sensitivity of the selected point to noise of the size BLAS
  kernels leave.

``python -m codegen.tools.spread [--cpu Nehalem] [--out docs/data/spread.json]``; ``uiogen docs``
renders the table.
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys

import numpy as np

from .. import families
from ..design import lmi
from ..project import observer_file as observers
from ..design.lock import variable_spread
from ..design.solver import FreshSolver
from ..design.sources import ROOT


def under_cpu(name: str, cpu: str) -> list:
    qemu = shutil.which("qemu-x86_64")
    if qemu is None:
        return [{"problem": None, "error": "qemu-x86_64 not installed (apt-get install qemu-user)"}]
    proc = subprocess.run([qemu, "-cpu", cpu, sys.executable, "-m", "codegen.cli", "design", name, "--json"],
                          cwd=ROOT, capture_output=True, text=True)
    if proc.returncode != 0:
        return [{"problem": None, "error": proc.stderr.strip().splitlines()[-1] if proc.stderr else "failed"}]
    rows = json.loads(proc.stdout)["committed_design"]["committed"] or []
    return [{"problem": r["problem"], "objective": r["relative_difference"],
             "variables": max(r["variables_relative_difference"].values(), default=0.0),
             "worst_variable": r["worst_variable"]} for r in rows]


class _Capturing(FreshSolver):
    """A fresh solve that also keeps each design problem and its tolerance."""

    def __init__(self):
        super().__init__()
        self.problems = []

    def solve(self, problem, **options):
        if problem.design:
            self.problems.append((problem, options.get("tol", 1e-9)))
        return super().solve(problem, **options)


def under_perturbation(name: str, relative: float = 1e-13, seed: int = 7) -> list:
    config = observers.get(name)
    capturing = _Capturing()
    families.get(config.family).build(config, capturing)
    captured = capturing.problems
    solve = lmi.LMIProblem.solve
    compile_ = lmi.LMIProblem._compile

    def perturbed(self):
        names, A, b, q, cones, blocks = compile_(self)
        rng = np.random.default_rng(seed)
        A = A.copy()
        A.data = A.data * (1 + relative * rng.standard_normal(A.data.size))
        return names, A, b * (1 + relative * rng.standard_normal(b.size)), q, cones, blocks
    rows = []
    for prob, tol in captured:
        ref = solve(prob, tol=tol)
        lmi.LMIProblem._compile = perturbed
        try:
            other = solve(prob, tol=tol)
        finally:
            lmi.LMIProblem._compile = compile_
        spread = variable_spread(ref.values, other.values)
        worst = max(spread, key=spread.get)
        rows.append({"problem": prob.name, "objective": abs(other.objective - ref.objective) / max(abs(ref.objective), 1e-300),
                     "variables": spread[worst], "worst_variable": worst})
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m codegen.tools.spread", description=__doc__.split("\n\n")[0])
    p.add_argument("--cpu", default="Nehalem", help="QEMU CPU model of the other machine")
    p.add_argument("--out", default=str(ROOT / "docs" / "data" / "spread.json"))
    p.add_argument("names", nargs="*")
    args = p.parse_args(argv)
    out = {"cpu": args.cpu, "observers": {}}
    for name in args.names or observers.names():
        out["observers"][name] = {"cpu": under_cpu(name, args.cpu), "perturbation": under_perturbation(name)}
        print(name, file=sys.stderr)
    with open(args.out, "w") as fh:
        json.dump(out, fh, indent=1, sort_keys=True)
        fh.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
