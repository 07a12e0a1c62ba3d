//! Host-side support for the XY bridge: line-level simulation, VCD I/O and the
//! `bridge-sim` tool. Integration tests live in `tests/`.
//!
//! Layers (all protocol-agnostic; the codecs live in `shared`):
//! - [`wave`] — the waveform model (named 1-bit signals on a picosecond axis);
//! - [`vcd_io`] — VCD captures in, VCD files out;
//! - [`line`] — waveforms <-> the firmware's DMA buffers, and a serial frame generator;
//! - [`impair`] — reproducible line impairments (rate offset, jitter, asymmetric
//!   edge delays, skew, noise, stuck/broken channels, clock gaps);
//! - [`pipeline`] — the whole bridge (receiver -> engine -> transmitter, status back)
//!   on DMA buffers with simulated time, and its task graph;
//! - [`sim`] — the `bridge-sim` tool's commands and JSON-lines formats.
#![deny(missing_docs)]
// `deny`, not `forbid`: the task graph's executor module (`pipeline::tasks`)
// needs embassy's `unsafe` poll and pender, and is the one exception.
#![deny(unsafe_code)]

pub mod impair;
pub mod line;
pub mod pipeline;
pub mod sim;
pub mod vcd_io;
pub mod wave;
