"""A campaign file (TOML): the observer, its scenarios and the dispersions, as data.

::

    observer = "lpv_linf_driver_torque"
    scenarios = ["track_varying_speed"]     # run K uses scenarios[K % len(scenarios)]
    scenario_seed = "per_run"               # "fixed": the scenario's own seed; "per_run": drawn per run
    runs = 1000
    seed = 2024
    duration = 60.0                         # s (optional: truncate the scenarios)
    worst = 3                               # traces of the worst runs to keep
    rank_by = "beta"                        # the signal whose RMS error ranks the runs
    run_timeout = 60.0                      # s a run may take on a worker (engine: lost workers)

    [parameters]                            # the plant's parameters (not the observer's model)
    M = { dist = "uniform", low = 0.9, high = 1.1, relative = true }
    mu = { dist = "uniform", low = 0.5, high = 1.0 }

    [driver]                                # the driver model's gains
    k_p = { dist = "normal", mean = 1.0, std = 0.1, relative = true }

    [sensors.r]                             # a measured signal: noise std, bias, delay [s]
    noise = 0.0009
    bias = { dist = "normal", mean = 0.0, std = 0.0005 }
    delay = { dist = "uniform", low = 0.0, high = 0.02 }

Or, in place of ``scenarios``, recorded runs of the car: ``logs = ["runs/a.mf4", "runs/b.blf"]`` (relative to
this file; run K reads ``logs[K % len(logs)]`` through the observer file's ``[data]`` map, every format
``validate --data`` reads). A log is the car itself: ``[parameters]``, ``[driver]`` and ``scenario_seed`` have
nothing to disperse and are refused; ``[sensors]`` adds its noise, bias and delay to the recorded signal (no
noise unless stated: the log has its own); the errors are scored against the map's ``[data.truth]``.

A distribution is a number (a constant) or a table ``dist`` = ``"uniform"`` (``low``, ``high``)
or ``"normal"`` (``mean``, ``std``), with ``relative = true`` for a factor on the nominal value.
Every value a distribution can draw must be admissible: a plant parameter within the range its
model declares (``positive=True``, ``parameter_ranges``: no zero mass, no negative friction), a
sensor's noise and delay >= 0; a normal draw is unbounded, so a bounded quantity takes a uniform
one. Every mistake is a :class:`~codegen.errors.ConfigurationError` naming the file, the key and
what is allowed, raised before any run or file.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import ConfigurationError
from ..settings import Rule, check_keys, config_error, parse_table, suggest
from ..validation.common import SETTLE_TIME

MAX_RUNS = 10_000_000

TOP = {
    "observer": Rule(str, required=True, doc="a built-in observer name, or an observer file (.toml, relative to "
                                             "this file)"),
    "scenarios": Rule(list, items=Rule(str), doc="scenario names, cycled over the runs: the library's (families "
                                                 "with a plant of their own) or excitation"),
    "logs": Rule(list, items=Rule(str), doc="recorded runs (files or ROS 2 bag folders, relative to this file), "
                                            "cycled over the runs in place of scenarios; read through the observer "
                                            "file's [data] map"),
    "runs": Rule(int, ge=1, le=MAX_RUNS, required=True, doc="number of dispersed runs"),
    "seed": Rule(int, ge=0, doc="campaign seed: run K draws from SeedSequence([seed, K])"),
    "duration": Rule(float, gt=SETTLE_TIME, doc=f"truncate every scenario to this many seconds (errors are "
                                                  f"scored after the settle time, {SETTLE_TIME:g} s)"),
    "run_timeout": Rule(float, gt=0, doc="seconds one run may take on a worker; a campaign with no run finished "
                                         "for that long per run in flight, or with no worker for that long, "
                                         "stops and keeps what it did (default 60)"),
    "scenario_seed": Rule(str, choices=("fixed", "per_run")),
    "worst": Rule(int, ge=0, doc="traces of this many worst runs are written"),
    "rank_by": Rule(str, doc="signal whose RMS error ranks the runs"),
    "chunk": Rule(int, ge=1, doc="runs per Dask task (default: about 4 tasks per worker, at most 50)"),
    "parameters": Rule(dict), "driver": Rule(dict), "sensors": Rule(dict),
}
DIST_KEYS = {"dist": Rule(str, choices=("uniform", "normal"), required=True), "low": Rule(float),
             "high": Rule(float), "mean": Rule(float), "std": Rule(float, ge=0), "relative": Rule(bool)}
SENSOR_KEYS = ("noise", "bias", "delay")


@dataclass(frozen=True)
class Dist:
    """One dispersion: ``kind`` constant / uniform / normal; ``relative``: a factor on the nominal."""

    kind: str
    a: float = 0.0            # constant value, low, or mean
    b: float = 0.0            # high or std
    relative: bool = False

    def support(self, nominal: float = 0.0) -> tuple:
        """(lowest, highest) value a draw can take (a normal one: unbounded unless std = 0)."""
        if self.kind == "normal" and self.b > 0:
            return -math.inf, math.inf
        lo, hi = (self.a, self.a) if self.kind != "uniform" else (self.a, self.b)
        if self.relative:
            lo, hi = sorted((lo * nominal, hi * nominal))
        return lo, hi

    def draw(self, rng, nominal: float = 0.0) -> float:
        if self.kind == "constant":
            v = self.a
        elif self.kind == "uniform":
            v = float(rng.uniform(self.a, self.b))
        else:
            v = float(self.a + self.b * rng.standard_normal())
        return v * nominal if self.relative else v


@dataclass(frozen=True)
class CampaignSpec:
    source: str
    observer: str
    scenarios: tuple
    runs: int
    seed: int = 0
    duration: float | None = None
    scenario_seed: str = "fixed"
    worst: int = 3
    rank_by: str | None = None
    chunk: int | None = None
    run_timeout: float = 60.0
    parameters: tuple = ()           # ((name, Dist), ...) in file order
    driver: tuple = ()
    sensors: tuple = ()              # ((signal, ((field, Dist), ...)), ...)
    logs: tuple = ()                 # recorded runs, as written in the file (resolved by log_path)
    project: str | None = None       # the observer's project folder (``uiogen campaign --project``)
    raw: dict = field(default_factory=dict, compare=False, hash=False, repr=False)

    def config(self):
        """The observer's configuration, in the campaign's project."""
        from ..project import observer_file as observers
        return observers.get(self.observer, project=self.project)

    def log_path(self, name: str) -> Path:
        """A log of ``logs`` as a path: relative to the campaign file."""
        return Path(self.source).resolve().parent / name

    def run_source(self, run: int) -> tuple:
        """("log", name) or ("scenario", name): what run ``run`` reads."""
        if self.logs:
            return "log", self.logs[run % len(self.logs)]
        return "scenario", self.scenarios[run % len(self.scenarios)]

    def with_runs(self, runs: int) -> "CampaignSpec":
        from dataclasses import replace
        return replace(self, runs=int(runs))

    def dispersed(self) -> list:
        """Column names of the drawn values of a run's row, in draw order."""
        cols = [f"param.{n}" for n, _ in self.parameters] + [f"driver.{n}" for n, _ in self.driver]
        for sig, fields in self.sensors:
            cols += [f"sensor.{sig}.{f}" for f, _ in fields]
        return cols


def parse_dist(value, *, source: str, section: str, key: str) -> Dist:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if not math.isfinite(value):
            raise config_error(source, section, key, value, "must be a finite number")
        return Dist("constant", float(value))
    if not isinstance(value, dict):
        raise config_error(source, section, key, value, 'must be a number or a table { dist = "uniform", low, high } '
                           'or { dist = "normal", mean, std } (optionally relative = true)')
    sec = f"{section}.{key}"
    t = parse_table(value, DIST_KEYS, source=source, section=sec)
    need = ("low", "high") if t["dist"] == "uniform" else ("mean", "std")
    other = [k for k in (("mean", "std") if t["dist"] == "uniform" else ("low", "high")) if k in t]
    if other:
        raise config_error(source, sec, other[0], t[other[0]], f"is not a key of dist = {t['dist']!r} "
                           f"(it takes {', '.join(need)})")
    missing = [k for k in need if k not in t]
    if missing:
        raise ConfigurationError(f"{source}: [{sec}] missing {', '.join(missing)} (dist = {t['dist']!r} takes "
                                 f"{', '.join(need)})", source=source, section=sec, key=missing[0], allowed="required")
    if t["dist"] == "uniform" and not t["low"] <= t["high"]:
        raise config_error(source, sec, "high", t["high"], f"must be >= low = {t['low']:g}")
    a, b = (t["low"], t["high"]) if t["dist"] == "uniform" else (t["mean"], t["std"])
    return Dist(t["dist"], a, b, t.get("relative", False))


_HOLDS = {">": lambda lo, hi, b: lo > b, ">=": lambda lo, hi, b: lo >= b, "<": lambda lo, hi, b: hi < b,
          "<=": lambda lo, hi, b: hi <= b, "!=": lambda lo, hi, b: not lo <= b <= hi}


def check_support(d: Dist, nominal: float, conditions, *, source: str, section: str, key: str,
                  what: str) -> None:
    """Refuse a dispersion that can draw a value outside ``conditions`` ([(op, bound, reason)],
    op in >, >=, <, <=, !=), naming the key of the distribution that crosses it."""
    lo, hi = d.support(nominal)
    failed = [op for op, b, _ in conditions if not _HOLDS[op](lo, hi, b)]
    if not failed:
        return
    why = "; ".join(dict.fromkeys(w for _, _, w in conditions if w))
    rule = f"{what} {' and '.join(f'{op} {b:g}' for op, b, _ in conditions)}" + (f" ({why})" if why else "")
    relative = f" (relative = true: a factor on the nominal {nominal:g}, draws from {lo:g} to {hi:g})" \
        if d.relative else ""
    if d.kind == "constant":
        raise config_error(source, section, key, d.a, f"must keep {rule}{relative}")
    sec = f"{section}.{key}"
    if d.kind == "normal":
        raise config_error(source, sec, "dist", "normal", f"must be 'uniform' here: a normal draw is unbounded, and "
                           f"every draw must keep {rule}")
    low_side = failed[0] in (">", ">=", "!=")
    if d.relative and nominal < 0:
        low_side = not low_side
    side = "low" if low_side else "high"
    raise config_error(source, sec, side, d.a if low_side else d.b, f"must keep every draw of {rule}{relative}")


def load(path, project: str | None = None) -> CampaignSpec:
    """Parse a campaign file; every key checked against the observer, its plant and its sensors.
    ``project``: the folder of the observer's design and extension (the default rule otherwise)."""
    path = Path(path)
    source = str(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigurationError(f"{source}: no such campaign file", source=source) from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigurationError(f"{source}: not valid TOML ({exc})", source=source) from None
    except UnicodeDecodeError as exc:
        raise ConfigurationError(f"{source}: not UTF-8 text ({exc.reason} at byte {exc.start}); save it as UTF-8",
                                 source=source) from None
    except IsADirectoryError:
        raise ConfigurationError(f"{source}: a folder, not a campaign file", source=source) from None
    return parse(data, source, project)


def parse(data: dict, source: str, project: str | None = None) -> CampaignSpec:
    from ..project import observer_file as observers
    from ..errors import UnknownObserverError
    from ..validation import scenarios as scn_lib
    from .. import families
    from ..project.sensor_noise import sensor_noise
    from ..model.definition import parameter_conditions
    from .plants import BANKED_DRIVER_KEYS, DRIVER_KEYS, EXCITATION, KINDS, families_with_plants, plant_kind
    top = parse_table(data, TOP, source=source)
    name = top["observer"]
    if observers.is_path(name):             # an observer file, relative to the campaign file
        name = str((Path(source).resolve().parent / name).resolve())
    try:
        config = observers.get(name, project=project)
    except UnknownObserverError:
        raise config_error(source, None, "observer", name, "must be a built-in observer ("
                           + ", ".join(observers.names()) + ") or an observer file (.toml) relative to "
                           + str(Path(source).resolve().parent), suggest(name, observers.names())) from None
    if ("scenarios" in top) == ("logs" in top):
        raise ConfigurationError(f"{source}: {'both scenarios and logs' if 'logs' in top else 'scenarios missing'}: "
                                 f"a campaign runs either simulated scenarios (scenarios = [...]) or recorded runs "
                                 f"(logs = [...])", source=source, key="scenarios", allowed="scenarios or logs, one")
    if "logs" in top:
        return _parse_logs(top, data, source, name, config, project)
    if not top["scenarios"]:
        raise config_error(source, None, "scenarios", [], "must name at least one scenario")
    known = (EXCITATION, *scn_lib.names())
    for i, s in enumerate(top["scenarios"]):
        if s not in known:
            raise config_error(source, None, f"scenarios[{i}]", s, "must be one of " + ", ".join(known),
                               suggest(s, list(known)))
    if EXCITATION in top["scenarios"] and set(top["scenarios"]) != {EXCITATION}:
        raise config_error(source, None, "scenarios", top["scenarios"], f"either [\"{EXCITATION}\"] (the model's own "
                           f"equations) or library scenarios (the family's plant), not both in one campaign")
    if top["scenarios"][0] != EXCITATION and config.family not in families_with_plants():
        raise config_error(source, None, "scenarios", top["scenarios"], f"[\"{EXCITATION}\"]: observer {name!r} is of "
                           f"family {config.family!r}, whose campaigns run on its own model; the library scenarios have "
                           f"compiled plants for the families {', '.join(families_with_plants())}")
    kind = plant_kind(config, top["scenarios"])
    plant = KINDS[kind][0](config)
    plant_params = _plant_parameters(plant)
    symbols = {str(p): p for p in plant.definition.parameters}
    params = []
    for k, v in top.get("parameters", {}).items():
        if k not in plant_params:
            raise config_error(source, "parameters", k, v, "must be a parameter of the plant: "
                               + ", ".join(plant_params), suggest(k, plant_params))
        d = parse_dist(v, source=source, section="parameters", key=k)
        conditions = parameter_conditions(plant.definition, symbols[k]) if k in symbols else []
        check_support(d, plant.params[k], conditions, source=source, section="parameters", key=k,
                      what=f"parameter {k} of the plant {plant.definition.name!r}")
        params.append((k, d))
    gains = {"steering_torque": DRIVER_KEYS, "banked_road": BANKED_DRIVER_KEYS, "model": ()}[kind]
    driver = []
    for k, v in top.get("driver", {}).items():
        if k not in gains:
            raise config_error(source, "driver", k, v, ("must be a gain of the driver: " + ", ".join(gains)) if gains
                               else f"not set: the {EXCITATION} scenario has no driver", suggest(k, gains))
        driver.append((k, parse_dist(v, source=source, section="driver", key=k)))
    run_s = _run_duration(config, top["scenarios"], top.get("duration"))
    sensors = _sensors(top.get("sensors", {}), source, _measured_signals(config),
                       sensor_noise(families.get(config.family)), run_s)
    signals = _error_signals(config, kind)
    rank = top.get("rank_by", signals[0])
    if rank not in signals:
        raise config_error(source, None, "rank_by", rank, "must be an estimated signal: " + ", ".join(signals),
                           suggest(rank, signals))
    return CampaignSpec(source=source, observer=name, scenarios=tuple(top["scenarios"]), runs=top["runs"],
                        seed=top.get("seed", 0), duration=top.get("duration"),
                        scenario_seed=top.get("scenario_seed", "fixed"), worst=top.get("worst", 3), rank_by=rank,
                        chunk=top.get("chunk"), run_timeout=top.get("run_timeout", 60.0),
                        parameters=tuple(params), driver=tuple(driver),
                        sensors=sensors, project=project, raw=data)


def _parse_logs(top: dict, data: dict, source: str, name: str, config, project) -> CampaignSpec:
    """A campaign over recorded runs: every log readable through the observer's ``[data]`` map,
    dispersions of the sensors alone, the errors scored against the map's references."""
    from ..errors import DatasetError
    from ..validation import logfiles
    if not top["logs"]:
        raise config_error(source, None, "logs", [], "must name at least one log")
    for key in ("parameters", "driver", "scenario_seed"):
        if key in top:
            raise config_error(source, None, key, top[key], "not set in a campaign over logs: a log is the recorded "
                               "car, whose parameters, driver and scenario are what they were; allowed there: "
                               "[sensors.SIGNAL] (noise, bias, delay added to the recorded signal)")
    if config.column_map is None:
        raise config_error(source, None, "logs", top["logs"], f"logs the observer file of {name!r} maps: it has no "
                           f"[data] table naming the log's columns for its inputs (docs/validation.md, 'Your own logs')")
    base = Path(source).resolve().parent
    for i, log in enumerate(top["logs"]):
        try:
            logfiles.kind(base / log)
        except DatasetError as exc:
            raise config_error(source, None, f"logs[{i}]", log, f"a readable log relative to {base} ({exc})") from None
    if len(set(top["logs"])) != len(top["logs"]):
        twice = next(x for x in top["logs"] if top["logs"].count(x) > 1)
        raise config_error(source, None, "logs", top["logs"], f"each log once ({twice!r} is named twice): runs cycle "
                           f"over the logs, and runs = N x len(logs) reads each N times")
    sensors = _sensors(top.get("sensors", {}), source, _measured_signals(config), None, None)
    signals = log_error_signals(config)
    if not signals:
        outputs = _outputs(config)
        raise config_error(source, None, "logs", top["logs"], f"logs with a reference to score: the [data.truth] table "
                           f"of {config.column_map.source} maps no output of the observer (its outputs: "
                           f"{', '.join(outputs)})")
    rank = top.get("rank_by", signals[0])
    if rank not in signals:
        raise config_error(source, None, "rank_by", rank, "must be an estimated signal with a reference in [data.truth]: "
                           + ", ".join(signals), suggest(rank, signals))
    # a log's run takes the time its file takes to read: about 0.6 s per MB for a ROS 2 bag or a CAN log
    # (docs/validation.md, 'Large logs'), so the default per-run timeout grows with the largest log
    largest = max(_bytes(base / log) for log in top["logs"])
    return CampaignSpec(source=source, observer=name, scenarios=(), runs=top["runs"], seed=top.get("seed", 0),
                        duration=top.get("duration"), worst=top.get("worst", 3), rank_by=rank, chunk=top.get("chunk"),
                        run_timeout=top.get("run_timeout", 60.0 + largest / 1e6), sensors=sensors,
                        logs=tuple(top["logs"]),
                        project=project, raw=data)


def _sensors(tables: dict, source: str, measured: tuple, noise: dict | None, run_s: float | None) -> tuple:
    """The ``[sensors.X]`` dispersions, each of a signal the observer reads: ((signal, ((field, Dist), ...)), ...).
    ``noise``: the nominal noise of each signal (a relative dispersion's scale); None over logs, whose sensors
    have no nominal (``relative`` refused). ``run_s``: the shortest run, which a delay must stay under."""
    sensors = []
    for sig, table in tables.items():
        if sig not in measured:
            raise config_error(source, "sensors", sig, table, "must be a signal the observer reads: "
                               + ", ".join(measured), suggest(sig, measured))
        sec = f"sensors.{sig}"
        if not isinstance(table, dict):
            raise config_error(source, "sensors", sig, table, "must be a table with noise, bias, delay")
        check_keys(table, SENSOR_KEYS, source=source, section=sec)
        fields = []
        for f in (f for f in SENSOR_KEYS if f in table):
            d = parse_dist(table[f], source=source, section=sec, key=f)
            if d.relative and noise is None:
                raise config_error(source, f"{sec}.{f}", "relative", True, "not set over logs: a recorded sensor has no "
                                   "nominal noise, bias or delay to scale; give the value itself")
            if f in ("noise", "delay"):
                nominal = (noise or {}).get(sig, 0.0) if f == "noise" else 0.0
                # a delay as long as the run leaves the observer nothing but the first sample (1e9 s was
                # accepted): it must be shorter than the shortest run
                bound = [("<", run_s, f"shorter than the run: {run_s:g} s")] if f == "delay" and run_s else []
                check_support(d, nominal, [(">=", 0.0, ""), *bound], source=source, section=sec, key=f,
                              what=f"the {'standard deviation' if f == 'noise' else 'delay'} of sensor {sig}")
            fields.append((f, d))
        sensors.append((sig, tuple(fields)))
    return tuple(sensors)


def _bytes(path: Path) -> int:
    """The size of a log: a file's, or a ROS 2 bag folder's files together."""
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file()) if path.is_dir() else path.stat().st_size


def _outputs(config) -> tuple:
    """The observer's outputs, as its design lock names them."""
    import json
    from ..design import lock as design_lock
    art = json.loads(design_lock.path(config).read_text())
    return tuple(art["signals"].get("output", art["signals"]["state"]))


def log_error_signals(config) -> tuple:
    """The observer's outputs the ``[data.truth]`` map gives a reference for, in the observer's order."""
    return tuple(s for s in _outputs(config) if s in config.column_map.truth)


def _run_duration(config, names, duration) -> float | None:
    """[s] The shortest run of the campaign: ``duration`` where it truncates the scenarios, else the
    scenarios' own (the excitation's :data:`codegen.validation.excitation.DURATION`); None where
    unknown."""
    from ..validation import excitation, scenarios as scn_lib
    from .plants import EXCITATION
    own = []
    for name in dict.fromkeys(names):
        if name == EXCITATION:
            own.append(excitation.DURATION)
            continue
        try:
            own.append(scn_lib.make(name, sample_rate=1.0 / config.sample_time).duration)
        except Exception:          # noqa: BLE001 -- a scenario that cannot be built here says so when it runs
            return duration
    return min([*own, *([duration] if duration else [])]) if own else duration


def _plant_parameters(plant) -> tuple:
    return tuple(n for n in plant.param_names if not n.startswith("driver."))


def _measured_signals(config) -> tuple:
    import json
    from ..design import lock as design_lock
    art = json.loads(design_lock.path(config).read_text())
    return tuple(c[2:] if c.startswith("y_") else c for c in art["signals"]["input"])


def _error_signals(config, kind: str) -> tuple:
    from .plants import KINDS
    outputs = _outputs(config)
    spec = KINDS[kind][0](config)
    truth = set(spec.output_names) | {"phi_r"} | set(getattr(spec.extra, "external", ()))   # a model plant's inputs
    return tuple(s for s in outputs if s in truth)
