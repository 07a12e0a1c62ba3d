//! The hand-worked wire tables of [`crate::xy3::vectors`] (bits written out from §5.1 /
//! §5.1.1, shared with the on-target runner) and bad input.

use crate::model::{self, Axis, ForwardFrame, Position};
use crate::xy3::neutral::{apply, command_frame, position_frame, to_neutral, Applied};
use crate::xy3::vectors::{
    COMMANDS, COMMAND_24, COMMAND_32, POSITION_24, POSITION_32, UNKNOWN, XY, XYZUW,
};
use crate::xy3::*;

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

#[test]
fn command_table() {
    for &(cmd, code) in COMMANDS {
        assert_eq!(cmd.code(), code, "{cmd:?}");
        assert_eq!(Command::from_code(code), Ok(cmd), "{code:#x}");
    }
}

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
