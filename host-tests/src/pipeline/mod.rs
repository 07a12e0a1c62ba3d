//! The whole bridge on the host: controller-side DMA buffers in, head-side DMA
//! buffers out, and the status path back, through exactly the `shared` code the
//! firmware runs (receivers, [`Bridge`], transmitters, status receivers/senders).
//!
//! # The synchronous core: [`Pipeline`]
//! ```text
//! controller lines (DMA buffers, README "DMA buffer layouts")
//!   -> Pipeline::feed(now_ns, ControllerInput::{Xy2, Xy3, Hans})
//!      -> xy2::rx / xy3::rx / hans::rx  -> LineEvents -> Bridge::on_line_event
//!   -> Pipeline::run_until(now_ns): output slots -> Bridge::tick -> xy2::tx /
//!      xy3::tx (BSRR words) / hans ring (hans::tx) -> HeadOutput
//! head status lines
//!   -> Pipeline::feed_status(now_ns, HeadStatusInput::{Xy2Level, Xy2Word, Xy3Back,
//!      HansStatus}) -> debouncer / status-word receiver / backchannel parser /
//!      HANS STATUS receiver -> the head's HeadStatus, copied into the bridge
//!      (Bridge::head_status_mut) + status_seen, as the firmware's status tasks do
//!   -> controller status (every 10 us): XY2 STATUS level changes, XY2 status words
//!      (one per controller frame), XY3 backchannel bytes (Bridge::xy3_back_poll, a
//!      UART at the controller-side rate), HANS STATUS frames (a second hans ring)
//!      -> ControllerStatus
//! ```
//! Time is the caller's: every call carries `now_ns` (monotonic, nanoseconds). All
//! events of one [`Pipeline::feed`] call are stamped with its `now_ns` (the moment
//! the firmware would have the buffer: a DMA half, or one sample when fed finely;
//! [`Pipeline::feed_spread`] spreads a DMA half's events over the following span
//! as the firmware's bridge loop does);
//! before they are applied, every output slot due before `now_ns` is computed, so
//! the output never sees the future.
//!
//! # Output timing
//! - **Free-running**: slot `k` plays from `k / frame_rate_hz` (first slot at 0) and
//!   is computed [`Options::lead_slots`] slot periods earlier (an XY2-100 / XY3-100
//!   slot must be in the ring before the DMA reaches it); HANS-100 heads use the
//!   firmware's ring ([`shared::hans::tx::Transmitter`], written
//!   [`shared::hans::tx::LEAD_SLOTS`] slots ahead) and the lead is that.
//! - **Slaved**: each frame the bridge forwards from `on_line_event` starts at the
//!   first output tick at least [`Options::slaved_lead_ns`] after its input event
//!   (later if the previous frame is still playing); the fail-safe frames (hold,
//!   park) are still clocked at the configured rate, as the engine specifies.
//! - As in the firmware (`firmware/tasks/line.rs`): every slot is idle until the
//!   bridge was first `Running` (no park frames before the controller spoke), and a
//!   frame the head cannot take (an axis without a position, a driven Z line without
//!   Z) is an idle slot, never a guessed frame.
//!
//! The record of every frame sent ([`SentFrame`]), the laser gate and link state
//! changes are kept for tests; [`HeadOutput::to_waveform`] and the
//! [`ControllerStatus`] helpers turn the buffers into waveforms (`crate::line`).
//!
//! # Parts
//! - [`Pipeline`] = controller-side receiver + head-side status receiver + [`Core`]
//!   (bridge, output clock and encoder, controller-side status);
//! - [`tasks`]: the same parts as the firmware's task graph (embassy-executor
//!   tasks, embassy-sync channels, simulated clock), tested to give the same output;
//! - [`stimulus`]: controller signals from `shared`'s transmitters, waveforms ->
//!   time-stamped DMA buffers, head status stimuli;
//! - [`check`]: independent decoding of the head-side output, expected values;
//! - [`latency`]: the added latency per pairing (bin `pipeline-latency`).

pub mod check;
mod core;
mod ctrl_status;
mod head_status;
mod input;
pub mod latency;
mod output;
pub mod stimulus;
pub mod tasks;
mod tx;

use std::fmt;

pub use self::core::Core;
pub use ctrl_status::{BackByte, ControllerStatus};
pub use head_status::{HansStatusHalf, HANS_STATUS_HALF};
pub use output::{HeadOutput, SentFrame, HEAD_PINS_XY2, HEAD_PINS_XY3};

use shared::bridge::{Bridge, Config, ConfigError, Counters, LinkState};
use shared::model::LineEvent;

/// Modelling choices of the pipeline that the configuration does not fix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Options {
    /// HANS-100 controller input: the oversampling clock (37.5..=50 MHz).
    pub hans_sample_hz: u32,
    /// HANS-100 head STATUS input: its oversampling clock (the firmware's TIM3 makes
    /// 40 MHz).
    pub hans_status_sample_hz: u32,
    /// Free-running XY2-100 / XY3-100 output: slot periods between computing a slot
    /// and playing it (1 = the slot is written during the slot before it).
    pub lead_slots: u32,
    /// Slaved output: the earliest start of an output frame after its input event
    /// (decode + encode + DMA set-up time), ns.
    pub slaved_lead_ns: u64,
    /// XY2-100 head STATUS level: consecutive equal samples before a change counts.
    pub status_debounce: u16,
    /// XY3-100 input: run the firmware's out-of-step watch
    /// (`shared::xy3::step::StepWatch`) on the receiver's periods (default). Off,
    /// every period's events go to the bridge as the receiver decided them: for a
    /// test of the receiver alone at fault rates at which the watch would withhold
    /// nearly everything.
    pub xy3_step_watch: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            hans_sample_hz: 37_500_000,
            hans_status_sample_hz: 40_000_000,
            lead_slots: 1,
            slaved_lead_ns: 1_000,
            status_debounce: 3,
            xy3_step_watch: true,
        }
    }
}

/// Why the pipeline cannot be built or fed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PipelineError {
    /// The bridge configuration is invalid.
    Config(ConfigError),
    /// A receiver or transmitter refused its set-up (message from `shared`).
    Setup(String),
    /// Input of another protocol than the configured one.
    WrongInput {
        /// What the configuration expects.
        expected: &'static str,
        /// What was fed.
        got: &'static str,
    },
    /// Input buffers that break the receiver's contract (line count, lengths).
    BadInput(String),
}

impl fmt::Display for PipelineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Config(e) => write!(f, "configuration: {e}"),
            Self::Setup(m) => write!(f, "set-up: {m}"),
            Self::WrongInput { expected, got } => {
                write!(f, "input is {got}, the configuration expects {expected}")
            }
            Self::BadInput(m) => write!(f, "bad input buffers: {m}"),
        }
    }
}

impl std::error::Error for PipelineError {}

/// One chunk of controller-side DMA buffers (README "DMA buffer layouts").
#[derive(Debug, Clone, Copy)]
pub enum ControllerInput<'a> {
    /// XY2-100: port samples, one `u16` per CLK falling edge; pins as
    /// [`CONTROLLER_PINS_XY2`].
    Xy2(&'a [u16]),
    /// XY3-100: bytes per received line (X, Y, then Z when `z.source = "input"`), equal
    /// lengths, and the X ring's byte counts at SYNC rising edges (count from 0).
    Xy3 {
        /// One slice per line, axis order.
        lines: &'a [&'a [u8]],
        /// Frame end positions.
        ends: &'a [u32],
    },
    /// HANS-100: the `u16` ring words of channels 1..=5 (index 0 = CH1), MSB first =
    /// earliest sample; channels the decode mode does not use may be empty.
    Hans([&'a [u16]; 5]),
}

impl ControllerInput<'_> {
    fn name(&self) -> &'static str {
        match self {
            Self::Xy2(_) => "XY2-100",
            Self::Xy3 { .. } => "XY3-100",
            Self::Hans(_) => "HANS-100",
        }
    }
}

/// The controller-side XY2-100 port bits (the firmware's port G wiring).
pub const CONTROLLER_PINS_XY2: crate::line::sample::PinMap = crate::sim::capture::XY2_PINS;

/// One chunk of head-side status buffers.
#[derive(Debug, Clone, Copy)]
pub enum HeadStatusInput<'a> {
    /// XY2-100 STATUS level samples (`true` = line high), in time order, all taken
    /// at about `now_ns`; each counts as the head's status seen.
    Xy2Level(&'a [bool]),
    /// XY2-100 STATUS word samples: one `u16` per output bit from the first output
    /// tick on (bit 0 = STATUS), aligned with the free-running output frames
    /// (`shared::xy2::StatusWordReceiver`, offset 1).
    Xy2Word(&'a [u16]),
    /// XY3-100 backchannel bytes from the UART.
    Xy3Back(&'a [u8]),
    /// HANS-100 STATUS line: `u16` ring words of its oversampling SPI, one stream
    /// across calls, taken in [`HANS_STATUS_HALF`]-word halves as the firmware
    /// does (every half, or every second one beside a HANS-100 controller once
    /// the receiver's lock can coast: `shared::hans::follow::status_passes`).
    HansStatus(&'a [u16]),
}

/// A change of the bridge's link state or laser gate, with its time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Change<T> {
    /// When (ns).
    pub t_ns: u64,
    /// The new value.
    pub value: T,
}

/// Counts of what the pipeline itself saw (the bridge's own are in
/// [`Bridge::counters`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PipelineCounters {
    /// Controller-side receiver events handed to the bridge.
    pub line_events: u64,
    /// Of those, frames.
    pub line_frames: u64,
    /// Output slots computed.
    pub slots: u64,
    /// Output slots left idle (nothing to send, or the head could not take it).
    pub idle_slots: u64,
    /// Frames the head could not take (encode refused: a missing axis, ...).
    pub encode_refused: u64,
    /// Valid head status items (packets, frames, status words, level samples).
    pub status_items: u64,
    /// Head-side status faults (bad words, backchannel sync, bad STATUS frames).
    pub status_faults: u64,
}

/// The synchronous pipeline (see the module docs): the controller-side receiver,
/// the head-side status receiver and the [`Core`] (bridge, output, status out).
pub struct Pipeline {
    options: Options,
    input: input::Input,
    head_status: head_status::HeadStatusIn,
    core: Core,
}

impl Pipeline {
    /// A pipeline for `config` (validated) with the modelling `options`.
    pub fn new(config: &Config, options: Options) -> Result<Pipeline, PipelineError> {
        Ok(Pipeline {
            input: input::Input::new(config, &options)?,
            head_status: head_status::HeadStatusIn::new(config, &options)?,
            core: Core::new(config, &options)?,
            options,
        })
    }

    /// The modelling options.
    pub fn options(&self) -> &Options {
        &self.options
    }

    /// The bridge, its output clock and the status producers.
    pub fn core(&self) -> &Core {
        &self.core
    }

    /// The bridge engine (counters, state, head status, alarms).
    pub fn bridge(&self) -> &Bridge {
        self.core.bridge()
    }

    /// The bridge's counters.
    pub fn bridge_counters(&self) -> &Counters {
        self.core.bridge().counters()
    }

    /// The pipeline's own counters.
    pub fn counters(&self) -> &PipelineCounters {
        self.core.counters()
    }

    /// The halves of a HANS-100 head's STATUS input that were decoded, with the
    /// frames each published (none for other heads).
    pub fn hans_status_halves(&self) -> &[HansStatusHalf] {
        self.head_status.hans_halves()
    }

    /// The head-side output so far (a copy of the buffers).
    pub fn head_output(&self) -> HeadOutput {
        self.core.head_output()
    }

    /// Every frame written to the head so far, in order.
    pub fn sent(&self) -> &[SentFrame] {
        self.core.sent()
    }

    /// The controller-side status output so far (a copy).
    pub fn controller_status(&self) -> ControllerStatus {
        self.core.controller_status()
    }

    /// Link state changes (the first entry is the power-up `Safe` at 0).
    pub fn states(&self) -> &[Change<LinkState>] {
        self.core.states()
    }

    /// Laser gate changes (the first entry is "off" at 0).
    pub fn gate(&self) -> &[Change<bool>] {
        self.core.gate()
    }

    /// The laser gate now.
    pub fn gate_on(&self) -> bool {
        self.core.gate_on()
    }

    /// The rate the head's backchannel is expected at (XY3-100 heads; changes when a
    /// forwarded BACK_RATE command went out).
    pub fn head_back_rate(&self) -> shared::xy3::BackRate {
        self.core.head_back_rate()
    }

    /// Time of the last call, ns.
    pub fn now_ns(&self) -> u64 {
        self.core.now_ns()
    }

    /// The time of the next thing the pipeline's own clocks do (an output slot or a
    /// controller status step), ns.
    pub fn next_deadline_ns(&self) -> u64 {
        self.core.next_deadline_ns()
    }

    /// Runs the output and controller-status clocks for every step due before
    /// `now_ns`. Times earlier than a previous call are taken as that call's time.
    pub fn run_until(&mut self, now_ns: u64) {
        // An XY3-100 period the step watch holds for confirmation goes out when
        // due if no input came first (the firmware's bridge looks every batch).
        if let Some(due) = self.input.release_due().filter(|&d| d < now_ns) {
            let mut events = Vec::new();
            self.input.release(due, &mut events);
            self.core.line_events(due, &events);
        }
        self.core.run_until(now_ns);
    }

    /// Feeds one chunk of controller-side buffers at `now_ns` (see [`Pipeline`]).
    pub fn feed(&mut self, now_ns: u64, chunk: ControllerInput<'_>) -> Result<(), PipelineError> {
        let mut events: Vec<LineEvent> = Vec::new();
        self.input.feed(now_ns, chunk, &mut events)?;
        self.core.line_events(now_ns, &events);
        Ok(())
    }

    /// Like [`Pipeline::feed`] for a chunk holding many frames (a DMA half that
    /// arrived at `now_ns`): its receiver events are applied in order, spread over
    /// `[now_ns, now_ns + span_ns)` by where they lie in the chunk, as the firmware's
    /// bridge loop spreads a half's events over the output slots of its next batch
    /// (`shared::bridge::pacing`): an event decided after `p` of the chunk's `n`
    /// units (samples, X bytes, ring words) is applied at
    /// `now_ns + span_ns * (p - 1) / n`. A free-running output then carries
    /// consecutive frames in consecutive slots instead of only the newest of the
    /// chunk, and fault events take no time of their own: a frame goes where its
    /// bits were. Later calls must not start before the last event's time.
    pub fn feed_spread(
        &mut self,
        now_ns: u64,
        span_ns: u64,
        chunk: ControllerInput<'_>,
    ) -> Result<(), PipelineError> {
        let mut events = Vec::new();
        let units = self.input.feed_at(now_ns, chunk, &mut events)?;
        let n = u64::from(units.max(1));
        for (at, e) in &events {
            let unit = u64::from((*at).min(units).saturating_sub(1));
            let t = now_ns + span_ns * unit / n;
            self.core.line_events(t, std::slice::from_ref(e));
        }
        Ok(())
    }

    /// The times (ns) the XY3-100 input asked for its session to be restarted
    /// (`shared::xy3::step::StepWatch`, the firmware's `XY3_RESYNC`); empty for
    /// other inputs. The pipeline does not restart by itself: the SPI slaves are
    /// the caller's ([`stimulus::xy3_sessions`] closes the loop as the firmware's
    /// line task does).
    pub fn xy3_restart_requests(&self) -> &[u64] {
        self.input.xy3_restart_requests()
    }

    /// The caller restarted the XY3-100 input session (every SPI slave together):
    /// the next controller chunk is the first of the new session's byte stream,
    /// counted from 0. Returns `false` (and changes nothing) for other inputs.
    pub fn xy3_new_session(&mut self) -> bool {
        self.input.xy3_new_session()
    }

    /// The bridge never got the next `bytes` bytes of every XY3-100 line, nor the
    /// frame ends drained with them (the firmware's line task found the
    /// `XY3_INPUT` queue full and lost a half): the next controller chunk
    /// continues the byte stream that much later. Returns `false` (and changes
    /// nothing) for other inputs.
    pub fn xy3_lost(&mut self, bytes: u32) -> bool {
        self.input.xy3_lost(bytes)
    }

    /// Feeds one chunk of head-side status buffers at `now_ns`.
    pub fn feed_status(
        &mut self,
        now_ns: u64,
        chunk: HeadStatusInput<'_>,
    ) -> Result<(), PipelineError> {
        let mut faults = Vec::new();
        let seen = self.head_status.feed(now_ns, chunk, &mut faults)?;
        self.core
            .head_status(now_ns, seen, self.head_status.status(), &faults);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shared::bridge::{Protocol, Timing, ZSource};
    use shared::model::{Axis, Line};
    use shared::xy2;

    /// The 20 port samples of one XY2-100 frame period on the controller pins
    /// (sample k = word bit 19 - k, SYNC high for samples 0..=18), from the
    /// protocol, with `bad` flipping the parity bit of every channel.
    fn period(v: u16, bad: bool) -> Vec<u16> {
        let p = CONTROLLER_PINS_XY2;
        let link = xy2::LinkConfig::default();
        let word = |v: u16| {
            let w = xy2::encode(xy2::Frame::Position16(v), &link).unwrap();
            w ^ u32::from(bad)
        };
        let (x, y, z) = (word(v), word(v ^ 0x5555), word(0x8000));
        (0..20)
            .map(|k| {
                let bit = |w: u32| ((w >> (19 - k)) & 1) as u16;
                u16::from(k < 19) << p.sync | bit(x) << p.x | bit(y) << p.y | bit(z) << p.z.unwrap()
            })
            .collect()
    }

    /// A third of the periods with a check failure on all three channels (three
    /// fault events, no frame), in DMA halves of 25 periods spread over 250 us: at
    /// the input's own rate every valid frame gets an output slot of its own, so the
    /// free-running output neither skips nor loses one. Spreading by event count
    /// (the old rule) put five events on three slots and skipped frames here.
    #[test]
    fn spread_by_position_gives_faults_no_slot() {
        let mut c = Config::default();
        c.controller.protocol = Protocol::Xy2;
        c.head.protocol = Protocol::Xy3;
        c.z.source = ZSource::Input;
        c.output.timing = Timing::FreeRunning;
        c.failsafe.recovery_frames = 1;
        let mut samples = vec![0u16];
        let n = 2_000u16;
        for k in 0..n {
            samples.extend(period(k, k % 3 == 1));
        }
        let mut p = Pipeline::new(&c, Options::default()).unwrap();
        for (k, half) in samples[1..].chunks(500).enumerate() {
            let t_ns = 1_000 + (k as u64 + 1) * 250_000;
            let first = if k == 0 { &samples[..1] } else { &[][..] };
            p.feed(t_ns - 250_000, ControllerInput::Xy2(first)).unwrap();
            p.feed_spread(t_ns, 250_000, ControllerInput::Xy2(half))
                .unwrap();
        }
        p.run_until(u64::from(n) * 10_000 + 600_000);
        let k = p.bridge_counters();
        let faulted = (0..n).filter(|k| k % 3 == 1).count() as u64;
        let x = k.line(Line::Axis(Axis::X));
        assert_eq!(x.check_failed, faulted, "{k:?}");
        assert_eq!(k.frames_ok, u64::from(n) - faulted);
        assert_eq!(k.skipped, 0, "{k:?}");
        // Every valid frame reached the head, once each and in order
        // (`recovery_frames = 1`: the first one already runs the link).
        let sent: Vec<u32> = p
            .sent()
            .iter()
            .filter(|s| s.state == LinkState::Running)
            .map(|s| s.frame.axes[0].unwrap().aligned())
            .collect();
        let mut distinct = sent.clone();
        distinct.dedup();
        assert_eq!(distinct.len() as u64, k.frames_ok);
        assert!(distinct.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(k.line(Line::Framing).framing, 0);
    }
}
