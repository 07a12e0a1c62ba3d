//! Inter-task communication: every `Channel` / `Signal` / `Watch` static and every
//! shared counter of the firmware lives here, so the data flow between tasks can be
//! read in one place.
//!
//! Conventions:
//! * `Watch` for state that has a current value many tasks may look at (health, head
//!   status); late readers get the latest value.
//! * `Signal` for "latest wins" commands to one task.
//! * `Channel` for queues where every item matters (raw input halves).
//! * Relaxed atomics for statistics counters (read once a second, no ordering needed).
//!
//! All use `CriticalSectionRawMutex`: senders include the high-priority
//! `InterruptExecutor` tasks (`tasks::line`).
//!
//! Flow (`[H]` = high-priority executor, others thread mode):
//! ```text
//! [H] xy2_in / xy3_in / hans_status_in --RAW_INPUT--> [H] bridge --(issue 4/5)-->
//! [H] wave_out, hans_out  <--HANS_FRAME-- (bridge, once decoders exist)
//! status_level_in / backchannel RX --HEAD_STATUS--> status_level_out, backchannel TX
//! (bridge, once decoders exist) --BACK_RATE--> backchannel
//! supervisor --HEALTH--> leds;  everyone --STATS--> stats
//! ```

use core::sync::atomic::{AtomicU32, Ordering};

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::signal::Signal;
use embassy_sync::watch::Watch;
use heapless::Vec;
use shared::hans::frame::Frame as HansFrame;
use shared::model::HeadStatus;
use shared::xy3::BackRate;

/// Overall state shown on the LEDs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub struct Health {
    /// Valid input frames are arriving (the laser gate may open). Stays false until
    /// the line-level decoders (issues 4/5) run in `tasks::line::bridge`.
    pub input_valid: bool,
    /// A fault is latched (watchdog reset at boot, link fault): red LED.
    pub fault: bool,
}

/// Subscribed receivers of [`HEALTH`]. The LED task polls through an anonymous
/// receiver, which needs no slot; one slot is left for a task that awaits changes.
const HEALTH_RECEIVERS: usize = 1;

/// Current [`Health`], published by the supervisor.
pub static HEALTH: Watch<CriticalSectionRawMutex, Health, HEALTH_RECEIVERS> = Watch::new();

/// Samples per XY2-100 input half-buffer (one per bit: 512 bits = 25 frames at
/// 2 MHz, a 256 us DMA half).
pub const XY2_HALF: usize = 512;
/// Bytes per XY3-100 input half-buffer (X line; 128 to 170 frames).
pub const XY3_HALF: usize = 512;
/// Frame-end marks carried with one XY3 half (a frame is at least 3 bytes).
pub const XY3_MARKS: usize = XY3_HALF / 3 + 1;
/// 16-bit words per HANS STATUS input half-buffer (8192 samples at 40 MHz = 205 us).
pub const HANS_HALF: usize = 512;

/// One DMA half-buffer of raw line data, in time order, exactly as `layouts.md`
/// defines it. TODO(issue 4 / issue 5): replace by decoded `LineEvent`s once the
/// line-level receivers (`shared/src/*/rx.rs`) are on main; the bridge task then
/// runs them in place instead of counting.
#[derive(Clone)]
pub enum RawInput {
    /// XY2-100 port samples (`layouts.md` §1).
    Xy2([u16; XY2_HALF]),
    /// XY3-100 X line bytes and frame-end positions (monotonic byte counts, §2).
    Xy3 {
        /// X ring bytes.
        bytes: [u8; XY3_HALF],
        /// SYNC rising edges in this half.
        marks: Vec<u32, XY3_MARKS>,
    },
    /// HANS-100 STATUS oversampled words (§3).
    HansStatus([u16; HANS_HALF]),
}

/// Raw input halves from the receivers to the bridge. Two slots: one being filled by
/// the DMA's next half, one being decoded; a third would only hide a slow bridge.
pub static RAW_INPUT: Channel<CriticalSectionRawMutex, RawInput, 2> = Channel::new();

/// The newest HANS-100 frame for the head (written two slots ahead by `hans_out`).
pub static HANS_FRAME: Signal<CriticalSectionRawMutex, HansFrame> = Signal::new();

/// Backchannel rate commanded by the controller (XY3-100 §6).
pub static BACK_RATE: Signal<CriticalSectionRawMutex, BackRate> = Signal::new();

/// What the head reports, in the neutral model.
pub static HEAD_STATUS: Watch<CriticalSectionRawMutex, HeadStatus, 2> = Watch::new();

/// Counters for the once-a-second summary.
pub struct Stats {
    /// Raw input halves handed to the bridge.
    pub input_halves: AtomicU32,
    /// Input halves lost (ring overrun, SPI overrun, bridge queue full).
    pub input_overruns: AtomicU32,
    /// XY3 frame-end marks seen.
    pub sync_marks: AtomicU32,
    /// Output halves written (waveform) / HANS ring laps.
    pub output_halves: AtomicU32,
    /// Output underruns (DMA replayed stale words).
    pub output_underruns: AtomicU32,
    /// Backchannel packets received.
    pub back_packets: AtomicU32,
    /// Backchannel resynchronisations.
    pub back_resyncs: AtomicU32,
    /// Backchannel errors (lost sync, UART errors).
    pub back_errors: AtomicU32,
    /// Head STATUS level changes.
    pub status_changes: AtomicU32,
}

impl Stats {
    /// Adds one to a counter.
    pub fn bump(counter: &AtomicU32) {
        counter.fetch_add(1, Ordering::Relaxed);
    }

    /// Reads and zeroes a counter.
    pub fn take(counter: &AtomicU32) -> u32 {
        counter.swap(0, Ordering::Relaxed)
    }
}

/// The firmware's counters.
pub static STATS: Stats = Stats {
    input_halves: AtomicU32::new(0),
    input_overruns: AtomicU32::new(0),
    sync_marks: AtomicU32::new(0),
    output_halves: AtomicU32::new(0),
    output_underruns: AtomicU32::new(0),
    back_packets: AtomicU32::new(0),
    back_resyncs: AtomicU32::new(0),
    back_errors: AtomicU32::new(0),
    status_changes: AtomicU32::new(0),
};
