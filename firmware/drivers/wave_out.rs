//! Timer-paced DMA of waveform words into a GPIO port's BSRR (XY2-100 / XY3-100 out,
//! `layouts.md` §4), plus the optional status-word sampler on the same timer (XY2-100
//! STATUS in, head side).
//!
//! embassy-stm32 0.6 has no DMA-to-GPIO helper. This driver lets the timer's update
//! event request one DMA transfer per tick; embassy's [`WritableRingBuffer`] sets up
//! and runs the stream in circular mode (half-transfer and transfer-complete
//! interrupts on), and the encoder writes the next half while the DMA plays the
//! current one (double buffering), under the ring guard below (not through embassy's
//! write path, whose underrun lets the DMA replay the ring).
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
//! # No stale words (the ring guard)
//! A circular stream never stops by itself (RM0433 §15.3 "DMA functional
//! description", "Circular mode": the number of data items is reloaded at the end of
//! each lap and the requests go on being served from the first address), so a writer that stalls past the words it queued would let the DMA play
//! the ring's old batches again: positions one and two half periods old, the laser
//! gate unchanged. The decision is `shared::bridge::ring_guard` (host-tested); here
//! it runs as follows:
//! - [`RingGuardHandler`] is bound on the stream's vector beside embassy's handler
//!   and runs at P0 on the half-transfer (HTIF) and transfer-complete (TCIF)
//!   interrupts (§15.5.1 / §15.5.2, DMA_LISR / DMA_HISR: HTIF when half the items
//!   of the lap are transferred, TCIF at its end; in circular mode the stream goes
//!   on either way). It finds the boundary from NDTR (§15.5.6, DMA_SxNDTR: items
//!   left in this lap, so `ring.len() - NDTR` is the index of the next word), and: on time, sets the first
//!   `ring_guard::LEAD_WORDS` (32) of the half just played to the idle word; on a
//!   miss (the half now playing was not refilled for this lap), sets the rest of it
//!   and the whole other half to idle, drives the laser gate pin (PF13) low through
//!   GPIOF BSRR and raises the stale flag, which keeps `channels::set_laser_gate`
//!   from opening the gate until the bridge has restarted its gate rule. Every
//!   miss is counted in the guard ([`guard_misses`], the statistics' "guard
//!   misses"); the bridge looks at the count after every batch and, when it moved,
//!   restarts its gate rule and lifts the refusal only if no miss came since
//!   ([`WaveOut::clear_stale_if`], under the guard's lock: `ring_guard`, "Misses,
//!   and lifting the gate refusal"; a clear at the underrun itself left the miss
//!   at the half a late claim skips standing for good). Cost on time: a few
//!   compares and 32 stores per half.
//!   The head gets idle words (no clock edges: it holds its last position); the
//!   lead covers the guard's latency (32 words are 4 us at 8 MHz ticks), so not even
//!   the first word of an old batch plays.
//! - [`WaveOut::write_half`] writes exactly one half: it claims the half after the
//!   one the DMA plays while at least `COPY_MARGIN_US` (20 us) of the playing half
//!   are left, copies with BASEPRI raised to mask everything below P0 (a stall of
//!   the executors cannot leave a half copied in part in front of the DMA), and
//!   marks it filled. Late, it drops the batch and reports
//!   [`WaveError::Underrun`]; the next write goes to the first half still ahead of
//!   the DMA, so the head gets fresh words again one to two half periods after the
//!   writer runs again. In direct mode (no FIFO; §15.3, "FIFO", direct mode) a
//!   memory-to-peripheral stream preloads one item ahead of its request, so a word
//!   written two or more ahead of the DMA position is the word played: the lead
//!   (32) and the margin are far beyond that.
//!
//! Bound: the gate goes off and the idle words start at the first boundary after the
//! last refilled half, i.e. within two half periods of a stall's start (one, if the
//! stall began after the writer had refilled), plus the guard's latency (< 1 us).
//! What it assumes: the P0 handlers together never delay the guard by more than the
//! lead nor the copy by more than the margin (they are microseconds long by design).
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
//! # Restart after an underrun, realignment after a status overrun
//! After an output underrun the word count stays exact (the guard counts halves
//! absolutely): the next write goes to a known half, and the status samples restart
//! at its first word ([`StatusRead::restart`]) without a snapshot. A status ring
//! overrun loses the reader's count: the driver takes **one consistent snapshot** of
//! both streams and the timer:
//! CR1.CEN = 0 stops the requests (the lines hold their levels for well under a
//! microsecond, interrupts masked), a short wait lets the DMA serve a request already
//! raised, then both NDTRs (RM0433 §15.5.6) and CNT are read, nothing moving. With
//! `o` the output ring index of the next word and `s` the status ring index of the
//! next sample, the samples taken exceed the words played by `k = (s - o) mod
//! out_len`, which must be 0 (CNT before the compare) or 1 (after it, CNT >= CCR1:
//! the sample of this period is taken, its word not yet played); the status ring is a
//! multiple of the output ring so `s mod out_len` is meaningful. The words played
//! are the guard's half count and `o` (the next half if the DMA crossed a boundary
//! whose interrupt is still pending, masked by the snapshot), so the samples taken
//! are `played + k`, checked against `s`; the output is not disturbed. Then the timer runs
//! again. The next [`WaveOut::read_status`] reports [`StatusRead::restart`]: its
//! samples (and all later ones) start at the first word of the next write. A snapshot
//! that fails its checks (`k` not 0 or 1, CNT disagreeing, the counts disagreeing)
//! leaves the samples unaligned ([`WaveError::StatusUnaligned`]) until a later realignment
//! succeeds; no phase is ever guessed.
//!
//! The ticks are exact only when the timer clock divides evenly (see
//! README.md (section "Firmware") "Clock tree"); [`WaveOut::tick_hz`] reports the real rate.

use core::cell::RefCell;
use core::future::poll_fn;
use core::sync::atomic::{compiler_fence, Ordering};
use core::task::Poll;

use embassy_stm32::dma::{
    Channel, InterruptHandler, Priority, ReadableRingBuffer, TransferOptions, WritableRingBuffer,
};
use embassy_stm32::pac::timer::vals::Ccds;
use embassy_stm32::peripherals::{DMA2_CH1, DMA2_CH2};
use embassy_stm32::timer::low_level::{OutputCompareMode, Timer};
use embassy_stm32::timer::{AdvancedInstance4Channel, Ch1, Dma, UpDma};
use embassy_stm32::{interrupt, pac, Peri};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::waitqueue::AtomicWaker;
use shared::bridge::ring_guard::{Claim, Fill, RingGuard, LEAD_WORDS};

use crate::channels::{clear_output_stale, output_stale_gate_off};
use crate::drivers::ring_index;

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
/// Time a claimed half's copy may take at most, interrupts of the guard's priority
/// included (module docs, "No stale words"): 1000 words copy in ~2..4 us.
const COPY_MARGIN_US: u32 = 20;
/// BASEPRI while a half is copied: masks every priority from 1 down (the
/// executors, the HIL tests' stall at P5), leaves P0 (DMA, EXTI, the time driver,
/// the guard). The H743 has 4 priority bits, in the high nibble.
const BASEPRI_COPY: u8 = 1 << 4;

/// What the guard interrupt needs: the [`RingGuard`] and the ring it blanks.
struct Guarded {
    guard: RingGuard,
    /// Ring address (0: no output running, the guard does nothing).
    ring: usize,
    /// Words per half.
    half: usize,
    /// The idle word.
    idle: u32,
}

/// The one output's guard state (the stream is DMA2 stream 1, so there is one).
static GUARD: Mutex<CriticalSectionRawMutex, RefCell<Guarded>> =
    Mutex::new(RefCell::new(Guarded {
        guard: RingGuard::new(),
        ring: 0,
        half: 0,
        idle: 0,
    }));
/// Woken by the guard at every boundary: the writer's next half may be free.
static BOUNDARY: AtomicWaker = AtomicWaker::new();
/// The output ring guard (module docs, "No stale words"): bound on DMA2 stream 1
/// beside embassy's handler (`tasks::Irqs`), it runs at every half-transfer and
/// transfer-complete interrupt of the output stream, at P0.
pub struct RingGuardHandler;

impl interrupt::typelevel::Handler<interrupt::typelevel::DMA2_STREAM1> for RingGuardHandler {
    unsafe fn on_interrupt() {
        on_boundary();
    }
}

/// Sets `ring[from..to]` to `idle`.
///
/// # Safety
/// `ring` is the running output ring's address, `to` at most its length.
unsafe fn blank(ring: usize, from: usize, to: usize, idle: u32) {
    let p = ring as *mut u32;
    for i in from..to {
        // SAFETY: in the ring (caller); the DMA only reads it.
        unsafe { core::ptr::write_volatile(p.add(i), idle) };
    }
}

/// The guard's work at a boundary (module docs, "No stale words").
fn on_boundary() {
    let mut blanks = [(0usize, 0usize); 3];
    let (ring, idle) = GUARD.lock(|g| {
        let mut g = g.borrow_mut();
        let half = g.half;
        if g.ring == 0 || half == 0 {
            return (0, 0);
        }
        let pos = out_position(2 * half);
        if pos / half == (g.guard.playing() % 2) as usize {
            // No boundary since the last call (an interrupt of another flag).
            return (0, 0);
        }
        let a = g.guard.boundary();
        let lead = LEAD_WORDS.min(half);
        let at = |s: usize| s * half;
        if let Some(s) = a.blank_lead {
            blanks[0] = (at(s), at(s) + lead);
        }
        if let Some(s) = a.blank_rest {
            // The lead went idle when the DMA left this half; words behind the DMA
            // are harmless to overwrite, so no position is needed.
            blanks[1] = (at(s) + lead, at(s) + half);
        }
        if let Some(s) = a.blank_all {
            blanks[2] = (at(s), at(s) + half);
        }
        if a.gate_off {
            // Straight to the pin, then the flag the gate-on path checks; under the
            // lock with the miss count, so a writer's `clear_stale_if` sees both or
            // neither.
            output_stale_gate_off();
        }
        (g.ring, g.idle)
    });
    if ring == 0 {
        return;
    }
    // Outside the lock: the writer runs below this priority, so nothing else writes
    // the ring now; the blanks outrun the DMA (a store per cycle or two against a
    // word per 30..60 cycles).
    for (from, to) in blanks {
        // SAFETY: ranges within the two halves of the running ring.
        unsafe { blank(ring, from, to, idle) };
    }
    compiler_fence(Ordering::Release);
    BOUNDARY.wake();
}

/// The ring guard's misses since boot (wrapping; halves the DMA entered that the
/// bridge had not refilled for this lap, each one a gate drop): the statistics'
/// "guard misses", also for the hardware-in-the-loop tests. It counts over every
/// output run (`RingGuard::restart`).
pub fn guard_misses() -> u32 {
    GUARD.lock(|g| g.borrow().guard.missed())
}

/// The output DMA's ring index (0..len) of the next word it fetches.
fn out_position(len: usize) -> usize {
    ring_index(pac::DMA2.st(OUT_STREAM).ndtr().read().ndt() as usize, len)
}

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
    /// The writer missed a half: the DMA entered it unfilled (it played idle words,
    /// the laser gate went off) or was about to; the batch is dropped and the
    /// encoder must resynchronise (module docs, "No stale words").
    Underrun,
    /// A batch that is not exactly half the ring.
    BatchLength {
        /// Words given.
        words: usize,
        /// Words per half.
        half: usize,
    },
    /// The status sampler's ring was overwritten before it was read.
    StatusOverrun,
    /// The status samples' phase against the output words is not known (a
    /// realignment snapshot failed its checks; see the module docs).
    StatusUnaligned,
    /// The status sampler was asked for after the timer had been started.
    AlreadyStarted,
    /// The output ring is empty or of odd length (two halves are needed).
    RingLength(usize),
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
            Self::BatchLength { words, half } => {
                write!(f, "batch of {words} words for a {half}-word ring half")
            }
            Self::StatusOverrun => f.write_str("status sample ring overrun"),
            Self::StatusUnaligned => f.write_str("status samples no longer aligned to the output"),
            Self::RingLength(n) => write!(f, "output ring of {n} words is not two halves"),
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
    /// Owns the running stream (configured and started by embassy, stopped on
    /// drop); its own write path is not used: the writer copies through
    /// `ring_addr` under the guard's claims (module docs, "No stale words").
    _stream: WritableRingBuffer<'d, u32>,
    /// Address of the output ring.
    ring_addr: usize,
    /// Length of the output ring (words).
    ring_len: usize,
    status: Option<StatusSampler<'d>>,
    /// The half the next write goes to (absolute, [`RingGuard`] numbering).
    next_half: u64,
    /// Number of the word the next write lands on (module docs): `next_half`
    /// halves.
    next_word: u64,
    started: bool,
    tick_hz: u32,
}

impl<'d, T: AdvancedInstance4Channel> WaveOut<'d, T> {
    /// Prepares playing `ring` into `port`'s BSRR at `tick_hz` ticks per second (steps
    /// 1..5; [`WaveOut::start`] starts it). The ring is filled with `idle` first.
    /// `ring.len()` must be even (two halves), and every [`WaveOut::write_half`]
    /// writes exactly one half. `irq` binds embassy's handler and the
    /// [`RingGuardHandler`] on the stream's vector.
    pub fn new(
        tim: Peri<'d, T>,
        dma: Peri<'d, DMA2_CH1>,
        irq: impl interrupt::typelevel::Binding<
                <DMA2_CH1 as embassy_stm32::dma::ChannelInstance>::Interrupt,
                InterruptHandler<DMA2_CH1>,
            > + interrupt::typelevel::Binding<
                <DMA2_CH1 as embassy_stm32::dma::ChannelInstance>::Interrupt,
                RingGuardHandler,
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
        let ring_len = ring.len();
        if ring_len == 0 || !ring_len.is_multiple_of(2) {
            return Err(WaveError::RingLength(ring_len));
        }
        ring.fill(idle);
        let ring_addr = ring.as_mut_ptr() as usize;

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

        // The guard knows the ring before the stream can interrupt; the DMA starts at
        // index 0, half 0 of the run.
        // A new run: the miss count goes on (statistics); no miss of an earlier
        // output stands against this one's gate rule.
        GUARD.lock(|g| {
            let mut g = g.borrow_mut();
            g.guard.restart();
            g.ring = ring_addr;
            g.half = ring_len / 2;
            g.idle = idle;
            clear_output_stale();
        });
        // The stream waits for requests: none come before step 7.
        ring.start();
        // Step 5.
        regs.dier().modify(|w| w.set_ude(true));
        Ok(Self {
            timer,
            _stream: ring,
            ring_addr,
            ring_len,
            status: None,
            next_half: 2,
            next_word: ring_len as u64,
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

    /// Waits until the guard grants the next half of the ring and writes `half`
    /// (exactly half the ring) into it (module docs, "No stale words"). If the writer
    /// came too late for that half (the DMA plays it, idle, or is about to) `half`
    /// is dropped, [`WaveError::Underrun`] is returned, and the next write goes to
    /// the first half still ahead of the DMA; the status samples then restart at it
    /// ([`StatusRead::restart`]). After every write (also an underrun) the caller
    /// looks at [`WaveOut::guard_misses`] and, when it moved, restarts its laser gate
    /// rule and calls [`WaveOut::clear_stale_if`].
    pub async fn write_half(&mut self, half: &[u32]) -> Result<(), WaveError> {
        let len = self.ring_len / 2;
        if half.len() != len {
            return Err(WaveError::BatchLength {
                words: half.len(),
                half: len,
            });
        }
        let margin = (u64::from(self.tick_hz) * u64::from(COPY_MARGIN_US) / 1_000_000) as usize;
        let n = self.next_half;
        let ring_len = self.ring_len;
        let claim = poll_fn(|cx| {
            BOUNDARY.register(cx.waker());
            let c = GUARD.lock(|g| {
                let pos = out_position(ring_len);
                g.borrow_mut()
                    .guard
                    .claim(n, pos / len, len - pos % len, margin)
            });
            match c {
                Claim::Wait => Poll::Pending,
                c => Poll::Ready(c),
            }
        })
        .await;
        if let Claim::Late { next } = claim {
            self.restart_at(next);
            return Err(WaveError::Underrun);
        }
        let base = (n % 2) as usize * len;
        let ring = self.ring_addr as *mut u32;
        // Only the guard (P0) may run during the copy: a stall below it cannot leave
        // a half copied in part in front of the DMA.
        let old = cortex_m::register::basepri::read();
        cortex_m::register::basepri_max::write(BASEPRI_COPY);
        // SAFETY: `base + len` is within the ring (two halves of `len`); the guard
        // granted this half, so the DMA does not fetch from it before the copy ends
        // (unless `fill` says otherwise, handled below).
        unsafe { core::ptr::copy_nonoverlapping(half.as_ptr(), ring.add(base), len) };
        compiler_fence(Ordering::Release);
        let (fill, idle) = GUARD.lock(|g| {
            let mut g = g.borrow_mut();
            (g.guard.fill(n), g.idle)
        });
        if fill == Fill::Torn {
            // The DMA entered the half during the copy (a stall at P0 longer than the
            // margin): idle again, so no more of it plays.
            // SAFETY: the half is within the ring.
            unsafe { blank(self.ring_addr, base, base + len, idle) };
        }
        // SAFETY: restores the caller's BASEPRI.
        unsafe { cortex_m::register::basepri::write(old) };
        if fill == Fill::Torn {
            self.restart_at(n + 1);
            return Err(WaveError::Underrun);
        }
        self.next_half = n + 1;
        self.next_word = self.next_half * len as u64;
        Ok(())
    }

    /// The guard's misses so far ([`guard_misses`]): when this changes, restart the
    /// laser gate rule, then [`WaveOut::clear_stale_if`] with the new count.
    pub fn guard_misses(&self) -> u32 {
        guard_misses()
    }

    /// Lifts the guard's gate refusal (`channels::laser_gate_allowed`) unless the
    /// guard has missed again since `seen`, the count the caller restarted its gate
    /// rule for (checked under the guard's lock: a newer miss keeps the refusal for
    /// the caller's next look; module docs, "No stale words").
    pub fn clear_stale_if(&mut self, seen: u32) {
        GUARD.lock(|g| {
            if g.borrow().guard.clear_if(seen) {
                clear_output_stale();
            }
        });
    }

    /// After an underrun: the next write goes to half `next`; the status samples
    /// restart at its first word.
    fn restart_at(&mut self, next: u64) {
        self.next_half = next;
        self.next_word = next * (self.ring_len / 2) as u64;
        if let Some(st) = self.status.as_mut() {
            st.keep_from = self.next_word + 1;
            st.restart = true;
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
            return if self.realign() {
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
                return if self.realign() {
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

    /// The realignment of the module docs after a status ring overrun: the samples
    /// taken are counted from the words played; the status sampler is aligned
    /// afterwards exactly when this returns true.
    fn realign(&mut self) -> bool {
        if self.status.is_none() {
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
                let ok = self.realign_frozen(cnt, ccr);
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

    /// The counting part of [`Self::realign`], with the timer stopped and
    /// interrupts masked.
    fn realign_frozen(&mut self, cnt: u32, ccr: u32) -> bool {
        let out_len = self.ring_len;
        let half = out_len / 2;
        let o = out_position(out_len);
        // Words played, absolutely: the guard's half, or the next one if the DMA
        // crossed a boundary whose interrupt is still pending (masked here; never
        // two: the guard runs within microseconds of each).
        let playing = GUARD.lock(|g| g.borrow().guard.playing());
        let in_half = (o / half) as u64;
        let playing = if in_half == playing % 2 {
            playing
        } else {
            playing + 1
        };
        let played = playing * half as u64 + (o % half) as u64;
        let Some(st) = self.status.as_mut() else {
            return false;
        };
        let s = ring_index(
            pac::DMA2.st(STATUS_STREAM).ndtr().read().ndt() as usize,
            st.ring_len,
        );
        // Samples taken minus words played; CNT after the compare <=> this period's
        // sample is taken (at CNT == CCR the order of the compare and our read is not
        // known, so only the positions decide).
        let k = (s % out_len + out_len - o) % out_len;
        let k_ok = k <= 1 && (cnt == ccr || (k == 1) == (cnt > ccr));
        st.ring.clear();
        let taken = played + k as u64;
        let ok = k_ok && taken % st.ring_len as u64 == s as u64;
        if ok {
            st.read = taken;
        }
        ok
    }
}

impl<T: AdvancedInstance4Channel> Drop for WaveOut<'_, T> {
    fn drop(&mut self) {
        // The guard lets go of the ring first (it is no longer the output's).
        GUARD.lock(|g| g.borrow_mut().ring = 0);
        // Stop the requests first; the ring buffers then stop their streams.
        self.timer.stop();
        self.timer.regs_advanced().dier().modify(|w| {
            w.set_ude(false);
            w.set_ccde(0, false);
        });
    }
}
