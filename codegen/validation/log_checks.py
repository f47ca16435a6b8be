"""One set of checks for every logged run: the declared units and the physics of the observer's model.

A log's numbers reach the observer only through a unit (and a scale) the user declares, or the
shared format's fixed units; a wrong one (a lateral acceleration in m/s^2 declared in g, a
steering angle in radians declared in degrees, a yaw acceleration mapped to the yaw rate, a
steering ratio applied twice) gives estimates that are wrong without any sign. So before any
estimate is reported, every mapped column, converted to the model's unit, is checked:

1. **units**: within the plausible range of its dimension (:data:`PLAUSIBLE`: no vehicle
   accelerates at 6 g) and within :data:`BOX_FACTOR` x the model's own box for it (the
   parameter file's ``[scheduling]`` box, ``[state_bounds]`` or ``[inputs]`` range) -- unless
   nothing but another unit of the same dimension puts it there, which is then named;
2. **physics derived from the model** (:func:`derive`: from the equations, for any model, not
   from one log):

   * *output identities*: a measured output that equals a state's derivative up to measured terms,
     ``y = c dx/dt + g`` (the lateral acceleration of a single-track model,
     ``a_y = dv_y/dt + v_x r``): ``y`` against ``g`` (``dx/dt`` is the unexplained part, zero on
     average; exact when ``x`` is measured);
   * *kinematic identities*: a measured state whose derivative is a function of measured signals
     only (``d delta/dt = delta_dot``);
   * *steady state at low slip*: each measured state against its steady state from the known
     inputs (``dx/dt = 0`` for it and the unmeasured states, unknown inputs 0, linearized at zero
     slip): the yaw rate against the steering geometry ``r = v_x delta / (L + K v_x^2)``.

   Each relation is judged as the Stanford loader judges its own (:func:`Moments.bracket`): the
   ratio of the two sides is bracketed by the direct and reverse least-squares slopes, on signals
   averaged over +-:data:`SMOOTH_S`; it fails only when the whole bracket misses its band, and is
   not judged when the log does not excite it.

A failed check is a :class:`~codegen.errors.DatasetError` naming the column and the likely cause:
the one column whose unit alternative (g vs m/s^2, deg vs rad, km/h vs m/s, ...), sign or scale
(a steering ratio) makes every judged relation hold at once; a relation whose sides vary strongly
but do not follow each other names a wrong column. Where a check is ambiguous (a ratio outside
its band but inside :data:`WIDE_BAND` with no single cause; a weak correlation) it is a warning
in the report and the JSON (``warnings``), never silent. Every check is streaming
(:class:`LogChecks` is fed chunk by chunk), so a log of any size is checked in bounded memory.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from ..errors import DatasetError
from ..project.columns import UNITS, normalize_unit

# --- limits -----------------------------------------------------------------------------------------

PLAUSIBLE = {"angle": 4 * math.pi, "speed": 150.0, "acceleration": 60.0}
"""Largest |value| of a vehicle signal of each dimension, in SI units (two steering-wheel turns,
540 km/h, 6 g); dimensions without one (angular rates: yaw rate and wheel speed differ 100-fold)
rely on the model's boxes and the physics."""
#: a column spanning less than 1/SMALL_FACTOR of its box, which another unit brings to the box's
#: scale, is named in a warning (a kN column declared in N)
SMALL_FACTOR = 100.0
REFERENCE_FACTOR = 10.0
"""An estimate whose RMS differs from its ``[data.truth]`` reference's by more than this factor
(either way) is named in a warning: its figures (RMS %, NMSE) measure a scale, not an error."""
REFERENCE_UNIT_BAND = (1 / 1.25, 1.25)
"""A ratio of estimate to reference within this band of another unit's factor (and that factor
beyond 2 either way: deg/rad 57.3, km/h to m/s 3.6, g 9.81, kN 1000) names that unit."""
BOX_FACTOR = 2.0
"""A column beyond BOX_FACTOR x the largest |bound| of the model's box for it is a unit mistake
when another unit of its dimension brings it inside the box."""
FILL = 0.05
"""A unit explains a column beyond its box only if, converted, it spans at least this fraction of the box."""
MIN_STD = {"angle": 2e-3, "angular rate": 0.02, "angular acceleration": 0.1, "speed": 0.2,
           "acceleration": 0.2, "force": 50.0, "torque": 5.0, "length": 0.05}
"""[SI] Standard deviation a side of a relation needs for the relation to be judged (below it the
log does not excite the relation: a straight drive says nothing about the steering geometry)."""
MIN_SAMPLES = 50
MIN_CORR = 0.5
"""|correlation| of the two sides below which a ratio is not judged."""
WRONG_CORR = 0.3
STRONG = 5.0
"""Both sides varying STRONG x their MIN_STD and correlated less than WRONG_CORR: a wrong column."""
NOISE_MARGIN = 1.0
"""A side is judged to vary only where the std of its noise-free part is at least NOISE_MARGIN x the
std its sensors' noise gives it (:meth:`Relation.noise`): below that, a low correlation is the noise
(a derivative of a speed with sigma 0.05 m/s at 100 Hz has a noise of 0.7 m/s^2), not a wrong column."""
NOISE_TRUST = 10.0
"""A column's own noise (its high-pass) is taken up to NOISE_TRUST x the sensor noise declared for it:
beyond, its high-frequency content is not that sensor's noise but another signal (a yaw acceleration
mapped to the yaw rate: 0.8 rad/s on the shared log against 8.7e-4 declared), which must not hide
a wrong column. A column without a declared noise is taken at its own."""
GAIN_ROWS = 256
"""Rows per chunk at which the sides' sensitivity to each signal's noise is taken (a mean of squares:
a subsample gives it)."""
IDENTITY_BAND = (1 / 1.4, 1.4)
"""Allowed ratio of an identity of the model (the same quantity twice)."""
STEADY_BAND = (0.75, 1 / 0.75)
"""Allowed ratio of a measured state to its low-slip steady state: real understeer, tyre and
parameter spread stay inside (the Stanford race car on the shared log: 0.81; the validation plants
of the built-in observers: 0.99 to 1.11), a steering ratio applied 1.5 times does not (0.54 and
0.71 on the Stanford car's log and a drive of its own linear model)."""
STEADY_TAU = 2.0
"""[s] The steady state is compared only where the linearized dynamics reach it with time
constants below STEADY_TAU (all eigenvalues left of -1/STEADY_TAU): not near or above an
oversteering model's critical speed, where it is slow, huge or unstable."""
IDENTITY_CLOSE = (1 / 1.1, 1.1)
"""An identity that holds inside IDENTITY_BAND but whose bracket misses this one is a warning: a scale
off by more than 10 % on one side (a speed from wheel speeds with a wrong rolling radius, 25 % off,
passed every check), which the refusing band leaves to real logs' mounting and bank (the shared logs:
0.997 to 1.013 and 0.977 to 1.002)."""
WIDE_BAND = (0.5, 2.0)
"""A failed ratio inside WIDE_BAND that no single column explains is a warning, not an error."""
SMOOTH_S = 0.05
"""[s] half-width of the moving average (and central difference) the relations are judged on."""
SAMPLE_CHUNKS, SAMPLE_ROWS = 16, 64
"""Rows of the log (SAMPLE_ROWS from each of the first SAMPLE_CHUNKS chunks) at which the
exponents of the diagnosis are taken (:func:`exponents`)."""


# --- streaming statistics -----------------------------------------------------------------------

@dataclass
class Moments:
    """Means and co-moments of (x, y) pairs, merged chunk by chunk (Chan et al. 1979)."""

    n: int = 0
    mx: float = 0.0
    my: float = 0.0
    cxx: float = 0.0
    cyy: float = 0.0
    cxy: float = 0.0

    def add(self, x: np.ndarray, y: np.ndarray) -> None:
        keep = np.isfinite(x) & np.isfinite(y)
        if not keep.all():
            x, y = x[keep], y[keep]
        m = x.size
        if not m:
            return
        mx, my = float(x.mean()), float(y.mean())
        xc, yc = x - mx, y - my
        # np.sum of products, not a BLAS dot: a threaded BLAS stalls on a busy machine
        cxx, cyy, cxy = float(np.sum(xc * xc)), float(np.sum(yc * yc)), float(np.sum(xc * yc))
        n = self.n + m
        dx, dy = mx - self.mx, my - self.my
        w = self.n * m / n
        self.cxx += cxx + dx * dx * w
        self.cyy += cyy + dy * dy * w
        self.cxy += cxy + dx * dy * w
        self.mx += dx * m / n
        self.my += dy * m / n
        self.n = n

    @property
    def std_x(self) -> float:
        return math.sqrt(self.cxx / self.n) if self.n else 0.0

    @property
    def std_y(self) -> float:
        return math.sqrt(self.cyy / self.n) if self.n else 0.0

    @property
    def corr(self) -> float:
        den = math.sqrt(self.cxx * self.cyy)
        return self.cxy / den if den > 0 else 0.0

    def bracket(self) -> tuple:
        """(k1, lo, hi): the direct slope cov/var(x) and the bracket [min, max] of it and the reverse
        slope var(y)/cov (with errors in both variables the true ratio lies between the two)."""
        k1, k2 = self.cxy / self.cxx, self.cyy / self.cxy
        return k1, min(k1, k2), max(k1, k2)


def meets(lo: float, hi: float, band) -> bool:
    a, b = min(band), max(band)
    return lo <= b and a <= hi


def box(x: np.ndarray, h: int) -> np.ndarray:
    """Centered moving average over 2h+1 samples ('valid' part)."""
    return np.convolve(x, np.full(2 * h + 1, 1.0 / (2 * h + 1)), mode="valid") if h else x


def ddt(x: np.ndarray, t: np.ndarray, h: int) -> np.ndarray:
    """Central difference over +-h samples (aligned with ``box(., h)``)."""
    h = max(h, 1)
    return (x[2 * h:] - x[:-2 * h]) / (t[2 * h:] - t[:-2 * h])


class Window:
    """Chunks joined by their last ``2 h`` samples, so that a centered window over +-h sees the
    same samples whatever the chunking: every center of the log is evaluated exactly once."""

    def __init__(self, h: int):
        self.h, self.tail = max(int(h), 1), None

    def join(self, cols: dict) -> dict | None:
        """The chunk with the previous tail in front, or None while shorter than 2h + 1."""
        if self.tail is not None:
            cols = {k: np.concatenate([self.tail[k], v]) for k, v in cols.items()}
        n = len(next(iter(cols.values())))
        self.tail = {k: v[-2 * self.h:] for k, v in cols.items()}
        return cols if n > 2 * self.h else None


# --- relations ------------------------------------------------------------------------------------

@dataclass(eq=False)
class Relation:
    """``y ~ k x`` with k expected in ``band``, accumulated over the log.

    ``sides(a)`` maps the averaged signals (``a[NAME]``) and their derivatives (``a["d/dt NAME"]``)
    of a window to the two sides; ``inputs`` are the signals it reads.
    """

    what: str
    lhs: str                       # the signal of the y side (the column a message names first)
    inputs: tuple
    sides: object
    band: tuple
    min_std: float
    kind: str                      # "identity", "kinematic", "steady state"
    moments: Moments = field(default_factory=Moments)
    exponents: dict = field(default_factory=dict)     # signal -> exponent of k in its scale (None: not homogeneous)
    derivatives: tuple = ()                            # signals whose derivative a side reads
    derived: tuple = ()                                # (name, function, keys) of derived signals it reads
    # key (a signal, or "d/dt NAME") -> [sum dy^2, sum dx^2, sum dx dy] of the sides' sensitivities to it, and rows
    gains: dict = field(default_factory=dict)
    gain_rows: int = 0
    key_noise: dict = field(default_factory=dict)      # key -> variance of its noise as the sides read it (finish)

    def evaluate(self, a: dict):
        """The two sides on averaged signals ``a`` whose derived signals are (re)computed here
        (for points scaled by a correction; :meth:`feed` gets them from :class:`LogChecks`)."""
        return self.sides(complete(a, self.derived))

    def feed(self, a: dict) -> None:
        y, x = self.sides(a)
        y, x = np.asarray(y, dtype=float).ravel(), np.asarray(x, dtype=float).ravel()
        self.moments.add(x, y)
        self._sensitivities(a, max(x.size, y.size))

    def _sensitivities(self, a: dict, m: int) -> None:
        """Accumulate, on up to GAIN_ROWS rows of the chunk, the squared sensitivities of the two sides
        to each signal (and derivative) they read: the noise of a signal reaches a side through them."""
        keys = [k for s in self.inputs for k in (s, f"d/dt {s}") if k in a]
        if not keys or m == 0:
            return
        pick = np.unique(np.linspace(0, m - 1, min(GAIN_ROWS, m)).astype(int))
        rows = {k: (np.asarray(v, dtype=float)[pick] if np.ndim(v) and np.size(v) == m else v) for k, v in a.items()}
        found = {}
        with np.errstate(all="ignore"):
            for k in keys:
                v = np.asarray(rows[k], dtype=float)
                step = 1e-6 * max(float(np.sqrt(np.nanmean(v * v))) if v.size else 0.0, 1e-6)
                hi, lo = dict(rows), dict(rows)
                hi[k], lo[k] = v + step, v - step
                (y1, x1), (y0, x0) = self.evaluate(hi), self.evaluate(lo)
                shape = (pick.size,)            # a side that does not vary with the rows is broadcast to them
                gy = np.broadcast_to(np.asarray(y1, dtype=float) - np.asarray(y0, dtype=float), shape)
                gx = np.broadcast_to(np.asarray(x1, dtype=float) - np.asarray(x0, dtype=float), shape)
                found[k] = (gy / (2 * step), gx / (2 * step))
        ok = np.logical_and.reduce([np.isfinite(g) for pair in found.values() for g in pair])
        n = int(np.count_nonzero(ok))
        if not n:
            return
        for k, (gy, gx) in found.items():
            gy, gx = gy[ok], gx[ok]
            acc = self.gains.setdefault(k, np.zeros(3))
            acc += (float(np.sum(gy * gy)), float(np.sum(gx * gx)), float(np.sum(gx * gy)))
        self.gain_rows += n

    def noise(self) -> tuple:
        """(var y, var x, cov xy): the variance the sensors' noise gives each side (per sample), from
        the sides' mean squared sensitivities and each key's noise variance (:attr:`key_noise`)."""
        if not self.gain_rows:
            return 0.0, 0.0, 0.0
        out = np.zeros(3)
        for k, acc in self.gains.items():
            out += acc / self.gain_rows * self.key_noise.get(k, 0.0)
        return float(out[0]), float(out[1]), float(out[2])

    def _signal(self) -> tuple:
        """(std y, std x, correlation) of the sides' noise-free parts: the moments less the noise's
        (the correlation is the measured one where no noise is known)."""
        m = self.moments
        vy, vx, cxy = self.noise()
        sy2, sx2 = m.cyy / m.n - vy, m.cxx / m.n - vx
        sy, sx = math.sqrt(max(sy2, 0.0)), math.sqrt(max(sx2, 0.0))
        if not (vy or vx or cxy):
            return sy, sx, m.corr
        if sy2 <= 0 or sx2 <= 0:
            return sy, sx, 0.0
        return sy, sx, max(-1.0, min(1.0, (m.cxy / m.n - cxy) / math.sqrt(sx2 * sy2)))

    def verdict(self) -> str:
        """'ok', 'ratio' (the bracket misses the band), 'uncorrelated' (both sides vary strongly
        and do not follow each other), 'weak' (a weak correlation under strong variation), or
        'not judged' (the log does not excite the relation, or its sensors' noise hides it).

        Strong variation is of the noise-free part of each side: STRONG x ``min_std`` and at least
        NOISE_MARGIN x the noise the side carries; the correlation judged is then the one of the
        noise-free parts (the moments less the noise's, :meth:`noise`). The ratio's bracket is the
        measured one, which holds the true ratio with noise on both sides."""
        m = self.moments
        # one side varying is enough: a unit mistake may shrink the other below min_std
        if m.n < MIN_SAMPLES or not (max(m.std_x, m.std_y) >= self.min_std and m.cxx > 0 and m.cyy > 0
                                     and m.cxy != 0):
            return "not judged"
        if abs(m.corr) < MIN_CORR:
            sy, sx, corr = self._signal()
            vy, vx, _ = self.noise()
            strong = all(sig >= STRONG * self.min_std and sig >= NOISE_MARGIN * math.sqrt(var) and sig > 0
                         for sig, var in ((sx, vx), (sy, vy)))
            if not strong:
                return "not judged"
            if abs(corr) < MIN_CORR:
                return "uncorrelated" if abs(corr) < WRONG_CORR else "weak"
        _, lo, hi = m.bracket()
        return "ok" if meets(lo, hi, self.band) else "ratio"

    def summary(self) -> dict:
        m, v = self.moments, self.verdict()
        row = {"check": self.what, "kind": self.kind, "signals": list(self.inputs), "verdict": v,
               "samples": m.n, "band": list(self.band)}
        if m.n and m.cxx > 0 and m.cxy != 0:
            k1, lo, hi = m.bracket()
            row.update(ratio=k1, bracket=[lo, hi], correlation=m.corr)
            vy, vx, _ = self.noise()
            if vy or vx:
                sy, sx, corr = self._signal()
                row.update(noise_std=[math.sqrt(vy), math.sqrt(vx)], signal_std=[sy, sx],
                           noise_free_correlation=corr)
        return row


# --- the model's relations ----------------------------------------------------------------------

@dataclass(frozen=True)
class Column:
    """Where an observer input comes from: its column and declared unit, for the messages."""

    column: str
    unit: str | None               # the unit declared for the column (None: the model's)
    model_unit: str | None
    scale: float = 1.0
    # "map": [data.inputs] (unit/scale can be fixed there); "format": the shared format; "file": the log's
    # own unit (an MDF channel's, a Parquet field's metadata), checked against the map's and the model's
    declared_by: str = "map"
    table: str = "data.inputs"     # the observer file's table that maps it ([data.truth] for a reference)

    def describe(self, signal: str) -> str:
        unit = self.unit or self.model_unit or "no unit"
        how = {"map": "declared", "file": "the file's unit"}.get(self.declared_by, "the shared format's unit")
        scale = f", scale {self.scale:g}" if self.scale != 1.0 else ""
        what = f"reference of {signal.removeprefix('truth:')}" if signal.startswith("truth:") else signal
        return f"column {self.column!r} ({what}, {how} {unit}{scale})"


def _dimension(unit: str | None) -> str | None:
    u = normalize_unit(unit) if unit else None
    return UNITS[u][0] if u in UNITS else None


def _sstr(e) -> str:
    return sp.sstr(e).replace("**", "^")


def _times(c) -> str:
    """``c*`` for a coefficient in a relation's text (nothing for 1)."""
    return "" if c == 1 else f"{_sstr(c)}*"


def _derivative_symbol(name: str) -> sp.Symbol:
    return sp.Symbol(f"d/dt {name}")


def _side_function(expr):
    """A numpy function of the window dict ``a`` for a sympy expression in the signals (and
    their derivative symbols)."""
    symbols = sorted(expr.free_symbols, key=str)
    fn = sp.lambdify(symbols, expr, "numpy")
    keys = [str(s) for s in symbols]
    return (lambda a: fn(*(a[k] for k in keys))), keys


def _opaque(exprs, hidden) -> tuple:
    """``exprs`` with each largest part that holds a hidden signal and is not built by +, * and
    powers (a tyre law's Min/Max or Piecewise, an atan of the slip) replaced by a symbol of its
    own, the same symbol in every expression; and those symbols."""
    hidden, found = set(hidden), {}

    def walk(e):
        if not (e.free_symbols & hidden) or e.is_Symbol:
            return
        if e.is_Add or e.is_Mul or (e.is_Pow and e.exp.is_number):
            for a in e.args:
                walk(a)
        elif e not in found:
            found[e] = sp.Dummy(f"opaque{len(found)}")
    for e in exprs:
        walk(e)
    return [e.xreplace(found) for e in exprs], list(found.values())


def _identity(h, f, hidden, is_measured):
    """(i, c, g) with ``h = c f[i] + g``, c and g free of the ``hidden`` signals, or None."""
    def hides(e) -> bool:
        return any(e.has(v) for v in hidden)

    for i, fi in enumerate(f):
        v0 = next((v for v in hidden if fi.has(v) and sp.diff(fi, v) != 0), None)
        if v0 is None:
            continue
        c = sp.simplify(sp.diff(h, v0) / sp.diff(fi, v0))
        if c == 0 or hides(c) or not is_measured(c):
            continue
        g = sp.simplify(sp.expand(h - c * fi))
        if any(sp.simplify(sp.diff(g, v)) != 0 for v in hidden if g.has(v)) or hides(g):
            continue
        return i, c, g
    return None


def derive(model, params, input_names) -> list:
    """The relations between measured signals that the model's equations give (see the module
    docstring): output identities, kinematic identities and low-slip steady states, as
    :class:`Relation` objects (not yet fed). ``input_names`` are the observer's inputs: known
    inputs, measured outputs ``y_NAME`` and scheduling signals."""
    from ..model import parameter_substitution
    values = {k: sp.Float(v) for k, v in parameter_substitution(model, params).items()}
    names = set(input_names)
    signal = {}                                   # measured name -> its symbol in the model
    for u in model.known_inputs:
        if str(u) in names:
            signal[str(u)] = u
    for g in model.scheduling:
        if g.derived is None and str(g.symbol) in names:
            signal[str(g.symbol)] = g.symbol
    for out, _ in model.outputs:
        if f"y_{out}" in names:
            signal[f"y_{out}"] = sp.Symbol(f"y_{out}")
    measured = set(signal.values())
    derived = {}
    for g in model.scheduling:
        if g.derived is not None and sp.sympify(g.derived).free_symbols <= measured | set(model.parameters):
            derived[g.symbol] = sp.sympify(g.derived)
    for w in model.derived_inputs:
        if sp.sympify(w.expr).free_symbols <= measured | set(model.parameters):
            derived[w.symbol] = sp.sympify(w.expr)
    measured_state = {}
    for out, expr in model.outputs:
        e = sp.sympify(expr)
        if e in model.states and f"y_{out}" in names:
            measured_state[e] = sp.Symbol(f"y_{out}")
    hidden = ([x for x in model.states if x not in measured_state] + list(model.unknown_inputs)
              + [u for u in model.known_inputs if str(u) not in names]
              + [g.symbol for g in model.scheduling if g.derived is None and str(g.symbol) not in names]
              + [g.symbol for g in model.scheduling if g.derived is not None and g.symbol not in derived])
    unmeasured = [x for x in model.states if x not in measured_state]
    with sp.evaluate(False):                      # a Min/Max rebuilt evaluated runs sympy's simplifier
        f = [sp.sympify(e).xreplace(measured_state) for e in model.dynamics]
    allowed = measured | set(derived) | set(model.parameters)

    def hides(e) -> bool:
        return any(e.has(v) for v in hidden)

    def numeric(e):
        """The expression in measured and derived signals, parameters substituted, unevaluated: it is
        only evaluated numerically (lambdify), and sympy's re-evaluation of a Min/Max with numbers put
        in runs its general simplifier (seconds per tyre law, on every validate)."""
        with sp.evaluate(False):
            return sp.sympify(e).xreplace(values)

    functions = []
    for sym, expr in derived.items():
        e = sp.sympify(expr).xreplace(values)
        keys = sorted(e.free_symbols, key=str)
        functions.append((str(sym), sp.lambdify(keys, e, "numpy"), tuple(str(k) for k in keys)))
    functions = tuple(functions)

    points = complete(_points(model, params, list(signal)), functions)
    relations = []
    is_measured = lambda e: e.free_symbols <= allowed                        # noqa: E731

    # output identities: y = c dx/dt + g(measured)
    for out, expr in model.outputs:
        y = sp.Symbol(f"y_{out}")
        with sp.evaluate(False):                  # as the dynamics above: no Min/Max re-evaluated
            h = sp.sympify(expr).xreplace(measured_state)
        if y not in measured or h in measured_state.values():
            continue
        if not hides(h):
            if h.free_symbols & (measured | set(derived)) and is_measured(h):
                relations.append(_relation(points, functions, f"{y} = {_sstr(h)} (output {out} of the model)",
                                           str(y), y, numeric(h), "identity", IDENTITY_BAND, model))
            continue
        # first with the tyre laws as opaque symbols (exact where the output and the dynamics share
        # them, as a_y and dv_y/dt share the axle forces: no derivative of a saturation), then as written
        (h_o, *f_o), opaque = _opaque([h, *f], hidden)
        found = _identity(h_o, f_o, [*hidden, *opaque], is_measured) if opaque else None
        found = found or _identity(h, f, hidden, is_measured)
        if found is not None:
            i, c, g = found
            x = model.states[i]
            if x in measured_state:               # exact: y - c d(y_x)/dt = g
                dx = _derivative_symbol(str(measured_state[x]))
                lhs = y - c * dx
                text = f"{y} = {_times(c)}d{x}/dt + {_sstr(g)} (output {out} and d{x}/dt of the model)"
            else:
                lhs = y
                text = (f"{y} = {_times(c)}d{x}/dt + {_sstr(g)} (output {out} and d{x}/dt of the model; "
                        f"{x} unmeasured, its derivative averages out)")
            relations.append(_relation(points, functions, text, str(y), numeric(lhs), numeric(g), "identity",
                                       IDENTITY_BAND, model))

    # kinematic identities: d(y_x)/dt = f_x(measured)
    chained = set()
    for x, ysym in measured_state.items():
        fx = f[model.states.index(x)]
        if hides(fx) or not (fx.free_symbols & (measured | set(derived))) or not is_measured(fx):
            continue
        chained |= {s for s in fx.free_symbols if s in measured_state.values()}
        relations.append(_relation(points, functions, f"d{ysym}/dt = {_sstr(fx)} (d{x}/dt of the model)",
                                   str(ysym), _derivative_symbol(str(ysym)), numeric(fx), "kinematic", IDENTITY_BAND,
                                   model))

    # steady state at low slip: measured state x against dx/dt = 0 with the unmeasured states
    for x, ysym in measured_state.items():
        if ysym in chained:                       # a derivative of a measured state: 0 in steady state
            continue
        unknowns = unmeasured + [x]
        # sp.S.Zero, not 0: xreplace returns the replacement itself when the whole equation is one
        # of the replaced symbols (d roll/dt = roll_rate), and a Python int has no .has
        # unevaluated (numeric() keeps them so): an evaluated Min/Max with zeros put in runs sympy's
        # simplifier; a hidden signal left in only by that is looked at evaluated
        zero_ui = {d: sp.S.Zero for d in model.unknown_inputs}
        other = {s: y for s, y in measured_state.items() if s != x}
        with sp.evaluate(False):
            eqs = [sp.sympify(model.dynamics[model.states.index(s)]).xreplace(zero_ui).xreplace(other)
                   for s in unknowns]
            at_zero = [e.xreplace({s: sp.S.Zero for s in unknowns}) for e in eqs]
        if any((hides(z) and hides(sp.sympify(e).xreplace({s: sp.S.Zero for s in unknowns}).doit()))
               or not (e.free_symbols - set(unknowns)) <= allowed for e, z in zip(eqs, at_zero)):
            continue
        pred = _SteadyState([numeric(e) for e in eqs], unknowns, len(unknowns) - 1,
                            {g.symbol for g in model.scheduling} | set(derived))
        if not pred.informative(points):
            continue
        zero = [str(s) for s in unmeasured]
        uis = [str(d) for d in model.unknown_inputs]
        text = (f"{ysym} against its low-slip steady state (d/dt of {', '.join(str(s) for s in unknowns)} = 0"
                + (f", linearized at {', '.join(zero)} = 0" if zero else "")
                + (f", unknown inputs {', '.join(uis)} = 0" if uis else "") + f"; model {model.name})")
        relations.append(_relation(points, functions, text, str(ysym), ysym, pred, "steady state", STEADY_BAND,
                                   model))
    return relations


def complete(a: dict, functions) -> dict:
    """``a`` with the derived signals (name, function, keys) computed from it."""
    if not functions:
        return a
    a = dict(a)
    with np.errstate(all="ignore"):
        for name, fn, keys in functions:
            a[name] = np.asarray(fn(*(a[k] for k in keys)), dtype=float)
    return a


def _attracts(J: np.ndarray, rate: float) -> np.ndarray:
    """Per matrix, whether every eigenvalue has real part < -rate (J + rate I Hurwitz): by trace
    and determinant up to 2 x 2, by the eigenvalues beyond."""
    k = J.shape[1]
    S = J + rate * np.eye(k)
    if k == 1:
        return S[:, 0, 0] < 0
    if k == 2:
        return (S[:, 0, 0] + S[:, 1, 1] < 0) & (S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] * S[:, 1, 0] > 0)
    return np.linalg.eigvals(J).real.max(axis=1) < -rate


class _SteadyState:
    """Per sample, the target (last unknown) of the steady state ``F(u, w) = 0`` linearized at
    ``u = 0, w = 0``: ``J_u u = -(F(0, 0) + J_w w)``, u the unknowns, w the measured signals that
    are not scheduling signals (known inputs, other measured states), the scheduling signals at
    their measured values. Derivatives by central differences: any model differentiable at zero
    slip, a tyre law with a saturation included, gives its low-slip (linear tyre) steady state."""

    EPS = 1e-6

    def __init__(self, eqs, unknowns, index: int, scheduling):
        self.index, self.k = index, len(unknowns)
        syms = sorted(set().union(*(e.free_symbols for e in eqs)) - set(unknowns), key=str)
        self.keys = [str(s) for s in syms]
        self.linear = [i for i, s in enumerate(syms) if s not in scheduling]
        self.f = [sp.lambdify([*unknowns, *syms], e, "numpy") for e in eqs]

    def _eval(self, u, args, n):
        return np.column_stack([np.broadcast_to(np.asarray(f(*u, *args), dtype=float), (n,)) for f in self.f])

    def __call__(self, a: dict) -> np.ndarray:
        measured = [np.asarray(a[k], dtype=float) for k in self.keys]
        n = max((x.size for x in measured), default=1)
        zero = np.zeros(n)
        u0 = [zero] * self.k
        args = [zero if i in self.linear else x for i, x in enumerate(measured)]
        e = self.EPS
        with np.errstate(all="ignore"):
            rhs = self._eval(u0, args, n)
            J = np.empty((n, self.k, self.k))
            for j in range(self.k):
                plus, minus = list(u0), list(u0)
                plus[j], minus[j] = np.full(n, e), np.full(n, -e)
                J[:, :, j] = (self._eval(plus, args, n) - self._eval(minus, args, n)) / (2 * e)
            for i in self.linear:
                plus, minus = list(args), list(args)
                plus[i], minus[i] = np.full(n, e), np.full(n, -e)
                rhs += (self._eval(u0, plus, n) - self._eval(u0, minus, n)) / (2 * e) * measured[i][:, None]
        out = np.full(n, np.nan)
        ok = np.isfinite(J).all(axis=(1, 2)) & np.isfinite(rhs).all(axis=1)
        if ok.any():                # a steady state only where it attracts within STEADY_TAU
            ok[ok] = _attracts(J[ok], 1.0 / STEADY_TAU)
        if ok.any():
            out[ok] = np.linalg.solve(J[ok], -rhs[ok][..., None])[:, self.index, 0]
        return out

    def informative(self, points: dict) -> bool:
        """Whether the prediction is defined somewhere on ``points`` (near zero slip across the
        scheduling box) and varies there: a singular system (the target's own equation free of
        it) or a steady state that is zero whatever the inputs (no known input drives it) says
        nothing."""
        p = self(points)
        p = p[np.isfinite(p)]
        return bool(p.size >= 2 and np.ptp(p) > 1e-12 * np.abs(p).max())


def _points(model, params, names, n: int = 16) -> dict:
    """Random operating points near zero slip: scheduling signals across their box, every other
    signal (and derivative) a small value of either sign."""
    rng = np.random.default_rng(7)
    out = {}
    for k in names:
        box_ = params.scheduling.get(k)
        if box_ is not None and box_.lower is not None and box_.upper is not None:
            out[k] = rng.uniform(box_.lower, box_.upper, n)
        else:
            out[k] = rng.uniform(0.01, 0.1, n) * rng.choice([-1.0, 1.0], n)
        out[f"d/dt {k}"] = rng.uniform(0.01, 0.1, n) * rng.choice([-1.0, 1.0], n)
    return out


def _relation(points, functions, what, lhs_name, lhs, rhs, kind, band, model) -> Relation:
    """A Relation of sympy sides ``lhs ~ rhs`` (rhs may be a _SteadyState)."""
    fy, ky = _side_function(sp.sympify(lhs))
    fx, kx = (rhs, rhs.keys) if isinstance(rhs, _SteadyState) else _side_function(sp.sympify(rhs))
    keys = {*ky, *kx}
    used = tuple(f for f in functions if f[0] in keys)
    keys = (keys - {f[0] for f in used}).union(*(f[2] for f in used))
    inputs = tuple(sorted({k[len("d/dt "):] if k.startswith("d/dt ") else k for k in keys}))
    derivatives = tuple(sorted(k[len("d/dt "):] for k in keys if k.startswith("d/dt ")))
    unit = (model.units or {}).get(lhs_name[2:] if lhs_name.startswith("y_") else lhs_name)
    min_std = MIN_STD.get(_dimension(unit), 0.0)
    if kind == "kinematic":             # the y side is a derivative: its dimension is the rate's
        min_std = 0.0
    rel = Relation(what, lhs_name, inputs, lambda a: (fy(a), fx(a)), band, min_std, kind, derivatives=derivatives,
                   derived=used)
    rel.exponents = exponents(rel, points)
    return rel


def exponents(rel: Relation, points: dict) -> dict:
    """For each signal s: e with k(c s) = c^e k(s) for a scale c of s (and of its derivative), on
    ``points`` (the log's own samples when known); None where not homogeneous (s inside a
    saturation, or added to another term)."""
    def ratio(a):
        y, x = rel.evaluate(a)
        y, x = np.broadcast_arrays(np.asarray(y, dtype=float), np.asarray(x, dtype=float))
        return y / x

    with np.errstate(all="ignore"):
        k0 = ratio(points)
        out = {}
        for s in rel.inputs:
            scaled = dict(points)
            for key in (s, f"d/dt {s}"):
                if key in scaled:
                    scaled[key] = points[key] * 2.0
            q = ratio(scaled) / k0
            q = q[np.isfinite(q)]
            out[s] = None if not q.size else next(
                (e for e in (1, -1, 0) if np.allclose(q, 2.0 ** e, rtol=1e-6)), None)
    return out


# --- the checks of one log ----------------------------------------------------------------------

@dataclass
class _Range:
    lo: float = math.inf
    hi: float = -math.inf
    beyond: int = 0


class LogChecks:
    """The checks of one log, fed chunk by chunk in the model's units.

    Parameters
    ----------
    source : str or Path
        The log (for the messages).
    model, params :
        The observer's model definition and parameter set.
    input_names : sequence of str
        The observer's inputs (the signals fed).
    columns : mapping of str to Column
        Where each input comes from.
    sample_time : float
        The log's period [s] (the averaging window).
    truth : mapping of str to Column, optional
        Where each estimate's reference comes from (``[data.truth]``): checked for its unit like an
        input (:meth:`feed_truth`), in no physical relation.
    noise : mapping of str to float, optional
        The declared standard deviation of each input's sensor noise, in the model's unit (the
        observer file's ``[precision] noise``, else the family's validation noise). Each input's
        noise is the larger of it and the log's own (:meth:`measured_noise`, a high-pass of the
        column); the physics relations are judged on the sides' noise-free parts
        (:meth:`Relation.verdict`).
    physics_checks : str
        "refuse" (default): a failed physics relation is a DatasetError; "warn" (the observer file's
        ``[data] physics_checks``): the same text is a warning in the report, marked as overridden.
    """

    def __init__(self, source, model, params, input_names, columns: dict, sample_time: float, truth=None,
                 noise=None, physics_checks: str = "refuse"):
        self.source, self.model, self.params = source, model, params
        self.sample_time, self.declared_noise = float(sample_time), dict(noise or {})
        self.physics_checks = physics_checks
        self.second = {}             # input -> [sum of squared second differences, count]: the log's own noise
        self.columns = dict(columns)
        self.names = [n for n in input_names if n in self.columns]
        self.truth = [f"truth:{n}" for n in (truth or {})]
        self.columns.update({f"truth:{n}": c for n, c in (truth or {}).items()})
        self.h = max(1, int(round(SMOOTH_S / sample_time)))
        self.relations = derive(model, params, input_names)
        self.window = Window(self.h)
        self.ranges = {n: _Range() for n in (*self.names, *self.truth)}
        self.derivatives = {s for r in self.relations for s in r.derivatives}
        self.functions = tuple({f[0]: f for r in self.relations for f in r.derived}.values())
        self.sample = []             # a few averaged rows of the log: the points the exponents are taken at

    def box_of(self, name: str):
        """The model's (lo, hi) for an input: scheduling box, [state_bounds] (of the input or of the
        state an output ``y_NAME`` measures), else the excitation's [inputs] range."""
        p = self.params
        if name in p.scheduling:
            b = p.scheduling[name]
            return (b.lower, b.upper) if b.lower is not None and b.upper is not None else None
        base = name[2:] if name.startswith("y_") else name
        out = dict(self.model.outputs).get(base) if name.startswith("y_") else None
        if out is not None and str(out) in p.state_bounds:
            return tuple(p.state_bounds[str(out)])
        if name in p.state_bounds:          # the set the design certifies, before the excitation's range
            return tuple(p.state_bounds[name])
        if name in p.inputs:
            return p.inputs[name]["min"], p.inputs[name]["max"]
        return None

    def _extend(self, n: str, a: np.ndarray) -> None:
        r = self.ranges[n]
        r.lo, r.hi = min(r.lo, float(a.min())), max(r.hi, float(a.max()))
        limit = PLAUSIBLE.get(_dimension(self.columns[n].model_unit))
        if limit is not None:
            r.beyond += int(np.count_nonzero(np.abs(a) > limit))

    def feed_truth(self, values: dict) -> None:
        """One chunk of the references: ``values[ESTIMATE]`` in the model's units."""
        for n, a in values.items():
            self._extend(f"truth:{n}", np.asarray(a, dtype=float))

    def feed(self, t: np.ndarray, values: dict) -> None:
        """One chunk: ``t`` [s] and ``values[INPUT]`` in the model's units."""
        for n in self.names:
            self._extend(n, values[n])
        if not self.relations:
            return
        w = self.window.join({"t": np.asarray(t, dtype=float), **{n: values[n] for n in self.names}})
        if w is None:
            return
        h = self.h
        self._high_pass(w, h)
        a = {n: box(w[n], h) for n in self.names}
        for n in self.derivatives:
            a[f"d/dt {n}"] = ddt(w[n], w["t"], h)
        a = complete(a, self.functions)
        for rel in self.relations:
            with np.errstate(all="ignore"):
                rel.feed(a)
        if len(self.sample) < SAMPLE_CHUNKS:
            m = len(next(iter(a.values())))
            pick = np.linspace(0, m - 1, min(SAMPLE_ROWS, m)).astype(int)
            self.sample.append({k: np.asarray(v)[pick] for k, v in a.items()})

    def _high_pass(self, w: dict, h: int) -> None:
        """Second differences x[k+1] - 2 x[k] + x[k-1] at the window's centers (each sample of the log
        once, whatever the chunking): of white noise of std s their mean square is 6 s^2, of a smooth
        signal sampled fast next to nothing."""
        for n in self.names:
            x = np.asarray(w[n], dtype=float)
            d2 = x[h + 1:x.size - h + 1] - 2.0 * x[h:x.size - h] + x[h - 1:x.size - h - 1]
            d2 = d2[np.isfinite(d2)]
            acc = self.second.setdefault(n, [0.0, 0])
            acc[0] += float(np.sum(d2 * d2))
            acc[1] += int(d2.size)

    def measured_noise(self) -> dict:
        """{input: std} of the log's own noise: the high-pass of :meth:`_high_pass` (an upper bound of
        a white noise's std where the signal itself is smooth)."""
        return {n: math.sqrt(acc[0] / (6.0 * acc[1])) for n, acc in self.second.items() if acc[1]}

    def noise(self) -> dict:
        """{input: std} the relations are judged with: the larger of the declared and the measured noise,
        the measured one taken up to NOISE_TRUST x the declared (the measured alone where none is declared)."""
        measured, out = self.measured_noise(), {}
        for n in self.names:
            declared, own = self.declared_noise.get(n, 0.0), measured.get(n, 0.0)
            out[n] = max(declared, min(own, NOISE_TRUST * declared)) if declared > 0 else own
        return out

    def _set_noise(self) -> None:
        """Each relation's key noise: an averaged signal's (std / sqrt(2h + 1)), a central difference's
        (sqrt(2) std / (2 h T_s))."""
        sigma, h = self.noise(), self.h
        for r in self.relations:
            r.key_noise = {}
            for s in r.inputs:
                v = sigma.get(s, 0.0) ** 2
                r.key_noise[s] = v / (2 * h + 1)
                r.key_noise[f"d/dt {s}"] = 2.0 * v / (2 * h * self.sample_time) ** 2

    # --- verdicts ---------------------------------------------------------------------------------

    def finish(self) -> dict:
        """Raise the first failed check (units first, then physics); return the report
        ``{"checks": [...], "warnings": [...]}``. With ``physics_checks = "warn"`` a failed physics
        relation is a warning marked as overridden (and ``overridden`` lists it)."""
        warnings = self._units()
        if self.sample:
            points = {k: np.concatenate([s[k] for s in self.sample]) for k in self.sample[0]}
            for r in self.relations:
                r.exponents = exponents(r, points)
        self._set_noise()
        results = [(r, r.verdict()) for r in self.relations]
        overridden = []
        try:
            warnings += self._physics(results)
        except DatasetError as exc:
            if self.physics_checks != "warn":
                raise
            overridden.append(str(exc))
            warnings.append(f"{exc} [refusal overridden by [data] physics_checks = \"warn\": the estimates below "
                            f"are of a log the physics checks reject]")
        report = {"checks": [r.summary() for r in self.relations], "warnings": warnings,
                  "unchecked_columns": self._unchecked(results),
                  "noise": {n: v for n, v in self.noise().items() if v > 0}}
        if overridden:
            report["overridden"] = overridden
        return report

    def _unchecked(self, results) -> list:
        """The mapped input columns (``[data.inputs]``) no judged physics relation reads with its
        scale: only the range checks saw them, which miss a unit off by a factor under
        :data:`SMALL_FACTOR` inside the box (rad/s declared deg/s); one row each, for the user to
        double-check (``[data.truth]`` columns are compared with their estimates instead)."""
        judged = set()
        for r, verdict in results:
            if verdict != "not judged":
                judged |= {s for s in r.inputs if r.exponents.get(s, 1) != 0}
        rows = []
        for n in self.names:
            col = self.columns[n]
            if n in judged or col.declared_by == "format":
                continue
            involved = any(n in r.inputs for r in self.relations)
            rows.append({"signal": n, "column": col.column, "unit": col.unit or col.model_unit, "table": col.table,
                         "why": "the log does not excite the model's relations that read it" if involved
                         else "no physics relation of the model reads it",
                         "range_checked": self.box_of(n) is not None
                         or PLAUSIBLE.get(_dimension(col.model_unit)) is not None})
        return rows

    def _alternatives(self, n: str):
        """(factor, unit) for each other unit of the column's dimension: the values in the model's
        unit times factor are what the column gives if it is in that unit."""
        col = self.columns[n]
        declared = normalize_unit(col.unit or col.model_unit or "")
        if declared not in UNITS:
            return []
        dim, f0 = UNITS[declared]
        return [(f / f0, u) for u, (d, f) in UNITS.items() if d == dim and u != declared]

    def _units(self) -> list:
        warnings = []
        for n in (*self.names, *self.truth):
            col, r = self.columns[n], self.ranges[n]
            unit_model = col.model_unit or "model units"
            dim = _dimension(col.model_unit)
            limit = PLAUSIBLE.get(dim)
            signal = n.removeprefix("truth:")
            bounds = self.box_of(signal)
            if limit is not None and r.beyond:
                fits = [(f, u) for f, u in self._alternatives(n) if max(abs(r.lo), abs(r.hi)) * f <= limit
                        and (bounds is None or self._inside(r, f, bounds))]
                raise DatasetError(
                    f"{self.source}: {col.describe(n)} spans [{r.lo:.4g}, {r.hi:.4g}] {unit_model} ({r.beyond} "
                    f"sample(s) beyond +-{limit:g} {_si(dim)}), outside the plausible range of {_article(dim)} {dim}"
                    + self._cause(n, fits))
            if bounds is not None:
                big = BOX_FACTOR * max(abs(bounds[0]), abs(bounds[1]))
                if max(abs(r.lo), abs(r.hi)) > big:
                    # a unit explains the excess only if it brings the column inside the box at the box's
                    # scale: any small excursion "fits" as degrees once divided by 57 (a heading drifting
                    # to 0.6 rad in a +-0.3 rad box is a state leaving its box, not a column in degrees)
                    fits = [(f, u) for f, u in self._alternatives(n)
                            if self._inside(r, f, bounds) and abs(r.hi - r.lo) * f >= FILL * (bounds[1] - bounds[0])]
                    if fits:
                        raise DatasetError(
                            f"{self.source}: {col.describe(n)} spans [{r.lo:.4g}, {r.hi:.4g}] {unit_model}, beyond "
                            f"{BOX_FACTOR:g} x the model's box [{bounds[0]:g}, {bounds[1]:g}] for {signal}"
                            + self._cause(n, fits))
                    warnings.append(f"{col.describe(n)} spans [{r.lo:.4g}, {r.hi:.4g}] {unit_model}, beyond "
                                    f"{BOX_FACTOR:g} x the model's box [{bounds[0]:g}, {bounds[1]:g}] for {signal}, and no "
                                    f"other unit brings it inside: check the column and the box")
                elif abs(r.hi - r.lo) * SMALL_FACTOR < bounds[1] - bounds[0]:
                    # the other way round (a kN column declared in N) the values stay inside the box, so
                    # it is only a warning: a log may hardly excite a signal; a unit that brings the
                    # column to the box's scale is named
                    fits = [(f, u) for f, u in self._alternatives(n) if f >= SMALL_FACTOR and self._inside(r, f, bounds)
                            and abs(r.hi - r.lo) * f >= FILL * (bounds[1] - bounds[0])]
                    if fits:
                        f, u = fits[0]
                        warnings.append(f"{col.describe(n)} spans [{r.lo:.4g}, {r.hi:.4g}] {unit_model}, under "
                                        f"1/{SMALL_FACTOR:g} of the model's box [{bounds[0]:g}, {bounds[1]:g}] for {signal}; "
                                        f"in {u} (x {f:.4g}) it would span [{r.lo * f:.4g}, {r.hi * f:.4g}]"
                                        + self._fix(col, f"unit = \"{u}\"", f"convert the column from {u}")
                                        + " if that is its unit")
        return warnings

    def reference_scale(self, name: str, ratio: float | None, after_s: float | None = None) -> str | None:
        """A warning when estimate ``name`` and its ``[data.truth]`` reference differ in scale by a
        unit factor or more than :data:`REFERENCE_FACTOR` (``ratio`` = RMS of the estimate / RMS of
        the reference, :meth:`codegen.validation.streaming.ErrorStats.scale_ratio`); None otherwise."""
        key = f"truth:{name}"
        if ratio is None or key not in self.columns or not ratio > 0:
            return None
        col = self.columns[key]
        lo, hi = REFERENCE_UNIT_BAND
        fits = [(f, u) for f, u in self._alternatives(key)
                if not 0.5 <= f <= 2.0 and lo <= ratio / f <= hi]
        if not fits and 1 / REFERENCE_FACTOR <= ratio <= REFERENCE_FACTOR:
            return None
        where = f" after the first {after_s:g} s" if after_s else ""
        text = (f"{self.source}: [{col.table}] {name}: {col.describe(key)}: the estimate's RMS is {ratio:.4g} x the "
                f"reference's{where}, so the RMS % and NMSE of {name} measure that factor, not the observer's error")
        if fits:
            f, u = min(fits, key=lambda fu: abs(math.log(ratio / fu[0])))
            return text + (f"; the column looks like {u} (x {f:.4g}), not {col.unit or col.model_unit}"
                           + self._fix(col, f"unit = \"{u}\"", f"convert the column from {u}") + " if that is its unit")
        return text + (f"; no unit of its dimension is that factor: check the column, its unit and scale "
                       f"(allowed: a factor within {REFERENCE_FACTOR:g} x either way, or a unit named)")

    @staticmethod
    def _inside(r: _Range, f: float, bounds) -> bool:
        lo, hi = sorted((r.lo * f, r.hi * f))
        margin = 0.1 * (bounds[1] - bounds[0])
        return bounds[0] - margin <= lo and hi <= bounds[1] + margin

    def _cause(self, n: str, fits) -> str:
        col = self.columns[n]
        if not fits:
            return "; no other unit of its dimension explains it: check the column and its unit"
        f, u = fits[0]
        return f"; it looks like {u} (x {f:.4g} gives [{self.ranges[n].lo * f:.4g}, {self.ranges[n].hi * f:.4g}])" \
               + self._fix(col, f"unit = \"{u}\"", f"convert the column from {u}")

    @staticmethod
    def _fix(col: Column, key: str, convert: str) -> str:
        return (f": declare {key} for {col.column!r} in [{col.table}]" if col.declared_by == "map"
                else f": {convert} to {col.model_unit}")

    def _physics(self, results) -> list:
        """Errors and warnings of the relations. An identity is exact physics: its failure is an
        error. A steady state is the model's low-slip approximation: a failure that no unit or
        sign of one column explains may be the model's parameters as well as the log's scale (a
        steering ratio), so it is a warning."""
        warnings = []
        judged = [(r, v) for r, v in results if v in ("ok", "ratio")]
        failed = sorted((r for r, v in results if v == "ratio"), key=lambda r: r.kind == "steady state")
        if failed:
            causes = self._explain(failed, judged)
            rel = failed[0]
            exact = rel.kind != "steady state"
            k1, lo, hi = rel.moments.bracket()
            found = (f"ratio {k1:.4g} (bracket [{lo:.4g}, {hi:.4g}], correlation {rel.moments.corr:.2f}, "
                     f"{rel.moments.n} samples); allowed {rel.band[0]:.3g} to {rel.band[1]:.3g}")
            named = causes[0][0] if causes else rel.lhs
            head = f"{self.source}: {self.columns[named].describe(named)} is inconsistent with {rel.what}: {found}"
            units = [text for _, text, kind in causes if kind in ("unit", "sign")]
            scales = [text for _, text, kind in causes if kind == "scale"]
            cols = ", ".join(self.columns[s].describe(s) for s in rel.inputs if s in self.columns)
            if units:
                raise DatasetError(f"{head}. Likely cause: " + "; or ".join(units))
            if exact and scales:
                raise DatasetError(f"{head}. Likely cause: " + "; or ".join(scales))
            if exact and not meets(lo, hi, WIDE_BAND):
                raise DatasetError(f"{head}; no single unit, sign or scale of one column explains it: check the "
                                   f"units, scales and sign conventions of {cols}")
            if scales:
                warnings.append(f"{head}. Either " + "; or ".join(scales)
                                + "; or the model's low-slip steady-state gain (its parameters) is off")
            else:
                warnings.append(f"{head}; no single column explains it: check the units and scales of {cols}, "
                                f"and the model's parameters")
        wrong = sorted((r for r, v in results if v == "uncorrelated"), key=lambda r: r.kind == "steady state")
        if wrong:
            rel = wrong[0]
            ok_signals = {s for r, v in results if v == "ok" for s in r.inputs}
            # the columns on a side of every uncorrelated relation (scaled with it), not in a relation that holds
            direct = [s for s in rel.inputs if s in self.columns and s not in ok_signals
                      and all(r.exponents.get(s) for r in wrong)]
            suspects = direct or [s for s in rel.inputs if s in self.columns and s not in ok_signals] \
                or [s for s in rel.inputs if s in self.columns]
            m = rel.moments
            vy, vx, _ = rel.noise()
            sy, sx, corr = rel._signal()
            noisy = (f" (without the sensors' noise, std {math.sqrt(vy):.3g} and {math.sqrt(vx):.3g}: correlation "
                     f"{corr:.2f}, std {sy:.3g} and {sx:.3g})") if (vy or vx) else ""
            text = (f"{self.source}: {' or '.join(self.columns[s].describe(s) for s in suspects)} does not follow "
                    f"{rel.what}: correlation {m.corr:.2f} over {m.n} samples while both sides vary (std {m.std_y:.3g} "
                    f"and {m.std_x:.3g}){noisy}; allowed: |correlation| >= {MIN_CORR:g}. Likely cause: a wrong column "
                    f"(e.g. a derivative or another signal mapped to {suspects[0]}): check the column map"
                    + (f" (if it is right: [data] physics_checks = \"warn\" runs the log with this as a warning)"
                       if any(self.columns[c].declared_by != "format" for c in self.names) else ""))
            if rel.kind != "steady state":
                raise DatasetError(text)
            warnings.append(text + ", or the model's low-slip steady state")
        for r, v in results:
            if v == "ok" and r.kind != "steady state":
                k1, lo, hi = r.moments.bracket()
                if not meets(lo, hi, IDENTITY_CLOSE):
                    cols = ", ".join(self.columns[s].describe(s) for s in r.inputs if s in self.columns)
                    warnings.append(f"{self.source}: {r.what} holds with ratio {k1:.4g} (bracket [{lo:.4g}, {hi:.4g}]), "
                                    f"within its allowed {r.band[0]:.3g} to {r.band[1]:.3g} but more than 10 % off 1: "
                                    f"check the scale of {cols} (a speed from wheel speeds with another rolling radius, "
                                    f"an accelerometer's gain or mounting); the estimates inherit it")
            if v == "weak":
                m = r.moments
                warnings.append(f"{', '.join(self.columns[s].describe(s) for s in r.inputs if s in self.columns)}: "
                                f"{r.what} holds only weakly (correlation {m.corr:.2f} over {m.n} samples while both "
                                f"sides vary): check the columns")
        return warnings

    def _explain(self, failed, judged) -> list:
        """(signal, text, kind) of every single-column correction -- another unit of its
        dimension, the opposite sign ("unit", "sign"), or else one scale ("scale", when only one
        column's scale does it) -- under which every judged relation holds."""
        first = failed[0]
        k1, lo, hi = first.moments.bracket()
        named, scales = [], []
        for s in dict.fromkeys(x for r in failed for x in r.inputs if x in self.columns):
            col = self.columns[s]
            e = first.exponents.get(s)
            cands = [(f, "unit", u) for f, u in self._alternatives(s)] + [(-1.0, "sign", None)]
            if e:
                mid = math.copysign(math.sqrt(abs(lo * hi)), k1)
                cands.append(((math.sqrt(first.band[0] * first.band[1]) / mid) ** (1.0 / e), "scale", None))
            for c, kind, u in cands:
                if (kind == "scale" and c <= 0) or not self._plausible(s, c) or not self._holds(s, c, judged):
                    continue
                gives = f"x {c:.4g} gives ratio {k1 * c ** e:.3g}" if e else f"x {c:.4g} makes every check hold"
                if kind == "unit":
                    named.append((s, f"{col.column!r} is in {u}, not {col.unit or col.model_unit} ({gives})"
                                     + self._fix(col, f"unit = \"{u}\"", f"convert it from {u}"), kind))
                elif kind == "sign":
                    named.append((s, f"{col.column!r} has the opposite sign convention ({gives})"
                                     + self._fix(col, f"scale = {-col.scale:g}", "flip its sign"), kind))
                else:
                    ratio = "a steering ratio" if _dimension(col.model_unit) == "angle" else "a ratio"
                    scales.append((s, f"{col.column!r} is scaled {1 / c:.3g} x too {'large' if c < 1 else 'small'} "
                                      f"({ratio} or scale slip? {gives})"
                                      + self._fix(col, f"scale = {col.scale * c:.4g}", f"rescale it by {c:.4g}"),
                                   kind))
        return named or (scales if len(scales) == 1 else [])

    def _holds(self, s: str, c: float, judged) -> bool:
        """Whether every judged relation holds with signal s multiplied by c: by its exponent where
        the relation is homogeneous in s, else re-evaluated on the sampled rows of the log."""
        for rel, v in judged:
            e = rel.exponents.get(s, 0) if s in rel.inputs else 0
            if e is None:
                lo_hi = self._resampled(rel, s, c)
                if lo_hi is None:           # the correction leaves nothing to judge: not shown to hold
                    return False
                lo, hi = lo_hi
            else:
                _, lo, hi = rel.moments.bracket()
                lo, hi = lo * c ** e, hi * c ** e
            if not meets(lo, hi, rel.band):
                return False
        return True

    def _plausible(self, s: str, c: float) -> bool:
        """Whether the column times c stays within its dimension's plausible range, within
        BOX_FACTOR x its model box, and on the box's side of zero when the box has one sign (a
        speed box [15, 65] m/s takes no negative speeds)."""
        r = self.ranges[s]
        lo, hi = sorted((r.lo * c, r.hi * c))
        limit = PLAUSIBLE.get(_dimension(self.columns[s].model_unit))
        if limit is not None and max(abs(lo), abs(hi)) > limit:
            return False
        bounds = self.box_of(s)
        if bounds is None:
            return True
        reach = BOX_FACTOR * max(abs(bounds[0]), abs(bounds[1]))
        return (max(abs(lo), abs(hi)) <= reach and not (bounds[0] >= 0 and lo < -0.1 * reach)
                and not (bounds[1] <= 0 and hi > 0.1 * reach))

    def _resampled(self, rel: Relation, s: str, c: float):
        """The bracket of ``rel`` on the sampled rows with s (and its derivative) times c, or None."""
        if not self.sample:
            return None
        points = {k: np.concatenate([x[k] for x in self.sample]) for k in self.sample[0]}
        for key in (s, f"d/dt {s}"):
            if key in points:
                points[key] = points[key] * c
        m = Moments()
        with np.errstate(all="ignore"):
            y, x = rel.evaluate(points)
            m.add(*np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float)))
        if m.n < MIN_SAMPLES or m.cxx <= 0 or m.cxy == 0 or abs(m.corr) < MIN_CORR:
            return None
        _, lo, hi = m.bracket()
        return lo, hi


def _si(dim: str) -> str:
    return {"angle": "rad", "speed": "m/s", "acceleration": "m/s^2"}.get(dim, "")


def _article(dim: str) -> str:
    return "an" if dim[:1] in "aeiou" else "a"
