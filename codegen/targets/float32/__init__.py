"""The single-precision (float32) build of an observer, and the bound its certificate gives it.

``render(b, "float32")`` (:mod:`codegen.emit`) gives the same C API in ``float``, every name
suffixed ``_f32``; it is emitted into ``build/float32/NAME/`` (never into ``generated_c/``: the
committed C is the double one) and compiled with the project's strict flags into a shared
library, called here through ctypes.

The bound. Write the double step ``z+ = F(z, w)`` and the float step ``z+ = F(z, w) + d`` where
``d_k`` is the float step's own error at its own state (its rounding and the rounding of the
inputs ``w``): ``d_k = z^f_k+1 - F(z^f_k, w_k)``, one double evaluation of the step at the float
state. The deviation ``e = z^f - z^d`` of the float run from the double run on the same inputs
then obeys ``e_k+1 = F(z^f_k, w_k) - F(z^d_k, w_k) + d_k``. The family's certificate
(:meth:`ObserverBuild.contraction_metrics`) proves, for the state entries ``S`` a Lyapunov
matrix ``P`` covers, ``|F_S(a) - F_S(b)|_P <= c |a - b|_P`` whenever ``a`` and ``b`` differ in
``S`` only; the other entries act on ``S`` through the step's Jacobian ``J_k`` at the double
state. So, with ``B`` the bound of ``|e_S|_P`` of each covered block and ``E`` the bound of
``|e_r|`` of every other entry::

    B_k+1 = c B_k + |d_S|_P + sum_other |P^(1/2) J[S, .] ...| (B or E of the other entries)
    E_k+1 = |d_r| + sum |J[r, .]| (B or E of the entries r depends on)
    |e_j| <= sqrt((P^-1)_jj) B  (j in S),   |e_r| <= E

sample by sample along the run: the contraction in the Lyapunov norm is applied to the
roundings as they occur, not to the worst one over ``1 - c``. What is measured: ``d_k`` (exact,
one double step per sample) and ``J_k`` (exact where the step is affine in its state, which the
report checks against the certified ``c``; first order in the deviation elsewhere). What is
proven: the accumulation. State entries with their own dynamics that no certificate covers
(the sliding-mode differentiators, which converge in finite time but do not contract) get
their measured deviation instead of a bound, as do the entries without dynamics they read (the
sample a differentiator holds); the report names them and every output they
reach, and such an output is accepted only where the observer file says so (``[precision]
uncertified_states = "measured"``). On a sample outside the certified set (SCHEDULING_CLAMPED:
the certificate does not cover it) the step's own gain in the norm replaces ``c`` where it is
larger; the report counts those samples.

The tolerance (:mod:`codegen.project.precision`): per output, in its unit, a declared fraction
of the estimate's RMS response to the sensor noise (the double step run again with the noise
added), or a declared absolute tolerance. The float build is accepted when every output's bound
is within its tolerance on every validation scenario, and refused
(:class:`~codegen.errors.CertificateError`) with the figures and the option that would fix it.
"""
from __future__ import annotations

import ctypes
from pathlib import Path

import casadi as ca
import numpy as np

from ...certificate.contraction import ContractionMetric
from ...emit import generate as emit
from ...project import observer_file as observers
from ... import pipeline
from ...errors import CertificateError, ConfigurationError, ModelDefinitionError
from ...emit.toolchain import STRICT_CFLAGS, compile_and_link

NOISE_SEED = 0
CHUNK = 2000          # samples per batched CasADi evaluation


def _config(observer) -> observers.ObserverConfig:
    return observers.get(observer if isinstance(observer, observers.ObserverConfig) else str(observer))


def emit_float(observer, out_dir: Path | None = None, build=None) -> Path:
    """The float32 C of ``observer`` in ``out_dir/NAME/`` (default: its project's
    ``build/float32/NAME/``, :mod:`python_bindings.workspace`)."""
    config = _config(observer)
    b = build or pipeline.build(config)
    target = Path(out_dir or config.workspace.float32) / config.name
    target.mkdir(parents=True, exist_ok=True)
    for fname, text in emit.render(b, "float32").items():
        (target / fname).write_text(text)
    return target


def build_float(observer, out_dir: Path | None = None, build=None) -> Path:
    """Emit and compile the float32 step into a shared library (strict flags, -O2); its path."""
    config = _config(observer)
    d = emit_float(config, out_dir, build)
    name = f"{config.name}_f32"
    return compile_and_link([d / f"{name}_kernel.c", d / f"{name}.c"], d / f"lib{name}.so", include=[d],
                            flags=STRICT_CFLAGS, shared=True, object_dir=d)


class FloatObserver:
    """The float32 step through ctypes: ``run(inputs)`` like :meth:`CompiledObserver.run`."""

    def __init__(self, name: str, lib: Path, n_state: int, n_input: int, n_output: int, compensated: tuple = ()):
        # n_state: the float state vector; a compensated update ([precision] accumulation) puts its
        # compensation entries first, ``compensated`` giving the index of the entry each belongs to
        # in the observer's own state (the rest of the vector)
        self.name, self.n_state, self.n_input, self.n_output = name, n_state, n_input, n_output
        self.compensated = tuple(compensated)
        self._lib = ctypes.CDLL(str(lib))
        self._run = getattr(self._lib, f"{name}_f32_run_flat")
        fp = ctypes.POINTER(ctypes.c_float)
        self._run.argtypes = [fp, fp, ctypes.c_size_t, fp, ctypes.POINTER(ctypes.c_int)]
        self._run.restype = None

    def run(self, inputs, state=None):
        inputs = np.ascontiguousarray(inputs, dtype=np.float32)
        state = np.zeros(self.n_state, np.float32) if state is None else np.array(state, dtype=np.float32)
        n = inputs.shape[0]
        out = np.empty((n, self.n_output), np.float32)
        status = np.empty(n, np.intc)
        fp = ctypes.POINTER(ctypes.c_float)
        self._run(state.ctypes.data_as(fp), inputs.ctypes.data_as(fp), n, out.ctypes.data_as(fp),
                  status.ctypes.data_as(ctypes.POINTER(ctypes.c_int)))
        return out, status, state

    def states(self, inputs) -> tuple:
        """(states (n + 1, n_state): the state before each sample and after the last, status (n,))."""
        inputs = np.ascontiguousarray(inputs, dtype=np.float32)
        n = inputs.shape[0]
        states = np.zeros((n + 1, self.n_state), np.float32)
        status = np.empty(n, np.intc)
        out = np.empty(self.n_output, np.float32)
        state = np.zeros(self.n_state, np.float32)
        fp = ctypes.POINTER(ctypes.c_float)
        ip = ctypes.POINTER(ctypes.c_int)
        sp_, op = state.ctypes.data_as(fp), out.ctypes.data_as(fp)
        for k in range(n):
            self._run(sp_, inputs[k].ctypes.data_as(fp), 1, op, status[k:].ctypes.data_as(ip))
            states[k + 1] = state
        return states, status


def load_float(observer, out_dir: Path | None = None, build=None) -> FloatObserver:
    from ...extension.build import load
    config = _config(observer)
    obs = load(config)
    b = build or pipeline.build(config)
    compensated = ()
    if config.precision.accumulation == "compensated":
        names = list(b.state_names)
        compensated = tuple(names.index(s) for s in emit.compensated_kernel(b)[1])
    return FloatObserver(config.name, build_float(config, out_dir, b), obs.n_state + len(compensated), obs.n_input,
                         obs.n_output, compensated)


def own_state(fobs: FloatObserver, states: np.ndarray) -> tuple:
    """(the state the float step carries, in double: z + c, exact, on the compensated entries;
    z, the float state entries it stores and reads its outputs from) of the float state vectors."""
    states = np.asarray(states, dtype=np.float64)
    nc = len(fobs.compensated)
    z = states[:, nc:]
    carried = z.copy()
    for i, j in enumerate(fobs.compensated):
        carried[:, j] += states[:, i]
    return carried, z


def double_states(obs, inputs) -> tuple:
    """(states (n + 1, n_state) before each sample and after the last, status (n,)) of the double step."""
    n = inputs.shape[0]
    states = np.zeros((n + 1, obs.n_state))
    out = np.empty(obs.n_output)
    status = np.empty(n, np.int32)
    state = obs.initial_state()
    states[0] = state
    for k in range(n):
        status[k] = obs.step(state, inputs[k], out)
        states[k + 1] = state
    return states, status


# ---- the step's one-sample terms, in double ---------------------------------------------------------

class StepTerms:
    """The double step ``F`` and its Jacobian in the state, evaluated in batches (CasADi)."""

    def __init__(self, b):
        f = b.step_function()
        self.nu, self.ny = b.nu, b.ny
        self.nz = int(f.numel_in(0))
        args = [ca.SX.sym(n, int(f.numel_in(i))) for i, n in enumerate(("z", "u", "y", "rho"))]
        z_next = f(*args)[0]
        self.F = ca.Function("F", args, [z_next])
        self.J = ca.Function("J", args, [ca.densify(ca.jacobian(z_next, args[0]))])

    def _split(self, z, w):
        nu, ny = self.nu, self.ny
        return [ca.DM(np.ascontiguousarray(a.T)) for a in (z, w[:, :nu], w[:, nu:nu + ny], w[:, nu + ny:])]

    def next_state(self, z, w) -> np.ndarray:
        """F(z_k, w_k) per row."""
        out = np.empty_like(z, dtype=float)
        for s in range(0, z.shape[0], CHUNK):
            sl = slice(s, min(s + CHUNK, z.shape[0]))
            n = sl.stop - sl.start
            out[sl] = np.array(self.F.map(n)(*self._split(z[sl], w[sl]))).T
        return out

    def jacobian(self, z, w) -> np.ndarray:
        """dF/dz at (z_k, w_k), (n, nz, nz)."""
        out = np.empty((z.shape[0], self.nz, self.nz))
        for s in range(0, z.shape[0], CHUNK):
            sl = slice(s, min(s + CHUNK, z.shape[0]))
            n = sl.stop - sl.start
            m = np.array(self.J.map(n)(*self._split(z[sl], w[sl])))
            out[sl] = m.reshape(self.nz, n, self.nz).transpose(1, 0, 2)
        return out


# ---- the bound --------------------------------------------------------------------------------------

def _uncertified_dynamics(J: np.ndarray, rest: list) -> list:
    """Entries of ``rest`` (not covered by a metric) whose dependencies among themselves do not
    contract: a strongly connected group whose largest entrywise slope matrix over the run has a
    spectral radius >= 1 (or an unbounded slope), i.e. state with its own dynamics and no
    certificate, such as a sliding-mode differentiator, and the entries without dynamics that such
    a group reads (the sample a differentiator holds). A group that does contract (an estimate
    fed back through a scheduling signal, say) is bounded by the recursion like the others."""
    from scipy.sparse.csgraph import connected_components
    if not rest:
        return []
    sub = J[:, rest][:, :, rest]
    slopes = np.max(np.where(np.isfinite(sub), np.abs(sub), np.inf), axis=0)
    pattern = slopes > 0
    _, label = connected_components(pattern, directed=True, connection="strong")
    free = []
    for group in set(label.tolist()):
        members = np.flatnonzero(label == group)
        block = slopes[np.ix_(members, members)]
        if not block.any():
            continue
        if not np.all(np.isfinite(block)) or max(abs(np.linalg.eigvals(block))) >= 1.0:
            free += list(members)
    # Entries without dynamics of their own (on no cycle: a held input sample, a start flag) that
    # such a group reads are measured with it: the group reads them through its own unbounded slope
    # (a differentiator in error coordinates reads the sample it holds through sigma, exactly as it
    # reads its first entry), which no Jacobian carries, so their deviation enters by the exact
    # coupling as the group's does. Their measured deviation is what the recursion would bound them
    # by where they hold an input (its rounding).
    memoryless = [i for i in range(len(rest)) if np.count_nonzero(label == label[i]) == 1 and not pattern[i, i]]
    free += [i for i in memoryless if free and np.any(pattern[free, i])]
    return sorted(rest[i] for i in set(free))


def partition(metrics: list, state_names: list, J: np.ndarray) -> tuple:
    """(blocks: the state indices of each metric, rest: the other entries, free: the entries of
    ``rest`` with uncertified dynamics of their own)."""
    index = {s: i for i, s in enumerate(state_names)}
    blocks = [[index[s] for s in m.states] for m in metrics]
    covered = {i for blk in blocks for i in blk}
    rest = [i for i in range(len(state_names)) if i not in covered]
    return blocks, rest, _uncertified_dynamics(J, rest)


def deviation_bound(metrics: list, state_names: list, J: np.ndarray, d: np.ndarray, measured: np.ndarray,
                    coupling: np.ndarray | None = None) -> dict:
    """Bound of |z^f_k - z^d_k| per state entry and sample (see the module docstring).

    ``J`` (n, nz, nz): the step's Jacobian at the double states; ``d`` (n, nz): the float step's
    one-sample errors; ``measured`` (n + 1, nz): the actual deviations, taken for the entries no
    certificate covers (:func:`partition`); ``coupling`` (n, nz): what those deviations do to the
    next state, evaluated exactly (F at the double state with them put in, less F at the double
    state; required when there are such entries: a differentiator's slope is unbounded at
    sigma = 0, so no Jacobian carries it). Returns {"bound": (n + 1, nz), "measured_entries",
    "from_measured": the entries they reach, "self_gain": [max |P^(1/2) J_SS P^(-1/2)| per
    metric over the run, or None]}.
    """
    n, nz = d.shape
    blocks, rest, free = partition(metrics, state_names, J)
    if free and coupling is None:
        raise ValueError("entries without a certificate need the exact coupling of their measured deviation")
    if free:
        d = d + coupling
    units = len(metrics) + len(rest)
    # the nonnegative gain matrix G_k of the recursion x_k+1 = G_k x_k + delta_k, x = [B..., E...]
    G = np.zeros((n, units, units))
    delta = np.zeros((n, units))
    mb = len(metrics)
    self_gain = []
    for a, (m, blk) in enumerate(zip(metrics, blocks)):
        # the certified c, or the step's own gain where its Jacobian exceeds it (a scheduling that
        # depends on the estimate, which the frozen-scheduling certificate does not cover: first order)
        g = m.self_gain(J[:, blk][:, :, blk])
        self_gain.append(None if g is None else float(np.max(g)))
        G[:, a, a] = m.contraction if g is None else np.maximum(m.contraction, g)
        delta[:, a] = m.norm(d[:, blk].T)
        for b2, (m2, blk2) in enumerate(zip(metrics, blocks)):
            if b2 != a:
                G[:, a, b2] = m.gain_from(m2, J[:, blk][:, :, blk2])
        for j, r in enumerate(rest):
            G[:, a, mb + j] = m.norm(J[:, blk, r].T)
    for i, r in enumerate(rest):
        delta[:, mb + i] = np.abs(d[:, r])
        for a, (m, blk) in enumerate(zip(metrics, blocks)):
            G[:, mb + i, a] = m.row_gain(J[:, r, blk])
        G[:, mb + i, mb:] = np.abs(J[:, r, rest])
    fixed = [mb + rest.index(r) for r in free]
    # which units the measured entries reach (through any coupling of the run)
    reach = np.any(G != 0, axis=0)
    G[:, fixed, :] = 0.0
    G[:, :, fixed] = 0.0          # their effect is in the exact coupling term instead
    delta[:, fixed] = 0.0
    x = np.zeros((n + 1, units))
    for k in range(n):
        # an entry whose bound is 0 (both runs equal there) contributes nothing, whatever its slope
        # (a differentiator started at the sample itself has an unbounded slope at sigma = 0)
        live = x[k] > 0
        with np.errstate(invalid="ignore", over="ignore"):      # a run that diverges: inf, said below
            x[k + 1] = G[k][:, live] @ x[k, live] + delta[k]
        x[k + 1][np.isnan(x[k + 1])] = np.inf                     # inf times 0: no bound, never 0
        x[k + 1, fixed] = np.abs(measured[k + 1, free])
    bound = np.zeros((n + 1, nz))
    for a, (m, blk) in enumerate(zip(metrics, blocks)):
        bound[:, blk] = x[:, a:a + 1] * m.extraction()[None, :]
    bound[:, rest] = x[:, mb:]
    bound[~np.isfinite(bound)] = np.inf
    reached = set(fixed)
    grown = True
    while grown:
        new = {u for u in range(units) if u not in reached and any(reach[u, v] for v in reached)}
        grown = bool(new)
        reached |= new
    from_measured = set()
    for a, blk in enumerate(blocks):
        if a in reached:
            from_measured |= set(blk)
    from_measured |= {rest[u - mb] for u in reached if u >= mb}
    return {"bound": bound, "measured_entries": [state_names[i] for i in free],
            "from_measured": [state_names[i] for i in sorted(from_measured)], "self_gain": self_gain}


# ---- the tolerance ----------------------------------------------------------------------------------

def _units(b) -> dict:
    from ...emit.header import unit_of
    _, _, outputs = b.signal_docs()
    return {s["name"]: unit_of(s["doc"]) for s in outputs}


def input_noise(config, b) -> dict:
    """{input name: standard deviation} of the sensor noise: the ``[precision] noise`` table (which must
    agree with the parameter file's ``[sensor_noise]``), else ``[sensor_noise]``, else the family's validation
    noise (:func:`codegen.project.precision.input_noise`, which ``validate --data`` judges a log with too)."""
    from ...project.precision import input_noise as table
    return table(config, list(b.input_names))


def noise_response(obs, inputs: np.ndarray, noise: dict, out_d: np.ndarray) -> np.ndarray:
    """RMS per output of what the sensor noise does to the double estimate (seeded white noise)."""
    rng = np.random.default_rng(NOISE_SEED)
    noisy = np.array(inputs, dtype=float)
    for j, name in enumerate(obs.input_names):
        if name in noise:
            noisy[:, j] += noise[name] * rng.standard_normal(noisy.shape[0])
    out_n, _, _ = obs.run(noisy)
    return np.sqrt(np.mean((np.asarray(out_n) - out_d) ** 2, axis=0))


def _did_you_mean(key: str, names) -> str:
    """" (did you mean 'y_r'?)" for a misspelt signal name (the measured yawr is the input y_yawr), or ""."""
    from ...settings import suggest
    near = suggest(key, list(names)) or suggest(f"y_{key}", list(names))
    return f" (did you mean {near!r}?)" if near else ""


def _check_tolerance_keys(config, outputs) -> None:
    source = config.source or f"{config.name}.toml"
    for key in config.precision.tolerance:
        if key not in outputs:
            raise ConfigurationError(f"{source}: [precision.tolerance] {key}: not an output of {config.name}; its "
                                     f"outputs: {', '.join(outputs)}{_did_you_mean(key, outputs)}", source=source,
                                     section="precision.tolerance", key=key, allowed=", ".join(outputs))


# ---- the comparison ---------------------------------------------------------------------------------

def scenario_inputs(config, obs, scenarios=None) -> dict:
    """{scenario: inputs} of the observer's validation scenarios (the generic excitation for a
    family whose scenarios need another plant) and, for an observer the demo validates on the
    real log (its real-data table), the shared log too: the float build is held to the data it is
    validated on, not to a synthetic run alone."""
    from ...validation import demo, logs, run as validate
    out = {}
    todo = list(scenarios or validate.scenario_names(config))
    real_data = (demo.REAL_DATA_OBSERVER, *demo.REAL_DATA_OTHERS)
    if scenarios is None and config.name in real_data and logs.SHARED_LOG not in todo:
        todo.append(logs.SHARED_LOG)
    from ...model import load_parameters
    own = load_parameters(config.parameter_path).meta.get("shared_log")       # the car's own shared log
    if scenarios is None and own is not None and f"{own} log" in logs.SHARED_LOGS and f"{own} log" not in todo:
        todo.append(f"{own} log")
    while todo:
        scenario = todo.pop(0)
        try:
            out[scenario] = (logs.shared_log_inputs(obs.input_names, logs.SHARED_LOGS[scenario])
                             if scenario in logs.SHARED_LOGS else validate.scenario_inputs(config, scenario))
        except ModelDefinitionError:
            fallbacks = [logs.SHARED_LOG] if logs.reads_the_log(obs.input_names) else ["excitation"]
            if scenarios is not None or scenario in fallbacks:
                raise
            if not out and not todo:
                todo += fallbacks
    return out


def compare_scenario(b, obs, fobs, terms: StepTerms, metrics: list, inputs: np.ndarray, noise: dict,
                     spec) -> dict:
    """One scenario: per output, the bound, the measured deviation and the tolerance, in its unit."""
    z_d, status_d = double_states(obs, inputs)
    states_f, status_f = fobs.states(inputs)
    # The recursion runs on the state the float step carries (z + c on the entries a compensated
    # update keeps a rounding error c for), with d_k its one-sample error there against one double
    # step from it; what it emits is z, within |c| of it, which the output's bound adds.
    z_f, stored = own_state(fobs, states_f)
    d = z_f[1:] - terms.next_state(z_f[:-1], inputs)
    J = terms.jacobian(z_d[:-1], inputs)
    measured = np.abs(z_f - z_d)
    _, _, free = partition(metrics, list(b.state_names), J)
    coupling = None
    if free:
        mixed = z_d[:-1].copy()
        mixed[:, free] = z_f[:-1, free]
        coupling = terms.next_state(mixed, inputs) - terms.next_state(z_d[:-1], inputs)
    res = deviation_bound(metrics, list(b.state_names), J, d, measured, coupling)
    nz, no = len(b.state_names), len(b.output_names)
    tail = slice(nz - no, nz)
    out_d = z_d[1:, tail]
    response = noise_response(obs, inputs, noise, out_d)
    units = _units(b)
    signals = {}
    emitted = np.abs(stored - z_d)
    carried_off = np.abs(stored - z_f)
    for i, name in enumerate(b.output_names):
        bound = float(np.max(res["bound"][1:, nz - no + i] + carried_off[1:, nz - no + i]))
        dev = float(np.max(emitted[1:, nz - no + i]))
        declared = spec.tolerance.get(name)
        tol = float(declared) if declared is not None else spec.fraction * float(response[i])
        signals[name] = {"unit": units.get(name, ""), "bound": bound, "deviation": dev, "tolerance": tol,
                         "tolerance_rule": ("declared" if declared is not None
                                            else f"{spec.fraction:g} x noise response {response[i]:.3g}"),
                         "noise_response": float(response[i]),
                         "certified": b.state_names[nz - no + i] not in res["from_measured"],
                         "within": bound <= tol}
    clamped = int(np.count_nonzero(status_d & obs.status_bits["SCHEDULING_CLAMPED"]))
    return {"samples": int(inputs.shape[0]), "signals": signals, "status_equal": bool(np.array_equal(status_d, status_f)),
            "outside_certified_set": clamped,
            "measured_entries": res["measured_entries"], "self_gain": res["self_gain"],
            "bound_covers_deviation": all(s["bound"] >= s["deviation"] for s in signals.values())}


def compare(observer, scenarios=None, out_dir: Path | None = None) -> dict:
    """The float32 step against the double step on the observer's validation scenarios: per
    scenario and output, the certified bound of the deviation, the measured deviation and the
    tolerance (all in the signal's unit); whether the float build passes, and why not."""
    from ...extension.build import load
    config = _config(observer)
    b = pipeline.build(config)
    obs = load(config)
    fobs = load_float(config, out_dir, b)
    metrics = b.contraction_metrics()
    _check_tolerance_keys(config, list(b.output_names))
    noise = input_noise(config, b)
    terms = StepTerms(b)
    rows = {sc: compare_scenario(b, obs, fobs, terms, metrics, inputs, noise, config.precision)
            for sc, inputs in scenario_inputs(config, obs, scenarios).items()}
    report = {"observer": config.name, "source": config.source or f"{config.name}.toml",
              "fraction": config.precision.fraction, "noise": noise,
              "noiseless_inputs": [n for n in b.input_names if n not in noise],
              "uncertified_states": config.precision.uncertified_states,
              "accumulation": config.precision.accumulation,
              "compensated": [list(b.state_names)[j] for j in fobs.compensated],
              "metrics": [{"states": list(m.states), "contraction": m.contraction, "margin": m.margin,
                           "source": m.source, "knob": m.knob} for m in metrics],
              "scenarios": rows}
    report.update(_verdict(report))
    return report


def _verdict(report: dict) -> dict:
    """passes, the worst signal (bound / tolerance) and, for a refusal, why and what would fix it."""
    worst, measured = None, set()
    for sc, row in report["scenarios"].items():
        measured |= set(row["measured_entries"])
        for name, s in row["signals"].items():
            ratio = s["bound"] / s["tolerance"] if s["tolerance"] > 0 else (0.0 if s["bound"] == 0 else np.inf)
            if worst is None or ratio > worst["ratio"]:
                worst = {"signal": name, "scenario": sc, "ratio": float(ratio), **s}
    uncertified = sorted({n for row in report["scenarios"].values() for n, s in row["signals"].items()
                          if not s["certified"]})
    within = all(s["within"] for row in report["scenarios"].values() for s in row["signals"].values())
    status = all(row["status_equal"] for row in report["scenarios"].values())
    accept_measured = report["uncertified_states"] == "measured"
    passes = bool(report["metrics"]) and within and (accept_measured or not uncertified) and status
    reason = ""
    if not report["metrics"]:
        reason = "its family provides no certified contraction in a Lyapunov norm to bound the deviation with"
    elif uncertified and not accept_measured:
        reason = (f"{', '.join(uncertified)} depend on state no certificate covers ({', '.join(sorted(measured))}: "
                  f"dynamics of their own that do not contract in any certified norm), whose float32 deviation is "
                  f"only measured; [precision] uncertified_states = \"measured\" accepts it on the measured figures"
                  + ("" if within else f" (then: {worst['signal']} bound {worst['bound']:.3g} {worst['unit']} > "
                                       f"tolerance {worst['tolerance']:.3g} {worst['unit']})"))
    elif not within and worst["tolerance"] == 0 and worst["tolerance_rule"] != "declared":
        # no sensor noise known: the rule's tolerance is 0, and no contraction margin can meet it
        quiet = report.get("noiseless_inputs") or []
        first = quiet[0] if quiet else "INPUT"
        reason = (f"{worst['signal']} on {worst['scenario']}: tolerance 0 {worst['unit']} ({worst['tolerance_rule']}): "
                  f"no sensor noise of {'its inputs ' + ', '.join(quiet) if quiet else 'its inputs'} is known, so "
                  f"the tolerance rule gives 0 and no certified margin can meet it; declare it in "
                  f"{report.get('source', report['observer'])}: [precision] noise = {{ {first} = SIGMA, ... }} "
                  f"(each input's sensor-noise standard deviation, in its unit; docs/embedding.md), or an absolute "
                  f"[precision] tolerance = {{ {worst['signal']} = ... }}")
    elif not within:
        m = min(report["metrics"], key=lambda m: m["margin"])
        need = m["margin"] * worst["ratio"]
        reason = (f"{worst['signal']} on {worst['scenario']}: bound {worst['bound']:.3g} {worst['unit']} > tolerance "
                  f"{worst['tolerance']:.3g} {worst['unit']} ({worst['tolerance_rule']}); the certified contraction "
                  f"margin 1 - c = {m['margin']:.4g} ({m['source']}) "
                  + (f"would need to be about {need:.3g}" if need < 1 else
                     f"cannot reach what the bound needs ({need:.3g} > 1): a faster contraction alone does not fix it")
                  + (f" ({m['knob']})" if m["knob"] else "") + ", or a declared [precision] tolerance")
        outside = report["scenarios"][worst["scenario"]]["outside_certified_set"]
        if outside:
            reason += (f"; {outside} samples of {worst['scenario']} lie outside the certified set (SCHEDULING_CLAMPED), "
                       f"where no certificate bounds the deviation (the step's own gain is used there)")
    elif not status:
        reason = "the float32 status bits differ from the double step's on some sample"
    return {"passes": passes, "worst": worst, "uncertified": uncertified, "reason": reason}


def check(observer, scenarios=None, out_dir: Path | None = None) -> dict:
    """:func:`compare`, refusing (CertificateError) a float build that does not pass."""
    r = compare(observer, scenarios, out_dir)
    if not r["passes"]:
        raise CertificateError(f"{r['observer']}: float32 build refused: {r['reason']}")
    return r


def format_report(r: dict) -> str:
    verdict = ("accepted" + (f" ({', '.join(r['uncertified'])} on measured differentiator/uncertified state)"
                             if r["uncertified"] else "") if r["passes"] else "REFUSED: " + r["reason"])
    lines = [f"{r['observer']}: float32 {verdict}"]
    if r.get("compensated"):
        lines.append(f"  compensated update of {', '.join(r['compensated'])} (TwoSum; the rounding error carried in "
                     f"their _comp entries, the bound on z + _comp plus |_comp| for the outputs)")
    for m in r["metrics"]:
        lines.append(f"  contraction {m['contraction']:.6f}/step (margin {m['margin']:.4g}) over "
                     f"{len(m['states'])} states: {m['source']}")
    for sc, row in r["scenarios"].items():
        lines.append(f"  {sc} ({row['samples']} samples):")
        for name, s in row["signals"].items():
            flag = "" if s["certified"] else "  (measured: no certificate)"
            lines.append(f"    {name:14s} bound {s['bound']:9.2e}  deviation {s['deviation']:9.2e}  tolerance "
                         f"{s['tolerance']:9.2e} {s['unit']:8s} {'ok' if s['within'] else 'OVER'}{flag}")
    return "\n".join(lines)


# ---- the target: uiogen export --format float32, uiogen build --float32 -------------------------------

from ..base import BuildVariant, Target  # noqa: E402  (the registry's entry, after what it runs)


class Float32(Target, BuildVariant):
    name = "float32"
    title = "the float32 C package, accepted where the certificate covers the rounding"
    out = "DIR"
    build_flag = "float32"
    build_help = ("emit and build the float (casadi_real) variant into build/float32/NAME/ instead, "
                  "compared with the double step on the validation scenarios; refused where the "
                  "certificate's margin does not cover the rounding")

    def export(self, config, out, log=print) -> Path:
        """The float32 C of ``config`` in ``out``, once :func:`compare` accepts it (its report logged;
        a refusal is a CertificateError and writes nothing)."""
        import tempfile
        from ..base import write_folder
        from ...extension.build import check_generated
        check_generated(config)
        with tempfile.TemporaryDirectory() as tmp:
            report = compare(config, out_dir=Path(tmp))
            log(format_report(report))
            if not report["passes"]:
                raise CertificateError(f"{config.name}: float32 build refused: {report['reason']}")
            folder = Path(tmp) / config.name
            files = {f.name: f.read_bytes() for f in sorted(folder.iterdir())
                     if f.is_file() and f.suffix in (".c", ".h", ".txt")}
        out = write_folder(out, files)
        log(f"{config.name}: wrote {out} (the float32 C package: {len(files)} files, API {config.name}_f32_*)")
        return out

    def build(self, names, project=None) -> int:
        """``uiogen build --float32 [NAME ...]``: each observer's float32 library in
        ``build/float32/NAME/``, its report printed; a CertificateError naming those refused."""
        refused = []
        for name in names or observers.names():
            config = observers.get(name, project=project)
            name = config.name
            report = compare(config)
            print(format_report(report), flush=True)
            if report["passes"]:
                print(f"{name}: built {config.workspace.float32 / name / f'lib{name}_f32.so'} (API {name}_f32_*, "
                      f"CMakeLists.txt and {name}_f32_example.c beside it)", flush=True)
            else:
                refused.append(name)
        if refused:
            raise CertificateError(f"float32 build refused for {', '.join(refused)} (the reasons and figures above)")
        return 0


TARGET = Float32()
