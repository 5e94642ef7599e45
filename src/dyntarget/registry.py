"""One generic name -> object registry, used for classifiers and planners.

An entry may be *lazy*: ``"module:attribute"``, imported the first time the
name is looked up, so listing names (and importing the registry) loads nothing.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Generic, TypeVar

from dyntarget.errors import UnknownNameError

T = TypeVar("T")


class Registry(Generic[T]):
    """Objects registered under unique names.

    Parameters
    ----------
    kind : str
        What is registered (``"planner"``, ``"classifier"``...), named in error messages.
    order : tuple of str
        Names that :meth:`available` lists first, in this order.

    Examples
    --------
    >>> r = Registry[type]("widget")
    >>> @r.register("a")
    ... class A: ...
    >>> r.get("a") is A
    True
    >>> r.available()
    ['a']
    >>> r.register_lazy("join", "os.path:join")
    >>> r.get("join").__name__
    'join'
    """

    def __init__(self, kind: str, *, order: tuple[str, ...] = ()) -> None:
        self.kind = kind
        self.order = order  # names listed first by available(), in this order
        self._items: dict[str, T | str] = {}

    def register(self, name: str) -> Callable[[T], T]:
        """Decorator registering an object under ``name`` (it may replace a lazy entry).

        Parameters
        ----------
        name : str
            The unique name.

        Returns
        -------
        Callable
            The decorator; it returns the object unchanged.
        """

        def decorator(obj: T) -> T:
            if name in self._items and not isinstance(self._items[name], str):
                raise ValueError(f"{self.kind} {name!r} is already registered")
            self._items[name] = obj
            return obj

        return decorator

    def register_lazy(self, name: str, target: str) -> None:
        """Register ``name`` as ``"module:attribute"``, imported on first :meth:`get`.

        Parameters
        ----------
        name : str
            The unique name.
        target : str
            Where the object lives, ``"package.module:attribute"``.
        """
        if name in self._items:
            raise ValueError(f"{self.kind} {name!r} is already registered")
        if target.count(":") != 1:
            raise ValueError(
                f"lazy {self.kind} {name!r}: expected 'module:attribute', got {target!r}"
            )
        self._items[name] = target

    def get(self, name: str) -> T:
        """The object registered as ``name`` (importing a lazy entry's module).

        Parameters
        ----------
        name : str
            A registered name.

        Returns
        -------
        object
            The registered object; an unknown name raises :class:`UnknownNameError`
            listing the valid ones.
        """
        try:
            item = self._items[name]
        except KeyError:
            raise UnknownNameError(
                f"unknown {self.kind} {name!r}; expected one of: {', '.join(self.available())}"
            ) from None
        if isinstance(item, str):
            module, attribute = item.split(":")
            item = getattr(importlib.import_module(module), attribute)
            self._items[name] = item
        return item

    def available(self) -> list[str]:
        """Registered names: those in ``order`` first (in that order), then the rest as registered.

        Returns
        -------
        list of str
            The registered names, lazy entries included.
        """
        first = [n for n in self.order if n in self._items]
        return first + [n for n in self._items if n not in first]

    def __contains__(self, name: object) -> bool:
        return name in self._items
