//! HANS-100 transmitter: keeps the circular SPI transmit ring (layout item 5) filled
//! ahead of the DMA, frame by frame. The same ring and writer serve the forward
//! channels (controller side of the bridge towards a HANS-100 head) and HANS STATUS
//! out (head side towards a HANS-100 controller).
//!
//! The SPI master sends the 125-byte ring forever at 12.5 MHz, i.e. 8 frame slots of
//! 125 bits back to back, which is exactly the continuous 100 kHz frame stream of the
//! spec (sender items 1-3). Between two DMA turns nothing is idle on the line, so
//! there is no separate idle pattern: "idle" means repeating a harmless frame, which
//! [`Transmitter::park`] writes into every slot (e.g. the last position, or
//! [`Frame::CENTRE`] at start-up).
//!
//! Each frame period the firmware reads the DMA's remaining-byte counter and calls
//! [`Transmitter::update`], which writes the slot two ahead of the one being sent:
//! far enough that neither the DMA nor the SPI FIFO (16 bytes) has fetched any of its
//! bytes, near enough that the frame goes out within 20-30 us. When updates came
//! late and slots were skipped, the skipped slots get the same frame, so the line
//! never replays a frame older than the latest one written.

use super::frame::{write_slot, DecodeError, Frame, FRAME_BITS, RING_BYTES, RING_SLOTS};

/// How many slots ahead of the one being sent a new frame is written.
pub const LEAD_SLOTS: usize = 2;

/// The slot the DMA is fetching when its remaining-byte counter (NDTR, counting
/// down from [`RING_BYTES`] each turn) reads `dma_remaining`. Values outside
/// `1..=RING_BYTES` are taken modulo the ring.
pub fn sending_slot(dma_remaining: usize) -> usize {
    let fetched = (RING_BYTES - dma_remaining % RING_BYTES) % RING_BYTES;
    (fetched * 8 / FRAME_BITS) % RING_SLOTS
}

/// Tracks which slot of the ring was written last.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Transmitter {
    last: Option<u8>,
}

impl Transmitter {
    /// A transmitter that has not written any slot yet.
    pub const fn new() -> Transmitter {
        Transmitter { last: None }
    }

    /// Fills every slot with `frame` (start-up, or parking the line on one frame
    /// before the DMA is started or after a fault).
    pub fn park(&mut self, buf: &mut [u8; RING_BYTES], frame: &Frame) -> Result<(), DecodeError> {
        for slot in 0..RING_SLOTS {
            write_slot(buf, slot, frame)?;
        }
        self.last = None;
        Ok(())
    }

    /// Writes `frame` into the slot [`LEAD_SLOTS`] ahead of the one being sent (see
    /// [`sending_slot`]), plus any slots skipped since the previous update that are
    /// still safely ahead of the DMA. Returns the slot written.
    pub fn update(
        &mut self,
        buf: &mut [u8; RING_BYTES],
        dma_remaining: usize,
        frame: &Frame,
    ) -> Result<usize, DecodeError> {
        let sending = sending_slot(dma_remaining);
        let target = (sending + LEAD_SLOTS) % RING_SLOTS;
        // Slots to write: after the last one written up to the target, but only those
        // at least LEAD_SLOTS ahead of the DMA (bounded by the ring size).
        let first = self
            .last
            .map_or(target, |l| (usize::from(l) + 1) % RING_SLOTS);
        let mut slot = first;
        for _ in 0..RING_SLOTS {
            let ahead = (slot + RING_SLOTS - sending) % RING_SLOTS;
            if ahead >= LEAD_SLOTS {
                write_slot(buf, slot, frame)?;
            }
            if slot == target {
                break;
            }
            slot = (slot + 1) % RING_SLOTS;
        }
        // `target` < 8 fits u8.
        self.last = Some(target as u8);
        Ok(target)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hans::read_slot;

    fn frame(n: u32) -> Frame {
        Frame::new(n, 0xF_FFFF - n, n ^ 0x5_5555).unwrap()
    }

    #[rustfmt::skip]
    const SENDING: &[(usize, usize)] = &[
        // (NDTR remaining, slot): slot k covers bytes 125k/8 .. (125k+124)/8.
        (125, 0),   // nothing fetched yet this turn: byte 0
        (110, 0),   // byte 15 = bits 120..127, starts in slot 0
        (109, 1),   // byte 16 = bit 128: slot 1
        (94, 1),    // byte 31 = bits 248..255: starts in slot 1 (bits 125..249)
        (1, 7),     // byte 124: last slot
        (0, 0),     // counter reload: start of the ring
    ];

    #[test]
    fn sending_slot_from_dma_counter() {
        for &(remaining, slot) in SENDING {
            assert_eq!(sending_slot(remaining), slot, "remaining {remaining}");
        }
    }

    #[test]
    fn park_fills_every_slot() {
        let mut buf = [0u8; RING_BYTES];
        let mut tx = Transmitter::new();
        tx.park(&mut buf, &Frame::CENTRE).unwrap();
        for slot in 0..RING_SLOTS {
            assert_eq!(read_slot(&buf, slot), Ok(Frame::CENTRE));
        }
    }

    #[test]
    fn update_writes_two_ahead_and_fills_skipped_slots() {
        let mut buf = [0u8; RING_BYTES];
        let mut tx = Transmitter::new();
        tx.park(&mut buf, &frame(0)).unwrap();
        // DMA in slot 0 -> write slot 2 only.
        assert_eq!(tx.update(&mut buf, 125, &frame(1)), Ok(2));
        assert_eq!(read_slot(&buf, 2), Ok(frame(1)));
        assert_eq!(read_slot(&buf, 3), Ok(frame(0)));
        // On time: DMA in slot 1 -> slot 3.
        assert_eq!(tx.update(&mut buf, 109, &frame(2)), Ok(3));
        assert_eq!(read_slot(&buf, 3), Ok(frame(2)));
        // Late by three frames: DMA in slot 4 -> slots 4, 5 are too close, 6 target.
        let remaining = RING_BYTES - 4 * FRAME_BITS / 8 - 1;
        assert_eq!(sending_slot(remaining), 4);
        assert_eq!(tx.update(&mut buf, remaining, &frame(3)), Ok(6));
        assert_eq!(read_slot(&buf, 6), Ok(frame(3)));
        assert_eq!(
            read_slot(&buf, 4),
            Ok(frame(0)),
            "slot being sent untouched"
        );
        assert_eq!(read_slot(&buf, 5), Ok(frame(0)), "next slot untouched");
        // Slots 0..=3 keep their frames (the ones before the sending slot are sent
        // again only after 6, 7 are refreshed).
        assert_eq!(read_slot(&buf, 2), Ok(frame(1)));
    }

    #[test]
    fn neighbours_survive_every_slot_write() {
        let mut buf = [0u8; RING_BYTES];
        let mut tx = Transmitter::new();
        tx.park(&mut buf, &frame(7)).unwrap();
        for s in 0..RING_SLOTS {
            let remaining = RING_BYTES - s * FRAME_BITS / 8;
            let target = tx.update(&mut buf, remaining, &frame(s as u32)).unwrap();
            assert_eq!(target, (sending_slot(remaining) + 2) % 8);
            for k in 0..RING_SLOTS {
                assert!(read_slot(&buf, k).is_ok(), "slot {k} broken after {s}");
            }
        }
    }
}
