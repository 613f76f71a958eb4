"""Registries of named classes (strategies, agents): adding one is adding one module."""

from __future__ import annotations

import importlib
import pkgutil
from typing import Generic, TypeVar

T = TypeVar("T")


class Registry(Generic[T]):
    """Classes registered by their ``name``, found by importing every module of a package
    the first time the names are asked for."""

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

    def get(self, name: str) -> T:
        """A new instance of the class registered as ``name``."""
        if name not in self.classes:  # not imported yet, or unknown
            names = self.available()
            if name not in self.classes:
                raise ValueError(f"unknown {self.kind} '{name}'; choose from {names}")
        return self.classes[name]()
