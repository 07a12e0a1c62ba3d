//! Everything the XY bridge decides without hardware: protocol codecs, the neutral
//! frame/status model, line-level receivers and transmitters, and the bridge engine.
//!
//! The crate is `no_std` and allocation-free so the same code runs in the STM32H7
//! firmware, in host simulations and tests, and on an emulated Cortex-M7. Nothing here
//! awaits or touches registers: decoders are state machines fed with words or samples
//! that return events, encoders fill caller-provided buffers.
//!
//! Modules, one per protocol plus the neutral model:
//! - [`model`]: protocol-neutral forward frame and head status.
//! - [`xy2`]: XY2-100 and XY2-100E.
//! - [`xy3`]: XY3-100 forward frames, commands and the RS485 backchannel.
//! - [`hans`]: the HANS-100 protocol.
//! - [`bridge`]: the bridge engine (configuration, translation, supervision, status).
//! - [`governor`]: the load governor that keeps a decoder above thread mode within
//!   its share of the core.
//! - [`head_port`]: the board's head-side waveform pins and ticks (firmware and host
//!   pipeline alike).
//! - [`rs485`]: the RS-485 driver-enable timing check the HIL test runs on captured
//!   UART TX and DE edges.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod bridge;
pub mod governor;
pub mod hans;
pub mod head_port;
pub mod model;
pub mod rs485;
pub mod xy2;
pub mod xy3;
