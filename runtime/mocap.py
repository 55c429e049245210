"""Motion capture sources: the latest poses of the robot base and the object, stamped on receipt.

Each source converts its raw poses once, at the boundary, into the runtime convention (world Z-up,
metres, quaternions (x, y, z, w)) and the policy's frames (``mocap.base_offset``/``object_offset``),
and stamps every pose with the runtime clock at the moment it was received: staleness is measured
from that stamp, never from the sender's clock. Only the two configured bodies are kept; poses with
non-finite values or a zero quaternion are dropped and counted (an occluded body then goes stale).

Sources: :class:`UdpMocapSource` (``DPM1`` datagrams, packets.py), :class:`MotionCaptureSource`
(the ``motioncapture`` package: Vicon, OptiTrack, Qualisys, VRPN, mock; a thread waits for frames),
:class:`ReplayMocapSource` (the poses recorded in a tick log, re-timed from the start of the run).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .config import MOTIONCAPTURE_SOURCES, MocapConfig
from .errors import StartupError
from .frames import Pose, PoseConverter
from .packets import decode_mocap
from .tick_log import read_log
from .trust import Drops, SenderGuard
from .udp import UdpEndpoint


@dataclass
class TrackedPose:
    pose: Pose
    receive_time: float  # runtime clock [s] when the frame carrying the pose arrived


@dataclass
class MocapStats(Drops):
    frames: int = 0  # frames (datagrams, mocap frames, log rows) taken in
    invalid: int = 0  # body poses dropped: non-finite values or a zero quaternion


class MocapSource:
    """Latest converted pose of ``mocap.base_body`` and ``mocap.object_body``; subclasses feed it."""

    def __init__(self, cfg: MocapConfig):
        self._converters = {
            cfg.base_body: PoseConverter(cfg.frames, cfg.base_offset),
            cfg.object_body: PoseConverter(cfg.frames, cfg.object_offset),
        }
        self._base_name, self._object_name = cfg.base_body, cfg.object_body
        self._latest: dict[str, TrackedPose] = {}
        self.stats = MocapStats()

    def poll(self, now: float) -> None:
        """Takes in everything that arrived since the last call (``now``: runtime clock [s])."""
        raise NotImplementedError

    @property
    def base(self) -> TrackedPose | None:
        return self._latest.get(self._base_name)

    @property
    def object(self) -> TrackedPose | None:
        return self._latest.get(self._object_name)

    def close(self) -> None:
        """Releases sockets and threads."""

    def _accept(self, name: str, position: np.ndarray, quat: np.ndarray, receive_time: float) -> None:
        converter = self._converters.get(name)
        if converter is None:
            return
        try:
            self._latest[name] = TrackedPose(converter(position, quat), receive_time)
        except ValueError:
            self.stats.invalid += 1


class UdpMocapSource(MocapSource):
    """``DPM1`` datagrams on ``mocap.bind_address:mocap.port`` from ``mocap.allowed_senders``; foreign, malformed
    and replayed ones are counted and dropped (trust.py).

    A pose's receive time is the tick's time minus how long its datagram waited in the socket.
    """

    def __init__(self, cfg: MocapConfig):
        super().__init__(cfg)
        self.endpoint = UdpEndpoint(cfg.bind_address, cfg.port)
        self.guard = SenderGuard("mocap", cfg.allowed_senders)

    def poll(self, now: float) -> None:
        for datagram, frame in self.guard.admit(self.endpoint.drain(), decode_mocap, self.stats):
            self.stats.frames += 1
            for body in frame.bodies:
                self._accept(body.name, body.position, body.quat, now - datagram.waited_s)

    def close(self) -> None:
        self.endpoint.close()


class MotionCaptureSource(MocapSource):
    """A ``motioncapture.connect(source, {hostname, **options})`` system, read by a daemon thread.

    ``waitForNextFrame`` blocks, so a thread waits for frames and stamps them with ``clock`` (a
    real-time clock, the runtime's); :meth:`poll` hands the newest pose per body to the loop.
    """

    def __init__(self, cfg: MocapConfig, clock: Callable[[], float]):
        super().__init__(cfg)
        import motioncapture  # a small I/O extension, imported only where used

        options = dict(cfg.options)
        if cfg.hostname:
            options["hostname"] = cfg.hostname
        try:
            self._system = motioncapture.connect(cfg.source, options)
        except Exception as error:  # the extension raises RuntimeError or its own types
            raise StartupError(f"mocap: cannot connect to {cfg.source} {cfg.hostname!r} ({options}): {error}") from error
        self._clock = clock
        self._lock = threading.Lock()
        self._pending: dict[str, tuple[np.ndarray, np.ndarray, float]] = {}
        self._frames = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._receive, name="motioncapture", daemon=True)
        self._thread.start()

    def _receive(self) -> None:
        while not self._stop.is_set():
            self._system.waitForNextFrame()
            stamp = self._clock()
            bodies = {}
            for name, body in self._system.rigidBodies.items():
                if name in self._converters:
                    r = body.rotation
                    bodies[name] = (np.array(body.position, dtype=np.float64), np.array([r.x, r.y, r.z, r.w]), stamp)
            with self._lock:
                self._pending.update(bodies)
                self._frames += 1

    def poll(self, now: float) -> None:
        with self._lock:
            pending, self._pending = self._pending, {}
            self.stats.frames = self._frames
        for name, (position, quat, stamp) in pending.items():
            self._accept(name, position, quat, stamp)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=0.5)


class ReplayMocapSource(MocapSource):
    """Re-plays the mocap poses of a tick log with their original receive timing, from the first poll."""

    def __init__(self, cfg: MocapConfig):
        super().__init__(cfg)
        log = read_log(cfg.replay_log)
        times = log.column("time_s")[:, 0]
        self._events: list[tuple[float, str, np.ndarray, np.ndarray]] = []
        for name, prefix in ((cfg.base_body, "base"), (cfg.object_body, "object")):
            received = times - log.column(f"{prefix}_age_s")[:, 0]
            position, quat = log.column(f"{prefix}_position"), log.column(f"{prefix}_quat_xyzw")
            new = np.isfinite(received) & np.concatenate([[True], np.diff(received) != 0.0])
            self._events += [(received[i] - times[0], name, position[i], quat[i]) for i in np.flatnonzero(new)]
        self._events.sort(key=lambda e: e[0])
        self._next = 0
        self._start: float | None = None

    def poll(self, now: float) -> None:
        if self._start is None:
            self._start = now
        while self._next < len(self._events) and self._events[self._next][0] <= now - self._start:
            offset, name, position, quat = self._events[self._next]
            self.stats.frames += 1
            self._accept(name, position, quat, self._start + offset)
            self._next += 1


def open_mocap(cfg: MocapConfig, clock: Callable[[], float]) -> MocapSource:
    """The source named by ``mocap.source``."""
    if cfg.source == "udp":
        return UdpMocapSource(cfg)
    if cfg.source == "replay":
        return ReplayMocapSource(cfg)
    assert cfg.source in MOTIONCAPTURE_SOURCES
    return MotionCaptureSource(cfg, clock)
