"""Exceptions raised by the identification package.

Every error a user can provoke with bad input is one of these; the command-line
front end turns them into a one-line message and exit status 2.
"""

__all__ = ["HelmetAncError", "RecordingError", "ModelError", "IdentificationError"]


class HelmetAncError(ValueError):
    """Base class of all user-facing errors of helmet-anc."""


class RecordingError(HelmetAncError):
    """A recording cannot be used: unreadable, wrong layout, bad samples, too short."""


class ModelError(HelmetAncError):
    """A model file or model object violates the helmet-anc/model@1 contract."""


class IdentificationError(HelmetAncError):
    """Identification cannot proceed with the given data or options."""
