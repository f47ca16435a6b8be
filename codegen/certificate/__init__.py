"""Stage 4, the certificate: the design artifact's shared parts (:mod:`.artifact`)."""
