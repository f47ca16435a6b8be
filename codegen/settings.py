"""Typed, validated settings from TOML tables: one parser for every configuration table.

Each observer family keeps its tuning in a frozen dataclass (``LinfDesignSettings``,
``TSDesignSettings``, ...). :func:`parse_settings` reads such a dataclass from the ``[design]``
table of an observer file:

* the allowed keys are the dataclass fields (plus explicit :class:`Alias` keys and ``extra``
  keys a family reads itself); any other key is refused, with a did-you-mean;
* each value is checked against the field's annotation (``float``, ``int``, ``str``, ``bool``,
  ``tuple``, ``dict``, ``X | None``): booleans are not numbers, numbers must be finite (TOML
  allows ``nan`` and ``inf``), strings are not numbers;
* ranges and choices come from the field metadata, written with :func:`setting`::

      alpha: float = setting(5.0, gt=0, doc="decay rate")
      lyapunov: str = setting("pdlf", choices=("pdlf", "quadratic"))

* the dataclass's own ``__post_init__`` checks (cross-field conditions) still run; their
  ``ValueError`` becomes a :class:`~codegen.errors.ConfigurationError` naming the file.

:func:`parse_table` is the same check for a table described by a ``{key: Rule}`` mapping (the
top level of an observer file, a parameter file's ``[scheduling.NAME]``, a nested
``[design.differentiators.NAME]``), and :func:`check_keys` only the unknown-key part.

Every refusal is one :class:`~codegen.errors.ConfigurationError` whose message reads
``FILE: [section] key = value: what is allowed`` (the section is left out at the top level).
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import re
import types
import tomllib
import typing
from dataclasses import MISSING, dataclass
from typing import Any, Callable, Mapping

from .errors import ConfigurationError

__all__ = ["Rule", "Alias", "setting", "rule_of", "settings_rules", "parse_value", "parse_table",
           "parse_settings", "check_keys", "config_error", "toml_repr", "suggest"]


@dataclass(frozen=True)
class Rule:
    """What one value may be.

    Attributes
    ----------
    type : type or None
        ``float`` (a finite number; an integer is accepted and converted), ``int``, ``str``,
        ``bool``, ``tuple``/``list`` (a TOML array, returned as that type), ``dict`` (a table)
        or None (anything).
    gt, ge, lt, le : float or None
        Bounds of a number: > gt, >= ge, < lt, <= le.
    choices : tuple or None
        The allowed values (strings: a misspelt one gets a did-you-mean).
    items : Rule or None
        Rule of each element of an array, or of each value of a table.
    parse : callable or None
        Custom conversion ``raw -> value`` (instead of the type check); it raises ``ValueError``
        or ``TypeError`` whose text says what is allowed.
    allowed : str
        Text of what is allowed, instead of the one derived from the fields above.
    doc : str
        What the setting means (for documentation and messages).
    required : bool
        The key must be present (:func:`parse_table`).
    """

    type: Any = None
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    choices: tuple | None = None
    items: "Rule | None" = None
    parse: Callable | None = None
    allowed: str = ""
    doc: str = ""
    required: bool = False

    def describe(self) -> str:
        """What is allowed, in words ("a finite number > 0", "one of "pdlf", "quadratic"")."""
        if self.allowed:
            return self.allowed
        if self.choices is not None:
            return "one of " + ", ".join(toml_repr(c) for c in self.choices)
        t = self.type
        if t is bool:
            return "true or false"
        if t is float or t is int:
            text = "a finite number" if t is float else "an integer"
            return text + self._range_text()
        if t is str:
            return "a string"
        if t in (tuple, list):
            return "an array" + (f" of {_plural(self.items.describe())}" if self.items else "")
        if t is dict:
            return "a table" + (f" of {_plural(self.items.describe())}" if self.items else "")
        return "a value"

    def _range_text(self) -> str:
        lo = (f"({_num(self.gt)}" if self.gt is not None else f"[{_num(self.ge)}" if self.ge is not None else None)
        hi = (f"{_num(self.lt)})" if self.lt is not None else f"{_num(self.le)}]" if self.le is not None else None)
        if lo and hi:
            return f" in {lo}, {hi}"
        if lo:
            return f" {'>' if self.gt is not None else '>='} {lo[1:]}"
        if hi:
            return f" {'<' if self.lt is not None else '<='} {hi[:-1]}"
        return ""


class _Absent:
    def __repr__(self) -> str:
        return "ABSENT"


ABSENT = _Absent()      # Alias.default: no TOML value assumed when the key is absent


@dataclass(frozen=True)
class Alias:
    """A TOML key that sets a dataclass field through a conversion (the field's name is then no key).

    ``convert`` maps the (checked) TOML value to the field value; ``default`` is the TOML value
    assumed when the key is absent (ABSENT: the field keeps its dataclass default); ``rule``
    checks the TOML value (None: the target field's rule). Example, the L-infinity family's
    ``gain_bound_times_sample_time`` (a bound on ||M|| Ts, read as ``gain_bound = value / Ts``)::

        Alias("gain_bound", lambda v: v / sample_time, default=1.0)
    """

    field: str
    convert: Callable = lambda v: v
    default: Any = ABSENT
    rule: Rule | None = None
    doc: str = ""


def setting(default=MISSING, *, default_factory=MISSING, gt=None, ge=None, lt=None, le=None, choices=None,
            items=None, parse=None, allowed: str = "", doc: str = "", **field_kwargs) -> dataclasses.Field:
    """A dataclass field with the checks :func:`parse_settings` applies (type from the annotation).

    ``alpha: float = setting(5.0, gt=0, doc="decay rate")`` is ``alpha: float = 5.0`` plus the rule
    that a configured alpha is a finite number > 0.
    """
    rule = Rule(None, gt, ge, lt, le, None if choices is None else tuple(choices), items, parse, allowed, doc)
    metadata = {**field_kwargs.pop("metadata", {}), "setting": rule}
    kwargs = dict(field_kwargs, metadata=metadata)
    if default_factory is not MISSING:
        return dataclasses.field(default_factory=default_factory, **kwargs)
    return dataclasses.field(default=default, **kwargs)


# ---- messages ------------------------------------------------------------------------------------------

def _num(x) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def _plural(text: str) -> str:
    """ "a finite number > 0" -> "finite numbers > 0" (for "an array of ...")."""
    if text == "true or false":
        return "booleans (true or false)"
    for article in ("a ", "an "):
        if text.startswith(article):
            text = text[len(article):]
            for noun in ("number", "integer", "string", "table", "array", "value"):
                if noun in text:
                    return text.replace(noun, noun + "s", 1)
    return text


def toml_repr(value, limit: int = 60) -> str:
    """A value as it is written in TOML (strings double-quoted, true/false, nan/inf), shortened."""
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, float):
        text = ("nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value)
                else repr(value))
    elif isinstance(value, str):
        text = '"' + value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    elif isinstance(value, (list, tuple)):
        text = "[" + ", ".join(toml_repr(v, limit) for v in value) + "]"
    elif isinstance(value, Mapping):
        text = "{" + ", ".join(f"{k} = {toml_repr(v, limit)}" for k, v in value.items()) + "}"
    else:
        text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def suggest(word, candidates) -> str | None:
    """The closest candidate to a misspelt key or choice (one that differs in case only; else difflib;
    else one that extends it), or None."""
    if not isinstance(word, str):
        return None
    candidates = [str(c) for c in candidates]
    same = [c for c in candidates if c.lower() == word.lower()]
    if same:                # 'Vx' for 'vx': difflib's ratio of two-letter names is too low to find it
        return same[0]
    close = difflib.get_close_matches(word, candidates, n=1, cutoff=0.6)
    if close:
        return close[0]
    longer = sorted((c for c in candidates if len(word) >= 4 and c.startswith(word)), key=len)
    return longer[0] if longer else None


_TOML_AT = re.compile(r"\s*\(at line (\d+), column (\d+)\)\s*$")
_TOML_HEADER = re.compile(r"^\s*\[\[?\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_TOML_TWICE = re.compile(r"Cannot declare \((.*)\) twice")


def toml_error(source: str, text: str, exc: Exception) -> ConfigurationError:
    """A ConfigurationError for a TOML syntax error of ``source`` (its ``text``): the file, the line,
    and for a key or table given twice, which one (tomllib says only 'Cannot overwrite a value')."""
    message = str(exc)
    at = _TOML_AT.search(message)
    what = _TOML_AT.sub("", message) if at else message
    if at is None:
        return ConfigurationError(f"{source}: not valid TOML: {message}", source=source)
    line = int(at.group(1))
    lines = text.splitlines()
    row = lines[line - 1] if 0 < line <= len(lines) else ""
    section = None
    for above in reversed(lines[:line - 1]):
        m = _TOML_HEADER.match(above)
        if m:
            section = m.group(1)
            break
    twice = _TOML_TWICE.search(what)
    if twice:
        table = ".".join(p.strip().strip("'\"") for p in twice.group(1).split(",") if p.strip())
        return ConfigurationError(f"{source}: line {line}: table [{table}] is declared twice (each table once; "
                                  f"merge the two)", source=source, section=table, key=table,
                                  allowed="each table declared once")
    if what.startswith("Cannot overwrite a value") and "=" in row:
        key = row.split("=", 1)[0].strip()
        where = f"[{section}] " if section else ""
        return ConfigurationError(f"{source}: line {line}: {where}{key} is set twice (a duplicate key: TOML allows "
                                  f"each key once per table; keep one)", source=source, section=section, key=key,
                                  allowed="each key once per table")
    return ConfigurationError(f"{source}: line {line}: not valid TOML: {what}: {row.strip()}", source=source,
                              section=section)


def _where(source: str, section: str | None) -> str:
    return f"{source}: [{section}]" if section else f"{source}:"


def config_error(source: str, section: str | None, key: str, value, allowed: str,
                 suggestion: str | None = None) -> ConfigurationError:
    """``FILE: [section] key = value: allowed (did you mean 'x'?)`` as a ConfigurationError."""
    hint = f" (did you mean {suggestion!r}?)" if suggestion else ""
    msg = f"{_where(source, section)} {key} = {toml_repr(value)}: {allowed}{hint}"
    return ConfigurationError(msg, source=source, section=section, key=key, value=value, allowed=allowed)


def check_keys(table: Mapping, allowed, *, source: str, section: str | None = None, what: str = "") -> None:
    """Refuse keys of ``table`` that are not in ``allowed`` (first one named, with a did-you-mean)."""
    allowed = sorted(allowed)
    unknown = [k for k in table if k not in allowed]
    if not unknown:
        return
    label = f"[{section}]" if section else "top-level"
    key = unknown[0]
    hint = suggest(key, allowed)
    hint = f" (did you mean {hint!r}?)" if hint else ""
    text = (f"unknown {label} keys {sorted(unknown)}{hint}; allowed{(' ' + what) if what else ''}: "
            f"{', '.join(allowed) or 'none'}")
    msg = f"{_where(source, section)} {key} = {toml_repr(table[key])}: {text}"
    raise ConfigurationError(msg, source=source, section=section, key=key, value=table[key], allowed=text)


# ---- values --------------------------------------------------------------------------------------------

def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def parse_value(value, rule: Rule, *, source: str, section: str | None, key: str):
    """``value`` checked against ``rule`` and converted (float for numbers, tuple for arrays...)."""
    raw = value

    def fail(allowed=None, suggestion=None):
        return config_error(source, section, key, raw, "must be " + (allowed or rule.describe()), suggestion)

    if rule.parse is not None:
        try:
            return rule.parse(value)
        except ConfigurationError:
            raise
        except (ValueError, TypeError) as exc:
            raise fail(str(exc) or None) from None
    t = rule.type
    if t is float:
        if not _is_number(value):
            raise fail()
        if not math.isfinite(value):
            raise fail(rule.describe() + " (nan and inf are not)")
        value = float(value)
    elif t is int:
        if not isinstance(value, int) or isinstance(value, bool):
            raise fail()
    elif t is str:
        if not isinstance(value, str):
            raise fail()
    elif t is bool:
        if not isinstance(value, bool):
            raise fail()
    elif t in (tuple, list):
        if not isinstance(value, list):
            raise fail()
        if rule.items is not None:
            value = [parse_value(v, rule.items, source=source, section=section, key=f"{key}[{i}]")
                     for i, v in enumerate(value)]
        value = t(value)
    elif t is dict:
        if not isinstance(value, dict):
            raise fail()
        if rule.items is not None:
            value = {k: parse_value(v, rule.items, source=source, section=f"{section}.{key}" if section else key,
                                    key=k) for k, v in value.items()}
        else:
            value = dict(value)
    if _is_number(value) and t in (float, int):
        if ((rule.gt is not None and not value > rule.gt) or (rule.ge is not None and not value >= rule.ge)
                or (rule.lt is not None and not value < rule.lt) or (rule.le is not None and not value <= rule.le)):
            raise fail()
    if rule.choices is not None and value not in rule.choices:
        raise fail(suggestion=suggest(value, rule.choices))
    return value


def parse_table(table, rules: Mapping[str, Rule], *, source: str, section: str | None = None,
                what: str = "") -> dict:
    """{key: checked value} of ``table``: unknown keys, missing required keys and bad values refused.

    ``what`` qualifies the allowed-keys list in the message (e.g. "for family linf_uio").
    """
    if not isinstance(table, Mapping):
        label = section or "table"
        raise ConfigurationError(f"{source}: {label} = {toml_repr(table)}: must be a table",
                                 source=source, section=section, key=section, value=table, allowed="a table")
    check_keys(table, rules, source=source, section=section, what=what)
    missing = [k for k, r in rules.items() if r.required and k not in table]
    if missing:
        label = f"[{section}] " if section else ""
        raise ConfigurationError(f"{source}: {label}missing {', '.join(missing)} (required: "
                                 f"{', '.join(k for k, r in rules.items() if r.required)})",
                                 source=source, section=section, key=missing[0], allowed="required")
    return {k: parse_value(v, rules[k], source=source, section=section, key=k) for k, v in table.items()}


# ---- settings dataclasses ------------------------------------------------------------------------------

def _annotation_rule(annotation) -> Rule:
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        return _annotation_rule(args[0]) if len(args) == 1 else Rule()
    if origin in (tuple, list):
        args = [a for a in typing.get_args(annotation) if a is not Ellipsis]
        items = _annotation_rule(args[0]) if len(set(args)) == 1 else None
        return Rule(origin, items=items if items and items.type else None)
    if origin is dict:
        return Rule(dict)
    if annotation in (float, int, str, bool, tuple, list, dict):
        return Rule(annotation)
    return Rule()


def rule_of(cls, f: dataclasses.Field) -> Rule:
    """The rule of one settings field: the metadata's, with the type from the annotation."""
    rule = f.metadata.get("setting", Rule())
    if rule.type is None and rule.parse is None:
        typed = _annotation_rule(typing.get_type_hints(cls)[f.name])
        rule = dataclasses.replace(rule, type=typed.type, items=rule.items or typed.items)
    return rule


def settings_rules(cls) -> dict:
    """{field name: Rule} of every init field of a settings dataclass."""
    return {f.name: rule_of(cls, f) for f in dataclasses.fields(cls) if f.init}


def parse_settings(cls, table, *, source: str, section: str = "design", aliases: Mapping[str, Alias] | None = None,
                   extra: Mapping[str, Rule] | None = None, **fixed):
    """A settings dataclass ``cls`` from a TOML table, every key and value checked.

    Parameters
    ----------
    cls : dataclass type
        Its init fields are the keys; types from the annotations, rules from :func:`setting` metadata.
    table : mapping
        The TOML table (e.g. ``config.design``); absent keys keep the dataclass defaults.
    source, section : str
        File and table named in messages (``section="design"`` -> ``[design]``).
    aliases : {TOML key: Alias}, optional
        Keys that set a field through a conversion; the field's own name is then not a key.
    extra : {TOML key: Rule}, optional
        Keys the family reads itself (checked here, not passed to ``cls``).
    **fixed
        Field values set by the caller (a command-line ``tol``, parsed nested tables); they win
        over the table, whose value for that key is still checked.

    Raises
    ------
    ConfigurationError
        An unknown key, a value of the wrong type, out of range or not among the choices, or a
        condition of ``cls.__post_init__`` that fails.
    """
    rules = settings_rules(cls)
    aliases = dict(aliases or {})
    targets = {a.field for a in aliases.values()}
    keys = {k: r for k, r in rules.items() if k not in targets}
    keys.update({k: a.rule or rules[a.field] for k, a in aliases.items()})
    keys.update(extra or {})
    values = parse_table(table, keys, source=source, section=section)
    kwargs = {}
    for key, alias in aliases.items():
        raw = values.get(key, alias.default)
        if raw is not ABSENT:
            kwargs[alias.field] = alias.convert(raw)
    kwargs.update({k: v for k, v in values.items() if k in rules and k not in targets})
    kwargs.update(fixed)
    try:
        return cls(**kwargs)
    except ConfigurationError as exc:
        if exc.source:          # already names its file
            raise
        text = str(exc)         # a dataclass's own cross-field check: give it the file and section
        raise ConfigurationError(f"{_where(source, section)} {text}", source=source, section=section,
                                 allowed=text) from None
    except (ValueError, TypeError) as exc:
        text = str(exc)
        raise ConfigurationError(f"{_where(source, section)} {text}", source=source, section=section,
                                 allowed=text) from None


def number_matrix(value) -> tuple:
    """A TOML array of arrays of finite numbers as a tuple of tuples of float (rows of equal length)."""
    if (not isinstance(value, list) or not value or not all(isinstance(row, list) and row for row in value)
            or not all(_is_number(v) and math.isfinite(v) for row in value for v in row)
            or len({len(row) for row in value}) != 1):
        raise ValueError("an array of rows of finite numbers, all rows of the same length (e.g. [[3.0], [0.0]])")
    return tuple(tuple(float(v) for v in row) for row in value)


def parse_set(text: str, source: str = "--set") -> tuple:
    """``KEY=[v1, v2, ...]`` (a TOML array of the values to try) as ``(KEY, [v1, v2, ...])``.

    A single TOML value (``design.alpha=5``) is a grid of one point. An array-valued setting is
    given as an array of arrays (``design.performance=[["beta"], ["beta", "r"]]``).
    """
    key, sep, rhs = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ConfigurationError(f"{source} {text!r}: expected KEY=[VALUE, ...] (a dotted key of the observer "
                                 f"file, e.g. design.pole_radius=[50, 100])", source=source, key=text)
    try:
        value = tomllib.loads(f"v = {rhs.strip()}")["v"]
    except tomllib.TOMLDecodeError as exc:
        raise ConfigurationError(f"{source} {key}: {rhs.strip()!r} is not a TOML value or array ({exc})",
                                 source=source, key=key, value=rhs) from None
    values = value if isinstance(value, list) else [value]
    if not values:
        raise ConfigurationError(f"{source} {key}: an empty list of values", source=source, key=key, value=rhs)
    return key, values
