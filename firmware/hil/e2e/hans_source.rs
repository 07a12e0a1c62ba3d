//! The HANS-100 controller of the end-to-end tests with a HANS-100 controller: an
//! SAI block the pairing leaves free (`drivers::serial_tx`) replays a ring of eight
//! frames at 12.5 MHz into the controller-side channel inputs, and one slot of it
//! carries a frame with a flipped bit for a while. The slot-safe ring updates serve
//! the test head's STATUS ring too (a HANS-100 head).

use embassy_time::Duration;
use shared::hans::frame::{read_slot, write_slot, Frame, FRAME_BITS, RING_BYTES, RING_SLOTS};
use shared::hans::tx::LEAD_SLOTS;
use xy_bridge::drivers::serial_tx::SerialTx;

/// The ring slot that carries the frame with a flipped bit for [`BAD_FOR`],
/// [`BAD_AT`] into the run (once the link runs: in normal mode a check failure
/// breaks the recovery run, so a bad frame every lap would keep the link down).
pub(super) const BAD_SLOT: usize = 5;
pub(super) const BAD_AT: Duration = Duration::from_millis(100);
pub(super) const BAD_FOR: Duration = Duration::from_millis(10);
/// The frame number whose corrupted copy is sent: no other slot carries it.
pub(super) const BAD_FRAME: u32 = RING_SLOTS as u32;

/// Head positions (X, Y, Z, 16 bits) of the frame in ring slot `slot`: none is
/// the park position's 0x8000 on X, and no two slots share an X.
pub(super) fn positions(slot: u32) -> [u16; 3] {
    [
        (0x1000 + slot * 0x1357) as u16,
        (0x2345 + slot * 0x0F0F) as u16,
        (0xC000 - slot * 0x0777) as u16,
    ]
}

/// The controller's frame in slot `slot`: each position MSB-aligned in its
/// 20-bit word (low four bits zero, so a 20 -> 16-bit resize is exact), DATA3
/// with extension code 0 (a Z position: `shared::hans::ext`).
pub(super) fn frame_of(slot: u32) -> Frame {
    let [x, y, z] = positions(slot).map(|v| u32::from(v) << 4);
    // Every word is below 2^20.
    Frame::new(x, y, z).unwrap()
}

/// The controller's ring (slot `s` carries [`frame_of`]`(s)`), and the same ring
/// with [`BAD_FRAME`]'s pattern in [`BAD_SLOT`], one bit flipped in the middle
/// (inside a complement pair), as `hans_controller_loopback` flips it.
pub(super) fn controller_rings() -> ([u8; RING_BYTES], [u8; RING_BYTES]) {
    let mut ring = [0u8; RING_BYTES];
    for slot in 0..RING_SLOTS {
        write_slot(&mut ring, slot, &frame_of(slot as u32)).unwrap();
    }
    let mut bad = ring;
    write_slot(&mut bad, BAD_SLOT, &frame_of(BAD_FRAME)).unwrap();
    let flip = BAD_SLOT * FRAME_BITS + 60;
    bad[flip / 8] ^= 0x80 >> (flip % 8);
    assert!(
        read_slot(&bad, BAD_SLOT).is_err(),
        "the flipped frame passes"
    );
    assert!(
        (0..RING_SLOTS as u32).all(|s| positions(s) != positions(BAD_FRAME)),
        "BAD_FRAME"
    );
    (ring, bad)
}

/// Copies slot `slot`'s bits of `image` into `ring` (its first and last bytes
/// are shared with the neighbouring slots, which keep theirs).
pub(super) fn copy_slot(ring: &mut [u8; RING_BYTES], image: &[u8; RING_BYTES], slot: usize) {
    for bit in slot * FRAME_BITS..(slot + 1) * FRAME_BITS {
        let mask = 0x80u8 >> (bit % 8);
        ring[bit / 8] = ring[bit / 8] & !mask | image[bit / 8] & mask;
    }
}

/// Runs `f` on a ring with interrupts off, only while slot `slot` is at least
/// `LEAD_SLOTS` ahead of the one the DMA fetches and not the one just behind it
/// (so neither the DMA nor the SAI FIFO holds any of its bits:
/// `drivers::serial_tx`); returns whether it ran. A slot is then never sent half
/// old, half new.
pub(super) fn update_ahead(
    tx: &mut SerialTx<'_>,
    slot: usize,
    f: impl FnOnce(&mut [u8; RING_BYTES]),
) -> bool {
    cortex_m::interrupt::free(|_| {
        let ahead = (slot + RING_SLOTS - tx.sending_slot()) % RING_SLOTS;
        let safe = (LEAD_SLOTS..RING_SLOTS - 1).contains(&ahead);
        if safe {
            tx.update(f);
        }
        safe
    })
}

/// The flipped frame's burst: [`BAD_SLOT`] of `bad` into the controller's ring
/// for [`BAD_FOR`] (about 125 laps), then `good`'s slot back, each written only
/// while the slot is safely ahead ([`update_ahead`]).
pub(super) async fn bad_burst(
    tx: &mut SerialTx<'_>,
    good: &[u8; RING_BYTES],
    bad: &[u8; RING_BYTES],
) {
    for image in [bad, good] {
        while !update_ahead(tx, BAD_SLOT, |ring| copy_slot(ring, image, BAD_SLOT)) {
            embassy_time::Timer::after_micros(10).await;
        }
        embassy_time::Timer::after(BAD_FOR).await;
    }
}

/// Switches every slot of a running ring to `image` so that the line carries no
/// frame torn between the two and never an old frame after a new one: with
/// interrupts off, the slots from `LEAD_SLOTS` ahead of the one being fetched
/// to the end of the lap, then, once the DMA has left the first two, those two
/// (they come round again 60 us later). Interrupts stay off for at most two slot
/// periods (20 us) and a few microseconds of copying.
#[cfg(bridge_pairing = "hans_to_hans")]
pub(super) fn switch_ring(tx: &mut SerialTx<'_>, image: &[u8; RING_BYTES]) {
    cortex_m::interrupt::free(|_| {
        let first = tx.sending_slot();
        tx.update(|ring| {
            for k in LEAD_SLOTS..RING_SLOTS {
                copy_slot(ring, image, (first + k) % RING_SLOTS);
            }
        });
        // Two slot periods; a ring that stopped would hold interrupts off for
        // good, so the wait is bounded (far beyond 20 us).
        let mut spins = 0u32;
        while (tx.sending_slot() + RING_SLOTS - first) % RING_SLOTS < LEAD_SLOTS {
            spins += 1;
            assert!(spins < 1_000_000, "the ring's DMA stands still");
        }
        tx.update(|ring| {
            for k in 0..LEAD_SLOTS {
                copy_slot(ring, image, (first + k) % RING_SLOTS);
            }
        });
    })
}
