"""Stage 2, the representation the families share: the LPV polytope (:mod:`.polytope`), sound
interval bounds of expressions over a box (:mod:`.bounds`) and the HOSMD differentiators
(:mod:`.differentiators`)."""
