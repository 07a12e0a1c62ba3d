//! High-priority line tasks, run by the `InterruptExecutor` (`main.rs`): one task per
//! receiver moves each DMA half-buffer to the bridge, the bridge turns input into
//! output, one task per transmitter keeps its DMA ring fed. Each loop iteration is one
//! DMA half, so these tasks preempt everything in thread mode but never block each
//! other for longer than one half's work.
//!
//! Wired end to end: XY2-100 controller -> [`bridge_wave_out`] -> XY2-100 or XY3-100
//! head. Other inputs are received but not bridged (README.md (section "Firmware"), "What is
//! left"): the output then stays idle and the laser gate off.
//!
//! Hot state (receiver, `Bridge`, encoder) lives in the task's future, i.e. in the
//! executor's task pool in AXI SRAM (`.bss`, zeroed by the runtime), not in `.dtcm`:
//! `.dtcm` is NOLOAD, so it would need a `MaybeUninit` static written before use, and
//! with the D-cache off the bridge's cost per batch has not been measured to need it.

use core::sync::atomic::Ordering;

use embassy_stm32::gpio::{Level, Output, OutputType, Speed};
use embassy_stm32::peripherals::PG8;
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm};
use embassy_stm32::{pac, Peri};
use shared::hans::frame::{write_slot, RING_BYTES};

use super::Irqs;
use crate::board::{HansOutRes, HansStatusInRes, WaveRes, Xy2InRes, Xy3InRes};
use embassy_time::Instant;
use shared::bridge::{Bridge, Config, LinkState, Protocol, StatusForm, Timing, ZSource};
use shared::model::{Axis, ForwardFrame, LineEvent};
use shared::xy3::neutral::{command_frame, position_frame};
use shared::xy3::FrameSize;
use shared::{xy2, xy3};

use crate::channels::{
    set_laser_gate, BridgeSnapshot, RawInput, Stats, BRIDGE_BEAT, BRIDGE_SNAPSHOT, CTRL_STATUS_OK,
    HANS_FRAME, HANS_HALF, HEAD_STATUS, LINK_RUNNING, RAW_INPUT, SNAPSHOT_WANTED, STATS, XY2_HALF,
    XY3_HALF, XY3_MARKS,
};
use crate::config::{Controller, Head};
use crate::drivers::serial_tx::SerialTx;
use crate::drivers::spi_slave_rx::SpiSlaveRx;
use crate::drivers::sync_marks::SyncMarks;
use crate::drivers::wave_out::WaveOut;
use crate::drivers::xy2_sampler::Xy2Sampler;
use xy_bridge::dma_ring;

/// Hands an XY2 half to the bridge without waiting: a full queue means the bridge is
/// late, and waiting would only turn that into a DMA overrun one half later.
fn forward(raw: RawInput) {
    if RAW_INPUT.try_send(raw).is_ok() {
        Stats::bump(&STATS.input_halves);
    } else {
        Stats::bump(&STATS.input_overruns);
    }
}

/// XY2-100 input (controller side): TIM1 samples port G on every CLK falling edge.
#[embassy_executor::task]
pub async fn xy2_in(r: Xy2InRes) {
    let ring = dma_ring!(".sram2", u16, 2 * XY2_HALF);
    let mut sampler = Xy2Sampler::new(r.tim, r.clk, r.dma, Irqs, pac::GPIOG, ring);
    let mut half = [0u16; XY2_HALF];
    loop {
        match sampler.read_exact(&mut half).await {
            Ok(()) => forward(half),
            Err(e) => {
                defmt::warn!("xy2 in: {} (at edge {})", e, sampler.edges());
                Stats::bump(&STATS.input_overruns);
            }
        }
    }
}

/// XY3-100 input (controller side): SPI3 receives X; EXTI4 marks every SYNC rising
/// edge. Only counted, not bridged: a frame period with X alone would make the bridge
/// hold Y at its last value, so the XY3 receiver (`shared::xy3::rx`) is fed once Y
/// (SPI4) and Z (SPI5) run too (README "What is left").
#[embassy_executor::task]
pub async fn xy3_in(r: Xy3InRes) {
    // OE# low: the pair-2 receiver (XY3 CLK) drives the shared SCK bus.
    let _sck_bus = Output::new(r.sck_buffer_oe, Level::Low, Speed::Low);
    const LEN: usize = 2 * XY3_HALF;
    let ring = dma_ring!(".sram1", u8, LEN);
    let mut marks = SyncMarks::new(r.sync, r.exti, Irqs, LEN as u16);
    let mut rx = match SpiSlaveRx::new(r.spi, r.sck, r.mosi, Some(r.nss), r.dma, Irqs, ring) {
        Ok(rx) => rx,
        Err(e) => {
            defmt::error!("xy3 in: {}", e);
            return;
        }
    };
    let mut bytes = [0u8; XY3_HALF];
    let mut ends = [0u32; XY3_MARKS];
    loop {
        let result = rx.read_exact(&mut bytes).await;
        let n = marks.drain(&mut ends);
        match result {
            Ok(()) => {
                Stats::bump(&STATS.input_halves);
                STATS.sync_marks.fetch_add(n as u32, Ordering::Relaxed);
            }
            Err(e) => {
                defmt::warn!("xy3 in: {} ({} marks dropped)", e, marks.dropped());
                Stats::bump(&STATS.input_overruns);
            }
        }
    }
}

/// HANS-100 STATUS input (head side): TIM3 CH2 makes the 40 MHz oversampling clock
/// (240 MHz / 6; README.md (section "Firmware") clock tree) that clocks SPI6 through a wire from
/// PC7 to PB3; SPI6 receives 16-bit words into a BDMA ring in SRAM4.
#[embassy_executor::task]
pub async fn hans_status_in(r: HansStatusInRes) {
    let fs_pin = PwmPin::new(r.fs_pin, OutputType::PushPull);
    let mut pwm = SimplePwm::new(
        r.fs_tim,
        None,
        Some(fs_pin),
        None,
        None,
        Hertz(40_000_000),
        CountingMode::EdgeAlignedUp,
    );
    let mut fs = pwm.ch2();
    fs.set_duty_cycle_fraction(1, 2);
    fs.enable();
    let ring = dma_ring!(".sram4", u16, 2 * HANS_HALF);
    // Free-running stream: no NSS pin (the type only names SPI6's NSS pin PG8).
    let no_nss: Option<Peri<'static, PG8>> = None;
    let mut rx = match SpiSlaveRx::new(r.spi, r.sck, r.mosi, no_nss, r.dma, Irqs, ring) {
        Ok(rx) => rx,
        Err(e) => {
            defmt::error!("hans status in: {}", e);
            return;
        }
    };
    let mut half = [0u16; HANS_HALF];
    loop {
        match rx.read_exact(&mut half).await {
            // Counted only: the HANS-100 STATUS receiver joins with the HANS head path
            // (README "What is left").
            Ok(()) => Stats::bump(&STATS.input_halves),
            Err(e) => {
                defmt::warn!("hans status in: {}", e);
                Stats::bump(&STATS.input_overruns);
            }
        }
    }
}

/// Port-D bit of each head-side pair (board wiring).
const PAIR_BITS: [u32; 7] = [0, 1, 2, 3, 10, 14, 15];
/// Pair index (0-based) carrying XY3's SYNC (pair 1; XY2's SYNC on pair 2 idles low
/// like every other line).
const XY3_SYNC_PAIR: usize = 0;

/// Idle BSRR word: every output low (reset half), except XY3's SYNC, which idles high
/// (`layouts.md` §4). It pre-fills the ring before the first batch.
fn idle_word(head: Head) -> u32 {
    let resets = PAIR_BITS.iter().fold(0u32, |w, b| w | 1 << (b + 16));
    match head {
        Head::Xy3 => {
            let sync = PAIR_BITS[XY3_SYNC_PAIR];
            (resets & !(1 << (sync + 16))) | 1 << sync
        }
        Head::Xy2 | Head::Hans => resets,
    }
}

/// Waveform words per batch at most (4..8 MHz ticks: 1000 words = 125..250 us).
const WAVE_BATCH: usize = 1000;
/// Ticks per XY2-100 bit: two (layouts.md §4).
const XY2_TICKS_PER_BIT: u32 = 2;
/// XY2-100 bit clock.
const XY2_BIT_HZ: u32 = 2_000_000;
/// Idle ticks after a 32-bit XY3-100 frame: 64 + 16 = 80 ticks make 8 MHz at 100 kHz,
/// an exact division of the 240 MHz timer clock (24-bit frames: the minimum, 50 ticks
/// = 5 MHz, already exact).
const XY3_IDLE_32: u8 = 16;

/// Gate-on history mask: the batch computed now and the two ahead of the one playing
/// must all have the gate on (see the gate in [`bridge_wave_out`]).
const GATE_ON_BATCHES: u8 = 0b111;

/// Input events buffered per batch: up to three XY2 halves of 25 frame periods, each
/// a frame or up to three channel faults, plus framing events.
const MAX_EVENTS: usize = 128;

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

/// The head-side encoder: neutral frames -> BSRR words of one frame slot.
enum Encoder {
    /// XY2-100 with the head's position mode; `z` = the Z line is driven.
    Xy2(xy2::tx::Transmitter, xy2::Mode, bool),
    /// XY3-100 with the head's frame size; `z` = the Z line is driven.
    Xy3(xy3::tx::Transmitter, FrameSize, bool),
}

impl Encoder {
    /// The encoder for the configured head, or why there is none.
    fn new(config: &Config) -> Result<Encoder, &'static str> {
        let rate = config.output.frame_rate_hz;
        let z = config.z.source != ZSource::None;
        match config.head.protocol {
            Protocol::Xy2 => {
                let h = config.head.xy2;
                let tick_hz = XY2_BIT_HZ * XY2_TICKS_PER_BIT;
                let ticks = (tick_hz / rate.max(1)) as usize;
                let pins = xy2::tx::OutPinMap {
                    clk: 0,
                    sync: 1,
                    x: 2,
                    y: 3,
                    z: z.then_some(10),
                };
                let link = xy2::LinkConfig {
                    mode: h.mode,
                    parity: h.parity,
                };
                xy2::tx::Transmitter::new(pins, ticks, link)
                    .map(|t| Encoder::Xy2(t, h.mode, z))
                    .map_err(|_| "XY2-100 transmitter refused the frame rate")
            }
            Protocol::Xy3 => {
                let size = config.head.xy3.frame_size;
                let idle_ticks = match size {
                    FrameSize::Bits24 => xy3::tx::MIN_IDLE_TICKS,
                    FrameSize::Bits32 => XY3_IDLE_32,
                };
                let pins = xy3::tx::OutPinMap {
                    clk: 1,
                    sync: 0,
                    data: [Some(2), Some(3), z.then_some(10), None, None],
                };
                let tx = xy3::tx::TxConfig {
                    pins,
                    size,
                    idle_ticks,
                };
                xy3::tx::Transmitter::new(&tx)
                    .map(|t| Encoder::Xy3(t, size, z))
                    .map_err(|_| "XY3-100 transmitter configuration refused")
            }
            Protocol::Hans => Err("HANS-100 head is not a waveform output"),
        }
    }

    fn ticks_per_frame(&self) -> usize {
        match self {
            Encoder::Xy2(t, ..) => t.ticks_per_frame(),
            Encoder::Xy3(t, ..) => t.ticks_per_frame(),
        }
    }

    /// The timer tick rate for `rate` frames per second.
    fn tick_hz(&self, rate: u32) -> u32 {
        let ticks = self.ticks_per_frame() as u64;
        u32::try_from(ticks.saturating_mul(u64::from(rate))).unwrap_or(u32::MAX)
    }

    /// Encodes `frame` into `slot`, or idles the slot for `None` and for a frame the
    /// head cannot take (an axis without a position): the head then sees no frame in
    /// this slot rather than a guessed one. Returns whether a frame was written.
    fn encode(&self, frame: Option<&ForwardFrame>, slot: &mut [u32]) -> bool {
        match self {
            Encoder::Xy2(t, mode, z) => {
                let f = frame.and_then(|f| {
                    let pos = |a: Axis| f.axis(a).map(|p| xy2::Frame::from_position(p, *mode));
                    // A command rides on X in place of the position (XY2-100 enhanced).
                    let x = f
                        .command
                        .and_then(xy2::Frame::from_command)
                        .or(pos(Axis::X))?;
                    // A driven Z line needs a Z frame: all-zero bits would be an
                    // invalid frame on the head's Z channel.
                    let z = if *z { Some(pos(Axis::Z)?) } else { None };
                    Some(xy2::tx::TxFrame {
                        x,
                        y: pos(Axis::Y)?,
                        z,
                    })
                });
                match f {
                    Some(f) => t.write_frame(slot, &f).is_ok(),
                    None => {
                        slot.fill(t.idle_word());
                        false
                    }
                }
            }
            Encoder::Xy3(t, size, z) => {
                let frames = frame.and_then(|f| {
                    let pos = |a: Axis| f.axis(a).map(|p| position_frame(p, *size));
                    let x = match f.command {
                        Some(c) => command_frame(&c, *size).ok(),
                        None => pos(Axis::X),
                    }?;
                    let zf = if *z { Some(pos(Axis::Z)?) } else { None };
                    Some([Some(x), Some(pos(Axis::Y)?), zf, None, None])
                });
                if let Some(fr) = frames {
                    if t.encode(&fr, slot).is_ok() {
                        return true;
                    }
                }
                // `slot` is exactly one frame period long, which is all `idle` checks.
                let _ = t.idle(slot);
                false
            }
        }
    }
}

/// The controller-side receiver the bridge runs on [`RawInput`] halves.
enum Decoder {
    /// XY2-100 port samples.
    Xy2(xy2::rx::Receiver),
    /// No receiver this board can run for the configured input (see `main`): halves
    /// are counted, the bridge never sees a frame, so the output stays idle and the
    /// laser gate off.
    None,
}

/// The bridge: controller-side receiver -> [`Bridge`] -> head-side transmitter, one
/// batch of whole output frames (about one DMA half) per iteration, on TIM8's BSRR
/// waveform ring (XY2-100 / XY3-100 heads). For an XY2 head the STATUS word samples of
/// TIM8 CC1 are taken too.
///
/// Per batch: drain the raw input halves into the receiver and feed its
/// [`LineEvent`]s to `Bridge::on_line_event` (time: `embassy_time::Instant` in ns);
/// take the head status the status tasks published; then `Bridge::tick` once per
/// output frame at its slot time, encode, and write the batch into the ring. The
/// laser gate follows `Output.laser.gate`, the XY2 STATUS level to the controller
/// the bridge's `xy2_status_line_high`.
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
) {
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
        Controller::Xy3 => Decoder::None,
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
    if head == Head::Xy2 {
        let status_ring = dma_ring!(".sram2", u16, 2 * WAVE_BATCH);
        out.start_status_sampler(r.status_dma, Irqs, pac::GPIOG, status_ring);
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
    let mut status = [0u16; WAVE_BATCH];
    let mut started = false;
    let mut slot_ns = 0u64;
    let mut gate_history = 0u8;
    let mut events: heapless::Vec<LineEvent, MAX_EVENTS> = heapless::Vec::new();
    loop {
        let now_ns = Instant::now().as_micros().saturating_mul(1000);
        // Input: every raw half that arrived since the last batch, decoded into
        // neutral events (in time order).
        events.clear();
        while let Ok(raw) = RAW_INPUT.try_receive() {
            if let Decoder::Xy2(rx) = &mut decoder {
                rx.feed(&raw, &mut |ev| {
                    ev.line_events(&mut |le| {
                        if events.push(le).is_err() {
                            Stats::bump(&STATS.input_overruns);
                        }
                    })
                });
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
            if encoder.encode(frame, slot) {
                Stats::bump(&STATS.output_frames);
            }
            gate &= o.laser.gate;
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
        let ok = ctrl_level.health(bridge.xy2_status_line_high()) == xy2::Health::Ok;
        CTRL_STATUS_OK.store(ok, Ordering::Relaxed);
        BRIDGE_BEAT.fetch_add(1, Ordering::Relaxed);

        let words = batch.get(..frames_per_batch * tpf).unwrap_or_default();
        match out.write_half(words).await {
            Ok(()) => Stats::bump(&STATS.output_halves),
            Err(_) => Stats::bump(&STATS.output_underruns),
        }
        // Keeps the status ring drained (no overrun); the STATUS word form of an XY2
        // head is not decoded yet (README "What is left").
        if head == Head::Xy2 && out.read_status(&mut status).is_err() {
            Stats::bump(&STATS.input_overruns);
        }
    }
}

/// HANS-100 output (head side): SAI1 block A replays the 125-byte ring; the newest
/// frame from the bridge goes two slots ahead of the DMA.
#[embassy_executor::task]
pub async fn hans_out(r: HansOutRes, head_enable: Output<'static>) {
    let mut head_enable = head_enable;
    let ring = dma_ring!(".sram2", u8, RING_BYTES);
    let mut slot = None;
    // The ring is all zeros: an idle line until the bridge has a frame.
    let mut tx = SerialTx::new(r.sai, r.sd, r.dma, Irqs, &mut slot, ring);
    head_enable.set_high();
    let mut last = tx.sending_slot();
    loop {
        let frame = HANS_FRAME.wait().await;
        let next = tx.next_free_slot();
        if tx.update(|buf| write_slot(buf, next, &frame)).is_err() {
            defmt::error!("hans out: slot {} out of range", next);
        }
        let now = tx.sending_slot();
        if now < last {
            Stats::bump(&STATS.output_halves);
        }
        last = now;
        if tx.take_underrun() {
            Stats::bump(&STATS.output_underruns);
        }
    }
}
