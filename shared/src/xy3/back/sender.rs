//! The backchannel transmitter (sans-IO): encodes packets into the caller's buffer
//! and puts SYNC packets in between so a receiver can (re)gain sync (XY3-100 §5.2).

use super::packet::{EncodeError, Packet};
use super::wire::{ty, HEAD, HEADER_LEN, MAX_PACKET_LEN};

/// A buffer of this size always holds what one [`Sender::send`] call writes: a SYNC
/// packet and the longest packet.
pub const SEND_BUF_LEN: usize = HEADER_LEN + MAX_PACKET_LEN;

/// The SYNC packet on the wire.
const SYNC_BYTES: [u8; HEADER_LEN] = [HEAD, ty::SYNC, 0];

/// Interleaves SYNC packets: one before the first packet, one whenever the last
/// SYNC is at least the interval old, and one before the first packet after a
/// baud-rate change. Times are microseconds from any monotonic clock.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Sender {
    interval_us: u64,
    last_sync_us: Option<u64>,
}

impl Default for Sender {
    fn default() -> Self {
        Self::new(Self::DEFAULT_SYNC_INTERVAL_US)
    }
}

impl Sender {
    /// Default SYNC interval: 50 ms, half the bridge's 100 ms upper bound so a
    /// packet that is late by less than that still keeps the bound.
    pub const DEFAULT_SYNC_INTERVAL_US: u64 = 50_000;

    /// A sender that puts a SYNC at least every `interval_us` microseconds of
    /// traffic (and before the first packet).
    pub const fn new(interval_us: u64) -> Self {
        Sender {
            interval_us,
            last_sync_us: None,
        }
    }

    /// The receiver may have lost sync because the baud rate changed: the next
    /// packet is preceded by a SYNC.
    pub fn note_rate_change(&mut self) {
        self.last_sync_us = None;
    }

    /// Whether the next packet would get a SYNC in front of it at time `now_us`.
    /// A clock that went backwards counts as "due" (the difference wraps to a huge
    /// value), which errs on the side of sending a SYNC.
    pub fn sync_due(&self, now_us: u64) -> bool {
        match self.last_sync_us {
            None => true,
            Some(last) => now_us.wrapping_sub(last) >= self.interval_us,
        }
    }

    /// Writes `packet` to `out`, preceded by a SYNC packet if one is due, and returns
    /// the number of bytes written. On error nothing is sent and the state is kept.
    pub fn send(
        &mut self,
        now_us: u64,
        packet: &Packet,
        out: &mut [u8],
    ) -> Result<usize, EncodeError> {
        let is_sync = packet.ty() == ty::SYNC;
        let prefix = if self.sync_due(now_us) && !is_sync {
            HEADER_LEN
        } else {
            0
        };
        let available = out.len();
        let (head, rest) = out
            .split_at_mut_checked(prefix)
            .ok_or(EncodeError::BufferTooSmall {
                needed: prefix,
                available,
            })?;
        let n = packet.encode(rest).map_err(|e| match e {
            EncodeError::BufferTooSmall { needed, .. } => EncodeError::BufferTooSmall {
                needed: needed + prefix,
                available,
            },
            other => other,
        })?;
        if prefix != 0 {
            head.copy_from_slice(&SYNC_BYTES);
        }
        if prefix != 0 || is_sync {
            self.last_sync_us = Some(now_us);
        }
        Ok(prefix + n)
    }

    /// For an idle line: writes a SYNC packet if one is due (returning 3), else
    /// nothing (returning 0). It counts as the due SYNC: a receiver completes its
    /// sync sequence with the head byte of the next packet, however late that comes.
    pub fn poll(&mut self, now_us: u64, out: &mut [u8]) -> Result<usize, EncodeError> {
        if !self.sync_due(now_us) {
            return Ok(0);
        }
        self.send(now_us, &Packet::Sync, out)
    }
}
