"""C == model: a compiled step is installed only when it computes what its model says.

``uiogen build`` compiles an observer's generated C into a Python extension at a temporary path
and installs it only after :func:`check` passes. The check compares the compiled step with two
evaluations of the same discrete step that share no code with the C:

* the family's **numpy reference step** (:meth:`~codegen.families.ObserverBuild.reference_step`),
  an implementation written apart from the CasADi graph (its own solves, its own sums);
* the **CasADi Function** the C was generated from, evaluated by CasADi's virtual machine.

It checks, in this order, and stops at the first disagreement with a
:class:`~codegen.errors.ConformanceError` that names the signal and the sample:

1. **Layout.** The signal names and their order in the design lock (``signals``), the C header
   (``N_STATE``/``N_INPUT``/``N_OUTPUT`` and the fields of the state, input and output structs),
   the extension (``N_STATE``, ``N_INPUT``, ``N_OUTPUT``) and the CasADi function's argument sizes
   agree, so the flat input row is read exactly as the model names it.
2. **Numbers.** On random samples covering every declared box (:func:`sample_boxes`): known inputs
   in their ``[inputs.NAME]`` ranges, scheduling inputs in their boxes *and on their edges and
   beyond them* (where the step must clamp and say so), measured outputs over the range the output
   map takes on the ``[state_bounds]`` box, and observer states reached by the reference step from
   such inputs, perturbed and pushed to their boxes' edges, the compiled step's next state, outputs
   and status bits equal both evaluations within :data:`TOLERANCE`.

The tolerance is relative to each signal's scale over the samples (its largest magnitude): the
numpy step sums and solves in another order than the C, so the two agree to rounding, amplified at
most by the conditioning of the step's solves; the CasADi evaluation runs the C's own graph and
agrees to a few ulps. A swapped input, a wrong offset, a stale kernel or a dropped term moves a
signal by far more than either.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..emit.header import struct_fields
from ..errors import ConformanceError

#: largest |C - numpy| relative to the entry's rounding scale |f| + |df/dargs| |args|: the numpy
#: step solves and sums in another order, which ill-conditioned internal solves amplify (5e-9 seen
#: on the built-in observers); a wrong signal, offset or term is off by orders of magnitude more
TOLERANCE = 1e-6
#: the same against the CasADi evaluation of the graph the C was generated from (same operations)
CASADI_TOLERANCE = 1e-12
#: range assumed for a known input or output without any declared box (in the model's unit)
DEFAULT_RANGE = (-1.0, 1.0)
#: samples of the numeric check (each one step from its own state) against the CasADi evaluation,
#: and how many of them (drawn at random) are also evaluated by the slower numpy reference step
SAMPLES = 1000
REFERENCE_SAMPLES = 250


@dataclass(frozen=True)
class Box:
    """The range one flat input (or state entry) is sampled in, and where the range comes from."""

    lower: float
    upper: float
    source: str          # "scheduling box", "[inputs.delta]", "output map on [state_bounds]", ...
    clamped: bool = False   # the step clamps this signal to the box (samples beyond it too)


@dataclass
class Report:
    """What :func:`check` compared, for ``uiogen build`` and the tests."""

    observer: str
    samples: int = 0
    boxes: dict = field(default_factory=dict)        # {input name: Box}
    worst: dict = field(default_factory=dict)        # {"numpy": (error, signal, sample), "casadi": ...}
    status_samples: dict = field(default_factory=dict)   # {status bits: count}
    carriers: tuple = ()     # names of substituted carriers, whose inverse also flags SCHEDULING_CLAMPED

    def as_record(self) -> dict:
        """The report as JSON data (what ``uiogen build`` records beside the extension it installed)."""
        return {"observer": self.observer, "samples": self.samples,
                "worst": {who: {"error": err, "signal": sig, "sample": k} for who, (err, sig, k) in self.worst.items()},
                "status_samples": {str(bits): n for bits, n in sorted(self.status_samples.items())},
                "line": self.line()}

    @classmethod
    def from_record(cls, record: dict) -> "Report":
        """The report :meth:`as_record` wrote (its sampled boxes are not recorded)."""
        return cls(observer=record["observer"], samples=record["samples"],
                   worst={who: (w["error"], w["signal"], w["sample"]) for who, w in record["worst"].items()},
                   status_samples={int(bits): n for bits, n in record["status_samples"].items()})

    def line(self) -> str:
        parts = [f"{who} {err:.1e} ({sig})" for who, (err, sig, _) in self.worst.items()]
        clamped = sum(n for bits, n in self.status_samples.items() if bits & 1)
        # the bit is every range check of the step, not only the scheduling box: the nonlinear-tyre step
        # flags an estimated slip outside its certified set, a substituted carrier's inverse an estimate
        # beyond the carrier's range; a random state sample trips these most of the time
        where = "a signal beyond a range the step checks: a scheduling box, a family's certified set" + (
            f", the range of {', '.join(self.carriers)} or of a state its inverse reads" if self.carriers else "")
        return (f"conformance: {self.samples} samples across every declared box ({clamped} flagged "
                f"SCHEDULING_CLAMPED, {where}), C against {', '.join(parts)} of the rounding scale (|f| + |df/dargs| |args|) per entry; tolerances {TOLERANCE:g} "
                f"(numpy) and {CASADI_TOLERANCE:g} (CasADi)")


# -- 1. layout -----------------------------------------------------------------------------------

def header_layout(header: str, name: str) -> dict:
    """{"state"|"input"|"output": [field names], "N_STATE": n, ...} read from a generated header."""
    NAME = name.upper()
    out = {}
    for key in ("N_STATE", "N_INPUT", "N_OUTPUT"):
        m = re.search(rf"^#define {NAME}_{key} (\d+)$", header, re.M)
        out[key] = int(m.group(1)) if m else None
    for part, fields in struct_fields(header, name).items():
        out[part] = None if fields is None else [f[0] for f in fields]
    return out


def check_layout(build, lock: dict, header: str, module) -> None:
    """Names and order of every signal: the build, its design lock, the C header, the extension
    and the CasADi function all describe the same vectors."""
    name = build.name
    want = {"state": list(build.state_names), "input": list(build.input_names), "output": list(build.output_names)}
    signals = lock.get("signals", {})
    head = header_layout(header, name)
    for what, names in want.items():
        if list(signals.get(what, [])) != names:
            raise ConformanceError(f"{name}: the design lock's {what} signals {signals.get(what)} are not the "
                                   f"build's {names}: regenerate with `uiogen generate --force`")
        if head[what] != names:
            raise ConformanceError(f"{name}: the C header's {what} struct has fields {head[what]}, the model's "
                                   f"{what} signals are {names}: the C does not read the vectors the model names")
        n = head[f"N_{what.upper()}"]
        if n != len(names):
            raise ConformanceError(f"{name}: the C header says N_{what.upper()} = {n}, the model has "
                                   f"{len(names)} {what} signals ({', '.join(names)})")
        got = getattr(module, f"N_{what.upper()}")
        if got != len(names):
            raise ConformanceError(f"{name}: the extension's N_{what.upper()} = {got}, the model has "
                                   f"{len(names)} {what} signals ({', '.join(names)})")
    f = build.step_function()
    nu, ny = build.nu, build.ny
    sizes = [f.numel_in(i) for i in range(4)]
    expected = [len(want["state"]), nu, ny, len(want["input"]) - nu - ny]
    labels = ("state z", "known inputs u", "measured outputs y", "scheduling inputs rho")
    for label, got, exp in zip(labels, sizes, expected):
        if got != exp:
            raise ConformanceError(f"{name}: the step's {label} has {got} entries but the input row gives it "
                                   f"{exp} (inputs {', '.join(want['input'])}; nu = {nu}, ny = {ny})")


# -- 2. numbers ----------------------------------------------------------------------------------

def _output_ranges(build, n: int, rng) -> dict:
    """{output name: (lo, hi)} the output map takes on the state box (declared [state_bounds];
    a state without one ranges over :data:`DEFAULT_RANGE`), with the known inputs in their ranges."""
    import sympy as sp
    from ..model import load_parameters, parameter_substitution
    from ..errors import ModelDefinitionError
    config = build.config
    try:
        model = config.load_model()
    except ModelDefinitionError:        # a family whose model module is not one ModelDefinition
        return {}
    params = load_parameters(config.parameter_path)
    subs = parameter_substitution(model, params)
    symbols = [*model.states, *model.known_inputs, *model.unknown_inputs, *(g.symbol for g in model.scheduling),
               *(w.symbol for w in model.derived_inputs)]
    columns = []
    for s in symbols:
        key = str(s)
        box = params.state_bounds.get(key) or _declared_input(params, key) or _scheduling(params, key)
        lo, hi = box if box else DEFAULT_RANGE
        columns.append(rng.uniform(lo, hi, n))
    values = np.column_stack(columns) if columns else np.zeros((n, 0))
    out = {}
    for oname, expr in model.outputs:
        fn = sp.lambdify(symbols, sp.sympify(expr).subs(subs), modules="numpy")
        with np.errstate(all="ignore"):
            v = np.broadcast_to(np.asarray(fn(*values.T), dtype=float), (n,))
        v = v[np.isfinite(v)]
        if v.size:
            out[oname] = (float(v.min()), float(v.max()))
    return out


def _declared_input(params, key):
    t = params.inputs.get(key)
    return (float(t["min"]), float(t["max"])) if t else None


def _scheduling(params, key):
    b = params.scheduling.get(key)
    return (b.lower, b.upper) if b is not None and b.lower is not None else None


def sample_boxes(build, rng=None) -> dict:
    """{flat input name: :class:`Box`}: where the numeric check samples each input of the step."""
    from ..model import load_parameters
    rng = np.random.default_rng(0) if rng is None else rng
    params = load_parameters(build.config.parameter_path)
    sched = {k: tuple(v) for k, v in build.input_boxes().items()}
    outputs = None
    boxes = {}
    for k, name in enumerate(build.input_names):
        if name in sched:
            boxes[name] = Box(*sched[name], "scheduling box", clamped=True)
            continue
        declared = _declared_input(params, name) or _scheduling(params, name)
        if declared:
            boxes[name] = Box(*declared, f"[inputs.{name}]" if name in params.inputs else "[scheduling]")
            continue
        if build.nu <= k < build.nu + build.ny and name.startswith("y_"):
            if outputs is None:
                outputs = _output_ranges(build, 4000, rng)
            lo_hi = outputs.get(name[2:])
            if lo_hi is not None:
                lo, hi = lo_hi
                if hi - lo < 1e-12 * max(1.0, abs(lo)):
                    lo, hi = lo - 1.0, hi + 1.0
                boxes[name] = Box(lo, hi, "output map on the state box")
                continue
        boxes[name] = Box(*DEFAULT_RANGE, "no declared range: +-1 in the model's unit")
    return boxes


def _input_samples(boxes: dict, names: list, n: int, rng) -> np.ndarray:
    """n rows: uniform inside each box, with a share on its edges and, for clamped signals, beyond."""
    cols = []
    for name in names:
        b = boxes[name]
        col = rng.uniform(b.lower, b.upper, n)
        pick = rng.random(n)
        col[pick < 0.08] = b.lower
        col[(pick >= 0.08) & (pick < 0.16)] = b.upper
        if b.clamped:
            width = b.upper - b.lower
            beyond = (pick >= 0.16) & (pick < 0.22)
            col[beyond] = np.where(rng.random(beyond.sum()) < 0.5, b.lower - 0.1 * width * rng.random(beyond.sum()),
                                   b.upper + 0.1 * width * rng.random(beyond.sum()))
        cols.append(col)
    return np.column_stack(cols) if cols else np.zeros((n, 0))


def _split(build, inputs):
    nu, ny = build.nu, build.ny
    return inputs[:nu], inputs[nu:nu + ny], inputs[nu + ny:]


def _reference(build, z, row) -> tuple:
    """(z_next, excess, warmup) of the numpy reference step."""
    u, y, rho = _split(build, row)
    try:
        res = build.reference_step(np.array(z, float), u, y, rho)
    except (TypeError, ValueError, ZeroDivisionError, FloatingPointError, OverflowError) as exc:
        # the model cannot be evaluated at a point of its declared boxes (a power of a negative is
        # complex in Python, a division by an exact 0 raises): the C would step through NaN there
        values = ", ".join(f"{n}={v:.6g}" for n, v in zip(build.input_names, row))
        raise ConformanceError(
            f"{build.name}: the numpy reference step of the model cannot be evaluated inside the declared boxes "
            f"({type(exc).__name__}: {exc}); inputs {values}: the model is not a finite real number there (a "
            f"sqrt or power of a negative, a division by 0): narrow the box or change the equation; the "
            f"extension is not installed") from None
    if isinstance(res, tuple):
        z_next = np.asarray(res[0], float).ravel()
        excess = float(np.asarray(res[1]).ravel()[0]) if len(res) > 1 else 0.0
        warmup = float(np.asarray(res[2]).ravel()[0]) if len(res) > 2 else 0.0
    else:
        z_next, excess, warmup = np.asarray(res, float).ravel(), 0.0, 0.0
    return z_next, excess, warmup


def state_samples(build, boxes: dict, n: int, rng) -> tuple:
    """(states (n, n_state), inputs (n, n_input)): states the step reaches from random
    inputs in the boxes, then a share perturbed around them and a share with the estimates of
    states with a declared [state_bounds] box drawn in that box or on its edges.

    Entries that take only a few integer values along the reached states (a "primed" flag, a
    mode index) are logic, not signals: they keep values the step itself produced.
    """
    from ..model import load_parameters
    names = list(build.input_names)
    inputs = _input_samples(boxes, names, n, rng)
    nz = len(build.state_names)
    states = np.zeros((n, nz))
    z = np.zeros(nz)
    f = build.step_function()
    nu, ny = build.nu, build.ny
    for k in range(n):
        states[k] = z
        row = inputs[k]
        out = f(z, row[:nu], row[nu:nu + ny], row[nu + ny:])
        z_next = np.array(out[0] if isinstance(out, (list, tuple)) else out, dtype=float).ravel()
        # a long random run may leave the certified region; restart rather than follow a blow-up
        z = z_next if np.all(np.isfinite(z_next)) and np.abs(z_next).max(initial=0) < 1e8 else np.zeros(nz)
    logic = np.array([np.all(states[:, i] == np.round(states[:, i])) and np.unique(states[:, i]).size <= 4
                      for i in range(nz)], dtype=bool)
    scale = np.maximum(np.abs(states).max(axis=0), 1e-3)
    perturbed = rng.random(n) < 0.3
    noise = 0.1 * scale * rng.standard_normal((perturbed.sum(), nz))
    noise[:, logic] = 0.0
    states[perturbed] += noise
    bounds = load_parameters(build.config.parameter_path).state_bounds
    in_box = rng.random(n) < 0.3
    for i, s in enumerate(build.state_names):
        if s in bounds and not logic[i]:
            lo, hi = bounds[s]
            col = rng.uniform(lo, hi, n)
            col[rng.random(n) < 0.2] = lo
            col[rng.random(n) < 0.2] = hi
            states[in_box, i] = col[in_box]
    return states, inputs


def _compiled(module, states, inputs) -> tuple:
    """(z_next, outputs, status) of the compiled step, one call per sample from its own state."""
    n, nz = states.shape
    nxt = states.copy()
    outs = np.empty((n, module.N_OUTPUT))
    status = np.empty(n, dtype=np.int64)
    for k in range(n):
        status[k] = module.step(nxt[k], np.ascontiguousarray(inputs[k]), outs[k])
    return nxt, outs, status


def _casadi(build, states, inputs) -> tuple:
    """(z_next, excess, warmup, sensitivity) of the CasADi Function the C was generated from;
    ``sensitivity`` (n, n_state) is |z_next| + |d z_next / d args| |args| per sample: the size of
    what rounding can move each entry by, relative to the unit roundoff."""
    import casadi as ca
    f = build.step_function()
    nu, ny = build.nu, build.ny
    args = [states.T, inputs[:, :nu].T, inputs[:, nu:nu + ny].T, inputs[:, nu + ny:].T]
    res = f.map(states.shape[0])(*args)
    res = res if isinstance(res, (list, tuple)) else [res]
    z = np.array(res[0]).T
    excess = np.array(res[1]).ravel() if len(res) > 1 else np.zeros(states.shape[0])
    warmup = np.array(res[2]).ravel() if len(res) > 2 else np.zeros(states.shape[0])
    sym = [ca.SX.sym(f.name_in(i), f.sparsity_in(i)) for i in range(4)]
    z_next = f(*sym)[0] if f.n_out() > 1 else f(*sym)
    x = ca.vertcat(*sym)
    jac = ca.Function("rounding_scale", sym, [ca.fabs(ca.jacobian(z_next, x)) @ ca.fabs(x) + ca.fabs(z_next)])
    with np.errstate(invalid="ignore"):
        sens = np.array(jac.map(states.shape[0])(*args)).T
    # where a derivative is not finite (a root's slope at 0, inside a differentiator or a derived
    # signal), the entry's largest finite scale over the samples stands in for it
    bad = ~np.isfinite(sens)
    if bad.any():
        fallback = np.max(np.where(bad, 0.0, sens), axis=0, initial=0.0)
        fallback = np.maximum(fallback, np.abs(np.where(np.isfinite(z), z, 0.0)).max(axis=0, initial=0.0))
        sens = np.where(bad, fallback, sens)
    return z, excess, warmup, sens


def _expected_status(module, excess, warmup) -> np.ndarray:
    bits = np.where(np.asarray(excess) > 0, module.SCHEDULING_CLAMPED, 0)
    return bits | np.where(np.asarray(warmup) > 0, module.WARMING_UP, 0)


def _worst(got, want, sens, names, who, build, inputs, tol):
    """(error, signal, sample) of the largest |got - want| / sensitivity; raises beyond ``tol``."""
    both_nan = np.isnan(got) & np.isnan(want)
    err = np.where(both_nan, 0.0, np.abs(got - want) / np.maximum(sens, 1e-300))
    err = np.where(np.isnan(err), np.inf, err)
    k, i = np.unravel_index(int(np.argmax(err)), err.shape)
    worst = float(err[k, i])
    if not worst <= tol:
        row = ", ".join(f"{n}={v:.6g}" for n, v in zip(build.input_names, inputs[k]))
        raise ConformanceError(
            f"{build.name}: the compiled step disagrees with the {who} evaluation of its model in signal "
            f"{names[i]!r} at sample {k}: C gives {float(got[k, i])!r}, the {who} step {float(want[k, i])!r} "
            f"(error {worst:.3g} of the entry's rounding scale {float(sens[k, i]):.3g}, tolerance {tol:g}); "
            f"inputs {row}; the extension is not installed")
    return worst, names[i], int(k)


def check_numbers(build, module, n: int = SAMPLES, seed: int = 0, n_reference: int = REFERENCE_SAMPLES) -> Report:
    """The compiled step against the CasADi evaluation on ``n`` samples and the numpy reference on
    ``n_reference`` of them."""
    rng = np.random.default_rng(seed)
    report = Report(build.name, carriers=tuple(str(sub.symbol) for sub in getattr(build, "substitutions", ())))
    boxes = sample_boxes(build, rng)
    states, inputs = state_samples(build, boxes, n, rng)
    report.boxes, report.samples = boxes, n
    z_c, out_c, status_c = _compiled(module, states, inputs)
    z_ca, ex_ca, wu_ca, sens = _casadi(build, states, inputs)
    sub = np.sort(rng.choice(n, size=min(n, n_reference), replace=False))
    ref = [_reference(build, states[k], inputs[k]) for k in sub]
    z_np = np.full_like(z_ca, np.nan)
    ex_np, wu_np = np.zeros(n), np.zeros(n)
    z_np[sub] = np.array([r[0] for r in ref])
    ex_np[sub], wu_np[sub] = [r[1] for r in ref], [r[2] for r in ref]
    referenced = np.zeros(n, dtype=bool)
    referenced[sub] = True
    names = list(build.state_names)
    finite = np.isfinite(z_ca).all(axis=1)
    keep = referenced & np.isfinite(z_np).all(axis=1)
    if (status_c & module.NUMERICAL_FAILURE).any() or (status_c & module.NONFINITE_INPUT).any():
        k = int(np.flatnonzero((status_c & (module.NUMERICAL_FAILURE | module.NONFINITE_INPUT)) != 0)[0])
        raise ConformanceError(f"{build.name}: the compiled step reports status {int(status_c[k])} at sample {k} "
                               f"inside the declared boxes (finite inputs, reachable state): the C fails where "
                               f"the model does not; the extension is not installed")
    report.worst["numpy"] = _worst(z_c[keep], z_np[keep], sens[keep], names, "numpy reference", build,
                                   inputs[keep], TOLERANCE)
    report.worst["casadi"] = _worst(z_c, z_ca, sens, names, "CasADi", build, inputs, CASADI_TOLERANCE)
    n_out = module.N_OUTPUT
    if not np.array_equal(out_c, z_c[:, len(names) - n_out:]):
        k = int(np.flatnonzero((out_c != z_c[:, len(names) - n_out:]).any(axis=1))[0])
        raise ConformanceError(f"{build.name}: at sample {k} the compiled step's outputs are not the last "
                               f"{n_out} entries of its next state")
    for who, excess, warmup, rows in (("numpy reference", ex_np, wu_np, keep), ("CasADi", ex_ca, wu_ca, finite)):
        want = _expected_status(module, excess, warmup)
        bad = np.flatnonzero((status_c != want) & rows)
        if bad.size:
            k = int(bad[0])
            row = ", ".join(f"{n}={v:.6g}" for n, v in zip(build.input_names, inputs[k]))
            raise ConformanceError(f"{build.name}: at sample {k} the compiled step returns status {int(status_c[k])}, "
                                   f"the {who} step implies {int(want[k])} (clamped {excess[k]:.3g}, warm-up "
                                   f"{warmup[k]:.3g}); inputs {row}; the extension is not installed")
    values, counts = np.unique(status_c, return_counts=True)
    report.status_samples = {int(v): int(c) for v, c in zip(values, counts)}
    return report


def check(build, module, generated: Path, lock: dict, n: int = SAMPLES, seed: int = 0) -> Report:
    """Layout, then numbers (module docstring); raises :class:`ConformanceError` at the first disagreement."""
    header = (Path(generated) / f"{build.name}.h").read_text()
    check_layout(build, lock, header, module)
    return check_numbers(build, module, n, seed)
