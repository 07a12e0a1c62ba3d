//! Peripheral drivers that embassy-stm32 0.6 lacks, one file each, register sequences
//! explained with RM0433 section references.

pub mod spi_slave_rx;
