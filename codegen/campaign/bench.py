"""Campaign throughput: runs/s of the core observer's campaign with 1 and 2 local Dask workers
(and the scaling between them), optionally the issue's target, 10,000 runs of 60 s at 100 Hz.

    python -m codegen.campaign.bench [--runs N] [--target] [--json]

Measured by ``make bench`` on an idle machine; never asserted in tests. Each measurement is its own
local cluster, timed from the first task's submission to the last row (cluster start-up and
plant compilation excluded; both are printed)."""
from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from . import engine
from . import spec as campaign_spec

SPEC = Path(__file__).resolve().parents[2] / "docs" / "campaigns" / "lpv_linf_driver_torque.toml"


def measure(spec, workers: int, runs: int) -> dict:
    s = spec.with_runs(runs)
    t0 = time.perf_counter()
    client, cluster = engine.client_for(None, workers)
    started = time.perf_counter() - t0
    try:
        with tempfile.TemporaryDirectory() as tmp:
            summary = engine.run(s, tmp, client=client)
    finally:
        client.close()
        cluster.close()
    return {"workers": workers, "runs": runs, "wall_s": summary["wall_s"], "runs_per_s": summary["runs_per_s"],
            "cluster_start_s": started, "observer_samples_per_s": summary["runs_per_s"] * _samples(s)}


def _samples(spec) -> int:
    from . import runner
    return runner._scenario(spec, spec.scenarios[0], None).t.size


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m codegen.campaign.bench")
    ap.add_argument("--runs", type=int, default=400, help="runs per worker count (default 400 per worker)")
    ap.add_argument("--target", action="store_true", help="also the 10,000-run campaign on all local cores")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    spec = campaign_spec.load(SPEC)
    from . import runner
    t0 = time.perf_counter()
    runner.prepare(spec)
    res = {"spec": str(SPEC), "cores": engine.local_workers(), "load_average": os.getloadavg(),
           "plant_compile_or_cache_s": time.perf_counter() - t0, "samples_per_run": _samples(spec)}
    res["one_worker"] = measure(spec, 1, a.runs)
    res["two_workers"] = measure(spec, 2, 2 * a.runs)
    res["scaling_2_vs_1"] = res["two_workers"]["runs_per_s"] / res["one_worker"]["runs_per_s"]
    if a.target:
        res["target_10000"] = measure(spec, engine.local_workers(), 10_000)
    res["load_average_after"] = os.getloadavg()
    if a.json:
        print(json.dumps(res, indent=1))
        return 0
    print(f"campaign bench ({res['spec']}, {res['samples_per_run']} samples per run, {res['cores']} cores, "
          f"load average {res['load_average'][0]:.2f} before, {res['load_average_after'][0]:.2f} after)")
    for key in ("one_worker", "two_workers", "target_10000"):
        if key in res:
            r = res[key]
            print(f"  {r['workers']} worker(s): {r['runs']} runs in {r['wall_s']:.1f} s = {r['runs_per_s']:.1f} runs/s "
                  f"({r['observer_samples_per_s'] / 1e6:.2f} M observer+plant samples/s; cluster start "
                  f"{r['cluster_start_s']:.1f} s)")
    print(f"  scaling 2 vs 1 worker: {res['scaling_2_vs_1']:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
