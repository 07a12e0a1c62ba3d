//! DMA ring storage in the RAM the DMA engines reach.
//!
//! `.sram1`..`.sram4` are NOLOAD (`memory.x`): nothing initialises them at reset, so
//! a ring is a `MaybeUninit` static that [`dma_ring!`] zeroes before handing out the
//! only `&'static mut` to it. SRAM1..3 serve DMA1/DMA2, SRAM4 serves BDMA (SPI6).

/// Zeroes a fresh ring of `$n` `$t` in section `$section` and returns
/// `&'static mut [$t; $n]`.
///
/// Must be expanded in code that runs at most once per boot (in the firmware each use
/// site is in a task that `app` spawns once from a pool of one, and that never
/// returns; in the HIL tests each test runs once per reset), so the returned
/// reference is unique.
#[macro_export]
macro_rules! dma_ring {
    ($section:literal, $t:ty, $n:expr) => {{
        #[link_section = $section]
        static mut RING: core::mem::MaybeUninit<[$t; $n]> = core::mem::MaybeUninit::uninit();
        // SAFETY: the use site runs at most once per boot (macro docs), so this is the
        // only reference to RING ever created; `write` initialises every element
        // before the reference is returned, so no uninitialised memory is read.
        unsafe { (*core::ptr::addr_of_mut!(RING)).write([0; $n]) }
    }};
}
