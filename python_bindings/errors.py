"""Typed errors of the runtime (loading and running a compiled observer).

The toolchain's errors (:mod:`codegen.errors`) derive from the same :class:`UiogenError` and
re-export these, so ``except UiogenError`` catches every uiogen error, runtime or toolchain.
"""
from __future__ import annotations


class UiogenError(Exception):
    """Base class of every uiogen error."""


class UnknownObserverError(UiogenError, KeyError):
    """No observer configuration is registered under that name, or it is not generated or compiled."""

    def __str__(self) -> str:  # KeyError quotes its argument; keep the message readable
        return str(self.args[0]) if self.args else ""


class StaleExtensionError(UnknownObserverError):
    """The compiled extension was built from another design than the design lock beside it (the
    design changed after the last ``uiogen build``); the message names the command to run."""


class DamagedExtensionError(StaleExtensionError):
    """The compiled extension's bytes are not those ``uiogen build`` recorded beside it (truncated,
    overwritten, or built by an older uiogen): it is not loaded; the message names the command to run."""


class ChangedSourceError(StaleExtensionError):
    """The observer file, parameter file or model the extension was built from changed since
    (``path``: the file); the message names the commands that bring the design and the extension up
    to date."""

    def __init__(self, message: str, path=None):
        super().__init__(message)
        self.path = path


class SourceFileError(UiogenError, ValueError):
    """A file :func:`python_bindings.load` reads (the observer file) cannot be read as what it must
    be (UTF-8 TOML); the message names the file."""


class SampleError(UiogenError, ValueError):
    """An input sample or array passed to an observer has the wrong shape, type or values."""
