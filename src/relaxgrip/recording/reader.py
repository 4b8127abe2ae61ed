"""Read a relaxgrip MCAP recording back: messages, periods, frames; recover a killed one.

A complete recording ends with MCAP's footer and magic.  A recording whose
writer was killed has neither: its complete chunks are readable one after the
other with mcap's :class:`mcap.stream_reader.StreamReader` (a linear scan that
needs no summary), until the record cut short by the kill, where the scan
raises.  :func:`iter_messages` with ``tolerant=True`` stops there quietly, so a
killed recording gives everything up to its last flushed chunk; without it, an
incomplete file is an :class:`~relaxgrip.errors.InputError` naming
``relaxgrip recover``.  :func:`recover` rewrites the readable part as a
complete file (summary, footer), which every MCAP tool then opens.
"""

from __future__ import annotations

import base64
import io
import json
import os
import struct
import typing
import zlib
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any, BinaryIO

import cv2
import numpy as np

from relaxgrip.backend import Frame
from relaxgrip.errors import InputError
from relaxgrip.fileio import atomic_file, check_input_file, check_writable, one_line
from relaxgrip.recording.recorder import require_mcap
from relaxgrip.recording.schemas import (
    RECORDING_FORMAT,
    RECORDING_VERSION,
    SESSION_METADATA,
    SESSION_TOPIC,
)
from relaxgrip.rig import RigGeometry

__all__ = ["Period", "RecoverReport", "iter_messages", "iter_periods", "malformed_fields",
           "read_replayable_session", "read_session", "recover", "rig_from_dict"]

_MAGIC = b"\x89MCAP0\r\n"
_FOOTER_OPCODE = 0x02
_FOOTER_RECORD = 1 + 8 + 8 + 8 + 4  # opcode, length, summary start, offset start, crc
_METADATA_OPCODE = 0x0C


def _check_file(path: Path, tolerant: bool) -> bool:
    """Whether ``path`` is a complete MCAP file; raise on a missing, foreign or special one.

    A FIFO (a shell's ``<(cat rec.mcap)``) or a device is refused before it is
    opened: the footer is found by a seek a pipe cannot make, and a FIFO
    without a writer would block the open for ever.
    """
    check_input_file(path, "recording", InputError)
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            head = f.read(len(_MAGIC))
            complete = False
            if size >= 2 * len(_MAGIC) + _FOOTER_RECORD:
                f.seek(size - len(_MAGIC) - _FOOTER_RECORD)
                tail = f.read()
                complete = tail[0] == _FOOTER_OPCODE and tail.endswith(_MAGIC)
    except FileNotFoundError:  # removed since the check
        raise InputError(f"{path}: no such recording") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or one_line(exc)})") from None
    if head != _MAGIC:
        raise InputError(f"{path}: not an MCAP file")
    if not complete and not tolerant:
        raise InputError(f"{path}: the recording is truncated (no MCAP footer: the recorder "
                         f"was killed?); run `relaxgrip recover {path} OUT.mcap`")
    return complete


def iter_records(path: Path, tolerant: bool = False) -> Iterator[Any]:
    """MCAP records of ``path`` in file order, chunks opened (schemas, channels, messages, ...).

    Parameters
    ----------
    path : Path
        The recording.
    tolerant : bool
        Read an incomplete file up to its last complete chunk instead of raising.

    Raises
    ------
    InputError
        Missing, foreign or (unless ``tolerant``) truncated or damaged file,
        or a path that is not a regular file (a directory, a FIFO, a device).
    """
    require_mcap()
    from mcap.exceptions import McapError

    path = Path(path)
    _check_file(path, tolerant)
    with open(path, "rb") as f:
        records = _records(f, validate_crcs=True)
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except (McapError, struct.error, ValueError, EOFError) as exc:
                # The record the writer was killed in (or a damaged one): what came
                # before is complete; nothing after it can be trusted.
                if tolerant:
                    return
                raise InputError(f"{path}: damaged MCAP data ({type(exc).__name__})") from None
            except Exception as exc:  # decompression libraries raise their own types
                if tolerant:
                    return
                raise InputError(f"{path}: damaged MCAP data ({type(exc).__name__})") from None
            yield record


def iter_messages(path: Path, tolerant: bool = False) -> Iterator[tuple[str, int, dict[str, Any]]]:
    """``(topic, log_time_ns, message)`` of every JSON message, in file order.

    Raises
    ------
    InputError
        As :func:`iter_records`, or a message that is not JSON.
    """
    from mcap.records import Channel, Message

    topics: dict[int, str] = {}
    for record in iter_records(path, tolerant):
        if isinstance(record, Channel):
            topics[record.id] = record.topic
        elif isinstance(record, Message):
            topic = topics.get(record.channel_id)
            if topic is None:
                raise InputError(f"{path}: a message on unknown channel {record.channel_id}")
            try:
                message = json.loads(record.data)
            except (UnicodeDecodeError, json.JSONDecodeError):
                raise InputError(f"{path}: a message on {topic} is not JSON") from None
            if not isinstance(message, dict):
                raise InputError(f"{path}: a message on {topic} is not a JSON object")
            yield topic, record.log_time, message


def read_session(path: Path, tolerant: bool = False) -> dict[str, Any]:
    """The recording's session message (backend, estimator, plan, rig).

    Raises
    ------
    InputError
        The file is not a relaxgrip recording, or one newer than this code reads.
    """
    for topic, _, message in iter_messages(path, tolerant):
        if topic == SESSION_TOPIC:
            return _check_session(path, message)
        break
    raise InputError(f"{path}: not a relaxgrip recording (no session message first)")


def read_replayable_session(path: Path, tolerant: bool = False) -> dict[str, Any]:
    """:func:`read_session` of a recording that can be replayed: one begun before its grasp.

    Raises
    ------
    InputError
        As :func:`read_session`, a recording ``recover`` restored without its
        start (``lost_start_s``), or one begun during a grasp (the
        dashboard's Record button): the marker's zero and the estimator's
        state from before it are not in it.
    """
    session = read_session(path, tolerant)
    lost = session.get("lost_start_s")
    if isinstance(lost, (int, float)) and not isinstance(lost, bool):
        raise InputError(
            f"{path}: recovered without its start (a damaged first chunk; it resumes at "
            f"{lost - float(session.get('t0_s') or 0.0):.2f} s): the marker's zero and the "
            "estimator's state from before then are lost")
    if session.get("grasp_in_progress"):
        raise InputError(
            f"{path}: the recording began during a grasp (phase "
            f"{session.get('started_in_phase')}): the marker's zero and the estimator's state "
            "from before it are not in it; record from before the grasp starts")
    return session


def _check_session(path: Path, session: dict[str, Any]) -> dict[str, Any]:
    if session.get("format") != RECORDING_FORMAT:
        raise InputError(f"{path}: not a relaxgrip recording")
    version = session.get("format_version")
    if isinstance(version, bool) or not isinstance(version, int):
        raise InputError(f"{path}: the session's format_version is not an integer: {version!r}")
    if version > RECORDING_VERSION:
        raise InputError(f"{path}: recording format {version} is newer "
                         f"than this relaxgrip reads ({RECORDING_VERSION})")
    for key, required in (("rig", True), ("backend", True), ("plan", False)):
        value = session.get(key)
        if not isinstance(value, dict) and (required or value is not None):
            raise InputError(f"{path}: the session's {key} is not an object: {value!r}")
    return session


@contextmanager
def malformed_fields(path: Path) -> Iterator[None]:
    """Turn a recording message's missing or mistyped field into one :class:`InputError` line.

    Wraps the reading of a recording's messages (``message["t_s"]``,
    ``float(...)``, base64), so that a file another program wrote, or an
    edited one, is refused by name rather than with a traceback.
    """
    try:
        yield
    except InputError as exc:  # a frame or a value the readers refuse: say whose
        if str(path) in str(exc):
            raise
        raise InputError(f"{path}: {exc}") from None
    except KeyError as exc:
        raise InputError(f"{path}: a message lacks the field {exc.args[0]!r}") from None
    except (TypeError, ValueError, AttributeError) as exc:  # binascii.Error is a ValueError
        raise InputError(f"{path}: a message has a malformed field ({one_line(exc)})") from None


def rig_from_dict(data: dict[str, Any]) -> RigGeometry:
    """Rebuild the :class:`RigGeometry` a recording's session stores.

    Raises
    ------
    InputError
        If the stored rig does not describe one.
    """
    if not isinstance(data, dict):
        raise InputError(f"the recording's rig is not an object: {data!r}")
    try:
        rig = _build(RigGeometry, data)
    except (TypeError, ValueError, KeyError) as exc:
        raise InputError(f"the recording's rig is not readable ({exc})") from None
    assert isinstance(rig, RigGeometry)
    return rig


def _build(cls: type, data: Any) -> Any:
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for f in fields(cls):
        if not f.init or f.name not in data:
            continue
        kind = hints[f.name]
        value = data[f.name]
        if isinstance(kind, type) and is_dataclass(kind):
            value = _build(kind, value)
        elif isinstance(value, list):
            value = tuple(value)
        kwargs[f.name] = value
    return cls(**kwargs)


@dataclass
class Period:
    """One control period of a recording.

    Attributes
    ----------
    t_s : float
        Loop time (s).
    rgb, ir : Frame or None
        The latest frame of each stream at this period (decoded; repeated
        between new frames, with the same ``seq``).
    messages : dict of str to dict
        This period's message per topic (``/relaxgrip/observation``, ...).
    events : list of dict
        This period's events (phase transitions, controller events, rezero).
    """

    t_s: float
    rgb: Frame | None
    ir: Frame | None
    messages: dict[str, dict[str, Any]] = field(default_factory=dict)
    events: list[dict[str, Any]] = field(default_factory=list)

    def get(self, topic: str) -> dict[str, Any] | None:
        """This period's message on ``topic``, if any."""
        return self.messages.get(topic)


def decode_rgb(message: dict[str, Any]) -> np.ndarray[Any, Any]:
    """A ``foxglove.CompressedImage`` message as an RGB ``(H, W, 3)`` uint8 image."""
    buf = np.frombuffer(base64.b64decode(message["data"]), dtype=np.uint8)
    bgr = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    if bgr is None:
        raise InputError(f"an RGB frame ({message.get('format')}) does not decode")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def decode_ir(message: dict[str, Any]) -> np.ndarray[Any, Any]:
    """A ``foxglove.RawImage`` ``32FC1`` message as a ``(H, W)`` float32 image (°C)."""
    if message.get("encoding") != "32FC1":
        raise InputError(f"infrared encoding {message.get('encoding')!r} is not 32FC1")
    h, w = int(message["height"]), int(message["width"])
    data = np.frombuffer(base64.b64decode(message["data"]), dtype="<f4")
    if data.size != h * w:
        raise InputError(f"an infrared frame has {data.size} values for {h}x{w}")
    return data.reshape(h, w).astype(np.float32)


def iter_periods(path: Path, tolerant: bool = False) -> Iterator[Period]:
    """Every complete control period of a recording, with its frames decoded.

    A period whose observation or estimate was lost (the end of a killed
    recording) is not returned.

    Raises
    ------
    InputError
        As :func:`iter_messages`; a file that is not a relaxgrip recording; a
        message that lacks a field or has a malformed one.
    """
    with malformed_fields(path):
        yield from _periods(path, tolerant)


def _periods(path: Path, tolerant: bool) -> Iterator[Period]:
    rgb: Frame | None = None
    ir: Frame | None = None
    pending_rgb: dict[str, Any] | None = None
    pending_ir: dict[str, Any] | None = None
    current: Period | None = None
    seen_session = False
    for topic, _, message in iter_messages(path, tolerant):
        if not seen_session:
            if topic != SESSION_TOPIC:
                raise InputError(f"{path}: not a relaxgrip recording (no session message first)")
            _check_session(path, message)
            seen_session = True
            continue
        if topic == "/rgb":
            pending_rgb = message
        elif topic == "/ir":
            pending_ir = message
        elif topic == "/relaxgrip/observation":
            if current is not None and _complete(current):
                yield current
            t = float(message["t_s"])
            # A frame written before this observation is its frame if it bears the time the
            # observation names: after a chunk lost to damage it can be an older one.
            rgb_t = _num(message.get("rgb_t_s"), t)
            if pending_rgb is not None and _stamped(pending_rgb, rgb_t):
                rgb = Frame(rgb_t, int(message["rgb_seq"]), decode_rgb(pending_rgb))
            ir_t = _num(message.get("ir_t_s"), t)
            if pending_ir is not None and _stamped(pending_ir, ir_t):
                ir = Frame(ir_t, int(message["ir_seq"]), decode_ir(pending_ir))
            pending_rgb = pending_ir = None
            current = Period(t, rgb if message.get("rgb_seq") is not None else None,
                             ir if message.get("ir_seq") is not None else None,
                             {topic: message})
        elif current is not None:
            if topic == "/relaxgrip/events":
                current.events.append(message)
            else:
                current.messages[topic] = message
    if not seen_session:
        raise InputError(f"{path}: not a relaxgrip recording (no messages)")
    if current is not None and _complete(current):
        yield current


def _complete(period: Period) -> bool:
    return "/relaxgrip/estimate" in period.messages and "/relaxgrip/phase" in period.messages


def _num(value: Any, default: float) -> float:
    return default if value is None else float(value)


def _stamped(image: dict[str, Any], t_s: float) -> bool:
    """Whether an image message's ``timestamp`` is ``t_s`` (s; to a microsecond)."""
    stamp = image["timestamp"]
    ns = int(stamp["sec"]) * 1_000_000_000 + int(stamp["nsec"])
    return abs(ns - max(0.0, t_s) * 1e9) < 1e3  # the recorder writes no time before 0


@dataclass(frozen=True)
class RecoverReport:
    """What :func:`recover` found.

    Attributes
    ----------
    complete : bool
        The source already had its footer.
    messages : int
        Messages written to the output.
    channels : int
        Channels written.
    end_s : float
        Log time of the last message (s); nan if none.
    damaged_chunks : int
        Chunks whose data did not check (CRC, decompression): skipped.
    expected_messages : int or None
        The message count the source's summary states (a complete file), else None.
    stopped_early : bool
        The file's record structure broke before its end (a killed recorder,
        or damage outside a chunk's data): nothing after that point is read,
        but for a complete file's chunks, which its chunk index finds (the
        chunk the break is in counts as damaged).
    lost_start_s : float or None
        The damage took the first chunk, session message included: the
        session was restored from its copy, and the recording resumes at this
        log time (s); it can no longer be replayed (the marker's zero is lost).
    """

    complete: bool
    messages: int
    channels: int
    end_s: float
    damaged_chunks: int = 0
    expected_messages: int | None = None
    stopped_early: bool = False
    lost_start_s: float | None = None

    @property
    def lost_messages(self) -> int | None:
        """Messages the summary counts that could not be recovered (None: unknown)."""
        return None if self.expected_messages is None else self.expected_messages - self.messages


def recover(src: Path, dst: Path) -> RecoverReport:
    """Rewrite the readable part of a killed or damaged recording as a complete MCAP file.

    Reads the file's records in order; a chunk whose data does not check
    (CRC, decompression) is skipped and counted, and the next one read, so
    one damaged chunk costs its own messages (about 0.2 s), not the rest of
    the file.  Where the record structure itself breaks (the end of a
    killed file) reading stops; in a complete file (damage to a chunk's
    header, say) it goes on from the next chunk its summary's chunk index
    lists.  The summary of a complete file is not
    copied (the writer makes a new one) but its message count is reported
    beside what was recovered, and the schemas and channels it lists stand
    in for any the data section lost (a damaged first chunk of a recording
    written before the recorder put a copy of them ahead of it).  So does the
    copy of the session message the recorder writes outside the chunks
    (:data:`~relaxgrip.recording.schemas.SESSION_METADATA`) for a session
    message the damage took: without it nothing reads the rest.  The output
    appears whole or not at all.

    Raises
    ------
    InputError
        Missing or foreign source, or one that is not a regular file (a
        FIFO, a pipe, a device), nothing readable, ``dst`` the same file,
        a directory or another non-regular file (a FIFO, a device), or ``dst``
        not writable.
    """
    require_mcap()
    from mcap.records import Channel, Chunk, DataEnd, Message, Metadata, Schema, Statistics
    from mcap.stream_reader import breakup_chunk
    from mcap.writer import Writer

    src, dst = Path(src), Path(dst)
    complete = _check_file(src, tolerant=True)
    if dst.exists() and os.path.samefile(src, dst):
        raise InputError(f"{dst}: the output must be another file than the input")
    if dst.is_dir():
        raise InputError(f"{dst}: is a directory; name the MCAP file to write")
    check_writable(dst, InputError)  # a FIFO or a device is not replaced by a file
    # A complete file's summary lists its schemas and channels again: what the data
    # section lost of them (in a damaged first chunk) is taken from there.
    listed = _summary_definitions(src) if complete else _Listed({}, {}, (), None)
    listed_schemas, listed_channels = listed.schemas, listed.channels
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    count = damaged = 0
    end_ns = -1
    expected: int | None = None
    stopped_early = False
    # The session message's copy outside the chunks, while the message is not copied.
    session: Any = None
    session_copied = False
    lost_start_s: float | None = None
    session_channel = next((c for c in listed_channels.values() if c.topic == SESSION_TOPIC),
                           None)

    def copy(record: Any, writer: Writer) -> None:
        nonlocal count, end_ns, session, session_copied, session_channel, lost_start_s
        if isinstance(record, Metadata) and record.name == SESSION_METADATA:
            writer.add_metadata(record.name, dict(record.metadata))
            session = None if session_copied else record
        elif isinstance(record, Channel) and record.topic == SESSION_TOPIC:
            session_channel = session_channel or record
        if isinstance(record, Schema) and record.id not in schemas:
            schemas[record.id] = writer.register_schema(record.name, record.encoding,
                                                        record.data)
        elif isinstance(record, Channel) and record.id not in channels:
            channels[record.id] = writer.register_channel(
                record.topic, record.message_encoding, schemas.get(record.schema_id, 0),
                dict(record.metadata))
        elif isinstance(record, Message):
            listed = listed_channels.get(record.channel_id)
            if record.channel_id not in channels and listed is not None:
                if listed.schema_id in listed_schemas:
                    copy(listed_schemas[listed.schema_id], writer)
                copy(listed, writer)
            if session_channel is not None and record.channel_id == session_channel.id:
                session, session_copied = None, True
            elif session is not None and session_channel is not None:
                # The damage took the message: put it first (unless the copy is damaged too).
                lost, session = _session_copy(session.metadata), None
                if lost is not None:
                    ns, message = lost
                    # ... saying what it lost with it: the marker's zero, the estimator's start.
                    lost_start_s = record.log_time * 1e-9
                    restored = {**message, "lost_start_s": lost_start_s}
                    copy(Message(channel_id=session_channel.id, sequence=0, log_time=ns,
                                 publish_time=ns, data=json.dumps(restored).encode()), writer)
            if record.channel_id in channels:
                writer.add_message(channels[record.channel_id], record.log_time, record.data,
                                   record.publish_time, record.sequence)
                count += 1
                end_ns = max(end_ns, record.log_time)

    try:
        with atomic_file(dst) as out, open(src, "rb") as f:
            writer = Writer(out)
            writer.start(profile="", library="relaxgrip recover")
            # CRCs are checked per chunk (below), not over the data section: a
            # damaged chunk is skipped, not the end of the reading.
            records = _records(f, emit_chunks=True, validate_crcs=False)
            in_summary = False
            read_to = f.tell()  # where the records read so far end (a chunk is read whole)
            while True:
                try:
                    record = next(records)
                except StopIteration:
                    break
                except Exception:  # the killed record, or damage to the structure
                    if in_summary:
                        break
                    # A complete file's chunk index finds the chunks after the break.
                    later = [o for o in listed.chunk_offsets if o >= read_to]
                    stopped_early = not later
                    records = _chunks_at(f, later)
                    continue
                read_to = f.tell()
                if record is None:  # a chunk the index lists that does not read
                    damaged += 1
                elif isinstance(record, DataEnd):
                    in_summary = True  # its schemas and channels repeat the data's
                elif isinstance(record, Statistics):
                    expected = int(record.message_count)
                elif in_summary:
                    continue
                elif isinstance(record, Chunk):
                    try:
                        inner = breakup_chunk(record, validate_crc=True)
                    except Exception:  # CRC, decompression: this chunk only
                        damaged += 1
                        continue
                    for item in inner:
                        copy(item, writer)
                else:
                    copy(record, writer)
            if count == 0:
                raise InputError(f"{src}: no complete message to recover")
            if expected is None:  # the summary was not reached in order
                expected = listed.message_count
            writer.finish()  # type: ignore[no-untyped-call]
    except OSError as exc:
        raise InputError(f"{dst}: cannot write ({exc.strerror or exc})") from None
    return RecoverReport(complete, count, len(channels),
                         end_ns * 1e-9 if end_ns >= 0 else float("nan"),
                         damaged_chunks=damaged, expected_messages=expected,
                         stopped_early=stopped_early, lost_start_s=lost_start_s)


def _records(f: BinaryIO, **options: Any) -> Iterator[Any]:
    """mcap's :class:`~mcap.stream_reader.StreamReader` records of ``f`` (``options`` its
    own), but for a damaged metadata record, which is skipped.

    The session's copy (:data:`SESSION_METADATA`) is the only metadata record, outside any
    chunk and without a CRC: a damaged byte of it (not UTF-8) stopped the scan there, and
    every chunk after it, intact, was lost for the sake of a copy.
    """
    from mcap.stream_reader import StreamReader

    size = os.fstat(f.fileno()).st_size
    skip_magic = False
    while True:
        # Where the record read next starts (a chunk's records are yielded once it is read).
        start = f.tell()
        try:
            for record in StreamReader(f, skip_magic=skip_magic, **options).records:
                yield record
                start = f.tell()
            return
        except Exception:
            f.seek(start)
            head = f.read(9)  # opcode, length
            if len(head) < 9 or head[0] != _METADATA_OPCODE:
                raise
            end = start + 9 + struct.unpack("<Q", head[1:])[0]
            if end > size:  # cut short: the end of a killed file
                raise
            f.seek(end)
            skip_magic = True  # read past already


def _session_copy(metadata: dict[str, str]) -> tuple[int, dict[str, Any]] | None:
    """The log time (ns) and the session message a :data:`SESSION_METADATA` record holds;
    None if the record is damaged (not JSON, not a session object, no time)."""
    try:
        ns = int(metadata["log_time_ns"])
        message = json.loads(metadata["message"])
    except (KeyError, ValueError):
        return None
    return (ns, message) if ns >= 0 and isinstance(message, dict) else None


@dataclass(frozen=True)
class _Listed:
    """What the summary of a complete MCAP file lists: schemas and channels by id, where
    its chunks start (from the chunk index), and its message count (None: not stated)."""

    schemas: dict[int, Any]
    channels: dict[int, Any]
    chunk_offsets: tuple[int, ...]
    message_count: int | None


def _summary_definitions(path: Path) -> _Listed:
    """What the summary of a complete MCAP file lists (:class:`_Listed`).

    Nothing if the file has no summary, or one that does not check (its CRC,
    its records).
    """
    from mcap.records import Channel, ChunkIndex, Footer, Schema, Statistics
    from mcap.stream_reader import StreamReader

    none = _Listed({}, {}, (), None)
    schemas: dict[int, Any] = {}
    channels: dict[int, Any] = {}
    offsets: list[int] = []
    count: int | None = None
    try:
        with open(path, "rb") as f:
            end = f.seek(-len(_MAGIC), os.SEEK_END)  # the footer's end
            f.seek(end - _FOOTER_RECORD)
            summary_start, _, crc = struct.unpack("<QQI", f.read(_FOOTER_RECORD)[9:])
            if summary_start == 0:
                return none
            f.seek(summary_start)
            summary = f.read(end - summary_start)
        if crc and zlib.crc32(summary[:-4]) != crc:  # it covers all but itself
            return none
        for record in StreamReader(io.BytesIO(summary), skip_magic=True).records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, ChunkIndex):
                offsets.append(int(record.chunk_start_offset))
            elif isinstance(record, Statistics):
                count = int(record.message_count)
            elif isinstance(record, Footer):
                break
    except Exception:  # a summary damaged beyond its CRC's notice: none to use
        return none
    return _Listed(schemas, channels, tuple(sorted(offsets)), count)


def _chunks_at(f: BinaryIO, offsets: Sequence[int]) -> Iterator[Any]:
    """The chunk record at each of ``offsets`` in ``f`` (its data unchecked), or None
    where none reads there."""
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    for offset in offsets:
        f.seek(offset)
        try:
            record = next(StreamReader(f, skip_magic=True, emit_chunks=True,
                                       validate_crcs=False).records)
        except Exception:  # its header is the damage
            record = None
        yield record if isinstance(record, Chunk) else None
