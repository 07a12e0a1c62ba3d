//! The bridge loop for a HANS-100 head, run by the high-priority executor:
//! controller-side receiver -> `shared::bridge::Bridge` -> `shared::hans::tx`
//! -> the SAI1 ring (8 frame slots of 125 bits replayed forever at 12.5 MHz, i.e.
//! exactly 100 kHz frames; `drivers::serial_tx`).
//!
//! Pacing: HANS-100 has no idle gap between frames, so the ring's DMA position is the
//! clock. The loop wakes once per slot period (10 us) and reads it; every slot that
//! started since the last wake is one `Bridge::tick`, at its own time (slot number
//! x 10 us: the bridge sees exactly 100 kHz whatever the wake-up jitter), and the
//! newest frame goes out through `Transmitter::update`, two slots ahead of the DMA
//! (slots skipped by a late wake get the same frame, so the line never replays an
//! older one). Input events wait in a queue and are handed to the bridge one frame
//! per slot, in order (an XY2-100 half brings 25 frames at once every 256 us).
//!
//! Safe start-up and "stop": until the bridge has been `Running` once, and whenever
//! it sends nothing, the ring holds zeros: no start marker, so the head sees no frame
//! at all (HANS-100 has no idle pattern of its own; repeating a frame would be a
//! command to hold a position).
//!
//! No stale frames: the ring runs under the slot ring guard (`drivers::serial_tx`,
//! "No stale frames"): a slot this loop did not write for the DMA's current lap is
//! zeros, never the last lap's frame; if the loop falls behind the DMA the guard
//! drops the laser gate and counts a miss; the loop, when the count moves,
//! restarts its gate rule and lifts the guard's refusal only if no miss came since
//! (the rule `bridge_wave_out` follows too: `channels::OUTPUT_STALE`).

use embassy_stm32::gpio::Output;
use embassy_time::{Duration, Instant, Ticker};
use heapless::Deque;
use shared::bridge::Config;
use shared::hans::frame::{FRAME_BITS, RING_BYTES, RING_SLOTS};
use shared::hans::tx::Transmitter;
use shared::hans::Frame;
use shared::model::LineEvent;

use super::bridge_core::Core;
use super::Irqs;
use crate::board::HansOutRes;
use crate::channels::{Stats, STATS};
use crate::config::{Controller, Head};
use crate::dma_ring;
use crate::drivers::serial_tx::SerialTx;

/// One HANS-100 frame slot: 125 bits at 12.5 MHz.
const SLOT_NS: u64 = FRAME_BITS as u64 * 80;
/// Input events waiting for their slot, at most (about seven XY2-100 halves).
const MAX_PENDING: usize = 192;
/// Queued events above which a slot takes more than one input frame: input faster
/// than 100 kHz, or a burst after a stall, must not grow the latency without end
/// (the bridge counts the frames it then skips).
const BACKLOG: usize = 64;

/// The events one slot hands to the bridge: every fault up to and including the next
/// frame, and more while the queue is above [`BACKLOG`].
struct SlotEvents<'a> {
    queue: &'a mut Deque<LineEvent, MAX_PENDING>,
    frame_taken: bool,
}

impl Iterator for SlotEvents<'_> {
    type Item = LineEvent;

    fn next(&mut self) -> Option<LineEvent> {
        if self.frame_taken && self.queue.len() <= BACKLOG {
            return None;
        }
        let e = self.queue.pop_front()?;
        self.frame_taken |= matches!(e, LineEvent::Frame(_));
        Some(e)
    }
}

/// The bridge for a HANS-100 head (see the module docs).
#[embassy_executor::task]
pub async fn bridge_hans_out(
    r: HansOutRes,
    config: Config,
    controller: Controller,
    head_enable: Output<'static>,
) {
    let mut head_enable = head_enable;
    let mut core = match Core::new(&config, Head::Hans, controller) {
        Ok(c) => c,
        Err(e) => {
            defmt::error!("bridge: {}; output stays idle", e);
            return;
        }
    };
    // Zeros: an idle line (see the module docs).
    let ring = dma_ring!(".sram2", u8, RING_BYTES);
    let mut channel = None;
    let mut out = SerialTx::new(r.sai, r.sd, r.dma, Irqs, &mut channel, ring);
    out.arm_head_guard(r.tick, Irqs);
    let mut misses = out.head_misses();
    head_enable.set_high();
    defmt::info!("bridge: {} -> HANS-100, 100000 Hz frames", controller);

    let mut tx = Transmitter::new();
    let mut hold = Frame::CENTRE;
    let mut line_idle = true;
    let mut pending: Deque<LineEvent, MAX_PENDING> = Deque::new();
    let origin = Instant::now();
    let mut slots = 0u64;
    let mut last_sending = out.sending_slot();
    let mut last_wake = origin;
    let mut ticker = Ticker::every(Duration::from_nanos(SLOT_NS));
    loop {
        ticker.next().await;
        let now = Instant::now();
        // Slots started since the last wake: exact modulo the ring from the DMA
        // position, the number of whole laps from the clock (a wake late by a lap
        // or more is an underrun of this loop).
        let sending = out.sending_slot();
        let turned = (sending + RING_SLOTS - last_sending) % RING_SLOTS;
        let waited = (now - last_wake).as_micros() * 1000 / SLOT_NS;
        let laps =
            (waited.saturating_sub(turned as u64) + RING_SLOTS as u64 / 2) / RING_SLOTS as u64;
        let started = turned as u64 + laps * RING_SLOTS as u64;
        if laps > 0 {
            Stats::bump(&STATS.output_underruns);
        }
        if sending < last_sending || laps > 0 {
            Stats::bump(&STATS.output_halves);
        }
        last_sending = sending;
        last_wake = now;
        if started == 0 {
            continue;
        }

        // Positions are not needed here: the queue hands each slot one frame (and
        // the faults before it), so faults take no slot anyway.
        core.take_input(&mut |_, _, le| {
            if pending.push_back(le).is_err() {
                Stats::bump(&STATS.input_overruns);
            }
        });
        let first_ns = slots * SLOT_NS;
        core.take_head_status(first_ns);
        let mut gate = true;
        let mut newest = None;
        for _ in 0..started {
            let events = SlotEvents {
                queue: &mut pending,
                frame_taken: false,
            };
            let (frame, slot_gate) = core.slot(events, slots * SLOT_NS);
            slots += 1;
            gate &= slot_gate;
            newest = Some(frame);
        }

        match newest.flatten() {
            Some(f) => match Frame::from_forward(&f, &hold) {
                Ok(frame) => {
                    if out
                        .update_guarded(|buf, remaining| tx.update(buf, remaining, &frame))
                        .is_ok()
                    {
                        Stats::bump(&STATS.output_frames);
                        hold = frame;
                        line_idle = false;
                    }
                }
                // Not reachable with the bridge's resized positions; never a guess.
                Err(_) => Stats::bump(&STATS.output_refused),
            },
            None if !line_idle => {
                // Stop: from now on the head sees no frame (a frame cut by this is
                // incomplete and fails the head's checks).
                out.stop_guarded();
                tx = Transmitter::new();
                line_idle = true;
            }
            None => {}
        }
        // The guard found the DMA on a slot this loop had not written (it dropped
        // the gate): the gate opens again only by the three-batch rule, restarted
        // before the guard's refusal is lifted.
        let now_misses = out.head_misses();
        if now_misses != misses {
            misses = now_misses;
            core.restart_gate();
            out.clear_stale_if(misses);
        }
        // The frame written now is sent two slots from now: `end_batch` keeps the
        // gate off until the slot being sent was computed with it on.
        core.end_batch(gate, slots * SLOT_NS);
        if out.take_underrun() {
            Stats::bump(&STATS.output_underruns);
        }
    }
}
