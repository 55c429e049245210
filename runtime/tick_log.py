"""The tick log: one fixed-size binary record per control tick, append-only, readable after a crash.

File layout::

    b"DPLOG1\\n"                magic
    u32 little-endian          length of the header
    header                     UTF-8 JSON: {"columns": [[name, size], ...], "meta": {...}}
    records                    each sum(sizes) little-endian float64 values, columns in header order

A log file is created exclusively: a run never overwrites another's log (two runs started in the same
second get ``NAME.dplog`` and ``NAME-2.dplog``). The header is written and flushed before the first
record; records go through a buffer that reaches the operating system at least every ``flush_s``
seconds (wall clock), so a process that is killed loses at most that much. A reader drops a trailing
partial record. Integers (tick index, state code) are stored as exact float64 values; "no value" is NaN.
"""

from __future__ import annotations

import json
import struct
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dynpush.errors import MissingFileError, UserError

MAGIC = b"DPLOG1\n"
_LENGTH = struct.Struct("<I")
_F64 = np.dtype("<f8")


class TickLogError(UserError, ValueError):
    """A file that is not a tick log."""


class RecordLayout:
    """Named column blocks of one record: ``view(record, name)`` is that block, a writable slice."""

    def __init__(self, columns: Sequence[tuple[str, int]]):
        self.columns = [(str(name), int(size)) for name, size in columns]
        self.slices: dict[str, slice] = {}
        start = 0
        for name, size in self.columns:
            if name in self.slices:
                raise ValueError(f"duplicate tick log column {name!r}")
            self.slices[name] = slice(start, start + size)
            start += size
        self.size = start

    def new_record(self) -> np.ndarray:
        return np.full(self.size, np.nan)

    def view(self, record: np.ndarray, name: str) -> np.ndarray:
        return record[self.slices[name]]


class TickLogWriter:
    """Appends records to a new tick log at ``path`` (its folder is created; FileExistsError if the file exists)."""

    def __init__(self, path: str | Path, layout: RecordLayout, meta: dict, flush_s: float = 1.0):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._layout = layout
        self._flush_s = flush_s
        self._file = open(self.path, "xb", buffering=1 << 20)  # noqa: SIM115 (kept open for the whole run)
        header = json.dumps({"columns": layout.columns, "meta": meta}, default=_jsonable).encode("utf-8")
        self._file.write(MAGIC + _LENGTH.pack(len(header)) + header)
        self._file.flush()
        self._last_flush = time.monotonic()
        self.records = 0

    @classmethod
    def new_in(cls, directory: str | Path, stem: str, layout: RecordLayout, meta: dict,
               flush_s: float = 1.0) -> TickLogWriter:
        """A new log ``directory/stem.dplog``, or ``stem-2.dplog``, ``stem-3.dplog``... where that name is taken."""
        Path(directory).mkdir(parents=True, exist_ok=True)  # here, so that a file in its place is no taken name
        count = 1
        while True:
            name = f"{stem}.dplog" if count == 1 else f"{stem}-{count}.dplog"
            try:
                return cls(Path(directory) / name, layout, meta, flush_s)
            except FileExistsError:
                count += 1

    def write(self, record: np.ndarray) -> None:
        if record.shape != (self._layout.size,):
            raise ValueError(f"tick log record must have {self._layout.size} values, got {record.shape}")
        self._file.write(record.astype(_F64, copy=False).tobytes())
        self.records += 1
        now = time.monotonic()
        if now - self._last_flush >= self._flush_s:
            self._file.flush()
            self._last_flush = now

    def close(self) -> None:
        if not self._file.closed:
            self._file.flush()
            self._file.close()


def _jsonable(value: object) -> object:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return str(value)


@dataclass
class TickLog:
    """A tick log read back: ``meta`` from its header and one (records, size) array per column."""

    meta: dict
    columns: dict[str, np.ndarray]
    records: int
    partial_bytes: int  # bytes of a trailing incomplete record (a crash mid-write)

    def column(self, name: str) -> np.ndarray:
        if name not in self.columns:
            raise KeyError(f"tick log has no column {name!r} (columns: {list(self.columns)})")
        return self.columns[name]


def read_log(path: str | Path) -> TickLog:
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise MissingFileError(f"tick log {path} does not exist") from None
    except OSError as error:
        raise TickLogError(f"cannot read tick log {path}: {error}") from error
    if not data.startswith(MAGIC) or len(data) < len(MAGIC) + _LENGTH.size:
        raise TickLogError(f"{path} is not a dynpush tick log (magic {MAGIC!r} missing)")
    (length,) = _LENGTH.unpack_from(data, len(MAGIC))
    start = len(MAGIC) + _LENGTH.size + length
    if start > len(data):
        raise TickLogError(f"{path}: the tick log header is truncated")
    try:
        header = json.loads(data[len(MAGIC) + _LENGTH.size:start].decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise TickLogError(f"{path}: the tick log header is not valid JSON: {error}") from error
    try:
        layout, meta = RecordLayout(header["columns"]), header["meta"]
    except (KeyError, TypeError, ValueError) as error:
        raise TickLogError(f"{path}: the tick log header lacks its columns or meta ({error!r})") from error
    body = len(data) - start
    records = body // (8 * layout.size)
    values = np.frombuffer(data, dtype=_F64, count=records * layout.size, offset=start).reshape(records, layout.size)
    columns = {name: values[:, layout.slices[name]] for name, _ in layout.columns}
    return TickLog(meta=meta, columns=columns, records=records, partial_bytes=body - records * 8 * layout.size)
