//! Conversions between backchannel packets and the neutral [`HeadStatus`].
//!
//! Receiving ([`apply`]):
//!
//! | packet | effect on `HeadStatus` |
//! |---|---|
//! | VENDOR / MODEL / FIRMWARE / SERIAL | the matching `identification` text |
//! | TEMPERATURES | `temperatures[i]`; components past the end of a short packet become `None` |
//! | FRAME_ERROR_COUNT | `frame_errors` |
//! | ERROR_STATE | `error_codes[i]` (past the end: `None`) and the derived alarms below |
//! | WORKING_HOURS | `working_hours[i]`; past the end: `None` |
//! | SYNC, DEBUG, unknown | nothing |
//!
//! Error code -> alarm (any component):
//!
//! | code | alarm |
//! |---|---|
//! | 1 temperature | `TEMPERATURE` |
//! | 2 data | `COMMUNICATION` |
//! | 3 out of range, 6 adjustment, 7 other mechanical | `MECHANICAL` |
//! | 4 power supply | `POWER` |
//! | 5 other electrical | `ELECTRICAL` |
//! | 8..=99 (undefined) and 100..=255 (vendor) | `VENDOR` |
//!
//! An ERROR_STATE packet is the head's complete error state, so it replaces the
//! alarms of this table (all six are cleared, then set from the codes); alarms no
//! code maps to (positions, laser, the bridge's own) are left alone. Undefined codes
//! are nonzero, i.e. an error by §5.2, so they must raise *some* alarm; `VENDOR`
//! ("an error of a kind we cannot name") is the closest.
//!
//! Sending ([`status_packet`]): one packet per [`StatusItem`], or `None` when the
//! status has nothing to say for it. Texts shorter than 3 bytes are padded with
//! spaces and non-ASCII bytes replaced by `?` (the wire needs 3..=200 ASCII bytes).
//! Temperatures and hours drop trailing `None`s. The ERROR_STATE packet carries the
//! per-component codes (`None` -> 0). If those codes signal no error while alarms
//! are set (e.g. the head behind the bridge speaks a protocol without component
//! codes, or the bridge raised `STATUS_LOST`), codes are derived from the alarms so
//! that an alarm is never reported as "all well":
//!
//! | alarm | component | code |
//! |---|---|---|
//! | `POWER` | Head | 4 |
//! | `TEMPERATURE` | Head (if not already set) | 1 |
//! | `ELECTRICAL`, `LASER` | Head (if not already set) | 5 |
//! | `MECHANICAL` | Head (if not already set) | 7 |
//! | `VENDOR` | Head (if not already set) | 100 |
//! | `COMMUNICATION`, `INPUT_LOST`, `STATUS_LOST` | DSP | 2 |
//! | `POSITION_X` / `_Y` / `_Z` | Galvo X / Y / Z | 7 |
//!
//! Only one code fits the Head slot, so the table's order is the priority.

use heapless::Vec;

use super::packet::{Component, ErrorCode, Packet, HOURS_NOT_SUPPORTED, TEMPERATURE_NOT_SUPPORTED};
use crate::model::{Alarms, HeadStatus, Text, COMPONENTS};

/// The alarms an XY3-100 error code can raise.
const CODE_ALARMS: Alarms = Alarms(
    Alarms::TEMPERATURE.0
        | Alarms::COMMUNICATION.0
        | Alarms::MECHANICAL.0
        | Alarms::POWER.0
        | Alarms::ELECTRICAL.0
        | Alarms::VENDOR.0,
);

/// The alarm an error code raises (`NONE` for 0).
pub fn alarm_for(code: u8) -> Alarms {
    match ErrorCode::from(code) {
        ErrorCode::Ok => Alarms::NONE,
        ErrorCode::Temperature => Alarms::TEMPERATURE,
        ErrorCode::Data => Alarms::COMMUNICATION,
        ErrorCode::OutOfRange | ErrorCode::Adjustment | ErrorCode::OtherMechanical => {
            Alarms::MECHANICAL
        }
        ErrorCode::PowerSupply => Alarms::POWER,
        ErrorCode::OtherElectrical => Alarms::ELECTRICAL,
        ErrorCode::Undefined(_) | ErrorCode::Vendor(_) => Alarms::VENDOR,
    }
}

fn spread<T: Copy>(dst: &mut [Option<T>; COMPONENTS], src: &[Option<T>]) {
    for (i, d) in dst.iter_mut().enumerate() {
        *d = src.get(i).copied().flatten();
    }
}

/// Applies a received packet to `status` (see the module docs for the mapping).
pub fn apply(packet: &Packet, status: &mut HeadStatus) {
    let id = &mut status.identification;
    match packet {
        Packet::Vendor(t) => id.vendor = t.clone(),
        Packet::Model(t) => id.model = t.clone(),
        Packet::Firmware(t) => id.firmware = t.clone(),
        Packet::Serial(t) => id.serial = t.clone(),
        Packet::Temperatures(v) => spread(&mut status.temperatures, v),
        Packet::WorkingHours(v) => spread(&mut status.working_hours, v),
        Packet::FrameErrorCount(c) => status.frame_errors = Some(*c),
        Packet::ErrorState(codes) => {
            let mut alarms = Alarms::NONE;
            for (i, slot) in status.error_codes.iter_mut().enumerate() {
                *slot = codes.get(i).copied();
                alarms = alarms.union(alarm_for(slot.unwrap_or(0)));
            }
            status.alarms.set(CODE_ALARMS, false);
            status.alarms = status.alarms.union(alarms);
        }
        Packet::Sync | Packet::Debug(_) | Packet::Unknown { .. } => {}
    }
}

/// The status packets a sender cycles through.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StatusItem {
    /// VENDOR text.
    Vendor,
    /// MODEL text.
    Model,
    /// FIRMWARE text.
    Firmware,
    /// SERIAL text.
    Serial,
    /// TEMPERATURES.
    Temperatures,
    /// FRAME_ERROR_COUNT.
    FrameErrors,
    /// ERROR_STATE.
    ErrorState,
    /// WORKING_HOURS.
    WorkingHours,
}

impl StatusItem {
    /// Every item, in a sensible sending order (errors first).
    pub const ALL: [StatusItem; 8] = [
        StatusItem::ErrorState,
        StatusItem::Temperatures,
        StatusItem::FrameErrors,
        StatusItem::WorkingHours,
        StatusItem::Vendor,
        StatusItem::Model,
        StatusItem::Firmware,
        StatusItem::Serial,
    ];
}

/// Makes a text sendable: non-ASCII bytes become `?`, short texts are padded with
/// spaces to 3 bytes; an empty text is not sent.
fn wire_text(t: &Text) -> Option<Text> {
    if t.is_empty() {
        return None;
    }
    let mut out = Text::new();
    for &b in t.iter() {
        // `out` has the capacity of `t`, so this cannot fail.
        let _ = out.push(if b.is_ascii() { b } else { b'?' });
    }
    while out.len() < 3 {
        let _ = out.push(b' ');
    }
    Some(out)
}

/// Copies per-component values up to the last `Some`, mapping the reserved value
/// to `None` (it means "not supported" on the wire anyway).
fn trimmed<T: Copy + PartialEq>(
    src: &[Option<T>; COMPONENTS],
    reserved: T,
) -> Option<Vec<Option<T>, COMPONENTS>> {
    let clean = |v: Option<T>| v.filter(|x| *x != reserved);
    let n = src.iter().rposition(|v| clean(*v).is_some())? + 1;
    let mut out = Vec::new();
    for v in src.iter().take(n) {
        let _ = out.push(clean(*v));
    }
    Some(out)
}

/// The error codes an ERROR_STATE packet should carry for `status` (see the module
/// docs), trimmed after the last nonzero or reported entry, at least one entry.
pub fn error_codes_for(status: &HeadStatus) -> Vec<u8, COMPONENTS> {
    let mut codes = [0u8; COMPONENTS];
    for (c, s) in codes.iter_mut().zip(status.error_codes.iter()) {
        *c = s.unwrap_or(0);
    }
    let mut len = status
        .error_codes
        .iter()
        .rposition(Option::is_some)
        .map_or(0, |i| i + 1);
    if codes.iter().all(|&c| c == 0) && status.alarms.any() {
        let a = status.alarms;
        let head = [
            (Alarms::POWER, 4),
            (Alarms::TEMPERATURE, 1),
            (Alarms::ELECTRICAL.union(Alarms::LASER), 5),
            (Alarms::MECHANICAL, 7),
            (Alarms::VENDOR, 100),
        ];
        let others = [
            (
                Alarms::COMMUNICATION
                    .union(Alarms::INPUT_LOST)
                    .union(Alarms::STATUS_LOST),
                Component::Dsp,
                2,
            ),
            (Alarms::POSITION_X, Component::GalvoX, 7),
            (Alarms::POSITION_Y, Component::GalvoY, 7),
            (Alarms::POSITION_Z, Component::GalvoZ, 7),
        ];
        if let Some(&(_, code)) = head.iter().find(|(al, _)| a.0 & al.0 != 0) {
            codes[Component::Head.index()] = code;
        }
        for (al, comp, code) in others {
            if a.0 & al.0 != 0 {
                if let Some(slot) = codes.get_mut(comp.index()) {
                    *slot = code;
                }
            }
        }
        // Alarm bits the model may gain later still must not read as "all well".
        if codes.iter().all(|&c| c == 0) {
            codes[Component::Head.index()] = 100;
        }
    }
    if let Some(last) = codes.iter().rposition(|&c| c != 0) {
        len = len.max(last + 1);
    }
    let mut out = Vec::new();
    for &c in codes.iter().take(len.max(1)) {
        let _ = out.push(c);
    }
    out
}

/// The packet that expresses `item` of `status`, or `None` if there is nothing to
/// send for it (empty text, no temperatures, …).
pub fn status_packet(status: &HeadStatus, item: StatusItem) -> Option<Packet> {
    let id = &status.identification;
    Some(match item {
        StatusItem::Vendor => Packet::Vendor(wire_text(&id.vendor)?),
        StatusItem::Model => Packet::Model(wire_text(&id.model)?),
        StatusItem::Firmware => Packet::Firmware(wire_text(&id.firmware)?),
        StatusItem::Serial => Packet::Serial(wire_text(&id.serial)?),
        StatusItem::Temperatures => {
            Packet::Temperatures(trimmed(&status.temperatures, TEMPERATURE_NOT_SUPPORTED)?)
        }
        StatusItem::WorkingHours => {
            Packet::WorkingHours(trimmed(&status.working_hours, HOURS_NOT_SUPPORTED)?)
        }
        StatusItem::FrameErrors => Packet::FrameErrorCount(status.frame_errors?),
        StatusItem::ErrorState => Packet::ErrorState(error_codes_for(status)),
    })
}
