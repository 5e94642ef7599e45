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
