//! HANS-100 line-level receiver: oversampled channel rings in, checked frames out, in
//! the four decode modes of the spec ("decoding modes" 1-4).
//!
//! # Input (layout item 3)
//! One `u16` ring per channel CH1..CH5, 16 samples per word, bit 15 first, taken at
//! `fs` = 3..4 times the 12.5 MHz bit rate by one clock for all channels: word `i` of
//! every ring covers the same 16 instants. [`HansRx::push`] takes the same stretch of
//! each ring (e.g. one DMA half) in any chunking; results do not depend on it.
//!
//! # One clock, one delay per channel
//! All five channels come from one sender clock, so the receiver recovers the frame
//! timing once ([`timing`]) and gives each channel only a delay against it
//! ([`channel`]):
//! 1. **Hunt** (no timing yet, [`hunt`]): every used channel looks for the
//!    `1 1 1 0 1` start marker word by word and remembers the last few
//!    candidates; a candidate one frame period (±5 %) after a remembered one is
//!    confirmed only if the frame between the two **reads right** (start pair,
//!    60 complement pairs, stop bits) on the least-squares line through the two
//!    start edges and the frame's 61 mid-pair edges, so a stretched data run
//!    (±25 % jitter) neither locks nor hides a true start edge. The first channel
//!    to confirm sets the timing and hands the fit to the young lock
//!    ([`timing::Timing::lock`]); a frame that does not also read right with the
//!    line moved a quarter of a bit either way waits for the next frame, and the
//!    lock starts on a two-frame fit.
//! 2. **Frames**: the words are copied into per-channel rings ([`ring`]); once a
//!    frame's samples up to its successor's start edge have arrived on every
//!    channel, it is decoded in one go and published right away if its timing is
//!    **confirmed**: the channel's start edge and the next frame's lie within 3/8
//!    of a bit (centred on the samples such an edge can give) of where the bit
//!    timing the pattern was read with puts them, and, once the lock has settled,
//!    the frame's last 8 mid-pair edges (every complement pair changes level in
//!    its middle) lie on average within a quarter bit of where it puts them, their
//!    deviations' mean size within 3/8 ([`confirm`]; a reference tail whose
//!    mean alone is beyond a quarter bit gets a second look on the edges between
//!    its pairs, [`confirm::tail_again`], `HansRx::looked_again`). Else the
//!    phase may have drifted within the frame (a false or missing start edge moved
//!    the tracking), and a tail read a bit off is random content whose complement
//!    pairs pass at 2^-n: the channel counts a check failure instead (unless the
//!    frame's edges show a rounding step of a clean line near a whole number of
//!    samples a bit, [`confirm::stepped`]: then it is re-read at its successor's
//!    phase and must pass every check there, and the timing moves there,
//!    `HansRx::rephased`; and a tail rejected as a short excursion on a
//!    jittered line is counted again 1/32 sample beyond the far bound,
//!    `HansRx::recounted`). Channels
//!    that matched the reference centre for centre hold one pattern and are
//!    confirmed together by the first of them whose edges all pass. The
//!    **reference** channel's 125 bit centres are gathered two windows (of 32
//!    samples) at a time with a per-phase table and four multiplications per window
//!    ([`table`]);
//!    every other aligned channel is checked **centre for centre** against the
//!    reference's samples, shifted by the whole samples between their delays. A
//!    channel that matches everywhere holds the reference's pattern; one that
//!    differs anywhere is gathered in full at its own delay and checked on its own.
//!    The centre-sample semantics are those of a per-channel sampler: a channel's
//!    pattern is its samples nearest to `start + delay + (k + ½)·bit`.
//! 3. **Tracking**: each channel's next start edge is searched ±1.5 bits around
//!    its prediction (exactly one falling edge lies there on a good line). The
//!    reference channel's edge, when it just verified, corrects phase and rate
//!    with an alpha-beta filter, blended with the mean of the last 8 mid-pair
//!    edges its tail confirmation measured (`timing::Timing::tail`; else the
//!    upper median of the edges of the channels that did: a glitch before the
//!    real edge reads early);
//!    for its first [`timing::YOUNG`] frames a lock is instead the least-squares
//!    line through its start edges and the 61 mid-pair edges (every complement
//!    pair has one) of each frame its reference channel verified ([`phase`]): a
//!    start edge per frame left a
//!    young lock's phase ~0.35 sample off at ±25 % jitter, the pairs make it a few
//!    hundredths; a lock that has not settled yet ([`timing::SETTLED`] start
//!    edges) is dropped after six failures in a row, not three ([`timing::Timing::relock_after`]);
//!    each channel's delay follows its own deviation from that edge (averaged,
//!    steps clamped to a sample), so a verified reference's delay stays put and
//!    anchors the others (a consensus that moved every delay, the reference's
//!    too, let their common part wander with the jitter, and the rate with it). A lock publishes nothing until it has measured
//!    [`timing::SETTLED`] start edges (its first gains are large: a rate measured
//!    over one jittered frame, or one false edge, can leave the phase half a bit
//!    off at a frame's end, which no check sees); from then on an edge half a bit
//!    or more from the prediction is not followed (the timing coasts; if it was
//!    right after all, the frames fail their confirmation and the channel realigns
//!    or the lock is lost). A channel that matched the reference and whose
//!    delay has settled is re-measured only every eighth frame. A channel without
//!    an edge, or failing three patterns in a row, drops its alignment and aligns
//!    again at the next frame's start edge; when no channel is left, or none
//!    verifies for three frames (a false lock), the hunt starts over. The reference
//!    moves to another channel as soon as it stops verifying, so a line that dies
//!    costs the others nothing.
//!
//! Skew between channels (up to ±2 samples, and more) is absorbed by the delays;
//! jitter and rate offset are handled as by a per-channel receiver (see the README
//! "Measured figures" for the limits).
//!
//! # Modes
//! - [`Mode::Normal`]: one channel's pattern is checked by [`Frame::decode`]
//!   (start pair, all 60 complement pairs, stop bits); only a frame that passes is
//!   published.
//! - [`Mode::Vote3`] / [`Mode::Vote5`]: **we vote per recovered bit**, not per raw
//!   sample: each channel's bits are taken at its own delay, so skew between
//!   channels is absorbed instead of smearing the vote. The patterns of one frame
//!   are combined by bitwise majority (2 of 3, 3 of 5) and the result must still
//!   pass every check. A channel without a pattern (not aligned) votes zeros, as a
//!   dead line would. When every voter matched the reference, the majority is the
//!   reference's pattern.
//! - [`Mode::Super`]: every channel's pattern is checked on its own; the frame held
//!   by a **strict majority of the verified channels** is published (one verified
//!   channel alone suffices); verified channels that disagree without a strict
//!   majority reject the frame ([`FaultKind::Disagree`] on [`Line::Framing`]), and
//!   verified channels in the minority get a per-channel `Disagree`.
//!
//! # Events and counters
//! A sink receives [`RxEvent`]s: frames, per-channel faults (check failed, resync,
//! disagreement, missing) and frame faults; [`RxEvent::to_line_event`] gives the
//! bridge's [`LineEvent`]. Per-channel [`ChannelStats`] count frames that passed,
//! frames that failed a check, losses of alignment and **missing** periods: every
//! frame period in which a used channel delivered no pattern (not aligned: dead,
//! stuck, unplugged) counts one and reports [`FaultKind::Missing`] on that channel,
//! **every period it stays so**, also while the frame comes from the other channels
//! (vote and super modes) and, while the timing is lost again (normal mode on a
//! dead channel, or every channel dead), once per nominal frame period of input
//! (not before the first lock: acquisition is not a fault). So a
//! dead redundant channel is visible in its counters at the frame rate, never just
//! once; a channel that comes back aligns at the next start edge and counts frames
//! again. In every locked period each used channel counts exactly one of frames
//! ok, check failures, missing; a period whose input was skipped
//! ([`HansRx::skip`], [`gap`]: a settled lock coasts across) counts none of them
//! but one [`HansRx::skipped`]. **In the vote and super modes every decoded
//! period ends in exactly one frame or one period fault**, except the first
//! `SETTLED - 2` of a lock (acquisition: frames verified, none published, nothing
//! reported) (`channel: None`;
//! CheckFailed or Disagree, whatever the channels reported before it), and losing
//! the shared timing reports a period [`FaultKind::Resync`]: there a channel fault
//! alone never means a lost period, and the bridge breaks its recovery run on
//! period faults only (a noisy backup channel must not keep the link in its
//! fail-safe states while verified frames flow). In normal mode the one channel's
//! faults are the period's. No frame that failed a check is ever published,
//! nothing panics, and the work per word is bounded.
//!
//! # Cost (QEMU Cortex-M7, `cargo xtask qemu`, steady state)
//! About 1 880 instructions per frame for one channel at 3x (2 030 at 4x), 2 850
//! for vote3 and 3 240 for vote5 / super (5 channels, 3x); as the firmware feeds
//! it (40 MHz, 64-word chunks) 2 010 in normal mode and 3 360 in super mode, once
//! a lock has settled (README "Measured figures" has the current rows; the
//! figures below are the history that led here). The tail confirmation,
//! [`confirm`], adds 150..230 (about 230 in `confirmed` for the reference's 8
//! last mid-pair edges, the rest the code around the call; before it 1 780 /
//! 1 870 / 2 690 / 3 170, firmware 1 830 / 3 290, young lock 5 780). The young
//! lock ([`phase`], its first [`timing::YOUNG`] frames) costs 5 110 in super mode as the firmware feeds it (bench row "young
//! lock", frames 4..36; 5 790 before its fit took every other pair after four
//! frames, [`timing::DENSE`]; 8 530 before `phase::mid_pairs` was made a register-only
//! loop of ~28 instructions an edge): ~930 measuring the 31 even mid-pair edges (~1 700 all 61),
//! ~320 the fit's 64-bit divisions, ~430 the frame step's and `Timing::advance`'s
//! fit bookkeeping; and for ~70 frames after it the rate settles from the fit's
//! estimate, dropping the gather table at every step (~370 more per frame,
//! measured over frames 36..68 of a lock). Before the steady-state shortcuts
//! (below) 1 870 / 1 960 / 2 920 / 3 570 (firmware 1 920 / 3 690, young lock
//! 6 130). Before the young fit and centred confirmation 1 930 / 1 940 /
//! 2 970 / 3 560 (firmware 1 900 / 3 660).
//! Before the five-ring store took the chunks and range itself 1 940 / 1 945 /
//! 2 980 / 3 580 (firmware 1 910 / 3 700), before the five-ring store 1 970 /
//! 1 980 / 3 080 / 3 870 (firmware 1 940 / 3 990), before the gather took two windows per step 2 170 / 2 310 / 3 480 /
//! 4 500, and 4 400 / 5 200 / 12 200 / 19 700 for the earlier per-channel, per-bit
//! design. Per frame at 3x that is roughly: gathering the reference ~760 (about 44
//! per 32-sample window, 88 per two-window step; plus ~110 in the bench's window
//! for table entries met for the first time, which a running line stops paying
//! once its phases have all been seen; ~950 at 40 MHz, where the step loop
//! spills), its decode 125, the start-edge
//! confirmation ~80 and the tail confirmation ~230, the timing filter ~70, copying the rings (one ring: ~5 per
//! word with the per-call overhead, ~130 per frame; all five in vote5 / super: one
//! pass, ~2.5 per word and channel plus ~85 per call, ~430 per frame for all
//! five), per other channel ~8.5 per window for the centre compare plus ~60 of
//! set-up (~190; ~12 a window and ~220 before `matching` took them all in one call), and
//! ~520 of per-frame bookkeeping (`push_at`, `frame`, `next`, `edges`,
//! `evaluate`, `need`) for one channel, ~750 for five (~1 190 before the
//! shortcuts). The **steady-state shortcuts**: `frame` reads the delays in one
//! pass when every used channel is aligned (aligning the others out of line),
//! compares the other channels before gathering only those that differ, and
//! clears no per-channel patterns when none does; `evaluate` publishes a frame
//! every channel verified without the per-channel checks (as before); `next` takes a lone
//! measured reference that verified as the consensus (no median, its tracking
//! step is zero); `need` reads the latest delay kept in a field instead of
//! walking the channels twice a frame. Each concludes what the general path
//! does: a test build can turn them off, and `tests::steady` checks on random
//! lines (jitter, skew, glitches, dead and noisy channels, gaps, every mode and
//! chunking) that events, positions and the whole receiver state are the same
//! after every push. **Still over the 1 200-instruction budget of the worst path**;
//! what is left is listed in the README ("Known limits").

pub mod channel;
pub mod confirm;
pub mod gap;
pub mod hunt;
pub mod modes;
pub mod phase;
pub mod ring;
pub mod table;
pub mod timing;

use crate::hans::{DecodeError, Frame, FRAME_BITS};
use crate::model::{FaultKind, Line, LineEvent};
use channel::Channel;
use modes::{majority3, majority5, super_vote, SuperOutcome};
use ring::{diff, Centres, Ring, FRAC, HALF, RING_WORDS};
use table::Table;
use timing::Timing;

/// Number of HANS-100 data channels.
pub const CHANNELS: usize = 5;

/// The bit rate of the sender, Hz.
pub const BIT_RATE_HZ: u32 = 12_500_000;

/// Failing patterns in a row after which a channel's alignment (or, when no channel
/// verifies, the shared lock) is abandoned.
pub const RELOCK_AFTER: u8 = 3;

/// A channel that matches the reference and has a settled delay has its start edge
/// measured only every this many frames (its delay is a fixed skew).
const REMEASURE: u32 = 8;

/// Which channels are decoded and how they are combined (channels numbered 1..=5).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Mode {
    /// One channel, frames checked on their own.
    Normal {
        /// The channel, 1..=5.
        channel: u8,
    },
    /// Bitwise 2-of-3 majority of three channels' recovered bits, then the checks.
    Vote3 {
        /// The three channels, distinct, each 1..=5.
        channels: [u8; 3],
    },
    /// Bitwise 3-of-5 majority of all channels' recovered bits, then the checks.
    Vote5,
    /// Every channel checked on its own; majority of the verified frames.
    Super,
}

impl Mode {
    /// Bit n-1 set for every channel n the mode uses.
    pub const fn channel_mask(&self) -> u8 {
        match *self {
            Mode::Normal { channel } => bit(channel),
            Mode::Vote3 {
                channels: [a, b, c],
            } => bit(a) | bit(b) | bit(c),
            Mode::Vote5 | Mode::Super => 0b1_1111,
        }
    }
}

const fn bit(channel: u8) -> u8 {
    if channel >= 1 && channel <= CHANNELS as u8 {
        1 << (channel - 1)
    } else {
        0
    }
}

/// Why a receiver cannot be built.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// The sampling rate is not 3..=4 times the bit rate (37.5..=50 MHz).
    SampleRate {
        /// The rate given, Hz.
        hz: u32,
    },
    /// A channel number is not 1..=5, or a vote names one channel twice.
    Channel {
        /// The offending channel number.
        channel: u8,
    },
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::SampleRate { hz } => write!(
                f,
                "HANS-100 sampling rate {hz} Hz is not 3..4 times 12.5 MHz"
            ),
            Self::Channel { channel } => {
                write!(f, "HANS-100 channel {channel} is not 1..5 or used twice")
            }
        }
    }
}

/// What the receiver reports.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RxEvent {
    /// A frame that passed every check of its mode.
    Frame(Frame),
    /// A fault. `channel` is 1..=5 for a channel's own fault (a check failure, a
    /// resync, a super-mode minority, or [`FaultKind::Missing`]: the channel
    /// delivered no pattern this period), `None` for the frame period as a whole:
    /// in the vote and super modes a decoded period that publishes no frame
    /// ([`FaultKind::CheckFailed`]: the vote failed, or no super-mode channel
    /// verified; [`FaultKind::Disagree`]: no strict super-mode majority) or the
    /// shared timing lost ([`FaultKind::Resync`]); in any mode input discarded
    /// ([`FaultKind::Dropped`]). In normal mode the channel's faults are the
    /// period's.
    Fault {
        /// The channel, or `None` for the period.
        channel: Option<u8>,
        /// What happened.
        kind: FaultKind,
    },
}

impl RxEvent {
    /// The protocol-neutral event: frames via [`Frame::to_forward`], channel faults on
    /// [`Line::HansChannel`], period faults on [`Line::Framing`].
    pub fn to_line_event(&self) -> LineEvent {
        match *self {
            RxEvent::Frame(f) => LineEvent::Frame(f.to_forward()),
            RxEvent::Fault { channel, kind } => LineEvent::Fault {
                line: channel.map_or(Line::Framing, Line::HansChannel),
                kind,
            },
        }
    }
}

/// Counters of one channel (wrapping).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChannelStats {
    /// Patterns that passed every check.
    pub frames_ok: u32,
    /// Patterns that failed a check.
    pub check_failures: u32,
    /// Times the channel lost frame alignment.
    pub resyncs: u32,
    /// Frame periods in which the channel delivered no pattern at all: not aligned
    /// (dead, stuck, unplugged, or its start edge not found), or, while the frame
    /// timing is lost after a first lock, every nominal frame period of input. With
    /// `frames_ok` and `check_failures` it accounts for every locked frame period
    /// the channel was used in, each exactly once, but those whose input was
    /// skipped ([`HansRx::skipped`]).
    pub missing: u32,
}

/// The HANS-100 receiver (see the module docs).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct HansRx {
    mode: Mode,
    used: u8,
    stats: [ChannelStats; CHANNELS],
    rejected: u32,
    rings: [Ring; CHANNELS],
    /// Stream words stored per channel (wrapping).
    written: u32,
    channels: [Channel; CHANNELS],
    timing: Timing,
    table: Table,
    /// The reference's centres of the frame being decoded (kept here only to spare
    /// clearing it every frame).
    centres: Centres,
    locked: bool,
    /// While locked: the stream word (modulo 4 096) before which the frame has all
    /// its samples ([`HansRx::need`]).
    need: u32,
    /// The last decoded frame, whose successor's start edges are still to be
    /// measured: the channels that verified and those that matched the reference.
    pending: Option<(u8, u8)>,
    /// Index of the reference channel: gathered in full, the others compared to it.
    reference: usize,
    /// Consecutive frames in which no channel verified.
    dry: u8,
    /// Frames decoded (wrapping; paces the re-measuring of settled delays).
    frames: u32,
    /// While hunting: input (Q16 samples) since the last nominal frame period that
    /// was counted as missing on every used channel.
    idle: i32,
    /// The timing was locked once: from then on a hunt counts missing periods.
    /// Before, nothing says a line is there at all (power-up acquisition, a
    /// controller never connected: the bridge's input timeout covers that), and
    /// every healthy channel would count the acquisition's first periods.
    seen: bool,
    /// [`HansRx::latest`], kept up to date.
    late: i32,
    /// Test builds only: the steady-state shortcuts off, so that a test can compare
    /// them with the general path ([`HansRx::shortcuts`]).
    #[cfg(test)]
    general: bool,
    /// Skipped input ([`HansRx::skip`]).
    gaps: gap::Gaps,
}

impl HansRx {
    /// A receiver sampling at `sample_hz` (37.5..=50 MHz) in `mode`.
    pub fn new(sample_hz: u32, mode: Mode) -> Result<HansRx, ConfigError> {
        if !(3 * BIT_RATE_HZ..=4 * BIT_RATE_HZ).contains(&sample_hz) {
            return Err(ConfigError::SampleRate { hz: sample_hz });
        }
        match mode {
            Mode::Normal { channel } if bit(channel) == 0 => {
                return Err(ConfigError::Channel { channel });
            }
            Mode::Vote3 { channels } => {
                let mut seen = 0u8;
                for c in channels {
                    if bit(c) == 0 || seen & bit(c) != 0 {
                        return Err(ConfigError::Channel { channel: c });
                    }
                    seen |= bit(c);
                }
            }
            _ => {}
        }
        let ratio = (u64::from(sample_hz) << 16) / u64::from(BIT_RATE_HZ);
        // 3..=4 times 2^16 fits i32.
        let ratio = i32::try_from(ratio).unwrap_or(i32::MAX);
        let used = mode.channel_mask();
        Ok(HansRx {
            mode,
            used,
            stats: [ChannelStats::default(); CHANNELS],
            rejected: 0,
            rings: [Ring::default(); CHANNELS],
            written: 0,
            channels: [Channel::default(); CHANNELS],
            timing: Timing::new(ratio),
            table: Table::new(ratio),
            centres: Centres::default(),
            locked: false,
            need: 0,
            pending: None,
            reference: used.trailing_zeros() as usize,
            dry: 0,
            frames: 0,
            idle: 0,
            seen: false,
            late: 0,
            #[cfg(test)]
            general: false,
            gaps: gap::Gaps::default(),
        })
        .map(|mut rx| {
            rx.late = rx.latest();
            rx
        })
    }

    /// The decode mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Counters of channel 1..=5 (`None` for another number).
    pub fn stats(&self, channel: u8) -> Option<ChannelStats> {
        self.stats
            .get(usize::from(channel).checked_sub(1)?)
            .copied()
    }

    /// Decoded frame periods of the vote and super modes rejected as a whole (each
    /// also reported as a period fault): a vote failed its checks, no super-mode
    /// channel verified, or verified channels without a strict majority.
    pub fn rejected(&self) -> u32 {
        self.rejected
    }

    /// Feeds the next stretch of every ring: `chunks[n - 1]` is channel n's words.
    /// Channels the mode does not use may be missing or empty. The used channels'
    /// chunks must have equal length; if not, only the common length is decoded and
    /// a [`FaultKind::Dropped`] period fault is reported.
    pub fn push(&mut self, chunks: &[&[u16]], sink: &mut impl FnMut(RxEvent)) {
        self.push_at(chunks, &mut |_, e| sink(e));
    }

    /// [`HansRx::push`], with each event's position: the number of words of the
    /// chunks consumed when it was decided (0 for the unequal-length fault, which
    /// is about the whole push). A bridge loop spreads a DMA half's events over its
    /// output slots by this position, so faults take no output slot of their own.
    pub fn push_at(&mut self, chunks: &[&[u16]], sink: &mut impl FnMut(usize, RxEvent)) {
        let mut len = usize::MAX;
        let mut longest = 0;
        for (n, chunk) in chunks.iter().enumerate().take(CHANNELS) {
            if self.used & (1 << n) != 0 {
                len = len.min(chunk.len());
                longest = longest.max(chunk.len());
            }
        }
        let used_present = (0..CHANNELS)
            .filter(|n| self.used & (1 << n) != 0)
            .all(|n| n < chunks.len());
        if !used_present || len == usize::MAX {
            len = 0;
        }
        if longest > len {
            sink(
                0,
                RxEvent::Fault {
                    channel: None,
                    kind: FaultKind::Dropped,
                },
            );
        }
        let mut at = 0;
        loop {
            if self.locked {
                // Words still missing before the frame can be decoded (positions
                // count words modulo 4 096, see `ring`).
                let missing = ((self.need << 20).wrapping_sub(self.written << 20)) as i32 >> 20;
                if missing <= 0 {
                    // The start edges of this frame move the timing on from the
                    // last one, then the frame is decoded.
                    let mut sink = |e| sink(at, e);
                    if let Some((verified, same)) = self.pending.take() {
                        let pred = self.timing.predicted();
                        self.next(verified, same, &mut sink);
                        // The edge measured may lie up to the search window after
                        // the prediction `need` was computed from: then wait for
                        // the frame's last samples at the measured start. Decoding
                        // now would read the ring's stale words from 4 096 words
                        // ago for the tail, which can pass every check (the tail of
                        // an old frame: valid pairs and stop bits) with the head of
                        // this one. An edge a sample or more early leaves only the
                        // rate and delay steps, within `need`'s slack.
                        if self.locked && diff(self.timing.start, pred) > -(1 << FRAC) {
                            self.need = self.need();
                            continue;
                        }
                    }
                    if self.locked {
                        self.frame(&mut sink);
                    }
                    self.need = self.need();
                    continue;
                }
                if at >= len {
                    break;
                }
                let n = (missing as usize).min(len - at).min(RING_WORDS / 2);
                self.store(chunks, at, n);
                at += n;
            } else {
                if at >= len {
                    break;
                }
                self.store(chunks, at, 1);
                at += 1;
                self.hunt();
                if !self.locked && self.seen {
                    self.idle = self.idle.saturating_add(16 << FRAC);
                    if self.idle >= self.timing.nominal_period() {
                        self.idle = self.idle.saturating_sub(self.timing.nominal_period());
                        self.missing(self.used, &mut |e| sink(at, e));
                    }
                }
            }
        }
    }

    /// Copies words `at..at + n` of every used channel into the rings.
    fn store(&mut self, chunks: &[&[u16]], at: usize, n: usize) {
        // Read once: the ring writes could alias these fields for the compiler.
        let (written, used) = (self.written, self.used);
        self.written = written.wrapping_add(n as u32);
        // All five channels (vote5, super): one pass over the words for all rings.
        if used == 0b1_1111 && Ring::write_all(&mut self.rings, written, chunks, at, n) {
            return;
        }
        for (k, (ring, chunk)) in self.rings.iter_mut().zip(chunks).enumerate() {
            if used & (1 << k) != 0 {
                if let Some(src) = chunk.get(at..at + n) {
                    ring.write(written, src);
                }
            }
        }
    }

    /// The stream word (modulo 4 096) before which every sample the next frame
    /// needs has arrived: up to its successor's start edge on the latest channel,
    /// which confirms the frame's timing before it is published.
    fn need(&self) -> u32 {
        let t = &self.timing;
        #[cfg(test)]
        assert_eq!(self.late, self.latest(), "`late` missed a delay change");
        let late = self.late;
        // The frame to decode next starts at the current edge, or, once that frame
        // is done, at the predicted next one (whose edge window lies before its
        // last centre).
        let start = if self.pending.is_some() {
            t.predicted()
        } else {
            t.start
        };
        // The last sample is the latest one that confirms the next start edge
        // ([`HansRx::confirmed`]), 3/8 of a bit after where the timing puts it.
        let last = start
            .wrapping_add((t.ratio as u32).wrapping_mul(FRAME_BITS as u32))
            .wrapping_add(confirm_window(t.ratio))
            .wrapping_add((1 << FRAC) - 1);
        // Two samples of slack: a table-gathered centre (or a shifted compare) may
        // fall one sample after the exact position.
        (last.wrapping_add(late as u32).wrapping_add(2 << FRAC) >> 20).wrapping_add(1)
    }

    /// True unless a test turned the steady-state shortcuts off: `evaluate`'s for a
    /// frame every channel verified, `next`'s for a lone measured reference. Each
    /// concludes what the general path does; `tests::steady` checks that on
    /// random lines.
    #[inline(always)]
    fn shortcuts(&self) -> bool {
        #[cfg(test)]
        return !self.general;
        #[cfg(not(test))]
        true
    }

    /// The latest delay of a used channel; one not aligned counts as
    /// [`channel::DELAY_MAX`] (it may align at this frame that late). Kept in
    /// `late` by every change of a delay (six places: the hunt's lock, `align`,
    /// `evaluate`, `edges`, the tracking in `next`, `lose`), so that
    /// [`HansRx::need`], twice a frame, does not walk the channels.
    fn latest(&self) -> i32 {
        let mut late = 0;
        for (n, c) in self.channels.iter().enumerate() {
            if self.used & (1 << n) != 0 {
                late = late.max(c.delay.unwrap_or(channel::DELAY_MAX));
            }
        }
        late
    }

    /// Hunts in the word just stored, on every used channel; the first channel to
    /// confirm a frame period sets the shared timing.
    fn hunt(&mut self) {
        let index = self.written.wrapping_sub(1);
        let threshold = self.timing.hunt_threshold();
        let bounds = self.timing.bounds;
        let mut lock = None;
        for (n, (ch, ring)) in self.channels.iter_mut().zip(&self.rings).enumerate() {
            if self.used & (1 << n) == 0 {
                continue;
            }
            if let Some(found) = ch.hunt(ring, index, threshold, bounds) {
                lock = Some((n, found));
                break;
            }
        }
        if let Some((n, found)) = lock {
            self.timing.lock(found);
            self.locked = true;
            self.pending = None;
            self.reference = n;
            self.dry = 0;
            self.idle = 0;
            self.seen = true;
            for ch in self.channels.iter_mut() {
                ch.reset_hunt();
                ch.unalign();
            }
            if let Some(ch) = self.channels.get_mut(n) {
                ch.align(0);
            }
            self.late = self.latest();
            self.need = self.need();
        }
    }

    /// Decodes the frame at the current start edge on every aligned channel, then
    /// finds the next start edge.
    fn frame(&mut self, sink: &mut impl FnMut(RxEvent)) {
        let ratio = self.timing.ratio;
        let start = self.timing.start;
        let half_bit = (ratio / 2) as u32 + HALF;
        // Channels not aligned yet try at this frame's start edge. A settled lock
        // has every used channel aligned: then one pass over the delays is all.
        let used = self.used;
        let mut delays = [0i32; CHANNELS];
        let mut aligned = 0u8;
        for (n, (ch, d)) in self.channels.iter().zip(delays.iter_mut()).enumerate() {
            if let Some(delay) = ch.delay {
                *d = delay;
                aligned |= 1 << n;
            }
        }
        aligned &= used;
        if aligned != used {
            aligned = self.align(used & !aligned, aligned, &mut delays);
        }
        if aligned == 0 {
            self.lose(sink);
            return;
        }
        // Counted every period a channel stays dead: one test in the healthy case.
        if aligned != used {
            self.missing(used & !aligned, sink);
        }
        if aligned & (1 << self.reference) == 0 {
            self.reference = aligned.trailing_zeros() as usize;
        }
        let reference = self.reference;
        let delay = |n: usize| delays.get(n).copied().unwrap_or(0);
        let ref_delay = delay(reference);
        self.table.follow(ratio);
        let Some(ring) = self.rings.get(reference) else {
            return;
        };
        let first = start.wrapping_add(ref_delay as u32).wrapping_add(half_bit);
        let others = aligned & !(1 << reference);
        let ref_pattern = if others == 0 {
            ring.gather::<false>(&mut self.table, first, ratio as u32, &mut self.centres)
        } else {
            ring.gather::<true>(&mut self.table, first, ratio as u32, &mut self.centres)
        };
        // Every other channel against the reference's centres, shifted by the whole
        // samples between the two delays: a match means this channel's pattern is
        // the reference's.
        let mut same = 1u8 << reference;
        if others != 0 {
            same |= self.matching(others, &delays, ref_delay);
        }
        // The ones that differ are gathered in full at their own delay (only their
        // entries of `patterns` are read; none in the steady state, which then
        // spares clearing them).
        let differ = aligned & !same;
        let gathered;
        let patterns = if differ == 0 {
            &[0; CHANNELS]
        } else {
            let mut p = [0u128; CHANNELS];
            for n in bits(differ) {
                if let (Some(slot), Some(ring)) = (p.get_mut(n), self.rings.get(n)) {
                    *slot = ring.gather::<false>(
                        &mut self.table,
                        start.wrapping_add(delay(n) as u32).wrapping_add(half_bit),
                        ratio as u32,
                        &mut Centres::default(),
                    );
                }
            }
            gathered = p;
            &gathered
        };
        // The channels that matched the reference hold one pattern, read right if
        // any of them confirms the timing at its own delay (the reference first; a
        // noisy edge on one of them costs nothing); the others are confirmed on
        // their own.
        // Failing that, a frame whose edges show a rounding step is confirmed
        // re-read at the phase they show, and the timing moves there
        // (`rephased`), a reference tail rejected as an excursion on a line
        // that is not steady is counted again a hair beyond the far bound
        // (`recounted`), and the reference's tail gets its second look
        // (`looked_again`).
        let mut confirmed = 0u8;
        // The reference's own tail deviation, when it confirmed the frame itself:
        // the settled timing's phase measurement (`Timing::advance`).
        let measured = self.confirmed(reference, start, ref_delay, ratio, ref_pattern);
        self.timing.tail = measured.sum;
        if measured.sum.is_some()
            || bits(same & !(1 << reference)).any(|n| {
                self.confirmed(n, start, delay(n), ratio, ref_pattern)
                    .sum
                    .is_some()
            })
            || self.rephased_or_recounted(ref_pattern)
            || (measured.tail.is_none() && self.looked_again(ref_pattern))
        {
            confirmed = same;
        }
        for n in bits(differ) {
            if let Some(&p) = patterns.get(n) {
                if self.confirmed(n, start, delay(n), ratio, p).sum.is_some() {
                    confirmed |= 1 << n;
                }
            }
        }
        // The reference's far and off tail edges go into the line's record after
        // every check of this frame used the record as it was
        // (`confirm::excursion`).
        if let Some(tail) = measured.tail {
            self.timing.count_tail(tail);
        }
        // A young lock decodes and tracks, but publishes nothing yet (acquisition,
        // see `timing::SETTLED`), nor does a coasted one before a verified frame
        // has re-measured its phase (`Timing::recentring`); faults are reported as
        // ever.
        let settled = self.timing.settled() && !self.timing.recentring();
        let mut gated = |e: RxEvent| {
            if settled || !matches!(e, RxEvent::Frame(_)) {
                sink(e);
            }
        };
        let verified = self.evaluate(patterns, aligned, same, confirmed, ref_pattern, &mut gated);
        // A young lock learns phase and rate from the verified reference's mid-pair
        // edges (`timing::YOUNG`; not those of a frame re-read at a rounding step,
        // `Timing::refine`): every pair's while the fit is thin, then every other
        // pair's (`timing::DENSE`). In normal mode an unsettled frame that failed
        // may still read right a little over, and its edges correct a line the hunt
        // left off (`reread`). One test of the stage on a settled lock's path.
        if self.timing.young() {
            if let (true, Some(ring)) =
                (verified & (1 << reference) != 0, self.rings.get(reference))
            {
                let at = start.wrapping_add(ref_delay as u32);
                self.timing.learn(ring, at, ref_pattern);
            } else if verified == 0 && matches!(self.mode, Mode::Normal { .. }) {
                self.reread();
            }
        }
        self.pending = Some((verified, same));
    }

    /// The channels of `others` whose samples agree with the reference's centres
    /// ([`HansRx::frame`]), each shifted by the whole samples between its delay
    /// and the reference's. Out of line, with [`Ring::agrees`] inlined: one call
    /// a frame instead of one per channel.
    #[inline(never)]
    fn matching(&self, others: u8, delays: &[i32; CHANNELS], ref_delay: i32) -> u8 {
        let mut same = 0u8;
        for n in bits(others) {
            let (Some(ring), Some(&d)) = (self.rings.get(n), delays.get(n)) else {
                continue;
            };
            let rel = (d - ref_delay + HALF as i32) >> FRAC;
            if ring.agrees(&self.centres, rel) {
                same |= 1 << n;
            }
        }
        same
    }

    /// Aligns the channels of `mask` (used, not aligned) at this frame's start edge
    /// if they have one there; returns `aligned` with those that did, their delays
    /// in `delays`.
    #[inline(never)]
    fn align(&mut self, mask: u8, aligned: u8, delays: &mut [i32; CHANNELS]) -> u8 {
        let (start, ratio) = (self.timing.start, self.timing.ratio);
        let mut aligned = aligned;
        for n in bits(mask) {
            let (Some(ch), Some(ring), Some(d)) = (
                self.channels.get_mut(n),
                self.rings.get(n),
                delays.get_mut(n),
            ) else {
                continue;
            };
            if let Some(e) = Channel::edge(ring, start, ratio) {
                ch.align(diff(e, start));
            }
            if let Some(delay) = ch.delay {
                *d = delay;
                aligned |= 1 << n;
            }
        }
        self.late = self.latest();
        aligned
    }

    /// Confirmed when channel `n`'s start edges of this frame (at `start` plus its
    /// `delay`) and of the next one (a frame later by the bit timing the pattern
    /// was read with) both lie within [`confirm_window`] of where that timing puts
    /// them, and the frame's last mid-pair edges, measured with `pattern` (read at
    /// this channel's timing, or the reference's when the channel matched it
    /// centre for centre), on average within [`confirm::tail_window`] (a quarter
    /// bit; their deviations' mean size within 3/8, [`confirm::tail`]). Only then were the frame's bits read at their
    /// centres from the first to the last: a false or missing start edge that
    /// moved the tracking, or a phase that drifted or jumped within the frame,
    /// leaves a tail read a bit off, random content whose complement pairs pass at
    /// 2^-n (README "Known limits", docs/engineering-log.md). The start edge follows the stop field and the
    /// next falling edge comes two bits later, so no other edge of a good line
    /// lies in either start-edge window. The start edges are checked first: they
    /// are cheaper and fail more often. The tail is checked once the lock has
    /// settled ([`timing::SETTLED`]), i.e. on every frame that can be published:
    /// before, a verified frame only feeds the young lock's fit, and the first
    /// frames of a lock (its rate measured over one frame, up to a sample off at
    /// the tail) are exactly those whose mid-pair edges fix the rate. Checking
    /// one channel of those that matched the reference suffices for all of them:
    /// they hold its samples at every centre (shifted by whole samples), so edges
    /// where one member's timing puts them vouch for the pattern they share.
    /// A tail within those bounds is still rejected when its far edges make it a
    /// short excursion of the line's phase on a line whose recent tails had
    /// (nearly) none, fewer of them on a steady line ([`confirm::excursion`],
    /// `Timing::clean`, `Timing::steady`); that check is part of the
    /// confirmation, so every caller gets it. See [`Checked`] for what is
    /// returned.
    fn confirmed(&self, n: usize, start: u32, delay: i32, ratio: i32, pattern: u128) -> Checked {
        const FAILED: Checked = Checked {
            sum: None,
            tail: None,
        };
        let Some(ring) = self.rings.get(n) else {
            return FAILED;
        };
        let w = confirm_window(ratio);
        let head = start.wrapping_add(delay as u32);
        let next = head.wrapping_add((ratio as u32).wrapping_mul(FRAME_BITS as u32));
        let edges = [head, next]
            .into_iter()
            .all(|at| start_edge(ring, at, w).is_some());
        if !edges {
            FAILED
        } else if !self.timing.settled() {
            Checked {
                sum: Some(0),
                tail: None,
            }
        } else if let Some(t) = confirm::tail(ring, head, ratio, pattern) {
            self.judged(t)
        } else {
            FAILED
        }
    }

    /// The confirmation of a tail that passed [`confirm::tail`]'s bounds (or
    /// [`confirm::tail_again`]'s): unless it is a short excursion
    /// ([`confirm::excursion`]).
    #[inline(always)]
    fn judged(&self, t: confirm::Tail) -> Checked {
        Checked {
            sum: (!confirm::excursion(t, self.timing.clean(), self.timing.steady()))
                .then_some(t.sum),
            tail: Some(t),
        }
    }

    /// When the reference's frame (read at the timing and its delay as
    /// `pattern`) failed its confirmation on every channel holding it, its
    /// tail not within its bounds, and was not re-read at a rounding step ([`HansRx::rephased`]): true when
    /// it is confirmed after all with the tail's second look
    /// ([`confirm::tail_again`]: a tail whose mid-pair edges alone lie beyond
    /// a quarter bit, confirmed by the edges between its pairs), on a settled
    /// lock, both start edges in their windows and no short excursion, as
    /// [`HansRx::confirmed`] checks. The tail is then the timing's phase
    /// measurement and goes into the line's record (`Timing::count_tail`),
    /// as a tail that passed its first look does. Out of line and cold: a
    /// good line at ±25 % jitter needs it about once in 10^4 frames. A call
    /// in `confirmed` itself, however cold, spilled values in the steady
    /// state's 8-edge loop (+26 instructions a frame at normal 3x, QEMU).
    #[cold]
    #[inline(never)]
    fn looked_again(&mut self, pattern: u128) -> bool {
        let ratio = self.timing.ratio;
        let Some(Second { ring, head, .. }) =
            second_started(&self.rings, &self.channels, &self.timing, self.reference)
        else {
            return false;
        };
        let Some(t) = confirm::tail_again(ring, head, ratio, pattern) else {
            return false;
        };
        let checked = self.judged(t);
        self.timing.tail = checked.sum;
        self.timing.count_tail(t);
        checked.sum.is_some()
    }

    /// [`HansRx::rephased`], failing that [`HansRx::recounted`]: one cold call
    /// in [`HansRx::frame`]'s chain of fallbacks. A call of its own there
    /// (however cold) moved the steady state's code: +18 instructions a frame
    /// on every `hans rx` row (QEMU, 2026-12-04).
    #[cold]
    #[inline(never)]
    fn rephased_or_recounted(&mut self, pattern: u128) -> bool {
        self.rephased(pattern) || self.recounted(pattern)
    }

    /// When the reference's frame (read at the timing and its delay as
    /// `pattern`) failed its confirmation on every channel holding it, its
    /// tail within its bounds ([`confirm::tail`]) but rejected as a short
    /// excursion ([`confirm::excursion`]) on a line that is not steady
    /// (`Timing::steady`: jitter to speak of), and both start edges in their
    /// windows: true when fewer than [`confirm::FAR_EDGES`] of its edges lie
    /// [`confirm::FAR_SLACK`] (1/32 sample) or more beyond the far bound
    /// ([`confirm::far_beyond`]). The tail is then the timing's phase
    /// measurement, as a confirmed one is; the line's record
    /// (`Timing::count_tail`, in [`HansRx::frame`]) still counts its far edges
    /// at the bound.
    ///
    /// Why: the record and the frame counted far edges at one bound, so a
    /// jittered line whose edges a sample off measured a hair under it (and
    /// counted as clean) lost a frame as soon as the timing moved them a hair
    /// over: at 4x with the timing a quarter sample off the sampling grid
    /// every edge a sample early measures 1.25 samples (the bound) to a
    /// hundredth, 1.249 on one frame and 1.251 two frames later; at 3x with
    /// a 0.01 % offset late edges moved from 0.84..0.90 sample to 0.95 within
    /// two frames (`limits_over_many_locks` at 640 locks a point, seeds 20587,
    /// 323 and 10185, docs/engineering-log.md 2026-12-03 `tol25`). A slack
    /// between the two is a hysteresis: the frame is judged with a bound the
    /// record's edges had to stay under. Not on a steady line, whose edges sit
    /// at fixed roundings: at 3.2x the far bound is one sample, where a
    /// slipped edge a sample off measures on a line without jitter, and the
    /// slack published frames not sent there (`tests::tail::BEYOND`, 3 and 4
    /// pairs, +2 to +6 lines, tried 2026-12-04). Cold: only a frame that
    /// failed every other confirmation gets here.
    fn recounted(&mut self, pattern: u128) -> bool {
        if self.timing.steady() {
            return false;
        }
        let ratio = self.timing.ratio;
        let Some(Second { ring, head, .. }) =
            second_started(&self.rings, &self.channels, &self.timing, self.reference)
        else {
            return false;
        };
        // Only a tail that the excursion check alone rejected.
        let Some(t) = confirm::tail(ring, head, ratio, pattern) else {
            return false;
        };
        let clean = self.timing.clean();
        let far = confirm::far_beyond(ring, head, ratio, pattern, confirm::FAR_SLACK);
        if !confirm::excursion(t, clean, false)
            || confirm::excursion(confirm::Tail { far, ..t }, clean, false)
        {
            return false;
        }
        self.timing.tail = Some(t.sum);
        true
    }

    /// After the reference's frame (read at the timing and its delay as
    /// `pattern`) failed its confirmation on every channel holding it:
    /// true when it is confirmed after all at another phase, and the timing has
    /// moved there ([`timing::Timing::rephase`]), because its edges show a
    /// rounding step ([`confirm::stepped`]: a clean line within a few hundred ppm
    /// of a whole number of samples a bit, whose tail measures a sample off the
    /// timing at the step). Only a settled lock's frame whose pattern passed its
    /// checks and whose start edges lie in their windows (so the tail failed) is
    /// tried: re-read from scratch at its successor's start edge, it must read the
    /// same pattern there and pass every check of [`HansRx::confirmed`] at that
    /// phase, the tail at the usual bounds. The channels that matched the
    /// reference hold its pattern and are confirmed with it, as ever. Out of line
    /// and cold: the steady state never calls it. The successor's edge was found
    /// in the window `need` waits for and lies in the shifted window, so samples
    /// past that window's end (which may not have arrived) cannot change its
    /// outcome; the centres read lie before it.
    #[cold]
    #[inline(never)]
    fn rephased(&mut self, pattern: u128) -> bool {
        let n = self.reference;
        let (start, ratio) = (self.timing.start, self.timing.ratio);
        let Some(Second {
            ring,
            delay,
            head,
            next,
            w,
        }) = second(&self.rings, &self.channels, &self.timing, n)
        else {
            return false;
        };
        if Frame::decode(pattern).is_err() {
            return false;
        }
        // Each start edge against where the timing puts it, found as `confirmed`
        // finds it.
        let edge = |at: u32| start_edge(ring, at, w).map(|e| diff(e, at));
        let (Some(d0), Some(d1)) = (edge(head), edge(next)) else {
            return false;
        };
        if !confirm::stepped(ring, head, ratio, pattern, d0, d1) {
            return false;
        }
        let first = head
            .wrapping_add((ratio / 2) as u32 + HALF)
            .wrapping_add(d1 as u32);
        let again = ring.gather::<false>(
            &mut self.table,
            first,
            ratio as u32,
            &mut Centres::default(),
        );
        let shifted = delay.wrapping_add(d1);
        // A shift of zero would be the reading that failed.
        let ok = d1 != 0
            && again == pattern
            && self
                .confirmed(n, start, shifted, ratio, pattern)
                .sum
                .is_some();
        if ok {
            self.timing.rephase(d1);
        }
        ok
    }

    /// A young lock's frame that its one channel (normal mode) did not verify,
    /// before the lock has settled (nothing is published yet): when both its
    /// start edges lie in their windows (as [`HansRx::confirmed`] wants them)
    /// and it reads right (start pair, 60 complement pairs, stop bits) at a
    /// phase moved by one of [`REREAD`], its 61 mid-pair edges, measured
    /// against the timing with that reading, go into the young fit
    /// ([`Timing::refine`], which takes no correction of half a bit or more).
    /// The frame stays unverified: it counts as a failure as before, is never
    /// published and feeds nothing else.
    ///
    /// Why: the hunt's line through two jittered frames is now and then ~0.3
    /// sample and ~0.2 sample a frame off at ±25 % jitter, where a 3x centre
    /// has as little as 0.25 sample of margin. The lock's first frames then
    /// read a pair or two wrong near their ends, none verifies, so no mid-pair
    /// edge corrects the line (a start edge a frame moves a fit of 125 points
    /// little), the phase drifts on, and after six failures the lock is dropped
    /// and the hunt starts over: 9 frames and more lost (12 of the 17 locks
    /// of 640 a point that lost frames at ±20 / ±25 % in the many-locks
    /// measurement of `host-tests/tests/hans_line.rs`, docs/engineering-log.md
    /// 2026-12-03). Read an eighth or a quarter of a bit over, such a frame
    /// reads right, and its edges put the line back. A misaligned lock (on a
    /// data edge) reads its complement pairs across pairs, each passing at
    /// about one in two: it learns nothing and is dropped as before.
    ///
    /// Normal mode only: in the vote and super modes a young lock saved so
    /// went on to move its reference to a channel whose young delay was ~0.3
    /// sample off, which tilted the fit's later points (the rate 6.7e-3 bit a
    /// frame off after the young fit, `tests::gap`, seed 10 at +1 %; the
    /// relock it replaced started clean). Out of line and cold: a settled lock
    /// never calls it.
    #[cold]
    #[inline(never)]
    fn reread(&mut self) {
        if self.timing.settled() {
            return;
        }
        let n = self.reference;
        let (start, ratio) = (self.timing.start, self.timing.ratio);
        let (Some(ring), Some(delay)) = (
            self.rings.get(n),
            self.channels.get(n).and_then(|c| c.delay),
        ) else {
            return;
        };
        let w = confirm_window(ratio);
        let head = start.wrapping_add(delay as u32);
        let next = head.wrapping_add((ratio as u32).wrapping_mul(FRAME_BITS as u32));
        if ![head, next]
            .into_iter()
            .all(|at| start_edge(ring, at, w).is_some())
        {
            return;
        }
        let centre = head.wrapping_add((ratio / 2) as u32 + HALF);
        for part in REREAD {
            let first = centre.wrapping_add((ratio / part) as u32);
            let pattern = ring.gather::<false>(
                &mut self.table,
                first,
                ratio as u32,
                &mut Centres::default(),
            );
            if Frame::decode(pattern).is_ok() {
                self.timing
                    .refine(&phase::mid_pairs(ring, head, ratio, pattern));
                return;
            }
        }
    }

    /// Checks every pattern and applies the decode mode. Returns the channels that
    /// verified. `present`: the channels with a pattern; those of `same` hold
    /// `ref_pattern`, the others theirs in `patterns`.
    fn evaluate(
        &mut self,
        patterns: &[u128; CHANNELS],
        present: u8,
        same: u8,
        confirmed: u8,
        ref_pattern: u128,
        sink: &mut impl FnMut(RxEvent),
    ) -> u8 {
        let ref_decoded = Frame::decode(ref_pattern);
        // The steady state: every used channel holds the reference's pattern, its
        // timing confirmed, and it passed. Every channel verified that one frame, so
        // every mode publishes it (what the general path below concludes too).
        if same & confirmed == self.used && present == self.used && self.shortcuts() {
            if let Ok(f) = ref_decoded {
                // All five slots with a mask test, not the set bits: unrolled with
                // constant offsets, no index arithmetic per channel.
                let slots = self.stats.iter_mut().zip(self.channels.iter_mut());
                for (n, (stats, ch)) in slots.enumerate() {
                    if present & (1 << n) != 0 {
                        stats.frames_ok = stats.frames_ok.wrapping_add(1);
                        ch.failures = 0;
                    }
                }
                sink(RxEvent::Frame(f));
                return present;
            }
        }
        let mut verified: [Option<Frame>; CHANNELS] = [None; CHANNELS];
        let mut ok = 0u8;
        let mut unaligned = false;
        for n in bits(present) {
            let (Some(p), Some(stats), Some(ch)) = (
                patterns.get(n),
                self.stats.get_mut(n),
                self.channels.get_mut(n),
            ) else {
                continue;
            };
            let decoded = if confirmed & (1 << n) == 0 {
                None
            } else if same & (1 << n) != 0 {
                ref_decoded.ok()
            } else {
                Frame::decode(*p).ok()
            };
            match decoded {
                Some(f) => {
                    stats.frames_ok = stats.frames_ok.wrapping_add(1);
                    ch.failures = 0;
                    ok |= 1 << n;
                    if let Some(v) = verified.get_mut(n) {
                        *v = Some(f);
                    }
                }
                None => {
                    stats.check_failures = stats.check_failures.wrapping_add(1);
                    sink(RxEvent::Fault {
                        channel: Some(number(n)),
                        kind: FaultKind::CheckFailed,
                    });
                    ch.failures = ch.failures.saturating_add(1);
                    // A channel that keeps failing is taken to be misaligned (a
                    // delay measured on a glitch): it aligns again from scratch.
                    if ch.failures >= self.timing.relock_after() && ch.unalign() {
                        unaligned = true;
                        stats.resyncs = stats.resyncs.wrapping_add(1);
                        sink(RxEvent::Fault {
                            channel: Some(number(n)),
                            kind: FaultKind::Resync,
                        });
                    }
                }
            }
        }
        if unaligned {
            self.late = self.latest();
        }
        // An unconfirmed channel counts as failed: it votes zeros, as a dead line.
        let all = same & confirmed == self.used && self.shortcuts();
        let get = |c: u8| match usize::from(c).checked_sub(1) {
            Some(i) if confirmed & present & same & (1 << i) != 0 => ref_pattern,
            Some(i) if confirmed & present & (1 << i) != 0 => patterns.get(i).copied().unwrap_or(0),
            _ => 0,
        };
        match self.mode {
            Mode::Normal { channel } => {
                let i = usize::from(channel).saturating_sub(1);
                // The channel's own fault (already reported) is the period's.
                if let Some(Some(f)) = verified.get(i) {
                    sink(RxEvent::Frame(*f));
                }
            }
            // Every voter holding the reference's pattern: the majority is that
            // pattern, already checked.
            Mode::Vote3 { .. } | Mode::Vote5 if all => self.voted(ref_decoded, sink),
            Mode::Vote3 {
                channels: [a, b, c],
            } => {
                self.voted(Frame::decode(majority3(get(a), get(b), get(c))), sink);
            }
            Mode::Vote5 => {
                let v = majority5([get(1), get(2), get(3), get(4), get(5)]);
                self.voted(Frame::decode(v), sink);
            }
            // Every verified channel holds the reference's frame: it is the majority.
            Mode::Super if all => match ref_decoded {
                Ok(f) => sink(RxEvent::Frame(f)),
                Err(_) => self.reject(FaultKind::CheckFailed, sink),
            },
            Mode::Super => match super_vote(&verified) {
                SuperOutcome::Nothing => self.reject(FaultKind::CheckFailed, sink),
                SuperOutcome::Publish { frame, minority } => {
                    for n in 0..CHANNELS {
                        if minority & (1 << n) != 0 {
                            sink(RxEvent::Fault {
                                channel: Some(number(n)),
                                kind: FaultKind::Disagree,
                            });
                        }
                    }
                    sink(RxEvent::Frame(frame));
                }
                SuperOutcome::Disagree => self.reject(FaultKind::Disagree, sink),
            },
        }
        ok
    }

    /// Publishes a voted pattern if it passed every check.
    fn voted(&mut self, decoded: Result<Frame, DecodeError>, sink: &mut impl FnMut(RxEvent)) {
        match decoded {
            Ok(f) => sink(RxEvent::Frame(f)),
            Err(_) => self.reject(FaultKind::CheckFailed, sink),
        }
    }

    /// Reports a decoded period that publishes no frame, as a whole (`channel:
    /// None`), whatever its channels reported: the bridge tells a lost period from
    /// a channel fault the mode rode through by this event alone.
    fn reject(&mut self, kind: FaultKind, sink: &mut impl FnMut(RxEvent)) {
        self.rejected = self.rejected.wrapping_add(1);
        sink(RxEvent::Fault {
            channel: None,
            kind,
        });
    }

    /// Finds the next start edge on every aligned channel and moves the shared
    /// timing and the delays on. `verified`: the channels whose frame just passed.
    fn next(&mut self, verified: u8, same: u8, sink: &mut impl FnMut(RxEvent)) {
        let pred = self.timing.predicted();
        // Each channel's estimate of the shared start edge, as an error against the
        // prediction. A channel that matched the reference centre for centre and
        // whose delay has settled is certainly still aligned, so it is measured only
        // every [`REMEASURE`]th frame, or when the reference's edge is missing or
        // untrusted.
        let mut errs = [0i32; CHANNELS];
        self.frames = self.frames.wrapping_add(1);
        let reference = 1u8 << self.reference;
        // No other channel matched (normal mode, or a frame they all differed
        // on): none to skip, and the channels are not read.
        let skip = if self.frames.is_multiple_of(REMEASURE) || same & !reference == 0 {
            0
        } else {
            let mut settled = 0u8;
            for (n, ch) in self.channels.iter().enumerate() {
                if ch.settled() {
                    settled |= 1 << n;
                }
            }
            settled & same & !reference
        };
        let mut found = self.edges(self.used & !skip, pred, &mut errs, sink);
        if found & verified & reference == 0 {
            found |= self.edges(skip, pred, &mut errs, sink);
        }
        // The steady state: only the reference was measured, and it verified. It
        // alone is trusted, so the consensus is its own edge and its deviation from
        // it zero (what the general path below concludes too).
        if found == reference && verified & reference != 0 && self.shortcuts() {
            let err = errs.get(self.reference).copied().unwrap_or(0);
            if !self.timing.advance(err) {
                self.lose(sink);
                return;
            }
            if let Some(ch) = self.channels.get_mut(self.reference) {
                ch.hold();
            }
            self.dry = 0;
            return;
        }
        // Channels that just verified are trusted; the others only when none did.
        let trusted = if found & verified != 0 {
            found & verified
        } else {
            found
        };
        let err = if trusted & verified & reference != 0 {
            // A verified reference times the frame alone, as on every frame the
            // others are not measured: its delay (its deviation from its own
            // edge) then stays put and anchors every other delay, and the timing
            // follows one channel's edges as in normal mode. A consensus of
            // several channels here, every [`REMEASURE`]th frame, moved every
            // delay toward it, the reference's too, and nothing held their common
            // part: it wandered with the jitter, the reference's next edges
            // read that wander as phase steps, and the filter's rate with it
            // (at 3x, ±25 % jitter: ~2e-3 bit a frame rms, 6e-3 worst in vote5 /
            // super against 2.5e-4 / 7e-4 for one channel).
            errs.get(self.reference).copied().unwrap_or(0)
        } else {
            // The upper median shrugs off a glitch on a minority of channels (a
            // glitch before the real edge reads early).
            let mut picked = [0i32; CHANNELS];
            let mut count = 0;
            for n in bits(trusted) {
                if let (Some(slot), Some(&e)) = (picked.get_mut(count), errs.get(n)) {
                    *slot = e;
                    count += 1;
                }
            }
            let picked = picked.get_mut(..count).unwrap_or_default();
            if count > 1 {
                picked.sort_unstable();
            }
            let Some(&err) = picked.get(count / 2) else {
                self.lose(sink);
                return;
            };
            // The reference's tail measured the phase at the reference's edge
            // only.
            self.timing.tail = None;
            err
        };
        if !self.timing.advance(err) {
            self.lose(sink);
            return;
        }
        // Each delay follows its channel's deviation from the consensus only, so a
        // lone channel's delay stays put and the shared filter alone smooths its
        // jitter.
        for n in bits(found) {
            let (Some(ch), Some(stats), Some(&e)) =
                (self.channels.get_mut(n), self.stats.get_mut(n), errs.get(n))
            else {
                continue;
            };
            let Some(d) = ch.delay else { continue };
            if !ch.track(e.wrapping_add(d).wrapping_sub(err)) {
                stats.resyncs = stats.resyncs.wrapping_add(1);
                sink(RxEvent::Fault {
                    channel: Some(number(n)),
                    kind: FaultKind::Resync,
                });
            }
        }
        self.late = self.latest();
        // Keep the reference while it verifies and has its edge; otherwise the first
        // channel that does, or at least has an edge.
        if trusted & reference == 0 {
            self.reference = trusted.trailing_zeros() as usize;
        }
        if verified == 0 {
            self.dry = self.dry.saturating_add(1);
            // A lock that yields nothing but failures is a false lock (on a data
            // edge that happened to repeat a frame apart, or a rate far off).
            if self.dry >= self.timing.relock_after() {
                self.lose(sink);
            }
        } else {
            self.dry = 0;
        }
    }

    /// Searches the next start edge of the aligned channels of `mask` around their
    /// predicted positions; stores each one's error against `pred` in `errs` and
    /// returns those found. A channel without an edge loses its alignment.
    fn edges(
        &mut self,
        mask: u8,
        pred: u32,
        errs: &mut [i32; CHANNELS],
        sink: &mut impl FnMut(RxEvent),
    ) -> u8 {
        let ratio = self.timing.ratio;
        let mut found = 0u8;
        let mut lost = false;
        for n in bits(mask) {
            let (Some(ch), Some(ring), Some(stats), Some(err)) = (
                self.channels.get_mut(n),
                self.rings.get(n),
                self.stats.get_mut(n),
                errs.get_mut(n),
            ) else {
                continue;
            };
            let Some(d) = ch.delay else { continue };
            match Channel::edge(ring, pred.wrapping_add(d as u32), ratio) {
                Some(e) => {
                    *err = diff(e, pred).wrapping_sub(d);
                    found |= 1 << n;
                }
                None => {
                    ch.unalign();
                    lost = true;
                    stats.resyncs = stats.resyncs.wrapping_add(1);
                    sink(RxEvent::Fault {
                        channel: Some(number(n)),
                        kind: FaultKind::Resync,
                    });
                }
            }
        }
        if lost {
            self.late = self.latest();
        }
        found
    }

    /// Counts a frame period in which the channels of `mask` delivered no pattern.
    ///
    /// One [`FaultKind::Missing`] event per channel and period, not one per change:
    /// the bridge's per-line counters (and the firmware's once-a-second stats line)
    /// then show a dead channel's count growing at the frame rate, as the issue
    /// asks, with no state here to say when to report. The cost is bounded and paid
    /// only while a channel is dead: an increment and a sink call per channel and
    /// period (the bridge applies its time check and counts such an event with a
    /// saturating add, nothing else), against ~4 000 instructions for the period's decode; no more events
    /// per period than a noisy channel already gives (a check failure each period).
    /// A healthy period pays the one compare in [`HansRx::frame`]: `cargo xtask
    /// qemu` measured +1 instruction per frame in normal mode, +9 in super mode
    /// and +6 on the worst path.
    // Out of line and cold: the healthy per-frame path only tests for it.
    #[cold]
    #[inline(never)]
    fn missing(&mut self, mask: u8, sink: &mut impl FnMut(RxEvent)) {
        for n in bits(mask) {
            if let Some(stats) = self.stats.get_mut(n) {
                stats.missing = stats.missing.wrapping_add(1);
                sink(RxEvent::Fault {
                    channel: Some(number(n)),
                    kind: FaultKind::Missing,
                });
            }
        }
    }

    /// Gives up the shared timing: in the vote and super modes a period resync (no
    /// frame until the hunt locks again; in normal mode the channel's resync says
    /// it), every aligned channel reports a resync, the frame period at hand (whose
    /// samples are all in) counts as missing on every used channel, and the hunt
    /// starts over from the next word, counting on.
    fn lose(&mut self, sink: &mut impl FnMut(RxEvent)) {
        if !matches!(self.mode, Mode::Normal { .. }) {
            sink(RxEvent::Fault {
                channel: None,
                kind: FaultKind::Resync,
            });
        }
        self.locked = false;
        self.pending = None;
        self.dry = 0;
        self.idle = 0;
        for (n, (ch, stats)) in self.channels.iter_mut().zip(&mut self.stats).enumerate() {
            ch.reset_hunt();
            if ch.unalign() {
                stats.resyncs = stats.resyncs.wrapping_add(1);
                sink(RxEvent::Fault {
                    channel: Some(number(n)),
                    kind: FaultKind::Resync,
                });
            }
        }
        self.late = self.latest();
        self.missing(self.used, sink);
    }
}

/// What [`HansRx::confirmed`] found for one channel's frame.
#[derive(Clone, Copy)]
struct Checked {
    /// The frame is confirmed, short-excursion check included: its tail's summed
    /// deviation ([`confirm::Tail::sum`]; 0 before the lock has settled, when the
    /// tail is not measured), the phase measurement `Timing::advance` blends in.
    /// `None` when a start edge or the tail failed, or the tail is an excursion.
    sum: Option<i32>,
    /// A settled lock's tail that passed the bounds of [`confirm::tail`],
    /// whether or not [`confirm::excursion`] rejected it: its far and off
    /// edges are what the line's record counts for the reference
    /// (`Timing::count_tail`). `None` when no tail was measured.
    tail: Option<confirm::Tail>,
}

/// The phase shifts [`HansRx::reread`] tries, in that order, as divisors of the
/// bit (negative: earlier): an eighth of a bit either way (0.375 to 0.5 sample),
/// then a quarter.
const REREAD: [i32; 4] = [8, -8, 4, -4];

/// Half-width (Q16 samples) of the windows in which [`HansRx::confirmed`] wants a
/// frame's start edge and its successor's: 3/8 of a bit (the frame's tail is
/// checked on its mid-pair edges, [`confirm::tail_window`]). A good line's edge lies
/// within its jitter plus half a sample (1/6 bit at 3x) of a settled prediction,
/// so up to about +-20 % jitter costs nothing. Half a bit let one wrong frame in
/// 250 000 through in the HANS campaign (normal mode, +-15 % jitter, edge faults):
/// the phase error a check can see must stay well inside the half bit at which a
/// centre reads its neighbour.
fn confirm_window(ratio: i32) -> u32 {
    (ratio * 3 / 8) as u32
}

/// Where a second reading of the reference's frame starts, for
/// [`HansRx::rephased`] and [`HansRx::looked_again`]: the reference channel's
/// ring and delay, the frame's start (`head`) and its successor's (`next`) at the
/// timing, and the start-edge window `w`. `None` unless the lock has settled and
/// the channel's delay is known. A free function over the fields it reads, so
/// that the ring stays borrowed while the callers use the decoder's table.
fn second<'a>(
    rings: &'a [Ring; CHANNELS],
    channels: &[Channel; CHANNELS],
    timing: &Timing,
    n: usize,
) -> Option<Second<'a>> {
    let ring = rings.get(n)?;
    let delay = channels.get(n)?.delay?;
    if !timing.settled() {
        return None;
    }
    let ratio = timing.ratio;
    let head = timing.start.wrapping_add(delay as u32);
    Some(Second {
        ring,
        delay,
        head,
        next: head.wrapping_add((ratio as u32).wrapping_mul(FRAME_BITS as u32)),
        w: confirm_window(ratio),
    })
}

/// [`second`], when both start edges (the frame's and its successor's) lie
/// in their windows: where the cold second looks ([`HansRx::looked_again`],
/// [`HansRx::recounted`]) start, as [`HansRx::confirmed`] requires of a frame.
fn second_started<'a>(
    rings: &'a [Ring; CHANNELS],
    channels: &[Channel; CHANNELS],
    timing: &Timing,
    n: usize,
) -> Option<Second<'a>> {
    let s = second(rings, channels, timing, n)?;
    [s.head, s.next]
        .into_iter()
        .all(|at| start_edge(s.ring, at, s.w).is_some())
        .then_some(s)
}

/// What [`second`] finds.
struct Second<'a> {
    ring: &'a Ring,
    delay: i32,
    head: u32,
    next: u32,
    w: u32,
}

/// The start edge (Q16, as [`Ring::first_fall`] gives it) within `w` of `at` on
/// `ring`, for [`HansRx::confirmed`] and [`HansRx::rephased`]. Centred: the low
/// samples an edge within `w` of `at` can give (the first sample after the edge,
/// `ceil(at - w)..=ceil(at + w)`; `first_fall` rounds its bounds down).
#[inline(always)]
fn start_edge(ring: &Ring, at: u32, w: u32) -> Option<u32> {
    let up = (1 << FRAC) - 1;
    ring.first_fall(
        at.wrapping_sub(w).wrapping_add(up),
        at.wrapping_add(w).wrapping_add(up),
    )
}

/// The indices of the set bits of `mask`, lowest first.
fn bits(mask: u8) -> impl Iterator<Item = usize> {
    let mut m = u32::from(mask);
    // Tested for zero first: a nonzero word's trailing zeros are two instructions
    // on the M7, and the loops here run a few dozen times a frame.
    core::iter::from_fn(move || {
        if m == 0 {
            return None;
        }
        let n = m.trailing_zeros() as usize;
        m &= m - 1;
        Some(n)
    })
}

/// Channel number 1..=5 of channel index 0..=4.
fn number(n: usize) -> u8 {
    // Truncation cannot happen: n < CHANNELS.
    (n as u8).wrapping_add(1)
}

#[cfg(test)]
mod tests;
