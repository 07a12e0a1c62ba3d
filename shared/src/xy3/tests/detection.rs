//! What the parity detects (see the module docs, "What the parity detects").

use proptest::prelude::*;

use super::props::frame;
use crate::xy3::*;

/// The same frame with the kind bit flipped, as a receiver would accept it.
fn other_kind(f: Frame) -> Frame {
    match f {
        Frame::Position24(v) => Frame::Command24(v),
        Frame::Command24(c) => Frame::Position24(c),
        Frame::Position32(v) => Frame::Command32 {
            code: v & 0xF_FFFF,
            unused: (v >> 20) as u8,
        },
        Frame::Command32 { code, unused } => Frame::Position32(u32::from(unused) << 20 | code),
    }
}

proptest! {
    #[test]
    fn single_bit_errors(f in frame()) {
        let (word, size) = encode(&f).unwrap();
        let top = u32::from(size.bits()) - 1;
        for bit in 0..32 {
            let got = decode(word ^ 1 << bit, size);
            if bit > top {
                // Outside the frame: only possible for 24-bit frames.
                let too_wide = matches!(got, Err(DecodeError::WordTooWide { .. }));
                prop_assert!(too_wide, "bit {} gave {:?}", bit, got);
            } else if bit == top {
                // Caught by the receiver's framing, not by the parity.
                let mismatch = matches!(got, Err(DecodeError::SizeMismatch { .. }));
                prop_assert!(mismatch, "bit {} gave {:?}", bit, got);
            } else if bit == top - 1 {
                // Undetectable by design: the kind bit is outside the parity count.
                prop_assert_eq!(got, Ok(other_kind(f)));
            } else {
                let parity = matches!(got, Err(DecodeError::Parity { .. }));
                prop_assert!(parity, "bit {} gave {:?}", bit, got);
            }
        }
    }
}

/// Number of 2-bit errors (over all bit pairs of the frame) that `decode` rejects.
fn detected_pairs(word: u32, size: FrameSize) -> u32 {
    let n = u32::from(size.bits());
    let mut detected = 0;
    for i in 0..n {
        for j in i + 1..n {
            if decode(word ^ (1 << i | 1 << j), size).is_err() {
                detected += 1;
            }
        }
    }
    detected
}

/// 2-bit errors, exhaustively over bit pairs. 24-bit frames: over every frame (both
/// kinds, all 2^20 data values), which must give exactly the share worked out in the
/// module docs: of the 276 pairs, the 23 with the size bit, the 22 with the kind bit
/// and the 20 (data, P1) and 1 (P0, P1) pairs are always caught; of the 190 (data,
/// data) and 20 (data, P0) pairs exactly half on average. 171 / 276 in all.
/// 32-bit frames: over a spread sample of data values; the expected share is
/// (31 + 30 + 325 / 2 + 26 / 2 + 78 + 6) / 496 = 320.5 / 496.
#[test]
fn two_bit_error_detection_share() {
    let pairs24 = 24 * 23 / 2;
    let mut detected24 = 0u64;
    for kind in [0x40_0000u32, 0] {
        for data in 0..1u32 << 20 {
            let word = encode(&Frame::Position24(data)).unwrap().0 & !0x40_0000 | kind;
            detected24 += u64::from(detected_pairs(word, FrameSize::Bits24));
        }
    }
    let frames24 = 2u64 << 20;
    let share24 = detected24 as f64 / (frames24 * pairs24) as f64;
    println!(
        "XY3-100 24-bit frames: {:.3} % of 2-bit errors detected",
        share24 * 100.0
    );
    assert_eq!(detected24, 171 * frames24);

    let pairs32 = 32 * 31 / 2;
    let mut detected32 = 0u64;
    let mut frames32 = 0u64;
    for k in 0..1u32 << 15 {
        // Multiplicative hashing spreads k over all 26 data bits.
        let data = k.wrapping_mul(0x9E37_79B9) >> 6;
        for f in [Frame::Position32(data), other_kind(Frame::Position32(data))] {
            let (word, size) = encode(&f).unwrap();
            detected32 += u64::from(detected_pairs(word, size));
            frames32 += 1;
        }
    }
    let share32 = detected32 as f64 / (frames32 * pairs32) as f64;
    println!(
        "XY3-100 32-bit frames: {:.3} % of 2-bit errors detected",
        share32 * 100.0
    );
    assert!((share32 - 320.5 / 496.0).abs() < 0.005, "{share32}");
}
