"""Reference force sensors the host reads beside the gripper: the ``force_ref`` of a rig.

A rig's force reference (the load cell in the calibration object) labels
recordings (``/relaxgrip/force_ref``) and calibrations; estimators and
controllers never read it.  :class:`ForceReference` is what
:class:`~relaxgrip.hardware.gripper.SerialGripper` needs of one, so that any
source plugs in: :class:`McuLoadCell` is the MCU's HX711 channel, reported
in Status (protocol minor 1); an external gauge on its own serial port is
another implementation of the same four methods.

Timestamps are on the host's clock.  A load-cell conversion is stamped
with the MCU's time of reading; the host maps it onto its clock through the
Status that carried it: ``t = t_rx - (mcu_time_us - load_cell_time_us) / 1e6``.

The tare (zeroing) is the host's: :meth:`ForceReference.shift_zero` moves a
linear source's zero so that a reading taken with nothing on the cell
becomes 0 N (:meth:`SerialGripper.tare_force_ref` averages such readings).
The MCU reports raw counts and keeps no calibration, so that every source,
the MCU's or an external gauge, is zeroed and scaled in one place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from relaxgrip.backend import ForceSamples
from relaxgrip.errors import InputError
from relaxgrip.hardware.protocol.client import McuClient
from relaxgrip.hardware.protocol.codec import Feature, Status

__all__ = ["ForceReference", "LinearCalibration", "McuLoadCell"]

_U32 = 1 << 32
_U16 = 1 << 16


@runtime_checkable
class ForceReference(Protocol):
    """A reference force sensor read by the host."""

    name: str

    def start(self) -> None:
        """Begin reading (after the MCU's handshake).

        Raises
        ------
        InputError
            If the sensor is not there or does not answer.
        """
        ...

    def read(self, now_s: float) -> ForceSamples | None:
        """Readings since the last call, on the host clock; None if there are none."""
        ...

    def shift_zero(self, force_n: float) -> None:
        """Subtract ``force_n`` from every later reading (the tare)."""
        ...

    def close(self) -> None:
        """Stop reading and release the sensor."""
        ...


@dataclass(frozen=True)
class LinearCalibration:
    """Force from raw counts: ``F = (counts - offset_counts) · scale_n_per_count``.

    Attributes
    ----------
    scale_n_per_count : float
        Newtons per count (from a calibration with known weights).
    offset_counts : float
        Reading with nothing on the cell (counts; the tare moves it).
    """

    scale_n_per_count: float
    offset_counts: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.scale_n_per_count) and self.scale_n_per_count != 0.0):
            raise InputError("load-cell scale_n_per_count must be a finite non-zero number, "
                             f"got {self.scale_n_per_count}")
        if not math.isfinite(self.offset_counts):
            raise InputError(f"load-cell offset_counts must be finite, got {self.offset_counts}")

    def force_n(self, counts: float) -> float:
        """Force of a reading (N)."""
        return (counts - self.offset_counts) * self.scale_n_per_count


@dataclass
class _Pending:
    t_s: list[float] = field(default_factory=list)
    force_n: list[float] = field(default_factory=list)


class McuLoadCell:
    """The MCU's load-cell channel as a :class:`ForceReference`.

    It listens to every Status the client receives (answers, unsolicited and
    late ones) and keeps each new conversion (a new ``load_cell_samples``).

    Parameters
    ----------
    client : McuClient
        The MCU's client; the load cell registers itself as a Status listener.
    calibration : LinearCalibration
        Scale and zero of the cell.

    Attributes
    ----------
    conversions : int
        Conversions received.
    conversions_missed : int
        Conversions the MCU made that no received Status carried.
    """

    name = "mcu-load-cell"

    def __init__(self, client: McuClient, calibration: LinearCalibration) -> None:
        self.client = client
        self.calibration = calibration
        self.conversions = 0
        self.conversions_missed = 0
        self._last_samples: int | None = None
        self._pending = _Pending()
        self._listening = False

    def start(self) -> None:
        """Check that the MCU reports a load cell, then listen to its Status frames.

        Raises
        ------
        InputError
            If the session's protocol minor is 0 (no load-cell fields) or the
            firmware was built without a load cell.
        """
        ack = self.client.hello_ack
        if ack is None:
            raise InputError("the MCU load cell starts after the MCU's handshake")
        if self.client.session_minor < 1 or ack.features is None:
            raise InputError(
                f"the force reference is the MCU's load cell, but the MCU ({ack.firmware_id!r}) "
                "speaks protocol minor 0, whose Status has no load cell: flash firmware "
                "of protocol 1.1 or later (docs/firmware.md)")
        if not ack.features & Feature.LOAD_CELL:
            raise InputError(
                f"the force reference is the MCU's load cell, but the MCU firmware "
                f"({ack.firmware_id!r}) was built without one: build it with LOAD_CELL=1 "
                "(docs/firmware.md)")
        self._last_samples = None
        if not self._listening:
            self.client.status_listeners.append(self.on_status)
            self._listening = True

    def on_status(self, status: Status, rx_time_s: float) -> None:
        """Take the conversion a Status carries, if it is a new one."""
        samples = status.load_cell_samples
        if samples is None or status.load_cell_counts is None or \
                status.load_cell_time_us is None or samples == 0:
            return
        if samples == self._last_samples:
            return
        if self._last_samples is not None:
            self.conversions_missed += (samples - self._last_samples - 1) % _U16
        self._last_samples = samples
        age_s = ((status.mcu_time_us - status.load_cell_time_us) % _U32) / 1e6
        self._pending.t_s.append(rx_time_s - age_s)
        self._pending.force_n.append(self.calibration.force_n(status.load_cell_counts))
        self.conversions += 1

    def read(self, now_s: float) -> ForceSamples | None:
        """Conversions received since the last call (host clock), None if none."""
        pending = self._pending
        if not pending.t_s:
            return None
        self._pending = _Pending()
        return ForceSamples(np.asarray(pending.t_s, dtype=np.float64),
                            np.asarray(pending.force_n, dtype=np.float64))

    def shift_zero(self, force_n: float) -> None:
        """Move the zero so that a reading of ``force_n`` becomes 0 N."""
        cal = self.calibration
        self.calibration = LinearCalibration(
            cal.scale_n_per_count, cal.offset_counts + force_n / cal.scale_n_per_count)

    def close(self) -> None:
        """Stop listening."""
        if self._listening:
            self.client.status_listeners.remove(self.on_status)
            self._listening = False
