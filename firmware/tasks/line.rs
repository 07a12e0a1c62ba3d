//! High-priority line tasks, run by the `InterruptExecutor` (`main.rs`): one task per
//! receiver moves each DMA half-buffer to the bridge, the bridge turns input into
//! output, one task per transmitter keeps its DMA ring fed. Each loop iteration is one
//! DMA half, so these tasks preempt everything in thread mode but never block each
//! other for longer than one half's work.
//!
//! TODO(issue 4 / issue 5): the line-level receivers and transmit encoders are not on
//! main yet (`shared/src/*/rx.rs` absent). Until then the bridge only counts the raw
//! halves, the laser gate stays off and every output plays its idle pattern, which is
//! exactly the safe start-up state.

use core::sync::atomic::Ordering;

use embassy_stm32::gpio::{Level, Output, OutputType, Speed};
use embassy_stm32::peripherals::PG8;
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm};
use embassy_stm32::{pac, Peri};
use heapless::Vec;
use shared::hans::frame::{write_slot, RING_BYTES};

use super::Irqs;
use crate::board::{HansOutRes, HansStatusInRes, WaveRes, Xy2InRes, Xy3InRes};
use crate::channels::{
    RawInput, Stats, HANS_FRAME, HANS_HALF, RAW_INPUT, STATS, XY2_HALF, XY3_HALF, XY3_MARKS,
};
use crate::config::Head;
use crate::drivers::serial_tx::SerialTx;
use crate::drivers::spi_slave_rx::SpiSlaveRx;
use crate::drivers::sync_marks::SyncMarks;
use crate::drivers::wave_out::WaveOut;
use crate::drivers::xy2_sampler::Xy2Sampler;
use xy_bridge::dma_ring;

/// Hands a half to the bridge without waiting: a full queue means the bridge is
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
            Ok(()) => forward(RawInput::Xy2(half)),
            Err(e) => {
                defmt::warn!("xy2 in: {} (at edge {})", e, sampler.edges());
                Stats::bump(&STATS.input_overruns);
            }
        }
    }
}

/// XY3-100 input (controller side): SPI3 receives X; EXTI4 marks every SYNC rising
/// edge. Y, Z, U, W use the same driver on SPI4, SPI5, SPI1, SPI2 once the decoder
/// takes more than X (issue 5).
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
                let mut list = Vec::new();
                // `ends` holds at most XY3_MARKS entries, the Vec's capacity.
                let _ = list.extend_from_slice(ends.get(..n).unwrap_or_default());
                forward(RawInput::Xy3 { bytes, marks: list });
            }
            Err(e) => {
                defmt::warn!("xy3 in: {} ({} marks dropped)", e, marks.dropped());
                Stats::bump(&STATS.input_overruns);
            }
        }
    }
}

/// HANS-100 STATUS input (head side): TIM3 CH2 makes the 40 MHz oversampling clock
/// (240 MHz / 6; README-firmware.md clock tree) that clocks SPI6 through a wire from
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
            Ok(()) => forward(RawInput::HansStatus(half)),
            Err(e) => {
                defmt::warn!("hans status in: {}", e);
                Stats::bump(&STATS.input_overruns);
            }
        }
    }
}

/// The bridge: one raw half in, its effect on the outputs out.
/// TODO(issue 4 / issue 5): decode with the `shared` line-level receivers into
/// `LineEvent`s, translate, publish `HANS_FRAME` / the waveform halves, and report
/// valid input to the supervisor. For now it only accounts for the data.
#[embassy_executor::task]
pub async fn bridge() {
    let mut samples: u32 = 0;
    loop {
        let n = match RAW_INPUT.receive().await {
            RawInput::Xy2(s) => s.len(),
            RawInput::Xy3 { bytes, marks } => {
                STATS
                    .sync_marks
                    .fetch_add(marks.len() as u32, Ordering::Relaxed);
                bytes.len()
            }
            RawInput::HansStatus(w) => w.len(),
        };
        samples = samples.wrapping_add(n as u32);
        defmt::trace!("bridge: {} raw samples so far", samples);
    }
}

/// Port-D bit of each head-side pair (board wiring).
const PAIR_BITS: [u32; 7] = [0, 1, 2, 3, 10, 14, 15];
/// Pair index (0-based) carrying XY3's SYNC (pair 1; XY2's SYNC on pair 2 idles low
/// like every other line).
const XY3_SYNC_PAIR: usize = 0;

/// Idle BSRR word: every output low (reset half), except XY3's SYNC, which idles high
/// (`layouts.md` §4).
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

/// Waveform words per half (4 MHz tick: 1024 words = 256 us).
const WAVE_HALF: usize = 1024;

/// XY2-100 / XY3-100 output (head side): TIM8 paces DMA into GPIOD BSRR. For XY2 the
/// STATUS word is sampled from port G by TIM8 CC1 on the same ticks.
#[embassy_executor::task]
pub async fn wave_out(r: WaveRes, head: Head, head_enable: Output<'static>) {
    let mut head_enable = head_enable;
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
    // Two ticks per bit: XY2-100 2 MHz, XY3-100 2.4 MHz (24-bit frames, 100 kHz).
    let tick_hz = match head {
        Head::Xy3 => 4_800_000,
        Head::Xy2 | Head::Hans => 4_000_000,
    };
    let ring = dma_ring!(".sram2", u32, 2 * WAVE_HALF);
    let mut out = match WaveOut::new(r.tim, r.dma, Irqs, pac::GPIOD, ring, idle, tick_hz) {
        Ok(out) => out,
        Err(e) => {
            defmt::error!("wave out: {}", e);
            return;
        }
    };
    if head == Head::Xy2 {
        let status_ring = dma_ring!(".sram2", u16, 2 * WAVE_HALF);
        out.start_status_sampler(r.status_dma, Irqs, pac::GPIOG, status_ring);
    }
    defmt::info!(
        "wave out: {} ticks/s, idle word {=u32:#x}",
        out.tick_hz(),
        idle
    );
    // The DMA already plays the idle ring: the drivers may be switched on.
    head_enable.set_high();
    let idle_half = [idle; WAVE_HALF];
    let mut status = [0u16; WAVE_HALF];
    loop {
        // TODO(issue 5): the encoder's half instead of idle, once the bridge has
        // valid input.
        match out.write_half(&idle_half).await {
            Ok(()) => Stats::bump(&STATS.output_halves),
            Err(_) => Stats::bump(&STATS.output_underruns),
        }
        // TODO(issue 4): feed the XY2 STATUS word receiver with these samples.
        if out.read_status(&mut status).is_err() {
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
