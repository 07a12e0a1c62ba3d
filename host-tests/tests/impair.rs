//! Impairments: ordering, reproducibility, and decoding through them.

use host_tests::impair::{self, ImpairError};
use host_tests::line::roles;
use host_tests::line::sample::{xy2_port_words, PinMap};
use host_tests::line::serial::{xy2_waveform, FrameTiming, FrameWord, Idle, Lane};
use host_tests::wave::{Signal, Waveform};
use proptest::prelude::*;

const PINS: PinMap = PinMap {
    sync: 0,
    x: 1,
    y: 2,
    z: None,
    status: None,
};
const RATE: f64 = 2e6;
const BIT_PS: u64 = 500_000;

fn frames() -> (Vec<FrameWord>, Vec<FrameWord>) {
    let x = [
        0x2_8001u32,
        0x3_FFFE,
        0x2_5A5A,
        0x3_0F0F,
        0x2_0000,
        0xF_FFFF,
    ];
    let y: Vec<u32> = x.iter().map(|v| v ^ 0xA_AAAA).collect();
    let mk = |v: &u32| FrameWord {
        value: *v,
        bits: 20,
    };
    (x.iter().map(mk).collect(), y.iter().map(mk).collect())
}

fn xy2_wave() -> Waveform {
    let (x, y) = frames();
    let lanes = [
        Lane {
            name: roles::X,
            words: &x,
        },
        Lane {
            name: roles::Y,
            words: &y,
        },
    ];
    let t = FrameTiming {
        bit_rate_hz: RATE,
        frame_period_ps: None,
        idle: Idle::ClockStopped,
        start_ps: 1e6,
    };
    xy2_waveform(&lanes, &t).unwrap()
}

fn strictly_ordered(s: &Signal) -> bool {
    s.changes()
        .windows(2)
        .all(|w| w[0].0 < w[1].0 && w[0].1 != w[1].1)
}

#[test]
fn jitter_keeps_order_count_and_bounds() {
    let clean = xy2_wave();
    let mut w = clean.clone();
    // ±40 % of a bit: larger than half the CLK pulse, so clipping must keep order.
    impair::jitter(&mut w, &[], 2 * BIT_PS / 5, 7).unwrap();
    for (a, b) in clean.signals().iter().zip(w.signals()) {
        assert!(strictly_ordered(b), "{}", b.name());
        assert_eq!(a.changes().len(), b.changes().len(), "{}", b.name());
        for (&(ta, la), &(tb, lb)) in a.changes().iter().zip(b.changes()) {
            assert_eq!(la, lb);
            assert!(ta.abs_diff(tb) <= 2 * BIT_PS / 5);
        }
    }
    assert_ne!(w, clean);
    // Reproducible for a seed, different for another.
    let mut again = clean.clone();
    impair::jitter(&mut again, &[], 2 * BIT_PS / 5, 7).unwrap();
    assert_eq!(again, w);
    let mut other = clean.clone();
    impair::jitter(&mut other, &[], 2 * BIT_PS / 5, 8).unwrap();
    assert_ne!(other, w);
    // Only the named signals move.
    let mut only_x = clean.clone();
    impair::jitter(&mut only_x, &[roles::X], BIT_PS / 10, 1).unwrap();
    assert_eq!(only_x.get(roles::CLK), clean.get(roles::CLK));
    assert_ne!(only_x.get(roles::X), clean.get(roles::X));
}

#[test]
fn small_jitter_and_skew_still_decode() {
    let clean = xy2_wave();
    let expected = xy2_port_words(&clean, &PINS).unwrap();
    assert_eq!(expected.len(), 6 * 20);
    let mut w = clean.clone();
    impair::jitter(&mut w, &[], BIT_PS / 10, 42).unwrap();
    impair::skew(&mut w, &[(roles::X, 30_000), (roles::Y, -30_000)]).unwrap();
    assert_eq!(xy2_port_words(&w, &PINS).unwrap(), expected);
}

#[test]
fn rate_offset_scales_time() {
    let clean = xy2_wave();
    let mut w = clean.clone();
    impair::rate_offset_ppm(&mut w, 1000.0).unwrap(); // 0.1 % fast
    for (a, b) in clean.signals().iter().zip(w.signals()) {
        for (&(ta, _), &(tb, _)) in a.changes().iter().zip(b.changes()) {
            assert_eq!(tb, (ta as f64 / 1.001).round() as u64);
        }
    }
    // Same samples: the receiver follows the clock.
    assert_eq!(xy2_port_words(&w, &PINS), xy2_port_words(&clean, &PINS));
    assert!(matches!(
        impair::rate_offset_ppm(&mut w, -1e6),
        Err(ImpairError::BadParameter { .. })
    ));
}

#[test]
fn noise_burst_is_reproducible_and_confined() {
    let clean = xy2_wave();
    let window = (3_000_000, 6_000_000);
    let mut a = clean.clone();
    impair::noise_burst(&mut a, roles::X, window, 5, 20_000, 99).unwrap();
    let mut b = clean.clone();
    impair::noise_burst(&mut b, roles::X, window, 5, 20_000, 99).unwrap();
    assert_eq!(a, b);
    let (sa, sc) = (a.get(roles::X).unwrap(), clean.get(roles::X).unwrap());
    assert!(strictly_ordered(sa));
    assert_ne!(sa, sc);
    // Outside the window (plus the widest glitch) nothing changed.
    for t in (0..20_000_000).step_by(7_919) {
        if t < window.0 || t >= window.1 + 20_000 {
            assert_eq!(sa.level_at(t), sc.level_at(t), "t = {t}");
        }
    }
    assert!(matches!(
        impair::noise_burst(&mut a, "nope", window, 1, 1, 0),
        Err(ImpairError::MissingSignal { .. })
    ));
}

#[test]
fn stuck_and_gap() {
    let clean = xy2_wave();
    let mut w = clean.clone();
    impair::stuck_at(&mut w, roles::Y, 5_000_000, true).unwrap();
    let y = w.get(roles::Y).unwrap();
    assert!(y.changes().iter().all(|&(t, _)| t <= 5_000_000));
    assert!(y.level_at(5_000_000) && y.final_level());

    let mut g = clean.clone();
    impair::gap(&mut g, roles::CLK, 11_000_000, 21_000_000, false).unwrap();
    let clk = g.get(roles::CLK).unwrap();
    assert!(strictly_ordered(clk));
    assert!(clk
        .changes()
        .iter()
        .all(|&(t, _)| !(11_000_000 < t && t < 21_000_000)));
    // Exactly the 20 falling edges of frame 1 (11..21 us) are lost.
    let before = clean.get(roles::CLK).unwrap().falling_edges().count();
    assert_eq!(clk.falling_edges().count(), before - 20);
    assert_eq!(xy2_port_words(&g, &PINS).unwrap().len(), 5 * 20);
}

#[test]
fn asymmetry_moves_one_kind_of_edge() {
    let clean = xy2_wave();
    for rise in [60_000i64, -60_000] {
        let mut w = clean.clone();
        impair::asymmetry(&mut w, &[roles::X], rise).unwrap();
        assert_eq!(
            w.get(roles::CLK),
            clean.get(roles::CLK),
            "only the named signal"
        );
        let (a, b) = (clean.get(roles::X).unwrap(), w.get(roles::X).unwrap());
        assert!(strictly_ordered(b));
        // Every pulse is longer than 60 ns: the same edges, the rising ones
        // `rise` later (positive) or the falling ones `-rise` later (negative).
        assert_eq!(a.changes().len(), b.changes().len());
        for (&(ta, la), &(tb, lb)) in a.changes().iter().zip(b.changes()) {
            assert_eq!(la, lb);
            let moved = if la == (rise > 0) {
                rise.unsigned_abs()
            } else {
                0
            };
            assert_eq!(tb, ta + moved, "rise {rise}, edge at {ta}");
        }
        // Deterministic.
        let mut again = clean.clone();
        impair::asymmetry(&mut again, &[roles::X], rise).unwrap();
        assert_eq!(again, w);
    }
    // A pulse shorter than the asymmetry vanishes instead of turning round.
    let mut w = Waveform::new();
    let s = Signal::from_changes(
        "d",
        false,
        [(100, true), (130, false), (500, true), (900, false)],
    );
    w.insert(s.unwrap());
    impair::asymmetry(&mut w, &[], 50).unwrap();
    assert_eq!(w.get("d").unwrap().changes(), &[(550, true), (900, false)]);
    let mut w = Waveform::new();
    let s = Signal::from_changes("d", true, [(100, false), (130, true), (500, false)]);
    w.insert(s.unwrap());
    impair::asymmetry(&mut w, &[], -50).unwrap();
    assert_eq!(w.get("d").unwrap().changes(), &[(550, false)]);
    // Nothing moves at 0; an unknown name is an error.
    let mut w = clean.clone();
    impair::asymmetry(&mut w, &[], 0).unwrap();
    assert_eq!(w, clean);
    assert!(matches!(
        impair::asymmetry(&mut w, &["nope"], 1),
        Err(ImpairError::MissingSignal { .. })
    ));
}

proptest! {
    #[test]
    fn random_impairments_keep_signals_well_formed(seed in any::<u64>(), ppm in -5000.0f64..5000.0,
                                                   jit in 0u64..400_000, skew in -100_000i64..100_000) {
        let mut w = xy2_wave();
        impair::rate_offset_ppm(&mut w, ppm).unwrap();
        impair::jitter(&mut w, &[], jit, seed).unwrap();
        impair::skew(&mut w, &[(roles::X, skew)]).unwrap();
        impair::asymmetry(&mut w, &[], skew / 2).unwrap();
        impair::noise_burst(&mut w, roles::SYNC, (0, 60_000_000), 10, 100_000, seed).unwrap();
        for s in w.signals() {
            prop_assert!(strictly_ordered(s));
        }
    }
}
