//! Host tests of the slot ring guard: a model of the DMA, the writer (two slots
//! ahead, as `tasks/bridge_hans.rs` with `hans::tx::Transmitter`) and the guard's
//! runs, byte by byte; and the wire: a blanked slot is no frame for `hans::rx`.

use super::*;
use crate::hans::frame::{blank_slot, read_slot, write_slot, Frame};
use crate::hans::rx::{HansRx, Mode, RxEvent};
use proptest::prelude::*;

/// Bytes per 10 us slot period (12.5 MHz bits): 15.625.
const SLOT_BYTES: f64 = FRAME_BITS as f64 / 8.0;
/// The ring byte at which the half-transfer interrupt comes (RM0433: half the
/// items of the lap; 125 / 2 rounded down).
const HALF: usize = RING_BYTES / 2;

/// The ring as the model sees it: which absolute slot's frame each ring slot holds
/// (`None`: zero bits).
struct Model {
    guard: SlotGuard,
    ring: [Option<u64>; RING_SLOTS],
    /// The writer's last ring slot (as `Transmitter::last`).
    last: Option<usize>,
    gate_offs: Vec<u64>,
    /// Absolute slots the DMA entered with zero bits while the writer was sending.
    blanks_played: Vec<u64>,
    /// Absolute slots the writer wrote.
    wrote: std::collections::BTreeSet<u64>,
    /// The bytes at which the writer wrote, and those at which the DMA started
    /// fetching a slot not written for this lap while the writer was sending
    /// (the first byte with that slot as `dma_slot`, before that byte's runs).
    write_at: Vec<u64>,
    stale_at: Vec<u64>,
    /// The firmware's stale flag (`channels`): set at every gate drop, cleared by
    /// the writer's rule ([`Model::look`]).
    stale: bool,
    /// The miss count the writer last acted on, and its gate-rule restarts.
    seen: u32,
    restarts: u32,
}

impl Model {
    fn new() -> Self {
        Self {
            guard: SlotGuard::new(),
            ring: [None; RING_SLOTS],
            last: None,
            gate_offs: Vec::new(),
            blanks_played: Vec::new(),
            wrote: Default::default(),
            write_at: Vec::new(),
            stale_at: Vec::new(),
            stale: false,
            seen: 0,
            restarts: 0,
        }
    }

    /// The writer's look after a write (`tasks/bridge_hans.rs`): a moved miss count
    /// restarts its gate rule, then the refusal is lifted if no miss came since.
    fn look(&mut self) {
        let missed = self.guard.missed();
        if missed != self.seen {
            self.seen = missed;
            self.restarts += 1;
            if self.guard.clear_if(self.seen) {
                self.stale = false;
            }
        }
    }

    fn run_guard(&mut self, fetched: u64) {
        let a = self.guard.run((fetched % RING_BYTES as u64) as usize);
        for k in 0..RING_SLOTS {
            if a.blank & (1 << k) != 0 {
                self.ring[k] = None;
            }
        }
        if a.gate_off {
            self.gate_offs.push(fetched);
            self.stale = true;
        }
    }

    /// One writer wake with the DMA at absolute byte `fetched` (read and write in
    /// one step, as the firmware's critical section).
    fn write(&mut self, fetched: u64) {
        let pos = (fetched % RING_BYTES as u64) as usize;
        let d = self.guard.dma_slot(pos);
        assert_eq!(
            d,
            fetched * 8 / FRAME_BITS as u64,
            "absolute slot at {fetched}"
        );
        let sending = (d % RING_SLOTS as u64) as usize;
        let target = (sending + 2) % RING_SLOTS;
        let mut slot = self.last.map_or(target, |l| (l + 1) % RING_SLOTS);
        for _ in 0..RING_SLOTS {
            let ahead = (slot + RING_SLOTS - sending) % RING_SLOTS;
            if ahead >= 2 {
                self.ring[slot] = Some(d + ahead as u64);
                self.wrote.insert(d + ahead as u64);
            }
            if slot == target {
                break;
            }
            slot = (slot + 1) % RING_SLOTS;
        }
        self.last = Some(target);
        self.write_at.push(fetched);
        assert_eq!(self.guard.wrote(target, pos), d + 2);
        self.look();
    }

    /// Byte `fetched` comes (before its runs): the DMA starting on a slot not
    /// written for this lap while the writer sends is noted (`stale_at`).
    fn enter(&mut self, fetched: u64) {
        let s = fetched * 8 / FRAME_BITS as u64;
        let entered = fetched > 0 && (fetched - 1) * 8 / FRAME_BITS as u64 != s;
        if entered && !self.guard.stopped && self.guard.written <= s {
            self.stale_at.push(fetched);
        }
    }

    /// The bound with a run at least once per slot (module docs, "Runs at any
    /// position"): every time the DMA started on an unwritten slot, the gate
    /// dropped within a slot (15.625 bytes) of it, unless the writer wrote again
    /// within that slot first. Returns how many entries dropped the gate.
    fn assert_slot_bound(&self, case: &str) -> usize {
        let within = |x: u64, at: u64| x >= at && x as f64 <= at as f64 + SLOT_BYTES;
        let mut dropped = 0;
        for &at in &self.stale_at {
            if self.gate_offs.iter().any(|&o| within(o, at)) {
                dropped += 1;
            } else {
                assert!(
                    self.write_at.iter().any(|&w| within(w, at)),
                    "{case}: DMA on an unwritten slot at byte {at}, gate offs {:?}",
                    self.gate_offs
                );
            }
        }
        // And no drop without an unwritten slot (at or before it, in that slot).
        for &o in &self.gate_offs {
            assert!(
                self.stale_at.iter().any(|&at| at <= o),
                "{case}: gate off at {o} with no unwritten slot before"
            );
        }
        dropped
    }

    /// The DMA fetches absolute byte `fetched`: every slot with bits in it must
    /// hold its own frame or zeros.
    fn fetch(&mut self, fetched: u64) {
        let first = fetched * 8 / FRAME_BITS as u64;
        let last = (fetched * 8 + 7) / FRAME_BITS as u64;
        for s in first..=last {
            let held = self.ring[(s % RING_SLOTS as u64) as usize];
            assert!(
                held.is_none() || held == Some(s),
                "byte {fetched}: slot {s} holds slot {held:?}"
            );
            if held.is_none()
                && (s * FRAME_BITS as u64).div_ceil(8) == fetched
                && !self.blanks_played.contains(&s)
            {
                self.blanks_played.push(s);
            }
        }
    }
}

/// Runs the model for `bytes` DMA bytes: the writer wakes every `wake` bytes
/// (plus `jitter(k)` for its k-th wake) except in the `stalls` (byte ranges), the
/// guard runs `latency` bytes after each half boundary.
fn simulate(
    bytes: u64,
    wake: f64,
    jitter: impl Fn(u64) -> f64,
    stalls: &[(u64, u64)],
    latency: u64,
) -> Model {
    simulate_ticked(bytes, wake, jitter, stalls, latency, |_| false)
}

/// [`simulate`] with a second trigger of the same guard (the firmware's slot
/// timer): one more run at every byte `f` with `tick(f)`, anywhere between the
/// half boundaries (before the boundary's run when both fall on one byte).
fn simulate_ticked(
    bytes: u64,
    wake: f64,
    jitter: impl Fn(u64) -> f64,
    stalls: &[(u64, u64)],
    latency: u64,
    mut tick: impl FnMut(u64) -> bool,
) -> Model {
    let mut m = Model::new();
    let mut next_wake = jitter(0);
    let mut wakes = 0u64;
    let mut pending_guard: Option<u64> = None;
    for f in 0..bytes {
        // The boundary: byte `f` is the first of a half.
        let pos = (f % RING_BYTES as u64) as usize;
        if f > 0 && (pos == 0 || pos == HALF) {
            pending_guard = Some(f + latency);
        }
        m.enter(f);
        if f > 0 && tick(f) {
            m.run_guard(f);
        }
        if pending_guard == Some(f) {
            m.run_guard(f);
            pending_guard = None;
        }
        let stalled = stalls.iter().any(|&(a, b)| (a..b).contains(&f));
        // The ticker's schedule is absolute (no drift); a stalled writer wakes as
        // soon as the stall ends, then goes on with the schedule.
        if f as f64 >= next_wake && !stalled {
            m.write(f);
            while next_wake <= f as f64 {
                wakes += 1;
                next_wake = wakes as f64 * wake + jitter(wakes);
            }
        }
        m.fetch(f);
    }
    m
}

#[test]
fn on_time_writer_plays_its_frames_and_keeps_the_gate() {
    // Wakes every slot period: every slot after the first two plays its frame.
    for phase in [0.0, 3.3, 7.9, 12.0] {
        for latency in [0, 1, 3] {
            let m = simulate(20_000, SLOT_BYTES, |_| phase, &[], latency);
            assert!(
                m.gate_offs.is_empty(),
                "latency {latency}: {:?}",
                m.gate_offs
            );
            assert_eq!(m.blanks_played, [0, 1], "phase {phase} latency {latency}");
            assert_eq!(m.guard.missed(), 0);
        }
    }
    // Late by up to 12.6 bytes (8 us of wake-up jitter): never a miss. A wake that
    // finds the DMA two slots on skips the slot one ahead (`Transmitter::update`
    // writes only slots two or more ahead): that slot now plays zeros (before the
    // guard: the frame of a lap ago).
    let m = simulate(20_000, SLOT_BYTES, |k| (k * 7 % 10) as f64 * 1.4, &[], 1);
    assert!(m.gate_offs.is_empty(), "{:?}", m.gate_offs);
    assert_eq!(m.guard.missed(), 0);
    assert!(m.blanks_played.iter().all(|s| !m.wrote.contains(s)));
    // Every other wake 20 bytes late (past the next slot boundary): the wake after
    // it skips a slot. Zeros there, never a miss.
    let m = simulate(20_000, SLOT_BYTES, |k| (k % 2) as f64 * 20.0, &[], 1);
    assert!(m.gate_offs.is_empty(), "{:?}", m.gate_offs);
    assert!(m.blanks_played.len() > 20, "{:?}", m.blanks_played);
    assert!(m.blanks_played.iter().all(|s| !m.wrote.contains(s)));
}

#[test]
fn stall_plays_zeros_never_old_frames_and_drops_the_gate() {
    // Stalls from 20 us to several laps, starting at every phase of the ring.
    for start in (2_000..2_125).step_by(7) {
        for len in [31, 50, 63, 100, 125, 200, 500, 1_300] {
            let m = simulate(5_000, SLOT_BYTES, |_| 0.0, &[(start, start + len)], 1);
            let first_blank = m.blanks_played.iter().copied().find(|&s| s > 10);
            match first_blank {
                None => assert!(m.gate_offs.is_empty(), "{start}+{len}"),
                Some(s) => {
                    // If the gate drops, it is within a half (62.5 bytes) + the
                    // latency of the DMA entering the first slot nobody wrote; a
                    // stall shorter than that may end before a guard run sees it.
                    let at = (s * FRAME_BITS as u64).div_ceil(8);
                    let off = m.gate_offs.first().copied();
                    assert!(
                        off.is_none_or(|o| o >= at && o <= at + 64),
                        "{start}+{len}: blank slot {s} at byte {at}, gate off {off:?}"
                    );
                    if len >= 100 {
                        assert!(off.is_some(), "{start}+{len}: no gate off");
                    }
                    assert_eq!(
                        m.guard.missed() as usize,
                        m.gate_offs.len(),
                        "{start}+{len}: a miss per gate drop"
                    );
                    // The runs of the stall that saw the DMA on an unwritten slot:
                    // all of them but those before that slot, or the last one.
                    if len >= 200 {
                        assert!(
                            m.gate_offs.len() as u64 >= (len - 63) / 63,
                            "{start}+{len}: {:?}",
                            m.gate_offs
                        );
                    }
                }
            }
            // A stall of more than three slot periods always runs dry.
            if len >= 63 {
                assert!(first_blank.is_some(), "{start}+{len}");
            }
            // Resumed: the writer's frames play again, the gate is not dropped again,
            // and the writer's rule lifted the refusal (once per look that saw the
            // count move).
            let resumed = m.gate_offs.last().copied().unwrap_or(0);
            assert!(resumed < start + len + 64, "{start}+{len}: {resumed}");
            assert!(!m.stale, "{start}+{len}: the gate refused for good");
            assert_eq!(m.seen, m.guard.missed());
            assert_eq!(m.restarts > 0, !m.gate_offs.is_empty());
        }
    }
}

#[test]
fn far_behind_writer_and_late_guard() {
    // Stalls of many laps; the guard itself late by up to a few bytes.
    for latency in [0, 2, 5] {
        let m = simulate(
            40_000,
            SLOT_BYTES,
            |_| 0.0,
            &[(3_000, 13_000), (20_000, 20_400)],
            latency,
        );
        assert_eq!(
            m.guard.missed() as usize,
            m.gate_offs.len(),
            "latency {latency}"
        );
        assert!(!m.stale);
        // One gate-rule restart per stall: the writer looks once it runs again.
        assert_eq!(m.restarts, 2, "latency {latency}");
        // During the long stall the gate is refused at every run.
        let during = m
            .gate_offs
            .iter()
            .filter(|&&o| (3_100..13_000).contains(&o))
            .count();
        assert!(during >= (13_000 - 3_100) / 63, "{during}");
    }
}

#[test]
fn writer_finishing_as_the_guard_runs() {
    // The write just before and just after the run at a boundary, every boundary
    // phase: the guard sees the write whole or not at all.
    for f in [125u64 * 40, 125 * 40 + HALF as u64] {
        for order in [false, true] {
            let mut m = Model::new();
            let mut x = 0;
            while x < f - 8 {
                if x % 16 == 0 {
                    m.write(x);
                }
                if x > 0 && (x % 125 == 0 || x % 125 == HALF as u64) {
                    m.run_guard(x);
                }
                m.fetch(x);
                x += 1;
            }
            // Writer late (the last write 8..24 bytes ago), then both at `f`.
            if order {
                m.write(f);
                m.run_guard(f);
            } else {
                m.run_guard(f);
                m.write(f);
            }
            for y in f..f + 250 {
                if y % 16 == 0 {
                    m.write(y);
                }
                if y % 125 == 0 || y % 125 == HALF as u64 {
                    m.run_guard(y);
                }
                m.fetch(y);
            }
            assert!(m.gate_offs.is_empty(), "{f} {order}: {:?}", m.gate_offs);
        }
    }
}

#[test]
fn position_read_before_the_lap_run_counts_the_lap() {
    let mut g = SlotGuard::new();
    g.run(HALF);
    // NDTR reloaded, the transfer-complete run still pending.
    assert_eq!(g.fetched(3), RING_BYTES as u64 + 3);
    assert_eq!(g.dma_slot(3), 8);
    assert_eq!(g.wrote(2, 3), 10);
    g.run(4);
    assert_eq!(g.fetched(4), RING_BYTES as u64 + 4);
}

#[test]
fn stopped_writer_is_no_miss_and_resume_rearms() {
    let mut g = SlotGuard::new();
    for k in 1..20u64 {
        let a = g.run((k * HALF as u64 % RING_BYTES as u64) as usize);
        assert!(!a.gate_off);
    }
    let mut g = SlotGuard::new();
    g.wrote(2, 0);
    g.run(HALF);
    assert_eq!(g.missed(), 1);
    assert!(!g.clear_if(0) && g.clear_if(1));
    g.stop();
    assert!(!g.run(0).gate_off);
    assert_eq!(g.wrote(2, 0), 10);
    // Resumed: no miss while the written slot is ahead; a new one after it.
    assert!(!g.run(20).gate_off);
    assert_eq!(g.missed(), 1);
    assert!(g.run(HALF).gate_off);
    assert_eq!(g.missed(), 2);
}

/// The stale flag's discipline (module docs): a miss between the writer's read of
/// the count and its clear keeps the refusal; the writer's next look lifts it.
#[test]
fn a_miss_between_the_writers_read_and_clear_keeps_the_refusal() {
    let mut g = SlotGuard::new();
    let mut stale = false;
    let mut run = |g: &mut SlotGuard, pos: usize| {
        if g.run(pos).gate_off {
            stale = true;
        }
        stale
    };
    // Slots 0..=2 written; the half run finds the DMA in slot 3: a miss.
    assert_eq!(g.wrote(2, 0), 2);
    assert!(run(&mut g, HALF));
    assert_eq!(g.missed(), 1);
    // The writer wakes (still behind: nothing written since), reads the count,
    // restarts its gate rule ...
    let seen = g.missed();
    // ... and the lap's run comes before its clear: another miss.
    assert!(run(&mut g, 0));
    assert_eq!(g.missed(), 2);
    assert!(!g.clear_if(seen), "a clear by the old count");
    // The next look: the writer writes (DMA in slot 10 of lap 1, byte 40), sees
    // the count moved, restarts again and clears.
    assert_eq!(g.wrote(4, 40), 12);
    let seen = g.missed();
    assert!(g.clear_if(seen));
    // Caught up: no miss at the next run, so the refusal stays lifted.
    assert!(!g.run(HALF).gate_off);
    assert_eq!(g.missed(), seen);
}

#[test]
fn restart_keeps_the_miss_count() {
    let mut g = SlotGuard::new();
    g.wrote(2, 0);
    assert!(g.run(HALF).gate_off);
    g.restart();
    assert_eq!(g.missed(), 1);
    let mut fresh = SlotGuard::new();
    assert_eq!(fresh.missed(), 0);
    // Otherwise a new run: stopped, lap 0.
    assert!(!g.run(HALF).gate_off);
    assert!(!fresh.run(HALF).gate_off);
    assert_eq!(g.fetched(HALF), fresh.fetched(HALF));
}

/// A timer's runs (the firmware's slot timer, `drivers/serial_tx.rs`): every
/// `period` bytes from `phase`, each one late by up to `late` bytes (`late_of`,
/// 0..1, picks how much for the k-th), not locked to the ring's bit clock.
fn timer(
    period: f64,
    phase: f64,
    late: f64,
    late_of: impl Fn(u64) -> f64,
) -> impl FnMut(u64) -> bool {
    let mut k = 0u64;
    move |f| {
        let due = phase + k as f64 * period + late * late_of(k);
        if f as f64 >= due {
            // One run for every tick due (a run that comes late covers the ticks
            // it was late for: a timer's pending flag is one bit).
            while phase + k as f64 * period + late * late_of(k) <= f as f64 {
                k += 1;
            }
            true
        } else {
            false
        }
    }
}

/// A small deterministic spread in 0..1 for the k-th tick's lateness.
fn spread(seed: u64) -> impl Fn(u64) -> f64 {
    move |k| ((k.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ seed) >> 40) as f64 / (1u64 << 24) as f64
}

#[test]
fn runs_at_any_position_keep_an_on_time_writer() {
    // A run at every byte (the densest trigger there is), and timers of several
    // periods and phases: an on-time or jittery writer is never a miss, and the
    // model's every-byte check (old frames) holds.
    let jitters: [&dyn Fn(u64) -> f64; 3] = [&|_| 0.0, &|k| (k * 7 % 10) as f64 * 1.4, &|k| {
        (k % 2) as f64 * 20.0
    }];
    for (j, jitter) in jitters.iter().enumerate() {
        let m = simulate_ticked(20_000, SLOT_BYTES, jitter, &[], 1, |_| true);
        assert!(m.gate_offs.is_empty(), "jitter {j}: {:?}", m.gate_offs);
        assert!(m.blanks_played.iter().all(|s| !m.wrote.contains(s)));
        for period in [12.5, 15.625, 9.3, 15.0] {
            for phase in [0.0, 4.1, 11.7] {
                let t = timer(period, phase, 0.6, spread(j as u64));
                let m = simulate_ticked(20_000, SLOT_BYTES, jitter, &[], 1, t);
                assert!(
                    m.gate_offs.is_empty(),
                    "jitter {j} period {period} phase {phase}: {:?}",
                    m.gate_offs
                );
                assert_eq!(m.guard.missed(), 0);
                assert!(m.blanks_played.iter().all(|s| !m.wrote.contains(s)));
            }
        }
    }
}

/// The new bound: with a run at least once per slot (any phase, any rate of at
/// least one per 15.625 bytes, lateness included), the gate drops no later than
/// one slot after the DMA starts fetching the first slot nobody wrote, and never
/// before (module docs, "Runs at any position").
#[test]
fn a_run_per_slot_drops_the_gate_within_a_slot() {
    // (period, lateness) in bytes: the firmware's 8 us timer (12.5 bytes) late by
    // up to 3 bytes (under 2 us), a timer at the slot rate itself, a fast one.
    for (period, late) in [(12.5, 3.1), (15.625, 0.0), (15.0, 0.6), (6.2, 9.0)] {
        assert!(period + late <= SLOT_BYTES);
        for start in (2_000..2_125).step_by(9) {
            for len in [20, 31, 50, 63, 100, 200, 1_300] {
                for phase in [0.0, 5.5, 10.9] {
                    let t = timer(period, phase, late, spread(start ^ len));
                    let m =
                        simulate_ticked(5_000, SLOT_BYTES, |_| 0.0, &[(start, start + len)], 1, t);
                    let case = format!("{period}+{late} {start}+{len} phase {phase}");
                    let dropped = m.assert_slot_bound(&case);
                    // The first gate drop: not before the DMA reached the first
                    // unwritten slot, within a slot of it.
                    if let Some(&o) = m.gate_offs.first() {
                        let at = m.stale_at[0];
                        assert!(
                            o >= at && o as f64 <= at as f64 + SLOT_BYTES,
                            "{case}: first unwritten slot at {at}, gate off at {o}"
                        );
                    }
                    // Not vacuous: a stall of three slots runs dry, and one that
                    // goes on a slot beyond that drops the gate.
                    if len >= 63 {
                        assert!(!m.stale_at.is_empty(), "{case}");
                    }
                    if len >= 63 + 16 {
                        assert!(dropped > 0, "{case}: no gate off");
                    }
                    assert_eq!(m.guard.missed() as usize, m.gate_offs.len(), "{case}");
                    assert!(!m.stale, "{case}: the gate refused for good");
                    assert_eq!(m.seen, m.guard.missed(), "{case}");
                }
            }
        }
    }
}

/// Why it needs a run per slot: the half-boundary runs alone can leave up to a
/// half (62.5 bytes) between the first unwritten slot and the gate drop, which
/// the bound above excludes (the test above is not vacuous).
#[test]
fn half_runs_alone_can_be_a_half_late() {
    let worst = (2_000..2_125u64)
        .filter_map(|start| {
            let m = simulate(5_000, SLOT_BYTES, |_| 0.0, &[(start, start + 200)], 1);
            Some(m.gate_offs.first()? - m.stale_at.first()?)
        })
        .max();
    assert!(
        worst.is_some_and(|w| w as f64 > 2.0 * SLOT_BYTES),
        "{worst:?}"
    );
}

#[test]
fn blank_slot_clears_only_its_bits() {
    let frames: Vec<Frame> = (0..8u32)
        .map(|k| Frame::new(k * 0x1_2345 + 7, 0xF_FFFF - k, k ^ 0x5_5555).unwrap())
        .collect();
    for k in 0..RING_SLOTS {
        let mut ring = [0xFFu8; RING_BYTES];
        for (s, f) in frames.iter().enumerate() {
            write_slot(&mut ring, s, f).unwrap();
        }
        blank_slot(&mut ring, k).unwrap();
        for (s, f) in frames.iter().enumerate() {
            if s == k {
                assert!(read_slot(&ring, s).is_err(), "slot {k} still decodes");
            } else {
                assert_eq!(
                    read_slot(&ring, s).unwrap(),
                    *f,
                    "slot {s} after blanking {k}"
                );
            }
        }
        for bit in 0..RING_BYTES * 8 {
            let set = ring[bit / 8] & (0x80 >> (bit % 8)) != 0;
            if bit / FRAME_BITS == k {
                assert!(!set, "slot {k} bit {bit}");
            }
        }
    }
    assert!(blank_slot(&mut [0; RING_BYTES], RING_SLOTS).is_err());
}

/// The ring's bits, `laps` times, as 16-bit sample words at `ratio` samples per
/// bit (MSB first).
fn samples(rings: &[[u8; RING_BYTES]], ratio: f64) -> Vec<u16> {
    let bits: Vec<bool> = rings
        .iter()
        .flat_map(|r| (0..RING_BYTES * 8).map(move |b| r[b / 8] & (0x80 >> (b % 8)) != 0))
        .collect();
    let n = (bits.len() as f64 * ratio) as usize / 16;
    (0..n)
        .map(|w| {
            (0..16).fold(0u16, |acc, k| {
                let b = (((w * 16 + k) as f64 + 0.5) / ratio) as usize;
                acc << 1 | u16::from(bits.get(b).copied().unwrap_or(false))
            })
        })
        .collect()
}

#[test]
fn blanked_slots_are_no_frame_on_the_wire() {
    let frame = |k: u32| Frame::new((k * 0x3_0001 + 11) & 0xF_FFFF, k * 977, 0xA_AAAA ^ k).unwrap();
    let ring = |base: u32| {
        let mut r = [0u8; RING_BYTES];
        for s in 0..RING_SLOTS {
            write_slot(&mut r, s, &frame(base + s as u32)).unwrap();
        }
        r
    };
    // Old laps (frames 0..8), then laps of new frames (100..108) with the blanked
    // slots, then laps of newer frames (200..208) in every slot.
    let (a, b, c) = (ring(0), ring(100), ring(200));
    for blanked in [&[5usize][..], &[3, 4], &[0, 1, 2, 3, 4, 5, 6, 7]] {
        let mut bb = b;
        for &s in blanked {
            blank_slot(&mut bb, s).unwrap();
        }
        let mut rings = vec![a; 6];
        rings.extend([bb; 6]);
        rings.extend([c; 6]);
        let words = samples(&rings, 3.2);
        let mut rx = HansRx::new(40_000_000, Mode::Normal { channel: 1 }).unwrap();
        let mut got = Vec::new();
        for part in words.chunks(64) {
            rx.push(&[part; 5], &mut |e| {
                if let RxEvent::Frame(f) = e {
                    got.push(f)
                }
            });
        }
        let which = |f: &Frame| {
            (0..RING_SLOTS as u32)
                .flat_map(|k| [k, 100 + k, 200 + k])
                .find(|&k| frame(k) == *f)
        };
        let ks: Vec<u32> = got.iter().map(|f| which(f).unwrap_or(u32::MAX)).collect();
        // Every frame published is one the rings sent, laps in order (never an
        // old one after a newer), and no frame of a blanked slot.
        assert!(
            ks.iter().all(|&k| k != u32::MAX),
            "{blanked:?}: unknown frame: {ks:?}"
        );
        assert!(
            ks.windows(2).all(|w| w[0] / 100 <= w[1] / 100),
            "{blanked:?}: {ks:?}"
        );
        for &s in blanked {
            assert!(!ks.contains(&(100 + s as u32)), "{blanked:?}: {ks:?}");
        }
        // Not vacuous: the old laps, the new frames not blanked, the newer laps all
        // decode.
        assert!(ks.iter().filter(|&&k| k < 100).count() >= 20, "{ks:?}");
        let shown = ks.iter().filter(|&&k| (100..200).contains(&k)).count();
        assert!(
            (shown > 0) == (blanked.len() < RING_SLOTS),
            "{blanked:?}: {ks:?}"
        );
        assert!(ks.iter().filter(|&&k| k >= 200).count() >= 20, "{ks:?}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Any stalls, wake periods, jitter and guard latency: the DMA never plays a
    /// slot written for an earlier lap (checked at every byte by the model).
    #[test]
    fn never_an_old_frame(
        stalls in proptest::collection::vec((100u64..9_000, 1u64..2_000), 0..4),
        jit in 0.0f64..9.0,
        latency in 0u64..6,
    ) {
        let stalls: Vec<(u64, u64)> = stalls.iter().map(|&(a, l)| (a, a + l)).collect();
        let m = simulate(12_000, SLOT_BYTES, |k| (k % 5) as f64 * jit / 4.0, &stalls, latency);
        prop_assert_eq!(m.guard.missed() as usize, m.gate_offs.len());
        prop_assert!(m.restarts as usize <= stalls.len());
        prop_assert!(!m.stale, "the gate refused for good");
    }

    /// The same with a second trigger at any rate and phase (the slot timer,
    /// runs anywhere between the boundaries): never an old frame, and a gate
    /// drop within a slot of the DMA's entry into each first unwritten slot.
    #[test]
    fn never_an_old_frame_with_a_timer(
        stalls in proptest::collection::vec((100u64..9_000, 1u64..2_000), 0..4),
        jit in 0.0f64..9.0,
        latency in 0u64..6,
        period in 1.0f64..15.625,
        phase in 0.0f64..16.0,
        late_frac in 0.0f64..1.0,
        seed in any::<u64>(),
    ) {
        let late = (SLOT_BYTES - period) * late_frac;
        let stalls: Vec<(u64, u64)> = stalls.iter().map(|&(a, l)| (a, a + l)).collect();
        let t = timer(period, phase, late, spread(seed));
        let m = simulate_ticked(12_000, SLOT_BYTES, |k| (k % 5) as f64 * jit / 4.0, &stalls, latency, t);
        prop_assert_eq!(m.guard.missed() as usize, m.gate_offs.len());
        prop_assert!(m.restarts as usize <= stalls.len());
        prop_assert!(!m.stale, "the gate refused for good");
        m.assert_slot_bound("proptest");
    }
}
