//! On-target test cases for `shared`, run by `bin/tests.rs` on the emulated Cortex-M7.
//! They check that the code behaves on the real instruction set and ABI as it does on
//! the host (shifts by the full width, 32-bit overflow, thumb codegen of `const fn`s).
//!
//! A case is a plain `fn()` that panics on failure (`assert!`, `assert_eq!`). To add
//! cases for a module, add a submodule here with its own `CASES` list and append it
//! to [`ALL`] (by hand: a `no_std` crate has no test collector).

pub mod hans;
pub mod position;
pub mod prng;
pub mod ring_guard;
pub mod xy2;
pub mod xy3;
pub mod xy3_back;

/// One named test case.
pub struct Case {
    /// Printed as `test <name> ... ok`.
    pub name: &'static str,
    /// Panics on failure.
    pub run: fn(),
}

/// Every case, in run order.
pub const ALL: &[&[Case]] = &[
    position::CASES,
    xy2::CASES,
    xy3::CASES,
    xy3_back::CASES,
    hans::CASES,
    ring_guard::CASES,
];
