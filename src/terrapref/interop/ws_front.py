"""The live view's front door: a TCP relay that lets a viewer in by either name of Foxglove's
WebSocket protocol.

The Foxglove SDK's server accepts only the subprotocol ``foxglove.sdk.v1``; viewers built before
it (older Foxglove apps, Lichtblick, clients of the ``foxglove.websocket.v1`` era) offer only
``foxglove.websocket.v1``, the same protocol under its earlier name, and get a bare HTTP 400. The
front listens where the user asked, reads each client's opening handshake, names the protocol by
the SDK's name towards the server and by the client's towards the client, and from then on
passes the bytes through untouched (a WebSocket's frames do not depend on the subprotocol's
name). A client that offers neither name is answered with one that says which it speaks.
"""

from __future__ import annotations

import re
import socket
import threading

SDK_PROTOCOL = "foxglove.sdk.v1"
OLD_PROTOCOL = "foxglove.websocket.v1"  # the same protocol, by the name of the earlier foxglove/ws-protocol
PROTOCOLS = (SDK_PROTOCOL, OLD_PROTOCOL)
MAX_HEAD_BYTES = 65536  # an opening handshake longer than this is not a viewer's
HANDSHAKE_TIMEOUT_S = 10.0

_PROTOCOL_HEADER = re.compile(rb"^sec-websocket-protocol:[ \t]*([^\r\n]*?)[ \t]*\r?$", re.IGNORECASE | re.MULTILINE)


class Front:
    """Listens on ``host``:``port`` (0: a free port) and relays each viewer to the server on
    127.0.0.1:``inner_port``.

    Raises:
        OSError: the address cannot be listened on (a port in use).
    """

    def __init__(self, host: str, port: int, inner_port: int) -> None:
        family, kind, proto, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
        self.listener = socket.socket(family, kind, proto)
        try:
            self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self.listener.bind(address)
            self.listener.listen()
        except OSError:
            self.listener.close()
            raise
        self.inner_port = inner_port
        self.port = int(self.listener.getsockname()[1])
        self._open: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._stopped = False
        threading.Thread(target=self._accept, name="live-view-front", daemon=True).start()

    def stop(self, drain_s: float = 2.0) -> None:
        """Stop listening; give the connections ``drain_s`` [s] to end (the server's closing
        frames to reach the viewers), then close those left."""
        import time

        self._stopped = True
        _close(self.listener)
        end = time.monotonic() + drain_s
        while time.monotonic() < end:
            with self._lock:
                if not self._open:
                    return
            time.sleep(0.02)
        with self._lock:
            for s in list(self._open):
                _close(s)
            self._open.clear()

    def _accept(self) -> None:
        while not self._stopped:
            try:
                client, _ = self.listener.accept()
            except OSError:  # stopped
                return
            threading.Thread(target=self._serve, args=(client,), name="live-view-client", daemon=True).start()

    def _keep(self, s: socket.socket) -> None:
        with self._lock:
            if self._stopped:
                _close(s)
                raise OSError("the live view has stopped")
            self._open.add(s)

    def _serve(self, client: socket.socket) -> None:
        upstream = None
        try:
            self._keep(client)
            client.settimeout(HANDSHAKE_TIMEOUT_S)
            head, rest = _read_head(client)
            request, rename = opening(head)
            if request is None:
                client.sendall(refusal(head))
                return
            upstream = socket.create_connection(("127.0.0.1", self.inner_port), timeout=HANDSHAKE_TIMEOUT_S)
            self._keep(upstream)
            upstream.sendall(request + rest)
            answer, more = _read_head(upstream)
            client.sendall(answering(answer, rename) + more)
            client.settimeout(None)
            upstream.settimeout(None)
            back = threading.Thread(target=_pump, args=(upstream, client), name="live-view-to-client", daemon=True)
            back.start()
            _pump(client, upstream)
            back.join(timeout=HANDSHAKE_TIMEOUT_S)
        except OSError:
            pass  # a viewer that went away, or the view stopping
        finally:
            for s in (client, upstream):
                if s is not None:
                    _close(s)
                    with self._lock:
                        self._open.discard(s)


def opening(head: bytes) -> tuple[bytes | None, bool]:
    """A client's opening handshake as the SDK's server takes it, and whether the answer must name
    the protocol by its old name; (None, False) when the client offers neither name."""
    match = _PROTOCOL_HEADER.search(head)
    offered = [p.strip() for p in match.group(1).decode("latin-1").split(",")] if match else []
    if SDK_PROTOCOL in offered:
        return head, False
    if OLD_PROTOCOL in offered:
        start, end = match.span(1)
        return head[:start] + SDK_PROTOCOL.encode() + head[end:], True
    return None, False


def answering(head: bytes, rename: bool) -> bytes:
    """The server's answer to a handshake, naming the protocol as the client offered it."""
    if not rename:
        return head
    match = _PROTOCOL_HEADER.search(head)
    if match is None:
        return head
    start, end = match.span(1)
    return head[:start] + OLD_PROTOCOL.encode() + head[end:]


def refusal(head: bytes) -> bytes:
    """The answer to a client that offers neither name: which protocol this server speaks."""
    websocket = re.search(rb"^upgrade:[ \t]*websocket", head, re.IGNORECASE | re.MULTILINE) is not None
    text = (
        f"terrapref live view: a Foxglove WebSocket server. It speaks the subprotocol {SDK_PROTOCOL} "
        f"(also by its earlier name {OLD_PROTOCOL}); {'offer one of them' if websocket else 'connect with a WebSocket client offering one'} "
        "(Foxglove: Open connection, Foxglove WebSocket).\n"
    ).encode()
    status = b"400 Bad Request" if websocket else b"426 Upgrade Required"
    return (
        b"HTTP/1.1 " + status + b"\r\nContent-Type: text/plain; charset=utf-8\r\nConnection: close\r\n"
        b"Sec-WebSocket-Protocol: " + ", ".join(PROTOCOLS).encode() + b"\r\nContent-Length: " + str(len(text)).encode() + b"\r\n\r\n" + text
    )


def _read_head(s: socket.socket) -> tuple[bytes, bytes]:
    """An HTTP head (up to its blank line, included) and the bytes read after it."""
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = s.recv(4096)
        if not chunk or len(data) > MAX_HEAD_BYTES:
            raise OSError("no HTTP head")
        data += chunk
    end = data.index(b"\r\n\r\n") + 4
    return data[:end], data[end:]


def _pump(src: socket.socket, dst: socket.socket) -> None:
    """Copy ``src`` to ``dst`` until ``src`` ends; then end ``dst``'s sending side."""
    try:
        while chunk := src.recv(65536):
            dst.sendall(chunk)
    except OSError:
        pass
    try:
        dst.shutdown(socket.SHUT_WR)
    except OSError:
        pass


def _close(s: socket.socket) -> None:
    try:
        s.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass
    s.close()
