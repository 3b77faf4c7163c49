"""uvicorn's httptools protocol with one ``send()`` per response instead of two.

uvicorn writes a response's status line and headers, then its body, as two transport
writes, and uvloop sends each at once: two system calls and two TCP segments per
response, which the client also wakes up for twice. On loopback, where robots' requests
for a single sample cost the service a few hundred microseconds each, a send is a
sizeable share of that. Here the writes made during one event-loop step are joined and
sent together at the end of the step; large writes (batch answers) go out at once, after
whatever is pending, so nothing is copied twice and the order never changes.
"""

from __future__ import annotations

import asyncio

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

# Writes up to this size wait for the end of the loop step; larger ones are sent at once.
COALESCE_BYTES = 64 * 1024


class CoalescingTransport:
    """A transport whose small writes within one loop step leave in one ``write``."""

    def __init__(self, transport: asyncio.Transport, loop: asyncio.AbstractEventLoop) -> None:
        self._transport = transport
        self._loop = loop
        self._pending: list[bytes] = []
        self._pending_bytes = 0

    def write(self, data: bytes) -> None:
        if len(data) > COALESCE_BYTES:
            self.flush()
            self._transport.write(data)
            return
        if not self._pending:
            self._loop.call_soon(self.flush)
        self._pending.append(data)
        self._pending_bytes += len(data)
        if self._pending_bytes > COALESCE_BYTES:  # many small writes in one step: no hoarding
            self.flush()

    def flush(self) -> None:
        if not self._pending:
            return
        data = b"".join(self._pending) if len(self._pending) > 1 else self._pending[0]
        self._pending, self._pending_bytes = [], 0
        if not self._transport.is_closing():
            self._transport.write(data)

    def close(self) -> None:
        self.flush()
        self._transport.close()

    def __getattr__(self, name: str):  # everything else is the real transport's
        return getattr(self._transport, name)


class CoalescingHttpToolsProtocol(HttpToolsProtocol):
    """``uvicorn.run(app, http=CoalescingHttpToolsProtocol)``."""

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(CoalescingTransport(transport, self.loop))  # type: ignore[arg-type]
