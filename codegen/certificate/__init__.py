"""Stage 4, the certificate: one typed :class:`~.certificate.Certificate` for every family
(:mod:`.certificate`), the design artifact's shared parts (:mod:`.artifact`), the check of
external gains (:mod:`.gains`) and every line of text about a design (:mod:`.text`)."""
