//! The `shared` XY2-100 / XY3-100 transmitters on a host pin map
//! ([`crate::line::drive::OutPinMap`]): one set-up for the controller generator
//! ([`super::stimulus`]) and the head output, so both drive their lines the same way.

use shared::xy3::FrameSize;
use shared::{xy2, xy3};

use crate::line::drive::OutPinMap;

/// Idle ticks after a 32-bit XY3-100 frame: 64 + 16 = 80 ticks per frame, as the
/// firmware (an exact division of its 240 MHz timer clock).
const XY3_IDLE_32: u8 = 16;

/// The pin map with Z kept only when the Z line is driven.
fn with_z(pins: &OutPinMap, z: bool) -> OutPinMap {
    OutPinMap {
        z: if z { pins.z } else { None },
        ..*pins
    }
}

/// An XY2-100 transmitter on `pins` (Z only when `z`), `ticks` words per frame, and
/// the pin map of the lines it drives.
pub(super) fn xy2(
    pins: &OutPinMap,
    z: bool,
    ticks: usize,
    link: xy2::LinkConfig,
) -> Result<(xy2::tx::Transmitter, OutPinMap), xy2::tx::TxError> {
    let p = with_z(pins, z);
    let tx_pins = xy2::tx::OutPinMap {
        clk: p.clk,
        sync: p.sync,
        x: p.x,
        y: p.y,
        z: p.z,
    };
    Ok((xy2::tx::Transmitter::new(tx_pins, ticks, link)?, p))
}

/// An XY3-100 transmitter of `size` on `pins` (X, Y, and Z only when `z`), with the
/// firmware's idle ticks, and the pin map of the lines it drives.
pub(super) fn xy3(
    pins: &OutPinMap,
    z: bool,
    size: FrameSize,
) -> Result<(xy3::tx::Transmitter, OutPinMap), xy3::tx::TxConfigError> {
    let p = with_z(pins, z);
    let idle_ticks = match size {
        FrameSize::Bits24 => xy3::tx::MIN_IDLE_TICKS,
        FrameSize::Bits32 => XY3_IDLE_32,
    };
    let tx = xy3::tx::Transmitter::new(&xy3::tx::TxConfig {
        pins: xy3::tx::OutPinMap {
            clk: p.clk,
            sync: p.sync,
            data: [Some(p.x), Some(p.y), p.z, None, None],
        },
        size,
        idle_ticks,
    })?;
    Ok((tx, p))
}
