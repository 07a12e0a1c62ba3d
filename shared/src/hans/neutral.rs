//! Conversions between HANS-100 frames and the protocol-neutral model
//! ([`crate::model`]). The mapping table is in the [module docs](super).

use super::ext::{ControllerExt, DeviceExt, ExtError, LaserAlarms, ZAlarms};
use super::frame::Frame;
use super::status::{GalvoAlarms, GalvoStatus};
use crate::model::{Alarms, Axis, ForwardFrame, HeadStatus, Position, Warnings};
use heapless::Vec;

/// Width of HANS-100 X / Y positions.
pub const XY_BITS: u8 = 20;
/// Width of the Z position in DATA3 (code 0) and of status positions (codes 64, 14).
pub const Z_BITS: u8 = 16;

fn position(raw: u32, bits: u8) -> Option<Position> {
    Position::from_raw(raw, bits).ok()
}

impl Frame {
    /// The neutral view of a forward frame: X = DATA1, Y = DATA2 (20 bits), DATA3 code
    /// 0 -> Z (16 bits), any other code -> `laser`.
    pub fn to_forward(&self) -> ForwardFrame {
        let mut f = ForwardFrame::default();
        f.axes[Axis::X.index()] = position(self.data1(), XY_BITS);
        f.axes[Axis::Y.index()] = position(self.data2(), XY_BITS);
        match ControllerExt::from_frame(self) {
            ControllerExt::Z(z) => f.axes[Axis::Z.index()] = position(u32::from(z), Z_BITS),
            ControllerExt::Laser(l) => f.laser = Some(l),
        }
        f
    }

    /// The forward frame to send for `f`. HANS-100 must send all three words every
    /// frame, so whatever `f` lacks is taken from `hold` (normally the previously
    /// sent frame, [`Frame::CENTRE`] at start):
    /// - X / Y: `f`'s position resized to 20 bits, else `hold`'s word.
    /// - DATA3: laser control when present (it is a one-off command that must not be
    ///   lost), else Z resized to 16 bits, else `hold`'s DATA3. When a frame has both,
    ///   Z is not sent this frame; a bridge that needs both alternates.
    /// - Commands and the U / W axes have no HANS-100 form and are dropped.
    pub fn from_forward(f: &ForwardFrame, hold: &Frame) -> Result<Frame, ExtError> {
        let word = |axis: Axis, held: u32| f.axis(axis).map_or(held, |p| p.to_raw(XY_BITS));
        let data3 = if let Some(l) = f.laser {
            ControllerExt::Laser(l).to_data3()?
        } else if let Some(z) = f.axis(Axis::Z) {
            // Truncation cannot happen: `to_raw(16)` is at most 0xFFFF.
            ControllerExt::Z(z.to_raw(Z_BITS) as u16).to_data3()?
        } else {
            hold.data3()
        };
        let frame = Frame::new(
            word(Axis::X, hold.data1()),
            word(Axis::Y, hold.data2()),
            data3,
        );
        frame.map_err(|super::EncodeError::TooWide { value, .. }| ExtError::WordTooWide(value))
    }
}

/// Alarm flags a HANS-100 status can report; [`StatusReceiver`] owns exactly these.
const OWNED_ALARMS: Alarms = Alarms(
    Alarms::POWER.0
        | Alarms::TEMPERATURE.0
        | Alarms::POSITION_X.0
        | Alarms::POSITION_Y.0
        | Alarms::POSITION_Z.0
        | Alarms::COMMUNICATION.0
        | Alarms::LASER.0,
);
/// Warning flags a HANS-100 status can report.
const OWNED_WARNINGS: Warnings = Warnings(
    Warnings::TEMPERATURE.0
        | Warnings::LOW_SPEED_FILTERED.0
        | Warnings::LOW_SPEED.0
        | Warnings::LASER_TEMPERATURE.0
        | Warnings::LASER_EMISSION.0,
);

/// Applies decoded HANS-100 status frames to a [`HeadStatus`].
///
/// The galvo (code 65), the Z galvo (code 15) and the laser (code 10) report
/// overlapping flags (e.g. over-temperature) in different frames, so the receiver
/// remembers the latest report of each source and sets every flag to the union of
/// all sources: an alarm from one source is never cleared by another source's
/// "normal". Flags HANS-100 cannot report (e.g. `STATUS_LOST`) are left untouched.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StatusReceiver {
    galvo: Option<GalvoAlarms>,
    z: Option<ZAlarms>,
    laser: Option<LaserAlarms>,
}

impl StatusReceiver {
    /// A receiver that has seen no status yet.
    pub const fn new() -> Self {
        Self {
            galvo: None,
            z: None,
            laser: None,
        }
    }

    /// Decodes both parts of a status frame (DATA1+DATA2 and DATA3) into `status`.
    pub fn apply(&mut self, frame: &Frame, status: &mut HeadStatus) {
        self.apply_galvo(&GalvoStatus::from_frame(frame), status);
        self.apply_device(&DeviceExt::from_frame(frame), status);
    }

    /// Applies a galvo status (codes 64, 65; other codes are ignored).
    pub fn apply_galvo(&mut self, galvo: &GalvoStatus, status: &mut HeadStatus) {
        match *galvo {
            GalvoStatus::Position { x, y } => {
                status.actual[0] = position(u32::from(x), Z_BITS);
                status.actual[1] = position(u32::from(y), Z_BITS);
            }
            GalvoStatus::Velocity { x, y, alarms } => {
                status.velocity[0] = Some(x);
                status.velocity[1] = Some(y);
                self.galvo = Some(alarms);
                self.update_flags(status);
            }
            GalvoStatus::Raw { .. } => {}
        }
    }

    /// Applies a device DATA3 (codes 2, 7, 10, 14, 15; other codes are ignored).
    pub fn apply_device(&mut self, device: &DeviceExt, status: &mut HeadStatus) {
        match *device {
            DeviceExt::RemoteInputs(d) => status.remote_inputs = Some(d),
            DeviceExt::PulseWidthMode(d) => status.pulse_width_mode = Some(d),
            DeviceExt::LaserAlarms(a) => {
                status.laser_state = Some(a.0);
                self.laser = Some(a);
                self.update_flags(status);
            }
            DeviceExt::ZActual(z) => status.actual[2] = position(u32::from(z), Z_BITS),
            DeviceExt::ZVelocity { velocity, alarms } => {
                status.velocity[2] = Some(velocity);
                self.z = Some(alarms);
                self.update_flags(status);
            }
            DeviceExt::Raw { .. } => {}
        }
    }

    fn update_flags(&self, status: &mut HeadStatus) {
        let g = self.galvo.unwrap_or_default();
        let z = self.z.unwrap_or_default();
        let l = self.laser.unwrap_or_default();
        let mut a = Alarms(status.alarms.0 & !OWNED_ALARMS.0);
        a.set(
            Alarms::TEMPERATURE,
            g.over_temperature || z.over_temperature,
        );
        a.set(
            Alarms::POSITION_X.union(Alarms::POSITION_Y),
            g.following_error,
        );
        a.set(Alarms::POSITION_Z, z.following_error);
        a.set(Alarms::POWER, g.power || z.power);
        a.set(Alarms::COMMUNICATION, g.communication || z.communication);
        a.set(Alarms::LASER, l.any_alarm());
        status.alarms = a;
        let mut w = Warnings(status.warnings.0 & !OWNED_WARNINGS.0);
        w.set(Warnings::TEMPERATURE, g.temperature_warning);
        w.set(Warnings::LOW_SPEED_FILTERED, g.low_speed_filtered);
        w.set(Warnings::LOW_SPEED, g.low_speed);
        w.set(
            Warnings::LASER_TEMPERATURE,
            l.contains(LaserAlarms::TEMPERATURE_WARNING),
        );
        w.set(Warnings::LASER_EMISSION, l.contains(LaserAlarms::EMISSION));
        status.warnings = w;
    }
}

/// Alarms without a HANS-100 bit that still must reach a HANS-100 controller; they
/// are reported as the power alarm, which the spec defines as "any power, sensor or
/// system fault".
const AS_POWER: Alarms = Alarms(
    Alarms::POWER.0
        | Alarms::ELECTRICAL.0
        | Alarms::MECHANICAL.0
        | Alarms::VENDOR.0
        | Alarms::STATUS_LOST.0,
);
/// Alarms reported as the communication alarm (the bridge losing its controller
/// input is exactly what the head's communication alarm means).
const AS_COMMUNICATION: Alarms = Alarms(Alarms::COMMUNICATION.0 | Alarms::INPUT_LOST.0);

fn any(a: Alarms, mask: Alarms) -> bool {
    a.0 & mask.0 != 0
}

fn actual16(p: Option<Position>) -> Option<u16> {
    // Truncation cannot happen: `to_raw(16)` is at most 0xFFFF.
    p.map(|p| p.to_raw(Z_BITS) as u16)
}

/// Builders of status frame parts from a neutral [`HeadStatus`], for a bridge that
/// emulates a HANS-100 head towards its controller and alternates them.
impl GalvoStatus {
    /// Code 64 from the actual X / Y positions (top 16 bits), `None` unless both are
    /// known.
    pub fn position_from(status: &HeadStatus) -> Option<Self> {
        Some(Self::Position {
            x: actual16(status.actual[0])?,
            y: actual16(status.actual[1])?,
        })
    }

    /// Code 65 from velocities (unknown -> 0) and flags; see the module docs for
    /// how alarms without a HANS-100 bit are reported.
    pub fn velocity_from(status: &HeadStatus) -> Self {
        let a = status.alarms;
        let w = status.warnings;
        Self::Velocity {
            x: status.velocity[0].unwrap_or(0) & 0xFFF,
            y: status.velocity[1].unwrap_or(0) & 0xFFF,
            alarms: GalvoAlarms {
                over_temperature: a.contains(Alarms::TEMPERATURE),
                following_error: any(a, Alarms::POSITION_X.union(Alarms::POSITION_Y)),
                low_speed_filtered: w.contains(Warnings::LOW_SPEED_FILTERED),
                power: any(a, AS_POWER),
                temperature_warning: w.contains(Warnings::TEMPERATURE),
                low_speed: w.contains(Warnings::LOW_SPEED),
                reserved_level: true,
                communication: any(a, AS_COMMUNICATION),
            },
        }
    }
}

impl DeviceExt {
    /// Every DATA3 item `status` has information for, in code order: remote inputs
    /// (2), pulse-width mode (7), laser alarms (10: `laser_state`, plus D3 system
    /// alarm for a `LASER` alarm it does not already show, D2 and D15 from the laser
    /// warnings), Z actual (14) and Z velocity/alarms (15, when Z actual or
    /// velocity is known).
    pub fn all_from(status: &HeadStatus) -> Vec<DeviceExt, 5> {
        let mut out = Vec::new();
        let mut push = |d| {
            // Cannot fail: at most 5 items are pushed into a 5-slot vector.
            let _ = out.push(d);
        };
        if let Some(d) = status.remote_inputs {
            push(DeviceExt::RemoteInputs(d));
        }
        if let Some(d) = status.pulse_width_mode {
            push(DeviceExt::PulseWidthMode(d));
        }
        let a = status.alarms;
        let w = status.warnings;
        let mut laser = LaserAlarms(status.laser_state.unwrap_or(0));
        if a.contains(Alarms::LASER) && !laser.any_alarm() {
            laser.0 |= LaserAlarms::SYSTEM;
        }
        if w.contains(Warnings::LASER_TEMPERATURE) {
            laser.0 |= LaserAlarms::TEMPERATURE_WARNING;
        }
        if w.contains(Warnings::LASER_EMISSION) {
            laser.0 |= LaserAlarms::EMISSION;
        }
        if status.laser_state.is_some() || laser.0 != 0 {
            push(DeviceExt::LaserAlarms(laser));
        }
        if let Some(z) = actual16(status.actual[2]) {
            push(DeviceExt::ZActual(z));
        }
        if status.actual[2].is_some() || status.velocity[2].is_some() {
            push(DeviceExt::ZVelocity {
                velocity: status.velocity[2].unwrap_or(0) & 0xFFF,
                alarms: ZAlarms {
                    over_temperature: a.contains(Alarms::TEMPERATURE),
                    following_error: a.contains(Alarms::POSITION_Z),
                    communication: any(a, AS_COMMUNICATION),
                    power: any(a, AS_POWER),
                },
            });
        }
        out
    }
}

/// Assembles a status frame from a galvo part (DATA1 + DATA2) and a device part
/// (DATA3).
pub fn status_frame(galvo: &GalvoStatus, device: &DeviceExt) -> Result<Frame, ExtError> {
    let (data1, data2) = galvo.to_words()?;
    let data3 = device.to_data3()?;
    Frame::new(data1, data2, data3)
        .map_err(|super::EncodeError::TooWide { value, .. }| ExtError::WordTooWide(value))
}
