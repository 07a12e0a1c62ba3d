//! XY2-100 input sampling (`layouts.md` §1): every falling edge of the controller's
//! CLK copies the GPIO port's input data register (SYNC, X, Y, Z, and STATUS where
//! used, all on one port) into a circular `[u16; N]` ring, one sample per bit.
//!
//! Deviation from the layout draft, measured against RM0433: the draft counts CLK with
//! ARR = 0 and uses the update DMA request. RM0433 §39.4.12 (TIMx_ARR) says the counter
//! is blocked while ARR is 0, so no update would ever happen; with ARR = 1 there would
//! be one update per *two* edges. Instead the timer's slave-mode controller takes CLK
//! as its trigger input and the **trigger** DMA request (DIER.TDE) fires on every
//! active trigger edge. The ring contents are exactly what the layout asks for.
//!
//! Register sequence (RM0433 §39 "Advanced-control timers", TIM1):
//! 1. Clock on and reset (RCC, §8), CEN = 0.
//! 2. SMCR: ETP = 1 (ETR inverted: the falling CLK edge is the active edge), ETPS = /1,
//!    ETF = 0 (no filter: a filter delays the sample, and the data lines must still be
//!    stable; the line receivers clean the edges), TS = ETRF, SMS = external clock
//!    mode 1 (§39.3.20 "Timers and external trigger synchronization": in every slave
//!    mode but gated mode each active TRGI edge sets SR.TIF).
//! 3. ARR = 0xFFFF (the count itself is unused; it only gives a bit counter for
//!    debugging).
//! 4. DMA stream (very high priority): GPIOx_IDR (16-bit, §11.4.5) -> ring, circular, request
//!    DMAMUX1 input 16 = TIM1_TRIG (RM0433 §17.3.2, table "DMAMUX1: assignment of
//!    multiplexer inputs to resources"; embassy-stm32 has no typed trigger-DMA trait,
//!    so the number is given here, next to TIM1_UP = 15 that embassy's own table
//!    confirms).
//! 5. DIER.TDE = 1, CEN = 1.
//!
//! Timing: the DMA request is raised a few timer-kernel clocks after the edge (ETR
//! resynchronisation), then the stream reads IDR; at 2 MHz XY2-100 the data is stable
//! for ~250 ns after the falling edge, far more than that latency.

use embassy_stm32::dma::{Channel, ChannelInstance, InterruptHandler, ReadableRingBuffer, Request};
use embassy_stm32::gpio::{AfType, Flex, Pull};
use embassy_stm32::pac::timer::vals::{Etp, Etps, Sms, Ts};
use embassy_stm32::peripherals::TIM1;
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::timer::ExternalTriggerPin;
use embassy_stm32::{interrupt, pac, Peri};

/// DMAMUX1 request number of TIM1_TRIG (RM0433 §17.3.2).
const TIM1_TRIG_REQUEST: Request = 16;

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
    _clk: Flex<'d>,
}

impl<'d> Xy2Sampler<'d> {
    /// Starts sampling `port` on every falling edge of `clk` (a TIM1_ETR pin).
    pub fn new<D: ChannelInstance>(
        tim: Peri<'d, TIM1>,
        clk: Peri<'d, impl ExternalTriggerPin<TIM1>>,
        dma: Peri<'d, D>,
        irq: impl interrupt::typelevel::Binding<D::Interrupt, InterruptHandler<D>> + 'd,
        port: pac::gpio::Gpio,
        ring: &'d mut [u16],
    ) -> Self {
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
        // Step 5.
        regs.dier().modify(|w| w.set_tde(true));
        timer.start();
        Self {
            timer,
            ring,
            _clk: clk,
        }
    }

    /// Waits until `buf` is full of samples (oldest first). Pass half the ring to be
    /// woken once per DMA half.
    pub async fn read_exact(&mut self, buf: &mut [u16]) -> Result<(), SampleError> {
        match self.ring.read_exact(buf).await {
            Ok(_) => Ok(()),
            Err(_) => {
                self.ring.clear();
                Err(SampleError::Overrun)
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
