"""Results that depend only on what they are derived from, kept across runs (the design lock's rules).

Symbolic work that gives the same answer every time -- a model's unit analysis, for one -- is done
once per content and reused, within a process and across runs. An entry is keyed by the SHA-256 of
everything it derives from (the model's equations as sympy writes them, the modules that derive
it byte for byte, the package versions): an edit of any of them is another key, so an entry can
be missing but never stale. Each entry records its key, its kind and the SHA-256 of its payload;
one whose record does not verify (truncated, edited, another format) is ignored and computed again,
never believed. Entries are written atomically (a temporary file renamed over); a cache folder that
cannot be written (read-only, disk full) costs the time of the work, never a result or an error.

The folder: ``$UIOGEN_CACHE_DIR``, else ``$XDG_CACHE_HOME/uiogen``, else ``~/.cache/uiogen``
(content-addressed, so one folder serves every project; delete it at any time).
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import sys
import tempfile
from pathlib import Path

FORMAT = 1


def folder() -> Path:
    """Where the entries live (module docstring)."""
    explicit = os.environ.get("UIOGEN_CACHE_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "uiogen"


def key(kind: str, parts: dict) -> str:
    """The SHA-256 of ``kind`` and ``parts`` (JSON-serializable: strings, numbers, lists, dicts)."""
    text = json.dumps({"format": FORMAT, "kind": kind, "parts": parts}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def code_digest(*modules) -> str:
    """SHA-256 of the source files of ``modules`` (module objects), byte for byte: the code that derives
    an entry is part of its key."""
    h = hashlib.sha256()
    for m in modules:
        path = Path(m.__file__)
        h.update(path.name.encode() + b"\0" + _file_digest(path, path.stat().st_mtime_ns).encode() + b"\0")
    return h.hexdigest()


@functools.lru_cache(maxsize=64)
def _file_digest(path: Path, mtime_ns: int) -> str:
    """A source file's SHA-256, read once per modification time (the stanford module is keyed on every
    column's noise level)."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def canonical(x):
    """``x`` as JSON-able data that says everything it means: sympy objects by ``srepr`` (with every
    symbol's assumptions), arrays by their type, shape and the SHA-256 of their bytes (their ``repr`` elides
    the middle of a long one), dataclasses field by field, mappings in key order."""
    import dataclasses

    import numpy as np
    import sympy as sp
    if isinstance(x, (sp.Basic, sp.MatrixBase)):
        return sp.srepr(x)
    if isinstance(x, np.ndarray) and not x.dtype.hasobject:
        return {"ndarray": x.dtype.str, "shape": list(x.shape),
                "sha256": hashlib.sha256(np.ascontiguousarray(x).tobytes()).hexdigest()}
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {"type": type(x).__name__, **{f.name: canonical(getattr(x, f.name)) for f in dataclasses.fields(x)}}
    if isinstance(x, dict) or hasattr(x, "items"):
        return [[str(k), canonical(v)] for k, v in sorted(x.items(), key=lambda kv: str(kv[0]))]
    if isinstance(x, (list, tuple)):
        return [canonical(v) for v in x]
    if x is None or isinstance(x, (str, int, float, bool)):
        return x
    return repr(x)


def model_digest(model) -> str:
    """SHA-256 of a model definition's content (its equations, signals, units, parameters and their
    assumptions): what a result derived from the model alone is keyed by. Once per model object (its
    ``srepr`` is the cost: the unit check and the unit analysis key on the same model)."""
    held = _digests.get(id(model))
    if held is None or held[0] is not model:
        text = json.dumps(canonical(model), sort_keys=True, separators=(",", ":"))
        held = (model, hashlib.sha256(text.encode()).hexdigest())
        _digests[id(model)] = held
    return held[1]


_digests: dict = {}          # {id(model): (model, digest)}: the object is kept, so its id is not reused


def _payload_sha(payload) -> str:
    return hashlib.sha256(json.dumps(payload, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def _path(kind: str, digest: str, base: Path | None) -> Path:
    return (base or folder()) / kind / f"{digest}.json"


_memory: dict = {}


def read(kind: str, digest: str, base: Path | None = None):
    """The payload of entry ``digest``, or None when it is absent or does not verify."""
    if (kind, digest) in _memory:
        return _memory[(kind, digest)]
    try:
        record = json.loads(_path(kind, digest, base).read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    if not (isinstance(record, dict) and record.get("format") == FORMAT and record.get("kind") == kind
            and record.get("key") == digest and "payload" in record
            and record.get("sha256") == _payload_sha(record["payload"])):
        return None
    _memory[(kind, digest)] = record["payload"]
    return record["payload"]


def write(kind: str, digest: str, payload, base: Path | None = None) -> bool:
    """Keep ``payload`` under ``digest`` (atomically); False when the folder cannot be written."""
    _memory[(kind, digest)] = payload
    path = _path(kind, digest, base)
    record = {"format": FORMAT, "kind": kind, "key": digest, "sha256": _payload_sha(payload), "payload": payload}
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".json")
        with os.fdopen(fd, "w") as fh:
            json.dump(record, fh, sort_keys=True)
        os.replace(tmp, path)
        return True
    except OSError:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
        return False


def forget() -> None:
    """Drop what this process holds in memory (the files stay): the next read verifies the file."""
    _memory.clear()


# --- whole results: a family's representation, kept as data ----------------------------------------------------
#
# A representation is a tree of dataclasses, tuples, mappings, numpy arrays, numbers and sympy expressions. It is
# kept as JSON that says every bit of it: sympy trees node by node (the class, its arguments; a symbol with its
# assumptions; a Float by its binary mantissa and exponent), arrays by their bytes, floats as Python writes them
# (which reads back to the same double). Read back, it is rebuilt as it was, without evaluating anything: an entry
# is written only when reading it back gives the same data again, so what a second run gets is the first run's
# result to the last bit. Classes are found by name only among sympy's and this package's own, never imported
# from elsewhere.


class Unkept(Exception):
    """A value :func:`encode` cannot write exactly (a callable, an undefined sympy function, ...): the result is
    then computed every time, never kept in part."""


_OWN = ("codegen.", "model_defs.")


def encode(x):
    """``x`` as JSON data (section comment above); :class:`Unkept` when some part of it cannot be written exactly."""
    import base64
    import dataclasses
    from pathlib import PurePath

    import numpy as np
    import sympy as sp
    if x is None or type(x) in (bool, str, int):
        return x
    if type(x) is float:
        return x if x == x and x not in (float("inf"), float("-inf")) else ["f", repr(x)]
    if isinstance(x, sp.Basic):
        return _encode_sympy(x)
    if isinstance(x, sp.MatrixBase):
        cls = type(x)
        return ["M", cls.__module__, cls.__qualname__, x.rows, x.cols, [_encode_sympy(e) for e in x]]
    if isinstance(x, np.ndarray):
        if x.dtype.hasobject:
            raise Unkept(f"an array of Python objects ({x.dtype})")
        order = "F" if x.flags.f_contiguous and not x.flags.c_contiguous else "C"     # its layout too: a sum's order
        return ["N", x.dtype.str, list(x.shape), order, base64.b64encode(x.tobytes(order)).decode()]
    if isinstance(x, np.generic):
        return ["n", x.dtype.str, base64.b64encode(np.asarray(x).tobytes()).decode()]
    if isinstance(x, tuple) and not hasattr(x, "_fields"):
        return ["T", [encode(v) for v in x]]
    if isinstance(x, list):
        return ["L", [encode(v) for v in x]]
    if type(x) is dict:
        return ["D", [[encode(k), encode(v)] for k, v in x.items()]]
    if isinstance(x, (set, frozenset)):
        items = sorted((encode(v) for v in x), key=lambda e: json.dumps(e, sort_keys=True))
        return ["S" if isinstance(x, set) else "Z", items]
    if isinstance(x, PurePath):
        return ["P", str(x)]
    if dataclasses.is_dataclass(x) and not isinstance(x, type) and (type(x).__module__ or "").startswith(_OWN):
        cls = type(x)
        return ["C", cls.__module__, cls.__qualname__,
                [[f.name, encode(getattr(x, f.name))] for f in dataclasses.fields(x)]]
    raise Unkept(f"a {type(x).__module__}.{type(x).__qualname__}")


def _encode_sympy(e):
    import sympy as sp
    cls = type(e)
    if not (cls.__module__ or "").startswith("sympy."):
        raise Unkept(f"the sympy object {cls.__name__} of {cls.__module__}")
    if isinstance(e, sp.Dummy):
        return ["y", e.name, e.dummy_index, _assumptions(e)]
    if isinstance(e, sp.Symbol):
        if cls is not sp.Symbol:
            raise Unkept(f"a symbol of class {cls.__name__}")
        return ["s", e.name, _assumptions(e)]
    if isinstance(e, sp.Float):
        sign, man, exp, bc = e._mpf_
        return ["F", sign, str(int(man)), exp, bc, e._prec]
    if isinstance(e, sp.Rational):
        return ["Q", str(e.p), str(e.q)]
    return ["E", cls.__module__, cls.__qualname__, [_encode_sympy(a) for a in e.args]]


def _assumptions(sym) -> dict:
    orig = getattr(sym, "_assumptions_orig", None)
    return {k: bool(v) for k, v in sorted((orig if orig is not None else sym.assumptions0).items())}


def _class(module: str, qualname: str, own: tuple):
    """The class ``module.qualname``, looked up only in modules of ``own`` (never imported from elsewhere)."""
    import importlib
    if not module.startswith(own):
        raise ValueError(f"a class of {module}")
    obj = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    if not isinstance(obj, type):
        raise ValueError(f"{module}.{qualname} is not a class")
    return obj


def decode(data):
    """The value :func:`encode` wrote (ValueError, TypeError or another error when ``data`` is not its output)."""
    import sympy as sp
    from sympy.core.parameters import evaluate
    with evaluate(False):
        return _decode(data, sp)


def _decode(d, sp):
    import base64
    import dataclasses

    import numpy as np
    if d is None or isinstance(d, (bool, str, int, float)):
        return d
    tag = d[0]
    if tag == "f":
        return float(d[1])
    if tag in ("s", "y", "F", "Q", "E"):
        return _decode_sympy(d, sp)
    if tag == "M":
        cls = _class(d[1], d[2], ("sympy.",))
        return cls(d[3], d[4], [_decode_sympy(e, sp) for e in d[5]])
    if tag == "N":
        flat = np.frombuffer(base64.b64decode(d[4]), dtype=np.dtype(d[1]))
        return np.array(flat.reshape(d[2], order=d[3]), order=d[3])
    if tag == "n":
        return np.frombuffer(base64.b64decode(d[2]), dtype=np.dtype(d[1]))[0]
    if tag == "T":
        return tuple(_decode(v, sp) for v in d[1])
    if tag == "L":
        return [_decode(v, sp) for v in d[1]]
    if tag == "D":
        return {_decode(k, sp): _decode(v, sp) for k, v in d[1]}
    if tag in ("S", "Z"):
        return (set if tag == "S" else frozenset)(_decode(v, sp) for v in d[1])
    if tag == "P":
        return Path(d[1])
    if tag == "C":
        cls = _class(d[1], d[2], _OWN)
        if not dataclasses.is_dataclass(cls):
            raise ValueError(f"{d[1]}.{d[2]} is not a dataclass")
        obj = object.__new__(cls)           # as it was written: no __init__ or __post_init__ run again
        for name, v in d[3]:
            object.__setattr__(obj, name, _decode(v, sp))
        return obj
    raise ValueError(f"unknown tag {tag!r}")


def _decode_sympy(d, sp):
    tag = d[0]
    if tag == "s":
        return sp.Symbol(d[1], **d[2])
    if tag == "y":
        return sp.Dummy(d[1], dummy_index=d[2], **d[3])
    if tag == "F":
        from mpmath.libmp import MPZ
        return sp.Float._new((d[1], MPZ(int(d[2])), d[3], d[4]), d[5])
    if tag == "Q":
        return sp.Rational(int(d[1]), int(d[2]))
    if tag == "E":
        cls = _class(d[1], d[2], ("sympy.",))
        if not issubclass(cls, sp.Basic):
            raise ValueError(f"{d[1]}.{d[2]} is not a sympy class")
        return cls(*(_decode_sympy(a, sp) for a in d[3]))
    raise ValueError(f"unknown sympy tag {tag!r}")


def remembered(kind: str, parts: dict, compute, *modules):
    """``compute()``, or what it returned before for the same ``parts`` (everything the result derives from),
    the deriving ``modules`` (byte for byte: this one is always among them) and package versions. A result is
    kept only when it reads back exactly (:func:`encode`); an entry that does not verify or does not read back
    is computed again; an exception of ``compute`` (a refusal) propagates and nothing is kept."""
    import platform

    import numpy as np
    import sympy as sp
    digest = key(kind, {**parts, "sympy": sp.__version__, "numpy": np.__version__,
                        "python": platform.python_version(),
                        "code": code_digest(sys.modules[__name__], *modules)})
    stored = read(kind, digest)
    if stored is not None:
        try:
            return decode(stored)
        except Exception:           # noqa: BLE001 -- an entry that does not read back is not believed
            _memory.pop((kind, digest), None)
    value = compute()
    try:
        data = encode(value)
        if encode(decode(data)) == data:
            write(kind, digest, data)
    except Exception:               # noqa: BLE001 -- not writable exactly: computed every time, never kept in part
        pass
    return value
