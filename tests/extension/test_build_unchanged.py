"""``uiogen build`` on an unchanged project: the installed extension is kept, saying so, only while every
thing it was built from and checked by is what is there now (the generated C, header and design lock,
the files the design is made from, the compiler and its flags); anything else builds and checks again."""
import os

from codegen import cli
from codegen.extension import build as extension
from codegen.project import observer_file as observers
from python_bindings import integrity

from conftest import new_starter


def _build(obs, capsys, *more):
    assert cli.main(["build", str(obs), *more]) == 0
    return capsys.readouterr().out


def test_an_unchanged_build_is_skipped_and_anything_changed_is_built_again(tmp_path, capsys, monkeypatch):
    folder = new_starter(tmp_path / "p")
    obs = folder / "obs1.toml"
    assert cli.main(["design", str(obs), "--update"]) == 0 and cli.main(["generate", str(obs)]) == 0
    assert "conformance:" in _build(obs, capsys)
    config = observers.get(str(obs))
    so = config.workspace.extensions / config.workspace.extension("obs1").name
    built = so.stat().st_mtime_ns
    out = _build(obs, capsys)
    assert "obs1: unchanged" in out and "conformance:" not in out and so.stat().st_mtime_ns == built
    # --force: compiled and checked again
    assert "conformance:" in _build(obs, capsys, "--force")
    # the extension's bytes changed after the build (its record no longer holds them): built again
    # (a new file in its place: this process has the old one mapped, as the build loaded it to check it)
    changed = so.with_name(so.name + ".new")
    changed.write_bytes(so.read_bytes() + b"\0")
    os.replace(changed, so)
    assert integrity.binary_mismatch(so)
    assert "conformance:" in _build(obs, capsys)
    assert not integrity.binary_mismatch(so) and extension.installed_unchanged(config) is not None
    # another compiler (CC): built again
    monkeypatch.setenv("CC", "gcc")
    assert extension.installed_unchanged(config) is None
    assert "conformance:" in _build(obs, capsys)
    assert "unchanged" in _build(obs, capsys)
    monkeypatch.delenv("CC")
    assert "conformance:" in _build(obs, capsys)
    # the generated folder changed (a file added beside the C): the key differs, built again
    gen = extension.generated_dir(config)
    (gen / "NOTES.txt").write_text("a note\n")
    assert extension.installed_unchanged(config) is None
    os.remove(gen / "NOTES.txt")
    assert extension.installed_unchanged(config) is not None
    # the record of the check removed: nothing says the extension passed, built again
    (config.workspace.objects("obs1") / extension.CONFORMANCE_RECORD).unlink()
    assert extension.installed_unchanged(config) is None
    assert "conformance:" in _build(obs, capsys)
