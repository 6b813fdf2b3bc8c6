"""The studio's gate: a token on every request, the WebSocket's Origin, the Host, body size caps.

Threat: any web page the user visits can make the browser send requests to
``http://127.0.0.1:9571`` (and a DNS-rebinding page can even read the answers), so nothing
may be reachable without a secret the page cannot know:

* the **token** (random per start unless given) comes with the URL the service prints; the
  first page load trades ``?token=`` for an HttpOnly, SameSite=Strict cookie (named after
  the port: two studios on one host keep their own) and redirects to the bare URL. Scripts
  may send ``Authorization: Bearer <token>`` instead. Compared in constant time.
* the **WebSocket** must come from the studio's own origin: ``Origin`` equal to
  ``http://<Host>``; state-changing requests with a foreign ``Origin`` are refused too.
* bound to a loopback address, the **Host** header must name a loopback host with the
  studio's port (a rebinding attacker's name is refused before the token is even looked at).
* request bodies are capped (:data:`BODY_CAP`, uploads :data:`UPLOAD_CAP`): refused from
  ``Content-Length`` before reading, and while streaming when there is none.

Every refusal answers 403 (413 for sizes) with one line, is counted by reason and shown in
the studio's status.
"""

from __future__ import annotations

import hmac
import ipaddress
import re
import secrets
import threading
from collections import Counter
from collections.abc import Awaitable, Callable
from typing import Any

from aiohttp import web

from vibsynth.errors import ParameterError

__all__ = [
    "BODY_CAP",
    "UPLOAD_CAP",
    "TOKEN_PATTERN",
    "Gate",
    "check_token",
    "new_token",
]

#: Largest JSON request body (a preset form is ~2 KB).
BODY_CAP = 1 << 20
#: Largest uploaded recording: a few minutes of 48 kHz float32 stereo.
UPLOAD_CAP = 64 << 20
#: Tokens given by the user (flag or environment): URL-safe characters, long enough to guess in no lifetime.
TOKEN_PATTERN = r"^[A-Za-z0-9_.~-]{16,256}$"
TOKEN_RULE = "16-256 characters among letters, digits and _ . ~ -"

Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]


def new_token() -> str:
    """A fresh random token (192 bits)."""
    return secrets.token_urlsafe(24)


def check_token(token: str, where: str = "--studio-token") -> str:
    """Validate a token given by the user; returns it.

    Raises
    ------
    ParameterError
        Too short, too long, or characters that do not survive a URL.
    """
    if not isinstance(token, str) or not re.fullmatch(TOKEN_PATTERN, token):
        shown = f"{len(token)} characters" if isinstance(token, str) else repr(token)
        raise ParameterError(f"{where}: the studio token must be {TOKEN_RULE} (got {shown})")
    return token


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class Gate:
    """Token, Origin, Host and size checks as an aiohttp middleware, with refusal counters.

    Parameters
    ----------
    token : str
    port : int
        The bound port (for the cookie name and the allowed Host values).
    bind_host : str
        The address the server listens on: loopback binds check the Host header.
    upload_paths : set of str
        Paths whose body may reach :data:`UPLOAD_CAP` (the handler streams and caps it).
    """

    def __init__(self, token: str, *, port: int, bind_host: str, upload_paths: frozenset[str] = frozenset()) -> None:
        self._token = token.encode()
        self.port = int(port)
        self.cookie = f"vibsynth_studio_{self.port}"
        self.loopback = _is_loopback(bind_host)
        self.upload_paths = upload_paths
        self._lock = threading.Lock()
        self._refused: Counter[str] = Counter()

    # ------------------------------------------------------------------ checks
    def token_ok(self, candidate: str | None) -> bool:
        """Constant-time comparison with the token (None or non-ASCII never match)."""
        if not candidate:
            return False
        try:
            given = candidate.encode("ascii")
        except UnicodeEncodeError:
            return False
        return hmac.compare_digest(given, self._token)

    def host_ok(self, host: str | None) -> bool:
        """Bound to loopback: the Host header names a loopback host with our port."""
        if not self.loopback:
            return True
        if not host:
            return False
        name, sep, port = host.rpartition(":")
        if not sep or not port.isdigit() or int(port) != self.port:
            return False
        return _is_loopback(name)

    def origin_ok(self, request: web.Request, *, required: bool) -> bool:
        """``Origin`` equals ``http://<Host>`` (a missing one passes unless ``required``)."""
        origin = request.headers.get("Origin")
        if origin is None:
            return not required
        return origin == f"http://{request.host}"

    def request_token(self, request: web.Request) -> str | None:
        """The token a request carries: cookie, ``Authorization: Bearer``, or ``?token=``."""
        auth = request.headers.get("Authorization", "")
        if auth.startswith("Bearer "):
            return auth[7:].strip()
        query = request.query.get("token")
        if query is not None:
            return query
        return request.cookies.get(self.cookie)

    # ------------------------------------------------------------------ counters
    def refuse(self, reason: str, status: int = 403, text: str = "") -> web.Response:
        """Count a refusal and build its one-line answer."""
        with self._lock:
            self._refused[reason] += 1
        message = text or {
            "token": "forbidden: no valid studio token (open the URL vibsynth serve printed, with ?token=...)",
            "host": "forbidden: unexpected Host header (open the studio at 127.0.0.1 or localhost)",
            "origin": "forbidden: request from another origin than the studio's own",
        }.get(reason, f"forbidden: {reason}")
        return web.Response(status=status, text=message + "\n", headers={"Cache-Control": "no-store"})

    def count(self, reason: str) -> None:
        """Count a refusal answered elsewhere (an oversize stream, a malformed WebSocket message)."""
        with self._lock:
            self._refused[reason] += 1

    def refused(self) -> dict[str, int]:
        """Refusals so far by reason (token, host, origin, too_large, malformed, flood)."""
        with self._lock:
            return dict(self._refused)

    # ------------------------------------------------------------------ middleware
    @web.middleware
    async def middleware(self, request: web.Request, handler: Handler) -> web.StreamResponse:
        if not self.host_ok(request.host):
            return self.refuse("host")
        websocket = request.headers.get("Upgrade", "").lower() == "websocket"
        changes = request.method not in ("GET", "HEAD", "OPTIONS")
        if (websocket or changes) and not self.origin_ok(request, required=websocket):
            return self.refuse("origin")
        if not self.token_ok(self.request_token(request)):
            return self.refuse("token")
        cap = UPLOAD_CAP if request.path in self.upload_paths else BODY_CAP
        length = request.content_length
        if length is not None and length > cap:
            return self.refuse(
                "too_large", 413, f"request body of {length} bytes is over the limit of {cap} bytes for {request.path}"
            )
        if request.method == "GET" and request.path == "/" and "token" in request.query:
            # Trade the token in the URL for a cookie, and drop it from the address bar and history.
            redirect = web.HTTPSeeOther("/")
            redirect.set_cookie(
                self.cookie, self._token.decode(), httponly=True, samesite="Strict", path="/", secure=False
            )
            redirect.headers["Cache-Control"] = "no-store"
            raise redirect
        try:
            response = await handler(request)
        except web.HTTPRequestEntityTooLarge:
            self.count("too_large")
            raise
        _security_headers(response, request)
        return response


def _security_headers(response: Any, request: web.Request) -> None:
    """What a browser may do with our pages: our own scripts and socket only, no framing, no sniffing."""
    if response.prepared:  # a WebSocket (its headers went out with the handshake)
        return
    headers = response.headers
    headers.setdefault(
        "Content-Security-Policy",
        f"default-src 'self'; connect-src 'self' ws://{request.host}; img-src 'self' data:; "
        "style-src 'self'; script-src 'self'; object-src 'none'; frame-ancestors 'none'; base-uri 'none'; "
        "form-action 'self'",
    )
    headers.setdefault("X-Content-Type-Options", "nosniff")
    headers.setdefault("Referrer-Policy", "no-referrer")
    headers.setdefault("X-Frame-Options", "DENY")
    headers.setdefault("Cache-Control", "no-store")
