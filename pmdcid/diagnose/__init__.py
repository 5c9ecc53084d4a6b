"""Diagnose: find which catalogue effect the model lacks, add it, refit, report before/after."""

from pmdcid.diagnose.loop import Candidate, DiagnoseResult, diagnose

__all__ = ["Candidate", "DiagnoseResult", "diagnose"]

from pmdcid._callable import make_callable  # noqa: E402

make_callable(__name__)  # pmdcid.diagnose(...) calls pmdcid.api.diagnose
