//! Input side: waveforms -> the receive DMA buffers (layouts items 1, 2, 3).

use super::{check_bits, positive, roles, signal, LineError};
use crate::wave::{Ps, Waveform, PS_PER_S};

/// Which GPIO input bit carries which XY2-100 signal (layouts item 1). Bits not mapped
/// read as 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PinMap {
    /// SYNC bit index (0..15).
    pub sync: u8,
    /// X data bit index.
    pub x: u8,
    /// Y data bit index.
    pub y: u8,
    /// Z data bit index, if wired.
    pub z: Option<u8>,
    /// STATUS bit index, if wired.
    pub status: Option<u8>,
}

impl PinMap {
    /// `(bit, role)` pairs of the mapped pins.
    pub fn pins(&self) -> Vec<(u8, &'static str)> {
        let mut v = vec![
            (self.sync, roles::SYNC),
            (self.x, roles::X),
            (self.y, roles::Y),
        ];
        v.extend(self.z.map(|b| (b, roles::Z)));
        v.extend(self.status.map(|b| (b, roles::STATUS)));
        v
    }
}

/// XY2-100 in: the port word (`u16`) sampled at every falling edge of `CLK`, one per
/// bit, as the timer-triggered DMA of IDR does. Signals for unmapped optional pins
/// (Z, STATUS) need not exist; mapped ones must.
pub fn xy2_port_words(wave: &Waveform, pins: &PinMap) -> Result<Vec<u16>, LineError> {
    xy2_port_samples(wave, pins).map(|(words, _)| words)
}

/// [`xy2_port_words`] plus the time of every sample (the CLK falling edge), a parallel
/// vector: the firmware's samples carry no time, a decoder on the host wants one.
pub fn xy2_port_samples(wave: &Waveform, pins: &PinMap) -> Result<(Vec<u16>, Vec<Ps>), LineError> {
    let pins = pins.pins();
    let bits: Vec<u8> = pins.iter().map(|&(b, _)| b).collect();
    check_bits(&bits, 16)?;
    let clk = signal(wave, roles::CLK)?;
    let sigs = pins
        .iter()
        .map(|&(b, name)| signal(wave, name).map(|s| (b, s)))
        .collect::<Result<Vec<_>, _>>()?;
    let times: Vec<Ps> = clk.falling_edges().collect();
    let words = times
        .iter()
        .map(|&t| {
            sigs.iter()
                .filter(|(_, s)| s.level_at(t))
                .fold(0u16, |w, &(b, _)| w | (1u16 << b))
        })
        .collect();
    Ok((words, times))
}

/// What an SPI slave does with an incomplete byte when NSS rises.
///
/// RM0433 does not say what the H7 SPI slave does with a partial data frame at NSS
/// release (§50.4.7 describes SS only as a chip select; searched 2026-12-04, see
/// the engineering log), and the field reports disagree (one: bits linger in the
/// shift register with 16-bit frames; the same report: 8-bit frames resynchronise
/// at NSS). Both are modelled so decoders are tested against either, and a third
/// for software slave select, which takes NSS out of the question.
///
/// The default is [`PartialByte::Discard`], the pessimistic one for the safety
/// question: a slave that drops the bits heals from a glitch of 1..7 extra edges
/// at the frame end, so the spoilt frame is the only trace and passes its checks
/// now and then (`shared::xy3::step`); a slave that keeps them stays out of step,
/// which the step watch sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PartialByte {
    /// The bits are dropped and the next frame starts a fresh byte (default).
    #[default]
    Discard,
    /// The bits stay in the shift register and complete with the next frame's bits.
    CarryOver,
    /// Software slave select held active (`controller.xy3.select = "always"`):
    /// NSS is not the slave's, so every CLK falling edge is sampled, also while
    /// SYNC is high, and bits carry over as with [`PartialByte::CarryOver`]. SYNC
    /// rises still mark the frame ends (the EXTI).
    Unselected,
}

/// XY3-100 in: what the SPI slaves and the NSS EXTI deliver (layouts item 2).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SpiCapture {
    /// Received bytes per data line, in the order of the `lines` argument.
    pub bytes: Vec<Vec<u8>>,
    /// At each SYNC (NSS) rising edge: the number of bytes received so far on the first
    /// line (monotonic, wrapping `u32` like the DMA-derived counter).
    pub frame_ends: Vec<u32>,
    /// Bits still in the shift register at the end of the waveform (not delivered).
    pub pending_bits: u8,
    /// Per delivered byte (same index as in `bytes`): the times of its first and last
    /// bit sample (CLK falling edges). The firmware's bytes carry no time; a decoder on
    /// the host wants one.
    pub byte_times: Vec<(Ps, Ps)>,
    /// Per entry of `frame_ends`: the time of that SYNC (NSS) rising edge.
    pub end_times: Vec<Ps>,
}

/// Emulates one SPI slave per data line: SCK = `CLK`, NSS = `SYNC` (active low), 8-bit
/// words, MSB first, sampled on CLK falling edges while NSS is low (a clock edge at
/// the instant NSS rises is not sampled; with [`PartialByte::Unselected`] on every
/// falling edge). One input session from time 0:
/// [`xy3_spi_session`] with `start_ps` 0, so a waveform that gives a line its own
/// SCK ([`roles::spi_sck`]) is sampled on it.
pub fn xy3_spi(
    wave: &Waveform,
    lines: &[&str],
    partial: PartialByte,
) -> Result<SpiCapture, LineError> {
    xy3_spi_session(wave, lines, partial, 0)
}

/// What one SPI slave of [`xy3_spi_session`] delivered.
struct SlaveRx {
    bytes: Vec<u8>,
    /// Per byte: its first and last bit sample.
    times: Vec<(Ps, Ps)>,
    /// At each NSS rising edge: bytes so far, and the time.
    ends: Vec<(u32, Ps)>,
    pending_bits: u8,
}

/// One SPI slave on `sck` from `start_ps` on (see [`xy3_spi`] for the sampling).
fn spi_slave(
    sck: &crate::wave::Signal,
    nss: &crate::wave::Signal,
    data: &crate::wave::Signal,
    partial: PartialByte,
    start_ps: Ps,
) -> SlaveRx {
    let mut events: Vec<(Ps, bool)> = sck
        .falling_edges()
        .filter(|&t| t >= start_ps)
        .map(|t| (t, false))
        .collect();
    events.extend(
        nss.rising_edges()
            .filter(|&t| t >= start_ps)
            .map(|t| (t, true)),
    );
    events.sort_unstable();
    let mut rx = SlaveRx {
        bytes: Vec::new(),
        times: Vec::new(),
        ends: Vec::new(),
        pending_bits: 0,
    };
    let (mut shift, mut nbits, mut first_bit) = (0u8, 0u8, 0);
    for (t, nss_rise) in events {
        if nss_rise {
            rx.ends.push((rx.bytes.len() as u32, t));
            if partial == PartialByte::Discard {
                (shift, nbits) = (0, 0);
            }
            continue;
        }
        if nss.level_at(t) && partial != PartialByte::Unselected {
            continue;
        }
        shift = (shift << 1) | u8::from(data.level_at(t));
        if nbits == 0 {
            first_bit = t;
        }
        nbits += 1;
        if nbits == 8 {
            rx.bytes.push(shift);
            rx.times.push((first_bit, t));
            (shift, nbits) = (0, 0);
        }
    }
    rx.pending_bits = nbits;
    rx
}

/// XY3-100 in for one input session (`firmware/tasks/line.rs`, `xy3_in`): the SPI
/// slaves are enabled together and the SCK bus let in at `start_ps`, so each
/// slave shifts from the first falling edge of its SCK at or after it (a session
/// may start inside a frame: that frame's first bits are never seen). Each
/// line's slave runs on its own SCK ([`roles::spi_sck`], when the waveform has
/// one, else `CLK`): one slave can see an edge the others miss, and its bytes
/// then hold other bits than the others' bytes of the same index.
///
/// The DMA hands over byte `i` once every line has it: `bytes` are cut to the
/// shortest line and `byte_times` end at the latest line's last sample. Frame
/// ends count the first line's bytes (the EXTI reads the X ring);
/// `pending_bits` is the first line's.
pub fn xy3_spi_session(
    wave: &Waveform,
    lines: &[&str],
    partial: PartialByte,
    start_ps: Ps,
) -> Result<SpiCapture, LineError> {
    let nss = signal(wave, roles::SYNC)?;
    let mut slaves = Vec::with_capacity(lines.len());
    for &n in lines {
        let own = roles::spi_sck(n);
        let sck = match wave.get(&own) {
            Some(s) => s,
            None => signal(wave, roles::CLK)?,
        };
        slaves.push(spi_slave(sck, nss, signal(wave, n)?, partial, start_ps));
    }
    let n = slaves.iter().map(|s| s.bytes.len()).min().unwrap_or(0);
    let mut cap = SpiCapture::default();
    for i in 0..n {
        let first = slaves
            .first()
            .and_then(|s| s.times.get(i))
            .map_or(0, |t| t.0);
        let last = slaves
            .iter()
            .filter_map(|s| s.times.get(i))
            .map(|t| t.1)
            .max()
            .unwrap_or(0);
        cap.byte_times.push((first, last));
    }
    if let Some(x) = slaves.first() {
        cap.frame_ends = x.ends.iter().map(|e| e.0).collect();
        cap.end_times = x.ends.iter().map(|e| e.1).collect();
        cap.pending_bits = x.pending_bits;
    }
    cap.bytes = slaves
        .into_iter()
        .map(|mut s| {
            s.bytes.truncate(n);
            s.bytes
        })
        .collect();
    Ok(cap)
}

/// Upper bound on words per channel from [`Oversampler::sample`] (1 GiB), so a wrong
/// end time gives an error instead of exhausting memory.
pub const MAX_WORDS: u64 = 1 << 28;

/// HANS-100 in: a free-running sampling clock (layouts item 3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Oversampler {
    /// Sampling frequency in Hz (37.5e6 ..= 50e6 in the firmware; any positive value here).
    pub fs_hz: f64,
    /// Time of the first sample instant in picoseconds (the arbitrary phase of the
    /// receiver's clock relative to the sender's).
    pub start_ps: f64,
}

impl Oversampler {
    /// Samples `channels` at `start_ps + k / fs` for every instant before `end_ps`, all
    /// channels at the same instants, packed MSB first into `u32` words (bit 31 of word
    /// 0 is the earliest sample). Like the DMA, only complete words are delivered.
    pub fn sample(
        &self,
        wave: &Waveform,
        channels: &[&str],
        end_ps: Ps,
    ) -> Result<Vec<Vec<u32>>, LineError> {
        let fs = positive("fs_hz", self.fs_hz)?;
        if !(self.start_ps.is_finite() && self.start_ps >= 0.0) {
            return Err(LineError::BadParameter {
                what: "start_ps",
                value: self.start_ps,
            });
        }
        let sigs = channels
            .iter()
            .map(|&n| signal(wave, n))
            .collect::<Result<Vec<_>, _>>()?;
        let period = PS_PER_S / fs;
        // Whole words before end_ps; `as` saturates a huge count, bounded by memory anyway.
        let samples = ((end_ps as f64 - self.start_ps) / period).max(0.0).floor() as u64;
        let words = samples / 32;
        if words > MAX_WORDS {
            return Err(LineError::BadParameter {
                what: "end_ps (too many samples)",
                value: end_ps as f64,
            });
        }
        let mut out: Vec<Vec<u32>> = vec![Vec::new(); sigs.len()];
        for w in 0..words {
            let mut acc = vec![0u32; sigs.len()];
            for b in 0..32u64 {
                let k = w * 32 + b;
                let t = super::ps(self.start_ps + k as f64 * period);
                for (a, s) in acc.iter_mut().zip(&sigs) {
                    *a = (*a << 1) | u32::from(s.level_at(t));
                }
            }
            for (o, a) in out.iter_mut().zip(acc) {
                o.push(a);
            }
        }
        Ok(out)
    }
}
