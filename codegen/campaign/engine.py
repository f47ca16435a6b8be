"""Campaigns on Dask: a local cluster of processes by default, any distributed scheduler by address.

Tasks carry the spec (a small frozen dataclass) and a list of run indices, never arrays; each
returns the summary rows of its runs. The same code runs on ``LocalCluster(n_workers=cores,
processes=True, threads_per_worker=1)`` and on ``Client(address)``: workers import ``codegen``,
load the observer's built extension and compile (or find in their disk cache) the plant.
"""
from __future__ import annotations

import csv
import json
import math
import os
import sys
import time
from pathlib import Path

from . import runner


def local_workers() -> int:
    """Cores available to this process."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def client_for(scheduler: str | None = None, workers: int | None = None):
    """(client, cluster or None): ``Client(scheduler)``, else a local cluster of processes."""
    from dask.distributed import Client, LocalCluster
    if scheduler:
        return Client(scheduler), None
    n = workers or local_workers()
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=40)
    return Client(cluster), cluster


def _chunks(spec, runs: int, n_workers: int) -> list:
    size = spec.chunk or max(1, min(50, runs // max(4 * n_workers, 1)))
    return [list(range(i, min(i + size, runs))) for i in range(0, runs, size)]


def run(spec, out_dir, scheduler: str | None = None, workers: int | None = None, progress=None,
        client=None) -> dict:
    """Run every run of ``spec`` on Dask; write ``runs.csv``, ``summary.json``, the worst runs'
    traces and the plots into ``out_dir``; return the summary."""
    from dask.distributed import as_completed
    from . import report
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    runner.prepare(spec)                    # compile the plant once, here: workers find it cached
    own = client is None
    cluster = None
    if own:
        client, cluster = client_for(scheduler, workers)
    try:
        n_workers = max(len(client.scheduler_info(n_workers=-1)["workers"]), 1)
        t0 = time.perf_counter()
        chunks = _chunks(spec, spec.runs, n_workers)
        futures = client.map(runner.run_chunk, [spec] * len(chunks), chunks, pure=False)
        rows, done = [], 0
        for fut in as_completed(futures):
            part = fut.result()
            rows.extend(part)
            done += len(part)
            if progress is not None:
                progress(done / spec.runs)
        wall = time.perf_counter() - t0
        rows.sort(key=lambda r: r["run"])
        worst = report.worst_runs(spec, rows)
        traces = {}
        if worst:
            for k, fut in zip(worst, client.map(runner.run_traces, [spec] * len(worst), worst, pure=False)):
                traces[k] = fut.result()[1]
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
    summary = report.summarize(spec, rows, wall_s=wall, workers=n_workers,
                               scheduler=scheduler or f"LocalCluster({n_workers} processes)")
    write_rows(rows, out_dir / "runs.csv")
    for k, tr in traces.items():
        write_trace(tr, out_dir / f"worst_run_{k}.csv")
    summary["files"] = {"runs": str(out_dir / "runs.csv"), "summary": str(out_dir / "summary.json"),
                        "traces": [str(out_dir / f"worst_run_{k}.csv") for k in traces],
                        "plots": report.plots(spec, rows, traces, out_dir)}
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=1, sort_keys=True))
    return summary


def columns(rows) -> list:
    cols = []
    for r in rows:
        for k in r:
            if k not in cols:
                cols.append(k)
    return cols


def _cell(v) -> str:
    if isinstance(v, float):
        return repr(v)           # shortest repr: reads back to the same double
    return str(v)


def write_rows(rows, path) -> None:
    cols = columns(rows)
    tmp = Path(str(path) + ".tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for r in rows:
            w.writerow([_cell(r.get(c, "")) for c in cols])
    os.replace(tmp, path)


def read_rows(path) -> list:
    """Rows of a ``runs.csv`` with numbers as numbers (floats exactly as written)."""
    out = []
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            row = {}
            for k, v in r.items():
                if k in ("run", "scenario_seed"):
                    row[k] = int(v)
                else:
                    try:
                        row[k] = float(v)
                    except ValueError:
                        row[k] = v
            out.append(row)
    return out


def write_trace(trace: dict, path) -> None:
    keys = list(trace)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for i in range(len(trace["t"])):
            w.writerow([repr(float(trace[k][i])) for k in keys])


def progress_bar():
    """A progress bar on stderr when it is a terminal (runs done / runs), else None."""
    if not sys.stderr.isatty():
        return None
    start = time.perf_counter()

    def show(fraction: float) -> None:
        filled = int(30 * fraction)
        el = time.perf_counter() - start
        eta = el * (1 - fraction) / fraction if fraction > 0 else math.nan
        sys.stderr.write(f"\rcampaign [{'#' * filled}{'.' * (30 - filled)}] {100 * fraction:3.0f}% "
                         f"{el:6.1f}s elapsed, {eta:6.1f}s left")
        if fraction >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()
    return show
