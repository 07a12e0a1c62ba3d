//! Test input for the pipeline: controller frames -> waveforms through the `shared`
//! line-level transmitters, and waveforms -> time-stamped DMA buffers through the
//! samplers of [`crate::line::sample`] (so impairments can be applied in between).

use shared::bridge::{Config, Protocol, Xy3Select, ZSource};
use shared::hans;
use shared::model::{Axis, Command, ForwardFrame};
use shared::xy2;
use shared::xy3::neutral::{command_frame, position_frame};
use shared::xy3::FrameSize;

use super::{tx, ControllerInput, HeadStatusInput, Pipeline, PipelineError};
use crate::line::drive::{self, OutPinMap};
use crate::line::sample::{self, Oversampler, PartialByte};
use crate::line::{roles, uart};
use crate::sim::capture;
use crate::wave::{Ps, Waveform, PS_PER_S};

/// Controller-side XY2-100 / XY3-100 generator pins (any distinct bits; the
/// waveform names the lines by role).
const GEN_PINS: OutPinMap = OutPinMap {
    clk: 4,
    sync: 0,
    x: 1,
    y: 2,
    z: Some(3),
    u: Some(5),
    w: Some(6),
};

/// HANS-100 bit time, ps.
const HANS_BIT_PS: Ps = 80_000;

/// One frame the controller sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SentInput {
    /// Its first bit, ps.
    pub start_ps: Ps,
    /// The middle of its last bit (where a receiver samples it), ps.
    pub last_bit_ps: Ps,
    /// The frame, at the controller's widths.
    pub frame: ForwardFrame,
}

/// A controller's signals and what they carry.
#[derive(Debug, Clone)]
pub struct Stimulus {
    /// The lines (roles `CLK SYNC X Y Z`, or `CH1`..`CH5`).
    pub wave: Waveform,
    /// The frames, in order.
    pub sent: Vec<SentInput>,
}

/// Frame timing of a generated controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GenTiming {
    /// First frame's first bit, ps.
    pub start_ps: Ps,
    /// Frame period, ps (XY2-100: a multiple of 250 ns, at least 10 us; HANS-100 is
    /// always 10 us back to back and ignores it).
    pub period_ps: Ps,
    /// XY3-100 controller frame size.
    pub xy3_size: FrameSize,
}

impl Default for GenTiming {
    fn default() -> Self {
        GenTiming {
            start_ps: 2_000_000,
            period_ps: 10_000_000,
            xy3_size: FrameSize::Bits24,
        }
    }
}

fn err(e: impl std::fmt::Display) -> PipelineError {
    PipelineError::BadInput(e.to_string())
}

/// Encodes `frames` (controller widths) as the configured controller would send
/// them, with `shared`'s transmitters. Z is driven when `z.source = "input"`; an
/// XY3-100 controller drives the lines the bridge receives
/// (`Config::xy3_input_lines`, so U / W too when listed for an XY3-100 head).
pub fn controller_signal(
    config: &Config,
    frames: &[ForwardFrame],
    timing: &GenTiming,
) -> Result<Stimulus, PipelineError> {
    let with_z = config.z.source == ZSource::Input;
    let c = &config.controller;
    let mut sent = Vec::with_capacity(frames.len());
    let wave = match c.protocol {
        Protocol::Xy2 => {
            let tick_ps: Ps = 250_000;
            let ticks = usize::try_from(timing.period_ps / tick_ps).map_err(err)?;
            let link = xy2::LinkConfig {
                mode: c.xy2.mode,
                parity: c.xy2.parity,
            };
            let (tx, host) = tx::xy2(&GEN_PINS, with_z, ticks, link).map_err(err)?;
            let mut words = vec![0u32; ticks * frames.len()];
            for (i, (f, slot)) in frames.iter().zip(words.chunks_exact_mut(ticks)).enumerate() {
                let pos = |a: Axis| {
                    f.axis(a)
                        .map(|p| xy2::Frame::from_position(p, c.xy2.mode))
                        .ok_or_else(|| err(format!("frame {i}: no {a:?} position")))
                };
                let x = match f.command {
                    Some(cmd) => xy2::Frame::from_command(cmd)
                        .ok_or_else(|| err(format!("frame {i}: {cmd:?} is not XY2-100")))?,
                    None => pos(Axis::X)?,
                };
                let z = if with_z { Some(pos(Axis::Z)?) } else { None };
                let y = pos(Axis::Y)?;
                tx.write_frame(slot, &xy2::tx::TxFrame { x, y, z })
                    .map_err(err)?;
                let start_ps = timing.start_ps + i as Ps * ticks as Ps * tick_ps;
                sent.push(SentInput {
                    start_ps,
                    last_bit_ps: start_ps + 39 * tick_ps,
                    frame: *f,
                });
            }
            drive::bsrr_to_wave(&words, tick_ps as f64, timing.start_ps, &host, &[]).map_err(err)?
        }
        Protocol::Xy3 => {
            let size = timing.xy3_size;
            let lines = config.xy3_input_lines();
            let (tx, host) = tx::xy3(&GEN_PINS, lines, size).map_err(err)?;
            let ticks = tx.ticks_per_frame();
            let tick_ps = timing.period_ps as f64 / ticks as f64;
            let bits = u64::from(size.bits());
            let mut words = vec![0u32; ticks * frames.len()];
            for (i, (f, slot)) in frames.iter().zip(words.chunks_exact_mut(ticks)).enumerate() {
                let pos = |a: Axis| {
                    f.axis(a)
                        .map(|p| position_frame(p, size))
                        .ok_or_else(|| err(format!("frame {i}: no {a:?} position")))
                };
                let x = match f.command {
                    Some(cmd) => command_frame(&cmd, size).map_err(err)?,
                    None => pos(Axis::X)?,
                };
                let other = |a: Axis| lines.has(a).then(|| pos(a)).transpose();
                let data = [
                    Some(x),
                    Some(pos(Axis::Y)?),
                    other(Axis::Z)?,
                    other(Axis::U)?,
                    other(Axis::W)?,
                ];
                tx.encode(&data, slot).map_err(err)?;
                let start_ps = timing.start_ps + i as Ps * timing.period_ps;
                sent.push(SentInput {
                    start_ps,
                    last_bit_ps: start_ps + ((2 * bits - 1) as f64 * tick_ps).round() as Ps,
                    frame: *f,
                });
            }
            // SYNC idles high before the first frame.
            drive::bsrr_to_wave(
                &words,
                tick_ps,
                timing.start_ps,
                &host,
                &[(roles::SYNC, true)],
            )
            .map_err(err)?
        }
        Protocol::Hans => {
            let mut buf = vec![0u8; (frames.len() * hans::FRAME_BITS).div_ceil(8) + 1];
            let mut hold = hans::Frame::CENTRE;
            for (i, f) in frames.iter().enumerate() {
                let wire = hans::Frame::from_forward(f, &hold).map_err(err)?;
                hold = wire;
                wire.write_at(&mut buf, i * hans::FRAME_BITS).map_err(err)?;
                let start_ps = timing.start_ps + (i * hans::FRAME_BITS) as Ps * HANS_BIT_PS;
                sent.push(SentInput {
                    start_ps,
                    last_bit_ps: start_ps
                        + (hans::FRAME_BITS as Ps - 1) * HANS_BIT_PS
                        + HANS_BIT_PS / 2,
                    frame: *f,
                });
            }
            buf.truncate((frames.len() * hans::FRAME_BITS).div_ceil(8));
            let mut wave = Waveform::new();
            for name in roles::HANS_CHANNELS {
                let mut s = drive::bitstream_to_signal(
                    name,
                    &buf,
                    drive::HANS_BIT_RATE_HZ,
                    timing.start_ps,
                )
                .map_err(err)?;
                // The line idles low after the last frame (the stream's last bits).
                let end = timing.start_ps + (frames.len() * hans::FRAME_BITS) as Ps * HANS_BIT_PS;
                let _ = s.push(end, false);
                wave.insert(s);
            }
            wave
        }
    };
    Ok(Stimulus { wave, sent })
}

/// Controller-side DMA buffers owned, for time-ordered feeding.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Buffers {
    /// XY2-100 port samples.
    Xy2(Vec<u16>),
    /// XY3-100 bytes per line and frame end positions.
    Xy3 {
        /// Bytes per line.
        lines: Vec<Vec<u8>>,
        /// End positions.
        ends: Vec<u32>,
    },
    /// HANS-100 ring words per channel (CH1..CH5).
    Hans([Vec<u16>; 5]),
    /// XY2-100 STATUS level samples.
    Level(Vec<bool>),
    /// XY2-100 STATUS word samples (one per output bit).
    Word(Vec<u16>),
    /// XY3-100 backchannel bytes from the head.
    Back(Vec<u8>),
    /// HANS-100 STATUS ring words.
    HansStatus(Vec<u16>),
}

/// Buffers and the time the firmware would have them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Timed {
    /// ns.
    pub t_ns: u64,
    /// The buffers.
    pub buffers: Buffers,
}

impl Buffers {
    fn append(&mut self, other: Buffers) -> Result<(), Buffers> {
        match (self, other) {
            (Buffers::Xy2(a), Buffers::Xy2(b)) => a.extend(b),
            (
                Buffers::Xy3 { lines, ends },
                Buffers::Xy3 {
                    lines: l2,
                    ends: e2,
                },
            ) => {
                for (a, b) in lines.iter_mut().zip(l2) {
                    a.extend(b);
                }
                ends.extend(e2);
            }
            (Buffers::Hans(a), Buffers::Hans(b)) => {
                for (x, y) in a.iter_mut().zip(b) {
                    x.extend(y);
                }
            }
            (Buffers::Level(a), Buffers::Level(b)) => a.extend(b),
            (Buffers::Word(a), Buffers::Word(b)) => a.extend(b),
            (Buffers::Back(a), Buffers::Back(b)) => a.extend(b),
            (Buffers::HansStatus(a), Buffers::HansStatus(b)) => a.extend(b),
            (_, other) => return Err(other),
        }
        Ok(())
    }

    /// Head-side status buffers (as opposed to the controller's lines).
    pub fn is_status(&self) -> bool {
        matches!(
            self,
            Buffers::Level(_) | Buffers::Word(_) | Buffers::Back(_) | Buffers::HansStatus(_)
        )
    }

    /// Runs `f` on the controller-side view of these buffers (`None` for status
    /// buffers).
    pub fn controller_input<R>(&self, f: impl FnOnce(ControllerInput<'_>) -> R) -> Option<R> {
        match self {
            Buffers::Xy2(s) => Some(f(ControllerInput::Xy2(s))),
            Buffers::Xy3 { lines, ends } => {
                let l: Vec<&[u8]> = lines.iter().map(Vec::as_slice).collect();
                Some(f(ControllerInput::Xy3 { lines: &l, ends }))
            }
            Buffers::Hans(r) => Some(f(ControllerInput::Hans([
                &r[0], &r[1], &r[2], &r[3], &r[4],
            ]))),
            _ => None,
        }
    }

    /// Runs `f` on the head-status view of these buffers (`None` for controller
    /// buffers).
    pub fn status_input<R>(&self, f: impl FnOnce(HeadStatusInput<'_>) -> R) -> Option<R> {
        match self {
            Buffers::Level(s) => Some(f(HeadStatusInput::Xy2Level(s))),
            Buffers::Word(s) => Some(f(HeadStatusInput::Xy2Word(s))),
            Buffers::Back(b) => Some(f(HeadStatusInput::Xy3Back(b))),
            Buffers::HansStatus(w) => Some(f(HeadStatusInput::HansStatus(w))),
            _ => None,
        }
    }

    /// Hands these buffers to the pipeline at `t_ns`.
    pub fn feed(&self, p: &mut Pipeline, t_ns: u64) -> Result<(), PipelineError> {
        if let Some(r) = self.controller_input(|c| p.feed(t_ns, c)) {
            return r;
        }
        self.status_input(|s| p.feed_status(t_ns, s))
            .unwrap_or(Ok(()))
    }
}

fn ns_ceil(ps: Ps) -> u64 {
    ps.div_ceil(1000)
}

/// The controller's lines of `wave` the configured receiver takes: CLK, SYNC and
/// the data lines of `axes` (other signals are left out, as the board's receiver
/// never sees them).
fn controller_lines(wave: &Waveform, axes: &[Axis]) -> Waveform {
    let data = axes.iter().map(|&a| roles::AXES[a.index()]);
    let mut lines = Waveform::new();
    for s in [roles::CLK, roles::SYNC]
        .into_iter()
        .chain(data)
        .filter_map(|r| wave.get(r))
    {
        lines.insert(s.clone());
    }
    lines
}

/// The controller's waveform as the firmware's input DMA would capture it, one item
/// per sample (XY2-100 CLK edge, XY3-100 byte or SYNC edge, HANS-100 `u16` word),
/// each at the time it is complete, sampled by the bridge-sim's capture helpers
/// ([`crate::sim::capture`]). `hans_phase` (0..1) places the HANS-100 sampling clock
/// within its first period.
pub fn capture(
    config: &Config,
    wave: &Waveform,
    hans_sample_hz: u32,
    hans_phase: f64,
) -> Result<Vec<Timed>, PipelineError> {
    let with_z = config.z.source == ZSource::Input;
    let mut out = Vec::new();
    match config.controller.protocol {
        Protocol::Xy2 => {
            // The generated line idles with SYNC low before the first frame: one idle
            // sample lets the receiver see the first frame's SYNC rising edge.
            let axes: &[Axis] = if with_z {
                &[Axis::X, Axis::Y, Axis::Z]
            } else {
                &[Axis::X, Axis::Y]
            };
            let lines = controller_lines(wave, axes);
            let input = capture::xy2_from_wave(&lines, capture::LeadIdle::Always).map_err(err)?;
            if with_z && input.pins.z.is_none() {
                return Err(err("XY2-100 capture: no Z line (z.source = \"input\")"));
            }
            for (w, t) in input.words.into_iter().zip(input.times) {
                out.push(Timed {
                    t_ns: ns_ceil(t),
                    buffers: Buffers::Xy2(vec![w]),
                });
            }
        }
        Protocol::Xy3 => {
            // As the firmware: the listed lines the bridge uses.
            let want: Vec<Axis> = config.xy3_input_lines().axes().collect();
            let input = capture::xy3_from_wave(&controller_lines(wave, &want)).map_err(err)?;
            if input.axes() != want {
                return Err(err(format!(
                    "XY3-100 capture: lines {:?}, the receiver takes {want:?}",
                    input.axes()
                )));
            }
            let cap = input.spi;
            for (i, &(_, last)) in cap.byte_times.iter().enumerate() {
                let lines = cap
                    .bytes
                    .iter()
                    .map(|l| l.get(i).copied().into_iter().collect())
                    .collect();
                out.push(Timed {
                    t_ns: ns_ceil(last),
                    buffers: Buffers::Xy3 {
                        lines,
                        ends: Vec::new(),
                    },
                });
            }
            for (&e, &t) in cap.frame_ends.iter().zip(&cap.end_times) {
                out.push(Timed {
                    t_ns: ns_ceil(t),
                    buffers: Buffers::Xy3 {
                        lines: vec![Vec::new(); want.len()],
                        ends: vec![e],
                    },
                });
            }
            // Stable: a byte and an end at the same ns keep bytes first.
            out.sort_by_key(|t| t.t_ns);
        }
        Protocol::Hans => {
            let fs = f64::from(hans_sample_hz);
            let (words, start_ps) =
                capture::oversample_at(wave, &roles::HANS_CHANNELS, fs, hans_phase).map_err(err)?;
            let n = words.first().map_or(0, Vec::len);
            for j in 0..n {
                let mut rings: [Vec<u16>; 5] = Default::default();
                for (r, ch) in rings.iter_mut().zip(&words) {
                    r.push(ch.get(j).copied().unwrap_or(0));
                }
                let last = start_ps + (16 * (j + 1) - 1) as f64 * PS_PER_S / fs;
                out.push(Timed {
                    t_ns: ns_ceil(last.round() as Ps),
                    buffers: Buffers::Hans(rings),
                });
            }
        }
    }
    Ok(out)
}

/// How [`xy3_sessions`] models the firmware's XY3-100 line task
/// (`firmware/tasks/line.rs`, `xy3_in`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SessionModel {
    /// What the SPI slaves do with a partial byte at NSS release, with
    /// `controller.xy3.select = "sync"` (with `"always"` the slaves have no NSS:
    /// [`PartialByte::Unselected`] whatever this says).
    pub partial: PartialByte,
    /// From the end of a session's last half to the next session's SCK gate
    /// opening, ns: dropping five SPI slaves, starting them and the SYNC EXTI again
    /// (not measured on the board; tens of microseconds at most).
    pub setup_ns: u64,
    /// Every `lose_every`-th half of a session (the last of each run of that
    /// many) never reaches the pipeline, as when the bridge falls behind and the
    /// line task finds the queue full (0: none lost).
    pub lose_every: u32,
    /// From a half's last byte to the line task draining the SYNC marks, ns: a
    /// SYNC rise that came meanwhile goes with that half (0: only those before
    /// its last byte).
    pub ends_lag_ns: u64,
}

impl Default for SessionModel {
    fn default() -> Self {
        SessionModel {
            partial: PartialByte::Discard,
            setup_ns: 20_000,
            lose_every: 0,
            ends_lag_ns: 0,
        }
    }
}

/// One input session of [`xy3_sessions`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Xy3Session {
    /// When its SCK gate opened, ps (0 for the first).
    pub start_ps: Ps,
    /// DMA halves it handed to the pipeline.
    pub halves: u32,
    /// When the pipeline asked for a restart during it, ns (`None`: it ran to the
    /// end of the waveform).
    pub requested_ns: Option<u64>,
    /// When its last half was complete, ns (the line task restarts right after).
    pub end_ns: u64,
}

/// The DMA half the firmware hands over per line (`firmware/channels.rs`,
/// `XY3_HALF`).
pub const XY3_HALF: usize = shared::xy3::rx::WINDOW / 2;

/// Feeds an XY3-100 controller's `wave` to `p` as the firmware's line task
/// delivers it, input session by input session, then runs the clocks to `end_ns`.
///
/// In a session the SPI slaves of the received lines ([`sample::xy3_spi_session`],
/// each on its own SCK when an impairment gave it one) fill their rings from the
/// session's start; every [`XY3_HALF`] bytes of every line, with the frame ends
/// the EXTI recorded by then, are one half, fed at the time its last byte is in
/// and spread over the time since the one before ([`Pipeline::feed_spread`]).
/// When the pipeline asks for a restart ([`Pipeline::xy3_restart_requests`],
/// raised while it decodes half `j`), the line task, which checks the request
/// once per half after handing one over, still delivers half `j + 1` (in flight
/// when the bridge decoded `j`) and ends the session there: the bytes after that
/// half, the partial byte and the frame ends not drained are lost. After
/// `model.setup_ns` a new session starts every slave together
/// ([`Pipeline::xy3_new_session`]), from the next clock edge, possibly inside a
/// frame. A glitch before that start no longer matters: all lines are in step
/// again. With `model.lose_every`, halves the bridge never gets are skipped
/// ([`Pipeline::xy3_lost`]): the session goes on, the byte stream has a gap.
pub fn xy3_sessions(
    p: &mut Pipeline,
    config: &Config,
    wave: &Waveform,
    model: &SessionModel,
    end_ns: u64,
) -> Result<Vec<Xy3Session>, PipelineError> {
    if config.controller.protocol != Protocol::Xy3 {
        return Err(PipelineError::WrongInput {
            expected: "XY3-100",
            got: "an XY3-100 session",
        });
    }
    let names: Vec<&str> = config
        .xy3_input_lines()
        .axes()
        .map(|a| roles::AXES[a.index()])
        .collect();
    // The slaves the firmware starts (`line::xy3_in`): NSS on SYNC, or none.
    let partial = match config.controller.xy3.select {
        Xy3Select::Sync => model.partial,
        Xy3Select::Always => PartialByte::Unselected,
    };
    let mut sessions = Vec::new();
    let mut start_ps: Ps = 0;
    let mut prev_ns = 0;
    loop {
        let cap = sample::xy3_spi_session(wave, &names, partial, start_ps).map_err(err)?;
        let len = cap.bytes.first().map_or(0, Vec::len);
        let halves = len / XY3_HALF;
        let asked = p.xy3_restart_requests().len();
        let mut session = Xy3Session {
            start_ps,
            halves: 0,
            requested_ns: None,
            end_ns: ns_ceil(start_ps),
        };
        let mut last_half = None;
        let mut next_end = 0;
        for h in 0..halves {
            let (lo, hi) = (h * XY3_HALF, (h + 1) * XY3_HALF);
            let done_ps = cap.byte_times.get(hi - 1).map_or(start_ps, |t| t.1);
            let t_ns = ns_ceil(done_ps);
            let mut ends = Vec::new();
            while let (Some(&e), Some(&t)) =
                (cap.frame_ends.get(next_end), cap.end_times.get(next_end))
            {
                if t > done_ps + model.ends_lag_ns * 1000 {
                    break;
                }
                ends.push(e);
                next_end += 1;
            }
            let lines: Vec<&[u8]> = cap
                .bytes
                .iter()
                .map(|l| l.get(lo..hi).unwrap_or_default())
                .collect();
            let every = model.lose_every as usize;
            if every > 0 && h % every == every - 1 {
                // Lost with its frame ends; the line task goes on (a request
                // the bridge never made stays unmade).
                p.xy3_lost(XY3_HALF as u32);
                session.end_ns = t_ns;
                if last_half == Some(h) {
                    break;
                }
                continue;
            }
            let span = t_ns.saturating_sub(prev_ns).max(1);
            p.feed_spread(
                t_ns,
                span,
                ControllerInput::Xy3 {
                    lines: &lines,
                    ends: &ends,
                },
            )?;
            prev_ns = t_ns;
            session.halves += 1;
            session.end_ns = t_ns;
            if last_half == Some(h) {
                break;
            }
            if last_half.is_none() {
                if let Some(&t) = p.xy3_restart_requests().get(asked) {
                    session.requested_ns = Some(t);
                    last_half = Some(h + 1);
                }
            }
        }
        sessions.push(session);
        if session.requested_ns.is_none() {
            break;
        }
        start_ps = session.end_ns * 1000 + model.setup_ns * 1000;
        p.xy3_new_session();
    }
    p.run_until(end_ns);
    Ok(sessions)
}

/// Merges consecutive items of the same kind that fall into the same window of
/// `window_ns` (as DMA halves would deliver them) into one chunk, at the window's
/// last item's time.
pub fn chunk(items: Vec<Timed>, window_ns: u64) -> Vec<Timed> {
    let w = window_ns.max(1);
    let mut out: Vec<Timed> = Vec::new();
    for it in items {
        if let Some(last) = out.last_mut() {
            if last.t_ns / w == it.t_ns / w {
                let t = it.t_ns;
                match last.buffers.append(it.buffers) {
                    Ok(()) => last.t_ns = t,
                    Err(b) => out.push(Timed {
                        t_ns: t,
                        buffers: b,
                    }),
                }
                continue;
            }
        }
        out.push(it);
    }
    out
}

/// Merges time-ordered item lists into one, ordered by time (stable).
pub fn merge(lists: Vec<Vec<Timed>>) -> Vec<Timed> {
    let mut all: Vec<Timed> = lists.into_iter().flatten().collect();
    all.sort_by_key(|t| t.t_ns);
    all
}

/// Feeds every item in order, then runs the clocks to `end_ns`.
pub fn run(p: &mut Pipeline, items: &[Timed], end_ns: u64) -> Result<(), PipelineError> {
    for it in items {
        it.buffers.feed(p, it.t_ns)?;
    }
    p.run_until(end_ns);
    Ok(())
}

/// Head backchannel: `bytes` as UART 8N1 from `t0_ps` at `baud`, received by a UART
/// model; one item per byte at its stop bit's middle.
pub fn back_bytes(bytes: &[u8], baud: u32, t0_ps: Ps) -> Result<Vec<Timed>, PipelineError> {
    let s = uart::uart_encode(roles::UART, bytes, f64::from(baud), t0_ps, 0).map_err(err)?;
    let bit = PS_PER_S / f64::from(baud.max(1));
    Ok(uart::uart_decode(&s, f64::from(baud))
        .map_err(err)?
        .into_iter()
        .map(|f| Timed {
            t_ns: ns_ceil(f.time + (9.5 * bit) as Ps),
            buffers: Buffers::Back(vec![f.value]),
        })
        .collect())
}

/// Head HANS-100 STATUS: `frames` back to back from `t0_ps`, sampled at `fs_hz`
/// from `t0_ps` on; one item per `u16` word.
pub fn hans_status(
    frames: &[hans::Frame],
    t0_ps: Ps,
    fs_hz: u32,
) -> Result<Vec<Timed>, PipelineError> {
    let mut buf = vec![0u8; (frames.len() * hans::FRAME_BITS).div_ceil(8) + 1];
    for (i, f) in frames.iter().enumerate() {
        f.write_at(&mut buf, i * hans::FRAME_BITS).map_err(err)?;
    }
    let mut s = drive::bitstream_to_signal(roles::STATUS, &buf, drive::HANS_BIT_RATE_HZ, t0_ps)
        .map_err(err)?;
    let end = t0_ps + (frames.len() * hans::FRAME_BITS) as Ps * HANS_BIT_PS;
    let _ = s.push(end, false);
    let mut w = Waveform::new();
    w.insert(s);
    let fs = f64::from(fs_hz);
    let words = Oversampler {
        fs_hz: fs,
        start_ps: t0_ps as f64,
    }
    .sample(&w, &[roles::STATUS], end + 2_000_000)
    .map_err(err)?;
    let mut out = Vec::new();
    for (i, &word) in words
        .first()
        .map(Vec::as_slice)
        .unwrap_or_default()
        .iter()
        .enumerate()
    {
        for (h, half) in [(word >> 16) as u16, word as u16].into_iter().enumerate() {
            let j = 2 * i + h;
            let last = t0_ps as f64 + (16 * (j + 1) - 1) as f64 * PS_PER_S / fs;
            out.push(Timed {
                t_ns: ns_ceil(last.round() as Ps),
                buffers: Buffers::HansStatus(vec![half]),
            });
        }
    }
    Ok(out)
}

/// XY2-100 head STATUS level: one sample every `every_ns` from 0 to `end_ns`,
/// `high(t_ns)` giving the line level.
pub fn level_samples(end_ns: u64, every_ns: u64, high: impl Fn(u64) -> bool) -> Vec<Timed> {
    (0..)
        .map(|k| k * every_ns.max(1))
        .take_while(|&t| t < end_ns)
        .map(|t| Timed {
            t_ns: t,
            buffers: Buffers::Level(vec![high(t)]),
        })
        .collect()
}

/// A neutral frame at the controller's widths (`command` replaces X); values are
/// taken modulo the width. No U / W: see [`frame_uw`].
pub fn frame(
    config: &Config,
    timing: &GenTiming,
    xyz: [u32; 3],
    command: Option<Command>,
) -> ForwardFrame {
    build(config, timing, xyz, None, command)
}

/// As [`frame`], with U and W for an XY3-100 controller whose U / W lines the
/// bridge receives (`Config::xy3_input_lines`); ignored otherwise.
pub fn frame_uw(
    config: &Config,
    timing: &GenTiming,
    [x, y, z, u, w]: [u32; 5],
    command: Option<Command>,
) -> ForwardFrame {
    build(config, timing, [x, y, z], Some([u, w]), command)
}

fn build(
    config: &Config,
    timing: &GenTiming,
    [x, y, z]: [u32; 3],
    uw: Option<[u32; 2]>,
    command: Option<Command>,
) -> ForwardFrame {
    let w = controller_widths(config, timing.xy3_size);
    let pos =
        |v: u32, bits: u8| shared::model::Position::from_raw(v & ((1u32 << bits) - 1), bits).ok();
    let mut f = ForwardFrame::default();
    f.axes[0] = if command.is_some() {
        None
    } else {
        pos(x, w[0])
    };
    f.axes[1] = pos(y, w[1]);
    if config.z.source == ZSource::Input || config.controller.protocol == Protocol::Hans {
        f.axes[2] = pos(z, w[2]);
    }
    if let (Protocol::Xy3, Some(uw)) = (config.controller.protocol, uw) {
        let lines = config.xy3_input_lines();
        let bits = timing.xy3_size.position_bits();
        for (axis, v) in [(Axis::U, uw[0]), (Axis::W, uw[1])] {
            if lines.has(axis) {
                f.axes[axis.index()] = pos(v, bits);
            }
        }
    }
    f.command = command;
    f
}

/// Position widths (X, Y, Z) the controller sends.
pub fn controller_widths(config: &Config, xy3_size: FrameSize) -> [u8; 3] {
    let c = &config.controller;
    match c.protocol {
        Protocol::Xy2 => match c.xy2.mode {
            xy2::Mode::Standard16 => [16; 3],
            xy2::Mode::Extended18 => [18; 3],
        },
        Protocol::Xy3 => [xy3_size.position_bits(); 3],
        Protocol::Hans => [20, 20, 16],
    }
}

/// XY2-100 head STATUS word: the head answers every output frame period with the
/// status frame of `word` (the `shared` STATUS transmitter's levels, pin 0), read
/// one sample per output bit with the frame at offset 1; one item per period, at
/// the period's end. `samples_per_period`: `shared::xy2::status_line::samples_per_period`
/// of the output's ticks per frame (the sample after an odd period's idle tick kept).
pub fn status_words(
    word: xy2::StatusWord,
    link: &xy2::LinkConfig,
    samples_per_period: usize,
    periods: usize,
) -> Vec<Timed> {
    let mut bsrr = [0u32; 20];
    let out = match xy2::status_line::StatusOut::new(
        0,
        xy2::StatusLevel {
            polarity: xy2::Polarity::LowIsOk,
        },
    ) {
        Ok(o) => o,
        Err(_) => return Vec::new(),
    };
    out.word_frame(word, link, &mut bsrr);
    // Set (low half) = high level.
    let bits: Vec<u16> = bsrr.iter().map(|w| u16::from(w & 1 != 0)).collect();
    let mut samples = vec![0u16; samples_per_period * periods + 1];
    for p in 0..periods {
        for (k, &b) in bits.iter().enumerate() {
            if let Some(s) = samples.get_mut(p * samples_per_period + 1 + k) {
                *s = b;
            }
        }
    }
    let period_ns = samples_per_period as u64 * 500;
    samples
        .chunks(samples_per_period)
        .enumerate()
        .map(|(p, c)| Timed {
            t_ns: (p as u64 + 1) * period_ns,
            buffers: Buffers::Word(c.to_vec()),
        })
        .collect()
}
