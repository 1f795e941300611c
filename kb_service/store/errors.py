"""Errors of the knowledge base. HTTP status codes are chosen only in kb_service's API layer."""
from __future__ import annotations

from planhrc.errors import DeadlineExceeded, PlanhrcError


class KBError(PlanhrcError):
    """Root of every knowledge-base error."""


class NotFoundError(KBError):
    """An id names no object, state, problem, plan or action."""


class ValidationError(KBError):
    """Input refused before anything was written; the message names the field."""


class ConflictError(KBError):
    """The write contradicts what is stored (duplicate id, action that is not the current one, ...)."""


class ReasonerError(KBError):
    """The DL reasoner could not run (no Java, Java error, timeout)."""


class DeadlineError(KBError, DeadlineExceeded):
    """The request's planning (with VAL) did not finish within its deadline; nothing was stored. The one
    `DeadlineExceeded` of planhrc, as the service raises it (a `KBError` too, for the service's handlers)."""


class DamagedStoreError(KBError):
    """What the store reads back is not what it writes (a record without a required fact, a journal row of an
    unknown layout): the database was changed by something else, or by a newer version."""


class UnavailableError(KBError):
    """The store's database server cannot be reached now (down, restarting, or the connection was cut); nothing of
    the request was written, and the same request may succeed later."""
