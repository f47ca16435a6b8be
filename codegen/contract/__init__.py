"""What the toolchain and an observer family agree on, below every stage that uses it.

* :mod:`.family`: :class:`~.family.Family` (the registry's entry: its paper, its keys, ``build``) and
  :class:`~.family.ObserverBuild` (what its pipeline returns, what :mod:`codegen.emit` renders);
* :mod:`.capabilities`: the optional capabilities, each a small protocol (scenarios, demo figures,
  campaigns, applicability, log peers, identification, a noise bound ...);
* :mod:`.registry`: a family's name to the family, asked by the observer-file reader only.

The families themselves (``codegen/families/NAME/``) stand above the stages and the validation they use;
this contract stands below them, so that a stage, the validation and the analysis see a family only as
the object handed to them, never by importing the families.
"""
