//! Hand-worked XY3-100 backchannel wire vectors (XY3-100 §5.2, little-endian per
//! erratum 6): packets with their bytes, and hand-built streams with the parser
//! events they must give. Shared by this module's host unit tests and the on-target
//! runner (`cm7`, built with the `vectors` feature) so both check the same rows. Not
//! part of the API: only compiled for tests or with `vectors`.
//!
//! The helpers panic on a row that does not fit its bounded vector: a broken table is
//! a broken test, never data.

use super::{LostSyncReason, Packet, RawPayload, Stats};
use crate::model::{Text, COMPONENTS};
use heapless::Vec;

/// A text payload.
pub fn txt(b: &[u8]) -> Text {
    Text::from_slice(b).expect("table text fits")
}

/// A temperature array.
pub fn temps(v: &[Option<i16>]) -> Vec<Option<i16>, COMPONENTS> {
    Vec::from_slice(v).expect("table temperatures fit")
}

/// A working-hours array.
pub fn hours(v: &[Option<u32>]) -> Vec<Option<u32>, COMPONENTS> {
    Vec::from_slice(v).expect("table hours fit")
}

/// An error-state array.
pub fn errors(v: &[u8]) -> Vec<u8, COMPONENTS> {
    Vec::from_slice(v).expect("table error codes fit")
}

/// A packet of an unknown type.
pub fn unknown(ty: u8, p: &[u8]) -> Packet {
    Packet::Unknown {
        ty,
        payload: RawPayload::from_slice(p).expect("table payload fits"),
    }
}

/// Number of rows of [`packet_rows`].
pub const PACKET_ROWS: usize = 27;

/// Every packet type, with its bytes on the wire (head, type, length, payload).
#[rustfmt::skip]
pub fn packet_rows() -> [(Packet, &'static [u8]); PACKET_ROWS] {
    [
        (Packet::Sync,                          &[0x48, 0x41, 0x00]),
        (Packet::Vendor(txt(b"abc")),           &[0x48, 0x01, 0x03, 0x61, 0x62, 0x63]),
        (Packet::Vendor(txt(&[0x00, 0x7F, 0x20])), &[0x48, 0x01, 0x03, 0x00, 0x7F, 0x20]),
        (Packet::Model(txt(b"XY3")),            &[0x48, 0x02, 0x03, 0x58, 0x59, 0x33]),
        (Packet::Model(txt(b"H-1")),            &[0x48, 0x02, 0x03, 0x48, 0x2D, 0x31]),
        (Packet::Firmware(txt(b"1.0.2")),       &[0x48, 0x03, 0x05, 0x31, 0x2E, 0x30, 0x2E, 0x32]),
        (Packet::Firmware(txt(b"v~~")),         &[0x48, 0x03, 0x03, 0x76, 0x7E, 0x7E]),
        (Packet::Serial(txt(b"SN-0001")),       &[0x48, 0x04, 0x07, 0x53, 0x4E, 0x2D, 0x30, 0x30, 0x30, 0x31]),
        (Packet::Serial(txt(b"000")),           &[0x48, 0x04, 0x03, 0x30, 0x30, 0x30]),
        (Packet::Debug(txt(&[0xFF, 0x80, 0x00])), &[0x48, 0x08, 0x03, 0xFF, 0x80, 0x00]),
        (Packet::Debug(txt(b"dbg!")),           &[0x48, 0x08, 0x04, 0x64, 0x62, 0x67, 0x21]),
        (Packet::Debug(txt(&[0x48, 0x41, 0x00])), &[0x48, 0x08, 0x03, 0x48, 0x41, 0x00]),
        // TEMPERATURES: i16 LE; -32767 = 0x8001 is "not supported".
        (Packet::Temperatures(temps(&[Some(0)])),   &[0x48, 0x05, 0x02, 0x00, 0x00]),
        (Packet::Temperatures(temps(&[None])),      &[0x48, 0x05, 0x02, 0x01, 0x80]),
        (Packet::Temperatures(temps(&[Some(i16::MAX), Some(-1), Some(2550), Some(i16::MIN), Some(-32766)])),
            &[0x48, 0x05, 0x0A, 0xFF, 0x7F, 0xFF, 0xFF, 0xF6, 0x09, 0x00, 0x80, 0x02, 0x80]),
        // FRAME_ERROR_COUNT: 5 x u32 LE.
        (Packet::FrameErrorCount([0, 1, 0x1234_5678, u32::MAX, 256]),
            &[0x48, 0x06, 0x14, 0x00, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x78, 0x56, 0x34, 0x12,
              0xFF, 0xFF, 0xFF, 0xFF, 0x00, 0x01, 0x00, 0x00]),
        (Packet::FrameErrorCount([0; 5]),
            &[0x48, 0x06, 0x14, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
        (Packet::FrameErrorCount([u32::MAX; 5]),
            &[0x48, 0x06, 0x14, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF,
              0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF]),
        // ERROR_STATE: raw bytes, 1..=22.
        (Packet::ErrorState(errors(&[0])), &[0x48, 0x07, 0x01, 0x00]),
        (Packet::ErrorState(errors(&[1, 2, 3, 4, 5, 6, 7, 8, 99, 100, 255])),
            &[0x48, 0x07, 0x0B, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0x63, 0x64, 0xFF]),
        (Packet::ErrorState(errors(&[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21])),
            &[0x48, 0x07, 0x16, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0x09, 0x0A, 0x0B,
              0x0C, 0x0D, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x13, 0x14, 0x15]),
        // WORKING_HOURS: u32 LE; 0xFFFF_FFFF is "not supported".
        (Packet::WorkingHours(hours(&[Some(0)])), &[0x48, 0x09, 0x04, 0x00, 0x00, 0x00, 0x00]),
        (Packet::WorkingHours(hours(&[None])),    &[0x48, 0x09, 0x04, 0xFF, 0xFF, 0xFF, 0xFF]),
        (Packet::WorkingHours(hours(&[Some(1), None, Some(0xFFFF_FFFE), Some(100_000)])),
            &[0x48, 0x09, 0x10, 0x01, 0x00, 0x00, 0x00, 0xFF, 0xFF, 0xFF, 0xFF, 0xFE, 0xFF, 0xFF, 0xFF,
              0xA0, 0x86, 0x01, 0x00]),
        // Unknown types keep their bytes.
        (unknown(0x42, &[]),                 &[0x48, 0x42, 0x00]),
        (unknown(0x00, &[0x48]),             &[0x48, 0x00, 0x01, 0x48]),
        (unknown(0xFF, &[0x01, 0x02, 0x03]), &[0x48, 0xFF, 0x03, 0x01, 0x02, 0x03]),
    ]
}

/// An event the parser must produce, with `'static` data so it fits a table.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Expected {
    /// [`super::Event::Packet`] with this type and payload.
    Packet(u8, &'static [u8]),
    /// [`super::Event::Resynced`] with this many dropped bytes.
    Resynced(u32),
    /// [`super::Event::LostSync`] for this reason.
    LostSync(LostSyncReason),
}

/// A stream in sync from its first byte, to be cut at every pair of chunk
/// boundaries: the events must not depend on the cuts.
#[rustfmt::skip]
pub const SPLIT_STREAM: &[u8] = &[
    0x48, 0x41, 0x00,                                   // SYNC
    0x48, 0x01, 0x03, 0x61, 0x62, 0x63,                 // VENDOR "abc"
    0x48, 0x05, 0x04, 0x01, 0x80, 0xF6, 0x09,           // TEMPERATURES [None, 25.50]
    0x48, 0x41, 0x00,                                   // SYNC
    0x48, 0x09, 0x04, 0x00, 0x00, 0x00, 0x00,           // WORKING_HOURS [0]
];

/// The events of [`SPLIT_STREAM`]: the first SYNC only resynchronises, the second
/// is a packet.
pub const SPLIT_EVENTS: &[Expected] = &[
    Expected::Resynced(0),
    Expected::Packet(0x01, b"abc"),
    Expected::Packet(0x05, &[0x01, 0x80, 0xF6, 0x09]),
    Expected::Packet(0x41, &[]),
    Expected::Packet(0x09, &[0, 0, 0, 0]),
];

/// Garbage and a near miss before the first sync sequence.
#[rustfmt::skip]
pub const GARBAGE_STREAM: &[u8] = &[
    0x00, 0xFF, 0x41, 0x00,             // 4 bytes of garbage
    0x48, 0x41, 0x01,                   // a near miss: 3 more dropped
    0x48, 0x41, 0x00, 0x48,             // the sync sequence
    0x01, 0x03, 0x61, 0x62, 0x63,       // VENDOR "abc", head was above
];

/// The events of [`GARBAGE_STREAM`].
pub const GARBAGE_EVENTS: &[Expected] = &[Expected::Resynced(7), Expected::Packet(0x01, b"abc")];

/// The parser's totals after [`GARBAGE_STREAM`].
pub const GARBAGE_STATS: Stats = Stats {
    packets: 1,
    resyncs: 1,
    lost_sync: 0,
    dropped_bytes: 7,
};

/// In sync, then two known types with lengths their rules forbid.
#[rustfmt::skip]
pub const BAD_LENGTH_STREAM: &[u8] = &[
    0x48, 0x41, 0x00,
    0x48, 0x07, 0x17, 0x00, 0x00,        // ERROR_STATE with 23 bytes: bad
    0x48, 0x07, 0x01, 0x01,              // valid, but out of sync: dropped
    0x48, 0x41, 0x00, 0x48,              // resync
    0x05, 0x03, 0x00, 0x00, 0x00,        // TEMPERATURES odd length: bad
];

/// The events of [`BAD_LENGTH_STREAM`].
pub const BAD_LENGTH_EVENTS: &[Expected] = &[
    Expected::Resynced(0),
    Expected::LostSync(LostSyncReason::BadLength {
        ty: 0x07,
        len: 0x17,
    }),
    // head + type, the length byte, 2 zeros, then 4 bytes of the packet
    Expected::Resynced(2 + 1 + 2 + 4),
    Expected::LostSync(LostSyncReason::BadLength {
        ty: 0x05,
        len: 0x03,
    }),
];

/// The parser's totals after [`BAD_LENGTH_STREAM`]: 9 bytes dropped before the
/// resync, then head + type + length + three zeros.
pub const BAD_LENGTH_STATS: Stats = Stats {
    packets: 0,
    resyncs: 2,
    lost_sync: 2,
    dropped_bytes: 9 + 6,
};
