"""Stage 3, the design: the LMI layer compiled to Clarabel with its numpy re-check (:mod:`.lmi`),
the committed design lock (:mod:`.lock`) and the
import-closure hashing every lock and stamp uses (:mod:`.sources`). A study over settings, which runs
the whole pipeline at each point, stands above it: :mod:`codegen.analysis.sweep`."""
