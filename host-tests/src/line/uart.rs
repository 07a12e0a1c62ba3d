//! UART 8N1 (XY3-100 backchannel, layouts item 6): bytes -> waveform and back.
//!
//! Frame: idle high, start bit low, 8 data bits LSB first, stop bit high.

use super::{positive, ps, LineError};
use crate::wave::{Ps, Signal, PS_PER_S};

/// Encodes `bytes` back to back (no idle between frames except `gap_bits` extra stop
/// time), starting at `t0_ps`; the line idles high before and after. Use `t0_ps > 0`:
/// a change at time 0 is the initial level, so a start bit at 0 has no falling edge.
pub fn uart_encode(
    name: &str,
    bytes: &[u8],
    baud: f64,
    t0_ps: Ps,
    gap_bits: u32,
) -> Result<Signal, LineError> {
    let bit = PS_PER_S / positive("baud", baud)?;
    let mut s = Signal::new(name, true);
    let mut k: u64 = 0; // bit slot index from t0
    for &byte in bytes {
        let levels = std::iter::once(false)
            .chain((0..8).map(|i| (byte >> i) & 1 != 0))
            .chain(std::iter::once(true));
        for level in levels {
            let _ = s.push(t0_ps.saturating_add(ps(k as f64 * bit)), level);
            k += 1;
        }
        k += u64::from(gap_bits);
    }
    Ok(s)
}

/// One received UART frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UartFrame {
    /// Time of the start bit's falling edge.
    pub time: Ps,
    /// The data bits.
    pub value: u8,
    /// The stop bit was sampled low (framing error); `value` is what was sampled.
    pub framing_error: bool,
}

/// Receives 8N1 frames: waits for a falling edge on an idle (high) line, checks the start
/// bit at its middle (a shorter low pulse is a glitch and ignored), samples the data bits
/// and the stop bit at their middles. After a framing error it waits for the line to go
/// high again before looking for the next start bit.
pub fn uart_decode(line: &Signal, baud: f64) -> Result<Vec<UartFrame>, LineError> {
    let bit = PS_PER_S / positive("baud", baud)?;
    let mut out = Vec::new();
    // Earliest time a start edge may be accepted (after the previous stop-bit middle).
    let mut ready_at: Ps = 0;
    for t in line.falling_edges() {
        if t < ready_at {
            continue;
        }
        let at = |n: f64| t.saturating_add(ps(n * bit));
        if line.level_at(at(0.5)) {
            continue; // glitch, not a start bit
        }
        let mut value = 0u8;
        for i in 0..8u8 {
            if line.level_at(at(1.5 + f64::from(i))) {
                value |= 1 << i;
            }
        }
        let stop_t = at(9.5);
        let framing_error = !line.level_at(stop_t);
        out.push(UartFrame {
            time: t,
            value,
            framing_error,
        });
        ready_at = stop_t;
        if framing_error {
            // Resume only after the line has returned high.
            ready_at = line.rising_edges().find(|&r| r > stop_t).unwrap_or(Ps::MAX);
        }
    }
    Ok(out)
}
