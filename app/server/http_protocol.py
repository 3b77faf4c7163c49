"""uvicorn's httptools protocol with one ``send()`` per response instead of two.

uvicorn writes a response's status line and headers, then its body, as two transport
writes, and uvloop sends each at once: two system calls and two TCP segments per
response, which the client also wakes up for twice. On loopback, where robots' requests
for a single sample cost the service a few hundred microseconds each, a send is a
sizeable share of that. Here the writes made during one event-loop step are joined and
sent together at the end of the step; large writes (batch answers) go out at once, after
whatever is pending, so nothing is copied twice and the order never changes.

A response that closes the connection before its request's body has all come (a 413 for
a body over the size limit, answered from its ``Content-Length``, to a client that sent
``Connection: close``, as Python's ``urllib`` does) would leave unread bytes in the
socket, and closing a socket with unread bytes sends a reset: a client still sending its
body never reads the answer (``urllib`` reports "connection reset by peer" or "broken
pipe"). Such a close lingers instead, as nginx's ``lingering_close`` does: the response
is sent, the sending side shut (the client reads the answer and its end), and what still
comes is read and dropped until the client closes, or nothing has come for
``LINGER_IDLE_SECONDS``, or ``LINGER_SECONDS`` have passed.
"""

from __future__ import annotations

import asyncio
import time

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

# Writes up to this size wait for the end of the loop step; larger ones are sent at once.
COALESCE_BYTES = 64 * 1024
# a lingering close (module docstring) reads what still comes for at most this long ...
LINGER_SECONDS = 30.0
# ... and gives up once nothing has come for this long (nginx's lingering_timeout)
LINGER_IDLE_SECONDS = 5.0


class CoalescingTransport:
    """A transport whose small writes within one loop step leave in one ``write``."""

    def __init__(
        self, transport: asyncio.Transport, loop: asyncio.AbstractEventLoop, linger=None
    ) -> None:
        self._transport = transport
        self._loop = loop
        self._pending: list[bytes] = []
        self._pending_bytes = 0
        # called at close(): True where the protocol lingers instead (module docstring)
        self._linger = linger

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
        if self._linger is None or not self._linger():
            self._transport.close()

    def close_now(self) -> None:
        self.flush()
        self._transport.close()

    def __getattr__(self, name: str):  # everything else is the real transport's
        return getattr(self._transport, name)


class CoalescingHttpToolsProtocol(HttpToolsProtocol):
    """``uvicorn.run(app, http=CoalescingHttpToolsProtocol)``."""

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        self._lingering_since: float | None = None
        self._last_data = 0.0
        self._lost = False
        coalescing = CoalescingTransport(transport, self.loop, self._linger)
        super().connection_made(coalescing)  # type: ignore[arg-type]

    def _linger(self) -> bool:
        """At a close: whether to linger (the response is sent, its request's body not all
        read), and if so, start to."""
        if self._lingering_since is not None:
            return True
        cycle = self.cycle
        if self._lost or cycle is None or not cycle.response_complete or not cycle.more_body:
            return False
        transport = self.transport
        if transport.is_closing() or not transport.can_write_eof():
            return False
        self._lingering_since = self._last_data = time.monotonic()
        transport.write_eof()  # the client reads the answer and then the end of it
        self.flow.resume_reading()
        self.loop.call_later(LINGER_IDLE_SECONDS, self._check_linger)
        return True

    def _check_linger(self) -> None:
        if self._lost or self._lingering_since is None:
            return
        now = time.monotonic()
        if now - self._last_data >= LINGER_IDLE_SECONDS or (
            now - self._lingering_since >= LINGER_SECONDS
        ):
            self.transport.close_now()  # type: ignore[attr-defined]
            return
        idle, lingered = now - self._last_data, now - self._lingering_since
        wait = min(LINGER_IDLE_SECONDS - idle, LINGER_SECONDS - lingered)
        self.loop.call_later(max(wait, 0.05), self._check_linger)

    def data_received(self, data: bytes) -> None:
        if self._lingering_since is None:
            super().data_received(data)
            return
        self._last_data = time.monotonic()  # the rest of a body no one reads: dropped

    def eof_received(self) -> bool | None:
        if self._lingering_since is not None:  # the client has sent everything: done
            self.transport.close_now()  # type: ignore[attr-defined]
        return super().eof_received()

    def connection_lost(self, exc: Exception | None) -> None:
        self._lost = True
        super().connection_lost(exc)
