//! Timer-paced DMA of waveform words into a GPIO port's BSRR (XY2-100 / XY3-100 out,
//! `layouts.md` §4), plus the optional status-word sampler on the same timer (XY2-100
//! STATUS in, head side).
//!
//! embassy-stm32 0.6 has no DMA-to-GPIO helper. This driver lets the timer's update
//! event request one DMA transfer per tick; embassy's [`WritableRingBuffer`] runs the
//! stream in circular mode and tells us when a half is free again, so the encoder
//! writes the next half while the DMA plays the current one (double buffering).
//!
//! Register sequence (RM0433 §39 "Advanced-control timers (TIM1/TIM8)", §11 GPIO,
//! §15/§17 DMA/DMAMUX):
//! 1. Timer clock on and reset (RCC, §8); counter stopped (CR1.CEN = 0).
//! 2. PSC = 0, ARR = timer clock / tick rate - 1 (§39.3.1 time-base unit): one update
//!    event per tick. The tick is twice the bit clock (two words per bit).
//! 3. The ring is pre-filled with the idle word (`OutPinMap::idle`), so whatever the
//!    DMA plays before the encoder has written anything keeps the lines idle.
//! 4. DMA stream: memory -> GPIOx_BSRR, 32-bit words (§11.4.7: BSRR is write-only;
//!    bits 0..15 set, 16..31 reset the pins; a 32-bit write changes all pins of the
//!    port in the same AHB cycle, so CLK and data edges are simultaneous), circular.
//! 5. DIER.UDE = 1 (§39.4.4): each update event raises a DMA request (DMAMUX1
//!    request TIMx_UP, §17.3.2).
//! 6. Optional status sampler ([`WaveOut::start_status_sampler`], before step 7): CC1
//!    in output-compare "frozen" mode with CCR1 at the middle of the tick, DIER.CC1DE
//!    = 1, CR2.CCDS = 0 (§39.4.3: the CC DMA request is sent on the compare event, not
//!    on update). A second stream copies GPIOx_IDR (16-bit, §11.4.5) into a
//!    [`ReadableRingBuffer`]: one sample per tick.
//! 7. [`WaveOut::start`]: CR1.CEN = 1. The counter was reset by the UG of step 2, so
//!    both DMA requests count from the same first period: in period `p` the compare
//!    (mid-period) takes sample `p`, then the update writes word `p` to BSRR. Sample
//!    `s` therefore sees word `s - 1` in the middle of its tick, for the whole run.
//!
//! # Status-word alignment (layouts.md §4, `shared::xy2::status_line`)
//! The first word the encoder writes lands at ring index 0 after the DMA has played
//! the idle pre-fill once (embassy's writable ring starts one lap ahead), i.e. it is
//! word number `ring.len()` of the run, and later writes follow it back to back. A
//! frame slot therefore starts at word `ring.len()` plus a multiple of the frame
//! length. [`WaveOut::read_status`] keeps one sample per tick pair, the one in the
//! middle of the pair's first tick (word `ring.len() + 2j` for bit `j` counted from
//! the first written word): for XY2-100 that is the CLK-high half of each bit, half a
//! bit after the head changed STATUS on the previous falling edge, which is where the
//! head's status bit is stable. An output underrun (embassy then restarts the write
//! position one lap ahead of wherever the DMA is), a status ring overrun or a write
//! of an odd number of words breaks this count; the samples are then reported as
//! unaligned ([`WaveError::StatusUnaligned`]) for the rest of the run instead of being
//! handed out at a guessed phase.
//!
//! The ticks are exact only when the timer clock divides evenly (see
//! README.md (section "Firmware") "Clock tree"); [`WaveOut::tick_hz`] reports the real rate.

use embassy_stm32::dma::{
    Channel, InterruptHandler, Priority, ReadableRingBuffer, TransferOptions, WritableRingBuffer,
};
use embassy_stm32::pac::timer::vals::Ccds;
use embassy_stm32::timer::low_level::{OutputCompareMode, Timer};
use embassy_stm32::timer::{AdvancedInstance4Channel, Ch1, Dma, UpDma};
use embassy_stm32::{interrupt, pac, Peri};

/// Errors of [`WaveOut`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum WaveError {
    /// The tick rate cannot be made from the timer clock (0, or above it).
    BadTickRate {
        /// Requested ticks per second.
        hz: u32,
        /// Timer clock.
        timer_hz: u32,
    },
    /// The DMA played a half before the encoder refilled it (the output repeated old
    /// words); the encoder must resynchronise.
    Underrun,
    /// The status sampler's ring was overwritten before it was read.
    StatusOverrun,
    /// The status samples' phase against the output words is no longer known (after an
    /// underrun, a status overrun or an odd-length write; see the module docs).
    StatusUnaligned,
    /// The status sampler was asked for after the timer had been started.
    AlreadyStarted,
}

impl core::fmt::Display for WaveError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BadTickRate { hz, timer_hz } => {
                write!(
                    f,
                    "tick rate {hz} Hz not possible from a {timer_hz} Hz timer"
                )
            }
            Self::Underrun => f.write_str("waveform DMA underrun"),
            Self::StatusOverrun => f.write_str("status sample ring overrun"),
            Self::StatusUnaligned => f.write_str("status samples no longer aligned to the output"),
            Self::AlreadyStarted => f.write_str("status sampler must start before the timer"),
        }
    }
}

/// DMA options for streams whose timing is the line timing: very high priority, so
/// the other streams on the same controller delay them by at most one transfer
/// (RM0433 §15.3.3, stream priority arbitration).
pub fn timing_critical() -> TransferOptions {
    let mut options = TransferOptions::default();
    options.priority = Priority::VeryHigh;
    options
}

/// The status sampler's ring and where the reader stands in the run (module docs).
struct StatusSampler<'d> {
    ring: ReadableRingBuffer<'d, u16>,
    /// Samples still to drop before the first kept one (sample `ring.len() + 1` of
    /// the output ring: the middle of the first written word).
    skip: usize,
    /// The next sample after `skip` is the second of a tick pair (dropped).
    odd: bool,
    /// The phase is still known.
    aligned: bool,
}

/// A waveform output (and optional status sampler); plays once [`WaveOut::start`]ed.
pub struct WaveOut<'d, T: AdvancedInstance4Channel> {
    timer: Timer<'d, T>,
    ring: WritableRingBuffer<'d, u32>,
    /// Length of the output ring (words).
    ring_len: usize,
    status: Option<StatusSampler<'d>>,
    /// Every write so far had an even length (tick pairs stay pairs).
    pairs: bool,
    started: bool,
    tick_hz: u32,
}

impl<'d, T: AdvancedInstance4Channel> WaveOut<'d, T> {
    /// Prepares playing `ring` into `port`'s BSRR at `tick_hz` ticks per second (steps
    /// 1..5; [`WaveOut::start`] starts it). The ring is filled with `idle` first.
    /// `ring.len()` must be even (two halves).
    pub fn new<D: UpDma<T>>(
        tim: Peri<'d, T>,
        dma: Peri<'d, D>,
        irq: impl interrupt::typelevel::Binding<D::Interrupt, InterruptHandler<D>> + 'd,
        port: pac::gpio::Gpio,
        ring: &'d mut [u32],
        idle: u32,
        tick_hz: u32,
    ) -> Result<Self, WaveError> {
        // Step 1.
        let timer = Timer::new(tim);
        let timer_hz = timer.get_clock_frequency().0;
        if tick_hz == 0 || tick_hz > timer_hz {
            return Err(WaveError::BadTickRate {
                hz: tick_hz,
                timer_hz,
            });
        }
        // Step 2. Rounded to the nearest divider; ARR is 16 bits on TIM1/TIM8, and
        // every rate we use (>= 1 MHz from 240 MHz) needs far fewer.
        let clocks = (timer_hz + tick_hz / 2) / tick_hz;
        let regs = timer.regs_advanced();
        regs.psc().write_value(0);
        regs.arr()
            .write(|w| w.set_arr(clocks.saturating_sub(1) as u16));
        // Load PSC/ARR now (UG) without a pending DMA request: UDE is still 0.
        timer.generate_update_event();
        regs.sr().write_value(pac::timer::regs::SrAdv(0));

        // Step 3.
        ring.fill(idle);
        let ring_len = ring.len();

        // Step 4.
        let request = dma.request();
        dma.remap();
        let channel = Channel::new(dma, irq);
        // SAFETY: BSRR is a valid 32-bit write-only peripheral register for as long
        // as the port exists (forever); the ring lives for 'd and the DMA reads it
        // only through the ring buffer, which owns it for 'd.
        let mut ring = unsafe {
            WritableRingBuffer::new(
                channel,
                request,
                port.bsrr().as_ptr() as *mut u32,
                ring,
                timing_critical(),
            )
        };

        // The stream waits for requests: none come before step 7.
        ring.start();
        // Step 5.
        regs.dier().modify(|w| w.set_ude(true));
        Ok(Self {
            timer,
            ring,
            ring_len,
            status: None,
            pairs: true,
            started: false,
            tick_hz: timer_hz / clocks.max(1),
        })
    }

    /// Step 7: starts the timer; the DMA plays the idle ring until the first
    /// [`WaveOut::write_half`] lands one ring length later. Idempotent.
    pub fn start(&mut self) {
        if !self.started {
            self.started = true;
            self.timer.start();
        }
    }

    /// Step 6: samples `port`'s IDR once per tick, in the middle of the tick, into
    /// `ring` (layouts.md §4, XY2-100 STATUS word in), from the first tick on. Must be
    /// called before [`WaveOut::start`] so that samples and words count from the same
    /// period (module docs); later it is refused.
    pub fn start_status_sampler<S: Dma<T, Ch1>>(
        &mut self,
        dma: Peri<'d, S>,
        irq: impl interrupt::typelevel::Binding<S::Interrupt, InterruptHandler<S>> + 'd,
        port: pac::gpio::Gpio,
        ring: &'d mut [u16],
    ) -> Result<(), WaveError> {
        if self.started {
            return Err(WaveError::AlreadyStarted);
        }
        let regs = self.timer.regs_advanced();
        let half_tick = (regs.arr().read().arr() / 2).max(1);
        regs.ccmr_output(0)
            .modify(|w| w.set_ocm(0, OutputCompareMode::Frozen.into()));
        regs.ccr(0).write(|w| w.set_ccr(half_tick));
        regs.cr2().modify(|w| w.set_ccds(Ccds::ON_COMPARE));
        let request = dma.request();
        dma.remap();
        let channel = Channel::new(dma, irq);
        // SAFETY: IDR is a valid readable peripheral register; a 16-bit read returns
        // the port's 16 inputs (RM0433 §11.4.5). The ring lives for 'd and is only
        // read through the ring buffer.
        let mut rb = unsafe {
            ReadableRingBuffer::new(
                channel,
                request,
                port.idr().as_ptr() as *mut u16,
                ring,
                timing_critical(),
            )
        };
        rb.start();
        regs.dier().modify(|w| w.set_ccde(0, true));
        self.status = Some(StatusSampler {
            ring: rb,
            skip: self.ring_len + 1,
            odd: false,
            aligned: true,
        });
        Ok(())
    }

    /// The real tick rate (timer clock / divider).
    pub fn tick_hz(&self) -> u32 {
        self.tick_hz
    }

    /// Waits until one half of the ring is free and writes `half` into it. Call with
    /// about `ring.len() / 2` words per call to stay in step with the DMA halves (the
    /// ring paces by free space, so whole frames of a slightly shorter batch are fine).
    pub async fn write_half(&mut self, half: &[u32]) -> Result<(), WaveError> {
        self.pairs &= half.len().is_multiple_of(2);
        match self.ring.write_exact(half).await {
            Ok(_) => Ok(()),
            Err(_) => {
                self.ring.clear();
                // The next write lands wherever the DMA is plus one lap: the status
                // samples' phase against the frames is lost.
                self.pairs = false;
                Err(WaveError::Underrun)
            }
        }
    }

    /// Reads the status samples taken since the last call into `buf` and keeps one per
    /// tick pair, aligned to the written words (module docs): on return `buf[..n]`
    /// holds them in time order; the first kept sample of the run belongs to the first
    /// word ever written. `Ok(0)` without a status sampler; [`WaveError::StatusOverrun`]
    /// once and then [`WaveError::StatusUnaligned`] when the phase is lost.
    pub fn read_status(&mut self, buf: &mut [u16]) -> Result<usize, WaveError> {
        let Some(st) = self.status.as_mut() else {
            return Ok(0);
        };
        st.aligned &= self.pairs;
        if !st.aligned {
            // Keep the ring drained so it does not report stale overruns.
            let _ = st.ring.read(buf);
            return Err(WaveError::StatusUnaligned);
        }
        let n = match st.ring.read(buf) {
            Ok((n, _)) => n,
            Err(_) => {
                st.ring.clear();
                st.aligned = false;
                return Err(WaveError::StatusOverrun);
            }
        };
        let mut kept = 0;
        for i in 0..n {
            if st.skip > 0 {
                st.skip -= 1;
                continue;
            }
            let keep = !st.odd;
            st.odd = !st.odd;
            // kept <= i: compacting in place never overtakes the reader.
            if let (true, Some(s)) = (keep, buf.get(i).copied()) {
                if let Some(d) = buf.get_mut(kept) {
                    *d = s;
                    kept += 1;
                }
            }
        }
        Ok(kept)
    }
}

impl<T: AdvancedInstance4Channel> Drop for WaveOut<'_, T> {
    fn drop(&mut self) {
        // Stop the requests first; the ring buffers then stop their streams.
        self.timer.stop();
        self.timer.regs_advanced().dier().modify(|w| {
            w.set_ude(false);
            w.set_ccde(0, false);
        });
    }
}
