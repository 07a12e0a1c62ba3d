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
//! All use `CriticalSectionRawMutex`: senders and receivers run in three priorities
//! (thread mode, the decode executor, the line executor; README "Tasks and
//! executors"), which preempt each other.
//!
//! Flow (`[H]` = line executor (UART8, P6), `[D]` = decode executor (UART5, P8),
//! others thread mode):
//! ```text
//! [H] xy2_in --RAW_INPUT--> [H] bridge_wave_out <--XY3_INPUT-- [H] xy3_in
//!     (receiver -> Bridge -> transmitter -> waveform ring; LASER_GATE, BRIDGE_BEAT,
//!      LINK_RUNNING, CTRL_STATUS_OK)
//! [H] xy2_in / xy3_in --> [H] bridge_hans_out (same inputs; HANS-100 head)
//! [H] bridge_* --XY3_RESYNC (session)--> [H] xy3_in (lines out of step: restart)
//! [H] hans_status_in --HANS_STATUS_RAW--> [D] hans_status --HEAD_STATUS--> bridge
//! [D] hans_status --HANS_STATUS_CONTIGUOUS--> [H] hans_status_in (every half, please)
//! [H] hans_in --HANS_INPUT--> [D] hans_decode --HANS_EVENTS--> [H] bridge loops
//! [D] hans_decode, hans_status <--> DECODE_GOVERNOR (decode / drop / pause)
//! [H] bridge loops --HANS_STATUS_OUT (frames)--> [H] hans_status_out (SAI2 B)
//! status_level_in / back_from_head --HEAD_STATUS--> bridge_wave_out, stats
//! bridge_wave_out --BACK_TX (bytes), BACK_RATE--> back_to_controller (UART7)
//! bridge_wave_out --HEAD_BACK_RATE--> back_from_head (USART2)
//! CTRL_STATUS_OK --> status_level_out;  CTRL_STATUS_WORD --> [H] xy2_in (word out)
//! bridge loops --LINK_RUNNING, HEAD_FAULT, BRIDGE_BEAT--> supervisor --HEALTH--> leds,
//!     status_level_out, [H] xy2_in (word out)
//! everyone --STATS--> stats;  STATS.output_frames --> leds (activity)
//! stats --SNAPSHOT_WANTED--> [H] bridge_wave_out --BRIDGE_SNAPSHOT--> stats
//! ```

use core::cell::RefCell;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use embassy_stm32::gpio::Output;
use embassy_sync::blocking_mutex::Mutex;

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::pipe::Pipe;
use embassy_sync::signal::Signal;
use embassy_sync::watch::Watch;
use shared::bridge::{Counters, LinkState};
use shared::governor::Governor;
use shared::model::{Alarms, HeadStatus, LineEvent};
use shared::xy3::BackRate;

/// Overall state, published by the supervisor: the LEDs show it, and the XY2-100
/// STATUS towards the controller says "fault" while `input_valid` is false.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub struct Health {
    /// Valid input frames are arriving (the bridge's link state is `Running`, and its
    /// loop completes batches): green LED on.
    pub input_valid: bool,
    /// The bridge reports a fault beyond missing input (a head alarm, the head's
    /// status lost: [`HEAD_FAULT`]), or its loop completes no batches (stalled, or
    /// never started): red LED while it lasts.
    pub fault: bool,
    /// The last reset was a watchdog reset (the firmware stalled): red LED, latched
    /// until the next reset. Nothing else changes: the bridge starts afresh, as
    /// after a power-on.
    pub watchdog_reset: bool,
}

/// Subscribed receivers of [`HEALTH`]. The LED task polls through an anonymous
/// receiver, which needs no slot; one slot is left for a task that awaits changes.
const HEALTH_RECEIVERS: usize = 1;

/// Current [`Health`], published by the supervisor.
pub static HEALTH: Watch<CriticalSectionRawMutex, Health, HEALTH_RECEIVERS> = Watch::new();

/// Samples per XY2-100 input half-buffer (one per bit: 500 bits = 25 frames at
/// 2 MHz, a 250 us DMA half). The ring (two halves) is a multiple of 20 bits, which
/// the STATUS word output's ring alignment needs (`drivers::status_word_out`).
pub const XY2_HALF: usize = 500;
/// Bytes per XY3-100 input half-buffer and line (16 to 21 frames, 160 to 213 us at
/// 100 kHz): half of `shared::xy3::rx::WINDOW`, the most the receiver may be fed
/// between two polls.
pub const XY3_HALF: usize = shared::xy3::rx::WINDOW / 2;
/// XY3-100 data lines this board can receive: X (SPI3), Y (SPI4), Z (SPI5), U (SPI1),
/// W (SPI2); which of them run: `Config::xy3_input_lines`.
pub const XY3_LINES: usize = 5;
/// Frame-end marks carried with one XY3 half: as many as the receiver lets wait
/// (a half holds at most 21 frame ends; later ones stay queued for the next half).
pub const XY3_MARKS: usize = shared::xy3::rx::MAX_PENDING_ENDS;
/// 16-bit words per HANS STATUS input half-buffer (8192 samples at 40 MHz = 205 us).
pub const HANS_HALF: usize = 512;

/// One DMA half-buffer of XY2-100 port samples (`layouts.md` §1), in time order.
/// The bridge (`tasks::line::bridge_wave_out`) runs the XY2 receiver on it.
pub type RawInput = [u16; XY2_HALF];

/// One DMA half of each received XY3-100 data line (`layouts.md` §2) and the
/// frame-end marks drained with it.
#[derive(Clone)]
pub struct Xy3Raw {
    /// Reception session: the input restarts every line together (clock gated) after
    /// an overrun, and byte counts start again at 0.
    pub session: u32,
    /// X ring byte count of `bytes[..][0]` within the session.
    pub first_byte: u32,
    /// `XY3_HALF` bytes per line, indexed by `Axis::index` (X..W); lines not
    /// received stay zero and are not read.
    pub bytes: [[u8; XY3_HALF]; XY3_LINES],
    /// Frame-end positions (X byte counts within the session) drained with this half.
    pub ends: heapless::Vec<u32, XY3_MARKS>,
}

/// XY3-100 halves to the bridge, drained once per output batch (up to two halves
/// arrive per batch; four slots leave room for one late batch).
pub static XY3_INPUT: Channel<CriticalSectionRawMutex, Xy3Raw, 4> = Channel::new();

/// The bridge's `shared::xy3::step::StepWatch` found the lines of this XY3-100 input
/// session out of step: the input task restarts every line together (a request for
/// an older session is ignored, that one has already ended).
pub static XY3_RESYNC: Signal<CriticalSectionRawMutex, u32> = Signal::new();

/// Raw input halves from the receivers to the bridge. The bridge drains it once per
/// output batch (about one DMA half), so three slots cover a half arriving while the
/// bridge waits for output space; a fourth would only hide a slow bridge.
pub static RAW_INPUT: Channel<CriticalSectionRawMutex, RawInput, 3> = Channel::new();

/// One half of the HANS-100 STATUS input (head side, SPI6 at `fs`), for the decoder
/// in the decode executor.
#[derive(Clone)]
pub struct HansStatusRaw {
    /// Reception session: it changes when words were lost at the SPI or in the
    /// ring (an overrun), so that how many is not known.
    pub session: u32,
    /// Number of this half in the SPI6 stream. Within a session, half numbers
    /// times [`HANS_HALF`] are word counts of one continuous signal: the decoder
    /// knows how many words lie between two halves it decodes (the halves not
    /// passed on, or dropped), and its receiver coasts across them
    /// (`shared::hans::follow`).
    pub half: u32,
    /// When the half was complete (`embassy_time::Instant` ticks): its age is the
    /// decode governor's backlog.
    pub ready: u64,
    /// The words, in time order.
    pub words: [u16; HANS_HALF],
}

/// HANS STATUS halves to `status::hans_status` (decode executor, under the
/// [`DECODE_GOVERNOR`] as optional work). Only every
/// `shared::hans::follow::status_every`-th half is sent (every half while
/// [`HANS_STATUS_CONTIGUOUS`] asks for it); a full queue drops the half (counted
/// in `input_overruns`).
pub static HANS_STATUS_RAW: Channel<CriticalSectionRawMutex, HansStatusRaw, 1> = Channel::new();

/// Set by `status::hans_status` while its receiver's lock cannot coast across a
/// skipped half yet (`HansRx::coasts`: from a new receiver until its lock's
/// young fit is in its last frames): `line::hans_status_in` then
/// passes on every half, not only every `follow::status_every`-th
/// (`shared::hans::follow::status_passes`), so that an acquisition is not cut
/// short by the halves in between. Set from reset on.
pub static HANS_STATUS_CONTIGUOUS: AtomicBool = AtomicBool::new(true);

/// Backchannel rate to switch the controller side (UART7 TX) to (XY3-100 §6):
/// raised by the bridge from `Output.controller_back_rate` once the bytes made for
/// the old rate have left [`BACK_TX`].
pub static BACK_RATE: Signal<CriticalSectionRawMutex, BackRate> = Signal::new();

/// Backchannel rate to switch the head side (USART2 RX) to: raised by the bridge
/// from `Output.head_back_rate`, in the batch that forwards the BACK_RATE command to
/// the head (the head answers at the new rate once it has the command).
pub static HEAD_BACK_RATE: Signal<CriticalSectionRawMutex, BackRate> = Signal::new();

/// Capacity of [`BACK_TX`]: a few packets (a text packet is up to ~210 bytes).
pub const BACK_TX_LEN: usize = 1024;

/// Backchannel bytes towards an XY3-100 controller, written by the bridge
/// (`Bridge::xy3_back_poll`, only when a whole packet fits: never a partial packet),
/// sent by the backchannel task.
pub static BACK_TX: Pipe<CriticalSectionRawMutex, BACK_TX_LEN> = Pipe::new();

/// What the head reports, in the neutral model.
pub static HEAD_STATUS: Watch<CriticalSectionRawMutex, HeadStatus, 2> = Watch::new();

/// The laser gate pin (PF13, high = laser may fire), shared by the bridge (which
/// follows `Output.laser.gate` every output batch) and the supervisor (which forces it
/// off when the bridge stops making progress). `None` until the supervisor, which
/// `app::spawn_supervision` hands the pin, puts it here.
pub static LASER_GATE: Mutex<CriticalSectionRawMutex, RefCell<Option<Output<'static>>>> =
    Mutex::new(RefCell::new(None));

/// Set by an output ring guard (the waveform heads' `drivers::wave_out`, the
/// HANS-100 head's `drivers::serial_tx`) when its DMA reached output the bridge had
/// not refreshed in time (the guard turned the gate off; the head gets idle words or
/// no frames); [`laser_gate_allowed`] refuses the gate until the bridge has
/// restarted its gate rule and cleared it ([`clear_output_stale`]). One flag for both
/// guards: an image drives one head.
///
/// One discipline for clearing it, in both bridge loops: the guard counts every
/// miss (every time it sets this flag, under its lock); the loop, after every
/// batch, compares the count with the one it last acted on, and when it moved
/// restarts its gate rule and then clears the flag only if the count is still
/// the one it read (`WaveOut::clear_stale_if`, `SerialTx::clear_stale_if`, under
/// the guard's lock). A miss between the loop's read and its clear thus keeps the
/// flag for the loop's next look, and the flag is never cleared unless the gate
/// rule restarted after the last miss. A clear without the count (at the waveform
/// loop's underrun) loses the miss that a late claim's skipped half brings after
/// the underrun: the flag would stay set for good.
static OUTPUT_STALE: AtomicBool = AtomicBool::new(false);

/// False while an output ring guard reports a missed refresh and the bridge has not
/// yet restarted its gate rule: the laser gate must stay off. Read under the laser
/// gate's lock, so a guard (which runs above it) cannot turn the gate off between
/// this check and a gate-on write.
pub fn laser_gate_allowed() -> bool {
    !OUTPUT_STALE.load(Ordering::Acquire)
}

/// An output ring guard's miss, from its P0 interrupt: the gate pin straight low
/// (BSRR: atomic, no lock, RM0433 §11.4.7), then the flag the gate-on path checks.
pub fn output_stale_gate_off() {
    embassy_stm32::pac::GPIOF
        .bsrr()
        .write(|w| w.set_br(crate::board::LASER_GATE_PIN, true));
    OUTPUT_STALE.store(true, Ordering::Release);
}

/// The bridge restarted its gate rule after a guard's miss and the guard has not
/// missed since (or a new output starts): the gate may open again by that rule.
/// Only under the guard's lock, after its count said so ([`OUTPUT_STALE`]).
pub fn clear_output_stale() {
    OUTPUT_STALE.store(false, Ordering::Release);
}

/// Drives the laser gate, if it has been handed over. On is refused while an
/// output ring guard reports a missed refresh ([`laser_gate_allowed`]: the head gets
/// idle words or no frames, the guard turned the gate off, and only the bridge's
/// gate rule restarted after the underrun may open it again). The check is under
/// the gate's lock, so the guard cannot close the gate between it and the write.
pub fn set_laser_gate(on: bool) {
    LASER_GATE.lock(|g| {
        if let Some(pin) = g.borrow_mut().as_mut() {
            let on = on && laser_gate_allowed();
            pin.set_level(on.into());
        }
    });
}

/// Output batches the bridge has completed (wrapping); the supervisor drops the gate
/// when this stops moving.
pub static BRIDGE_BEAT: AtomicU32 = AtomicU32::new(0);

/// The bridge's link state is `Running` (valid input frames arrive).
pub static LINK_RUNNING: AtomicBool = AtomicBool::new(false);

/// The bridge reports an alarm other than `INPUT_LOST` (the head's alarms,
/// `STATUS_LOST`) after its last batch: the red LED (a missing input shows as the
/// green LED off instead).
pub static HEAD_FAULT: AtomicBool = AtomicBool::new(false);

/// XY2-100 STATUS towards the controller means "OK" (from the bridge's
/// `xy2_status_line_high`, i.e. head alarms merged with the bridge's own).
pub static CTRL_STATUS_OK: AtomicBool = AtomicBool::new(false);

/// The XY2-100 status word towards the controller (`Bridge::xy2_status_word`, the
/// 16-bit word in the low bits), from the bridge's last batch; [`NO_STATUS_WORD`]
/// until the first one.
pub static CTRL_STATUS_WORD: AtomicU32 = AtomicU32::new(NO_STATUS_WORD);

/// [`CTRL_STATUS_WORD`] before the bridge published a word (not a 16-bit value).
pub const NO_STATUS_WORD: u32 = u32::MAX;

/// The bridge engine's own view for the statistics line: its counters (cumulative,
/// saturating) and its link state and alarms, copied by the bridge task.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BridgeSnapshot {
    /// `Bridge::counters` (frames, faults per line, repeats, commands not carried).
    pub counters: Counters,
    /// The link state after the last output slot.
    pub state: LinkState,
    /// The bridge's own alarms (`INPUT_LOST`, `STATUS_LOST`).
    pub alarms: Alarms,
    /// What the controller is told: the head's alarms merged with the bridge's own.
    pub reported: Alarms,
    /// The laser gate as the bridge drove it after this batch.
    pub gate: bool,
}

/// Set by the statistics task to ask for a [`BridgeSnapshot`]. The bridge task looks
/// at it once per output batch and copies its state only when asked, so the
/// high-priority loop pays the copy (a few hundred bytes inside a critical section)
/// once a second, not every batch, and never waits for the reader.
pub static SNAPSHOT_WANTED: AtomicBool = AtomicBool::new(false);

/// The bridge's answer to [`SNAPSHOT_WANTED`] ("latest wins"; `signal` only takes
/// the critical section for the copy, so the bridge task never blocks on it).
pub static BRIDGE_SNAPSHOT: Signal<CriticalSectionRawMutex, BridgeSnapshot> = Signal::new();

/// Counters for the once-a-second summary.
pub struct Stats {
    /// Raw input halves handed to the bridge.
    pub input_halves: AtomicU32,
    /// Input halves lost (ring overrun, SPI overrun, bridge queue full). Not
    /// zeroed by the statistics task: it counts on (wrapping) since boot, so the
    /// hardware-in-the-loop tests can compare it across a run of any length.
    pub input_overruns: AtomicU32,
    /// XY3 frame-end marks seen.
    pub sync_marks: AtomicU32,
    /// Frames the bridge sent to the head (idle slots not counted). Not zeroed by
    /// the statistics task: it counts on (wrapping), and the activity LED watches it
    /// move.
    pub output_frames: AtomicU32,
    /// Output halves written (waveform) / HANS ring laps.
    pub output_halves: AtomicU32,
    /// Output underruns: a waveform batch dropped as too late for its half (the ring
    /// guard plays idle words instead), a HANS-100 loop wake a lap or more late,
    /// an SAI FIFO underrun.
    pub output_underruns: AtomicU32,
    /// Backchannel packets received.
    pub back_packets: AtomicU32,
    /// Backchannel resynchronisations.
    pub back_resyncs: AtomicU32,
    /// Backchannel errors (lost sync, UART errors).
    pub back_errors: AtomicU32,
    /// Head STATUS level changes.
    pub status_changes: AtomicU32,
    /// Head STATUS frames that failed their check (HANS-100 STATUS).
    pub status_faults: AtomicU32,
    /// Frames the bridge gave that the head-side encoder refused (not sent).
    pub output_refused: AtomicU32,
    /// XY2 STATUS word input realigned to the output after an output underrun or a
    /// status ring overrun.
    pub status_realigns: AtomicU32,
    /// HANS-100 controller input halves decoded (decode executor).
    pub decoded_halves: AtomicU32,
    /// HANS-100 controller input halves the decode governor dropped as stale.
    pub decode_drops: AtomicU32,
    /// HANS STATUS halves decoded (decode executor).
    pub status_decoded: AtomicU32,
    /// HANS STATUS halves the decode governor dropped (no spare credit, or stale).
    pub status_drops: AtomicU32,
    /// Pauses the decode governor imposed on the decoders.
    pub decode_pauses: AtomicU32,
    /// Time spent in those pauses, microseconds.
    pub decode_paused_us: AtomicU32,
    /// Time the decoders were busy (their work and what preempted it), microseconds.
    pub decode_busy_us: AtomicU32,
    /// Longest busy time of one half, microseconds (maximum since the last summary).
    pub decode_busy_max_us: AtomicU32,
}

impl Stats {
    /// Adds one to a counter.
    pub fn bump(counter: &AtomicU32) {
        counter.fetch_add(1, Ordering::Relaxed);
    }

    /// Adds `n` to a counter.
    pub fn add(counter: &AtomicU32, n: u32) {
        counter.fetch_add(n, Ordering::Relaxed);
    }

    /// Raises a maximum to `n`.
    pub fn raise(counter: &AtomicU32, n: u32) {
        counter.fetch_max(n, Ordering::Relaxed);
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
    output_frames: AtomicU32::new(0),
    output_halves: AtomicU32::new(0),
    output_underruns: AtomicU32::new(0),
    back_packets: AtomicU32::new(0),
    back_resyncs: AtomicU32::new(0),
    back_errors: AtomicU32::new(0),
    status_changes: AtomicU32::new(0),
    status_faults: AtomicU32::new(0),
    output_refused: AtomicU32::new(0),
    status_realigns: AtomicU32::new(0),
    decoded_halves: AtomicU32::new(0),
    decode_drops: AtomicU32::new(0),
    status_decoded: AtomicU32::new(0),
    status_drops: AtomicU32::new(0),
    decode_pauses: AtomicU32::new(0),
    decode_paused_us: AtomicU32::new(0),
    decode_busy_us: AtomicU32::new(0),
    decode_busy_max_us: AtomicU32::new(0),
};

// HANS-100 controller side (`tasks/hans_in.rs`, `tasks/hans_status_out.rs`).

/// 16-bit words per HANS-100 controller input half and channel: 8192 samples at
/// 40 MHz = 205 us, about 20 frames.
pub const HANS_IN_HALF: usize = 512;

/// One DMA half of every HANS-100 controller channel (`layouts.md` §3).
#[derive(Clone)]
pub struct HansRaw {
    /// Reception session: the input restarts every channel together (fs held low)
    /// after an overrun, and word counts start again at 0.
    pub session: u32,
    /// Ring word count of `words[..][0]` within the session.
    pub first_word: u32,
    /// When the half was complete (`embassy_time::Instant` ticks): its age is the
    /// decode governor's backlog (it also covers halves lost on a full queue).
    pub ready: u64,
    /// `HANS_IN_HALF` words per channel, indexed by channel number - 1; channels the
    /// decode mode does not use stay zero and are not read.
    pub words: [[u16; HANS_IN_HALF]; 5],
}

/// HANS-100 controller halves from `hans_in` to the decoder in the decode executor
/// (`hans_decode`). A full queue drops the newest half (the decoder sees the gap in
/// `first_word`), so a decoder that cannot keep up loses input, counted, instead of
/// delaying the line tasks; the [`DECODE_GOVERNOR`] drops the oldest ones before
/// that happens (halves older than its age limit).
pub static HANS_INPUT: Channel<CriticalSectionRawMutex, HansRaw, 2> = Channel::new();

/// Decoded HANS-100 controller events to the bridge loop, which drains them every
/// output batch (or slot), each with its word position in the input stream (for
/// spreading over the output slots; `hans_in::take_events`). The decoder waits
/// while it is full: the bridge paces it (that wait is not busy time for the
/// governor: the decode executor idles meanwhile).
pub static HANS_EVENTS: Channel<CriticalSectionRawMutex, (u32, LineEvent), HANS_EVENTS_DEPTH> =
    Channel::new();

/// Depth of [`HANS_EVENTS`].
pub const HANS_EVENTS_DEPTH: usize = 64;

/// HANS STATUS frames towards a HANS-100 controller (`Bridge::hans_status_frame`),
/// kept full by the bridge loop, written into the SAI2 ring by `hans_status_out`.
pub static HANS_STATUS_OUT: Channel<CriticalSectionRawMutex, shared::hans::Frame, 8> =
    Channel::new();

/// The load governor both HANS-100 decoders in the decode executor answer to
/// (`tasks::governor`: controller input as essential work, head STATUS as optional
/// work), so together they never take more than its share of the core and thread
/// mode (the supervisor feeding the watchdog) always runs. Only the decode executor
/// touches it; the mutex makes the static shareable, its critical section is a few
/// instructions.
pub static DECODE_GOVERNOR: Mutex<CriticalSectionRawMutex, RefCell<Governor>> =
    Mutex::new(RefCell::new(crate::tasks::governor::GOVERNOR));
