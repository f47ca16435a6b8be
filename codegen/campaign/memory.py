"""What a campaign holds in memory, the memory limit that applies to it, and the refusal, before
anything runs or is written, of a campaign that cannot fit.

A run is held whole: its scenario's inputs (for the ``excitation`` scenario, the stage-input matrix
of :class:`~codegen.validation.model_plant.ModelPlant`, ``2 SUBSTEPS + 1`` rows per external signal),
the compiled plant's trajectory, the measurements and the observer's outputs, every one an array of
float64 over the run's samples. :func:`estimate` counts those arrays, with the copies the pipeline
makes (CasADi copies the plant's input matrix in and its trajectory out), per worker process and for
the coordinator (which also re-runs the worst runs for their traces, keeps those traces and keeps
every run's summary row); :func:`memory_limit` reads the limit that applies (the smallest of the
physical memory, the memory available now, the cgroup's, v2 or v1, and ``RLIMIT_AS``); :func:`check` refuses, naming the
campaign file, the key, both figures and what would fit.

The per-sample counts are those of the code (see :func:`run_bytes`); the constant parts (a worker
process's interpreter, numpy, CasADi, Dask and the loaded extension: :data:`PROCESS_BYTES`) were
measured. ``tests/campaign/test_campaign_memory.py`` measures a run's peak resident memory and holds
the estimate within :data:`FACTOR` of it.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

GiB = 2 ** 30
# resident memory of a worker (or the coordinator) before its first run: Python, numpy, CasADi, Dask,
# the observer's extension and the compiled plant (measured on Linux x86-64 after a short campaign:
# 155 MiB a worker, 183 MiB the coordinator)
PROCESS_BYTES = 256 * 2 ** 20
# a summary row the coordinator keeps per run (a dict from one JSON line: a key string, a float and a
# hash-table slot per column; measured with tracemalloc: 1,990 bytes a row of 18 columns, 110 a column)
ROW_BYTES_PER_COLUMN = 120
ROW_BYTES = 200                  # the dict itself
# copies of a chunk of the plant's input matrix alive at once in a call of the compiled plant (numpy's
# array converted to CasADi's column-major DM on the way in, the plant's work vector and trajectory): the
# peak of a run above the per-sample arrays, 41 MB for a chunk of 10,000 samples of 63 rows (measured
# at 300 and 1,200 s of excitation, the slope and the intercept of the peak)
CASADI_COPIES = 7
# the estimate of a run's peak is within this factor of the measured one (from above: it is an
# upper bound at long durations, where the per-sample arrays dominate)
FACTOR = 2.0
# a run over a log streams it (a campaign over ``logs``): the peak of ``uiogen validate --data`` on a 1 GB
# MDF4 file, 396 MB (docs/validation.md, 'Large logs'), rounded up; its trace is kept decimated
LOG_RUN_BYTES = 512 * 2 ** 20


# --- the limit -----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Limit:
    """The memory a campaign may use: ``bytes``, and ``source``, where that figure comes from."""

    bytes: int
    source: str


_READ = object()          # the default of memory_limit's injectable figures: read them from the system


def _limit_file(path: Path) -> int | None:
    """The limit in a cgroup file: bytes, or None for none ("max", a missing or unreadable file)."""
    try:
        text = path.read_text().strip()
    except OSError:
        return None
    if text == "max" or not text.isdigit():
        return None
    return int(text)


def memory_limit(root: str | Path = "/", physical=_READ, address_space=_READ) -> Limit:
    """The memory limit that applies to this process: the smallest of

    * the physical memory (``physical``, else ``sysconf``), and the memory available now
      (``MemAvailable`` of ``/proc/meminfo``);
    * the cgroup v2 ``memory.max`` of the process's cgroup (``/proc/self/cgroup``'s ``0::PATH``) and of
      every cgroup above it (a parent's limit applies to its children), "max" meaning none, and that
      limit less the cgroup's ``memory.current``;
    * the cgroup v1 ``memory.limit_in_bytes`` the same way (``N:memory:PATH``, less ``memory.usage_in_bytes``);
    * ``RLIMIT_AS`` (``address_space``, else ``getrlimit``; None: unlimited).

    Parameters
    ----------
    root : str or Path
        The file system root under which ``proc/self/cgroup`` and ``sys/fs/cgroup`` are read (a folder
        of fake files, for tests).
    physical, address_space : int or None
        The figures to use instead of the system's.

    Returns
    -------
    Limit
        The smallest, with its source ("physical memory", "available memory, ...", "cgroup v2 FILE",
        "cgroup v1 FILE", "RLIMIT_AS").
    """
    root = Path(root)
    if physical is _READ:
        physical = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    if address_space is _READ:
        import resource
        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        address_space = None if soft == resource.RLIM_INFINITY else soft
    found = [Limit(int(physical), "physical memory")]
    # what the machine has free now (another job's memory is not this campaign's: on a shared machine a
    # campaign within the physical memory was still killed by the kernel)
    try:
        meminfo = (root / "proc" / "meminfo").read_text()
        kib = next(int(line.split()[1]) for line in meminfo.splitlines() if line.startswith("MemAvailable:"))
        found.append(Limit(1024 * kib, "available memory, MemAvailable of /proc/meminfo"))
    except (OSError, StopIteration, ValueError, IndexError):
        pass
    if address_space is not None:
        found.append(Limit(int(address_space), "RLIMIT_AS"))
    try:
        lines = (root / "proc" / "self" / "cgroup").read_text().splitlines()
    except OSError:
        lines = []
    # the process's own cgroup per hierarchy; the mount's root is read as well (a container without a
    # cgroup namespace sees its host's path for itself, and its own limit at the root of the mount)
    where = {("v2", "sys/fs/cgroup", "memory.max"): "/",
             ("v1", "sys/fs/cgroup/memory", "memory.limit_in_bytes"): "/"}
    for line in lines:
        hierarchy, _, rest = line.partition(":")
        controllers, _, path = rest.partition(":")
        if hierarchy == "0" and controllers == "":
            where[("v2", "sys/fs/cgroup", "memory.max")] = path
        elif "memory" in controllers.split(","):
            where[("v1", "sys/fs/cgroup/memory", "memory.limit_in_bytes")] = path
    for (version, mount, name), path in where.items():
        parts = [p for p in path.strip().split("/") if p]
        for k in range(len(parts), -1, -1):
            f = root.joinpath(mount, *parts[:k], name)
            value = _limit_file(f)
            if value is not None:
                found.append(Limit(value, f"cgroup {version} {f}"))
                # less what the cgroup already holds (its other processes)
                used = _limit_file(f.with_name("memory.current" if version == "v2" else "memory.usage_in_bytes"))
                if used is not None and used < value:
                    found.append(Limit(value - used, f"cgroup {version} {f} less the {used} bytes in use"))
    return min(found, key=lambda lim: lim.bytes)


# --- the estimate --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Sizes:
    """The sizes a campaign's memory follows: ``samples`` per run (the longest scenario), and per sample
    the float64 values of each kind a run holds."""

    samples: int
    sample_time: float
    inputs: int             # rows of the plant's input matrix (stage inputs of the excitation scenario)
    signals: int            # the scenario's signals kept beside it (the excitation's external signals)
    plant: int              # rows of the plant's trajectory (its outputs), parameters and states
    trajectory: int         # rows of the plant's trajectory alone
    observer: int           # the observer's inputs and outputs, and the measured signals
    errors: int             # the signals whose errors are scored (traces: truth and estimate of each)
    columns: int            # the columns of a run's summary row
    streamed: bool = False  # a run over a log: read chunk by chunk, ``samples`` the decimated trace's


def run_bytes(s: Sizes) -> int:
    """Peak bytes one run holds beyond its process's :data:`PROCESS_BYTES`, per sample:

    * the plant's input matrix (``inputs`` rows), held by the scenario, the scenario's signals and
      times (``signals`` + 1);
    * the plant's trajectory (``trajectory``);
    * the measured signals, the observer's input matrix and outputs (``observer``), its status;
    * the error series of the scoring (a few temporaries per error signal, 4 ``errors``);

    and, per chunk of :data:`~codegen.campaign.plants.CHUNK` samples (the compiled plant's call),
    :data:`CASADI_COPIES` copies of the chunk's inputs and the plant's work (``plant``: its outputs,
    parameters and states over the chunk).
    """
    from .plants import CHUNK
    if s.streamed:               # a log's run: the stream's peak and its decimated trace (time, truth, estimate)
        return LOG_RUN_BYTES + 8 * (1 + 2 * s.errors) * s.samples
    per_sample = s.inputs + s.signals + 1 + s.trajectory + s.observer + 1 + 4 * s.errors
    per_chunk = (CASADI_COPIES * s.inputs + s.plant) * min(s.samples, CHUNK)
    return 8 * (per_sample * s.samples + per_chunk)


def coordinator_bytes(spec, s: Sizes) -> int:
    """Peak bytes of the coordinator: its process, one run (the worst runs are re-run one at a time for
    their traces), the traces kept (time, truth and estimate of each error signal per worst run) and
    every run's summary row."""
    traces = 8 * spec.worst * (1 + 2 * s.errors) * s.samples
    return PROCESS_BYTES + run_bytes(s) + traces + rows_bytes(spec, s)


def rows_bytes(spec, s: Sizes) -> int:
    """Bytes of the summary rows the coordinator keeps, one per run (the journal's, read back)."""
    return spec.runs * (ROW_BYTES + ROW_BYTES_PER_COLUMN * s.columns)


def excitation_samples(duration: float, sample_time: float) -> int:
    """Samples of an excitation run (``numpy.arange(0, duration + Ts / 2, Ts)``), without allocating them."""
    return max(int(math.ceil((duration + 0.5 * sample_time) / sample_time)), 1)


def sizes(spec) -> Sizes:
    """The :class:`Sizes` of campaign ``spec`` (its observer's design, its plant, its scenarios); builds
    no run (a library scenario, 60 s or so, is built to count its samples)."""
    import json
    from ..design import lock as design_lock
    from ..validation import excitation, scenarios as scn_lib
    from ..validation.common import truncate
    from .plants import EXCITATION, KINDS, plant_kind
    from .spec import _error_signals
    config = spec.config()
    if spec.logs:
        from ..validation.streaming import KEEP_SAMPLES
        from .spec import log_error_signals
        errors = len(log_error_signals(config))
        return Sizes(samples=KEEP_SAMPLES, sample_time=config.sample_time, inputs=0, signals=0, plant=0, trajectory=0,
                     observer=0, errors=errors, columns=6 + len(spec.dispersed()) + 2 * errors + 3, streamed=True)
    kind = plant_kind(config, spec.scenarios)
    plant = KINDS[kind][0](config)
    art = json.loads(design_lock.path(config).read_text())
    ins = art["signals"]["input"]
    outs = art["signals"].get("output", art["signals"]["state"])
    signals = len(getattr(plant.extra, "external", ()))
    if spec.scenarios[0] == EXCITATION:
        samples = excitation_samples(spec.duration or excitation.DURATION, config.sample_time)
    else:
        rate = 1.0 / config.sample_time
        samples = max(truncate(scn_lib.make(n, sample_rate=rate), spec.duration).t.size
                      for n in dict.fromkeys(spec.scenarios))
        signals = 5                      # v_ref, a_ref, T_a, T_d_open and an optional series
    errors = len(_error_signals(config, kind))
    columns = 6 + len(spec.dispersed()) + 2 * errors + 3
    return Sizes(samples=samples, sample_time=config.sample_time, inputs=len(plant.input_names), signals=signals,
                 plant=len(plant.output_names) + len(plant.param_names) + plant.n_state,
                 trajectory=len(plant.output_names),
                 observer=2 * len(ins) + len(outs), errors=errors, columns=columns)


@dataclass(frozen=True)
class Estimate:
    """A campaign's memory: per worker process, the coordinator's, and the total with ``workers`` local
    worker processes (remote workers count nothing here)."""

    worker: int
    coordinator: int
    workers: int
    sizes: Sizes

    @property
    def total(self) -> int:
        return self.coordinator + self.workers * self.worker


def estimate(spec, workers: int, s: Sizes | None = None) -> Estimate:
    """The memory of campaign ``spec`` run by ``workers`` local worker processes (0: the workers are
    another machine's, behind ``--scheduler``; the coordinator alone is counted)."""
    s = s or sizes(spec)
    return Estimate(worker=PROCESS_BYTES + run_bytes(s), coordinator=coordinator_bytes(spec, s), workers=int(workers),
                    sizes=s)


# --- the refusal ---------------------------------------------------------------------------------------

def _gib(n: float) -> str:
    return f"{n / GiB:.3g} GiB"


def check(spec, workers: int, limit: Limit | None = None) -> Estimate:
    """Refuse campaign ``spec`` if its :func:`estimate` with ``workers`` local workers exceeds the
    :func:`memory_limit` (or ``limit``): a run is held whole, so one that does not fit ends in the
    kernel's out-of-memory kill (exit status 137, no message) after minutes, or exhausts the machine.

    Raises
    ------
    ConfigurationError
        naming the campaign file, the key (``duration`` when no run fits even with one worker,
        ``runs`` when the rows the coordinator keeps do not fit, else ``--workers``), the estimate, the
        limit and its source, and what would fit (the longest duration, the most workers).
    """
    from ..errors import ConfigurationError
    from ..settings import config_error
    limit = limit or memory_limit()
    est = estimate(spec, workers)
    if est.total <= limit.bytes:
        return est
    s = est.sizes
    one = estimate(spec, min(workers, 1), s)
    figures = (f"the campaign needs about {_gib(est.total)} ({workers} worker(s) of {_gib(est.worker)} each, "
               f"a run of {s.samples} samples held whole, and the coordinator's {_gib(est.coordinator)}), more than "
               f"the limit of {_gib(limit.bytes)} ({limit.source})")
    if one.total <= limit.bytes and workers > 1:
        fit = max(int((limit.bytes - est.coordinator) // est.worker), 1)
        msg = (f"{spec.source}: --workers {workers}: {figures}; at most {fit} local worker(s) fit "
               f"(`--workers {fit}`), or shorten the runs (duration)")
        raise ConfigurationError(msg, source=spec.source, key="--workers", value=workers,
                                 allowed=f"at most {fit} workers")
    rows = rows_bytes(spec, s)
    if rows > limit.bytes / 2:
        fit = max(int((limit.bytes / 2) // (ROW_BYTES + ROW_BYTES_PER_COLUMN * s.columns)), 1)
        raise config_error(spec.source, None, "runs", spec.runs,
                           f"{figures}: the coordinator keeps every run's row ({_gib(rows)}); at most about "
                           f"{fit} runs fit: split the campaign into several of fewer runs")
    if s.streamed:               # a log's run has no length to shorten: it is streamed
        raise config_error(spec.source, None, "logs", list(spec.logs),
                           f"{figures}: a run over a log streams it, and even one worker's does not fit; run the "
                           f"campaign where more memory is available (--scheduler ADDRESS)")
    # the total is affine in a run's samples beyond one chunk of the plant, fixed + slope N (below, the
    # chunk is shorter and the total under the line): solved for the limit, with one worker (the
    # coordinator alone when the workers are elsewhere), and with the workers asked for
    from .plants import CHUNK

    def longest(n_workers: int) -> float:
        one, two = (estimate(spec, n_workers, _with_samples(s, k * CHUNK)).total for k in (1, 2))
        slope = (two - one) / CHUNK
        return max((limit.bytes - (one - slope * CHUNK)) / slope - 1, 0.0) * s.sample_time
    alone = 1 if workers else 0
    value = spec.duration if spec.duration is not None else (s.samples - 1) * s.sample_time
    also = f" ({_down(longest(workers))} s with {workers} workers)" if workers > 1 else ""
    raise config_error(spec.source, None, "duration", value,
                       f"{figures}; a run of at most {_down(longest(alone))} s fits with {alone or 'no local'} "
                       f"worker{'' if alone == 1 else 's'}{also}: take more, shorter runs")


def _down(seconds: float) -> str:
    """``seconds`` to 4 significant digits, rounded down (the duration named must fit, not one a little longer)."""
    if seconds <= 0:
        return "0"
    step = 10.0 ** (math.floor(math.log10(seconds)) - 3)
    return f"{math.floor(seconds / step) * step:.4g}"


def _with_samples(s: Sizes, samples: int) -> Sizes:
    from dataclasses import replace
    return replace(s, samples=int(samples))
