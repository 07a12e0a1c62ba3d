//! The bridge loop, run by the high-priority executor: controller-side receiver ->
//! `shared::bridge::Bridge` -> head-side encoder -> TIM8 BSRR waveform ring, one batch
//! of whole output frames per iteration (README "Tasks and executors", "The bridge
//! loop"). The receivers' DMA halves arrive through `channels`; this task owns the
//! head-side output, the XY2 STATUS word sampler and the laser gate.
//!
//! Hot state (receiver, `Bridge`, encoder) lives in the task's future, i.e. in the
//! executor's task pool in AXI SRAM (`.bss`, zeroed by the runtime), not in `.dtcm`:
//! `.dtcm` is NOLOAD, so it would need a `MaybeUninit` static written before use, and
//! with the D-cache off the bridge's cost per batch has not been measured to need it.

use core::sync::atomic::Ordering;

use embassy_stm32::gpio::{Input, Level, Output, Speed};
use embassy_stm32::pac;
use embassy_time::Instant;
use shared::bridge::{Bridge, Config, LinkState, StatusForm, Timing, ZSource};
use shared::model::{FaultKind, Line, LineEvent};
use shared::xy3::back::SEND_BUF_LEN;
use shared::xy3::BackRate;
use shared::{xy2, xy3};

use super::encode::{idle_word, Encoder};
use super::head_word::{SentPeriods, StatusWordIn};
use super::Irqs;
use crate::board::WaveRes;
use crate::channels::{
    set_laser_gate, BridgeSnapshot, Stats, Xy3Raw, BACK_RATE, BACK_TX, BRIDGE_BEAT,
    BRIDGE_SNAPSHOT, CTRL_STATUS_OK, HEAD_STATUS, LINK_RUNNING, RAW_INPUT, SNAPSHOT_WANTED, STATS,
    XY3_HALF, XY3_INPUT, XY3_LINES,
};
use crate::config::{Controller, Head};
use crate::drivers::wave_out::WaveOut;
use xy_bridge::dma_ring;

/// Waveform words per batch at most (4..8 MHz ticks: 1000 words = 125..250 us).
const WAVE_BATCH: usize = 1000;
/// Gate-on history mask: the batch computed now and the two ahead of the one playing
/// must all have the gate on (see the gate in [`bridge_wave_out`]).
const GATE_ON_BATCHES: u8 = 0b111;

/// Input events buffered per batch: up to three XY2 halves of 25 frame periods (or
/// four XY3 halves of up to 21), each a frame or up to three line faults.
const MAX_EVENTS: usize = 192;

/// XY2-100 input pins on port G (board wiring: PG0 SYNC, PG1 X, PG2 Y, PG3 Z). Z is
/// received only with `z.source = "input"`: a frame period counts only if every
/// received channel decodes, so an unconnected Z input (reading the RS-422 fail-safe
/// level) would otherwise reject every frame.
fn xy2_in_pins(config: &Config) -> xy2::rx::PinMap {
    xy2::rx::PinMap {
        sync: 0,
        x: 1,
        y: 2,
        z: (config.z.source == ZSource::Input).then_some(3),
    }
}

/// The controller-side receiver the bridge runs on the input halves.
#[expect(
    clippy::large_enum_variant,
    reason = "one instance, inside the task's future; no heap to box into"
)]
enum Decoder {
    /// XY2-100 port samples ([`RAW_INPUT`]).
    Xy2(xy2::rx::Receiver),
    /// XY3-100 SPI bytes and frame-end marks ([`XY3_INPUT`]).
    Xy3(Xy3Decoder),
}

/// The XY3-100 receiver and where its byte count stands against the input task's.
struct Xy3Decoder {
    rx: xy3::rx::Receiver,
    lines: xy3::rx::Lines,
    /// The input session the receiver follows (`None` before the first half).
    session: Option<u32>,
    /// `first_byte` the next half must have to continue the byte stream.
    next_byte: u32,
}

impl Xy3Decoder {
    fn new(config: &Config) -> Self {
        // X and Y always; Z only when the bridge takes Z from the input (an
        // unconnected Z line would read dead and fail every period).
        let lines = if config.z.source == ZSource::Input {
            xy3::rx::Lines::XYZ
        } else {
            xy3::rx::Lines::XY
        };
        Xy3Decoder {
            rx: xy3::rx::Receiver::new(lines),
            lines,
            session: None,
            next_byte: 0,
        }
    }

    /// Feeds one half and hands the events of every completed period to `emit`.
    fn feed(&mut self, raw: &Xy3Raw, emit: &mut impl FnMut(LineEvent)) {
        if self.session != Some(raw.session) || raw.first_byte != self.next_byte {
            // A new input session (all lines restarted) or a lost half: the byte
            // stream is not continuous, so start a receiver at this half's count
            // (pending frame ends of the old stream are meaningless now).
            if self.session.is_some() {
                emit(LineEvent::Fault {
                    line: Line::Framing,
                    kind: FaultKind::Dropped,
                });
            }
            self.rx = xy3::rx::Receiver::with_origin(self.lines, raw.first_byte);
            self.session = Some(raw.session);
        }
        self.next_byte = raw.first_byte.wrapping_add(XY3_HALF as u32);
        let [x, y, z] = &raw.bytes;
        let all: [&[u8]; XY3_LINES] = [x, y, z];
        let lines = all.get(..self.lines.count()).unwrap_or_default();
        if let Err(e) = self.rx.push_bytes(lines) {
            // Not reachable (one equal-length slice per configured line), but never
            // silent: the bytes are not taken.
            defmt::error!("xy3 receiver refused a half: {}", e);
            return;
        }
        self.rx.push_ends(&raw.ends);
        while let Some(period) = self.rx.poll() {
            period.for_each_event(&mut *emit);
        }
    }
}

/// The bridge: controller-side receiver -> [`Bridge`] -> head-side transmitter, one
/// batch of whole output frames (about one DMA half) per iteration, on TIM8's BSRR
/// waveform ring (XY2-100 / XY3-100 heads). For an XY2 head with `status = "word"`
/// the STATUS word samples of TIM8 CC1 are decoded too ([`StatusWordIn`]).
///
/// Per batch: drain the input halves (XY2 port samples from [`RAW_INPUT`], or XY3
/// bytes + frame ends from [`XY3_INPUT`]) into the receiver and feed its
/// [`LineEvent`]s to `Bridge::on_line_event` (time: `embassy_time::Instant` in ns);
/// take the head status the status tasks published; then `Bridge::tick` once per
/// output frame at its slot time, encode, and write the batch into the ring. The
/// laser gate follows `Output.laser.gate`, the XY2 STATUS level to the controller
/// the bridge's `xy2_status_line_high`; towards an XY3-100 controller the
/// backchannel bytes come from `Bridge::xy3_back_poll` ([`BACK_TX`]) and rate
/// changes go to [`BACK_RATE`].
///
/// Safe start-up: until the bridge has been `Running` once (its first valid input
/// frames), every slot is idle -- not the configured park position -- so the head sees
/// no frame before the controller has sent one; afterwards the bridge's fail-safe
/// frames (hold, park, stop) are sent as configured.
#[embassy_executor::task]
pub async fn bridge_wave_out(
    r: WaveRes,
    config: Config,
    head: Head,
    controller: Controller,
    head_enable: Output<'static>,
    status_pin: Option<Input<'static>>,
) {
    // Keeps PG9 an input (out of its analog reset state) for the STATUS word sampler.
    let _status_pin = status_pin;
    let mut head_enable = head_enable;
    let mut bridge = match Bridge::new(&config) {
        Ok(b) => b,
        Err(e) => {
            defmt::error!("bridge: configuration refused: {}", e);
            return;
        }
    };
    let encoder = match Encoder::new(&config) {
        Ok(e) => e,
        Err(e) => {
            defmt::error!("bridge: {}", e);
            return;
        }
    };
    if config.output.timing == Timing::Slaved {
        // Slaved output sends each frame from `on_line_event`, which needs the ring
        // write position per input frame; this loop writes whole batches.
        defmt::error!("bridge: output.timing = \"slaved\" is not supported by this firmware yet; output stays idle");
        return;
    }
    let mut decoder = match controller {
        Controller::Xy2 => {
            let link = xy2::LinkConfig {
                mode: config.controller.xy2.mode,
                parity: config.controller.xy2.parity,
            };
            match xy2::rx::Receiver::new(xy2_in_pins(&config), link) {
                Ok(rx) => Decoder::Xy2(rx),
                Err(e) => {
                    defmt::error!("bridge: xy2 receiver: {}", e);
                    return;
                }
            }
        }
        Controller::Xy3 => Decoder::Xy3(Xy3Decoder::new(&config)),
    };
    let speed = Speed::VeryHigh;
    let _pins = [
        Output::new(r.pins.p1, Level::Low, speed),
        Output::new(r.pins.p2, Level::Low, speed),
        Output::new(r.pins.p3, Level::Low, speed),
        Output::new(r.pins.p4, Level::Low, speed),
        Output::new(r.pins.p5, Level::Low, speed),
        Output::new(r.pins.p7, Level::Low, speed),
        Output::new(r.pins.p8, Level::Low, speed),
    ];
    let idle = idle_word(head);
    let rate = config.output.frame_rate_hz;
    let tpf = encoder.ticks_per_frame();
    if tpf == 0 || tpf > WAVE_BATCH {
        // XY2-100 below 4 kHz: one frame period is longer than a batch.
        defmt::error!(
            "bridge: {} ticks per frame do not fit a {}-word batch; output stays idle",
            tpf,
            WAVE_BATCH
        );
        return;
    }
    let frames_per_batch = WAVE_BATCH / tpf;
    let ring = dma_ring!(".sram2", u32, 2 * WAVE_BATCH);
    let tick_hz = encoder.tick_hz(rate);
    let mut out = match WaveOut::new(r.tim, r.dma, Irqs, pac::GPIOD, ring, idle, tick_hz) {
        Ok(out) => out,
        Err(e) => {
            defmt::error!("wave out: {}", e);
            return;
        }
    };
    // XY2 STATUS word: sampled from the first tick on (before `start`), so the
    // samples stay aligned with the output frames (`wave_out` module docs).
    let mut word_in = None;
    if head == Head::Xy2 && config.head.xy2.status == StatusForm::Word {
        match StatusWordIn::new(&config, tpf) {
            Ok(w) => {
                let status_ring = dma_ring!(".sram2", u16, 4 * WAVE_BATCH);
                match out.start_status_sampler(r.status_dma, Irqs, pac::GPIOG, status_ring) {
                    Ok(()) => word_in = Some(w),
                    Err(e) => defmt::error!("head status word: {}", e),
                }
            }
            // The bridge then never sees the head's status: STATUS_LOST after
            // `failsafe.status_timeout_us`.
            Err(e) => defmt::error!("head status word: {}", e),
        }
    }
    defmt::info!(
        "bridge: {} -> {}, {} Hz frames, {} ticks/frame at {} ticks/s (asked {}), {} frames/batch",
        controller,
        head,
        rate,
        tpf,
        out.tick_hz(),
        tick_hz,
        frames_per_batch
    );
    out.start();
    // The DMA already plays the idle ring: the drivers may be switched on.
    head_enable.set_high();

    let ctrl_level = xy2::StatusLevel {
        polarity: config.controller.xy2.polarity,
    };
    // An XY2 head with a STATUS level reports only changes; the line itself is always
    // there (an open RS-485 receiver reads its fail-safe level, which the debouncer
    // reports as a level), so the status counts as seen every batch.
    let level_status = head == Head::Xy2 && config.head.xy2.status == StatusForm::Level;
    let period_ns = 1_000_000_000u64 / u64::from(rate.max(1));
    let mut head_status = HEAD_STATUS.anon_receiver();
    let mut batch = [idle; WAVE_BATCH];
    let mut status = [0u16; 2 * WAVE_BATCH];
    let mut sent = SentPeriods::default();
    // Output frame periods written so far (period 0 = the first slot written).
    let mut period = 0u64;
    let mut started = false;
    // XY3-100 controller: the bridge's backchannel packets go out through BACK_TX.
    let back_ctrl = controller == Controller::Xy3;
    let mut back_buf = [0u8; SEND_BUF_LEN];
    let mut rate_due: Option<BackRate> = None;
    let mut slot_ns = 0u64;
    let mut gate_history = 0u8;
    let mut events: heapless::Vec<LineEvent, MAX_EVENTS> = heapless::Vec::new();
    loop {
        let now_ns = Instant::now().as_micros().saturating_mul(1000);
        // Input: every raw half that arrived since the last batch, decoded into
        // neutral events (in time order).
        events.clear();
        let mut push = |le| {
            if events.push(le).is_err() {
                Stats::bump(&STATS.input_overruns);
            }
        };
        match &mut decoder {
            Decoder::Xy2(rx) => {
                while let Ok(raw) = RAW_INPUT.try_receive() {
                    rx.feed(&raw, &mut |ev| ev.line_events(&mut push));
                }
            }
            Decoder::Xy3(rx) => {
                while let Ok(raw) = XY3_INPUT.try_receive() {
                    rx.feed(&raw, &mut push);
                }
            }
        }
        // Head status from the status tasks (XY2 level, XY3 backchannel).
        if let Some(s) = head_status.try_changed() {
            *bridge.head_status_mut() = s;
            bridge.status_seen(slot_ns.max(now_ns));
        } else if level_status {
            bridge.status_seen(slot_ns.max(now_ns));
        }
        // Output: one tick per frame slot. The input events are spread over the
        // batch's slots in order (the input half and the output batch cover about the
        // same time), so consecutive input frames reach consecutive slots instead of
        // all but the newest being skipped. Slot times continue from the last batch
        // and never go back, so the bridge sees one monotonic clock.
        slot_ns = slot_ns.max(now_ns);
        let n_events = events.len();
        let mut next_event = 0;
        let mut gate = true;
        for (i, slot) in batch
            .chunks_exact_mut(tpf)
            .take(frames_per_batch)
            .enumerate()
        {
            let due = (i + 1) * n_events / frames_per_batch;
            for le in events.get(next_event..due).unwrap_or_default() {
                // Free-running only (checked above): the engine keeps the newest
                // frame for the next `tick`; the immediate output is always `None`.
                let _ = bridge.on_line_event(slot_ns, *le);
            }
            next_event = due.max(next_event);
            let o = bridge.tick(slot_ns);
            slot_ns = slot_ns.saturating_add(period_ns);
            started |= o.state == LinkState::Running;
            let frame = if started { o.frame.as_ref() } else { None };
            let encoded = encoder.encode(frame, slot);
            if encoded {
                Stats::bump(&STATS.output_frames);
            }
            sent.set(period, encoded);
            period += 1;
            gate &= o.laser.gate;
            // One UART serves both sides (channels::BACK_RATE); the controller's
            // command and the head's (the same command, forwarded) agree.
            if let Some(rate) = o.controller_back_rate.or(o.head_back_rate) {
                rate_due = Some(rate);
            }
            LINK_RUNNING.store(o.state == LinkState::Running, Ordering::Relaxed);
        }
        // The batch just computed plays two batches from now (the ring holds the
        // playing batch and the queued one). Gate off at once, as soon as any slot
        // ahead says so; gate on only once the batch now playing was computed with
        // the gate on, so the laser never fires before the head has the first
        // forwarded position.
        gate_history = (gate_history << 1 | u8::from(gate)) & GATE_ON_BATCHES;
        set_laser_gate(gate_history == GATE_ON_BATCHES);
        if SNAPSHOT_WANTED.swap(false, Ordering::Relaxed) {
            BRIDGE_SNAPSHOT.signal(BridgeSnapshot {
                counters: *bridge.counters(),
                state: bridge.state(),
                alarms: bridge.alarms(),
                reported: bridge.reported_alarms(),
                gate: gate_history == GATE_ON_BATCHES,
            });
        }
        if let Some(rate) = rate_due {
            // Bytes already queued were made for the old rate: switch once they are
            // out (the backchannel task finishes the write it has taken first).
            if !back_ctrl || BACK_TX.is_empty() {
                BACK_RATE.signal(rate);
                rate_due = None;
            }
        }
        if back_ctrl && rate_due.is_none() && BACK_TX.free_capacity() >= SEND_BUF_LEN {
            match bridge.xy3_back_poll(slot_ns, &mut back_buf) {
                // Fits: the bridge is the only writer and checked the space.
                Ok(n) => {
                    let _ = BACK_TX.try_write(back_buf.get(..n).unwrap_or_default());
                }
                Err(_) => Stats::bump(&STATS.back_errors),
            }
        }
        let ok = ctrl_level.health(bridge.xy2_status_line_high()) == xy2::Health::Ok;
        CTRL_STATUS_OK.store(ok, Ordering::Relaxed);
        BRIDGE_BEAT.fetch_add(1, Ordering::Relaxed);

        let words = batch.get(..frames_per_batch * tpf).unwrap_or_default();
        match out.write_half(words).await {
            Ok(()) => Stats::bump(&STATS.output_halves),
            Err(_) => Stats::bump(&STATS.output_underruns),
        }
        if let Some(w) = word_in.as_mut() {
            let samples = out
                .read_status(&mut status)
                .map(|n| status.get(..n).unwrap_or_default());
            w.apply(samples, &sent, &mut bridge, slot_ns);
        }
    }
}
