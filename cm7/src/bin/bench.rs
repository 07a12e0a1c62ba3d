//! Instruction-count bench: for each workload of [`cm7::workloads::ALL`] it prints
//! `BENCH <name> <frames>` and then runs the workload between calls to `bench_start`
//! and `bench_end`. The QEMU plugin (`plugin/insn_count.c`) counts the guest
//! instructions executed from the entry of one to the entry of the other and prints
//! one count per window; `cargo xtask test` pairs the n-th count with the n-th name.
//!
//! The first workload is empty (0 frames): its count is the fixed cost of the window
//! itself (the marker calls and the indirect call), which xtask subtracts from the others.
#![no_std]
#![no_main]

use core::hint::black_box;
use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;

/// How many windows have started; also keeps the two markers' bodies different.
static WINDOWS: AtomicU32 = AtomicU32::new(0);

/// Window start marker. Never inlined and given a body distinct from `bench_end`'s so
/// the linker cannot fold the two into one address (the plugin finds them by address).
#[inline(never)]
#[no_mangle]
pub extern "C" fn bench_start() {
    WINDOWS.fetch_add(1, Ordering::Relaxed);
}

/// Window end marker (see [`bench_start`]).
#[inline(never)]
#[no_mangle]
pub extern "C" fn bench_end() {
    black_box(WINDOWS.load(Ordering::Relaxed));
}

#[entry]
fn main() -> ! {
    let mut input = [[0u32; cm7::workloads::WORDS]; cm7::workloads::FRAMES];
    for w in cm7::workloads::ALL {
        (w.prepare)(&mut input);
        hprintln!("BENCH {} {}", w.name, w.frames);
        bench_start();
        let out = (w.run)(black_box(&input));
        bench_end();
        black_box(out);
    }
    hprintln!("BENCH done");
    cm7::exit(true)
}
