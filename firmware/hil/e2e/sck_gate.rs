//! The SCK-bus buffer the NUCLEO lacks, emulated for the XY3-100 input's session
//! restarts under a running clock (README "Hardware-in-the-loop self-tests").
//!
//! On the board, pair 2 (XY3-100 CLK) reaches the SPI slaves' SCK bus through a
//! buffer whose OE# is PF14: `line::xy3_in` holds it off (high) while it starts
//! the SPIs of a new session one after the other, then lets the clock in (low), so
//! that every line counts from the same edge. On the NUCLEO the source's CLK pin
//! (PE3) is wired straight to the SCK pins. Here an interrupt on PF14's own edges
//! (EXTI line 14 routed from port F, §20: the pad's input stage, which feeds the
//! EXTI multiplexer, stays on in output mode, RM0433 "GPIO functional
//! description"; only analog mode turns it off) switches PE3 to an input while
//! OE# is high and back to an output while it is low. As an input PE3 drives nothing and the pull-downs (its own and the SPI
//! SCK pins', `spi_slave_rx`) hold the bus low, as the buffer's off state and the
//! board's pull-downs do; the source's DMA keeps writing PE3's output register, so
//! the clock comes back at the source's current level, as through the buffer.
//!
//! What makes it honest is its own check of its latency, per edge: when OE# goes
//! high the new session's SPIs (SPI3, SPI4, SPI5: X, Y, Z) must all still be off
//! (`xy3_in` drops the old session's SPIs, which clears SPE, before it turns the
//! buffer off, and enables the new ones only after), so no edge the emulation lets
//! through late can reach an SPI that counts; when OE# goes low they must all be on
//! (the firmware lets the clock in only once every line is ready) and PE3 must
//! still be the input the last close left. (`xy3_in` sets the SPI4 pins PE11,
//! PE12, PE14 with read-modify-writes of the same mode register, between the two
//! edges; embassy makes them inside critical sections, so the interrupt cannot
//! split one, and the check guards the rest.) The interrupt runs at
//! P0 (the DMA handlers' level, above the line executor's P6), so it waits at most
//! for one short DMA or SYNC-mark handler and the firmware's own short critical
//! sections: well under a microsecond at 400-480 MHz against the microseconds
//! `SpiSlaveRx::new` spends on SPI3's pins, clock, reset, registers and DMA stream
//! before it sets SPE.

use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use embassy_stm32::interrupt::typelevel::{Handler, Interrupt, EXTI15_10};
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::pac;
use embassy_stm32::pac::gpio::vals::{Idr, Moder, Pupdr};

/// PF14: the SCK-bus buffer's OE# (EXTI line 14, routed from port F).
const OE_PIN: usize = 14;
const PORT_F: u8 = 5;
/// PE3: the test source's CLK (`xy3_to_xy2`'s `SRC_PINS`).
const CLK_PIN: usize = 3;

/// Times the buffer went off (OE# high) and on (low).
static CLOSES: AtomicU32 = AtomicU32::new(0);
static OPENS: AtomicU32 = AtomicU32::new(0);
/// Closes that came with an X, Y or Z SPI already enabled (the emulation too late).
static LATE: AtomicU32 = AtomicU32::new(0);
/// Opens with an X, Y or Z SPI not enabled (the firmware let the clock in early).
static EARLY: AtomicU32 = AtomicU32::new(0);
/// Opens that found PE3 no longer an input (its mode rewritten behind the gate).
static CLOBBERED: AtomicU32 = AtomicU32::new(0);
/// `embassy_time` microseconds (low 32 bits) of the last close.
static CLOSED_AT_US: AtomicU32 = AtomicU32::new(0);
/// A close switched PE3 to an input and no open has followed yet.
static GATED: AtomicBool = AtomicBool::new(false);

/// What the emulated buffer saw, as counted by its interrupt.
#[derive(Clone, Copy, Debug, defmt::Format)]
pub struct GateCounts {
    pub closes: u32,
    pub opens: u32,
    pub late: u32,
    pub early: u32,
    pub clobbered: u32,
    /// Microseconds (`embassy_time`, low 32 bits) of the last close.
    pub closed_at_us: u32,
}

impl GateCounts {
    /// The emulation's own verdict: every close before any new SPI counted, every
    /// open after all of them, PE3's mode left alone between.
    pub fn check(&self) {
        assert_eq!(
            self.late, 0,
            "SCK gate emulation too late: an SPI already on"
        );
        assert_eq!(self.early, 0, "clock let in before every line's SPI was on");
        assert_eq!(self.clobbered, 0, "PE3's mode rewritten while gated");
    }
}

/// The EXTI15_10 handler: follows PF14's level (line 14 is the only one of 10..15
/// unmasked here).
pub struct SckGateHandler;

impl Handler<EXTI15_10> for SckGateHandler {
    unsafe fn on_interrupt() {
        // Clear first: an edge that comes while this runs pends again, and the next
        // run follows the level it left.
        pac::EXTI.pr(0).write(|w| w.set_line(OE_PIN, true));
        let spi_on = [pac::SPI3, pac::SPI4, pac::SPI5].map(|s| s.cr1().read().spe());
        if oe_high() {
            CLOSES.fetch_add(1, Ordering::Relaxed);
            if spi_on.iter().any(|&on| on) {
                LATE.fetch_add(1, Ordering::Relaxed);
            }
            set_clk_mode(Moder::INPUT);
            GATED.store(true, Ordering::Relaxed);
            CLOSED_AT_US.store(
                embassy_time::Instant::now().as_micros() as u32,
                Ordering::Relaxed,
            );
        } else {
            OPENS.fetch_add(1, Ordering::Relaxed);
            if !spi_on.iter().all(|&on| on) {
                EARLY.fetch_add(1, Ordering::Relaxed);
            }
            let input = pac::GPIOE.moder().read().moder(CLK_PIN) == Moder::INPUT;
            if GATED.swap(false, Ordering::Relaxed) && !input {
                CLOBBERED.fetch_add(1, Ordering::Relaxed);
            }
            set_clk_mode(Moder::OUTPUT);
        }
    }
}

fn oe_high() -> bool {
    pac::GPIOF.idr().read().idr(OE_PIN) == Idr::HIGH
}

fn set_clk_mode(mode: Moder) {
    pac::GPIOE.moder().modify(|w| w.set_moder(CLK_PIN, mode));
}

/// The armed emulation (the interrupt stays bound for the image; dropping this
/// masks the line and leaves PE3 an output).
pub struct SckGate;

impl SckGate {
    /// Arms the emulation. Call it after the source drives PE3 and before
    /// `line::xy3_in` is spawned (it takes PF14 over): PE3 gets its pull-down, the
    /// counters start at 0 and PE3 follows PF14's level from now on.
    pub fn arm(
        _irq: impl embassy_stm32::interrupt::typelevel::Binding<EXTI15_10, SckGateHandler>,
    ) -> Self {
        for c in [&CLOSES, &OPENS, &LATE, &EARLY, &CLOBBERED, &CLOSED_AT_US] {
            c.store(0, Ordering::Relaxed);
        }
        GATED.store(false, Ordering::Relaxed);
        // Nothing else runs yet that touches port E's pull register.
        pac::GPIOE
            .pupdr()
            .modify(|w| w.set_pupdr(CLK_PIN, Pupdr::PULL_DOWN));
        // SYSCFG_EXTICR4 field 2 routes line 14 (embassy's init clocks SYSCFG).
        pac::SYSCFG
            .exticr(OE_PIN / 4)
            .modify(|w| w.set_exti(OE_PIN % 4, PORT_F));
        pac::EXTI.rtsr(0).modify(|w| w.set_line(OE_PIN, true));
        pac::EXTI.ftsr(0).modify(|w| w.set_line(OE_PIN, true));
        pac::EXTI.pr(0).write(|w| w.set_line(OE_PIN, true));
        // The level now (a PF14 still in its reset state, analog, reads low: PE3
        // drives; `xy3_in` then makes it an output high, the first close).
        let high = oe_high();
        set_clk_mode(if high { Moder::INPUT } else { Moder::OUTPUT });
        GATED.store(high, Ordering::Relaxed);
        embassy_stm32::interrupt::EXTI15_10.set_priority(Priority::P0);
        EXTI15_10::unpend();
        pac::EXTI.imr(0).modify(|w| w.set_line(OE_PIN, true));
        // SAFETY: the handler bound for EXTI15_10 is `SckGateHandler`, which touches
        // only its atomics, line 14's pending bit, three SPI control registers
        // (read) and PE3's mode bits.
        unsafe { EXTI15_10::enable() };
        SckGate
    }

    /// The counts so far.
    pub fn counts(&self) -> GateCounts {
        GateCounts {
            closes: CLOSES.load(Ordering::Relaxed),
            opens: OPENS.load(Ordering::Relaxed),
            late: LATE.load(Ordering::Relaxed),
            early: EARLY.load(Ordering::Relaxed),
            clobbered: CLOBBERED.load(Ordering::Relaxed),
            closed_at_us: CLOSED_AT_US.load(Ordering::Relaxed),
        }
    }
}

impl Drop for SckGate {
    fn drop(&mut self) {
        pac::EXTI.imr(0).modify(|w| w.set_line(OE_PIN, false));
        set_clk_mode(Moder::OUTPUT);
    }
}
