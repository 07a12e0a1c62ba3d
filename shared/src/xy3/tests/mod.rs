//! Tests of the XY3-100 forward codec: hand-worked tables, bad input, round trips and
//! error detection.

mod detection;
mod props;
mod tables;
