//! `bridge::ring_guard` on the target (it runs in the firmware's P0 DMA handler):
//! an on-time writer, a stall with its catch-up, and random writers, stalls and
//! races against a model of the two ring halves, with the host tests' invariant:
//! the DMA plays a half's own words or idle, never another half's, and the gate
//! goes off in every half that is not wholly its own.

use super::prng::Prng;
use super::Case;
use shared::bridge::ring_guard::{Actions, Claim, Fill, RingGuard};

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

const HALF: usize = 1000;
const MARGIN: usize = 100;
/// Random runs and steps per run.
const RUNS: u32 = 200;
const STEPS: u32 = 300;

/// What a part of a ring half holds: `None` idle, `Some(n)` half `n`'s words.
type Words = Option<u64>;

/// The model ring: per ring half its lead and the rest.
struct Ring {
    lead: [Words; 2],
    body: [Words; 2],
}

impl Ring {
    fn apply(&mut self, a: &Actions) {
        if let Some(s) = a.blank_lead {
            self.lead[s] = None;
        }
        if let Some(s) = a.blank_rest {
            self.body[s] = None;
        }
        if let Some(s) = a.blank_all {
            self.lead[s] = None;
            self.body[s] = None;
        }
    }
    fn write(&mut self, n: u64) {
        let s = (n % 2) as usize;
        self.lead[s] = Some(n);
        self.body[s] = Some(n);
    }
}

/// A boundary: the DMA plays the lead of the half it enters during the guard's
/// latency, the rest after the guard acted. Checks the invariant; returns whether
/// the half played wholly its own words.
fn boundary(g: &mut RingGuard, ring: &mut Ring) -> bool {
    let p = g.playing() + 1;
    let s = (p % 2) as usize;
    let lead = ring.lead[s];
    let a = g.boundary();
    assert_eq!(g.playing(), p);
    ring.apply(&a);
    let body = ring.body[s];
    assert!(
        lead.is_none() || lead == Some(p),
        "half {} lead {:?}",
        p,
        lead
    );
    assert!(
        body.is_none() || body == Some(p),
        "half {} body {:?}",
        p,
        body
    );
    let own = lead == Some(p) && body == Some(p);
    if p >= 2 && !own {
        assert!(a.gate_off, "half {} not its own, gate not off", p);
    }
    if a.gate_off {
        assert!(!own, "gate off in a half playing its own words");
    }
    own
}

fn on_time_and_stall() {
    let mut g = RingGuard::new();
    let mut ring = Ring {
        lead: [None; 2],
        body: [None; 2],
    };
    let mut next = 2u64;
    boundary(&mut g, &mut ring);
    for _ in 0..20 {
        assert_eq!(
            g.claim(next, (g.playing() % 2) as usize, HALF, MARGIN),
            Claim::Granted
        );
        ring.write(next);
        assert_eq!(g.fill(next), Fill::Done);
        next += 1;
        assert!(boundary(&mut g, &mut ring));
    }
    assert_eq!(g.missed(), 0);
    // A stall of 5 boundaries: 5 halves idle with the gate off.
    for _ in 0..5 {
        boundary(&mut g, &mut ring);
    }
    assert_eq!(g.missed(), 5);
    let dma = (g.playing() % 2) as usize;
    assert_eq!(
        g.claim(next, dma, HALF, MARGIN),
        Claim::Late {
            next: g.playing() + 2
        }
    );
    next = g.playing() + 2;
    assert_eq!(g.claim(next, dma, HALF, MARGIN), Claim::Wait);
    assert!(!boundary(&mut g, &mut ring));
    assert_eq!(g.claim(next, 1 - dma, HALF, MARGIN), Claim::Granted);
    ring.write(next);
    assert_eq!(g.fill(next), Fill::Done);
    assert!(boundary(&mut g, &mut ring));
}

fn random_runs() {
    let mut rng = Prng::new(0x5EED_0A11);
    for _ in 0..RUNS {
        let mut g = RingGuard::new();
        let mut ring = Ring {
            lead: [None; 2],
            body: [None; 2],
        };
        let mut next = 2u64;
        for _ in 0..STEPS {
            match rng.bits(4) {
                // A boundary without the writer.
                0..=6 => {
                    boundary(&mut g, &mut ring);
                }
                // A claim while a boundary is pending.
                7 => {
                    let other = ((g.playing() + 1) % 2) as usize;
                    assert_eq!(g.claim(next, other, HALF, MARGIN), Claim::Wait);
                }
                // The writer, at a random point of the playing half; rarely
                // overtaken by the boundary mid-copy.
                _ => {
                    let left = rng.bits(10) as usize % HALF;
                    let torn = rng.bits(5) == 0;
                    let dma = (g.playing() % 2) as usize;
                    let mut granted = false;
                    for _ in 0..2 {
                        match g.claim(next, dma, left, MARGIN) {
                            Claim::Granted => {
                                granted = true;
                                break;
                            }
                            Claim::Late { next: n } => {
                                assert!(n > next && n > g.playing());
                                next = n;
                            }
                            Claim::Wait => break,
                        }
                    }
                    if !granted {
                        continue;
                    }
                    assert!(left >= MARGIN && next == g.playing() + 1);
                    if torn {
                        assert!(!boundary(&mut g, &mut ring));
                        ring.write(next);
                        assert_eq!(g.fill(next), Fill::Torn);
                        let s = (next % 2) as usize;
                        ring.lead[s] = None;
                        ring.body[s] = None;
                    } else {
                        ring.write(next);
                        assert_eq!(g.fill(next), Fill::Done);
                        assert!(boundary(&mut g, &mut ring));
                    }
                    next += 1;
                }
            }
        }
    }
}
