"""The errors dyntarget raises.

Every error the library raises on purpose derives from :class:`DynTargetError`,
so callers (and the CLI) can tell "your input is wrong" from "the code is
broken". Each message names the argument or file, what was received and what
was expected.
"""

from __future__ import annotations


class DynTargetError(Exception):
    """Root of every error raised on purpose by dyntarget."""


class InvalidSceneError(DynTargetError, ValueError):
    """An image or label does not meet the scene conventions (shape, bands, values)."""


class InvalidParameterError(DynTargetError, ValueError):
    """A setting is out of its valid range or of the wrong type."""


class DataFileError(DynTargetError, OSError):
    """A file is missing, unreadable, corrupt or of the wrong kind."""


class UnknownNameError(DynTargetError, LookupError):
    """A name (classifier, planner, preset) is not registered."""

    def __str__(self) -> str:  # LookupError would quote the message
        return str(self.args[0]) if self.args else ""


class ModelFileError(DataFileError):
    """A model file is foreign, tampered with, or does not match its metadata."""


class ExportError(ModelFileError):
    """An exported model (ONNX) does not reproduce the native model's output."""


class MissingExtraError(DynTargetError, ImportError):
    """An optional dependency is not installed; the message names the extra to install."""


EXTRAS = {
    "onnxruntime": "onboard",
    **dict.fromkeys(
        (
            "torch", "sklearn", "skops", "safetensors", "matplotlib", "dask", "distributed",
            "onnx", "onnxscript", "skl2onnx",
        ),
        "full",
    ),
}  # fmt: skip
"""Top-level module -> the ``pip install "dyntarget[EXTRA]"`` extra that provides it."""


def missing_extra(exc: ImportError) -> MissingExtraError | None:
    """The :class:`MissingExtraError` for an import of an optional dependency that failed.

    Parameters
    ----------
    exc : ImportError
        The error an ``import`` raised.

    Returns
    -------
    MissingExtraError or None
        ``None`` when the missing module is not one of the optional dependencies.

    Examples
    --------
    >>> print(missing_extra(ModuleNotFoundError("No module named 'torch'", name="torch")))
    torch is not installed: pip install "dyntarget[full]"
    >>> missing_extra(ModuleNotFoundError("No module named 'foo'", name="foo")) is None
    True
    """
    top = (getattr(exc, "name", None) or "").split(".")[0]
    extra = EXTRAS.get(top)
    if extra is None:
        return None
    return MissingExtraError(f'{top} is not installed: pip install "dyntarget[{extra}]"')


def require(module: str) -> None:
    """Raise :class:`MissingExtraError` now if the optional ``module`` is not installed.

    For commands that would otherwise find out after writing part of their output.

    Parameters
    ----------
    module : str
        A key of :data:`EXTRAS`.

    Examples
    --------
    >>> require("numpy") is None  # not optional: nothing to check
    True
    """
    import importlib.util

    extra = EXTRAS.get(module)
    if extra is not None and importlib.util.find_spec(module) is None:
        raise MissingExtraError(f'{module} is not installed: pip install "dyntarget[{extra}]"')
