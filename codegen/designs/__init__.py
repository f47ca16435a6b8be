"""Observer design families (LMI conditions of each seed)."""
