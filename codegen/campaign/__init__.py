"""Robustness campaigns: thousands of dispersed runs of an observer on its compiled truth plant, on Dask.

``spec`` (the campaign file), ``plants`` (the closed-loop plants as compiled C), ``runner`` (one
run from (spec, index) alone), ``engine`` (Dask: local cluster or a scheduler's address),
``report`` (summary and plots). CLI: ``uiogen campaign SPEC.toml [--runs N] [--only K] [--json]``.
"""
from .spec import CampaignSpec, load

__all__ = ["CampaignSpec", "load"]
