"""A non-blocking UDP socket: bind, drain every pending datagram, send, wait until readable.

On Linux every datagram carries its kernel arrival time (``SO_TIMESTAMPNS``), so a receiver knows
how long it waited in the socket before the loop drained it: receive times are then accurate to the
arrival, not to the next tick. Elsewhere the wait counts as zero.
"""

from __future__ import annotations

import select
import socket
import struct
import sys
import time
from dataclasses import dataclass

from .errors import StartupError
from .packets import MAX_DATAGRAM

# SO_TIMESTAMPNS of Linux's asm-generic socket.h (x86-64, arm64); Python's socket module lacks the name.
_SO_TIMESTAMPNS = 35 if sys.platform == "linux" else None
_TIMESPEC = struct.Struct("@qq")


@dataclass
class Datagram:
    data: bytes
    sender: tuple[str, int]
    waited_s: float  # time between its arrival and the drain [s] (0 where unknown)


class UdpEndpoint:
    """One bound UDP socket. Port 0 binds an ephemeral port (read it back from :attr:`port`)."""

    def __init__(self, bind_address: str, port: int):
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self._stamped = _SO_TIMESTAMPNS is not None
        if self._stamped:
            self._socket.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
        try:
            self._socket.bind((bind_address, port))
        except OSError as error:
            self._socket.close()
            raise StartupError(f"cannot listen on UDP {bind_address}:{port}: {error}") from error
        self._socket.setblocking(False)

    @property
    def port(self) -> int:
        return self._socket.getsockname()[1]

    def drain(self) -> list[Datagram]:
        """Every datagram waiting in the socket, oldest first."""
        datagrams = []
        while True:
            try:
                data, ancillary, _, sender = self._socket.recvmsg(MAX_DATAGRAM, 64)
            except (BlockingIOError, InterruptedError):
                return datagrams
            except ConnectionError:  # ICMP port unreachable of an earlier send: nothing to read
                continue
            waited = 0.0
            for level, kind, payload in ancillary:
                if self._stamped and level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(payload) >= 16:
                    seconds, nanoseconds = _TIMESPEC.unpack_from(payload)
                    waited = max(0.0, time.time() - (seconds + 1e-9 * nanoseconds))
            datagrams.append(Datagram(data, sender, waited))

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
