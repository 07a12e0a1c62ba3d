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
//! a DMAMUX request line must not feed two streams at once (RM0433 §17.4.2, DMAMUX
//! request line multiplexer: one DMAREQ_ID per active channel). TIM1's counter is
//! clocked by CLK (external clock mode 1), so neither its update nor a compare event
//! happens once per edge. The **commutation** event does: with the capture/compare
//! control bits preloaded (CR2.CCPC = 1) and CR2.CCUS = 1, every rising edge of TRGI
//! is a COM event (RM0433 §39.4.2 TIMx_CR2, CCUS; §39.3.16 "Six-step PWM
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
//! status value or a new frame phase needs writes (`tasks/ctrl_word.rs` finds the
//! phase from the SYNC pattern in the sampler halves). The writer touches only whole
//! frames at least [`GUARD`] edges ahead of the DMA ([`StatusWordOut::position`]).

use core::marker::PhantomData;

use embassy_stm32::dma::{Channel, ChannelInstance, InterruptHandler, Request, Transfer};
use embassy_stm32::gpio::Output;
use embassy_stm32::{interrupt, pac, Peri};

use super::wave_out::timing_critical;
use super::xy2_sampler::Xy2Sampler;

/// DMAMUX1 request number of TIM1_COM (RM0433 §17.3.2, next to TIM1_TRIG = 16).
const TIM1_COM_REQUEST: Request = 17;

/// Bits of a status frame.
pub const FRAME_BITS: usize = 20;

/// Edges the writer stays ahead of the DMA: 32 us at 2 MHz, far more than one frame
/// write takes; a whole-ring refill runs forward from here and never meets the DMA.
pub const GUARD: usize = 64;

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

/// The running STATUS word output.
pub struct StatusWordOut<'d> {
    transfer: Transfer<'d>,
    ring: *mut u32,
    len: usize,
    _ring: PhantomData<&'d mut [u32]>,
    _pin: Output<'d>,
}

impl<'d> StatusWordOut<'d> {
    /// Hangs the STATUS ring on `sampler`'s edges (steps 1..3). `pin` must be bit
    /// `k` of `port` for the words the caller writes; `slot` keeps the DMA channel
    /// for as long as the transfer borrows it.
    #[expect(
        clippy::too_many_arguments,
        reason = "the sampler, the stream, its interrupt and slot, the port, pin, ring and idle word"
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
    ) -> Result<Self, StatusOutError> {
        if sampler.started() {
            return Err(StatusOutError::SamplerStarted);
        }
        let sampler_len = sampler.ring_len();
        let len = ring.len();
        if len == 0 || sampler_len == 0 || len % sampler_len != 0 || len % FRAME_BITS != 0 {
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
            _ring: PhantomData,
            _pin: pin,
        })
    }

    /// Ring length in words.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Ring index of the word the next edge plays (DMA_SxNDTR counts `len` down to 1
    /// and reloads, RM0433 §15.5.6).
    pub fn position(&self) -> usize {
        let remaining = self.transfer.get_remaining_transfers() as usize;
        (self.len + self.len - remaining.min(self.len)) % self.len
    }

    /// Writes `words` (one status frame) at ring indices `start..start + 20` (mod the
    /// length). The caller keeps them [`GUARD`] edges away from [`Self::position`].
    pub fn write_frame(&mut self, start: usize, words: &[u32; FRAME_BITS]) {
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
