//! `model::Position` on the target: hand-worked scaling and inversion tables, the
//! error cases, and randomised round trips against an independent reference.

use super::prng::Prng;
use super::Case;
use shared::model::{Position, PositionError};

/// This module's cases.
pub const CASES: &[Case] = &[
    Case {
        name: "position::resize_table",
        run: resize_table,
    },
    Case {
        name: "position::invert_table",
        run: invert_table,
    },
    Case {
        name: "position::errors",
        run: errors,
    },
    Case {
        name: "position::widen_roundtrip_random",
        run: widen_roundtrip_random,
    },
    Case {
        name: "position::narrow_vs_reference_random",
        run: narrow_vs_reference_random,
    },
    Case {
        name: "position::narrow_monotonic_random",
        run: narrow_monotonic_random,
    },
    Case {
        name: "position::invert_random",
        run: invert_random,
    },
];

/// Widths the protocols use, plus the extremes.
const WIDTHS: [u8; 6] = [1, 16, 18, 20, 26, 32];
/// Random draws per randomised case (a few ms of emulated time).
const ROUNDS: u32 = 2000;

/// (value, from bits, to bits, expected), worked out by hand: narrowing rounds to
/// nearest with ties upward and saturates at full scale; widening shifts exactly.
#[rustfmt::skip]
const RESIZE: &[(u32, u8, u8, u32)] = &[
    (0x000_0000, 26, 16, 0x0000),      // zero
    (0x200_0000, 26, 16, 0x8000),      // centre
    (0x3FF_FFFF, 26, 16, 0xFFFF),      // full scale
    (0x000_01FF, 26, 16, 0x0000),      // just under half an LSB: down
    (0x000_0200, 26, 16, 0x0001),      // exactly half an LSB: up
    (0x3FF_F9FF, 26, 16, 0xFFFE),      // 0xFFFE<<10 | 0x1FF: down
    (0x3FF_FA00, 26, 16, 0xFFFF),      // 0xFFFE<<10 | 0x200: up
    (0x3FF_FE00, 26, 16, 0xFFFF),      // 0xFFFF<<10 | 0x200: saturates, no wrap to 0
    (0x8_0007,   20, 16, 0x8000),      // 7/16 LSB: down
    (0x8_0008,   20, 16, 0x8001),      // 8/16 LSB: up
    (0x0_0000,   20, 18, 0x0_0000),
    (0x0_0002,   20, 18, 0x0_0001),    // 2/4 LSB: up
    (0x8_0000,   20, 18, 0x2_0000),
    (0xF_FFFF,   20, 18, 0x3_FFFF),
    (0x0000,     16, 26, 0x000_0000),  // widening: exact shift by 10
    (0x8000,     16, 26, 0x200_0000),
    (0xFFFF,     16, 26, 0x3FF_FC00),
    (0x0001,     16, 20, 0x0_0010),
    (0x8000_7FFF, 32, 16, 0x8000),
    (0x8000_8000, 32, 16, 0x8001),
    (0xFFFF_FFFF, 32, 16, 0xFFFF),
    (0x1,         1, 32, 0x8000_0000),
];

fn resize_table() {
    for &(value, from, to, expected) in RESIZE {
        let p = Position::from_raw(value, from).unwrap();
        assert_eq!(p.to_raw(to), expected, "{value:#x} {from}->{to} bits");
        assert_eq!(
            p.resized(to).to_raw(to),
            expected,
            "{value:#x} resized {from}->{to}"
        );
        assert_eq!(p.resized(to).bits(), to);
    }
}

/// (value, bits, expected `2^bits - 1 - value`), by hand.
#[rustfmt::skip]
const INVERT: &[(u32, u8, u32)] = &[
    (0x0000,      16, 0xFFFF),
    (0x8000,      16, 0x7FFF),
    (0xFFFF,      16, 0x0000),
    (0x000_0000,  26, 0x3FF_FFFF),
    (0x200_0000,  26, 0x1FF_FFFF),
    (0x3FF_FFFF,  26, 0x000_0000),
    (0x0000_0000, 32, 0xFFFF_FFFF),
    (0x8000_0000, 32, 0x7FFF_FFFF),
];

fn invert_table() {
    for &(value, bits, expected) in INVERT {
        let p = Position::from_raw(value, bits).unwrap();
        assert_eq!(
            p.inverted().to_raw(bits),
            expected,
            "invert {value:#x} at {bits} bits"
        );
        assert_eq!(p.inverted().bits(), bits);
    }
}

fn errors() {
    assert_eq!(Position::from_raw(0, 0), Err(PositionError::BadWidth(0)));
    assert_eq!(Position::from_raw(0, 33), Err(PositionError::BadWidth(33)));
    assert_eq!(
        Position::from_raw(0x1_0000, 16),
        Err(PositionError::TooWide {
            value: 0x1_0000,
            bits: 16
        })
    );
    assert_eq!(
        Position::from_raw(0x10_0000, 20),
        Err(PositionError::TooWide {
            value: 0x10_0000,
            bits: 20
        })
    );
    assert_eq!(
        Position::from_raw(2, 1),
        Err(PositionError::TooWide { value: 2, bits: 1 })
    );
    assert!(Position::from_raw(u32::MAX, 32).is_ok());
    assert!(Position::from_raw(0xFFFF, 16).is_ok());
}

fn pick_width(rng: &mut Prng) -> u8 {
    WIDTHS[(rng.next_u32() % WIDTHS.len() as u32) as usize]
}

/// Widening is exact and narrowing back to the original width restores the value.
fn widen_roundtrip_random() {
    let mut rng = Prng::new(1);
    for _ in 0..ROUNDS {
        let (a, b) = (pick_width(&mut rng), pick_width(&mut rng));
        let (narrow, wide) = (a.min(b), a.max(b));
        let value = rng.bits(narrow);
        let p = Position::from_raw(value, narrow).unwrap();
        let widened = u64::from(value) << (wide - narrow);
        assert_eq!(
            u64::from(p.to_raw(wide)),
            widened,
            "{value:#x} {narrow}->{wide}"
        );
        assert_eq!(
            p.resized(wide).to_raw(narrow),
            value,
            "{value:#x} {narrow}->{wide}->{narrow}"
        );
    }
}

/// Reference narrowing in 64-bit arithmetic: floor((v + half) / 2^k), capped at the
/// largest code (a different formula from the implementation's round bit).
fn reference_narrow(value: u32, from: u8, to: u8) -> u32 {
    let k = u32::from(from - to);
    let max = (1u64 << to) - 1;
    let rounded = (u64::from(value) + (1u64 << k >> 1)) >> k;
    rounded.min(max) as u32
}

fn narrow_vs_reference_random() {
    let mut rng = Prng::new(2);
    for _ in 0..ROUNDS {
        let (a, b) = (pick_width(&mut rng), pick_width(&mut rng));
        let (to, from) = (a.min(b), a.max(b));
        let value = rng.bits(from);
        let got = Position::from_raw(value, from).unwrap().to_raw(to);
        assert_eq!(
            got,
            reference_narrow(value, from, to),
            "{value:#x} {from}->{to}"
        );
    }
}

/// A larger input never narrows to a smaller code (no wrap at the top).
fn narrow_monotonic_random() {
    let mut rng = Prng::new(3);
    for _ in 0..ROUNDS {
        let from = pick_width(&mut rng);
        let to = pick_width(&mut rng);
        let (x, y) = (rng.bits(from), rng.bits(from));
        let (lo, hi) = (x.min(y), x.max(y));
        let lo_out = Position::from_raw(lo, from).unwrap().to_raw(to);
        let hi_out = Position::from_raw(hi, from).unwrap().to_raw(to);
        assert!(
            lo_out <= hi_out,
            "{lo:#x} -> {lo_out:#x} > {hi:#x} -> {hi_out:#x} ({from}->{to})"
        );
    }
}

fn invert_random() {
    let mut rng = Prng::new(4);
    for _ in 0..ROUNDS {
        let bits = pick_width(&mut rng);
        let value = rng.bits(bits);
        let p = Position::from_raw(value, bits).unwrap();
        let max = (u64::from(u32::MAX) >> (32 - u32::from(bits))) as u32;
        assert_eq!(
            p.inverted().to_raw(bits),
            max - value,
            "{value:#x} at {bits} bits"
        );
        assert_eq!(p.inverted().inverted(), p);
    }
}
