"""The code's structure, read from the code: no import cycles, the family boundary, derived hashes.

* Import cycles: every ``import`` statement of the project's modules (also inside functions),
  resolved to the module it loads, as a graph; no strongly connected component may have more
  than one module, and no two of the top-level packages may import each other.
* The family boundary: outside ``codegen/families/`` no code names a family (string literals
  equal to a registered family's name), so the toolchain can only reach a family through the
  registry.
* The generation hash covers the sources: derived from the imports, it lists every module the
  family's pipeline imports.
"""
import ast
from pathlib import Path

import pytest

from codegen.design import lock as design_lock, sources
from codegen import families
from codegen.project import observer_file as observers

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
PACKAGES = ("codegen", "model_defs", "python_bindings")


def _modules() -> dict:
    out = {}
    for pkg in PACKAGES:
        for p in (ROOT / pkg).rglob("*.py"):
            parts = list(p.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = p
    return out


def _graph() -> dict:
    mods = _modules()

    def resolve(name):
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    edges = {m: set() for m in mods}
    for m, p in mods.items():
        pkg = m.split(".") if p.name == "__init__.py" else m.split(".")[:-1]
        for node in ast.walk(ast.parse(p.read_text())):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = pkg[:len(pkg) - node.level + 1] if node.level else []
                mod = ".".join(base + ([node.module] if node.module else []))
                targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in mods else mod for a in node.names]
            for t in targets:
                r = resolve(t) if t.split(".")[0] in PACKAGES else None
                if r and r != m:
                    edges[m].add(r)
    return edges


def _cycles(edges: dict) -> list:
    """Strongly connected components with more than one node (Tarjan, iterative)."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]
    for root in edges:
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            nxt = next(it, None)
            if nxt is not None:
                if nxt not in index:
                    index[nxt] = low[nxt] = counter[0]
                    counter[0] += 1
                    stack.append(nxt)
                    on.add(nxt)
                    work.append((nxt, iter(sorted(edges[nxt]))))
                elif nxt in on:
                    low[v] = min(low[v], index[nxt])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle_between_modules():
    assert _cycles(_graph()) == []


def test_no_import_cycle_between_packages():
    edges = _graph()
    pkg_edges = {(m.split(".")[0], t.split(".")[0]) for m, ts in edges.items() for t in ts}
    pairs = sorted((a, b) for a, b in pkg_edges if a != b and (b, a) in pkg_edges)
    assert not pairs, f"top-level packages import each other: {pairs}"


def test_no_family_name_outside_the_families_folder():
    names = set(families.names())
    hits = []
    for p in (ROOT / "codegen").rglob("*.py"):
        if "families" in p.relative_to(ROOT / "codegen").parts:
            continue
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in names:
                hits.append(f"{p.relative_to(ROOT)}:{node.lineno}: {node.value!r}")
    assert not hits, "family names outside codegen/families/ (ask the registry instead):\n" + "\n".join(hits)


@pytest.mark.parametrize("NAME", ["lpv_linf_driver_torque", "ts_fuzzy_uio", "switched_pi_bank_angle",
                                  "algebraic_uio_example2", "interconnected_uio"])
def test_design_hash_covers_every_module_the_pipeline_imports(NAME):
    config = observers.get(NAME)
    covered = set(design_lock.design_sources(config))
    package = ROOT / "codegen" / "families" / config.family
    for f in ("__init__.py", "build.py", "design.py"):
        assert package / f in covered, f
    assert ROOT / "codegen" / "design" / "lmi.py" in covered and config.model_path in covered
    # validation code is not a design input: editing a plot does not re-solve a design
    assert package / "validation.py" not in covered



UNSTAMPED = ("validation", "analysis", "campaign", "targets", "workflow.py", "tools", "cli.py", "commandline.py",
             "acceptance")
"""What no design and no generated C derives from: editing a metric, a plot, a campaign, an export target, a
maintainer tool or the command line re-solves and regenerates nothing."""


def test_no_design_or_c_stamp_reaches_validation_campaigns_targets_tools_or_the_cli():
    stamped = set(sources.closure("codegen.emit.generate"))
    for name in observers.names():
        stamped |= set(design_lock.design_sources(observers.get(name)))
    reached = sorted(str(f.relative_to(ROOT)) for f in stamped
                     if f.is_relative_to(ROOT / "codegen") and f.relative_to(ROOT / "codegen").parts[0] in UNSTAMPED)
    assert not reached, f"a design or C stamp reads {reached}"


@pytest.mark.parametrize("NAME", ["lpv_linf_driver_torque", "interconnected_uio"])
def test_the_c_hash_covers_the_design_the_emitters_and_the_templates(NAME, monkeypatch):
    # the files emission_inputs really hashes (read off sources.digest as it is called)
    from codegen.emit import generate as emit
    from codegen.emit.toolchain import TEMPLATES
    config = observers.get(NAME)
    lock = design_lock.path(config).read_text()
    hashed, real_digest = [], sources.digest

    def spy(files, extra=None, contents=None):
        hashed.append(([Path(f) for f in files], dict(extra or {})))
        return real_digest(files, extra, contents)
    monkeypatch.setattr(sources, "digest", spy)
    emit.emission_inputs(config, lock)
    (files, extra), = [h for h in hashed if "lock" in h[1]]
    design = set(design_lock.design_sources(config))
    assert design <= set(files)                                   # a change that re-solves also regenerates
    emitter = ROOT / "codegen" / "emit" / "generate.py"
    assert emitter in files and emitter not in design             # emission code: new C, not a new design
    assert set(TEMPLATES.glob("observer.*.j2")) <= set(files)
    assert {"casadi", "jinja2"} <= set(extra) and extra["lock"] != ""
    monkeypatch.undo()
    # and the hash moves with the lock's text
    assert emit.emission_inputs(config, lock) != emit.emission_inputs(config, lock + " ")


# ---- floors: a stage imports only what stands below it --------------------------------------------------

#: The floors, from the ground up (below all: the errors, the typed settings, the plug-in registry of codegen.plugins):
#: the stages in pipeline order (the model, its representation, the LMI design, the
#: certificate), the contract a family and the toolchain agree on (codegen.contract), the project's files (observer
#: and parameter files, what a command writes), C emission, the pipeline that runs a family's stages, the compiled
#: extension; then what uses them: validation, analysis, the families themselves (each one folder, over the stages
#: and the validation it runs), campaigns, export targets, the loops of `uiogen generate`, the maintainer tools and
#: the command line. A package of codegen (or a top-level module) imports only what stands below it, at module level
#: or inside a function; the family is handed down (config.observer_family), never imported from below.
FLOORS = ("errors", "settings", "plugins", "model", "representation", "design", "certificate", "contract", "project",
          "emit", "pipeline", "extension", "validation", "analysis", "families", "commandline", "campaign", "targets",
          "workflow", "tools", "cli", "acceptance")
ABOVE = {f: FLOORS[i + 1:] for i, f in enumerate(FLOORS)}


def _upward(edges: dict, above: dict = ABOVE) -> list:
    out = []
    for m, ts in edges.items():
        parts = m.split(".")
        if parts[0] != "codegen" or len(parts) < 2 or parts[1] not in above:
            continue
        for t in sorted(ts):
            tp = t.split(".")
            if tp[0] == "codegen" and len(tp) > 1 and tp[1] in above[parts[1]]:
                out.append(f"{m} -> {t}")
    return sorted(out)


def test_the_floor_check_finds_an_upward_import():
    assert _upward({"codegen.project.precision": {"codegen.validation.noise", "codegen.settings"},
                    "codegen.validation.noise": {"codegen.project.sensor_noise"}}) == \
        ["codegen.project.precision -> codegen.validation.noise"]


def test_no_stage_imports_a_stage_above_it():
    assert _upward(_graph()) == [], "upward imports (move the shared part down instead)"


def test_every_package_of_codegen_stands_on_a_floor():
    children = {p.stem if p.is_file() else p.name for p in (ROOT / "codegen").iterdir()
                if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").is_file()}
    assert children == set(FLOORS), f"not on a floor: {sorted(children - set(FLOORS))}; gone: {sorted(set(FLOORS) - children)}"


def test_the_cli_reaches_a_target_only_through_the_registry():
    from codegen import targets
    edges = _graph()
    named = sorted(t for t in edges["codegen.cli"] if t.startswith("codegen.targets."))
    assert named == [], f"codegen/cli.py imports target modules by name: {named}"
    hits = [f"codegen/cli.py:{node.lineno}: {node.value!r}"
            for node in ast.walk(ast.parse((ROOT / "codegen" / "cli.py").read_text()))
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in targets.names()]
    assert not hits, "target names in the command line (ask the registry instead):\n" + "\n".join(hits)


def test_a_target_is_one_folder_and_one_registry_line():
    from codegen import targets
    folders = {p.parent.name for p in (ROOT / "codegen" / "targets").glob("*/__init__.py")}
    assert folders == set(targets.BUILTIN), "a target folder without its registry line, or the reverse"
    for name in targets.BUILTIN:
        target = targets.get(name)
        assert target.name == name and type(target).__module__ == f"codegen.targets.{name}"
        assert isinstance(target, targets.Target) and target.title
