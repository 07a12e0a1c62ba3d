//! The XY3-100 backchannel: status packets from the scan head over RS485
//! (XY3-100 §5.2; 115200 8N1 unless a rate command changed it, §5.1.1).
//!
//! # Packets
//! Every packet is a head byte `0x48`, a type byte, a length byte and that many
//! payload bytes. Known types and their payload lengths:
//!
//! | type | name | length | payload |
//! |---|---|---|---|
//! | 0x41 | SYNC | 0 | none |
//! | 0x01..=0x04 | VENDOR, MODEL, FIRMWARE, SERIAL | 3..=200 | 7-bit ASCII text |
//! | 0x05 | TEMPERATURES | 2..=44, even | `i16` per component, 1/100 °C, -32767 = not supported |
//! | 0x06 | FRAME_ERROR_COUNT | 20 | `u32` parity-error frames on X, Y, Z, U, W |
//! | 0x07 | ERROR_STATE | 1..=22 | `u8` error code per component ([`ErrorCode`]) |
//! | 0x08 | DEBUG | 3..=200 | anything |
//! | 0x09 | WORKING_HOURS | 4..=88, multiple of 4 | `u32` hours per component, `0xFFFF_FFFF` = not supported |
//!
//! Type 0x03 is printed with the MODEL identifier in the spec; it is its own type
//! (notes, erratum 4). The per-component arrays follow [`Component`] order and may
//! stop early when the last components have nothing to report. Multi-byte fields
//! are little-endian by our decision (erratum 6); the order lives in
//! [`wire::order`] only. Other type bytes are kept as [`Packet::Unknown`].
//!
//! # Synchronisation (receiver, [`Parser`])
//! - The parser starts out of sync and discards bytes until it sees `48 41 00 48`:
//!   a SYNC packet and the head byte of the next packet. That head byte starts the
//!   next packet. The SYNC packet that resynchronised is not reported as a packet;
//!   [`Event::Resynced`] stands for it.
//! - In sync, packets are cut by their length byte. After each packet the next byte
//!   must be `0x48`; anything else loses sync ([`LostSyncReason::MissingHead`]).
//! - A known type whose length breaks its rule (range or element size) loses sync
//!   ([`LostSyncReason::BadLength`]); an unknown type is delivered by its length so
//!   the format can grow.
//! - A packet is reported as soon as its last byte arrives, not when the next head
//!   byte confirms it. A head may go quiet for up to a SYNC interval after a
//!   packet, and an error state must not wait that long. The link has no checksum,
//!   so the confirmation would only catch some framing errors anyway; a missing head
//!   still loses sync for everything after it.
//!
//! # Sending ([`Sender`])
//! A SYNC goes before the first packet, whenever the last one is older than the
//! interval (default 50 ms; the bridge must stay under 100 ms) and before the first
//! packet after a baud-rate change.
//!
//! # Neutral model
//! [`neutral`] maps packets to and from [`crate::model::HeadStatus`]; its module
//! docs hold the mapping tables.

pub mod neutral;
mod packet;
mod parser;
mod sender;
#[cfg(any(test, feature = "vectors"))]
#[doc(hidden)]
pub mod vectors;
pub mod wire;

pub use packet::{
    Component, EncodeError, ErrorCode, Packet, PacketError, RawPayload, HOURS_NOT_SUPPORTED,
    TEMPERATURE_NOT_SUPPORTED,
};
pub use parser::{Event, LostSyncReason, Parser, RawPacket, Stats};
pub use sender::{Sender, SEND_BUF_LEN};

#[cfg(test)]
mod tests_packet;
#[cfg(test)]
mod tests_parser;
#[cfg(test)]
mod tests_sender_neutral;
