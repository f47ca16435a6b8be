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


def _canonical(x):
    """``x`` as JSON-able data that says everything it means: sympy objects by ``srepr`` (with every
    symbol's assumptions), dataclasses field by field, mappings in key order."""
    import dataclasses

    import sympy as sp
    if isinstance(x, (sp.Basic, sp.MatrixBase)):
        return sp.srepr(x)
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {"type": type(x).__name__, **{f.name: _canonical(getattr(x, f.name)) for f in dataclasses.fields(x)}}
    if isinstance(x, dict) or hasattr(x, "items"):
        return [[str(k), _canonical(v)] for k, v in sorted(x.items(), key=lambda kv: str(kv[0]))]
    if isinstance(x, (list, tuple)):
        return [_canonical(v) for v in x]
    if x is None or isinstance(x, (str, int, float, bool)):
        return x
    return repr(x)


def model_digest(model) -> str:
    """SHA-256 of a model definition's content (its equations, signals, units, parameters and their
    assumptions): what a result derived from the model alone is keyed by. Once per model object (its
    ``srepr`` is the cost: the unit check and the unit analysis key on the same model)."""
    held = _digests.get(id(model))
    if held is None or held[0] is not model:
        text = json.dumps(_canonical(model), sort_keys=True, separators=(",", ":"))
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
