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

use config::{Controller, Head, Roles};
use drivers::backchannel;
use drivers::oversample_clock;
use shared::bridge::StatusForm;
use shared::hans::rx::Mode as HansMode;
use tasks::{bridge, bridge_hans, hans_in, hans_status_out, line, status};

/// Runs the line tasks at interrupt priority. UART8 is unused on this board, so its
/// vector serves as the executor's software interrupt.
static EXECUTOR_HIGH: InterruptExecutor = InterruptExecutor::new();

/// Priority of the line tasks: below the DMA interrupts (P0, embassy's default), which
/// only record progress and wake these tasks, above the decode executor and thread
/// mode.
const LINE_PRIORITY: Priority = Priority::P6;

/// Runs the HANS-100 decoders (controller input, head STATUS) at interrupt priority,
/// under the load governor (`tasks::governor`). UART5 is unused on this board, so its
/// vector serves as the executor's software interrupt.
static EXECUTOR_DECODE: InterruptExecutor = InterruptExecutor::new();

/// Priority of the decoders: below the line tasks (numerically higher: on the
/// Cortex-M a lower number preempts), so every output refill preempts a decode, and
/// above thread mode, so the decoders' latency does not depend on thread-mode work.
/// The governor keeps them from starving thread mode. P8 leaves P7 free for
/// anything that must sit between the two.
const DECODE_PRIORITY: Priority = Priority::P8;

#[interrupt]
unsafe fn UART8() {
    // SAFETY: UART8's vector is used for nothing else; `on_interrupt` must only run
    // from the interrupt given to `start`, which is this one.
    unsafe { EXECUTOR_HIGH.on_interrupt() }
}

#[interrupt]
unsafe fn UART5() {
    // SAFETY: UART5's vector is used for nothing else; `on_interrupt` must only run
    // from the interrupt given to `start`, which is this one.
    unsafe { EXECUTOR_DECODE.on_interrupt() }
}

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
    let r = board.res;

    // Each task is spawned once from a pool of one, so the tokens cannot be exhausted.
    spawner.spawn(tasks::supervisor(board.iwdg, board.laser_gate, fault).unwrap());
    spawner.spawn(tasks::leds(board.led_green, board.led_yellow, board.led_red).unwrap());
    spawner.spawn(tasks::stats::stats().unwrap());

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
    let roles = Roles::of(&config);
    defmt::info!("configuration: {}", roles);

    interrupt::UART8.set_priority(LINE_PRIORITY);
    let high = EXECUTOR_HIGH.start(interrupt::UART8);
    interrupt::UART5.set_priority(DECODE_PRIORITY);
    let decode = EXECUTOR_DECODE.start(interrupt::UART5);

    // Head-side drivers stay off until an output DMA plays its idle pattern.
    let head_enable = Output::new(r.head_enable, Level::Low, Speed::Low);
    let hans_head = roles.head == Head::Hans;
    let _head_mux = Output::new(r.head_mux, Level::from(hans_head), Speed::Low);

    // The HANS-100 oversampling clock (TIM3), with the output of each HANS input
    // that runs; PC6 drives the controller-side SCK bus only for a HANS controller.
    let hans_ctrl = roles.controller == Controller::Hans;
    let (fs_ctrl, fs_status) = if hans_ctrl || hans_head {
        let f = r.fs;
        let fs = oversample_clock::start(
            f.tim,
            hans_ctrl.then_some(f.ctrl),
            hans_head.then_some(f.status),
        );
        (Some(fs.ctrl), Some(fs.status))
    } else {
        (None, None)
    };

    // Controller side.
    let back_config = backchannel::config(config.controller.xy3.back_rate.baud());
    match roles.controller {
        Controller::Xy2 => {
            let c = config.controller.xy2;
            let word = match c.status {
                StatusForm::Level => {
                    let pin = Output::new(r.ctrl_status, Level::High, Speed::Low);
                    let level = shared::xy2::StatusLevel {
                        polarity: c.polarity,
                    };
                    spawner.spawn(status::status_level_out(pin, level).unwrap());
                    None
                }
                // Played by a DMA stream on the controller's clock (xy2_in); low
                // until the first frame phase is known.
                StatusForm::Word => Some(line::WordOut {
                    pin: Output::new(r.ctrl_status, Level::Low, Speed::VeryHigh),
                    link: c,
                }),
            };
            high.spawn(line::xy2_in(r.xy2_in, word).unwrap());
            // The pair-6 driver is always on: it carries the STATUS level. Forgotten
            // on purpose: dropping an `Output` would turn the pin back into an input.
            core::mem::forget(Output::new(r.back.de, Level::High, Speed::Low));
        }
        Controller::Xy3 => {
            // The lines the controller drives that the bridge uses
            // (`controller.xy3.lines`; Z only with `z.source = "input"`, U / W only
            // for an XY3-100 head): an unconnected line would fail every period.
            let lines = config.xy3_input_lines();
            defmt::info!("xy3 in: lines {}", lines);
            high.spawn(line::xy3_in(r.xy3_in, lines).unwrap());
            let b = r.back;
            match Uart::new_with_de(
                b.uart,
                b.rx,
                b.tx,
                b.de,
                b.tx_dma,
                b.rx_dma,
                tasks::Irqs,
                back_config,
            ) {
                Ok(u) => spawner
                    .spawn(status::back_to_controller(backchannel::controller_tx(u)).unwrap()),
                Err(_) => defmt::error!("backchannel UART (controller) configuration rejected"),
            }
        }
        Controller::Hans => {
            let mode = hans_in::mode_of(config.controller.hans.decode);
            defmt::info!("hans in: {}", mode);
            if matches!(mode, HansMode::Vote5 | HansMode::Super) {
                // README "Tasks and executors", HANS-100 controller cost.
                defmt::warn!(
                    "hans in: {} costs ~3200..3400 instructions per 10 us frame settled \
                     (QEMU), more during a young lock: at or above the decode governor's \
                     share beside the line tasks, expect dropped input halves",
                    mode
                );
            }
            if let Some(fs) = fs_ctrl {
                high.spawn(hans_in::hans_in(r.xy3_in, r.hans_in, fs, mode).unwrap());
            }
            decode.spawn(hans_in::hans_decode(mode).unwrap());
            high.spawn(hans_status_out::hans_status_out(r.hans_status_out, r.ctrl_status).unwrap());
            // The pair-6 driver is always on: it carries the HANS STATUS stream.
            core::mem::forget(Output::new(r.back.de, Level::High, Speed::Low));
        }
    }
    // The head's backchannel on its own UART, at its own rate (the controller's
    // power-up rate until the bridge forwards a BACK_RATE command).
    if roles.head == Head::Xy3 {
        let b = r.head_back;
        match UartRx::new(b.uart, b.rx, b.rx_dma, tasks::Irqs, back_config) {
            Ok(rx) => {
                let rx = backchannel::head_rx(rx, tasks::back_ring());
                spawner.spawn(status::back_from_head(rx).unwrap());
            }
            Err(_) => defmt::error!("backchannel UART (head) configuration rejected"),
        }
    }

    // Head side.
    match roles.head {
        Head::Xy2 | Head::Xy3 => {
            let mut status_pin = None;
            if roles.head == Head::Xy2 {
                let pin = Input::new(r.head_status, Pull::None);
                match config.head.xy2.status {
                    StatusForm::Level => {
                        let level = shared::xy2::StatusLevel {
                            polarity: config.head.xy2.polarity,
                        };
                        spawner.spawn(status::status_level_in(pin, level).unwrap());
                    }
                    // Sampled by TIM8 CC1 in the bridge task, which keeps the pin.
                    StatusForm::Word => status_pin = Some(pin),
                }
            }
            let wave = bridge::bridge_wave_out(
                r.wave,
                config,
                roles.head,
                roles.controller,
                head_enable,
                status_pin,
            );
            high.spawn(wave.unwrap());
        }
        Head::Hans => {
            let hans =
                bridge_hans::bridge_hans_out(r.hans_out, config, roles.controller, head_enable);
            high.spawn(hans.unwrap());
            if let Some(fs) = fs_status {
                let every = shared::hans::follow::status_every(hans_ctrl);
                defmt::info!("hans status in: every {} half decoded", every);
                high.spawn(line::hans_status_in(r.hans_status_in, fs, every).unwrap());
            }
            decode.spawn(status::hans_status().unwrap());
        }
    }
}
