"""Each family contributes its own random-model drawer (the capability RandomModels, issue 40): the
acceptance of C == model (codegen.acceptance.random_models) draws every registered family that has one, a
family registered by a user's code included, and names the registered families that have none."""
from __future__ import annotations

import dataclasses

import pytest

from codegen import families
from codegen.families import random_models as R
from codegen.contract.capabilities import RandomModels
from codegen.acceptance import random_models as H

LINF = families.get("linf_uio")


class ToyFamily(type(LINF)):
    """A family of a user's own: the L-infinity pipeline under another name, with its own drawer."""

    name = "toy_linf"
    example = ""

    def draw_random_model(self, rng):
        m = R.draw_linf(rng)
        observer = f"{m.name}.toml"
        text = m.files[observer].replace('family = "linf_uio"', f'family = "{self.name}"', 1)
        assert text != m.files[observer]
        return dataclasses.replace(m, family=self.name, files={**m.files, observer: text})


class Drawless(type(LINF)):
    name = "toy_without_drawer"
    example = ""
    draw_random_model = None          # not the capability


@pytest.fixture
def toy():
    family = families.register(ToyFamily())
    yield family
    families.unregister(family.name)


def test_every_builtin_family_draws_through_its_own_capability():
    assert list(R.drawers()) == [n for n in families.BUILTIN]
    for name in families.BUILTIN:
        assert isinstance(families.get(name), RandomModels)
        assert R.draw(name, 3).family == name and R.draw(name, 3).files == R.draw(name, 3).files


def test_a_family_registered_by_a_user_is_drawn_by_the_acceptance(toy, tmp_path, capsys):
    assert "toy_linf" in R.drawers()
    assert H.main(["--family", "toy_linf", "--draws", "1", "--dir", str(tmp_path)]) == 0
    captured = capsys.readouterr()
    assert "toy_linf: 1 of 1 designed and conform" in captured.out, captured


def test_a_family_without_a_drawer_is_named_not_drawn(tmp_path, capsys):
    family = families.register(Drawless())
    try:
        assert "toy_without_drawer" not in R.drawers()
        assert not isinstance(family, RandomModels)
        assert H.main(["--draws", "0", "--dir", str(tmp_path)]) == 0
        assert "toy_without_drawer: no random-model drawer" in capsys.readouterr().err
    finally:
        families.unregister(family.name)
