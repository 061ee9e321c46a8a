"""Request guards that run before any route: the body-size limit and the API key.

Why the size limit is raw ASGI: it must hold before the body is parsed, for bodies announced with a
Content-Length (refused at once) and for chunked ones (counted as they arrive), so a client cannot make
the server buffer more than ``max_bytes``. The API key is a FastAPI dependency instead, so that it
appears in the OpenAPI document as the scheme clients must use (no ``from __future__ import
annotations`` here: FastAPI must read the dependency's annotations, which name closure variables).
"""

import asyncio
import hmac
import json
from typing import Annotated

from fastapi import HTTPException, Security
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer


class BodyLimitMiddleware:
    """Answer 413 to any request whose body is larger than ``max_bytes``, and 408 when the body stops
    arriving: each part of it must come within ``read_timeout_s`` seconds (a client that announces more
    bytes than it sends would otherwise hold a connection and a request open for ever)."""

    def __init__(self, app, max_bytes: int, read_timeout_s: float = 10.0):
        self.app = app
        self.max_bytes = max_bytes
        self.read_timeout_s = read_timeout_s

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        length = dict(scope.get("headers") or []).get(b"content-length")
        if length is not None and (not length.strip().isdigit() or int(length) > self.max_bytes):
            await self._refuse(send)
            return
        received = 0

        async def limited_receive():
            nonlocal received
            try:
                message = await asyncio.wait_for(receive(), self.read_timeout_s)
            except TimeoutError:
                raise HTTPException(408, f"request body not received: nothing came for {self.read_timeout_s:g} s "
                                         "(does Content-Length match the body sent?)",
                                    headers={"Connection": "close"}) from None
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_bytes:
                    # FastAPI turns an HTTPException raised while reading the body into this answer
                    raise HTTPException(413, self._message())
            return message

        await self.app(scope, limited_receive, send)

    def _message(self) -> str:
        return f"request body larger than this server's limit of {self.max_bytes} bytes"

    async def _refuse(self, send) -> None:
        body = json.dumps({"detail": self._message()}).encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})


def api_key_dependency(keys: tuple[str, ...]):
    """A dependency accepting ``Authorization: Bearer KEY`` or ``X-API-Key: KEY`` for one of ``keys``."""
    bearer = HTTPBearer(auto_error=False, description="Authorization: Bearer <API key>")
    header = APIKeyHeader(name="X-API-Key", auto_error=False, description="the API key")
    encoded = [k.encode() for k in keys]

    async def require_key(cred: Annotated[HTTPAuthorizationCredentials | None, Security(bearer)],
                          key: Annotated[str | None, Security(header)]) -> None:
        given = cred.credentials if cred is not None else key
        # compare against every key (constant time each) so the timing does not tell which matched
        ok = given is not None and sum(hmac.compare_digest(given.encode(), k) for k in encoded) > 0
        if not ok:
            raise HTTPException(401, "missing or wrong API key (send 'Authorization: Bearer KEY' or 'X-API-Key: KEY')",
                                headers={"WWW-Authenticate": "Bearer"})

    return require_key
