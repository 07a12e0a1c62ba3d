//! `bridge::ring_guard` on the target (it runs in the firmware's P0 DMA handler):
//! an on-time writer, a stall with its catch-up, and random writers, stalls and
//! races. Both drive the walk of `shared::bridge::ring_guard::model` (the host
//! proptest's too: one model of the two ring halves, one writer step, one set of
//! checks); only the steps' source differs (here the xorshift PRNG). The invariant:
//! the DMA plays a half's own words or idle, never another half's, the gate goes off
//! in every half that is not wholly its own, and the guard counts those misses.

use super::prng::Prng;
use super::Case;
use shared::bridge::ring_guard::model::{Step, Walk, HALF, MARGIN};
use shared::bridge::ring_guard::{Claim, Fill};

/// This module's cases.
pub const CASES: &[Case] = &[
    Case {
        name: "ring_guard::on_time_and_stall",
        run: on_time_and_stall,
    },
    Case {
        name: "ring_guard::never_plays_another_halfs_words_random",
        run: random_runs,
    },
];

/// Random runs and steps per run.
const RUNS: u32 = 200;
const STEPS: u32 = 300;

fn on_time_and_stall() {
    let mut w = Walk::new();
    // Every boundary and write below goes through the walk's checks (`Walk::boundary`).
    w.boundary().unwrap();
    for _ in 0..20 {
        assert_eq!(w.write(HALF, false), Ok(true));
    }
    assert_eq!(w.guard.missed(), 0);
    // A stall of 5 boundaries: 5 halves idle with the gate off.
    for _ in 0..5 {
        assert!(!w.boundary().unwrap().own());
    }
    assert_eq!(w.guard.missed(), 5);
    let dma = (w.guard.playing() % 2) as usize;
    let resume = w.guard.playing() + 2;
    assert_eq!(
        w.guard.claim(w.next, dma, HALF, MARGIN),
        Claim::Late { next: resume }
    );
    w.next = resume;
    assert_eq!(w.guard.claim(w.next, dma, HALF, MARGIN), Claim::Wait);
    assert!(!w.boundary().unwrap().own());
    assert_eq!(w.guard.claim(w.next, 1 - dma, HALF, MARGIN), Claim::Granted);
    w.ring.write(w.next);
    assert_eq!(w.guard.fill(w.next), Fill::Done);
    assert!(w.boundary().unwrap().own());
}

fn random_runs() {
    let mut rng = Prng::new(0x5EED_0A11);
    for _ in 0..RUNS {
        let mut w = Walk::new();
        for _ in 0..STEPS {
            let s = match rng.bits(4) {
                // A boundary without the writer.
                0..=6 => Step::Boundary,
                // A claim while a boundary is pending.
                7 => Step::Pending,
                // The writer, at a random point of the playing half; rarely
                // overtaken by the boundary mid-copy.
                _ => Step::Write {
                    left: rng.bits(10) as usize % HALF,
                    torn: rng.bits(5) == 0,
                },
            };
            assert_eq!(w.step(s), Ok(()), "step {:?}", s);
        }
    }
}
