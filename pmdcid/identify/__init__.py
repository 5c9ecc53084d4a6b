"""Identification stages of the paper, each in its own module, and the shared fitting engine."""
