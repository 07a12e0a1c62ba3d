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
//!
//! # No stale frames at the head (the slot ring guard)
//! A circular stream never stops by itself (RM0433 §15.3 "DMA functional
//! description", "Circular mode": NDTR is reloaded at the end of each lap and the
//! requests go on being served from the first address), so a bridge loop that stalls
//! would let the SAI play the last lap's frames again, lap after lap. The HANS-100
//! head's ring (DMA2 stream 3) is guarded ([`SerialTx::arm_head_guard`]); the
//! decision is `shared::bridge::slot_guard` (host-tested):
//! - [`HeadGuardHandler`] is bound on the stream's vector beside embassy's handler
//!   (`tasks::Irqs`) and runs at P0 on the half-transfer (HTIF, enabled here: the
//!   circular `Transfer` enables only TCIE) and transfer-complete (TCIF) interrupts
//!   (§15.5.1 / §15.5.2, DMA_LISR / DMA_HISR; DMA_SxCR.HTIE §15.5.5): every 40 us
//!   (62 / 63 bytes). From NDTR (§15.5.6) and its lap count it knows the DMA's
//!   absolute byte; it sets every slot the DMA has wholly fetched since its last run
//!   to zero bits (`shared::hans::frame::blank_slot`, bit-level: the half boundary
//!   cuts slots 3 / 4 inside byte 62), unless the writer already wrote that ring
//!   slot for its next lap. Zeros carry no start marker: the head decodes no frame.
//!   A slot is blanked at most a half after the DMA left it and fetched again 70 us
//!   after, so the DMA only ever fetches a frame written for this lap, or zeros.
//! - The writer ([`SerialTx::update_guarded`]) reads NDTR, writes and publishes the
//!   slot's absolute number in one critical section (~1 us), so the guard sees a
//!   write wholly or not at all. If at a guard run the slot the DMA fetches was not
//!   written for this lap, the guard drives the laser gate pin low and raises
//!   `channels`' stale flag (the waveform guard's: one mechanism), which refuses the
//!   gate until the bridge has restarted its gate rule
//!   ([`SerialTx::clear_stale_if`] after [`SerialTx::head_misses`] changed: the
//!   waveform loop's discipline, `shared::bridge::ring_guard` "Misses, and lifting
//!   the gate refusal"). Every run that drops the gate counts a miss
//!   ([`head_guard_misses`], the statistics' "guard misses").
//! - A second trigger runs the same guard once per slot (below, "The slot
//!   timer"): one state, one lock ([`head_guard_run`]), two interrupts.
//! - Bound: no frame older than this lap ever plays; a stall shows as at most one
//!   slot (10 us) of no frames with the gate still on, then the gate drops (below).
//!
//! # The slot timer
//! With the stream's interrupts alone the guard ran every 40 us, so a stall could
//! leave up to ~40 us of zeros at the head with the gate on. [`HeadSlotTickHandler`]
//! runs the same guard from TIM7's update interrupt (RM0433 §42 "Basic timers
//! (TIM6/TIM7)": no pin, no other user; TIM2 is embassy's time driver, TIM1 / TIM3 /
//! TIM8 the protocol timers, TIM4 / TIM5 the HIL tests'), at P0 like the stream's
//! handler, every [`SLOT_TICK_NS`] = 8 us of the APB1 timer clock (240 MHz, 1920
//! ticks; 200 MHz on revision Y, 1600: `board.rs` clock tree).
//! - Not phase-locked to the SAI, and it need not be: TIM7 counts PLL1, the SAI
//!   PLL2, from an arbitrary start. A run takes the DMA's absolute slot from NDTR
//!   and the lap count whenever it comes (`SlotGuard::run` takes any position,
//!   host-tested) and drops the gate if that slot was not written for this lap.
//! - Bound: let the DMA start fetching the first slot nobody wrote at t0. TIM7
//!   raises an update in every 8 us window, so one falls in [t0, t0 + 8 us); its
//!   run starts at most Δ later, Δ being what delays a P0 interrupt: a critical
//!   section (the writer's, ~1 us) or another P0 handler (a stream handler of
//!   this guard runs the same check itself). That run sees the DMA at that slot
//!   or later, still unwritten unless the writer caught up (then there is no
//!   stall to stop), and drops the gate: by t0 + 8 us + Δ, i.e. within one slot
//!   (10 us) for Δ up to 2 us. Any rate of at least one run per slot (period +
//!   Δ <= 10 us) gives the same bound; the host model runs the guard at random
//!   positions and rates (`shared::bridge::slot_guard`, "Runs at any position").
//! - Cost: 125 000 interrupts per second. The costliest run (a slot blanked and
//!   a miss, as in a stall) is 254 instructions in the cm7 bench (`slot guard: a
//!   run per slot`; 750 before `SlotGuard::run` lost its 64-bit divisions and
//!   `blank_slot` its per-byte masks), plus the interrupt's entry and exit, the
//!   lock and the NDTR read across the AHB/APB bridge (a few tens of cycles):
//!   ~300 cycles, at most ~38 M per second, ~8 % of the 480 MHz core (9 % at
//!   400 MHz, revision Y); in normal running a run blanks one slot about every
//!   10 us, so a little less. The stream's runs alone cost about a fifth of that.
//!   The blanking itself is no extra: each slot is blanked once either way, now
//!   by the first run after the DMA leaves it. The HT / TC runs stay (a second
//!   trigger if TIM7 stopped).
//! - Misses: every run that drops the gate counts one, so a stall now counts up
//!   to ~5 per 40 us (125 000 + 25 000 runs per second) instead of 1; the
//!   writer's clear-by-count rule is unchanged.
use core::cell::RefCell;
use core::marker::PhantomData;

use embassy_stm32::dma::{Channel, InterruptHandler, Transfer, TransferOptions};
use embassy_stm32::gpio::{AfType, Flex, OutputType, Speed};
use embassy_stm32::pac::sai::vals::{
    Ckstr, Ds, Fth, Lsbfirst, Mckdiv, Mode, Outdriv, Prtcfg, Sloten, Slotsz, Syncen,
};
use embassy_stm32::sai::{Dma, SdPin, SubBlockInstance};
use embassy_stm32::{interrupt, pac, peripherals, rcc, Peri};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use shared::bridge::slot_guard::SlotGuard;

use crate::drivers::ring_index;
use shared::hans::frame::{blank_slot, write_slot, DecodeError, Frame, RING_BYTES, RING_SLOTS};
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

/// The HANS-100 head ring's stream (DMA2 stream 3, `board::HansOutRes`).
const HEAD_STREAM: usize = 3;

/// The head ring guard's state (module docs, "No stale frames"): the decision and
/// the ring's address (0: no guarded ring, the handler does nothing).
struct HeadGuard {
    guard: SlotGuard,
    ring: usize,
}

static HEAD_GUARD: Mutex<CriticalSectionRawMutex, RefCell<HeadGuard>> =
    Mutex::new(RefCell::new(HeadGuard {
        guard: SlotGuard::new(),
        ring: 0,
    }));

/// The head ring guard's misses since boot (wrapping; guard runs that found the
/// DMA on a slot the bridge had not written for this lap, each one a gate drop):
/// the statistics' "guard misses", also for the hardware-in-the-loop tests. It
/// counts over every guarded run (`SlotGuard::restart`).
pub fn head_guard_misses() -> u32 {
    HEAD_GUARD.lock(|g| g.borrow().guard.missed())
}

/// One guard run (module docs, "No stale frames"), from either trigger: the
/// stream's half-transfer / transfer-complete interrupt ([`HeadGuardHandler`]) or
/// the slot timer ([`HeadSlotTickHandler`]). One state and one lock for both: a run
/// reads NDTR and decides under the lock, so the two triggers' runs are ordered
/// like any two runs of one trigger, and `SlotGuard::run` takes any position
/// (host-tested, `shared::bridge::slot_guard` "Runs at any position").
fn head_guard_run() {
    HEAD_GUARD.lock(|g| {
        let mut g = g.borrow_mut();
        if g.ring == 0 {
            return;
        }
        let ndtr = pac::DMA2.st(HEAD_STREAM).ndtr().read().ndt() as usize;
        let act = g.guard.run(ring_index(ndtr, RING_BYTES));
        // SAFETY: the address of the running ring (set by `arm_head_guard`, which
        // the ring's `SerialTx` outlives: `Drop` unsets it); the writer writes it
        // only under this lock, the DMA only reads it.
        let ring = unsafe { &mut *(g.ring as *mut [u8; RING_BYTES]) };
        for slot in (0..RING_SLOTS).filter(|k| act.blank & (1 << k) != 0) {
            // In range: `slot` < RING_SLOTS.
            let _ = blank_slot(ring, slot);
        }
        if act.gate_off {
            crate::channels::output_stale_gate_off();
        }
    });
}

/// The head ring guard's stream trigger (module docs, "No stale frames"): bound
/// on DMA2 stream 3 beside embassy's handler (`tasks::Irqs`), it runs the guard at
/// every half-transfer and transfer-complete interrupt of the head's stream, at P0.
pub struct HeadGuardHandler;

impl interrupt::typelevel::Handler<interrupt::typelevel::DMA2_STREAM3> for HeadGuardHandler {
    unsafe fn on_interrupt() {
        head_guard_run();
    }
}

/// The head ring guard's slot timer period (ns): at least one guard run per 10 us
/// slot, with room for the run's latency (module docs, "The slot timer").
pub const SLOT_TICK_NS: u64 = 8_000;

/// The head ring guard's slot trigger (module docs, "The slot timer"): bound on
/// TIM7's update interrupt (`tasks::Irqs`), at P0, every [`SLOT_TICK_NS`].
pub struct HeadSlotTickHandler;

impl interrupt::typelevel::Handler<interrupt::typelevel::TIM7> for HeadSlotTickHandler {
    unsafe fn on_interrupt() {
        // UIF is rc_w0 (RM0433 §42.4 "TIM6/TIM7 registers", TIMx_SR): writing 0
        // clears it, and it is TIM7's only flag. Cleared first: the run that
        // follows outlasts the write's way to the timer, so the interrupt is not
        // taken again on exit (a second run would blank nothing more; in a stall
        // it would count one more miss, which the writer's rule takes as any).
        pac::TIM7.sr().write(|w| w.set_uif(false));
        head_guard_run();
    }
}

/// Starts TIM7 as the guard's slot timer (module docs, "The slot timer"; RM0433
/// §42 "Basic timers (TIM6/TIM7)"): kernel clock on and reset (RCC_APB1LENR, §8),
/// PSC = 0 and ARR = ticks - 1 for an update event every [`SLOT_TICK_NS`] of the
/// APB1 timer clock (240 MHz: 1920 ticks; 200 MHz on revision Y: 1600; both
/// exact, under ARR's 16 bits), EGR.UG to load them, UIF cleared, DIER.UIE, CR1.CEN
/// (counting up, ARPE = 0: the period never changes); the update interrupt at P0,
/// the guard's priority.
fn start_slot_tick() {
    use embassy_stm32::interrupt::typelevel::{Interrupt, TIM7};
    use embassy_stm32::interrupt::Priority;

    rcc::enable_and_reset::<peripherals::TIM7>();
    let hz = rcc::frequency::<peripherals::TIM7>().0 as u64;
    let ticks = hz * SLOT_TICK_NS / 1_000_000_000;
    let t = pac::TIM7;
    t.psc().write_value(0);
    // In range on both revisions (above); clamped for any other clock.
    t.arr()
        .write(|w| w.set_arr((ticks.clamp(2, 1 << 16) - 1) as u16));
    t.egr().write(|w| w.set_ug(true));
    t.sr().write(|w| w.set_uif(false));
    t.dier().write(|w| w.set_uie(true));
    TIM7::set_priority(Priority::P0);
    TIM7::unpend();
    // SAFETY: the handler bound for TIM7 is `HeadSlotTickHandler` (`arm_head_guard`'s
    // binding), which runs the guard under its lock and clears TIM7's flag.
    unsafe { TIM7::enable() };
    t.cr1().modify(|w| w.set_cen(true));
}

/// Stops the slot timer and its interrupt (the guarded ring is going away).
fn stop_slot_tick() {
    use embassy_stm32::interrupt::typelevel::{Interrupt, TIM7};

    pac::TIM7.cr1().modify(|w| w.set_cen(false));
    TIM7::disable();
    pac::TIM7.sr().write(|w| w.set_uif(false));
    TIM7::unpend();
}

/// A running circular serial transmitter.
pub struct SerialTx<'a> {
    ch: pac::sai::Ch,
    transfer: Transfer<'a>,
    ring: *mut [u8; RING_BYTES],
    _ring: PhantomData<&'a mut [u8; RING_BYTES]>,
    _sd: Flex<'a>,
    /// The guard's slot timer, while this ring is the guarded head ring.
    tick: Option<Peri<'a, peripherals::TIM7>>,
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
            tick: None,
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
        let byte = ring_index(remaining, RING_BYTES);
        (byte * 8 / shared::hans::frame::FRAME_BITS) % RING_SLOTS
    }

    /// Runs `f` on the ring to update slots in place (e.g.
    /// `shared::hans::tx::Transmitter::update` from [`Self::remaining`]).
    pub fn update<R>(&mut self, f: impl FnOnce(&mut [u8; RING_BYTES]) -> R) -> R {
        // SAFETY: the pointer comes from the `&'a mut` given to `new` and stays valid
        // for 'a; `&mut self` makes this the only CPU reference. The DMA reads the
        // buffer concurrently, which is the point of the design: callers only touch
        // a slot the DMA is not fetching (module docs).
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

    /// Guards this ring as the HANS-100 head's (module docs, "No stale frames"):
    /// call once, right after [`SerialTx::new`] on DMA2 stream 3 with the ring still
    /// zeros; from then on write it only through [`SerialTx::update_guarded`] and
    /// [`SerialTx::stop_guarded`]. `irq` proves both of the guard's handlers are
    /// bound; `tick` is the slot timer ("The slot timer"), stopped on drop.
    pub fn arm_head_guard(
        &mut self,
        tick: Peri<'a, peripherals::TIM7>,
        _irq: impl interrupt::typelevel::Binding<interrupt::typelevel::DMA2_STREAM3, HeadGuardHandler>
            + interrupt::typelevel::Binding<interrupt::typelevel::TIM7, HeadSlotTickHandler>,
    ) {
        let ring = self.ring as usize;
        // A new run: the miss count goes on (statistics); no miss of an earlier
        // run stands against this one's gate rule.
        HEAD_GUARD.lock(|g| {
            let mut g = g.borrow_mut();
            g.guard.restart();
            g.ring = ring;
            crate::channels::clear_output_stale();
        });
        // HTIE may be set on the running stream (DMA_SxCR, RM0433 §15.5.5: only the
        // configuration bits are locked while EN = 1); embassy's handler clears HTIF.
        pac::DMA2.st(HEAD_STREAM).cr().modify(|w| w.set_htie(true));
        start_slot_tick();
        self.tick = Some(tick);
    }

    /// Runs `f(ring, NDTR)` (it writes slots from that position, e.g.
    /// `shared::hans::tx::Transmitter::update`, and returns the slot it wrote last)
    /// and publishes the slot to the guard, all in one critical section (module
    /// docs, "No stale frames").
    pub fn update_guarded<E>(
        &mut self,
        f: impl FnOnce(&mut [u8; RING_BYTES], usize) -> Result<usize, E>,
    ) -> Result<usize, E> {
        let ring = self.ring;
        let transfer = &self.transfer;
        HEAD_GUARD.lock(|g| {
            let remaining = transfer.get_remaining_transfers() as usize;
            // SAFETY: as in `update`; the guard writes the ring only under this lock.
            let r = f(unsafe { &mut *ring }, remaining);
            if let Ok(slot) = r {
                g.borrow_mut()
                    .guard
                    .wrote(slot, ring_index(remaining, RING_BYTES));
            }
            r
        })
    }

    /// Sets the whole ring to zeros (the head decodes no frame) and tells the guard
    /// that nothing is sent (no miss until the next [`SerialTx::update_guarded`]).
    pub fn stop_guarded(&mut self) {
        let ring = self.ring;
        HEAD_GUARD.lock(|g| {
            // SAFETY: as in `update`.
            unsafe { &mut *ring }.fill(0);
            g.borrow_mut().guard.stop();
        });
    }

    /// Misses of the head ring guard so far (wrapping): when this changes, restart
    /// the gate rule, then [`SerialTx::clear_stale_if`] with the new count.
    pub fn head_misses(&self) -> u32 {
        head_guard_misses()
    }

    /// Lets the laser gate open again (by the bridge's rule) unless the guard has
    /// missed again since `seen` (checked under the guard's lock: a new miss keeps
    /// the gate refused).
    pub fn clear_stale_if(&mut self, seen: u32) {
        HEAD_GUARD.lock(|g| {
            if g.borrow().guard.clear_if(seen) {
                crate::channels::clear_output_stale();
            }
        });
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
        if self.tick.is_some() {
            stop_slot_tick();
        }
        let ring = self.ring as usize;
        HEAD_GUARD.lock(|g| {
            let mut g = g.borrow_mut();
            if g.ring == ring {
                g.ring = 0;
            }
        });
        self.ch.cr1().modify(|w| {
            w.set_saien(false);
            w.set_dmaen(false);
        });
    }
}
