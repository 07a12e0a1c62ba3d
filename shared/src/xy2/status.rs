//! The STATUS line (head -> controller) in its two supported forms: a plain level and
//! the SCANLAB-style status word carried in 20-bit frames.

use core::fmt;

use super::frame::{decode, position16_word, DecodeError, Frame, LinkConfig, Mode};

/// Which line level means "OK" for a level-style STATUS line.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Polarity {
    /// Low = OK, high = fault (Newson and most legacy heads; the default).
    #[default]
    LowIsOk,
    /// High = OK, low = fault.
    HighIsOk,
}

/// What a level-style STATUS line says.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Health {
    /// The head is ready (position within limits, currents normal, regulator running).
    Ok,
    /// The head reports a fault of unspecified kind.
    Fault,
}

/// The setting of a level-style STATUS line.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StatusLevel {
    /// Which level means OK.
    pub polarity: Polarity,
}

impl StatusLevel {
    /// The health a line level (`true` = high) means.
    pub const fn health(self, line_high: bool) -> Health {
        let ok = match self.polarity {
            Polarity::LowIsOk => !line_high,
            Polarity::HighIsOk => line_high,
        };
        if ok {
            Health::Ok
        } else {
            Health::Fault
        }
    }

    /// The line level (`true` = high) to drive for `health`.
    pub const fn line_high(self, health: Health) -> bool {
        let ok = matches!(health, Health::Ok);
        match self.polarity {
            Polarity::LowIsOk => !ok,
            Polarity::HighIsOk => ok,
        }
    }
}

/// Per-byte bit: supply voltages OK.
const POWER_OK: u8 = 1 << 7;
/// Per-byte bit: temperature OK.
const TEMPERATURE_OK: u8 = 1 << 6;
/// Per-byte bit: position acknowledge Y.
const ACK_Y: u8 = 1 << 4;
/// Per-byte bit: position acknowledge X.
const ACK_X: u8 = 1 << 3;
/// The bits with a fixed value: 0, 1, 2 and 5.
const FIXED_MASK: u8 = 0b0010_0111;
/// Their values: 0, 2 and 5 are 1, bit 1 is 0.
const FIXED_VALUE: u8 = 0b0010_0101;

/// The SCANLAB-style status word: two equal bytes, each carrying these four flags and
/// four fixed bits (all OK = `0xFDFD`).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StatusWord {
    /// Bit 7: supply voltages OK.
    pub power_ok: bool,
    /// Bit 6: temperature OK.
    pub temperature_ok: bool,
    /// Bit 3: X reached its commanded position.
    pub position_ack_x: bool,
    /// Bit 4: Y reached its commanded position.
    pub position_ack_y: bool,
}

/// Why a 16-bit word (or the frame carrying it) is not a valid status word.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StatusError {
    /// The two bytes differ.
    BytesDiffer {
        /// Bits 15..8.
        high: u8,
        /// Bits 7..0.
        low: u8,
    },
    /// Bits 0, 2, 5 are not all 1 or bit 1 is not 0.
    FixedBits {
        /// The (repeated) byte.
        byte: u8,
    },
    /// The STATUS frame itself failed to decode.
    Frame(DecodeError),
    /// The STATUS frame decoded as an enhanced command, not as a status word.
    NotStatusWord,
}

impl fmt::Display for StatusError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BytesDiffer { high, low } => {
                write!(f, "status bytes differ: {high:#04x} vs {low:#04x}")
            }
            Self::FixedBits { byte } => {
                write!(f, "status byte {byte:#010b} has wrong fixed bits")
            }
            Self::Frame(e) => write!(f, "status frame: {e}"),
            Self::NotStatusWord => f.write_str("status frame carries a command"),
        }
    }
}

impl StatusWord {
    /// Everything OK (`0xFDFD`).
    pub const ALL_OK: StatusWord = StatusWord {
        power_ok: true,
        temperature_ok: true,
        position_ack_x: true,
        position_ack_y: true,
    };

    /// The 16-bit word (both bytes equal).
    pub const fn to_word(self) -> u16 {
        let mut byte = FIXED_VALUE;
        if self.power_ok {
            byte |= POWER_OK;
        }
        if self.temperature_ok {
            byte |= TEMPERATURE_OK;
        }
        if self.position_ack_x {
            byte |= ACK_X;
        }
        if self.position_ack_y {
            byte |= ACK_Y;
        }
        u16::from_be_bytes([byte, byte])
    }

    /// Parses a 16-bit word: the bytes must be equal and the fixed bits right.
    pub const fn from_word(word: u16) -> Result<Self, StatusError> {
        let [high, low] = word.to_be_bytes();
        if high != low {
            return Err(StatusError::BytesDiffer { high, low });
        }
        if low & FIXED_MASK != FIXED_VALUE {
            return Err(StatusError::FixedBits { byte: low });
        }
        Ok(StatusWord {
            power_ok: low & POWER_OK != 0,
            temperature_ok: low & TEMPERATURE_OK != 0,
            position_ack_x: low & ACK_X != 0,
            position_ack_y: low & ACK_Y != 0,
        })
    }

    /// The 20-bit STATUS frame: by our decision the standard 16-bit layout (`001`,
    /// word in bits 16..1, parity per `config.parity`), whatever `config.mode` is.
    pub fn to_frame(self, config: &LinkConfig) -> u32 {
        position16_word(self.to_word(), config.parity)
    }

    /// Parses a 20-bit STATUS frame (see [`StatusWord::to_frame`]).
    pub fn from_frame(word: u32, config: &LinkConfig) -> Result<Self, StatusError> {
        // Always the 16-bit layout; only the parity policy is the link's.
        let link = LinkConfig {
            mode: Mode::Standard16,
            parity: config.parity,
        };
        match decode(word, &link) {
            Ok(Frame::Position16(w)) => StatusWord::from_word(w),
            Ok(_) => Err(StatusError::NotStatusWord),
            Err(e) => Err(StatusError::Frame(e)),
        }
    }
}

#[cfg(test)]
// Wire literals are grouped by field (header_data_parity), not in nibbles: that is
// what makes them checkable by eye against the frame layout.
#[allow(clippy::unusual_byte_groupings)]
mod tests {
    use super::*;
    use crate::xy2::Parity;
    use proptest::prelude::*;

    use crate::xy2::vectors::{Flags, STATUS_FRAMES as FRAMES, STATUS_WORDS as WORDS};

    fn fields(w: StatusWord) -> Flags {
        (
            w.power_ok,
            w.temperature_ok,
            w.position_ack_x,
            w.position_ack_y,
        )
    }

    #[test]
    fn word_table() {
        for &(f, word) in WORDS {
            let (power_ok, temperature_ok, position_ack_x, position_ack_y) = f;
            let s = StatusWord {
                power_ok,
                temperature_ok,
                position_ack_x,
                position_ack_y,
            };
            assert_eq!(s.to_word(), word, "{f:?}");
            assert_eq!(StatusWord::from_word(word).map(fields), Ok(f));
        }
        assert_eq!(StatusWord::ALL_OK.to_word(), 0xFDFD);
    }

    #[test]
    fn frame_table() {
        for &(word, whole, data) in FRAMES {
            let s = StatusWord::from_word(word).unwrap();
            for mode in [Mode::Standard16, Mode::Extended18] {
                let cfg = |parity| LinkConfig { mode, parity };
                assert_eq!(s.to_frame(&cfg(Parity::WholeFrame)), whole);
                assert_eq!(s.to_frame(&cfg(Parity::DataOnly)), data);
                assert_eq!(s.to_frame(&cfg(Parity::Ignore)), whole);
                assert_eq!(
                    StatusWord::from_frame(whole, &cfg(Parity::WholeFrame)),
                    Ok(s)
                );
                assert_eq!(StatusWord::from_frame(data, &cfg(Parity::DataOnly)), Ok(s));
                assert_eq!(StatusWord::from_frame(data, &cfg(Parity::Ignore)), Ok(s));
                assert!(matches!(
                    StatusWord::from_frame(data, &cfg(Parity::WholeFrame)),
                    Err(StatusError::Frame(DecodeError::Parity { .. }))
                ));
                assert!(matches!(
                    StatusWord::from_frame(whole, &cfg(Parity::DataOnly)),
                    Err(StatusError::Frame(DecodeError::Parity { .. }))
                ));
            }
        }
    }

    #[test]
    fn bad_words_say_what_failed() {
        assert_eq!(
            StatusWord::from_word(0xFDFC),
            Err(StatusError::BytesDiffer {
                high: 0xFD,
                low: 0xFC
            })
        );
        assert_eq!(
            StatusWord::from_word(0x00FD),
            Err(StatusError::BytesDiffer {
                high: 0x00,
                low: 0xFD
            })
        );
        // One wrong fixed bit at a time: 0, 1, 2, 5.
        for bad in [0xFC, 0xFF, 0xF9, 0xDD] {
            let word = u16::from_be_bytes([bad, bad]);
            assert_eq!(
                StatusWord::from_word(word),
                Err(StatusError::FixedBits { byte: bad })
            );
        }
        assert_eq!(
            StatusWord::from_word(0),
            Err(StatusError::FixedBits { byte: 0 })
        );
    }

    #[test]
    fn bad_frames_say_what_failed() {
        let cfg = LinkConfig::default();
        // An enhanced command frame on STATUS: 111 + 0x05 0x01 + parity.
        assert_eq!(
            StatusWord::from_frame(0b111_00000101_00000001_0, &cfg),
            Err(StatusError::NotStatusWord)
        );
        // A valid 16-bit frame whose word is not a status word (0xFDFC, 13 data ones).
        assert_eq!(
            StatusWord::from_frame(0b001_1111110111111100_0, &cfg),
            Err(StatusError::BytesDiffer {
                high: 0xFD,
                low: 0xFC
            })
        );
        assert_eq!(
            StatusWord::from_frame(0b010_1111110111111101_1, &cfg),
            Err(StatusError::Frame(DecodeError::ReservedHeader {
                header: 0b010,
                mode: Mode::Standard16
            }))
        );
        assert_eq!(
            StatusWord::from_frame(1 << 20, &cfg),
            Err(StatusError::Frame(DecodeError::TooWide { word: 1 << 20 }))
        );
    }

    #[test]
    fn errors_display_what_failed() {
        let e = StatusError::BytesDiffer {
            high: 0xFD,
            low: 0xFC,
        };
        assert_eq!(e.to_string(), "status bytes differ: 0xfd vs 0xfc");
        let e = StatusError::FixedBits { byte: 0xFF };
        assert_eq!(e.to_string(), "status byte 0b11111111 has wrong fixed bits");
        let e = StatusError::Frame(DecodeError::TooWide { word: 1 << 20 });
        assert_eq!(
            e.to_string(),
            "status frame: word 0x100000 is wider than 20 bits"
        );
    }

    #[test]
    fn level_polarity() {
        let low_ok = StatusLevel::default();
        assert_eq!(low_ok.polarity, Polarity::LowIsOk);
        assert_eq!(low_ok.health(false), Health::Ok);
        assert_eq!(low_ok.health(true), Health::Fault);
        assert!(!low_ok.line_high(Health::Ok));
        assert!(low_ok.line_high(Health::Fault));
        let high_ok = StatusLevel {
            polarity: Polarity::HighIsOk,
        };
        assert_eq!(high_ok.health(true), Health::Ok);
        assert_eq!(high_ok.health(false), Health::Fault);
        assert!(high_ok.line_high(Health::Ok));
        assert!(!high_ok.line_high(Health::Fault));
    }

    proptest! {
        #[test]
        fn word_round_trip(p: bool, t: bool, x: bool, y: bool) {
            let s = StatusWord { power_ok: p, temperature_ok: t, position_ack_x: x, position_ack_y: y };
            prop_assert_eq!(StatusWord::from_word(s.to_word()), Ok(s));
            for parity in [Parity::WholeFrame, Parity::DataOnly, Parity::Ignore] {
                let cfg = LinkConfig { mode: Mode::Standard16, parity };
                prop_assert_eq!(StatusWord::from_frame(s.to_frame(&cfg), &cfg), Ok(s));
            }
        }

        /// Exactly the 16 valid words decode, and they re-encode unchanged.
        #[test]
        fn any_word_is_valid_or_rejected(word: u16) {
            match StatusWord::from_word(word) {
                Ok(s) => prop_assert_eq!(s.to_word(), word),
                Err(_) => {
                    let [h, l] = word.to_be_bytes();
                    prop_assert!(h != l || l & FIXED_MASK != FIXED_VALUE);
                }
            }
        }

        #[test]
        fn level_round_trip(high: bool, high_ok: bool) {
            let polarity = if high_ok { Polarity::HighIsOk } else { Polarity::LowIsOk };
            let level = StatusLevel { polarity };
            prop_assert_eq!(level.line_high(level.health(high)), high);
        }
    }

    #[test]
    fn single_bit_errors_in_status_frames_are_detected() {
        for &(word, _, _) in FRAMES {
            let s = StatusWord::from_word(word).unwrap();
            for parity in [Parity::WholeFrame, Parity::DataOnly] {
                let cfg = LinkConfig {
                    mode: Mode::Standard16,
                    parity,
                };
                let frame = s.to_frame(&cfg);
                for bit in 0..20 {
                    assert!(StatusWord::from_frame(frame ^ 1 << bit, &cfg).is_err());
                }
            }
        }
    }
}
