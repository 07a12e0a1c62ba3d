//! `serde` forms of the configuration's foreign types (feature `serde`): the XY2-100
//! and XY3-100 codec types are used in [`Config`](super::Config) as they are, and
//! described here as serde "remote" types so the codec modules need no serde code.

use serde::de::{Error, Unexpected};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::model::Axis;
use crate::xy2::{Mode, Parity, Polarity};
use crate::xy3::rx::Lines;
use crate::xy3::{BackRate, FrameSize};

/// File form of [`Mode`]: `"standard16"` or `"extended18"`.
#[derive(Serialize, Deserialize)]
#[serde(remote = "Mode", rename_all = "snake_case")]
pub enum ModeDef {
    /// 16-bit positions and commands.
    Standard16,
    /// 18-bit positions.
    Extended18,
}

/// File form of [`Parity`]: `"whole_frame"`, `"data_only"` or `"ignore"`.
#[derive(Serialize, Deserialize)]
#[serde(remote = "Parity", rename_all = "snake_case")]
pub enum ParityDef {
    /// All 20 bits.
    WholeFrame,
    /// Data bits only.
    DataOnly,
    /// Not checked.
    Ignore,
}

/// File form of [`Polarity`]: `"low_is_ok"` or `"high_is_ok"`.
#[derive(Serialize, Deserialize)]
#[serde(remote = "Polarity", rename_all = "snake_case")]
pub enum PolarityDef {
    /// Low = OK.
    LowIsOk,
    /// High = OK.
    HighIsOk,
}

/// [`BackRate`] as its baud rate (`back_rate = 115200`).
pub mod back_rate {
    use super::*;

    /// Writes the baud rate.
    pub fn serialize<S: Serializer>(rate: &BackRate, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u32(rate.baud())
    }

    /// Reads a baud rate; only the five XY3-100 rates are accepted.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<BackRate, D::Error> {
        let baud = u32::deserialize(d)?;
        BackRate::ALL
            .iter()
            .copied()
            .find(|r| r.baud() == baud)
            .ok_or_else(|| {
                D::Error::invalid_value(
                    Unexpected::Unsigned(baud.into()),
                    &"one of 57600, 115200, 230400, 460800, 921600",
                )
            })
    }
}

/// [`FrameSize`] as its length in bits (`frame_bits = 24` or `32`).
pub mod frame_bits {
    use super::*;

    /// Writes 24 or 32.
    pub fn serialize<S: Serializer>(size: &FrameSize, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u8(size.bits())
    }

    /// Reads 24 or 32.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<FrameSize, D::Error> {
        match u8::deserialize(d)? {
            24 => Ok(FrameSize::Bits24),
            32 => Ok(FrameSize::Bits32),
            n => Err(D::Error::invalid_value(
                Unexpected::Unsigned(n.into()),
                &"24 or 32",
            )),
        }
    }
}

/// File form of one XY3-100 data line: `"x"`, `"y"`, `"z"`, `"u"` or `"w"`.
#[derive(Serialize, Deserialize)]
#[serde(remote = "Axis", rename_all = "snake_case")]
enum AxisDef {
    X,
    Y,
    Z,
    U,
    W,
}

/// [`Axis`] through [`AxisDef`], as a list element.
#[derive(Serialize, Deserialize)]
struct AxisName(#[serde(with = "AxisDef")] Axis);

/// [`Lines`] as the list of its axes (`lines = ["x", "y", "z"]`).
pub mod xy3_lines {
    use core::fmt;

    use serde::de::{SeqAccess, Visitor};
    use serde::ser::SerializeSeq;

    use super::*;

    /// Writes the lines in axis order.
    pub fn serialize<S: Serializer>(lines: &Lines, s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(lines.count()))?;
        for axis in lines.axes() {
            seq.serialize_element(&AxisName(axis))?;
        }
        seq.end()
    }

    /// Reads a list of line names, each at most once, in any order; "x" and "y"
    /// must be among them.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Lines, D::Error> {
        d.deserialize_seq(LinesVisitor)
    }

    struct LinesVisitor;

    const EXPECTED: &str = "a list of distinct XY3-100 lines (\"x\", \"y\", \"z\", \"u\", \"w\") \
                            with \"x\" and \"y\"";

    impl<'de> Visitor<'de> for LinesVisitor {
        type Value = Lines;

        fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            f.write_str(EXPECTED)
        }

        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Lines, A::Error> {
            let mut axes = heapless::Vec::<Axis, 5>::new();
            while let Some(AxisName(axis)) = seq.next_element()? {
                // Five names at most once each always fit.
                if axes.contains(&axis) || axes.push(axis).is_err() {
                    return Err(A::Error::invalid_value(
                        Unexpected::Other("a line listed twice"),
                        &EXPECTED,
                    ));
                }
            }
            match Lines::new(&axes) {
                Some(lines) if lines.has(Axis::Y) => Ok(lines),
                _ => Err(A::Error::invalid_value(
                    Unexpected::Other("a list without \"x\" or \"y\""),
                    &EXPECTED,
                )),
            }
        }
    }
}
