"""Stage 6: the compiled step as a CPython extension, built from the generated C.

The observer's C is compiled with the project's strict flags (:data:`codegen.emit.toolchain.STRICT_CFLAGS`,
no fast-math, ``-ffp-contract=off`` so results do not depend on FMA availability) plus the speed
flags below; the Python glue is rendered from ``codegen/emit/templates/pymodule.c.j2`` and
linked with it. The glue compiles in what the runtime shows (:mod:`python_bindings`): the signal
names and units of the header's structs, the sample time, and the SHA-256 of the design lock the
C was generated from, so that :func:`python_bindings.load` refuses an extension older than its lock,
and the hashes of the observer file, parameter file and model it was made from, so that ``load``
refuses it once one of them changed (:mod:`python_bindings.integrity`). The SHA-256 of the
extension's bytes is written beside it (``_NAME.<abi>.so.sha256``): ``load`` checks it before the
extension is loaded. Everything is compiled from one snapshot of the generated folder
(:func:`snapshot_generated`), so the design hash compiled in is that of the C compiled.

Where things go: the observer's project (:mod:`python_bindings.workspace`): the extension in
``build/extensions/``, its objects in ``build/objects/NAME/``.
"""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import importlib.util
import json
import os
import sys
import sysconfig
import tempfile
from pathlib import Path

from python_bindings import integrity
from python_bindings.runtime import CompiledObserver, open_observer
from python_bindings.workspace import Workspace, source_checkout

from ..design import lock as design_lock
from ..emit.header import signals as header_signals
from ..emit.toolchain import STRICT_CFLAGS, compile_and_link, compiler, render_template, run
from ..errors import DesignLockError, UnknownObserverError, UnsupportedError
from ..project import observer_file as observers
from ..project import outputs

STRICT_FLAGS = list(STRICT_CFLAGS)
# Python.h is not -pedantic/-Wconversion clean; the glue gets the same flags minus those two.
GLUE_FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-ffp-contract=off", "-O2"]
# Speed flags of the extension (after the strict ones, so -O3 wins over -O2). Link-time
# optimization makes the batch loop, the step and the CasADi kernel one function: no call, no
# argument arrays, no null-pointer tests on them; hidden visibility lets it (only PyInit is
# exported). Neither changes a result: -ffp-contract=off stays and nothing implies fast-math.
SPEED_FLAGS = ["-O3"]
LTO_FLAGS = ["-flto", "-fvisibility=hidden"]

_LTO = None


def lto_supported() -> bool:
    """Whether the compiler and linker build a shared object with -flto (clang with a linker
    lacking its LTO plugin does not); checked once per process."""
    global _LTO
    if _LTO is None:
        with tempfile.TemporaryDirectory() as tmp:
            src = Path(tmp, "probe.c")
            src.write_text("int uiogen_probe(int x) { return x + 1; }\n")
            try:
                run([compiler(), *SPEED_FLAGS, *LTO_FLAGS, "-fPIC", "-shared", src, "-o", Path(tmp, "probe.so")])
                _LTO = True
            except Exception:
                _LTO = False
    return _LTO


def _config(observer) -> observers.ObserverConfig:
    return observers.get(observer if isinstance(observer, observers.ObserverConfig) else str(observer))


def generated_dir(observer) -> Path:
    """The folder with the observer's generated C and design lock."""
    config = _config(observer)
    return design_lock.path(config).parent


def observer_sources(observer) -> list:
    d = generated_dir(observer)
    name = d.name
    return [d / f"{name}_kernel.c", d / f"{name}.c"]


def check_generated(config: observers.ObserverConfig) -> str:
    """The lock text of ``config`` after checking that its generated folder is exactly what
    ``uiogen generate`` wrote from the current design and toolchain (the stamp,
    :func:`codegen.emit.generate.stamp_matches`): an edited, truncated or stale C file is never compiled.

    Raises
    ------
    UnknownObserverError
        nothing generated yet.
    GenerationError
        the folder does not match its stamp (names the command that regenerates it).
    """
    return _verify_generated(config, generated_dir(config))


def _verify_generated(config: observers.ObserverConfig, folder: Path, where: Path | None = None) -> str:
    """:func:`check_generated` of the generated files in ``folder`` (the generated folder itself,
    or a snapshot of it); ``where``: the generated folder the messages name (default ``folder``)."""
    from ..emit import generate as emit
    from ..errors import GenerationError
    name = config.name
    where = where or folder
    how = config.source if not config.builtin else name
    if not (folder / f"{name}.h").is_file():
        raise UnknownObserverError(f"observer {name!r} has not been generated (no {where / (name + '.h')}); "
                                   f"run `uiogen generate {how}`")
    lock = folder / design_lock.path(config).name
    try:
        lock_text = lock.read_text()
    except (OSError, UnicodeDecodeError):
        raise UnknownObserverError(f"observer {name!r} has no readable design lock {where / lock.name}; "
                                   f"run `uiogen generate {how}`") from None
    if not emit.stamp_matches(folder, emit.emission_inputs(config, lock_text)):
        raise GenerationError(f"{where} does not match its stamp {emit.STAMP}: its C was edited, or the design, "
                              f"model or toolchain changed since it was generated; run `uiogen generate {how}` "
                              f"(the C is never compiled as found)")
    return lock_text


@contextlib.contextmanager
def _flock(path: Path, mode: int):
    """Hold ``flock(mode)`` on ``path`` (created if missing); a folder that does not take the lock
    file (read-only) is used without it."""
    try:
        fh = open(path, "a")
    except OSError:
        yield
        return
    with fh:
        fcntl.flock(fh, mode)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def snapshot_generated(config: observers.ObserverConfig, dest: Path) -> str:
    """Copy the generated folder of ``config`` into ``dest`` (each file read once), holding the
    lock ``generate`` and ``design --update`` write under (shared: they wait for the copy, and
    the copy for them), then check the copy against its stamp (:func:`check_generated`);
    returns the copy's lock text. What is compiled, checked and hashed afterwards is this copy
    alone: a design changed on disk while the extension builds cannot mix into it."""
    src_dir = generated_dir(config)
    outputs.make_folder(dest)
    with _flock(src_dir.parent / ".generate.lock", fcntl.LOCK_SH):
        try:
            files = [p for p in src_dir.iterdir() if p.is_file()] if src_dir.is_dir() else []
            for p in files:
                (dest / p.name).write_bytes(p.read_bytes())
        except FileNotFoundError:      # the folder swapped by a generate without the lock: its stamp says
            pass
    return _verify_generated(config, dest, where=src_dir)


BUILD_LOCK = ".build.lock"


def remove_leftovers(ext_dir: Path, name: str) -> list:
    """Remove the staging folders (``.NAME.new-*``) of ``ext_dir`` that builds of ``name`` killed
    before they finished left behind; call it holding the build lock of ``name`` (no live build
    of ``name`` has one then). Returns the folders removed."""
    import shutil
    gone = []
    for leftover in sorted(Path(ext_dir).glob(f".{name}.new-*")):
        if leftover.is_dir():
            shutil.rmtree(leftover, ignore_errors=True)
            gone.append(leftover)
    return gone


def build_extension(observer, extra_flags: list | None = None, ext_dir: Path | None = None,
                    suffix: str = "", log=None) -> Path:
    """Compile observer ``observer`` (a name, an observer-file path or a config) and install the
    extension module only if its step conforms to the model; returns the installed path.

    1. The hashes of the observer file, the parameter file and the model are taken (compiled
       into the extension: :mod:`python_bindings.integrity`).
    2. The generated folder is copied into a staging folder beside the target, holding the lock
       of ``generate`` (:func:`snapshot_generated`), and the copy is checked against its stamp.
    3. The copy's C is compiled there, with the SHA-256 of the copy's design lock.
    4. The module is loaded from there and checked against independent evaluations of the copy's
       design (:func:`codegen.extension.conformance.check`: signal layout, then numbers across every declared box).
    5. Only then the SHA-256 of its bytes is recorded beside the target, and it replaces the
       installed module (one rename): a failed check leaves the previous extension as it was and
       raises :class:`~codegen.errors.ConformanceError`.

    One build of an observer at a time (a second waits: ``build/objects/NAME/.build.lock``); it
    removes the staging folders of builds killed before they finished.
    """
    import shutil
    from .. import pipeline
    from . import conformance
    config = _config(observer)
    name = config.name
    src_dir = generated_dir(config)
    extra = SPEED_FLAGS + (LTO_FLAGS if lto_supported() else []) + list(extra_flags or [])
    workspace = config.workspace
    ext_dir = Path(ext_dir) if ext_dir is not None else workspace.extensions
    build_dir = outputs.make_folder(workspace.objects(name))
    outputs.make_folder(ext_dir)
    module_file = workspace.extension(name).name
    target = ext_dir / module_file
    with _flock(build_dir / BUILD_LOCK, fcntl.LOCK_EX):
        remove_leftovers(ext_dir, name)
        # the sources before the stamp check: one edited after it differs from what is recorded
        sources = json.dumps(source_record(config), sort_keys=True)
        staging = outputs.make_temp_folder(f".{name}.new-", ext_dir)
        try:
            snap = staging / "generated"
            lock_text = snapshot_generated(config, snap)
            lock_name = design_lock.path(config).name
            signals = header_signals((snap / f"{name}.h").read_text(), name)
            glue = outputs.write_atomic(build_dir / f"{name}_pymodule.c", render_template(
                "pymodule.c.j2", name=name, NAME=name.upper(), signals=signals, c_string=c_string,
                design_sha256=hashlib.sha256((snap / lock_name).read_bytes()).hexdigest(), sources=sources))
            import numpy
            glue_flags = [*GLUE_FLAGS, "-I", sysconfig.get_paths()["include"], "-I", numpy.get_include()]
            candidate = compile_and_link([snap / f"{name}_kernel.c", snap / f"{name}.c", glue],
                                         staging / module_file, include=[snap], flags=STRICT_FLAGS,
                                         extra_flags=extra, source_flags={glue: glue_flags}, shared=True,
                                         object_dir=build_dir, suffix=suffix)
            spec = importlib.util.spec_from_file_location(f"_{name}", candidate)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            data = json.loads(lock_text)
            where = str(src_dir / lock_name)
            design_lock.verify(data, where, config.name if config.builtin else config.source)
            report = conformance.check(pipeline.build(config, design_lock.replay(data, where)), module, snap, data)
            key = build_key(snap, sources, extra, suffix, module_file)
            with outputs.writing(target):
                outputs.write_atomic(integrity.record_path(target),
                                     integrity.record_text(candidate.read_bytes(), module_file))
                os.replace(candidate, target)
        finally:
            shutil.rmtree(staging, ignore_errors=True)
        # the evidence the extension was installed on, beside its objects: a reader checks that its
        # design hash is the installed module's (a build killed between the two writes leaves them apart)
        record = {"extension": module_file, "design_sha256": module.DESIGN_SHA256, "build_key": key,
                  **report.as_record()}
        outputs.write_atomic(build_dir / CONFORMANCE_RECORD, json.dumps(record, indent=1) + "\n")
    if log is not None:
        log(f"{name}: {report.line()}")
    return target


def build_key(generated: Path, sources: str, extra: list, suffix: str, module_file: str) -> str:
    """The SHA-256 of everything an installed extension is made from and checked by: every file of the
    generated folder ``generated`` (the C, the header, the design lock), the hashes of the files the design
    is made from (``sources``), the compiler and every flag, the Python ABI and numpy the glue is compiled
    against, the glue's template and the conformance check that let it be installed."""
    import numpy
    from . import conformance
    from ..emit.toolchain import TEMPLATES
    h = hashlib.sha256()
    for p in sorted(q for q in generated.iterdir() if q.is_file()):
        h.update(p.name.encode() + b"\0" + hashlib.sha256(p.read_bytes()).digest())
    for part in (sources, compiler(), " ".join(STRICT_FLAGS), " ".join(GLUE_FLAGS), " ".join(extra), suffix,
                 module_file, sys.version, numpy.__version__):
        h.update(part.encode() + b"\0")
    for f in (TEMPLATES / "pymodule.c.j2", Path(conformance.__file__), Path(__file__)):
        h.update(hashlib.sha256(f.read_bytes()).digest())
    return h.hexdigest()


def installed_unchanged(config: observers.ObserverConfig, extra_flags: list | None = None) -> dict | None:
    """The conformance record of ``config``'s installed extension when nothing it is made from changed since
    it was built and checked (:func:`build_key` of the generated folder now, under the lock of ``generate``,
    equals the one recorded, and the extension's bytes are those its build record holds); else None."""
    name = config.name
    src_dir = generated_dir(config)
    target = config.workspace.extensions / config.workspace.extension(name).name
    record = conformance_record(config)
    if not record.get("build_key") or record.get("extension") != target.name or not target.is_file():
        return None
    if integrity.binary_mismatch(target):
        return None
    extra = SPEED_FLAGS + (LTO_FLAGS if lto_supported() else []) + list(extra_flags or [])
    sources = json.dumps(source_record(config), sort_keys=True)
    with _flock(src_dir.parent / ".generate.lock", fcntl.LOCK_SH):
        if not src_dir.is_dir():
            return None
        key = build_key(src_dir, sources, extra, "", target.name)
    return record if key == record["build_key"] else None


def source_record(config: observers.ObserverConfig) -> dict:
    """The hashes of the files ``config``'s design is made from, as the extension records them
    (:func:`python_bindings.integrity.source_digests`); {} for a configuration without a file."""
    if not config.source:
        return {}
    try:
        from ..design.sources import helper_modules
        return integrity.source_digests(config.source, config.parameter_path, config.model_path,
                                        helper_modules(config.model_path))
    except integrity.SourceFileUnreadable as exc:
        from ..errors import ConfigurationError
        raise ConfigurationError(f"{config.source}: {exc.args[0]}", source=str(config.source)) from None
    except OSError as exc:
        raise UnknownObserverError(f"{exc.filename}: cannot be read ({exc.strerror}); the extension of "
                                   f"{config.name} records it") from None


CONFORMANCE_RECORD = "conformance.json"


def conformance_record(config) -> dict:
    """What the last conformance check that installed ``config``'s extension measured
    (:func:`build_extension`), or {} when there is none."""
    path = config.workspace.objects(config.name) / CONFORMANCE_RECORD
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def generated_names(project: Path | None = None) -> list:
    """Built-in observers that have been generated in ``project`` (default: the built-in
    observers' project, :mod:`python_bindings.workspace`)."""
    builtin = set(observers.names())
    ws = Workspace.of(project if project is not None else source_checkout())
    return [n for n in ws.generated_names() if n in builtin]


def c_string(text: str) -> str:
    """``text`` as a C string literal: printable ASCII as is, anything else (quotes, backslashes,
    UTF-8 bytes) as octal escapes."""
    out = []
    for byte in text.encode():
        ch = chr(byte)
        out.append(ch if 32 <= byte < 127 and ch not in '"\\?' else f"\\{byte:03o}")
    return '"' + "".join(out) + '"'


def load(observer) -> CompiledObserver:
    """The compiled extension of an observer (:func:`python_bindings.load`): a built-in name, the
    path of an observer file, or an :class:`~codegen.project.observer_file.ObserverConfig`, from
    its project (built by ``make build`` / ``uiogen build``)."""
    config = _config(observer)
    argument = config.name if config.builtin else config.source
    if config.workspace != Workspace.locate(argument)[0]:
        argument += f" --project {config.workspace.root}"
    return open_observer(config.workspace, config.name, argument, observer_file=config.source)


def require_built(verb: str, make_target: str) -> list:
    """The built-in observers' names, once every one has its extension here; else one
    UnsupportedError before any work (an installed uiogen in an empty folder has none of them)."""
    names = observers.names()
    missing = [n for n in names if not observers.get(n).workspace.extension(n).is_file()]
    if missing:
        raise UnsupportedError(f"uiogen {verb} runs every built-in observer; {len(missing)} of {len(names)} are not "
                               f"built here ({', '.join(missing[:3])}{', ...' if len(missing) > 3 else ''}): run "
                               f"`uiogen generate` and `uiogen build` first (in a checkout: make {make_target})")
    return names


def require_current(config: observers.ObserverConfig) -> None:
    """Refuse to run an observer whose committed design is not the one its files describe now
    (the observer file, parameters or model changed since ``uiogen generate``): its C and its
    extension are of the old design. :func:`load` refuses an extension of another lock; this is
    the check before it, for the commands that run a compiled observer (validate, export, campaign).

    Raises
    ------
    DesignLockError
        The lock is missing or stale (names the commands that bring it up to date), or edited.
    """
    how = config.name if config.builtin else config.source
    data, why = design_lock.status(config)
    if data is None:
        raise DesignLockError(f"{config.name}: the committed design {design_lock.path(config)} is not the current one "
                              f"({why}), so neither is its C or its extension: run `uiogen generate {how}` and "
                              f"`uiogen build {how}`")


def main(argv=None, project: Path | None = None, force: bool = False) -> int:
    """``uiogen build [NAME ...]``: compile the named observers (default: every generated built-in
    one) into their project's ``build/extensions/``, or ``project``'s. An observer whose installed
    extension was built and checked from exactly what is there now (:func:`installed_unchanged`) is
    skipped, saying so, unless ``force``."""
    names = (argv if argv is not None else sys.argv[1:]) or generated_names(project)
    for name in names:
        config = observers.get(name, project=project)
        kept = None if force else installed_unchanged(config)
        if kept is not None:
            print(f"{config.name}: unchanged (the installed extension was built from this generated C and these "
                  f"files, and passed its conformance check: {kept.get('samples', '?')} samples), skipped; "
                  f"--force builds and checks it again")
            continue
        path = build_extension(config, log=print)
        try:
            shown = path.relative_to(config.workspace.root)
        except ValueError:
            shown = path
        print(f"{config.name}: built {shown}")
    return 0
