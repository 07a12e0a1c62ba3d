//! HANS STATUS towards a HANS-100 controller: SAI2 block B sends a ring of 8 STATUS
//! frames forever at 12.5 MHz (`drivers::serial_tx`, the same driver and layout as
//! the HANS-100 head output), on the controller-side pair-6 driver (PA0).
//!
//! The frames are the bridge's own (`Bridge::hans_status_frame`: the head's status
//! merged with the bridge's alarms, codes 64 / 65 and the device codes in turn, as
//! the host pipeline sends them). The bridge loop keeps [`HANS_STATUS_OUT`] full
//! ([`feed`], once per batch or slot); [`hans_status_out`] wakes every
//! [`REFRESH`] and writes the frames it finds into the six slots that are at least
//! two slots ahead of the DMA (`shared::hans::tx::LEAD_SLOTS`), so the STATUS line
//! is never more than about 280 us behind the bridge. A slot not refreshed is sent
//! again as it was: an older, complete and valid STATUS frame.
//!
//! Fail-safe: until the bridge has made its first frame the ring is zeros (no start
//! marker: the controller sees no STATUS at all), and when no frame has come for
//! [`STALE_AFTER`] wake-ups (the bridge loop stopped) the ring is zeroed again, so a
//! stalled bridge never keeps reporting its last "healthy" status.
//!
//! Runs in the high-priority executor: writing a slot two ahead of the DMA is only
//! safe if nothing but the DMA interrupts can delay the write by a slot period
//! (10 us); the HANS-100 decoders (decode executor, below it) could.

use embassy_stm32::peripherals::PA0;
use embassy_stm32::Peri;
use embassy_time::{Duration, Ticker};
use heapless::Vec;
use shared::bridge::Bridge;
use shared::hans::frame::{Frame, RING_BYTES, RING_SLOTS};
use shared::hans::tx::LEAD_SLOTS;

use super::Irqs;
use crate::board::HansStatusOutRes;
use crate::channels::{Stats, HANS_STATUS_OUT, STATS};
use crate::dma_ring;
use crate::drivers::serial_tx::SerialTx;

/// How often the ring is refreshed: 20 slot periods, so each slot is sent about
/// 2.5 times between refreshes and the task costs about six slot writes per 200 us.
const REFRESH: Duration = Duration::from_micros(200);

/// Slots written per refresh: every slot at least [`LEAD_SLOTS`] ahead of the one
/// the DMA is fetching.
const WRITE_AHEAD: usize = RING_SLOTS - LEAD_SLOTS;

/// Refreshes without a single new frame after which the line is silenced: 1 ms, four
/// times the longest bridge batch (250 us).
const STALE_AFTER: u32 = 5;

/// Called by the bridge loop (HANS-100 controller only): tops [`HANS_STATUS_OUT`] up
/// with the bridge's next STATUS frames.
pub(super) fn feed(bridge: &mut Bridge) {
    while !HANS_STATUS_OUT.is_full() {
        // Fits: the bridge loop is the only sender and checked for room.
        let _ = HANS_STATUS_OUT.try_send(bridge.hans_status_frame());
    }
}

/// HANS STATUS out (see the module docs). `pin` is PA0 (SAI2_SD_B).
#[embassy_executor::task]
pub async fn hans_status_out(r: HansStatusOutRes, pin: Peri<'static, PA0>) {
    // Zeros: no STATUS frame until the bridge has made one.
    let ring = dma_ring!(".sram2", u8, RING_BYTES);
    let mut channel = None;
    let mut out = SerialTx::new(r.sai, pin, r.dma, Irqs, &mut channel, ring);
    let mut ticker = Ticker::every(REFRESH);
    let mut stale = 0u32;
    let mut silent = true;
    loop {
        ticker.next().await;
        let mut frames: Vec<Frame, WRITE_AHEAD> = Vec::new();
        while let Ok(f) = HANS_STATUS_OUT.try_receive() {
            // Room: at most WRITE_AHEAD are taken.
            let _ = frames.push(f);
            if frames.is_full() {
                break;
            }
        }
        if frames.is_empty() {
            stale = stale.saturating_add(1);
            if stale >= STALE_AFTER && !silent {
                // A frame cut by this fails the controller's checks.
                defmt::warn!("hans status out: no frames from the bridge; line silenced");
                out.update(|buf| buf.fill(0));
                silent = true;
            }
            continue;
        }
        stale = 0;
        silent = false;
        if out.write_ahead(&frames).is_err() {
            // Not reachable (every `Frame` encodes), but never silent.
            Stats::bump(&STATS.output_refused);
        }
        if out.take_underrun() {
            Stats::bump(&STATS.output_underruns);
        }
    }
}
