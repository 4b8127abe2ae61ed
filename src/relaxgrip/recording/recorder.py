"""Record a run of the loop to MCAP as it goes.

:class:`McapRecorder` implements :class:`relaxgrip.control.runner.LoopRecorder`:
``run_loop(..., recorder=rec)`` hands it the observation, the controller and
the command of every period; it writes them (see
:mod:`relaxgrip.recording.schemas` for the channels) and never changes them.

**Surviving an abrupt end.**  Messages go into MCAP chunks of at most
``chunk_size_bytes`` (uncompressed); a chunk is written to the file when it is
full and, whatever its size, every ``flush_every_s`` of loop time
(:meth:`mcap.writer.Writer.flush`), and the file object is flushed to the
operating system after every period.  A process killed with SIGKILL therefore
leaves a file whose complete chunks are all readable: at most the last
``flush_every_s`` of loop time (or one chunk) is lost.  (The schemas and
channels are written ahead of the first chunk as well as in it, so a damaged
chunk, the first included, costs only its own messages.)  Such a file has no
summary or footer; :func:`relaxgrip.recording.reader.read_recording` reads it
with ``tolerant=True`` and :func:`relaxgrip.recording.reader.recover` (``relaxgrip
recover``) rewrites it as a complete file.  Losing power needs an ``fsync`` as
well, which the recorder does not do (it would stall the loop).

**A full disk.**  A write that fails (no space left, a quota, a device gone)
ends the recording, not the data: the file is cut back to its last complete
record and given an MCAP footer without a summary (:func:`seal_recording`),
so it reads as it is, without ``relaxgrip recover`` (which would need space
for a second file).  The error that stops the loop says so.
"""

from __future__ import annotations

import base64
import json
import math
import os
import struct
from collections.abc import Iterator, Mapping
from contextlib import contextmanager, suppress
from dataclasses import asdict
from pathlib import Path
from types import TracebackType
from typing import IO, TYPE_CHECKING, Any, NoReturn

import cv2
import numpy as np

from relaxgrip import __version__
from relaxgrip.backend import BackendInfo, Command, Frame, Observation
from relaxgrip.control.phases import GraspPhase, PhaseLog
from relaxgrip.errors import InputError
from relaxgrip.fileio import check_replaceable, named_errors
from relaxgrip.interrupts import deferred
from relaxgrip.perception.features import marker_pose
from relaxgrip.perception.marker import TrackStatus
from relaxgrip.recording.schemas import (
    CHANNELS,
    RECORDING_FORMAT,
    RECORDING_VERSION,
    SESSION_METADATA,
    schema_bytes,
)
from relaxgrip.serialize import json_safe

if TYPE_CHECKING:
    from mcap.writer import Writer

    from relaxgrip.control.controller import GraspController

__all__ = ["RGB_FORMATS", "McapRecorder", "require_mcap", "seal_recording"]

#: Encodings of the RGB channel: ``jpeg`` (small) or ``png`` (lossless).
RGB_FORMATS = ("jpeg", "png")
IR_ENCODING = "32FC1"


def require_mcap() -> None:
    """Raise a helpful :class:`InputError` if the ``mcap`` package is missing."""
    try:
        import mcap  # noqa: F401
    except ImportError:
        raise InputError("recording needs the mcap package: pip install 'relaxgrip[record]'"
                         ) from None


def seal_recording(path: Path) -> float | None:
    """Make a recording cut short (a full disk) a complete MCAP file, in place.

    The file is cut back to the end of its last complete top-level record (a
    record whose length runs past the end of the file, or a byte that is no
    MCAP opcode, ends the reading), then a data end record and a footer
    without a summary are appended: readers then scan the data, as they do
    for any MCAP file without a summary.  Cutting the unfinished record off
    frees the few bytes the footer needs.

    Returns
    -------
    float or None
        Log time of the last message in a kept chunk (s), None if no chunk
        was complete.

    Raises
    ------
    OSError
        The file cannot be opened, cut or written; or it has no complete
        MCAP header to keep.
    """
    from mcap.data_stream import RecordBuilder
    from mcap.opcode import Opcode
    from mcap.records import DataEnd, Footer
    from mcap.writer import MCAP0_MAGIC

    opcodes = {int(op) for op in Opcode}
    with open(path, "r+b") as f:
        size = os.fstat(f.fileno()).st_size
        if f.read(len(MCAP0_MAGIC)) != MCAP0_MAGIC:
            raise OSError(f"{path}: no MCAP header to keep")
        pos = len(MCAP0_MAGIC)
        end_ns: int | None = None
        while pos + 9 <= size:
            f.seek(pos)
            opcode, length = struct.unpack("<BQ", f.read(9))
            if (opcode not in opcodes or opcode in (Opcode.DATA_END, Opcode.FOOTER)
                    or pos + 9 + length > size
                    or (pos == len(MCAP0_MAGIC)) != (opcode == Opcode.HEADER)):
                break
            if opcode == Opcode.CHUNK and length >= 16:
                end_ns = struct.unpack("<8xQ", f.read(16))[0]  # message start, end time
            pos += 9 + length
        if pos == len(MCAP0_MAGIC):
            raise OSError(f"{path}: no complete MCAP header to keep")
        f.truncate(pos)
        f.seek(pos)
        builder = RecordBuilder()
        DataEnd(data_section_crc=0).write(builder)  # 0: not computed
        Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
        f.write(builder.end() + MCAP0_MAGIC)  # type: ignore[no-untyped-call]
        f.flush()
        os.fsync(f.fileno())
    return None if end_ns is None else end_ns / 1e9


def _ns(t_s: float) -> int:
    """Seconds on the loop's clock as MCAP nanoseconds (never negative)."""
    return max(0, round(t_s * 1e9))


def _stamp(t_s: float) -> dict[str, int]:
    ns = _ns(t_s)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _encode(message: dict[str, Any]) -> bytes:
    """A message as the JSON its channel carries (nan and inf as null)."""
    return json.dumps(json_safe(message), allow_nan=False, separators=(",", ":")).encode()


def encode_rgb(image: np.ndarray[Any, Any], fmt: str, jpeg_quality: int) -> bytes:
    """An RGB ``(H, W, 3)`` uint8 image as JPEG or PNG bytes (colours as a viewer shows them)."""
    bgr = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2BGR)
    if fmt == "png":
        ok, buf = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    else:
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
    if not ok:
        raise InputError(f"could not encode an RGB frame of shape {image.shape} as {fmt}")
    return bytes(buf.tobytes())


class McapRecorder:
    """Write every period of a loop run to an MCAP file.

    Parameters
    ----------
    path : Path
        File to write (replaced if it exists).
    rgb_format : {"jpeg", "png"}
        Encoding of the RGB frames: JPEG (about 55 kB a frame) or lossless PNG
        (about 0.5 MB a frame; offline replay then matches exactly).
    jpeg_quality : int
        JPEG quality, 1-100.
    chunk_size_bytes : int
        Largest uncompressed chunk before it is written out.
    flush_every_s : float
        Loop time between forced chunk writes: the most a kill can lose.
    compression : {"zstd", "lz4", "none"}
        Chunk compression.
    scenario : mapping of str to str, optional
        What the run changes besides the plan, as given (``hold --temp-profile``,
        ``--target-profile``, ``--disturbance``): written in the session, so
        that nothing takes the hold for one at its plan's target and
        temperature.
    """

    def __init__(self, path: Path, rgb_format: str = "jpeg", jpeg_quality: int = 95,
                 chunk_size_bytes: int = 512 * 1024, flush_every_s: float = 1.0,
                 compression: str = "zstd", scenario: Mapping[str, str] | None = None) -> None:
        require_mcap()
        from mcap.data_stream import RecordBuilder
        from mcap.records import Channel, Schema
        from mcap.writer import CompressionType, Writer

        if rgb_format not in RGB_FORMATS:
            raise InputError(f"RGB format must be jpeg or png, got {rgb_format!r}")
        if not 1 <= jpeg_quality <= 100:
            raise InputError(f"JPEG quality must be 1-100, got {jpeg_quality}")
        if chunk_size_bytes < 1024:
            raise InputError(f"chunk size must be >= 1024 bytes, got {chunk_size_bytes}")
        if not (math.isfinite(flush_every_s) and flush_every_s > 0):
            raise InputError(f"flush interval must be > 0 s, got {flush_every_s}")
        kinds = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                 "none": CompressionType.NONE}
        if compression not in kinds:
            raise InputError(f"compression must be zstd, lz4 or none, got {compression!r}")
        self.path = Path(path)
        self.scenario = dict(scenario or {})
        self.rgb_format = rgb_format
        self.jpeg_quality = jpeg_quality
        self.flush_every_s = flush_every_s
        # A FIFO would block the open until something read it, then take the recording.
        check_replaceable(self.path, InputError)
        try:
            self._file: IO[bytes] = open(self.path, "wb")  # noqa: SIM115  (closed in close())
        except OSError as exc:
            raise InputError(f"{self.path}: cannot write ({exc.strerror})") from None
        self._writer: Writer = Writer(self._file, chunk_size=chunk_size_bytes,
                                      compression=kinds[compression])
        self._channels: dict[str, int] = {}
        definitions = RecordBuilder()
        try:
            with named_errors(self.path):
                self._writer.start(profile="", library=f"relaxgrip {__version__}")
                for topic, schema in CHANNELS.items():
                    data = schema_bytes(schema)
                    schema_id = self._writer.register_schema(schema["title"], "jsonschema",
                                                             data)
                    channel_id = self._writer.register_channel(topic, "json", schema_id)
                    self._channels[topic] = channel_id
                    Schema(id=schema_id, name=schema["title"], encoding="jsonschema",
                           data=data).write(definitions)
                    Channel(id=channel_id, topic=topic, message_encoding="json",
                            schema_id=schema_id, metadata={}).write(definitions)
                self._writer.flush()  # type: ignore[no-untyped-call]
                self._file.flush()
        except OSError:  # nothing recorded yet: no file is left
            with suppress(OSError):  # its flush fails as the write did
                self._file.close()
            with suppress(OSError):
                self.path.unlink()
            raise
        self._definitions: bytes = definitions.end()  # type: ignore[no-untyped-call]
        self._closed = False
        self._last_flush_s = -math.inf
        self._rgb_seq: int | None = None
        self._ir_seq: int | None = None
        self._log: PhaseLog | None = None
        self._n_transitions = 0
        self._n_events = 0
        self._zeroed = False
        self.messages = 0

    # -- LoopRecorder ----------------------------------------------------------------------

    def start(self, info: BackendInfo, controller: GraspController, t_s: float) -> None:
        """Write the session message (backend, estimator and its models, plan, rig).

        A recording started during a grasp (the dashboard's Record button)
        says so (``grasp_in_progress``): the marker's zero and the
        estimator's state from before it are not in it, so it cannot be
        replayed or made a dataset of.  So is one started in Open once the
        marker's zero has taken a frame: that frame is not in it either.  The
        controller's log entries from before ``t_s`` are not written.
        """
        phase = controller.phase
        tracker = controller.perception.tracker
        zeroed = tracker.zero_pose is not None
        in_progress = phase not in (GraspPhase.DONE, GraspPhase.STOPPED) and not (
            phase is GraspPhase.OPEN and tracker.zero_samples == 0)
        self._write_session(t_s, {
            "format": RECORDING_FORMAT, "format_version": RECORDING_VERSION,
            "relaxgrip_version": __version__,
            "backend": {"name": info.name, "version": info.version, "has_truth": info.has_truth},
            "estimator": controller.estimator.name,
            "plan": {k: (v.value if hasattr(v, "value") else v)
                     for k, v in asdict(controller.plan).items()},
            "rig": asdict(controller.rig), "t0_s": t_s, "rgb_format": self.rgb_format,
            "ir_encoding": IR_ENCODING, "started_in_phase": phase.value,
            "grasp_in_progress": in_progress, "scenario": self.scenario,
            "models": controller.estimator.provenance or None,
        })
        self._last_flush_s = t_s
        log = controller.log
        self._log = log
        self._n_transitions = sum(1 for t, _ in log.transitions if t < t_s)
        self._n_events = sum(1 for e in log.events if e.t_s < t_s)
        self._zeroed = zeroed

    def step(self, obs: Observation, controller: GraspController, command: Command) -> None:
        """Write one period: frames that are new, then the controller's view, then the truth."""
        t = obs.t_s
        if obs.rgb is not None and obs.rgb.seq != self._rgb_seq:
            self._rgb_seq = obs.rgb.seq
            self._write_rgb(t, obs.rgb)
        if obs.ir is not None and obs.ir.seq != self._ir_seq:
            self._ir_seq = obs.ir.seq
            self._write_ir(t, obs.ir)
        self._write("/relaxgrip/observation", t, {
            "t_s": t, "motor_position_mm": obs.motor_position_mm,
            "arm_height_mm": obs.arm_height_mm, "arm_forward_mm": obs.arm_forward_mm,
            "heater_duty": list(obs.heater_duty),
            "rgb_seq": None if obs.rgb is None else obs.rgb.seq,
            "rgb_t_s": None if obs.rgb is None else obs.rgb.t_s,
            "ir_seq": None if obs.ir is None else obs.ir.seq,
            "ir_t_s": None if obs.ir is None else obs.ir.t_s,
            "faults": sorted(obs.faults),
        })
        self._write_controller(t, controller, command)
        self._write_truth(t, obs)
        self._write_events(t, controller)
        with self._writing():
            if t - self._last_flush_s >= self.flush_every_s:
                self._writer.flush()  # type: ignore[no-untyped-call]
                self._last_flush_s = t
            self._file.flush()

    # -- parts -----------------------------------------------------------------------------

    def _write_rgb(self, t: float, frame: Frame) -> None:
        data = encode_rgb(frame.image, self.rgb_format, self.jpeg_quality)
        self._write("/rgb", t, {"timestamp": _stamp(frame.t_s), "frame_id": "rgb_camera",
                                "data": base64.b64encode(data).decode("ascii"),
                                "format": self.rgb_format})

    def _write_ir(self, t: float, frame: Frame) -> None:
        image = np.ascontiguousarray(frame.image, dtype="<f4")
        if image.ndim != 2:
            raise InputError(f"an infrared frame must be 2-D, got shape {image.shape}")
        height, width = image.shape
        self._write("/ir", t, {"timestamp": _stamp(frame.t_s), "frame_id": "ir_camera",
                               "width": width, "height": height, "encoding": IR_ENCODING,
                               "step": 4 * width,
                               "data": base64.b64encode(image.tobytes()).decode("ascii")})

    def _write_controller(self, t: float, c: GraspController, command: Command) -> None:
        percept = c.percept
        temps = [math.nan, math.nan]
        if percept is not None:
            pose = marker_pose(percept.marker)
            self._write("/relaxgrip/perception", t, {
                "t_s": percept.t_s, "marker_status": percept.marker.status.value,
                "marker_pose": None if pose is None else [float(v) for v in pose],
                "ir_age_s": percept.ir_age_s, "ir_error": percept.ir_error,
                "has_features": percept.features is not None,
            })
            if percept.thermal is not None:
                temps = list(c.temperature.readings_c(percept.thermal))
        est = c.estimate
        self._write("/relaxgrip/estimate", t, {
            "t_s": t, "force_n": est.force_n, "f_icfn_n": est.f_icfn_n,
            "f_onset_n": est.f_onset_n, "k_n": est.k_n, "tau_s": est.tau_s,
            "hold_s": est.hold_s, "calibration_n": est.calibration_n, "chain_n": est.chain_n,
            "valid": est.valid,
        })
        if math.isfinite(est.hold_s):
            stiffness = getattr(c.estimator, "closure_stiffness_n_per_mm", math.nan)
            self._write("/relaxgrip/relaxation", t, {
                "t_s": t, "f_onset_n": est.f_onset_n, "k_n": est.k_n, "tau_s": est.tau_s,
                "kappa": est.k_n / est.f_onset_n if est.f_onset_n else math.nan,
                "hold_s": est.hold_s, "closure_stiffness_n_per_mm": float(stiffness),
            })
        self._write("/relaxgrip/command", t, {
            "t_s": t, "motor_velocity_mm_s": command.motor_velocity_mm_s,
            "arm_velocity_mm_s": command.arm_velocity_mm_s,
            "approach_velocity_mm_s": command.approach_velocity_mm_s,
            "heater_duty": list(command.heater_duty),
        })
        setpoint = c.temperature.setpoint_c
        self._write("/relaxgrip/temperature", t, {
            "t_s": t, "ir_temp_c": temps, "setpoint_c": math.nan if setpoint is None else setpoint,
            "truth_temp_c": None,
        })
        self._write("/relaxgrip/phase", t, {"t_s": t, "phase": c.phase.value,
                                            "target_n": c.plan.target_n})

    def _write_truth(self, t: float, obs: Observation) -> None:
        truth = obs.truth
        if truth is not None:
            self._write("/relaxgrip/truth", t, {
                "t_s": t, "contact_force_n": truth.contact_force_n,
                "finger_temp_c": [float(np.mean(f)) for f in truth.finger_temps_c],
                "finger_deflection_m": list(truth.finger_deflection_m),
                "marker_deflection_m": list(truth.marker_deflection_m),
                "contact_position_m": truth.contact_position_m, "aperture_m": truth.aperture_m,
                "object_name": truth.object_name, "object_lifted": truth.object_lifted,
                "object_slipping": truth.object_slipping,
                "object_crushed": truth.object_crushed,
            })
        if obs.force_ref is not None:
            self._write("/relaxgrip/force_ref", t, {
                "t_s": [float(v) for v in obs.force_ref.t_s],
                "force_n": [float(v) for v in obs.force_ref.force_n],
            })

    def _write_events(self, t: float, c: GraspController) -> None:
        log = c.log
        if log is not self._log:
            # A new grasp started (GraspController.start) since the last period.  What the
            # old log gained before it (a Stop, a Release) comes first.  The start reset
            # perception, which the replay repeats on the new log's ``open``: the zero pose
            # it dropped is no rezero of the controller's.
            if self._log is not None:
                self._write_log(t, self._log)
            self._log, self._n_transitions, self._n_events = log, 0, 0
            self._zeroed = False
        self._write_log(t, log)
        # The controller may zero the marker again after this period's frame (it does so
        # once the fingers are at temperature); the zero pose only ever comes back by
        # averaging, so a zero that is gone now was dropped during this period.
        percept = c.percept
        tracked = percept is not None and percept.marker.status is TrackStatus.TRACKING
        zeroed = c.perception.tracker.zero_pose is not None
        if not zeroed and (tracked or self._zeroed):
            self._write("/relaxgrip/events", t, {"t_s": t, "kind": "marker_rezero",
                                                 "detail": "zero pose dropped by the controller"})
        self._zeroed = zeroed

    def _write_log(self, t: float, log: PhaseLog) -> None:
        """Write the transitions and events ``log`` gained since they were last written."""
        for t_s, phase in log.transitions[self._n_transitions:]:
            self._write("/relaxgrip/events", t, {"t_s": t_s, "kind": "phase",
                                                 "detail": phase.value})
        self._n_transitions = len(log.transitions)
        for event in log.events[self._n_events:]:
            self._write("/relaxgrip/events", t, {"t_s": event.t_s, "kind": event.kind.value,
                                                 "detail": event.detail})
        self._n_events = len(log.events)

    def _write_session(self, t_s: float, session: dict[str, Any]) -> None:
        """The session message, and a copy of it outside the chunks (MCAP metadata,
        :data:`SESSION_METADATA`): the chunk it is in could be damaged, and without it
        nothing reads the rest."""
        if self._closed:
            raise InputError(f"{self.path}: the recording is closed")
        data = _encode(session)
        with self._writing():
            self._writer.add_metadata(SESSION_METADATA, {"log_time_ns": str(_ns(t_s)),
                                                         "message": data.decode()})
        self._write_data("/relaxgrip/session", t_s, data)

    def _write(self, topic: str, t_s: float, message: dict[str, Any]) -> None:
        if self._closed:
            raise InputError(f"{self.path}: the recording is closed")
        self._write_data(topic, t_s, _encode(message))

    def _write_data(self, topic: str, t_s: float, data: bytes) -> None:
        """A message already encoded (:func:`_encode`)."""
        ns = _ns(t_s)
        with self._writing():  # a full chunk is written out here
            if self._definitions:
                # The writer puts the schemas and channels in the first chunk only (it
                # writes no chunk without a message): a copy of them ahead of it keeps the
                # other chunks readable if that one is damaged.  MCAP allows them outside
                # chunks, and repeated if the same.
                self._file.write(self._definitions)
                self._definitions = b""
            self._writer.add_message(self._channels[topic], log_time=ns, data=data,
                                     publish_time=ns, sequence=self.messages)
        self.messages += 1

    # -- life ------------------------------------------------------------------------------

    def close(self) -> None:
        """Write the summary and footer and close the file (idempotent)."""
        if self._closed:
            return
        with self._writing():
            try:
                self._writer.finish()  # type: ignore[no-untyped-call]
            finally:
                self._closed = True
                self._file.close()

    @contextmanager
    def _writing(self) -> Iterator[None]:
        """A block that writes to the file: if the system refuses (a full disk), the
        recording ends there, sealed as far as it was written (:func:`seal_recording`).

        Ctrl-C or ``kill`` stops the command after the block, not inside it
        (:func:`relaxgrip.interrupts.deferred`): cut in a chunk's write, the
        chunk was lost while the summary counted its messages.
        """
        try:
            with deferred(), named_errors(self.path):
                yield
        except OSError as exc:
            self._abandon(exc)

    def _abandon(self, exc: OSError) -> NoReturn:
        self._closed = True
        with suppress(OSError):  # its buffer's flush fails as the write did
            self._file.close()
        try:
            end_s = seal_recording(self.path)
        except OSError:
            kept = ("cut short: free some space, then run "
                    f"`relaxgrip recover {self.path} OUT.mcap`")
        else:
            kept = ("sealed before its first chunk was complete: it holds no messages"
                    if end_s is None else
                    f"sealed at its last complete chunk ({end_s:.2f} s of loop time)")
        raise OSError(exc.errno, f"{exc.strerror or exc}; the recording stops, {kept}",
                      str(self.path)) from exc

    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
