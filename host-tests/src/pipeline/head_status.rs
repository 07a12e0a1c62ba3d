//! The reverse path in: the head's status lines through their `shared` receivers into
//! the bridge's [`HeadStatus`](shared::model::HeadStatus).

use shared::bridge::{Config, Protocol, StatusForm};
use shared::hans::{self, StatusReceiver};
use shared::head_port::XY2_TICK_HZ;
use shared::model::{FaultKind, HeadStatus, Line, LineEvent};
use shared::xy2::status_line::{LevelDebouncer, StatusWordConfig, StatusWordReceiver};
use shared::xy2::{self, StatusLevel};
use shared::xy3::back::Parser;
use shared::xy3::back_rx;

use super::{HeadStatusInput, Options, PipelineError};

enum Kind {
    Xy2Level(LevelDebouncer),
    Xy2Word(StatusWordReceiver),
    Xy3(Box<Parser>),
    Hans(Box<hans::rx::HansRx>, StatusReceiver),
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
                    // The status-word sample geometry: one sample per output tick.
                    let ticks = XY2_TICK_HZ / config.output.frame_rate_hz.max(1);
                    let rx = StatusWordReceiver::new(StatusWordConfig {
                        pin: 0,
                        samples_per_period: u16::try_from(ticks / 2).unwrap_or(u16::MAX),
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
                let rx = hans::rx::HansRx::new(
                    options.hans_status_sample_hz,
                    hans::rx::Mode::Normal { channel: 1 },
                )
                .map_err(|e| PipelineError::Setup(e.to_string()))?;
                Kind::Hans(Box::new(rx), StatusReceiver::new())
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
                    seen += 1;
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
            (Kind::Hans(rx, receiver), HeadStatusInput::HansStatus(words)) => {
                let chunks: [&[u16]; 1] = [words];
                rx.push(&chunks, &mut |ev| match ev {
                    hans::rx::RxEvent::Frame(f) => {
                        receiver.apply(&f, status);
                        seen += 1;
                    }
                    // The head's STATUS line is not a controller channel. A period
                    // it delivered nothing in (`Missing`) is not reported: the status
                    // watchdog (`STATUS_LOST`) is what watches for a silent head.
                    hans::rx::RxEvent::Fault {
                        kind: FaultKind::Missing,
                        ..
                    } => {}
                    hans::rx::RxEvent::Fault { kind, .. } => faults.push(status_fault(kind)),
                });
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
