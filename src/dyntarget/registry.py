"""One generic name -> object registry, used for classifiers and planners."""

from __future__ import annotations

from collections.abc import Callable
from typing import Generic, TypeVar

from dyntarget.errors import UnknownNameError

T = TypeVar("T")


class Registry(Generic[T]):
    """Objects registered under unique names.

    Examples
    --------
    >>> r = Registry[type]("widget")
    >>> @r.register("a")
    ... class A: ...
    >>> r.get("a") is A
    True
    >>> r.available()
    ['a']
    """

    def __init__(self, kind: str, *, order: tuple[str, ...] = ()) -> None:
        self.kind = kind
        self.order = order  # names listed first by available(), in this order
        self._items: dict[str, T] = {}

    def register(self, name: str) -> Callable[[T], T]:
        def decorator(obj: T) -> T:
            if name in self._items:
                raise ValueError(f"{self.kind} {name!r} is already registered")
            self._items[name] = obj
            return obj

        return decorator

    def get(self, name: str) -> T:
        try:
            return self._items[name]
        except KeyError:
            raise UnknownNameError(
                f"unknown {self.kind} {name!r}; expected one of: {', '.join(self.available())}"
            ) from None

    def available(self) -> list[str]:
        """Registered names: those in ``order`` first (in that order), then the rest as registered."""
        first = [n for n in self.order if n in self._items]
        return first + [n for n in self._items if n not in first]

    def __contains__(self, name: object) -> bool:
        return name in self._items
