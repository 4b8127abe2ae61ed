"""Who may use the dashboard: an access token, the ``Host`` header and the ``Origin`` header.

As Jupyter does it: the server makes a random token on every start (or takes
one the operator chose) and every request but the static files (the page's
script, style and plot library, which hold no state) must carry it, on the
loopback interface too, for any program on the machine, and any web page
its browser opens, can reach a loopback port.  Three checks, in this order:

* **Host** (DNS rebinding): a server bound to the loopback interface answers
  only requests addressed to a loopback name (``localhost``, ``127.0.0.1``,
  ``[::1]``); a page of ``evil.example`` whose name was rebound to 127.0.0.1
  sends ``Host: evil.example`` and is refused.  A server bound for remote
  access answers any host name (the token and TLS protect it).
* **Origin** (cross-site requests): a browser names the page that opens a
  WebSocket, posts a control or fetches the state; it must be the
  dashboard's own (``scheme://host`` equal to the request's ``Host``).
  Programs that are no browser, and a browser opening the page itself, send
  none, and are let through to the token check.
* **Token**: the ``token`` query parameter, the ``X-Relaxgrip-Token`` header
  or ``Authorization: token ...``, compared in constant time.

A refused HTTP request gets 403 and a one-line reason; a refused WebSocket is
closed with code 1008 (policy violation) before its handshake completes, so
it never opens and nothing is sent or read.  :class:`AccessGuard` is a pure
ASGI middleware: it runs before any route, so no route can forget a check.
"""

from __future__ import annotations

import ipaddress
import re
import secrets
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any
from urllib.parse import parse_qs, urlsplit

from relaxgrip.errors import InputError

__all__ = ["TOKEN_HEADER", "AccessGuard", "check_token", "host_name", "is_loopback",
           "new_token", "origin_allowed"]

#: Header a program may carry the token in (besides ``?token=`` and ``Authorization``).
TOKEN_HEADER = "x-relaxgrip-token"
#: Characters a token may hold: it goes into a URL as it is.
_TOKEN = re.compile(r"[A-Za-z0-9._~-]{8,256}")
#: Paths served to anyone who passes the Host check: files without state.
PUBLIC_PREFIX = "/static/"

Scope = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[MutableMapping[str, Any]]]
Send = Callable[[MutableMapping[str, Any]], Awaitable[None]]
App = Callable[[Scope, Receive, Send], Awaitable[None]]


def new_token() -> str:
    """A random access token (32 bytes of :mod:`secrets`, URL-safe base64)."""
    return secrets.token_urlsafe(32)


def check_token(token: str, name: str = "--token") -> str:
    """Return ``token`` if it is 8-256 URL-safe characters (letters, digits, ``._~-``).

    Raises
    ------
    InputError
        Naming ``name`` and what is wrong (the token itself is not repeated).
    """
    if not _TOKEN.fullmatch(token):
        raise InputError(f"{name} must be 8-256 characters of letters, digits and ._~- "
                         f"(got {len(token)} characters"
                         + (")" if 8 <= len(token) <= 256 else ", too "
                            + ("short)" if len(token) < 8 else "long)")))
    return token


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a name or an address, brackets allowed) names the loopback interface."""
    name = host.strip("[]").lower().removesuffix(".")
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def host_name(host_header: str) -> str:
    """The host of a ``Host`` header value (``[::1]:8000`` -> ``::1``), lower case."""
    value = host_header.strip().lower()
    if value.startswith("["):
        return value[1:value.find("]")] if "]" in value else value
    return value.rsplit(":", 1)[0] if value.count(":") == 1 else value


def origin_allowed(origin: str | None, host_header: str) -> bool:
    """Whether a browser's ``Origin`` is the dashboard's own page (or absent: no browser).

    The origin's ``host[:port]`` must equal the request's ``Host`` (case
    aside), with an ``http`` or ``https`` scheme; ``null`` (a sandboxed or
    local-file page) is refused.
    """
    if origin is None:
        return True
    parts = urlsplit(origin.strip())
    return (parts.scheme in ("http", "https") and not parts.path.strip("/")
            and parts.netloc.lower() == host_header.strip().lower())


def _headers(scope: Scope) -> dict[str, str]:
    """The request's headers, lower-case names; a repeated header's last value."""
    return {k.decode("latin-1").lower(): v.decode("latin-1")
            for k, v in scope.get("headers", [])}


def _given_token(scope: Scope, headers: dict[str, str]) -> str | None:
    raw: bytes = scope.get("query_string", b"")
    query = parse_qs(raw.decode("latin-1"))
    if query.get("token"):
        return query["token"][-1]
    if TOKEN_HEADER in headers:
        return headers[TOKEN_HEADER]
    scheme, _, value = headers.get("authorization", "").partition(" ")
    return value.strip() if scheme.lower() == "token" and value.strip() else None


class AccessGuard:
    """ASGI middleware: the Host, Origin and token checks of the module notes.

    Parameters
    ----------
    app : ASGI application
        The dashboard.
    token : str
        The access token (:func:`check_token`).
    loopback_only : bool
        The server is bound to the loopback interface: only loopback host
        names are answered.
    """

    def __init__(self, app: App, token: str, loopback_only: bool = True) -> None:
        self.app = app
        self.token = check_token(token, "access token")
        self.loopback_only = loopback_only
        self.refused = 0

    def reason(self, scope: Scope) -> str | None:
        """Why the request is refused, or None if it may pass."""
        headers = _headers(scope)
        host = headers.get("host", "")
        if not host:
            return "no Host header"
        if self.loopback_only and not is_loopback(host_name(host)):
            return f"host {host_name(host)!r} is not this loopback dashboard's"
        path = str(scope.get("path", ""))
        if scope["type"] == "http" and path.startswith(PUBLIC_PREFIX):
            return None
        if not origin_allowed(headers.get("origin"), host):
            return f"origin {headers.get('origin')!r} is not this dashboard's page"
        given = _given_token(scope, headers)
        if given is None or not secrets.compare_digest(given.encode("utf-8", "replace"),
                                                       self.token.encode()):
            return "this dashboard needs its access token (?token=...)"
        return None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Pass the request on, or refuse it: 403, or a WebSocket closed with 1008."""
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        why = self.reason(scope)
        if why is None:
            await self.app(scope, receive, send)
            return
        self.refused += 1
        if scope["type"] == "websocket":
            await receive()  # the connect event, then refused before the handshake completes
            await send({"type": "websocket.close", "code": 1008, "reason": why[:120]})
            return
        body = f"403: {why}\n".encode()
        await send({"type": "http.response.start", "status": 403,
                    "headers": [(b"content-type", b"text/plain; charset=utf-8"),
                                (b"content-length", str(len(body)).encode()),
                                (b"cache-control", b"no-store")]})
        await send({"type": "http.response.body", "body": body})
