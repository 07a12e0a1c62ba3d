//! Hand-worked HANS-100 wire vectors, shared by this module's host unit tests and the
//! on-target runner (`cm7`, built with the `vectors` feature) so both check the same
//! rows. Not part of the API: only compiled for tests or with `vectors`.
//!
//! Line patterns are worked out by hand from the spec's figure 1 (start `01`, each
//! data bit followed by its complement: 0 -> `01`, 1 -> `10`, stop `111`). Extension
//! words likewise: DATA3 = data << 4 | code; DATA1 = data_high << 4 | code >> 4,
//! DATA2 = data_low << 4 | code & 0xF.

use super::ext::{ControllerExt, DeviceExt, LaserAlarms, ZAlarms};
use super::status::{GalvoAlarms, GalvoStatus};
use crate::model::LaserControl;

use ControllerExt::{Laser, Z};
use LaserControl::*;

/// Parses a hand-written bit string ('0'/'1', anything else ignored) into a pattern,
/// first character = first bit on the line = u128 bit 124.
pub fn bits(s: &str) -> u128 {
    let mut v = 0u128;
    let mut n = 0;
    for c in s.chars() {
        match c {
            '0' => v <<= 1,
            '1' => v = v << 1 | 1,
            _ => continue,
        }
        n += 1;
    }
    assert_eq!(n, 125, "hand-written pattern must have 125 bits");
    v
}

/// DATA1, DATA2, DATA3 of a table row.
pub type Words = (u32, u32, u32);

// Hex of the u128 pattern: 3 zero padding bits on top, then the 125 line bits.
// Zero: 000 + "01" x 61 + 111 -> nibbles 0, A x 30, F.
// Full scale: 000 + 01 + "10" x 60 + 111 -> 0, D, 5 x 29, 7.
// Centre: like zero, but the D19 pair of each word is "10": line bits 3,4 / 43,44 /
// 83,84 (u128 display positions 5,6 / 45,46 / 85,86) -> nibbles 1, 11, 21 become C.
/// Frames and their `u128` line patterns.
#[rustfmt::skip]
pub const PATTERNS: &[(Words, u128)] = &[
    ((0x0_0000, 0x0_0000, 0x0_0000), 0x0AAA_AAAA_AAAA_AAAA_AAAA_AAAA_AAAA_AAAF),
    ((0x8_0000, 0x8_0000, 0x8_0000), 0x0CAA_AAAA_AAAC_AAAA_AAAA_ACAA_AAAA_AAAF),
    ((0xF_FFFF, 0xF_FFFF, 0xF_FFFF), 0x0D55_5555_5555_5555_5555_5555_5555_5557),
];

// The same kind of table written bit by bit (start | DATA1 | DATA2 | DATA3 | stop),
// one nibble (4 pairs) per group.
/// Frames and their line patterns written bit by bit (parse with [`bits`]).
#[rustfmt::skip]
pub const BIT_PATTERNS: &[(Words, &str)] = &[
    ((0x1_2345, 0xA_BCDE, 0x0_F0F7),
     "01 \
      01010110 01011001 01011010 01100101 01100110 \
      10011001 10011010 10100101 10100110 10101001 \
      01010101 10101010 01010101 10101010 01101010 \
      111"),
    ((0xF_FFFF, 0x0_0000, 0x0_0001),
     "01 \
      10101010 10101010 10101010 10101010 10101010 \
      01010101 01010101 01010101 01010101 01010101 \
      01010101 01010101 01010101 01010101 01010110 \
      111"),
    ((0x8_0000, 0x8_0000, 0x8_0000),
     "01 \
      10010101 01010101 01010101 01010101 01010101 \
      10010101 01010101 01010101 01010101 01010101 \
      10010101 01010101 01010101 01010101 01010101 \
      111"),
];

// The 16-byte form: the pattern followed by 3 zero bits.
// Zero: "01" x 60 = 15 x 0x55, then 01 111 000 = 0x78.
// Full: 01 101010 = 0x6A, 14 x 0xAA, then 10 111 000 = 0xB8.
// Centre: like zero but bytes 0, 5, 10 hold a "10" pair at their bits 5..4: 0x65.
/// Frames and their 16-byte form ([`Frame::to_bytes`](super::Frame::to_bytes)).
#[rustfmt::skip]
pub const BYTES: &[(Words, [u8; 16])] = &[
    ((0x0_0000, 0x0_0000, 0x0_0000),
     [0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x78]),
    ((0x8_0000, 0x8_0000, 0x8_0000),
     [0x65, 0x55, 0x55, 0x55, 0x55, 0x65, 0x55, 0x55, 0x55, 0x55, 0x65, 0x55, 0x55, 0x55, 0x55, 0x78]),
    ((0xF_FFFF, 0xF_FFFF, 0xF_FFFF),
     [0x6A, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xB8]),
];

// Slot 1 = stream bits 125..249: it shares byte 15 (its first 3 bits in bits 2..0) with
// slot 0 and byte 31 (its last 2 bits in bits 7..6) with slot 2.
// Zero frame into an all-ones ring: byte 15 = 11111 010 = 0xFA, bytes 16..=29 carry
// line bits 3..114 ("1010...") = 0xAA, byte 30 = bits 115..122 = 1010101 1 = 0xAB,
// byte 31 = 11 + neighbour 111111 = 0xFF.
// Full-scale frame into an all-zero ring: byte 15 = 00000 011 = 0x03, bytes 16..=30 =
// 0x55 (line bits 3..122 alternate 0101..., bit 122 is a stop 1), byte 31 = 11 000000.
/// (byte index, expected value) pairs.
pub type Changed = &'static [(usize, u8)];

/// Frames written into slot 1 of a ring filled with one byte value.
#[rustfmt::skip]
pub const SLOT1: &[(u8, Words, Changed)] = &[
    // (fill, frame, changed bytes (index, value); all others keep the fill)
    (0xFF, (0x0_0000, 0x0_0000, 0x0_0000),
     &[(15, 0xFA), (16, 0xAA), (17, 0xAA), (18, 0xAA), (19, 0xAA), (20, 0xAA), (21, 0xAA),
       (22, 0xAA), (23, 0xAA), (24, 0xAA), (25, 0xAA), (26, 0xAA), (27, 0xAA), (28, 0xAA),
       (29, 0xAA), (30, 0xAB), (31, 0xFF)]),
    (0x00, (0xF_FFFF, 0xF_FFFF, 0xF_FFFF),
     &[(15, 0x03), (16, 0x55), (17, 0x55), (18, 0x55), (19, 0x55), (20, 0x55), (21, 0x55),
       (22, 0x55), (23, 0x55), (24, 0x55), (25, 0x55), (26, 0x55), (27, 0x55), (28, 0x55),
       (29, 0x55), (30, 0x55), (31, 0xC0)]),
];

/// A forward laser power word (code 3).
pub const fn power(
    power: u8,
    mo: bool,
    pa: bool,
    red_pointer: bool,
    reserved: u8,
) -> ControllerExt {
    Laser(Power {
        power,
        mo,
        pa,
        red_pointer,
        reserved,
    })
}

/// Forward DATA3 extension codes and their words.
#[rustfmt::skip]
pub const FORWARD: &[(ControllerExt, u32)] = &[
    (Z(0x0000), 0x0_0000),
    (Z(0x8000), 0x8_0000),
    (Z(0xFFFF), 0xF_FFF0),
    (Laser(RemoteOutputs(0x0000)), 0x0_0001),
    (Laser(RemoteOutputs(0x8001)), 0x8_0011),
    (Laser(RemoteOutputs(0xFFFF)), 0xF_FFF1),
    // D7..D0 power, D8 MO, D9 PA, D10 red pointer, D15..D11 reserved.
    (power(0x00, false, false, false, 0x00), 0x0_0003),
    (power(0x80, true, false, false, 0x00),  0x0_1803), // data 0x0180
    (power(0x12, false, true, true, 0x01),   0x0_E123), // data 0x0800|0x0400|0x0200|0x12
    (power(0xFF, true, true, true, 0x1F),    0xF_FFF3),
    (Laser(QPeriod(0x0000)), 0x0_0004),
    (Laser(QPeriod(0x0032)), 0x0_0324), // 50 counts = 1 us
    (Laser(QPeriod(0xFFFF)), 0xF_FFF4),
    (Laser(StandbyFrequency(0x0000)), 0x0_0005),
    (Laser(StandbyFrequency(0x1234)), 0x1_2345),
    (Laser(StandbyFrequency(0xFFFF)), 0xF_FFF5),
    (Laser(PulseWidthMode(0x0000)), 0x0_0006),
    (Laser(PulseWidthMode(0x8000)), 0x8_0006),
    (Laser(PulseWidthMode(0xFFFF)), 0xF_FFF6),
    (Laser(StandbyPower(0x0000)), 0x0_0009),
    (Laser(StandbyPower(0x8000)), 0x8_0009),
    (Laser(StandbyPower(0xFFFF)), 0xF_FFF9),
    (Laser(Other { code: 2, data: 0x0000 }),  0x0_0002),
    (Laser(Other { code: 7, data: 0x8000 }),  0x8_0007),
    (Laser(Other { code: 8, data: 0x0001 }),  0x0_0018),
    (Laser(Other { code: 10, data: 0xABCD }), 0xA_BCDA),
    (Laser(Other { code: 15, data: 0xFFFF }), 0xF_FFFF),
];

/// A device Z velocity word with its alarms (code 15).
pub const fn z15(
    velocity: u16,
    over_temperature: bool,
    following_error: bool,
    communication: bool,
    power: bool,
) -> DeviceExt {
    DeviceExt::ZVelocity {
        velocity,
        alarms: ZAlarms {
            over_temperature,
            following_error,
            communication,
            power,
        },
    }
}

/// Device (STATUS) DATA3 extension codes and their words.
#[rustfmt::skip]
pub const DEVICE: &[(DeviceExt, u32)] = &[
    (DeviceExt::RemoteInputs(0x0000), 0x0_0002),
    (DeviceExt::RemoteInputs(0x8000), 0x8_0002),
    (DeviceExt::RemoteInputs(0xFFFF), 0xF_FFF2),
    (DeviceExt::PulseWidthMode(0x0000), 0x0_0007),
    (DeviceExt::PulseWidthMode(0x8000), 0x8_0007),
    (DeviceExt::PulseWidthMode(0xFFFF), 0xF_FFF7),
    (DeviceExt::LaserAlarms(LaserAlarms(0x0000)), 0x0_000A),
    (DeviceExt::LaserAlarms(LaserAlarms(0x8001)), 0x8_001A), // emission + power alarm
    (DeviceExt::LaserAlarms(LaserAlarms(0x0204)), 0x0_204A), // communication + temp warning
    (DeviceExt::LaserAlarms(LaserAlarms(0xFFFF)), 0xF_FFFA),
    (DeviceExt::ZActual(0x0000), 0x0_000E),
    (DeviceExt::ZActual(0x8000), 0x8_000E),
    (DeviceExt::ZActual(0xFFFF), 0xF_FFFE),
    // DATA3[19:8] velocity, [7] over-temp, [6] following, [5] comm, [4] power; 0 = alarm.
    (z15(0x000, false, false, false, false), 0x0_00FF), // all normal: 1111
    (z15(0x800, true, true, true, true),     0x8_000F), // all alarms: 0000
    (z15(0xFFF, true, false, false, false),  0xF_FF7F), // 0111
    (z15(0x123, false, false, false, true),  0x1_23EF), // 1110
    (DeviceExt::Raw { code: 0, data: 0x0000 }, 0x0_0000),
    (DeviceExt::Raw { code: 1, data: 0xFFFF }, 0xF_FFF1),
    (DeviceExt::Raw { code: 3, data: 0x8000 }, 0x8_0003),
    (DeviceExt::Raw { code: 9, data: 0x1234 }, 0x1_2349),
];

/// Galvo alarms: nothing active (the reserved level bit at its idle 1).
pub const NORMAL: GalvoAlarms = GalvoAlarms::NONE;
/// Galvo alarms: everything active.
pub const ALL_ACTIVE: GalvoAlarms = GalvoAlarms {
    over_temperature: true,
    following_error: true,
    low_speed_filtered: true,
    power: true,
    temperature_warning: true,
    low_speed: true,
    reserved_level: false,
    communication: true,
};
/// Galvo alarms: over-temperature and low speed.
pub const HOT_AND_SLOW: GalvoAlarms = GalvoAlarms {
    over_temperature: true,
    low_speed: true,
    ..NORMAL
};

/// Galvo status (codes 64, 65 and raw) and their DATA1, DATA2 words.
#[rustfmt::skip]
pub const GALVO: &[(GalvoStatus, (u32, u32))] = &[
    // Code 64 = 0x40: DATA1 nibble 4, DATA2 nibble 0.
    (GalvoStatus::Position { x: 0x0000, y: 0x0000 }, (0x0_0004, 0x0_0000)),
    (GalvoStatus::Position { x: 0x8000, y: 0x8000 }, (0x8_0004, 0x8_0000)),
    (GalvoStatus::Position { x: 0x1234, y: 0xABCD }, (0x1_2344, 0xA_BCD0)),
    (GalvoStatus::Position { x: 0xFFFF, y: 0xFFFF }, (0xF_FFF4, 0xF_FFF0)),
    // Code 65 = 0x41: DATA1 nibble 4, DATA2 nibble 1; flag nibbles 0 = active.
    (GalvoStatus::Velocity { x: 0x000, y: 0x000, alarms: NORMAL },       (0x0_00F4, 0x0_00F1)),
    (GalvoStatus::Velocity { x: 0x800, y: 0x800, alarms: ALL_ACTIVE },   (0x8_0004, 0x8_0001)),
    (GalvoStatus::Velocity { x: 0x123, y: 0xABC, alarms: HOT_AND_SLOW }, (0x1_2374, 0xA_BCB1)),
    (GalvoStatus::Velocity { x: 0xFFF, y: 0xFFF, alarms: NORMAL },       (0xF_FFF4, 0xF_FFF1)),
    (GalvoStatus::Raw { code: 0x00, data: 0x0000_0000 }, (0x0_0000, 0x0_0000)),
    (GalvoStatus::Raw { code: 0x42, data: 0x1234_5678 }, (0x1_2344, 0x5_6782)),
    (GalvoStatus::Raw { code: 0xFF, data: 0xFFFF_FFFF }, (0xF_FFFF, 0xF_FFFF)),
];
