//! The HANS-100 oversampling clock fs: TIM3 CH2 as a 50 % PWM at
//! [`HANS_FS_HZ`](crate::board::HANS_FS_HZ) on PC7, wired to the SCK input of the
//! receive-only SPI slaves, so every HANS-100 sample is taken by this one clock
//! (README "Clock tree": 240 MHz / 6, exact on both silicon revisions).
//!
//! embassy's `SimplePwm` (RM0433 §39, general-purpose timer PWM mode 1) does all the
//! register work; this file only fixes the channel, rate and duty cycle so the
//! firmware's STATUS input and the HIL tests cannot drift apart.

use embassy_stm32::gpio::OutputType;
use embassy_stm32::peripherals::{PC7, TIM3};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm};
use embassy_stm32::Peri;

use crate::board::HANS_FS_HZ;

/// Starts fs; it runs for as long as the returned timer lives.
pub fn start(tim: Peri<'static, TIM3>, pin: Peri<'static, PC7>) -> SimplePwm<'static, TIM3> {
    let mut pwm = SimplePwm::new(
        tim,
        None,
        Some(PwmPin::new(pin, OutputType::PushPull)),
        None,
        None,
        Hertz(HANS_FS_HZ),
        CountingMode::EdgeAlignedUp,
    );
    {
        let mut fs = pwm.ch2();
        fs.set_duty_cycle_fraction(1, 2);
        fs.enable();
    }
    pwm
}
