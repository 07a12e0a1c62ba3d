//! On-target test runner: runs every case of [`cm7::tests::ALL`] in order on the
//! emulated Cortex-M7, one `test <name> ... ok` line each, then the summary line that
//! `cargo xtask test` parses. A failing case panics: the panic handler prints the
//! message and QEMU exits nonzero, so the first failure ends the run.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::{hprint, hprintln};

#[entry]
fn main() -> ! {
    let mut passed = 0u32;
    for case in cm7::tests::ALL.iter().flat_map(|cases| cases.iter()) {
        hprint!("test {} ... ", case.name);
        (case.run)();
        hprintln!("ok");
        passed += 1;
    }
    hprintln!("cm7 tests: {} passed, 0 failed", passed);
    cm7::exit(true)
}
