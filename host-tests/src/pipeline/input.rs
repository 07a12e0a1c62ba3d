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
    Xy3(Box<Xy3Input>),
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
                Input::Xy3(Box::new(Xy3Input {
                    rx: xy3::rx::Receiver::new(config.xy3_input_lines()),
                    bytes: 0,
                }))
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
        let mut at = Vec::new();
        self.feed_at(chunk, &mut at)?;
        out.extend(at.into_iter().map(|(_, e)| e));
        Ok(())
    }

    /// [`Input::feed`] with each event's position in the chunk: the units (XY2-100
    /// samples, XY3-100 X bytes, HANS-100 ring words) consumed when the receiver
    /// decided it, `0..=units`. Returns the chunk's units.
    pub fn feed_at(
        &mut self,
        chunk: ControllerInput<'_>,
        out: &mut Vec<(u32, LineEvent)>,
    ) -> Result<u32, PipelineError> {
        let units = match (self, chunk) {
            (Input::Xy2(rx), ControllerInput::Xy2(samples)) => {
                rx.feed_at(samples, &mut |at, ev| {
                    ev.line_events(&mut |le| out.push((unit(at), le)))
                });
                samples.len()
            }
            (Input::Xy3(x), ControllerInput::Xy3 { lines, ends }) => {
                let len = lines.first().map_or(0, |l| l.len());
                let origin = x.bytes;
                let mut from = 0;
                while from < len {
                    let to = (from + XY3_CHUNK).min(len);
                    let part: Vec<&[u8]> = lines
                        .iter()
                        .map(|l| l.get(from..to).unwrap_or_default())
                        .collect();
                    x.rx.push_bytes(&part)
                        .map_err(|e| PipelineError::BadInput(e.to_string()))?;
                    drain_xy3(&mut x.rx, origin, len, out);
                    from = to;
                }
                if len == 0 {
                    // Nothing to push, but the line count is still checked.
                    x.rx.push_bytes(lines)
                        .map_err(|e| PipelineError::BadInput(e.to_string()))?;
                }
                x.bytes = origin.wrapping_add(len as u32);
                x.rx.push_ends(ends);
                drain_xy3(&mut x.rx, origin, len, out);
                len
            }
            (Input::Hans(rx), ControllerInput::Hans(rings)) => {
                rx.push_at(&rings, &mut |at, ev| {
                    out.push((unit(at), ev.to_line_event()))
                });
                rings.iter().map(|r| r.len()).max().unwrap_or(0)
            }
            (this, chunk) => {
                return Err(PipelineError::WrongInput {
                    expected: this.name(),
                    got: chunk.name(),
                })
            }
        };
        Ok(unit(units))
    }
}

/// A position or length in units as `u32` (a chunk of more than 4 G units is not a
/// DMA half; saturate rather than wrap).
fn unit(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// The XY3-100 receiver and the X bytes pushed into it so far (wrapping, the
/// count its end positions use).
pub(super) struct Xy3Input {
    rx: xy3::rx::Receiver,
    bytes: u32,
}

/// The events of every period decoded so far, at their end positions counted from
/// the chunk's first byte (`origin`), within `0..=len` (a period closed by an end
/// position of an earlier chunk is at 0).
fn drain_xy3(rx: &mut xy3::rx::Receiver, origin: u32, len: usize, out: &mut Vec<(u32, LineEvent)>) {
    while let Some(p) = rx.poll() {
        // Signed: an end before the chunk's origin wraps to a large u32.
        let max = i32::try_from(len).unwrap_or(i32::MAX);
        let at = (p.end.wrapping_sub(origin) as i32).clamp(0, max) as u32;
        p.for_each_event(|le| out.push((at, le)));
    }
}
