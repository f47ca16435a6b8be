"""A registry of plug-ins by name: the observer families (:mod:`codegen.contract.registry`) and the export
targets (:mod:`codegen.targets`) are each one.

The plug-ins that ship with uiogen are the modules ``PACKAGE.NAME`` for each NAME of ``PACKAGE.BUILTIN``,
imported on first use by the module's name (the registry imports none of them: it stands below them), each
defining its entry as a module attribute (``FAMILY``, ``TARGET``). A user's own is registered with
:meth:`Registry.register`.
"""
from __future__ import annotations

import importlib


class Registry:
    """Entries of ``kind`` (instances of ``entry_type``) by their ``name``.

    ``package``/``attribute``: where the built-in entries are (``package.BUILTIN`` names the modules);
    ``unknown(name, known)``: the typed error of a name nothing is registered under; ``required``: the
    attributes an entry must set (a TypeError at registration otherwise)."""

    def __init__(self, kind: str, entry_type: type, package: str, attribute: str, unknown, required: tuple = ()):
        self.kind, self.entry_type, self.package, self.attribute = kind, entry_type, package, attribute
        self._unknown, self._required, self._entries, self._loaded = unknown, required, {}, False

    def _load_builtin(self) -> None:
        if not self._loaded:
            self._loaded = True
            for name in importlib.import_module(self.package).BUILTIN:
                self.register(getattr(importlib.import_module(f"{self.package}.{name}"), self.attribute))

    def register(self, entry, replace: bool = False):
        """Make ``entry`` available by ``entry.name``."""
        self._load_builtin()
        what = f"{self.entry_type.__module__}.{self.entry_type.__name__}"
        if not isinstance(entry, self.entry_type):
            raise TypeError(f"register() takes a {what}, got {type(entry).__name__}")
        if not all(getattr(entry, k, "") for k in self._required):
            raise TypeError(f"{type(entry).__name__}: a {self.kind} needs {' and '.join(f'a {k}' for k in self._required)}")
        if entry.name in self._entries and not replace and self._entries[entry.name] is not entry:
            raise ValueError(f"a {self.kind} named {entry.name!r} is registered already (replace=True to override)")
        self._entries[entry.name] = entry
        return entry

    def unregister(self, name: str) -> None:
        self._entries.pop(name, None)

    def get(self, name: str):
        self._load_builtin()
        try:
            return self._entries[name]
        except KeyError:
            raise self._unknown(name, self.names()) from None

    def names(self) -> tuple:
        self._load_builtin()
        return tuple(self._entries)

    def entries(self) -> tuple:
        self._load_builtin()
        return tuple(self._entries.values())
