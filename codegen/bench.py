"""``uiogen bench``: speed measured against peers in the same run (never asserted in tests).

* one-sample ``step`` from Python (compiled C) vs a CasADi ``Function`` call on the same
  step vs a numpy implementation of the same step;
* batch ``run`` throughput (C loop) in ns/sample and samples/s;
* LMI design time: our Clarabel path (build + solve).
"""
from __future__ import annotations

import json
import time
import timeit

import numpy as np

from . import discrete, observers, pipeline


def _per_call(fn, repeat: int = 7, number: int = 2000) -> float:
    times = timeit.repeat(fn, repeat=repeat, number=number)
    return float(np.median(times) / number)


def bench_observer(name: str) -> dict:
    from python_bindings import load
    cfg = observers.get(name)
    t0 = time.perf_counter()
    b = pipeline.build(cfg)
    design_total = time.perf_counter() - t0
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
    for _ in range(5):
        s0 = np.zeros(obs.n_state)
        t = time.perf_counter()
        obs.run(batch, s0)
        runs.append((time.perf_counter() - t) / n)
    t_batch = float(np.median(runs))
    return {
        "step_python_ns": 1e9 * t_c, "casadi_function_call_ns": 1e9 * t_casadi,
        "numpy_step_ns": 1e9 * t_numpy, "speedup_vs_casadi": t_casadi / t_c,
        "speedup_vs_numpy": t_numpy / t_c, "batch_ns_per_sample": 1e9 * t_batch,
        "batch_samples_per_s": 1.0 / t_batch,
        "lmi_build_ms": 1e3 * b.design.solution.build_time_s,
        "lmi_solve_ms": 1e3 * b.design.solution.solve_time_s,
        "design_total_s": design_total,
    }


def main(json_output: bool = False) -> int:
    res = {name: bench_observer(name) for name in observers.names()}
    if json_output:
        print(json.dumps(res, indent=1, sort_keys=True))
        return 0
    for name, r in res.items():
        print(f"== {name}")
        print(f"   one-sample step from Python (C)   {r['step_python_ns']:9.0f} ns")
        print(f"   CasADi Function call, same step   {r['casadi_function_call_ns']:9.0f} ns   "
              f"(C step is {r['speedup_vs_casadi']:.0f}x faster)")
        print(f"   numpy implementation, same step   {r['numpy_step_ns']:9.0f} ns   "
              f"(C step is {r['speedup_vs_numpy']:.0f}x faster)")
        print(f"   batch run (loop in C)             {r['batch_ns_per_sample']:9.1f} ns/sample   "
              f"({r['batch_samples_per_s'] / 1e6:.1f} M samples/s)")
        print(f"   LMI design: build {r['lmi_build_ms']:.1f} ms + Clarabel solve {r['lmi_solve_ms']:.1f} ms; "
              f"whole pipeline {r['design_total_s']:.2f} s")
    return 0
