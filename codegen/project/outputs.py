"""Writing a project's outputs: whole or not at all, with the user's permissions.

Every file a command writes goes through a temporary sibling that replaces the target in one
rename (:func:`write_atomic`), and a disk error -- a read-only or full file system, no
permission -- is an :class:`~codegen.errors.OutputError` naming the path, with the temporary
removed (:func:`writing`). Folders made by :func:`make_temp_folder` (``tempfile.mkdtemp`` is
always 0700) get the mode the user's umask gives a new folder, so a generated folder swapped into
place reads as any folder the user creates.
"""
from __future__ import annotations

import contextlib
import errno
import json
import os
import stat
import tempfile
from pathlib import Path

from ..errors import OutputError, UnsupportedError, install_hint

DISK_ERRORS = frozenset({errno.EROFS, errno.ENOSPC, errno.EDQUOT, errno.EACCES, errno.EPERM, errno.EFBIG,
                         errno.EIO})
"""errno values of a file system that does not take the output (rather than a missing input)."""


def umask() -> int:
    """The process's umask (read by setting it and restoring it at once)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def folder_mode() -> int:
    """The mode ``mkdir`` gives a new folder under the user's umask."""
    return 0o777 & ~umask()


def file_mode() -> int:
    """The mode ``open(..., "w")`` gives a new file under the user's umask."""
    return 0o666 & ~umask()


def error(path, exc: OSError, what: str = "write") -> OutputError:
    name = errno.errorcode.get(exc.errno, "") if exc.errno else ""
    cause = exc.strerror or str(exc)
    return OutputError(f"cannot {what} {path}: {cause}{f' ({name})' if name else ''}; nothing partial was left "
                       f"there: make the folder writable or free space, or write elsewhere")


@contextlib.contextmanager
def writing(path, what: str = "write"):
    """Turn an OSError of the block into an :class:`OutputError` naming ``path``."""
    try:
        yield
    except OutputError:
        raise
    except OSError as exc:
        raise error(path, exc, what) from None


def make_folder(path) -> Path:
    """``mkdir -p`` of an output folder (an OSError is an OutputError); a file in the way (an
    ``--out`` under an existing file) is named, not reported as mkdir's bare 'File exists'."""
    path = Path(path)
    for folder in (path, *path.parents):
        if folder.exists():
            if not folder.is_dir():
                raise OutputError(f"cannot create the folder {path}: {folder} is a file, not a folder; move it "
                                  f"away or write elsewhere")
            break
    with writing(path, "create the folder"):
        path.mkdir(parents=True, exist_ok=True)
    return path


def make_temp_folder(prefix: str, parent) -> Path:
    """A fresh folder in ``parent`` with the user's folder mode (not mkdtemp's 0700)."""
    with writing(parent, "create a folder in"):
        tmp = Path(tempfile.mkdtemp(prefix=prefix, dir=parent))
        os.chmod(tmp, folder_mode())
    return tmp


def _write_temporary(path: Path, tmp: Path, data, sync: bool = False) -> None:
    """``data`` into ``tmp``, with the mode of the file ``path`` it will replace (a 0600 file stays 0600)."""
    with open(tmp, "wb" if isinstance(data, bytes) else "w") as fh:
        fh.write(data)
        if sync:
            fh.flush()
            os.fsync(fh.fileno())
    with contextlib.suppress(FileNotFoundError):
        os.chmod(tmp, stat.S_IMODE(os.stat(path).st_mode))


def write_atomic(path, data) -> Path:
    """Write ``data`` (str or bytes) to ``path`` through a temporary sibling and one rename: the
    target is the old file or the new one, never a part, with the old one's permission mode; the
    temporary never stays."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with writing(path):
            _write_temporary(path, tmp, data)
            os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return path


def pyplot():
    """matplotlib's pyplot on the Agg backend (every figure goes to a file), or an
    :class:`UnsupportedError` saying which extra installs it (a wheel installs no plotting library)."""
    try:
        import matplotlib
    except ImportError:
        raise UnsupportedError("figures (--plot, --report, a campaign's plots) need matplotlib, which is not installed: "
                               + install_hint("validation")) from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def pending_path(anchor) -> Path:
    """The record of a :func:`write_together` in progress, beside the file ``anchor`` it belongs to."""
    anchor = Path(anchor)
    return anchor.with_name(f".{anchor.name}.pending")


def write_together(files: dict, anchor) -> list:
    """Write several files ``{path: text}`` as one change (``uiogen fit --write``: a parameter file
    and an observer file): every new text is written to a temporary sibling and synced first, then
    a record of the renames (:func:`pending_path` of ``anchor``) is committed in one rename, then the
    files are renamed into place and the record removed. Killed before the record exists: every
    file is the old one; after: :func:`finish_pending` (run by the next command that reads
    ``anchor``) completes the renames, so no reader ever works from one new file and one old one.
    Each file keeps its permission mode. Returns the paths written."""
    record = pending_path(anchor)
    temps = {}
    try:
        for path, data in files.items():
            path = Path(path)
            tmp = path.with_name(f".{path.name}.new-{os.getpid()}")
            temps[path] = tmp
            with writing(path):
                _write_temporary(path, tmp, data, sync=True)
        write_atomic(record, json.dumps([[str(t.resolve()), str(p.resolve())] for p, t in temps.items()]))
    except BaseException:
        for tmp in temps.values():
            with contextlib.suppress(OSError):
                tmp.unlink()
        raise
    finish_pending(anchor)
    return list(temps)


def finish_pending(anchor, log=None) -> list:
    """Complete the renames of an interrupted :func:`write_together` recorded beside ``anchor`` (none:
    nothing to do); returns the files it completed and says so through ``log``."""
    record = pending_path(anchor)
    try:
        pairs = json.loads(record.read_text())
    except FileNotFoundError:
        return []
    except (ValueError, UnicodeDecodeError):      # never written whole (write_atomic): a stray file
        record.unlink(missing_ok=True)
        return []
    done = []
    with writing(record, "complete the interrupted write recorded in"):
        for tmp, target in pairs:
            if os.path.exists(tmp):
                os.replace(tmp, target)
                done.append(target)
        for folder in {os.path.dirname(t) for _, t in pairs}:
            fd = os.open(folder, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        record.unlink()
    if done and log is not None:
        log(f"completed an interrupted write of {', '.join(done)} (recorded in {record})")
    return done
