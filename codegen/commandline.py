"""What a command line does with a user's mistake: one line on stderr and exit status 2, never a
traceback (:func:`report_errors`), and the options the commands share. The ``uiogen`` verbs
(:mod:`codegen.cli`) and the embedded tools (:mod:`codegen.targets.cortexm`,
:mod:`codegen.tools.m4cycles`, :mod:`codegen.tools.qemu`) report through it."""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from .errors import UiogenError, install_hint
from .project import outputs

OPTIONAL_MODULES = {"vehiclemodels": "validation", "matplotlib": "validation", "dask": "validation",
                    "distributed": "validation", "asammdf": "validation", "rosbags": "validation",
                    "fmpy": "fmu", "cvxpy": "bench", "scs": "bench", "AlgDiff": "bench"}
"""The modules of pyproject's extras: a verb that needs one a wheel did not install says which extra installs it."""


def _file_of(tb) -> str | None:
    """The file a failed read was reading: the innermost frame's ``path`` (or ``file``, ``source``)."""
    frames = []
    while tb is not None:
        frames.append(tb.tb_frame)
        tb = tb.tb_next
    for frame in reversed(frames):
        for key in ("path", "file", "filename", "source"):
            value = frame.f_locals.get(key)
            if isinstance(value, (str, Path)) and str(value):
                return str(value)
        value = frame.f_locals.get("self")
        if isinstance(getattr(value, "path", None), (str, Path)):
            return str(value.path)
    return None


def report_errors(command: str, call) -> int:
    """``call()``'s exit status, every mistake a user can make ending as one line on stderr,
    ``uiogen: error: ErrorType: message``, and exit status 2 (no traceback): a typed error of
    :mod:`codegen.errors`, a text file that is not UTF-8, an optional dependency not installed, a
    disk that does not take an output; Ctrl-C is one line and status 130; a reader that closed the
    pipe (``| head -1``) ends it quietly with status 141. ``command``: what the user
    ran, as the messages name it (``uiogen build``, ``python -m codegen.tools.qemu``). The verbs'
    :func:`main` and the embedded tools' (:mod:`codegen.targets.cortexm`, :mod:`codegen.tools.m4cycles`,
    :mod:`codegen.tools.qemu`) report through it."""
    try:
        code = call()
        sys.stdout.flush()           # a closed pipe shows here, inside the handlers, not at exit
        return code
    except BrokenPipeError:          # `uiogen design X | head -1`: the reader has what it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())   # nothing more to flush at exit
        return 141                   # as a command killed by SIGPIPE
    except KeyboardInterrupt:     # Ctrl-C: every output is written whole or not at all (outputs, generate)
        print(f"uiogen: interrupted: {command} stopped before it finished (the previous state is kept)",
              file=sys.stderr)
        return 130
    except UnicodeDecodeError as exc:     # a text file read where no reader names it: the file, if we can tell
        where = _file_of(exc.__traceback__)
        print(f"uiogen: error: ConfigurationError: {where or 'an input file'}: not UTF-8 text ({exc.reason} at byte "
              f"{exc.start}); save it as UTF-8", file=sys.stderr)
        return 2
    except UiogenError as exc:
        print(f"uiogen: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as exc:    # an optional dependency the command needs: which extra installs it
        package = (exc.name or "").split(".")[0]
        extra = OPTIONAL_MODULES.get(package)
        if extra is None:
            raise
        print(f"uiogen: error: UnsupportedError: {package} is not installed, and {command} needs it here: "
              f"{install_hint(extra)}", file=sys.stderr)
        return 2
    except OSError as exc:        # a disk that does not take an output the command writes: one line, no traceback
        if exc.errno not in outputs.DISK_ERRORS:
            raise
        err = outputs.error(exc.filename or "an output", exc)
        print(f"uiogen: error: {type(err).__name__}: {err}", file=sys.stderr)
        return 2


def project_option() -> argparse.ArgumentParser:
    """The ``--project DIR`` option (a parent parser) of the commands that read or write an
    observer's generated files."""
    project = argparse.ArgumentParser(add_help=False)
    project.add_argument("--project", metavar="DIR",
                         help="the project folder of the generated files (generated_c/, build/); default: the "
                              "observer file's folder, for a built-in observer the source checkout (installed: "
                              "the current directory)")
    return project
