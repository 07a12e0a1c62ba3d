//! The JSON-lines formats of `bridge-sim` (one JSON object per line; see the README, section "bridge-sim").
//!
//! - XY2-100 / XY3-100 ([`ForwardRecord`]): `{"t_ns": T, "x": CH, "y": CH, ...}` with a
//!   key per channel present; CH is [`Channel`]: `{"pos": P, "bits": 16|18|20|26}`,
//!   `{"cmd": C}` (XY3: `"frame_bits": 32` marks a 32-bit command frame) or
//!   `{"error": "reason"}`.
//! - HANS-100 ([`HansRecord`]): `{"t_ns": T, "x": {"pos": DATA1, "bits": 20}, "y":
//!   {..DATA2}, "z": {..DATA3}}` or `{"t_ns": T, "error": "reason"}`.
//! - Backchannel ([`BackRecord`]): `{"t_ns": T, "type": N, "payload": "<lowercase
//!   hex>"}` or `{"t_ns": T, "error": "reason"}`.
//!
//! `t_ns` is the frame (packet) start in ns from the start of the capture; it is always
//! printed and optional on input. Unknown keys are rejected so typos do not pass
//! silently. Parsing checks the shape and ranges; protocol-specific checks (e.g. 18-bit
//! positions on an XY2-100 link in 16-bit mode) are the encoder's.

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use super::SimError;

/// One channel of one XY2-100 / XY3-100 frame.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(into = "ChannelWire", try_from = "ChannelWire")]
pub enum Channel {
    /// A position `pos` of width `bits` (16 or 18: XY2-100; 20 or 26: XY3-100 24- or
    /// 32-bit frames), offset binary.
    Pos {
        /// The value, `< 2^bits`.
        pos: u32,
        /// Its width.
        bits: u8,
    },
    /// A command: XY3-100 the 20-bit code, XY2-100 `command << 8 | parameter`.
    Cmd {
        /// The code.
        cmd: u32,
        /// XY3-100 frame size (24 or 32); `None` = the size of the frame's position
        /// channels, else 24.
        frame_bits: Option<u8>,
    },
    /// The receiver rejected this channel's frame.
    Error(String),
}

/// The flat JSON shape of [`Channel`], validated on the way in.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ChannelWire {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pos: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    bits: Option<u8>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cmd: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    frame_bits: Option<u8>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

impl From<Channel> for ChannelWire {
    fn from(c: Channel) -> Self {
        let mut w = ChannelWire {
            pos: None,
            bits: None,
            cmd: None,
            frame_bits: None,
            error: None,
        };
        match c {
            Channel::Pos { pos, bits } => {
                w.pos = Some(pos);
                w.bits = Some(bits);
            }
            Channel::Cmd { cmd, frame_bits } => {
                w.cmd = Some(cmd);
                w.frame_bits = frame_bits;
            }
            Channel::Error(e) => w.error = Some(e),
        }
        w
    }
}

impl TryFrom<ChannelWire> for Channel {
    type Error = String;

    fn try_from(w: ChannelWire) -> Result<Self, String> {
        match w {
            ChannelWire {
                pos: Some(pos),
                bits: Some(bits),
                cmd: None,
                frame_bits: None,
                error: None,
            } => {
                if !matches!(bits, 16 | 18 | 20 | 26) {
                    return Err(format!("\"bits\" must be 16, 18, 20 or 26, not {bits}"));
                }
                if pos >> bits != 0 {
                    return Err(format!("position {pos} does not fit {bits} bits"));
                }
                Ok(Channel::Pos { pos, bits })
            }
            ChannelWire {
                pos: None,
                bits: None,
                cmd: Some(cmd),
                frame_bits,
                error: None,
            } => {
                if cmd >> 20 != 0 {
                    return Err(format!("command {cmd} does not fit 20 bits"));
                }
                if frame_bits.is_some_and(|b| b != 24 && b != 32) {
                    return Err("\"frame_bits\" must be 24 or 32".to_owned());
                }
                Ok(Channel::Cmd { cmd, frame_bits })
            }
            ChannelWire {
                pos: None,
                bits: None,
                cmd: None,
                frame_bits: None,
                error: Some(e),
            } => Ok(Channel::Error(e)),
            _ => Err(
                "a channel is {\"pos\":..,\"bits\":..}, {\"cmd\":..} or {\"error\":..}".to_owned(),
            ),
        }
    }
}

/// One XY2-100 / XY3-100 frame: a key per channel present.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForwardRecord {
    /// Frame start (first clock edge) in ns.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub t_ns: Option<u64>,
    /// X channel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub x: Option<Channel>,
    /// Y channel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub y: Option<Channel>,
    /// Z channel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub z: Option<Channel>,
    /// U channel (XY3-100).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u: Option<Channel>,
    /// W channel (XY3-100).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub w: Option<Channel>,
}

impl ForwardRecord {
    /// The channel named `lane` (`x`, `y`, `z`, `u` or `w`).
    pub fn channel(&self, lane: &str) -> Option<&Channel> {
        self.slot(lane).and_then(Option::as_ref)
    }

    /// Sets the channel named `lane`; other names are ignored.
    pub fn set(&mut self, lane: &str, channel: Channel) {
        let slot = match lane {
            "x" => &mut self.x,
            "y" => &mut self.y,
            "z" => &mut self.z,
            "u" => &mut self.u,
            "w" => &mut self.w,
            _ => return,
        };
        *slot = Some(channel);
    }

    fn slot(&self, lane: &str) -> Option<&Option<Channel>> {
        match lane {
            "x" => Some(&self.x),
            "y" => Some(&self.y),
            "z" => Some(&self.z),
            "u" => Some(&self.u),
            "w" => Some(&self.w),
            _ => None,
        }
    }
}

/// One HANS-100 frame as the decoder saw it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(into = "HansWire", try_from = "HansWire")]
pub enum HansRecord {
    /// An accepted frame.
    Frame {
        /// Frame start in ns.
        t_ns: Option<u64>,
        /// DATA1, DATA2, DATA3 (20 bits each).
        data: [u32; 3],
    },
    /// A rejected frame.
    Error {
        /// Frame start in ns.
        t_ns: Option<u64>,
        /// Why it was rejected.
        error: String,
    },
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct HansWire {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    t_ns: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    x: Option<Channel>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    y: Option<Channel>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    z: Option<Channel>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

impl From<HansRecord> for HansWire {
    fn from(r: HansRecord) -> Self {
        let pos = |pos| Some(Channel::Pos { pos, bits: 20 });
        match r {
            HansRecord::Frame {
                t_ns,
                data: [a, b, c],
            } => HansWire {
                t_ns,
                x: pos(a),
                y: pos(b),
                z: pos(c),
                error: None,
            },
            HansRecord::Error { t_ns, error } => HansWire {
                t_ns,
                x: None,
                y: None,
                z: None,
                error: Some(error),
            },
        }
    }
}

impl TryFrom<HansWire> for HansRecord {
    type Error = String;

    fn try_from(w: HansWire) -> Result<Self, String> {
        let word = |c: Option<Channel>, key: &str| match c {
            Some(Channel::Pos { pos, bits: 20 }) => Ok(pos),
            _ => Err(format!(
                "HANS-100 \"{key}\" must be {{\"pos\": <20-bit word>, \"bits\": 20}}"
            )),
        };
        match w {
            HansWire {
                t_ns,
                x: None,
                y: None,
                z: None,
                error: Some(error),
            } => Ok(HansRecord::Error { t_ns, error }),
            HansWire {
                t_ns,
                x,
                y,
                z,
                error: None,
            } => Ok(HansRecord::Frame {
                t_ns,
                data: [word(x, "x")?, word(y, "y")?, word(z, "z")?],
            }),
            _ => Err("a HANS-100 record has either \"x\", \"y\", \"z\" or \"error\"".to_owned()),
        }
    }
}

/// One backchannel event.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(into = "BackWire", try_from = "BackWire")]
pub enum BackRecord {
    /// A packet the parser accepted (SYNC packets included).
    Packet {
        /// Start bit of the packet's head byte, in ns.
        t_ns: Option<u64>,
        /// Type byte.
        ty: u8,
        /// Payload bytes.
        payload: Vec<u8>,
    },
    /// Lost sync, resync after dropped bytes, or a UART framing error.
    Error {
        /// When it happened, in ns.
        t_ns: Option<u64>,
        /// What happened.
        error: String,
    },
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct BackWire {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    t_ns: Option<u64>,
    #[serde(default, rename = "type", skip_serializing_if = "Option::is_none")]
    ty: Option<u8>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    payload: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

impl From<BackRecord> for BackWire {
    fn from(r: BackRecord) -> Self {
        match r {
            BackRecord::Packet { t_ns, ty, payload } => BackWire {
                t_ns,
                ty: Some(ty),
                payload: Some(to_hex(&payload)),
                error: None,
            },
            BackRecord::Error { t_ns, error } => BackWire {
                t_ns,
                ty: None,
                payload: None,
                error: Some(error),
            },
        }
    }
}

impl TryFrom<BackWire> for BackRecord {
    type Error = String;

    fn try_from(w: BackWire) -> Result<Self, String> {
        match w {
            BackWire {
                t_ns,
                ty: Some(ty),
                payload,
                error: None,
            } => {
                let payload = from_hex(payload.as_deref().unwrap_or(""))?;
                if payload.len() > 255 {
                    return Err(format!("payload of {} bytes exceeds 255", payload.len()));
                }
                Ok(BackRecord::Packet { t_ns, ty, payload })
            }
            BackWire {
                t_ns,
                ty: None,
                payload: None,
                error: Some(error),
            } => Ok(BackRecord::Error { t_ns, error }),
            _ => Err("a backchannel record has \"type\" (+ \"payload\") or \"error\"".to_owned()),
        }
    }
}

/// Lower-case hex of `bytes`. (Two tiny functions do not justify the `hex` crate.)
pub fn to_hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Parses hex (either case, even length, no separators).
pub fn from_hex(s: &str) -> Result<Vec<u8>, String> {
    if !s.len().is_multiple_of(2) {
        return Err(format!("payload \"{s}\" has an odd number of hex digits"));
    }
    s.as_bytes()
        .chunks(2)
        .map(|pair| {
            std::str::from_utf8(pair)
                .ok()
                .and_then(|p| u8::from_str_radix(p, 16).ok())
                .ok_or_else(|| format!("payload \"{s}\" is not hex"))
        })
        .collect()
}

/// Parses JSON lines (blank lines are skipped) into `(line number, record)` pairs.
pub fn parse<T: DeserializeOwned>(text: &str) -> Result<Vec<(usize, T)>, SimError> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l)
                .map(|r| (i + 1, r))
                .map_err(|e| SimError::Json {
                    line: i + 1,
                    message: e.to_string(),
                })
        })
        .collect()
}

/// One record as a JSON line (without the newline).
pub fn to_line<T: Serialize>(record: &T) -> String {
    // Serialising these types cannot fail: no maps with non-string keys, no floats.
    serde_json::to_string(record).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
}
