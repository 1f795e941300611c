"""The store's unit of work (`UnitOfWork`), written once for every engine: the store's lock and the guard every
public method takes (`Guard`), nested transactions that join the outermost one, the counts of triples and objects
(kept by the commits, so /health reads them without a query) and what is told of a commit or a rollback
(`TransactionListener`: the record caches, the count of journalled plans).

An engine (`abox.Abox` on SQLite, `postgres.session.Session`) supplies only its connection: one transaction on it
(`_one_transaction`: commit, or roll back and forget what it cached of the transaction), closing it, and what the
guard asks of it (`ready`, `lost`). Every method here but the guard's is called with `lock` held.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
import threading
from contextlib import AbstractContextManager, contextmanager
from typing import Callable, Iterator, Protocol, TypeVar

from .errors import KBError

T = TypeVar("T")


class TransactionListener(Protocol):
    """What keeps state about uncommitted writes: told when the open transaction commits or rolls back."""

    def committed(self) -> None: ...

    def rolled_back(self) -> None: ...


class Guard:
    """`with guard:` holds the store's lock, refuses a closed store and readies the engine's connection (what every
    public method of the store does first); an error the engine names (a lost connection) is raised as its own."""

    __slots__ = ("_unit",)

    def __init__(self, unit: UnitOfWork) -> None:
        self._unit = unit

    def __enter__(self) -> None:
        unit = self._unit
        unit.lock.acquire()
        try:
            unit.check_open()
            unit.ready()
        except BaseException:
            unit.lock.release()
            raise

    def __exit__(self, exc_type: object, exc: BaseException | None, tb: object) -> None:
        self._unit.lock.release()
        lost = None if exc is None else self._unit.lost(exc)
        if lost is not None:
            raise lost from None


class UnitOfWork(ABC):
    """One connection's transactions, one at a time, with the store's counts and listeners."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.closed = False
        self.depth = 0  # nesting of `transaction()`: writes inside commit with the outermost one
        self.triples = self.objects = 0  # counted once at open, then kept by this process's commits
        self.pending_triples = self.pending_objects = 0  # written by the open transaction
        self._listeners: tuple[TransactionListener, ...] = ()
        self.guard = Guard(self)

    def listen(self, *listeners: TransactionListener) -> None:
        self._listeners = listeners

    def check_open(self) -> None:
        if self.closed:
            raise KBError("knowledge base: closed")

    def close(self) -> None:
        self.closed = True
        self._close_connection()

    def note_object(self) -> None:
        """The open transaction creates one more object (the store's count follows its commit)."""
        self.pending_objects += 1

    # -- transactions ---------------------------------------------------------------------------------------
    def write(self, fill: Callable[[], T]) -> T:
        """Run `fill()` (which adds triples / side-table rows) in one transaction; roll back on any error.
        Inside `transaction()` it only adds to the open transaction, which commits or rolls back as a whole."""
        if self.depth:
            return fill()
        with self.transaction():
            return fill()

    @contextmanager
    def transaction(self) -> Iterator[None]:
        """Every write inside the block is one transaction: all of them commit together at the end, or, when
        anything in the block raises (a refused write included), none does and the store is as before."""
        if self.depth:
            self.depth += 1
            try:
                yield
            finally:
                self.depth -= 1
            return
        self.depth = 1
        try:
            with self._one_transaction():
                yield
        except BaseException:
            self.pending_triples = self.pending_objects = 0
            for listener in self._listeners:
                listener.rolled_back()
            raise
        else:
            self.triples += self.pending_triples
            self.objects += self.pending_objects
            self.pending_triples = self.pending_objects = 0
            for listener in self._listeners:
                listener.committed()
        finally:
            self.depth = 0

    # -- what an engine supplies ------------------------------------------------------------------------------
    @abstractmethod
    def _one_transaction(self) -> AbstractContextManager[None]:
        """One transaction on the connection: committed when the block ends, rolled back when it raises (and what
        the engine cached of it forgotten)."""

    @abstractmethod
    def _close_connection(self) -> None:
        """Close the engine's connection."""

    def ready(self) -> None:
        """Make the connection ready for a request (the guard held): nothing, unless the engine can lose it."""

    def lost(self, exc: BaseException) -> BaseException | None:
        """The error a request that raised `exc` ends with instead (a lost connection), or None to let it be."""
        return None
