//! Circular 12.5 MHz serial transmit of a `[u8; 125]` ring (HANS-100 out on the head
//! side, HANS STATUS out on the controller side; `layouts.md` §5) on an SAI block.
//!
//! All six SPIs are receivers (README.md (section "Firmware") allocation), so the bit streams go
//! out of SAI blocks in free-protocol mode: 8-bit slots filling 8-bit frames make the
//! SD line one continuous MSB-first stream (FS and SCK are not routed to a pin).
//! The ring is never re-queued: the DMA stream replays it forever, and the bridge
//! updates one 125-bit slot in place ([`SerialTx::update`]) two slots ahead of the
//! one being sent ([`SerialTx::sending_slot`]).
//!
//! Register sequence (RM0433 §51 "Serial audio interface"):
//! 1. Kernel + bus clock on, reset (RCC §8; SAI kernel = PLL2_P 100 MHz, board.rs),
//!    unless the SAI's other sub-block runs (both share the enable and the reset).
//! 2. CR1 with SAIEN = 0: MODE = master transmitter, PRTCFG = free protocol,
//!    DS = 8 bits, LSBFIRST = 0 (MSB first), CKSTR = 0 (the pac calls it
//!    FALLING_EDGE, the sampling edge: our data changes on the rising SCK edge, so a
//!    receiver clocked by SCK -- the HIL test's SPI slave -- samples it on the falling
//!    edge; the head itself oversamples and never sees SCK), SYNCEN = asynchronous, OUTDRIV = 1 (SD driven as soon as SAIEN, so the line
//!    idles at the first bit instead of floating), NODIV = 1 and MCKDIV = 8:
//!    f_SCK = f_sai_ker_ck / MCKDIV = 100 MHz / 8 = 12.5 MHz (§51.4.8 clock
//!    generator, "clock generator programming when NODIV = 1"; FRL + 1 may then be
//!    any value from 8 to 256).
//! 3. FRCR: FRL = 7 (8-bit frame), FSALL = 0, FSDEF = 0, FSOFF = 0 (FS is unused).
//!    SLOTR: SLOTSZ = data size, NBSLOT = 0 (one slot), SLOTEN = slot 0 (§51.4.10).
//!    Every SCK cycle then carries a data bit: no gaps between bytes.
//! 4. CR2: FTH = half FIFO; CR1.DMAEN = 1 (§51.4.15).
//! 5. DMA stream memory -> SAI_xDR, bytes, circular, started; then SAIEN = 1.
//!
//! Position: DMA_SxNDTR counts the bytes the stream has still to fetch in this lap
//! (RM0433 §15.5.6). The SAI FIFO (8 words) plus the shift register hold up to 9
//! bytes between the DMA position and the wire, i.e. less than one 125-bit slot: the
//! slot two ahead of the DMA position is never on the wire or in the FIFO.

use core::marker::PhantomData;

use embassy_stm32::dma::{Channel, InterruptHandler, Transfer, TransferOptions};
use embassy_stm32::gpio::{AfType, Flex, OutputType, Speed};
use embassy_stm32::pac::sai::vals::{
    Ckstr, Ds, Fth, Lsbfirst, Mckdiv, Mode, Outdriv, Prtcfg, Sloten, Slotsz, Syncen,
};
use embassy_stm32::sai::{Dma, SdPin, SubBlockInstance};
use embassy_stm32::{interrupt, pac, peripherals, rcc, Peri};
use shared::hans::frame::{write_slot, DecodeError, Frame, RING_BYTES, RING_SLOTS};
use shared::hans::tx::LEAD_SLOTS;

/// An SAI instance this driver can run.
pub trait Instance: embassy_stm32::sai::Instance {
    /// Register block.
    const REGS: pac::sai::Sai;
    /// Whether the SAI's clock enable is set (RCC_APB2ENR, RM0433 §8 "Reset and
    /// clock control"): only then do its registers read back.
    fn clock_on() -> bool;
}
impl Instance for peripherals::SAI1 {
    const REGS: pac::sai::Sai = pac::SAI1;
    fn clock_on() -> bool {
        pac::RCC.apb2enr().read().sai1en()
    }
}
impl Instance for peripherals::SAI2 {
    const REGS: pac::sai::Sai = pac::SAI2;
    fn clock_on() -> bool {
        pac::RCC.apb2enr().read().sai2en()
    }
}

/// Sub-block A or B with its register index.
pub trait SubBlock: SubBlockInstance {
    /// Index into `Sai::ch`.
    const INDEX: usize;
}
impl SubBlock for embassy_stm32::sai::A {
    const INDEX: usize = 0;
}
impl SubBlock for embassy_stm32::sai::B {
    const INDEX: usize = 1;
}

/// A running circular serial transmitter.
pub struct SerialTx<'a> {
    ch: pac::sai::Ch,
    transfer: Transfer<'a>,
    ring: *mut [u8; RING_BYTES],
    _ring: PhantomData<&'a mut [u8; RING_BYTES]>,
    _sd: Flex<'a>,
}

impl<'a> SerialTx<'a> {
    /// Starts sending `ring` in a loop on sub-block `S` of `T`, after the caller has
    /// filled it with idle frames. `slot` holds the DMA channel for as long as the
    /// running transfer borrows it (the caller keeps it, e.g. on its task's stack).
    pub fn new<T: Instance, S: SubBlock, D: Dma<T, S>>(
        _sai: Peri<'a, T>,
        sd: Peri<'a, impl SdPin<T, S>>,
        dma: Peri<'a, D>,
        irq: impl interrupt::typelevel::Binding<D::Interrupt, InterruptHandler<D>> + 'a,
        slot: &'a mut Option<Channel<'a>>,
        ring: &'a mut [u8; RING_BYTES],
    ) -> Self {
        let af = sd.af_num();
        let mut sd = Flex::new(sd);
        sd.set_as_af_unchecked(af, AfType::output(OutputType::PushPull, Speed::VeryHigh));

        // Step 1. The two sub-blocks share the SAI's clock enable and reset (RCC;
        // embassy keeps no count for SAIs): a block started beside a running one
        // keeps it running and skips the reset, which would stop it. The firmware
        // never runs both blocks of one SAI; the HIL tests play their sources on
        // the block the firmware leaves free.
        let other = T::REGS.ch(1 - S::INDEX);
        if !(T::clock_on() && other.cr1().read().saien()) {
            rcc::enable_and_reset::<T>();
        }
        let ch = T::REGS.ch(S::INDEX);
        // Step 2.
        ch.cr1().modify(|w| {
            w.set_saien(false);
            w.set_mode(Mode::MASTER_TX);
            w.set_prtcfg(Prtcfg::FREE);
            w.set_ds(Ds::BIT8);
            w.set_lsbfirst(Lsbfirst::MSB_FIRST);
            w.set_ckstr(Ckstr::FALLING_EDGE);
            w.set_syncen(Syncen::ASYNCHRONOUS);
            w.set_outdriv(Outdriv::IMMEDIATELY);
            w.set_nodiv(true);
            w.set_mckdiv(Mckdiv::DIV8);
        });
        // Step 3.
        ch.frcr().write(|w| w.set_frl(7));
        ch.slotr().write(|w| {
            w.set_slotsz(Slotsz::DATA_SIZE);
            w.set_nbslot(0);
            w.set_sloten(Sloten::from_bits(1));
        });
        // Step 4.
        ch.cr2().write(|w| w.set_fth(Fth::QUARTER2));
        ch.cr1().modify(|w| w.set_dmaen(true));

        // Step 5.
        let request = dma.request();
        dma.remap();
        let channel = slot.insert(Channel::new(dma, irq));
        let ring: *mut [u8; RING_BYTES] = ring;
        let mut options = TransferOptions::default();
        options.circular = true;
        // SAFETY: DR is a valid peripheral write address for bytes; the ring is
        // borrowed for 'a (PhantomData) and from now on only written through the raw
        // pointer in `update`, never through a reference the DMA could race with
        // beyond the byte-wise writes the protocol design accepts (the slot written
        // is at least one slot away from the DMA read position).
        let transfer = unsafe {
            channel.write_raw(
                request,
                ring as *const [u8],
                ch.dr().as_ptr() as *mut u8,
                options,
            )
        };
        ch.cr1().modify(|w| w.set_saien(true));
        Self {
            ch,
            transfer,
            ring,
            _ring: PhantomData,
            _sd: sd,
        }
    }

    /// Bytes the DMA has still to fetch in this lap (DMA_SxNDTR, `RING_BYTES` down to
    /// 1), the position `shared::hans::tx::Transmitter::update` works from.
    pub fn remaining(&self) -> usize {
        self.transfer.get_remaining_transfers() as usize
    }

    /// The slot (0..8) whose bits the DMA is fetching now.
    pub fn sending_slot(&self) -> usize {
        let remaining = self.transfer.get_remaining_transfers() as usize;
        let byte = RING_BYTES.saturating_sub(remaining) % RING_BYTES;
        (byte * 8 / shared::hans::frame::FRAME_BITS) % RING_SLOTS
    }

    /// The slot to fill next: two ahead of the one being fetched (module docs).
    pub fn next_free_slot(&self) -> usize {
        (self.sending_slot() + 2) % RING_SLOTS
    }

    /// Runs `f` on the ring to update slots in place (use
    /// `shared::hans::frame::write_slot` with [`Self::next_free_slot`]).
    pub fn update<R>(&mut self, f: impl FnOnce(&mut [u8; RING_BYTES]) -> R) -> R {
        // SAFETY: the pointer comes from the `&'a mut` given to `new` and stays valid
        // for 'a; `&mut self` makes this the only CPU reference. The DMA reads the
        // buffer concurrently, which is the point of the design: callers only touch
        // a slot the DMA is not fetching (module docs, `next_free_slot`).
        f(unsafe { &mut *self.ring })
    }

    /// Writes `frames` into consecutive slots from the first one at least
    /// [`LEAD_SLOTS`] ahead of the one being fetched, at most the
    /// `RING_SLOTS - LEAD_SLOTS` slots that are (HANS STATUS out: the bridge's next
    /// frames). Returns how many were written; frames beyond that are not.
    pub fn write_ahead(&mut self, frames: &[Frame]) -> Result<usize, DecodeError> {
        let sending = self.sending_slot();
        let n = frames.len().min(RING_SLOTS - LEAD_SLOTS);
        self.update(|buf| {
            for (k, f) in frames.iter().take(n).enumerate() {
                write_slot(buf, (sending + LEAD_SLOTS + k) % RING_SLOTS, f)?;
            }
            Ok(n)
        })
    }

    /// True while the SAI reports no underrun (SR.OVRUDR; cleared after reading).
    pub fn take_underrun(&mut self) -> bool {
        let underrun = self.ch.sr().read().ovrudr();
        if underrun {
            self.ch.clrfr().write(|w| w.set_covrudr(true));
        }
        underrun
    }
}

impl Drop for SerialTx<'_> {
    fn drop(&mut self) {
        self.ch.cr1().modify(|w| {
            w.set_saien(false);
            w.set_dmaen(false);
        });
    }
}
