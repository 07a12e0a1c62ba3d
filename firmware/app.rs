//! Start-up of the bridge: the two interrupt executors and the spawning of every task
//! the baked roles need (README "Tasks and executors"). The firmware binary
//! (`firmware/main.rs`) calls [`Executors::start`], [`spawn_supervision`] and
//! [`spawn_bridge`]; the hardware-in-the-loop tests (`firmware/hil/e2e`) call
//! the same functions, or the per-side ones below for the resources of one pairing,
//! so the tasks they run are the firmware's, spawned the firmware's way.

use embassy_executor::{InterruptExecutor, SendSpawner, Spawner};
use embassy_stm32::gpio::{Input, Level, Output, Pull, Speed};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::peripherals::{DMA1_CH5, IWDG1, PA0, PD6, PF11, PF14, PF15, PF8, PG9, USART2};
use embassy_stm32::usart::{Uart, UartRx};
use embassy_stm32::Peri;
use shared::bridge::{Config, StatusForm};
use shared::hans::rx::Mode as HansMode;

use crate::board::{
    BackRes, HansInRes, HansOutRes, HansStatusInRes, HansStatusOutRes, Resources, WaveRes,
    Xy2InRes, Xy3InRes,
};
use crate::config::{Controller, Head, Roles};
use crate::drivers::backchannel;
use crate::drivers::oversample_clock::{self, Fs};
use crate::tasks::{self, bridge, bridge_hans, hans_in, hans_status_out, line, status};

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

/// The spawners of the two interrupt executors.
#[derive(Clone, Copy)]
pub struct Executors {
    /// The line executor (UART8 vector, P6): line tasks and bridge loops.
    pub line: SendSpawner,
    /// The decode executor (UART5 vector, P8): the HANS-100 decoders.
    pub decode: SendSpawner,
}

impl Executors {
    /// Sets both priorities and starts both executors. Once per boot:
    /// `InterruptExecutor::start` panics when called twice.
    pub fn start() -> Executors {
        interrupt::UART8.set_priority(LINE_PRIORITY);
        let line = EXECUTOR_HIGH.start(interrupt::UART8);
        interrupt::UART5.set_priority(DECODE_PRIORITY);
        let decode = EXECUTOR_DECODE.start(interrupt::UART5);
        Executors { line, decode }
    }
}

/// The thread-mode tasks that run whatever the configuration: the supervisor
/// (watchdog, laser gate `laser_gate`, health), the LEDs (`leds`: green, yellow,
/// red) and the statistics. `watchdog_reset`: the last reset was the watchdog's.
pub fn spawn_supervision(
    spawner: Spawner,
    iwdg: Peri<'static, IWDG1>,
    laser_gate: Output<'static>,
    leds: [Output<'static>; 3],
    watchdog_reset: bool,
) {
    let [green, yellow, red] = leds;
    // Each task is spawned once per boot from a pool of one, so the tokens cannot be
    // exhausted.
    spawner.spawn(tasks::supervisor(iwdg, laser_gate, watchdog_reset).unwrap());
    spawner.spawn(tasks::leds(green, yellow, red).unwrap());
    spawner.spawn(tasks::stats::stats().unwrap());
}

/// Every bridge task for the roles of `config` on the board's resources `r`: the
/// controller side's input (and its STATUS or backchannel towards the controller),
/// the head side's output loop (and its STATUS or backchannel input), the HANS-100
/// oversampling clock when a HANS-100 input runs.
pub fn spawn_bridge(spawner: Spawner, ex: Executors, config: Config, r: Resources) {
    let roles = Roles::of(&config);
    defmt::info!("configuration: {}", roles);

    let head_enable = head_drivers(r.head_enable, r.head_mux, roles.head);
    let hans_head = roles.head == Head::Hans;

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
    match roles.controller {
        Controller::Xy2 => controller_xy2(
            spawner,
            ex,
            &config,
            r.xy2_in,
            r.ctrl_status,
            r.back.de,
            r.xy3_in.sck_buffer_oe,
        ),
        Controller::Xy3 => controller_xy3(spawner, ex, &config, r.xy3_in, r.back),
        Controller::Hans => {
            if let Some(fs) = fs_ctrl {
                controller_hans(ex, &config, r.xy3_in, r.hans_in, fs);
            }
            controller_hans_status(ex, r.hans_status_out, r.ctrl_status, r.back.de);
        }
    }

    // Head side.
    match roles.head {
        Head::Xy2 | Head::Xy3 => {
            if roles.head == Head::Xy3 {
                let b = r.head_back;
                head_xy3_backchannel(spawner, &config, b.uart, b.rx, b.rx_dma);
            }
            head_wave(
                spawner,
                ex,
                &config,
                roles,
                r.wave,
                head_enable,
                r.head_status,
            );
        }
        Head::Hans => {
            if let Some(fs) = fs_status {
                head_hans(
                    ex,
                    &config,
                    roles,
                    r.hans_out,
                    head_enable,
                    r.hans_status_in,
                    fs,
                );
            }
        }
    }
}

/// The head-side line drivers: their enable (PF11), returned off for the output
/// loop to switch on once its DMA plays the idle pattern, and the mux select (PF15)
/// for `head`'s source, driven for good (dropping an `Output` would turn the pin back
/// into an unconnected input, and the select would float).
pub fn head_drivers(
    enable: Peri<'static, PF11>,
    mux: Peri<'static, PF15>,
    head: Head,
) -> Output<'static> {
    let hans = head == Head::Hans;
    core::mem::forget(Output::new(mux, Level::from(hans), Speed::Low));
    Output::new(enable, Level::Low, Speed::Low)
}

/// The XY2-100 controller side: the input line task (TIM1 sampler halves to the
/// bridge) on the line executor, and the STATUS towards the controller on PA0 (the
/// pair-6 driver input): a level from thread mode, or with `status = "word"` the
/// word stream the input task plays on the controller's clock. The pair-6 driver
/// (enable `de`) is switched on for good, and the XY3-100 clock buffer
/// (`sck_buffer_oe`) off for good.
pub fn controller_xy2(
    spawner: Spawner,
    ex: Executors,
    config: &Config,
    xy2_in: Xy2InRes,
    ctrl_status: Peri<'static, PA0>,
    de: Peri<'static, PF8>,
    sck_buffer_oe: Peri<'static, PF14>,
) {
    let c = config.controller.xy2;
    let word = match c.status {
        StatusForm::Level => {
            let pin = Output::new(ctrl_status, Level::High, Speed::Low);
            let level = shared::xy2::StatusLevel {
                polarity: c.polarity,
            };
            spawner.spawn(status::status_level_out(pin, level).unwrap());
            None
        }
        // Played by a DMA stream on the controller's clock (xy2_in); low until the
        // first frame phase is known.
        StatusForm::Word => Some(line::WordOut {
            pin: Output::new(ctrl_status, Level::Low, Speed::VeryHigh),
            link: c,
        }),
    };
    ex.line.spawn(line::xy2_in(xy2_in, word).unwrap());
    // The pair-6 driver is always on: it carries the STATUS level. Forgotten on
    // purpose: dropping an `Output` would turn the pin back into an input.
    core::mem::forget(Output::new(de, Level::High, Speed::Low));
    // The buffer that puts pair 2 (here the XY2-100 SYNC) on the SPI SCK bus for
    // an XY3-100 controller stays off (OE# high, README wiring table): left in its
    // reset state the pin floats, and so would the buffer's enable.
    core::mem::forget(Output::new(sck_buffer_oe, Level::High, Speed::Low));
}

/// The XY3-100 controller side: the input line task `line::xy3_in` (the lines the
/// controller drives that the bridge uses, in sessions) on the line executor, and
/// the backchannel towards the controller (UART7 with hardware DE on the pair-6
/// driver, at `controller.xy3.back_rate`) in thread mode.
pub fn controller_xy3(
    spawner: Spawner,
    ex: Executors,
    config: &Config,
    xy3_in: Xy3InRes,
    back: BackRes,
) {
    // The lines the controller drives that the bridge uses (`controller.xy3.lines`;
    // Z only with `z.source = "input"`, U / W only for an XY3-100 head): an
    // unconnected line would fail every period.
    let lines = config.xy3_input_lines();
    let select = config.controller.xy3.select;
    defmt::info!("xy3 in: lines {}, select {}", lines, select);
    ex.line.spawn(line::xy3_in(xy3_in, lines, select).unwrap());
    let b = back;
    let back_config = backchannel::config(config.controller.xy3.back_rate.baud());
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
        Ok(u) => spawner.spawn(status::back_to_controller(backchannel::controller_tx(u)).unwrap()),
        Err(_) => defmt::error!("backchannel UART (controller) configuration rejected"),
    }
}

/// The HANS-100 controller input: `hans_in` (the channels `controller.hans.decode`
/// uses, on SPI1..5 clocked by `fs`) on the line executor, `hans_decode` on the
/// decode executor.
pub fn controller_hans(ex: Executors, config: &Config, xy3_in: Xy3InRes, hans: HansInRes, fs: Fs) {
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
    ex.line
        .spawn(hans_in::hans_in(xy3_in, hans, fs, mode).unwrap());
    ex.decode.spawn(hans_in::hans_decode(mode).unwrap());
}

/// The HANS STATUS stream towards a HANS-100 controller: `hans_status_out` (SAI2
/// block B on PA0, the pair-6 driver input) on the line executor, with the pair-6
/// driver (enable `de`) switched on for good.
pub fn controller_hans_status(
    ex: Executors,
    out: HansStatusOutRes,
    ctrl_status: Peri<'static, PA0>,
    de: Peri<'static, PF8>,
) {
    ex.line
        .spawn(hans_status_out::hans_status_out(out, ctrl_status).unwrap());
    // The pair-6 driver is always on: it carries the HANS STATUS stream. Forgotten
    // on purpose: dropping an `Output` would turn the pin back into an input.
    core::mem::forget(Output::new(de, Level::High, Speed::Low));
}

/// The HANS-100 head: the bridge loop `bridge_hans_out` (SAI1 ring on PE6, head
/// drivers enabled by `head_enable` once it runs) on the line executor, and the
/// head's STATUS: `line::hans_status_in` (SPI6 clocked by `fs`, TIM3 CH2) on the
/// line executor, `status::hans_status` on the decode executor.
pub fn head_hans(
    ex: Executors,
    config: &Config,
    roles: Roles,
    out: HansOutRes,
    head_enable: Output<'static>,
    status_in: HansStatusInRes,
    fs: Fs,
) {
    let hans = bridge_hans::bridge_hans_out(out, *config, roles.controller, head_enable);
    ex.line.spawn(hans.unwrap());
    let every = shared::hans::follow::status_every(roles.controller == Controller::Hans);
    defmt::info!("hans status in: every {} half decoded", every);
    ex.line
        .spawn(line::hans_status_in(status_in, fs, every).unwrap());
    ex.decode.spawn(status::hans_status().unwrap());
}

/// The XY3-100 head's backchannel on its own UART (USART2 RX, thread mode), at its
/// own rate: the controller's power-up rate until the bridge forwards a BACK_RATE
/// command.
/// (`board::HeadBackRes` without its TX, which is the HIL tests'.)
pub fn head_xy3_backchannel(
    spawner: Spawner,
    config: &Config,
    uart: Peri<'static, USART2>,
    rx: Peri<'static, PD6>,
    rx_dma: Peri<'static, DMA1_CH5>,
) {
    let back_config = backchannel::config(config.controller.xy3.back_rate.baud());
    match UartRx::new(uart, rx, rx_dma, tasks::Irqs, back_config) {
        Ok(rx) => {
            let rx = backchannel::head_rx(rx, tasks::back_ring());
            spawner.spawn(status::back_from_head(rx).unwrap());
        }
        Err(_) => defmt::error!("backchannel UART (head) configuration rejected"),
    }
}

/// The waveform head (XY2-100 or XY3-100, `roles.head`): the bridge loop on the line
/// executor (TIM8 BSRR output on port D, drivers enabled by `head_enable` once the
/// idle pattern plays) and, for an XY2-100 head, its STATUS input on PG9 (a level
/// task in thread mode, or the word the bridge loop samples).
pub fn head_wave(
    spawner: Spawner,
    ex: Executors,
    config: &Config,
    roles: Roles,
    wave: WaveRes,
    head_enable: Output<'static>,
    head_status: Peri<'static, PG9>,
) {
    let mut status_pin = None;
    if roles.head == Head::Xy2 {
        let pin = Input::new(head_status, Pull::None);
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
        wave,
        *config,
        roles.head,
        roles.controller,
        head_enable,
        status_pin,
    );
    ex.line.spawn(wave.unwrap());
}
