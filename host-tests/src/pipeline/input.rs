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
                let lines = config.xy3_input_lines();
                Input::Xy3(Box::new(Xy3Input {
                    rx: xy3::rx::Receiver::new(lines),
                    lines,
                    bytes: 0,
                    watch: options
                        .xy3_step_watch
                        .then(|| xy3::step::StepWatch::new(xy3::step::OUT_OF_STEP_NS)),
                    requests: Vec::new(),
                    gap: None,
                }))
            }
            Protocol::Hans => {
                let rx = hans::rx::HansRx::new(options.hans_sample_hz, hans_mode(c.hans.decode))
                    .map_err(|e| PipelineError::Setup(e.to_string()))?;
                Input::Hans(Box::new(rx))
            }
        })
    }

    /// The times (ns) the XY3-100 input's [`xy3::step::StepWatch`] asked for a
    /// restart of the input session (empty for other inputs).
    pub fn xy3_restart_requests(&self) -> &[u64] {
        match self {
            Input::Xy3(x) => &x.requests,
            _ => &[],
        }
    }

    /// An XY3-100 input session starts over (the line task restarted every SPI
    /// slave together, `firmware/tasks/line.rs`): the next chunk is the first of
    /// the new byte stream. `false` for other inputs.
    pub fn xy3_new_session(&mut self) -> bool {
        self.xy3_gap(|_| 0)
    }

    /// The bridge never gets the next `bytes` bytes of every line (a DMA half
    /// the firmware's full `XY3_INPUT` queue lost, with its frame ends): the next
    /// chunk continues the byte stream that much later. `false` for other inputs.
    pub fn xy3_lost(&mut self, bytes: u32) -> bool {
        self.xy3_gap(|at| at.wrapping_add(bytes))
    }

    /// The next chunk starts at byte count `first(bytes so far)`, not where the
    /// last one ended; gaps add up until a chunk comes.
    fn xy3_gap(&mut self, first: impl FnOnce(u32) -> u32) -> bool {
        match self {
            Input::Xy3(x) => {
                x.gap = Some(first(x.gap.unwrap_or(x.bytes)));
                true
            }
            _ => false,
        }
    }

    /// When the XY3-100 watch's held period goes out unconfirmed if no period
    /// comes first (`StepWatch::release_due`); `None` for other inputs.
    pub fn release_due(&self) -> Option<u64> {
        match self {
            Input::Xy3(x) => x.watch.as_ref().and_then(|w| w.release_due()),
            _ => None,
        }
    }

    /// At `now_ns` with no new input: the XY3-100 watch's held period, once due
    /// (`StepWatch::release`), as the firmware's bridge releases it every batch.
    pub fn release(&mut self, now_ns: u64, out: &mut Vec<LineEvent>) {
        if let Input::Xy3(x) = self {
            if let Some(w) = x.watch.as_mut() {
                w.release(now_ns, |le| out.push(le));
            }
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            Input::Xy2(_) => "XY2-100",
            Input::Xy3(_) => "XY3-100",
            Input::Hans(_) => "HANS-100",
        }
    }

    /// Runs the receiver over `chunk`, which the bridge has at `now_ns`, and
    /// appends its events in order.
    pub fn feed(
        &mut self,
        now_ns: u64,
        chunk: ControllerInput<'_>,
        out: &mut Vec<LineEvent>,
    ) -> Result<(), PipelineError> {
        let mut at = Vec::new();
        self.feed_at(now_ns, chunk, &mut at)?;
        out.extend(at.into_iter().map(|(_, e)| e));
        Ok(())
    }

    /// [`Input::feed`] with each event's position in the chunk: the units (XY2-100
    /// samples, XY3-100 X bytes, HANS-100 ring words) consumed when the receiver
    /// decided it, `0..=units`. Returns the chunk's units.
    pub fn feed_at(
        &mut self,
        now_ns: u64,
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
                if let Some(first) = x.gap.take() {
                    // As the bridge on a half that does not continue the byte
                    // stream, a new session's first or one after a lost half
                    // (`firmware/tasks/bridge_core.rs`, `Xy3Decoder::feed`): a
                    // receiver from this half's count on, what the old one still
                    // held is gone. The watch carries on (its backoff).
                    x.rx = xy3::rx::Receiver::with_origin(x.lines, first);
                    x.bytes = first;
                    out.push((0, xy3::step::dropped()));
                }
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
                    x.drain(now_ns, origin, len, out);
                    from = to;
                }
                if len == 0 {
                    // Nothing to push, but the line count is still checked.
                    x.rx.push_bytes(lines)
                        .map_err(|e| PipelineError::BadInput(e.to_string()))?;
                }
                x.bytes = origin.wrapping_add(len as u32);
                x.rx.push_ends(ends);
                x.drain(now_ns, origin, len, out);
                x.release(now_ns, len, out);
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

/// The XY3-100 receiver, the X bytes pushed into it in this session so far
/// (wrapping, the count its end positions use), and the out-of-step watch the
/// firmware's bridge runs on its periods (`firmware/tasks/bridge_core.rs`,
/// `Xy3Decoder`).
pub(super) struct Xy3Input {
    rx: xy3::rx::Receiver,
    lines: xy3::rx::Lines,
    bytes: u32,
    /// Withholds suspect periods and asks for a session restart, with the
    /// firmware's limit (`None`: `Options::xy3_step_watch` off).
    watch: Option<xy3::step::StepWatch>,
    /// When the watch asked for a restart, ns (the firmware's `XY3_RESYNC`).
    requests: Vec<u64>,
    /// The next chunk does not continue the byte stream: its first byte's count
    /// (0 for a new session).
    gap: Option<u32>,
}

impl Xy3Input {
    /// The watch's held period once it has waited too long for the next one
    /// (`StepWatch::release`), at the end of the chunk (`len`).
    fn release(&mut self, now_ns: u64, len: usize, out: &mut Vec<(u32, LineEvent)>) {
        if let Some(w) = self.watch.as_mut() {
            let at = unit(len);
            w.release(now_ns, |le| out.push((at, le)));
        }
    }

    /// The events of every period decoded so far through the watch, at their end
    /// positions counted from the chunk's first byte (`origin`), within `0..=len`
    /// (a period closed by an end position of an earlier chunk is at 0). The
    /// watch's clock is the chunk's time, as the firmware's is the time the bridge
    /// drains the half.
    fn drain(&mut self, now_ns: u64, origin: u32, len: usize, out: &mut Vec<(u32, LineEvent)>) {
        while let Some(p) = self.rx.poll() {
            // Signed: an end before the chunk's origin wraps to a large u32.
            let max = i32::try_from(len).unwrap_or(i32::MAX);
            let at = (p.end.wrapping_sub(origin) as i32).clamp(0, max) as u32;
            let mut emit = |le| out.push((at, le));
            match self.watch.as_mut() {
                Some(w) => {
                    if w.period(now_ns, &p, emit) {
                        self.requests.push(now_ns);
                    }
                }
                None => p.for_each_event(&mut emit),
            }
        }
    }
}
