//! Independent checks of the pipeline's output: the head-side buffers are played
//! into waveforms, captured again as a head would (its own samplers) and decoded by
//! fresh `shared` receivers configured for the head; and the expected head frame of
//! a controller frame is computed from the configuration without the engine.

use shared::bridge::{Config, Protocol, ZSource};
use shared::hans;
use shared::model::{Axis, Command, ForwardFrame, LineEvent, Position};
use shared::{xy2, xy3};

use super::output::HeadOutput;
use super::PipelineError;
use crate::line::roles;
use crate::line::sample::{self, Oversampler, PartialByte};
use crate::wave::Ps;

/// One frame a head decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decoded {
    /// About where it started (XY2 / XY3: first CLK rising edge; HANS: within a
    /// sampler word), ps.
    pub start_ps: Ps,
    /// The frame, at the head's widths.
    pub frame: ForwardFrame,
}

/// What a head made of the output.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct HeadView {
    /// Frames that passed every check, in order.
    pub frames: Vec<Decoded>,
    /// Faults the head's receiver reported (any: the bridge must never send a
    /// frame that fails a check).
    pub faults: u32,
}

fn err(e: impl std::fmt::Display) -> PipelineError {
    PipelineError::BadInput(e.to_string())
}

/// Decodes the head-side output as the configured head would.
pub fn decode_head(config: &Config, out: &HeadOutput) -> Result<HeadView, PipelineError> {
    let wave = out.to_waveform().map_err(err)?;
    let with_z = config.z.source != ZSource::None;
    let mut view = HeadView::default();
    let h = &config.head;
    match h.protocol {
        Protocol::Xy2 => {
            let pins = sample::PinMap {
                sync: 0,
                x: 1,
                y: 2,
                z: with_z.then_some(3),
                status: None,
            };
            let (mut words, mut times) = sample::xy2_port_samples(&wave, &pins).map_err(err)?;
            // SYNC idles low before the first frame (see `stimulus::capture`).
            words.insert(0, 0);
            times.insert(0, 0);
            let link = xy2::LinkConfig {
                mode: h.xy2.mode,
                parity: h.xy2.parity,
            };
            let mut rx = xy2::rx::Receiver::new(
                xy2::rx::PinMap {
                    sync: 0,
                    x: 1,
                    y: 2,
                    z: pins.z,
                },
                link,
            )
            .map_err(err)?;
            let tick = match out {
                HeadOutput::Wave { tick_ps, .. } => *tick_ps,
                HeadOutput::Hans { .. } => 0.0,
            };
            for (i, w) in words.iter().enumerate() {
                let mut evs = Vec::new();
                rx.feed(std::slice::from_ref(w), &mut |e| {
                    e.line_events(&mut |le| evs.push(le))
                });
                let first = times.get(i.saturating_sub(19)).copied().unwrap_or(0);
                for le in evs {
                    match le {
                        LineEvent::Frame(f) => view.frames.push(Decoded {
                            start_ps: first.saturating_sub(tick.round() as Ps),
                            frame: f,
                        }),
                        LineEvent::Fault { .. } => view.faults += 1,
                    }
                }
            }
            view.faults += rx.counters().framing;
        }
        Protocol::Xy3 => {
            // The head listens on every line the bridge drives (U / W included).
            let lines = config.xy3_head_lines();
            let lanes: Vec<&str> = lines.axes().map(|a| roles::AXES[a.index()]).collect();
            let cap = sample::xy3_spi(&wave, &lanes, PartialByte::Discard).map_err(err)?;
            let mut rx = xy3::rx::Receiver::new(lines);
            let tick = match out {
                HeadOutput::Wave { tick_ps, .. } => *tick_ps,
                HeadOutput::Hans { .. } => 0.0,
            };
            let mut pushed = 0usize;
            let total = cap.bytes.first().map_or(0, Vec::len);
            let mut period_start = 0usize;
            let mut drain = |rx: &mut xy3::rx::Receiver, view: &mut HeadView| {
                while let Some(p) = rx.poll() {
                    let start = cap
                        .byte_times
                        .get(period_start)
                        .map_or(0, |&(first, _)| first.saturating_sub(tick.round() as Ps));
                    period_start = p.end as usize;
                    p.for_each_event(|le| match le {
                        LineEvent::Frame(f) => view.frames.push(Decoded {
                            start_ps: start,
                            frame: f,
                        }),
                        LineEvent::Fault { .. } => view.faults += 1,
                    });
                }
            };
            for &end in &cap.frame_ends {
                let to = (end as usize).min(total);
                while pushed < to {
                    let n = (to - pushed).min(xy3::rx::WINDOW / 2);
                    let part: Vec<&[u8]> = cap
                        .bytes
                        .iter()
                        .map(|l| l.get(pushed..pushed + n).unwrap_or_default())
                        .collect();
                    rx.push_bytes(&part).map_err(err)?;
                    pushed += n;
                    drain(&mut rx, &mut view);
                }
                rx.push_ends(&[end]);
                drain(&mut rx, &mut view);
            }
        }
        Protocol::Hans => {
            let fs = 37_500_000.0;
            let words = Oversampler {
                fs_hz: fs,
                start_ps: 7_000.0,
            }
            .sample(&wave, &[roles::HANS_CHANNELS[0]], wave.end_time())
            .map_err(err)?;
            let mut rx = hans::rx::HansRx::new(37_500_000, hans::rx::Mode::Normal { channel: 1 })
                .map_err(err)?;
            let ring: Vec<u16> = words
                .first()
                .map(|w| {
                    w.iter()
                        .flat_map(|w| [(w >> 16) as u16, *w as u16])
                        .collect()
                })
                .unwrap_or_default();
            let frame_ps = (hans::FRAME_BITS as f64 * 80_000.0) as Ps;
            for (j, w) in ring.iter().enumerate() {
                let at = (7_000.0 + (16 * (j + 1)) as f64 * 1e12 / fs) as Ps;
                rx.push(&[std::slice::from_ref(w)], &mut |e| match e {
                    hans::rx::RxEvent::Frame(f) => view.frames.push(Decoded {
                        start_ps: at.saturating_sub(frame_ps),
                        frame: f.to_forward(),
                    }),
                    // Losing alignment on an idle (all-zero) stretch, or the line
                    // delivering no frame there (`Missing`), is not a bad frame; every
                    // other fault is.
                    hans::rx::RxEvent::Fault { kind, .. } => {
                        if !matches!(
                            kind,
                            shared::model::FaultKind::Resync | shared::model::FaultKind::Missing
                        ) {
                            view.faults += 1;
                        }
                    }
                });
            }
        }
    }
    Ok(view)
}

/// Position widths of the head (X, Y, Z, U, W).
pub fn head_widths(config: &Config) -> [u8; 5] {
    Axis::ALL.map(|a| config.head.width(a))
}

/// Whether the head gets `axis` (U / W: an XY3-100 head driving it).
fn head_gets_uw(config: &Config, axis: Axis) -> bool {
    config.head.protocol == Protocol::Xy3 && config.xy3_head_lines().has(axis)
}

/// The raw head value of a position after resizing to `bits` and the axis map's
/// inversion and offset (offset in head LSBs, clamped).
fn mapped(p: Position, bits: u8, invert: bool, offset: i32) -> u32 {
    let max = if bits >= 32 {
        u32::MAX
    } else {
        (1u32 << bits) - 1
    };
    let mut v = i64::from(p.to_raw(bits));
    if invert {
        v = i64::from(max) - v;
    }
    (v + i64::from(offset)).clamp(0, i64::from(max)) as u32
}

/// What a head should receive for controller frame `f`: X/Y/Z/U/W raw values at
/// the head's widths after the axis map (`None` for an axis the bridge does not
/// drive; U / W pass unmapped), and the command if the head can carry it.
pub fn expected(config: &Config, f: &ForwardFrame) -> ([Option<u32>; 5], Option<Command>) {
    let a = &config.axes;
    let w = head_widths(config);
    let (sx, sy) = if a.swap_xy {
        (Axis::Y, Axis::X)
    } else {
        (Axis::X, Axis::Y)
    };
    let x = f.axis(sx).map(|p| mapped(p, w[0], a.invert_x, a.offset_x));
    let y = f.axis(sy).map(|p| mapped(p, w[1], a.invert_y, a.offset_y));
    let z = match config.z.source {
        ZSource::Input => f
            .axis(Axis::Z)
            .map(|p| mapped(p, w[2], a.invert_z, a.offset_z)),
        ZSource::Fixed => Position::from_raw(config.z.fixed, 20)
            .ok()
            .map(|p| p.to_raw(w[2])),
        ZSource::None => None,
    };
    let cmd = match (f.command, config.head.protocol) {
        (Some(c @ Command::Xy3(_)), Protocol::Xy3) => Some(c),
        (Some(c @ Command::Xy2Enhanced { .. }), Protocol::Xy2)
            if config.head.xy2.enhanced_commands =>
        {
            Some(c)
        }
        _ => None,
    };
    let x = if cmd.is_some() { None } else { x };
    let [u, w_pos] = [Axis::U, Axis::W].map(|a| {
        f.axis(a)
            .filter(|_| head_gets_uw(config, a))
            .map(|p| p.to_raw(w[a.index()]))
    });
    ([x, y, z, u, w_pos], cmd)
}

/// The raw values of a decoded head frame (X, Y, Z and the U / W the head gets, at
/// the head's widths) and its command.
pub fn raw(config: &Config, f: &ForwardFrame) -> ([Option<u32>; 5], Option<Command>) {
    let w = head_widths(config);
    let v = |a: Axis, bits: u8| f.axis(a).map(|p| p.to_raw(bits));
    let z = match config.z.source {
        ZSource::None => None,
        _ => v(Axis::Z, w[2]),
    };
    let x = if f.command.is_some() {
        None
    } else {
        v(Axis::X, w[0])
    };
    let [u, w_pos] =
        [Axis::U, Axis::W].map(|a| v(a, w[a.index()]).filter(|_| head_gets_uw(config, a)));
    ([x, v(Axis::Y, w[1]), z, u, w_pos], f.command)
}
