//! HANS-100 controller input: up to five receive-only SPI slaves, CH1..CH5 on SPI1,
//! SPI2, SPI3, SPI4, SPI5 (README "Peripheral allocation"), all clocked by the one
//! oversampling clock fs ([`Fs`], TIM3 CH1 on the SCK bus) into `u16` DMA rings
//! (`layouts.md` §3: MSB first, bit 15 of a word the earliest sample).
//!
//! `shared::hans::rx::HansRx` needs word `i` of every ring to cover the same 16
//! instants. Each SPI counts the edges it has seen since it was enabled, so they all
//! have to be enabled before the first edge: [`HansInput::start`] holds fs low,
//! starts every used channel's SPI and DMA ([`SpiSlaveRx`]: software slave select,
//! free-running stream, SCK pulled down while undriven), then lets fs run. An
//! overrun on any channel breaks that alignment for good, so the caller drops the
//! whole set and starts a new one (a new session) from the same [`HansInput`].
//!
//! Register sequence of a session ([`HansInput::start`]), on top of the two drivers
//! it combines:
//! 1. fs held low: TIM3 CH1's compare value 0, applied by the preloaded CCR at the
//!    next update event, within one fs period (RM0433, general-purpose timers
//!    TIM2..TIM5, output compare preload; [`Fs::hold_low`]). The SCK bus then stays low, the idle level of CPOL = 0.
//! 2. Each used channel's SPI configured and enabled as a receive-only slave with
//!    software slave select held active (SSM = 1, SSI = 0) and its circular DMA
//!    stream running before SPE = 1 (RM0433 §50.4, slave select management and
//!    DMA; [`SpiSlaveRx::new`]). An SPI slave has no frame sync of its own: it
//!    shifts in one bit per SCK sampling edge while SPE = 1 and packs them into
//!    words counted from the first edge after enabling (RM0433 §50.4, data frame
//!    size and packing), which is why every SPI must be enabled before fs runs.
//! 3. fs runs (compare value = half the period, from the next update: a whole first
//!    pulse, [`Fs::run`]): every SPI sees the same first edge, so word `i` of every
//!    ring covers the same 16 samples.
//! 4. Reading: an overrun (RxFIFO OVR, RM0433 §50.4 error flags, or a DMA ring lap
//!    by the reader, RM0433 §15.4, circular mode) loses words on one channel only;
//!    [`HansLines::read`] reports it and the caller starts a new session from 1.
//!
//! The firmware's `hans_in` task and the HIL test `hans_controller_loopback` both
//! take their rings from [`hans_rings!`] and start every session through
//! [`HansInput`], so the test runs the task's start sequence, not a copy of it.
//!
//! The pins: CH3..CH5 on the X, Y, Z MOSI pins the XY3-100 input uses too (pairs 3..5),
//! CH1 on PD7 (SPI1), CH2 on PC1 (SPI2); the SPIs, SCK pins and DMA1 streams 0..4 are
//! the XY3-100 input's ([`Xy3InRes`]): one controller protocol runs at a time.

use embassy_stm32::dma::InterruptHandler;
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::interrupt::typelevel::{
    Binding, DMA1_STREAM0, DMA1_STREAM1, DMA1_STREAM2, DMA1_STREAM3, DMA1_STREAM4,
};
use embassy_stm32::peripherals::{DMA1_CH0, DMA1_CH1, DMA1_CH2, DMA1_CH3, DMA1_CH4};
use embassy_stm32::spi::{CsPin, MosiPin, RxDma, SckPin};
use embassy_stm32::{Peri, PeripheralType};

use super::oversample_clock::Fs;
use super::spi_slave_rx::{Instance, RxError, SpiSlaveRx};
use crate::board::{HansInRes, SpiLineRes, Xy3InRes};

/// HANS-100 data channels.
pub const CHANNELS: usize = 5;

/// Zeroes five fresh `u16` DMA rings of `$n` words in SRAM1 (which DMA1 reaches),
/// one per channel, for [`HansInput::new`](crate::drivers::hans_lines::HansInput::new):
/// `[&'static mut [u16; $n]; 5]`. Its caller must fit one read of every channel in
/// a ring ([`HansLines::read`](crate::drivers::hans_lines::HansLines::read) reads the
/// channels one after the other while all of them fill).
///
/// Same rule as [`dma_ring!`](crate::dma_ring): expand it only in code that runs at
/// most once per boot.
#[macro_export]
macro_rules! hans_rings {
    ($n:expr) => {
        [
            $crate::dma_ring!(".sram1", u16, $n),
            $crate::dma_ring!(".sram1", u16, $n),
            $crate::dma_ring!(".sram1", u16, $n),
            $crate::dma_ring!(".sram1", u16, $n),
            $crate::dma_ring!(".sram1", u16, $n),
        ]
    };
}

/// What the HANS-100 controller input keeps across sessions: the lines' resources and
/// one ring per channel. Each [`HansInput::start`] starts a new aligned set on them.
pub struct HansInput<'d> {
    x: Xy3InRes,
    h: HansInRes,
    rings: [&'d mut [u16]; CHANNELS],
}

impl<'d> HansInput<'d> {
    /// Takes the lines and `rings` (indexed by channel number - 1, from
    /// [`hans_rings!`]) and turns the XY3-100 clock buffer off for good: fs drives
    /// the SCK bus now, and the buffer would drive it too (README "Wiring / pin
    /// map", pair 2). The `Output` is forgotten on purpose: dropping it would
    /// turn the pin back into an input and let OE# float.
    pub fn new<const N: usize>(
        x: Xy3InRes,
        h: HansInRes,
        rings: [&'d mut [u16; N]; CHANNELS],
    ) -> Self {
        let mut x = x;
        core::mem::forget(Output::new(
            x.sck_buffer_oe.reborrow(),
            Level::High,
            Speed::Low,
        ));
        let rings = rings.map(|r| -> &'d mut [u16] { r });
        HansInput { x, h, rings }
    }

    /// Starts the channels in `used` (bit n-1 for channel n, as
    /// `shared::hans::rx::Mode::channel_mask`) with `fs` held low, then lets `fs`
    /// run, so every ring starts at the same clock edge. Channels not used stay off.
    /// Dropping the returned set stops it; the next call starts a new session.
    pub fn start(
        &mut self,
        used: u8,
        irqs: impl LineIrqs + 'd,
        fs: &mut Fs,
    ) -> Result<HansLines<'_>, RxError> {
        let rings = self.rings.each_mut().map(|r| &mut **r);
        HansLines::start(&mut self.x, &mut self.h, used, rings, irqs, fs)
    }
}

/// The DMA interrupt bindings the five channels need (the firmware's and the HIL
/// tests' `bind_interrupts!` structs both have them).
pub trait LineIrqs:
    Binding<DMA1_STREAM0, InterruptHandler<DMA1_CH0>>
    + Binding<DMA1_STREAM1, InterruptHandler<DMA1_CH1>>
    + Binding<DMA1_STREAM2, InterruptHandler<DMA1_CH2>>
    + Binding<DMA1_STREAM3, InterruptHandler<DMA1_CH3>>
    + Binding<DMA1_STREAM4, InterruptHandler<DMA1_CH4>>
    + Copy
{
}

impl<I> LineIrqs for I where
    I: Binding<DMA1_STREAM0, InterruptHandler<DMA1_CH0>>
        + Binding<DMA1_STREAM1, InterruptHandler<DMA1_CH1>>
        + Binding<DMA1_STREAM2, InterruptHandler<DMA1_CH2>>
        + Binding<DMA1_STREAM3, InterruptHandler<DMA1_CH3>>
        + Binding<DMA1_STREAM4, InterruptHandler<DMA1_CH4>>
        + Copy
{
}

/// The running channels of one session, indexed by channel number - 1.
pub struct HansLines<'d> {
    rx: [Option<SpiSlaveRx<'d, u16>>; CHANNELS],
}

/// No NSS pin, typed as the line's NSS pin (the stream is free-running).
fn no_nss<'d, S, K, M, N, D>(_: &SpiLineRes<S, K, M, N, D>) -> Option<Peri<'d, N>>
where
    S: PeripheralType,
    K: PeripheralType,
    M: PeripheralType,
    N: PeripheralType,
    D: PeripheralType,
{
    None
}

/// Starts one channel's SPI slave into `ring`, if `on`.
#[expect(
    clippy::too_many_arguments,
    reason = "the parts of one SPI line, each typed by its pin trait"
)]
fn start_one<'d, T, D>(
    on: bool,
    spi: Peri<'d, T>,
    sck: Peri<'d, impl SckPin<T>>,
    mosi: Peri<'d, impl MosiPin<T>>,
    nss: Option<Peri<'d, impl CsPin<T>>>,
    dma: Peri<'d, D>,
    irq: impl Binding<D::Interrupt, InterruptHandler<D>> + 'd,
    ring: &'d mut [u16],
) -> Result<Option<SpiSlaveRx<'d, u16>>, RxError>
where
    T: Instance,
    D: RxDma<T>,
{
    if !on {
        return Ok(None);
    }
    SpiSlaveRx::new(spi, sck, mosi, nss, dma, irq, ring).map(Some)
}

impl<'d> HansLines<'d> {
    /// [`HansInput::start`] on `x`, `h` and `rings` (indexed by channel number - 1;
    /// all the same length).
    fn start(
        x: &'d mut Xy3InRes,
        h: &'d mut HansInRes,
        used: u8,
        rings: [&'d mut [u16]; CHANNELS],
        irqs: impl LineIrqs + 'd,
        fs: &mut Fs,
    ) -> Result<Self, RxError> {
        fs.hold_low();
        let on = |ch: usize| used & (1 << (ch - 1)) != 0;
        let [r1, r2, r3, r4, r5] = rings;
        let (n1, n2, n3, n4, n5) = (
            no_nss(&x.u),
            no_nss(&x.w),
            no_nss(&x.x),
            no_nss(&x.y),
            no_nss(&x.z),
        );
        let (u, w) = (&mut x.u, &mut x.w);
        let (cx, cy, cz) = (&mut x.x, &mut x.y, &mut x.z);
        let rx = [
            start_one(
                on(1),
                u.spi.reborrow(),
                u.sck.reborrow(),
                h.ch1.reborrow(),
                n1,
                u.dma.reborrow(),
                irqs,
                r1,
            )?,
            start_one(
                on(2),
                w.spi.reborrow(),
                w.sck.reborrow(),
                h.ch2.reborrow(),
                n2,
                w.dma.reborrow(),
                irqs,
                r2,
            )?,
            start_one(
                on(3),
                cx.spi.reborrow(),
                cx.sck.reborrow(),
                cx.mosi.reborrow(),
                n3,
                cx.dma.reborrow(),
                irqs,
                r3,
            )?,
            start_one(
                on(4),
                cy.spi.reborrow(),
                cy.sck.reborrow(),
                cy.mosi.reborrow(),
                n4,
                cy.dma.reborrow(),
                irqs,
                r4,
            )?,
            start_one(
                on(5),
                cz.spi.reborrow(),
                cz.sck.reborrow(),
                cz.mosi.reborrow(),
                n5,
                cz.dma.reborrow(),
                irqs,
                r5,
            )?,
        ];
        // Every used SPI is enabled and waits for its first edge.
        fs.run();
        Ok(HansLines { rx })
    }

    /// Waits until every running channel has `N` more words and copies them into
    /// `out[channel - 1]` (channels not running are left as they are). An error
    /// means words were lost on some channel: the channels are no longer aligned,
    /// so the caller must start a new set.
    pub async fn read<const N: usize>(
        &mut self,
        out: &mut [[u16; N]; CHANNELS],
    ) -> Result<(), RxError> {
        for (rx, buf) in self.rx.iter_mut().zip(out.iter_mut()) {
            if let Some(rx) = rx {
                rx.read_exact(buf).await?;
            }
        }
        Ok(())
    }
}
