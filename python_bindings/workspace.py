"""Where a project's files go: every generated path, derived from one folder.

A *project* is a folder. An observer file's project is its own folder, unless the command line
names another (``uiogen ... --project DIR``); a built-in observer's project is the source
checkout when uiogen runs from one (its committed ``generated_c/``), otherwise ``--project`` or
the current directory. Nothing is ever written where the package is installed.

::

    PROJECT/generated_c/NAME/NAME_design.json   the design lock   } commit these
    PROJECT/generated_c/NAME/NAME*.{c,h}        the C             }
    PROJECT/build/extensions/_NAME.<abi>.so     the Python extension (uiogen build)
    PROJECT/build/objects/NAME/                 its object files and C glue
    PROJECT/build/float32/NAME/                 the float32 variant (uiogen build --float32)
    PROJECT/build/plants/                       compiled campaign truth plants
    PROJECT/build/campaigns/SPEC/               campaign results (uiogen campaign)
    PROJECT/build/plots/                        figures of uiogen demo

The rule lives in the runtime (standard library only) because :func:`python_bindings.load` finds
an extension by it without the toolchain; the toolchain writes by the same rule
(:attr:`codegen.project.observer_file.ObserverConfig.workspace`).
"""
from __future__ import annotations

import importlib.machinery
from dataclasses import dataclass
from pathlib import Path

# Where the packages are: the checkout, or site-packages once installed.
PACKAGE_ROOT = Path(__file__).resolve().parents[1]
BUILTIN_OBSERVERS = PACKAGE_ROOT / "model_defs" / "observers"
# This interpreter's extension-module suffix (sysconfig's EXT_SUFFIX, without importing sysconfig).
EXT_SUFFIX = importlib.machinery.EXTENSION_SUFFIXES[0]


def source_checkout() -> Path | None:
    """The source checkout uiogen runs from, or None when it is installed (a wheel): the folder
    above the packages when it holds the project file and the committed generated C."""
    root = PACKAGE_ROOT
    if (root / "pyproject.toml").is_file() and (root / "generated_c").is_dir():
        return root
    return None


@dataclass(frozen=True)
class Workspace:
    """The folders of one project (see the module's layout)."""

    root: Path

    @classmethod
    def of(cls, project: str | Path | None = None) -> "Workspace":
        """The workspace of ``project`` (a folder), or of the current directory if None."""
        return cls(Path(project if project is not None else Path.cwd()).resolve())

    @classmethod
    def locate(cls, observer: str | Path, project: str | Path | None = None) -> tuple:
        """(workspace, name) of ``observer``: a built-in observer's name, or the path of an
        observer file (``.toml``), whose stem is the observer's name; the file is not read."""
        text = str(observer)
        if text.endswith(".toml") or "/" in text:
            path = Path(text)
            builtin = path.resolve().parent == BUILTIN_OBSERVERS
            return cls.for_observer_file(path, project, builtin), path.stem
        return cls.for_observer_file(BUILTIN_OBSERVERS / f"{text}.toml", project, builtin=True), text

    @classmethod
    def for_observer_file(cls, path: str | Path, project: str | Path | None = None,
                          builtin: bool = False) -> "Workspace":
        """The workspace of an observer file: ``project`` when given; else a built-in observer's
        (the checkout, or the current directory when installed) or the file's own folder."""
        if project is not None:
            return cls.of(project)
        if builtin:
            return cls.of(source_checkout())
        return cls.of(Path(path).resolve().parent)

    @property
    def generated(self) -> Path:
        """``generated_c/``: one folder per observer, with its design lock and C."""
        return self.root / "generated_c"

    def observer_dir(self, name: str) -> Path:
        return self.generated / name

    def design_lock(self, name: str) -> Path:
        return self.observer_dir(name) / f"{name}_design.json"

    @property
    def build(self) -> Path:
        """``build/``: everything compiled or run from the committed files (never committed)."""
        return self.root / "build"

    @property
    def extensions(self) -> Path:
        return self.build / "extensions"

    def extension(self, name: str) -> Path:
        """The compiled extension module of observer ``name`` (this interpreter's ABI suffix)."""
        return self.extensions / f"_{name}{EXT_SUFFIX}"

    def objects(self, name: str) -> Path:
        return self.build / "objects" / name

    @property
    def float32(self) -> Path:
        return self.build / "float32"

    @property
    def plants(self) -> Path:
        return self.build / "plants"

    @property
    def campaigns(self) -> Path:
        return self.build / "campaigns"

    @property
    def plots(self) -> Path:
        return self.build / "plots"

    def generated_names(self) -> list:
        """Observers generated in this project (a folder with its ``NAME.h``)."""
        if not self.generated.is_dir():
            return []
        return sorted(p.name for p in self.generated.iterdir() if (p / f"{p.name}.h").is_file())
