"""The compiled step as a CPython extension: build it from the generated C, load it.

The observer's C is compiled with the project's strict flags (:data:`codegen.emit.toolchain.STRICT_CFLAGS`,
no fast-math, ``-ffp-contract=off`` so results do not depend on FMA availability) plus the speed
flags below; the Python glue is rendered from ``codegen/emit/templates/pymodule.c.j2`` and
linked with it. :mod:`python_bindings` is the user-facing name of :func:`load` and
:class:`CompiledObserver`.

Where things go: the observer's project (:mod:`codegen.project.workspace`): the extension in
``build/extensions/``, its objects in ``build/objects/NAME/``.
"""
from __future__ import annotations

import contextlib
import importlib.util
import json
import os
import sys
import sysconfig
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..design import lock as design_lock
from ..project import observer_file as observers
from ..project.workspace import Workspace, source_checkout
from ..errors import DesignLockError, SampleError, StaleExtensionError, UnknownObserverError
from ..emit.toolchain import STRICT_CFLAGS, compile_and_link, compiler, render_template, run

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
# Open recordings of the inputs given to CompiledObserver.run (see :func:`recording`).
_RECORDINGS: list = []


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
    :func:`codegen.emit.stamp_matches`): an edited, truncated or stale C file is never compiled.

    Raises
    ------
    UnknownObserverError
        nothing generated yet.
    GenerationError
        the folder does not match its stamp (names the command that regenerates it).
    """
    from ..emit import generate as emit
    from ..errors import GenerationError
    name = config.name
    src_dir = generated_dir(config)
    how = config.source if not config.builtin else name
    if not (src_dir / f"{name}.h").is_file():
        raise UnknownObserverError(f"observer {name!r} has not been generated (no {src_dir / (name + '.h')}); "
                                   f"run `uiogen generate {how}`")
    lock = design_lock.path(config)
    try:
        lock_text = lock.read_text()
    except OSError:
        raise UnknownObserverError(f"observer {name!r} has no design lock {lock}; run `uiogen generate {how}`") from None
    if not emit.stamp_matches(src_dir, emit.emission_inputs(config, lock_text)):
        raise GenerationError(f"{src_dir} does not match its stamp {emit.STAMP}: its C was edited, or the design, "
                              f"model or toolchain changed since it was generated; run `uiogen generate {how}` "
                              f"(the C is never compiled as found)")
    return lock_text


def build_extension(observer, extra_flags: list | None = None, ext_dir: Path | None = None,
                    suffix: str = "", log=None) -> Path:
    """Compile observer ``observer`` (a name, an observer-file path or a config) and install the
    extension module only if its step conforms to the model; returns the installed path.

    1. The generated folder matches its stamp (:func:`check_generated`).
    2. The C is compiled into a temporary folder beside the target.
    3. The module is loaded from there and checked against independent evaluations of its model
       (:func:`codegen.conformance.check`: signal layout, then numbers across every declared box).
    4. Only then it replaces the installed module (one rename): a failed check leaves the previous
       extension as it was and raises :class:`~codegen.errors.ConformanceError`.
    """
    import shutil
    from .. import pipeline
    from . import conformance
    config = _config(observer)
    name = config.name
    src_dir = generated_dir(config)
    lock_text = check_generated(config)
    extra = SPEED_FLAGS + (LTO_FLAGS if lto_supported() else []) + list(extra_flags or [])
    workspace = config.workspace
    ext_dir = Path(ext_dir) if ext_dir is not None else workspace.extensions
    build_dir = workspace.objects(name)
    build_dir.mkdir(parents=True, exist_ok=True)
    ext_dir.mkdir(parents=True, exist_ok=True)
    glue = build_dir / f"{name}_pymodule.c"
    # the design hash of the lock the C was generated from: load() refuses the module beside another lock
    design_hash = json.loads(lock_text)["lock"]["sha256"]
    glue.write_text(render_template("pymodule.c.j2", name=name, NAME=name.upper(), design_hash=design_hash))
    import numpy
    glue_flags = [*GLUE_FLAGS, "-I", sysconfig.get_paths()["include"], "-I", numpy.get_include()]
    module_file = f"_{name}{sysconfig.get_config_var('EXT_SUFFIX')}"
    staging = Path(tempfile.mkdtemp(prefix=f".{name}.new-", dir=ext_dir))
    try:
        candidate = compile_and_link(observer_sources(config) + [glue], staging / module_file, include=[src_dir],
                                     flags=STRICT_FLAGS, extra_flags=extra, source_flags={glue: glue_flags},
                                     shared=True, object_dir=build_dir, suffix=suffix)
        spec = importlib.util.spec_from_file_location(f"_{name}", candidate)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        report = conformance.check(pipeline.build(config), module, src_dir, json.loads(lock_text))
        target = ext_dir / module_file
        os.replace(candidate, target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    if log is not None:
        log(f"{name}: {report.line()}")
    return target


def generated_names(project: Path | None = None) -> list:
    """Built-in observers that have been generated in ``project`` (default: the built-in
    observers' project, :mod:`codegen.project.workspace`)."""
    builtin = set(observers.names())
    ws = Workspace.of(project if project is not None else source_checkout())
    return [n for n in ws.generated_names() if n in builtin]


@dataclass(frozen=True)
class CompiledObserver:
    """A compiled observer step and the names of its vectors."""

    name: str
    module: object
    state_names: tuple
    input_names: tuple
    sample_time: float
    output_names: tuple = ()

    @property
    def step(self):
        if not _RECORDINGS:
            return self.module.step
        step = self.module.step

        def recorded(state, inputs, out):
            for rec in _RECORDINGS:
                rec.append((self.name, np.array(inputs, dtype=np.float64, copy=True), None))
            return step(state, inputs, out)
        return recorded

    @property
    def n_state(self) -> int:
        return self.module.N_STATE

    @property
    def n_input(self) -> int:
        return self.module.N_INPUT

    @property
    def n_output(self) -> int:
        return self.module.N_OUTPUT

    @property
    def status_bits(self) -> dict:
        return {k: getattr(self.module, k) for k in
                ("OK", "SCHEDULING_CLAMPED", "NONFINITE_INPUT", "NUMERICAL_FAILURE", "WARMING_UP")}

    def output_index(self, signal: str) -> int:
        """Column of ``signal`` in the outputs."""
        try:
            return self.output_names.index(signal)
        except ValueError:
            raise UnknownObserverError(f"{self.name} has no output {signal!r}; outputs: "
                                       f"{', '.join(self.output_names)}") from None

    def initial_state(self) -> np.ndarray:
        return np.zeros(self.n_state)

    def run(self, inputs, state=None):
        """Run over an (n, n_input) array; returns (outputs (n, n_output), status (n,), final state)."""
        inputs = np.ascontiguousarray(inputs, dtype=np.float64)
        if inputs.ndim != 2 or inputs.shape[1] != self.n_input:
            raise SampleError(f"{self.name}: inputs must have shape (n, {self.n_input}) with columns "
                              f"{', '.join(self.input_names)}; got {inputs.shape}")
        state = self.initial_state() if state is None else np.array(state, dtype=np.float64)
        if state.shape != (self.n_state,):
            raise SampleError(f"{self.name}: state must have shape ({self.n_state},), got {state.shape}")
        for rec in _RECORDINGS:
            rec.append((self.name, inputs.copy(), state.copy()))
        n = inputs.shape[0]
        outputs = np.empty((n, self.n_output))
        status = np.empty(n, dtype=np.int32)
        self.module.run(state, inputs, outputs, status, n)
        return outputs, status, state


@contextlib.contextmanager
def recording():
    """Record what :meth:`CompiledObserver.run` (and ``step``) is given inside the block: yields
    a list that fills with (observer name, inputs, initial state) per call (one input row and
    None for a step), e.g. the input sequence of a
    validation scenario, to replay it through the FMU or a cross-compiled build."""
    rec: list = []
    _RECORDINGS.append(rec)
    try:
        yield rec
    finally:
        _RECORDINGS.remove(rec)


def load(observer) -> CompiledObserver:
    """The compiled extension of an observer: a built-in name, the path of an observer file, or
    an :class:`~codegen.project.observer_file.ObserverConfig` (built by ``make build`` / ``uiogen build``)."""
    config = _config(observer)
    name = config.name
    how = name if config.builtin else config.source
    design = design_lock.path(config)
    if not design.is_file():
        raise UnknownObserverError(f"observer {name!r} has not been generated (no {design}); run `uiogen generate`")
    path = config.workspace.extension(name)
    key = f"uiogen_ext_{abs(hash(str(path)))}__{name}"
    module = sys.modules.get(key)
    if module is None:
        if not path.is_file():
            raise UnknownObserverError(f"observer {name!r} is generated but not compiled (no {path}); run "
                                       f"`uiogen build {name if config.builtin else config.source}`")
        spec = importlib.util.spec_from_file_location(f"_{name}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules[key] = module
    try:
        art = json.loads(design.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DesignLockError(f"{design}: unreadable design lock ({type(exc).__name__}); run `uiogen generate {how}`") \
            from None
    lock_hash = design_lock.verify(art, str(design), how)
    built = getattr(module, "DESIGN_HASH", None)
    if built != lock_hash:
        raise StaleExtensionError(f"{path} was built from another design than the lock {design} (design hash "
                                  f"{(built or 'none')[:12]} in the extension, {lock_hash[:12]} in the lock): run "
                                  f"`uiogen build {how}`")
    signals = art["signals"]
    return CompiledObserver(name, module, tuple(signals["state"]), tuple(signals["input"]),
                            float(art["config"]["sample_time"]), tuple(signals.get("output", signals["state"])))


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


def main(argv=None, project: Path | None = None) -> int:
    """``uiogen build [NAME ...]``: compile the named observers (default: every generated built-in
    one) into their project's ``build/extensions/``, or ``project``'s."""
    names = (argv if argv is not None else sys.argv[1:]) or generated_names(project)
    for name in names:
        config = observers.get(name, project=project)
        path = build_extension(config, log=print)
        try:
            shown = path.relative_to(config.workspace.root)
        except ValueError:
            shown = path
        print(f"{config.name}: built {shown}")
    return 0
