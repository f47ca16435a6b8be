"""Maintainer tools, outside what users import: the benchmark (:mod:`.bench`), the docs'
tables (:mod:`.docs`), the re-solve spread across CPUs (:mod:`.spread`), the stand-alone C
harness (:mod:`.harness`) and the QEMU runs (:mod:`.qemu`)."""
