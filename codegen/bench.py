"""``uiogen bench``: speed measured against peers in the same run (never asserted in tests).

Per observer:

* C step in the batch loop of the extension (ns/sample of thread CPU time, median and fastest
  of repeats), instructions per step from ``valgrind --tool=callgrind`` on the stand-alone
  driver built with the portable strict flags (repeatable on a noisy machine), and the step's
  floating-point operation count (the floor for this code); the ratio is the headline;
* one-sample ``step`` from Python vs a CasADi ``Function`` call on the same step vs a
  numpy implementation of the same step; batch ``run`` throughput;
* design time: our LMI path (build + Clarabel solve) vs the same LMIs through CVXPY with
  Clarabel and with SCS at the same tolerance, and the objective each reaches;
* toolchain: ``uiogen generate`` cold (forced) and with nothing changed.
"""
from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
import timeit
from pathlib import Path

import casadi as ca
import numpy as np

from . import discrete, harness, observers, pipeline
from .designs import linf_uio

ARITHMETIC_OPS = ("OP_ADD", "OP_SUB", "OP_MUL", "OP_DIV", "OP_NEG", "OP_SQ", "OP_SQRT", "OP_FMIN",
                  "OP_FMAX", "OP_FABS", "OP_EXP", "OP_LOG", "OP_POW", "OP_CONSTPOW", "OP_INV",
                  "OP_TWICE", "OP_FMOD", "OP_ATAN2", "OP_SIN", "OP_COS", "OP_TAN")


def flop_count(f: ca.Function) -> dict:
    """Floating-point operations of a CasADi SX Function, by kind."""
    codes = {getattr(ca, n): n for n in ARITHMETIC_OPS if hasattr(ca, n)}
    counts: dict = {}
    for k in range(f.n_instructions()):
        name = codes.get(f.instruction_id(k))
        if name:
            counts[name] = counts.get(name, 0) + 1
    counts["total"] = sum(counts.values())
    return counts


def callgrind_instructions_per_step(name: str, n1: int = 2000, n2: int = 12000) -> float | None:
    """Instructions per step: (Ir(n2 steps) - Ir(n1 steps)) / (n2 - n1), start-up cancels."""
    if shutil.which("valgrind") is None:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        exe = harness.build_harness(name, Path(tmp))
        counts = []
        for n in (n1, n2):
            proc = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null",
                                   str(exe), str(n)], capture_output=True, text=True)
            m = re.search(r"Collected\s*:\s*(\d+)", proc.stderr)
            if proc.returncode != 0 or not m:
                return None
            counts.append(int(m.group(1)))
    return (counts[1] - counts[0]) / (n2 - n1)


def _per_call(fn, repeat: int = 7, number: int = 2000) -> float:
    return float(np.median(timeit.repeat(fn, repeat=repeat, number=number)) / number)


def _cvxpy_same_lmis(prob_builder, solver: str, tol: float):
    """The same LMI blocks (same coefficients) through CVXPY; returns (seconds, objective) or None."""
    try:
        import cvxpy as cp
    except ImportError:
        return None
    from scipy import sparse
    t0 = time.perf_counter()
    prob, _ = prob_builder()
    x_sym, A, b, q, cones, blocks = prob._compile()
    x = cp.Variable(A.shape[1])
    constraints = []
    for con, sl, _ in blocks:
        n = con.expr.shape[0]
        k = n * (n + 1) // 2
        rows = -A[sl]
        # unpack the scaled triangle into a full symmetric matrix expression
        iu = [(i, j) for j in range(n) for i in range(j + 1)]
        T = sparse.lil_matrix((n * n, k))
        for col, (i, j) in enumerate(iu):
            s = 1.0 if i == j else 1.0 / np.sqrt(2.0)
            T[i * n + j, col] = s
            T[j * n + i, col] = s
        T = T.tocsr()
        mat = cp.reshape(T @ (rows @ x + b[sl]), (n, n), order="C")
        constraints.append(0.5 * (mat + mat.T) >> 0)
    problem = cp.Problem(cp.Minimize(q @ x), constraints)
    kwargs = {"CLARABEL": dict(tol_gap_abs=tol, tol_gap_rel=tol, tol_feas=tol),
              # a peer gets a budget: SCS at 1e-8 can run for many minutes (its status says so)
              "SCS": dict(eps_abs=tol, eps_rel=tol, max_iters=100000, time_limit_secs=60.0)}[solver]
    try:
        problem.solve(solver=solver, **kwargs)
    except Exception as exc:  # a peer failing is a result, not a crash of the benchmark
        return {"seconds": time.perf_counter() - t0, "objective": None, "status": f"error: {exc}"[:120]}
    return {"seconds": time.perf_counter() - t0, "objective": problem.value, "status": problem.status}


def bench_design(b: pipeline.ObserverBuild) -> dict:
    settings = b.design.settings
    builder = lambda: linf_uio.build_problem(b.poly, settings)
    ours = []
    for _ in range(5):
        t0 = time.perf_counter()
        prob, _ = builder()
        sol = prob.solve(tol=settings.tol)
        ours.append((time.perf_counter() - t0, sol.objective))
    t_ours = float(np.median([t for t, _ in ours]))
    obj = ours[0][1]
    out = {"ours_clarabel": {"seconds": t_ours, "objective": obj, "gamma": float(np.sqrt(obj))}}
    for solver in ("CLARABEL", "SCS"):
        res = _cvxpy_same_lmis(builder, solver, settings.tol)
        if res is None:
            out[f"cvxpy_{solver.lower()}"] = {"status": "cvxpy not installed (pip install '.[bench]')"}
            continue
        if res["objective"] is not None and res["objective"] > 0:
            res["gamma"] = float(np.sqrt(res["objective"]))
            res["gamma_rel_diff"] = abs(res["gamma"] - out["ours_clarabel"]["gamma"]) / out["ours_clarabel"]["gamma"]
        res["speedup_of_ours"] = res["seconds"] / t_ours
        out[f"cvxpy_{solver.lower()}"] = res
    return out


def bench_observer(name: str) -> dict:
    from python_bindings import load
    b = pipeline.build(observers.get(name))
    obs = load(name)
    f = b.step_function()
    rng = np.random.default_rng(0)
    nu, ny = b.lpv.nu, b.lpv.ny
    state = rng.standard_normal(obs.n_state) * 0.01
    inp = np.concatenate([rng.standard_normal(nu), rng.standard_normal(ny) * 0.01,
                          [0.5 * (b.poly.signal_lower + b.poly.signal_upper)]])
    out = np.empty(obs.n_output)
    u, y, rho = inp[:nu], inp[nu:nu + ny], inp[-1]
    step = obs.step
    t_c = _per_call(lambda: step(state, inp, out), number=20000)
    t_casadi = _per_call(lambda: f(state, u, y, rho), number=2000)
    t_numpy = _per_call(lambda: discrete.step_numpy(b.data, state, u, y, rho), number=500)
    n = 200000
    batch = np.tile(inp, (n, 1))
    batch[:, -1] = np.linspace(b.poly.signal_lower, b.poly.signal_upper, n)
    runs = []
    for _ in range(15):
        # CPU time of this thread (the C loop runs in it): time slices that other processes
        # take on a shared machine do not count
        t = time.thread_time()
        obs.run(batch, np.zeros(obs.n_state))
        runs.append((time.thread_time() - t) / n)
    t_batch = float(np.median(runs))
    flops = flop_count(f)
    instr = callgrind_instructions_per_step(name)
    return {
        "step_python_ns": 1e9 * t_c, "casadi_function_call_ns": 1e9 * t_casadi,
        "numpy_step_ns": 1e9 * t_numpy, "speedup_vs_casadi": t_casadi / t_c,
        "speedup_vs_numpy": t_numpy / t_c, "batch_ns_per_sample": 1e9 * t_batch,
        "batch_samples_per_s": 1.0 / t_batch, "batch_ns_per_sample_min": 1e9 * min(runs),
        "flops_per_step": flops,
        "instructions_per_step": instr,
        "instructions_per_flop": (instr / flops["total"]) if instr else None,
        "design": bench_design(b),
    }


def bench_toolchain() -> dict:
    """Wall time of `uiogen generate`: forced (cold) into a temp dir, and with nothing changed."""
    cmd = [sys.executable, "-m", "codegen.cli", "generate"]
    root = Path(__file__).resolve().parent.parent
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        subprocess.run([*cmd, "--force", "--out", tmp], check=True, capture_output=True, cwd=root)
        cold = time.perf_counter() - t0
        t0 = time.perf_counter()
        subprocess.run([*cmd, "--out", tmp], check=True, capture_output=True, cwd=root)
        warm = time.perf_counter() - t0
    return {"generate_cold_s": cold, "generate_unchanged_s": warm}


def main(json_output: bool = False) -> int:
    res = {"observers": {name: bench_observer(name) for name in observers.names()},
           "toolchain": bench_toolchain()}
    if json_output:
        print(json.dumps(res, indent=1, sort_keys=True))
        return 0
    for name, r in res["observers"].items():
        print(f"== {name}")
        print(f"   C step, batch loop                {r['batch_ns_per_sample']:9.1f} ns/sample "
              f"({r['batch_samples_per_s'] / 1e6:.1f} M samples/s; fastest repeat "
              f"{r['batch_ns_per_sample_min']:.1f} ns)")
        ins = r["instructions_per_step"]
        print(f"   instructions per step (callgrind) {ins if ins is None else f'{ins:9.0f}'}   "
              f"flops per step {r['flops_per_step']['total']} "
              f"(div {r['flops_per_step'].get('OP_DIV', 0)})   "
              f"ratio {r['instructions_per_flop'] and round(r['instructions_per_flop'], 2)}")
        print(f"   one-sample step from Python (C)   {r['step_python_ns']:9.0f} ns")
        print(f"   CasADi Function call, same step   {r['casadi_function_call_ns']:9.0f} ns   "
              f"(C step {r['speedup_vs_casadi']:.0f}x faster)")
        print(f"   numpy implementation, same step   {r['numpy_step_ns']:9.0f} ns   "
              f"(C step {r['speedup_vs_numpy']:.0f}x faster)")
        d = r["design"]
        print(f"   LMI design, build + solve: ours (Clarabel) {1e3 * d['ours_clarabel']['seconds']:.1f} ms, "
              f"gamma {d['ours_clarabel']['gamma']:.6g}")
        for peer in ("cvxpy_clarabel", "cvxpy_scs"):
            p = d[peer]
            if "seconds" not in p:
                print(f"     {peer}: {p['status']}")
                continue
            g = p.get("gamma")
            print(f"     {peer:15s} {1e3 * p['seconds']:8.1f} ms  gamma {g if g is None else f'{g:.6g}'} "
                  f"({p['status']}; ours {p['speedup_of_ours']:.1f}x faster)")
    t = res["toolchain"]
    print(f"== toolchain: uiogen generate cold {t['generate_cold_s']:.2f} s, unchanged {t['generate_unchanged_s']:.2f} s")
    return 0
