//! Host tests of the ring guard: tables of the named cases and a model of the ring
//! (what each ring half holds, lead and body apart) driven by random writers,
//! stalls and races, checking that the DMA never plays words of another half. The
//! model and its random walk are [`super::model`], shared with the on-target runner
//! (`cm7`): the proptest here only draws the steps.

use super::model::{Ring, Step, Walk, Words, HALF, MARGIN};
use super::*;
use proptest::prelude::*;

/// One boundary of the model, for the named cases (the random walks check each
/// one in [`Walk::boundary`]). Returns the words played (lead, body) and the
/// actions.
fn boundary(g: &mut RingGuard, ring: &mut Ring) -> (u64, Words, Words, Actions) {
    let p = ring.boundary(g);
    assert_eq!(g.playing(), p.half);
    (p.half, p.lead, p.body, p.actions)
}

/// A writer that writes every half on time, and the guard.
fn writer_on_time(g: &mut RingGuard, ring: &mut Ring, next: &mut u64) {
    let dma = (g.playing() % 2) as usize;
    assert_eq!(g.claim(*next, dma, HALF, MARGIN), Claim::Granted);
    ring.write(*next);
    assert_eq!(g.fill(*next), Fill::Done);
    *next += 1;
}

#[test]
fn on_time_writer_plays_every_half_fresh_and_only_blanks_leads() {
    let mut g = RingGuard::new();
    let mut ring = Ring::new();
    let mut next = 2;
    // The pre-fill: the writer may claim half 2 while the DMA plays half 0? No:
    // only the half after the one playing.
    assert_eq!(g.claim(2, 0, HALF, MARGIN), Claim::Wait);
    for _ in 0..50 {
        let (p, lead, body, a) = boundary(&mut g, &mut ring);
        if p >= 2 {
            assert_eq!((lead, body), (Words::Of(p), Words::Of(p)));
        }
        assert!(!a.gate_off);
        assert_eq!(a.blank_rest, None);
        assert_eq!(a.blank_all, None);
        // The half just played is a written one from half 3 on: its lead goes idle.
        assert_eq!(a.blank_lead.is_some(), p >= 3);
        writer_on_time(&mut g, &mut ring, &mut next);
    }
    assert_eq!(g.missed(), 0);
}

#[test]
fn a_stall_plays_idle_with_the_gate_off_then_resumes() {
    let mut g = RingGuard::new();
    let mut ring = Ring::new();
    let mut next = 2;
    for _ in 0..6 {
        boundary(&mut g, &mut ring);
        writer_on_time(&mut g, &mut ring, &mut next);
    }
    // DMA plays 6, half 7 written. The writer stalls for 5 boundaries.
    assert_eq!(g.playing(), 6);
    let (p, lead, body, a) = boundary(&mut g, &mut ring);
    assert_eq!((p, lead, body), (7, Words::Of(7), Words::Of(7)));
    assert!(!a.gate_off);
    // Half 8 not written: a miss. Its lead was blanked when the DMA left it.
    let (p, lead, body, a) = boundary(&mut g, &mut ring);
    assert_eq!((p, lead, body), (8, Words::Idle, Words::Idle));
    assert_eq!(
        a,
        Actions {
            blank_lead: None,
            blank_rest: Some(0),
            blank_all: Some(1),
            gate_off: true
        }
    );
    assert_eq!(g.missed(), 1);
    // Further missed halves: already idle, nothing to blank, gate off again.
    for p in 9..12 {
        let (q, lead, body, a) = boundary(&mut g, &mut ring);
        assert_eq!((q, lead, body), (p, Words::Idle, Words::Idle));
        assert_eq!(
            a,
            Actions {
                gate_off: true,
                ..Actions::default()
            }
        );
    }
    assert_eq!(g.missed(), 4);
    // The writer runs again while the DMA plays 11: its half 8 is late; it drops
    // that batch and claims 13 next, which waits for the DMA to enter 12 (idle).
    assert_eq!(g.claim(next, 1, 500, MARGIN), Claim::Late { next: 13 });
    next = 13;
    assert_eq!(g.claim(next, 1, 500, MARGIN), Claim::Wait);
    let (p, lead, body, a) = boundary(&mut g, &mut ring);
    assert_eq!((p, lead, body), (12, Words::Idle, Words::Idle));
    assert!(a.gate_off);
    assert_eq!(g.claim(next, 0, 10, MARGIN), Claim::Late { next: 14 });
    assert_eq!(g.claim(next, 0, MARGIN, MARGIN), Claim::Granted);
    ring.write(13);
    assert_eq!(g.fill(13), Fill::Done);
    next += 1;
    let (p, lead, body, a) = boundary(&mut g, &mut ring);
    assert_eq!((p, lead, body), (13, Words::Of(13), Words::Of(13)));
    assert!(!a.gate_off);
    writer_on_time(&mut g, &mut ring, &mut next);
    let (p, lead, body, _) = boundary(&mut g, &mut ring);
    assert_eq!((p, lead, body), (14, Words::Of(14), Words::Of(14)));
}

/// The writer's side of the stale flag (module docs, "Misses, and lifting the gate
/// refusal"), as `tasks/bridge.rs` runs it after every batch.
struct Refusal {
    /// The firmware's stale flag: set at every gate drop.
    stale: bool,
    /// The miss count the writer last acted on, and its gate-rule restarts.
    seen: u32,
    restarts: u32,
}

impl Refusal {
    fn new() -> Self {
        Self {
            stale: false,
            seen: 0,
            restarts: 0,
        }
    }
    fn guard(&mut self, a: &Actions) {
        self.stale |= a.gate_off;
    }
    /// The look after a batch (written or dropped).
    fn look(&mut self, g: &RingGuard) {
        let missed = g.missed();
        if missed != self.seen {
            self.seen = missed;
            self.restarts += 1;
            if g.clear_if(self.seen) {
                self.stale = false;
            }
        }
    }
}

/// A late claim skips the next half, so the DMA misses once more *after* the
/// writer saw its underrun: a clear at the underrun (the rule before) left the
/// refusal of that miss standing for good; the look by count after the next batch
/// lifts it.
#[test]
fn the_miss_after_a_late_claim_is_lifted_by_the_next_look() {
    let mut g = RingGuard::new();
    let mut ring = Ring::new();
    let mut r = Refusal::new();
    let mut next = 2;
    for _ in 0..4 {
        boundary(&mut g, &mut ring);
        writer_on_time(&mut g, &mut ring, &mut next);
        r.look(&g);
    }
    // Stall: two boundaries miss.
    for _ in 0..3 {
        let (_, _, _, a) = boundary(&mut g, &mut ring);
        r.guard(&a);
    }
    assert_eq!(g.missed(), 2);
    assert!(r.stale);
    // Back: late, the batch dropped; the look restarts the rule and lifts the
    // refusal (the rule before cleared here too).
    let p = g.playing();
    assert_eq!(
        g.claim(next, (p % 2) as usize, HALF, MARGIN),
        Claim::Late { next: p + 2 }
    );
    next = p + 2;
    // The rule before, beside it: the flag cleared at the underrun only.
    let mut before = false;
    r.look(&g);
    assert!(!r.stale);
    assert_eq!(r.restarts, 1);
    // The half after the playing one was skipped: the DMA misses it, after the
    // writer's look.
    let (_, lead, body, a) = boundary(&mut g, &mut ring);
    assert_eq!((lead, body), (Words::Idle, Words::Idle));
    assert!(a.gate_off);
    r.guard(&a);
    before |= a.gate_off;
    assert!(r.stale);
    // The next batch is on time; the look after it sees the count moved.
    writer_on_time(&mut g, &mut ring, &mut next);
    r.look(&g);
    assert!(!r.stale, "the refusal stands after the writer caught up");
    assert_eq!(r.restarts, 2);
    // Fresh words from here, no more misses.
    for _ in 0..4 {
        let (p, lead, body, a) = boundary(&mut g, &mut ring);
        assert_eq!((lead, body), (Words::Of(p), Words::Of(p)));
        assert!(!a.gate_off);
        writer_on_time(&mut g, &mut ring, &mut next);
        r.look(&g);
    }
    assert!(!r.stale);
    assert_eq!(r.restarts, 2);
    assert!(before, "the rule before lifts the refusal after all");
}

/// A miss between the writer's read of the count and its clear (the guard runs
/// above the writer) keeps the refusal; the writer's next look lifts it.
#[test]
fn a_miss_between_the_writers_read_and_clear_keeps_the_refusal() {
    let mut g = RingGuard::new();
    let mut ring = Ring::new();
    let mut r = Refusal::new();
    g.boundary();
    // Half 2 never written: the DMA misses it.
    let (_, _, _, a) = boundary(&mut g, &mut ring);
    r.guard(&a);
    assert_eq!(g.missed(), 1);
    // The writer reads the count and restarts its gate rule ...
    let seen = g.missed();
    // ... and the next boundary (half 3, not written either) comes first.
    let (_, _, _, a) = boundary(&mut g, &mut ring);
    r.guard(&a);
    assert!(!g.clear_if(seen), "a clear by the old count");
    assert!(r.stale);
    // The next look: the count moved, so it restarts again and clears.
    r.seen = seen;
    r.look(&g);
    assert!(!r.stale);
    assert_eq!(r.seen, 2);
}

#[test]
fn restart_keeps_the_miss_count() {
    let mut g = RingGuard::new();
    g.boundary();
    assert!(g.boundary().gate_off);
    g.restart();
    assert_eq!(g.missed(), 1);
    assert_eq!(g, {
        let mut fresh = RingGuard::new();
        fresh.missed = 1;
        fresh
    });
}

#[test]
fn claims_wait_while_a_boundary_is_pending_or_the_ring_is_full() {
    let mut g = RingGuard::new();
    // DMA in ring half 1 but the guard has not seen the boundary yet.
    assert_eq!(g.claim(1, 1, HALF, MARGIN), Claim::Wait);
    assert_eq!(g.claim(2, 1, HALF, MARGIN), Claim::Wait);
    g.boundary();
    // Half 3 would overwrite the half playing.
    assert_eq!(g.claim(3, 1, HALF, MARGIN), Claim::Wait);
    assert_eq!(g.claim(2, 1, HALF, MARGIN), Claim::Granted);
}

#[test]
fn a_claim_too_close_to_the_boundary_is_late() {
    let mut g = RingGuard::new();
    g.boundary();
    assert_eq!(g.claim(2, 1, MARGIN - 1, MARGIN), Claim::Late { next: 3 });
    assert_eq!(g.claim(2, 1, MARGIN, MARGIN), Claim::Granted);
    // A late claim of a half already playing skips to the one after the next.
    let mut g = RingGuard::new();
    g.boundary();
    g.boundary();
    assert_eq!(g.claim(2, 0, HALF, MARGIN), Claim::Late { next: 4 });
}

#[test]
fn writer_finishing_as_the_guard_runs() {
    // Guard first: the boundary comes between claim and fill (only a stall of the
    // guard's own priority can do that). The guard blanks; the fill is torn.
    let mut g = RingGuard::new();
    let mut ring = Ring::new();
    g.boundary();
    assert_eq!(g.claim(2, 1, HALF, MARGIN), Claim::Granted);
    let (p, lead, body, a) = boundary(&mut g, &mut ring);
    assert_eq!((p, lead, body), (2, Words::Idle, Words::Idle));
    assert!(a.gate_off);
    // The copy lands now, in front of the DMA: new words of half 2, then the writer
    // blanks the rest again.
    ring.write(2);
    assert_eq!(g.fill(2), Fill::Torn);
    assert_eq!(g.claim(3, 0, HALF, MARGIN), Claim::Granted);
    // Writer first: fill before the boundary, the half plays.
    let mut g = RingGuard::new();
    g.boundary();
    assert_eq!(g.claim(2, 1, MARGIN, MARGIN), Claim::Granted);
    assert_eq!(g.fill(2), Fill::Done);
    let a = g.boundary();
    assert!(!a.gate_off);
}

#[test]
fn a_fill_without_its_claim_is_torn() {
    let mut g = RingGuard::new();
    g.boundary();
    assert_eq!(g.fill(2), Fill::Torn);
    let a = g.boundary();
    assert!(a.gate_off);
}

fn step() -> impl Strategy<Value = Step> {
    prop_oneof![
        4 => (0..HALF, prop::bool::weighted(0.05)).prop_map(|(left, torn)| Step::Write { left, torn }),
        4 => Just(Step::Boundary),
        1 => Just(Step::Pending),
    ]
}

proptest! {
    /// Random writers against the DMA: every half played holds its own words or
    /// idle (lead and rest), the gate goes off in every half that is not wholly its
    /// own from half 2 on, a writer that writes on time after a stall plays fresh
    /// words again within two boundaries, and `missed` counts the misses.
    #[test]
    fn never_plays_another_halfs_words(steps in proptest::collection::vec(step(), 0..400)) {
        // The walk (`model`, shared with the on-target runner) checks every half
        // played and every claim and fill; the first broken invariant ends it.
        let mut walk = Walk::new();
        for s in steps {
            prop_assert_eq!(walk.step(s), Ok(()), "step {:?}", s);
        }
    }

    /// Catch-up: after a stall of any length, a writer on time plays its own words
    /// from the second boundary on.
    #[test]
    fn resumes_within_two_boundaries(before in 0usize..10, stall in 0usize..20, left in 0..HALF) {
        let mut g = RingGuard::new();
        let mut ring = Ring::new();
        let mut next = 2;
        g.boundary();
        for _ in 0..before {
            writer_on_time(&mut g, &mut ring, &mut next);
            boundary(&mut g, &mut ring);
        }
        for _ in 0..stall {
            boundary(&mut g, &mut ring);
        }
        // Back: claim at wherever the DMA is (`left` words before its boundary).
        // A late claim moves on to the half after the next and waits one
        // boundary for it; then it is granted with the whole half left.
        let back_at = g.playing();
        let mut waited = 0;
        loop {
            let dma = (g.playing() % 2) as usize;
            let room = if waited == 0 { left } else { HALF };
            match g.claim(next, dma, room, MARGIN) {
                Claim::Granted => break,
                Claim::Late { next: n } => {
                    prop_assert!(n > next);
                    prop_assert_eq!(n, g.playing() + 2);
                    next = n;
                }
                Claim::Wait => {
                    prop_assert!(waited == 0);
                    waited += 1;
                    boundary(&mut g, &mut ring);
                }
            }
        }
        prop_assert!(g.playing() <= back_at + 1);
        prop_assert_eq!(next, g.playing() + 1);
        ring.write(next);
        prop_assert_eq!(g.fill(next), Fill::Done);
        let (p, lead, body, a) = boundary(&mut g, &mut ring);
        prop_assert_eq!((p, lead, body), (next, Words::Of(next), Words::Of(next)));
        prop_assert!(!a.gate_off);
    }
}
