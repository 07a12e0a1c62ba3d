//! The streaming receiver for the backchannel: bytes in, events out (sans-IO).
//!
//! Synchronisation follows XY3-100 §5.2 (see the module docs of `back` for the rules
//! in our words). Per byte the work is constant and nothing is allocated; the
//! payload is gathered in a 255-byte buffer inside the parser and handed out by
//! reference, so an event borrows the parser until the next byte is pushed.

use heapless::Vec;

use super::wire::{LengthRule, HEAD};

/// The byte sequence that (re)establishes sync: a SYNC packet and the head byte of
/// the packet after it.
const SYNC_SEQUENCE: [u8; 4] = [HEAD, super::wire::ty::SYNC, 0, HEAD];

/// A complete packet as received: its type and payload (not yet typed; see
/// [`super::Packet::decode`]).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RawPacket<'a> {
    /// The type byte.
    pub ty: u8,
    /// The payload; its length satisfies the type's rule if the type is known.
    pub payload: &'a [u8],
}

/// Why the parser fell out of sync.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LostSyncReason {
    /// The byte after a complete packet was not the head byte 0x48.
    MissingHead {
        /// The byte found instead.
        byte: u8,
    },
    /// A known packet type arrived with a length its rule does not allow.
    BadLength {
        /// The packet type.
        ty: u8,
        /// The length byte.
        len: u8,
    },
}

impl core::fmt::Display for LostSyncReason {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::MissingHead { byte } => {
                write!(f, "byte {byte:#04x} after a packet instead of head 0x48")
            }
            Self::BadLength { ty, len } => {
                write!(f, "packet type {ty:#04x} with invalid length {len}")
            }
        }
    }
}

/// What one pushed byte produced.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event<'a> {
    /// A complete packet, reported as soon as its last byte arrived.
    Packet(RawPacket<'a>),
    /// The parser found the sync sequence and is in sync again (also the first time).
    Resynced {
        /// Bytes discarded since sync was lost (or since the start).
        dropped: u32,
    },
    /// The parser fell out of sync and discards bytes until the next sync sequence.
    LostSync {
        /// What broke the framing.
        reason: LostSyncReason,
    },
}

/// Running totals, for diagnostics.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Stats {
    /// Packets delivered (including SYNC packets received while in sync).
    pub packets: u32,
    /// Times sync was (re)established, the first time included.
    pub resyncs: u32,
    /// Times sync was lost.
    pub lost_sync: u32,
    /// Bytes discarded while out of sync, including the header of a packet whose
    /// length broke its rule. Bytes that may still turn out to be the sync sequence
    /// are only counted once they cannot.
    pub dropped_bytes: u32,
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
enum State {
    /// Out of sync; `matched` bytes of [`SYNC_SEQUENCE`] have been seen.
    Hunt { matched: u8 },
    /// In sync, between packets: the next byte must be the head.
    Head,
    /// Head seen, type next.
    Type,
    /// Type seen, length next.
    Length { ty: u8 },
    /// Collecting `len` payload bytes (at least one).
    Payload { ty: u8, len: u8 },
}

/// What a byte did, without borrowing the payload buffer (see [`Parser::push`]).
#[derive(Clone, Copy)]
enum Step {
    Packet(u8),
    Resynced(u32),
    LostSync(LostSyncReason),
}

/// The backchannel receiver. Starts out of sync.
#[derive(Clone, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Parser {
    state: State,
    payload: Vec<u8, 255>,
    /// Bytes discarded since sync was lost.
    dropped: u32,
    stats: Stats,
}

impl Default for Parser {
    fn default() -> Self {
        Self::new()
    }
}

impl Parser {
    /// A parser that is out of sync and has seen nothing.
    pub const fn new() -> Self {
        Parser {
            state: State::Hunt { matched: 0 },
            payload: Vec::new(),
            dropped: 0,
            stats: Stats {
                packets: 0,
                resyncs: 0,
                lost_sync: 0,
                dropped_bytes: 0,
            },
        }
    }

    /// Whether the parser is currently in sync.
    pub fn in_sync(&self) -> bool {
        !matches!(self.state, State::Hunt { .. })
    }

    /// The running totals.
    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// Feeds one byte. At most one event results; a packet's payload is borrowed
    /// from the parser and valid until the next call.
    pub fn push(&mut self, byte: u8) -> Option<Event<'_>> {
        let step = self.step(byte)?;
        Some(self.event(step))
    }

    /// Feeds bytes until one produces an event. Returns how many bytes were
    /// consumed (call again with the rest) and the event, if any.
    pub fn push_slice(&mut self, bytes: &[u8]) -> (usize, Option<Event<'_>>) {
        for (i, &b) in bytes.iter().enumerate() {
            if let Some(step) = self.step(b) {
                return (i + 1, Some(self.event(step)));
            }
        }
        (bytes.len(), None)
    }

    fn event(&self, step: Step) -> Event<'_> {
        match step {
            Step::Packet(ty) => Event::Packet(RawPacket {
                ty,
                payload: &self.payload,
            }),
            Step::Resynced(dropped) => Event::Resynced { dropped },
            Step::LostSync(reason) => Event::LostSync { reason },
        }
    }

    fn discard(&mut self, n: u32) {
        self.dropped = self.dropped.saturating_add(n);
        self.stats.dropped_bytes = self.stats.dropped_bytes.saturating_add(n);
    }

    fn lose_sync(&mut self, reason: LostSyncReason) -> Step {
        self.stats.lost_sync = self.stats.lost_sync.saturating_add(1);
        self.state = State::Hunt { matched: 0 };
        self.dropped = 0;
        Step::LostSync(reason)
    }

    /// Out of sync: matches the sync sequence. The sequence starts with its only
    /// head byte, so on a mismatch the match restarts at 1 if the byte is the head
    /// and at 0 otherwise (no longer partial match can survive).
    fn hunt(&mut self, matched: u8, byte: u8) -> Option<Step> {
        if SYNC_SEQUENCE.get(usize::from(matched)) == Some(&byte) {
            if usize::from(matched) + 1 == SYNC_SEQUENCE.len() {
                // The final head byte starts the next packet.
                self.state = State::Type;
                self.stats.resyncs = self.stats.resyncs.saturating_add(1);
                let dropped = core::mem::take(&mut self.dropped);
                return Some(Step::Resynced(dropped));
            }
            self.state = State::Hunt {
                matched: matched + 1,
            };
            return None;
        }
        let now = u8::from(byte == HEAD);
        // The bytes that were partially matched, plus this one unless it starts a
        // new match, can no longer be part of a sync sequence.
        self.discard(u32::from(matched) + 1 - u32::from(now));
        self.state = State::Hunt { matched: now };
        None
    }

    fn step(&mut self, byte: u8) -> Option<Step> {
        match self.state {
            State::Hunt { matched } => self.hunt(matched, byte),
            State::Head if byte == HEAD => {
                self.state = State::Type;
                None
            }
            State::Head => {
                let step = self.lose_sync(LostSyncReason::MissingHead { byte });
                // Not the head, so it cannot start a sync sequence: just count it.
                self.discard(1);
                Some(step)
            }
            State::Type => {
                self.state = State::Length { ty: byte };
                None
            }
            State::Length { ty } => {
                if LengthRule::for_type(ty).is_some_and(|r| !r.allows(usize::from(byte))) {
                    let step = self.lose_sync(LostSyncReason::BadLength { ty, len: byte });
                    // Head and type are discarded. The length byte could itself be
                    // the head of a sync sequence, so it goes to the hunter (which
                    // cannot complete a match with one byte, so no event is lost).
                    self.discard(2);
                    let _ = self.hunt(0, byte);
                    return Some(step);
                }
                self.payload.clear();
                if byte == 0 {
                    return Some(self.complete(ty));
                }
                self.state = State::Payload { ty, len: byte };
                None
            }
            State::Payload { ty, len } => {
                // Cannot fail: the buffer holds 255 bytes and `len` is a u8.
                let _ = self.payload.push(byte);
                if self.payload.len() >= usize::from(len) {
                    return Some(self.complete(ty));
                }
                None
            }
        }
    }

    fn complete(&mut self, ty: u8) -> Step {
        self.state = State::Head;
        self.stats.packets = self.stats.packets.saturating_add(1);
        Step::Packet(ty)
    }
}
