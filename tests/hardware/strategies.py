"""Hypothesis strategies for every protocol message (full wire ranges)."""

from __future__ import annotations

from hypothesis import strategies as st

from relaxgrip.hardware.protocol import codec as c

u8 = st.integers(0, 0xFF)
u16 = st.integers(0, 0xFFFF)
u32 = st.integers(0, 0xFFFF_FFFF)
i32 = st.integers(-(1 << 31), (1 << 31) - 1)
duty_pair = st.tuples(u16, u16)
firmware_id = st.text(
    alphabet=st.characters(min_codepoint=0x20, max_codepoint=0x7E), max_size=c.FIRMWARE_ID_BYTES
)

messages: st.SearchStrategy[c.Message] = st.one_of(
    st.just(c.Hello()),
    st.builds(c.Hello, u8),
    st.just(c.GetStatus()),
    st.builds(c.SetMotorVelocity, i32),
    st.builds(c.SetHeaterDuty, duty_pair),
    st.builds(c.SetEnable, st.booleans()),
    st.builds(c.SetWatchdog, u16),
    st.builds(c.Command, i32, duty_pair),
    st.builds(c.HelloAck, u16, u16, i32, firmware_id),
    st.builds(c.HelloAck, u16, u16, i32, firmware_id, u8, u8, u16),
    st.builds(c.Status, u16, u32, i32, i32, duty_pair, u16, u8, u16, u16),
    st.builds(c.Status, u16, u32, i32, i32, duty_pair, u16, u8, u16, u16, i32, u32, u16),
    st.builds(c.ErrorReply, u16, u8, u8, u16),
)
packets = st.builds(c.Packet, seq=u16, message=messages)
