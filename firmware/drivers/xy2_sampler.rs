//! XY2-100 input sampling (`layouts.md` §1): every falling edge of the controller's
//! CLK copies the GPIO port's input data register (SYNC, X, Y, Z, and STATUS where
//! used, all on one port) into a circular `[u16; N]` ring, one sample per bit.
//!
//! Deviation from the layout draft, measured against RM0433: the draft counts CLK with
//! ARR = 0 and uses the update DMA request. RM0433 §38.4 (TIMx_ARR) says the counter
//! is blocked while ARR is 0, so no update would ever happen; with ARR = 1 there would
//! be one update per *two* edges. Instead the timer's slave-mode controller takes CLK
//! as its trigger input and the **trigger** DMA request (DIER.TDE) fires on every
//! active trigger edge. The ring contents are exactly what the layout asks for.
//!
//! Register sequence (RM0433 §38 "Advanced-control timers (TIM1/TIM8)", TIM1):
//! 1. Clock on and reset (RCC, §8), CEN = 0.
//! 2. SMCR: ETP = 1 (ETR inverted: the falling CLK edge is the active edge), ETPS = /1,
//!    ETF = 0 (no filter: a filter delays the sample, and the data lines must still be
//!    stable; the line receivers clean the edges), TS = ETRF, SMS = external clock
//!    mode 1 (§38.3, "Timers and external trigger synchronization": in every slave
//!    mode but gated mode each active TRGI edge sets SR.TIF).
//! 3. ARR = 0xFFFF (the count itself is unused; it only gives a bit counter for
//!    debugging).
//! 4. DMA stream (very high priority): GPIOx_IDR (16-bit, §11.4.5) -> ring, circular, request
//!    DMAMUX1 input 16 = TIM1_TRIG (RM0433 §17.3.2, table "DMAMUX1: assignment of
//!    multiplexer inputs to resources"; embassy-stm32 has no typed trigger-DMA trait,
//!    so the number is given here, next to TIM1_UP = 15 that embassy's own table
//!    confirms).
//! 5. DIER.TDE = 1; CEN = 1 in [`Xy2Sampler::start`] ([`Xy2Sampler::new`] does both).
//!    Between [`Xy2Sampler::prepare`] and `start` a second stream can be hung on the
//!    same edges (`status_word_out`, the STATUS word towards the controller): both
//!    then count from the first edge on.
//!
//! # Ring positions
//! The stream is never restarted, so sample `n` (the `n`-th falling edge since
//! `start`) always lands at ring index `n mod ring.len()`. [`Xy2Sampler::read_exact`]
//! reports where each half it returns starts ([`Xy2Sampler::last_start`]); after an
//! overrun the reader jumps to the DMA's position, which is read consistently: NDTR
//! (RM0433 §15.5.6) before and after the ring buffer's own reset, interrupts masked,
//! must agree (they change at most once per edge, 500 ns at 2 MHz, and the pair of
//! reads takes well under 100 ns), otherwise the position stays unknown until the
//! next overrun-free resynchronisation.
//!
//! Timing: the DMA request is raised a few timer-kernel clocks after the edge (ETR
//! resynchronisation), then the stream reads IDR; at 2 MHz XY2-100 the data is stable
//! for ~250 ns after the falling edge, far more than that latency.

use embassy_stm32::dma::{Channel, InterruptHandler, ReadableRingBuffer, Request};
use embassy_stm32::gpio::{AfType, Flex, Pull};
use embassy_stm32::pac::timer::vals::{Etp, Etps, Sms, Ts};
use embassy_stm32::peripherals::{DMA2_CH0, TIM1};
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::timer::ExternalTriggerPin;
use embassy_stm32::{interrupt, pac, Peri};

use super::ring_index;

/// DMAMUX1 request number of TIM1_TRIG (RM0433 §17.3.2).
const TIM1_TRIG_REQUEST: Request = 16;
/// The sampler's stream (board allocation: DMA2 stream 0, the type of `new`'s `dma`).
const STREAM: usize = 0;
/// Tries at a consistent position read after an overrun.
const RESYNC_TRIES: usize = 4;

/// Errors of [`Xy2Sampler`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum SampleError {
    /// The DMA overwrote samples before they were read: bits were lost, the decoder
    /// must resynchronise on the SYNC pattern.
    Overrun,
}

impl core::fmt::Display for SampleError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Overrun => f.write_str("XY2 sample ring overrun"),
        }
    }
}

/// Running XY2-100 input sampler on TIM1.
pub struct Xy2Sampler<'d> {
    timer: Timer<'d, TIM1>,
    ring: ReadableRingBuffer<'d, u16>,
    ring_len: usize,
    /// Ring index of the next sample `read_exact` returns (`None`: unknown).
    next: Option<usize>,
    /// Ring index of the first sample of the last successful `read_exact`.
    last_start: Option<usize>,
    started: bool,
    _clk: Flex<'d>,
}

impl<'d> Xy2Sampler<'d> {
    /// Starts sampling `port` on every falling edge of `clk` (a TIM1_ETR pin).
    pub fn new(
        tim: Peri<'d, TIM1>,
        clk: Peri<'d, impl ExternalTriggerPin<TIM1>>,
        dma: Peri<'d, DMA2_CH0>,
        irq: impl interrupt::typelevel::Binding<
                <DMA2_CH0 as embassy_stm32::dma::ChannelInstance>::Interrupt,
                InterruptHandler<DMA2_CH0>,
            > + 'd,
        port: pac::gpio::Gpio,
        ring: &'d mut [u16],
    ) -> Self {
        let mut s = Self::prepare(tim, clk, dma, irq, port, ring);
        s.start();
        s
    }

    /// Steps 1..4 and DIER.TDE: everything but counting. [`Xy2Sampler::start`] starts.
    pub fn prepare(
        tim: Peri<'d, TIM1>,
        clk: Peri<'d, impl ExternalTriggerPin<TIM1>>,
        dma: Peri<'d, DMA2_CH0>,
        irq: impl interrupt::typelevel::Binding<
                <DMA2_CH0 as embassy_stm32::dma::ChannelInstance>::Interrupt,
                InterruptHandler<DMA2_CH0>,
            > + 'd,
        port: pac::gpio::Gpio,
        ring: &'d mut [u16],
    ) -> Self {
        let ring_len = ring.len();
        let af = clk.af_num();
        let mut clk = Flex::new(clk);
        clk.set_as_af_unchecked(af, AfType::input(Pull::None));

        // Step 1.
        let timer = Timer::new(tim);
        let regs = timer.regs_advanced();
        // Step 2.
        regs.smcr().modify(|w| {
            w.set_etp(Etp::INVERTED);
            w.set_etps(Etps::DIV1);
            w.set_etf(pac::timer::vals::FilterValue::NO_FILTER);
            w.set_ts(Ts::ETRF);
            w.set_sms(Sms::EXT_CLOCK_MODE);
        });
        // Step 3.
        regs.arr().write(|w| w.set_arr(u16::MAX));

        // Step 4.
        let channel = Channel::new(dma, irq);
        // SAFETY: IDR is a valid readable peripheral register; a 16-bit read returns
        // the port's 16 inputs (RM0433 §11.4.5). The ring lives for 'd and is only
        // read through the ring buffer.
        let mut ring = unsafe {
            ReadableRingBuffer::new(
                channel,
                TIM1_TRIG_REQUEST,
                port.idr().as_ptr() as *mut u16,
                ring,
                super::wave_out::timing_critical(),
            )
        };
        ring.start();
        // Step 5 (CEN in `start`).
        regs.dier().modify(|w| w.set_tde(true));
        Self {
            timer,
            ring,
            ring_len,
            next: Some(0),
            last_start: None,
            started: false,
            _clk: clk,
        }
    }

    /// CR1.CEN = 1: sampling starts with the next falling edge. Idempotent.
    pub fn start(&mut self) {
        if !self.started {
            self.started = true;
            self.timer.start();
        }
    }

    /// Whether [`Xy2Sampler::start`] was called.
    pub fn started(&self) -> bool {
        self.started
    }

    /// TIM1's registers, for a driver that adds a DMA request on the same edges
    /// before `start`.
    pub(crate) fn regs(&self) -> pac::timer::TimAdv {
        self.timer.regs_advanced()
    }

    /// Ring length in samples.
    pub fn ring_len(&self) -> usize {
        self.ring_len
    }

    /// Waits until `buf` is full of samples (oldest first). Pass half the ring to be
    /// woken once per DMA half.
    pub async fn read_exact(&mut self, buf: &mut [u16]) -> Result<(), SampleError> {
        match self.ring.read_exact(buf).await {
            Ok(_) => {
                self.last_start = self.next;
                self.next = self.next.map(|i| (i + buf.len()) % self.ring_len);
                Ok(())
            }
            Err(_) => {
                self.last_start = None;
                self.resync();
                Err(SampleError::Overrun)
            }
        }
    }

    /// Ring index (`n mod ring_len` of the edge count) of the first sample the last
    /// successful [`Xy2Sampler::read_exact`] returned; `None` if unknown.
    pub fn last_start(&self) -> Option<usize> {
        self.last_start
    }

    /// After an overrun: the reader restarts at the DMA's position, read consistently
    /// (module docs, "Ring positions").
    fn resync(&mut self) {
        let ndtr = || pac::DMA2.st(STREAM).ndtr().read().ndt() as usize;
        self.next = None;
        for _ in 0..RESYNC_TRIES {
            let agreed = cortex_m::interrupt::free(|_| {
                let before = ndtr();
                self.ring.clear();
                (ndtr() == before).then_some(before)
            });
            if let Some(n) = agreed {
                self.next = Some(ring_index(n, self.ring_len));
                return;
            }
        }
    }

    /// CLK falling edges counted so far (modulo 2^16), for statistics.
    pub fn edges(&self) -> u16 {
        self.timer.regs_advanced().cnt().read().cnt()
    }
}

impl Drop for Xy2Sampler<'_> {
    fn drop(&mut self) {
        self.timer
            .regs_advanced()
            .dier()
            .modify(|w| w.set_tde(false));
        self.timer.stop();
    }
}
