//! The bridge loop for the GPIO waveform heads (XY2-100, XY3-100), run by the
//! high-priority executor: controller-side receiver -> `shared::bridge::Bridge` ->
//! head-side encoder -> TIM8 BSRR waveform ring, one batch of whole output frames per
//! iteration (README "Tasks and executors", "The bridge loop"). What it shares with
//! the HANS-100 loop is in [`super::bridge_core`]; this task owns the waveform output
//! and the XY2 STATUS word sampler.
//!
//! Hot state (receiver, `Bridge`, encoder, batch buffer) lives in the task's future,
//! i.e. in the executor's task pool, which `memory.x` puts into DTCM (`.dtcm_bss`,
//! zeroed by `xy_bridge::tcm` at reset; no buffer of the future is handed to a DMA).

use embassy_stm32::gpio::{Input, Level, Output, Speed};
use embassy_stm32::pac;
use embassy_time::Instant;
use shared::bridge::pacing::{batch_slot, Refused, SlotQueue};
use shared::bridge::{Config, StatusForm, Timing};
use shared::model::{FaultKind, Line, LineEvent};

use super::bridge_core::Core;
use super::encode::{idle_word, Encoder};
use super::head_word::{SentPeriods, StatusWordIn};
use super::Irqs;
use crate::board::WaveRes;
use crate::channels::{Stats, STATS};
use crate::config::{Controller, Head};
use crate::dma_ring;
use crate::drivers::wave_out::WaveOut;

/// Waveform words per batch at most (4..8 MHz ticks: 1000 words = 125..250 us).
const WAVE_BATCH: usize = 1000;

/// Input events waiting for their output slot: up to three XY2 halves of 25 frame
/// periods (or four XY3 halves of up to 21), each a frame or up to three line
/// faults; slaved, plus the frames carried over (at most [`SLAVED_BACKLOG`]
/// batches' worth).
const MAX_EVENTS: usize = 192;

/// Slaved timing: batches of frames that may wait for an output slot. Input faster
/// than the slots (the controller's clock above `output.frame_rate_hz`) fills this,
/// and each frame beyond it is dropped (a `Dropped` fault on `Line::Framing`,
/// counted by the bridge) rather than the latency growing without end.
const SLAVED_BACKLOG: usize = 2;

/// What a slaved frame that found the backlog full becomes for the bridge.
const BACKLOG_DROP: LineEvent = LineEvent::Fault {
    line: Line::Framing,
    kind: FaultKind::Dropped,
};

/// The bridge: controller-side receiver -> [`Bridge`] -> head-side transmitter, one
/// batch of whole output frames (about one DMA half) per iteration, on TIM8's BSRR
/// waveform ring (XY2-100 / XY3-100 heads). For an XY2 head with `status = "word"`
/// the STATUS word samples of TIM8 CC1 are decoded too ([`StatusWordIn`]).
///
/// Per batch: drain the input halves (XY2 port samples from `channels::RAW_INPUT`, or XY3
/// bytes + frame ends from `channels::XY3_INPUT`) into the receiver and feed its
/// [`LineEvent`]s to `Bridge::on_line_event` (time: `embassy_time::Instant` in ns);
/// take the head status the status tasks published; then `Bridge::tick` once per
/// output frame at its slot time, encode, and write the batch into the ring. The
/// laser gate follows `Output.laser.gate`, the XY2 STATUS level to the controller
/// the bridge's `xy2_status_line_high`; towards an XY3-100 controller the
/// backchannel bytes come from `Bridge::xy3_back_poll` (`channels::BACK_TX`) and rate
/// changes go to `channels::BACK_RATE`.
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
    let mut core = match Core::new(&config, head, controller) {
        Ok(c) => c,
        Err(e) => {
            defmt::error!("bridge: {}; output stays idle", e);
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
    // Each batch is exactly one half of the ring (the guard's unit: `wave_out`
    // "No stale words"), so the ring is two batches of whole frames.
    let batch_words = frames_per_batch * tpf;
    let ring = dma_ring!(".sram2", u32, 2 * WAVE_BATCH);
    let ring = &mut ring[..2 * batch_words];
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
                // A multiple of the output ring (realignment, `wave_out`).
                let status_ring = &mut status_ring[..4 * batch_words];
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
    let mut misses = out.guard_misses();
    // The DMA already plays the idle ring: the drivers may be switched on.
    head_enable.set_high();

    let period_ns = 1_000_000_000u64 / u64::from(rate.max(1));
    let mut batch = [idle; WAVE_BATCH];
    let mut status = [0u16; 2 * WAVE_BATCH];
    let mut sent = SentPeriods::default();
    // Output frame periods written so far (period 0 = the first slot written).
    let mut period = 0u64;
    let mut slot_ns = 0u64;
    // Slaved: one output frame per input frame (README "Slaved timing").
    let slaved = config.output.timing == Timing::Slaved;
    let max_frames = if slaved {
        SLAVED_BACKLOG * frames_per_batch
    } else {
        MAX_EVENTS
    };
    let mut queue: SlotQueue<MAX_EVENTS> = SlotQueue::new(max_frames);
    loop {
        let now_ns = Instant::now().as_micros().saturating_mul(1000);
        // Input: the halves that arrived since the last batch, decoded into neutral
        // events in time order, each queued for the slot of this batch where its
        // bits lie in the drained input (`pacing::batch_slot`: the input halves and
        // the output batch cover about the same time), so consecutive input frames
        // reach consecutive slots and faults take no slot of their own.
        let base = period;
        core.take_input(&mut |at, units, le| {
            let due = base + batch_slot(at, units, frames_per_batch) as u64;
            match queue.push(due, le) {
                Ok(()) => {}
                Err(Refused::Backlog(_)) => {
                    if queue.push(due, BACKLOG_DROP).is_err() {
                        Stats::bump(&STATS.input_overruns);
                    }
                }
                Err(Refused::Full(_)) => Stats::bump(&STATS.input_overruns),
            }
        });
        // Slot times continue from the last batch and never go back, so the bridge
        // sees one monotonic clock.
        slot_ns = slot_ns.max(now_ns);
        core.take_head_status(slot_ns);
        // Output: one tick per frame slot, with the events due by then. Free-running,
        // every event due (all of this batch's by its last slot); slaved, at most
        // one frame per slot, the rest carried to the next slots. A slot without a
        // frame is idle: no clock edges, XY3-100 SYNC high.
        let mut gate = true;
        for slot in batch.chunks_exact_mut(tpf).take(frames_per_batch) {
            let (frame, slot_gate) = core.slot(queue.take(period, slaved), slot_ns);
            slot_ns = slot_ns.saturating_add(period_ns);
            let encoded = encoder.encode(frame.as_ref(), slot);
            if encoded {
                Stats::bump(&STATS.output_frames);
            }
            sent.set(period, encoded);
            period += 1;
            gate &= slot_gate;
        }
        // The batch just computed plays two batches from now (the ring holds the
        // playing batch and the queued one): `end_batch` keeps the gate off until
        // the batch now playing was computed with it on.
        core.end_batch(gate, slot_ns);

        let words = batch.get(..batch_words).unwrap_or_default();
        match out.write_half(words).await {
            Ok(()) => Stats::bump(&STATS.output_halves),
            Err(_) => {
                // The batch is dropped and the head got (or gets) idle words with the
                // gate off: the gate opens again only by the three-batch rule.
                Stats::bump(&STATS.output_underruns);
                core.restart_gate();
            }
        }
        // The guard found the DMA in a half this loop had not refilled (it dropped
        // the gate): restart the gate rule, then lift the guard's refusal only if
        // it has not missed again since (`wave_out` "No stale words"). Looked at
        // after every batch, not only after an underrun: a late claim skips the
        // next half, whose miss comes after the underrun was seen.
        let now_misses = out.guard_misses();
        if now_misses != misses {
            misses = now_misses;
            core.restart_gate();
            out.clear_stale_if(misses);
        }
        if let Some(w) = word_in.as_mut() {
            // `period`: the first slot of the next batch, where samples realigned
            // after an underrun (or a status overrun) start again.
            let read = out.read_status(&mut status);
            w.apply(read, &mut status, period, &sent, &mut core.bridge, slot_ns);
        }
    }
}
