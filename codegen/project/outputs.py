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
import os
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
    """``mkdir -p`` of an output folder (an OSError is an OutputError)."""
    path = Path(path)
    with writing(path, "create the folder"):
        path.mkdir(parents=True, exist_ok=True)
    return path


def make_temp_folder(prefix: str, parent) -> Path:
    """A fresh folder in ``parent`` with the user's folder mode (not mkdtemp's 0700)."""
    with writing(parent, "create a folder in"):
        tmp = Path(tempfile.mkdtemp(prefix=prefix, dir=parent))
        os.chmod(tmp, folder_mode())
    return tmp


def write_atomic(path, data) -> Path:
    """Write ``data`` (str or bytes) to ``path`` through a temporary sibling and one rename: the
    target is the old file or the new one, never a part; the temporary never stays."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with writing(path):
            with open(tmp, "wb" if isinstance(data, bytes) else "w") as fh:
                fh.write(data)
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
