//! Per-line and per-bridge counters. They are `u64` because a `u32` counting every
//! frame of a 100 kHz link fills up in 12 hours, and a bridge runs for years: a
//! counter stuck at its maximum would make the once-a-second rates read zero. They
//! still saturate instead of wrapping (unreachable at u64): a wrapped error counter
//! would read as "few errors" on a bad link.

use crate::model::{Axis, FaultKind, Line};

/// Fault counts of one input line.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LineCounters {
    /// Frames that failed their check (parity, complement, fixed bits, header).
    pub check_failed: u64,
    /// Truncated, overlong or misaligned frames.
    pub framing: u64,
    /// Losses and recoveries of alignment.
    pub resyncs: u64,
    /// Input discarded undecoded (overrun, garbage, a lost DMA half).
    pub dropped: u64,
    /// HANS-100 channels: frame periods the channel delivered no pattern for (dead,
    /// stuck, unplugged, not aligned), counted every such period.
    pub missing: u64,
    /// Verified channels that disagreed / votes without majority.
    pub disagree: u64,
}

impl LineCounters {
    fn count(&mut self, kind: FaultKind) {
        let c = match kind {
            FaultKind::CheckFailed => &mut self.check_failed,
            FaultKind::Framing => &mut self.framing,
            FaultKind::Resync => &mut self.resyncs,
            FaultKind::Dropped => &mut self.dropped,
            FaultKind::Missing => &mut self.missing,
            FaultKind::Disagree => &mut self.disagree,
        };
        *c = c.saturating_add(1);
    }

    /// Every fault of this line.
    pub fn total(&self) -> u64 {
        self.check_failed
            .saturating_add(self.framing)
            .saturating_add(self.resyncs)
            .saturating_add(self.dropped)
            .saturating_add(self.missing)
            .saturating_add(self.disagree)
    }
}

/// Number of line slots: 5 axes, 5 HANS channels, framing, status, backchannel and
/// one for a HANS channel number outside 1..=5 (a receiver bug, still counted).
const LINES: usize = 14;

/// The bridge's counters.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    lines: [LineCounters; LINES],
    /// Valid frames received from the controller.
    pub frames_ok: u64,
    /// Valid frames received while the link was not running (fail-safe states,
    /// recovery hysteresis): not forwarded.
    pub not_forwarded: u64,
    /// Free-running output slots that repeated the last positions (input slower).
    pub repeated: u64,
    /// Input frames replaced by a newer one before an output slot (input faster).
    pub skipped: u64,
    /// Commands that the head protocol cannot carry, or that were lost (skipped,
    /// received while not running).
    pub commands_not_carried: u64,
    /// Commands forwarded to the head.
    pub commands_forwarded: u64,
    /// Laser-control items not forwarded to the head (exposed as bridge outputs).
    pub laser_not_carried: u64,
    /// Transitions from running into the fail-safe states.
    pub input_losses: u64,
    /// Transitions back to running.
    pub recoveries: u64,
    /// Times the head's status was declared lost.
    pub status_losses: u64,
}

/// Slot of a line in the counter array.
const fn slot(line: Line) -> usize {
    match line {
        Line::Axis(a) => a.index(),
        Line::HansChannel(c @ 1..=5) => 4 + c as usize,
        Line::HansChannel(_) => 13,
        Line::Framing => 10,
        Line::Status => 11,
        Line::Backchannel => 12,
    }
}

/// Adds one to a saturating counter.
#[inline(always)]
pub(crate) fn bump(c: &mut u64) {
    // Same as `saturating_add(1)`, which the compiler turns into a 65-bit sum and two
    // selects; this is one compare of the carry.
    if let Some(n) = c.checked_add(1) {
        *c = n;
    }
}

impl Counters {
    /// The fault counts of `line`.
    pub fn line(&self, line: Line) -> LineCounters {
        self.lines.get(slot(line)).copied().unwrap_or_default()
    }

    /// Counts a fault on `line`.
    pub fn fault(&mut self, line: Line, kind: FaultKind) {
        if let Some(l) = self.lines.get_mut(slot(line)) {
            l.count(kind);
        }
    }

    /// Frames with a check failure on X, Y, Z, U, W as the bridge counted them (the
    /// XY3-100 FRAME_ERROR_COUNT the bridge reports towards an XY3-100 controller),
    /// saturated to the packet's `u32` fields.
    pub fn axis_check_failures(&self) -> [u32; 5] {
        Axis::ALL.map(|a| u32::try_from(self.line(Line::Axis(a)).check_failed).unwrap_or(u32::MAX))
    }
}

#[cfg(test)]
mod tests {
    use super::bump;

    /// `bump` counts and sticks at the maximum instead of wrapping to 0.
    #[test]
    fn bump_counts_and_saturates() {
        let mut c = 0;
        bump(&mut c);
        assert_eq!(c, 1);
        let mut m = u64::MAX - 1;
        bump(&mut m);
        assert_eq!(m, u64::MAX);
        bump(&mut m);
        assert_eq!(m, u64::MAX);
    }
}
