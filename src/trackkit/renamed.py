"""Refusing a keyword under its old name, with a message that names the new one.

A renamed keyword that Python merely rejected ("unexpected keyword argument 'T'") would leave
the caller to guess the new spelling; one silently accepted would keep two vocabularies alive.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])


def renamed_keywords(**old_to_new: str) -> Callable[[F], F]:
    """Decorate a function whose keywords ``old`` are now spelled ``new``: a call that uses an
    old spelling raises ``TypeError`` naming the new one (``renamed_keywords(T="dt")``)."""

    def decorate(fn: F) -> F:
        @functools.wraps(fn)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            if kwargs:
                old = next((k for k in kwargs if k in old_to_new), None)
                if old is not None:
                    raise TypeError(f"{fn.__qualname__}: the keyword {old!r} is now spelled "
                                    f"{old_to_new[old]!r}; pass {old_to_new[old]}= instead")
            return fn(*args, **kwargs)

        return wrapper  # type: ignore[return-value]

    return decorate


def renamed_attribute(owner: str, old: str, new: str) -> property:
    """A property that refuses ``owner.old`` with an ``AttributeError`` naming ``owner.new``
    (for a field renamed on a NamedTuple, where an alias would keep the old name alive)."""

    def refuse(self: Any) -> Any:
        raise AttributeError(f"{owner}.{old} is now spelled {owner}.{new}")

    return property(refuse)
