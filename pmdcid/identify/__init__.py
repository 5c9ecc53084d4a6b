"""Identification stages of the paper, each in its own module (their fits: :mod:`pmdcid.fit`)."""
