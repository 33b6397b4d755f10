"""References ``"package.module:attribute"`` to an effect's functions, resolved on first use.

An ``Effect`` may name its detector, builder, completion, ... by a dotted reference
instead of holding the function (``detect="sysid.findings.delay:delay_finding"``):
the registry then imports nothing of what the reference names until the field is
read, so looking effects up (``sysid.simulate``) does not load the detectors
(``sysid.findings``) or the refits (``sysid.refits``) and the estimators behind
them. A callable is taken as it is (a user's own effect passes its functions).
"""

from __future__ import annotations

import importlib

from ..core.errors import HelmetAncError

__all__ = ["resolve", "Resolved"]


def resolve(target):
    """The object ``target`` names when it is a reference ``"package.module:attribute"`` (the attribute
    may be dotted); anything else (a callable, None) as it is."""
    if not isinstance(target, str):
        return target
    module_name, colon, attribute = target.partition(":")
    if not colon or not module_name or not attribute:
        raise HelmetAncError(f"reference {target!r}: expected 'package.module:attribute'")
    value = importlib.import_module(module_name)
    for name in attribute.split("."):
        try:
            value = getattr(value, name)
        except AttributeError:
            raise HelmetAncError(f"reference {target!r}: {module_name} has no attribute {attribute!r}") from None
    if not callable(value):
        raise HelmetAncError(f"reference {target!r}: names {type(value).__name__}, not a callable")
    return value


class Resolved:
    """A dataclass field (default None) holding a callable or a reference to one: reading it resolves
    the reference (``resolve``) once and keeps the callable. The value as given stays readable in the
    instance's ``__dict__`` under the field's name."""

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, instance, owner=None):
        if instance is None:
            # What dataclasses read as the field's default.
            return None
        value = instance.__dict__[self.name]
        if isinstance(value, str):
            value = instance.__dict__[self.name] = resolve(value)
        return value

    def __set__(self, instance, value) -> None:
        if value is not None and not isinstance(value, str) and not callable(value):
            raise HelmetAncError(f"{self.name} must be a callable or a reference 'package.module:attribute'; "
                                 f"found {type(value).__name__}")
        # The instance's own dict: a frozen dataclass sets its fields once, in __init__, through here.
        instance.__dict__[self.name] = value
