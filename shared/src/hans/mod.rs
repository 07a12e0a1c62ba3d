//! HANS-100 word-level codec: frames <-> 125-bit line patterns, the DATA3 and
//! DATA1/DATA2 extension codes, and conversions to the neutral [`crate::model`].
//!
//! # The protocol in brief (HANS-100 spec V2.0, Chinese original)
//! The controller sends the same frame on five independent differential channels at
//! 12.5 Mbit/s; a frame is 125 bits = 10 us, so 100 000 frames per second. Every data
//! bit is followed by its complement, which keeps the line DC-free and lets the
//! receiver check every bit ("数据传输协议", sender items 1-2): start `0` + `1`, then
//! DATA1, DATA2, DATA3 (20 bits each, D19 first, each bit + complement), then three
//! stop `1`s that are not complemented. A receiver discards every frame that fails
//! a check, so a broken wire never yields a wrong position. The STATUS line back from
//! the head uses the same frame format with different meanings. See [`frame`].
//!
//! Forward, DATA1 = X and DATA2 = Y (20-bit offset binary) and DATA3 carries either a
//! 16-bit Z or laser control, selected by its low nibble ([`ext::ControllerExt`]).
//! On STATUS, DATA3 carries laser / Z / IO data ([`ext::DeviceExt`]) and DATA1+DATA2
//! together carry actual positions or velocities and alarms of the galvo
//! ([`status::GalvoStatus`]). In status alarm bits the wire sends **0 for active**.
//!
//! # Neutral model mapping ([`neutral`])
//! | HANS-100 | neutral model |
//! |---|---|
//! | forward DATA1 / DATA2 | `axes[X]` / `axes[Y]`, 20-bit `Position` |
//! | forward DATA3 code 0 | `axes[Z]`, 16-bit `Position` |
//! | forward DATA3 codes 1..=15 | `laser` (`LaserControl`; undefined codes `Other`) |
//! | status 64 X / Y | `actual[0]` / `actual[1]`, 16-bit |
//! | status 65 X / Y velocity | `velocity[0]` / `velocity[1]` (opaque 12 bits) |
//! | 65 over-temperature, 15 Z over-temperature | `Alarms::TEMPERATURE` |
//! | 65 following error | `Alarms::POSITION_X \| POSITION_Y` (galvo-wide) |
//! | 15 Z following error | `Alarms::POSITION_Z` |
//! | 65 / 15 power | `Alarms::POWER` |
//! | 65 / 15 communication | `Alarms::COMMUNICATION` |
//! | 65 `DATA1[5]` / `DATA2[6]` low speed | `Warnings::LOW_SPEED_FILTERED` / `LOW_SPEED` |
//! | 65 `DATA2[7]` over-temperature warning | `Warnings::TEMPERATURE` |
//! | 65 `DATA2[5]` reserved | not mapped (sent as 1) |
//! | 10 laser word | `laser_state` (raw); any alarm bit (all but D2, D15) -> `Alarms::LASER` |
//! | 10 D2 / D15 | `Warnings::LASER_TEMPERATURE` / `LASER_EMISSION` |
//! | 14 Z actual, 15 Z velocity | `actual[2]` (16-bit), `velocity[2]` |
//! | 2 remote inputs, 7 pulse-width mode | `remote_inputs`, `pulse_width_mode` |
//!
//! Flags shared by several sources (galvo code 65, Z code 15, laser code 10) are the
//! union of the latest report of each source ([`neutral::StatusReceiver`]). Towards a
//! HANS-100 controller, alarms without a HANS-100 bit (`ELECTRICAL`, `MECHANICAL`,
//! `VENDOR`, `STATUS_LOST`) are sent as the power alarm ("any power, sensor or system
//! fault") and `INPUT_LOST` as the communication alarm, so no fault is hidden.
//!
//! # Spec ambiguities and our decisions
//! - Velocity scale and sign are undefined: kept as opaque 12-bit fields.
//! - Status cadence and the alternation of codes 64 / 65 and of DATA3 codes are not
//!   stated: every status frame decodes on its own, in any interleaving.
//! - Code-4/5 units "50/us" are read as 20 ns counts; the codec keeps them raw.
//! - Forward DATA3 can carry Z or laser control, not both: laser control takes the
//!   slot when present (see [`Frame::from_forward`]).
//! - Codes 65 `DATA2[5]` and 3 D15..D11 are reserved: kept for exact round trips.

pub mod ext;
pub mod follow;
pub mod frame;
pub mod neutral;
pub mod rx;
pub mod status;
pub mod tx;
#[cfg(any(test, feature = "vectors"))]
#[doc(hidden)]
pub mod vectors;

pub use ext::{ControllerExt, DeviceExt, ExtError, LaserAlarms, ZAlarms};
pub use frame::{
    read_slot, write_slot, DecodeError, EncodeError, Frame, FRAME_BITS, RING_BYTES, RING_SLOTS,
    WORD_MAX,
};
pub use neutral::{status_frame, StatusReceiver};
pub use status::{GalvoAlarms, GalvoStatus};

#[cfg(test)]
mod tests_ext;
#[cfg(test)]
mod tests_frame;
#[cfg(test)]
mod tests_neutral;
