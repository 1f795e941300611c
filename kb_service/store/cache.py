"""The one cached get of the store's records: from the cache, else loaded from
the backend (a journalled plan, its actions and expected states from its row), else NotFoundError.

Records are immutable, so a cached one is never stale; the cache is dropped whole (after a rollback, or when it
grows past its limit) and refills on demand. Nothing here depends on a backend: it is given the loader.
"""
from __future__ import annotations

from typing import Callable, Generic, Protocol, TypeVar

from .errors import NotFoundError


class Record(Protocol):
    @property
    def id(self) -> str: ...


R = TypeVar("R", bound=Record)


class RecordCache(Generic[R]):
    """Records of one kind by id; a record may be put as the way to make it (`put_later`), made when first got."""

    def __init__(self, noun: str, kind: type[R], load: Callable[[str], R | None]) -> None:
        self.noun = noun
        self._kind = kind
        self._load = load
        self._records: dict[str, R] = {}
        self._later: dict[str, Callable[[], R]] = {}

    def get(self, ident: str) -> R:
        """The record `ident`; NotFoundError naming the field `<noun>_id` when there is none."""
        if not isinstance(ident, str):
            raise NotFoundError(f"{self.noun}_id: no {self.noun} {ident!r}")
        record = self._records.get(ident)
        if record is None:
            make = self._later.pop(ident, None)
            record = make() if make is not None else self._load(ident)
            if record is None:
                raise NotFoundError(f"{self.noun}_id: no {self.noun} {ident!r}")
            self._records[ident] = record
        return record

    def put(self, record: R) -> None:
        self._records[record.id] = record
        self._later.pop(record.id, None)

    def put_later(self, ident: str, make: Callable[[], R]) -> None:
        """The record `ident`, made by `make()` when it is first got (a plan's expected state, made whole only
        then)."""
        self._records.pop(ident, None)
        self._later[ident] = make

    def clear(self) -> None:
        self._records.clear()
        self._later.clear()

    def __len__(self) -> int:
        return len(self._records) + len(self._later)

