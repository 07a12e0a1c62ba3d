//! The reverse path out: what the bridge tells the controller, in its protocol, on a
//! 10 us status clock (HANS-100 STATUS frames, XY3-100 backchannel UART polls) and
//! at every controller frame (XY2-100 status words) or bridge step (XY2-100 level).

use shared::bridge::{Bridge, Config, Protocol, StatusForm};
use shared::xy3::back::SEND_BUF_LEN;
use shared::xy3::BackRate;

use super::output::HansRing;
use super::Change;
use crate::line::{drive, roles, LineError};
use crate::wave::{Ps, Signal, PS_PER_S};

/// The controller-status clock: 100 kHz, one HANS-100 STATUS frame per step.
const STEP_NS: u64 = 10_000;

/// Bits of one UART 8N1 byte.
const UART_BITS: u64 = 10;

/// One backchannel byte towards the controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BackByte {
    /// Start of its start bit, ps.
    pub start_ps: Ps,
    /// The rate it goes out at.
    pub baud: u32,
    /// The byte.
    pub value: u8,
}

/// What the bridge sent towards the controller, by protocol.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ControllerStatus {
    /// XY2-100 STATUS level: changes of the line level (`true` = high); the first
    /// entry is the level at 0.
    pub level: Vec<Change<bool>>,
    /// XY2-100 status word form: the 20-bit STATUS frame the bridge had ready when
    /// each controller frame arrived (`(ns, frame)`), clocked out with the next one.
    pub words: Vec<(u64, u32)>,
    /// XY3-100 backchannel bytes.
    pub back: Vec<BackByte>,
    /// XY3-100 backchannel rate changes the controller asked for (`BACK_RATE`).
    pub back_rates: Vec<Change<BackRate>>,
    /// HANS-100 STATUS: the bitstream from 0 (12.5 Mbit/s, MSB first) and its length.
    pub hans: (Vec<u8>, u64),
}

impl ControllerStatus {
    /// The backchannel bytes in order.
    pub fn back_bytes(&self) -> Vec<u8> {
        self.back.iter().map(|b| b.value).collect()
    }

    /// The backchannel line (UART 8N1, idle high), each byte at its own rate.
    pub fn back_signal(&self) -> Signal {
        let mut s = Signal::new(roles::UART, true);
        for b in &self.back {
            let bit = PS_PER_S / f64::from(b.baud.max(1));
            let levels = std::iter::once(false)
                .chain((0..8).map(|i| (b.value >> i) & 1 != 0))
                .chain(std::iter::once(true));
            for (k, level) in levels.enumerate() {
                let t = b.start_ps + (k as f64 * bit).round() as Ps;
                // Bytes never overlap (the UART model queues them), so times grow.
                let _ = s.push(t, level);
            }
        }
        s
    }

    /// The HANS-100 STATUS line.
    pub fn hans_signal(&self) -> Result<Signal, LineError> {
        let n = usize::try_from(self.hans.1.div_ceil(8)).unwrap_or(usize::MAX);
        let used = self
            .hans
            .0
            .get(..n.min(self.hans.0.len()))
            .unwrap_or_default();
        drive::bitstream_to_signal(roles::STATUS, used, drive::HANS_BIT_RATE_HZ, 0)
    }

    /// The XY2-100 STATUS level line.
    pub fn level_signal(&self) -> Signal {
        let initial = self.level.first().is_some_and(|c| c.value);
        let mut s = Signal::new(roles::STATUS, initial);
        for c in self.level.iter().skip(1) {
            let _ = s.push(c.t_ns * 1000, c.value);
        }
        s
    }
}

/// The controller-side status producers.
pub(super) struct CtrlStatus {
    out: ControllerStatus,
    protocol: Protocol,
    form: StatusForm,
    step: u64,
    hans: Option<Box<HansRing>>,
    /// When the UART has sent everything queued, ns.
    back_free_ns: u64,
    baud: u32,
}

impl CtrlStatus {
    pub fn new(config: &Config) -> CtrlStatus {
        let c = &config.controller;
        CtrlStatus {
            out: ControllerStatus::default(),
            protocol: c.protocol,
            form: c.xy2.status,
            step: 0,
            hans: (c.protocol == Protocol::Hans).then(|| Box::new(HansRing::new())),
            back_free_ns: 0,
            baud: c.xy3.back_rate.baud(),
        }
    }

    /// What was sent so far (a copy).
    pub fn out(&self) -> ControllerStatus {
        let mut o = self.out.clone();
        if let Some(ring) = &self.hans {
            let (bytes, bits) = ring.stream();
            o.hans = (bytes.to_vec(), bits);
        }
        o
    }

    /// When the next status step is due, ns.
    pub fn next_ns(&self) -> u64 {
        self.step * STEP_NS
    }

    /// One 10 us status step.
    pub fn step(&mut self, bridge: &mut Bridge) {
        let now = self.next_ns();
        let k = self.step;
        self.step += 1;
        match self.protocol {
            Protocol::Hans => {
                let frame = bridge.hans_status_frame();
                if let Some(ring) = &mut self.hans {
                    ring.step(k, Some(frame));
                }
            }
            // The UART starts with the first step after power-up (time 0 itself is
            // the line's initial level).
            Protocol::Xy3 if now >= self.back_free_ns && now > 0 => {
                let mut buf = [0u8; SEND_BUF_LEN];
                let n = bridge.xy3_back_poll(now, &mut buf).unwrap_or(0);
                let byte_ns = UART_BITS * 1_000_000_000 / u64::from(self.baud.max(1));
                for (i, &value) in buf.iter().take(n).enumerate() {
                    self.out.back.push(BackByte {
                        start_ps: (now + i as u64 * byte_ns) * 1000,
                        baud: self.baud,
                        value,
                    });
                }
                self.back_free_ns = now + n as u64 * byte_ns;
            }
            _ => {}
        }
        self.after_event(now, bridge);
    }

    /// A controller frame arrived at `now`: an XY2-100 status word goes back with it.
    pub fn on_controller_frame(&mut self, now: u64, bridge: &Bridge) {
        if self.protocol == Protocol::Xy2 && self.form == StatusForm::Word {
            self.out.words.push((now, bridge.xy2_status_frame()));
        }
    }

    /// The controller asked for another backchannel rate at `now`: bytes queued from
    /// the next poll on go out at it.
    pub fn set_back_rate(&mut self, now: u64, rate: BackRate) {
        self.baud = rate.baud();
        self.out.back_rates.push(Change {
            t_ns: now,
            value: rate,
        });
    }

    /// Follows the XY2-100 STATUS level after anything that may change it.
    pub fn after_event(&mut self, now: u64, bridge: &Bridge) {
        if self.protocol == Protocol::Xy2 && self.form == StatusForm::Level {
            let high = bridge.xy2_status_line_high();
            if self.out.level.last().map(|c| c.value) != Some(high) {
                self.out.level.push(Change {
                    t_ns: now,
                    value: high,
                });
            }
        }
    }
}
