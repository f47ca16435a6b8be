"""Random small valid models of the built-in families: the drawers, and what they draw with.

A seeded numpy generator draws, per family, a model a user could have written (its equations as a
``model.py``, its numbers as a parameter file, an observer file beside them). Each family hands its
drawer in through its own capability (:class:`~codegen.contract.capabilities.RandomModels`:
``draw_random_model``), so :func:`drawers` is every registered family that draws, a family of a user's
included; the acceptance that writes the models into folders and takes them through the user's commands
is a maintainer tool, :mod:`codegen.acceptance.random_models` (the property tests of the C == model check,
``tests/extension/test_random_models.py``, run it).

What is drawn, per family (the structure where the family's theory allows it, plausible numbers
where the family's model is fixed):

* ``linf_uio``: 2-3 states, scheduling on the speed through 1/v_x (and v_x) terms, 1-2 unknown
  inputs each reaching a measured state's equation, 0-1 known input, outputs that are states or
  combinations of states, sometimes an unknown input in an output (a lateral force seen by an
  accelerometer), sometimes a second scheduling signal derived from a measured output, sometimes a
  constant term (a known input of value 1) and sometimes one nonlinearity 1/(v_x + c) written into
  two rows with c differing in the last digit (one premise once merged);
* ``ts_fuzzy_uio``: a speed state v_x measured (its 1/v_x terms are measured premises), 1-2 more
  states, the unknown inputs reaching measured states, sometimes a known input, sometimes a
  saturating (tanh) tyre law in an unmeasured state, sometimes a constant term (the known input of
  value 1);
* ``switched_pi``: 2-3 states, LPV in the speed with 2-3 operating points, one unknown input,
  outputs that are states or combinations, sometimes a known input;
* ``algebraic_uio``: a chain of 2-3 states with the unknown input at its end (relative degree
  1-3), an LPV coefficient in a scheduling signal rho, differentiators of the orders the
  relative degree needs;
* ``interconnected_uio`` and ``nonlinear_tyre_observer`` (whose theory fixes the model): their
  built-in model with every physical parameter dispersed (mass, inertias, lengths, stiffnesses).

and, from a generator of their own (:func:`_kinds_rng`: the rest of a seed's draw unchanged), the kinds
of equations of issue 42 (:data:`KINDS`): an exact constant beside a parameter, terms that are 0 once
simplified (in a row, and as an unknown input's coefficient in an output), a coupling whose
coefficient crosses zero inside the speed box (``linf_uio``, ``switched_pi``, ``ts_fuzzy_uio``), and
a ``[sensor_noise]`` table (those and ``algebraic_uio``).

A design the family refuses is an acceptable outcome only as a typed error (exit 2, one line, no
traceback); :func:`codegen.acceptance.random_models.acceptance` reports how many draws design.
"""
from __future__ import annotations

import re
import textwrap
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: state names (and units) the generic generators draw from: what a vehicle model's states are
STATE_POOL = (("v_y", "m/s"), ("r", "rad/s"), ("phi", "rad"), ("p", "rad/s"), ("psi_L", "rad"), ("y_L", "m"))
#: unknown and known inputs (and units)
UNKNOWN_POOL = ("F_d", "M_d")
#: the unit an unknown input is drawn in: (unit, size of its gain in a state's equation, its range in the
#: excitation scenario); a force in N reaches a rate through ~1/mass, in kN through ~1000/mass
UI_UNITS = {"F_d": (("N", 1e-3, 1000.0), ("kN", 1.0, 1.0)), "M_d": (("N m", 1e-2, 100.0), ("kN m", 10.0, 0.1))}
KNOWN_POOL = (("delta", "rad"), ("T_a", "N m"))


@dataclass(frozen=True)
class RandomModel:
    """One drawn model: the files a user would write, and what was drawn.

    Attributes
    ----------
    family : str
    name : str
        The observer's name: the family and the drawn structure (``linf_3x_2y_1u_1d_dd``).
    structure : dict
        What was drawn (counts of states, outputs, inputs; flags such as ``ui_feedthrough``).
    files : dict
        {file name: text}: ``model.py`` (absent for a built-in model), ``parameters.toml`` and the
        observer file ``NAME.toml``.
    """

    family: str
    name: str
    structure: dict
    files: dict

    def write(self, folder: Path) -> Path:
        """Write the files into ``folder`` (created); returns the observer file's path."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        for fname, text in self.files.items():
            (folder / fname).write_text(text)
        return folder / f"{self.name}.toml"


def _fmt(v: float) -> str:
    return repr(float(v))


def _uniform(rng, lo: float, hi: float, sign: bool = False) -> float:
    v = float(rng.uniform(lo, hi))
    return -v if sign and rng.random() < 0.5 else v


def _speed_box(rng) -> tuple:
    lo = float(np.round(rng.uniform(3.0, 8.0), 1))
    hi = float(np.round(rng.uniform(20.0, 40.0), 1))
    rate = float(np.round(rng.uniform(2.0, 6.0), 1))
    return lo, hi, rate


def _model_py(doc: str, symbols: list, body: str) -> str:
    """The text of a model file: imports, symbols (name, assumptions), the body that defines MODEL."""
    lines = [f'"""{doc}"""', "import sympy as sp", "",
             "from codegen.model import ModelDefinition, SchedulingSignal", ""]
    for name, assume in symbols:
        lines.append(f'{name} = sp.Symbol("{name}"{", " + assume if assume else ""})')
    return "\n".join(lines) + "\n\n" + textwrap.dedent(body).strip() + "\n"


def _params_toml(values: dict, tables: str = "") -> str:
    lines = ["[parameters]"] + [f"{k} = {_fmt(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n\n" + textwrap.dedent(tables).strip() + "\n"


# -- linf_uio ------------------------------------------------------------------------------------------

def _linear_rows(rng, states, entries: dict, values: dict, speed: str, v_terms: bool) -> tuple:
    """Random rows of A(v_x) x = (A0 + A1 / v_x + A2 v_x / 100) x plus each state's input terms
    (``entries``): sympy text per state, every parameter carrying its own sign; values added to
    ``values``. The diagonal of A0 is negative (each state decays on its own); a row has 1/v_x terms
    with probability 0.5, at least one row has them (the model is LPV in the speed). Returns (rows,
    whether a v_x term was drawn)."""
    n = len(states)
    rows, drawn = [], False
    inv_rows = rng.random(n) < 0.5
    inv_rows[rng.integers(n)] = True
    for i, si in enumerate(states):
        terms = []
        for j, sj in enumerate(states):
            if i == j:
                values[f"a_{si}"] = -_uniform(rng, 1.0, 4.0)
                terms.append(f"a_{si} * {sj}")
            elif rng.random() < 0.5:
                values[f"a_{si}_{sj}"] = _uniform(rng, 0.3, 2.0, sign=True)
                terms.append(f"a_{si}_{sj} * {sj}")
            if inv_rows[i] and (i == j or rng.random() < 0.4):
                values[f"b_{si}_{sj}"] = _uniform(rng, 2.0, 15.0, sign=True)
                terms.append(f"b_{si}_{sj} * {sj} / {speed}")
            if v_terms and i != j and rng.random() < 0.3:
                values[f"c_{si}_{sj}"] = _uniform(rng, 0.5, 3.0, sign=True)
                terms.append(f"c_{si}_{sj} * {speed} * {sj} / 100")
                drawn = True
        rows.append(" + ".join(terms + entries.get(si, [])))
    return rows, drawn


def _draw_lpv_core(rng, family: str, max_states: int = 3, allow_feedthrough: bool = True,
                   allow_derived: bool = True, max_unknown: int = 2):
    """The common draw of the LPV families: states, inputs, outputs, their sympy text and numbers."""
    n = int(rng.integers(2, max_states + 1))
    pool = list(STATE_POOL)
    picks = rng.choice(len(pool), size=n, replace=False)
    states = [pool[k] for k in sorted(picks)]
    names = [s for s, _ in states]
    n_d = 1 if n == 2 else int(rng.integers(1, max_unknown + 1))
    scale = {}
    for d in UNKNOWN_POOL[:n_d]:
        unit, gain, half = UI_UNITS[d][int(rng.integers(2))]
        scale[d] = (unit, gain, half)
    unknown = [(d, scale[d][0]) for d in UNKNOWN_POOL[:n_d]]
    n_u = int(rng.integers(0, 2))
    known = [KNOWN_POOL[0]] if n_u else []
    values: dict = {}
    entries: dict = {s: [] for s in names}
    # each unknown input reaches its own state's equation (the state its first output sees)
    ui_states = [names[k] for k in rng.choice(n, size=n_d, replace=False)]
    for (d, _), s in zip(unknown, ui_states):
        k = f"g_{s}_{d}"
        values[k] = _uniform(rng, 0.5, 3.0, sign=True) * scale[d][1]
        entries[s].append(f"{k} * {d}")
        if rng.random() < 0.3:                        # and sometimes another state's
            other = names[int(rng.integers(n))]
            if other != s:
                k = f"g_{other}_{d}"
                values[k] = _uniform(rng, 0.2, 1.0, sign=True) * scale[d][1]
                entries[other].append(f"{k} * {d}")
    for u, _ in known:
        s = names[int(rng.integers(n))]
        k = f"h_{s}_{u}"
        values[k] = _uniform(rng, 0.5, 5.0, sign=True)
        entries[s].append(f"{k} * {u}")
    # outputs: the states the unknown inputs reach (sometimes mixed with another state), then others
    outputs, combos = [], 0
    measured = list(ui_states)
    extra = [s for s in names if s not in measured]
    n_extra = int(rng.integers(0, len(extra) + 1))
    measured += [extra[k] for k in rng.choice(len(extra), size=n_extra, replace=False)] if n_extra else []
    for s in measured:
        expr = s
        if rng.random() < 0.35:
            other = names[int(rng.integers(n))]
            if other != s:
                k = f"c_y_{s}_{other}"
                values[k] = _uniform(rng, 0.2, 1.0, sign=True)
                expr = f"{s} + {k} * {other}"
                combos += 1
        outputs.append((s if expr == s else f"{s}_plus_{other}", expr))
    feedthrough = False
    if allow_feedthrough and rng.random() < 0.25:
        d = unknown[0][0]
        k = f"e_{d}"
        values[k] = _uniform(rng, 0.5, 2.0) * scale[d][1]
        name, expr = outputs[0]
        outputs[0] = (f"{name}_with_{d}", f"{expr} + {k} * {d}")
        feedthrough = True
    derived = allow_derived and rng.random() < 0.3
    return {"n": n, "states": states, "ui_scale": scale, "names": names, "unknown": unknown, "known": known, "values": values,
            "entries": entries, "outputs": outputs, "combos": combos, "feedthrough": feedthrough, "derived": derived}


def _ui_ranges(core) -> str:
    """The ``[inputs]`` rows of the unknown inputs: the excitation scenario's range in their unit."""
    return "".join(f"{d} = {{ min = {-core['ui_scale'][d][2]}, max = {core['ui_scale'][d][2]}, bandwidth = 0.5 }}\n"
                   for d, _ in core["unknown"])


def _signal_units(core) -> dict:
    units = {s: u for s, u in core["states"]}
    units.update({d: u for d, u in core["unknown"]})
    units.update({u: un for u, un in core["known"]})
    return units


def _constant_term(rng, rows: list, names: list, values: dict) -> bool:
    """Add to ``rows`` (in place), with probability 0.4, a constant term ``k0_<state>`` in one row
    (rolling resistance: the design carries it as a known input of value 1), drawn from the second
    child of the seed's sequence (the rest of each draw unchanged; other seeds than the first child's
    of :func:`_constant_and_duplicated_terms`). Returns whether one was drawn."""
    side = np.random.default_rng(rng.bit_generator.seed_seq.spawn(2)[1])
    if side.random() >= 0.4:
        return False
    i = int(side.integers(len(rows)))
    values[f"k0_{names[i]}"] = _uniform(side, 0.05, 0.5, sign=True)
    rows[i] = f"{rows[i]} + k0_{names[i]}"
    return True


def _constant_and_duplicated_terms(rng, rows: list, names: list, values: dict) -> tuple:
    """Add to ``rows`` (in place), each with probability 0.4: a constant term ``k0_<state>`` in one row
    (rolling resistance: the design carries it as a known input of value 1), and one nonlinearity
    ``1/(v_x + c)`` written into two rows with ``c`` differing in the last digit (as ``sp.solve``
    writes one law twice: merged into one premise). Drawn from a child of the seed's sequence, so
    the draws of the rest of the model are those of the seed before these terms existed. Returns
    (constant term drawn, duplicated term drawn)."""
    side = np.random.default_rng(rng.bit_generator.seed_seq.spawn(1)[0])
    constant = bool(side.random() < 0.4)
    if constant:
        i = int(side.integers(len(rows)))
        values[f"k0_{names[i]}"] = _uniform(side, 0.05, 0.5, sign=True)
        rows[i] = f"{rows[i]} + k0_{names[i]}"
    duplicated = bool(side.random() < 0.4)
    if duplicated:
        i, j = (int(k) for k in side.choice(len(rows), size=2, replace=False))
        sj = names[int(side.integers(len(names)))]
        c = float(np.round(side.uniform(0.5, 3.0), 2))
        c_noisy = float(np.nextafter(np.nextafter(c, np.inf), np.inf))      # 2 ulps: the other row's rounding
        for row, k, cc in ((i, f"m_{names[i]}_{sj}", c), (j, f"m_{names[j]}_{sj}", c_noisy)):
            values[k] = _uniform(side, 0.5, 3.0, sign=True)
            rows[row] = f"{rows[row]} + {k} * {sj} / (v_x + {cc!r})"
    return constant, duplicated


#: the levels of the drawn [sensor_noise] per unit (a car's sensors: a gyro, GNSS speed, a steering
#: angle sensor, a camera's lateral offset), multiplied by a drawn factor in 10^[-0.3, 0.5]
NOISE_LEVELS = {"rad/s": 8.7e-4, "m/s": 0.02, "rad": 1e-3, "m": 0.01}
NOISE_SPEED = 0.05            # m/s: the measured scheduling speed (wheel speeds, GNSS)
#: the kinds of equations issue 42 asks the draws to hold (each a key of a draw's ``structure`` where its
#: family takes it): an exact constant beside a parameter, terms that are 0 once simplified, a coefficient
#: whose zero crosses the scheduling box, the sensors' noise declared in ``[sensor_noise]``
KINDS = ("exact_constants", "zero_terms", "zero_crossing", "sensor_noise")
#: the key of the child seed sequence the kinds of issue 42 are drawn from (exact constants, terms that
#: simplify to zero, a coefficient whose zero crosses the scheduling box, sensor noise)
KINDS_KEY = 42


def _kinds_rng(rng, family: str):
    """A generator of its own for the kinds of issue 42: the child (``KINDS_KEY``, crc32 of the family's
    name) of the seed's sequence (so every other draw of a seed is the one it was before these kinds
    existed, and one seed draws other kinds in each family)."""
    ss = rng.bit_generator.seed_seq
    key = (KINDS_KEY, zlib.crc32(family.encode()))
    return np.random.default_rng(np.random.SeedSequence(ss.entropy, spawn_key=tuple(ss.spawn_key) + key))


def _exact_constant(side, rows: list, values: dict) -> str:
    """Rewrite, with probability 0.4, one term ``k * ...`` of a row (a drawn parameter k leading it)
    with an exact constant beside k, its value rescaled so the model's numbers are those drawn:
    ``k / 2 * ...`` (a half track), ``sp.Rational(3, 4) * k * ...`` or ``2 * k * ...``. Returns the
    form written ("" when none)."""
    if side.random() >= 0.4:
        return ""
    terms = [(i, k) for i, row in enumerate(rows) for k in values
             if re.search(rf"(?<![\w.]){k} \* ", row) and not k.startswith(("z_", "t_"))]
    if not terms:
        return ""
    i, k = terms[int(side.integers(len(terms)))]
    form, factor = (("{k} / 2 * ", 2.0), ("sp.Rational(3, 4) * {k} * ", 4.0 / 3.0),
                    ("2 * {k} * ", 0.5))[int(side.integers(3))]
    values[k] = values[k] * factor
    rows[i] = re.sub(rf"(?<![\w.]){k} \* ", form.format(k=k), rows[i], count=1)
    return form.format(k="k").strip(" *")


def _zero_terms(side, rows: list, names: list, values: dict, outputs: list | None, d: str | None) -> str:
    """Add, with probability 0.4, terms that simplify to zero: in a row ``(z_a + z_b) * x - z_a * x -
    z_b * x`` and ``(sin(z_th)^2 + cos(z_th)^2 - 1) * z_c * x / v_x`` (exactly 0, a float residue once the
    parameters are numbers), and where an output list and an unknown input are given, ``(sin(z_th)^2 +
    cos(z_th)^2 - 1) * z_y * d`` in the first output (a feedthrough that is none). Returns where ("")."""
    if side.random() >= 0.4:
        return ""
    i = int(side.integers(len(rows)))
    sj = names[int(side.integers(len(names)))]
    values["z_a"] = _uniform(side, 0.3, 2.0, sign=True)
    values["z_b"] = _uniform(side, 0.3, 2.0, sign=True)
    values["z_th"] = _uniform(side, 0.1, 1.5)
    values["z_c"] = _uniform(side, 2.0, 15.0, sign=True)
    trig = "(sp.sin(z_th) ** 2 + sp.cos(z_th) ** 2 - 1)"
    rows[i] = f"{rows[i]} + (z_a + z_b) * {sj} - z_a * {sj} - z_b * {sj} + {trig} * z_c * {sj} / v_x"
    where = "row"
    if outputs is not None and d is not None:
        values["z_y"] = _uniform(side, 0.5, 2.0)
        name, expr = outputs[0]
        outputs[0] = (name, f"{expr} + {trig} * z_y * {d}")
        where = "row and output"
    return where


def _zero_crossing(side, rows: list, names: list, values: dict, lo: float, hi: float) -> float | None:
    """Add, with probability 0.4, a coupling ``t_c * (v_x - t_v0) * x / 10`` (x another row's state) to one row whose
    coefficient changes sign at t_v0, drawn inside the speed box [lo, hi] (in its middle 60 %).
    Returns t_v0 (None when not drawn)."""
    if side.random() >= 0.4:
        return None
    i, j = (int(k) for k in side.choice(len(rows), size=2, replace=False))
    sj = names[j]                   # a coupling (on the diagonal, it could make the drawn car unstable)
    values["t_c"] = _uniform(side, 0.05, 0.2, sign=True)
    v0 = float(np.round(side.uniform(lo + 0.2 * (hi - lo), hi - 0.2 * (hi - lo)), 2))
    values["t_v0"] = v0
    rows[i] = f"{rows[i]} + t_c * (v_x - t_v0) * {sj} / 10"
    return v0


def _noise_table(side, signals: dict) -> str:
    """With probability 0.6, the parameter file's ``[sensor_noise]`` table of the measured ``signals``
    ({name: unit}): each at the level of its unit (:data:`NOISE_LEVELS`, the speed at
    :data:`NOISE_SPEED`) times a factor drawn in 10^[-0.3, 0.5]; "" when not drawn."""
    if side.random() >= 0.6:
        return ""
    lines = []
    for name, unit in signals.items():
        base = NOISE_SPEED if name == "v_x" else NOISE_LEVELS[unit]
        lines.append(f"{name} = {float(base * 10 ** side.uniform(-0.3, 0.5)):.3g}")
    return "\n[sensor_noise]\n" + "\n".join(lines) + "\n"


def _measured_units(core, speed: bool = True) -> dict:
    """{measured signal: unit} of an LPV draw: its outputs (the unit of the state each starts with),
    its known inputs, and the scheduling speed."""
    units = dict(core["states"])
    out = {name: units[expr.split()[0]] for name, expr in core["outputs"]}
    out.update(dict(core["known"]))
    if speed:
        out["v_x"] = "m/s"
    return out


def draw_linf(rng) -> RandomModel:
    core = _draw_lpv_core(rng, "linf_uio")
    names, values = core["names"], core["values"]
    lo, hi, rate = _speed_box(rng)
    rows, v_terms = _linear_rows(rng, names, core["entries"], values, "v_x", rng.random() < 0.5)
    scheduling = ['SchedulingSignal(v_x, "m/s")']
    tables = f"[scheduling.v_x]\nmin = {lo}\nmax = {hi}\nrate_min = {-rate}\nrate_max = {rate}\n"
    derived_note = ""
    if core["derived"]:
        # a gain scheduled on the measured first output: s = 1 / (1 + (y / k_s)^2), in [s_min, 1]
        y0, expr0 = core["outputs"][0]
        values["k_s"] = _uniform(rng, 0.5, 2.0)
        scheduling.append(f'SchedulingSignal(s, "-", derived=1 / (1 + (sp.Symbol("y_{y0}") / k_s) ** 2))')
        tables += "\n[scheduling.s]\nmin = 0.2\nmax = 1.0\nrate_min = -50.0\nrate_max = 50.0\n"
        # the scheduled gain multiplies one coupling: a softening spring on the first state
        k = f"q_{names[0]}"
        values[k] = -_uniform(rng, 0.5, 2.0)
        rows[0] = f"{rows[0]} + {k} * s * {names[0]}"
        derived_note = ", a gain scheduled on the measured first output"
    constant, duplicated = _constant_and_duplicated_terms(rng, rows, names, values)
    side = _kinds_rng(rng, "linf_uio")
    exact = _exact_constant(side, rows, values)
    zero = _zero_terms(side, rows, names, values, core["outputs"], core["unknown"][0][0])
    crossing = _zero_crossing(side, rows, names, values, lo, hi)
    noise = _noise_table(side, _measured_units(core))
    units = _signal_units(core)
    symbols = [(s, "") for s in names] + [(d, "") for d, _ in core["unknown"]] + [(u, "") for u, _ in core["known"]]
    symbols += [("v_x", "positive=True")] + ([("s", "positive=True")] if core["derived"] else [])
    symbols += [(k, "real=True") for k in values]
    body = f"""
    MODEL = ModelDefinition(
        name="random_lpv",
        states=({", ".join(names)},),
        known_inputs=({"".join(u + ", " for u, _ in core["known"])}),
        unknown_inputs=({"".join(d + ", " for d, _ in core["unknown"])}),
        dynamics=sp.Matrix([{", ".join(rows)}]),
        outputs=({"".join(f'("{y}", {e}), ' for y, e in core["outputs"])}),
        scheduling=({"".join(s + ", " for s in scheduling)}),
        parameters=({"".join(k + ", " for k in values)}),
        units={units!r})
    """
    structure = {"states": core["n"], "outputs": len(core["outputs"]), "known_inputs": len(core["known"]),
                 "unknown_inputs": len(core["unknown"]), "output_combinations": core["combos"],
                 "ui_feedthrough": core["feedthrough"], "derived_scheduling": core["derived"],
                 "v_x_terms": v_terms, "ui_units": [u for _, u in core["unknown"]],
                 "constant_terms": constant, "duplicated_terms": duplicated, "exact_constants": exact,
                 "zero_terms": zero, "zero_crossing": crossing, "sensor_noise": bool(noise)}
    name = _name("linf", structure)
    inputs = "\n[inputs]\n" + _ui_ranges(core)
    inputs += "".join(f"{u} = {{ min = -0.05, max = 0.05, bandwidth = 0.5 }}\n" for u, _ in core["known"])
    # quadratic where a premise more would double the PDLF's membership-rate corners (a draw took 10 min)
    quadratic = core["derived"] or duplicated
    observer = (f'family = "linf_uio"\nmodel = "model.py"\nparameters = "parameters.toml"\npolytope = "sector"\n'
                f'rate_bounds = "{"none" if quadratic else "exact"}"\nsample_time = 0.01\n\n'
                f'[design]\nalpha = 2.0\nlyapunov = "{"quadratic" if quadratic else "pdlf"}"\n'
                f'gain_bound_times_sample_time = 1.0\n\n[ui_filter]\ntime_constant = 0.02\n')
    model = _model_py(f"Random LPV model (linf_uio): {_describe(structure)}{derived_note}.", symbols, body)
    return RandomModel("linf_uio", name, structure,
                       {"model.py": model, "parameters.toml": _params_toml(values, tables + inputs + noise),
                        f"{name}.toml": observer})


# -- switched_pi ------------------------------------------------------------------------------------

def draw_switched(rng) -> RandomModel:
    """An LPV model in the speed, as :func:`draw_linf` draws it (no unknown input in an output, no
    derived scheduling: Menhour et al. 2014's y = C x), one unknown input, modes at 2-3 speeds."""
    core = _draw_lpv_core(rng, "switched_pi", allow_feedthrough=False, allow_derived=False, max_unknown=1)
    names, values = core["names"], core["values"]
    lo, hi, rate = _speed_box(rng)
    rows, v_terms = _linear_rows(rng, names, core["entries"], values, "v_x", rng.random() < 0.5)
    n_modes = int(rng.integers(2, 4))
    centres = [float(np.round(c, 2)) for c in np.linspace(lo + 0.2 * (hi - lo), hi - 0.2 * (hi - lo), n_modes)]
    side = _kinds_rng(rng, "switched_pi")
    exact = _exact_constant(side, rows, values)
    zero = _zero_terms(side, rows, names, values, core["outputs"], core["unknown"][0][0])
    crossing = _zero_crossing(side, rows, names, values, lo, hi)
    noise = _noise_table(side, _measured_units(core))
    units = _signal_units(core)
    symbols = [(s_, "") for s_ in names] + [(d, "") for d, _ in core["unknown"]] + [(u, "") for u, _ in core["known"]]
    symbols += [("v_x", "positive=True")] + [(k, "real=True") for k in values]
    body = f"""
    MODEL = ModelDefinition(
        name="random_switched",
        states=({", ".join(names)},),
        known_inputs=({"".join(u + ", " for u, _ in core["known"])}),
        unknown_inputs=({"".join(d + ", " for d, _ in core["unknown"])}),
        dynamics=sp.Matrix([{", ".join(rows)}]),
        outputs=({"".join(f'("{y}", {e}), ' for y, e in core["outputs"])}),
        scheduling=(SchedulingSignal(v_x, "m/s"),),
        parameters=({"".join(k + ", " for k in values)}),
        units={units!r})
    """
    structure = {"states": core["n"], "outputs": len(core["outputs"]), "known_inputs": len(core["known"]),
                 "unknown_inputs": 1, "output_combinations": core["combos"], "modes": n_modes, "v_x_terms": v_terms,
                 "ui_units": [u for _, u in core["unknown"]], "exact_constants": exact, "zero_terms": zero,
                 "zero_crossing": crossing, "sensor_noise": bool(noise)}
    name = _name("switched", structure) + f"_{n_modes}m"
    tables = f"[scheduling.v_x]\nmin = {lo}\nmax = {hi}\nrate_min = {-rate}\nrate_max = {rate}\n"
    tables += "\n[inputs]\n" + _ui_ranges(core)
    tables += "".join(f"{u} = {{ min = -0.05, max = 0.05, bandwidth = 0.5 }}\n" for u, _ in core["known"]) + noise
    points = ", ".join(f"{{ v_x = {c} }}" for c in centres)
    observer = (f'family = "switched_pi"\nmodel = "model.py"\nparameters = "parameters.toml"\nsample_time = 0.01\n\n'
                f'[design]\npole_radius = 50.0\ndecay_rate = 0.5\n\n[switching]\nperformance = ["{names[0]}"]\n'
                f'[[switching.axis]]\nname = "v_x"\npremise = "v_x"\nunit = "m/s"\ncentres = {centres}\n'
                f'points = [{points}]\n')
    model = _model_py(f"Random LPV model (switched_pi): {_describe(structure)}, {n_modes} speed modes.", symbols, body)
    return RandomModel("switched_pi", name, structure,
                       {"model.py": model, "parameters.toml": _params_toml(values, tables), f"{name}.toml": observer})


# -- algebraic_uio ----------------------------------------------------------------------------------

def draw_algebraic(rng) -> RandomModel:
    """A lateral-offset chain of Ichalal and Mammar 2015's shape: y_L' = c(v_x) psi_L + ...,
    psi_L' = c(v_x) r + ..., r' = ... with the unknown yaw moment entering the chain at a drawn
    position (relative degree 1-3 of the measured first state), every coupling of the chain and the
    unknown input's gain affine in the scheduling speed (its derivatives then enter the observer),
    sometimes a known input; differentiators of the orders the relative degree needs."""
    chain = [("y_L", "m"), ("psi_L", "rad"), ("r", "rad/s")]
    n = int(rng.integers(2, 4))
    states = chain[3 - n:]
    names = [s_ for s_, _ in states]
    degree = int(rng.integers(1, n + 1))                      # the unknown input enters state `degree`
    values: dict = {}
    rows = []
    for i, si in enumerate(names):
        terms = []
        for j in range(i + 1):
            if j == i:
                values[f"a_{si}"] = -_uniform(rng, 0.5, 3.0)
                terms.append(f"a_{si} * {si}")
            elif rng.random() < 0.5:
                values[f"a_{si}_{names[j]}"] = _uniform(rng, 0.2, 1.5, sign=True)
                terms.append(f"a_{si}_{names[j]} * {names[j]}")
        if i + 1 < n:                      # the chain: a coupling that never vanishes on the speed box
            values[f"k_{si}"] = _uniform(rng, 0.5, 2.0)
            values[f"m_{si}"] = _uniform(rng, 0.0, 0.1)
            terms.append(f"(k_{si} + m_{si} * v_x) * {names[i + 1]}")
        rows.append(terms)
    target = names[degree - 1]
    values["g_0"] = _uniform(rng, 0.5, 2.0)
    values["g_1"] = _uniform(rng, 0.0, 0.05)
    rows[degree - 1].append("(g_0 + g_1 * v_x) * M_d")
    known = []
    if rng.random() < 0.3:
        known = [("delta", "rad")]
        at = names[int(rng.integers(n))]
        values[f"h_{at}"] = _uniform(rng, 1.0, 5.0, sign=True)
        rows[names.index(at)].append(f"h_{at} * delta")
    lo, hi, rate = _speed_box(rng)
    order = degree + 2
    units = {**dict(states), "M_d": "kN m", **dict(known)}
    symbols = [(s_, "") for s_ in names] + [("M_d", "")] + [(u, "") for u, _ in known]
    symbols += [("v_x", "positive=True")] + [(k, "real=True") for k in values]
    body = f"""
    MODEL = ModelDefinition(
        name="random_chain",
        states=({", ".join(names)},),
        known_inputs=({"".join(u + ", " for u, _ in known)}),
        unknown_inputs=(M_d,),
        dynamics=sp.Matrix([{", ".join(" + ".join(r_) for r_ in rows)}]),
        outputs=(("{names[0]}", {names[0]}),),
        scheduling=(SchedulingSignal(v_x, "m/s"),),
        parameters=({"".join(k + ", " for k in values)}),
        units={units!r})
    """
    structure = {"states": n, "outputs": 1, "known_inputs": len(known), "unknown_inputs": 1,
                 "relative_degree": degree}
    name = _name("algebraic", structure) + f"_r{degree}"
    bounds = ", ".join(f"[{-10.0 ** m}, {10.0 ** m}]" for m in range(1, order + 1))
    tables = (f"[scheduling.v_x]\nmin = {lo}\nmax = {hi}\nrate_min = {-rate}\nrate_max = {rate}\n"
              f"derivative_bounds = [{bounds}]\n\n[inputs]\nM_d = {{ min = -1.0, max = 1.0, bandwidth = 0.5 }}\n")
    tables += "".join("delta = { min = -0.05, max = 0.05, bandwidth = 0.5 }\n" for _ in known)
    noise = _noise_table(_kinds_rng(rng, "algebraic_uio"), {names[0]: dict(states)[names[0]], **dict(known), "v_x": "m/s"})
    tables += noise
    structure["sensor_noise"] = bool(noise)
    name += "_noise" if noise else ""
    observer = (f'family = "algebraic_uio"\nmodel = "model.py"\nparameters = "parameters.toml"\nsample_time = 0.002\n\n'
                f'[design]\nlmi = "direct"\nalpha = 1.0\nmargin = 1e-4\n\n'
                f'[design.differentiators.y_{names[0]}]\norder = {order}\nlipschitz = 1000.0\n\n'
                f'[design.differentiators.v_x]\norder = {order}\nlipschitz = 100.0\n')
    model = _model_py(f"Random chain (algebraic_uio): {_describe(structure)}, relative degree {degree}.", symbols, body)
    return RandomModel("algebraic_uio", name, structure,
                       {"model.py": model, "parameters.toml": _params_toml(values, tables), f"{name}.toml": observer})


# -- ts_fuzzy_uio -----------------------------------------------------------------------------------

def draw_ts(rng) -> RandomModel:
    """A longitudinal-lateral model of Nguyen et al. 2021's shape, its structure drawn: the speed
    v_x a measured state (the 1/v_x of the other rows a measured premise), 1-2 more states of which
    some are measured, 1-2 unknown inputs each reaching a measured state, sometimes a known input,
    sometimes a saturating tyre law (tanh) of an unmeasured state, sometimes a coupling of the two
    other states in the speed's row (v_y r, v_y p, or h p r with a height h: a premise in the measured
    one of the two), sometimes a constant term (rolling resistance)."""
    extra = [("v_y", "m/s"), ("r", "rad/s"), ("p", "rad/s")]
    n_extra = int(rng.integers(1, 3))
    others = [extra[k] for k in sorted(rng.choice(len(extra), size=n_extra, replace=False))]
    states = [("v_x", "m/s")] + others
    names = [s for s, _ in states]
    # measured: v_x and, with two more states, one of them; at least one state is not measured
    measured = ["v_x"] + ([others[int(rng.integers(2))][0]] if n_extra == 2 else [])
    unmeasured = [s for s in names if s not in measured]
    n_d = int(rng.integers(1, len(measured) + 1))
    ui_states = [measured[k] for k in sorted(rng.choice(len(measured), size=n_d, replace=False))]
    # the unknown input a state's balance takes: engine torque in the speed's, a yaw or roll moment
    # in a rate's, a lateral force in v_y's (gains: the inverse inertias of a car, roughly)
    kinds = {"v_x": ("T_eng", "N m", 2e-3), "r": ("M_d", "N m", 5e-4), "p": ("M_x", "N m", 1e-3),
             "v_y": ("F_d", "N", 1e-3)}
    unknown = [kinds[s][:2] for s in ui_states]
    values: dict = {}
    entries: dict = {s: [] for s in names}
    for (d, _), s in zip(unknown, ui_states):
        values[f"g_{s}"] = _uniform(rng, 0.5, 2.0, sign=s != "v_x") * kinds[s][2]
        entries[s].append(f"g_{s} * {d}")
    known = []
    if rng.random() < 0.5:
        known = [("delta", "rad")]
        target = [s for s in names if s != "v_x"][int(rng.integers(n_extra))]
        values[f"h_{target}"] = _uniform(rng, 5.0, 40.0)
        entries[target].append(f"h_{target} * delta")
    values["k_drag"] = -_uniform(rng, 0.005, 0.05)          # rolling and air resistance, linearized
    rows = {"v_x": ["k_drag * v_x"]}
    coupling = len(others) == 2 and rng.random() < 0.5
    if coupling:
        a, b = others[0][0], others[1][0]
        if {a, b} == {"r", "p"}:        # two rates make no acceleration: a height times them does (h p r)
            values["h_pr"] = 0.5
            rows["v_x"].append(f"h_pr * {a} * {b}")
        else:                           # v_y r, v_y p: a speed times a rate
            rows["v_x"].append(f"{a} * {b}")
    for si in names[1:]:
        terms = []
        for sj in names[1:]:
            if si == sj:
                values[f"b_{si}"] = -_uniform(rng, 10.0, 40.0)
                terms.append(f"b_{si} * {sj} / v_x")
                values[f"a_{si}"] = -_uniform(rng, 0.2, 1.0)
                terms.append(f"a_{si} * {sj}")
            elif rng.random() < 0.6:
                values[f"b_{si}_{sj}"] = _uniform(rng, 2.0, 15.0, sign=True)
                terms.append(f"b_{si}_{sj} * {sj} / v_x")
        if si == "v_y" and "r" in names and rng.random() < 0.5:
            terms.append("-v_x * r")                    # the kinematic coupling of the lateral balance
        rows[si] = terms
    saturating = bool(unmeasured) and rng.random() < 0.5
    if saturating:
        u_state = unmeasured[0]
        target = measured[-1] if measured[-1] != "v_x" else names[1]
        values["F_sat"] = _uniform(rng, 2.0, 6.0)
        values["k_sat"] = _uniform(rng, 1.0, 4.0)
        rows[target].append(f"-F_sat * sp.tanh(k_sat * {u_state} / F_sat)")
    for s_ in names:
        rows[s_] = rows[s_] + entries[s_]
    dynamics = [" + ".join(rows[s_]) or "0" for s_ in names]
    constant = _constant_term(rng, dynamics, names, values)
    lo, hi, _ = _speed_box(rng)
    side = _kinds_rng(rng, "ts_fuzzy_uio")
    outputs = [(m, m) for m in measured]
    exact = _exact_constant(side, dynamics, values)
    zero = _zero_terms(side, dynamics, names, values, outputs, unknown[0][0])
    crossing = _zero_crossing(side, dynamics, names, values, lo, hi)
    noise = _noise_table(side, {**{m: dict(states)[m] for m in measured}, **dict(known)})
    bounds = {"v_x": [lo, hi], "v_y": [-1.5, 1.5], "r": [-0.6, 0.6], "p": [-0.6, 0.6]}
    tables = "[state_bounds]\n" + "".join(f"{s_} = [{bounds[s_][0]}, {bounds[s_][1]}]\n" for s_ in names)
    tables += "\n[inputs]\n" + "".join(f"{d} = {{ min = {-200.0}, max = {200.0}, bandwidth = 0.5 }}\n"
                                        for d, _ in unknown)
    tables += "".join("delta = { min = -0.03, max = 0.03, bandwidth = 0.5 }\n" for _ in known)
    units = {**dict(states), **dict(unknown), **dict(known)}
    symbols = [(s_, "positive=True" if s_ == "v_x" else "") for s_ in names]
    symbols += [(d, "") for d, _ in unknown] + [(u, "") for u, _ in known] + [(k, "real=True") for k in values]
    body = f"""
    MODEL = ModelDefinition(
        name="random_ts",
        states=({", ".join(names)},),
        known_inputs=({"".join(u + ", " for u, _ in known)}),
        unknown_inputs=({"".join(d + ", " for d, _ in unknown)}),
        dynamics=sp.Matrix([{", ".join(dynamics)}]),
        outputs=({"".join(f'("{y}", {e}), ' for y, e in outputs)}),
        scheduling=(),
        parameters=({"".join(k + ", " for k in values)}),
        units={units!r})
    """
    structure = {"states": len(names), "outputs": len(outputs), "known_inputs": len(known),
                 "unknown_inputs": len(unknown), "saturating_tyre": saturating, "coupling": coupling,
                 "derived_scheduling": True, "constant_terms": constant, "exact_constants": exact, "zero_terms": zero,
                 "zero_crossing": crossing, "sensor_noise": bool(noise)}
    name = _name("ts", structure)
    observer = ('family = "ts_fuzzy_uio"\nmodel = "model.py"\nparameters = "parameters.toml"\nsample_time = 0.01\n\n'
                '[design]\ndecay = 1.0\nmargin = 1e-4\n')
    model = _model_py(f"Random TS model (ts_fuzzy_uio): {_describe(structure)}; the 1/v_x premise from the "
                      f"measured speed.", symbols, body)
    return RandomModel("ts_fuzzy_uio", name, structure,
                       {"model.py": model, "parameters.toml": _params_toml(values, tables + noise),
                        f"{name}.toml": observer})


# -- dmvt_observer ------------------------------------------------------------------------------------

def draw_dmvt(rng) -> RandomModel:
    """A single-track model with saturating (tanh) axle laws in lateral acceleration, observed from a_y
    (a nonlinear output: both laws of v_y and r) and the yaw rate: the speed a measured scheduling signal,
    the steering angle a known input, sometimes a third state (a roll angle driven by a_y, its decay of its
    own, not observable: detectable), sometimes an exact constant beside a parameter. The slip box keeps
    each law's slope above about a third of its cornering stiffness (the DMVT corners stay observable)."""
    third = rng.random() < 0.5
    names = ["v_y", "r"] + (["phi"] if third else [])
    values = {}
    for k in ("f", "r"):
        values[f"A_{k}"] = _uniform(rng, 4.0, 7.0)              # m/s^2: the axle's grip, per unit of mass
        values[f"c_{k}"] = values[f"A_{k}"] * _uniform(rng, 6.0, 10.0)   # m/s^2/rad: its cornering stiffness
    values["l_f"] = _uniform(rng, 1.0, 1.5)
    values["l_r"] = _uniform(rng, 1.2, 1.7)
    values["k_z"] = _uniform(rng, 0.5, 1.0)                   # 1/m^2: m / I_z
    lo = float(np.round(rng.uniform(10.0, 15.0), 1))
    hi = float(np.round(rng.uniform(25.0, 40.0), 1))
    law_f = "A_f * sp.tanh(c_f * (delta - (v_y + l_f * r) / v_x) / A_f)"
    law_r = "A_r * sp.tanh(c_r * (l_r * r - v_y) / v_x / A_r)"
    rows = [f"{law_f} + {law_r} - r * v_x", f"k_z * l_f * {law_f} - k_z * l_r * {law_r}"]
    if third:
        values["b_phi"] = _uniform(rng, 4.0, 10.0)            # 1/s
        values["h_phi"] = _uniform(rng, 0.005, 0.02)          # s/m: roll per lateral acceleration
        rows.append(f"-b_phi * phi + h_phi * ({law_f} + {law_r})")
    side = _kinds_rng(rng, "dmvt_observer")
    exact = _exact_constant(side, rows, values)
    outputs = [("a_y", f"{law_f} + {law_r}"), ("r", "r")]
    units = {"v_y": "m/s", "r": "rad/s", "phi": "rad", "delta": "rad", "v_x": "m/s", "a_y": "m/s^2",
             "A_f": "m/s^2", "A_r": "m/s^2", "c_f": "m/s^2", "c_r": "m/s^2", "l_f": "m", "l_r": "m",
             "k_z": "1/m^2", "b_phi": "1/s", "h_phi": "s/m"}
    units = {k: v for k, v in units.items() if k in names or k in values or k in ("delta", "v_x", "a_y")}
    symbols = [(n, "") for n in names] + [("delta", ""), ("v_x", "positive=True")]
    symbols += [(k, "real=True") for k in values]
    body = f"""
    MODEL = ModelDefinition(
        name="random_dmvt",
        states=({", ".join(names)},),
        known_inputs=(delta,),
        unknown_inputs=(),
        dynamics=sp.Matrix([{", ".join(rows)}]),
        outputs=({"".join(f'("{y}", {e}), ' for y, e in outputs)}),
        scheduling=(SchedulingSignal(v_x, "m/s"),),
        parameters=({"".join(k + ", " for k in values)}),
        units={units!r})
    """
    structure = {"states": len(names), "outputs": len(outputs), "known_inputs": 1, "unknown_inputs": 0,
                 "saturating_tyre": True, "nonlinear_output": True, "detectable_state": third,
                 "exact_constants": exact}
    name = _name("dmvt", structure)
    bounds = {"v_y": (-0.3, 0.3), "r": (-0.3, 0.3), "phi": (-0.1, 0.1)}
    tables = (f"[scheduling.v_x]\nmin = {lo}\nmax = {hi}\n\n[state_bounds]\n"
              + "".join(f"{n} = [{bounds[n][0]}, {bounds[n][1]}]\n" for n in names)
              + "\n[inputs]\ndelta = { min = -0.02, max = 0.02, bandwidth = 0.5 }\n"
              + f"v_x = {{ min = {lo + 2.0}, max = {hi - 2.0} }}\n")
    noise = {"a_y": float(np.round(_uniform(rng, 0.02, 0.2), 3)), "r": float(np.round(_uniform(rng, 5e-4, 3e-3), 5))}
    observer = ('family = "dmvt_observer"\nmodel = "model.py"\nparameters = "parameters.toml"\nsample_time = 0.01\n\n'
                f'[design]\nnoise = {{ a_y = {noise["a_y"]}, r = {noise["r"]} }}\n')
    model = _model_py(f"Random single-track model with tanh axle laws (dmvt_observer): {len(names)} states, a_y "
                      f"(nonlinear in v_y and r) and r measured.", symbols, body)
    return RandomModel("dmvt_observer", name, structure,
                       {"model.py": model, "parameters.toml": _params_toml(values, tables), f"{name}.toml": observer})


# -- interconnected_uio, nonlinear_tyre_observer: their built-in model, its parameters dispersed ------

#: {family: (built-in observer file, {parameter: relative half-width of its dispersion}, parameters drawn
#: with the same factor as another (mu_r as mu_f))}: the physical parameters of the car; a gravity,
#: a force share or a floor is no property of another car
DISPERSED = {
    "interconnected_uio": ("interconnected_uio", dict.fromkeys(
        ("m", "I_z", "C_f", "C_r", "C_lf", "C_lr", "I_wf", "I_wr", "I_s", "B_s", "t_sb", "c_a", "sigma", "l_w"), 0.2)
        | dict.fromkeys(("l_f", "l_r", "R", "l_s", "R_s"), 0.1), {}),
    "nonlinear_tyre_observer": ("stanford_sideslip_nonlinear_tyre", dict.fromkeys(
        ("m", "I_z", "C_f", "C_r"), 0.2) | {"l_f": 0.1, "l_r": 0.1, "mu_f": 0.15}, {"mu_r": "mu_f"}),
}


def _disperse(text: str, rng, spread: dict, tied: dict) -> tuple:
    """The parameter file ``text`` with each ``[parameters]`` value named in ``spread`` multiplied
    by a factor drawn uniformly in 1 +- its half-width (``tied``: parameters taking another's
    factor); comments and every other table kept. Returns (text, {parameter: factor})."""
    out, section, factors = [], None, {}
    for line in text.splitlines():
        head = line.strip()
        if head.startswith("[") and head.endswith("]") or head.startswith("[") and "#" in head:
            section = head.split("#")[0].strip()
        key, _, rest = line.partition("=")
        key = key.strip()
        if section == "[parameters]" and (key in spread or key in tied) and rest:
            value, _, comment = rest.partition("#")
            k = factors.get(tied[key]) if key in tied else None
            if k is None:
                k = float(rng.uniform(1.0 - spread[key], 1.0 + spread[key]))
            factors[key] = k
            line = f"{key} = {_fmt(float(value) * k)}" + (f"  # {comment.strip()} (x {k:.3f})" if comment else "")
        out.append(line)
    missing = sorted(set(spread) - set(factors))
    if missing:
        raise KeyError(f"not in the [parameters] of the built-in file: {missing}")
    return "\n".join(out) + "\n", factors


def _draw_dispersed(family: str, rng) -> RandomModel:
    """The family's built-in observer on a car whose physical parameters are drawn around the
    built-in car's (:data:`DISPERSED`); the model and every design setting are the built-in ones."""
    from ..project import observer_file as observers
    builtin, spread, tied = DISPERSED[family]
    config = observers.get(builtin)
    params, factors = _disperse(Path(config.parameter_path).read_text(), rng, spread, tied)
    if family == "nonlinear_tyre_observer":
        # the braking share is the static front load share l_r / (l_f + l_r) of the drawn car
        vals = {}
        for line in params.splitlines():
            key, _, rest = line.partition("=")
            if key.strip() in ("l_f", "l_r") and rest:
                vals[key.strip()] = float(rest.split("#")[0])
        share = vals["l_r"] / (vals["l_f"] + vals["l_r"])
        params = "\n".join(f"brake_front = {_fmt(share)}  # l_r / (l_f + l_r) of the drawn car"
                           if ln.startswith("brake_front") else ln for ln in params.splitlines()) + "\n"
    lines = Path(config.source).read_text().splitlines()
    observer = "\n".join(f'parameters = "parameters.toml"' if ln.startswith("parameters =") else ln for ln in lines)
    structure = {"states": None, "dispersed": {k: round(v, 4) for k, v in factors.items()}}
    name = f"{builtin}_dispersed_{int(rng.integers(10 ** 6)):06d}"
    return RandomModel(family, name, structure, {"parameters.toml": params, f"{name}.toml": observer + "\n"})


def draw_interconnected(rng) -> RandomModel:
    """Sentouh et al. 2023's interconnected model (fixed by its theory) on a drawn car."""
    return _draw_dispersed("interconnected_uio", rng)


def draw_nonlinear_tyre(rng) -> RandomModel:
    """The nonlinear-tyre single-track observer (fixed model) on a drawn car."""
    return _draw_dispersed("nonlinear_tyre_observer", rng)


def _name(prefix: str, s: dict) -> str:
    parts = [prefix, f"{s['states']}x", f"{s['outputs']}y", f"{s['known_inputs']}u", f"{s['unknown_inputs']}d"]
    parts += [tag for key, tag in (("output_combinations", "mix"), ("ui_feedthrough", "ff"),
                                   ("derived_scheduling", "der"), ("saturating_tyre", "sat"),
                                   ("v_x_terms", "vx"), ("constant_terms", "k0"),
                                   ("duplicated_terms", "dup"), ("exact_constants", "ex"), ("zero_terms", "z0"),
                                   ("zero_crossing", "zc"), ("sensor_noise", "noise")) if s.get(key)]
    if any(u.startswith("kN") for u in s.get("ui_units", ())):
        parts.append("kN")
    return "_".join(parts)


def _describe(s: dict) -> str:
    out = (f"{s['states']} states, {s['outputs']} outputs ({s.get('output_combinations', 0)} of them combinations "
           f"of states), {s['known_inputs']} known and {s['unknown_inputs']} unknown inputs")
    if s.get("ui_feedthrough"):
        out += ", an unknown input in an output"
    if s.get("saturating_tyre"):
        out += ", a saturating tyre law"
    return out


# -- running a draw ----------------------------------------------------------------------------------

def drawers() -> dict:
    """{name: family} of every registered family that draws random models (the capability
    :class:`~codegen.contract.capabilities.RandomModels`), in the registry's order."""
    from . import get, names
    from ..contract.capabilities import RandomModels
    return {n: get(n) for n in names() if isinstance(get(n), RandomModels)}


def draw(family: str, seed: int) -> RandomModel:
    """The model the family ``family`` draws from ``numpy.random.default_rng(seed)``."""
    from . import get
    from ..contract.capabilities import RandomModels, require
    return require(get(family), RandomModels).draw_random_model(np.random.default_rng(seed))
