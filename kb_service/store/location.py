"""A store's location as logs, errors and the process list may show it: a URL's password is never shown."""
from __future__ import annotations

from urllib.parse import urlsplit, urlunsplit


def shown_location(db: str) -> str:
    """The URL as logs and errors may show it: a password is replaced by `***`."""
    try:
        parts = urlsplit(db)
        if parts.password is None:
            return db
        netloc = parts.netloc.rsplit("@", 1)
        user = (parts.username or "") + ":***"
        return urlunsplit(parts._replace(netloc=f"{user}@{netloc[1]}"))
    except ValueError:
        return "<a database URL that does not parse>"


def url_password(db: str) -> bool:
    """Whether a database URL carries a password."""
    try:
        return urlsplit(db).password is not None
    except ValueError:
        return False
