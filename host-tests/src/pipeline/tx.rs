//! The `shared` XY2-100 / XY3-100 transmitters on a host pin map
//! ([`crate::line::drive::OutPinMap`]): one set-up for the controller generator
//! ([`super::stimulus`]) and the head output, so both drive their lines the same way.

use shared::head_port;
use shared::model::Axis;
use shared::xy3::rx::Lines;
use shared::xy3::FrameSize;
use shared::{xy2, xy3};

use crate::line::drive::OutPinMap;

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

/// An XY3-100 transmitter of `size` on `pins` driving the data lines `lines` (a
/// line must have a pin in `pins`), with the firmware's idle ticks
/// ([`head_port::xy3_idle_ticks`]), and the pin map of the lines it drives.
pub(super) fn xy3(
    pins: &OutPinMap,
    lines: Lines,
    size: FrameSize,
) -> Result<(xy3::tx::Transmitter, OutPinMap), xy3::tx::TxConfigError> {
    let keep = |axis: Axis, pin: Option<u8>| pin.filter(|_| lines.has(axis));
    let p = OutPinMap {
        z: keep(Axis::Z, pins.z),
        u: keep(Axis::U, pins.u),
        w: keep(Axis::W, pins.w),
        ..*pins
    };
    // A listed line without a pin would be silently missing from the waveform.
    for (axis, pin) in [(Axis::Z, p.z), (Axis::U, p.u), (Axis::W, p.w)] {
        if lines.has(axis) && pin.is_none() {
            return Err(xy3::tx::TxConfigError::MissingLine(axis));
        }
    }
    let tx = xy3::tx::Transmitter::new(&xy3::tx::TxConfig {
        pins: xy3::tx::OutPinMap {
            clk: p.clk,
            sync: p.sync,
            data: [Some(p.x), Some(p.y), p.z, p.u, p.w],
        },
        size,
        idle_ticks: head_port::xy3_idle_ticks(size),
    })?;
    Ok((tx, p))
}
