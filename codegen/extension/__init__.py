"""Stage 6, the extension: the generated C compiled into a CPython extension (:mod:`.build`)."""
