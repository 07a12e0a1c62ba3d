//! When to restart an XY3-100 input session whose lines have fallen out of step
//! (sans-IO policy: periods and time in, a yes / no out).
//!
//! # The problem
//! The receiver ([`super::rx`]) needs byte `i` of every line to come from the same
//! clock edges: the firmware starts every line's SPI slave together and restarts them
//! all after an overrun. A glitch that clocks one SPI but not the others (a spike on
//! one SCK input, an edge one slave misses) leaves that line a bit or more ahead or
//! behind for the rest of the session, without any overrun. The byte and frame-end
//! counts stay plausible, so the receiver cannot tell this from a bad line: it stays
//! locked, that line fails its check every period, and no period is forwarded again.
//! A receiver-side bit offset cannot repair it (the offset is common to all lines by
//! design, see `rx` "Partial bytes and bit slips"); only restarting the SPIs
//! together brings the lines back in step.
//!
//! Worse, a line one bit out of step does not fail *every* period: the shifted
//! bits pass the 24-bit checks now and then (up to one time in eight for random
//! data, the residual risk in `rx`; 36 of 699 periods in the test), and such a
//! period would carry a wrong position. A rule that waits for "no good
//! period" would never fire, and the bridge would keep running on those.
//!
//! # The rule
//! [`StepWatch::period`] sees every period the receiver reports and hands its events
//! on. A bad period (some line failed) opens a *window*; only [`GOOD_RUN`]
//! consecutive good periods close it again (an in-step link produces them at once, a
//! shifted line about once in `8^8` periods).
//! - Once the window holds [`SUSPECT_BAD`] bad periods, the session is *suspect*:
//!   good periods are withheld (a `Dropped` fault on `Framing` instead of the frame)
//!   until the window closes. Sporadic noise (bad periods more than `GOOD_RUN`
//!   apart) never gets there; a burst costs `GOOD_RUN` extra periods after it.
//! - Once the window is `limit_ns` old ([`OUT_OF_STEP_NS`] in the firmware) *and*
//!   holds at least [`MIN_BAD_PERIODS`] bad periods (bytes are flowing: a controller
//!   that pauses or stops delivers no periods, and a restart would not help it), it
//!   answers "restart" and reports a `Resync` on `Framing`. The input is lost by then
//!   (the bridge's `failsafe.input_timeout_us` is 1 ms by default, and it needs
//!   `recovery_frames` consecutive frames to run again), so the restart costs nothing
//!   that still worked; at 2 ms it comes well inside the hold time (10 ms), so a
//!   head whose input got out of step recovers without parking.
//!
//! - A decoded period counts as bad too, and is withheld (`Dropped`), when its
//!   frame kinds are not what a controller sends: a command on a line other than
//!   X without the same command on X (§5.1.1: commands go on X, and may be
//!   repeated on the other lines). A shifted line that passes its check by
//!   chance often reads a command (one bit late on 24-bit frames it always
//!   does: the frame's size bit 0 becomes the second bit); an in-step link
//!   never trips it. Measured (400 glitches, below): 17 wrong frames in 16 runs
//!   without it, 11 in 11 with it (before the open-window rule below); nothing
//!   more lost on clean lines.
//! - A good period the rule passes is *held* until the next period confirms it:
//!   the next one good releases it, the next one bad turns it into a `Dropped`
//!   fault on `Framing`. The first periods of a shift are the ones the suspect
//!   rule cannot withhold yet (no bad period seen), and a chance pass is followed
//!   by a failing period most of the time, so a wrong position needs two chance
//!   passes in a row to get out. Measured on the host pipeline (400 random SCK
//!   glitches): 17 wrong frames in 16 runs, against 71 in 60 without it; the
//!   frame a stuck line breaks in no longer gets out. Its cost: one period of
//!   latency, and on a noisy in-step line the good period before each bad one
//!   (an isolated bad period costs 2 periods, not 1). Lowering [`SUSPECT_BAD`]
//!   instead removes fewer (31 escapes at 1, 48 at 2) and makes every isolated
//!   bad period withhold a good run (9 periods lost, not 1). What is left is
//!   mostly the glitch's own frame of a glitch the line heals from at once (an
//!   SPI that drops partial bytes, 1..3 extra edges): the next period is in step
//!   and confirms it. Only a per-line count of clock edges would tell.
//! - Inside an open window (a bad period seen, no run of [`GOOD_RUN`] since) a
//!   good period needs [`CONFIRM_OPEN`] (2) good direct successors, not one. A
//!   lasting shift opens the window with its first bad period, and its chance
//!   passes before [`SUSPECT_BAD`] then need three in a row to get out, not two
//!   (about one in 8^3 instead of 8^2 per start for random 24-bit data, the
//!   second and third being chance passes too). Measured (400 glitches): 9
//!   wrong frames in 9 runs, was 11 in 11; the two it removes were lasting
//!   shifts (24-bit, slaves dropping partial bytes, 1..2 missed edges: the line
//!   a byte early) whose second and third periods passed. Restart and resume
//!   times, frames lost and clean lines unchanged. Its cost: one more period of
//!   latency while a window is open (the held periods go out two periods after
//!   they came until the good run closes it, then one again: two at once), and
//!   on a noisy in-step line a bad period within two periods of an earlier one
//!   also drops the second held period. Bad periods [`GOOD_RUN`] + 1 or more
//!   apart cost what they did (the window closes before the next one). The 9
//!   left are all the glitch's own frame (24-bit, partial bytes dropped, 1..3
//!   extra edges): no period before or after it fails, so nothing the watch
//!   sees can refuse it, and nothing in the bytes either (the slave dropped the
//!   extra bits with the frame's tail; only the content is spoilt). The same
//!   400 glitches with every slave dropping partial bytes: 10 wrong frames;
//!   with every slave keeping them, or without SS
//!   (`controller.xy3.select = "always"`, where nothing heals and every glitch
//!   restarts): 3 (two glitch frames confirmed by a chance pass of the first
//!   shifted period, one lasting shift). See README "Known limits".
//! - Only the held period's direct successor confirms it: a good period whose
//!   bytes do not begin where the held one's ended (a new input session, a half
//!   the bridge never got, anything that gave the receiver a new byte count)
//!   says nothing about the line before the gap, and the held period is dropped.
//!   It costs at most the one held frame per gap, on top of the half or session
//!   the gap lost (16..24 frames): measured with every tenth half lost on clean
//!   lines, +1 frame per gap whose next period is whole (32-bit frames, a half
//!   ending on a frame boundary), none where the gap cuts a frame (that cut
//!   period fails and drops the held one under either rule).
//! - A stream that stops leaves its last good period held: [`StepWatch::release`]
//!   lets it out unconfirmed once it has waited [`CONFIRM_NS`] (0.5 ms) with no
//!   period after it. That is longer than a running stream ever leaves a period
//!   waiting (the firmware drains a 64-byte half, at most 213 us of 24-bit
//!   frames at 100 kHz, at its next 200-250 us batch), and short enough for a
//!   last frame (a laser-off command, say) to reach the head before the bridge's
//!   input timeout (1 ms by default) makes it hold. The gap rule does not touch
//!   it: only a period drops a held one, and a stopped stream brings none.
//!
//! A cause a restart cannot fix (an unplugged or broken listed line, a noisy line)
//! would restart the session again and again; each restart not followed by a closed
//! window doubles the limit, up to `2^`[`MAX_BACKOFF`] times.

use super::rx::{Period, RxError};
use super::Frame;
use crate::model::{FaultKind, Line, LineEvent};

/// Default window age before a restart (2 ms: 200 periods at 100 kHz).
pub const OUT_OF_STEP_NS: u64 = 2_000_000;
/// Bad periods needed in the window before a restart: proof that frames arrive.
pub const MIN_BAD_PERIODS: u32 = 16;
/// Bad periods in the window that make the session suspect.
pub const SUSPECT_BAD: u32 = 3;
/// Longest a good period waits for the next one to confirm it (0.5 ms, see the
/// module docs): then it goes out unconfirmed.
pub const CONFIRM_NS: u64 = 500_000;
/// Good direct successors a period the rule passed needs while a window is open
/// (a bad period seen, no good run since); 1 otherwise.
pub const CONFIRM_OPEN: u8 = 2;
/// Consecutive good periods that close the window.
pub const GOOD_RUN: u8 = 8;
/// The limit doubles at most this many times while restarts do not help.
pub const MAX_BACKOFF: u8 = 6;

/// The restart policy of one XY3-100 input (see the module docs).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepWatch {
    limit_ns: u64,
    /// Time of the window's first bad period (`None`: no window open).
    bad_since: Option<u64>,
    /// Bad periods in the window.
    bad: u32,
    /// Consecutive good periods.
    good_run: u8,
    /// Restarts since the last closed window (the limit's doubling).
    backoff: u8,
    /// The oldest good period the rule passed that waits for the periods after
    /// it to confirm it.
    held: Option<Held>,
    /// The one after it, also waiting (only inside an open window, where a
    /// period needs [`CONFIRM_OPEN`] = 2 successors: at most two wait).
    second: Option<Held>,
}

/// A good period waiting for its confirmation.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Held {
    period: Period,
    /// When it came.
    at: u64,
    /// Good direct successors it still needs.
    need: u8,
}

impl StepWatch {
    /// A watch that asks for a restart once a window is `limit_ns` old.
    pub const fn new(limit_ns: u64) -> Self {
        StepWatch {
            limit_ns,
            bad_since: None,
            bad: 0,
            good_run: 0,
            backoff: 0,
            held: None,
            second: None,
        }
    }

    /// The current limit: `limit_ns`, doubled per restart that did not help.
    pub const fn limit_ns(&self) -> u64 {
        self.limit_ns.saturating_mul(1 << self.backoff)
    }

    /// Whether good periods are withheld now.
    pub const fn suspect(&self) -> bool {
        self.bad >= SUSPECT_BAD
    }

    /// One period the receiver reported at `now_ns` (non-decreasing). It settles
    /// the periods held before it (one, or two inside an open window): a good one
    /// that directly follows them counts as a confirmation for each, and releases
    /// its events to `emit` once it has had its [`CONFIRM_OPEN`] or 1; a bad one,
    /// or one after a gap in the byte stream, turns each into a `Dropped` fault on
    /// `Framing`. Then its own events go out (not decoded), or it is held for the
    /// next ones to confirm (good, passed by the rule), or withheld (good but suspect, or decoded with frame kinds no
    /// controller sends: a `Dropped` fault). Returns whether the
    /// input session should be restarted now (a `Resync` fault on `Framing` has
    /// been emitted for it); the window then starts over.
    pub fn period(
        &mut self,
        now_ns: u64,
        period: &Period,
        mut emit: impl FnMut(LineEvent),
    ) -> bool {
        let decoded = period.all_ok();
        let good = decoded && kinds_agree(period);
        let (pass, restart) = self.outcome(now_ns, good);
        if let Some(h) = self.held.as_mut() {
            // The waiting periods are contiguous (each directly follows the one
            // before it): this one confirms both or neither.
            let last_end = self.second.as_ref().map_or(h.period.end, |s| s.period.end);
            if good && start(period) == Some(last_end) {
                h.need = h.need.saturating_sub(1);
                if let Some(s) = self.second.as_mut() {
                    s.need = s.need.saturating_sub(1);
                }
                // The oldest needs the fewest: release from the front.
                if h.need == 0 {
                    h.period.for_each_event(&mut emit);
                    // In step, nothing else waits: no move of a period.
                    if self.second.is_none() {
                        self.held = None;
                    } else if let Some(s) = self.second.as_ref().filter(|s| s.need == 0) {
                        s.period.for_each_event(&mut emit);
                        self.held = None;
                        self.second = None;
                    } else {
                        self.held = self.second.take();
                    }
                }
            } else {
                self.held = None;
                emit(dropped());
                if self.second.take().is_some() {
                    emit(dropped());
                }
            }
        }
        if !decoded {
            period.for_each_event(&mut emit);
        } else if !good {
            emit(dropped());
        } else if pass {
            // Inside an open window (a bad period seen, the good run not yet
            // made) a period needs more confirmation (see the module docs).
            let need = if self.bad_since.is_some() {
                CONFIRM_OPEN
            } else {
                1
            };
            let new = Held {
                period: *period,
                at: now_ns,
                need,
            };
            if self.held.is_none() {
                self.held = Some(new);
            } else if self.second.is_none() {
                self.second = Some(new);
            } else {
                // Cannot happen: a period that finds one waiting needs more than
                // one successor only inside an open window, where 2 suffice, so
                // the older one went out or was dropped by now.
                emit(dropped());
            }
        } else {
            emit(dropped());
        }
        if restart {
            emit(LineEvent::Fault {
                line: Line::Framing,
                kind: FaultKind::Resync,
            });
        }
        restart
    }

    /// No period came since the held ones: once the newest has waited
    /// [`CONFIRM_NS`] (the controller paused or stopped), their events go to
    /// `emit` unconfirmed, oldest first.
    /// Call it whenever the input has been looked at (also with nothing new), at
    /// `now_ns`, after the periods that arrived.
    pub fn release(&mut self, now_ns: u64, mut emit: impl FnMut(LineEvent)) {
        // The newest waiting period came last: once it has waited, so have all.
        if self
            .newest()
            .is_some_and(|h| now_ns.saturating_sub(h.at) >= CONFIRM_NS)
        {
            for h in [self.held.take(), self.second.take()].iter().flatten() {
                h.period.for_each_event(&mut emit);
            }
        }
    }

    /// When the held periods (if any) go out unconfirmed: the newest one's time
    /// plus [`CONFIRM_NS`].
    pub fn release_due(&self) -> Option<u64> {
        self.newest().map(|h| h.at.saturating_add(CONFIRM_NS))
    }

    /// The newest period waiting for its confirmation.
    fn newest(&self) -> Option<&Held> {
        self.second.as_ref().or(self.held.as_ref())
    }

    /// The rule on a period's outcome (`good`: every line decoded). Returns (a good
    /// period may pass, restart now).
    pub fn outcome(&mut self, now_ns: u64, good: bool) -> (bool, bool) {
        if good {
            self.good_run = self.good_run.saturating_add(1);
            if self.good_run >= GOOD_RUN {
                self.bad_since = None;
                self.bad = 0;
                self.backoff = 0;
            }
            return (!self.suspect(), false);
        }
        self.good_run = 0;
        let since = *self.bad_since.get_or_insert(now_ns);
        self.bad = self.bad.saturating_add(1);
        let due = now_ns.saturating_sub(since) >= self.limit_ns() && self.bad >= MIN_BAD_PERIODS;
        if due {
            // A new window for the new session, still suspect: its first periods
            // pass once they make a good run.
            self.bad_since = None;
            self.bad = SUSPECT_BAD;
            self.backoff = (self.backoff + 1).min(MAX_BACKOFF);
        }
        (false, due)
    }
}

/// The event of a period the bridge does not get: withheld by the watch (it
/// failed no check, but the watch does not trust it), or lost with the bytes
/// around a gap in the input (a new session, a half the bridge never saw).
pub const fn dropped() -> LineEvent {
    LineEvent::Fault {
        line: Line::Framing,
        kind: FaultKind::Dropped,
    }
}

/// Whether a decoded period's frame kinds are what a controller can send: a
/// command goes on X and may be repeated on the other lines (§5.1.1), so a
/// command on another line needs the same command on X. A line out of step
/// reads bits of two frames, and a period it passes by chance breaks this now
/// and then (a 24-bit line one bit late always reads a command, its second bit
/// being the frame's size bit 0); an in-step link never does.
fn kinds_agree(period: &Period) -> bool {
    let code = |r: &Option<Result<Frame, RxError>>| match r {
        Some(Ok(Frame::Command24(code) | Frame::Command32 { code, .. })) => Some(*code),
        _ => None,
    };
    let x = period.lines.first().and_then(code);
    period
        .lines
        .iter()
        .skip(1)
        .filter_map(code)
        .all(|c| Some(c) == x)
}

/// Where a good period's bytes begin: its end less its frame's length (X's
/// frame: every line of a period has the same byte count). `None` for a period
/// without a frame on X (not good).
fn start(period: &Period) -> Option<u32> {
    match period.lines.first() {
        Some(Some(Ok(f))) => Some(period.end.wrapping_sub(u32::from(f.size().bits() / 8))),
        _ => None,
    }
}

#[cfg(test)]
mod tests;
