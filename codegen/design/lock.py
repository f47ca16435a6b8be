"""The certified design as a committed artifact, like a lock file.

An LMI solve is not reproducible bit for bit across machines: Clarabel's PSD algebra runs
through the BLAS kernel of the CPU it runs on. So the design is solved once, certified, and
committed as ``NAME_design.json`` (the design lock); everything after it, C generation
included, is a pure function of (model, parameters, configuration, design lock, templates,
pinned tool versions) and never solves an LMI again.

The lock records, beside the design data of the family (gains) and its certificate (one typed
record for every family, :mod:`codegen.certificate.certificate`), the exact
decision variables of every LMI problem the design solved (:class:`codegen.design.lmi.SolveRecord`)
and the hash of the design's inputs (:func:`design_inputs`: the observer file, the parameter
file and the model for what they say -- comments and layout are not inputs --, every toolchain
module the design imports byte for byte, the numeric packages' versions). A lock whose hash
matches is *current*: :func:`codegen.pipeline.build` replays it (:func:`replay`, a
:class:`codegen.design.solver.LockReplay` handed to the family's build), re-checking every block
with numpy; its solutions are matched to the design's problems by name.
A stale or missing lock is re-solved by ``uiogen generate`` (and on request by ``uiogen design NAME --update``).

Nothing in a lock is taken on trust: ``design_inputs`` is re-derived and compared, and every
other entry is covered by a checksum (``lock.sections``: the SHA-256 of each entry's JSON;
``lock.sha256``: of those) that :func:`status` verifies, so a lock edited by hand (two signal
names swapped, a gain or gamma changed) is refused, naming the entries, instead of compiled.
(The extension built from a lock carries the SHA-256 of its file, and ``load`` refuses it beside
another lock: :mod:`python_bindings.runtime`.)
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Protocol

import numpy as np

from . import sources
from ..errors import DesignLockError
from .lmi import SolveRecord
from .solver import LockReplay


class ObserverConfig(Protocol):
    """What the design lock reads of an observer's configuration: a
    :class:`codegen.project.observer_file.ObserverConfig`, handed down by the layer that read the observer
    file (its family resolved there: ``family_type``)."""

    name: str
    source: str
    builtin: bool
    doc: str
    family_type: type
    model_path: Path
    parameter_path: Path
    workspace: object

    def to_json(self) -> dict: ...

FORMAT = 2
# The entries of the lock record that seal the rest (not covered by themselves).
SEALS = ("sha256", "sections")
DESIGN_PACKAGES = ("numpy", "scipy", "sympy", "mpmath", "clarabel")


def path(config: ObserverConfig, base: Path | None = None) -> Path:
    """Where the design lock of ``config`` lives: ``base/NAME/NAME_design.json``, base defaulting
    to its project's ``generated_c/`` (:mod:`python_bindings.workspace`)."""
    if base is None:
        return config.workspace.design_lock(config.name)
    return Path(base) / config.name / f"{config.name}_design.json"


def design_sources(config: ObserverConfig) -> list:
    """Every file the design of ``config`` derives from, in a fixed order: the parameter file, the
    model and every project module the family and the model import (a family or model defined
    outside the project by its own file). The observer file enters as parsed
    (:func:`observer_file_digest`)."""
    import inspect
    family = config.family_type          # resolved by the layer that read the observer file
    extra = [config.model_path]
    if family.__module__.split(".")[0] not in sources.PACKAGES:      # a family registered by a user's code
        extra.append(Path(inspect.getsourcefile(family)))
    pipeline_module = f"{family.__module__}.build"      # a family package's pipeline (README of families/)
    entry = pipeline_module if sources._module_file(pipeline_module) is not None else family.__module__
    code = sources.closure("codegen.pipeline", entry, files=extra)
    return [config.parameter_path, *code]


def observer_file_digest(config: ObserverConfig) -> str:
    """Hash of the observer file as parsed, less its ``[data]`` table (the column map of logs) and
    its ``[precision]`` table (the float32 build's tolerances), which no design or C derives from:
    editing them or any comment never re-solves a design. Its leading comment (``config.doc``) is
    the description in the C's header, not a design input: :func:`codegen.emit.generate.emission_inputs`
    hashes it, so an edit of it regenerates the C and keeps the design, and the extension (which
    does not carry it) stays current. The hash is ``load``'s (:mod:`python_bindings.integrity`):
    the two never disagree on whether the observer file changed."""
    from python_bindings.integrity import observer_file_sha256     # the one rule, shared with load's source check
    return observer_file_sha256(config.source)


def file_meanings(config: ObserverConfig) -> dict:
    """{file: what is hashed of it} for the user's inputs hashed for what they say, not how they are
    written -- the parameter file (as parsed) and the model (its syntax tree) -- by the functions
    ``load`` checks them with (:mod:`python_bindings.integrity`): a comment, blank line or spacing
    edited in them re-solves nothing, and what re-solves a design also makes ``load`` refuse the
    extension built before it. Every other source (the toolchain's modules) is hashed byte for byte."""
    from python_bindings import integrity
    return {Path(config.parameter_path).resolve(): integrity.parameters_sha256(config.parameter_path).encode(),
            Path(config.model_path).resolve(): integrity.model_sha256(config.model_path).encode()}


def design_inputs(config: ObserverConfig) -> str:
    """Hash of the design's inputs: files (:func:`design_sources`, the user's as :func:`file_meanings`)
    and numeric package versions."""
    v = sources.versions()
    # the parsed configuration too: a configuration changed in memory (dataclasses.replace) is
    # another design even though its file is the same
    # the parameter file counts for what it says, wherever it lies: a project's copy of a built-in file is
    # the same design input as the file it copies (its path is the configuration's, hashed above)
    return sources.digest(design_sources(config), {"configuration": json.dumps(config.to_json(), sort_keys=True),
                                                   "observer_file": observer_file_digest(config),
                                                   **{k: v[k] for k in DESIGN_PACKAGES}},
                          contents=file_meanings(config),
                          labels={Path(config.parameter_path).resolve(): "parameter file"})


def read(config: ObserverConfig, base: Path | None = None) -> tuple:
    """(parsed lock or None, reason) of the file at :func:`path`."""
    p = path(config, base)
    if not p.is_file():
        return None, "no committed design"
    try:
        data = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        return None, f"the committed design is unreadable ({type(exc).__name__})"
    if not isinstance(data, dict) or not isinstance(data.get("lock"), dict):
        return None, "the committed design has no lock record"
    return data, ""


def status(config: ObserverConfig, base: Path | None = None) -> tuple:
    """(lock or None, reason): the lock when it is current, else None and why not.

    Raises
    ------
    DesignLockError
        The lock is current but was edited after uiogen wrote it (:func:`verify`).
    """
    data, why = read(config, base)
    if data is None:
        return None, why
    lock = data["lock"]
    if lock.get("format") != FORMAT:
        return None, f"lock format {lock.get('format')!r}, this toolchain writes {FORMAT}"
    if lock.get("design_inputs") != design_inputs(config):
        return None, "design inputs changed (model, parameters, configuration, toolchain or package versions)"
    verify(data, str(path(config, base)), config.name if config.builtin else config.source)
    return data, "current"


def _digest(value) -> str:
    return hashlib.sha256(json.dumps(value, sort_keys=True).encode()).hexdigest()


def sections(doc: dict) -> dict:
    """{entry: SHA-256 of its JSON} of every top-level entry of a lock and every entry of its
    ``lock`` record (``lock.KEY``) but the seals."""
    out = {}
    for key, value in doc.items():
        if key == "lock" and isinstance(value, dict):
            out.update({f"lock.{k}": _digest(v) for k, v in value.items() if k not in SEALS})
        else:
            out[key] = _digest(value)
    return out


def seal(doc: dict) -> dict:
    """``doc`` (as its JSON reads back) with its checksums: ``lock.sections`` and ``lock.sha256``."""
    doc = json.loads(json.dumps(doc, sort_keys=True))
    doc["lock"] = {k: v for k, v in doc["lock"].items() if k not in SEALS}
    parts = sections(doc)
    doc["lock"].update(sections=parts, sha256=_digest(parts))
    return doc


def verify(data: dict, source: str, how: str = "NAME") -> str:
    """The checksum (``lock.sha256``) of a parsed lock after checking every entry against its
    checksum.

    Raises
    ------
    DesignLockError
        An entry was edited, added or removed after uiogen wrote the lock (the message names
        them, the file, and how to get a lock uiogen wrote: restore it, or re-solve it).
    """
    lock = data.get("lock") if isinstance(data, dict) else None
    if not isinstance(lock, dict):
        raise DesignLockError(f"{source}: no lock record; re-solve it with `uiogen design {how} --update`")
    parts = sections(data)
    recorded = lock.get("sections")
    if recorded == parts and lock.get("sha256") == _digest(parts):
        return lock["sha256"]
    if not isinstance(recorded, dict) or lock.get("sha256") != _digest(recorded):
        edited = ["lock.sections / lock.sha256 (the checksums themselves)"]
    else:
        edited = sorted(k for k in set(parts) | set(recorded) if parts.get(k) != recorded.get(k))
    raise DesignLockError(f"{source}: the design lock was edited after uiogen wrote it: {', '.join(edited)} "
                          f"{'does' if len(edited) == 1 else 'do'} not match the checksums in lock.sections; a lock "
                          f"is not edited by hand (its C, names and certificate derive from it): restore it from "
                          f"version control, or re-solve it with `uiogen design {how} --update`")


def solutions(data: dict, source: str = "") -> list:
    """The committed LMI solutions of a lock, in solve order (each names its problem)."""
    raw = data["lock"].get("lmi_solutions")
    if not isinstance(raw, list):
        raise DesignLockError(f"{source}: the lock has no list 'lmi_solutions'")
    return [SolveRecord.from_json(r, source) for r in raw]


def replay(data: dict, source: str = ""):
    """A :class:`~codegen.design.solver.LockReplay` of the lock ``data`` (read from ``source``); the
    design it rebuilds must reproduce the lock's entries (:func:`check_reproduced`)."""
    return LockReplay(solutions(data, source), source, recorded=data)


def _differs(a, b) -> bool:
    """Whether two JSON values differ beyond the last bits of a number (a re-check's eigenvalues on
    another CPU may differ there; a forged number does not)."""
    import math
    if isinstance(a, bool) or isinstance(b, bool) or not (isinstance(a, (int, float)) and isinstance(b, (int, float))):
        if isinstance(a, dict) and isinstance(b, dict):
            return a.keys() != b.keys() or any(_differs(a[k], b[k]) for k in a)
        if isinstance(a, list) and isinstance(b, list):
            return len(a) != len(b) or any(_differs(x, y) for x, y in zip(a, b))
        return a != b
    if math.isnan(a) or math.isnan(b):
        return not (math.isnan(a) and math.isnan(b))
    return not math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-300)


def check_reproduced(data: dict, build, source: str, how: str = "NAME") -> None:
    """Refuse a lock whose entries are not what its own solutions give: every number the tool reports
    from a lock (gamma, gains, bounds, the certificate) is the one the replay re-derives and re-checks,
    so a lock forged with its checksums recomputed (gamma times 1000) cannot be believed by one verb
    and contradicted by the C of another.

    Raises
    ------
    DesignLockError
        naming the entries that differ, with the lock's value and the re-derived one of the first.
    """
    fresh = json.loads(json.dumps({**build.artifact(), "certificate": build.certificate.to_json()}, sort_keys=True))
    recorded = {k: v for k, v in data.items() if k != "lock"}
    wrong = sorted(k for k in set(fresh) | set(recorded) if k not in fresh or k not in recorded
                   or _differs(fresh[k], recorded[k]))
    if wrong:
        first = wrong[0]
        show = (f" ({first}: the lock says {json.dumps(recorded.get(first))[:120]}, its solutions give "
                f"{json.dumps(fresh.get(first))[:120]})")
        raise DesignLockError(f"{source}: the design lock's {', '.join(wrong)} {'is' if len(wrong) == 1 else 'are'} "
                              f"not what its own LMI solutions give when replayed and re-checked{show}: a lock edited "
                              f"with its checksums recomputed, or written by another uiogen; restore it from version "
                              f"control, or re-solve it with `uiogen design {how} --update`")


def document(build, records: list) -> dict:
    """The lock of a freshly solved design: the family's design data, its typed certificate
    (:class:`~codegen.certificate.certificate.Certificate`, the same keys for every family), the
    solutions and the hash."""
    v = sources.versions()
    return seal({**build.artifact(), "certificate": build.certificate.to_json(),
                 "lock": {"format": FORMAT, "design_inputs": design_inputs(build.config),
                          "versions": {k: v[k] for k in DESIGN_PACKAGES},
                          "lmi_solutions": [r.to_json() for r in records]}})


def dumps(doc: dict) -> str:
    return json.dumps(doc, indent=1, sort_keys=True) + "\n"


def variable_spread(reference: dict, other: dict) -> dict:
    """{variable: max |difference| / its size}: each decision matrix against its largest entry,
    or a thousandth of the design's largest entry if it is smaller (a matrix the design leaves
    near zero is not 'different' for an absolute difference of 1e-9)."""
    big = max((np.abs(np.asarray(v, float)).max(initial=0.0) for v in reference.values()), default=0.0)
    out = {}
    for key, value in reference.items():
        if key in other:
            a, b = np.asarray(other[key], float), np.asarray(value, float)
            if a.shape == b.shape:
                size = max(np.abs(b).max(initial=0.0), 1e-3 * big, 1e-300)
                out[key] = float(np.abs(a - b).max(initial=0.0) / size)
    return out


def cache_parts(config, **more) -> dict:
    """What a result derived from an observer file's model, parameters and settings is keyed by: the design's
    inputs as the design lock hashes them (:func:`design_inputs`: the parameter file and the
    model as they read, every module the family and the model import byte for byte, the observer file as parsed,
    the numeric packages' versions), the files' paths (which messages and results name), and ``more``; for :func:`codegen.model.cache.remembered`
    (here, above the cache: the model stage does not read the design stage)."""
    from ..model import cache
    return {"design_inputs": design_inputs(config), "source": str(config.source),
            "parameters": str(config.parameter_path), "model": str(config.model_path),
            **{k: cache.canonical(v) for k, v in more.items()}}
