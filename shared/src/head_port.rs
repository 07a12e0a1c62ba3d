//! The head-side waveform port of the bridge board: which bit of the `u32` BSRR words
//! (README "DMA buffer layouts", XY2 / XY3 out; GPIO port D on the board) drives
//! each head-side pair, the XY2-100 / XY3-100 transmitters' pin maps on it, and the
//! output tick timing.
//!
//! Board wiring, not protocol: it lives here because the firmware's encoder
//! (`firmware/tasks/encode.rs`) and the host pipeline's simulated head
//! (`host-tests/src/pipeline/output.rs`) must encode on the same pins and ticks,
//! and `shared` is the crate both build on (host-tests cannot link the firmware's
//! Embassy / STM32 code). A change of the wiring is then one change here, and the
//! host tests decode what the firmware would drive.

use crate::model::Axis;
use crate::xy3::rx::Lines;
use crate::xy3::FrameSize;
use crate::{xy2, xy3};

/// BSRR bit (port-D pin) of head-side pairs 1, 2, 3, 4, 5, 7 and 8 (pair 6 carries
/// the controller-side STATUS out).
pub const PAIR_BITS: [u8; 7] = [0, 1, 2, 3, 10, 14, 15];

/// XY2-100 head: CLK pair 1, SYNC pair 2, X pair 3, Y pair 4, Z pair 5.
pub const XY2_PINS: xy2::tx::OutPinMap = xy2::tx::OutPinMap {
    clk: 0,
    sync: 1,
    x: 2,
    y: 3,
    z: Some(10),
};

/// XY3-100 head, every line: SYNC pair 1, CLK pair 2, X pair 3, Y pair 4, Z pair 5,
/// U pair 7, W pair 8.
pub const XY3_PINS: xy3::tx::OutPinMap = xy3::tx::OutPinMap {
    clk: 1,
    sync: 0,
    data: [Some(2), Some(3), Some(10), Some(14), Some(15)],
};

/// XY2-100 output tick rate: two ticks per bit of the 2 MHz bit clock (CLK high
/// with the new data, then CLK low).
pub const XY2_TICK_HZ: u32 = 4_000_000;

/// Idle ticks after a 32-bit XY3-100 frame: 64 + 16 = 80 ticks per frame make
/// 8 MHz at 100 kHz, an exact division of the board's 240 MHz timer clock.
const XY3_IDLE_32: u8 = 16;

/// [`XY2_PINS`] with Z only when the head's Z line is driven (`z`).
pub fn xy2_pins(z: bool) -> xy2::tx::OutPinMap {
    xy2::tx::OutPinMap {
        z: XY2_PINS.z.filter(|_| z),
        ..XY2_PINS
    }
}

/// [`XY3_PINS`] with only the data lines in `lines` driven (X and Y always are);
/// an undriven pair stays low.
pub fn xy3_pins(lines: Lines) -> xy3::tx::OutPinMap {
    let mut pins = XY3_PINS;
    for axis in [Axis::Z, Axis::U, Axis::W] {
        if let Some(pin) = pins.data.get_mut(axis.index()) {
            if !lines.has(axis) {
                *pin = None;
            }
        }
    }
    pins
}

/// Idle ticks after each XY3-100 frame of `size`: the transmitter's minimum for
/// 24-bit frames (50 ticks = 5 MHz at 100 kHz, already an exact division of the
/// timer clock), 16 for 32-bit ones.
pub const fn xy3_idle_ticks(size: FrameSize) -> u8 {
    match size {
        FrameSize::Bits24 => xy3::tx::MIN_IDLE_TICKS,
        FrameSize::Bits32 => XY3_IDLE_32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pin of `pins` is a head-side pair, and no two lines share one.
    fn on_distinct_pairs(pins: &[u8]) {
        for (i, p) in pins.iter().enumerate() {
            assert!(PAIR_BITS.contains(p), "bit {p} is not a head pair");
            assert!(!pins[..i].contains(p), "bit {p} drives two lines");
        }
    }

    #[test]
    fn pin_maps_use_distinct_head_pairs() {
        let p = XY2_PINS;
        on_distinct_pairs(&[p.clk, p.sync, p.x, p.y, p.z.unwrap()]);
        let p = XY3_PINS;
        let mut bits = vec![p.clk, p.sync];
        bits.extend(p.data.iter().map(|d| d.unwrap()));
        on_distinct_pairs(&bits);
    }

    #[test]
    fn only_driven_lines_keep_their_pins() {
        assert_eq!(xy2_pins(true), XY2_PINS);
        assert_eq!(xy2_pins(false).z, None);
        assert_eq!(xy2_pins(false).x, XY2_PINS.x);
        assert_eq!(xy3_pins(Lines::ALL), XY3_PINS);
        let xy = xy3_pins(Lines::XY);
        assert_eq!(xy.data, [Some(2), Some(3), None, None, None]);
        assert_eq!((xy.clk, xy.sync), (XY3_PINS.clk, XY3_PINS.sync));
        // X and Y are driven whatever `lines` says (the transmitter needs them).
        let u = Lines::new(&[Axis::X, Axis::U]).unwrap();
        assert_eq!(xy3_pins(u).data, [Some(2), Some(3), None, Some(14), None]);
    }

    #[test]
    fn transmitters_take_the_maps_and_ticks() {
        let link = xy2::LinkConfig::default();
        let ticks = (XY2_TICK_HZ / 100_000) as usize;
        assert!(xy2::tx::Transmitter::new(xy2_pins(true), ticks, link).is_ok());
        for (size, period) in [(FrameSize::Bits24, 50), (FrameSize::Bits32, 80)] {
            let config = xy3::tx::TxConfig {
                pins: xy3_pins(Lines::ALL),
                size,
                idle_ticks: xy3_idle_ticks(size),
            };
            let tx = xy3::tx::Transmitter::new(&config).unwrap();
            // The periods the idle ticks are chosen for (module docs).
            assert_eq!(tx.ticks_per_frame(), period, "{size:?}");
        }
    }
}
