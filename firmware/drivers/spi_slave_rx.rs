//! Continuous, receive-only SPI slave into a circular DMA ring.
//!
//! embassy-stm32 0.6 only offers one-shot SPI transfers; the bridge needs an SPI that
//! never stops receiving (XY3-100 data lines, HANS-100 oversampled channels, see
//! `layouts.md` §2 and §3). This driver programs the SPI registers directly
//! (`unstable-pac`) and lets embassy's [`ReadableRingBuffer`] run the DMA stream in
//! circular mode. The decoder gets the words in time order through
//! [`SpiSlaveRx::read_exact`].
//!
//! Register sequence (RM0433 §50 "Serial peripheral interface"):
//! 1. Kernel and bus clock on, peripheral reset (RCC, §8), SPE = 0: CFG1/CFG2 can only
//!    be written while the SPI is disabled (§50.4, configuration protection).
//! 2. CFG1: DSIZE = word bits - 1, FTHLV = one frame (one DMA request per received
//!    word; §50.4, FIFO threshold), RXDMAEN = 1 (§50.4, DMA: the Rx DMA request is
//!    enabled before the stream and before SPE).
//! 3. CFG2: MASTER = 0 (slave), COMM = simplex receiver (only MOSI is used),
//!    CPOL = 0 / CPHA = 1 (§50.4, clock phase and polarity): sample on the falling SCK
//!    edge, which XY3-100 needs (`layouts.md` §2) and HANS-100's free-running
//!    oversampling clock does not care about; MSB first; and either hardware SS with
//!    active-low polarity (XY3-100: SYNC is the frame's chip select) or software SS
//!    held active (SSM = 1, SSI = 0; HANS-100: a free-running stream, and XY3-100
//!    with `controller.xy3.select = "always"`) (§50.4, slave select (SS)
//!    pin management).
//!
//! SS and a cut data frame: §50.4 (slave select (SS) pin management) presents the
//! slave's SS input as a chip select and nothing more; neither it nor the data
//! frame size (CFG1.DSIZE), FIFO threshold (CFG1.FTHLV) or transfer size
//! (CR2.TSIZE) text says what becomes of the bits of a frame that SS ends early,
//! and SSOM / MIDI / MSSI (CFG2) time a *master's* SS output only. So with hardware SS whether such bits are dropped
//! or completed by the next frame's is not ours to rely on (the XY3-100 receiver
//! copes with both, `shared::xy3::rx`); software SS never ends a frame, and SPE =
//! 0 (SPI_CR1.SPE: state machine reset, FIFOs flushed) is the one documented reset of the shift logic and FIFOs (what
//! an input restart does, by dropping and re-creating the driver).
//! 4. CR2.TSIZE = 0: endless transfer, the SPI never ends a transaction by itself.
//! 5. DMA stream started (circular, half/complete interrupts), then SPE = 1.
//!
//! Overrun (§50.4, error flags): when the RxFIFO is full the SPI discards new data
//! **and everything after it** until OVR is cleared. [`SpiSlaveRx::read_exact`] checks
//! OVR while it waits, clears it (IFCR.OVRC) and reports [`RxError::SpiOverrun`], so
//! the decoder resynchronises instead of silently gluing together data from both sides
//! of a gap.
//!
//! Instance limits (RM0433 §50.3 implementation table): SPI1..3 accept 4..32-bit words,
//! SPI4..6 only up to 16 bits. [`SpiSlaveRx::new`] refuses a word the instance cannot
//! take. SPI6 is served by BDMA: its ring must be in SRAM4.

use core::pin::pin;

use embassy_stm32::dma::word::Word;
use embassy_stm32::dma::{Channel, InterruptHandler, ReadableRingBuffer, TransferOptions};
use embassy_stm32::gpio::{AfType, Flex, Pull};
use embassy_stm32::pac::spi::vals::{Comm, Cpha, Cpol, Fthlv, Lsbfirst, Master, Ssiop};
use embassy_stm32::spi::{CsPin, MosiPin, RxDma, SckPin};
use embassy_stm32::{interrupt, pac, peripherals, rcc, Peri};
use embassy_time::{with_timeout, Duration, TimeoutError};

/// An SPI instance this driver can run, with its register block and word-size limit.
pub trait Instance: embassy_stm32::spi::Instance {
    /// The register block.
    const REGS: pac::spi::Spi;
    /// Largest data frame in bits (RM0433 §50.3).
    const MAX_BITS: u32;
}

macro_rules! impl_instance {
    ($($spi:ident: $bits:expr),*) => {
        $(impl Instance for peripherals::$spi {
            const REGS: pac::spi::Spi = pac::$spi;
            const MAX_BITS: u32 = $bits;
        })*
    };
}
impl_instance!(SPI1: 32, SPI2: 32, SPI3: 32, SPI4: 16, SPI5: 16, SPI6: 16);

/// Errors of [`SpiSlaveRx`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum RxError {
    /// The word type is wider than the instance supports.
    WordTooWide {
        /// Bits requested.
        bits: u32,
        /// Bits the instance supports.
        max: u32,
    },
    /// The SPI's RxFIFO overflowed (DMA too slow); words were lost at the SPI.
    SpiOverrun,
    /// The DMA overwrote words in the ring before they were read.
    RingOverrun,
}

impl core::fmt::Display for RxError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::WordTooWide { bits, max } => {
                write!(f, "{bits}-bit words requested, the SPI takes at most {max}")
            }
            Self::SpiOverrun => f.write_str("SPI receive FIFO overrun"),
            Self::RingOverrun => f.write_str("DMA ring overrun"),
        }
    }
}

/// A running receive-only SPI slave. Dropping it stops the DMA and releases the pins.
pub struct SpiSlaveRx<'d, W: Word> {
    regs: pac::spi::Spi,
    ring: ReadableRingBuffer<'d, W>,
    // Held so the pins stay in their alternate function while receiving.
    _sck: Flex<'d>,
    _mosi: Flex<'d>,
    _nss: Option<Flex<'d>>,
}

impl<'d, W: Word> SpiSlaveRx<'d, W> {
    /// Configures `T` as a receive-only slave and starts receiving into `ring`.
    /// `nss`: hardware chip select (active low), or `None` for a free-running stream.
    pub fn new<T: Instance, D: RxDma<T>>(
        _spi: Peri<'d, T>,
        sck: Peri<'d, impl SckPin<T>>,
        mosi: Peri<'d, impl MosiPin<T>>,
        nss: Option<Peri<'d, impl CsPin<T>>>,
        dma: Peri<'d, D>,
        irq: impl interrupt::typelevel::Binding<D::Interrupt, InterruptHandler<D>> + 'd,
        ring: &'d mut [W],
    ) -> Result<Self, RxError> {
        let bits = W::size().bytes() as u32 * 8;
        if bits > T::MAX_BITS {
            return Err(RxError::WordTooWide {
                bits,
                max: T::MAX_BITS,
            });
        }
        let regs = T::REGS;

        // Pins first: inputs in their alternate function (a slave drives nothing).
        // SCK is pulled down: on the board's shared SCK bus nobody drives it while the
        // bus buffer is off (XY3-100 input gates its clock that way until every line's
        // SPI is ready), and a floating clock would shift noise into some SPIs but
        // not others. A driven clock (buffer, HANS fs timer) overrides the pull.
        let input = AfType::input(Pull::None);
        let sck_af = sck.af_num();
        let mut sck = Flex::new(sck);
        sck.set_as_af_unchecked(sck_af, AfType::input(Pull::Down));
        let mosi_af = mosi.af_num();
        let mut mosi = Flex::new(mosi);
        mosi.set_as_af_unchecked(mosi_af, input);
        let nss = nss.map(|pin| {
            let af = pin.af_num();
            let mut pin = Flex::new(pin);
            pin.set_as_af_unchecked(af, input);
            pin
        });

        // Step 1: clock on and reset; SPE is 0 after reset.
        rcc::enable_and_reset::<T>();
        regs.cr1().modify(|w| w.set_spe(false));

        // Step 2. `bits` is 8, 16 or 32 (Word sizes), so `bits - 1` fits DSIZE.
        regs.cfg1().modify(|w| {
            w.set_dsize((bits - 1) as u8);
            w.set_fthlv(Fthlv::ONE_FRAME);
            w.set_rxdmaen(true);
        });
        // Step 3. CPOL = 0, CPHA = 1: sample on the falling SCK edge.
        let hardware_ss = nss.is_some();
        regs.cfg2().modify(|w| {
            w.set_master(Master::SLAVE);
            w.set_comm(Comm::RECEIVER);
            w.set_cpol(Cpol::IDLE_LOW);
            w.set_cpha(Cpha::SECOND_EDGE);
            w.set_lsbfirst(Lsbfirst::MSBFIRST);
            w.set_ssm(!hardware_ss);
            w.set_ssiop(Ssiop::ACTIVE_LOW);
        });
        // With software SS the internal SS level is SSI: 0 = selected (active low).
        regs.cr1().modify(|w| w.set_ssi(false));
        // Step 4.
        regs.cr2().modify(|w| w.set_tsize(0));

        // Step 5: DMA stream from RXDR (read with the word's width, RM0433 §50.4,
        // data packing) into the ring, then enable the SPI.
        let request = dma.request();
        dma.remap();
        let channel = Channel::new(dma, irq);
        let options = TransferOptions::default();
        // SAFETY: RXDR is a valid peripheral address for reads of width W; the ring
        // lives as long as the driver ('d) and is only read through `ring.read`.
        let mut ring = unsafe {
            ReadableRingBuffer::new(
                channel,
                request,
                regs.rxdr32().as_ptr() as *mut W,
                ring,
                options,
            )
        };
        ring.start();
        regs.cr1().modify(|w| w.set_spe(true));

        Ok(Self {
            regs,
            ring,
            _sck: sck,
            _mosi: mosi,
            _nss: nss,
        })
    }

    /// Waits until `buf` is full (woken by the DMA half / complete interrupts) and
    /// fills it (oldest word first). An error means words were lost: the caller must
    /// resynchronise its decoder; reception continues.
    ///
    /// While waiting, OVR is checked every [`OVR_POLL`]: after an overrun the SPI
    /// receives nothing until OVR is cleared, so without this the wait would never end.
    pub async fn read_exact(&mut self, buf: &mut [W]) -> Result<(), RxError> {
        let regs = self.regs;
        let mut overrun = false;
        let result = {
            let read = self.ring.read_exact(buf);
            let mut read = pin!(read);
            loop {
                // The read future is only borrowed here, never dropped early, so a
                // timeout loses no words.
                match with_timeout(OVR_POLL, read.as_mut()).await {
                    Ok(result) => break result,
                    Err(TimeoutError) => overrun |= take_overrun(regs),
                }
            }
        };
        overrun |= take_overrun(regs);
        if overrun {
            self.ring.clear();
            return Err(RxError::SpiOverrun);
        }
        match result {
            Ok(_) => Ok(()),
            Err(_) => {
                self.ring.clear();
                Err(RxError::RingOverrun)
            }
        }
    }
}

/// How often [`SpiSlaveRx::read_exact`] checks for an SPI overrun while waiting.
const OVR_POLL: Duration = Duration::from_millis(1);

/// Reads and clears the SPI overrun flag (SR.OVR, cleared by IFCR.OVRC).
fn take_overrun(regs: pac::spi::Spi) -> bool {
    let ovr = regs.sr().read().ovr();
    if ovr {
        regs.ifcr().write(|w| w.set_ovrc(true));
    }
    ovr
}

impl<W: Word> Drop for SpiSlaveRx<'_, W> {
    fn drop(&mut self) {
        // Stop the SPI before the ring (dropped next) stops the DMA stream.
        self.regs.cr1().modify(|w| w.set_spe(false));
        self.regs.cfg1().modify(|w| w.set_rxdmaen(false));
    }
}
