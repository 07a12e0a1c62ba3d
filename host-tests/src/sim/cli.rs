//! The `bridge-sim` command line and its commands (see the README, section "bridge-sim").
//!
//! Exit codes: 0 success, 1 error (bad input, I/O), 2 usage (clap).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand, ValueEnum};
use shared::{xy2, xy3};

use super::decode::{self, HansMode, Summary};
use super::encode::{self, Encoded, ForwardTiming};
use super::generate::{self, GenOptions, ImpairOpts, Pattern};
use super::jsonl::{self, BackRecord, ForwardRecord, HansRecord};
use super::{bridge, capture, demo};
use super::{names, Protocol, SimError};
use crate::vcd_io::{self, NameMap, WriteTimescale};

/// bridge-sim: the bridge's `shared` code on waveforms — decode logic-analyser captures
/// (VCD), encode and generate test signals, run the whole bridge on a capture.
#[derive(Debug, Parser)]
#[command(name = "bridge-sim", version, about, long_about = None)]
pub struct Cli {
    /// The command; without one, the demo runs.
    #[command(subcommand)]
    pub command: Option<Cmd>,
}

/// The commands.
#[derive(Debug, Subcommand)]
pub enum Cmd {
    /// Decode a capture: JSON lines on stdout, a summary on stderr.
    Decode(DecodeArgs),
    /// JSON-lines frames -> a VCD waveform.
    Encode(EncodeArgs),
    /// A test pattern -> a VCD waveform (with optional impairments).
    Generate(GenerateArgs),
    /// The whole bridge on a controller-side capture.
    Bridge(BridgeArgs),
}

/// XY2-100 frame width.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Xy2ModeArg {
    /// 16-bit positions and enhanced commands (XY2-100).
    #[value(name = "16")]
    Bits16,
    /// 18-bit positions (XY2-100E).
    #[value(name = "18")]
    Bits18,
}

/// XY2-100 parity scope.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ParityArg {
    /// All 20 bits.
    Whole,
    /// Data bits only.
    Data,
    /// Not checked (encode: whole-frame parity).
    Ignore,
}

/// XY3-100 frame size for `generate`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Xy3BitsArg {
    /// 24-bit frames (20-bit positions).
    #[value(name = "24")]
    Bits24,
    /// 32-bit frames (26-bit positions).
    #[value(name = "32")]
    Bits32,
}

/// Link options shared by the commands.
#[derive(Debug, Clone, Args)]
pub struct LinkArgs {
    /// The link.
    #[arg(long, value_enum)]
    pub protocol: Protocol,
    /// XY2-100 frame width.
    #[arg(long, value_enum, default_value = "16")]
    pub xy2_mode: Xy2ModeArg,
    /// XY2-100 parity scope.
    #[arg(long, value_enum, default_value = "whole")]
    pub parity: ParityArg,
    /// Backchannel baud rate.
    #[arg(long, default_value_t = 115_200)]
    pub baud: u32,
    /// File signal NAME for ROLE (ROLE = a default name: clk, sync, x, .., ch1, back);
    /// repeatable.
    #[arg(long = "map", value_name = "ROLE=NAME")]
    pub map: Vec<String>,
    /// Seed for everything random (impairments, patterns, sampling phase).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

impl LinkArgs {
    fn xy2_config(&self) -> xy2::LinkConfig {
        xy2::LinkConfig {
            mode: match self.xy2_mode {
                Xy2ModeArg::Bits16 => xy2::Mode::Standard16,
                Xy2ModeArg::Bits18 => xy2::Mode::Extended18,
            },
            parity: match self.parity {
                ParityArg::Whole => xy2::Parity::WholeFrame,
                ParityArg::Data => xy2::Parity::DataOnly,
                ParityArg::Ignore => xy2::Parity::Ignore,
            },
        }
    }

    fn name_map(&self) -> Result<NameMap, SimError> {
        let mut m = NameMap::new();
        for a in &self.map {
            m.parse_arg(a)?;
        }
        Ok(m)
    }
}

/// `decode` options.
#[derive(Debug, Clone, Args)]
pub struct DecodeArgs {
    /// Link options.
    #[command(flatten)]
    pub link: LinkArgs,
    /// The capture.
    #[arg(long, value_name = "FILE.vcd")]
    pub input: PathBuf,
    /// HANS-100 decode mode: normal:N (channel N only), vote3, vote5 or super.
    #[arg(long, default_value = "super")]
    pub hans_mode: HansMode,
    /// HANS-100 oversampling ratio (sampling clock = ratio x 12.5 MHz).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u8).range(3..=4))]
    pub hans_oversample: u8,
}

/// Waveform output options shared by `encode` and `generate`.
#[derive(Debug, Clone, Args)]
pub struct WaveArgs {
    /// The VCD file to write.
    #[arg(long, value_name = "FILE.vcd")]
    pub output: PathBuf,
    /// XY2-100 / XY3-100 bit clock in Hz [default: XY2 2e6; XY3 2.4e6 (24-bit), 3.2e6
    /// (32-bit)].
    #[arg(long, value_name = "HZ")]
    pub bit_rate: Option<f64>,
    /// XY2-100 / XY3-100 frame period in ns [default: back to back; XY3-100 with one
    /// idle bit].
    #[arg(long, value_name = "NS")]
    pub frame_period_ns: Option<f64>,
    /// Line impairments.
    #[command(flatten)]
    pub impair: ImpairOpts,
}

/// `encode` options.
#[derive(Debug, Clone, Args)]
pub struct EncodeArgs {
    /// Link options.
    #[command(flatten)]
    pub link: LinkArgs,
    /// The JSON-lines frames.
    #[arg(long, value_name = "FILE.jsonl")]
    pub frames: PathBuf,
    /// Output and impairments.
    #[command(flatten)]
    pub wave: WaveArgs,
}

/// `generate` options.
#[derive(Debug, Clone, Args)]
pub struct GenerateArgs {
    /// Link options.
    #[command(flatten)]
    pub link: LinkArgs,
    /// The pattern.
    #[arg(long, value_enum, default_value = "circle")]
    pub pattern: Pattern,
    /// Number of frames (backchannel: status packets).
    #[arg(long, default_value_t = 1000)]
    pub frames: usize,
    /// XY3-100 frame size.
    #[arg(long, value_enum, default_value = "24")]
    pub xy3_bits: Xy3BitsArg,
    /// Every N-th frame carries a command on X (0: none; not in XY2-100E).
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub command_every: usize,
    /// Also write the generated frames as JSON lines (the decoder's expected output).
    #[arg(long, value_name = "FILE.jsonl")]
    pub frames_out: Option<PathBuf>,
    /// Output and impairments.
    #[command(flatten)]
    pub wave: WaveArgs,
}

/// `bridge` options.
#[derive(Debug, Clone, Args)]
pub struct BridgeArgs {
    /// Bridge configuration (the firmware's file format: every key optional).
    #[arg(long, value_name = "bridge.toml")]
    pub config: PathBuf,
    /// Controller-side capture (signals named as for `decode` of the controller's
    /// protocol).
    #[arg(long, value_name = "FILE.vcd")]
    pub input: PathBuf,
    /// Where the waveforms go (created if missing): head.vcd, controller-status.vcd.
    #[arg(long, value_name = "DIR")]
    pub output_dir: PathBuf,
    /// The head's status capture: `status` (XY2-100 level or word, HANS-100 STATUS)
    /// or `back` (XY3-100 backchannel).
    #[arg(long, value_name = "FILE.vcd")]
    pub head_status: Option<PathBuf>,
    /// File signal NAME for ROLE in both captures; repeatable.
    #[arg(long = "map", value_name = "ROLE=NAME")]
    pub map: Vec<String>,
    /// Seed of the HANS-100 oversampling clocks' phases.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// HANS-100 controller input: oversampling ratio (sampling clock = ratio x 12.5
    /// MHz).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u8).range(3..=4))]
    pub hans_oversample: u8,
}

/// Parses the arguments, runs the command, prints any error as one line.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(&cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("bridge-sim: error: {e}");
            ExitCode::from(1)
        }
    }
}

/// Runs one parsed command line.
pub fn run(cli: &Cli) -> Result<(), SimError> {
    match &cli.command {
        Some(Cmd::Decode(a)) => run_decode(a),
        Some(Cmd::Encode(a)) => run_encode(a),
        Some(Cmd::Generate(a)) => run_generate(a),
        Some(Cmd::Bridge(a)) => run_bridge(a),
        None => {
            let report = demo::run(Path::new(demo::DEMO_DIR))?;
            print!("{report}");
            Ok(())
        }
    }
}

fn run_bridge(a: &BridgeArgs) -> Result<(), SimError> {
    let mut map = NameMap::new();
    for m in &a.map {
        map.parse_arg(m)?;
    }
    let run = bridge::BridgeRun {
        config: bridge::load_config(&a.config)?,
        input: &a.input,
        head_status: a.head_status.as_deref(),
        map: &map,
        seed: a.seed,
        hans_sample_hz: 12_500_000 * u32::from(a.hans_oversample),
        output_dir: &a.output_dir,
    };
    let report = bridge::run(&run)?;
    eprint!("{report}");
    Ok(())
}

fn read_text(path: &Path) -> Result<String, SimError> {
    std::fs::read_to_string(path).map_err(|e| SimError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    })
}

fn io_err(path: &str, e: std::io::Error) -> SimError {
    SimError::Io {
        path: path.to_owned(),
        message: e.to_string(),
    }
}

/// Writes records as JSON lines to `out`.
fn write_lines<T: serde::Serialize>(
    out: impl Write,
    what: &str,
    records: &[T],
) -> Result<(), SimError> {
    let mut out = std::io::BufWriter::new(out);
    for r in records {
        writeln!(out, "{}", jsonl::to_line(r)).map_err(|e| io_err(what, e))?;
    }
    out.flush().map_err(|e| io_err(what, e))
}

fn run_decode(a: &DecodeArgs) -> Result<(), SimError> {
    let map = a.link.name_map()?;
    let stdout = std::io::stdout().lock();
    let summary: Summary = match a.link.protocol {
        Protocol::Xy2 => {
            let (records, s) = decode::xy2(&a.input, &map, &a.link.xy2_config())?;
            write_lines(stdout, "stdout", &records)?;
            s
        }
        Protocol::Xy3 => {
            let (records, s) = decode::xy3(&a.input, &map)?;
            write_lines(stdout, "stdout", &records)?;
            s
        }
        Protocol::Hans => {
            let (records, s) =
                decode::hans(&a.input, &map, a.hans_mode, a.hans_oversample, a.link.seed)?;
            write_lines(stdout, "stdout", &records)?;
            s
        }
        Protocol::Xy3Back => {
            let frames = capture::uart_line(
                &a.input,
                &map,
                names::BACK,
                names::BACK,
                f64::from(a.link.baud),
            )?;
            let (records, s) = decode::back(frames);
            write_lines(stdout, "stdout", &records)?;
            s
        }
    };
    eprintln!("decode {}: {summary}", a.link.protocol);
    Ok(())
}

/// Forward timing from the options and the frame size.
fn forward_timing(protocol: Protocol, w: &WaveArgs, xy3_32: bool) -> ForwardTiming {
    let default_rate = match (protocol, xy3_32) {
        (Protocol::Xy2, _) => 2e6,
        (_, false) => 2.4e6,
        (_, true) => 3.2e6,
    };
    ForwardTiming {
        bit_rate_hz: w.bit_rate.unwrap_or(default_rate),
        frame_period_ns: w.frame_period_ns,
        start_ns: 1000.0,
    }
}

/// Impairs, renames per `--map` and writes the waveform.
fn finish(link: &LinkArgs, w: &WaveArgs, mut enc: Encoded) -> Result<Encoded, SimError> {
    w.impair.apply(&mut enc.wave, link.seed)?;
    let map = link.name_map()?;
    for s in enc.wave.signals_mut() {
        let to = map.resolve(s.name()).to_owned();
        s.set_name(to);
    }
    if enc.starts_ns.len() >= encode::Progress::MIN_ITEMS {
        eprintln!("writing {} ...", w.output.display());
    }
    vcd_io::write_vcd_file(&w.output, &enc.wave, WriteTimescale::Ps)?;
    Ok(enc)
}

fn run_encode(a: &EncodeArgs) -> Result<(), SimError> {
    let text = read_text(&a.frames)?;
    let enc = match a.link.protocol {
        p @ (Protocol::Xy2 | Protocol::Xy3) => {
            let records: Vec<(usize, ForwardRecord)> = jsonl::parse(&text)?;
            let is32 = records.first().is_some_and(|(_, r)| {
                ["x", "y", "z", "u", "w"].iter().any(|l| {
                    matches!(
                        r.channel(l),
                        Some(jsonl::Channel::Pos { bits: 26, .. })
                            | Some(jsonl::Channel::Cmd {
                                frame_bits: Some(32),
                                ..
                            })
                    )
                })
            });
            encode::forward(
                p,
                &records,
                &a.link.xy2_config(),
                &forward_timing(p, &a.wave, is32),
            )?
        }
        Protocol::Hans => encode::hans(&jsonl::parse::<HansRecord>(&text)?, 1000.0)?,
        Protocol::Xy3Back => encode::back(
            &jsonl::parse::<BackRecord>(&text)?,
            f64::from(a.link.baud),
            1000.0,
        )?,
    };
    let enc = finish(&a.link, &a.wave, enc)?;
    eprintln!(
        "encode {}: {} frames -> {}",
        a.link.protocol,
        enc.starts_ns.len(),
        a.wave.output.display()
    );
    Ok(())
}

fn run_generate(a: &GenerateArgs) -> Result<(), SimError> {
    let config = a.link.xy2_config();
    let opts = GenOptions {
        pattern: a.pattern,
        frames: a.frames,
        seed: a.link.seed,
        xy2_mode: config.mode,
        xy3_size: match a.xy3_bits {
            Xy3BitsArg::Bits24 => xy3::FrameSize::Bits24,
            Xy3BitsArg::Bits32 => xy3::FrameSize::Bits32,
        },
        command_every: a.command_every,
        baud: f64::from(a.link.baud),
    };
    if a.frames == 0 {
        return Err(SimError::BadOption {
            option: "--frames",
            message: "at least one frame".to_owned(),
        });
    }
    let p = a.link.protocol;
    let (enc, lines): (Encoded, Vec<String>) = match p {
        Protocol::Xy2 | Protocol::Xy3 => {
            let mut records = generate::forward_records(p, &opts);
            let timing = forward_timing(p, &a.wave, a.xy3_bits == Xy3BitsArg::Bits32);
            let enc = encode::forward(p, &records, &config, &timing)?;
            for ((_, r), t) in records.iter_mut().zip(&enc.starts_ns) {
                r.t_ns = Some(*t);
            }
            (
                enc,
                records.iter().map(|(_, r)| jsonl::to_line(r)).collect(),
            )
        }
        Protocol::Hans => {
            let mut records = generate::hans_records(&opts)?;
            let enc = encode::hans(&records, 1000.0)?;
            for ((_, r), t) in records.iter_mut().zip(&enc.starts_ns) {
                if let HansRecord::Frame { t_ns, .. } = r {
                    *t_ns = Some(*t);
                }
            }
            (
                enc,
                records.iter().map(|(_, r)| jsonl::to_line(r)).collect(),
            )
        }
        Protocol::Xy3Back => {
            let mut records = generate::back_records(&opts)?;
            let enc = encode::back(&records, opts.baud, 1000.0)?;
            for ((_, r), t) in records.iter_mut().zip(&enc.starts_ns) {
                if let BackRecord::Packet { t_ns, .. } = r {
                    *t_ns = Some(*t);
                }
            }
            (
                enc,
                records.iter().map(|(_, r)| jsonl::to_line(r)).collect(),
            )
        }
    };
    let enc = finish(&a.link, &a.wave, enc)?;
    if let Some(path) = &a.frames_out {
        let mut text = lines.join("\n");
        text.push('\n');
        std::fs::write(path, text).map_err(|e| io_err(&path.display().to_string(), e))?;
    }
    eprintln!(
        "generate {p}: {} frames, {} signals -> {}",
        enc.starts_ns.len(),
        enc.wave.signals().len(),
        a.wave.output.display()
    );
    Ok(())
}
