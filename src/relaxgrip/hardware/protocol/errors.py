"""Exceptions of the MCU protocol, one line each, all :class:`InputError`."""

from __future__ import annotations

from typing import TYPE_CHECKING

from relaxgrip.errors import InputError

if TYPE_CHECKING:
    from relaxgrip.hardware.protocol.codec import FrameError

__all__ = [
    "DependencyNotInstalledError",
    "FrameDecodeError",
    "LinkCorruptedError",
    "LinkError",
    "LinkTimeoutError",
    "McuFaultError",
    "McuRejectedError",
    "ProtocolError",
    "VersionMismatchError",
]


class ProtocolError(InputError):
    """Something on the MCU link broke the protocol (bytes, versions, replies)."""


class FrameDecodeError(ProtocolError):
    """A frame could not be decoded; ``error`` holds the typed details."""

    def __init__(self, error: FrameError) -> None:
        super().__init__(str(error))
        self.error = error


class VersionMismatchError(ProtocolError):
    """Host and MCU speak different protocol versions."""

    def __init__(self, host_version: int, mcu_version: int) -> None:
        super().__init__(
            f"MCU speaks protocol version {mcu_version}, this host speaks version "
            f"{host_version}: flash matching firmware or install a matching relaxgrip"
        )
        self.host_version = host_version
        self.mcu_version = mcu_version


class LinkError(ProtocolError):
    """The link to the MCU is dead, corrupted or out of step."""


class LinkTimeoutError(LinkError):
    """No valid reply arrived in time."""


class LinkCorruptedError(LinkError):
    """No valid reply arrived in time, and corrupted frames did."""


class McuRejectedError(ProtocolError):
    """The MCU answered a frame with an Error reply; ``code`` is its error code."""

    def __init__(self, message: str, code: int | None = None) -> None:
        super().__init__(message)
        self.code = code


class McuFaultError(McuRejectedError):
    """The MCU refused a command because a fault (e.g. its watchdog) stopped its outputs."""


class DependencyNotInstalledError(ImportError):
    """An optional dependency (an extra of relaxgrip) is missing."""
