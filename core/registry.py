"""One registry type for every "name -> thing" catalogue roadload keeps (model structures, candidate effects,
regimes, road profiles): registration with an explicit replace, look-up by name or pass-through of an instance,
and an error that names the closest known name and lists them all."""

from __future__ import annotations

import difflib
from typing import Callable, Generic, Iterable, Iterator, TypeVar

__all__ = ["Registry", "did_you_mean"]

T = TypeVar("T")


def did_you_mean(value: object, choices: Iterable[object]) -> str:
    """`` (did you mean 'x'?)`` naming the closest of ``choices`` to ``value`` (case-insensitive, difflib ratio
    >= 0.6), or an empty string when none is close: the hint every "unknown name" message carries."""
    options = {str(c).lower(): str(c) for c in choices}
    close = difflib.get_close_matches(str(value).lower(), list(options), n=1, cutoff=0.6)
    return f" (did you mean {options[close[0]]!r}?)" if close else ""


class Registry(Generic[T]):
    """Named entries of one kind.

    kind: what the entries are, for messages ("model", "candidate effect", ...); item_type: the entries' class
    (instances of it pass through :meth:`get` unchanged); error: the exception type raised for bad names;
    normalise: maps a name to its key (e.g. ``str.lower`` for case-insensitive names).
    """

    def __init__(self, kind: str, item_type: type[T] | None = None, error: type[Exception] = KeyError,
                 normalise: Callable[[str], str] | None = None) -> None:
        self.kind = kind
        self.item_type = item_type
        self.error = error
        self._normalise = normalise or (lambda name: name)
        self._items: dict[str, T] = {}

    def register(self, name: str, item: T, replace_existing: bool = False) -> T:
        """Add ``item`` under ``name``; the error type if the name is taken and ``replace_existing`` is False."""
        if self.item_type is not None and not isinstance(item, self.item_type):
            raise self.error(f"a {self.kind} must be a {self.item_type.__name__}, got {type(item).__name__}")
        if not isinstance(name, str) or not name:
            raise self.error(f"a {self.kind} needs a non-empty name, got {name!r}")
        key = self._normalise(name)
        if key in self._items and not replace_existing:
            raise self.error(f"a {self.kind} named {name!r} is already registered; pass replace_existing=True")
        self._items[key] = item
        return item

    def get(self, name: str | T) -> T:
        """The entry of that name (an instance of ``item_type`` is returned as it is)."""
        if self.item_type is not None and isinstance(name, self.item_type):
            return name
        entry = self.find(name) if isinstance(name, str) else None
        if entry is None:
            raise self.error(f"unknown {self.kind} {name!r}{did_you_mean(name, self.names())}; known: "
                             f"{', '.join(self.names()) or '(none)'}")
        return entry

    def find(self, name: str) -> T | None:
        """The entry of that name, or None."""
        return self._items.get(self._normalise(name))

    def names(self) -> list[str]:
        """Registered names in registration order."""
        return list(self._items)

    def items(self) -> Iterator[tuple[str, T]]:
        return iter(self._items.items())

    def snapshot(self) -> dict[str, T]:
        """A copy of the entries (for :meth:`restore`, e.g. to undo registrations made in a test)."""
        return dict(self._items)

    def restore(self, snapshot: dict[str, T]) -> None:
        self._items = dict(snapshot)

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and self._normalise(name) in self._items

    def __len__(self) -> int:
        return len(self._items)
