//! Timer-paced DMA of waveform words into a GPIO port's BSRR (XY2-100 / XY3-100 out,
//! `layouts.md` §4), plus the optional status-word sampler on the same timer (XY2-100
//! STATUS in, head side).
//!
//! embassy-stm32 0.6 has no DMA-to-GPIO helper. This driver lets the timer's update
//! event request one DMA transfer per tick; embassy's [`WritableRingBuffer`] runs the
//! stream in circular mode and tells us when a half is free again, so the encoder
//! writes the next half while the DMA plays the current one (double buffering).
//!
//! Register sequence (RM0433 §38 "Advanced-control timers (TIM1/TIM8)", §11 GPIO,
//! §15/§17 DMA/DMAMUX):
//! 1. Timer clock on and reset (RCC, §8); counter stopped (CR1.CEN = 0).
//! 2. PSC = 0, ARR = timer clock / tick rate - 1 (§38.3, "Time-base unit"): one update
//!    event per tick. The tick is twice the bit clock (two words per bit).
//! 3. The ring is pre-filled with the idle word (`OutPinMap::idle`), so whatever the
//!    DMA plays before the encoder has written anything keeps the lines idle.
//! 4. DMA stream: memory -> GPIOx_BSRR, 32-bit words (§11.4.7: BSRR is write-only;
//!    bits 0..15 set, 16..31 reset the pins; a 32-bit write changes all pins of the
//!    port in the same AHB cycle, so CLK and data edges are simultaneous), circular.
//! 5. DIER.UDE = 1 (§38.4, TIMx_DIER): each update event raises a DMA request (DMAMUX1
//!    request TIMx_UP, §17.3.2).
//! 6. Optional status sampler ([`WaveOut::start_status_sampler`], before step 7): CC1
//!    in output-compare "frozen" mode with CCR1 at the middle of the tick, DIER.CC1DE
//!    = 1, CR2.CCDS = 0 (§38.4, TIMx_CR2: the CC DMA request is sent on the compare event, not
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
//! word number `ring.len()` of the run, and later writes follow it back to back. The
//! driver counts words absolutely (`next_word`: the number of the word the next
//! write lands on) and samples absolutely (`read`: samples taken out of the status
//! ring). [`WaveOut::read_status`] hands out every sample from the one in the middle
//! of the first written word's tick on (sample `ring.len() + 1`), one per tick, in
//! order; the caller picks the ticks it needs (one per bit, per frame period).
//!
//! # Realignment after an underrun or a status overrun
//! An output underrun makes embassy restart the write position one lap ahead of
//! wherever the DMA is; a status ring overrun loses the reader's count. Either way
//! the driver takes **one consistent snapshot** of both streams and the timer:
//! CR1.CEN = 0 stops the requests (the lines hold their levels for well under a
//! microsecond, interrupts masked), a short wait lets the DMA serve a request already
//! raised, then both NDTRs (RM0433 §15.5.6) and CNT are read, nothing moving. With
//! `o` the output ring index of the next word and `s` the status ring index of the
//! next sample, the samples taken exceed the words played by `k = (s - o) mod
//! out_len`, which must be 0 (CNT before the compare) or 1 (after it, CNT >= CCR1:
//! the sample of this period is taken, its word not yet played); the status ring is a
//! multiple of the output ring so `s mod out_len` is meaningful. The side that kept
//! its count anchors the other. After an underrun the output ring restarts anyway
//! (the next write lands one lap after the DMA), so the status reader restarts at its
//! DMA position too and both counts start afresh from the snapshot (only their
//! difference matters): this works even when the status ring overran as well. After
//! a status overrun alone the output's count (`next_word` minus the queued words)
//! gives the samples taken, and the output is not disturbed. Then the timer runs
//! again. The next [`WaveOut::read_status`] reports [`StatusRead::restart`]: its
//! samples (and all later ones) start at the first word of the next write. A snapshot
//! that fails its checks (`k` not 0 or 1, CNT disagreeing, the output count unknown)
//! leaves the samples unaligned ([`WaveError::StatusUnaligned`]) until a later realignment
//! succeeds; no phase is ever guessed.
//!
//! The ticks are exact only when the timer clock divides evenly (see
//! README.md (section "Firmware") "Clock tree"); [`WaveOut::tick_hz`] reports the real rate.

use embassy_stm32::dma::{
    Channel, InterruptHandler, Priority, ReadableRingBuffer, TransferOptions, WritableRingBuffer,
};
use embassy_stm32::pac::timer::vals::Ccds;
use embassy_stm32::peripherals::{DMA2_CH1, DMA2_CH2};
use embassy_stm32::timer::low_level::{OutputCompareMode, Timer};
use embassy_stm32::timer::{AdvancedInstance4Channel, Ch1, Dma, UpDma};
use embassy_stm32::{interrupt, pac, Peri};

/// The output stream (board allocation: DMA2 stream 1, the type of `new`'s `dma`).
const OUT_STREAM: usize = 1;
/// The status sampler's stream (DMA2 stream 2, the type of its `dma`).
const STATUS_STREAM: usize = 2;
/// CPU cycles to wait after stopping the timer, so that a DMA request raised just
/// before is served (a single-word transfer takes a few AHB cycles; 200 cycles are
/// 0.4 us at 480 MHz).
const SETTLE_CYCLES: u32 = 200;
/// Snapshots tried per realignment.
const REALIGN_TRIES: usize = 3;

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
    /// The status samples' phase against the output words is not known (a
    /// realignment snapshot failed its checks; see the module docs).
    StatusUnaligned,
    /// The status sampler was asked for after the timer had been started.
    AlreadyStarted,
    /// The status ring is not a multiple of the output ring.
    StatusRingLength {
        /// Status ring length.
        status: usize,
        /// Output ring length.
        output: usize,
    },
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
            Self::StatusRingLength { status, output } => write!(
                f,
                "status ring of {status} samples is not a multiple of the {output}-word output ring"
            ),
        }
    }
}

/// DMA options for streams whose timing is the line timing: very high priority, so
/// the other streams on the same controller delay them by at most one transfer
/// (RM0433 §15.4, DMA functional description, "Arbiter").
pub fn timing_critical() -> TransferOptions {
    let mut options = TransferOptions::default();
    options.priority = Priority::VeryHigh;
    options
}

/// What [`WaveOut::read_status`] delivered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub struct StatusRead {
    /// Samples at the front of the buffer, one per tick, in time order.
    pub samples: usize,
    /// The samples were realigned since the last call (module docs): these samples
    /// and all later ones start at the first word of the next
    /// [`WaveOut::write_half`] after the realignment (none of them may be here yet).
    pub restart: bool,
}

/// The status sampler's ring and where the reader stands in the run (module docs).
struct StatusSampler<'d> {
    ring: ReadableRingBuffer<'d, u16>,
    ring_len: usize,
    /// Samples taken out of the ring so far (valid while `aligned`).
    read: u64,
    /// Number of the first sample handed out: the middle of a written word's tick.
    keep_from: u64,
    /// The phase is known.
    aligned: bool,
    /// A realignment is still to be reported.
    restart: bool,
}

/// A waveform output (and optional status sampler); plays once [`WaveOut::start`]ed.
pub struct WaveOut<'d, T: AdvancedInstance4Channel> {
    timer: Timer<'d, T>,
    ring: WritableRingBuffer<'d, u32>,
    /// Length of the output ring (words).
    ring_len: usize,
    status: Option<StatusSampler<'d>>,
    /// Number of the word the next write lands on (module docs).
    next_word: u64,
    /// `next_word` is known (false after an underrun whose realignment failed).
    words_known: bool,
    started: bool,
    tick_hz: u32,
}

impl<'d, T: AdvancedInstance4Channel> WaveOut<'d, T> {
    /// Prepares playing `ring` into `port`'s BSRR at `tick_hz` ticks per second (steps
    /// 1..5; [`WaveOut::start`] starts it). The ring is filled with `idle` first.
    /// `ring.len()` must be even (two halves).
    pub fn new(
        tim: Peri<'d, T>,
        dma: Peri<'d, DMA2_CH1>,
        irq: impl interrupt::typelevel::Binding<
                <DMA2_CH1 as embassy_stm32::dma::ChannelInstance>::Interrupt,
                InterruptHandler<DMA2_CH1>,
            > + 'd,
        port: pac::gpio::Gpio,
        ring: &'d mut [u32],
        idle: u32,
        tick_hz: u32,
    ) -> Result<Self, WaveError>
    where
        DMA2_CH1: UpDma<T>,
    {
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
        let request = UpDma::<T>::request(&*dma);
        UpDma::<T>::remap(&*dma);
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
            next_word: ring_len as u64,
            words_known: true,
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
    /// The status ring must be a multiple of the output ring (realignment, module
    /// docs).
    pub fn start_status_sampler(
        &mut self,
        dma: Peri<'d, DMA2_CH2>,
        irq: impl interrupt::typelevel::Binding<
                <DMA2_CH2 as embassy_stm32::dma::ChannelInstance>::Interrupt,
                InterruptHandler<DMA2_CH2>,
            > + 'd,
        port: pac::gpio::Gpio,
        ring: &'d mut [u16],
    ) -> Result<(), WaveError>
    where
        DMA2_CH2: Dma<T, Ch1>,
    {
        if self.started {
            return Err(WaveError::AlreadyStarted);
        }
        let ring_len = ring.len();
        if ring_len == 0 || !ring_len.is_multiple_of(self.ring_len) {
            return Err(WaveError::StatusRingLength {
                status: ring_len,
                output: self.ring_len,
            });
        }
        let regs = self.timer.regs_advanced();
        let half_tick = (regs.arr().read().arr() / 2).max(1);
        regs.ccmr_output(0)
            .modify(|w| w.set_ocm(0, OutputCompareMode::Frozen.into()));
        regs.ccr(0).write(|w| w.set_ccr(half_tick));
        regs.cr2().modify(|w| w.set_ccds(Ccds::ON_COMPARE));
        let request = Dma::<T, Ch1>::request(&*dma);
        Dma::<T, Ch1>::remap(&*dma);
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
            ring_len,
            read: 0,
            keep_from: self.next_word + 1,
            aligned: true,
            restart: false,
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
    /// On an underrun `half` is dropped, the next write lands one lap after the DMA's
    /// position and the status samples are realigned to it (module docs).
    pub async fn write_half(&mut self, half: &[u32]) -> Result<(), WaveError> {
        match self.ring.write_exact(half).await {
            Ok(_) => {
                self.next_word += half.len() as u64;
                Ok(())
            }
            Err(_) => {
                self.realign(Anchor::Fresh);
                Err(WaveError::Underrun)
            }
        }
    }

    /// Reads the status samples taken since the last call into `buf`, keeping those
    /// from the middle of the first written word's tick on (module docs): on return
    /// `buf[..samples]` holds them in time order, one per tick. `samples: 0` without
    /// a status sampler. A status ring overrun realigns (`restart`, no samples this
    /// time) or, if that fails, returns [`WaveError::StatusOverrun`] once and then
    /// [`WaveError::StatusUnaligned`] until a realignment succeeds.
    pub fn read_status(&mut self, buf: &mut [u16]) -> Result<StatusRead, WaveError> {
        let Some(st) = self.status.as_mut() else {
            return Ok(StatusRead {
                samples: 0,
                restart: false,
            });
        };
        if !st.aligned {
            // Anchored on the output's count if that is known; otherwise keep the
            // ring drained so it does not report stale overruns.
            let _ = st.ring.read(buf);
            return if self.words_known && self.realign(Anchor::Output) {
                Ok(StatusRead {
                    samples: 0,
                    restart: self.take_restart(),
                })
            } else {
                Err(WaveError::StatusUnaligned)
            };
        }
        let n = match st.ring.read(buf) {
            Ok((n, _)) => n,
            Err(_) => {
                return if self.realign(Anchor::Output) {
                    Ok(StatusRead {
                        samples: 0,
                        restart: self.take_restart(),
                    })
                } else {
                    Err(WaveError::StatusOverrun)
                };
            }
        };
        let first = st.read;
        st.read += n as u64;
        // Samples before `keep_from` are dropped; compacting in place never
        // overtakes the reader.
        let skip = usize::try_from(st.keep_from.saturating_sub(first))
            .unwrap_or(usize::MAX)
            .min(n);
        buf.copy_within(skip..n, 0);
        let restart = core::mem::take(&mut st.restart);
        Ok(StatusRead {
            samples: n - skip,
            restart,
        })
    }

    fn take_restart(&mut self) -> bool {
        self.status
            .as_mut()
            .is_some_and(|st| core::mem::take(&mut st.restart))
    }

    /// The realignment of the module docs, anchored on `anchor`'s count; the status
    /// sampler (if any) is aligned afterwards exactly when this returns true. Without
    /// a status sampler only the output ring is reset.
    fn realign(&mut self, anchor: Anchor) -> bool {
        if self.status.is_none() {
            // Nothing to align: only the output ring restarts (one lap ahead).
            self.ring.clear();
            return false;
        }
        let regs = self.timer.regs_advanced();
        let ccr = u32::from(regs.ccr(0).read().ccr());
        // A snapshot can only fail its checks by a request not yet served: a retry
        // (timer running again in between) takes a fresh one.
        let ok = (0..REALIGN_TRIES).any(|_| {
            cortex_m::interrupt::free(|_| {
                // Freeze: no request after this, a pending one served before the reads.
                regs.cr1().modify(|w| w.set_cen(false));
                cortex_m::asm::delay(SETTLE_CYCLES);
                let cnt = u32::from(regs.cnt().read().cnt());
                let ok = self.realign_frozen(anchor, cnt, ccr);
                regs.cr1().modify(|w| w.set_cen(true));
                ok
            })
        });
        if let Some(st) = self.status.as_mut() {
            st.aligned = ok;
            if ok {
                st.keep_from = self.next_word + 1;
                st.restart = true;
            }
        }
        ok
    }

    /// The counting part of [`Self::realign`], with the timer stopped.
    fn realign_frozen(&mut self, anchor: Anchor, cnt: u32, ccr: u32) -> bool {
        let out_len = self.ring_len;
        let ndtr = |stream: usize| pac::DMA2.st(stream).ndtr().read().ndt() as usize;
        let o = (out_len - ndtr(OUT_STREAM).min(out_len)) % out_len;
        let Some(st) = self.status.as_mut() else {
            return false;
        };
        let s = (st.ring_len - ndtr(STATUS_STREAM).min(st.ring_len)) % st.ring_len;
        // Samples taken minus words played; CNT after the compare <=> this period's
        // sample is taken (at CNT == CCR the order of the compare and our read is not
        // known, so only the positions decide).
        let k = (s % out_len + out_len - o) % out_len;
        let k_ok = k <= 1 && (cnt == ccr || (k == 1) == (cnt > ccr));
        let (out_len, st_len) = (out_len as u64, st.ring_len as u64);
        let (o, s, k) = (o as u64, s as u64, k as u64);
        match anchor {
            Anchor::Fresh => {
                // Both readers restart at their DMA's position; only differences
                // of the counts matter, so the words played are renumbered from
                // `next_word` on, keeping the samples taken (`played + k`) equal to
                // `s` mod the status ring (and so `played` to `o` mod the output
                // ring) for a later realignment's checks.
                self.ring.clear();
                st.ring.clear();
                let base = self.next_word;
                let target = (s + st_len - k % st_len) % st_len;
                let played = base + (target + st_len - base % st_len) % st_len;
                self.next_word = played + out_len;
                st.read = played + k;
                self.words_known = k_ok;
                k_ok
            }
            Anchor::Output => {
                // Samples taken from the words played.
                st.ring.clear();
                let Ok(free) = self.ring.len() else {
                    return false;
                };
                let queued = out_len - (free as u64).min(out_len);
                let Some(played) = self.next_word.checked_sub(queued) else {
                    return false;
                };
                let taken = played + k;
                let ok = k_ok && self.words_known && played % out_len == o && taken % st_len == s;
                if ok {
                    st.read = taken;
                }
                ok
            }
        }
    }
}

/// How a realignment counts (module docs).
#[derive(Clone, Copy)]
enum Anchor {
    /// After an output underrun: both rings restart at their DMA's position.
    Fresh,
    /// After a status ring overrun: the samples are counted from the output's words.
    Output,
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
