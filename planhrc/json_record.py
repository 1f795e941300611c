"""Frozen records kept as JSON data: the object's event log's (`event_log`) and the answers the service's
idempotency keys remember (`kb_service.usecases.values.Turn`, `FeedbackResult`). A record's `to_data` and `of_data`
come from its fields' types, which pydantic reads (`TypeAdapter`): one definition writes a record, reads it back (old
rows included: a field added later has a default) and gives the HTTP API its schema, the attribute docstrings its
descriptions.
"""
from __future__ import annotations

from typing import Any, ClassVar, Mapping, TypeVar

from pydantic import ConfigDict, TypeAdapter, ValidationError

from planhrc.errors import PlanhrcError

R = TypeVar("R", bound="JsonRecord")


class RecordError(PlanhrcError):
    """JSON data that holds no record of the class asked for (a field missing or of another type)."""


class JsonRecord:
    """A frozen dataclass kept as JSON (subclass it, `@dataclass(frozen=True, kw_only=True)`)."""

    __pydantic_config__: ClassVar[ConfigDict] = ConfigDict(use_attribute_docstrings=True)

    def to_data(self, defaults: bool = False) -> dict[str, Any]:
        """The record as JSON data; the fields left at their defaults only with `defaults` (a stored record omits
        them: `of_data` puts them back)."""
        data: dict[str, Any] = _adapter(type(self)).dump_python(self, mode="json", exclude_defaults=not defaults)
        return data

    @classmethod
    def of_data(cls: type[R], data: Mapping[str, Any]) -> R:
        """The record `data` holds; RecordError when it holds none."""
        try:
            record: R = _adapter(cls).validate_python(data)
        except ValidationError as exc:
            error = exc.errors()[0]
            where = ".".join(str(part) for part in error["loc"]) or "data"
            raise RecordError(f"{cls.__name__}: {where}: {error['msg']}") from None
        return record


_ADAPTERS: dict[type, TypeAdapter[Any]] = {}  # made on a class's first use (two threads may both make one)


def _adapter(cls: type) -> TypeAdapter[Any]:
    adapter = _ADAPTERS.get(cls)
    if adapter is None:
        adapter = _ADAPTERS[cls] = TypeAdapter(cls)
    return adapter
