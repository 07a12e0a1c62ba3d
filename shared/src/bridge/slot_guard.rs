//! The slot ring guard: a HANS-100 head is never sent a frame written for an
//! earlier lap of its ring.
//!
//! The HANS-100 head's frames go out of a circular DMA ring of
//! [`RING_SLOTS`] 125-bit slots (firmware `drivers/serial_tx.rs`, `tasks/bridge_hans.rs`):
//! the bridge loop writes each slot two ahead of the DMA and the stream never stops
//! by itself, so a loop that stalls would let the DMA play the frames of the last
//! lap again (positions going back, the gate as it was). The waveform heads' guard
//! ([`super::ring_guard`]) works on whole halves a writer claims; this ring is
//! written slot by slot, so this sibling decides, sans I/O, in slot numbers:
//!
//! - Slots are numbered absolutely from the start of the run (`u64`: no wrap), ring
//!   slot `n % RING_SLOTS` holds slot `n`; the DMA's absolute byte position is the
//!   guard's lap count and DMA_SxNDTR ([`SlotGuard::fetched`]).
//! - The writer publishes the slots it wrote ([`SlotGuard::wrote`]): `written` is one
//!   past the newest. It reads the position and writes in one step the guard cannot
//!   split (the firmware holds a critical section; a slot is ~16 stores).
//! - At every guard run ([`SlotGuard::run`]: the stream's half-transfer and
//!   transfer-complete interrupts, and a timer at least once per slot, below
//!   "Runs at any position") every slot the DMA has wholly fetched since the
//!   last run is set to zero bits ([`crate::hans::frame::blank_slot`]: no start
//!   marker, the head decodes no frame) unless the writer already wrote the slot
//!   that takes its place next lap. A slot is blanked at most 40 us (a half) after
//!   the DMA leaves it and played again 70 us after, so every slot the DMA enters
//!   holds a frame written for this lap or zeros: never an old frame, whatever the
//!   writer does.
//! - If the slot the DMA is fetching was not written for this lap (`written` not
//!   past it) while the writer is sending, the run is a **miss**: the laser gate
//!   goes off and stays refused until the writer has restarted its gate rule.
//!   Every miss is counted ([`SlotGuard::missed`], wrapping `u32`): one per guard
//!   run that turned the gate off (in the firmware up to ~5 per 40 us), so the count
//!   moves with every gate drop, and the firmware reports it in the statistics.
//!   The writer lifts the refusal by that count, as the waveform writer does
//!   ([`super::ring_guard`], "Misses, and lifting the gate refusal"): after a
//!   change of [`SlotGuard::missed`] it restarts its gate rule, then clears only
//!   if [`SlotGuard::clear_if`] the count it read (under the guard's lock): a miss
//!   in between keeps the refusal for its next look. Counting every gate drop (not
//!   once per stall) is what makes that exact: a gate drop that did not move the
//!   count could land after the writer's clear and stay for good.
//!
//! # Races (all host-tested)
//! - The writer finishing as the guard runs: the two never interleave (above), so
//!   the guard sees the write either wholly (the slot counts as written) or not at
//!   all (the write then lands after the blanking, fresh for this lap).
//! - Wrap-around: a position read while a transfer-complete is pending (NDTR
//!   reloaded, the guard not yet run) is below the guard's last one: a lap on.
//! - A far-behind writer: every run blanks what the DMA fetched (at most the whole
//!   ring) and reports a miss at every run of the stall; the writer's late write lands where
//!   its slot number says, ahead of the DMA or (not published in time) on a slot
//!   the guard blanks at its next run.
//! - Resume: the first write re-arms the miss check; the DMA plays zeros until the
//!   writer's first slot (two ahead).
//!
//! # Runs at any position
//! A run decides by absolute numbers only: the DMA's slot from its position and
//! the lap count, `written`, `blanked`. Nothing in it assumes the position is a
//! half boundary, so any number of triggers may run it at any positions, in any
//! order, provided the runs are serialised (one lock) and come more often than
//! once a lap (so a lower position means exactly one lap on, as above):
//! - A run between boundaries blanks the slots wholly fetched since the last run
//!   (a slot whose last bits share a byte with the one being fetched counts only
//!   once that byte is fetched, so the DMA never re-reads what was blanked this
//!   lap); a second run at the same position changes nothing.
//! - The miss check compares the slot being fetched with `written`, wherever the
//!   DMA is in it. So with a run at least once per slot (10 us, the firmware's
//!   slot timer: `drivers/serial_tx.rs` "The slot timer"), the first run after
//!   the DMA starts fetching a slot nobody wrote comes within a slot of it and
//!   sees that slot (or a later one) unwritten: the gate is off at most one slot
//!   after the first stale slot starts (the guard's latency included in that
//!   slot). With the half-boundary runs alone it was up to a half (40 us).
//!
//! Host-tested at every byte and with timers of any rate from one run per slot up,
//! any phase and lateness (the byte model of `tests.rs`).

use crate::hans::frame::{FRAME_BITS, RING_BYTES, RING_SLOTS};

/// What a guard run must do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Actions {
    /// Ring slots to set to zero bits: bit `k` is ring slot `k`.
    pub blank: u8,
    /// Turn the laser gate off and refuse it until the writer restarts its gate rule.
    pub gate_off: bool,
}

/// The guard's state, shared by the writer and the guard interrupt (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlotGuard {
    /// Whole laps of the ring the DMA has fetched, as of the last run.
    laps: u64,
    /// The DMA's byte position in the ring (0..RING_BYTES) at the last run.
    pos: usize,
    /// Every slot below this one was blanked after the DMA fetched it (or written
    /// for its next lap first).
    blanked: u64,
    /// One past the newest slot the writer wrote.
    written: u64,
    /// The writer sends nothing (start-up, or the line stopped: the ring is zeros).
    stopped: bool,
    /// Guard runs that turned the gate off so far (wrapping).
    missed: u32,
}

impl Default for SlotGuard {
    fn default() -> Self {
        Self::new()
    }
}

impl SlotGuard {
    /// At the start of a run: the ring holds zeros, the DMA is at byte 0.
    pub const fn new() -> Self {
        Self {
            laps: 0,
            pos: 0,
            blanked: 0,
            written: 0,
            stopped: true,
            missed: 0,
        }
    }

    /// A new run of the ring (zeros, the DMA at byte 0 again), with the miss count
    /// kept: it counts over every run (module docs).
    pub fn restart(&mut self) {
        *self = Self {
            missed: self.missed,
            ..Self::new()
        };
    }

    /// The DMA's absolute byte position, from `pos` (its ring byte, 0..RING_BYTES,
    /// `RING_BYTES - NDTR`) read now: a position below the last run's is a lap on
    /// (the transfer-complete run is pending).
    pub fn fetched(&self, pos: usize) -> u64 {
        let (laps, pos) = self.lap_of(pos);
        laps * RING_BYTES as u64 + pos as u64
    }

    /// The DMA's lap and ring byte for `pos` read now ([`SlotGuard::fetched`]).
    fn lap_of(&self, pos: usize) -> (u64, usize) {
        let pos = pos.min(RING_BYTES - 1);
        let laps = if pos < self.pos {
            self.laps + 1
        } else {
            self.laps
        };
        (laps, pos)
    }

    /// The absolute number of the slot the DMA is fetching at `pos` (its first slot
    /// not wholly fetched).
    pub fn dma_slot(&self, pos: usize) -> u64 {
        let (laps, pos) = self.lap_of(pos);
        Self::slot_at(laps, pos)
    }

    /// The absolute slot at lap `laps`, ring byte `pos`: a lap is exactly
    /// [`RING_SLOTS`] slots (1000 bits, 125 bytes), so no 64-bit division (a
    /// library call on the Cortex-M7, in a run every 8 us).
    fn slot_at(laps: u64, pos: usize) -> u64 {
        const { assert!(RING_BYTES * 8 == RING_SLOTS * FRAME_BITS) };
        laps * RING_SLOTS as u64 + (pos * 8 / FRAME_BITS) as u64
    }

    /// Misses so far (wrapping; guard runs that turned the gate off): a writer that
    /// sees this change restarts its gate rule, then [`SlotGuard::clear_if`].
    pub fn missed(&self) -> u32 {
        self.missed
    }

    /// Whether the gate refusal may be lifted by a writer that restarted its gate
    /// rule after reading [`SlotGuard::missed`] as `seen`: only if no miss came
    /// since (module docs). The firmware asks under the guard's lock, so no miss
    /// can come between this answer and the clear.
    pub fn clear_if(&self, seen: u32) -> bool {
        self.missed == seen
    }

    /// The writer wrote ring slot `ring_slot` for the absolute slot it makes of it
    /// at `pos` (the position it read before writing, in the same step): the first
    /// slot with that ring index at or after the one the DMA fetched.
    pub fn wrote(&mut self, ring_slot: usize, pos: usize) -> u64 {
        let d = self.dma_slot(pos);
        let ahead =
            (ring_slot % RING_SLOTS + RING_SLOTS - (d % RING_SLOTS as u64) as usize) % RING_SLOTS;
        let n = d + ahead as u64;
        self.written = self.written.max(n + 1);
        self.stopped = false;
        n
    }

    /// The writer stopped sending and zeroed the ring: no miss until it writes again.
    pub fn stop(&mut self) {
        self.stopped = true;
    }

    /// A guard run with the DMA at ring byte `pos` (module docs). The caller carries
    /// out the actions before anything else may write the ring.
    pub fn run(&mut self, pos: usize) -> Actions {
        let (laps, pos) = self.lap_of(pos);
        self.laps = laps;
        self.pos = pos;
        let current = Self::slot_at(laps, pos);
        let mut act = Actions::default();
        // A run late by more than a lap (a stall of the interrupts above the tasks)
        // still blanks every ring slot once.
        let from = self.blanked.max(current.saturating_sub(RING_SLOTS as u64));
        for s in from..current {
            // Ring slot `s % 8` holds slot `s + 8` once the writer wrote that: fresh.
            if self.written <= s + RING_SLOTS as u64 {
                act.blank |= 1 << (s % RING_SLOTS as u64);
            }
        }
        self.blanked = self.blanked.max(current);
        if !self.stopped && self.written <= current {
            // Counted at every gate drop (module docs: the writer's clear by count).
            act.gate_off = true;
            self.missed = self.missed.wrapping_add(1);
        }
        act
    }
}

#[cfg(test)]
mod tests;
