"""Identification stages of the paper, each in its own module, and the shared fitting engine."""

from pmdcid._callable import make_callable  # noqa: E402

make_callable(__name__)  # pmdcid.identify(...) calls pmdcid.api.identify
