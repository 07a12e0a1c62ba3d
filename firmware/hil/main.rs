//! Hardware-in-the-loop self-tests (issue 6): every head-side output is looped back to
//! a controller-side input with jumper wires on one NUCLEO-H743ZI2, and the real
//! drivers send and receive through them. Wiring and how to run: README.md (section "Firmware"),
//! "Hardware-in-the-loop self-tests". `embedded-test` runs each test after a reset, so
//! every test starts from a fresh `board::init`.
#![no_std]
#![no_main]

use defmt_rtt as _;
use embassy_time::Duration;

mod backchannel;
mod boot;
mod e2e;
mod hans;
mod xy2;
mod xy2_status;
mod xy3;

/// A small deterministic bit source for test patterns (xorshift32).
struct Prng(u32);

impl Prng {
    fn bit(&mut self) -> bool {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        self.0 & 1 == 1
    }
}

/// Head-side port-D bits used here: pair 1, 2, 3.
const P1: u32 = 0;
const P2: u32 = 1;
const P3: u32 = 2;
const P4: u32 = 3;
/// Every output low.
const ALL_LOW: u32 = (1 << (P1 + 16)) | (1 << (P2 + 16)) | (1 << (P3 + 16));
/// A timeout long enough for a few DMA halves.
const WAIT: Duration = Duration::from_millis(200);

fn level(bit: u32, high: bool) -> u32 {
    if high {
        1 << bit
    } else {
        1 << (bit + 16)
    }
}
