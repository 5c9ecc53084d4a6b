"""Diagnose: find which catalogue effect the model lacks, add it, refit, report before/after."""

from pmdcid.diagnose.loop import Candidate, DiagnoseResult, diagnose

__all__ = ["Candidate", "DiagnoseResult", "diagnose"]
