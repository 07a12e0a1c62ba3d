//! Load governor for a decoder that runs above the lowest priority.
//!
//! The firmware decodes HANS-100 streams in an interrupt executor that preempts thread
//! mode, where the supervisor feeds the watchdog. A decoder that cannot keep up with
//! its input would then never let thread mode run, and the watchdog would reset the
//! chip. This module decides, half-buffer by half-buffer, whether the decoder may
//! work, so that it never takes more than a set share of the time; it is pure logic
//! (time and queue lengths in, a [`Step`] out), so the firmware only measures and
//! obeys.
//!
//! **Policy.** The decoder earns credit at `share` of the wall time and spends one
//! unit of credit per unit of time it is busy (its own work and whatever preempts it:
//! both keep thread mode from running). Credit is capped at `burst`, so time the
//! decoder did not use is not banked for later. For each half at hand:
//! * credit below zero -> [`Step::Pause`] until it is back to zero: the decoder's
//!   executor idles and the lower priorities run;
//! * otherwise the half at hand older than `max_age` (the decoder's backlog, as time:
//!   it also counts halves the input task lost on a full queue) -> [`Step::Drop`]: it
//!   is stale, a newer one follows (drops shed the oldest input, so a half's decode
//!   never starts more than `max_age` after the half was complete);
//! * otherwise [`Step::Decode`].
//!
//! Work of [`Class::Optional`] (a status stream that is re-read every half anyway)
//! is dropped unless the credit covers what its last run cost, so it normally only
//! uses time the essential decoder leaves over; but once it has been refused for
//! `optional_gap`, its next half is admitted like essential work (paused for, then
//! decoded), so an overloaded essential decoder cannot silence it for good.
//!
//! **Guarantee.** The credit only decreases while the decoder is busy, a decode only
//! starts with credit >= 0, and a decode of length `b` costs `(1 - share) * b` of
//! credit net (credit keeps accruing while it runs). So in any interval of length `L`
//! the decoder is busy for at most `share * L + burst + (1 - share) * b_max`, where
//! `b_max` is its longest single decode; the rest of the interval belongs to the other
//! priorities. A decoder whose load stays below `share` (and whose excess over it in
//! any stretch stays below `burst`) is never paused and never drops a half.

use core::fmt;

/// Limits the governor enforces. Times are in one unit of the caller's choice (the
/// firmware uses embassy time ticks, 1 us), the same for every input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Limits {
    /// Time between two input halves (one DMA half-buffer of the stream).
    pub half: u64,
    /// Most of the wall time the decoder may be busy, in per mille (1..=999).
    pub share_permille: u16,
    /// Most credit the decoder may hold: busy time beyond its share that it may take
    /// in one stretch before it is paused (absorbs the jitter of single halves).
    pub burst: u64,
    /// Oldest a half may be (time since it was complete) when its decode starts;
    /// an older one is dropped as stale. At least one half period.
    pub max_age: u64,
    /// Longest optional work may go without a decode for lack of credit; then its
    /// next half is admitted like essential work. At least one half period.
    pub optional_gap: u64,
}

/// Why [`Limits`] were refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LimitsError {
    /// The half period is zero.
    ZeroHalf,
    /// The share is 0 (the decoder could never run) or 1000 or more (the other
    /// priorities would get no time).
    Share {
        /// The refused share, per mille.
        permille: u16,
    },
    /// The burst is longer than the half period: one stretch could then take a whole
    /// half more than the share allows.
    Burst,
    /// The age limit is shorter than a half period: a decoder only a little behind
    /// would drop halves.
    MaxAge,
    /// The optional gap is shorter than a half period: optional work would run as
    /// essential work every time.
    OptionalGap,
}

impl fmt::Display for LimitsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::ZeroHalf => write!(f, "decoder governor: the half period is zero"),
            Self::Share { permille } => write!(
                f,
                "decoder governor: share {permille} per mille is not 1..=999"
            ),
            Self::Burst => write!(
                f,
                "decoder governor: the burst is longer than the half period"
            ),
            Self::MaxAge => write!(
                f,
                "decoder governor: the age limit is shorter than the half period"
            ),
            Self::OptionalGap => write!(
                f,
                "decoder governor: the optional gap is shorter than the half period"
            ),
        }
    }
}

/// What a piece of decoding work is worth.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Class {
    /// Input the bridge forwards (the controller's stream): paused for when over
    /// budget, dropped only when stale.
    Essential,
    /// Work that only refreshes a state (the head's STATUS): dropped whenever the
    /// credit does not cover its last cost, unless it has waited `optional_gap`.
    Optional,
}

/// The governor's decision for the half at hand.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Step {
    /// Decode it, then report the busy time with [`Governor::spent`].
    Decode,
    /// Do not decode it (stale, or optional work without credit): the stream has a
    /// gap here.
    Drop,
    /// Idle until `until` (same unit and origin as `now`), then ask again.
    Pause {
        /// When the credit is back to zero.
        until: u64,
    },
}

/// Per-mille scale of the credit: credit is kept in thousandths of a time unit so
/// the share needs no division until a pause is computed.
const SCALE: i64 = 1000;

/// The governor's state (see the module docs).
#[derive(Debug, Clone)]
pub struct Governor {
    limits: Limits,
    /// Credit in thousandths of a time unit.
    credit: i64,
    /// The time credit was last brought up to (`None` before the first call).
    last: Option<u64>,
    /// Credit the last optional decode cost net, in thousandths of a time unit.
    optional_cost: i64,
    /// When optional work was last decoded (or first asked about).
    optional_since: Option<u64>,
}

/// `x` as `i64`, saturating (times are far below `i64::MAX`; garbage must not wrap).
fn sat(x: u64) -> i64 {
    i64::try_from(x).unwrap_or(i64::MAX)
}

impl Governor {
    /// A governor with a full credit. `const`, so a firmware can check its limits at
    /// compile time.
    pub const fn new(limits: Limits) -> Result<Self, LimitsError> {
        if limits.half == 0 {
            return Err(LimitsError::ZeroHalf);
        }
        if limits.share_permille == 0 || limits.share_permille >= 1000 {
            return Err(LimitsError::Share {
                permille: limits.share_permille,
            });
        }
        if limits.burst > limits.half {
            return Err(LimitsError::Burst);
        }
        if limits.max_age < limits.half {
            return Err(LimitsError::MaxAge);
        }
        if limits.optional_gap < limits.half {
            return Err(LimitsError::OptionalGap);
        }
        // `burst <= half`, and `half` is a time: far below `i64::MAX / SCALE` for
        // any real clock; saturate anyway.
        let cap = if limits.burst > (i64::MAX / SCALE) as u64 {
            i64::MAX
        } else {
            limits.burst as i64 * SCALE
        };
        Ok(Self {
            limits,
            credit: cap,
            last: None,
            optional_cost: 0,
            optional_since: None,
        })
    }

    /// The limits it enforces.
    pub fn limits(&self) -> Limits {
        self.limits
    }

    /// The credit cap in thousandths of a time unit.
    fn cap(&self) -> i64 {
        sat(self.limits.burst).saturating_mul(SCALE)
    }

    /// Brings the credit up to `now`: `share` of the time since the last call, capped.
    /// A `now` before the last one (a clock that went back) earns nothing.
    fn accrue(&mut self, now: u64) {
        let elapsed = match self.last {
            Some(last) => now.saturating_sub(last),
            None => 0,
        };
        self.last = Some(self.last.map_or(now, |last| last.max(now)));
        let earned = sat(elapsed).saturating_mul(i64::from(self.limits.share_permille));
        self.credit = self.credit.saturating_add(earned).min(self.cap());
    }

    /// The decision for the half at hand, at time `now`; `ready` is when the half was
    /// complete (same unit and origin). After [`Step::Pause`] ask again at or after
    /// its `until`.
    pub fn next(&mut self, now: u64, class: Class, ready: u64) -> Step {
        self.accrue(now);
        let stale = now.saturating_sub(ready) > self.limits.max_age;
        if class == Class::Optional {
            let since = *self.optional_since.get_or_insert(now);
            let starved = now.saturating_sub(since) >= self.limits.optional_gap;
            // Unless starved, optional work is never paused for and never takes the
            // credit the essential decoder would need: its last cost must fit.
            if !starved {
                return if self.credit >= self.optional_cost && !stale {
                    self.optional_since = Some(now);
                    Step::Decode
                } else {
                    Step::Drop
                };
            }
        }
        if self.credit < 0 {
            let share = i64::from(self.limits.share_permille);
            // Round up, so the credit is >= 0 at `until`.
            let debt = self.credit.saturating_neg();
            let wait = debt.saturating_add(share - 1) / share;
            return Step::Pause {
                until: now.saturating_add(wait.unsigned_abs()),
            };
        }
        if stale {
            return Step::Drop;
        }
        if class == Class::Optional {
            self.optional_since = Some(now);
        }
        Step::Decode
    }

    /// The decoder was busy for `busy` on a half [`Governor::next`] admitted (its own
    /// work plus whatever preempted it, without its waits).
    pub fn spent(&mut self, class: Class, busy: u64) {
        let cost = sat(busy).saturating_mul(SCALE);
        self.credit = self.credit.saturating_sub(cost);
        if class == Class::Optional {
            // Net of what accrues while it runs: what the next optional run must find.
            let keep = SCALE - i64::from(self.limits.share_permille);
            self.optional_cost = sat(busy).saturating_mul(keep);
        }
    }

    /// The current credit in time units, rounded towards zero (negative: in debt).
    pub fn credit(&self) -> i64 {
        self.credit / SCALE
    }
}

#[cfg(test)]
mod tests;
