//! Hand-worked wire tables (bits written out from §5.1 / §5.1.1) and bad input.

// The binary literals are grouped by frame field (size bit, kind bit, data nibbles,
// parity), not in equal groups: that is what makes them checkable by eye.
#![allow(clippy::unusual_byte_groupings)]

use crate::model::{self, Axis, ForwardFrame, Position};
use crate::xy3::neutral::{apply, command_frame, position_frame, to_neutral, Applied};
use crate::xy3::*;

// Each row: frame, expected word in binary grouped by field (size, kind, data in
// nibbles, parity), the same word in hex. The test checks both spellings agree, which
// guards the hand work against typos.

#[rustfmt::skip]
const POSITION_24: &[(u32, u32, u32)] = &[
    // value      S K D19..D0                    P       hex       popcount
    (0x0_0000, 0b0_1_0000_0000_0000_0000_0000_00, 0x40_0000), // 0: zero
    (0x8_0000, 0b0_1_1000_0000_0000_0000_0000_01, 0x60_0001), // 1: centre
    (0xF_FFFF, 0b0_1_1111_1111_1111_1111_1111_00, 0x7F_FFFC), // 20 = 0 mod 4: full scale
    (0x0_0007, 0b0_1_0000_0000_0000_0000_0111_11, 0x40_001F), // 3
    (0x0_000F, 0b0_1_0000_0000_0000_0000_1111_00, 0x40_003C), // 4 wraps to 0
    (0x7_FFFF, 0b0_1_0111_1111_1111_1111_1111_11, 0x5F_FFFF), // 19 = 3 mod 4
    (0x0_0005, 0b0_1_0000_0000_0000_0000_0101_10, 0x40_0016), // 2
];

#[rustfmt::skip]
const POSITION_32: &[(u32, u32, u32)] = &[
    // value         S K D25,24 D23..D0                      P3..P0    hex         popcount
    (0x000_0000, 0b1_1_00_0000_0000_0000_0000_0000_0000_0000, 0xC000_0000), // 0: zero
    (0x200_0000, 0b1_1_10_0000_0000_0000_0000_0000_0000_0001, 0xE000_0001), // 1: centre
    (0x3FF_FFFF, 0b1_1_11_1111_1111_1111_1111_1111_1111_1010, 0xFFFF_FFFA), // 26 = 10: full scale
    (0x000_FFFF, 0b1_1_00_0000_0000_1111_1111_1111_1111_0000, 0xC00F_FFF0), // 16 wraps to 0
    (0x000_7FFF, 0b1_1_00_0000_0000_0111_1111_1111_1111_1111, 0xC007_FFFF), // 15
    (0x001_FFFF, 0b1_1_00_0000_0001_1111_1111_1111_1111_0001, 0xC01F_FFF1), // 17 = 1 mod 16
];

#[rustfmt::skip]
const COMMAND_24: &[(u32, u32, u32)] = &[
    // code       S K C19..C0                    P       hex       popcount
    (0x0_0000, 0b0_0_0000_0000_0000_0000_0000_00, 0x00_0000), // 0
    (0x8_0000, 0b0_0_1000_0000_0000_0000_0000_01, 0x20_0001), // 1: AUTOCALIB_ON, all axes
    (0xF_FFFF, 0b0_0_1111_1111_1111_1111_1111_00, 0x3F_FFFC), // 20 = 0 mod 4
    (0x8_801F, 0b0_0_1000_1000_0000_0001_1111_11, 0x22_007F), // 7 = 3 mod 4
    (0xE_0000, 0b0_0_1110_0000_0000_0000_0000_11, 0x38_0003), // 3: BACK_RATE115
];

#[rustfmt::skip]
const COMMAND_32: &[(u32, u8, u32, u32)] = &[
    // code     unused    S K x5..x0 C19..C0                  P3..P0    hex        popcount
    (0x0_0000, 0x00, 0b1_0_000000_0000_0000_0000_0000_0000_0000, 0x8000_0000), // 0
    (0x8_0000, 0x00, 0b1_0_000000_1000_0000_0000_0000_0000_0001, 0x8080_0001), // 1
    (0xF_FFFF, 0x00, 0b1_0_000000_1111_1111_1111_1111_1111_0100, 0x80FF_FFF4), // 20 = 4
    (0xF_FFFF, 0x3F, 0b1_0_111111_1111_1111_1111_1111_1111_1010, 0xBFFF_FFFA), // 26 = 10
    (0x0_0000, 0x21, 0b1_0_100001_0000_0000_0000_0000_0000_0010, 0xA100_0002), // 2, x bits only
    (0xD_0000, 0x00, 0b1_0_000000_1101_0000_0000_0000_0000_0011, 0x80D0_0003), // 3: BACK_RATE912
    (0x0_FFFF, 0x00, 0b1_0_000000_0000_1111_1111_1111_1111_0000, 0x800F_FFF0), // 16 wraps to 0
];

fn check_row(frame: Frame, bin: u32, hex: u32, size: FrameSize) {
    assert_eq!(bin, hex, "table typo in row {frame:?}");
    assert_eq!(encode(&frame), Ok((hex, size)), "encode {frame:?}");
    assert_eq!(decode(hex, size), Ok(frame), "decode {hex:#x}");
    let first_bit = hex >> (size.bits() - 1) & 1 == 1;
    assert_eq!(FrameSize::from_first_bit(first_bit), size);
}

#[test]
fn position_24_table() {
    for &(v, bin, hex) in POSITION_24 {
        check_row(Frame::Position24(v), bin, hex, FrameSize::Bits24);
    }
}

#[test]
fn position_32_table() {
    for &(v, bin, hex) in POSITION_32 {
        check_row(Frame::Position32(v), bin, hex, FrameSize::Bits32);
    }
}

#[test]
fn command_24_table() {
    for &(c, bin, hex) in COMMAND_24 {
        check_row(Frame::Command24(c), bin, hex, FrameSize::Bits24);
    }
}

#[test]
fn command_32_table() {
    for &(code, unused, bin, hex) in COMMAND_32 {
        check_row(
            Frame::Command32 { code, unused },
            bin,
            hex,
            FrameSize::Bits32,
        );
    }
}

const XY: AxisFlags = AxisFlags::X.union(AxisFlags::Y);
const UW: AxisFlags = AxisFlags::U.union(AxisFlags::W);
const XYZUW: AxisFlags = XY.union(AxisFlags::Z).union(UW);

#[rustfmt::skip]
const COMMANDS: &[(Command, u32)] = &[
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

#[test]
fn command_table() {
    for &(cmd, code) in COMMANDS {
        assert_eq!(cmd.code(), code, "{cmd:?}");
        assert_eq!(Command::from_code(code), Ok(cmd), "{code:#x}");
    }
}

#[rustfmt::skip]
const UNKNOWN: &[u32] = &[
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

#[test]
fn unknown_codes_round_trip() {
    for &code in UNKNOWN {
        let cmd = Command::from_code(code);
        assert_eq!(cmd, Ok(Command::Unknown(code)), "{code:#x}");
        let frame = Frame::Command24(code);
        let (word, size) = encode(&frame).unwrap();
        assert_eq!(decode(word, size), Ok(frame));
    }
}

#[test]
fn codes_wider_than_20_bits_are_rejected() {
    for code in [0x10_0000, 0x18_0000, u32::MAX] {
        assert_eq!(Command::from_code(code), Err(CodeTooWide(code)));
        assert_eq!(
            encode(&Frame::Command24(code)),
            Err(EncodeError::CodeTooWide(code))
        );
        let f = Frame::Command32 { code, unused: 0 };
        assert_eq!(encode(&f), Err(EncodeError::CodeTooWide(code)));
        let neutral = model::Command::Xy3(code);
        assert_eq!(
            command_frame(&neutral, FrameSize::Bits24),
            Err(neutral::CommandFrameError::CodeTooWide(code))
        );
        assert_eq!(to_neutral(&f), Err(EncodeError::CodeTooWide(code)));
    }
    // A hand-built Unknown with a wide value cannot reach the wire.
    let wide = Command::Unknown(0x10_0000);
    assert!(command_frame(&wide.into(), FrameSize::Bits32).is_err());
}

#[test]
fn rates_and_flags() {
    let bauds: [u32; 5] = BackRate::ALL.map(BackRate::baud);
    assert_eq!(bauds, [57_600, 115_200, 230_400, 460_800, 921_600]);
    assert_eq!(BackRate::default(), BackRate::B115200);
    assert_eq!(AxisFlags::from_bits(0x1F), Some(XYZUW));
    assert_eq!(AxisFlags::from_bits(0x20), None);
    assert_eq!(AxisFlags::from_bits(0xFF), None);
    assert_eq!(AxisFlags::of(Axis::U), AxisFlags::U);
    assert!(AxisFlags::ALL_AXES.applies_to(Axis::W));
    assert!(XY.applies_to(Axis::Y));
    assert!(!XY.applies_to(Axis::Z));
}

#[test]
fn encode_rejects_too_wide_fields() {
    let cases = [
        (
            Frame::Position24(0x10_0000),
            EncodeError::PositionTooWide {
                value: 0x10_0000,
                bits: 20,
            },
        ),
        (
            Frame::Position32(0x400_0000),
            EncodeError::PositionTooWide {
                value: 0x400_0000,
                bits: 26,
            },
        ),
        (
            Frame::Command32 {
                code: 0,
                unused: 0x40,
            },
            EncodeError::UnusedTooWide(0x40),
        ),
    ];
    for (frame, err) in cases {
        assert_eq!(encode(&frame), Err(err));
    }
    assert!(to_neutral(&Frame::Position24(0x10_0000)).is_err());
}

#[test]
fn decode_rejects_bad_words() {
    use DecodeError::*;
    use FrameSize::*;
    let cases = [
        // centre with parity 00 instead of 01
        (
            0x60_0000,
            Bits24,
            Parity {
                expected: 1,
                got: 0,
            },
        ),
        // value 7 with parity 00 instead of 11
        (
            0x40_001C,
            Bits24,
            Parity {
                expected: 3,
                got: 0,
            },
        ),
        // 32-bit full scale with parity 1111 instead of 1010
        (
            0xFFFF_FFFF,
            Bits32,
            Parity {
                expected: 0xA,
                got: 0xF,
            },
        ),
        // x bits counted: x = 000001, code 0, parity 0000 instead of 0001
        (
            0x8100_0000,
            Bits32,
            Parity {
                expected: 1,
                got: 0,
            },
        ),
        // first bit says 32 in a 24-bit window, and vice versa
        (
            0xC0_0000,
            Bits24,
            SizeMismatch {
                framed: Bits24,
                announced: Bits32,
            },
        ),
        (
            0x4000_0000,
            Bits32,
            SizeMismatch {
                framed: Bits32,
                announced: Bits24,
            },
        ),
        // bits above a 24-bit frame
        (
            0x100_0000,
            Bits24,
            WordTooWide {
                word: 0x100_0000,
                size: Bits24,
            },
        ),
        (
            0xFF40_0000,
            Bits24,
            WordTooWide {
                word: 0xFF40_0000,
                size: Bits24,
            },
        ),
    ];
    for (word, size, err) in cases {
        assert_eq!(decode(word, size), Err(err), "{word:#x}");
    }
}

#[test]
fn stuck_lines() {
    // Documented blind spot: a line stuck low reads as a valid 24-bit command frame
    // with the unknown code 0.
    assert_eq!(decode(0, FrameSize::Bits24), Ok(Frame::Command24(0)));
    assert_eq!(Command::from_code(0), Ok(Command::Unknown(0)));
    // In a 32-bit window the same line fails the size check; stuck high fails both.
    assert!(matches!(
        decode(0, FrameSize::Bits32),
        Err(DecodeError::SizeMismatch { .. })
    ));
    assert!(matches!(
        decode(0xFF_FFFF, FrameSize::Bits24),
        Err(DecodeError::SizeMismatch { .. })
    ));
    assert!(matches!(
        decode(u32::MAX, FrameSize::Bits32),
        Err(DecodeError::Parity { .. })
    ));
}

#[test]
fn errors_display_their_data() {
    extern crate std;
    use std::string::ToString;
    let e = DecodeError::Parity {
        expected: 1,
        got: 0,
    };
    assert_eq!(e.to_string(), "parity mismatch: expected 0x1, got 0x0");
    let e = DecodeError::SizeMismatch {
        framed: FrameSize::Bits24,
        announced: FrameSize::Bits32,
    };
    assert_eq!(e.to_string(), "received 24 bits but first bit announces 32");
    let e = EncodeError::PositionTooWide {
        value: 0x10_0000,
        bits: 20,
    };
    assert_eq!(e.to_string(), "position 0x100000 does not fit 20 bits");
}

#[test]
fn neutral_conversions() {
    // 16-bit value 0x1234 travels MSB-aligned: << 4 in 24-bit, << 10 in 32-bit frames.
    let p16 = Position::from_raw(0x1234, 16).unwrap();
    assert_eq!(
        position_frame(p16, FrameSize::Bits24),
        Frame::Position24(0x1_2340)
    );
    assert_eq!(
        position_frame(p16, FrameSize::Bits32),
        Frame::Position32(0x48_D000)
    );
    // 26 -> 20 bits (6 bits dropped): 0x1F is below half an LSB and rounds down,
    // 0x20 is exactly half and rounds up, 0x3F rounds up, full scale saturates.
    let p = |v| Position::from_raw(v, 26).unwrap();
    assert_eq!(
        position_frame(p(0x000_003F), FrameSize::Bits24),
        Frame::Position24(1)
    );
    assert_eq!(
        position_frame(p(0x000_001F), FrameSize::Bits24),
        Frame::Position24(0)
    );
    assert_eq!(
        position_frame(p(0x000_0020), FrameSize::Bits24),
        Frame::Position24(1)
    );
    assert_eq!(
        position_frame(p(0x3FF_FFFF), FrameSize::Bits24),
        Frame::Position24(0xF_FFFF)
    );
    assert_eq!(
        to_neutral(&Frame::Position24(0x8_0000)),
        Ok(neutral::Neutral::Position(
            Position::from_raw(0x8_0000, 20).unwrap()
        ))
    );
    assert_eq!(
        to_neutral(&Frame::Command32 {
            code: 0x8_0001,
            unused: 0x3F
        }),
        Ok(neutral::Neutral::Command(model::Command::Xy3(0x8_0001)))
    );
    let xy2 = model::Command::Xy2Enhanced {
        command: 1,
        parameter: 2,
    };
    assert_eq!(
        command_frame(&xy2, FrameSize::Bits24),
        Err(neutral::CommandFrameError::Foreign)
    );
    assert_eq!(
        command_frame(&Command::RefStart(AxisFlags::X).into(), FrameSize::Bits32),
        Ok(Frame::Command32 {
            code: 0x2_0001,
            unused: 0
        })
    );
}

#[test]
fn apply_takes_commands_from_x_only() {
    let mut out = ForwardFrame::default();
    let cmd = Frame::Command24(0x8_0000);
    assert_eq!(apply(&cmd, Axis::Y, &mut out), Ok(Applied::CommandIgnored));
    assert_eq!(out.command, None);
    assert_eq!(apply(&cmd, Axis::X, &mut out), Ok(Applied::Command));
    assert_eq!(out.command, Some(model::Command::Xy3(0x8_0000)));
    assert_eq!(
        apply(&Frame::Position32(0x200_0000), Axis::W, &mut out),
        Ok(Applied::Position)
    );
    assert_eq!(
        out.axis(Axis::W),
        Some(Position::from_raw(0x200_0000, 26).unwrap())
    );
    assert_eq!(out.axis(Axis::X), None);
}
