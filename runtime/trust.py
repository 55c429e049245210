"""Who may send the runtime datagrams, and which of their datagrams count.

Every UDP receiver (mocap ``DPM1``, robot state ``DPS1``, goals ``DPG1``) takes its datagrams through a
:class:`SenderGuard`, in this order:

- the sender's address must be one of its config section's ``allowed_senders``, else the datagram is
  dropped as ``foreign`` before it is parsed; with ``latch`` (the robot link replying to the sender of
  the state, ``robot.robot_address: ""``) the first admitted sender (address and port) becomes the only
  peer, so a spoofed state from anywhere else cannot redirect the commands;
- it must be a well-formed message of the stream's kind, else it is dropped as ``malformed``;
- its ``seq`` must be newer than the last admitted one of the same sender (address and port; serial
  number arithmetic on the wrapping 32-bit counter, RFC 1982), else it is dropped as ``replayed``: a
  duplicated, reordered or replayed datagram. A sender that restarts from a new port starts a new stream.

UDP has no authentication: whoever can forge an allowed sender's address and port gets through, so the
robot's network must stay closed. Every drop is counted (the receivers' stats, the run's summary); the
first drop of each kind per receiver is logged with its reason.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Protocol, TypeVar

from .packets import PacketError
from .udp import Datagram

SEQ_MODULUS = 1 << 32
MAX_STREAMS = 64  # senders whose last seq a receiver remembers (only allowed addresses add any)
_LOG = logging.getLogger(__name__)


class Sequenced(Protocol):
    seq: int


M = TypeVar("M", bound=Sequenced)


@dataclass
class Drops:
    """Datagrams a receiver dropped, by reason."""

    malformed: int = 0  # not a well-formed message of the stream's kind (or joint counts other than the config's)
    foreign: int = 0  # from a sender not in allowed_senders (or not the latched peer)
    replayed: int = 0  # seq not newer than the last admitted one of its sender


def newer(seq: int, last: int) -> bool:
    """Whether ``seq`` follows ``last`` on the wrapping 32-bit counter (RFC 1982)."""
    return 0 < (seq - last) % SEQ_MODULUS < SEQ_MODULUS // 2


class SenderGuard:
    """Admits one receiver's datagrams (see the module docstring); ``section`` names its config section."""

    def __init__(self, section: str, allowed_senders: list[str], latch: bool = False):
        self._section = section
        self._allowed = frozenset(allowed_senders)
        self._latch = latch
        self.peer: tuple[str, int] | None = None
        self._last_seq: dict[tuple[str, int], int] = {}  # oldest first
        self._logged: set[str] = set()

    def admit(self, datagrams: Iterable[Datagram], decode: Callable[[bytes], M],
              drops: Drops) -> Iterator[tuple[Datagram, M]]:
        """The admitted datagrams with their messages (``decode`` raises PacketError); counts the others in ``drops``."""
        for datagram in datagrams:
            if not self._allows(datagram.sender):
                drops.foreign += 1
                continue
            try:
                message = decode(datagram.data)
            except PacketError as error:
                drops.malformed += 1
                self._log("malformed", datagram.sender, str(error))
                continue
            if not self._fresh(datagram.sender, message.seq):
                drops.replayed += 1
                continue
            if self._latch:
                self.peer = datagram.sender
            yield datagram, message

    def _allows(self, sender: tuple[str, int]) -> bool:
        if self.peer is not None:
            ok, rule = sender == self.peer, f"the peer {self.peer[0]}:{self.peer[1]} is the only sender"
        else:
            ok, rule = sender[0] in self._allowed, f"not in {self._section}.allowed_senders {sorted(self._allowed)}"
        if not ok:
            self._log("foreign", sender, rule)
        return ok

    def _fresh(self, sender: tuple[str, int], seq: int) -> bool:
        last = self._last_seq.pop(sender, None)
        if last is not None and not newer(seq, last):
            self._last_seq[sender] = last
            self._log("replayed", sender, f"seq {seq} is not newer than {last}")
            return False
        if len(self._last_seq) >= MAX_STREAMS:
            del self._last_seq[next(iter(self._last_seq))]  # the longest silent sender
        self._last_seq[sender] = seq
        return True

    def _log(self, kind: str, sender: tuple[str, int], reason: str) -> None:
        """Logs the first drop of ``kind``; later ones are only counted, so a flood cannot flood the log."""
        if kind not in self._logged:
            self._logged.add(kind)
            _LOG.warning("%s: dropped a %s datagram from %s:%s: %s (further ones are only counted)", self._section, kind,
                         sender[0], sender[1], reason)
