"""One dispersed run, from (spec, run index) alone: draw, simulate the compiled plant, measure, run
the compiled observer step, summarize. Everything a worker process needs is built on its first run
and cached in the process (the observer's extension, the compiled plant per scenario length,
the scenarios per seed)."""
from __future__ import annotations

import json
import math

import numpy as np

from ..validation.common import SETTLE_TIME, truncate

_CACHE: dict = {}
SPIN_BETA = math.pi / 4      # |beta| above 45 deg: the plant car has spun (not an observer error)



def certified_gain_norm(config) -> str | None:
    """The norm of the family's certified gain (``Campaigns.certified_gain_norm``): "peak" (L-infinity,
    sup_t |x - x_hat|_2 over the model's states / sup_t |d|), "l2" (H-infinity, |xi - xi_hat|_2 /
    |w|_2 with xi the performance outputs), or None."""
    from .. import families
    from ..contract.capabilities import Campaigns
    family = families.get(config.family)
    return family.certified_gain_norm if isinstance(family, Campaigns) else None


def _cached(key, make):
    if key not in _CACHE:
        _CACHE[key] = make()
    return _CACHE[key]


def _config(spec):
    return _cached(("config", spec.observer, spec.project), spec.config)


def _observer(spec):
    from ..extension.build import load
    return _cached(("obs", spec.observer, spec.project), lambda: load(_config(spec)))


def _artifact(spec) -> dict:
    from ..design import lock as design_lock
    return _cached(("art", spec.observer, spec.project), lambda: json.loads(design_lock.path(_config(spec)).read_text()))


def _plant(spec, n: int):
    from .plants import CompiledPlant, plant_kind
    kind = plant_kind(_config(spec), spec.scenarios)
    return _cached(("plant", spec.observer, kind, n), lambda: CompiledPlant(_config(spec), n, kind))


def _scenario(spec, name: str, seed: int | None):
    from ..validation import scenarios
    from .plants import EXCITATION
    if name == EXCITATION:             # the model's own plant: the generic scenario, its seed drawn or 0
        config = _config(spec)
        if seed is not None:
            return _excitation(spec, config, seed)
        return _cached(("scn", spec.observer, name, spec.duration), lambda: _excitation(spec, config, 0))
    rate = 1.0 / _config(spec).sample_time
    if seed is not None:       # drawn per run: not kept (10,000 of them would fill a worker's memory)
        return truncate(scenarios.make(name, seed=seed, sample_rate=rate), spec.duration)
    return _cached(("scn", name, rate, spec.duration),
                   lambda: truncate(scenarios.make(name, sample_rate=rate), spec.duration))


def _excitation(spec, config, seed: int):
    """The excitation run of ``spec``; a ``duration`` whose run does not fit in memory (a run is
    held whole: its stage inputs, the plant's trajectory) is the campaign file's mistake, named.
    :func:`codegen.campaign.memory.check` refuses the whole campaign before it starts; this is the
    check of one run where it runs (a worker of another machine, behind ``--scheduler``)."""
    from ..settings import config_error
    from ..validation import excitation
    from . import memory
    duration = spec.duration or excitation.DURATION
    sizes = _cached(("sizes", spec), lambda: memory.sizes(spec))
    held = memory.PROCESS_BYTES + memory.run_bytes(sizes)
    limit = memory.memory_limit()
    why = None
    if held > limit.bytes:       # refused before the allocation: one this large may succeed, then exhaust the machine
        why = (f"it holds about {held / memory.GiB:.3g} GiB, the limit is {limit.bytes / memory.GiB:.3g} GiB "
               f"({limit.source})")
    else:
        try:
            return excitation.scenario(config, duration, seed)
        except MemoryError as exc:
            why = str(exc) or "MemoryError"
    raise config_error(spec.source, None, "duration", duration,
                       f"a run that fits in memory ({sizes.samples:.3g} samples at the sample time "
                       f"{config.sample_time:g} s: {why}); a campaign holds each run whole, so take more, shorter runs")


def default_noise(config) -> dict:
    """The sensor noise of the family's own validation (std per measured signal): the family's
    (``Campaigns.sensor_noise``), else the common one of the library's validations."""
    from .. import families
    from ..project.sensor_noise import sensor_noise
    return sensor_noise(families.get(config.family))


def draw(spec, run: int) -> dict:
    """The dispersed values of run ``run`` (and its scenario), from SeedSequence([seed, run]) alone:
    one independent stream per kind of draw, so adding a dispersion of one kind leaves the others'."""
    ss = np.random.SeedSequence([spec.seed, run])
    s_scn, s_par, s_drv, s_sen, s_noise = (np.random.default_rng(s) for s in ss.spawn(5))
    if spec.logs:          # a recorded run: its sensors alone are dispersed, from no noise of their own
        values = {f"sensor.{sig}.{f}": d.draw(s_sen, 0.0) for sig, fields in spec.sensors for f, d in fields}
        return {"log": spec.run_source(run)[1], "values": values, "noise_rng": s_noise}
    name = spec.scenarios[run % len(spec.scenarios)]
    seed = int(s_scn.integers(0, 2 ** 31 - 1)) if spec.scenario_seed == "per_run" else None
    config = _config(spec)
    scn = _scenario(spec, name, seed)
    plant = _plant(spec, scn.t.size)
    from .plants import default_driver_gains
    nominal = plant.spec.params
    gains0 = default_driver_gains(plant.kind, scn)
    values = {}
    for k, d in spec.parameters:
        values[f"param.{k}"] = d.draw(s_par, nominal[k])
    for k, d in spec.driver:
        values[f"driver.{k}"] = d.draw(s_drv, gains0[k])
    for sig, fields in spec.sensors:
        for f, d in fields:
            values[f"sensor.{sig}.{f}"] = d.draw(s_sen, default_noise(config).get(sig, 0.0) if f == "noise" else 0.0)
    return {"scenario": name, "scenario_seed": scn.seed, "scn": scn, "plant": plant, "values": values,
            "noise_rng": s_noise}


def _measure(spec, truth: dict, values: dict, rng, sample_time: float) -> dict:
    config = _config(spec)
    noise = {k: v for k, v in default_noise(config).items() if k in truth}
    fields = {sig: dict(f) for sig, f in spec.sensors}
    measured = {}
    for sig in sorted(set(noise) | set(fields)):
        y = np.asarray(truth.get(f"y_{sig}", truth[sig]), float)      # the output y_X of a model plant, else X
        std = values.get(f"sensor.{sig}.noise", noise.get(sig, 0.0))
        delay = int(round(values.get(f"sensor.{sig}.delay", 0.0) / sample_time))
        if delay > 0:
            y = np.concatenate([np.full(min(delay, y.size), y[0]), y[:max(y.size - delay, 0)]])
        y = y + values.get(f"sensor.{sig}.bias", 0.0) + std * rng.standard_normal(y.shape)
        measured[sig] = y
    return measured


def _error_signals(spec) -> tuple:
    from .spec import _error_signals as errs, log_error_signals
    from .plants import plant_kind
    if spec.logs:
        return _cached(("errs", spec.observer, "logs"), lambda: log_error_signals(_config(spec)))
    return _cached(("errs", spec.observer, spec.scenarios),
                   lambda: errs(_config(spec), plant_kind(_config(spec), spec.scenarios)))


def run_one(spec, run: int, traces: bool = False):
    """The summary row of run ``run`` (a dict of numbers and strings); with ``traces``, also
    (row, signals) with the truth and the estimates of the error signals over time."""
    from ..validation import simulate
    if spec.logs:
        from ..errors import UiogenError
        try:
            return _run_log(spec, run, traces)
        except UiogenError as exc:      # the log refused by its checks: a run without result, said in its row
            d = draw(spec, run)
            row = {"run": int(run), "log": d["log"], **d["values"], "status": "error",
                   "error": f"{type(exc).__name__}: {exc}"}
            return (row, None) if traces else row
    config, obs = _config(spec), _observer(spec)
    d = draw(spec, run)
    scn, plant, values = d["scn"], d["plant"], d["values"]
    row = {"run": int(run), "scenario": d["scenario"], "scenario_seed": int(d["scenario_seed"]), **values}
    params = {k[6:]: v for k, v in values.items() if k.startswith("param.")}
    gains = {k[7:]: v for k, v in values.items() if k.startswith("driver.")}
    truth = plant.simulate(scn, params, gains)
    signals = _error_signals(spec)
    units = dict(config.load_model().units) if ("units", spec.observer) not in _CACHE else _CACHE[("units", spec.observer)]
    _CACHE[("units", spec.observer)] = units
    finite = all(np.all(np.isfinite(truth[k])) for k in truth)
    spun = finite and "beta" in truth and float(np.max(np.abs(truth["beta"]))) > SPIN_BETA
    if not finite or spun:
        # outside every model's domain (the car spun, or the integration blew up): counted, not scored
        row.update({"status": "plant_diverged" if not finite else "plant_spun", "clamped_fraction": math.nan, "flagged_fraction": math.nan,
                    "ratio": math.nan, **{f"rms.{s}": math.nan for s in signals},
                    **{f"max.{s}": math.nan for s in signals}})
        return (row, None) if traces else row
    measured = _measure(spec, truth, values, d["noise_rng"], config.sample_time)
    inputs = simulate.observer_input_matrix(obs.input_names, truth, measured)
    out, status, _ = obs.run(inputs)
    bits = obs.status_bits
    row["clamped_fraction"] = int(np.count_nonzero(status & bits["SCHEDULING_CLAMPED"])) / status.size
    row["flagged_fraction"] = int(np.count_nonzero(status & (bits["NONFINITE_INPUT"] | bits["NUMERICAL_FAILURE"]))) / status.size
    keep = truth["t"] >= SETTLE_TIME
    est = {s: out[:, obs.output_names.index(s)] for s in signals}
    ok = all(np.all(np.isfinite(est[s][keep])) for s in signals)
    # a run whose step flagged a sample (a non-finite input, a numerical failure) is not "ok",
    # whatever its estimates: it is counted apart, never scored among the ok runs
    row["status"] = "observer_nonfinite" if not ok else "flagged" if row["flagged_fraction"] > 0 else "ok"
    for s in signals:
        scale = 180.0 / math.pi if units.get(s, "").startswith("rad") else 1.0
        e = (est[s] - truth[s])[keep] * scale
        row[f"rms.{s}"] = math.sqrt(_sum(e * e) / e.size)
        row[f"max.{s}"] = float(np.max(np.abs(e)))
    row["ratio"] = _ratio(spec, config, truth, est, keep)
    row["gamma"] = float(_artifact(spec).get("gamma", math.nan))     # families with a certified gain
    if traces:
        return row, {"t": truth["t"], **{f"{s}_truth": truth[s] for s in signals},
                     **{f"{s}_estimate": est[s] for s in signals}}
    return row


def _run_log(spec, run: int, traces: bool):
    """Run ``run`` of a campaign over logs: the log read chunk by chunk through the observer file's ``[data]``
    map (:class:`codegen.validation.logs.MappedLog`, every check of ``validate --data``), the sensors' drawn
    bias, delay and noise added to the recorded inputs, the compiled step run with its state carried over,
    the errors scored against the map's references after the settle time. The traces are kept decimated
    (:class:`codegen.validation.streaming.Decimated`): a log of any length runs in bounded memory."""
    from ..validation import streaming
    from ..validation.logs import MappedLog
    config, obs = _config(spec), _observer(spec)
    d = draw(spec, run)
    values = d["values"]
    row = {"run": int(run), "log": d["log"], **values}
    signals = _error_signals(spec)
    units = _cached(("units", spec.observer, spec.project), lambda: dict(config.load_model().units))
    log = MappedLog(config, spec.log_path(d["log"]), obs.input_names, obs.output_names, config.sample_time)
    sensors = _LogSensors(spec, obs.input_names, values, d["noise_rng"], config.sample_time)
    bits = obs.status_bits
    flagged_bits = bits["NONFINITE_INPUT"] | bits["NUMERICAL_FAILURE"]
    sq = {s: [] for s in signals}
    peak = {s: 0.0 for s in signals}
    kept = {s: 0 for s in signals}
    finite = True
    n = clamped = flagged = 0
    state, t0 = obs.initial_state(), None
    trace = streaming.Decimated() if traces else None
    for t, ins, refs, _ in log.chunks():
        t0 = t[0] if t0 is None else t0
        t = t - t0
        last = spec.duration is not None and t[-1] >= spec.duration - 0.5 * config.sample_time
        if spec.duration is not None and t[-1] > spec.duration:         # truncated: the samples up to it
            cut = int(np.searchsorted(t, spec.duration, side="right"))
            if cut == 0:
                break
            t, ins, refs = t[:cut], {k: v[:cut] for k, v in ins.items()}, {k: v[:cut] for k, v in refs.items()}
        inputs = np.column_stack([sensors.measure(name, ins[name]) for name in obs.input_names])
        out, status, state = obs.run(inputs, state)
        n += status.size
        clamped += int(np.count_nonzero(status & bits["SCHEDULING_CLAMPED"]))
        flagged += int(np.count_nonzero(status & flagged_bits))
        keep = t >= SETTLE_TIME
        for s in signals:
            scale = 180.0 / math.pi if units.get(s, "").startswith("rad") else 1.0
            e = (out[:, obs.output_names.index(s)] - refs[s])[keep] * scale
            finite = finite and bool(np.all(np.isfinite(e)))
            if finite and e.size:
                sq[s].append(_sum(e * e))
                peak[s] = max(peak[s], float(np.max(np.abs(e))))
                kept[s] += e.size
        if trace is not None:
            trace.add({"t": t, **{f"{s}_truth": refs[s] for s in signals},
                       **{f"{s}_estimate": out[:, obs.output_names.index(s)] for s in signals}})
        if last:
            break
    log.finish()                 # the time and physics checks of what was read (a DatasetError: no row)
    row["clamped_fraction"] = clamped / n if n else math.nan
    row["flagged_fraction"] = flagged / n if n else math.nan
    ok = finite and all(kept[s] for s in signals)
    row["status"] = "observer_nonfinite" if not ok else "flagged" if flagged else "ok"
    for s in signals:
        row[f"rms.{s}"] = math.sqrt(math.fsum(sq[s]) / kept[s]) if ok else math.nan
        row[f"max.{s}"] = peak[s] if ok else math.nan
    row["ratio"] = math.nan        # the certified gains' ratio needs the unknown input's truth: a log has none
    row["gamma"] = float(_artifact(spec).get("gamma", math.nan))
    if traces:
        return row, trace.signals()
    return row


class _LogSensors:
    """The drawn bias, delay and noise of ``[sensors.X]`` added to a recorded input, chunk by chunk: the delay
    holds the first recorded value, then the samples carried over from the chunk before."""

    def __init__(self, spec, input_names, values: dict, rng, sample_time: float):
        self.rng, self.fields = rng, {}
        for sig, fields in spec.sensors:
            name = sig if sig in input_names else f"y_{sig}"
            self.fields[name] = {f: values[f"sensor.{sig}.{f}"] for f, _ in fields}
        self.delay = {k: int(round(v.get("delay", 0.0) / sample_time)) for k, v in self.fields.items()}
        self.held: dict = {}

    def measure(self, name: str, y: np.ndarray) -> np.ndarray:
        f = self.fields.get(name)
        if f is None:
            return y
        k = self.delay[name]
        if k > 0 and y.size:
            before = self.held.get(name, np.full(k, y[0]))
            both = np.concatenate([before, y])
            y, self.held[name] = both[:y.size], both[-k:]
        return y + f.get("bias", 0.0) + f.get("noise", 0.0) * self.rng.standard_normal(y.shape)


def _sum(x) -> float:
    """Correctly rounded sum: the same double in every process (numpy's SIMD sums depend on the
    array's alignment, which differs between a worker and a re-run)."""
    return math.fsum(np.asarray(x, float).tolist())


def _ratio(spec, config, truth, est, keep) -> float:
    kind = certified_gain_norm(config)
    if kind == "peak":
        model = config.load_model()
        states = [s for s in model.state_names if s in est]
        ui = str(model.unknown_inputs[0])
        e = np.sqrt(sum((est[s] - truth[s])[keep] ** 2 for s in states))
        peak_d = float(np.max(np.abs(truth[ui][keep])))
        return float(np.max(e) / peak_d) if peak_d > 0 else math.nan
    if kind == "l2":
        perf = list(config.switching.get("performance", ["beta"]))
        e = math.sqrt(sum(_sum((est[s] - truth[s])[keep] ** 2) for s in perf))
        w = math.sqrt(sum(_sum(truth[str(u)][keep] ** 2) for u in config.load_model().unknown_inputs))
        return float(e / w) if w > 0 else math.nan
    return math.nan


def run_chunk(spec, runs) -> list:
    """Rows of several runs (one Dask task)."""
    return [run_one(spec, int(k)) for k in runs]


def run_traces(spec, run: int):
    return run_one(spec, int(run), traces=True)


def design_hash(spec) -> str:
    """The design hash of the observer a campaign runs (checked current, its extension built
    from it): part of the campaign's identity, so ``--resume`` never mixes two designs' rows."""
    from ..extension.build import require_current
    require_current(_config(spec))
    _observer(spec)                        # load() refuses an extension of another design
    return _artifact(spec)["lock"]["sha256"]


def prepare(spec) -> str:
    """Check the observer's design and extension are current (:func:`design_hash`, returned) and
    compile (or find in the cache) the plant of every scenario length of the campaign."""
    from ..validation import excitation
    from .memory import excitation_samples
    from .plants import EXCITATION
    design = design_hash(spec)
    if spec.logs:                   # read where they run: each worker streams its own
        return design
    for name in spec.scenarios:
        if name == EXCITATION:       # its length alone: the run itself would stay in the coordinator's cache
            _plant(spec, excitation_samples(spec.duration or excitation.DURATION, _config(spec).sample_time))
            continue
        scn = _scenario(spec, name, None)
        _plant(spec, scn.t.size)
    return design
