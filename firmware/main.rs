//! XY bridge firmware for the STM32H743: translates XY2-100(E), XY3-100 and HANS-100
//! between a laser marking controller and a galvo scan head.
//!
//! Boot: [`board::init`] forces the laser gate off, records the reset cause, sets up
//! power, clocks, SRAM and the I-cache; then the housekeeping tasks start. The protocol
//! drivers and the bridge tasks follow in issue 6 (see `firmware/README-firmware.md`).
#![no_std]
#![no_main]

mod board;
mod channels;
mod drivers;
mod tasks;

use embassy_executor::Spawner;
use {defmt_rtt as _, panic_probe as _};

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let board = board::init();
    defmt::info!(
        "xy-bridge firmware {} (silicon {}, core {} Hz), reset cause: {}",
        env!("CARGO_PKG_VERSION"),
        board.silicon,
        board.core_hz,
        board.reset_cause
    );
    if let board::Silicon::Other(rev) = board.silicon {
        defmt::warn!(
            "silicon REV_ID {=u16:#x} is not revision V: VOS0 not allowed, running at 400 MHz",
            rev
        );
    }
    let fault = board.reset_cause.is_fault();
    if fault {
        defmt::error!("last reset was a watchdog reset: the firmware stalled");
    }

    // Each task is spawned once from a pool of one, so the tokens cannot be exhausted.
    spawner.spawn(tasks::supervisor(board.iwdg, board.laser_gate, fault).unwrap());
    spawner.spawn(tasks::leds(board.led_green, board.led_yellow, board.led_red).unwrap());
    if PROBE_PAIR3 {
        spawner.spawn(tasks::pair3_probe(board.pair3_rx).unwrap());
    }
}

/// Bring-up configuration: run the line probe on controller-side pair 3 (XY3-100 X,
/// framed by SYNC on NSS), logging throughput and receive errors. Replaced by the
/// runtime role configuration in issue 6.
const PROBE_PAIR3: bool = true;
