"""The coalescing HTTP protocol: one write per response, same bytes, same order."""

from __future__ import annotations

import asyncio
import socket
import threading
import time
import urllib.error
import urllib.request

import pytest
import uvicorn
from fastapi import FastAPI
from fastapi.responses import PlainTextResponse

from app.server.http_protocol import (
    COALESCE_BYTES,
    CoalescingHttpToolsProtocol,
    CoalescingTransport,
)


class RecordingTransport(asyncio.Transport):
    """An asyncio transport that keeps what is written to it."""

    def __init__(self) -> None:
        super().__init__()
        self.writes: list[bytes] = []
        self.closed = False

    def write(self, data: bytes) -> None:
        assert not self.closed, "written after close"
        self.writes.append(bytes(data))

    def is_closing(self) -> bool:
        return self.closed

    def close(self) -> None:
        self.closed = True


def test_small_writes_of_one_loop_step_leave_as_one():
    async def run() -> RecordingTransport:
        real = RecordingTransport()
        t = CoalescingTransport(real, asyncio.get_running_loop())
        t.write(b"HTTP/1.1 200 OK\r\n\r\n")
        t.write(b"body")
        assert real.writes == []  # nothing sent before the step ends
        await asyncio.sleep(0)
        t.write(b"next")
        await asyncio.sleep(0)
        return real

    real = asyncio.run(run())
    assert real.writes == [b"HTTP/1.1 200 OK\r\n\r\nbody", b"next"]


def test_a_large_write_goes_out_at_once_after_what_is_pending():
    async def run() -> RecordingTransport:
        real = RecordingTransport()
        t = CoalescingTransport(real, asyncio.get_running_loop())
        big = b"x" * (COALESCE_BYTES + 1)
        t.write(b"head")
        t.write(big)
        assert real.writes == [b"head", big]
        await asyncio.sleep(0)  # the scheduled flush finds nothing left
        return real

    assert len(asyncio.run(run()).writes) == 2


def test_many_small_writes_in_one_step_are_sent_once_they_add_up():
    async def run() -> RecordingTransport:
        real = RecordingTransport()
        t = CoalescingTransport(real, asyncio.get_running_loop())
        chunk = b"c" * 1000
        for _ in range(COALESCE_BYTES // 1000 + 1):
            t.write(chunk)
        assert len(real.writes) == 1  # sent in the same step, not hoarded
        t.write(b"tail")
        await asyncio.sleep(0)
        return real

    real = asyncio.run(run())
    assert b"".join(real.writes) == b"c" * 1000 * (COALESCE_BYTES // 1000 + 1) + b"tail"
    assert len(real.writes) == 2


def test_close_sends_what_is_pending_first():
    async def run() -> RecordingTransport:
        real = RecordingTransport()
        t = CoalescingTransport(real, asyncio.get_running_loop())
        t.write(b"last words")
        t.close()
        await asyncio.sleep(0)
        return real

    real = asyncio.run(run())
    assert real.writes == [b"last words"] and real.closed


@pytest.fixture
def server():
    app = FastAPI()

    @app.get("/size/{n}")
    async def sized(n: int) -> PlainTextResponse:
        return PlainTextResponse("a" * n)

    @app.post("/refuse")
    async def refuse() -> PlainTextResponse:  # answers without reading the body, as a 413 does
        return PlainTextResponse("too large", status_code=413)

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    config = uvicorn.Config(
        app, host="127.0.0.1", port=port, log_level="warning", http=CoalescingHttpToolsProtocol
    )
    srv = uvicorn.Server(config)
    thread = threading.Thread(target=srv.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 20
    while not srv.started:
        assert time.monotonic() < deadline, "server did not start"
        time.sleep(0.05)
    yield port
    srv.should_exit = True
    thread.join(10)


def read_response(f) -> tuple[int, bytes]:
    status = int(f.readline().split()[1])
    length = 0
    while (line := f.readline()) not in (b"\r\n", b""):
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"content-length":
            length = int(value)
    return status, f.read(length)


@pytest.mark.parametrize("sizes", [[5, 0, 70_000, 3], [200_000, 1, 200_000]])
def test_a_real_server_answers_pipelined_requests_in_order(server, sizes):
    """Small and large bodies on one keep-alive connection, requests sent back to back."""
    with socket.create_connection(("127.0.0.1", server), timeout=10) as sock:
        sock.sendall(b"".join(f"GET /size/{n} HTTP/1.1\r\nHost: x\r\n\r\n".encode() for n in sizes))
        with sock.makefile("rb") as f:
            for n in sizes:
                status, body = read_response(f)
                assert status == 200 and body == b"a" * n


def test_an_answer_before_the_body_reaches_a_client_that_closes_after_it(server):
    """urllib sends ``Connection: close`` and its whole body before it reads: an answer
    given without reading the body (a 413 from its Content-Length) reaches it instead of
    a connection reset, and the server serves on."""
    body = b"x" * (64 * 1024 * 1024)  # far beyond what the sockets' buffers hold
    for _ in range(2):
        request = urllib.request.Request(f"http://127.0.0.1:{server}/refuse", data=body)
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(request, timeout=30)
        assert refused.value.code == 413 and refused.value.read() == b"too large"
    with urllib.request.urlopen(f"http://127.0.0.1:{server}/size/3", timeout=10) as r:
        assert r.read() == b"aaa"
