"""Every public function and class of ``dyntarget`` has a numpydoc docstring with the sections
its signature calls for.

The public API walked here:

* modules: every module and package under ``dyntarget`` with no dotted part starting with
  ``_`` (so not ``dyntarget.cli._common`` nor ``__main__``). The command modules of the CLI
  (``dyntarget.cli.<command>``) are left out: they hold argparse glue, ``cmd_*`` handlers
  (an ``argparse.Namespace`` in, an exit code out) and ``register(sub)``, whose interface is
  the command line that ``--help`` documents. ``dyntarget.cli`` itself (``main``,
  ``build_parser``) is checked.
* objects: the functions and classes a public module defines under a name not starting
  with ``_``, plus the names its ``__all__`` re-exports (which may come from a private
  module). Each object is checked once, however many modules import it.
* methods: the public methods (functions, static and class methods) of a public class,
  including those it inherits from a base class defined in ``dyntarget`` (even a private
  one), each checked once on the class that defines it. Dunder methods, hence the methods
  that ``dataclass`` and ``NamedTuple`` generate (``__init__``, ``__repr__``, ``__eq__``...),
  are not checked themselves. A class or an override without a docstring of its own
  inherits its base's (``inspect.getdoc``), which must then match its own signature.
* properties are attributes: they need a docstring (what the value is), but no
  Parameters or Returns section.

The rule, per function or method:

* a docstring that numpydoc's ``NumpyDocString`` parses without a warning or an error;
* when it takes parameters besides ``self``/``cls``: a ``Parameters`` section documenting
  exactly the signature's names (``*args``/``**kwargs`` as ``*args``/``**kwargs`` or
  without the stars; ``a, b : float`` documents both). Parameters whose names start
  with ``_`` (a dataclass's private fields) are private and need not be documented;
* when it returns something: a ``Returns`` or ``Yields`` section (``Yields`` for
  generators and context managers, by convention; either satisfies the check). It
  returns something when its return annotation is present and not ``None`` (nor
  ``NoReturn``/``Never``); without an annotation, when its body has a ``return`` with a
  value or a ``yield``.

Per class: numpydoc's convention, the constructor's parameters are documented in the
class docstring's ``Parameters`` section (``__init__`` itself is not checked); for a
dataclass or a ``NamedTuple`` these are its ``__init__`` fields. The constructor is
checked when ``dyntarget`` defines it (an ``__init__`` or ``__new__`` of the class or of
a ``dyntarget`` base, generated ones included); enums, protocols, ``int`` subclasses and
exceptions that keep ``Exception``'s constructor are not, but still need a docstring.

Only names and sections are checked by machine; types, units and descriptions are
reviewed by people. The failure message lists every offender, one line each.
"""

from __future__ import annotations

import ast
import dataclasses
import enum
import importlib
import inspect
import pkgutil
import textwrap
import types
import warnings
from collections.abc import Iterator

import dyntarget

CLI_COMMAND_PACKAGE = "dyntarget.cli"
NOTHING = {"None", "NoReturn", "Never", "typing.NoReturn", "typing.Never"}


def _public_modules() -> list[types.ModuleType]:
    names = [dyntarget.__name__]
    for info in pkgutil.walk_packages(dyntarget.__path__, prefix="dyntarget."):
        parts = info.name.split(".")
        if any(p.startswith("_") for p in parts):
            continue
        if info.name.startswith(CLI_COMMAND_PACKAGE + "."):
            continue
        names.append(info.name)
    return [importlib.import_module(n) for n in sorted(names)]


def _ours(obj: object) -> bool:
    return (getattr(obj, "__module__", None) or "").split(".")[0] == "dyntarget"


def _public_objects() -> dict[int, tuple[str, object]]:
    """``id -> (dotted name, object)`` of the public functions and classes."""
    found: dict[int, tuple[str, object]] = {}
    for module in _public_modules():
        exported = set(getattr(module, "__all__", ()))
        for name, obj in vars(module).items():
            if name.startswith("_") or not (inspect.isfunction(obj) or inspect.isclass(obj)):
                continue
            if not _ours(obj):
                continue
            defined_here = obj.__module__ == module.__name__
            if defined_here or name in exported:
                found.setdefault(id(obj), (f"{obj.__module__}.{obj.__qualname__}", obj))
    return found


def _returns_something(func) -> bool:
    try:
        annotation = inspect.signature(func).return_annotation
    except (TypeError, ValueError):
        annotation = inspect.Signature.empty
    if annotation is not inspect.Signature.empty:
        if annotation is None or annotation is type(None):
            return False
        return str(getattr(annotation, "__name__", annotation)).strip("'\"") not in NOTHING
    try:
        source = textwrap.dedent(inspect.getsource(func))
    except (OSError, TypeError):
        return False
    tree = ast.parse(source).body[0]
    pending = list(ast.iter_child_nodes(tree))
    while pending:
        node = pending.pop()
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda | ast.ClassDef):
            continue  # a nested scope's returns are its own
        if isinstance(node, ast.Yield | ast.YieldFrom):
            return True
        if isinstance(node, ast.Return) and node.value is not None:
            if not (isinstance(node.value, ast.Constant) and node.value.value is None):
                return True
        pending.extend(ast.iter_child_nodes(node))
    return False


def _parse(doc: str):
    """numpydoc's parse of ``doc``, or the reason it fails."""
    from numpydoc.docscrape import NumpyDocString

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            parsed = NumpyDocString(doc)
        except Exception as exc:  # numpydoc raises ValueError on malformed sections
            return None, f"numpydoc cannot parse it ({exc})"
    if caught:
        return None, f"numpydoc warns: {caught[0].message}"
    return parsed, None


def _documented(parsed) -> set[str]:
    names = set()
    for param in parsed["Parameters"]:
        for name in param.name.split(","):
            names.add(name.strip().lstrip("*"))
    return names - {""}


def _parameter_names(sig: inspect.Signature, skip_first: bool) -> list[str]:
    params = list(sig.parameters.values())
    if skip_first and params:
        params = params[1:]
    return [p.name for p in params if not p.name.startswith("_")]


def _check(
    label: str, doc: str | None, names: list[str], returns: bool, generator: bool
) -> Iterator[str]:
    if not doc or not doc.strip():
        yield f"{label}: no docstring"
        return
    parsed, problem = _parse(doc)
    if problem:
        yield f"{label}: {problem}"
        return
    if names or parsed["Parameters"]:
        documented = _documented(parsed)
        missing = [n for n in names if n not in documented]
        extra = sorted(documented - set(names))
        if not parsed["Parameters"]:
            yield f"{label}: no Parameters section (takes {', '.join(names)})"
        elif missing or extra:
            what = []
            if missing:
                what.append(f"undocumented {', '.join(missing)}")
            if extra:
                what.append(f"documented but not in the signature {', '.join(extra)}")
            yield f"{label}: Parameters do not match the signature ({'; '.join(what)})"
    if returns:
        if generator and not (parsed["Yields"] or parsed["Returns"]):
            yield f"{label}: no Yields section"
        elif not generator and not (parsed["Returns"] or parsed["Yields"]):
            yield f"{label}: no Returns section"


def _check_function(label: str, func, *, method: bool) -> Iterator[str]:
    try:
        sig = inspect.signature(func)
    except (TypeError, ValueError):
        return
    names = _parameter_names(sig, skip_first=method)
    generator = inspect.isgeneratorfunction(func) or inspect.isasyncgenfunction(func)
    yield from _check(label, inspect.getdoc(func), names, _returns_something(func), generator)


def _constructor_is_ours(cls: type) -> bool:
    if issubclass(cls, enum.Enum) or getattr(cls, "_is_protocol", False):
        return False
    if dataclasses.is_dataclass(cls):
        return True
    for base in cls.__mro__:
        if base is object:
            return False
        if "__init__" in vars(base) or "__new__" in vars(base):
            return _ours(base) or hasattr(base, "_fields")  # a NamedTuple's generated __new__
    return False


def _check_class(label: str, cls: type, seen: set[tuple[type, str]]) -> Iterator[str]:
    doc = inspect.getdoc(cls)
    if _constructor_is_ours(cls):
        try:
            names = _parameter_names(inspect.signature(cls), skip_first=False)
        except (TypeError, ValueError):
            names = []
        yield from _check(label, doc, names, returns=False, generator=False)
    elif not doc or not doc.strip():
        yield f"{label}: no docstring"
    for owner in cls.__mro__:
        if not _ours(owner):
            continue
        for name, attr in vars(owner).items():
            if name.startswith("_") or (owner, name) in seen:
                continue
            where = f"{owner.__module__}.{owner.__qualname__}.{name}"
            if isinstance(attr, property):
                seen.add((owner, name))
                if not (attr.__doc__ or "").strip():
                    yield f"{where}: property without a docstring"
                continue
            if isinstance(attr, staticmethod):
                seen.add((owner, name))
                yield from _check_function(where, attr.__func__, method=False)
            elif isinstance(attr, classmethod):
                seen.add((owner, name))
                yield from _check_function(where, attr.__func__, method=True)
            elif inspect.isfunction(attr):
                seen.add((owner, name))
                yield from _check_function(where, attr, method=True)


def offenders() -> list[str]:
    """Every public function, class and method that breaks the rule, one line each."""
    found: list[str] = []
    seen: set[tuple[type, str]] = set()
    for label, obj in sorted(_public_objects().values(), key=lambda item: item[0]):
        if inspect.isclass(obj):
            found.extend(_check_class(label, obj, seen))
        else:
            found.extend(_check_function(label, obj, method=False))
    return found


def test_public_api_has_numpydoc_sections():
    found = offenders()
    assert not found, f"{len(found)} docstrings break the rule:\n" + "\n".join(found)


def test_the_walk_finds_the_api():
    """The checker sees what it should (a guard against a walk that finds nothing)."""
    labels = {label for label, _ in _public_objects().values()}
    assert {"dyntarget.plan.planners.plan", "dyntarget.perceive.unet.Stitching"} <= labels
    assert "dyntarget.cli.main" in labels
    assert not any(label.startswith("dyntarget.cli.plan.") for label in labels)
    assert len(labels) > 100
