"""Every verb for every family (issue 23 items 5 and 6): each family's starter, from ``uiogen new``
in an empty folder outside the checkout, through design, generate, build, validate (excitation,
and a logged run with a column map), check-gains, the FMU, the float32 build and a campaign on
the model's own equations (:mod:`codegen.acceptance.verbs`). The committed record the docs' table is rendered
from (``docs/data/families_and_verbs.json``; ``tests/product/test_docs.py`` compares the page) must say
what the run measured."""
import json

import pytest

from codegen import families
from codegen.acceptance import verbs
from codegen.tools import docs

FAMILIES = [f for f in families.names() if families.get(f).example]
_ROWS: dict = {}


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    return tmp_path_factory.mktemp("verbs")


def row(family, base) -> dict:
    if family not in _ROWS:
        _ROWS[family] = verbs.family_row(family, base)
    return _ROWS[family]


@pytest.mark.slow       # 99 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
@pytest.mark.parametrize("family", FAMILIES)
def test_the_starter_takes_every_verb(family, base):
    r = row(family, base)
    assert list(r) == list(verbs.VERBS)
    failed = {v: c["note"] for v, c in r.items() if c["outcome"] == "fail"}
    assert not failed, failed
    refused = [v for v, c in r.items() if c["outcome"] == "refused"]
    assert refused in ([], ["build --float32"])             # only the float32 build may refuse ...
    if refused:
        assert r["build --float32"]["note"].startswith("margin 1-c = ")      # ... and says by what margin
    assert r["campaign"]["note"] == f"{verbs.CAMPAIGN_RUNS}/{verbs.CAMPAIGN_RUNS} runs"


@pytest.mark.slow       # runs the whole matrix when the starters' tests above are deselected (180 s)
def test_the_record_of_every_family(base, tmp_path):
    """The committed record (docs/data, rendered into docs/families_and_verbs.md) says what this run
    measured: the same outcome in every cell. The test writes its own copy, never the docs; the
    record is refreshed by ``python -m codegen.acceptance.verbs --out docs/data/families_and_verbs.json``."""
    rows = {f: row(f, base) for f in FAMILIES}
    path = verbs.write_record(rows, tmp_path / "record.json")
    rec = json.loads(path.read_text())
    committed = json.loads((docs.DATA / f"{verbs.RECORD}.json").read_text())
    assert [r[0] for r in rec["table"]["rows"]] == [f"`{f}`" for f in FAMILIES]
    assert rec["table"]["header"] == committed["table"]["header"] == ["family", *verbs.VERBS]
    outcomes = {f: {v: c["outcome"] for v, c in cells.items()} for f, cells in rec["cells"].items()}
    assert outcomes == {f: {v: c["outcome"] for v, c in cells.items()} for f, cells in committed["cells"].items()}
    assert f"<!-- uiogen:record {verbs.RECORD} -->" in (docs.DOCS / "families_and_verbs.md").read_text()
