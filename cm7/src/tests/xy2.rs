//! `xy2` on the target: the shared hand-worked wire tables (`shared::xy2::vectors`)
//! both ways, random round trips, every single-bit error of random frames under every
//! link setting, and garbage words.

use super::prng::Prng;
use super::Case;
use shared::xy2::vectors::{COMMANDS, POSITION16, POSITION18, STATUS_FRAMES, STATUS_WORDS};
use shared::xy2::{
    decode, encode, DecodeError, Frame, LinkConfig, Mode, Parity, StatusError, StatusWord,
    FRAME_BITS, FRAME_MASK,
};

/// This module's cases.
pub const CASES: &[Case] = &[
    Case {
        name: "xy2::position16_table",
        run: position16_table,
    },
    Case {
        name: "xy2::position18_table",
        run: position18_table,
    },
    Case {
        name: "xy2::command_table",
        run: command_table,
    },
    Case {
        name: "xy2::status_tables",
        run: status_tables,
    },
    Case {
        name: "xy2::round_trip_random",
        run: round_trip_random,
    },
    Case {
        name: "xy2::single_bit_errors_random",
        run: single_bit_errors_random,
    },
    Case {
        name: "xy2::garbage_words_random",
        run: garbage_words_random,
    },
];

/// Random frames per link setting in the round trips.
const ROUNDS: u32 = 1000;
/// Random frames per link setting whose every bit is flipped.
const FLIP_FRAMES: u32 = 300;

const PARITIES: [Parity; 3] = [Parity::WholeFrame, Parity::DataOnly, Parity::Ignore];
const MODES: [Mode; 2] = [Mode::Standard16, Mode::Extended18];

/// Encode and decode of one table row under both checked policies and Ignore
/// (encodes whole-frame parity, decodes either parity bit); each checked policy
/// rejects the other's parity bit.
fn check_row(frame: Frame, mode: Mode, whole: u32, data: u32) {
    let cfg = |parity| LinkConfig { mode, parity };
    assert_eq!(encode(frame, &cfg(Parity::WholeFrame)), Ok(whole));
    assert_eq!(encode(frame, &cfg(Parity::DataOnly)), Ok(data));
    assert_eq!(encode(frame, &cfg(Parity::Ignore)), Ok(whole));
    assert_eq!(decode(whole, &cfg(Parity::WholeFrame)), Ok(frame));
    assert_eq!(decode(data, &cfg(Parity::DataOnly)), Ok(frame));
    assert_eq!(decode(whole, &cfg(Parity::Ignore)), Ok(frame));
    assert_eq!(decode(data, &cfg(Parity::Ignore)), Ok(frame));
    assert_eq!(
        decode(data, &cfg(Parity::WholeFrame)),
        Err(DecodeError::Parity {
            word: data,
            policy: Parity::WholeFrame
        })
    );
    assert_eq!(
        decode(whole, &cfg(Parity::DataOnly)),
        Err(DecodeError::Parity {
            word: whole,
            policy: Parity::DataOnly
        })
    );
}

fn position16_table() {
    for &(v, whole, data) in POSITION16 {
        check_row(Frame::Position16(v), Mode::Standard16, whole, data);
    }
}

fn position18_table() {
    for &(v, whole, data) in POSITION18 {
        check_row(Frame::Position18(v), Mode::Extended18, whole, data);
    }
}

fn command_table() {
    for &(command, parameter, whole, data) in COMMANDS {
        let frame = Frame::Command { command, parameter };
        check_row(frame, Mode::Standard16, whole, data);
    }
}

fn status_tables() {
    for &((power_ok, temperature_ok, position_ack_x, position_ack_y), word) in STATUS_WORDS {
        let s = StatusWord {
            power_ok,
            temperature_ok,
            position_ack_x,
            position_ack_y,
        };
        assert_eq!(s.to_word(), word);
        assert_eq!(StatusWord::from_word(word), Ok(s));
    }
    for &(word, whole, data) in STATUS_FRAMES {
        let s = StatusWord::from_word(word).unwrap();
        for mode in MODES {
            let cfg = |parity| LinkConfig { mode, parity };
            assert_eq!(s.to_frame(&cfg(Parity::WholeFrame)), whole);
            assert_eq!(s.to_frame(&cfg(Parity::DataOnly)), data);
            assert_eq!(s.to_frame(&cfg(Parity::Ignore)), whole);
            assert_eq!(
                StatusWord::from_frame(whole, &cfg(Parity::WholeFrame)),
                Ok(s)
            );
            assert_eq!(StatusWord::from_frame(data, &cfg(Parity::DataOnly)), Ok(s));
            assert_eq!(StatusWord::from_frame(data, &cfg(Parity::Ignore)), Ok(s));
            assert!(matches!(
                StatusWord::from_frame(data, &cfg(Parity::WholeFrame)),
                Err(StatusError::Frame(DecodeError::Parity { .. }))
            ));
            assert!(matches!(
                StatusWord::from_frame(whole, &cfg(Parity::DataOnly)),
                Err(StatusError::Frame(DecodeError::Parity { .. }))
            ));
        }
    }
}

/// A random frame the link's mode can carry.
fn random_frame(rng: &mut Prng, mode: Mode) -> Frame {
    match mode {
        Mode::Extended18 => Frame::Position18(rng.bits(18)),
        Mode::Standard16 => {
            let r = rng.next_u32();
            // Truncations intended: random bytes of `r`.
            if r & 1 == 0 {
                Frame::Position16((r >> 16) as u16)
            } else {
                Frame::Command {
                    command: (r >> 8) as u8,
                    parameter: (r >> 16) as u8,
                }
            }
        }
    }
}

/// Every link setting, in a fixed order.
fn configs() -> impl Iterator<Item = LinkConfig> {
    MODES.into_iter().flat_map(|mode| {
        PARITIES
            .into_iter()
            .map(move |parity| LinkConfig { mode, parity })
    })
}

fn round_trip_random() {
    let mut rng = Prng::new(0x0002_0001);
    for cfg in configs() {
        for _ in 0..ROUNDS {
            let frame = random_frame(&mut rng, cfg.mode);
            let word = encode(frame, &cfg).unwrap();
            assert_eq!(word & !FRAME_MASK, 0, "{frame:?}");
            assert_eq!(decode(word, &cfg), Ok(frame), "{word:#07x} {cfg:?}");
        }
    }
}

/// Under WholeFrame and DataOnly every flip is rejected; under Ignore exactly the
/// flips below the header pass (bit 0 giving the same frame, the others another
/// frame) and header flips are still rejected.
fn single_bit_errors_random() {
    let mut rng = Prng::new(0x0002_0002);
    for cfg in configs() {
        let unchecked = match (cfg.parity, cfg.mode) {
            (Parity::Ignore, Mode::Standard16) => 0x1_FFFF,
            (Parity::Ignore, Mode::Extended18) => 0x7_FFFF,
            _ => 0,
        };
        for _ in 0..FLIP_FRAMES {
            let frame = random_frame(&mut rng, cfg.mode);
            let word = encode(frame, &cfg).unwrap();
            for bit in 0..FRAME_BITS {
                let result = decode(word ^ 1 << bit, &cfg);
                if unchecked & 1 << bit == 0 {
                    assert!(result.is_err(), "bit {bit} of {word:#07x} under {cfg:?}");
                } else if bit == 0 {
                    assert_eq!(result, Ok(frame));
                } else {
                    assert!(result.is_ok() && result != Ok(frame), "bit {bit}");
                }
            }
        }
    }
}

/// Random words (20-bit and wider): wide ones are rejected as such, and an accepted
/// word re-encodes to itself (under Ignore up to the parity bit).
fn garbage_words_random() {
    let mut rng = Prng::new(0x0002_0003);
    for cfg in configs() {
        for _ in 0..ROUNDS {
            let wide = rng.next_u32();
            if wide & !FRAME_MASK != 0 {
                assert_eq!(decode(wide, &cfg), Err(DecodeError::TooWide { word: wide }));
            }
            let word = wide & FRAME_MASK;
            if let Ok(frame) = decode(word, &cfg) {
                let again = encode(frame, &cfg).unwrap();
                if cfg.parity == Parity::Ignore {
                    assert_eq!(again >> 1, word >> 1);
                } else {
                    assert_eq!(again, word);
                }
            }
        }
    }
}
