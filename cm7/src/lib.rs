//! `shared` on an emulated Cortex-M7 (QEMU `mps2-an500`): the pieces both binaries use.
//!
//! - `bin/tests.rs`: the on-target test runner ([`tests::ALL`]).
//! - `bin/bench.rs`: per-frame instruction counts of [`workloads::ALL`], measured by the
//!   QEMU plugin in `plugin/insn_count.c` between `bench_start` and `bench_end`.
//!
//! Everything talks to the host over Arm semihosting (QEMU runs with
//! `-semihosting-config enable=on,target=native`); the exit status of QEMU is the
//! verdict, so [`exit`] and the panic handler here are the only ways out.
//!
//! Why not `embedded-test` (0.7): its harness lists and selects tests through probe-rs
//! (its semihosting list/run-by-name path is gone in 0.7 and tells the user to upgrade
//! probe-rs), so it cannot run under plain QEMU; a list of `fn()` is all we need.
#![no_std]
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod tests;
pub mod workloads;

use cortex_m_semihosting::{debug, hprintln};

/// Ends the program: QEMU exits with status 0 if `ok`, nonzero otherwise.
pub fn exit(ok: bool) -> ! {
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    // Only reached if the host ignored the exit request (no semihosting): stop here
    // rather than run on.
    loop {
        cortex_m::asm::bkpt();
    }
}

/// A failed assertion (or any panic) ends the run with a nonzero QEMU exit status,
/// after printing where and why; there is no unwinding on the MCU target.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("PANIC: {}", info);
    exit(false)
}
