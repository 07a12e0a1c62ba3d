//! XY bridge firmware for the STM32H743: translates XY2-100(E), XY3-100 and HANS-100
//! between a laser marking controller and a galvo scan head.
//!
//! Boot: [`board::init`] forces the laser gate off, records the reset cause, sets up
//! power, clocks, SRAM and the I-cache. Then the thread-mode tasks start (supervisor
//! with watchdog and laser gate, LEDs, statistics, status paths), and the
//! high-priority `InterruptExecutor` takes the line tasks for the roles this image was
//! built for ([`config::ROLES`]). Every output starts idle and the gate stays off
//! until valid input frames arrive -- after a watchdog reset too, because this is the
//! only boot path.
#![no_std]
#![no_main]

mod channels;
mod config;
mod tasks;

use embassy_executor::{InterruptExecutor, Spawner};
use embassy_stm32::gpio::{Input, Level, Output, Pull, Speed};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::usart::{Uart, UartRx};
use xy_bridge::{board, drivers};
use {defmt_rtt as _, panic_probe as _};

use config::{Controller, Head, ROLES};
use drivers::backchannel::{self, Backchannel};
use tasks::{line, status};

/// Runs the line tasks at interrupt priority. UART8 is unused on this board, so its
/// vector serves as the executor's software interrupt.
static EXECUTOR_HIGH: InterruptExecutor = InterruptExecutor::new();

/// Priority of the line tasks: below the DMA interrupts (P0, embassy's default), which
/// only record progress and wake these tasks, above thread mode.
const LINE_PRIORITY: Priority = Priority::P6;

#[interrupt]
unsafe fn UART8() {
    // SAFETY: UART8's vector is used for nothing else; `on_interrupt` must only run
    // from the interrupt given to `start`, which is this one.
    unsafe { EXECUTOR_HIGH.on_interrupt() }
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let board = board::init();
    defmt::info!(
        "xy-bridge firmware {} (silicon {}, core {} Hz), reset cause: {}, roles: {}",
        env!("CARGO_PKG_VERSION"),
        board.silicon,
        board.core_hz,
        board.reset_cause,
        ROLES
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
    let r = board.res;

    // Each task is spawned once from a pool of one, so the tokens cannot be exhausted.
    spawner.spawn(tasks::supervisor(board.iwdg, board.laser_gate, fault).unwrap());
    spawner.spawn(tasks::leds(board.led_green, board.led_yellow, board.led_red).unwrap());
    spawner.spawn(tasks::stats().unwrap());

    interrupt::UART8.set_priority(LINE_PRIORITY);
    let high = EXECUTOR_HIGH.start(interrupt::UART8);
    high.spawn(line::bridge().unwrap());

    // Head-side drivers stay off until an output DMA plays its idle pattern.
    let head_enable = Output::new(r.head_enable, Level::Low, Speed::Low);
    let hans_head = ROLES.head == Head::Hans;
    let _head_mux = Output::new(r.head_mux, Level::from(hans_head), Speed::Low);

    // Controller side.
    let back_config = backchannel::config(shared::xy3::BackRate::B115200.baud());
    let back = match ROLES.controller {
        Controller::Xy2 => {
            high.spawn(line::xy2_in(r.xy2_in).unwrap());
            let pin = Output::new(r.ctrl_status, Level::High, Speed::Low);
            spawner.spawn(status::status_level_out(pin).unwrap());
            let b = r.back;
            // The pair-6 driver is always on: it carries the STATUS level. Forgotten
            // on purpose: dropping an `Output` would turn the pin back into an input.
            core::mem::forget(Output::new(b.de, Level::High, Speed::Low));
            (ROLES.head == Head::Xy3)
                .then(|| UartRx::new(b.uart, b.rx, b.rx_dma, tasks::Irqs, back_config).ok())
                .flatten()
                .map(|rx| Backchannel::receive_only(rx, tasks::back_ring()))
        }
        Controller::Xy3 => {
            high.spawn(line::xy3_in(r.xy3_in).unwrap());
            let b = r.back;
            Uart::new_with_de(
                b.uart,
                b.rx,
                b.tx,
                b.de,
                b.tx_dma,
                b.rx_dma,
                tasks::Irqs,
                back_config,
            )
            .ok()
            .map(|u| Backchannel::duplex(u, tasks::back_ring(), ROLES.head == Head::Xy3))
        }
    };
    match back {
        Some(back) => spawner.spawn(status::backchannel(back).unwrap()),
        None if ROLES.head == Head::Xy3 || ROLES.controller == Controller::Xy3 => {
            defmt::error!("backchannel UART configuration rejected");
        }
        None => {}
    }

    // Head side.
    match ROLES.head {
        Head::Xy2 | Head::Xy3 => {
            if ROLES.head == Head::Xy2 {
                let pin = Input::new(r.head_status, Pull::None);
                spawner.spawn(status::status_level_in(pin).unwrap());
            }
            high.spawn(line::wave_out(r.wave, ROLES.head, head_enable).unwrap());
        }
        Head::Hans => {
            high.spawn(line::hans_out(r.hans_out, head_enable).unwrap());
            high.spawn(line::hans_status_in(r.hans_status_in).unwrap());
        }
    }
}
