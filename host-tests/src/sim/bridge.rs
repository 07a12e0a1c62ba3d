//! `bridge`: the whole bridge on a controller-side capture, through
//! [`crate::pipeline::Pipeline`] (the firmware's receivers, `shared::bridge::Bridge`
//! and transmitters, the same `shared` code).
//!
//! 1. The configuration is read as the firmware build reads it ([`load_config`]).
//! 2. The capture becomes the controller-side DMA buffers ([`capture`]), cut into
//!    chunks stamped with the time the firmware would have them: XY2-100 at each
//!    frame's last sample (SYNC low) or every 20 samples, XY3-100 at each SYNC rising
//!    edge, HANS-100 every [`HANS_WORDS_PER_CHUNK`] ring words.
//! 3. An optional head-status capture becomes the head-side status buffers: an XY2-100
//!    STATUS level sampled once per output frame period, an XY2-100 status word
//!    sampled once per output bit (the firmware's TIM8 compare DMA), XY3-100
//!    backchannel bytes at their stop bit, HANS-100 STATUS oversampled like the
//!    firmware's status SPI.
//! 4. Every chunk goes to the pipeline in time order; its output clocks then run to
//!    the end of the captures plus [`TAIL_SLOTS`] output periods.
//! 5. The head-side waveforms and the controller-side status waveforms are written to
//!    the output directory ([`HEAD_FILE`], [`STATUS_FILE`]) under the default signal
//!    names, and a [`Report`] with the counters comes back.

use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};

use shared::bridge::{Config, Counters, LinkState, Protocol, StatusForm, ZSource};
use shared::model::{Alarms, Axis, Line};

use super::capture::{self, HansInput, Lines, Xy2Input, Xy3Input};
use super::encode::Progress;
use super::{names, SimError};
use crate::line::roles;
use crate::pipeline::{
    Change, ControllerInput, ControllerStatus, HeadOutput, HeadStatusInput, Options, Pipeline,
    PipelineCounters,
};
use crate::vcd_io::{self, NameMap, WriteTimescale};
use crate::wave::{Ps, Signal, Waveform};

/// The head-side waveforms, in the output directory.
pub const HEAD_FILE: &str = "head.vcd";
/// The controller-side status waveforms, in the output directory.
pub const STATUS_FILE: &str = "controller-status.vcd";
/// HANS-100 ring words per channel fed per chunk (4 words = 64 samples, 1.3..1.7 us:
/// well inside one 10 us frame, so event times are within a frame of the truth).
pub const HANS_WORDS_PER_CHUNK: usize = 4;
/// Output periods run after the end of the captures, so the last input frame
/// reaches the head (free-running output computes a slot ahead of playing it).
pub const TAIL_SLOTS: u64 = 3;

/// Reads a bridge configuration file the way the firmware build does (`build.rs`:
/// TOML -> [`Config`] -> [`Config::validate`]). Errors are one line naming the file
/// and the key: the TOML line and its table for a file that does not parse, the key
/// from [`shared::bridge::ConfigError`] for one that does not validate.
pub fn load_config(path: &Path) -> Result<Config, SimError> {
    let shown = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| SimError::Io {
        path: shown.clone(),
        message: e.to_string(),
    })?;
    let config: Config = toml::from_str(&text).map_err(|e| SimError::Config {
        path: shown.clone(),
        message: toml_message(&text, &e),
    })?;
    config.validate().map_err(|e| SimError::Config {
        path: shown,
        message: e.to_string(),
    })?;
    Ok(config)
}

/// A TOML error on one line: where, what, and the offending line with its table.
fn toml_message(text: &str, e: &toml::de::Error) -> String {
    let message = e.message().trim().replace('\n', "; ");
    let Some(at) = e.span().map(|s| s.start.min(text.len())) else {
        return message;
    };
    let before = text.get(..at).unwrap_or("");
    let line_no = before.matches('\n').count() + 1;
    let line = text.lines().nth(line_no - 1).unwrap_or("").trim();
    // The table the line belongs to: the nearest `[...]` header above it.
    let table = before
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| l.starts_with('['))
        .unwrap_or("top level");
    format!("line {line_no}: {message} (in {table}: `{line}`)")
}

/// What to run.
#[derive(Debug, Clone)]
pub struct BridgeRun<'a> {
    /// The bridge configuration (validated).
    pub config: Config,
    /// The controller-side capture.
    pub input: &'a Path,
    /// The head's status capture, if any.
    pub head_status: Option<&'a Path>,
    /// `--map ROLE=NAME` for both captures.
    pub map: &'a NameMap,
    /// Seed of the oversampling clocks' phases.
    pub seed: u64,
    /// HANS-100 controller input: the oversampling clock (37.5 or 50 MHz).
    pub hans_sample_hz: u32,
    /// Where the waveforms go (created if missing).
    pub output_dir: &'a Path,
}

/// What a run did.
#[derive(Debug, Clone)]
pub struct Report {
    /// The configuration it ran.
    pub config: Config,
    /// The bridge's counters.
    pub counters: Counters,
    /// The pipeline's own counts (slots, idle slots, status items).
    pub pipeline: PipelineCounters,
    /// Link state changes (the first is the power-up `Safe` at 0).
    pub states: Vec<Change<LinkState>>,
    /// Laser gate changes (the first is "off" at 0).
    pub gate: Vec<Change<bool>>,
    /// The bridge's alarms at the end (its own and the head's).
    pub alarms: Alarms,
    /// Frames written to the head.
    pub head_frames: usize,
    /// Simulated time, ns.
    pub end_ns: u64,
    /// A head-status capture was given.
    pub had_status: bool,
    /// The files written: path and signal names.
    pub files: Vec<(PathBuf, Vec<String>)>,
}

/// The controller-side buffers of one capture.
enum CtrlData {
    Xy2(Xy2Input),
    Xy3(Xy3Input),
    Hans(HansInput),
}

/// The head-side status buffers of one capture.
enum StatusData {
    /// XY2-100 STATUS level: the samples are in the chunks themselves.
    Level,
    /// XY2-100 status word: one port sample per output bit.
    Word(Vec<u16>),
    /// XY3-100 backchannel bytes.
    Back(Vec<u8>),
    /// HANS-100 STATUS `u16` ring words.
    Hans(Vec<u16>),
}

/// A capture read into buffers: the data, its chunks in time order (ns) and the
/// capture's end (ps).
struct Read<D> {
    data: D,
    steps: Vec<(u64, Step)>,
    end_ps: Ps,
}

/// One chunk of buffers, by index into the data above.
#[derive(Debug, Clone)]
enum Step {
    Xy2(Range<usize>),
    Xy3 {
        bytes: Range<usize>,
        end: Option<usize>,
    },
    Hans(Range<usize>),
    Level(bool),
    Word(Range<usize>),
    Back(usize),
    HansStatus(Range<usize>),
}

fn ns(ps: Ps) -> u64 {
    (ps + 500) / 1000
}

fn ns_f(ps: f64) -> u64 {
    (ps / 1000.0).round().max(0.0) as u64
}

fn pipeline_err(e: crate::pipeline::PipelineError) -> SimError {
    SimError::Bridge(e.to_string())
}

/// The XY2-100 controller's data lines the firmware's receiver takes (Z only when the
/// bridge takes Z from the input: an unwired Z line would fail every frame).
fn xy2_controller_lines(config: &Config) -> &'static [Axis] {
    if config.z.source == ZSource::Input {
        &[Axis::X, Axis::Y, Axis::Z]
    } else {
        &[Axis::X, Axis::Y]
    }
}

/// The HANS-100 channels a decode mode reads.
fn hans_channels(config: &Config) -> Vec<u8> {
    use shared::bridge::HansDecode;
    match config.controller.hans.decode {
        HansDecode::Normal(n) => vec![n],
        HansDecode::Vote3(c) => c.to_vec(),
        HansDecode::Vote5 | HansDecode::Super => (1..=5).collect(),
    }
}

/// Reads the controller-side capture; returns the buffers, their chunks and the
/// capture's end (ps).
fn controller_steps(run: &BridgeRun<'_>) -> Result<Read<CtrlData>, SimError> {
    let c = &run.config;
    let mut steps = Vec::new();
    match c.controller.protocol {
        Protocol::Xy2 => {
            let input = capture::xy2(run.input, run.map, Lines::Exactly(xy2_controller_lines(c)))?;
            let sync = 1u16 << input.pins.sync;
            let mut from = 0;
            for (i, w) in input.words.iter().enumerate() {
                // A frame ends at its SYNC-low sample; a line without frames (SYNC
                // stuck) is still handed over every 20 samples, as DMA halves would.
                if w & sync == 0 || i + 1 - from >= 20 {
                    let t = input.times.get(i).copied().unwrap_or(0);
                    steps.push((ns(t), Step::Xy2(from..i + 1)));
                    from = i + 1;
                }
            }
            if from < input.words.len() {
                let t = input.times.last().copied().unwrap_or(0);
                steps.push((ns(t), Step::Xy2(from..input.words.len())));
            }
            let end = input.times.last().copied().unwrap_or(0);
            Ok(Read {
                data: CtrlData::Xy2(input),
                steps,
                end_ps: end,
            })
        }
        Protocol::Xy3 => {
            // The lines the bridge's XY3-100 receiver takes (`controller.xy3.lines`).
            let axes: Vec<Axis> = c.xy3_input_lines().axes().collect();
            let input = capture::xy3(run.input, run.map, Lines::Exactly(&axes))?;
            let spi = &input.spi;
            let total = spi.bytes.first().map_or(0, Vec::len);
            let mut from = 0usize;
            for (k, (&end, &t)) in spi.frame_ends.iter().zip(&spi.end_times).enumerate() {
                let to = (end as usize).clamp(from, total);
                steps.push((
                    ns(t),
                    Step::Xy3 {
                        bytes: from..to,
                        end: Some(k),
                    },
                ));
                from = to;
            }
            let last_byte = spi.byte_times.last().map_or(0, |&(_, t)| t);
            if from < total {
                steps.push((
                    ns(last_byte),
                    Step::Xy3 {
                        bytes: from..total,
                        end: None,
                    },
                ));
            }
            let end = last_byte.max(spi.end_times.last().copied().unwrap_or(0));
            Ok(Read {
                data: CtrlData::Xy3(input),
                steps,
                end_ps: end,
            })
        }
        Protocol::Hans => {
            let input = capture::hans(
                run.input,
                run.map,
                &hans_channels(c),
                f64::from(run.hans_sample_hz),
                run.seed,
            )?;
            let (n, word_ps) = (input.words(), input.word_ps());
            let mut i = 0;
            while i < n {
                let to = (i + HANS_WORDS_PER_CHUNK).min(n);
                let t = input.start_ps + to as f64 * word_ps;
                steps.push((ns_f(t), Step::Hans(i..to)));
                i = to;
            }
            let end = input.capture_end_ps;
            Ok(Read {
                data: CtrlData::Hans(input),
                steps,
                end_ps: end,
            })
        }
    }
}

/// Reads the head-status capture; returns the buffers, their chunks and its end (ps).
/// `until_ps` bounds the level samples (a level line's last change says nothing about
/// how long it was watched); `out` gives the head output's bit timing.
fn status_steps(
    run: &BridgeRun<'_>,
    path: &Path,
    until_ps: Ps,
    out: &HeadOutput,
    options: &Options,
) -> Result<Read<StatusData>, SimError> {
    let c = &run.config;
    let rate = u64::from(c.output.frame_rate_hz.max(1));
    let mut steps = Vec::new();
    match (c.head.protocol, c.head.xy2.status) {
        (Protocol::Xy2, StatusForm::Level) => {
            let wave = capture::read_capture(path, &[roles::STATUS], &[names::STATUS], 1, run.map)?;
            let line = crate::line::signal(&wave, roles::STATUS)?;
            let period_ps = 1_000_000_000_000 / rate;
            let mut t = 0;
            while t <= until_ps {
                steps.push((ns(t), Step::Level(line.level_at(t))));
                t += period_ps;
            }
            Ok(Read {
                data: StatusData::Level,
                steps,
                end_ps: line.end_time(),
            })
        }
        (Protocol::Xy2, StatusForm::Word) => {
            let wave = capture::read_capture(path, &[roles::STATUS], &[names::STATUS], 1, run.map)?;
            let line = crate::line::signal(&wave, roles::STATUS)?;
            let HeadOutput::Wave { tick_ps, .. } = out else {
                return Err(SimError::Bridge(
                    "internal: an XY2-100 head without a BSRR output".to_owned(),
                ));
            };
            // One sample per output bit, counted from each frame period's start as
            // the firmware thins them (`tasks/head_word.rs`): bit j's is taken at
            // its sampling edge (CLK low, tick 2j + 1), `samples_per_period` per
            // period, so with an odd number of ticks (97.56 kHz: 41) the last one
            // falls after the idle tick and the next period starts afresh. Uniform
            // sampling every two ticks drifted half a bit per period there. Bit 0 of
            // the sample is STATUS.
            let ticks = (1e12 / rate as f64 / tick_ps).round().max(1.0) as usize;
            let per_frame = shared::xy2::status_line::samples_per_period(ticks);
            let period_ps = ticks as f64 * tick_ps;
            let sample_ps = |i: usize| {
                (i / per_frame) as f64 * period_ps + (2 * (i % per_frame) + 1) as f64 * tick_ps
            };
            // Samples whose tick ends by `until_ps`.
            let n = (0..)
                .take_while(|&i| sample_ps(i) + tick_ps <= until_ps as f64)
                .count();
            let samples: Vec<u16> = (0..n)
                .map(|i| u16::from(line.level_at(crate::line::ps(sample_ps(i)))))
                .collect();
            // One step per frame period, at its end (a last partial one at the end
            // of its last sample's tick).
            let mut i = 0;
            while i < n {
                let to = (i + per_frame).min(n);
                let end = if to - i == per_frame {
                    (to / per_frame) as f64 * period_ps
                } else {
                    sample_ps(to - 1) + tick_ps
                };
                steps.push((ns_f(end), Step::Word(i..to)));
                i = to;
            }
            Ok(Read {
                data: StatusData::Word(samples),
                steps,
                end_ps: line.end_time(),
            })
        }
        (Protocol::Xy3, _) => {
            let baud = f64::from(c.controller.xy3.back_rate.baud());
            let frames = capture::uart_line(path, run.map, roles::UART, names::BACK, baud)?;
            let bit_ps = 1e12 / baud;
            let mut bytes = Vec::with_capacity(frames.len());
            for (k, f) in frames.iter().enumerate() {
                // The UART has the byte after its stop bit (10 bit times from the start).
                steps.push((ns_f(f.time as f64 + 10.0 * bit_ps), Step::Back(k)));
                bytes.push(f.value);
            }
            let end = frames
                .last()
                .map_or(0, |f| crate::line::ps(f.time as f64 + 10.0 * bit_ps));
            Ok(Read {
                data: StatusData::Back(bytes),
                steps,
                end_ps: end,
            })
        }
        (Protocol::Hans, _) => {
            let wave = capture::read_capture(path, &[roles::STATUS], &[names::STATUS], 1, run.map)?;
            let fs = f64::from(options.hans_status_sample_hz);
            let (mut words, start_ps) = capture::oversample(&wave, &[roles::STATUS], fs, run.seed)?;
            let ring = words.pop().unwrap_or_default();
            let word_ps = 16.0 * 1e12 / fs;
            let mut i = 0;
            while i < ring.len() {
                let to = (i + HANS_WORDS_PER_CHUNK).min(ring.len());
                steps.push((
                    ns_f(start_ps + to as f64 * word_ps),
                    Step::HansStatus(i..to),
                ));
                i = to;
            }
            Ok(Read {
                data: StatusData::Hans(ring),
                steps,
                end_ps: wave.end_time(),
            })
        }
    }
}

/// Feeds one chunk.
fn feed(
    p: &mut Pipeline,
    t: u64,
    step: &Step,
    ctrl: &CtrlData,
    status: Option<&StatusData>,
) -> Result<(), SimError> {
    let r = match (step, ctrl, status) {
        (Step::Xy2(r), CtrlData::Xy2(d), _) => p.feed(
            t,
            ControllerInput::Xy2(d.words.get(r.clone()).unwrap_or(&[])),
        ),
        (Step::Xy3 { bytes, end }, CtrlData::Xy3(d), _) => {
            let lines: Vec<&[u8]> = d
                .spi
                .bytes
                .iter()
                .map(|l| l.get(bytes.clone()).unwrap_or(&[]))
                .collect();
            let ends = end.and_then(|k| d.spi.frame_ends.get(k..=k)).unwrap_or(&[]);
            p.feed(
                t,
                ControllerInput::Xy3 {
                    lines: &lines,
                    ends,
                },
            )
        }
        (Step::Hans(r), CtrlData::Hans(d), _) => {
            let mut chunks: [&[u16]; 5] = [&[]; 5];
            for (ch, ring) in &d.rings {
                if let Some(slot) = chunks.get_mut(usize::from(ch.saturating_sub(1))) {
                    *slot = ring.get(r.clone()).unwrap_or(&[]);
                }
            }
            p.feed(t, ControllerInput::Hans(chunks))
        }
        (Step::Level(l), _, Some(StatusData::Level)) => {
            p.feed_status(t, HeadStatusInput::Xy2Level(&[*l]))
        }
        (Step::Word(r), _, Some(StatusData::Word(s))) => {
            p.feed_status(t, HeadStatusInput::Xy2Word(s.get(r.clone()).unwrap_or(&[])))
        }
        (Step::Back(k), _, Some(StatusData::Back(b))) => {
            p.feed_status(t, HeadStatusInput::Xy3Back(b.get(*k..=*k).unwrap_or(&[])))
        }
        (Step::HansStatus(r), _, Some(StatusData::Hans(s))) => p.feed_status(
            t,
            HeadStatusInput::HansStatus(s.get(r.clone()).unwrap_or(&[])),
        ),
        _ => {
            return Err(SimError::Bridge(format!(
                "internal: chunk {step:?} does not match its buffers"
            )))
        }
    };
    r.map_err(pipeline_err)
}

/// Renames role-named signals to the default file names.
fn to_file_names(wave: &mut Waveform) {
    for s in wave.signals_mut() {
        let name = match s.name() {
            roles::CLK => names::CLK,
            roles::SYNC => names::SYNC,
            roles::X => names::XY3_DATA[0],
            roles::Y => names::XY3_DATA[1],
            roles::Z => names::XY3_DATA[2],
            roles::U => names::XY3_DATA[3],
            roles::W => names::XY3_DATA[4],
            roles::STATUS => names::STATUS,
            roles::UART => names::BACK,
            other => match roles::HANS_CHANNELS.iter().position(|c| *c == other) {
                Some(i) => names::HANS.get(i).copied().unwrap_or(names::HANS[0]),
                None => continue,
            },
        };
        s.set_name(name);
    }
}

/// Writes a waveform (signals renamed to the file names) and lists it in `files`.
fn write(
    dir: &Path,
    file: &str,
    mut wave: Waveform,
    files: &mut Vec<(PathBuf, Vec<String>)>,
) -> Result<(), SimError> {
    to_file_names(&mut wave);
    let path = dir.join(file);
    vcd_io::write_vcd_file(&path, &wave, WriteTimescale::Ps)?;
    files.push((path, wave.names()));
    Ok(())
}

/// Runs the bridge on the captures and writes the output directory.
pub fn run(run: &BridgeRun<'_>) -> Result<Report, SimError> {
    let options = Options {
        hans_sample_hz: run.hans_sample_hz,
        ..Options::default()
    };
    let mut p = Pipeline::new(&run.config, options).map_err(pipeline_err)?;
    let Read {
        data: ctrl,
        mut steps,
        end_ps: ctrl_end,
    } = controller_steps(run)?;
    let rate = u64::from(run.config.output.frame_rate_hz.max(1));
    let period_ps = 1_000_000_000_000 / rate;
    let mut end_ps = ctrl_end;
    let status = match run.head_status {
        Some(path) => {
            let r = status_steps(run, path, ctrl_end, &p.head_output(), p.options())?;
            steps.extend(r.steps);
            end_ps = end_ps.max(r.end_ps);
            Some(r.data)
        }
        None => None,
    };
    // Stable: at equal times the controller's chunk goes first.
    steps.sort_by_key(|(t, _)| *t);
    let mut progress = Progress::new("bridge", steps.len());
    for (i, (t, step)) in steps.iter().enumerate() {
        feed(&mut p, *t, step, &ctrl, status.as_ref())?;
        progress.tick(i + 1);
    }
    let mut end_ns = ns(end_ps.saturating_add(TAIL_SLOTS * period_ps));
    if run.config.controller.protocol == Protocol::Xy3 {
        // The XY3-100 step watch lets the last period out once no period followed
        // it for this long (`shared::xy3::step::CONFIRM_NS`): the stream stopped.
        end_ns = end_ns.saturating_add(shared::xy3::step::CONFIRM_NS);
    }
    p.run_until(end_ns);

    std::fs::create_dir_all(run.output_dir).map_err(|e| SimError::Io {
        path: run.output_dir.display().to_string(),
        message: e.to_string(),
    })?;
    if steps.len() >= Progress::MIN_ITEMS {
        eprintln!("bridge: writing {} ...", run.output_dir.display());
    }
    let mut files = Vec::new();
    let mut head = p.head_output().to_waveform()?;
    head.add(gate_signal(p.gate()))?;
    write(run.output_dir, HEAD_FILE, head, &mut files)?;
    let ctrl_status = controller_status_wave(&run.config, &p.controller_status(), &ctrl)?;
    write(run.output_dir, STATUS_FILE, ctrl_status, &mut files)?;
    Ok(Report {
        config: run.config,
        counters: *p.bridge_counters(),
        pipeline: *p.counters(),
        states: p.states().to_vec(),
        gate: p.gate().to_vec(),
        alarms: p.bridge().alarms().union(p.bridge().head_status().alarms),
        head_frames: p.sent().len(),
        end_ns,
        had_status: run.head_status.is_some(),
        files,
    })
}

/// The controller-side status line the bridge drives, as a waveform (`STATUS` or
/// `UART` role).
fn controller_status_wave(
    config: &Config,
    cs: &ControllerStatus,
    ctrl: &CtrlData,
) -> Result<Waveform, SimError> {
    let signal = match (
        config.controller.protocol,
        config.controller.xy2.status,
        ctrl,
    ) {
        (Protocol::Xy2, StatusForm::Word, CtrlData::Xy2(input)) => {
            status_word_signal(&cs.words, &input.times)
        }
        (Protocol::Xy2, ..) => cs.level_signal(),
        (Protocol::Xy3, ..) => cs.back_signal(),
        (Protocol::Hans, ..) => cs.hans_signal()?,
    };
    let mut wave = Waveform::new();
    wave.add(signal)?;
    Ok(wave)
}

/// XY2-100 status words towards the controller on its own clock: each word the
/// bridge had ready when a controller frame ended goes out MSB first during the
/// controller's next frame, each bit set up at the CLK rising edge before the falling
/// edge the controller samples it on (`sample_times`: the capture's CLK falling edges).
fn status_word_signal(words: &[(u64, u32)], sample_times: &[Ps]) -> Signal {
    let mut s = Signal::new(roles::STATUS, false);
    let mut last = 0;
    for &(t_ns, frame) in words {
        // The word was ready at the frame's last sample (`t_ns` is its time rounded
        // to the ns): it goes out from the sample after that.
        let first =
            sample_times.partition_point(|&t| t <= t_ns.saturating_mul(1000).saturating_add(500));
        for i in 0..20usize {
            let Some(&fall) = sample_times.get(first + i) else {
                return s;
            };
            let prev = (first + i)
                .checked_sub(1)
                .and_then(|k| sample_times.get(k))
                .copied()
                .unwrap_or(0);
            // The rising edge is half-way between two falling edges.
            let at = prev + (fall - prev) / 2;
            if at >= last {
                let _ = s.push(at, frame >> (19 - i) & 1 != 0);
                last = at;
            }
        }
    }
    s
}

/// The laser gate output as a signal.
fn gate_signal(changes: &[Change<bool>]) -> Signal {
    let mut s = Signal::new(names::LASER_GATE, false);
    for c in changes {
        // Changes come in time order; an equal time replaces the previous level.
        let _ = s.push(c.t_ns.saturating_mul(1000), c.value);
    }
    s
}

/// Alarm names as the README's status table calls them.
const ALARM_NAMES: [(Alarms, &str); 12] = [
    (Alarms::POWER, "power"),
    (Alarms::TEMPERATURE, "temperature"),
    (Alarms::POSITION_X, "position X"),
    (Alarms::POSITION_Y, "position Y"),
    (Alarms::POSITION_Z, "position Z"),
    (Alarms::COMMUNICATION, "communication"),
    (Alarms::LASER, "laser"),
    (Alarms::ELECTRICAL, "electrical"),
    (Alarms::MECHANICAL, "mechanical"),
    (Alarms::VENDOR, "vendor"),
    (Alarms::STATUS_LOST, "STATUS_LOST"),
    (Alarms::INPUT_LOST, "INPUT_LOST"),
];

/// The names of the alarms in `a`, or "none".
pub fn alarm_names(a: Alarms) -> String {
    let v: Vec<&str> = ALARM_NAMES
        .iter()
        .filter(|(f, _)| a.contains(*f))
        .map(|(_, n)| *n)
        .collect();
    if v.is_empty() {
        "none".to_owned()
    } else {
        v.join(", ")
    }
}

fn protocol_name(p: Protocol) -> &'static str {
    match p {
        Protocol::Xy2 => "XY2-100",
        Protocol::Xy3 => "XY3-100",
        Protocol::Hans => "HANS-100",
    }
}

/// A time in ms with three decimals (us resolution).
pub fn ms(t_ns: u64) -> String {
    format!("{:.3} ms", t_ns as f64 / 1e6)
}

/// The input lines whose counters are printed, with their names.
fn lines() -> Vec<(Line, String)> {
    let mut v: Vec<(Line, String)> = Axis::ALL
        .iter()
        .zip(names::XY3_DATA)
        .map(|(a, n)| (Line::Axis(*a), n.to_owned()))
        .collect();
    v.extend((1..=5).map(|c| (Line::HansChannel(c), format!("ch{c}"))));
    v.push((Line::Framing, "framing".to_owned()));
    v.push((Line::Status, "head status".to_owned()));
    v.push((Line::Backchannel, "backchannel".to_owned()));
    v
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = &self.counters;
        let cfg = &self.config;
        writeln!(
            f,
            "bridge {} controller -> {} head, {} output at {} Hz, {} simulated",
            protocol_name(cfg.controller.protocol),
            protocol_name(cfg.head.protocol),
            match cfg.output.timing {
                shared::bridge::Timing::FreeRunning => "free-running",
                shared::bridge::Timing::Slaved => "slaved",
            },
            cfg.output.frame_rate_hz,
            ms(self.end_ns)
        )?;
        let sum = |g: fn(&shared::bridge::LineCounters) -> u64| -> u64 {
            lines()
                .iter()
                .map(|(l, _)| g(&c.line(*l)))
                .fold(0u64, u64::saturating_add)
        };
        writeln!(
            f,
            "  frames ok {} (not forwarded while the link was not running: {}), frames sent to the head {}",
            c.frames_ok, c.not_forwarded, self.head_frames
        )?;
        writeln!(
            f,
            "  check failures {}, framing {}, resyncs {}, dropped {}, missing {}, disagreeing channels {}",
            sum(|l| l.check_failed),
            sum(|l| l.framing),
            sum(|l| l.resyncs),
            sum(|l| l.dropped),
            sum(|l| l.missing),
            sum(|l| l.disagree)
        )?;
        for (line, name) in lines() {
            let l = c.line(line);
            if l.total() > 0 {
                writeln!(
                    f,
                    "    {name}: check failures {}, framing {}, resyncs {}, dropped {}, missing {}, disagree {}",
                    l.check_failed, l.framing, l.resyncs, l.dropped, l.missing, l.disagree
                )?;
            }
        }
        writeln!(
            f,
            "  repeated {}, skipped {}, commands not carried {} (forwarded {}), laser control not carried {}",
            c.repeated, c.skipped, c.commands_not_carried, c.commands_forwarded, c.laser_not_carried
        )?;
        writeln!(
            f,
            "  input losses {}, recoveries {}, head status losses {}; alarms at the end: {}",
            c.input_losses,
            c.recoveries,
            c.status_losses,
            alarm_names(self.alarms)
        )?;
        let states: Vec<String> = self
            .states
            .iter()
            .map(|s| format!("{:?} at {}", s.value, ms(s.t_ns)))
            .collect();
        writeln!(f, "  link: {}", states.join(", "))?;
        let gate: Vec<String> = self
            .gate
            .iter()
            .map(|g| format!("{} at {}", if g.value { "on" } else { "off" }, ms(g.t_ns)))
            .collect();
        writeln!(f, "  laser gate: {}", gate.join(", "))?;
        if self.had_status {
            writeln!(
                f,
                "  head status received: {} items, {} faults",
                self.pipeline.status_items, self.pipeline.status_faults
            )?;
        } else if cfg.failsafe.status_timeout_us > 0 {
            writeln!(
                f,
                "  no --head-status: the head's status counts as missing (laser gate off with \
                 laser.off_on_head_alarm, STATUS_LOST after failsafe.status_timeout_us = {} us; \
                 0 turns the supervision off)",
                cfg.failsafe.status_timeout_us
            )?;
        }
        for (path, signals) in &self.files {
            writeln!(f, "  wrote {} ({})", path.display(), signals.join(" "))?;
        }
        Ok(())
    }
}
