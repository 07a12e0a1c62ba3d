//! The decode executor's load governor: `shared::governor` with the firmware's
//! limits, and the two calls the HANS-100 decoders make around each half ([`admit`]
//! before, [`Busy::report`] after). The policy is `shared`'s (host-tested); this file
//! only measures time with `embassy_time::Instant` and obeys.
//!
//! Why it exists: the decode executor (`app.rs`, UART5 vector) preempts thread mode,
//! where the supervisor feeds the watchdog. A decoder that cannot keep up would have
//! a half queued at every moment and never let thread mode run; the chip would reset.
//! The governor pauses it (its executor idles) whenever it was busy for more than
//! [`SHARE_PERMILLE`] of the time, and drops halves that waited too long.

use embassy_time::{Duration, Instant, Timer, TICK_HZ};
use shared::governor::{Class, Governor, Limits, Step};

use crate::board::HANS_FS_HZ;
use crate::channels::{Stats, DECODE_GOVERNOR, HANS_HALF, HANS_IN_HALF, STATS};

/// Half period of both HANS-100 inputs in embassy ticks (1 us): 512 words of 16
/// samples at 40 MHz = 204.8 us, rounded up.
const HALF_TICKS: u64 = (HANS_IN_HALF as u64 * 16 * TICK_HZ).div_ceil(HANS_FS_HZ as u64);

// The STATUS input's halves are as long as the controller input's: one half period
// serves both.
const _: () = assert!(HANS_HALF == HANS_IN_HALF);

/// Most of the time the decoders may be busy (their work and the line executor's
/// preemptions during it): 90 %. The rest is for thread mode and the line executor
/// while the decoders idle. Thread mode needs little (supervisor every 50 ms, the
/// stats line once a second, an XY3-100 head's backchannel parser: about 1 % at
/// 921 600 baud), but needs it within milliseconds; 10 % of the time is that many
/// times over even when the line executor takes a third of it. It is also above
/// what normal mode costs today (~1 950 instructions of 4 800 cycles a frame plus
/// the line executor's preemptions: about 50 %) and vote3 (~3 110: 75..80 %), so a
/// decoder that keeps up is never paused; vote5 / super (~3 920..4 080: 95..100 %)
/// are over it and are governed until the receiver is cheaper.
pub const SHARE_PERMILLE: u16 = 900;

/// The firmware's limits: [`SHARE_PERMILLE`]; a burst of half a half period (single
/// halves up to 50 % over the share pass without a pause: the line executor's
/// batches make the busy time of a half jitter); halves up to two half periods old
/// (410 us: a half is decoded at most that long after it was complete, and with
/// `HANS_INPUT`'s two slots the oldest is dropped here before the input task has to
/// drop the newest); the head STATUS (optional work) refused for lack of credit for
/// at most eight half periods (1.6 ms, what the thread-mode decoder of every 8th half
/// guaranteed before), then decoded at the input's expense.
const LIMITS: Limits = Limits {
    half: HALF_TICKS,
    share_permille: SHARE_PERMILLE,
    burst: HALF_TICKS / 2,
    max_age: 2 * HALF_TICKS,
    optional_gap: 8 * HALF_TICKS,
};

/// The governor with [`LIMITS`], checked at compile time (a refused limit fails the
/// build, never the chip).
pub const GOVERNOR: Governor = match Governor::new(LIMITS) {
    Ok(g) => g,
    Err(_) => panic!("decode governor limits refused"),
};

/// Microseconds in `ticks`, saturating into the `u32` statistics counters.
fn micros(ticks: u64) -> u32 {
    u32::try_from(Duration::from_ticks(ticks).as_micros()).unwrap_or(u32::MAX)
}

/// Asks the governor about the half at hand (`ready`: when it was complete, in
/// ticks), sleeping through the pauses it imposes. `true`: decode it and report the
/// busy time with [`Busy::report`]; `false`: the governor dropped it (counted), so
/// the stream has a gap here.
pub async fn admit(class: Class, ready: u64) -> bool {
    loop {
        let now = Instant::now().as_ticks();
        match DECODE_GOVERNOR.lock(|g| g.borrow_mut().next(now, class, ready)) {
            Step::Decode => return true,
            Step::Drop => {
                Stats::bump(match class {
                    Class::Essential => &STATS.decode_drops,
                    Class::Optional => &STATS.status_drops,
                });
                return false;
            }
            Step::Pause { until } => {
                Stats::bump(&STATS.decode_pauses);
                Stats::add(&STATS.decode_paused_us, micros(until.saturating_sub(now)));
                Timer::at(Instant::from_ticks(until)).await;
            }
        }
    }
}

/// Busy time of one half's decode, summed over its synchronous pieces: the waits in
/// between (for room in `HANS_EVENTS`) idle the decode executor, so they are not
/// busy time.
pub struct Busy(u64);

impl Busy {
    /// Nothing measured yet.
    pub const fn new() -> Self {
        Self(0)
    }

    /// Runs `f` and adds its duration (with whatever preempted it).
    pub fn run<R>(&mut self, f: impl FnOnce() -> R) -> R {
        let start = Instant::now();
        let r = f();
        self.0 = self.0.saturating_add(start.elapsed().as_ticks());
        r
    }

    /// Tells the governor what the half cost, and counts it.
    pub fn report(self, class: Class) {
        DECODE_GOVERNOR.lock(|g| g.borrow_mut().spent(class, self.0));
        let us = micros(self.0);
        Stats::add(&STATS.decode_busy_us, us);
        Stats::raise(&STATS.decode_busy_max_us, us);
        Stats::bump(match class {
            Class::Essential => &STATS.decoded_halves,
            Class::Optional => &STATS.status_decoded,
        });
    }
}
