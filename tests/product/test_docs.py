"""The documentation builds without a broken page, link or figure, its tables are what the
recorded runs give, and the README stays a README."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from codegen.tools import docs

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())


def test_tables_match_the_recorded_runs():
    changed = docs.update(check=True)
    assert not changed, f"docs differ from docs/data/*.json (run `uiogen docs`): {changed}"


def test_docs_from_an_installed_uiogen_is_refused_not_a_traceback(tmp_path, monkeypatch, capsys):
    """A wheel ships no docs/: `uiogen docs` there said nothing useful (FileNotFoundError traceback; with
    --check, 'the docs differ')."""
    from codegen import cli
    monkeypatch.setattr(docs, "DOCS", tmp_path / "site-packages" / "docs")
    for args in (["docs"], ["docs", "--check"]):
        assert cli.main(args) == 2
        err = capsys.readouterr().err
        assert "UnsupportedError" in err and "source checkout" in err and "Traceback" not in err


def test_a_changed_record_changes_the_page(tmp_path):
    import json
    demo = json.loads((docs.DATA / "demo.json").read_text())
    shutil.copytree(ROOT / "docs", tmp_path / "docs")
    name = next(n for n, e in demo.items() if isinstance(e, dict) and e.get("family") == "linf_uio")
    demo[name]["gamma"] = 123.0
    (tmp_path / "demo.json").write_text(json.dumps(demo))
    changed = docs.update(check=True, demo_path=tmp_path / "demo.json", docs=tmp_path / "docs")
    assert tmp_path / "docs" / "families" / "linf_uio.md" in changed


@pytest.mark.slow          # mkdocs
def test_mkdocs_build_is_strict_clean(tmp_path):
    mkdocs = shutil.which("mkdocs", path=str(Path(sys.executable).parent))
    assert mkdocs, "mkdocs is installed by `make test` ([test] extra)"
    proc = subprocess.run([mkdocs, "build", "--strict", "--site-dir", str(tmp_path / "site")], cwd=ROOT,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_readme_is_a_readme():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 200
    for page in ("docs/families/linf_uio.md", "docs/validation.md", "docs/guarantees.md", "docs/performance.md",
                 "docs/references.md", "codegen/families/README.md"):
        assert page in text and (ROOT / page).is_file(), page
    assert "seed 00" not in text.lower() and "seed-00" not in text.lower()
