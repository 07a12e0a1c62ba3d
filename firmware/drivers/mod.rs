//! Peripheral drivers that embassy-stm32 0.6 lacks, one file each, register sequences
//! explained with RM0433 section references (`backchannel` only configures embassy's
//! own UART driver and says why that suffices).

pub mod backchannel;
pub mod hans_lines;
pub mod oversample_clock;
pub mod serial_tx;
pub mod spi_slave_rx;
pub mod status_level;
pub mod status_word_out;
pub mod sync_marks;
pub mod wave_out;
pub mod xy2_sampler;
