"""Exceptions raised by firmware generation.

All subclass :class:`sysid.core.errors.HelmetAncError` (a ``ValueError``), so the
command-line front ends turn them into a one-line message and exit status 2.
The lowest floor of ``codegen``: every other module may import it, it imports none.
"""

from sysid.core.errors import HelmetAncError

__all__ = [
    "BuildError",
    "CodegenError",
    "InvalidNameError",
    "OutputError",
    "PrecisionError",
    "UnstableModelError",
    "VerificationError",
]


class CodegenError(HelmetAncError):
    """Base class of the errors of firmware generation."""


class InvalidNameError(CodegenError):
    """A requested C identifier is not a safe, non-reserved C99 identifier."""


class UnstableModelError(CodegenError):
    """The model (or its re-discretisation) has a pole on or outside the unit circle."""


class PrecisionError(CodegenError):
    """A variant cannot meet the requested signal-to-noise ratio or cannot be represented."""


class OutputError(CodegenError):
    """The output directory cannot be written."""


class BuildError(CodegenError):
    """The generated C code does not compile on the host."""


class VerificationError(CodegenError):
    """The generated C code disagrees with its Python reference."""
