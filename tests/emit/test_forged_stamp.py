"""``uiogen generate`` on a lock forged with its checksums and the generated folder's stamp recomputed (issue 39:
it said "unchanged"): the C header's design hash is compared with the lock's before the stamp is believed, so
the forged lock is replayed and refused; an unchanged folder is still skipped without a replay."""
import json
from pathlib import Path

import pytest

from codegen import pipeline
from codegen.design import lock as design_lock
from codegen.emit import generate as emit
from codegen import workflow
from codegen.errors import GenerationError
from codegen.project import observer_file as observers
from tests.conftest import new_starter

pytestmark = pytest.mark.slow       # a starter designed and generated (about 10 s, 40 s on a loaded machine)


@pytest.fixture(scope="module")
def project(tmp_path_factory) -> Path:
    folder = new_starter(tmp_path_factory.mktemp("forged") / "p")
    workflow.generate([str(folder / "obs1.toml")], log=lambda line: None)
    return folder


def _generate(config) -> list:
    said = []
    try:
        workflow.generate([config], log=said.append)
    except GenerationError:
        said.append("GenerationError")
    return said


def _restamp(config, folder: Path) -> None:
    """The stamp recomputed over the folder as it is (what a forger who knows the format does)."""
    lock_text = design_lock.path(config).read_text()
    files = {f.name: f.read_text() for f in folder.iterdir() if f.name != emit.STAMP}
    (folder / emit.STAMP).write_text(emit.stamp_text(emit.emission_inputs(config, lock_text), files))


def test_an_unchanged_folder_is_skipped_without_a_replay(project, monkeypatch):
    config = observers.get(str(project / "obs1.toml"))
    monkeypatch.setattr(pipeline, "build", lambda *a, **k: pytest.fail("an unchanged observer was replayed"))
    said = _generate(config)
    assert len(said) == 1 and "unchanged" in said[0], said


def test_a_lock_forged_with_its_stamp_is_replayed_and_refused(project, tmp_path):
    config = observers.get(str(project / "obs1.toml"))
    lock = design_lock.path(config)
    folder = lock.parent
    good = {p: p.read_bytes() for p in folder.iterdir()}
    try:
        data = json.loads(lock.read_text())
        bound = data["certificate"]["bounds"][0]
        bound["value"] *= 1000                          # the certificate's figure, as the gamma x 1000
        lock.write_text(design_lock.dumps(design_lock.seal(data)))
        _restamp(config, folder)
        assert emit.stamp_matches(folder, emit.emission_inputs(config, lock.read_text()))   # the stamp believes it
        said = _generate(config)
        assert not any("unchanged" in line for line in said), said
        assert said[-1] == "GenerationError", said
        assert any("DesignLockError" in line and "not what its own LMI solutions give" in line for line in said), said
        assert lock.read_bytes() != good[lock]          # refused: nothing rewritten from the forged lock
    finally:
        for p in folder.iterdir():
            if p not in good:
                p.unlink()
        for p, b in good.items():
            p.write_bytes(b)


def test_a_header_edited_with_its_stamp_is_emitted_again_from_the_lock(project):
    config = observers.get(str(project / "obs1.toml"))
    folder = design_lock.path(config).parent
    header = folder / f"{config.name}.h"
    true = header.read_text()
    found = emit._HEADER_HASH.search(true)
    header.write_text(true.replace(found.group(1), "0" * 64))      # a C that says another lock emitted it
    _restamp(config, folder)
    said = _generate(config)
    assert any("not emitted from this design lock" in line for line in said), said
    assert any("generated" in line for line in said), said
    assert header.read_text() == true
