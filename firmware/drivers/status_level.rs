//! XY2-100 STATUS as a plain level (`layouts.md` §7): a debounced GPIO input on the
//! head side, a GPIO output on the controller side.
//!
//! The input is sampled on a fixed tick (embassy-time's `Ticker`, i.e. the TIM2 time
//! driver, RM0433 §39; nothing here needs a timer of its own) and a new level is only
//! accepted after [`STABLE_SAMPLES`] equal samples in a row, so spikes on the long
//! cable do not flip the head's health. The line is slow by nature (a head's ready
//! signal), so a millisecond tick costs nothing and still reacts within milliseconds.

use embassy_stm32::gpio::{Input, Level, Output};
use embassy_time::{Duration, Ticker};
use shared::xy2::{Health, StatusLevel};

/// Sample period.
pub const TICK: Duration = Duration::from_millis(1);
/// Equal samples needed to accept a level change (5 ms at 1 ms ticks).
pub const STABLE_SAMPLES: u8 = 5;

/// Debounced STATUS level input.
pub struct StatusIn<'d> {
    pin: Input<'d>,
    setting: StatusLevel,
    ticker: Ticker,
    level: bool,
    run: u8,
}

impl<'d> StatusIn<'d> {
    /// Starts from the level the line has now.
    pub fn new(pin: Input<'d>, setting: StatusLevel) -> Self {
        let level = pin.is_high();
        Self {
            pin,
            setting,
            ticker: Ticker::every(TICK),
            level,
            run: 0,
        }
    }

    /// Waits until the debounced level changes and returns the health it means.
    pub async fn changed(&mut self) -> Health {
        loop {
            self.ticker.next().await;
            let now = self.pin.is_high();
            if now == self.level {
                self.run = 0;
                continue;
            }
            self.run = self.run.saturating_add(1);
            if self.run >= STABLE_SAMPLES {
                self.level = now;
                self.run = 0;
                return self.setting.health(now);
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
