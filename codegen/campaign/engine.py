"""Campaigns on Dask: a local cluster of processes by default, any distributed scheduler by address.

Tasks carry the spec (a small frozen dataclass) and a list of run indices, never arrays; each
returns the summary rows of its runs. The same code runs on ``LocalCluster(n_workers=cores,
processes=True, threads_per_worker=1)`` and on ``Client(address)``: workers import ``codegen``,
load the observer's built extension and compile (or find in their disk cache) the plant.

What a campaign did is never lost: every finished task's rows are appended to ``runs.jsonl``
(synced to disk) as it finishes; ``--resume`` continues an interrupted campaign from there; a
lost worker is Dask's to replace, and a cluster with no worker left, or no run finished within
the per-run timeout, stops the campaign with a typed error instead of waiting forever.
"""
from __future__ import annotations

import contextlib
import csv
import errno
import fcntl
import hashlib
import json
import logging
import math
import os
import sys
import time
from pathlib import Path

from . import runner
from ..errors import CampaignError, OutputError
from ..project import outputs


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
        try:
            return Client(scheduler), None
        except (OSError, TimeoutError) as exc:        # no scheduler there (distributed waits 30 s, then this)
            cause = " ".join(str(exc).split()) or type(exc).__name__
            raise CampaignError(f"cannot reach the Dask scheduler at {scheduler} ({cause}); start it (`dask "
                                f"scheduler`, then workers) or leave out --scheduler for a local cluster") from None
    n = workers or local_workers()
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=40)
    return Client(cluster), cluster


def _chunks(spec, runs, n_workers: int) -> list:
    runs = list(runs)
    size = spec.chunk or max(1, min(50, len(runs) // max(4 * n_workers, 1)))
    return [runs[i:i + size] for i in range(0, len(runs), size)]


JOURNAL = "runs.jsonl"
# statuses of runs that produced no result; --resume runs the worker_lost ones again (a lost worker is the
# machine's failure, not the run's: the run itself re-runs bit for bit from its index)
NO_RESULT = ("worker_lost", "error")
RETRIED = ("worker_lost",)
LOCK = ".campaign.lock"
JOURNAL_FORMAT = 1
GATHER_TIMEOUT = 5.0       # s to fetch a finished task's rows before looking at the cluster again


def identity(spec, design_hash: str) -> dict:
    """What a run's row derives from besides its index: the campaign's draws and scenarios as
    parsed (not ``runs``: run K is the same run in a campaign of any length; not how it is
    scheduled or ranked) and the observer's design."""
    import dataclasses
    rows_from = {k: getattr(spec, k) for k in ("observer", "scenarios", "seed", "duration", "scenario_seed",
                                               "parameters", "driver", "sensors")}
    if spec.logs:            # a log rewritten since is another run: its size and time of change
        rows_from["logs"] = [[name, *_stat(spec.log_path(name))] for name in spec.logs]
    text = json.dumps(rows_from, sort_keys=True, default=lambda d: dataclasses.asdict(d))
    return {"format": JOURNAL_FORMAT, "observer": spec.observer, "design": design_hash,
            "spec_sha256": hashlib.sha256(text.encode()).hexdigest()}


class Journal:
    """The rows of a campaign, appended as their runs finish: one JSON line per run (floats
    written as their shortest repr, which reads back to the same double), flushed and synced to
    disk per finished task, so a campaign killed at any point keeps every run it finished. The
    first line is the campaign's :func:`identity`; the last, once every run is in, ``{"complete": N}``.
    """

    def __init__(self, path: Path, header: dict, resume: bool, source: str = "SPEC"):
        self.path, self.header, self.source = Path(path), header, source
        self.rows: dict = {}
        self.finished = False               # the end mark is in the file (a resumed, finished campaign)
        self._fd = None
        # the folder too: without --out the command would continue the default folder, not this one
        resume_hint = f"`uiogen campaign {source} --resume --out {self.path.parent}` continues it"
        if self.path.exists():
            found, rows, complete = self._read()
            if resume:
                if found != header:
                    diff = ", ".join(k for k in header if found.get(k) != header.get(k)) or "format"
                    raise CampaignError(f"{self.path}: --resume: these results are of another campaign ({diff} "
                                        f"differ: the campaign file or the observer's design changed since); "
                                        f"run without --resume into another --out folder, or delete {self.path}")
                self.rows, self.finished = rows, complete
            elif not complete and rows:         # a header alone: nothing was run, nothing to lose
                raise CampaignError(f"{self.path}: holds {len(rows)} finished runs of an interrupted campaign; "
                                    f"{resume_hint}, or delete {self.path} to start over")

    def start(self) -> None:
        """Open the journal for appending (a new one, or one without runs, gets its header first):
        called once the campaign has a cluster, so a campaign that never ran leaves no journal."""
        if not self.rows:
            self._write_all([self.header])
        with outputs.writing(self.path, "open"):
            self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND)

    def _read(self) -> tuple:
        """(header, {run: row}, complete) of an existing journal; a torn last line (the process
        killed while writing it) is cut off, any other damage is an error."""
        raw = self.path.read_bytes()
        end = raw.rfind(b"\n") + 1             # after it: a line cut by a kill while it was written
        if end < len(raw):
            with open(self.path, "r+b") as fh:
                fh.truncate(end)
        entries = []
        for i, line in enumerate(raw[:end].splitlines()):
            try:
                entries.append(json.loads(line))
            except (json.JSONDecodeError, UnicodeDecodeError):
                raise CampaignError(f"{self.path}: line {i + 1} is not a JSON row: the results file is damaged "
                                    f"(it is only ever appended to); delete it to start over") from None
        if not entries or not isinstance(entries[0], dict) or "spec_sha256" not in entries[0]:
            raise CampaignError(f"{self.path}: not a campaign results file (no header line); delete it to start over")
        rows, complete = {}, False
        for i, e in enumerate(entries[1:], start=2):
            if isinstance(e, dict) and "complete" in e:
                complete = True
            elif isinstance(e, dict) and isinstance(e.get("run"), int):
                if e["run"] not in rows or rows[e["run"]].get("status") in RETRIED:
                    rows[e["run"]] = e          # a lost run run again by --resume: its later row
            else:
                raise CampaignError(f"{self.path}: line {i} is neither a run's row nor the end mark: the results "
                                    f"file is damaged; delete it to start over")
        return entries[0], rows, complete

    def _write_all(self, entries) -> None:
        tmp = self.path.with_name(self.path.name + ".tmp")
        try:
            with outputs.writing(self.path):
                with open(tmp, "w") as fh:
                    fh.write("".join(json.dumps(e) + "\n" for e in entries))
                    fh.flush()
                    os.fsync(fh.fileno())
                os.replace(tmp, self.path)
        except BaseException:
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise

    def _append(self, text: str) -> None:
        """Append whole lines and sync them; a write the disk refuses is cut off again (the journal
        keeps every line before it) and is an :class:`OutputError` saying what is kept and how to go on."""
        data = text.encode()
        end = os.lseek(self._fd, 0, os.SEEK_END)
        try:
            while data:
                data = data[os.write(self._fd, data):]
            os.fsync(self._fd)
        except OSError as exc:
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, end)
            if exc.errno not in outputs.DISK_ERRORS:
                raise
            name = errno.errorcode.get(exc.errno, "")
            raise OutputError(f"cannot write {self.path}: {exc.strerror}{f' ({name})' if name else ''}; the "
                              f"{len(self.rows)} runs finished before are kept there: free space (or make it "
                              f"writable), then `uiogen campaign {self.source} --resume --out {self.path.parent}` "
                              f"continues the campaign") from None

    def append(self, rows) -> None:
        """Keep ``rows`` (one write, then synced to disk)."""
        if not rows:
            return
        self._append("".join(json.dumps(r) + "\n" for r in rows))
        for r in rows:
            k = int(r["run"])
            if k not in self.rows or self.rows[k].get("status") in RETRIED:
                self.rows[k] = r

    def complete(self, runs: int) -> None:
        """Mark the campaign finished (a later campaign into the same folder may start over); once:
        resuming a finished campaign only re-writes its reports (and runs its lost runs again, whose
        later rows count)."""
        if not self.finished:
            self._append(json.dumps({"complete": runs}) + "\n")
            self.finished = True

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


@contextlib.contextmanager
def exclusive(out_dir: Path, source: str = "SPEC"):
    """Hold ``out_dir/.campaign.lock`` (``flock``, released when the process ends however it ends):
    a second campaign into the same folder is refused instead of sharing (or deleting) its journal."""
    path = out_dir / LOCK
    with outputs.writing(path, "open"):
        fh = open(path, "a+")
    with fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            pid = fh.read().strip() or "?"
            raise CampaignError(f"another campaign is running into {out_dir} (pid {pid}); wait for it, or stop it "
                                f"(its finished runs are kept: `uiogen campaign {source} --resume --out {out_dir}` "
                                f"continues it), or choose another --out") from None
        with contextlib.suppress(OSError):          # who holds it, for the message above (best effort)
            fh.seek(0)
            fh.truncate()
            fh.write(f"{os.getpid()}\n")
            fh.flush()
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _stat(path: Path) -> list:
    """[bytes, mtime_ns] of a log (a ROS 2 bag: of each file in its folder)."""
    files = sorted(f for f in path.rglob("*") if f.is_file()) if path.is_dir() else [path]
    return [[f.name, f.stat().st_size, f.stat().st_mtime_ns] for f in files]


def _failed_rows(spec, runs, status: str, error: str) -> list:
    """Rows of runs that produced no result (their worker died, or the run raised): the run, its
    scenario (or log), the status and what happened; counted, never scored."""
    return [{"run": int(k), spec.run_source(int(k))[0]: spec.run_source(int(k))[1], "status": status,
             "error": error} for k in runs]


class _OrphanedGather(logging.Filter):
    """Drops one log record: a gather that timed out (the rows of a task whose worker died, waited
    for again as a pending task's) leaves a helper task in distributed that fails with AllExit
    when the client closes, which asyncio logs as a "Task exception was never retrieved"
    traceback. Nothing failed: the task was re-run or is reported among the unfinished runs."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        return type(exc).__name__ != "AllExit"


def _quiet_orphaned_gathers() -> None:
    log = logging.getLogger("asyncio")
    if not any(isinstance(f, _OrphanedGather) for f in log.filters):
        log.addFilter(_OrphanedGather())


def _execute(client, spec, todo: list, n_workers: int, journal: Journal, progress, done_before: int,
             log) -> list:
    """Run the runs ``todo`` on the cluster, appending each finished task's rows to the journal;
    returns the runs left unfinished (empty unless the cluster lost every worker, or no run
    finished within the per-run timeout)."""
    from dask.distributed import TimeoutError as DaskTimeoutError, as_completed
    from distributed import KilledWorker
    _quiet_orphaned_gathers()
    chunks = _chunks(spec, todo, n_workers)
    futures = client.map(runner.run_chunk, [spec] * len(chunks), chunks, pure=False)
    pending = dict(zip(futures, chunks))
    queue = as_completed(futures)
    done = done_before
    last_progress = last_check = time.monotonic()
    no_workers_since = None
    while pending:
        batch = queue.next_batch(block=False) if queue.has_ready() else []
        for fut in batch:
            chunk = pending.pop(fut)
            try:
                # the rows live on the worker that ran the task: if it died since, Dask re-runs the
                # task, and its rows are waited for like any pending task's, not here
                rows = fut.result(timeout=GATHER_TIMEOUT)
            except DaskTimeoutError:
                pending[fut] = chunk
                queue.add(fut)
                continue
            except Exception as exc:           # a run raised, or killed its worker (Dask gave up re-running it)
                if len(chunk) > 1:             # which run: each alone, once; the others are kept
                    singles = client.map(runner.run_chunk, [spec] * len(chunk), [[k] for k in chunk], pure=False)
                    pending.update(zip(singles, [[k] for k in chunk]))
                    queue.update(singles)
                    continue
                rows = _failed_rows(spec, chunk, "worker_lost" if isinstance(exc, KilledWorker) else "error",
                                    f"{type(exc).__name__}: {exc}")
            journal.append(rows)
            done += len(rows)
            last_progress = time.monotonic()
            if progress is not None:
                progress(done / spec.runs)
        if not batch:
            time.sleep(0.1)
        now = time.monotonic()
        if now - last_check < 1.0 or not pending:        # the cluster's state: once a second
            continue
        last_check = now
        try:
            workers = len(client.scheduler_info(n_workers=-1)["workers"])
        except Exception as exc:               # the scheduler itself is gone
            log(f"campaign: the scheduler is unreachable ({type(exc).__name__}: {exc})")
            break
        no_workers_since = None if workers else (no_workers_since or now)
        if no_workers_since is not None and now - no_workers_since > spec.run_timeout:
            log(f"campaign: no worker for {spec.run_timeout:g} s (run_timeout): every worker was lost")
            break
        stall = spec.run_timeout * max(len(c) for c in pending.values())
        if now - last_progress > stall:
            log(f"campaign: no task finished for {stall:g} s ({spec.run_timeout:g} s per run of a task) with "
                f"{workers} worker(s): they were lost or hang")
            break
    left = sorted(k for chunk in pending.values() for k in chunk)
    for fut in pending:
        fut.cancel()
    return left


def run(spec, out_dir, scheduler: str | None = None, workers: int | None = None, progress=None,
        client=None, resume: bool = False, log=None) -> dict:
    """Run every run of ``spec`` on Dask; write ``runs.csv``, ``summary.json``, the worst runs'
    traces and the plots into ``out_dir``; return the summary.

    Each finished task's rows are appended to ``out_dir/runs.jsonl`` (:class:`Journal`) as it
    finishes; with ``resume`` the runs already there are not run again (the journal must be of
    the same campaign file and design). A worker that dies is replaced (Dask re-runs its tasks);
    a task that kills its worker repeatedly is re-run one run at a time and the run that does is
    reported (status ``worker_lost``: ``resume`` runs it again); a run that raises is reported (status
    ``error``). When
    every worker is gone, or no run finishes within ``run_timeout``, the campaign stops and
    raises :class:`CampaignError` naming the runs it kept and the command that continues it.
    """
    log = log or (lambda text: print(text, file=sys.stderr))
    from . import memory
    # before the folder, the lock or a cluster: a campaign that cannot fit writes nothing (the workers of a
    # scheduler given by address, or of a client passed in, are another machine's: not counted here)
    memory.check(spec, 0 if (scheduler or client is not None) else (workers or local_workers()))
    out_dir = outputs.make_folder(out_dir)     # a file in the way is named
    with exclusive(out_dir, spec.source):
        return _run(spec, out_dir, scheduler, workers, progress, client, resume, log)


def _run(spec, out_dir: Path, scheduler, workers, progress, client, resume: bool, log) -> dict:
    design = runner.prepare(spec)           # the design is current; the plant compiled once, here
    journal = Journal(out_dir / JOURNAL, identity(spec, design), resume, source=spec.source)
    try:
        todo = [k for k in range(spec.runs) if k not in journal.rows or journal.rows[k].get("status") in RETRIED]
        wall, n_workers, left = 0.0, 0, []
        if not todo:
            journal.start()
        else:
            own = client is None
            cluster = None
            if own:
                client, cluster = client_for(scheduler, workers)
            try:
                journal.start()                 # a cluster exists: from here on the campaign has run
                if not resume:
                    with outputs.writing(out_dir):
                        for stale in ("runs.csv", "summary.json"):
                            (out_dir / stale).unlink(missing_ok=True)   # never beside another campaign's results
                n_workers = max(len(client.scheduler_info(n_workers=-1)["workers"]), 1)
                t0 = time.perf_counter()
                left = _execute(client, spec, todo, n_workers, journal, progress, spec.runs - len(todo), log)
                wall = time.perf_counter() - t0
            finally:
                if own:
                    client.close()
                    if cluster is not None:
                        cluster.close()
        if left:
            raise CampaignError(f"campaign {spec.source}: {spec.runs - len(left)} of {spec.runs} runs finished and "
                                f"kept in {journal.path}; {len(left)} did not finish (runs {_ranges(left)}): "
                                f"`uiogen campaign {spec.source} --resume --out {out_dir}` continues it")
        journal.complete(spec.runs)
    finally:
        journal.close()
    writing = [out_dir]                 # the file being written, for the message
    try:
        return _reports(spec, out_dir, journal, scheduler, wall, n_workers, len(todo), writing)
    except OSError as exc:           # a full disk after the last run: every run is in the journal
        if exc.errno not in outputs.DISK_ERRORS:
            raise
        name = errno.errorcode.get(exc.errno, "")
        where = writing[-1]
        raise OutputError(f"cannot write {where}: {exc.strerror}{f' ({name})' if name else ''}; all {spec.runs} runs "
                          f"finished and are kept in {journal.path}: free space, then `uiogen campaign {spec.source} "
                          f"--resume --out {out_dir}` writes the reports without running them again") from None


def _reports(spec, out_dir: Path, journal: Journal, scheduler, wall: float, n_workers: int, ran: int,
             writing: list) -> dict:
    """runs.csv, the worst runs' traces, the plots and summary.json of a finished campaign (``writing``
    gets each file as it is written)."""
    from . import report
    rows = sorted((journal.rows[k] for k in range(spec.runs)), key=lambda r: r["run"])
    # the worst runs' traces: re-run here (a row re-runs bit for bit from its index alone)
    worst = report.worst_runs(spec, rows)
    traces = {k: runner.run_traces(spec, k)[1] for k in worst}
    summary = report.summarize(spec, rows, wall_s=wall, workers=n_workers,
                               scheduler=scheduler or f"LocalCluster({n_workers} processes)")
    summary["resumed_runs"] = spec.runs - ran
    summary["runs_per_s"] = ran / wall if wall > 0 else None       # the runs this call ran
    writing.append(out_dir / "runs.csv")
    write_rows(rows, out_dir / "runs.csv")
    for k, tr in traces.items():
        writing.append(out_dir / f"worst_run_{k}.csv")
        write_trace(tr, out_dir / f"worst_run_{k}.csv")
    writing.append(out_dir)                      # the plots: PNG files in it
    summary["files"] = {"runs": str(out_dir / "runs.csv"), "journal": str(journal.path),
                        "summary": str(out_dir / "summary.json"),
                        "traces": [str(out_dir / f"worst_run_{k}.csv") for k in traces],
                        "plots": report.plots(spec, rows, traces, out_dir)}
    writing.append(out_dir / "summary.json")
    with _replacing(out_dir / "summary.json") as tmp:
        tmp.write_text(json.dumps(summary, indent=1, sort_keys=True))
    return summary


@contextlib.contextmanager
def _replacing(path: Path):
    """A temporary sibling of ``path`` to write, renamed onto it when the block succeeds and
    removed when it does not (a full disk leaves the previous file, never a part)."""
    tmp = Path(str(path) + ".tmp")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def _ranges(runs: list) -> str:
    """``[3, 4, 5, 9]`` as ``3-5, 9`` (at most ten groups shown)."""
    groups, start = [], None
    for i, k in enumerate(runs):
        if start is None:
            start = k
        if i + 1 == len(runs) or runs[i + 1] != k + 1:
            groups.append(f"{start}-{k}" if k != start else f"{k}")
            start = None
    return ", ".join(groups[:10]) + (f", ... ({len(groups) - 10} more)" if len(groups) > 10 else "")


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
    with _replacing(Path(path)) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for r in rows:
            w.writerow([_cell(r.get(c, "")) for c in cols])


def read_rows(path) -> list:
    """Rows of a ``runs.csv`` with numbers as numbers (floats exactly as written)."""
    out = []
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            row = {}
            for k, v in r.items():
                if v == "":                    # a key the row does not have (write_rows leaves it blank)
                    continue
                if k in ("run", "scenario_seed"):
                    row[k] = int(v)
                elif k in ("scenario", "log", "status", "error"):      # names, whatever they look like
                    row[k] = v
                else:
                    try:
                        row[k] = float(v)
                    except ValueError:
                        row[k] = v
            out.append(row)
    return out


def write_trace(trace: dict, path) -> None:
    keys = list(trace)
    with _replacing(Path(path)) as tmp, open(tmp, "w", newline="") as fh:
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
