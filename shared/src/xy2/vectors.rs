//! Hand-worked XY2-100 wire tables, shared by this module's host unit tests and the
//! on-target runner (`cm7`, built with the `vectors` feature) so both check the same
//! rows. Not part of the API: only compiled for tests or with `vectors`.
//!
//! Worked by hand: count the ones of header + data; the parity bit makes the count
//! even (16-bit, commands) or odd (18-bit) over the policy's scope (see the module
//! docs of [`crate::xy2`]).

// Wire literals are grouped by field (header_data_parity), not in nibbles: that is
// what makes them checkable by eye against the frame layout.
#![allow(clippy::unusual_byte_groupings)]

/// 16-bit positions: (value, WholeFrame word, DataOnly word).
/// Literals are grouped header_data_parity.
#[rustfmt::skip]
pub const POSITION16: &[(u16, u32, u32)] = &[
    // (value,  WholeFrame word,                   DataOnly word)
    (0x0000, 0b001_0000000000000000_1, 0b001_0000000000000000_0), // 1 one (header)
    (0x8000, 0b001_1000000000000000_0, 0b001_1000000000000000_1), // centre, 2 ones
    (0xFFFF, 0b001_1111111111111111_1, 0b001_1111111111111111_0), // full scale, 17 ones
    (0x1234, 0b001_0001001000110100_0, 0b001_0001001000110100_1), // 5 data ones
    (0x0001, 0b001_0000000000000001_0, 0b001_0000000000000001_1),
];

/// XY2-100E 18-bit positions: (value, WholeFrame word, DataOnly word).
#[rustfmt::skip]
pub const POSITION18: &[(u32, u32, u32)] = &[
    // (value,   WholeFrame word (odd, 20 bits),     DataOnly word (odd, bits 18..0))
    (0x0_0000, 0b1_000000000000000000_0, 0b1_000000000000000000_1), // header one only
    (0x2_0000, 0b1_100000000000000000_1, 0b1_100000000000000000_0), // centre
    (0x3_FFFF, 0b1_111111111111111111_0, 0b1_111111111111111111_1), // full scale
    (0x1_2345, 0b1_010010001101000101_1, 0b1_010010001101000101_0), // 7 data ones
];

/// Enhanced commands: (command, parameter, WholeFrame word, DataOnly word).
/// Literals are grouped header_command_parameter_parity.
#[rustfmt::skip]
pub const COMMANDS: &[(u8, u8, u32, u32)] = &[
    // (command, parameter, WholeFrame word,              DataOnly word)
    (0x00, 0x00, 0b111_00000000_00000000_1, 0b111_00000000_00000000_0),
    (0x80, 0x00, 0b111_10000000_00000000_0, 0b111_10000000_00000000_1),
    (0xFF, 0xFF, 0b111_11111111_11111111_1, 0b111_11111111_11111111_0),
    (0x05, 0x01, 0b111_00000101_00000001_0, 0b111_00000101_00000001_1), // status select
];

/// The flags of a status word: (power OK, temperature OK, ack X, ack Y).
pub type Flags = (bool, bool, bool, bool);

/// Status words. Per byte: bit 7 power, 6 temperature, 4 ack Y, 3 ack X; bits 5, 2,
/// 0 = 1, bit 1 = 0.
#[rustfmt::skip]
pub const STATUS_WORDS: &[(Flags, u16)] = &[
    // ((power, temperature, ack X, ack Y), word)
    ((true,  true,  true,  true ), 0b11111101_11111101), // 0xFDFD, all OK
    ((false, false, false, false), 0b00100101_00100101), // 0x2525, fixed bits only
    ((false, true,  true,  true ), 0b01111101_01111101), // 0x7D7D, supply fault
    ((true,  false, true,  true ), 0b10111101_10111101), // 0xBDBD, temperature
    ((true,  true,  false, true ), 0b11110101_11110101), // 0xF5F5, X not reached
    ((true,  true,  true,  false), 0b11101101_11101101), // 0xEDED, Y not reached
];

/// The STATUS frame: `001` + word + parity (WholeFrame: 20 bits even).
#[rustfmt::skip]
pub const STATUS_FRAMES: &[(u16, u32, u32)] = &[
    // (word, WholeFrame frame,                    DataOnly frame)
    (0xFDFD, 0b001_1111110111111101_1, 0b001_1111110111111101_0), // 14 data ones + header: P = 1
    (0x2525, 0b001_0010010100100101_1, 0b001_0010010100100101_0), // 6 data ones + header: P = 1
    (0x7D7D, 0b001_0111110101111101_1, 0b001_0111110101111101_0), // 12 data ones + header: P = 1
];
