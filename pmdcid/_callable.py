"""Subpackages that are also functions: ``pmdcid.identify(logs)`` calls
:func:`pmdcid.api.identify` although ``pmdcid.identify`` is the package of the stages.

Python binds ``pmdcid.identify`` to the subpackage as soon as anything imports it, so a plain
function of that name in ``pmdcid/__init__.py`` would be replaced. Instead the subpackage's
module object gets a class with ``__call__`` (module ``__class__`` assignment, Python >= 3.5).
"""

from __future__ import annotations

import sys
import types


class _CallableModule(types.ModuleType):
    def __call__(self, *args, **kwargs):
        from pmdcid import api

        return getattr(api, self.__name__.rsplit(".", 1)[1])(*args, **kwargs)


def make_callable(module_name: str) -> None:
    """Make the module ``module_name`` (``pmdcid.X``) call :func:`pmdcid.api.X`."""
    sys.modules[module_name].__class__ = _CallableModule
