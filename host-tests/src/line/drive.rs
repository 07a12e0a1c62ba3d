//! Output side: the transmit DMA buffers -> waveforms (layouts items 4 and 5).

use super::{check_bits, positive, ps, roles, LineError};
use crate::wave::{Ps, Signal, Waveform, PS_PER_S};

/// Which output port bit drives which line (layouts item 4). Optional lines that are
/// `None` produce no signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutPinMap {
    /// CLK bit index (0..15).
    pub clk: u8,
    /// SYNC bit index.
    pub sync: u8,
    /// X data bit index.
    pub x: u8,
    /// Y data bit index.
    pub y: u8,
    /// Z data bit index.
    pub z: Option<u8>,
    /// U data bit index (XY3-100).
    pub u: Option<u8>,
    /// W data bit index (XY3-100).
    pub w: Option<u8>,
}

impl OutPinMap {
    /// The lines of a `shared` XY2-100 transmitter's pin map (no U / W).
    pub const fn from_xy2(p: &shared::xy2::tx::OutPinMap) -> OutPinMap {
        OutPinMap {
            clk: p.clk,
            sync: p.sync,
            x: p.x,
            y: p.y,
            z: p.z,
            u: None,
            w: None,
        }
    }

    /// The lines of a `shared` XY3-100 transmitter's pin map, or `None` without X
    /// or Y (which every XY3-100 link drives).
    pub const fn from_xy3(p: &shared::xy3::tx::OutPinMap) -> Option<OutPinMap> {
        let [x, y, z, u, w] = p.data;
        let (Some(x), Some(y)) = (x, y) else {
            return None;
        };
        Some(OutPinMap {
            clk: p.clk,
            sync: p.sync,
            x,
            y,
            z,
            u,
            w,
        })
    }

    /// `(bit, role)` pairs of the mapped pins.
    pub fn pins(&self) -> Vec<(u8, &'static str)> {
        let mut v = vec![
            (self.clk, roles::CLK),
            (self.sync, roles::SYNC),
            (self.x, roles::X),
            (self.y, roles::Y),
        ];
        v.extend(self.z.map(|b| (b, roles::Z)));
        v.extend(self.u.map(|b| (b, roles::U)));
        v.extend(self.w.map(|b| (b, roles::W)));
        v
    }
}

/// Plays BSRR words into a waveform: word `k` takes effect at `t0_ps + k * tick_ps`.
/// Low half bit `i` sets pin `i`, high half bit `i + 16` resets it; when both are set the
/// set wins (as on STM32 GPIO). Pins start at `initial` levels given per role (missing
/// roles start low).
pub fn bsrr_to_wave(
    words: &[u32],
    tick_ps: f64,
    t0_ps: Ps,
    pins: &OutPinMap,
    initial: &[(&str, bool)],
) -> Result<Waveform, LineError> {
    let tick = positive("tick_ps", tick_ps)?;
    let pins = pins.pins();
    let bits: Vec<u8> = pins.iter().map(|&(b, _)| b).collect();
    check_bits(&bits, 16)?;
    let mut sigs: Vec<(u8, Signal)> = pins
        .iter()
        .map(|&(b, role)| {
            let init = initial
                .iter()
                .find(|(r, _)| *r == role)
                .is_some_and(|&(_, l)| l);
            (b, Signal::new(role, init))
        })
        .collect();
    for (k, &word) in words.iter().enumerate() {
        let t = t0_ps.saturating_add(ps(k as f64 * tick));
        for (b, s) in sigs.iter_mut() {
            let set = word & (1 << *b) != 0;
            let reset = word & (1 << (*b + 16)) != 0;
            if set || reset {
                // Times grow with k, so push cannot fail.
                let _ = s.push(t, set);
            }
        }
    }
    let mut wave = Waveform::new();
    for (_, s) in sigs {
        wave.insert(s);
    }
    Ok(wave)
}

/// HANS-100 out SPI master bit rate.
pub const HANS_BIT_RATE_HZ: f64 = 12.5e6;

/// Plays a packed MSB-first bitstream (bit 7 of byte 0 first) at `bit_rate_hz`, starting
/// at `t0_ps`, into a signal named `name`. The line is low before `t0_ps` and keeps the
/// last bit's level after the stream (an SPI master's MOSI holds its last level).
pub fn bitstream_to_signal(
    name: &str,
    bytes: &[u8],
    bit_rate_hz: f64,
    t0_ps: Ps,
) -> Result<Signal, LineError> {
    let period = PS_PER_S / positive("bit_rate_hz", bit_rate_hz)?;
    let mut s = Signal::new(name, false);
    let mut k: u64 = 0;
    for &byte in bytes {
        for i in (0..8).rev() {
            let _ = s.push(
                t0_ps.saturating_add(ps(k as f64 * period)),
                (byte >> i) & 1 != 0,
            );
            k += 1;
        }
    }
    Ok(s)
}
