//! The reverse path in: the head's status lines through their `shared` receivers into
//! the bridge's [`HeadStatus`](shared::model::HeadStatus).
//!
//! The HANS-100 STATUS line goes as the firmware takes it (`line::hans_status_in`,
//! `status::hans_status`): the words fed are the SPI6 stream, cut into halves of
//! [`HANS_STATUS_HALF`] words numbered from 1; a half goes to the decoder when
//! `shared::hans::follow::status_passes` says so (every half, every second one
//! beside a HANS-100 controller once the lock can coast), and one receiver
//! follows the signal across the halves not passed on (`Follow::apply`). The
//! decoder here always keeps up (no load governor, no full queue), and a half's
//! frames count when the word that completes it is fed.

use shared::bridge::{Config, Protocol, StatusForm};
use shared::hans::follow::{self, Follow};
use shared::hans::rx::{ConfigError, HansRx, Mode, RxEvent};
use shared::hans::{self, StatusReceiver};
use shared::head_port::XY2_TICK_HZ;
use shared::model::{FaultKind, HeadStatus, Line, LineEvent};
use shared::xy2::status_line::{
    samples_per_period, LevelDebouncer, StatusWordConfig, StatusWordReceiver,
};
use shared::xy2::{self, StatusLevel};
use shared::xy3::back::Parser;
use shared::xy3::back_rx;

use super::{HeadStatusInput, Options, PipelineError};

enum Kind {
    Xy2Level(LevelDebouncer),
    Xy2Word(StatusWordReceiver),
    Xy3(Box<Parser>),
    Hans(Box<HansStatus>),
}

/// `firmware/channels.rs` `HANS_HALF`: words per SPI6 DMA half of the head's
/// HANS-100 STATUS input (205 us at 40 MHz).
pub const HANS_STATUS_HALF: usize = 512;

/// One half of the HANS-100 STATUS input that went to the decoder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HansStatusHalf {
    /// Its number (1 = the first half).
    pub number: u32,
    /// When it was decoded (the time of the chunk that completed it), ns.
    pub t_ns: u64,
    /// It went to the decoder because the lock could not coast yet (the firmware's
    /// `HANS_STATUS_CONTIGUOUS`), not by the every-n rule alone
    /// (`follow::status_due`).
    pub asked: bool,
    /// The frames it published (applied to the head's status), in order.
    pub frames: Vec<hans::Frame>,
}

/// The firmware's HANS-100 STATUS path (see the module docs).
struct HansStatus {
    sample_hz: u32,
    rx: HansRx,
    follow: Follow,
    receiver: StatusReceiver,
    /// `follow::status_every` for the configured controller.
    every: u32,
    /// The decoder asks for every half (`!HansRx::coasts` after the last one).
    contiguous: bool,
    /// The half being filled.
    words: Vec<u16>,
    /// Halves completed so far (the number of the last one).
    number: u32,
    /// Every half decoded.
    decoded: Vec<HansStatusHalf>,
}

impl HansStatus {
    /// A receiver for the head's STATUS line: the one constructor, for the first
    /// receiver and every fresh one `Follow::apply` starts.
    fn receiver(sample_hz: u32) -> Result<HansRx, ConfigError> {
        HansRx::new(sample_hz, Mode::Normal { channel: 1 })
    }

    fn new(sample_hz: u32, hans_controller: bool) -> Result<HansStatus, ConfigError> {
        Ok(HansStatus {
            sample_hz,
            rx: HansStatus::receiver(sample_hz)?,
            follow: Follow::new(),
            receiver: StatusReceiver::new(),
            every: follow::status_every(hans_controller),
            // As the firmware's `HANS_STATUS_CONTIGUOUS` from reset on.
            contiguous: true,
            words: Vec::with_capacity(HANS_STATUS_HALF),
            number: 0,
            decoded: Vec::new(),
        })
    }

    /// Takes `words`; decodes each half they complete that is passed on.
    fn feed(
        &mut self,
        now: u64,
        mut words: &[u16],
        status: &mut HeadStatus,
        faults: &mut Vec<LineEvent>,
    ) -> u32 {
        let mut seen = 0u32;
        while !words.is_empty() {
            let take = (HANS_STATUS_HALF - self.words.len()).min(words.len());
            let (now_words, rest) = words.split_at(take);
            self.words.extend_from_slice(now_words);
            words = rest;
            if self.words.len() < HANS_STATUS_HALF {
                break;
            }
            self.number = self.number.wrapping_add(1);
            if follow::status_passes(self.number, self.every, self.contiguous) {
                seen += self.decode(now, status, faults);
            }
            self.words.clear();
        }
        seen
    }

    /// Decodes the half in `self.words` as `status::hans_status` does.
    fn decode(&mut self, now: u64, status: &mut HeadStatus, faults: &mut Vec<LineEvent>) -> u32 {
        let mut frames = Vec::new();
        let receiver = &mut self.receiver;
        let mut sink = |ev: RxEvent| match ev {
            RxEvent::Frame(f) => {
                receiver.apply(&f, status);
                frames.push(f);
            }
            // The head's STATUS line is not a controller channel. A period it
            // delivered nothing in (`Missing`) is not reported: the status watchdog
            // (`STATUS_LOST`) is what watches for a silent head.
            RxEvent::Fault {
                kind: FaultKind::Missing,
                ..
            } => {}
            RxEvent::Fault { kind, .. } => faults.push(status_fault(kind)),
        };
        let sample_hz = self.sample_hz;
        let first_word = self.number.wrapping_mul(HANS_STATUS_HALF as u32);
        // One session: the words fed are one stream (the firmware starts a new one
        // after an SPI6 overrun, which the host does not model).
        self.follow.apply(
            &mut self.rx,
            0,
            first_word,
            HANS_STATUS_HALF as u32,
            || HansStatus::receiver(sample_hz),
            &mut sink,
        );
        self.rx.push(&[&self.words], &mut sink);
        let asked = self.contiguous && !follow::status_due(self.number, self.every);
        self.contiguous = !self.rx.coasts();
        let seen = frames.len() as u32;
        self.decoded.push(HansStatusHalf {
            number: self.number,
            t_ns: now,
            asked,
            frames,
        });
        seen
    }
}

/// The head-side status receiver the configuration selects.
pub(super) struct HeadStatusIn {
    kind: Kind,
    /// The head's status as received (the firmware's status tasks publish theirs
    /// the same way, for the bridge loop to copy).
    status: HeadStatus,
}

fn status_fault(kind: FaultKind) -> LineEvent {
    LineEvent::Fault {
        line: Line::Status,
        kind,
    }
}

impl HeadStatusIn {
    pub fn new(config: &Config, options: &Options) -> Result<HeadStatusIn, PipelineError> {
        let h = &config.head;
        let kind = match h.protocol {
            Protocol::Xy2 => match h.xy2.status {
                StatusForm::Level => Kind::Xy2Level(LevelDebouncer::new(
                    StatusLevel {
                        polarity: h.xy2.polarity,
                    },
                    options.status_debounce,
                )),
                StatusForm::Word => {
                    // The status-word sample geometry: one sample per output bit,
                    // counted from each frame period's start as the firmware thins
                    // them (`tasks/head_word.rs`).
                    let ticks = XY2_TICK_HZ / config.output.frame_rate_hz.max(1);
                    let rx = StatusWordReceiver::new(StatusWordConfig {
                        pin: 0,
                        samples_per_period: u16::try_from(samples_per_period(ticks as usize))
                            .unwrap_or(u16::MAX),
                        offset: 1,
                        link: xy2::LinkConfig {
                            mode: h.xy2.mode,
                            parity: h.xy2.parity,
                        },
                    })
                    .map_err(|e| PipelineError::Setup(e.to_string()))?;
                    Kind::Xy2Word(rx)
                }
            },
            Protocol::Xy3 => Kind::Xy3(Box::new(Parser::new())),
            Protocol::Hans => {
                let hans_controller = config.controller.protocol == Protocol::Hans;
                let rx = HansStatus::new(options.hans_status_sample_hz, hans_controller)
                    .map_err(|e| PipelineError::Setup(e.to_string()))?;
                Kind::Hans(Box::new(rx))
            }
        };
        Ok(HeadStatusIn {
            kind,
            status: HeadStatus::default(),
        })
    }

    /// The head's status as received so far.
    pub fn status(&self) -> &HeadStatus {
        &self.status
    }

    /// The HANS-100 STATUS halves decoded so far (none for other heads).
    pub fn hans_halves(&self) -> &[HansStatusHalf] {
        match &self.kind {
            Kind::Hans(h) => &h.decoded,
            _ => &[],
        }
    }

    /// Feeds one chunk; updates the head's status, appends head-side faults (on
    /// [`Line::Status`] / [`Line::Backchannel`]) and returns how many valid status
    /// items arrived.
    pub fn feed(
        &mut self,
        now: u64,
        chunk: HeadStatusInput<'_>,
        faults: &mut Vec<LineEvent>,
    ) -> Result<u32, PipelineError> {
        let status = &mut self.status;
        let mut seen = 0u32;
        match (&mut self.kind, chunk) {
            (Kind::Xy2Level(deb), HeadStatusInput::Xy2Level(samples)) => {
                for &high in samples {
                    if let Some(change) = deb.feed(now, high) {
                        status.alarms = change.health.alarms();
                    }
                    // The level is the head's status only once the debouncer
                    // accepted one: before, the head's state is not known.
                    seen += u32::from(deb.health().is_some());
                }
            }
            (Kind::Xy2Word(rx), HeadStatusInput::Xy2Word(samples)) => {
                rx.feed(samples, &mut |r| match r {
                    Ok(word) => {
                        status.alarms = word.alarms();
                        seen += 1;
                    }
                    Err(_) => faults.push(status_fault(FaultKind::CheckFailed)),
                });
            }
            (Kind::Xy3(parser), HeadStatusInput::Xy3Back(bytes)) => {
                let before = parser.stats();
                back_rx::push_bytes(parser, bytes, status, |f| faults.push(f));
                let after = parser.stats();
                // Every packet counts, SYNC packets too (a resync is built on one).
                seen += after.packets.wrapping_sub(before.packets)
                    + after.resyncs.wrapping_sub(before.resyncs);
            }
            (Kind::Hans(h), HeadStatusInput::HansStatus(words)) => {
                seen += h.feed(now, words, status, faults);
            }
            (_, chunk) => {
                return Err(PipelineError::WrongInput {
                    expected: self.name(),
                    got: input_name(&chunk),
                })
            }
        }
        Ok(seen)
    }

    fn name(&self) -> &'static str {
        match self.kind {
            Kind::Xy2Level(_) => "XY2-100 STATUS level",
            Kind::Xy2Word(_) => "XY2-100 STATUS word samples",
            Kind::Xy3(_) => "XY3-100 backchannel bytes",
            Kind::Hans(..) => "HANS-100 STATUS words",
        }
    }
}

fn input_name(chunk: &HeadStatusInput<'_>) -> &'static str {
    match chunk {
        HeadStatusInput::Xy2Level(_) => "XY2-100 STATUS level",
        HeadStatusInput::Xy2Word(_) => "XY2-100 STATUS word samples",
        HeadStatusInput::Xy3Back(_) => "XY3-100 backchannel bytes",
        HeadStatusInput::HansStatus(_) => "HANS-100 STATUS words",
    }
}
