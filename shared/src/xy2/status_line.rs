//! The STATUS line at line level, both directions (notes, "STATUS"; layout items 4, 7).
//!
//! # Level form (head side, input)
//! A plain GPIO level, not clocked. [`LevelDebouncer`] is fed level samples with the
//! caller's time stamp and accepts a new level only after a configurable number of
//! consecutive equal samples, so a glitch shorter than that never flips the head's
//! health. The report carries the time of the first sample of the new level.
//!
//! # Status-word form (head side, input)
//! The bridge clocks the head itself, so the STATUS samples (layout item 4: the
//! output timer's compare event copies the status port's `u16` into a ring, one
//! sample per output bit slot, started together with the output ring) are aligned
//! with the bridge's own output frames: every frame period has the same number of
//! samples, and the status frame starts at a fixed sample offset within it. The head
//! changes STATUS on the clock's falling edge, half a bit after our data changed, so
//! status bit *k* is read one sample after data bit *k*: the default offset is 1 (the
//! frame then ends in the next period's sample 0 when frames are back to back).
//! [`StatusWordReceiver`] collects the 20 bits MSB first and parses them with
//! [`StatusWord::from_frame`] (the 16-bit layout and the link's parity policy).
//!
//! # Outputs (controller side)
//! [`StatusOut`] makes BSRR words for one status pin: the level for a [`Health`]
//! (polarity from [`StatusLevel`]), and the 20 words of a status-word frame, one per
//! bit, MSB first. The firmware clocks them with the *controller's* clock: the same
//! CLK falling-edge timer that samples the input port (layout item 1) triggers a second
//! DMA stream that copies the next word from a ring of 20·K words to the status port's
//! BSRR, so STATUS changes on the falling edge, half a bit after the controller's data,
//! as heads do. The ring must be started at a frame boundary (at a SYNC rising edge the
//! receiver found), which only holds while the controller clocks frames back to back.

use super::frame::{LinkConfig, FRAME_BITS, FRAME_MASK};
use super::rx::{check_pins, PinError};
use super::status::{Health, StatusError, StatusLevel, StatusWord};

/// A level change the debouncer accepted.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LevelChange {
    /// The new health.
    pub health: Health,
    /// Time stamp of the first sample at the new level.
    pub since: u64,
}

/// Debounces a level-style STATUS input (see the module docs).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LevelDebouncer {
    level: StatusLevel,
    required: u16,
    /// The level being counted, its count (saturating at `required`) and first time.
    candidate: bool,
    count: u16,
    first: u64,
    /// The accepted level, `None` until the first one is accepted.
    stable: Option<bool>,
}

impl LevelDebouncer {
    /// Accepts a level after `required` consecutive equal samples (0 counts as 1).
    pub const fn new(level: StatusLevel, required: u16) -> Self {
        LevelDebouncer {
            level,
            required: if required == 0 { 1 } else { required },
            candidate: false,
            count: 0,
            first: 0,
            stable: None,
        }
    }

    /// The accepted health, `None` before the first level is accepted.
    pub fn health(&self) -> Option<Health> {
        self.stable.map(|high| self.level.health(high))
    }

    /// Feeds one sample (`high` = line high) taken at time `now` (caller's unit);
    /// returns the change when a new level is accepted, including the first one.
    pub fn feed(&mut self, now: u64, high: bool) -> Option<LevelChange> {
        if high != self.candidate || self.count == 0 {
            self.candidate = high;
            self.count = 0;
            self.first = now;
        }
        self.count = self.count.saturating_add(1).min(self.required);
        if self.count == self.required && self.stable != Some(high) {
            self.stable = Some(high);
            return Some(LevelChange {
                health: self.level.health(high),
                since: self.first,
            });
        }
        None
    }
}

/// Alignment of the status-word samples (see the module docs).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StatusWordConfig {
    /// The status port bit (0..15).
    pub pin: u8,
    /// Samples per output frame period ([`samples_per_period`] of the output's
    /// ticks per frame; >= 20).
    pub samples_per_period: u16,
    /// Index within the period of the sample holding the status frame's first bit
    /// (bit 19); may be up to `samples_per_period - 1`, the frame then continues into
    /// the next period. Default choice: 1.
    pub offset: u16,
    /// The link's parity policy (the status frame is always 16-bit layout).
    pub link: LinkConfig,
}

/// Status-word samples per output frame period of `ticks_per_frame` output ticks
/// (two per bit; a period with an odd number ends with an idle tick): one per bit
/// slot counted from the period's start, `ceil(ticks / 2)`, so an odd period's last
/// sample falls after its idle tick and the next period starts afresh (as the
/// firmware thins the compare samples). Sampling every two ticks throughout would
/// drift half a bit per odd period.
pub const fn samples_per_period(ticks_per_frame: usize) -> usize {
    ticks_per_frame.div_ceil(2)
}

/// Why a status-word configuration is unusable.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StatusConfigError {
    /// The pin is not below 16.
    Pin(PinError),
    /// Fewer than 20 samples per period, or the offset not inside the period.
    Geometry {
        /// Samples per period.
        samples_per_period: u16,
        /// Offset.
        offset: u16,
    },
}

impl core::fmt::Display for StatusConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Pin(e) => write!(f, "status pin: {e}"),
            Self::Geometry {
                samples_per_period,
                offset,
            } => write!(
                f,
                "status offset {offset} with {samples_per_period} samples per period \
                 (need >= 20 samples and offset < samples)"
            ),
        }
    }
}

/// Collects status-word frames from status-port samples (see the module docs).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StatusWordReceiver {
    link: LinkConfig,
    bit: u32,
    period: u16,
    /// Index in the period of the sample holding the frame's last bit.
    last: u16,
    /// Index in the period of the next sample.
    pos: u16,
    /// Samples seen, saturating at 20: a frame needs 20 of them.
    seen: u8,
    register: u32,
}

impl StatusWordReceiver {
    /// A receiver for `config`; the first sample fed is sample 0 of a period.
    pub fn new(config: StatusWordConfig) -> Result<Self, StatusConfigError> {
        check_pins(&[Some(config.pin)]).map_err(StatusConfigError::Pin)?;
        let period = config.samples_per_period;
        if u32::from(period) < FRAME_BITS || config.offset >= period {
            return Err(StatusConfigError::Geometry {
                samples_per_period: period,
                offset: config.offset,
            });
        }
        // offset + 19 < 2 * period <= 2^17, computed in u32 then reduced below `period`.
        let last = (u32::from(config.offset) + FRAME_BITS - 1) % u32::from(period);
        Ok(StatusWordReceiver {
            link: config.link,
            bit: u32::from(config.pin),
            period,
            last: u16::try_from(last).unwrap_or(0),
            pos: 0,
            seen: 0,
            register: 0,
        })
    }

    /// Processes samples in time order; every completed status frame goes to `sink`.
    pub fn feed(
        &mut self,
        samples: &[u16],
        sink: &mut impl FnMut(Result<StatusWord, StatusError>),
    ) {
        for &s in samples {
            self.register = self.register << 1 | (u32::from(s) >> self.bit & 1);
            self.seen = self.seen.saturating_add(1).min(FRAME_BITS as u8);
            if self.pos == self.last && u32::from(self.seen) == FRAME_BITS {
                sink(StatusWord::from_frame(
                    self.register & FRAME_MASK,
                    &self.link,
                ));
            }
            self.pos += 1;
            if self.pos == self.period {
                self.pos = 0;
            }
        }
    }
}

/// BSRR words for one STATUS output pin (see the module docs).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StatusOut {
    level: StatusLevel,
    set: u32,
}

impl StatusOut {
    /// Drives port bit `pin` (0..15) with `level`'s polarity.
    pub fn new(pin: u8, level: StatusLevel) -> Result<Self, PinError> {
        check_pins(&[Some(pin)])?;
        Ok(StatusOut {
            level,
            set: 1 << pin,
        })
    }

    /// The BSRR word that drives the level for `health`.
    pub const fn level_word(&self, health: Health) -> u32 {
        let high = self.level.line_high(health);
        (self.set << 16) >> ((high as u32) << 4)
    }

    /// The 20 BSRR words of the status frame for `word`, bit 19 first, one per
    /// controller clock (see the module docs).
    pub fn word_frame(&self, word: StatusWord, link: &LinkConfig, out: &mut [u32; 20]) {
        let frame = word.to_frame(link);
        for (w, shift) in out.iter_mut().zip((0..FRAME_BITS).rev()) {
            *w = (self.set << 16) >> ((frame >> shift & 1) << 4);
        }
    }
}
