//! `xy3` forward frames on the target: the shared hand-worked wire and command tables
//! (`shared::xy3::vectors`) both ways, random round trips, every single-bit error of
//! random 24- and 32-bit frames, and garbage words.

use super::prng::Prng;
use super::Case;
use shared::xy3::vectors::{COMMANDS, COMMAND_24, COMMAND_32, POSITION_24, POSITION_32, UNKNOWN};
use shared::xy3::{decode, encode, Command, DecodeError, Frame, FrameSize};

/// This module's cases.
pub const CASES: &[Case] = &[
    Case {
        name: "xy3::frame_tables",
        run: frame_tables,
    },
    Case {
        name: "xy3::command_tables",
        run: command_tables,
    },
    Case {
        name: "xy3::round_trip_random",
        run: round_trip_random,
    },
    Case {
        name: "xy3::single_bit_errors_random",
        run: single_bit_errors_random,
    },
    Case {
        name: "xy3::garbage_words_random",
        run: garbage_words_random,
    },
];

/// Random values per randomised case.
const ROUNDS: u32 = 4000;
/// Random frames per frame size whose every bit is flipped.
const FLIP_FRAMES: u32 = 400;

/// One row: the binary and hex spellings agree, encode gives the word and size,
/// decode gives the frame, the first bit announces the size.
fn check_row(frame: Frame, bin: u32, hex: u32, size: FrameSize) {
    assert_eq!(bin, hex, "table typo in row {frame:?}");
    assert_eq!(encode(&frame), Ok((hex, size)), "encode {frame:?}");
    assert_eq!(decode(hex, size), Ok(frame), "decode {hex:#x}");
    let first_bit = hex >> (size.bits() - 1) & 1 == 1;
    assert_eq!(FrameSize::from_first_bit(first_bit), size);
}

fn frame_tables() {
    for &(v, bin, hex) in POSITION_24 {
        check_row(Frame::Position24(v), bin, hex, FrameSize::Bits24);
    }
    for &(v, bin, hex) in POSITION_32 {
        check_row(Frame::Position32(v), bin, hex, FrameSize::Bits32);
    }
    for &(c, bin, hex) in COMMAND_24 {
        check_row(Frame::Command24(c), bin, hex, FrameSize::Bits24);
    }
    for &(code, unused, bin, hex) in COMMAND_32 {
        check_row(
            Frame::Command32 { code, unused },
            bin,
            hex,
            FrameSize::Bits32,
        );
    }
}

fn command_tables() {
    for &(cmd, code) in COMMANDS {
        assert_eq!(cmd.code(), code, "{cmd:?}");
        assert_eq!(Command::from_code(code), Ok(cmd), "{code:#x}");
    }
    for &code in UNKNOWN {
        assert_eq!(Command::from_code(code), Ok(Command::Unknown(code)));
        let frame = Frame::Command24(code);
        let (word, size) = encode(&frame).unwrap();
        assert_eq!(decode(word, size), Ok(frame));
    }
}

/// A random frame of any kind and size.
fn random_frame(rng: &mut Prng) -> Frame {
    match rng.next_u32() % 4 {
        0 => Frame::Position24(rng.bits(20)),
        1 => Frame::Position32(rng.bits(26)),
        2 => Frame::Command24(rng.bits(20)),
        // Truncation intended: 6 random bits.
        _ => Frame::Command32 {
            code: rng.bits(20),
            unused: rng.bits(6) as u8,
        },
    }
}

/// The same frame with the kind bit flipped, as a receiver would accept it.
fn other_kind(f: Frame) -> Frame {
    match f {
        Frame::Position24(v) => Frame::Command24(v),
        Frame::Command24(c) => Frame::Position24(c),
        // Truncation intended: bits 25..20 of the position are the unused bits.
        Frame::Position32(v) => Frame::Command32 {
            code: v & 0xF_FFFF,
            unused: (v >> 20) as u8,
        },
        Frame::Command32 { code, unused } => Frame::Position32(u32::from(unused) << 20 | code),
    }
}

/// Frames and command codes survive encode and decode.
fn round_trip_random() {
    let mut rng = Prng::new(0x0003_0001);
    for _ in 0..ROUNDS {
        let f = random_frame(&mut rng);
        let (word, size) = encode(&f).unwrap();
        assert_eq!(size, f.size());
        assert!(size.bits() == 32 || word >> size.bits() == 0, "{word:#x}");
        let first_bit = word >> (size.bits() - 1) & 1 == 1;
        assert_eq!(FrameSize::from_first_bit(first_bit), size);
        assert_eq!(decode(word, size), Ok(f), "{word:#x}");
        let code = rng.bits(20);
        assert_eq!(Command::from_code(code).map(Command::code), Ok(code));
    }
}

/// Every flip is caught except the kind bit's, which the protocol cannot see: bits
/// above a 24-bit frame by the width check, the first bit by the framing, the kind
/// bit gives the other kind, every other bit breaks the parity.
fn single_bit_errors_random() {
    let mut rng = Prng::new(0x0003_0002);
    for size in [FrameSize::Bits24, FrameSize::Bits32] {
        let mut n = 0;
        while n < FLIP_FRAMES {
            let f = random_frame(&mut rng);
            if f.size() != size {
                continue;
            }
            n += 1;
            let (word, _) = encode(&f).unwrap();
            let top = u32::from(size.bits()) - 1;
            for bit in 0..32 {
                let got = decode(word ^ 1 << bit, size);
                let ok = if bit > top {
                    matches!(got, Err(DecodeError::WordTooWide { .. }))
                } else if bit == top {
                    matches!(got, Err(DecodeError::SizeMismatch { .. }))
                } else if bit == top - 1 {
                    got == Ok(other_kind(f))
                } else {
                    matches!(got, Err(DecodeError::Parity { .. }))
                };
                assert!(ok, "bit {bit} of {word:#x} gave {got:?}");
            }
        }
    }
}

/// Any accepted random word re-encodes identically (nothing is accepted "nearly").
fn garbage_words_random() {
    let mut rng = Prng::new(0x0003_0003);
    let mut accepted = 0u32;
    for _ in 0..ROUNDS {
        let word = rng.next_u32();
        for size in [FrameSize::Bits24, FrameSize::Bits32] {
            // Also the 24-bit window of the same word, which is mostly in range.
            for w in [word, word & 0xFF_FFFF] {
                if let Ok(f) = decode(w, size) {
                    assert_eq!(encode(&f), Ok((w, size)), "{w:#x}");
                    accepted += 1;
                }
            }
        }
    }
    // About a quarter (24-bit) or a sixteenth (32-bit) of the in-range words pass
    // the parity: the check above must have run.
    assert!(accepted > ROUNDS / 8, "{accepted}");
}
