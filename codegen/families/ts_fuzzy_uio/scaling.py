"""How the TS design grows with the number of rules (``uiogen bench``): 2 to 32 rules.

One model family, the single-track model of Nguyen et al. 2021 with linear tyres, given one more
measured premise at a time (1/v_x; then r; then r^2 v_y, r^3 v_y, r^4 v_y terms of small
weight): 2, 4, 8, 16 and 32 rules. Each point is designed in a fresh process under both
relaxations of (27) (the paper's rule triples, N^3 blocks per DMVT vertex; rule pairs with a
common bound of the next Lyapunov matrix, N^2), and reports its blocks, variables, the size
guard's estimate, the measured design time and the process's peak memory, or the refusal (and
how long it took). ``python -m codegen.families.ts_fuzzy_uio.scaling N RELAXATION DIR`` runs one.
"""
from __future__ import annotations

import json
import resource
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

from ...design.sources import ROOT

RULES = (2, 4, 8, 16, 32)

MODEL = '''
"""Single-track model, linear tyres, {extra} extra measured premises (uiogen bench, TS growth)."""
import sympy as sp
from codegen.model import ModelDefinition

v_x = sp.Symbol("v_x", positive=True)
v_y, r, T_eng, delta = sp.symbols("v_y r T_eng delta")
M, l_f, l_r, I_e, I_z, C_f, C_r = sp.symbols("M l_f l_r I_e I_z C_f C_r", positive=True)
F_yf = 2 * C_f * (delta - (v_y + l_f * r) / v_x)
F_yr = 2 * C_r * (l_r * r - v_y) / v_x + M * ({terms})
MODEL = ModelDefinition(
    name="ts_growth_{rules}", states=(v_x, v_y, r), known_inputs=(), unknown_inputs=(T_eng, delta),
    dynamics=sp.Matrix([T_eng / I_e{coupling}, (F_yf + F_yr) / M - v_x * r, (l_f * F_yf - l_r * F_yr) / I_z]),
    outputs=(("v_x", v_x), ("r", r)), scheduling=(),
    parameters=(M, l_f, l_r, I_e, I_z, C_f, C_r))
'''

PARAMETERS = """[parameters]
M = 1476.0
l_f = 1.13
l_r = 1.49
I_e = 442.8
I_z = 1810.0
C_f = 57000.0
C_r = 59000.0

[state_bounds]
v_x = [5.0, 30.0]
v_y = [-1.5, 1.5]
r = [-0.55, 0.55]
"""


def write_project(rules: int, relaxation: str, folder: Path) -> Path:
    """The model, parameter and observer files of the ``rules``-rule point."""
    extra = {2: 0, 4: 0, 8: 1, 16: 2, 32: 3}[rules]
    terms = " + ".join(f"1e-3 * r**{k + 2} * v_y" for k in range(extra)) or "0"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "car.py").write_text(MODEL.format(extra=extra, terms=terms, rules=rules,
                                                coupling="" if rules == 2 else " + v_y * r"))
    (folder / "car.toml").write_text(PARAMETERS)
    obs = folder / f"ts_growth_{rules}_{relaxation}.toml"
    obs.write_text(textwrap.dedent(f'''\
        family = "ts_fuzzy_uio"
        model = "car.py"
        parameters = "car.toml"
        sample_time = 0.01

        [design]
        relaxation = "{relaxation}"
        '''))
    return obs


def run_point(rules: int, relaxation: str, folder: Path) -> dict:
    """Design one point in this process: counts, the pipeline's time (model to certificate, or to
    the refusal), peak memory, outcome."""
    from ...project import observer_file as observers
    from ... import pipeline
    from ...design.solver import FreshSolver
    from ...errors import UiogenError
    from ...model import load_parameters
    from . import design as ts_design
    from . import representation
    config = observers.get(str(write_project(rules, relaxation, folder)))
    row = {"rules": rules, "relaxation": relaxation}
    # the counts (bounds included) outside the timing: the pipeline refuses before its bounds
    ts = representation.build(config.load_model(), load_parameters(config.parameter_path), config.sample_time)
    row.update(ts_design.problem_size(ts.n_rules, ts.nx, ts.ny, int(ts.theta_vertices.shape[0]), relaxation))
    t0 = time.perf_counter()
    try:
        b = pipeline.build(config, FreshSolver())
        row.update(outcome="certified", blocks_built=b.recheck["blocks"],
                   lyapunov_decrease=b.decrease["max_ratio"])
    except UiogenError as exc:
        row.update(outcome=f"{type(exc).__name__}")
    row["seconds"] = time.perf_counter() - t0
    row["peak_memory_gb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6   # KiB on Linux
    return row


def growth(rules=RULES, timeout_s: float = 300.0) -> list:
    """Every point in a fresh interpreter (its own peak memory), both relaxations."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="uiogen-ts-growth-") as tmp:
        for n in rules:
            for relaxation in ("triples", "pairs"):
                proc = subprocess.run([sys.executable, "-m", __name__, str(n), relaxation, str(Path(tmp) / f"{n}")],
                                      capture_output=True, text=True, cwd=ROOT, timeout=timeout_s)
                if proc.returncode != 0:
                    rows.append({"rules": n, "relaxation": relaxation, "outcome": "process failed",
                                 "error": proc.stderr.strip().splitlines()[-1:]})
                    continue
                rows.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    return rows


def lines(rows: list) -> list:
    out = [f"   {'rules':>5s} {'relaxation':10s} {'blocks':>8s} {'variables':>9s} {'est. GB':>8s} {'s':>7s} "
           f"{'peak GB':>8s}  outcome"]
    for r in rows:
        out.append(f"   {r['rules']:5d} {r['relaxation']:10s} {r.get('lmi_blocks', 0):8d} {r.get('variables', 0):9d} "
                   f"{r.get('memory_gb', float('nan')):8.3g} {r.get('seconds', float('nan')):7.2f} "
                   f"{r.get('peak_memory_gb', float('nan')):8.2f}  {r['outcome']}")
    return out


if __name__ == "__main__":
    print(json.dumps(run_point(int(sys.argv[1]), sys.argv[2], Path(sys.argv[3]))))
