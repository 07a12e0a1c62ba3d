//! XY2-100 STATUS word from the head (`head.xy2.status = "word"`): the TIM8 CC1
//! samples of the head's STATUS line (PG9, one per output tick, aligned to the written
//! words by `WaveOut::read_status`) are thinned to one per bit -- the middle of the
//! bit's CLK-high tick, ticks 0, 2, 4, ... of every frame period counted from the
//! period's own start, so a period with an odd number of ticks (e.g. 41 ticks at
//! 4 MHz for 97.56 kHz frames: 20 bits and one idle tick) keeps every bit's sample:
//! `ceil(ticks / 2)` samples per period -- and go through `shared::xy2::status_line::StatusWordReceiver`; valid
//! words become the head's alarms in the bridge (`head_status_mut` + `status_seen`)
//! and in `channels::HEAD_STATUS`, invalid ones a `Line::Status` fault.
//!
//! After an output underrun or a status ring overrun the driver realigns the samples
//! (`WaveOut` module docs) and says so (`StatusRead::restart`): the next samples
//! start with the first slot the bridge writes next, so the receiver starts afresh
//! at that period (counted in `channels::STATS.status_realigns`).
//!
//! The head shifts its status out on the clock we send, so a frame period in which
//! the bridge sent no frame (idle slot: no clock edges) carries no status word. The
//! bridge loop records which periods it filled ([`SentPeriods`]); a word decoded from
//! an idle period is dropped, neither a status nor a fault.

use shared::bridge::{Bridge, Config};
use shared::model::{Alarms, FaultKind, Line, LineEvent};
use shared::xy2::status_line::{samples_per_period, StatusWordConfig, StatusWordReceiver};
use shared::xy2::{LinkConfig, StatusWord};

use crate::channels::{Stats, HEAD_STATUS, STATS};
use crate::drivers::wave_out::{StatusRead, WaveError};

/// The head's STATUS receiver output: PG9 (board wiring, pair 6 of the head side).
pub(super) const STATUS_PIN: u8 = 9;
/// Period sample holding the status frame's first bit: the head changes STATUS on
/// the falling CLK edge of bit k and the sampler reads the CLK-high half of bit k+1
/// (`shared::xy2::status_line`, "Status-word form").
const STATUS_OFFSET: u16 = 1;
/// Bits of a status frame.
const FRAME_BITS: u64 = 20;

/// Which output frame periods carried a frame, for the last 128 periods (the status
/// of a period is read about two batches, at most 75 periods, after it was encoded).
#[derive(Default)]
pub(super) struct SentPeriods(u128);

impl SentPeriods {
    /// Records whether period `p` (counted from the first written slot) had a frame.
    pub(super) fn set(&mut self, p: u64, sent: bool) {
        let bit = 1u128 << (p % 128);
        if sent {
            self.0 |= bit;
        } else {
            self.0 &= !bit;
        }
    }

    fn get(&self, p: u64) -> bool {
        self.0 >> (p % 128) & 1 == 1
    }
}

/// The head-side STATUS word input.
pub(super) struct StatusWordIn {
    config: StatusWordConfig,
    rx: StatusWordReceiver,
    /// Output ticks per frame period.
    ticks: u64,
    /// Tick of the next sample within its period.
    tick: u64,
    /// Samples fed per output frame period ([`samples_per_period`]).
    period: u64,
    /// Samples fed so far (sample 0 = the middle of the first written word).
    fed: u64,
    /// Alarms last published to `HEAD_STATUS`.
    published: Option<Alarms>,
    /// The samples lost their phase (reported once).
    lost: bool,
}

impl StatusWordIn {
    /// The receiver for an XY2-100 head with `ticks_per_frame` output ticks (two per
    /// bit, an idle tick when odd) per frame period.
    pub(super) fn new(config: &Config, ticks_per_frame: usize) -> Result<Self, &'static str> {
        let period = u16::try_from(samples_per_period(ticks_per_frame))
            .map_err(|_| "frame period too long")?;
        let h = config.head.xy2;
        let config = StatusWordConfig {
            pin: STATUS_PIN,
            samples_per_period: period,
            offset: STATUS_OFFSET,
            link: LinkConfig {
                mode: h.mode,
                parity: h.parity,
            },
        };
        let rx = StatusWordReceiver::new(config).map_err(|_| "status word geometry refused")?;
        Ok(StatusWordIn {
            config,
            rx,
            ticks: ticks_per_frame as u64,
            tick: 0,
            period: u64::from(period),
            fed: 0,
            published: None,
            lost: false,
        })
    }

    /// The samples restart at output period `p` (after a realignment).
    fn restart_at(&mut self, p: u64) {
        if let Ok(rx) = StatusWordReceiver::new(self.config) {
            self.rx = rx;
        }
        self.tick = 0;
        self.fed = p * self.period;
    }

    /// Keeps one sample per bit of `samples` (ticks 0, 2, 4, ... of each period,
    /// module docs), compacted to the front; returns how many.
    fn thin(&mut self, samples: &mut [u16]) -> usize {
        let mut kept = 0;
        for i in 0..samples.len() {
            if self.tick.is_multiple_of(2) {
                // kept <= i: compacting in place never overtakes the reader.
                if let Some(s) = samples.get(i).copied() {
                    if let Some(d) = samples.get_mut(kept) {
                        *d = s;
                        kept += 1;
                    }
                }
            }
            self.tick += 1;
            if self.tick == self.ticks {
                self.tick = 0;
            }
        }
        kept
    }

    /// Feeds what `WaveOut::read_status` returned (`read`, its samples in
    /// `samples`) and applies the words of periods that carried a frame to `bridge`
    /// at `now_ns`. `next_period` is the period of the next slot the bridge writes
    /// (where a realignment restarts the samples).
    pub(super) fn apply(
        &mut self,
        read: Result<StatusRead, WaveError>,
        samples: &mut [u16],
        next_period: u64,
        sent: &SentPeriods,
        bridge: &mut Bridge,
        now_ns: u64,
    ) {
        let read = match read {
            Ok(r) => r,
            Err(e) => {
                if !self.lost {
                    self.lost = true;
                    Stats::bump(&STATS.input_overruns);
                    defmt::error!(
                        "head status word: {}; no words until realigned (STATUS_LOST follows)",
                        e
                    );
                }
                return;
            }
        };
        if read.restart {
            self.restart_at(next_period);
            Stats::bump(&STATS.status_realigns);
            if core::mem::take(&mut self.lost) {
                defmt::info!("head status word: realigned at period {}", next_period);
            }
        }
        let n = read.samples.min(samples.len());
        let kept = self.thin(samples.get_mut(..n).unwrap_or_default());
        let mut rest: &[u16] = samples.get(..kept).unwrap_or_default();
        // The frame whose first bit is period sample `offset` of period p ends at
        // sample p * period + offset + 19: feed up to each such sample, so every word
        // is known to belong to one period.
        let end_phase = (u64::from(STATUS_OFFSET) + FRAME_BITS - 1) % self.period;
        let mut last: Option<StatusWord> = None;
        let mut faults = 0u32;
        while !rest.is_empty() {
            let to_end = (end_phase + self.period - self.fed % self.period) % self.period + 1;
            let n = usize::try_from(to_end)
                .unwrap_or(usize::MAX)
                .min(rest.len());
            let (chunk, tail) = rest.split_at(n);
            rest = tail;
            let mut word = None;
            self.rx.feed(chunk, &mut |r| word = Some(r));
            self.fed += n as u64;
            let ending = self.fed - 1;
            let first = u64::from(STATUS_OFFSET) + FRAME_BITS - 1;
            let Some(r) = word else { continue };
            if ending < first || !sent.get((ending - first) / self.period) {
                continue;
            }
            match r {
                Ok(w) => last = Some(w),
                Err(_) => faults += 1,
            }
        }
        for _ in 0..faults {
            let fault = LineEvent::Fault {
                line: Line::Status,
                kind: FaultKind::CheckFailed,
            };
            let _ = bridge.on_line_event(now_ns, fault);
        }
        if let Some(w) = last {
            let alarms = w.alarms();
            bridge.head_status_mut().alarms = alarms;
            bridge.status_seen(now_ns);
            if self.published != Some(alarms) {
                self.published = Some(alarms);
                Stats::bump(&STATS.status_changes);
                HEAD_STATUS.sender().send(bridge.head_status().clone());
            }
        }
    }
}
