"""The host <-> MCU protocol, in layers (see ``docs/protocol.md``).

- :mod:`~relaxgrip.hardware.protocol.codec`: bytes <-> message dataclasses, pure.
- :mod:`~relaxgrip.hardware.protocol.transport`: in-memory, file-descriptor
  and serial byte transports.
- :mod:`~relaxgrip.hardware.protocol.client`: :class:`McuClient`, the host side.
- :mod:`~relaxgrip.hardware.protocol.mcu`: :class:`McuCore`, the MCU side as a
  pure state machine, and :class:`McuEndpoint` wiring it to a transport.

Importing this package does not import pyserial.
"""

from relaxgrip.hardware.protocol.client import LinkStats, McuClient
from relaxgrip.hardware.protocol.codec import (
    PROTOCOL_VERSION,
    Command,
    ErrorCode,
    ErrorReply,
    FaultFlag,
    FrameDecoder,
    FrameError,
    GetStatus,
    Hello,
    HelloAck,
    Message,
    MsgType,
    Packet,
    SetEnable,
    SetHeaterDuty,
    SetMotorVelocity,
    SetWatchdog,
    StateFlag,
    Status,
    decode_frame,
    encode_frame,
)
from relaxgrip.hardware.protocol.errors import (
    DependencyNotInstalledError,
    FrameDecodeError,
    LinkCorruptedError,
    LinkError,
    LinkTimeoutError,
    McuFaultError,
    McuRejectedError,
    ProtocolError,
    VersionMismatchError,
)
from relaxgrip.hardware.protocol.mcu import (
    AppliedOutputs,
    IdealMotorPlant,
    McuConfig,
    McuCore,
    McuEndpoint,
    Plant,
)
from relaxgrip.hardware.protocol.transport import (
    FdTransport,
    MemoryLink,
    MemoryTransport,
    SerialTransport,
    Transport,
)

__all__ = [
    "PROTOCOL_VERSION",
    "AppliedOutputs",
    "Command",
    "DependencyNotInstalledError",
    "ErrorCode",
    "ErrorReply",
    "FaultFlag",
    "FdTransport",
    "FrameDecodeError",
    "FrameDecoder",
    "FrameError",
    "GetStatus",
    "Hello",
    "HelloAck",
    "IdealMotorPlant",
    "LinkCorruptedError",
    "LinkError",
    "LinkStats",
    "LinkTimeoutError",
    "McuClient",
    "McuConfig",
    "McuCore",
    "McuEndpoint",
    "McuFaultError",
    "McuRejectedError",
    "MemoryLink",
    "MemoryTransport",
    "Message",
    "MsgType",
    "Packet",
    "Plant",
    "ProtocolError",
    "SerialTransport",
    "SetEnable",
    "SetHeaterDuty",
    "SetMotorVelocity",
    "SetWatchdog",
    "StateFlag",
    "Status",
    "Transport",
    "VersionMismatchError",
    "decode_frame",
    "encode_frame",
]
