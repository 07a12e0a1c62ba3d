//! Generator of clocked serial waveforms (CLK, SYNC, data lanes) from already encoded
//! frame words, independent of the codecs.
//!
//! Per bit of period `T` starting at `s`: CLK rises at `s` together with the new data and
//! SYNC levels, and falls at `s + T/2`, where the receiver samples (XY2-100 notes
//! "Timing"; XY3-100 §3 and the XY3 notes: data valid at the falling edge).
//! - XY2-100: 20-bit frames; SYNC high for bits 1..19, low for bit 20. Without a frame
//!   period frames are back to back (10 us at 2 MHz).
//! - XY3-100: 24- or 32-bit frames (per frame); SYNC low for the whole frame, rising half
//!   a bit after the last falling CLK edge; without a frame period one idle bit time
//!   with SYNC high separates frames.
//!
//! Between frames the lines idle as the firmware's output does (layouts item 4): CLK
//! low (or still toggling, see [`Idle`]), SYNC at its idle level (XY2 low, XY3 high),
//! data low.

use super::{positive, ps, roles, LineError};
use crate::wave::{Signal, Waveform, PS_PER_S};

/// One encoded frame word on one lane: the `bits` low bits of `value`, sent MSB first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameWord {
    /// The bits, right-aligned.
    pub value: u32,
    /// Number of bits (1..=32).
    pub bits: u8,
}

/// One data line and its frame words (one per frame).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lane<'a> {
    /// Signal name (e.g. [`roles::X`]).
    pub name: &'a str,
    /// Frame words, one per frame; every lane must have the same count and lengths.
    pub words: &'a [FrameWord],
}

/// What the clock does between frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Idle {
    /// CLK stays low between frames (gated clock).
    #[default]
    ClockStopped,
    /// CLK keeps toggling at the bit rate for every whole bit slot between frames (data
    /// low, SYNC idle).
    ClockRunning,
}

/// Bit and frame timing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameTiming {
    /// Bit clock in Hz (XY2-100: 2e6; XY3-100: 2.4e6 for 24-bit frames at 100 kHz).
    pub bit_rate_hz: f64,
    /// Frame start-to-start period in picoseconds; `None` = back to back (see module
    /// docs).
    pub frame_period_ps: Option<f64>,
    /// Clock behaviour between frames.
    pub idle: Idle,
    /// Start of the first frame in picoseconds.
    pub start_ps: f64,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Proto {
    Xy2,
    Xy3,
}

/// XY2-100 CLK/SYNC/data waveform; every word must be 20 bits.
pub fn xy2_waveform(lanes: &[Lane<'_>], timing: &FrameTiming) -> Result<Waveform, LineError> {
    generate(lanes, timing, Proto::Xy2)
}

/// XY3-100 CLK/SYNC/data waveform; words must be 24 or 32 bits (per frame, equal on all
/// lanes).
pub fn xy3_waveform(lanes: &[Lane<'_>], timing: &FrameTiming) -> Result<Waveform, LineError> {
    generate(lanes, timing, Proto::Xy3)
}

fn frame_bits(lanes: &[Lane<'_>], frame: usize, proto: Proto) -> Result<u8, LineError> {
    let bits = lanes
        .first()
        .and_then(|l| l.words.get(frame))
        .map(|w| w.bits)
        .ok_or(LineError::LaneMismatch { frame })?;
    if lanes
        .iter()
        .any(|l| l.words.get(frame).map(|w| w.bits) != Some(bits))
    {
        return Err(LineError::LaneMismatch { frame });
    }
    let ok = match proto {
        Proto::Xy2 => bits == 20,
        Proto::Xy3 => bits == 24 || bits == 32,
    };
    if ok {
        Ok(bits)
    } else {
        Err(LineError::BadWordLength { frame, bits })
    }
}

fn generate(lanes: &[Lane<'_>], timing: &FrameTiming, proto: Proto) -> Result<Waveform, LineError> {
    let t_bit = PS_PER_S / positive("bit_rate_hz", timing.bit_rate_hz)?;
    if !(timing.start_ps.is_finite() && timing.start_ps >= 0.0) {
        return Err(LineError::BadParameter {
            what: "start_ps",
            value: timing.start_ps,
        });
    }
    if let Some(p) = timing.frame_period_ps {
        positive("frame_period_ps", p)?;
    }
    for (i, l) in lanes.iter().enumerate() {
        let taken = lanes
            .get(..i)
            .is_some_and(|p| p.iter().any(|o| o.name == l.name));
        if taken || l.name == roles::CLK || l.name == roles::SYNC {
            return Err(LineError::BadLaneName {
                name: l.name.to_owned(),
            });
        }
    }
    let frames = lanes.first().map_or(0, |l| l.words.len());
    if lanes.iter().any(|l| l.words.len() != frames) {
        return Err(LineError::LaneMismatch { frame: frames });
    }
    let sync_idle = proto == Proto::Xy3;
    let mut clk = Signal::new(roles::CLK, false);
    let mut sync = Signal::new(roles::SYNC, sync_idle);
    let mut data: Vec<Signal> = lanes.iter().map(|l| Signal::new(l.name, false)).collect();

    // Times only grow below, so `push` cannot fail; its result is ignored.
    let mut start = timing.start_ps;
    for f in 0..frames {
        let n = frame_bits(lanes, f, proto)?;
        let nf = f64::from(n);
        let natural = match proto {
            Proto::Xy2 => nf * t_bit,
            Proto::Xy3 => (nf + 1.0) * t_bit,
        };
        let period = match timing.frame_period_ps {
            Some(p) if p + 0.5 < nf * t_bit => {
                return Err(LineError::FramePeriodTooShort {
                    needed_ps: nf * t_bit,
                    period_ps: p,
                })
            }
            Some(p) => p,
            None => natural,
        };
        for b in 0..n {
            let rise = start + f64::from(b) * t_bit;
            let sync_level = match proto {
                Proto::Xy2 => b + 1 < n,
                Proto::Xy3 => false,
            };
            let _ = sync.push(ps(rise), sync_level);
            for (sig, lane) in data.iter_mut().zip(lanes) {
                let w = lane.words.get(f).map_or(0, |w| w.value);
                let _ = sig.push(ps(rise), (w >> (n - 1 - b)) & 1 != 0);
            }
            let _ = clk.push(ps(rise), true);
            let _ = clk.push(ps(rise + t_bit / 2.0), false);
        }
        let end = start + nf * t_bit;
        let next = start + period;
        let last_frame = f + 1 == frames;
        // Idle unless the next frame starts right here (back-to-back XY2).
        if last_frame || next > end + 0.5 {
            let _ = sync.push(ps(end), sync_idle);
            for sig in data.iter_mut() {
                let _ = sig.push(ps(end), false);
            }
            if timing.idle == Idle::ClockRunning && !last_frame {
                let mut t = end;
                while t + t_bit <= next + 0.5 {
                    let _ = clk.push(ps(t), true);
                    let _ = clk.push(ps(t + t_bit / 2.0), false);
                    t += t_bit;
                }
            }
        }
        start = next;
    }
    let mut wave = Waveform::new();
    wave.insert(clk);
    wave.insert(sync);
    for s in data {
        wave.insert(s);
    }
    Ok(wave)
}
