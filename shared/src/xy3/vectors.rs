//! Hand-worked XY3-100 forward wire tables (bits written out from §5.1 / §5.1.1),
//! shared by this module's host unit tests and the on-target runner (`cm7`, built
//! with the `vectors` feature) so both check the same rows. Not part of the API: only
//! compiled for tests or with `vectors`.

// The binary literals are grouped by frame field (size bit, kind bit, data nibbles,
// parity), not in equal groups: that is what makes them checkable by eye.
#![allow(clippy::unusual_byte_groupings)]

use super::{AxisFlags, BackRate, Command};

// Each row: frame, expected word in binary grouped by field (size, kind, data in
// nibbles, parity), the same word in hex. The test checks both spellings agree, which
// guards the hand work against typos.

/// 24-bit position frames: (value, word in binary, word in hex).
#[rustfmt::skip]
pub const POSITION_24: &[(u32, u32, u32)] = &[
    // value      S K D19..D0                    P       hex       popcount
    (0x0_0000, 0b0_1_0000_0000_0000_0000_0000_00, 0x40_0000), // 0: zero
    (0x8_0000, 0b0_1_1000_0000_0000_0000_0000_01, 0x60_0001), // 1: centre
    (0xF_FFFF, 0b0_1_1111_1111_1111_1111_1111_00, 0x7F_FFFC), // 20 = 0 mod 4: full scale
    (0x0_0007, 0b0_1_0000_0000_0000_0000_0111_11, 0x40_001F), // 3
    (0x0_000F, 0b0_1_0000_0000_0000_0000_1111_00, 0x40_003C), // 4 wraps to 0
    (0x7_FFFF, 0b0_1_0111_1111_1111_1111_1111_11, 0x5F_FFFF), // 19 = 3 mod 4
    (0x0_0005, 0b0_1_0000_0000_0000_0000_0101_10, 0x40_0016), // 2
];

/// 32-bit position frames: (value, word in binary, word in hex).
#[rustfmt::skip]
pub const POSITION_32: &[(u32, u32, u32)] = &[
    // value         S K D25,24 D23..D0                      P3..P0    hex         popcount
    (0x000_0000, 0b1_1_00_0000_0000_0000_0000_0000_0000_0000, 0xC000_0000), // 0: zero
    (0x200_0000, 0b1_1_10_0000_0000_0000_0000_0000_0000_0001, 0xE000_0001), // 1: centre
    (0x3FF_FFFF, 0b1_1_11_1111_1111_1111_1111_1111_1111_1010, 0xFFFF_FFFA), // 26 = 10: full scale
    (0x000_FFFF, 0b1_1_00_0000_0000_1111_1111_1111_1111_0000, 0xC00F_FFF0), // 16 wraps to 0
    (0x000_7FFF, 0b1_1_00_0000_0000_0111_1111_1111_1111_1111, 0xC007_FFFF), // 15
    (0x001_FFFF, 0b1_1_00_0000_0001_1111_1111_1111_1111_0001, 0xC01F_FFF1), // 17 = 1 mod 16
];

/// 24-bit command frames: (code, word in binary, word in hex).
#[rustfmt::skip]
pub const COMMAND_24: &[(u32, u32, u32)] = &[
    // code       S K C19..C0                    P       hex       popcount
    (0x0_0000, 0b0_0_0000_0000_0000_0000_0000_00, 0x00_0000), // 0
    (0x8_0000, 0b0_0_1000_0000_0000_0000_0000_01, 0x20_0001), // 1: AUTOCALIB_ON, all axes
    (0xF_FFFF, 0b0_0_1111_1111_1111_1111_1111_00, 0x3F_FFFC), // 20 = 0 mod 4
    (0x8_801F, 0b0_0_1000_1000_0000_0001_1111_11, 0x22_007F), // 7 = 3 mod 4
    (0xE_0000, 0b0_0_1110_0000_0000_0000_0000_11, 0x38_0003), // 3: BACK_RATE115
];

/// 32-bit command frames: (code, unused bits, word in binary, word in hex).
#[rustfmt::skip]
pub const COMMAND_32: &[(u32, u8, u32, u32)] = &[
    // code     unused    S K x5..x0 C19..C0                  P3..P0    hex        popcount
    (0x0_0000, 0x00, 0b1_0_000000_0000_0000_0000_0000_0000_0000, 0x8000_0000), // 0
    (0x8_0000, 0x00, 0b1_0_000000_1000_0000_0000_0000_0000_0001, 0x8080_0001), // 1
    (0xF_FFFF, 0x00, 0b1_0_000000_1111_1111_1111_1111_1111_0100, 0x80FF_FFF4), // 20 = 4
    (0xF_FFFF, 0x3F, 0b1_0_111111_1111_1111_1111_1111_1111_1010, 0xBFFF_FFFA), // 26 = 10
    (0x0_0000, 0x21, 0b1_0_100001_0000_0000_0000_0000_0000_0010, 0xA100_0002), // 2, x bits only
    (0xD_0000, 0x00, 0b1_0_000000_1101_0000_0000_0000_0000_0011, 0x80D0_0003), // 3: BACK_RATE912
    (0x0_FFFF, 0x00, 0b1_0_000000_0000_1111_1111_1111_1111_0000, 0x800F_FFF0), // 16 wraps to 0
];

/// Axes X and Y.
pub const XY: AxisFlags = AxisFlags::X.union(AxisFlags::Y);
/// Axes U and W.
pub const UW: AxisFlags = AxisFlags::U.union(AxisFlags::W);
/// All five axis flags.
pub const XYZUW: AxisFlags = XY.union(AxisFlags::Z).union(UW);

/// Typed commands and their 20-bit codes (§5.1.1, errata 2 and 3).
#[rustfmt::skip]
pub const COMMANDS: &[(Command, u32)] = &[
    (Command::AutocalibOn(AxisFlags::ALL_AXES),  0x8_0000),
    (Command::AutocalibOn(AxisFlags::X),         0x8_0001),
    (Command::AutocalibOn(XYZUW),                0x8_001F),
    (Command::AutocalibOff(AxisFlags::ALL_AXES), 0x4_0000),
    (Command::AutocalibOff(AxisFlags::Y),        0x4_0002),
    (Command::CalibStart(AxisFlags::ALL_AXES),   0xC_0000),
    (Command::CalibStart(AxisFlags::Z),          0xC_0004),
    (Command::RefStart(AxisFlags::ALL_AXES),     0x2_0000),
    (Command::RefStart(UW),                      0x2_0018),
    (Command::TempCompOn(AxisFlags::ALL_AXES),   0x8_8000),
    (Command::TempCompOn(XY),                    0x8_8003),
    (Command::TempCompOff(AxisFlags::ALL_AXES),  0x4_8000),
    (Command::TempCompOff(AxisFlags::W),         0x4_8010),
    (Command::BackRate(BackRate::B57600),        0xA_0000),
    (Command::BackRate(BackRate::B115200),       0xE_0000),
    (Command::BackRate(BackRate::B230400),       0x1_0000),
    (Command::BackRate(BackRate::B460800),       0x9_0000),
    (Command::BackRate(BackRate::B921600),       0xD_0000),
];

/// Codes without a meaning: they type as [`Command::Unknown`].
#[rustfmt::skip]
pub const UNKNOWN: &[u32] = &[
    0x0_0000, // zero: nothing
    0x8_0020, // AUTOCALIB_ON base with bit 5: not an axis flag
    0x8_003F,
    0x4_8020,
    0xA_0001, // a rate code takes no flags
    0xE_001F,
    0x1_0010,
    0x0_0001,
    0xF_FFFF,
];
