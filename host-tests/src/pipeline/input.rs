//! The controller-side receiver the configuration selects, fed with DMA buffers and
//! turned into the bridge's neutral [`LineEvent`]s.

use shared::bridge::{Config, HansDecode, Protocol, ZSource};
use shared::model::LineEvent;
use shared::{hans, xy2, xy3};

use super::{ControllerInput, Options, PipelineError, CONTROLLER_PINS_XY2};

/// XY3-100 bytes pushed per call: the receiver must be polled at least every
/// `WINDOW / 2` bytes.
const XY3_CHUNK: usize = xy3::rx::WINDOW / 2;

/// One receiver per protocol.
pub(super) enum Input {
    Xy2(xy2::rx::Receiver),
    Xy3(Box<xy3::rx::Receiver>),
    Hans(Box<hans::rx::HansRx>),
}

/// The HANS-100 receiver mode for a configured decode mode.
pub(super) fn hans_mode(decode: HansDecode) -> hans::rx::Mode {
    match decode {
        HansDecode::Normal(channel) => hans::rx::Mode::Normal { channel },
        HansDecode::Vote3(channels) => hans::rx::Mode::Vote3 { channels },
        HansDecode::Vote5 => hans::rx::Mode::Vote5,
        HansDecode::Super => hans::rx::Mode::Super,
    }
}

impl Input {
    pub fn new(config: &Config, options: &Options) -> Result<Input, PipelineError> {
        let c = &config.controller;
        Ok(match c.protocol {
            Protocol::Xy2 => {
                let p = CONTROLLER_PINS_XY2;
                let pins = xy2::rx::PinMap {
                    sync: p.sync,
                    x: p.x,
                    y: p.y,
                    // As the firmware: Z only when the bridge uses it.
                    z: (config.z.source == ZSource::Input).then_some(p.z).flatten(),
                };
                let link = xy2::LinkConfig {
                    mode: c.xy2.mode,
                    parity: c.xy2.parity,
                };
                let rx = xy2::rx::Receiver::new(pins, link)
                    .map_err(|e| PipelineError::Setup(e.to_string()))?;
                Input::Xy2(rx)
            }
            Protocol::Xy3 => {
                // As the firmware: the configured lines the bridge uses.
                Input::Xy3(Box::new(xy3::rx::Receiver::new(config.xy3_input_lines())))
            }
            Protocol::Hans => {
                let rx = hans::rx::HansRx::new(options.hans_sample_hz, hans_mode(c.hans.decode))
                    .map_err(|e| PipelineError::Setup(e.to_string()))?;
                Input::Hans(Box::new(rx))
            }
        })
    }

    pub fn name(&self) -> &'static str {
        match self {
            Input::Xy2(_) => "XY2-100",
            Input::Xy3(_) => "XY3-100",
            Input::Hans(_) => "HANS-100",
        }
    }

    /// Runs the receiver over `chunk` and appends its events in order.
    pub fn feed(
        &mut self,
        chunk: ControllerInput<'_>,
        out: &mut Vec<LineEvent>,
    ) -> Result<(), PipelineError> {
        match (self, chunk) {
            (Input::Xy2(rx), ControllerInput::Xy2(samples)) => {
                rx.feed(samples, &mut |ev| ev.line_events(&mut |le| out.push(le)));
            }
            (Input::Xy3(rx), ControllerInput::Xy3 { lines, ends }) => {
                let len = lines.first().map_or(0, |l| l.len());
                let mut from = 0;
                while from < len {
                    let to = (from + XY3_CHUNK).min(len);
                    let part: Vec<&[u8]> = lines
                        .iter()
                        .map(|l| l.get(from..to).unwrap_or_default())
                        .collect();
                    rx.push_bytes(&part)
                        .map_err(|e| PipelineError::BadInput(e.to_string()))?;
                    drain_xy3(rx, out);
                    from = to;
                }
                if len == 0 {
                    // Nothing to push, but the line count is still checked.
                    rx.push_bytes(lines)
                        .map_err(|e| PipelineError::BadInput(e.to_string()))?;
                }
                rx.push_ends(ends);
                drain_xy3(rx, out);
            }
            (Input::Hans(rx), ControllerInput::Hans(rings)) => {
                rx.push(&rings, &mut |ev| out.push(ev.to_line_event()));
            }
            (this, chunk) => {
                return Err(PipelineError::WrongInput {
                    expected: this.name(),
                    got: chunk.name(),
                })
            }
        }
        Ok(())
    }
}

fn drain_xy3(rx: &mut xy3::rx::Receiver, out: &mut Vec<LineEvent>) {
    while let Some(p) = rx.poll() {
        p.for_each_event(|le| out.push(le));
    }
}
