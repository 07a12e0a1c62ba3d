//! The output ring guard: a head is never sent words the DMA already played.
//!
//! A waveform head's words go out of a circular DMA ring of two halves
//! (firmware `drivers/wave_out.rs`): the DMA plays one half while the bridge loop
//! writes the other, and a circular stream never stops by itself. If the loop stalls
//! (it runs at the line executor's priority: anything above it can hold it) and the
//! DMA comes back to a half the loop did not refill, it would play that half's old
//! words again: frames one and two half periods old, positions going back, with the
//! laser gate still on. This module decides, sans I/O, what the firmware's guard (the
//! stream's own half-transfer / transfer-complete interrupt, above every task) and
//! the writer do so that never happens:
//!
//! - the writer **claims** the half it wants to write ([`RingGuard::claim`]): only the
//!   half after the one the DMA plays, and only while at least a margin of that half
//!   is left to play, so the copy (short, shielded from everything but the
//!   interrupts above the tasks) ends before the DMA gets there; then it **fills** it
//!   ([`RingGuard::fill`]);
//! - at every **boundary** (the DMA enters the next half, [`RingGuard::boundary`]) the
//!   guard checks that the half now playing was filled for this lap. If it was, the
//!   first [`LEAD_WORDS`] of the half just played are set to the idle word (the
//!   writer refills the whole half after this, so on time this costs 32 stores). If
//!   it was not (a **miss**), the half now playing is set to idle from where the DMA
//!   is (its lead is idle already: it covers the interrupt's latency), the other half
//!   (the words just played, old by the next lap) wholly, and the laser gate goes
//!   off. The head then gets idle words (no clock edges: it holds its last
//!   position) until the writer fills a half again.
//!
//! Halves are numbered absolutely from the start of the run (`u64`: no wrap); ring
//! half `n % 2` holds half `n`. Halves 0 and 1 are the idle pre-fill.
//!
//! # Races (all host-tested)
//! - The writer finishing just as the boundary comes: the guard runs at a higher
//!   priority than the writer, so one of them is first. A claim is refused while a
//!   boundary is pending (the DMA already in the other ring half: `dma_half` is not
//!   the half the guard saw last), so a half is never claimed after the DMA entered
//!   it. A claimed half the DMA enters before its fill (only a stall of the
//!   interrupts above the tasks longer than the margin can do that) is a miss: the
//!   guard blanks it, and the late fill reports [`Fill::Torn`]: the writer blanks
//!   the whole half again after its copy (its words may have landed in front
//!   of the DMA), so at worst a fragment of a **new** batch is played, never old
//!   words.
//! - A writer far behind: every claim of a half the DMA already entered is
//!   [`Claim::Late`] with the half it claims next, the one after the next (so that
//!   its next batch, made in the meantime, is not late again); the batch is dropped
//!   (the caller counts an underrun), and the halves it missed play idle.
//! - Catch-up: the head gets fresh words again two to three half periods after the
//!   writer runs again (the first batch it makes after the late one).
//!
//! # Misses, and lifting the gate refusal
//! Every boundary that finds its half unfilled is a **miss**: it turns the gate off,
//! and [`RingGuard::missed`] counts it (wrapping `u32`; one per half played idle,
//! the firmware reports it in the statistics). The firmware keeps a stale flag that
//! refuses the gate from the guard's miss until the writer has restarted its gate
//! rule. The writer clears it by the miss count, never unconditionally: it looks at
//! [`RingGuard::missed`] after every batch; when the count moved from the one it
//! last acted on, it restarts its gate rule and then lifts the refusal with
//! [`RingGuard::clear_if`] and the count it read, under the guard's lock. A miss
//! between its read and its clear (the guard runs above the writer) changes the
//! count, so the refusal stays, and the writer's next look restarts the rule again.
//! Why not clear on the writer's own [`Claim::Late`]: the late claim skips the
//! next half (it claims the one after), so the boundary into that half is one more
//! miss *after* the writer saw its underrun; a clear at the underrun left the flag
//! set by that miss for good (the gate refused until the next underrun).
//! [`RingGuard::restart`] starts a new run of the ring and keeps the count, so the
//! statistics never go back.

/// Words at the start of each half set to idle when the DMA leaves it: they cover
/// the guard interrupt's latency when the DMA comes back to an unfilled half (at
/// 8 MHz ticks 32 words are 4 us; the guard runs well under 1 us after the boundary
/// unless other interrupts of its priority are ahead of it).
pub const LEAD_WORDS: usize = 32;

/// The answer to a [`RingGuard::claim`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Claim {
    /// Write the half now, then [`RingGuard::fill`] it.
    Granted,
    /// Not yet: the DMA still plays the half before the one before it, or a
    /// boundary is pending. Retry after the next boundary.
    Wait,
    /// The half asked for is (or is about to be) played already: drop the batch
    /// (an underrun) and claim `next` instead: the half after the next one, so the
    /// next batch has a whole half period to be made.
    Late {
        /// The first half that may still be claimed.
        next: u64,
    },
}

/// The answer to a [`RingGuard::fill`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fill {
    /// The half holds the new words and plays as written.
    Done,
    /// The DMA entered the half before the fill (the guard took the claim back and
    /// blanked it): set the whole half to idle again (behind the DMA that is
    /// harmless, in front of it the copy's words must not play on).
    Torn,
}

/// What the guard must do at a boundary, in this order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Actions {
    /// Set the first [`LEAD_WORDS`] of this ring half (0 or 1) to idle.
    pub blank_lead: Option<usize>,
    /// Set this ring half to idle from the DMA's position on (at least from
    /// [`LEAD_WORDS`]) to its end.
    pub blank_rest: Option<usize>,
    /// Set this whole ring half to idle.
    pub blank_all: Option<usize>,
    /// Turn the laser gate off.
    pub gate_off: bool,
}

/// The guard's state, shared by the writer and the guard interrupt (module docs).
/// The firmware keeps it in a critical section; every call is a few compares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RingGuard {
    /// The half the DMA plays.
    playing: u64,
    /// Every half below this one holds its own words (written, or the pre-fill).
    filled: u64,
    /// The ring half holds idle words only.
    blank: [bool; 2],
    /// The half the writer is copying.
    claimed: Option<u64>,
    /// Halves the DMA entered unfilled (wrapping count).
    missed: u32,
}

impl Default for RingGuard {
    fn default() -> Self {
        Self::new()
    }
}

impl RingGuard {
    /// At the start of a run: the DMA plays half 0 of the idle pre-fill.
    pub const fn new() -> Self {
        Self {
            playing: 0,
            filled: 2,
            blank: [true, true],
            claimed: None,
            missed: 0,
        }
    }

    /// The half the DMA plays.
    pub fn playing(&self) -> u64 {
        self.playing
    }

    /// A new run of the ring (the DMA at half 0 of the idle pre-fill again), with
    /// the miss count kept: it counts over every run (module docs).
    pub fn restart(&mut self) {
        *self = Self {
            missed: self.missed,
            ..Self::new()
        };
    }

    /// Halves the DMA entered without their words so far (wrapping; every one
    /// turned the gate off): a writer that sees this change has missed its
    /// deadline and restarts its gate rule (module docs).
    pub fn missed(&self) -> u32 {
        self.missed
    }

    /// Whether the gate refusal may be lifted by a writer that restarted its gate
    /// rule after reading [`RingGuard::missed`] as `seen`: only if no miss came
    /// since (module docs). The firmware asks under the guard's lock, so no miss
    /// can come between this answer and the clear.
    pub fn clear_if(&self, seen: u32) -> bool {
        self.missed == seen
    }

    /// The DMA has entered the next half. The caller carries out the returned
    /// actions before anything else may write the ring.
    pub fn boundary(&mut self) -> Actions {
        self.playing += 1;
        let slot = (self.playing % 2) as usize;
        let other = 1 - slot;
        let mut act = Actions::default();
        if self.filled > self.playing {
            // On time. The half just played is the writer's next: its lead goes idle
            // now, before the writer may claim it, in case the writer misses it.
            if !self.blank[other] {
                act.blank_lead = Some(other);
            }
            return act;
        }
        // A miss: this half holds words of two halves ago (or idle).
        self.missed = self.missed.wrapping_add(1);
        if self.claimed == Some(self.playing) {
            self.claimed = None;
        }
        if !self.blank[slot] {
            act.blank_rest = Some(slot);
            self.blank[slot] = true;
        }
        if !self.blank[other] {
            act.blank_all = Some(other);
            self.blank[other] = true;
        }
        act.gate_off = true;
        act
    }

    /// The writer asks for half `n`. `dma_half` is the ring half (0 / 1) the DMA's
    /// position is in now, `left` the words it has still to play there, `margin`
    /// the words a copy needs at most (module docs).
    pub fn claim(&mut self, n: u64, dma_half: usize, left: usize, margin: usize) -> Claim {
        if dma_half != (self.playing % 2) as usize {
            // The DMA crossed a boundary the guard has not handled yet.
            return Claim::Wait;
        }
        let next = self.playing + 1;
        // A late writer skips to the half after the next: the caller then has at
        // least the rest of the playing half and the whole next one to make its
        // next batch, so it is not late again by the time that batch is ready.
        let resume = Claim::Late {
            next: self.playing + 2,
        };
        if n < next {
            return resume;
        }
        if n > next {
            return Claim::Wait;
        }
        if left < margin {
            // Too close: the DMA would reach the half during the copy.
            return resume;
        }
        self.claimed = Some(n);
        Claim::Granted
    }

    /// The writer has copied half `n` (claimed before).
    pub fn fill(&mut self, n: u64) -> Fill {
        let slot = (n % 2) as usize;
        if self.claimed == Some(n) {
            self.claimed = None;
            self.filled = n + 1;
            self.blank[slot] = false;
            Fill::Done
        } else {
            // The guard revoked the claim: the writer blanks the half again, which
            // leaves it idle.
            self.blank[slot] = true;
            Fill::Torn
        }
    }
}

#[cfg(any(test, feature = "vectors"))]
#[doc(hidden)]
pub mod model;
#[cfg(test)]
mod tests;
