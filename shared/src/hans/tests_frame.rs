//! Frame <-> pattern tests. The expected patterns (in [`super::vectors`], shared with
//! the on-target runner) are worked out by hand from the spec's figure 1 (start `01`,
//! each data bit followed by its complement: 0 -> `01`, 1 -> `10`, stop `111`).

use super::frame::{read_slot, write_slot, DecodeError, EncodeError, Frame, RING_BYTES};
use super::vectors::{bits, BIT_PATTERNS, BYTES, PATTERNS, SLOT1};
use proptest::prelude::*;
use proptest::strategy::ValueTree;
use proptest::test_runner::TestRunner;

fn frame(d1: u32, d2: u32, d3: u32) -> Frame {
    Frame::new(d1, d2, d3).unwrap()
}

#[test]
fn hex_pattern_table() {
    for &((d1, d2, d3), want) in PATTERNS {
        let f = frame(d1, d2, d3);
        assert_eq!(f.encode(), want, "encode {f:?}: {:#034x}", f.encode());
        assert_eq!(Frame::decode(want), Ok(f));
    }
}

#[test]
fn bit_pattern_table() {
    for &((d1, d2, d3), s) in BIT_PATTERNS {
        let f = frame(d1, d2, d3);
        assert_eq!(f.encode(), bits(s), "encode {f:?}");
        assert_eq!(Frame::decode(bits(s)), Ok(f));
    }
}

#[test]
fn byte_table() {
    for &((d1, d2, d3), want) in BYTES {
        let f = frame(d1, d2, d3);
        assert_eq!(f.to_bytes(), want);
        assert_eq!(Frame::from_bytes(&want), Ok(f));
    }
}

#[test]
fn encoding_checks_widths() {
    let e = |word, value| Err(EncodeError::TooWide { word, value });
    assert_eq!(Frame::new(0x10_0000, 0, 0), e(1, 0x10_0000));
    assert_eq!(Frame::new(0, 0xFFFF_FFFF, 0), e(2, 0xFFFF_FFFF));
    assert_eq!(Frame::new(0, 0, 0x10_0000), e(3, 0x10_0000));
    assert!(Frame::new(0xF_FFFF, 0xF_FFFF, 0xF_FFFF).is_ok());
}

#[test]
fn bad_input_reports_the_failing_check() {
    let zero = 0x0AAA_AAAA_AAAA_AAAA_AAAA_AAAA_AAAA_AAAFu128;
    // Garbage.
    assert_eq!(Frame::decode(0), Err(DecodeError::StartPair { got: 0b00 }));
    assert_eq!(
        Frame::decode(u128::MAX),
        Err(DecodeError::Padding { got: 0b111 })
    );
    assert_eq!(
        Frame::decode(u128::MAX >> 3),
        Err(DecodeError::StartPair { got: 0b11 })
    );
    // Padding above the pattern.
    assert_eq!(
        Frame::decode(zero | 1 << 126),
        Err(DecodeError::Padding { got: 0b010 })
    );
    // First line bit (start 0) flipped.
    assert_eq!(
        Frame::decode(zero ^ 1 << 124),
        Err(DecodeError::StartPair { got: 0b11 })
    );
    // Line bit 2 is DATA1 D19; line bit 5 is the complement of DATA1 D18.
    assert_eq!(
        Frame::decode(zero ^ 1 << (124 - 2)),
        Err(DecodeError::Complement { word: 1, bit: 19 })
    );
    assert_eq!(
        Frame::decode(zero ^ 1 << (124 - 5)),
        Err(DecodeError::Complement { word: 1, bit: 18 })
    );
    // Line bit 42 is DATA2 D19, line bit 121 the complement of DATA3 D0.
    assert_eq!(
        Frame::decode(zero ^ 1 << (124 - 42)),
        Err(DecodeError::Complement { word: 2, bit: 19 })
    );
    assert_eq!(
        Frame::decode(zero ^ 1 << (124 - 121)),
        Err(DecodeError::Complement { word: 3, bit: 0 })
    );
    // Two bad pairs: the first on the line is reported.
    assert_eq!(
        Frame::decode(zero ^ 1 << (124 - 100) ^ 1 << (124 - 60)),
        Err(DecodeError::Complement { word: 2, bit: 10 })
    );
    // Middle stop bit cleared.
    assert_eq!(
        Frame::decode(zero ^ 0b010),
        Err(DecodeError::StopBits { got: 0b101 })
    );
    // Byte input: length and trailing padding.
    let bytes = frame(0, 0, 0).to_bytes();
    assert_eq!(
        Frame::from_bytes(&bytes[..15]),
        Err(DecodeError::Length { got: 15 })
    );
    assert_eq!(
        Frame::from_bytes(&[0; 17]),
        Err(DecodeError::Length { got: 17 })
    );
    assert_eq!(Frame::from_bytes(&[]), Err(DecodeError::Length { got: 0 }));
    let mut padded = bytes;
    padded[15] |= 1;
    assert_eq!(
        Frame::from_bytes(&padded),
        Err(DecodeError::Padding { got: 0b001 })
    );
    // Out-of-range stream positions.
    let buf = [0u8; RING_BYTES];
    assert_eq!(
        read_slot(&buf, 8),
        Err(DecodeError::OutOfBuffer {
            bit_offset: 1000,
            buf_bytes: 125
        })
    );
    assert_eq!(
        Frame::read_at(&buf, 876),
        Err(DecodeError::OutOfBuffer {
            bit_offset: 876,
            buf_bytes: 125
        })
    );
    assert_eq!(
        Frame::read_at(&buf[..15], 0),
        Err(DecodeError::OutOfBuffer {
            bit_offset: 0,
            buf_bytes: 15
        })
    );
    assert_eq!(
        Frame::read_at(&buf, usize::MAX),
        Err(DecodeError::OutOfBuffer {
            bit_offset: usize::MAX,
            buf_bytes: 125
        })
    );
    let mut buf = [0u8; RING_BYTES];
    assert!(write_slot(&mut buf, 8, &frame(0, 0, 0)).is_err());
    assert!(frame(0, 0, 0).write_at(&mut buf, 876).is_err());
    assert_eq!(
        buf, [0u8; RING_BYTES],
        "a failed write must not touch the buffer"
    );
}

#[test]
fn slot_table_next_to_filled_neighbours() {
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

#[test]
fn last_slot_ends_exactly_at_the_ring_end() {
    // Slot 7 = bits 875..999: byte 109 bits 4..0 onwards, up to byte 124 bit 0.
    let mut buf = [0u8; RING_BYTES];
    write_slot(&mut buf, 7, &frame(0, 0, 0)).unwrap();
    // Line bits 0..4 = 0 1 0 1 0 in byte 109 bits 4..0.
    assert_eq!(buf[109], 0b000_01010);
    // Byte 124 = line bits 117..124 = 1 0 1 0 1 + stop 1 1 1.
    assert_eq!(buf[124], 0b1010_1111);
    assert!(buf[..109].iter().all(|&b| b == 0));
}

fn any_frame() -> impl Strategy<Value = Frame> {
    (0..=0xF_FFFFu32, 0..=0xF_FFFFu32, 0..=0xF_FFFFu32).prop_map(|(a, b, c)| frame(a, b, c))
}

/// The error a single flipped line bit `t` (0 = first) must produce.
fn expected_error(t: usize, pattern: u128) -> DecodeError {
    let flipped = pattern ^ 1 << (124 - t);
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

/// `Frame::decode` spelled out bit by bit (the order of the checks and the error
/// of the first failing one), to hold the word-parallel version to.
fn decode_bit_by_bit(pattern: u128) -> Result<Frame, DecodeError> {
    let bit = |t: usize| (pattern >> (124 - t)) as u32 & 1;
    if pattern >> 125 != 0 {
        return Err(DecodeError::Padding {
            got: (pattern >> 125) as u8,
        });
    }
    let start = (bit(0) << 1 | bit(1)) as u8;
    if start != 0b01 {
        return Err(DecodeError::StartPair { got: start });
    }
    let mut words = [0u32; 3];
    for (w, slot) in words.iter_mut().enumerate() {
        for i in 0..20 {
            let t = 2 + 40 * w + 2 * i;
            if bit(t) == bit(t + 1) {
                return Err(DecodeError::Complement {
                    word: w as u8 + 1,
                    bit: 19 - i as u8,
                });
            }
            *slot = *slot << 1 | bit(t);
        }
    }
    let stop = (bit(122) << 2 | bit(123) << 1 | bit(124)) as u8;
    if stop != 0b111 {
        return Err(DecodeError::StopBits { got: stop });
    }
    Ok(frame(words[0], words[1], words[2]))
}

proptest! {
    #[test]
    fn decode_matches_bit_by_bit(
        f in any_frame(),
        flips in proptest::collection::vec(0usize..128, 0..6),
        random in any::<u128>(),
        use_random in any::<bool>(),
    ) {
        // A valid frame with a few bits flipped (padding included), or any
        // pattern at all.
        let mut p = if use_random { random } else { f.encode() };
        for t in flips {
            p ^= 1 << t;
        }
        prop_assert_eq!(Frame::decode(p), decode_bit_by_bit(p));
    }

    #[test]
    fn pattern_round_trip(f in any_frame()) {
        prop_assert_eq!(Frame::decode(f.encode()), Ok(f));
        prop_assert_eq!(Frame::from_bytes(&f.to_bytes()), Ok(f));
    }

    #[test]
    fn every_single_bit_error_is_detected_and_located(f in any_frame()) {
        let p = f.encode();
        for t in 0..125 {
            prop_assert_eq!(Frame::decode(p ^ 1 << (124 - t)), Err(expected_error(t, p)), "bit {}", t);
        }
    }

    #[test]
    fn write_at_touches_only_its_bits(
        mut buf in proptest::collection::vec(any::<u8>(), 16..40),
        off in 0usize..200,
        f in any_frame(),
    ) {
        let before = buf.clone();
        let fits = off + 125 <= buf.len() * 8;
        prop_assert_eq!(f.write_at(&mut buf, off).is_ok(), fits);
        if fits {
            for bit in 0..buf.len() * 8 {
                let get = |b: &[u8]| b[bit / 8] >> (7 - bit % 8) & 1;
                if (off..off + 125).contains(&bit) {
                    let want = (f.encode() >> (124 - (bit - off))) as u8 & 1;
                    prop_assert_eq!(get(&buf), want, "bit {}", bit);
                } else {
                    prop_assert_eq!(get(&buf), get(&before), "neighbour bit {}", bit);
                }
            }
            prop_assert_eq!(Frame::read_at(&buf, off), Ok(f));
        } else {
            prop_assert_eq!(buf, before);
        }
    }

    #[test]
    fn ring_of_frames_reads_back_and_rejects_misalignment(
        frames in proptest::collection::vec(any_frame(), 8),
        order in Just([3usize, 0, 7, 1, 6, 2, 5, 4]),
    ) {
        let mut buf = [0u8; RING_BYTES];
        for &k in &order {
            write_slot(&mut buf, k, &frames[k]).unwrap();
        }
        for (k, f) in frames.iter().enumerate() {
            prop_assert_eq!(read_slot(&buf, k), Ok(*f));
        }
        // Any misaligned window of a valid stream contains the 3 stop bits where a
        // start pair or a data pair should be, and so fails a check.
        for off in 1..875 {
            if off % 125 != 0 {
                prop_assert!(Frame::read_at(&buf, off).is_err(), "offset {}", off);
            }
        }
    }
}

#[test]
fn two_bit_errors_share_detected() {
    let mut runner = TestRunner::deterministic();
    let pairs = 125 * 124 / 2;
    let (mut total, mut missed) = (0usize, 0usize);
    for _ in 0..32 {
        let f = any_frame().new_tree(&mut runner).unwrap().current();
        let p = f.encode();
        let mut undetected = 0;
        for a in 0..125 {
            for b in a + 1..125 {
                if Frame::decode(p ^ 1 << (124 - a) ^ 1 << (124 - b)).is_ok() {
                    // Only both bits of one complement pair swap into a valid pair.
                    assert!(a >= 2 && a % 2 == 0 && b == a + 1 && b <= 121, "{a},{b}");
                    undetected += 1;
                }
            }
        }
        assert_eq!(undetected, 60, "one undetectable pair per data bit");
        total += pairs;
        missed += undetected;
    }
    println!(
        "HANS-100 2-bit errors: {} of {} detected ({:.3} %), {} undetected per frame \
         (both bits of one of the 60 complement pairs)",
        total - missed,
        total,
        100.0 * (total - missed) as f64 / total as f64,
        missed / 32,
    );
}
