//! Link supervision: the input-loss / hold / safe / recovery state machine and the
//! head-status watchdog (the table is in the [module docs](super)).
//!
//! With the watchdog on (`status_timeout_us != 0`) the head's status is *known*
//! only from its first valid status on and until it is declared lost: before the
//! first one the head may be reporting an alarm nobody has decoded yet, so the
//! laser gate (with `off_on_head_alarm`) waits for it. That start-up wait is not an
//! alarm: `STATUS_LOST` still comes only after the timeout. With the watchdog off
//! no status is expected, and the status counts as known throughout.
//!
//! Times are nanoseconds from any monotonic clock. A clock that goes backwards
//! counts as no time passed (saturating differences), so it can delay an alarm by
//! the size of the jump but never raise a false recovery.
//!
//! # Cost
//! [`Supervisor::poll`] runs twice per frame (event and output slot). While running
//! with fresh input and status it can change nothing until the earlier of the two
//! deadlines, so it keeps that instant (`quiet_until`, refreshed after every change)
//! and returns at once before it: one 64-bit compare instead of the full rules. At
//! and after the instant the full rules run, so the outcome is the same either way.
//! A valid frame while running leaves the instant where it is (the input deadline
//! only moves later; unless the clock went back): the rules then run once per input
//! timeout, find the input fresh and set the next instant, instead of every frame
//! re-arming it (~10 instructions a frame on the worst path, for one pass of the
//! rules per millisecond at the default timeout).

use super::config::FailSafe;

/// The link states of the bridge (see the state machine table in the module docs).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LinkState {
    /// Valid input arrives; frames are forwarded; the laser gate may be on.
    Running,
    /// Input lost; the last valid positions are repeated until the hold time ends.
    Holding,
    /// Input lost (or never seen) and the hold time over: park or stop.
    Safe,
}

/// What one call changed, for the engine's counters and clean-up.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub(crate) struct Changes {
    /// Running -> Holding / Safe happened.
    pub lost: bool,
    /// The head status was declared lost.
    pub status_lost: bool,
}

/// The supervisor.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) struct Supervisor {
    state: LinkState,
    /// When `Holding` ends.
    hold_end_ns: u64,
    /// Arrival of the last valid input frame.
    last_valid_ns: Option<u64>,
    /// Consecutive valid frames seen outside `Running`.
    run: u32,
    timeout_ns: u64,
    hold_ns: u64,
    recovery_frames: u32,
    status_timeout_ns: u64,
    /// Last head status, or the first time the supervisor saw the clock.
    status_ref_ns: Option<u64>,
    status_lost: bool,
    /// The watchdog is on and no valid head status arrived since start-up or since
    /// it was declared lost (kept in this sense, not as "known", so the gate's
    /// test has the shape and cost of a plain flag).
    status_unknown: bool,
    /// Before this instant `poll` cannot change anything (0: always run the rules).
    quiet_until: u64,
    /// The status watchdog's part of `quiet_until` (kept for `valid`'s update).
    status_quiet: u64,
}

const NS_PER_US: u64 = 1_000;

impl Supervisor {
    /// A supervisor in [`LinkState::Safe`]: at power-up there is no valid position
    /// to hold, and the controller must prove its link first.
    pub fn new(f: &FailSafe) -> Self {
        Supervisor {
            state: LinkState::Safe,
            hold_end_ns: 0,
            last_valid_ns: None,
            run: 0,
            timeout_ns: u64::from(f.input_timeout_us) * NS_PER_US,
            hold_ns: u64::from(f.hold_us) * NS_PER_US,
            recovery_frames: f.recovery_frames.max(1),
            status_timeout_ns: u64::from(f.status_timeout_us) * NS_PER_US,
            status_ref_ns: None,
            status_lost: false,
            status_unknown: f.status_timeout_us != 0,
            quiet_until: 0,
            status_quiet: 0,
        }
    }

    /// Recomputes `quiet_until` after a change. Only the running state gets a quiet
    /// interval; "never" is `u64::MAX`, which at worst runs the rules once too often.
    fn refresh(&mut self) {
        self.status_quiet = match self.status_ref_ns {
            _ if self.status_timeout_ns == 0 || self.status_lost => u64::MAX,
            Some(since) => since.saturating_add(self.status_timeout_ns),
            // The reference is set by the next poll.
            None => 0,
        };
        self.refresh_input();
    }

    /// Recomputes `quiet_until` after a change of the input side only.
    fn refresh_input(&mut self) {
        self.quiet_until = match (self.state, self.last_valid_ns) {
            // A zero timeout makes the input stale at once, whatever the clock does.
            (LinkState::Running, Some(last)) if self.timeout_ns != 0 => {
                last.saturating_add(self.timeout_ns).min(self.status_quiet)
            }
            _ => 0,
        };
    }

    pub fn state(&self) -> LinkState {
        self.state
    }

    pub fn status_lost(&self) -> bool {
        self.status_lost
    }

    /// Whether the head's status is not known (see the module docs): the laser
    /// gate stays off then where `off_on_head_alarm` is set.
    pub fn status_unknown(&self) -> bool {
        self.status_unknown
    }

    /// Applies the passage of time up to `now_ns`: input timeout, end of hold,
    /// broken recovery runs and the status watchdog.
    /// Inlined so the quiet case costs its compare at the call site, not a call.
    #[inline(always)]
    pub fn poll(&mut self, now_ns: u64) -> Changes {
        if now_ns < self.quiet_until {
            return Changes::default();
        }
        self.poll_rules(now_ns)
    }

    /// [`Supervisor::poll`] at or after the quiet interval's end.
    #[inline(never)]
    fn poll_rules(&mut self, now_ns: u64) -> Changes {
        let ch = self.rules(now_ns);
        self.refresh();
        ch
    }

    /// The rules of [`Supervisor::poll`].
    fn rules(&mut self, now_ns: u64) -> Changes {
        let mut ch = Changes::default();
        let stale = |last: Option<u64>, timeout: u64| {
            last.is_none_or(|t| now_ns.saturating_sub(t) >= timeout)
        };
        if self.state == LinkState::Running && stale(self.last_valid_ns, self.timeout_ns) {
            // The hold is timed from the moment the timeout expired, not from when
            // this poll noticed it, so late polls do not stretch it.
            let lost_at = self
                .last_valid_ns
                .unwrap_or(now_ns)
                .saturating_add(self.timeout_ns);
            self.state = LinkState::Holding;
            self.hold_end_ns = lost_at.saturating_add(self.hold_ns);
            self.run = 0;
            ch.lost = true;
        }
        if self.state == LinkState::Holding && now_ns >= self.hold_end_ns {
            self.state = LinkState::Safe;
        }
        if self.state != LinkState::Running && stale(self.last_valid_ns, self.timeout_ns) {
            // A gap as long as the timeout breaks a recovery run.
            self.run = 0;
        }
        if self.status_timeout_ns != 0 {
            let since = *self.status_ref_ns.get_or_insert(now_ns);
            if !self.status_lost && now_ns.saturating_sub(since) >= self.status_timeout_ns {
                self.status_lost = true;
                self.status_unknown = true;
                ch.status_lost = true;
            }
        }
        ch
    }

    /// A valid input frame at `now_ns` (after [`Supervisor::poll`]). Returns whether
    /// it may be forwarded: always while running; outside running only the frame
    /// that completes the recovery run, which also switches to running.
    pub fn valid(&mut self, now_ns: u64) -> bool {
        let previous = self.last_valid_ns.replace(now_ns);
        if self.state == LinkState::Running {
            // While running, `quiet_until` was set from an earlier valid frame (or
            // the status side); a newer frame only moves the input deadline later,
            // so the old instant still lies before anything can change: the rules
            // run there once, find the input fresh and set the next one. Only a
            // clock that went back moves the deadline earlier and needs it now.
            if previous.is_none_or(|p| now_ns < p) {
                self.refresh_input();
            }
            return true;
        }
        self.run = self.run.saturating_add(1);
        if self.run >= self.recovery_frames {
            self.state = LinkState::Running;
            self.run = 0;
            self.refresh();
            true
        } else {
            false
        }
    }

    /// A controller-side frame period the receiver could not publish (the engine
    /// decides which faults are that): breaks a recovery run (running is not
    /// affected; only the absence of valid frames for the timeout ends it).
    pub fn fault(&mut self) {
        self.run = 0;
    }

    /// The head's status was received at `now_ns`.
    pub fn status_seen(&mut self, now_ns: u64) {
        self.status_ref_ns = Some(now_ns);
        self.status_lost = false;
        self.status_unknown = false;
        self.refresh();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// One input to the supervisor: (kind, time step in us, backwards?).
    fn op() -> impl Strategy<Value = (u8, u32, bool)> {
        (0u8..5, 0u32..2_500, proptest::bool::weighted(0.1))
    }

    proptest! {
        /// The quiet-interval shortcut of `poll` never changes the outcome: a twin
        /// that always runs the full rules sees the same changes and states, over
        /// random event / poll / status / fault sequences with the clock jumping
        /// backwards now and then, zero and non-zero status timeouts. The head's
        /// status is known exactly when the reference says so: with the watchdog
        /// off always; with it on from a status seen until a status loss.
        #[test]
        fn quiet_shortcut_matches_the_full_rules(
            ops in proptest::collection::vec(op(), 1..300),
            status_us in prop_oneof![Just(0u32), 500u32..5_000],
            recovery in 1u32..4,
        ) {
            let f = FailSafe {
                input_timeout_us: 1_000,
                hold_us: 3_000,
                recovery_frames: recovery,
                status_timeout_us: status_us,
                ..FailSafe::default()
            };
            let mut fast = Supervisor::new(&f);
            let mut full = Supervisor::new(&f);
            let mut now: u64 = 1_000_000;
            let mut unknown = status_us != 0;
            for (kind, step, back) in ops {
                let step = u64::from(step) * 1_000;
                now = if back { now.saturating_sub(step) } else { now + step };
                let (a, b) = match kind {
                    0 => (fast.poll(now), full.rules(now)),
                    1 => (Changes::default(), Changes::default()),
                    _ => (fast.poll(now), full.rules(now)),
                };
                prop_assert_eq!(a, b);
                if a.status_lost {
                    unknown = true;
                }
                match kind {
                    1 => {
                        fast.status_seen(now);
                        full.status_seen(now);
                        unknown = false;
                    }
                    2 | 3 => prop_assert_eq!(fast.valid(now), full.valid(now)),
                    4 => {
                        fast.fault();
                        full.fault();
                    }
                    _ => {}
                }
                prop_assert_eq!((fast.state(), fast.status_lost()), (full.state(), full.status_lost()));
                prop_assert_eq!((fast.status_unknown(), full.status_unknown()), (unknown, unknown));
            }
        }
    }
}
