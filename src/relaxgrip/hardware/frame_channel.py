"""The emulator's frame channel: camera frames (and the twin's truth) over a Unix socket.

The MCU emulator renders the twin's RGB and infrared frames; they reach the
host through this channel, beside the serial link, as a real rig's frames
reach it over USB beside the MCU's serial port.  It is one stream socket
carrying length-prefixed messages, each a fixed little-endian header then a
payload:

======  =====  ==========================================================
offset  type   field
======  =====  ==========================================================
0       4 s    magic ``b"RGFC"``
4       u8     channel version (1)
5       u8     kind: 1 RGB frame, 2 infrared frame, 3 tick
6       u8     dtype: 0 none, 1 uint8, 2 float32, 3 uint16
7       u8     channels (1 or 3; 0 for a tick)
8       u32    seq (frame counter of the stream; tick counter)
12      f64    t_s: capture time of a frame, time covered by a tick (s)
20      u32    height (pixels; 0 for a tick)
24      u32    width (pixels; 0 for a tick)
28      u32    payload length (bytes)
======  =====  ==========================================================

A frame's payload is its pixels, row-major.  A **tick** says "every frame
captured up to ``t_s`` has been sent"; its payload is UTF-8 JSON with the
twin's ground truth at ``t_s`` and the force-ball readings since the previous
tick (the twin is the only backend with a truth; experiments score with it,
estimators never see it).  In lockstep (virtual time, see ``docs/emulator.md``)
the host waits for the tick of the time it observes, so it sees exactly the
frames the twin backend would show at that time.
"""

from __future__ import annotations

import json
import math
import socket
import struct
import threading
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import ForceSamples, Frame, Truth
from relaxgrip.errors import InputError

__all__ = [
    "KIND_IR",
    "KIND_RGB",
    "KIND_TICK",
    "ChannelMessage",
    "MessageReader",
    "encode_frame_message",
    "encode_tick",
    "truth_from_dict",
]

MAGIC = b"RGFC"
CHANNEL_VERSION = 1
KIND_RGB = 1
KIND_IR = 2
KIND_TICK = 3
_HEADER = struct.Struct("<4sBBBBIdIII")
HEADER_SIZE = _HEADER.size
_DTYPES: dict[int, np.dtype[Any]] = {
    1: np.dtype(np.uint8), 2: np.dtype("<f4"), 3: np.dtype("<u2"),
}
_CODES = {np.dtype(np.uint8): 1, np.dtype(np.float32): 2, np.dtype(np.uint16): 3}
#: Largest payload accepted (bytes): a 4K RGB frame.
MAX_PAYLOAD = 4096 * 2160 * 3


@dataclass(frozen=True)
class ChannelMessage:
    """One decoded message: a frame (``frame`` set) or a tick (``tick`` set)."""

    kind: int
    seq: int
    t_s: float
    frame: Frame | None = None
    tick: dict[str, Any] | None = None


def encode_frame_message(kind: int, frame: Frame) -> bytes:
    """Header and pixels of a frame message.

    Parameters
    ----------
    kind : int
        :data:`KIND_RGB` or :data:`KIND_IR`.
    frame : Frame
        ``(H, W, 3)`` uint8 or ``(H, W)`` float32 / uint16.
    """
    image = np.ascontiguousarray(frame.image)
    code = _CODES.get(image.dtype.newbyteorder("=") if image.dtype.byteorder == ">"
                      else image.dtype)
    if code is None or image.ndim not in (2, 3):
        raise InputError(f"cannot send a {image.dtype} frame of shape {image.shape}")
    channels = 1 if image.ndim == 2 else int(image.shape[2])
    data = image.astype(_DTYPES[code], copy=False).tobytes()
    header = _HEADER.pack(MAGIC, CHANNEL_VERSION, kind, code, channels, frame.seq % (1 << 32),
                          float(frame.t_s), int(image.shape[0]), int(image.shape[1]), len(data))
    return header + data


def encode_tick(seq: int, t_s: float, truth: Truth | None,
                force: ForceSamples | None) -> bytes:
    """A tick: all frames up to ``t_s`` are sent; the truth and force readings with it."""
    body: dict[str, Any] = {"truth": None if truth is None else asdict(truth), "force": None}
    if force is not None:
        body["force"] = {"t_s": force.t_s.tolist(), "force_n": force.force_n.tolist()}
    data = json.dumps(body, allow_nan=True).encode()
    return _HEADER.pack(MAGIC, CHANNEL_VERSION, KIND_TICK, 0, 0, seq % (1 << 32), float(t_s),
                        0, 0, len(data)) + data


def truth_from_dict(d: dict[str, Any]) -> Truth:
    """Rebuild a :class:`Truth` from its JSON form (lists back to tuples)."""
    def tup(x: Any) -> Any:
        return tuple(tup(v) for v in x) if isinstance(x, list) else x

    return Truth(**{k: tup(v) for k, v in d.items()})


_TRUTH_FIELDS = frozenset(f.name for f in fields(Truth))


def _checked_tick(body: Any) -> dict[str, Any]:
    """A tick's JSON body, checked to be what :func:`encode_tick` writes.

    Raises
    ------
    InputError
        Naming what is wrong: not an object, a truth with other fields, force
        readings that are not two number lists of one length.
    """
    if not isinstance(body, dict):
        raise InputError(f"frame channel: a tick is not a JSON object: {type(body).__name__}")
    truth, force = body.get("truth"), body.get("force")
    if truth is not None and (not isinstance(truth, dict) or set(truth) != _TRUTH_FIELDS):
        raise InputError("frame channel: a tick's truth does not have the Truth fields")
    if force is not None:
        t, f = (force.get("t_s"), force.get("force_n")) if isinstance(force, dict) else (0, 0)
        if not (isinstance(t, list) and isinstance(f, list) and len(t) == len(f)
                and all(isinstance(v, int | float) for v in (*t, *f))):
            raise InputError("frame channel: a tick's force readings are not two number "
                             "lists of one length")
    return body


class MessageReader:
    """Blocking reader of channel messages from a connected socket.

    Parameters
    ----------
    sock : socket.socket
        A connected stream socket.
    """

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self._lock = threading.Lock()

    def _exactly(self, n: int) -> bytes | None:
        buf = bytearray(n)
        view = memoryview(buf)
        got = 0
        while got < n:
            k = self.sock.recv_into(view[got:], n - got)
            if k == 0:
                return None
            got += k
        return bytes(buf)

    def read(self) -> ChannelMessage | None:
        """The next message; ``None`` once the peer closed the channel.

        Raises
        ------
        InputError
            A message that does not follow the format (bad magic, version, sizes).
        """
        header = self._exactly(HEADER_SIZE)
        if header is None:
            return None
        magic, version, kind, code, channels, seq, t_s, h, w, n = _HEADER.unpack(header)
        if magic != MAGIC:
            raise InputError(f"frame channel: bad magic {magic!r}")
        if version != CHANNEL_VERSION:
            raise InputError(f"frame channel speaks version {version}, this host "
                             f"version {CHANNEL_VERSION}")
        if n > MAX_PAYLOAD or not math.isfinite(t_s):
            raise InputError(f"frame channel: implausible message (payload {n} bytes, "
                             f"t {t_s})")
        payload = self._exactly(n)
        if payload is None:
            return None
        if kind == KIND_TICK:
            return ChannelMessage(kind, seq, t_s, tick=_checked_tick(json.loads(payload.decode())))
        if kind not in (KIND_RGB, KIND_IR) or code not in _DTYPES or channels not in (1, 3):
            raise InputError(f"frame channel: unknown message kind {kind} / dtype {code}")
        dtype = _DTYPES[code]
        if n != h * w * channels * dtype.itemsize:
            raise InputError(f"frame channel: {n} bytes do not make a {h}x{w}x{channels} "
                             f"{dtype} frame")
        shape = (h, w) if channels == 1 else (h, w, channels)
        image: NDArray[np.generic] = np.frombuffer(payload, dtype=dtype).reshape(shape)
        if dtype.byteorder not in ("=", "|"):
            image = image.astype(dtype.newbyteorder("="))
        return ChannelMessage(kind, seq, t_s, frame=Frame(t_s, seq, image))
