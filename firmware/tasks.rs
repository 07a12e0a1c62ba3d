//! Thread-mode housekeeping tasks: the supervisor (watchdog, laser gate, health) and
//! the status LEDs. The timing-critical decode/encode work will run elsewhere (DMA
//! interrupts and a high-priority `InterruptExecutor`, issue 6), so these tasks may be
//! slow without affecting the line timing.

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;
use embassy_stm32::gpio::Output;
use embassy_stm32::peripherals::IWDG1;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::Peri;

use embassy_stm32::{bind_interrupts, dma, peripherals};
use embassy_time::{Duration, Instant, Ticker};

use crate::board::Pair3Rx;
use crate::channels::{Health, HEALTH};
use crate::drivers::spi_slave_rx::SpiSlaveRx;

bind_interrupts!(struct ProbeIrqs {
    DMA1_STREAM0 => dma::InterruptHandler<peripherals::DMA1_CH0>;
});

/// Probe ring length in bytes: 2 halves of 512, i.e. 1.28 ms of XY3-100 at 3.2 MHz.
const PROBE_RING_LEN: usize = 1024;

/// The probe's DMA ring, in SRAM1 (reachable by DMA1; `.sram1` is NOLOAD, hence
/// `MaybeUninit`, written before use).
#[link_section = ".sram1"]
static mut PROBE_RING: MaybeUninit<[u8; PROBE_RING_LEN]> = MaybeUninit::uninit();

/// Watchdog timeout. The IWDG runs from the 32 kHz LSI, independent of the main clocks,
/// so it also catches a dead PLL. 250 ms is long against the 50 ms feed period (a feed
/// may be late by a few long critical sections or a defmt burst) and short enough that
/// a stalled executor resets the chip -- and with it, via the board's pull-down, forces
/// the laser gate off -- well before an operator would notice a frozen head. The LSI is
/// only roughly 32 kHz (DS12110 gives a few percent of spread over temperature and
/// supply), so the real timeout moves by that much; it stays far above 50 ms.
const WATCHDOG_TIMEOUT_US: u32 = 250_000;

/// How often the supervisor runs and feeds the watchdog.
const SUPERVISOR_PERIOD: Duration = Duration::from_millis(50);

/// Owns the watchdog and the laser gate. Runs in the thread-mode executor, so if that
/// executor stalls (a task that never yields, a deadlock) the watchdog is no longer fed
/// and resets the chip.
#[embassy_executor::task]
pub async fn supervisor(
    iwdg: Peri<'static, IWDG1>,
    mut laser_gate: Output<'static>,
    fault_at_boot: bool,
) {
    let mut watchdog = IndependentWatchdog::new(iwdg, WATCHDOG_TIMEOUT_US);
    watchdog.unleash();
    defmt::info!("watchdog running, timeout {} us", WATCHDOG_TIMEOUT_US);

    let health = Health {
        input_valid: false,
        fault: fault_at_boot,
    };
    HEALTH.sender().send(health);

    let mut ticker = Ticker::every(SUPERVISOR_PERIOD);
    loop {
        // The laser gate stays off until the bridge reports valid input frames; the
        // permit from the input decoders is wired in issue 6. Re-asserted every period
        // so no other code path can leave it on.
        laser_gate.set_low();
        watchdog.pet();
        ticker.next().await;
    }
}

/// Green LED blinks at 1 Hz while the thread executor runs; yellow shows "no valid
/// input" (laser gate held off); red shows a latched fault.
#[embassy_executor::task]
pub async fn leds(
    mut green: Output<'static>,
    mut yellow: Output<'static>,
    mut red: Output<'static>,
) {
    let mut health = HEALTH.anon_receiver();
    let mut ticker = Ticker::every(Duration::from_millis(500));
    loop {
        green.toggle();
        if let Some(h) = health.try_changed() {
            yellow.set_level((!h.input_valid).into());
            red.set_level(h.fault.into());
        }
        ticker.next().await;
    }
}

/// Line probe for bring-up: receives controller-side pair 3 as an XY3-100 data line
/// (SPI3 slave, 8-bit words, sampled on the falling CLK edge, SYNC = NSS) and logs once
/// a second how many bytes arrived and whether any were lost.
#[embassy_executor::task]
pub async fn pair3_probe(r: Pair3Rx) {
    // SAFETY: this task is spawned at most once (pool size 1), so this is the only
    // reference to PROBE_RING ever created.
    let ring: &'static mut [u8; PROBE_RING_LEN] =
        unsafe { (*addr_of_mut!(PROBE_RING)).write([0; PROBE_RING_LEN]) };
    let mut rx = match SpiSlaveRx::new(r.spi, r.sck, r.mosi, Some(r.nss), r.dma, ProbeIrqs, ring) {
        Ok(rx) => rx,
        Err(e) => {
            defmt::error!("pair 3 probe: {}", e);
            return;
        }
    };
    defmt::info!("pair 3 probe: SPI3 slave receiving (XY3-100 X)");
    let mut chunk = [0u8; PROBE_RING_LEN / 2];
    let mut bytes: u32 = 0;
    let mut errors: u32 = 0;
    let mut last_report = Instant::now();
    loop {
        match rx.read_exact(&mut chunk).await {
            Ok(()) => bytes = bytes.wrapping_add(chunk.len() as u32),
            Err(e) => {
                errors = errors.wrapping_add(1);
                defmt::warn!("pair 3 probe: {}", e);
            }
        }
        if last_report.elapsed() >= Duration::from_secs(1) {
            defmt::info!("pair 3 probe: {} bytes, {} errors", bytes, errors);
            last_report = Instant::now();
        }
    }
}
