//! XY bridge firmware for the STM32H743: translates XY2-100(E), XY3-100 and HANS-100
//! between a laser marking controller and a galvo scan head.
//!
//! Boot: [`board::init`] forces the laser gate off, records the reset cause, sets up
//! power, clocks, SRAM and the I-cache. Then the thread-mode tasks start (supervisor
//! with watchdog and laser gate, LEDs, statistics, status paths), the high-priority
//! line `InterruptExecutor` takes the line tasks for the roles of the configuration
//! baked in at build time ([`config::load`], from `bridge.toml`), and the
//! medium-priority decode `InterruptExecutor` the HANS-100 decoders. Every
//! output starts idle and the gate stays off until valid input frames arrive -- after
//! a watchdog reset too, because this is the only boot path. A configuration that
//! fails to load leaves the bridge in that safe state.
//!
//! The tasks, their channels and the spawning are the library's ([`xy_bridge::app`]),
//! which the hardware-in-the-loop tests run too; this file only brings the board up,
//! loads the configuration and calls it.
#![no_std]
#![no_main]

use embassy_executor::Spawner;
use xy_bridge::app::{self, Executors};
use xy_bridge::{board, config};
use {defmt_rtt as _, panic_probe as _};

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let board = board::init();
    defmt::info!(
        "xy-bridge firmware {} (silicon {}, core {} Hz), reset cause: {}",
        env!("CARGO_PKG_VERSION"),
        board.silicon,
        board.core_hz,
        board.reset_cause,
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
    let leds = [board.led_green, board.led_yellow, board.led_red];
    app::spawn_supervision(spawner, board.iwdg, board.laser_gate, leds, fault);

    // The configuration baked in by build.rs, validated again here. Without it
    // nothing else starts: head drivers off, laser gate off (the supervisor forces it
    // off while no bridge runs).
    let config = match config::load() {
        Ok(c) => c,
        Err(e) => {
            defmt::error!(
                "baked configuration unusable: {}; staying in the safe state",
                e
            );
            return;
        }
    };
    app::spawn_bridge(spawner, Executors::start(), config, board.res);
}
