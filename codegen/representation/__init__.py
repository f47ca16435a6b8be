"""Stage 2, the representation the families share: the LPV polytope (:mod:`.polytope`), sound
interval bounds of expressions over a box (:mod:`.bounds`), the HOSMD differentiators
(:mod:`.differentiators`; their stand-alone C: :mod:`codegen.emit.hosmd`), scheduling signals derived from
the outputs written in the states (:mod:`.derived`) and the machine-independent numbers of everything
emitted (:mod:`.canonical`)."""
