//! The head side: output slots on the configured clock, the bridge's frame per slot,
//! encoded into the buffers the output DMA plays (BSRR words for XY2-100 / XY3-100,
//! the HANS-100 SAI ring for HANS-100).
//!
//! The neutral -> wire conversion and the idle rules are the firmware's:
//! `shared::bridge::head_out::HeadTx`, which `firmware/tasks/encode.rs` calls too.

use shared::bridge::head_out::HeadTx;
use shared::bridge::{
    Bridge, Config, LinkState, Output as BridgeOutput, Protocol, Timing, ZSource,
};
use shared::hans::frame::{RING_BYTES, RING_SLOTS};
use shared::head_port::{self, XY2_TICK_HZ};
use shared::model::ForwardFrame;
use shared::xy3::BackRate;
use shared::{hans, xy2};

use super::{tx, Options, PipelineCounters, PipelineError};
use crate::line::drive::{self, OutPinMap};
use crate::line::{roles, LineError};
use crate::wave::{Ps, Waveform, PS_PER_S};

/// Head-side XY2-100 port bits: the firmware's ([`head_port::XY2_PINS`]).
pub const HEAD_PINS_XY2: OutPinMap = OutPinMap::from_xy2(&head_port::XY2_PINS);

/// Head-side XY3-100 port bits, every line: the firmware's
/// ([`head_port::XY3_PINS`]); the lines driven are `Config::xy3_head_lines`.
pub const HEAD_PINS_XY3: OutPinMap = match OutPinMap::from_xy3(&head_port::XY3_PINS) {
    Some(pins) => pins,
    // Evaluated at build time: a map without X or Y does not build.
    None => panic!("head_port::XY3_PINS without X or Y"),
};
/// HANS-100 output bit time, ps (12.5 MHz).
const HANS_BIT_PS: u64 = 80_000;

/// One frame written to the head.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SentFrame {
    /// Start of its first bit on the head's lines, ps.
    pub start_ps: Ps,
    /// When the bridge decided it, ns.
    pub decided_ns: u64,
    /// The frame as the bridge gave it (head widths, missing axes held).
    pub frame: ForwardFrame,
    /// The link state it was sent in.
    pub state: LinkState,
}

/// The buffers the head-side output DMA plays, from time 0.
#[derive(Debug, Clone, PartialEq)]
pub enum HeadOutput {
    /// XY2-100 / XY3-100: BSRR words, word `i` at `i * tick_ps`.
    Wave {
        /// The words.
        words: Vec<u32>,
        /// Tick period, ps.
        tick_ps: f64,
        /// Which bit drives which line.
        pins: OutPinMap,
        /// The protocol (idle levels differ).
        protocol: Protocol,
    },
    /// HANS-100: the SAI bitstream (12.5 Mbit/s, MSB first), the same on CH1..CH5.
    Hans {
        /// Packed bits, bit 7 of byte 0 first.
        bytes: Vec<u8>,
        /// Number of valid bits.
        bits: u64,
    },
}

impl HeadOutput {
    /// Time covered so far, ps.
    pub fn end_ps(&self) -> Ps {
        match self {
            HeadOutput::Wave { words, tick_ps, .. } => (words.len() as f64 * tick_ps).round() as Ps,
            HeadOutput::Hans { bits, .. } => bits * HANS_BIT_PS,
        }
    }

    /// The output as waveforms (roles `CLK SYNC X Y Z U W` as driven, or
    /// `CH1`..`CH5`).
    pub fn to_waveform(&self) -> Result<Waveform, LineError> {
        match self {
            HeadOutput::Wave {
                words,
                tick_ps,
                pins,
                protocol,
            } => {
                let initial: &[(&str, bool)] = match protocol {
                    Protocol::Xy3 => &[(roles::SYNC, true)],
                    _ => &[],
                };
                drive::bsrr_to_wave(words, *tick_ps, 0, pins, initial)
            }
            HeadOutput::Hans { bytes, bits } => {
                let n = usize::try_from(bits.div_ceil(8)).unwrap_or(usize::MAX);
                let used = bytes.get(..n.min(bytes.len())).unwrap_or_default();
                let mut wave = Waveform::new();
                for name in roles::HANS_CHANNELS {
                    wave.insert(drive::bitstream_to_signal(
                        name,
                        used,
                        drive::HANS_BIT_RATE_HZ,
                        0,
                    )?);
                }
                Ok(wave)
            }
        }
    }
}

/// The neutral -> wire encoder of the head.
enum Encoder {
    /// XY2-100 / XY3-100: the shared neutral -> BSRR words encoder (boxed: its
    /// transmitter carries a 2 KiB table of two-bit words).
    Wave(Box<HeadTx>),
    /// HANS-100: the SAI ring and its writer, the last frame written (DATA words a
    /// frame lacks are held from it).
    Hans(Box<HansRing>),
}

/// The HANS-100 SAI ring as the firmware keeps it, and the stream it plays.
pub(super) struct HansRing {
    ring: [u8; RING_BYTES],
    tx: hans::tx::Transmitter,
    hold: hans::Frame,
    out: Vec<u8>,
    bits: u64,
}

impl HansRing {
    pub fn new() -> HansRing {
        HansRing {
            // All zeros: no valid frame (the head sees an idle line) until written.
            ring: [0; RING_BYTES],
            tx: hans::tx::Transmitter::new(),
            hold: hans::Frame::CENTRE,
            out: Vec::new(),
            bits: 0,
        }
    }

    /// The DMA's remaining-byte count while it fetches slot `s` (the inverse of
    /// [`hans::tx::sending_slot`]).
    fn remaining_for(s: usize) -> usize {
        RING_BYTES - (hans::FRAME_BITS * s).div_ceil(8)
    }

    /// One slot period: while slot `playing` goes out, `frame` is written
    /// [`hans::tx::LEAD_SLOTS`] ahead (`None`: that slot is cleared, no frame).
    /// Returns whether a frame was written.
    pub fn step(&mut self, playing: u64, frame: Option<hans::Frame>) -> bool {
        let sending = (playing % RING_SLOTS as u64) as usize;
        let rem = Self::remaining_for(sending);
        let written = match frame {
            Some(f) => self.tx.update(&mut self.ring, rem, &f).is_ok(),
            None => {
                let target = (sending + hans::tx::LEAD_SLOTS) % RING_SLOTS;
                self.clear_slot(target);
                false
            }
        };
        // The DMA plays the sending slot now; copy its 125 bits into the stream.
        let first = hans::FRAME_BITS * sending;
        for i in first..first + hans::FRAME_BITS {
            let bit = self
                .ring
                .get(i / 8)
                .is_some_and(|b| b >> (7 - i % 8) & 1 != 0);
            let at = self.bits as usize;
            if at / 8 >= self.out.len() {
                self.out.push(0);
            }
            if let Some(b) = self.out.get_mut(at / 8) {
                *b |= u8::from(bit) << (7 - at % 8);
            }
            self.bits += 1;
        }
        written
    }

    fn clear_slot(&mut self, slot: usize) {
        let first = hans::FRAME_BITS * slot;
        for i in first..first + hans::FRAME_BITS {
            if let Some(b) = self.ring.get_mut(i / 8) {
                *b &= !(1 << (7 - i % 8));
            }
        }
    }

    pub fn stream(&self) -> (&[u8], u64) {
        (&self.out, self.bits)
    }
}

/// The head-side output clock and encoder.
pub(super) struct Output {
    timing: Timing,
    rate: u32,
    lead: u64,
    slaved_lead_ns: u64,
    /// The next slot to compute.
    next_slot: u64,
    enc: Encoder,
    /// BSRR words so far (XY2 / XY3 heads).
    words: Vec<u32>,
    ticks_per_frame: usize,
    tick_ps: f64,
    /// The first word of an idle stretch and the words after it.
    idle: (u32, u32),
    protocol: Protocol,
    pins: OutPinMap,
    sent: Vec<SentFrame>,
    /// The bridge has been `Running` once (before that every slot is idle).
    started: bool,
    head_back_rate: BackRate,
}

impl Output {
    pub fn new(config: &Config, options: &Options) -> Result<Output, PipelineError> {
        let rate = config.output.frame_rate_hz.max(1);
        let z = config.z.source != ZSource::None;
        let setup = |e: String| PipelineError::Setup(e);
        let (enc, ticks_per_frame, idle, pins) = match config.head.protocol {
            Protocol::Xy2 => {
                let h = config.head.xy2;
                let ticks = (XY2_TICK_HZ / rate) as usize;
                let link = xy2::LinkConfig {
                    mode: h.mode,
                    parity: h.parity,
                };
                let (tx, out) = tx::xy2(&HEAD_PINS_XY2, z, ticks, link)
                    .map_err(|e| setup(format!("XY2-100 transmitter: {e}")))?;
                let idle = (tx.idle_word(), tx.idle_word());
                (
                    Encoder::Wave(Box::new(HeadTx::Xy2 {
                        tx,
                        mode: h.mode,
                        z,
                    })),
                    ticks,
                    idle,
                    out,
                )
            }
            Protocol::Xy3 => {
                let size = config.head.xy3.frame_size;
                let lines = config.xy3_head_lines();
                let (tx, out) = tx::xy3(&HEAD_PINS_XY3, lines, size)
                    .map_err(|e| setup(format!("XY3-100 transmitter: {e}")))?;
                let ticks = tx.ticks_per_frame();
                let mut one = vec![0u32; ticks];
                tx.idle(&mut one)
                    .map_err(|e| setup(format!("XY3-100 idle: {e}")))?;
                let idle = (one.first().copied().unwrap_or(0), 0);
                (
                    Encoder::Wave(Box::new(HeadTx::Xy3 { tx, lines })),
                    ticks,
                    idle,
                    out,
                )
            }
            Protocol::Hans => (
                Encoder::Hans(Box::new(HansRing::new())),
                1,
                (0, 0),
                HEAD_PINS_XY2,
            ),
        };
        let frame_ps = PS_PER_S / f64::from(rate);
        let lead = match config.head.protocol {
            Protocol::Hans => hans::tx::LEAD_SLOTS as u64,
            _ => u64::from(options.lead_slots),
        };
        let protocol = config.head.protocol;
        Ok(Output {
            timing: config.output.timing,
            rate,
            lead,
            slaved_lead_ns: options.slaved_lead_ns,
            // HANS-100: at time 0 the ring plays slot 0 (zeros) and slot `lead` is
            // the first one written.
            next_slot: if protocol == Protocol::Hans { lead } else { 0 },
            enc,
            words: Vec::new(),
            ticks_per_frame,
            tick_ps: frame_ps / ticks_per_frame as f64,
            idle,
            protocol,
            pins,
            sent: Vec::new(),
            started: false,
            head_back_rate: config.controller.xy3.back_rate,
        })
    }

    /// Start of slot `k`, ns.
    fn slot_ns(&self, k: u64) -> u64 {
        (u128::from(k) * 1_000_000_000 / u128::from(self.rate)) as u64
    }

    /// Start of slot `k`, ps.
    fn slot_ps(&self, k: u64) -> Ps {
        (u128::from(k) * 1_000_000_000_000 / u128::from(self.rate)) as Ps
    }

    /// When the next slot is computed, ns.
    pub fn next_ns(&self) -> u64 {
        match self.timing {
            Timing::Slaved => self.slot_ns(self.next_slot),
            Timing::FreeRunning => self.slot_ns(self.next_slot.saturating_sub(self.lead)),
        }
    }

    /// The buffers played so far (a copy).
    pub fn head(&self) -> HeadOutput {
        match &self.enc {
            Encoder::Hans(ring) => {
                let (bytes, bits) = ring.stream();
                HeadOutput::Hans {
                    bytes: bytes.to_vec(),
                    bits,
                }
            }
            _ => HeadOutput::Wave {
                words: self.words.clone(),
                tick_ps: self.tick_ps,
                pins: self.pins,
                protocol: self.protocol,
            },
        }
    }

    pub fn sent(&self) -> &[SentFrame] {
        &self.sent
    }

    pub fn head_back_rate(&self) -> BackRate {
        self.head_back_rate
    }

    /// One slot of the output clock: `Bridge::tick` and the frame into its slot.
    pub fn step(&mut self, bridge: &mut Bridge, c: &mut PipelineCounters) -> BridgeOutput {
        let now = self.next_ns();
        let k = self.next_slot;
        self.next_slot += 1;
        let o = bridge.tick(now);
        self.note(&o);
        c.slots += 1;
        let frame = if self.started { o.frame } else { None };
        match self.timing {
            Timing::FreeRunning => self.write_slot(k, now, frame.as_ref(), o.state, c),
            Timing::Slaved => {
                // Idle up to this slot's start; a fail-safe frame goes out as soon as
                // the line is free.
                let at = self.tick_at(self.slot_ps(k));
                self.pad_to(at);
                match frame {
                    Some(f) => self.place(now, &f, o.state, c),
                    None => c.idle_slots += 1,
                }
            }
        }
        o
    }

    /// Slaved timing: the frame the bridge forwarded at `now` goes out at once.
    pub fn slaved(&mut self, now: u64, o: &BridgeOutput, c: &mut PipelineCounters) {
        self.note(o);
        if let (true, Some(f)) = (self.started, o.frame) {
            self.place(now, &f, o.state, c);
        }
    }

    fn note(&mut self, o: &BridgeOutput) {
        self.started |= o.state == LinkState::Running;
        if let Some(r) = o.head_back_rate {
            self.head_back_rate = r;
        }
    }

    /// The first tick at or after `t` ps.
    fn tick_at(&self, t: Ps) -> usize {
        (t as f64 / self.tick_ps).ceil() as usize
    }

    fn pad_to(&mut self, tick: usize) {
        if self.words.len() < tick {
            self.words.push(self.idle.0);
            self.words.resize(tick, self.idle.1);
        }
    }

    /// Slaved: writes `f` at the first tick after `now + slaved_lead_ns` when the
    /// line is free.
    fn place(&mut self, now: u64, f: &ForwardFrame, state: LinkState, c: &mut PipelineCounters) {
        let earliest = self.tick_at(now.saturating_add(self.slaved_lead_ns) * 1000);
        let at = earliest.max(self.words.len());
        self.pad_to(at);
        let mut slot = vec![self.idle.0; self.ticks_per_frame];
        if self.encode_wave(Some(f), &mut slot) {
            self.sent.push(SentFrame {
                start_ps: (at as f64 * self.tick_ps).round() as Ps,
                decided_ns: now,
                frame: *f,
                state,
            });
        } else {
            c.encode_refused += 1;
            c.idle_slots += 1;
        }
        self.words.extend_from_slice(&slot);
    }

    /// Free-running: slot `k`'s words (or, for HANS-100, the ring write two slots
    /// ahead while slot `k - LEAD_SLOTS` plays).
    fn write_slot(
        &mut self,
        k: u64,
        now: u64,
        frame: Option<&ForwardFrame>,
        state: LinkState,
        c: &mut PipelineCounters,
    ) {
        let start_ps = self.slot_ps(k);
        let written = if let Encoder::Hans(ring) = &mut self.enc {
            let wire = frame.and_then(|f| hans::Frame::from_forward(f, &ring.hold).ok());
            if let Some(w) = wire {
                ring.hold = w;
            }
            let playing = k.saturating_sub(self.lead);
            ring.step(playing, wire) && frame.is_some()
        } else {
            let mut slot = vec![self.idle.0; self.ticks_per_frame];
            let ok = self.encode_wave(frame, &mut slot);
            self.words.extend_from_slice(&slot);
            ok
        };
        if written {
            if let Some(f) = frame {
                self.sent.push(SentFrame {
                    start_ps,
                    decided_ns: now,
                    frame: *f,
                    state,
                });
            }
        } else {
            c.idle_slots += 1;
            if frame.is_some() {
                c.encode_refused += 1;
            }
        }
    }

    /// Encodes `frame` into one slot of BSRR words, or idles the slot for `None` and
    /// for a frame the head cannot take (`HeadTx::encode`, as the firmware). Returns
    /// whether a frame was written.
    fn encode_wave(&self, frame: Option<&ForwardFrame>, slot: &mut [u32]) -> bool {
        match &self.enc {
            Encoder::Wave(head) => head.encode(frame, slot),
            Encoder::Hans(_) => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn remaining_for_inverts_sending_slot() {
        for s in 0..RING_SLOTS {
            assert_eq!(hans::tx::sending_slot(HansRing::remaining_for(s)), s);
        }
    }

    #[test]
    fn write_slot_round_trip_of_the_ring_model() {
        let mut r = HansRing::new();
        let f = hans::Frame::new(1, 2, 3).unwrap();
        // Slots 0 and 1 play zeros; the frame written while 0 plays shows in slot 2.
        assert!(r.step(0, Some(f)));
        assert!(!r.step(1, None));
        assert!(r.step(2, Some(f)));
        let (bytes, bits) = r.stream();
        assert_eq!(bits, 3 * hans::FRAME_BITS as u64);
        assert_eq!(hans::Frame::read_at(bytes, 2 * hans::FRAME_BITS), Ok(f));
        assert!(hans::Frame::read_at(bytes, 0).is_err());
    }
}
