//! The HANS-100 oversampling clock fs: TIM3 as a 50 % PWM at
//! [`HANS_FS_HZ`](crate::board::HANS_FS_HZ), wired to the SCK inputs of the
//! receive-only SPI slaves, so every HANS-100 sample is taken by this one clock
//! (README "Clock tree": 240 MHz / 6, exact on both silicon revisions). Two outputs
//! of the one timer: CH1 on PC6 drives the controller-side SCK bus (HANS-100
//! controller input, SPI1..5), CH2 on PC7 clocks SPI6 (HANS STATUS from the head).
//!
//! embassy's `SimplePwm` (RM0433 §39, general-purpose timer PWM mode 1) does all the
//! register work; this file only fixes the channels, rate and duty cycle so the
//! firmware and the HIL tests cannot drift apart. Each output starts held low: a
//! receiver that needs all its SPIs to count from the same first edge (the
//! controller input) starts them first and then lets its clock run ([`Fs::run`]).
//! Holding low is a compare value of 0 (PWM mode 1: the output is high while the
//! counter is below it, so never), which the preloaded CCR applies at the next
//! update event, i.e. within one fs period (RM0433 §39.3, output compare preload),
//! and never cuts a pulse short.

use embassy_stm32::gpio::OutputType;
use embassy_stm32::peripherals::{PC6, PC7, TIM3};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm, SimplePwmChannel};
use embassy_stm32::Peri;

use crate::board::HANS_FS_HZ;

/// One fs output. The timer runs for the rest of the boot (`SimplePwm::split`).
pub struct Fs(SimplePwmChannel<'static, TIM3>);

impl Fs {
    /// Lets the clock out (50 % duty).
    pub fn run(&mut self) {
        self.0.set_duty_cycle_fraction(1, 2);
    }

    /// Holds the output low: no clock edges.
    pub fn hold_low(&mut self) {
        self.0.set_duty_cycle_fully_off();
    }
}

/// Both fs outputs; an output whose pin was not given drives nothing.
pub struct FsOutputs {
    /// CH1: the controller-side SCK bus (PC6).
    pub ctrl: Fs,
    /// CH2: SPI6 SCK for the HANS STATUS input (PC7).
    pub status: Fs,
}

/// Starts TIM3 at fs with both outputs held low. Give only the pins of the HANS
/// inputs that run: PC6 must stay off the SCK bus unless the controller speaks
/// HANS-100 (the XY3-100 clock buffer drives that bus otherwise).
pub fn start(
    tim: Peri<'static, TIM3>,
    ctrl: Option<Peri<'static, PC6>>,
    status: Option<Peri<'static, PC7>>,
) -> FsOutputs {
    let pwm = SimplePwm::new(
        tim,
        ctrl.map(|p| PwmPin::new(p, OutputType::PushPull)),
        status.map(|p| PwmPin::new(p, OutputType::PushPull)),
        None,
        None,
        Hertz(HANS_FS_HZ),
        CountingMode::EdgeAlignedUp,
    );
    let ch = pwm.split();
    let mut out = FsOutputs {
        ctrl: Fs(ch.ch1),
        status: Fs(ch.ch2),
    };
    for fs in [&mut out.ctrl, &mut out.status] {
        fs.hold_low();
        fs.0.enable();
    }
    out
}
