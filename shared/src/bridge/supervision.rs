//! Link supervision: the input-loss / hold / safe / recovery state machine and the
//! head-status watchdog (the table is in the [module docs](super)).
//!
//! Times are nanoseconds from any monotonic clock. A clock that goes backwards
//! counts as no time passed (saturating differences), so it can delay an alarm by
//! the size of the jump but never raise a false recovery.

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
        }
    }

    pub fn state(&self) -> LinkState {
        self.state
    }

    pub fn status_lost(&self) -> bool {
        self.status_lost
    }

    /// Applies the passage of time up to `now_ns`: input timeout, end of hold,
    /// broken recovery runs and the status watchdog.
    pub fn poll(&mut self, now_ns: u64) -> Changes {
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
                ch.status_lost = true;
            }
        }
        ch
    }

    /// A valid input frame at `now_ns` (after [`Supervisor::poll`]). Returns whether
    /// it may be forwarded: always while running; outside running only the frame
    /// that completes the recovery run, which also switches to running.
    pub fn valid(&mut self, now_ns: u64) -> bool {
        self.last_valid_ns = Some(now_ns);
        if self.state == LinkState::Running {
            return true;
        }
        self.run = self.run.saturating_add(1);
        if self.run >= self.recovery_frames {
            self.state = LinkState::Running;
            self.run = 0;
            true
        } else {
            false
        }
    }

    /// A fault on a controller-side line: breaks a recovery run (running is not
    /// affected; only the absence of valid frames for the timeout ends it).
    pub fn fault(&mut self) {
        self.run = 0;
    }

    /// The head's status was received at `now_ns`.
    pub fn status_seen(&mut self, now_ns: u64) {
        self.status_ref_ns = Some(now_ns);
        self.status_lost = false;
    }
}
