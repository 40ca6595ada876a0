"""The built-in search methods, one module each (and ``lanes``, the trust-region lanes two of
them share); every method's module registers itself when this package is imported
(:mod:`kadv.attack` imports it), so adding a method is adding a module here (and its YAML under
``conf/attack/``)."""

import importlib
import pkgutil

for _module in pkgutil.iter_modules(__path__):
    importlib.import_module(f"{__name__}.{_module.name}")
