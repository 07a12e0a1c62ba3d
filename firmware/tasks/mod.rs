//! Tasks, in three priorities (README "Tasks and executors"). Thread mode (this
//! file, [`stats`], most of [`status`]): the supervisor (watchdog, laser gate,
//! health), the status LEDs, the once-a-second statistics, the slow status paths.
//! Decode executor (medium priority, `app.rs`): the HANS-100 decoders
//! ([`hans_in::hans_decode`], [`status::hans_status`]) under the load governor
//! ([`governor`]), which keeps them from starving thread mode. Line executor (high
//! priority, [`line`], [`bridge`], [`bridge_hans`]): the per-DMA-half receive ->
//! bridge -> transmit loops. Thread-mode tasks may be slow without affecting the
//! line timing or the decoders.

pub(crate) mod bridge;
mod bridge_core;
pub(crate) mod bridge_hans;
mod ctrl_word;
mod encode;
pub(crate) mod governor;
pub(crate) mod hans_in;
pub(crate) mod hans_status_out;
mod head_word;
pub(crate) mod line;
pub(crate) mod stats;
pub(crate) mod status;

use embassy_stm32::gpio::Output;
use embassy_stm32::peripherals::IWDG1;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, dma, peripherals, usart, Peri};
use embassy_time::{Duration, Ticker};

use core::sync::atomic::Ordering;

use crate::channels::{
    set_laser_gate, Health, BRIDGE_BEAT, HEAD_FAULT, HEALTH, LASER_GATE, LINK_RUNNING, STATS,
};
use crate::drivers::serial_tx::{HeadGuardHandler, HeadSlotTickHandler};
use crate::drivers::sync_marks::SyncEdgeHandler;
use crate::drivers::wave_out::RingGuardHandler;

bind_interrupts!(
    /// Every interrupt a protocol driver uses (README.md (section "Firmware") allocation
    /// table). The hardware-in-the-loop tests bind through this one too (a vector can
    /// have one handler per image): DMA1 stream 6 (USART2 TX) is theirs only.
    pub struct Irqs {
        DMA1_STREAM0 => dma::InterruptHandler<peripherals::DMA1_CH0>;
        DMA1_STREAM1 => dma::InterruptHandler<peripherals::DMA1_CH1>;
        DMA1_STREAM2 => dma::InterruptHandler<peripherals::DMA1_CH2>;
        DMA1_STREAM3 => dma::InterruptHandler<peripherals::DMA1_CH3>;
        DMA1_STREAM4 => dma::InterruptHandler<peripherals::DMA1_CH4>;
        DMA1_STREAM5 => dma::InterruptHandler<peripherals::DMA1_CH5>;
        DMA1_STREAM6 => dma::InterruptHandler<peripherals::DMA1_CH6>;
        DMA2_STREAM0 => dma::InterruptHandler<peripherals::DMA2_CH0>;
        /// The waveform output's stream: embassy's handler and the ring guard
        /// (`wave_out::RingGuardHandler`: no stale words at the head).
        DMA2_STREAM1 => dma::InterruptHandler<peripherals::DMA2_CH1>, RingGuardHandler;
        DMA2_STREAM2 => dma::InterruptHandler<peripherals::DMA2_CH2>;
        /// The HANS-100 head's stream: embassy's handler and the slot ring guard
        /// (`serial_tx::HeadGuardHandler`: no stale frames at the head).
        DMA2_STREAM3 => dma::InterruptHandler<peripherals::DMA2_CH3>, HeadGuardHandler;
        DMA2_STREAM4 => dma::InterruptHandler<peripherals::DMA2_CH4>;
        DMA2_STREAM5 => dma::InterruptHandler<peripherals::DMA2_CH5>;
        DMA2_STREAM6 => dma::InterruptHandler<peripherals::DMA2_CH6>;
        DMA2_STREAM7 => dma::InterruptHandler<peripherals::DMA2_CH7>;
        BDMA_CHANNEL0 => dma::InterruptHandler<peripherals::BDMA_CH0>;
        EXTI4 => SyncEdgeHandler;
        UART7 => usart::InterruptHandler<peripherals::UART7>;
        USART2 => usart::InterruptHandler<peripherals::USART2>;
        /// The slot ring guard's slot timer (`serial_tx::HeadSlotTickHandler`: the
        /// same guard once per HANS-100 slot).
        TIM7 => HeadSlotTickHandler;
    }
);

/// Input halves lost since boot, wrapping (`Stats::input_overruns`: an SPI or DMA ring
/// overrun, or a half the bridge's queue had no room for). Read-only, for the
/// hardware-in-the-loop tests: an XY3-100 input restarts its session after every
/// overrun of a line, so a test that sees a restart and no overrun knows the bridge
/// asked for it (`XY3_RESYNC`, lines out of step).
pub fn input_overruns() -> u32 {
    STATS.input_overruns.load(Ordering::Relaxed)
}

/// Misses of the output ring guards since boot (wrapping): halves of a waveform
/// head's ring (`wave_out::guard_misses`) and guard runs of a HANS-100 head's ring
/// (`serial_tx::head_guard_misses`) that found output the bridge had not refreshed
/// for this lap, each one a laser gate drop. An image drives one head, so one of
/// the two counts. Read-only, kept in the guards (never zeroed): the statistics
/// print its gain per second, the hardware-in-the-loop tests its change over a
/// stall.
pub fn guard_misses() -> u32 {
    crate::drivers::wave_out::guard_misses()
        .wrapping_add(crate::drivers::serial_tx::head_guard_misses())
}

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

/// Owns the watchdog and guards the laser gate. Runs in the thread-mode executor, so
/// if that executor stalls (a task that never yields, a deadlock) the watchdog is no
/// longer fed and resets the chip (the gate's pull-down then holds it off).
///
/// The gate pin goes to [`LASER_GATE`], where the bridge sets it from
/// `Output.laser.gate` every output batch. If the bridge stops completing batches
/// (its DMA stalled, or it never started: unsupported role, refused configuration),
/// the supervisor forces the gate off within one period.
#[embassy_executor::task]
pub(crate) async fn supervisor(
    iwdg: Peri<'static, IWDG1>,
    mut laser_gate: Output<'static>,
    watchdog_reset: bool,
) {
    laser_gate.set_low();
    LASER_GATE.lock(|g| *g.borrow_mut() = Some(laser_gate));
    let mut watchdog = IndependentWatchdog::new(iwdg, WATCHDOG_TIMEOUT_US);
    watchdog.unleash();
    defmt::info!("watchdog running, timeout {} us", WATCHDOG_TIMEOUT_US);

    let mut health = Health {
        input_valid: false,
        fault: false,
        watchdog_reset,
    };
    HEALTH.sender().send(health);

    let mut ticker = Ticker::every(SUPERVISOR_PERIOD);
    let mut last_beat = BRIDGE_BEAT.load(Ordering::Relaxed);
    loop {
        ticker.next().await;
        let beat = BRIDGE_BEAT.load(Ordering::Relaxed);
        let alive = beat != last_beat;
        last_beat = beat;
        if !alive {
            set_laser_gate(false);
        }
        let now = Health {
            input_valid: alive && LINK_RUNNING.load(Ordering::Relaxed),
            fault: !alive || HEAD_FAULT.load(Ordering::Relaxed),
            watchdog_reset,
        };
        if now != health {
            health = now;
            HEALTH.sender().send(health);
        }
        watchdog.pet();
    }
}

/// LED update period: the activity LED's flicker.
const LED_PERIOD: Duration = Duration::from_millis(50);
/// LED periods per half blink of the green LED while the link is not OK (1 Hz).
const BLINK_PERIODS: u32 = 10;

/// The three NUCLEO LEDs (README "Boot sequence and fail-safety"):
/// * LD1 green, **link OK**: on while valid input frames arrive; blinking at 1 Hz
///   otherwise (the thread executor runs, but there is no link);
/// * LD2 yellow, **activity**: flickers (toggles every 50 ms) while frames go out to
///   the head, off when none do;
/// * LD3 red, **fault**: on while the bridge reports a head alarm or lost head
///   status, or its loop is not running; on for good after a watchdog reset.
#[embassy_executor::task]
pub(crate) async fn leds(
    mut green: Output<'static>,
    mut yellow: Output<'static>,
    mut red: Output<'static>,
) {
    let mut health = HEALTH.anon_receiver();
    let mut h = Health {
        input_valid: false,
        fault: false,
        watchdog_reset: false,
    };
    let mut ticker = Ticker::every(LED_PERIOD);
    let mut frames = STATS.output_frames.load(Ordering::Relaxed);
    let mut periods = 0u32;
    loop {
        if let Some(now) = health.try_changed() {
            h = now;
        }
        periods = periods.wrapping_add(1);
        let blink_on = (periods / BLINK_PERIODS).is_multiple_of(2);
        green.set_level((h.input_valid || blink_on).into());
        let sent = STATS.output_frames.load(Ordering::Relaxed);
        if sent != frames {
            yellow.toggle();
        } else {
            yellow.set_low();
        }
        frames = sent;
        red.set_level((h.fault || h.watchdog_reset).into());
        ticker.next().await;
    }
}

/// Backchannel receive ring length (embassy's ring-buffered UART; 1024 bytes = 11 ms
/// at 921600 baud between reads).
const BACK_RING: usize = 1024;

/// The head backchannel's receive ring in SRAM3 (USART2 RX, DMA1 S5). Called once
/// per boot, by `app::head_xy3_backchannel`.
pub(crate) fn back_ring() -> &'static mut [u8; BACK_RING] {
    crate::dma_ring!(".sram3", u8, BACK_RING)
}
