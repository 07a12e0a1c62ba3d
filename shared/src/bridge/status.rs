//! Status back-translation: the head's [`HeadStatus`] (kept up to date by the
//! head-side receivers through the protocols' neutral `apply` functions) plus the
//! bridge's own alarms, expressed in the controller's protocol with the existing
//! neutral converters. The mapping table is `STATUS_MAP.md` next to this file.
//!
//! The XY2-100 and HANS-100 accessors take no time: they report the state as of the
//! last event or tick (which the output clock calls every frame).
//!
#![doc = include_str!("STATUS_MAP.md")]
//!
//! The bridge's alarms are merged only for the duration of a conversion (swapped
//! into the stored status and back), so no copy of the large status is made.

use super::engine::Bridge;
use crate::hans::{self, DeviceExt, GalvoStatus};
use crate::model::{Alarms, HeadStatus, Text};
use crate::xy2::{Health, LinkConfig, StatusLevel, StatusWord};
use crate::xy3::back::neutral::{error_codes_for, status_packet, StatusItem};
use crate::xy3::back::{Component, EncodeError, Packet, Sender};

/// Vendor text the bridge reports towards an XY3-100 controller.
pub const BRIDGE_VENDOR: &str = "XY bridge project";
/// Model text; the head's model is appended (`"XY bridge / head: <model>"`).
pub const BRIDGE_MODEL: &str = "XY bridge";
/// Firmware text: the version of this crate.
pub const BRIDGE_FIRMWARE: &str = concat!("xy-bridge ", env!("CARGO_PKG_VERSION"));

/// Minimum time between two scheduled backchannel packets. An error-state change
/// is sent at the next poll regardless.
pub const PACKET_INTERVAL_US: u64 = 10_000;

/// The backchannel schedule: the error state every other packet (so a fault is
/// repeated at least every 2 intervals), the other items in turn.
const SCHEDULE: [StatusItem; 14] = [
    StatusItem::ErrorState,
    StatusItem::Temperatures,
    StatusItem::ErrorState,
    StatusItem::FrameErrors,
    StatusItem::ErrorState,
    StatusItem::WorkingHours,
    StatusItem::ErrorState,
    StatusItem::Vendor,
    StatusItem::ErrorState,
    StatusItem::Model,
    StatusItem::ErrorState,
    StatusItem::Firmware,
    StatusItem::ErrorState,
    StatusItem::Serial,
];

/// XY3-100 error code 2, data error ([`crate::xy3::back::ErrorCode::Data`]): what
/// the bridge's own alarms are reported as, on the DSP slot.
const DATA_ERROR: u8 = 2;

/// Status-side state of the bridge.
#[derive(Clone, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) struct StatusState {
    /// The head's status as its receivers reported it.
    pub head: HeadStatus,
    sender: Sender,
    next: usize,
    last_packet_us: Option<u64>,
    /// The alarms the last ERROR_STATE packet reported.
    reported: Option<Alarms>,
    hans_phase: u32,
}

impl StatusState {
    pub fn new() -> Self {
        StatusState {
            head: HeadStatus::default(),
            sender: Sender::default(),
            next: 0,
            last_packet_us: None,
            reported: None,
            hans_phase: 0,
        }
    }

    pub fn note_rate_change(&mut self) {
        self.sender.note_rate_change();
    }
}

fn text(parts: &[&[u8]]) -> Text {
    let mut t = Text::new();
    for &b in parts.iter().flat_map(|p| p.iter()) {
        // Longer texts are cut at the wire's 200-byte limit.
        let _ = t.push(b);
    }
    t
}

impl Bridge {
    /// The head's status as last received.
    pub fn head_status(&self) -> &HeadStatus {
        &self.status.head
    }

    /// The head's status, for the head-side receivers to update with the neutral
    /// `apply` functions (`xy3::back::neutral::apply`, `hans::StatusReceiver::apply`,
    /// `xy2::StatusWord::alarms`); call [`Bridge::status_seen`] with each valid one.
    pub fn head_status_mut(&mut self) -> &mut HeadStatus {
        &mut self.status.head
    }

    /// Everything the controller is told: the head's alarms and the bridge's own.
    pub fn reported_alarms(&self) -> Alarms {
        self.status.head.alarms.union(self.alarms())
    }

    /// Runs `f` on the head status with the bridge's alarms merged in.
    fn with_merged<R>(&mut self, f: impl FnOnce(&mut HeadStatus) -> R) -> R {
        let merged = self.reported_alarms();
        let head = &mut self.status.head;
        let saved = head.alarms;
        head.alarms = merged;
        let r = f(head);
        head.alarms = saved;
        r
    }

    /// XY2-100 controller, level form: whether to drive STATUS high (per the
    /// configured polarity); any reported alarm is a fault.
    pub fn xy2_status_line_high(&self) -> bool {
        let level = StatusLevel {
            polarity: self.config.controller.xy2.polarity,
        };
        level.line_high(Health::from_alarms(self.reported_alarms()))
    }

    /// XY2-100 controller, word form: the status word for the reported alarms.
    pub fn xy2_status_word(&self) -> StatusWord {
        StatusWord::from_alarms(self.reported_alarms())
    }

    /// XY2-100 controller, word form: the 20-bit STATUS frame (controller link's
    /// parity policy).
    pub fn xy2_status_frame(&self) -> u32 {
        let c = &self.config.controller.xy2;
        let link = LinkConfig {
            mode: c.mode,
            parity: c.parity,
        };
        self.xy2_status_word().to_frame(&link)
    }

    /// HANS-100 controller: the next STATUS frame. DATA1 + DATA2 alternate code 65
    /// (velocities and alarms, every other frame so alarms are never more than two
    /// frames old) and code 64 (actual positions, when known; else 65 again); DATA3
    /// cycles through every device code the status has data for (code 15 with the
    /// Z alarm bits when it has none).
    pub fn hans_status_frame(&mut self) -> hans::Frame {
        let phase = self.status.hans_phase;
        self.status.hans_phase = phase.wrapping_add(1);
        self.with_merged(|s| {
            let galvo = if phase % 2 == 1 {
                GalvoStatus::position_from(s).unwrap_or_else(|| GalvoStatus::velocity_from(s))
            } else {
                GalvoStatus::velocity_from(s)
            };
            // Code 15 carries Z and communication / power alarm bits; when the
            // status has no Z data it is still sent (velocity 0) if DATA3 would
            // otherwise say nothing or a Z alarm would go unreported.
            let no_z = s.actual[2].is_none() && s.velocity[2].is_none();
            let saved = s.velocity[2];
            if no_z && (s.alarms.contains(Alarms::POSITION_Z) || DeviceExt::all_from(s).is_empty())
            {
                s.velocity[2] = Some(0);
            }
            let devices = DeviceExt::all_from(s);
            s.velocity[2] = saved;
            let n = u32::try_from(devices.len()).unwrap_or(1).max(1);
            let pick = usize::try_from((phase / 2) % n).unwrap_or(0);
            let device = devices
                .get(pick)
                .copied()
                .unwrap_or(DeviceExt::Raw { code: 0, data: 0 });
            hans::status_frame(&galvo, &device).unwrap_or(hans::Frame::CENTRE)
        })
    }

    /// The packet for one schedule item towards an XY3-100 controller: the bridge
    /// names itself (vendor, model with the head's model, firmware), passes the
    /// head's serial, temperatures and working hours, reports frame errors as it
    /// counted them on the controller side and the merged error state.
    fn packet_for(&mut self, item: StatusItem) -> Option<Packet> {
        match item {
            StatusItem::Vendor => Some(Packet::Vendor(text(&[BRIDGE_VENDOR.as_bytes()]))),
            StatusItem::Firmware => Some(Packet::Firmware(text(&[BRIDGE_FIRMWARE.as_bytes()]))),
            StatusItem::Model => {
                let head = &self.status.head.identification.model;
                let t = if head.is_empty() {
                    text(&[BRIDGE_MODEL.as_bytes()])
                } else {
                    text(&[BRIDGE_MODEL.as_bytes(), b" / head: ", head])
                };
                Some(Packet::Model(t))
            }
            StatusItem::FrameErrors => {
                Some(Packet::FrameErrorCount(self.counters.axis_check_failures()))
            }
            StatusItem::ErrorState => {
                let own = self.alarms().any();
                let mut codes = self.with_merged(|s| error_codes_for(s));
                if own {
                    // The head's own codes take precedence in `error_codes_for`; the
                    // bridge's alarms must still show: data error on the DSP slot.
                    let dsp = Component::Dsp.index();
                    while codes.len() <= dsp {
                        let _ = codes.push(0);
                    }
                    if let Some(c @ 0) = codes.get_mut(dsp) {
                        *c = DATA_ERROR;
                    }
                }
                Some(Packet::ErrorState(codes))
            }
            _ => self.with_merged(|s| status_packet(s, item)),
        }
    }

    /// XY3-100 controller: applies time up to `now_ns` (like [`Bridge::tick`]),
    /// then writes the next backchannel bytes into `out` (at least
    /// [`crate::xy3::back::SEND_BUF_LEN`] bytes) and returns how many. Call it
    /// whenever the UART can take more; it sends one packet per
    /// [`PACKET_INTERVAL_US`] (an error-state change at once), SYNC packets as the
    /// [`Sender`] interleaves them, and on an idle line only the SYNC keep-alive.
    pub fn xy3_back_poll(&mut self, now_ns: u64, out: &mut [u8]) -> Result<usize, EncodeError> {
        self.poll(now_ns);
        let now_us = now_ns / 1_000;
        let alarms = self.reported_alarms();
        let changed = self.status.reported != Some(alarms);
        let due = self
            .status
            .last_packet_us
            .is_none_or(|t| now_us.saturating_sub(t) >= PACKET_INTERVAL_US);
        if !changed && !due {
            return self.status.sender.poll(now_us, out);
        }
        let mut found = None;
        if changed {
            found = self
                .packet_for(StatusItem::ErrorState)
                .map(|p| (StatusItem::ErrorState, p));
        }
        // Items with nothing to say (no temperatures, …) are skipped.
        for _ in 0..SCHEDULE.len() {
            if found.is_some() {
                break;
            }
            let item = SCHEDULE.get(self.status.next).copied();
            self.status.next = (self.status.next + 1) % SCHEDULE.len();
            found = item.and_then(|i| self.packet_for(i).map(|p| (i, p)));
        }
        let Some((item, packet)) = found else {
            return self.status.sender.poll(now_us, out);
        };
        let n = self.status.sender.send(now_us, &packet, out)?;
        self.status.last_packet_us = Some(now_us);
        if item == StatusItem::ErrorState {
            self.status.reported = Some(alarms);
        }
        Ok(n)
    }

    /// The controller-side backchannel rate currently in force.
    pub fn controller_back_rate(&self) -> crate::xy3::BackRate {
        self.controller_rate
    }
}
