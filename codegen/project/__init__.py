"""The inputs a user writes: observer files (:mod:`.observer_file`), their settings tables
(:mod:`.settings`) and the column maps of data logs (:mod:`.columns`)."""
