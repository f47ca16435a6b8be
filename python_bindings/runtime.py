"""Loading and running a compiled observer: numpy and the extension, nothing of the toolchain.

The extension module carries everything :class:`CompiledObserver` shows (compiled in by
``uiogen build`` from the generated C and its design lock): its signal names and units, the
sample time, and the SHA-256 of the design lock it was built from. :func:`load` finds the
extension by the workspace rule (:mod:`python_bindings.workspace`: the folder and stem of the
observer file, or a built-in name) and refuses, before the extension is used:

* one whose bytes are not those ``uiogen build`` recorded beside it (truncated, overwritten:
  :class:`~python_bindings.errors.DamagedExtensionError`, checked before it is loaded);
* one whose design hash is not that of the design lock beside it
  (:class:`~python_bindings.errors.StaleExtensionError`);
* one whose observer file, parameter file or model changed since it was built
  (:class:`~python_bindings.errors.ChangedSourceError`; a source file that is absent, as in a
  deployment of the extension and its lock alone, is not checked: :mod:`python_bindings.integrity`);
* an observer file that is not UTF-8 TOML (:class:`~python_bindings.errors.SourceFileError`).
"""
from __future__ import annotations

import difflib
import hashlib
import importlib.util
import sys
from pathlib import Path

import numpy as np

from . import integrity
from .errors import (ChangedSourceError, DamagedExtensionError, SampleError, SourceFileError, StaleExtensionError,
                     UnknownObserverError)
from .workspace import BUILTIN_OBSERVERS, Workspace

STATUS_BITS = ("OK", "SCHEDULING_CLAMPED", "NONFINITE_INPUT", "NUMERICAL_FAILURE", "WARMING_UP")


class CompiledObserver:
    """A compiled observer step and what its vectors hold.

    ``step(state, inputs, out) -> status`` is the extension's C function itself, a method of the
    subclass the extension makes (:func:`observer_class`; no Python in between); ``run`` loops
    in C over a whole array. Names, units and the sample time come from the extension.
    """

    # no "step": it is a method of the extension's subclass (observer_class)
    __slots__ = ("name", "module", "path", "state_names", "input_names", "output_names",
                 "state_units", "input_units", "output_units", "sample_time", "design_sha256")

    def __init__(self, module, path: Path):
        self.module = module
        self.path = Path(path)
        self.name = module.NAME
        self.state_names, self.input_names, self.output_names = (module.STATE_NAMES, module.INPUT_NAMES,
                                                                 module.OUTPUT_NAMES)
        self.state_units, self.input_units, self.output_units = (module.STATE_UNITS, module.INPUT_UNITS,
                                                                 module.OUTPUT_UNITS)
        self.sample_time = module.SAMPLE_TIME
        self.design_sha256 = module.DESIGN_SHA256

    def __repr__(self) -> str:
        return f"<CompiledObserver {self.name} from {self.path}>"

    # The object holds no state (a run's state is the caller's array) and nothing the extension does
    # not carry: a copy is the object itself, and a pickle (multiprocessing, concurrent.futures) opens
    # the same extension file again in the receiving process, refused there if it was rebuilt since.
    def __copy__(self):
        return self

    def __deepcopy__(self, memo):
        return self

    def __reduce__(self):
        return _reopen, (str(self.path), self.name, self.design_sha256)

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
        return {k: getattr(self.module, k) for k in STATUS_BITS}

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
        """Run over an (n, n_input) array; returns (outputs (n, n_output), status (n,), final state).

        ``inputs`` and ``state`` must hold real numbers (float or integer dtypes): complex, string,
        boolean or object arrays are refused, not converted (a complex part would be dropped, a
        string parsed). One state must not be run by two threads at once: the compiled module
        refuses a state (or an output) that another thread's run is using (RuntimeError)."""
        inputs = np.ascontiguousarray(real(inputs, self.name, "inputs"), dtype=np.float64)
        if inputs.ndim != 2 or inputs.shape[1] != self.n_input:
            raise SampleError(f"{self.name}: inputs must have shape (n, {self.n_input}) with columns "
                              f"{', '.join(self.input_names)}; got {inputs.shape}")
        state = (self.initial_state() if state is None
                 else np.array(real(state, self.name, "state"), dtype=np.float64))
        if state.shape != (self.n_state,):
            raise SampleError(f"{self.name}: state must have shape ({self.n_state},), got {state.shape}")
        n = inputs.shape[0]
        outputs = np.empty((n, self.n_output))
        status = np.empty(n, dtype=np.int32)
        self.module.run(state, inputs, outputs, status, n)
        return outputs, status, state


def _reopen(path: str, name: str, design_sha256: str) -> CompiledObserver:
    """The observer a pickle names: the extension at ``path`` (``PROJECT/build/extensions/``), checked
    as :func:`load` checks it, of the design it was pickled with."""
    workspace = Workspace(Path(path).parents[2])
    if workspace.extension(name) != Path(path):
        raise UnknownObserverError(f"{path} is not where uiogen build puts observer {name!r}; load() it by its "
                                   f"observer file in this process")
    obs = open_observer(workspace, name)
    if obs.design_sha256 != design_sha256:
        raise StaleExtensionError(f"the extension {path} was rebuilt from another design since the observer was "
                                  f"pickled; load() the observer again and send that")
    return obs


def observer_class(module) -> type:
    """The class of ``module``'s observers: a subclass of :class:`CompiledObserver` that the
    extension makes (``module.observer_type``) with ``step`` as its own method. CPython calls
    ``obs.step(...)`` directly (the lookup specialized, about 1 ns) only for a method of
    ``type(obs)`` itself; the module's function held by the instance was looked up and called the
    generic way on every call (about 11 ns, 13 % of the core observer's step)."""
    cls = module.__dict__.get("_uiogen_observer_class")
    if cls is None:
        cls = module.observer_type(CompiledObserver)
        cls.__doc__ = CompiledObserver.__doc__
        module._uiogen_observer_class = cls
    return cls


def real(a, name: str, what: str) -> np.ndarray:
    """``a`` as an array of real numbers, or a SampleError: numpy would drop a complex part
    (ComplexWarning) and parse strings ('1.5') where the caller meant numbers, and a masked array's
    mask."""
    if isinstance(a, np.ma.MaskedArray) and np.ma.is_masked(a):
        # np.asarray drops the mask: the masked samples' stored values would be run as measurements
        raise SampleError(f"{name}: {what} is a masked array with {int(np.ma.count_masked(a))} masked entries; the "
                          f"step runs every sample it is given: pass the samples to use (a[~a.mask]), or fill "
                          f"the masked ones on purpose (a.filled(value))")
    arr = np.asarray(a)
    if arr.dtype.kind not in "fiu":
        why = "a complex part would be dropped" if arr.dtype.kind == "c" else "not numbers"
        raise SampleError(f"{name}: {what} must be real numbers (a float or integer array), got dtype {arr.dtype} "
                          f"({why})")
    return arr


class Recorder:
    """A compiled observer that records what it is given: ``calls`` fills with (inputs, initial
    state) per ``run`` and (input row, None) per ``step``, e.g. the input sequence of a
    validation scenario, to replay it through the FMU or a cross-compiled build. Pass it where a
    compiled observer is run (``codegen.validation.run.run_scenario(..., observer=Recorder(obs))``)."""

    def __init__(self, observer: CompiledObserver):
        self.observer = observer
        self.calls: list = []

    def __getattr__(self, attr):          # names, units, sizes: those of the observer
        return getattr(self.observer, attr)

    def step(self, state, inputs, out):
        self.calls.append((np.array(inputs, dtype=np.float64, copy=True), None))
        return self.observer.step(state, inputs, out)

    def run(self, inputs, state=None):
        inputs = np.ascontiguousarray(real(inputs, self.name, "inputs"), dtype=np.float64)
        first = (self.observer.initial_state() if state is None
                 else np.array(real(state, self.name, "state"), dtype=np.float64))
        self.calls.append((inputs.copy(), first.copy()))
        return self.observer.run(inputs, first)


def load(observer, project: str | Path | None = None) -> CompiledObserver:
    """The compiled observer of ``observer``: a built-in observer's name or the path of an
    observer file (built by ``uiogen build``); ``project``: its project folder when it is not
    the default (:mod:`python_bindings.workspace`)."""
    workspace, name = Workspace.locate(observer, project)
    text = str(observer)
    is_path = text.endswith(".toml") or "/" in text
    if not workspace.design_lock(name).is_file() or not (is_path or (BUILTIN_OBSERVERS / f"{text}.toml").is_file()):
        # a bare name is a built-in's: one of the user's own, generated here, would load without the
        # check of its observer file, parameters and model (the CLI refuses it too)
        _refuse_unknown(text, workspace.design_lock(name))
    source = Path(text) if is_path else BUILTIN_OBSERVERS / f"{text}.toml"
    return open_observer(workspace, name, text + (f" --project {project}" if project is not None else ""),
                         observer_file=source)


def _refuse_unknown(text: str, lock: Path) -> None:
    """A path to no observer file, or a name no built-in observer has, said as such (not as an
    observer that was never generated)."""
    if text.endswith(".toml") or "/" in text:
        if not Path(text).is_file():
            folder = Path(text).parent
            siblings = sorted(p.name for p in folder.glob("*.toml")) if folder.is_dir() else []
            close = difflib.get_close_matches(Path(text).name, siblings, n=1)
            raise UnknownObserverError(f"no observer file {text} (and no generated design {lock}): check the path"
                                       + (f" (did you mean {str(folder / close[0])!r}?)" if close else ""))
    elif not (BUILTIN_OBSERVERS / f"{text}.toml").is_file():
        known = sorted(p.stem for p in BUILTIN_OBSERVERS.glob("*.toml"))
        close = difflib.get_close_matches(text, known, n=1)
        own = Path(f"{text}.toml")
        raise UnknownObserverError(f"{text!r} is not a built-in observer"
                                   + (f" (did you mean {close[0]!r}?)" if close else f" (built-in: {', '.join(known)})")
                                   + "; for an observer of your own, pass the path of its observer file"
                                   + (f": load({str(own)!r})" if own.is_file() else " (.toml)"))


def open_observer(workspace: Workspace, name: str, argument: str | None = None,
                  observer_file: str | Path | None = None) -> CompiledObserver:
    """The compiled observer ``name`` of ``workspace``; ``argument``: how the commands the
    errors suggest name it (default ``name``); ``observer_file``: the observer file it was built
    from, whose sources are checked against those the extension records (module docstring);
    None checks none."""
    argument = argument or name
    lock = workspace.design_lock(name)
    if not lock.is_file():
        raise UnknownObserverError(f"observer {name!r} has not been generated (no {lock}); "
                                   f"run `uiogen generate {argument}`")
    path = workspace.extension(name)
    key = f"uiogen_ext_{hashlib.sha256(str(path).encode()).hexdigest()[:16]}_{name}"
    module = sys.modules.get(key)
    if module is not None and path.is_file() and _file_identity(path) != _LOADED_FROM.get(key):
        module = None          # rebuilt since this process loaded it: load the new build, not the one held
    if module is None:
        if not path.is_file():
            raise UnknownObserverError(f"observer {name!r} is generated but not compiled (no {path}); "
                                       f"run `uiogen build {argument}`")
        # before dlopen: a truncated object dies of SIGBUS (its record may have been recomputed: the structure too)
        damage = integrity.binary_mismatch(path) or integrity.elf_truncation(path)
        if damage:
            raise DamagedExtensionError(f"the extension {path} is not loaded: {damage}; run `uiogen build {argument}`")
        identity = _file_identity(path)
        module = _import_extension(name, path, argument, again=key in sys.modules)
        sys.modules[key] = module
        _LOADED_FROM[key] = identity
    design = hashlib.sha256(lock.read_bytes()).hexdigest()
    if getattr(module, "DESIGN_SHA256", None) != design:
        raise StaleExtensionError(f"the extension {path} was built from another design than {lock} (the design "
                                  f"changed since the last build); run `uiogen build {argument}`")
    if not hasattr(module, "observer_type") or not hasattr(module, "SOURCES"):
        raise StaleExtensionError(f"the extension {path} was built by an older uiogen (it has no "
                                  f"{'observer_type' if not hasattr(module, 'observer_type') else 'SOURCES'}); "
                                  f"run `uiogen build {argument}`")
    if observer_file is not None:
        _check_sources(module, path, Path(observer_file), argument)
    return observer_class(module)(module, path)


_ABSENT = object()

# {module key: (device, inode, size, mtime) of the file the module held under it was loaded from}
_LOADED_FROM: dict = {}


def _file_identity(path: Path) -> tuple:
    st = path.stat()
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns


def _import_extension(name: str, path: Path, argument: str, again: bool):
    """The extension module in ``path``. ``again``: this process already holds a module loaded from
    ``path`` (an earlier build). Python keeps an extension module per (file name, module name), so
    the new build is imported from a copy under another file name; the copy is removed once loaded
    (the mapping stays)."""
    import shutil
    import tempfile

    def imported(file: Path):
        spec = importlib.util.spec_from_file_location(f"_{name}", file)
        # CPython files a single-phase extension module under its own name (_NAME) in sys.modules as
        # it loads: an observer named socket, io or ssl would replace the standard library's _socket,
        # _io, _ssl there. The module is held under a key private to uiogen (open_observer), so
        # whatever sys.modules held under _NAME before is put back.
        before = sys.modules.get(spec.name, _ABSENT)
        try:
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
        finally:
            if before is _ABSENT:
                sys.modules.pop(spec.name, None)
            else:
                sys.modules[spec.name] = before
        return module
    if not again:
        return imported(path)
    with tempfile.TemporaryDirectory(prefix="uiogen-reload-") as tmp:
        copy = Path(tmp) / path.name
        shutil.copyfile(path, copy)
        damage = integrity.binary_mismatch(path, copy)     # the file may have been rebuilt again meanwhile
        if damage:
            raise DamagedExtensionError(f"the extension {path} is not loaded: {damage}; run `uiogen build {argument}`")
        return imported(copy)


def _check_sources(module, path: Path, observer_file: Path, argument: str) -> None:
    """Refuse ``module`` when a file it was built from changed since (:mod:`python_bindings.integrity`)."""
    import json
    try:
        recorded = json.loads(module.SOURCES)
        changed = integrity.changed_sources(recorded, observer_file)
    except integrity.SourceFileUnreadable as exc:
        raise SourceFileError(f"{exc.args[1]}: the observer file cannot be read: {exc.args[0]}; fix or restore it "
                              f"(an observer file is UTF-8 TOML)") from None
    except (ValueError, KeyError, TypeError):
        raise StaleExtensionError(f"the extension {path} has no readable record of its sources; "
                                  f"run `uiogen build {argument}`") from None
    except OSError as exc:
        raise SourceFileError(f"{exc.filename}: cannot be read ({exc.strerror}); the extension {path} is "
                              f"checked against it") from None
    if changed:
        role, file = changed[0]
        others = "".join(f", and {r} {f}" for r, f in changed[1:])
        raise ChangedSourceError(f"{file} (the {role} of {module.NAME}){others} changed since the extension {path} "
                                 f"was built: its compiled step is of the old files, so it is not used; run "
                                 f"`uiogen generate {argument}` (it re-solves the design where it changed) and "
                                 f"`uiogen build {argument}`", path=file)
