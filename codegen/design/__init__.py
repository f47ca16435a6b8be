"""Stage 3, the design: the LMI layer compiled to Clarabel with its numpy re-check (:mod:`.lmi`),
the committed design lock (:mod:`.lock`), machine-independent numbers (:mod:`.canonical`), the
import-closure hashing every lock and stamp uses (:mod:`.sources`) and design sweeps
(:mod:`.sweep`)."""
