//! XY2-100 STATUS word towards the controller (`layouts.md` §7, word form;
//! `shared::xy2::status_line`, "Outputs"): a circular ring of BSRR words for the
//! STATUS pin, one word per falling edge of the **controller's** CLK, played by a
//! second DMA stream on the same TIM1 that samples the XY2 input ([`Xy2Sampler`]).
//! The bridge's 20-bit status frame goes out MSB first, one bit per clock, changing
//! just after the falling edge (half a bit after the controller's data changed), as a
//! head does; the controller reads it on its next falling edge.
//!
//! # Two DMA requests from one edge
//! The sampler already uses TIM1's trigger request (DIER.TDE, DMAMUX1 input 16), and
//! a DMAMUX request line must not feed two streams at once (RM0433 §17, DMAMUX
//! request line multiplexer: the same DMAREQ_ID must not be programmed into two
//! channels that are active together). TIM1's counter is
//! clocked by CLK (external clock mode 1), so neither its update nor a compare event
//! happens once per edge. The **commutation** event does: with the capture/compare
//! control bits preloaded (CR2.CCPC = 1) and CR2.CCUS = 1, every rising edge of TRGI
//! is a COM event (RM0433 §38.4, TIMx_CR2 bits CCPC and CCUS; §38.3, "Six-step PWM
//! generation"), and DIER.COMDE turns it into a DMA request (DMAMUX1 input 17,
//! TIM1_COM, §17.3.2). TRGI is ETRF after the ETP inversion, i.e. the falling CLK
//! edge, the same edge the sampler's trigger request fires on. TIM1 drives no output
//! (every CCxE = 0, BDTR.MOE = 0), so preloading its output-control bits changes
//! nothing else.
//!
//! Register sequence (after [`Xy2Sampler::prepare`], before [`Xy2Sampler::start`]):
//! 1. The STATUS pin is a push-pull GPIO output (the caller's `Output`); the ring is
//!    filled with the caller's idle word.
//! 2. DMA stream: memory -> GPIOx_BSRR (32-bit, §11.4.7: a set and a reset half, so
//!    only the STATUS pin changes), circular, very high priority, request TIM1_COM.
//! 3. TIM1 CR2: CCPC = 1, CCUS = 1; DIER: COMDE = 1.
//! 4. The sampler's `start` sets CEN: edge `n` (0-based) samples into sampler index
//!    `n mod sampler_len` and plays status index `n mod ring_len`.
//!
//! # Ring length and frame alignment
//! The ring length is a multiple of the sampler ring's and of 20 (a status frame). So
//! the sampler index of an edge is its status index mod the sampler length, and a
//! ring filled with back-to-back frames keeps its phase lap after lap: only a new
//! status value or a new frame phase needs writes. [`StatusWordOut::refresh`] runs
//! after every sampler half:
//! * **Phase**: the newest well-formed frame end in the half (SYNC high for exactly
//!   19 samples, then low: `shared::xy2::rx`'s framing) is the edge on which the
//!   status frame's first bit (bit 19) is written; the controller reads it one edge
//!   later, with the first bit of its next frame (bridge-sim's `status_word_signal`
//!   does the same). Its status index is the DMA's position minus the edges since
//!   that sample. A half whose ring position is unknown (a sampler overrun that could
//!   not be resynchronised) or that is more than half a sampler ring old keeps the
//!   last phase.
//! * **Writes**: only when the frame or the phase changed: a sweep writes every whole
//!   frame from [`GUARD`] edges ahead of the DMA up to where it would lap, so a frame
//!   is never changed while it may be playing; a second sweep at least
//!   [`SWEEP_APART`] edges later writes the frames the first one left out.
//!
//! Frames sent while the phase changes (the controller paused mid-frame, or runs its
//! clock between frames: the phase then moves every frame) are broken; the
//! controller's own check on the status frame rejects them.

use core::marker::PhantomData;

use embassy_stm32::dma::{Channel, ChannelInstance, InterruptHandler, Request, Transfer};
use embassy_stm32::gpio::Output;
use embassy_stm32::{interrupt, pac, Peri};

use super::ring_index;
use super::wave_out::timing_critical;
use super::xy2_sampler::Xy2Sampler;

/// DMAMUX1 request number of TIM1_COM (RM0433 §17.3.2, next to TIM1_TRIG = 16).
const TIM1_COM_REQUEST: Request = 17;

/// Bits of a status frame.
pub const FRAME_BITS: usize = 20;

/// Edges the writer stays ahead of the DMA: 32 us at 2 MHz, far more than a sweep
/// takes to get past the first frames; a sweep runs forward from here and never meets
/// the DMA.
pub const GUARD: usize = 64;
/// Edges between the two sweeps after a change, so that the frames the first one
/// left out (near the DMA) are out of the second one's guard.
pub const SWEEP_APART: usize = GUARD + 2 * FRAME_BITS;
/// Sweeps after a change.
const SWEEPS: u8 = 2;
/// High SYNC samples of a well-formed frame.
const SYNC_HIGH: usize = 19;

/// Why the status word output cannot run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum StatusOutError {
    /// The sampler already counts edges: the two streams would not count from the
    /// same first edge.
    SamplerStarted,
    /// The ring length is not a multiple of the sampler ring and of 20 words.
    RingLength {
        /// Status ring length.
        len: usize,
        /// Sampler ring length.
        sampler: usize,
    },
}

impl core::fmt::Display for StatusOutError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::SamplerStarted => f.write_str("status word output must start before the sampler"),
            Self::RingLength { len, sampler } => write!(
                f,
                "status ring of {len} words is not a multiple of the {sampler}-sample ring and of 20"
            ),
        }
    }
}

/// What the ring is being brought to: the frame words and the phase (status ring
/// index mod 20 of a frame's first bit).
#[derive(Clone, Copy, PartialEq, Eq)]
struct Content {
    words: [u32; FRAME_BITS],
    phase: usize,
}

/// The running STATUS word output.
pub struct StatusWordOut<'d> {
    transfer: Transfer<'d>,
    ring: *mut u32,
    len: usize,
    sampler_len: usize,
    sync_mask: u16,
    /// Phase of the controller's frames (status ring index mod 20), once found.
    phase: Option<usize>,
    content: Option<Content>,
    /// Sweeps still due for `content`, and the DMA position at the last one.
    sweeps_due: u8,
    last_sweep: usize,
    _ring: PhantomData<&'d mut [u32]>,
    _pin: Output<'d>,
}

impl<'d> StatusWordOut<'d> {
    /// Hangs the STATUS ring on `sampler`'s edges (steps 1..3). `pin` must be the
    /// port bit the caller's frame words drive; `sync` is the SYNC bit in the
    /// sampler's port samples; `slot` keeps the DMA channel for as long as the
    /// transfer borrows it.
    #[expect(
        clippy::too_many_arguments,
        reason = "the sampler, the stream, its interrupt and slot, the port, pin, ring, idle word, SYNC bit"
    )]
    pub fn new<D: ChannelInstance>(
        sampler: &mut Xy2Sampler<'d>,
        dma: Peri<'d, D>,
        irq: impl interrupt::typelevel::Binding<D::Interrupt, InterruptHandler<D>> + 'd,
        slot: &'d mut Option<Channel<'d>>,
        port: pac::gpio::Gpio,
        pin: Output<'d>,
        ring: &'d mut [u32],
        idle: u32,
        sync: u8,
    ) -> Result<Self, StatusOutError> {
        if sampler.started() {
            return Err(StatusOutError::SamplerStarted);
        }
        let sampler_len = sampler.ring_len();
        let len = ring.len();
        if len == 0
            || sampler_len == 0
            || !len.is_multiple_of(sampler_len)
            || !len.is_multiple_of(FRAME_BITS)
        {
            return Err(StatusOutError::RingLength {
                len,
                sampler: sampler_len,
            });
        }
        // Step 1.
        ring.fill(idle);
        // Step 2.
        let channel = slot.insert(Channel::new(dma, irq));
        let ring: *mut [u32] = ring;
        let mut options = timing_critical();
        options.circular = true;
        // SAFETY: BSRR is a valid 32-bit write-only register of a port that exists
        // forever; the ring is borrowed for 'd (PhantomData) and from now on written
        // only through `write_frame`, whole frames away from the DMA's read position
        // (module docs), so the DMA never reads a word while it is being written.
        let transfer = unsafe {
            channel.write_raw(
                TIM1_COM_REQUEST,
                ring as *const [u32],
                port.bsrr().as_ptr() as *mut u32,
                options,
            )
        };
        // Step 3.
        let regs = sampler.regs();
        regs.cr2().modify(|w| {
            w.set_ccpc(true);
            w.set_ccus(true);
        });
        regs.dier().modify(|w| w.set_comde(true));
        Ok(Self {
            transfer,
            ring: ring as *mut u32,
            len,
            sampler_len,
            sync_mask: 1u16.checked_shl(u32::from(sync)).unwrap_or(0),
            phase: None,
            content: None,
            sweeps_due: 0,
            last_sweep: 0,
            _ring: PhantomData,
            _pin: pin,
        })
    }

    /// The frame phase found so far (status ring index mod 20 of a frame's first
    /// bit), `None` before the first well-formed frame.
    pub fn phase(&self) -> Option<usize> {
        self.phase
    }

    /// Ring index of the word the next edge plays (DMA_SxNDTR counts `len` down to 1
    /// and reloads, RM0433 §15.5.6).
    pub fn position(&self) -> usize {
        ring_index(self.transfer.get_remaining_transfers() as usize, self.len)
    }

    /// After a sampler half (`half`, starting at sampler ring index `start`, `None`
    /// if unknown): follows the controller's frame phase and brings the ring to
    /// back-to-back copies of `words`, the BSRR words of one status frame, bit 19
    /// first (`shared::xy2::status_line::StatusOut::word_frame`); module docs.
    pub fn refresh(&mut self, half: &[u16], start: Option<usize>, words: &[u32; FRAME_BITS]) {
        let p = self.position();
        if let (Some(start), Some(end)) = (start, self.frame_end(half)) {
            // Edges since the half's last sample and since the frame end; both are
            // below a sampler ring while the half is fresh.
            let sl = self.sampler_len;
            let half_end = (start + half.len()) % sl;
            let since_half = (p + sl - half_end) % sl;
            if since_half < sl / 2 {
                let since_end = since_half + half.len() - end;
                self.phase = Some((p + self.len - since_end % self.len) % FRAME_BITS);
            }
        }
        let Some(phase) = self.phase else { return };
        let want = Content {
            words: *words,
            phase,
        };
        if self.content != Some(want) {
            self.content = Some(want);
            self.sweeps_due = SWEEPS;
        }
        let apart = (p + self.len - self.last_sweep) % self.len;
        if self.sweeps_due == SWEEPS || (self.sweeps_due > 0 && apart >= SWEEP_APART) {
            self.sweep(want, p);
            self.last_sweep = p;
            self.sweeps_due -= 1;
        }
    }

    /// Index in `half` of the newest well-formed frame end (SYNC low after exactly
    /// 19 high samples that follow a low one), scanning back from the end.
    fn frame_end(&self, half: &[u16]) -> Option<usize> {
        let high = |i: usize| half.get(i).is_some_and(|s| s & self.sync_mask != 0);
        (SYNC_HIGH + 1..half.len())
            .rev()
            .find(|&i| !high(i) && !high(i - SYNC_HIGH - 1) && (i - SYNC_HIGH..i).all(high))
    }

    /// Writes `c` into every whole frame slot from [`GUARD`] edges ahead of the DMA
    /// (at `p`) up to where it would lap.
    fn sweep(&mut self, c: Content, p: usize) {
        // Offsets from `p`; the first frame start at or after GUARD.
        let mut k = GUARD + (c.phase + FRAME_BITS - (p + GUARD) % FRAME_BITS) % FRAME_BITS;
        while k + FRAME_BITS <= self.len {
            self.write_frame((p + k) % self.len, &c.words);
            k += FRAME_BITS;
        }
    }

    /// Writes one status frame at ring indices `start..start + 20` (mod the length).
    fn write_frame(&mut self, start: usize, words: &[u32; FRAME_BITS]) {
        for (k, &w) in words.iter().enumerate() {
            let i = (start + k) % self.len;
            // SAFETY: `i < len`, inside the ring borrowed for 'd; `&mut self` is the
            // only CPU access; a volatile store, since the DMA reads the ring too.
            unsafe { self.ring.add(i).write_volatile(w) };
        }
    }
}

impl Drop for StatusWordOut<'_> {
    fn drop(&mut self) {
        // The COM requests stop with the sampler's timer; the transfer's own drop
        // stops the stream.
        pac::TIM1.dier().modify(|w| w.set_comde(false));
    }
}
