//! The backchannel receive path in one call: UART bytes (layouts item 6) through the
//! [`back::Parser`] into [`HeadStatus`] updates, with the link's troubles reported as
//! neutral [`LineEvent`] faults on [`Line::Backchannel`] (XY3-100 §5.2).
//!
//! | parser event | effect |
//! |---|---|
//! | packet that types cleanly ([`back::Packet::decode`]) | [`back::neutral::apply`] to the status |
//! | packet whose payload breaks its type's rules (e.g. non-ASCII text) | fault `CheckFailed`, status untouched |
//! | lost sync | fault `Framing` |
//! | (re)synced | fault `Resync` (the first sync after start-up counts too) |

use super::back::{self, Event, Packet, Parser};
use crate::model::{FaultKind, HeadStatus, Line, LineEvent};

/// Applies one parser event to `status`; returns the fault it stands for, if any.
pub fn apply_event(event: &Event<'_>, status: &mut HeadStatus) -> Option<LineEvent> {
    let kind = match event {
        Event::Packet(raw) => match Packet::decode(raw.ty, raw.payload) {
            Ok(packet) => {
                back::neutral::apply(&packet, status);
                return None;
            }
            Err(_) => FaultKind::CheckFailed,
        },
        Event::LostSync { .. } => FaultKind::Framing,
        Event::Resynced { .. } => FaultKind::Resync,
    };
    Some(LineEvent::Fault {
        line: Line::Backchannel,
        kind,
    })
}

/// Feeds `bytes` to `parser`, applies every event to `status` and hands each fault to
/// `on_fault`. Work is constant per byte.
pub fn push_bytes(
    parser: &mut Parser,
    bytes: &[u8],
    status: &mut HeadStatus,
    mut on_fault: impl FnMut(LineEvent),
) {
    let mut rest = bytes;
    while !rest.is_empty() {
        let (used, event) = parser.push_slice(rest);
        if let Some(fault) = event.and_then(|e| apply_event(&e, status)) {
            on_fault(fault);
        }
        rest = rest.get(used..).unwrap_or_default();
    }
}
