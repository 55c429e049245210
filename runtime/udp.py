"""A non-blocking UDP socket: bind, drain every pending datagram, send, wait until readable."""

from __future__ import annotations

import select
import socket

from .packets import MAX_DATAGRAM


class UdpEndpoint:
    """One bound UDP socket. Port 0 binds an ephemeral port (read it back from :attr:`port`)."""

    def __init__(self, bind_address: str, port: int):
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self._socket.bind((bind_address, port))
        self._socket.setblocking(False)

    @property
    def port(self) -> int:
        return self._socket.getsockname()[1]

    def drain(self) -> list[tuple[bytes, tuple[str, int]]]:
        """Every datagram waiting in the socket, oldest first, with its sender's address."""
        datagrams = []
        while True:
            try:
                datagrams.append(self._socket.recvfrom(MAX_DATAGRAM))
            except (BlockingIOError, InterruptedError):
                return datagrams
            except ConnectionError:  # ICMP port unreachable of an earlier send: nothing to read
                continue

    def wait_readable(self, timeout_s: float) -> bool:
        """Blocks up to ``timeout_s`` until a datagram is waiting."""
        readable, _, _ = select.select([self._socket], [], [], max(0.0, timeout_s))
        return bool(readable)

    def send(self, data: bytes, address: tuple[str, int]) -> None:
        try:
            self._socket.sendto(data, address)
        except (BlockingIOError, ConnectionError):  # a full buffer or an absent receiver drops the datagram, as UDP does
            pass

    def close(self) -> None:
        self._socket.close()
