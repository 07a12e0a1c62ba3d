//! Host-side support for the XY bridge: line-level simulation, VCD I/O and the
//! `bridge-sim` tool. Integration tests live in `tests/`.
#![deny(missing_docs)]
