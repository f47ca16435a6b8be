"""``uiogen generate``: every observer of a project through the stages, into its ``generated_c/``.

For each observer the committed design lock is replayed (:func:`codegen.pipeline.build` with
:func:`codegen.design.lock.replay`), or a missing or stale one re-solved (:func:`codegen.pipeline.solve`),
and :mod:`codegen.emit.generate` renders its C, stamps it and puts the folder in place whole. This
module stands above the stages it walks: the pipeline runs the family the observer file names
(``config.observer_family``), emit renders what the pipeline returns, and neither imports this loop.
"""
from __future__ import annotations

from pathlib import Path

from . import pipeline
from .certificate import text
from .design import lock as design_lock
from .design.solver import progress_after
from .emit import generate as emit
from .errors import GenerationError, UiogenError
from .project import observer_file as observers


def generate(names: list | None = None, out_dir: Path | None = None, force: bool = False,
             log=print, project: Path | None = None) -> list:
    """Generate the C of the named observers (built-in names, observer-file paths or
    configurations; all built-in ones if None); returns the builds that ran.

    Each observer's files go to ``out_dir/NAME/`` (default: its project's ``generated_c/``,
    :mod:`python_bindings.workspace`; ``project`` names another project folder).
    The design comes from the committed lock, replayed without solving; only a missing or stale
    lock is re-solved (and written with the C). An observer whose stamp matches its inputs and
    whose files are intact is skipped unless ``force``. One failing observer does not stop the
    others: each failure is reported, and :class:`GenerationError` lists them at the end.
    """
    done, failed = [], []
    for name in names or observers.names():
        label = getattr(name, "name", name)
        try:
            config = observers.get(name, project=project)
            target_dir = Path(out_dir) if out_dir is not None else config.workspace.generated
            with emit.exclusive(target_dir):
                b = _generate_one(config, target_dir, force, log)
        except UiogenError as exc:
            log(f"{label}: FAILED: {type(exc).__name__}: {exc}")
            failed.append(f"{label} ({type(exc).__name__})")
            continue
        if b is not None:
            done.append(b)
    if failed:
        raise GenerationError(f"{len(failed)} observer(s) failed to generate: {', '.join(failed)}; "
                              f"the others were generated")
    return done


def _generate_one(config: observers.ObserverConfig, out_dir: Path, force: bool, log):
    name = config.name
    target = out_dir / name
    emit.recover(target, log)
    data, why = design_lock.status(config)
    records = None
    if data is None:
        log(f"{name}: {why}: solving the design")
        b, records = pipeline.solve(config, progress=progress_after(lambda line: log(f"{name}: {line}")))
        lock_text = design_lock.dumps(design_lock.document(b, records))
    else:
        lock_text = design_lock.path(config).read_text()
    digest = emit.emission_inputs(config, lock_text)
    if records is None and not force and target.is_dir() and emit.stamp_matches(target, digest):
        if emit.emitted_from(target, name, lock_text):
            log(f"{name}: unchanged (inputs hash {digest[:12]}), skipped")
            return None
        # the stamp lists these files, but the C was emitted from another lock: the lock (or the C) was
        # edited and the stamp recomputed; the replay below re-derives every entry of the lock and refuses
        # one its own solutions do not give (codegen.design.lock.check_reproduced)
        log(f"{name}: its C was not emitted from this design lock (the header's design hash differs although "
            f"the stamp matches): replaying the lock")
    if records is None:        # the committed design, replayed and re-checked
        b = pipeline.build(config, design_lock.replay(data, str(design_lock.path(config))))
    files = emit.render(b, lock_text=lock_text)
    files[design_lock.path(config).name] = lock_text
    files[emit.STAMP] = emit.stamp_text(digest, files)
    emit.write_atomically(target, files)
    log(f"{name}: generated {len(files)} files in {target} ({text.headline(b.certificate)}"
        f"{'; design re-solved' if records is not None else '; committed design'})")
    return b
