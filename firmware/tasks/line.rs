//! High-priority line tasks, run by the `InterruptExecutor` (`main.rs`): one task per
//! receiver moves each DMA half-buffer towards the bridge loop ([`super::bridge`]),
//! one task per transmitter keeps its DMA ring fed. Each loop iteration is one DMA
//! half, so these tasks preempt everything in thread mode but never block each other
//! for longer than one half's work.

use core::sync::atomic::Ordering;

use embassy_stm32::gpio::{Level, Output, OutputType, Speed};
use embassy_stm32::peripherals::PG8;
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm};
use embassy_stm32::{pac, Peri};
use shared::hans::frame::{write_slot, RING_BYTES};

use super::Irqs;
use crate::board::{HansOutRes, HansStatusInRes, Xy2InRes, Xy3InRes};
use crate::channels::{
    RawInput, Stats, HANS_FRAME, HANS_HALF, RAW_INPUT, STATS, XY2_HALF, XY3_HALF, XY3_MARKS,
};
use crate::drivers::serial_tx::SerialTx;
use crate::drivers::spi_slave_rx::SpiSlaveRx;
use crate::drivers::sync_marks::SyncMarks;
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
