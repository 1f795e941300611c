"""How `planhrc serve` may face a network: a service bound to an address other than loopback needs a token (or
`--insecure`, said at every start); secrets (tokens, the database password) come from files or the environment,
and one given on the command line, which every user of the machine sees in the process list, is warned about; TLS
is uvicorn's (a certificate and its key) or a reverse proxy's.

The checks run before anything starts: a setting the service cannot start with is a `SettingsProblem` naming the
option or `PLANHRC_*` variable; what it can start with but should not is a warning line.
"""
from __future__ import annotations

import ipaddress
import os
import socket
import ssl
import stat
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from pydantic import SecretStr

from .store.errors import KBError
from .store.location import url_password

if TYPE_CHECKING:
    from planhrc.settings import Settings

Name = Callable[[str], str]  # settings field -> the option or variable that set it


class SettingsProblem(KBError):
    """A setting the service cannot start with; the message names the option or variable."""


def is_loopback(host: str) -> bool:
    """Whether `host` (an address or a name) is reachable from this machine only: every address it resolves to is
    a loopback one. The wildcard addresses (0.0.0.0, ::) are every interface, not loopback."""
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        pass
    try:
        found = {info[4][0] for info in socket.getaddrinfo(host, None)}
    except OSError:
        return False
    return bool(found) and all(ipaddress.ip_address(str(a).split("%", 1)[0]).is_loopback for a in found)


def read_secret(path: str, option: str, warnings: list[str]) -> str:
    """The first line of a secret's file; a file others may read is warned about."""
    try:
        info = os.stat(path)
        with open(path, encoding="utf-8") as f:
            secret = f.readline().strip()
    except OSError as exc:
        raise SettingsProblem(f"{option}: cannot read {path} ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise SettingsProblem(f"{option}: {path} is not text") from None
    if not secret:
        raise SettingsProblem(f"{option}: {path} is empty (the secret is its first line)")
    if info.st_mode & (stat.S_IRGRP | stat.S_IROTH):
        warnings.append(f"{option}: {path} is readable by other users of this machine (chmod 600 {path})")
    return secret


def resolve_secrets(settings: Settings, given: set[str], name: Name, warnings: list[str]) -> Settings:
    """Settings with the tokens and the database password read from their files, and a warning for each secret
    given on the command line."""
    update: dict[str, object] = {}
    for field, file_field in (("token", "token_file"), ("read_token", "read_token_file")):
        path = getattr(settings, file_field)
        if path and getattr(settings, field):
            raise SettingsProblem(f"{name(field)} and {name(file_field)}: give the {field.replace('_', ' ')} one "
                                  "way, not both")
        if path:
            update[field] = read_secret(path, name(file_field), warnings)
        elif getattr(settings, field) and field in given:
            warnings.append(f"{name(field)}: a secret on the command line shows in the process list (ps) of every "
                            f"user of this machine; use {name(file_field)} or PLANHRC_{field.upper()}")
    if settings.db_password_file:
        if settings.db_password is not None:
            raise SettingsProblem(f"{name('db_password_file')} and PLANHRC_DB_PASSWORD: give the password one way")
        update["db_password"] = SecretStr(read_secret(settings.db_password_file, name("db_password_file"), warnings))
    if "db_path" in given and _url_password(settings.db_path):
        warnings.append(f"{name('db_path')}: the URL's password shows in the process list (ps) of every user of "
                        f"this machine; use {name('db_password_file')}, PGPASSFILE or PLANHRC_DB")
    return settings.model_copy(update=update) if update else settings  # values of the fields' types: no validation


def check_exposure(settings: Settings, name: Name, warnings: list[str], has_clients: bool = False) -> None:
    """Refuse a service open to the network without a token or a client's key in its store (`has_clients`:
    `planhrc keys add`), unless `insecure`, and TLS files that do not load; warn of an insecure service and of a
    key sent in clear over a network."""
    if settings.ssl_keyfile and not settings.ssl_certfile:
        raise SettingsProblem(f"{name('ssl_keyfile')}: a key needs its certificate ({name('ssl_certfile')})")
    if settings.ssl_certfile:
        for field in ("ssl_certfile", "ssl_keyfile"):
            path = getattr(settings, field)
            if path and not Path(path).is_file():
                raise SettingsProblem(f"{name(field)}: no such file {path}")
        try:
            ssl.create_default_context(ssl.Purpose.CLIENT_AUTH).load_cert_chain(settings.ssl_certfile,
                                                                               settings.ssl_keyfile)
        except (ssl.SSLError, OSError) as exc:
            which = "ssl_keyfile" if settings.ssl_keyfile else "ssl_certfile"
            raise SettingsProblem(f"{name('ssl_certfile')}/{name(which)}: the certificate and key do not load "
                                  f"({getattr(exc, 'reason', None) or exc})") from None
    if is_loopback(settings.host):
        return
    where = f"{settings.host}:{settings.port}"
    if not settings.token and not has_clients:
        if not settings.insecure:
            raise SettingsProblem(
                f"{name('host')}: {settings.host} is not a loopback address, and without a token anyone who reaches "
                f"{where} may set goals and post perceptions that the robot then acts on; add clients' keys "
                "(`planhrc keys add NAME --role ROLE --db ...`) or give a token (--token-file or PLANHRC_TOKEN_FILE, "
                "or PLANHRC_TOKEN), or say --insecure (PLANHRC_INSECURE) to serve without one")
        warnings.append(f"{name('insecure')}: serving {where} without a token: anyone who reaches it may set goals "
                        "and post perceptions that the robot then acts on")
    elif not settings.ssl_certfile:
        warnings.append(f"{name('host')}: keys and tokens travel in clear text to {where}; serve HTTPS "
                        "(--ssl-certfile and --ssl-keyfile) or behind a TLS reverse proxy")


def _url_password(db: str | None) -> bool:
    return bool(db) and "://" in str(db) and url_password(str(db))
