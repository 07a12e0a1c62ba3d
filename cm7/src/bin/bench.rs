//! Instruction-count bench: for each workload of [`cm7::workloads::GROUPS`] it prints
//! `BENCH <name> <frames>` and then runs the workload, which brackets its measured part
//! with calls to `bench_start` and `bench_end`. The QEMU plugin (`plugin/insn_count.c`) counts the guest
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
extern "C" fn bench_start() {
    WINDOWS.fetch_add(1, Ordering::Relaxed);
}

/// Window end marker (see [`bench_start`]).
#[inline(never)]
#[no_mangle]
extern "C" fn bench_end() {
    black_box(WINDOWS.load(Ordering::Relaxed));
}

#[entry]
fn main() -> ! {
    let mut window = cm7::workloads::Window::new(bench_start, bench_end);
    for group in cm7::workloads::GROUPS {
        for w in *group {
            hprintln!("BENCH {} {}", w.name, w.frames);
            black_box((w.run)(&mut window));
        }
    }
    hprintln!("BENCH done");
    cm7::exit(true)
}
