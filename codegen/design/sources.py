"""The source files an output depends on, derived from the imports (not kept by hand).

:func:`closure` follows the ``import`` statements (module level and inside functions) of the
project's own packages with :mod:`ast`, so a design or a generated file is stamped with every
module that can change it, and a module added to a family is covered without anyone listing it.
:func:`digest` hashes files by their path relative to the checkout and their bytes (a user's
parameter file and model for what they say: ``codegen.design.lock.file_meanings``).
"""
from __future__ import annotations

import ast
import functools
import hashlib
import importlib.metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("codegen", "model_defs", "python_bindings")

# Third-party packages whose arithmetic or output format reaches a design or the generated C;
# their exact versions are part of every stamp (pinned in constraints.txt).
NUMERIC_PACKAGES = ("numpy", "scipy", "sympy", "mpmath", "clarabel", "casadi", "jinja2")


def _module_file(module: str) -> Path | None:
    """File of a module of the project's packages, or None for anything else."""
    parts = module.split(".")
    if parts[0] not in PACKAGES:
        return None
    base = ROOT.joinpath(*parts)
    if (base / "__init__.py").is_file():
        return base / "__init__.py"
    if base.with_suffix(".py").is_file():
        return base.with_suffix(".py")
    return None


IMPORT_STATEMENTS = "import_statements"
"""The kind of a source file's import statements kept across runs (:mod:`codegen.model.cache`)."""


def _statements(path: Path, module_level: bool) -> list:
    """The import statements of ``path`` as written: ``[0, names]`` of ``import``, ``[level, module, names]`` of
    ``from``; anywhere, or with ``module_level`` only the module's own. Parsing every source of a stamp is most of
    what a verb costs beside its own work, and gives the same statements for the same bytes: kept across runs
    (:mod:`codegen.model.cache`), keyed by the file's bytes, this module's and Python's version."""
    import platform
    import sys

    from ..model import cache
    try:
        data = path.read_bytes()
        text = data.decode()
    except UnicodeDecodeError as exc:       # a user's model with a stray byte: name the file, not the codec
        from ..errors import ModelDefinitionError
        raise ModelDefinitionError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start}); save it as "
                                   f"UTF-8") from None
    digest = cache.key(IMPORT_STATEMENTS, {"source": hashlib.sha256(data).hexdigest(), "module_level": module_level,
                                           "python": platform.python_version(),
                                           "code": cache.code_digest(sys.modules[__name__])})
    stored = cache.read(IMPORT_STATEMENTS, digest)
    if _well_formed(stored):
        return stored
    tree = ast.parse(text, str(path))
    found = []
    for node in (tree.body if module_level else ast.walk(tree)):
        if isinstance(node, ast.Import):
            found.append([0, [a.name for a in node.names]])
        elif isinstance(node, ast.ImportFrom):
            found.append([node.level, node.module, [a.name for a in node.names]])
    cache.write(IMPORT_STATEMENTS, digest, found)
    return found


def _well_formed(statements) -> bool:
    """Whether ``statements`` is what :func:`_statements` writes (an entry that is not is parsed again)."""
    def names(x):
        return isinstance(x, list) and all(isinstance(n, str) for n in x)
    return isinstance(statements, list) and all(
        isinstance(s, list) and ((len(s) == 2 and s[0] == 0 and names(s[1]))
                                 or (len(s) == 3 and type(s[0]) is int and s[0] >= 0
                                     and (s[1] is None or isinstance(s[1], str)) and names(s[2])))
        for s in statements)


@functools.lru_cache(maxsize=None)
def _imports(path: Path, module_level: bool = False) -> tuple:
    """Project modules imported in ``path`` (absolute names): anywhere, or with ``module_level``
    only the statements that run when the module is imported."""
    statements = _statements(path, module_level)
    try:
        rel = path.relative_to(ROOT).with_suffix("")
        package = list(rel.parts[:-1])      # the package a relative import starts from
    except ValueError:                      # a file outside the project: no relative imports
        package = []
    found = []
    for statement in statements:
        if statement[0] == 0 and len(statement) == 2:
            found += statement[1]
        else:
            level, module, names = statement
            if level:
                base = package[:len(package) - level + 1]
                mod = ".".join(base + ([module] if module else []))
            else:
                mod = module or ""
            for name in names:       # "from pkg import module" imports the module, else pkg's names
                found.append(f"{mod}.{name}" if _module_file(f"{mod}.{name}") is not None else mod)
    return tuple(m for m in found if m and m.split(".")[0] in PACKAGES)


def _beside(folder: Path, module: str) -> list:
    """Files of ``module`` (and of the packages above it) found in ``folder``: a user's model imports
    the modules beside it by their bare names (``from tyre_data import C_SCALE``)."""
    parts, out = module.split("."), []
    for k in range(1, len(parts) + 1):
        base = folder.joinpath(*parts[:k])
        for f in (base / "__init__.py", base.with_suffix(".py")):
            if f.is_file():
                out.append(f.resolve())
                break
    return out


BASE_MODEL = "BASE_MODEL"
"""The name a model file gives the model file it builds on (``BASE_MODEL = "../model.py"``: a path relative to
its folder, or absolute), which it loads with :func:`codegen.project.observer_file.load_base`: the file
``uiogen new --from-model --outputs`` writes over the user's model. That file is in the stamp with the modules
beside it that it imports, as an imported module is."""


def _user_imports(path: Path) -> tuple:
    """(module names imported anywhere in a user's file, absolute or relative to its folder; the files its
    module-level ``BASE_MODEL = "PATH"`` names); read again once the file changes."""
    try:
        st = path.stat()
    except OSError:
        return (), ()
    return _user_imports_of(path, st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=None)
def _user_imports_of(path: Path, mtime_ns: int, size: int) -> tuple:
    try:
        tree = ast.parse(path.read_text(), str(path))
    except (SyntaxError, UnicodeDecodeError, ValueError):
        return (), ()           # refused with its own message where the file is imported
    found, bases = [], []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level <= 1:
            mod = node.module or ""
            found += [f"{mod}.{a.name}" if mod else a.name for a in node.names] + ([mod] if mod else [])
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == BASE_MODEL for t in node.targets) \
                and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            bases.append((path.parent / node.value.value).resolve())
    return tuple(found), tuple(bases)


def user_closure(path) -> list:
    """A user's file and every module beside it that it imports, transitively (a helper module
    with the tyre data is as much a design input as the model), and the model file it builds on
    (:data:`BASE_MODEL`) with its own."""
    start = Path(path).resolve()
    seen, todo = {start}, [start]
    while todo:
        f = todo.pop()
        modules, bases = _user_imports(f)
        for g in [*(g for mod in modules for g in _beside(f.parent, mod)), *(b for b in bases if b.is_file())]:
            if g not in seen:
                seen.add(g)
                todo.append(g)
    return sorted(seen, key=_order)


def helper_modules(model) -> list:
    """The modules beside a user's model that it imports (none for a model of the checkout: the
    toolchain's stamp covers those byte for byte)."""
    model = Path(model).resolve()
    return [f for f in user_closure(model) if f != model] if _outside(model) else []


def closure(*modules: str, files=()) -> list:
    """Sorted files of ``modules`` and of every project module they import, transitively.

    A module counts with every import it makes (those inside functions run when its code
    runs); the packages above a module count with the imports their ``__init__`` makes when
    imported (a family's package wires its validation lazily: designs do not depend on it).
    ``files``: more source files, e.g. a user's model outside the project, followed the same way,
    with the modules beside it that it imports (:func:`user_closure`).
    """
    seen, todo = set(), [(m, False) for m in modules]
    for f in files:
        f = Path(f).resolve()
        for g in (user_closure(f) if _outside(f) else [f]):
            if g not in seen:
                seen.add(g)
                todo += [(m, False) for m in _imports(g)]
    done = set()
    while todo:
        mod, parent_only = todo.pop()
        if (mod, parent_only) in done:
            continue
        done.add((mod, parent_only))
        parts = mod.split(".")
        for k in range(1, len(parts) + 1):     # a module's packages run their __init__ first
            f = _module_file(".".join(parts[:k]))
            if f is None:
                continue
            seen.add(f)
            module_level = parent_only or k < len(parts)
            todo += [(m, False) for m in _imports(f, module_level) if (m, False) not in done]
    return sorted(seen, key=_order)


def _outside(f: Path) -> bool:
    """Whether ``f`` lies outside the checkout (a user's file)."""
    try:
        f.relative_to(ROOT)
        return False
    except ValueError:
        return True


def _order(f: Path) -> tuple:
    """Sort key of a source file that does not depend on where the project is installed: the
    project's files by their path inside it, then files outside it (a user's model) by name.
    (Sorting absolute paths put a user's model before or after the package depending on whether
    the checkout's folder sorts above /tmp: the same design hashed differently on two machines.)"""
    try:
        return (0, str(f.relative_to(ROOT)), "")
    except ValueError:
        return (1, f.name, str(f))


def versions() -> dict:
    """{package: installed version} of :data:`NUMERIC_PACKAGES`."""
    out = {}
    for name in NUMERIC_PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def digest(files, extra: dict | None = None, contents: dict | None = None, labels: dict | None = None) -> str:
    """SHA-256 over (path relative to the checkout, bytes) of ``files`` in the given order, then
    ``extra`` items (e.g. versions) in key order. ``contents``: {resolved path: bytes hashed
    instead of the file's} (a user's file hashed for what it says: ``codegen.design.lock.file_meanings``);
    ``labels``: {resolved path: the name it is hashed under instead of its path} (a file that counts for
    its content wherever it lies)."""
    h = hashlib.sha256()
    contents, labels = contents or {}, labels or {}
    for f in files:
        f = Path(f)
        try:
            label = labels.get(f.resolve()) or str(f.resolve().relative_to(ROOT))
        except ValueError:      # a user's file outside the checkout: its name is enough
            label = f.name
        h.update(label.encode() + b"\0")
        h.update(contents.get(f.resolve()) or f.read_bytes())
        h.update(b"\0")
    for k, v in sorted((extra or {}).items()):
        h.update(f"{k}={v}\0".encode())
    return h.hexdigest()
