"""Registries of named classes (strategies, agents): adding one is adding one module."""

from __future__ import annotations

import importlib
import importlib.util
import pkgutil
from typing import Generic, TypeVar

T = TypeVar("T")


class Registry(Generic[T]):
    """Classes registered by their ``name``, found by importing every module of a package
    the first time the names are asked for.  A class asked for by name is looked for in
    its own module first, the package's module of that name (dashes as underscores:
    agent ``paper`` in ``calibrators.agents.paper``), so that making one imports what it
    needs and not what every other class does."""

    def __init__(self, kind: str, package: str) -> None:
        self.kind, self.package = kind, package
        self.classes: dict[str, type[T]] = {}

    def register(self, cls: type[T]) -> type[T]:
        """Class decorator: make ``cls`` available by its ``name``."""
        name = getattr(cls, "name", "")
        if not name or name in self.classes:
            raise ValueError(f"{self.kind} name '{name}' is empty or taken")
        self.classes[name] = cls
        return cls

    def available(self) -> list[str]:
        """Every registered name (imports each module of the package once)."""
        package = importlib.import_module(self.package)
        for module in pkgutil.iter_modules(package.__path__):
            importlib.import_module(f"{self.package}.{module.name}")
        return sorted(self.classes)

    def _import_own_module(self, name: str) -> None:
        """Import the package's module named as ``name``, if there is one."""
        module = name.replace("-", "_")
        if module.isidentifier() and not module.startswith("_"):
            importlib.import_module(self.package)
            if importlib.util.find_spec(f"{self.package}.{module}") is not None:
                importlib.import_module(f"{self.package}.{module}")

    def get(self, name: str) -> T:
        """A new instance of the class registered as ``name``."""
        if name not in self.classes:  # not imported yet, or unknown
            self._import_own_module(name)
        if name not in self.classes:
            names = self.available()
            if name not in self.classes:
                raise ValueError(f"unknown {self.kind} '{name}'; choose from {names}")
        return self.classes[name]()
