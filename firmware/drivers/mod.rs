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

/// The ring index (`0..len`) of the item a circular DMA stream transfers next, from
/// its DMA_SxNDTR (RM0433 §15.5.6: NDTR counts the items left in this lap, `len`
/// down to 1, and reloads to `len` at the end of each lap in circular mode, §15.3).
/// 0 for an empty ring, and for NDTR 0 (a stream not running).
pub fn ring_index(ndtr: usize, len: usize) -> usize {
    len.saturating_sub(ndtr).checked_rem(len).unwrap_or(0)
}
