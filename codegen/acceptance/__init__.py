"""Acceptance runs that drive the command line as a user does, above it (the maintainer tools of
:mod:`codegen.tools` stand below the command line, which runs two of them as ``uiogen docs`` and ``uiogen
bench``):

* :mod:`.verbs`: every verb for every family, on a project of the family's own starter
  (``docs/families_and_verbs.md``; ``python -m codegen.acceptance.verbs``);
* :mod:`.random_models`: C == model on random small valid models of every family with a drawer
  (``python -m codegen.acceptance.random_models``).
"""
