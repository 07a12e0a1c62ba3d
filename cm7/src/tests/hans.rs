//! `hans` on the target: the shared hand-worked line patterns, byte forms, ring slot
//! and extension-code tables (`shared::hans::vectors`) both ways, random round trips,
//! every single-bit error of random frames (located), and `write_slot` / `read_slot`
//! keeping the neighbours' bits.

use super::prng::Prng;
use super::Case;
use shared::hans::vectors::{bits, BIT_PATTERNS, BYTES, DEVICE, FORWARD, GALVO, PATTERNS, SLOT1};
use shared::hans::{
    read_slot, write_slot, ControllerExt, DecodeError, DeviceExt, Frame, GalvoStatus, FRAME_BITS,
    RING_BYTES, RING_SLOTS,
};

/// This module's cases.
pub const CASES: &[Case] = &[
    Case {
        name: "hans::pattern_tables",
        run: pattern_tables,
    },
    Case {
        name: "hans::slot_table",
        run: slot_table,
    },
    Case {
        name: "hans::ext_tables",
        run: ext_tables,
    },
    Case {
        name: "hans::round_trip_random",
        run: round_trip_random,
    },
    Case {
        name: "hans::single_bit_errors_random",
        run: single_bit_errors_random,
    },
    Case {
        name: "hans::slots_keep_neighbours_random",
        run: slots_keep_neighbours_random,
    },
];

/// Random values per round-trip case.
const ROUNDS: u32 = 3000;
/// Random frames whose every one of the 125 line bits is flipped.
const FLIP_FRAMES: u32 = 300;
/// Random ring writes checked bit by bit.
const SLOT_WRITES: u32 = 300;

fn frame(d1: u32, d2: u32, d3: u32) -> Frame {
    Frame::new(d1, d2, d3).unwrap()
}

fn pattern_tables() {
    for &((d1, d2, d3), want) in PATTERNS {
        let f = frame(d1, d2, d3);
        assert_eq!(f.encode(), want, "encode {f:?}");
        assert_eq!(Frame::decode(want), Ok(f));
    }
    for &((d1, d2, d3), s) in BIT_PATTERNS {
        let f = frame(d1, d2, d3);
        assert_eq!(f.encode(), bits(s), "encode {f:?}");
        assert_eq!(Frame::decode(bits(s)), Ok(f));
    }
    for &((d1, d2, d3), want) in BYTES {
        let f = frame(d1, d2, d3);
        assert_eq!(f.to_bytes(), want);
        assert_eq!(Frame::from_bytes(&want), Ok(f));
    }
}

fn slot_table() {
    for &(fill, (d1, d2, d3), changed) in SLOT1 {
        let f = frame(d1, d2, d3);
        let mut buf = [fill; RING_BYTES];
        write_slot(&mut buf, 1, &f).unwrap();
        let mut want = [fill; RING_BYTES];
        for &(i, v) in changed {
            want[i] = v;
        }
        assert_eq!(buf, want);
        assert_eq!(read_slot(&buf, 1), Ok(f));
    }
}

fn ext_tables() {
    for &(ext, word) in FORWARD {
        assert_eq!(ext.to_data3(), Ok(word), "{ext:?}");
        assert_eq!(ControllerExt::from_data3(word), Ok(ext), "{word:#x}");
    }
    for &(ext, word) in DEVICE {
        assert_eq!(ext.to_data3(), Ok(word), "{ext:?}");
        assert_eq!(DeviceExt::from_data3(word), Ok(ext), "{word:#x}");
    }
    for &(st, words) in GALVO {
        assert_eq!(st.to_words(), Ok(words), "{st:?}");
        assert_eq!(GalvoStatus::from_words(words.0, words.1), Ok(st));
    }
}

fn random_frame(rng: &mut Prng) -> Frame {
    frame(rng.bits(20), rng.bits(20), rng.bits(20))
}

/// Frames through the pattern and the byte form; DATA3 and the status words
/// through their extension codes.
fn round_trip_random() {
    let mut rng = Prng::new(0x0004_0001);
    for _ in 0..ROUNDS {
        let f = random_frame(&mut rng);
        let p = f.encode();
        assert_eq!(p >> FRAME_BITS, 0, "{f:?}");
        assert_eq!(Frame::decode(p), Ok(f));
        assert_eq!(Frame::from_bytes(&f.to_bytes()), Ok(f));
        let [w1, w2, w3] = f.words();
        let forward = ControllerExt::from_data3(w3).unwrap();
        assert_eq!(forward.to_data3(), Ok(w3));
        assert_eq!(ControllerExt::from_frame(&f), forward);
        let device = DeviceExt::from_data3(w3).unwrap();
        assert_eq!(device.to_data3(), Ok(w3));
        let galvo = GalvoStatus::from_words(w1, w2).unwrap();
        assert_eq!(galvo.to_words(), Ok((w1, w2)));
    }
}

/// The error a flipped line bit `t` (0 = first on the line) must give: the first
/// failing check in line order, at the right place.
fn expected_error(t: usize, pattern: u128) -> DecodeError {
    let flipped = pattern ^ 1 << (124 - t);
    // Truncations intended: 2- and 3-bit fields, word 1..=3, bit 0..=19.
    match t {
        0 | 1 => DecodeError::StartPair {
            got: (flipped >> 123) as u8 & 0b11,
        },
        2..=121 => DecodeError::Complement {
            word: ((t - 2) / 40 + 1) as u8,
            bit: (19 - (t - 2) % 40 / 2) as u8,
        },
        _ => DecodeError::StopBits {
            got: flipped as u8 & 0b111,
        },
    }
}

fn single_bit_errors_random() {
    let mut rng = Prng::new(0x0004_0002);
    for _ in 0..FLIP_FRAMES {
        let p = random_frame(&mut rng).encode();
        for t in 0..FRAME_BITS {
            assert_eq!(
                Frame::decode(p ^ 1 << (124 - t)),
                Err(expected_error(t, p)),
                "line bit {t} of {p:#034x}"
            );
        }
    }
}

/// Stream bit `bit` (bit 7 of byte 0 first).
fn bit_at(buf: &[u8], bit: usize) -> u8 {
    buf[bit / 8] >> (7 - bit % 8) & 1
}

/// A random slot of a random ring: exactly that slot's 125 bits change, to the
/// frame's pattern, and it reads back; then a full ring written in scrambled order
/// reads back slot by slot, and every misaligned window is rejected.
fn slots_keep_neighbours_random() {
    let mut rng = Prng::new(0x0004_0003);
    for _ in 0..SLOT_WRITES {
        let mut ring = [0u8; RING_BYTES];
        // Truncation intended: random bytes.
        ring.iter_mut().for_each(|b| *b = rng.next_u32() as u8);
        let before = ring;
        let slot = (rng.next_u32() as usize) % RING_SLOTS;
        let f = random_frame(&mut rng);
        write_slot(&mut ring, slot, &f).unwrap();
        let (start, p) = (slot * FRAME_BITS, f.encode());
        for bit in 0..RING_BYTES * 8 {
            if (start..start + FRAME_BITS).contains(&bit) {
                let want = (p >> (124 - (bit - start))) as u8 & 1;
                assert_eq!(bit_at(&ring, bit), want, "slot {slot}, bit {bit}");
            } else {
                assert_eq!(bit_at(&ring, bit), bit_at(&before, bit), "neighbour {bit}");
            }
        }
        assert_eq!(read_slot(&ring, slot), Ok(f));
    }
    for _ in 0..8 {
        let mut ring = [0u8; RING_BYTES];
        let frames = [(); RING_SLOTS].map(|_| random_frame(&mut rng));
        for k in [3usize, 0, 7, 1, 6, 2, 5, 4] {
            write_slot(&mut ring, k, &frames[k]).unwrap();
        }
        for (k, f) in frames.iter().enumerate() {
            assert_eq!(read_slot(&ring, k), Ok(*f));
        }
        for off in (1..RING_BYTES * 8 - FRAME_BITS).filter(|o| o % FRAME_BITS != 0) {
            assert!(Frame::read_at(&ring, off).is_err(), "offset {off}");
        }
    }
}
