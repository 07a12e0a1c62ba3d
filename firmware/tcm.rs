//! Loading the tightly coupled memories at reset: the hot code into ITCM, the hot
//! per-frame state into DTCM (what goes where: `memory.x`; why: README "Firmware",
//! "Memory placement").
//!
//! The work is done by `__pre_init`, the hook cortex-m-rt's reset handler calls
//! first (`bl __pre_init`, before it zeroes `.bss`, copies `.data`, enables the FPU
//! and calls `main`). Doing it there rather than at the top of `main`:
//! * nothing can run ITCM code or touch DTCM state before it: embassy's `main`
//!   macro runs its own code (executor set-up) before the first line of our `main`,
//!   and the HIL test binary has a `main` of its own; the hook serves both;
//! * it is sound only because it is assembly. cortex-m-rt documents that a Rust
//!   `#[pre_init]` function is undefined behaviour (no statics, no stack promises
//!   before RAM is initialised), so this one touches nothing but registers, the
//!   linker's symbols and the memory it initialises.
//!
//! Steps (all with 64-bit transfers: the section bounds and load addresses are
//! 8-byte aligned, `memory.x`):
//! 1. set the enable bit of the Cortex-M7's ITCMCR / DTCMCR (SCB 0xE000_EF90 /
//!    0xE000_EF94, Cortex-M7 TRM DDI 0489, "TCM control registers"). RM0433
//!    section 2.3.2 maps ITCM (64 KiB) at 0x0000_0000 and DTCM (128 KiB) at
//!    0x2000_0000 with no enable step, i.e. enabled out of reset; setting the bit
//!    again costs nothing and removes the dependence on that reset value. DSB + ISB
//!    so the accesses below see the enabled TCMs;
//! 2. copy `.itcm` (code) from its flash load image. ITCM keeps 8 ECC bits per
//!    64-bit word (RM0433 section 3.2, "RAMECC main features"); a narrower write is
//!    a read-modify-write of a word whose ECC is still random after power-on, so the
//!    copy writes whole aligned doublewords (STRD);
//! 3. copy `.dtcm` (initialised state) and zero `.dtcm_bss` (zeroed state);
//! 4. DSB + ISB: the code in ITCM was written through the data side; the DSB
//!    completes the writes and the ISB discards anything already fetched, as the
//!    ARMv7-M architecture requires after writing instructions and before running
//!    them (TCM accesses are never cached, so no I-cache maintenance is needed).
//!
//! [`itcm`] and [`itcm_load_image`] let the HIL test check the result on the board.

use core::ops::Range;

core::arch::global_asm!(
    ".section .text.__pre_init,\"ax\",%progbits",
    ".global __pre_init",
    ".type __pre_init,%function",
    ".thumb_func",
    "__pre_init:",
    // 1. Enable ITCM and DTCM (bit 0 of ITCMCR / DTCMCR).
    "ldr r0, =0xE000EF90",
    "ldr r1, [r0]",
    "orr r1, r1, #1",
    "str r1, [r0]",
    "ldr r1, [r0, #4]",
    "orr r1, r1, #1",
    "str r1, [r0, #4]",
    "dsb",
    "isb",
    // 2. .itcm <- its load image (r0 destination, r1 end, r2 source).
    "ldr r0, =__sitcm",
    "ldr r1, =__eitcm",
    "ldr r2, =__siitcm",
    "0:",
    "cmp r0, r1",
    "bhs 1f",
    "ldrd r3, r12, [r2], #8",
    "strd r3, r12, [r0], #8",
    "b 0b",
    "1:",
    // 3. .dtcm <- its load image, then .dtcm_bss <- 0.
    "ldr r0, =__sdtcm",
    "ldr r1, =__edtcm",
    "ldr r2, =__sidtcm",
    "2:",
    "cmp r0, r1",
    "bhs 3f",
    "ldrd r3, r12, [r2], #8",
    "strd r3, r12, [r0], #8",
    "b 2b",
    "3:",
    "ldr r0, =__sdtcm_bss",
    "ldr r1, =__edtcm_bss",
    "movs r2, #0",
    "movs r3, #0",
    "4:",
    "cmp r0, r1",
    "bhs 5f",
    "strd r2, r3, [r0], #8",
    "b 4b",
    "5:",
    // 4. Writes done and visible to instruction fetches before anything runs.
    "dsb",
    "isb",
    "bx lr",
    ".ltorg",
    ".size __pre_init, . - __pre_init",
);

extern "C" {
    /// Start of `.itcm` in ITCM (run address).
    static __sitcm: u8;
    /// End of `.itcm` in ITCM.
    static __eitcm: u8;
    /// Start of `.itcm`'s load image in flash.
    static __siitcm: u8;
}

/// Where the hot code runs: the address range of `.itcm` in ITCM.
pub fn itcm() -> Range<usize> {
    // Only the addresses of the linker's symbols are taken (no read, so no `unsafe`).
    core::ptr::addr_of!(__sitcm) as usize..core::ptr::addr_of!(__eitcm) as usize
}

/// The running ITCM code and the flash image it was copied from, as byte slices of
/// equal length.
pub fn itcm_load_image() -> (&'static [u8], &'static [u8]) {
    let run = itcm();
    let len = run.end - run.start;
    // SAFETY: both ranges are what the linker laid out for `.itcm` (memory.x):
    // `len` bytes at its run address in ITCM, initialised by `__pre_init` before any
    // Rust code ran, and `len` bytes of its load image in flash. Neither is written
    // after reset, so shared slices over them are valid for the whole run.
    unsafe {
        (
            core::slice::from_raw_parts(run.start as *const u8, len),
            core::slice::from_raw_parts(core::ptr::addr_of!(__siitcm), len),
        )
    }
}
