//! Frame <-> pattern tests. Expected patterns are worked out by hand from the spec's
//! figure 1 (start `01`, each data bit followed by its complement: 0 -> `01`,
//! 1 -> `10`, stop `111`).

use super::frame::{read_slot, write_slot, DecodeError, EncodeError, Frame, RING_BYTES};
use proptest::prelude::*;
use proptest::strategy::ValueTree;
use proptest::test_runner::TestRunner;

/// Parses a hand-written bit string ('0'/'1', anything else ignored) into a pattern,
/// first character = first bit on the line = u128 bit 124.
fn bits(s: &str) -> u128 {
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
type Words = (u32, u32, u32);

fn frame(d1: u32, d2: u32, d3: u32) -> Frame {
    Frame::new(d1, d2, d3).unwrap()
}

// Hex of the u128 pattern: 3 zero padding bits on top, then the 125 line bits.
// Zero: 000 + "01" x 61 + 111 -> nibbles 0, A x 30, F.
// Full scale: 000 + 01 + "10" x 60 + 111 -> 0, D, 5 x 29, 7.
// Centre: like zero, but the D19 pair of each word is "10": line bits 3,4 / 43,44 /
// 83,84 (u128 display positions 5,6 / 45,46 / 85,86) -> nibbles 1, 11, 21 become C.
#[rustfmt::skip]
const PATTERNS: &[(Words, u128)] = &[
    ((0x0_0000, 0x0_0000, 0x0_0000), 0x0AAA_AAAA_AAAA_AAAA_AAAA_AAAA_AAAA_AAAF),
    ((0x8_0000, 0x8_0000, 0x8_0000), 0x0CAA_AAAA_AAAC_AAAA_AAAA_ACAA_AAAA_AAAF),
    ((0xF_FFFF, 0xF_FFFF, 0xF_FFFF), 0x0D55_5555_5555_5555_5555_5555_5555_5557),
];

// The same kind of table written bit by bit (start | DATA1 | DATA2 | DATA3 | stop),
// one nibble (4 pairs) per group.
#[rustfmt::skip]
const BIT_PATTERNS: &[(Words, &str)] = &[
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
#[rustfmt::skip]
const BYTES: &[(Words, [u8; 16])] = &[
    ((0x0_0000, 0x0_0000, 0x0_0000),
     [0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x78]),
    ((0x8_0000, 0x8_0000, 0x8_0000),
     [0x65, 0x55, 0x55, 0x55, 0x55, 0x65, 0x55, 0x55, 0x55, 0x55, 0x65, 0x55, 0x55, 0x55, 0x55, 0x78]),
    ((0xF_FFFF, 0xF_FFFF, 0xF_FFFF),
     [0x6A, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xB8]),
];

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

// Slot 1 = stream bits 125..249: it shares byte 15 (its first 3 bits in bits 2..0) with
// slot 0 and byte 31 (its last 2 bits in bits 7..6) with slot 2.
// Zero frame into an all-ones ring: byte 15 = 11111 010 = 0xFA, bytes 16..=29 carry
// line bits 3..114 ("1010...") = 0xAA, byte 30 = bits 115..122 = 1010101 1 = 0xAB,
// byte 31 = 11 + neighbour 111111 = 0xFF.
// Full-scale frame into an all-zero ring: byte 15 = 00000 011 = 0x03, bytes 16..=30 =
// 0x55 (line bits 3..122 alternate 0101..., bit 122 is a stop 1), byte 31 = 11 000000.
/// (byte index, expected value) pairs.
type Changed = &'static [(usize, u8)];

#[rustfmt::skip]
const SLOT1: &[(u8, Words, Changed)] = &[
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

proptest! {
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
