//! The last step of the forward path for a waveform head: the bridge's neutral
//! [`ForwardFrame`] into the BSRR words of one frame slot of the head's transmitter
//! ([`xy2::tx`] / [`xy3::tx`]). The firmware's output task and the host pipeline
//! both call this, so what the simulation plays is what the board plays.
//!
//! The rule is the same on both protocols: a slot carries the whole frame or is
//! idle. A frame the head cannot take as it is (X or Y without a position, no Z
//! position while the Z line is driven, a command the head's protocol does not
//! carry, a transmitter error) leaves the slot idle, so the head sees a missing
//! frame rather than a guessed one (fail-safe policy in the README). HANS-100 heads
//! are not a waveform output (their SAI ring is written by `hans::tx`).
//!
//! # Cost
//! The wire words are computed here, straight from each position's MSB-aligned
//! value, and the transmitter only fills the slot (`write_words` /
//! `encode_words_for`): rounding to the field is one saturating add, and the protocol
//! modules' position-word functions ([`xy2::position_word`],
//! [`xy3::frame::position_bits_word`], the one place each layout is written down)
//! turn the value into the word: the XY2-100 parity bit is the value's parity (a
//! few XOR folds) XOR a constant of the link's mode and parity scope, the XY3-100
//! parity is the value's count of ones. Each mode / parity scope / frame size has
//! its own copy of the word code, so the header and parity constants fold instead
//! of being looked up per frame; the
//! checked routes through the frame enums (`xy2::encode`, `xy3::encode`) are only
//! taken for commands. XY3-100 heads dispatch once on frame size and "U or W
//! driven" and call the transmitter's fill of that layout directly, so a head
//! without U and W neither asks for them nor passes through the transmitter's own
//! dispatch. The tests compare every output with those routes. About 198
//! instructions for one slot on each of the worst path's heads together (XY3-100
//! 32-bit on X Y Z, XY2-100 with Z; 320, then 210 before), fills not included
//! (`cargo xtask profile worst`). The fills stay out of line (in ITCM on the
//! board, "Memory placement" in the README): inlining them here would save ~20.

use crate::model::{Axis, ForwardFrame, Position};
use crate::xy3::neutral::command_frame;
use crate::xy3::rx::Lines;
use crate::{xy2, xy3};

/// A waveform head transmitter with what it needs to map neutral frames onto it.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum HeadTx {
    /// XY2-100 / XY2-100E head.
    Xy2 {
        /// The transmitter (its pin map decides whether a Z line exists).
        tx: xy2::tx::Transmitter,
        /// The head's position width.
        mode: xy2::Mode,
        /// The Z line is driven: every slot needs a Z position.
        z: bool,
    },
    /// XY3-100 head (frame size from the transmitter).
    Xy3 {
        /// The transmitter; its pin map must drive exactly `lines`.
        tx: xy3::tx::Transmitter,
        /// The data lines driven ([`crate::bridge::Config::xy3_head_lines`]): every
        /// slot needs a position (or, on X, a command) for each of them.
        lines: Lines,
    },
}

impl HeadTx {
    /// Words (ticks) per frame slot.
    pub const fn ticks_per_frame(&self) -> usize {
        match self {
            HeadTx::Xy2 { tx, .. } => tx.ticks_per_frame(),
            HeadTx::Xy3 { tx, .. } => tx.ticks_per_frame(),
        }
    }

    /// Fills `slot` with one idle frame period: XY2-100 all lines low, XY3-100 SYNC
    /// high (its first word sets the levels, the rest leave them).
    pub fn idle(&self, slot: &mut [u32]) {
        match self {
            HeadTx::Xy2 { tx, .. } => slot.fill(tx.idle_word()),
            // The only error is a slot shorter than a frame period, which the caller
            // sizes from `ticks_per_frame`: nothing better to write into it then.
            HeadTx::Xy3 { tx, .. } => {
                let _ = tx.idle(slot);
            }
        }
    }

    /// Encodes `frame` into `slot` (exactly [`Self::ticks_per_frame`] words), or
    /// idles the slot for `None` and for a frame the head cannot take (module docs).
    /// Returns whether a frame was written.
    pub fn encode(&self, frame: Option<&ForwardFrame>, slot: &mut [u32]) -> bool {
        let written = match (self, frame) {
            (HeadTx::Xy2 { tx, mode, z }, Some(f)) => {
                xy2_words(tx, f, *mode, *z).is_some_and(|w| tx.write_words(slot, w).is_ok())
            }
            (HeadTx::Xy3 { tx, lines }, Some(f)) => xy3_write(tx, f, *lines, slot),
            (_, None) => false,
        };
        if !written {
            self.idle(slot);
        }
        written
    }
}

/// `p` at a field of `bits` bits (1..=31; a constant after inlining):
/// [`Position::to_raw`]'s rounding (to nearest, ties upward, saturated at full scale)
/// in one saturating add. Below full scale the sum cannot wrap (the value is below
/// the field's top step and the half step below one step); at full scale it either
/// stays in the top step or saturates there, and both shift down to the field's
/// maximum.
#[inline(always)]
fn rounded(p: Position, bits: u32) -> u32 {
    let shift = 32 - bits;
    p.aligned().saturating_add(1 << (shift - 1)) >> shift
}

/// The XY2-100 wire words of one slot (X, Y, Z; Z 0 without a Z line), or `None`
/// if `f` lacks one of them or the link cannot carry it. Exactly what
/// [`xy2::tx::Transmitter::write_frame`] would write for the frames
/// `xy2::Frame::from_position` / `from_command` give (the tests check it), with the
/// position words computed straight from the rounded value by
/// [`xy2::position_word`], one copy per mode and parity scope so its header and
/// parity constants fold.
#[inline(always)]
fn xy2_words(
    tx: &xy2::tx::Transmitter,
    f: &ForwardFrame,
    mode: xy2::Mode,
    z: bool,
) -> Option<[u32; 3]> {
    let link = tx.link();
    // A position frame of the head's width on a link of the other mode is refused
    // by the encoder; every slot carries at least Y's.
    if mode != link.mode {
        return None;
    }
    // `Parity::Ignore` encodes whole-frame parity, like `xy2::encode`.
    use xy2::{Mode, Parity};
    match (mode, link.parity) {
        (Mode::Standard16, Parity::DataOnly) => xy2_slot::<16, false>(f, &link, z),
        (Mode::Standard16, _) => xy2_slot::<16, true>(f, &link, z),
        (Mode::Extended18, Parity::DataOnly) => xy2_slot::<18, false>(f, &link, z),
        (Mode::Extended18, _) => xy2_slot::<18, true>(f, &link, z),
    }
}

/// [`xy2_words`] for positions of `BITS` bits and whole-frame parity if `WHOLE`.
#[inline(always)]
fn xy2_slot<const BITS: u32, const WHOLE: bool>(
    f: &ForwardFrame,
    link: &xy2::LinkConfig,
    z: bool,
) -> Option<[u32; 3]> {
    // Inner functions, not closures: those are not inlined here, and each call
    // would then pay for a call and the constants it could not fold.
    #[inline(always)]
    fn word<const BITS: u32, const WHOLE: bool>(p: Position) -> u32 {
        xy2::position_word::<BITS, WHOLE>(rounded(p, BITS))
    }
    #[inline(always)]
    fn pos<const BITS: u32, const WHOLE: bool>(f: &ForwardFrame, a: Axis) -> Option<u32> {
        f.axis(a).map(word::<BITS, WHOLE>)
    }
    let pos = |a: Axis| pos::<BITS, WHOLE>(f, a);
    // A command rides on X in place of the position (XY2-100 enhanced); a command
    // XY2-100 cannot carry falls back to the X position.
    let x = match f.command.and_then(xy2::Frame::from_command) {
        Some(c) => xy2::encode(c, link).ok()?,
        None => pos(Axis::X)?,
    };
    // A driven Z line needs a Z frame: all-zero bits would be an invalid frame on the
    // head's Z channel. Without a Z pin the transmitter ignores the word.
    let z = if z { pos(Axis::Z)? } else { 0 };
    Some([x, pos(Axis::Y)?, z])
}

/// Writes the XY3-100 slot of `f` into `slot`; false (nothing useful written) if `f`
/// lacks a frame for one of the driven lines, carries a command XY3-100 cannot send,
/// the transmitter's pins for Z, U and W are not exactly those of `lines` (which
/// [`xy3::tx::Transmitter::encode`] would refuse too), or `slot` is too short. Axes
/// `f` carries for lines the head does not drive are left out.
///
/// The words are built at the transmitter's size here, once, so the transmitter
/// only fills the slot ([`xy3::tx::Transmitter::encode_words_for`]): this is exactly
/// what [`xy3::tx::Transmitter::encode`] would write for the frames
/// `position_frame` / `command_frame` give, without checking again what this
/// function guarantees (frame size, a frame exactly for every driven line).
#[inline(always)]
fn xy3_write(tx: &xy3::tx::Transmitter, f: &ForwardFrame, lines: Lines, slot: &mut [u32]) -> bool {
    // X and Y always have pins (the transmitter requires them) and always go out;
    // Z, U and W must be driven exactly as `lines` says.
    const OPTIONAL: u8 = 0b11100;
    if (tx.driven() ^ lines.bits()) & OPTIONAL != 0 {
        return false;
    }
    // One copy per frame size, so the layout constants fold, and per "U or W
    // driven" (then, and only then, `lines` has U or W, as just checked), so the
    // common X Y Z head neither asks for U and W nor fills their lines.
    #[inline(always)]
    fn write<const BITS32: bool, const WIDE: bool>(
        tx: &xy3::tx::Transmitter,
        f: &ForwardFrame,
        lines: Lines,
        slot: &mut [u32],
    ) -> bool {
        xy3_slot::<BITS32, WIDE>(f, lines)
            .is_some_and(|words| tx.encode_words_for::<BITS32, WIDE>(words, slot).is_ok())
    }
    match (tx.size(), tx.wide()) {
        (xy3::FrameSize::Bits24, false) => write::<false, false>(tx, f, lines, slot),
        (xy3::FrameSize::Bits24, true) => write::<false, true>(tx, f, lines, slot),
        (xy3::FrameSize::Bits32, false) => write::<true, false>(tx, f, lines, slot),
        (xy3::FrameSize::Bits32, true) => write::<true, true>(tx, f, lines, slot),
    }
}

/// The wire words of [`xy3_write`] (0 for lines not driven) for 32-bit frames if
/// `BITS32`, else 24-bit ones, and U or W driven if `WIDE`. A position word is
/// computed straight from the rounded value by [`xy3::frame::position_bits_word`]
/// (XY3-100 §5.1 layout).
#[inline(always)]
fn xy3_slot<const BITS32: bool, const WIDE: bool>(
    f: &ForwardFrame,
    lines: Lines,
) -> Option<[u32; 5]> {
    let size = if BITS32 {
        xy3::FrameSize::Bits32
    } else {
        xy3::FrameSize::Bits24
    };
    // Inner functions, not closures (see `xy2_slot`).
    #[inline(always)]
    fn word<const BITS32: bool>(p: Position) -> u32 {
        let size = if BITS32 {
            xy3::FrameSize::Bits32
        } else {
            xy3::FrameSize::Bits24
        };
        xy3::frame::position_bits_word(rounded(p, u32::from(size.position_bits())), size)
    }
    #[inline(always)]
    fn pos<const BITS32: bool>(f: &ForwardFrame, a: Axis) -> Option<u32> {
        f.axis(a).map(word::<BITS32>)
    }
    let pos = |a: Axis| pos::<BITS32>(f, a);
    // The command frame takes X's place (XY3-100 sends commands on the X line).
    let x = match f.command {
        Some(c) => command_frame(&c, size)
            .ok()
            .and_then(|frame| xy3::encode(&frame).ok())
            .map(|(w, _)| w),
        None => pos(Axis::X),
    }?;
    // A driven line needs its frame: all-zero bits would be a dead line to the head.
    let other = |a: Axis| if lines.has(a) { pos(a) } else { Some(0) };
    let (u, w) = if WIDE {
        (other(Axis::U)?, other(Axis::W)?)
    } else {
        (0, 0)
    };
    Some([x, pos(Axis::Y)?, other(Axis::Z)?, u, w])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Command;
    use crate::xy3::neutral::position_frame;
    use crate::xy3::FrameSize;

    fn pos(raw: u32) -> Option<Position> {
        Position::from_raw(raw, 20).ok()
    }

    /// X, Y, Z present (20-bit positions), no command.
    fn xyz() -> ForwardFrame {
        ForwardFrame {
            axes: [pos(0x1_2345), pos(0xA_BCDE), pos(0x8_0000), None, None],
            ..ForwardFrame::default()
        }
    }

    /// All five axes present.
    fn xyzuw() -> ForwardFrame {
        let mut f = xyz();
        f.axes[Axis::U.index()] = pos(0x0_0F0F);
        f.axes[Axis::W.index()] = pos(0xF_5A5A);
        f
    }

    fn xy2(mode: xy2::Mode, z: bool) -> HeadTx {
        let pins = xy2::tx::OutPinMap {
            clk: 4,
            sync: 5,
            x: 6,
            y: 7,
            z: z.then_some(8),
        };
        let link = xy2::LinkConfig {
            mode,
            ..xy2::LinkConfig::default()
        };
        match xy2::tx::Transmitter::new(pins, 50, link) {
            Ok(tx) => HeadTx::Xy2 { tx, mode, z },
            Err(e) => panic!("{e}"),
        }
    }

    /// An XY3-100 head on the firmware's pins driving X, Y and Z if `z`.
    fn xy3(size: FrameSize, z: bool) -> HeadTx {
        let lines = if z { Lines::XYZ } else { Lines::XY };
        xy3_lines(size, lines)
    }

    /// An XY3-100 head on the firmware's pins (`head_port::xy3_pins`) driving `lines`.
    fn xy3_lines(size: FrameSize, lines: Lines) -> HeadTx {
        let config = xy3::tx::TxConfig {
            pins: crate::head_port::xy3_pins(lines),
            size,
            idle_ticks: xy3::tx::MIN_IDLE_TICKS,
        };
        match xy3::tx::Transmitter::new(&config) {
            Ok(tx) => HeadTx::Xy3 { tx, lines },
            Err(e) => panic!("{e}"),
        }
    }

    /// `head.encode(frame)` into a slot pre-filled with garbage: (written, words).
    fn run(head: &HeadTx, frame: Option<&ForwardFrame>) -> (bool, Vec<u32>) {
        let mut slot = vec![0xDEAD_BEEF; head.ticks_per_frame()];
        let ok = head.encode(frame, &mut slot);
        (ok, slot)
    }

    fn idle(head: &HeadTx) -> Vec<u32> {
        let mut slot = vec![0xDEAD_BEEF; head.ticks_per_frame()];
        head.idle(&mut slot);
        slot
    }

    /// What the XY2-100 transmitter itself writes for `frame`.
    fn xy2_direct(head: &HeadTx, frame: xy2::tx::TxFrame) -> Vec<u32> {
        let HeadTx::Xy2 { tx, .. } = head else {
            panic!("not an XY2-100 head")
        };
        let mut slot = vec![0; tx.ticks_per_frame()];
        assert_eq!(tx.write_frame(&mut slot, &frame), Ok(()));
        slot
    }

    /// What the XY3-100 transmitter itself writes for `frames`.
    fn xy3_direct(head: &HeadTx, frames: [Option<xy3::Frame>; 5]) -> Vec<u32> {
        let HeadTx::Xy3 { tx, .. } = head else {
            panic!("not an XY3-100 head")
        };
        let mut slot = vec![0; tx.ticks_per_frame()];
        assert_eq!(tx.encode(&frames, &mut slot), Ok(()));
        slot
    }

    /// No frame, or a frame without X, Y or (Z driven) Z: an idle slot. `no_z`, the
    /// same head without a Z line, takes a frame without Z.
    fn missing_axes_idle(z: &HeadTx, no_z: &HeadTx) {
        let i = idle(z);
        assert_eq!(run(z, None), (false, i.clone()));
        for axis in [Axis::X, Axis::Y, Axis::Z] {
            let mut f = xyz();
            f.axes[axis.index()] = None;
            assert_eq!(run(z, Some(&f)), (false, i.clone()), "{axis:?}");
        }
        let mut f = xyz();
        f.axes[Axis::Z.index()] = None;
        assert!(run(no_z, Some(&f)).0);
    }

    #[test]
    fn idle_levels() {
        let h = xy2(xy2::Mode::Standard16, true);
        let HeadTx::Xy2 { tx, .. } = h else { panic!() };
        assert!(idle(&h).iter().all(|&w| w == tx.idle_word()));
        // XY3-100: SYNC (bit 0) set, CLK (bit 1) reset by the first word.
        let w = idle(&xy3(FrameSize::Bits32, true));
        assert_eq!(w[0] & 1, 1);
        assert_ne!(w[0] & 1 << (1 + 16), 0);
        assert!(w[1..].iter().all(|&x| x == 0));
    }

    #[test]
    fn xy2_positions_and_z() {
        let f = xyz();
        let p = |a: Axis, m| f.axis(a).map(|p| xy2::Frame::from_position(p, m));
        for mode in [xy2::Mode::Standard16, xy2::Mode::Extended18] {
            for z in [false, true] {
                let h = xy2(mode, z);
                let (ok, words) = run(&h, Some(&f));
                assert!(ok, "{mode:?} z={z}");
                let want = xy2::tx::TxFrame {
                    x: p(Axis::X, mode).unwrap(),
                    y: p(Axis::Y, mode).unwrap(),
                    z: if z { p(Axis::Z, mode) } else { None },
                };
                assert_eq!(words, xy2_direct(&h, want), "{mode:?} z={z}");
            }
        }
    }

    #[test]
    fn xy2_command_replaces_x() {
        let h = xy2(xy2::Mode::Standard16, false);
        let command = Command::Xy2Enhanced {
            command: 0x5A,
            parameter: 0x0F,
        };
        let f = ForwardFrame {
            command: Some(command),
            axes: [None, pos(0x4_0000), None, None, None],
            ..ForwardFrame::default()
        };
        let (ok, words) = run(&h, Some(&f));
        assert!(ok);
        let want = xy2::tx::TxFrame {
            x: xy2::Frame::Command {
                command: 0x5A,
                parameter: 0x0F,
            },
            y: xy2::Frame::from_position(pos(0x4_0000).unwrap(), xy2::Mode::Standard16),
            z: None,
        };
        assert_eq!(words, xy2_direct(&h, want));
        // An XY3-100 command XY2-100 cannot carry leaves X's position in place.
        let f = ForwardFrame {
            command: Some(Command::Xy3(0x12)),
            ..xyz()
        };
        assert_eq!(run(&h, Some(&f)), run(&h, Some(&xyz())));
        assert!(run(&h, Some(&f)).0);
    }

    #[test]
    fn xy2_missing_axis_or_refused_frame_idles() {
        let h = xy2(xy2::Mode::Standard16, true);
        let i = idle(&h);
        missing_axes_idle(&h, &xy2(xy2::Mode::Standard16, false));
        // A command on an 18-bit link is refused by the encoder: idle, not a guess.
        let h18 = xy2(xy2::Mode::Extended18, false);
        let f = ForwardFrame {
            command: Some(Command::Xy2Enhanced {
                command: 1,
                parameter: 2,
            }),
            ..xyz()
        };
        assert_eq!(run(&h18, Some(&f)), (false, idle(&h18)));
        // A slot of the wrong length: refused, filled with idle, no panic.
        let mut short = vec![0xDEAD_BEEF; 7];
        assert!(!h.encode(Some(&xyz()), &mut short));
        assert!(short.iter().all(|&w| w == i[0]));
    }

    #[test]
    fn xy3_positions_and_z() {
        let f = xyz();
        for size in [FrameSize::Bits24, FrameSize::Bits32] {
            let p = |a: Axis| f.axis(a).map(|p| position_frame(p, size));
            for z in [false, true] {
                let h = xy3(size, z);
                let (ok, words) = run(&h, Some(&f));
                assert!(ok, "{size:?} z={z}");
                let zf = if z { p(Axis::Z) } else { None };
                let want = xy3_direct(&h, [p(Axis::X), p(Axis::Y), zf, None, None]);
                assert_eq!(words, want, "{size:?} z={z}");
            }
        }
    }

    #[test]
    fn xy3_command_replaces_x() {
        for size in [FrameSize::Bits24, FrameSize::Bits32] {
            let h = xy3(size, false);
            let f = ForwardFrame {
                command: Some(Command::Xy3(0x0123)),
                axes: [None, pos(0x7_0000), None, None, None],
                ..ForwardFrame::default()
            };
            let (ok, words) = run(&h, Some(&f));
            assert!(ok, "{size:?}");
            let c = command_frame(&Command::Xy3(0x0123), size).ok();
            let y = pos(0x7_0000).map(|p| position_frame(p, size));
            assert_eq!(words, xy3_direct(&h, [c, y, None, None, None]), "{size:?}");
        }
    }

    #[test]
    fn xy3_missing_axis_or_refused_frame_idles() {
        let h = xy3(FrameSize::Bits32, true);
        let i = idle(&h);
        missing_axes_idle(&h, &xy3(FrameSize::Bits32, false));
        // Commands XY3-100 cannot send: an XY2-100 one, a code wider than the field.
        for command in [
            Command::Xy2Enhanced {
                command: 1,
                parameter: 2,
            },
            Command::Xy3(u32::MAX),
        ] {
            let f = ForwardFrame {
                command: Some(command),
                ..xyz()
            };
            assert_eq!(run(&h, Some(&f)), (false, i.clone()), "{command:?}");
        }
        // A slot shorter than a frame period: refused, no panic.
        let mut short = [0xDEAD_BEEF; 5];
        assert!(!h.encode(Some(&xyz()), &mut short));
    }

    #[test]
    fn xy3_u_and_w_lines() {
        use Axis::{U, W, X, Y, Z};
        let f = xyzuw();
        for size in [FrameSize::Bits24, FrameSize::Bits32] {
            let p = |a: Axis| f.axis(a).map(|p| position_frame(p, size));
            for axes in [&[X, Y, Z, U, W][..], &[X, Y, U], &[X, Y, Z, W], &[X, Y, W]] {
                let lines = Lines::new(axes).unwrap();
                let h = xy3_lines(size, lines);
                // Every driven line carries its position, the others nothing (a
                // frame's axes beyond the head's lines are left out, not refused).
                let want = Axis::ALL.map(|a| if lines.has(a) { p(a) } else { None });
                assert_eq!(run(&h, Some(&f)), (true, xy3_direct(&h, want)), "{axes:?}");
                // A driven line without a position: idle, never a zero frame.
                for missing in lines.axes() {
                    let mut g = f;
                    g.axes[missing.index()] = None;
                    assert_eq!(run(&h, Some(&g)), (false, idle(&h)), "{axes:?} {missing:?}");
                }
                // A command replaces X; U and W still go out.
                let g = ForwardFrame {
                    command: Some(Command::Xy3(0x0042)),
                    ..f
                };
                let mut want_c = want;
                want_c[0] = command_frame(&Command::Xy3(0x0042), size).ok();
                assert_eq!(run(&h, Some(&g)), (true, xy3_direct(&h, want_c)));
            }
        }
        // U and W on the wire: their pins toggle with the data, the idle ones never.
        let h = xy3_lines(FrameSize::Bits24, Lines::new(&[X, Y, U]).unwrap());
        let (ok, words) = run(&h, Some(&f));
        assert!(ok);
        assert!(words.iter().any(|w| w & 1 << 14 != 0), "U (PD14) never set");
        assert!(
            words.iter().all(|w| w & 1 << 15 == 0),
            "W (PD15) not driven"
        );
    }

    /// A transmitter whose Z / U / W pins are not those of `lines` idles every
    /// slot, as the transmitter's own frame checks would have it.
    #[test]
    fn xy3_pins_not_matching_lines_idle() {
        use Axis::{U, X, Y, Z};
        let f = xyzuw();
        for (pins, lines) in [
            (&[X, Y][..], &[X, Y, Z][..]),
            (&[X, Y, Z], &[X, Y]),
            (&[X, Y, U], &[X, Y, Z]),
        ] {
            let HeadTx::Xy3 { tx, .. } = xy3_lines(FrameSize::Bits32, Lines::new(pins).unwrap())
            else {
                panic!()
            };
            let h = HeadTx::Xy3 {
                tx,
                lines: Lines::new(lines).unwrap(),
            };
            assert_eq!(run(&h, Some(&f)), (false, idle(&h)), "{pins:?} {lines:?}");
        }
    }

    /// What the head encoder wrote before it encoded the XY3-100 words itself: the
    /// frames of the driven lines through the transmitter's checked `encode`.
    fn xy3_reference(head: &HeadTx, f: &ForwardFrame) -> (bool, Vec<u32>) {
        let HeadTx::Xy3 { tx, lines } = head else {
            panic!("not an XY3-100 head")
        };
        let size = tx.size();
        let pos = |a: Axis| f.axis(a).map(|p| position_frame(p, size));
        let frames = || -> Option<[Option<xy3::Frame>; 5]> {
            let x = match f.command {
                Some(c) => command_frame(&c, size).ok(),
                None => pos(Axis::X),
            }?;
            let other = |a: Axis| {
                if lines.has(a) {
                    pos(a).map(Some)
                } else {
                    Some(None)
                }
            };
            Some([
                Some(x),
                Some(pos(Axis::Y)?),
                other(Axis::Z)?,
                other(Axis::U)?,
                other(Axis::W)?,
            ])
        };
        let mut slot = vec![0xDEAD_BEEF; tx.ticks_per_frame()];
        match frames().map(|t| tx.encode(&t, &mut slot)) {
            Some(Ok(())) => (true, slot),
            _ => (false, idle(head)),
        }
    }

    /// What the head encoder wrote before it computed the XY2-100 words itself: the
    /// frames `from_position` / `from_command` give through the transmitter's
    /// checked `write_frame`.
    fn xy2_reference(head: &HeadTx, f: &ForwardFrame) -> (bool, Vec<u32>) {
        let HeadTx::Xy2 { tx, mode, z } = head else {
            panic!("not an XY2-100 head")
        };
        let pos = |a: Axis| f.axis(a).map(|p| xy2::Frame::from_position(p, *mode));
        let frame = || -> Option<xy2::tx::TxFrame> {
            let x = f
                .command
                .and_then(xy2::Frame::from_command)
                .or_else(|| pos(Axis::X))?;
            let z = if *z { Some(pos(Axis::Z)?) } else { None };
            Some(xy2::tx::TxFrame {
                x,
                y: pos(Axis::Y)?,
                z,
            })
        };
        let mut slot = vec![0xDEAD_BEEF; tx.ticks_per_frame()];
        match frame().map(|t| tx.write_frame(&mut slot, &t)) {
            Some(Ok(())) => (true, slot),
            _ => (false, idle(head)),
        }
    }

    /// A random neutral frame: any axes present at any width, commands of either
    /// protocol (XY3-100 codes also beyond the field), positions near full scale
    /// and the centre as often as elsewhere.
    fn any_frame() -> impl proptest::strategy::Strategy<Value = ForwardFrame> {
        use proptest::prelude::*;
        let value = prop_oneof![
            any::<u32>(),
            (0u32..64).prop_map(|d| u32::MAX - d),
            Just(0x8000_0000)
        ];
        let axis = proptest::option::of((value, 1u8..=32));
        let command = proptest::option::of((any::<bool>(), 0u32..0x20_0000, any::<u8>()));
        (proptest::array::uniform5(axis), command).prop_map(|(raw, command)| {
            let mut f = ForwardFrame::default();
            for (axis, a) in f.axes.iter_mut().zip(raw) {
                *axis = a.and_then(|(v, bits)| {
                    Position::from_raw(v >> (32 - u32::from(bits)), bits).ok()
                });
            }
            f.command = command.map(|(xy3, code, parameter)| {
                if xy3 {
                    Command::Xy3(code)
                } else {
                    Command::Xy2Enhanced {
                        command: code as u8,
                        parameter,
                    }
                }
            });
            f
        })
    }

    proptest::proptest! {
        /// The XY2-100 path equals the checked reference for random frames, both
        /// modes and every parity policy, with and without a Z line, also when the
        /// head's mode and the transmitter's link disagree.
        #[test]
        fn xy2_matches_the_checked_encoder(
            f in any_frame(),
            modes in proptest::array::uniform2(proptest::bool::ANY),
            parity in 0u8..3,
            z in proptest::array::uniform2(proptest::bool::ANY),
        ) {
            let mode = |m| if m { xy2::Mode::Extended18 } else { xy2::Mode::Standard16 };
            let parity = match parity {
                0 => xy2::Parity::WholeFrame,
                1 => xy2::Parity::DataOnly,
                _ => xy2::Parity::Ignore,
            };
            let pins = xy2::tx::OutPinMap { clk: 4, sync: 5, x: 6, y: 7, z: z[0].then_some(8) };
            let link = xy2::LinkConfig { mode: mode(modes[0]), parity };
            let tx = xy2::tx::Transmitter::new(pins, 44, link).unwrap();
            let h = HeadTx::Xy2 { tx, mode: mode(modes[1]), z: z[1] };
            proptest::prop_assert_eq!(run(&h, Some(&f)), xy2_reference(&h, &f));
        }

        /// The XY3-100 path equals the checked reference for random frames (any
        /// axes present at any width, also at full scale, commands XY3-100 can and
        /// cannot send), random line sets and both frame sizes.
        #[test]
        fn xy3_matches_the_checked_encoder(
            f in any_frame(),
            optional in proptest::array::uniform3(proptest::bool::ANY),
            big in proptest::bool::ANY,
        ) {
            let mut axes = vec![Axis::X, Axis::Y];
            axes.extend([Axis::Z, Axis::U, Axis::W].into_iter().zip(optional).filter(|(_, on)| *on).map(|(a, _)| a));
            let size = if big { FrameSize::Bits32 } else { FrameSize::Bits24 };
            let h = xy3_lines(size, Lines::new(&axes).unwrap());
            proptest::prop_assert_eq!(run(&h, Some(&f)), xy3_reference(&h, &f));
        }
    }
}
