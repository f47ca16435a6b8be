"""Stage 5, the C: an observer's files from its committed design (:mod:`.generate`), the compiler
flags and CasADi options every C file goes through (:mod:`.toolchain`), CasADi step functions
(:mod:`.stepgen`), the float32 kernel (:mod:`.floatgen`) and the Jinja2 templates
(``templates/``)."""
