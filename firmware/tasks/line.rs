//! High-priority line tasks, run by the line `InterruptExecutor` (`app.rs`): one task
//! per receiver moves each DMA half-buffer towards the bridge loops ([`super::bridge`],
//! [`super::bridge_hans`]) or the HANS STATUS decoder (decode executor). Each loop iteration is one DMA
//! half, so these tasks preempt everything in thread mode but never block each other
//! for longer than one half's work.

use core::sync::atomic::Ordering;

use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::peripherals::PG8;
use embassy_stm32::{pac, Peri};
use embassy_time::Instant;

use super::ctrl_word::{self, CtrlWord};
use super::Irqs;
use crate::board::{HansStatusInRes, SpiLineRes, Xy2InRes, Xy3InRes};
use crate::channels::{
    HansStatusRaw, RawInput, Stats, Xy3Raw, HANS_HALF, HANS_STATUS_CONTIGUOUS, HANS_STATUS_RAW,
    RAW_INPUT, STATS, XY2_HALF, XY3_HALF, XY3_INPUT, XY3_LINES, XY3_MARKS, XY3_RESYNC,
};
use crate::dma_ring;
use crate::drivers::oversample_clock::Fs;
use crate::drivers::spi_slave_rx::{Instance, RxError, SpiSlaveRx};
use crate::drivers::status_word_out::StatusWordOut;
use crate::drivers::sync_marks::SyncMarks;
use crate::drivers::xy2_sampler::Xy2Sampler;
use embassy_stm32::dma;
use embassy_stm32::interrupt::typelevel::Binding;
use embassy_stm32::peripherals::{
    DMA1_CH0, DMA1_CH1, DMA1_CH2, DMA1_CH3, DMA1_CH4, EXTI4, PA15, PA4, PA5, PB10, PB12, PB15, PB5,
    PC10, PC12, PE11, PE12, PE14, PF6, PF7, PF9, PG10, SPI1, SPI2, SPI3, SPI4, SPI5,
};
use embassy_stm32::spi::{CsPin, MosiPin, RxDma, SckPin};
use shared::bridge::{Xy2Controller, Xy3Select};
use shared::hans::follow;
use shared::model::Axis;
use shared::xy3::rx::Lines;
use static_cell::StaticCell;

/// The STATUS word stream's channel, kept for as long as its transfer runs (forever).
static STATUS_DMA_SLOT: StaticCell<Option<dma::Channel<'static>>> = StaticCell::new();

/// Hands an XY2 half to the bridge without waiting: a full queue means the bridge is
/// late, and waiting would only turn that into a DMA overrun one half later.
fn forward(raw: RawInput) {
    if RAW_INPUT.try_send(raw).is_ok() {
        Stats::bump(&STATS.input_halves);
    } else {
        Stats::bump(&STATS.input_overruns);
    }
}

/// The XY2 STATUS word towards the controller (`controller.xy2.status = "word"`):
/// the STATUS pin (PA0, an output) and the controller link.
pub struct WordOut {
    /// PA0, driving the pair-6 driver input.
    pub pin: Output<'static>,
    /// The controller link (parity, polarity).
    pub link: Xy2Controller,
}

/// STATUS word ring: as long as the sampler ring (it must be a multiple of it and of
/// 20 words, `drivers::status_word_out`): 1000 words, 50 status frames, 500 us at
/// 2 MHz; a refill sweep writes it in a few microseconds.
const STATUS_WORD_RING: usize = 2 * XY2_HALF;

/// XY2-100 input (controller side): TIM1 samples port G on every CLK falling edge.
/// With `word`, a second stream on the same edges plays the STATUS word towards the
/// controller ([`super::ctrl_word`]), refreshed after every half.
#[embassy_executor::task]
pub async fn xy2_in(r: Xy2InRes, word: Option<WordOut>) {
    // Kept for as long as the task runs (forever): the samples read these pins.
    let _data = r.data.inputs();
    let ring = dma_ring!(".sram2", u16, 2 * XY2_HALF);
    let mut sampler = Xy2Sampler::prepare(r.tim, r.clk, r.dma, Irqs, pac::GPIOG, ring);
    let mut ctrl_word = None;
    if let Some(w) = word {
        let slot = STATUS_DMA_SLOT.init(None);
        let status_ring = dma_ring!(".sram2", u32, STATUS_WORD_RING);
        let out = StatusWordOut::new(
            &mut sampler,
            r.status_dma,
            Irqs,
            slot,
            pac::GPIOA,
            w.pin,
            status_ring,
            ctrl_word::idle_word(),
            ctrl_word::SYNC_BIT,
        );
        let word = out
            .map_err(|e| defmt::error!("xy2 status word out: {}", e))
            .ok()
            .map(|out| CtrlWord::new(out, w.link));
        match word {
            Some(Ok(c)) => ctrl_word = Some(c),
            Some(Err(e)) => defmt::error!("xy2 status word out: {}", e),
            None => {}
        }
    }
    sampler.start();
    let mut half = [0u16; XY2_HALF];
    loop {
        match sampler.read_exact(&mut half).await {
            Ok(()) => {
                if let Some(c) = ctrl_word.as_mut() {
                    c.after_half(&half, sampler.last_start());
                }
                forward(half)
            }
            Err(e) => {
                defmt::warn!("xy2 in: {} (at edge {})", e, sampler.edges());
                Stats::bump(&STATS.input_overruns);
            }
        }
    }
}

/// XY3-100 input (controller side): one SPI slave per received data line (`lines`:
/// X on SPI3, Y on SPI4, Z on SPI5, U on SPI1, W on SPI2), clocked by the
/// controller's CLK (shared SCK bus) and selected by SYNC; EXTI4 marks every SYNC
/// rising edge with the X ring position. Each DMA half of every line, with the marks
/// drained alongside, goes to the bridge ([`XY3_INPUT`]), which runs
/// `shared::xy3::rx::Receiver` on it. Lines not in `lines` stay off: an unconnected
/// line would read dead and fail every period.
///
/// The receiver needs byte `i` of every line to come from the same clock edges, so
/// all SPIs must start counting together: each session starts them with the SCK-bus
/// buffer off (OE# high, the bus pulled low, no edges), then turns the buffer on. An
/// overrun on any line ends the session (its lines are no longer in step) and a new
/// one starts the same way; the bridge restarts its receiver on the new session. So
/// does a request from the bridge ([`XY3_RESYNC`]): a glitch that clocked one SPI
/// but not the others leaves the lines out of step without any overrun, which only
/// the decoded periods show (`shared::xy3::step`).
///
/// `select` (`controller.xy3.select`): SYNC as every SPI's hardware NSS, or
/// software slave select held active (`SpiSlaveRx::new` without an NSS pin: SSM =
/// 1, SSI = 0, RM0433 §50.4, slave select (SS) pin management), so that no bit of a frame is ever dropped at SS
/// release and a glitch's extra edges shift their line for good instead of
/// spoiling one frame unseen (`shared::bridge::Xy3Select`). SYNC's EXTI marks the
/// frame ends either way.
#[embassy_executor::task]
pub async fn xy3_in(r: Xy3InRes, lines: Lines, select: Xy3Select) {
    let mut r = r;
    let mut sck_bus = Output::new(r.sck_buffer_oe.reborrow(), Level::High, Speed::Low);
    let x_ring = dma_ring!(".sram1", u8, 2 * XY3_HALF);
    let y_ring = dma_ring!(".sram1", u8, 2 * XY3_HALF);
    let z_ring = dma_ring!(".sram1", u8, 2 * XY3_HALF);
    let u_ring = dma_ring!(".sram1", u8, 2 * XY3_HALF);
    let w_ring = dma_ring!(".sram1", u8, 2 * XY3_HALF);
    let mut session = 0u32;
    loop {
        // Gate the clock (the last session's SPIs are off by now), so the new ones
        // start together.
        sck_bus.set_high();
        let rings = [
            &mut x_ring[..],
            &mut y_ring[..],
            &mut z_ring[..],
            &mut u_ring[..],
            &mut w_ring[..],
        ];
        let res = Xy3Lines {
            x: &mut r.x,
            y: &mut r.y,
            z: &mut r.z,
            u: &mut r.u,
            w: &mut r.w,
            sync: &mut r.sync,
            exti: &mut r.exti,
        };
        // A request for an older session is stale: this one starts in step.
        XY3_RESYNC.reset();
        if let Err(e) = xy3_session(res, lines, select, rings, session, &mut sck_bus).await {
            defmt::warn!("xy3 in: {}; restarting all lines together", e);
            Stats::bump(&STATS.input_overruns);
            // A failure that repeats at once must not spin the high-priority
            // executor: one restart per millisecond at most.
            embassy_time::Timer::after_millis(1).await;
        }
        session = session.wrapping_add(1);
    }
}

/// The parts of [`Xy3InRes`] a session borrows (the SCK-bus enable stays with the
/// task).
struct Xy3Lines<'a> {
    x: &'a mut SpiLineRes<SPI3, PC10, PC12, PA15, DMA1_CH0>,
    y: &'a mut SpiLineRes<SPI4, PE12, PE14, PE11, DMA1_CH1>,
    z: &'a mut SpiLineRes<SPI5, PF7, PF9, PF6, DMA1_CH2>,
    u: &'a mut SpiLineRes<SPI1, PA5, PB5, PG10, DMA1_CH3>,
    w: &'a mut SpiLineRes<SPI2, PB10, PB15, PB12, DMA1_CH4>,
    sync: &'a mut Peri<'static, PA4>,
    exti: &'a mut Peri<'static, EXTI4>,
}

/// Starts one data line's SPI slave into `ring`, if `on`, selected by its NSS
/// pin (SYNC) or by software (see [`xy3_in`]).
fn start_line<'a, T, K, M, N, D>(
    on: bool,
    select: Xy3Select,
    l: &'a mut SpiLineRes<T, K, M, N, D>,
    ring: &'a mut [u8],
) -> Result<Option<SpiSlaveRx<'a, u8>>, RxError>
where
    T: Instance,
    K: SckPin<T>,
    M: MosiPin<T>,
    N: CsPin<T>,
    D: RxDma<T>,
    Irqs: Binding<D::Interrupt, dma::InterruptHandler<D>>,
{
    if !on {
        return Ok(None);
    }
    let rx = SpiSlaveRx::new(
        l.spi.reborrow(),
        l.sck.reborrow(),
        l.mosi.reborrow(),
        (select == Xy3Select::Sync).then(|| l.nss.reborrow()),
        l.dma.reborrow(),
        Irqs,
        ring,
    )?;
    Ok(Some(rx))
}

/// One reception session of [`xy3_in`]: returns `Ok` when the bridge asks for a
/// restart ([`XY3_RESYNC`], checked once per half), an error when a line fails.
async fn xy3_session(
    r: Xy3Lines<'_>,
    lines: Lines,
    select: Xy3Select,
    rings: [&mut [u8]; XY3_LINES],
    session: u32,
    sck_bus: &mut Output<'_>,
) -> Result<(), RxError> {
    let [x_ring, y_ring, z_ring, u_ring, w_ring] = rings;
    let ring_len = x_ring.len() as u16;
    // Indexed by `Axis::index`, like `Xy3Raw::bytes`. X is in every set.
    let mut rx = [
        start_line(true, select, r.x, x_ring)?,
        start_line(lines.has(Axis::Y), select, r.y, y_ring)?,
        start_line(lines.has(Axis::Z), select, r.z, z_ring)?,
        start_line(lines.has(Axis::U), select, r.u, u_ring)?,
        start_line(lines.has(Axis::W), select, r.w, w_ring)?,
    ];
    let mut marks = SyncMarks::new(r.sync.reborrow(), r.exti.reborrow(), Irqs, ring_len);
    // Every line is ready: let the clock in.
    sck_bus.set_low();
    let mut raw = Xy3Raw {
        session,
        first_byte: 0,
        bytes: [[0; XY3_HALF]; XY3_LINES],
        ends: heapless::Vec::new(),
    };
    let mut ends = [0u32; XY3_MARKS];
    loop {
        for (line, bytes) in rx.iter_mut().zip(raw.bytes.iter_mut()) {
            if let Some(line) = line {
                line.read_exact(bytes).await?;
            }
        }
        let n = marks.drain(&mut ends);
        raw.ends.clear();
        // `ends` has the Vec's capacity: everything drained fits.
        let _ = raw
            .ends
            .extend_from_slice(ends.get(..n).unwrap_or_default());
        STATS.sync_marks.fetch_add(n as u32, Ordering::Relaxed);
        // Never wait for the bridge: a full queue loses this half (the bridge sees
        // the gap in `first_byte` and restarts its receiver there).
        if XY3_INPUT.try_send(raw.clone()).is_ok() {
            Stats::bump(&STATS.input_halves);
        } else {
            Stats::bump(&STATS.input_overruns);
        }
        raw.first_byte = raw.first_byte.wrapping_add(XY3_HALF as u32);
        if XY3_RESYNC.try_take() == Some(session) {
            return Ok(());
        }
    }
}

/// HANS-100 STATUS input (head side): `fs` (TIM3 CH2) is the oversampling clock that
/// clocks SPI6 through a wire from PC7 to PB3; SPI6 receives 16-bit words into a
/// BDMA ring in SRAM4. Every `every`-th half (`shared::hans::follow::status_every`),
/// and every half while [`HANS_STATUS_CONTIGUOUS`] asks for it, goes to the STATUS
/// decoder (`follow::status_passes`, the rule the host pipeline runs too) in
/// the decode executor (`status::hans_status`, via [`HANS_STATUS_RAW`]), numbered
/// so the decoder knows how many words lie between two halves, in a session that
/// changes when words were lost (an overrun: how many is not known).
#[embassy_executor::task]
pub async fn hans_status_in(r: HansStatusInRes, fs: Fs, every: u32) {
    let mut fs = fs;
    fs.run();
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
    let mut raw = HansStatusRaw {
        session: 0,
        half: 0,
        ready: 0,
        words: [0u16; HANS_HALF],
    };
    loop {
        match rx.read_exact(&mut raw.words).await {
            Ok(()) => {
                Stats::bump(&STATS.input_halves);
                raw.half = raw.half.wrapping_add(1);
                raw.ready = Instant::now().as_ticks();
                let contiguous = HANS_STATUS_CONTIGUOUS.load(Ordering::Relaxed);
                let wanted = follow::status_passes(raw.half, every, contiguous);
                // A full queue means the decoder is still on the last one: skip.
                if wanted && HANS_STATUS_RAW.try_send(raw.clone()).is_err() {
                    Stats::bump(&STATS.input_overruns);
                }
            }
            Err(e) => {
                defmt::warn!("hans status in: {}", e);
                Stats::bump(&STATS.input_overruns);
                // Words were lost, how many is not known: the decoder must not
                // count across (a new receiver on the next half).
                raw.session = raw.session.wrapping_add(1);
            }
        }
    }
}
