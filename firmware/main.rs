//! XY bridge firmware for the STM32H743 (placeholder entry point, replaced by the
//! foundation work).
#![no_std]
#![no_main]

use embassy_executor::Spawner;
use {defmt_rtt as _, panic_probe as _};

#[embassy_executor::main]
async fn main(_spawner: Spawner) {
    let _p = embassy_stm32::init(Default::default());
    defmt::info!("xy-bridge {}", env!("CARGO_PKG_VERSION"));
}
