//! XY2-100 STATUS as a plain level (`layouts.md` §7): a debounced GPIO input on the
//! head side, a GPIO output on the controller side.
//!
//! The input is sampled on a fixed tick (embassy-time's `Ticker`, i.e. the TIM2 time
//! driver, RM0433 §39; nothing here needs a timer of its own) and a new level is only
//! accepted after [`STABLE_SAMPLES`] equal samples in a row, so spikes on the long
//! cable do not flip the head's health. The line is slow by nature (a head's ready
//! signal), so a millisecond tick costs nothing and still reacts within milliseconds.
//! The level at start-up is reported too, once stable (`shared`'s
//! `LevelDebouncer`): a head in fault from power-up must be known as such.

use embassy_stm32::gpio::{Input, Level, Output};
use embassy_time::{Duration, Instant, Ticker};
use shared::xy2::status_line::LevelDebouncer;
use shared::xy2::{Health, StatusLevel};

/// Sample period.
pub const TICK: Duration = Duration::from_millis(1);
/// Equal samples needed to accept a level change (5 ms at 1 ms ticks).
pub const STABLE_SAMPLES: u16 = 5;

/// Debounced STATUS level input.
pub struct StatusIn<'d> {
    pin: Input<'d>,
    ticker: Ticker,
    debouncer: LevelDebouncer,
}

impl<'d> StatusIn<'d> {
    /// No level known until the line has been stable for [`STABLE_SAMPLES`].
    pub fn new(pin: Input<'d>, setting: StatusLevel) -> Self {
        Self {
            pin,
            ticker: Ticker::every(TICK),
            debouncer: LevelDebouncer::new(setting, STABLE_SAMPLES),
        }
    }

    /// Waits until the debounced level is first known or changes and returns the
    /// health it means.
    pub async fn changed(&mut self) -> Health {
        loop {
            self.ticker.next().await;
            let now = Instant::now().as_micros();
            if let Some(change) = self.debouncer.feed(now, self.pin.is_high()) {
                return change.health;
            }
        }
    }
}

/// STATUS level output.
pub struct StatusOut<'d> {
    pin: Output<'d>,
    setting: StatusLevel,
}

impl<'d> StatusOut<'d> {
    /// Drives "fault" until told otherwise (safe start-up: the controller must not
    /// see a ready head before the bridge knows the real head is ready).
    pub fn new(mut pin: Output<'d>, setting: StatusLevel) -> Self {
        pin.set_level(Level::from(setting.line_high(Health::Fault)));
        Self { pin, setting }
    }

    /// Drives the level that means `health`.
    pub fn set(&mut self, health: Health) {
        self.pin
            .set_level(Level::from(self.setting.line_high(health)));
    }
}
