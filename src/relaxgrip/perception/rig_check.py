"""Check a rig: handshake with its MCU, a frame from each camera, the marker where the file says.

:func:`check_rig` computes a :class:`RigCheck`; ``relaxgrip check-rig``
displays it.  Nothing is enabled: the MCU's outputs stay off throughout.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from relaxgrip.backend import Frame
from relaxgrip.clock import Clock, WallClock
from relaxgrip.hardware.cameras import CameraError, FrameSource, open_frame_sources
from relaxgrip.hardware.gripper import GuardedTransport, fault_names
from relaxgrip.hardware.protocol.client import McuClient
from relaxgrip.hardware.protocol.transport import SerialTransport
from relaxgrip.hardware.rig_file import RigFile
from relaxgrip.perception.marker import (
    PoseSolver,
    detect_markers,
    detection_pose,
    make_detector,
    to_gray,
)

__all__ = ["RigCheck", "check_rig", "grab_frame"]


@dataclass(frozen=True)
class RigCheck:
    """What :func:`check_rig` found.

    Attributes
    ----------
    rig : str
        Rig name.
    port : str
        Serial port.
    firmware_id : str
        The MCU's firmware.
    watchdog_ms : int
        The MCU's watchdog period (ms).
    max_velocity_mm_s : float
        The MCU's velocity limit (mm/s).
    fault_flags : list of str
        Faults the MCU reports (``RESET`` after a power-up is normal).
    rgb_shape, ir_shape : tuple of int
        Frame shapes.
    ir_temp_c : tuple of float
        Minimum, mean and maximum of the thermal frame (°C).
    marker_id : int
        The marker the rig file names (its id in the file's dictionary).
    marker_found : bool
        Whether that marker was detected on the RGB frame.
    marker_distance_mm : float
        Distance of the marker from the camera (mm; nan if not found).
    marker_offset_mm : float
        How far the detected marker is from where the rig file puts it on an
        unloaded finger (its ``[zero_pose]``, else its mounts; mm; nan if not
        found).
    reprojection_px : float
        RMS corner reprojection error of the marker pose (pixels).
    marker_ids_seen : list of int
        The ids of every marker of the file's dictionary on the frame: another
        id than the file's means the file names the wrong marker (the loop
        tracks only the file's).
    """

    rig: str
    port: str
    firmware_id: str
    watchdog_ms: int
    max_velocity_mm_s: float
    fault_flags: list[str]
    rgb_shape: tuple[int, ...]
    ir_shape: tuple[int, ...]
    ir_temp_c: tuple[float, float, float]
    marker_id: int
    marker_found: bool
    marker_distance_mm: float
    marker_offset_mm: float
    reprojection_px: float
    marker_ids_seen: list[int]

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form (``--json``)."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


def grab_frame(source: FrameSource, clock: Clock, poll_s: float = 0.01) -> Frame:
    """Wait for a source's first frame (its stall limit bounds the wait)."""
    while True:
        frame = source.read(clock.now())
        if frame is not None:
            return frame
        time.sleep(poll_s)


def check_rig(rig: RigFile, clock: Clock | None = None, *,
              sources: tuple[FrameSource, FrameSource] | None = None) -> RigCheck:
    """Open the rig's port, handshake, grab one frame per camera and find the marker.

    Parameters
    ----------
    rig : RigFile
        The rig.
    clock : Clock, optional
        Wall clock by default.
    sources : (FrameSource, FrameSource), optional
        Camera sources (default: those the rig names).

    Returns
    -------
    RigCheck

    Raises
    ------
    InputError
        A port that cannot be opened, an MCU that does not answer or speaks
        another version, a camera that cannot be opened or stays silent.
    """
    clk = clock if clock is not None else WallClock()
    client = McuClient(GuardedTransport(SerialTransport(rig.serial.port, rig.serial.baud), clk),
                       clk, reply_timeout_s=rig.serial.reply_timeout_s)
    rgb_src, ir_src = sources if sources is not None else open_frame_sources(rig, clk)
    started: list[FrameSource] = []
    try:
        for src in (rgb_src, ir_src):
            src.start()
            started.append(src)
        ack = client.handshake()
        status = client.request_status()
        rgb = grab_frame(rgb_src, clk)
        ir = grab_frame(ir_src, clk)
    finally:
        for src in started:
            src.close()
        client.close()
    image = np.asarray(rgb.image, dtype=np.uint8)
    if image.ndim != 3:
        raise CameraError(f"RGB camera gave a {image.shape} frame, expected (H, W, 3)")
    intr = rig.rgb.mount.intrinsics
    detector = make_detector(rig.marker.aruco_dictionary)
    gray = to_gray(image)
    detections = detect_markers(gray, detector)
    seen = sorted({d.marker_id for d in detections})
    ours = [d for d in detections if d.marker_id == rig.marker.marker_id]
    pose = (detection_pose(gray, ours[0], PoseSolver(rig.marker.size_m, intr)) if ours
            else None)
    temps = np.asarray(ir.image, dtype=np.float64)
    if pose is None:
        distance = offset = reproj = math.nan
    else:
        expected = np.asarray(rig.geometry.marker_home_m)
        distance = float(np.linalg.norm(pose.tvec_m)) * 1e3
        offset = float(np.linalg.norm(pose.tvec_m - expected)) * 1e3
        reproj = float(pose.reprojection_px)
    return RigCheck(
        rig.name, rig.serial.port, ack.firmware_id, ack.watchdog_ms,
        ack.max_velocity_um_s / 1000.0, sorted(fault_names(status.fault_flags)),
        tuple(image.shape), tuple(temps.shape),
        (float(np.nanmin(temps)), float(np.nanmean(temps)), float(np.nanmax(temps))),
        rig.marker.marker_id, pose is not None, distance, offset, reproj, seen,
    )
