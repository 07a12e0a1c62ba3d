//! The no-argument demo: an XY2-100 controller draws a circle, bridged to a HANS-100
//! head that reports a healthy status; halfway the controller's X line breaks (an
//! open RS-422 line reads high). It shows the fail-safe from the outside: every
//! frame from the break on fails its check and none reaches the head; the head keeps
//! the last good position; after `failsafe.input_timeout_us` (1 ms) the link is lost
//! (laser gate off, fault on the controller's STATUS line); after `hold_us` (10 ms)
//! the head is parked at the centre.
//!
//! Everything goes through the same code as `generate` (the controller's capture),
//! `bridge` (the run) and `decode` (what the head got): the directory it writes
//! ([`DEMO_DIR`]) can be replayed with the `bridge` command and the config written
//! there.

use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};

use shared::bridge::{Config, Protocol};
use shared::hans::{DeviceExt, GalvoAlarms, GalvoStatus, ZAlarms};
use shared::model::Position;

use super::bridge::{self, ms, Report};
use super::decode::{self, HansMode};
use super::encode::{self, ForwardTiming};
use super::generate::{self, GenOptions, Pattern};
use super::jsonl::{Channel, HansRecord};
use super::{names, Protocol as Link, SimError};
use crate::vcd_io::{self, NameMap, WriteTimescale};
use crate::wave::Waveform;

/// Where the demo writes (relative to the working directory).
pub const DEMO_DIR: &str = "bridge-sim-demo";
/// Controller frames: 30 ms at 100 kHz.
pub const FRAMES: usize = 3000;
/// When the controller's X line breaks, us (halfway).
pub const BREAK_US: u64 = 15_000;
/// The controller's capture in the demo directory.
pub const CONTROLLER_FILE: &str = "controller.vcd";
/// The head's status capture in the demo directory.
pub const HEAD_STATUS_FILE: &str = "head-status.vcd";
/// The configuration in the demo directory.
pub const CONFIG_FILE: &str = "bridge.toml";

/// The demo's bridge: the defaults (XY2-100 16-bit controller, 1 ms input timeout,
/// 10 ms hold, park at the centre, 100 recovery frames) with a HANS-100 head.
pub fn config() -> Config {
    let mut c = Config::default();
    c.controller.protocol = Protocol::Xy2;
    c.head.protocol = Protocol::Hans;
    c
}

/// A run of head frames of one kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Positions the controller sent (resized to the head's 20 bits), in order.
    Forwarded,
    /// The previous frame again.
    Repeated,
    /// The park position.
    Parked,
    /// Anything else (never expected: the test fails on it).
    Other,
}

/// Consecutive head frames of one kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Phase {
    /// The kind.
    pub kind: Kind,
    /// First frame's start, ns.
    pub from_ns: u64,
    /// Last frame's start, ns.
    pub to_ns: u64,
    /// Frames in the run.
    pub frames: usize,
    /// Forwarded runs: the controller frames (0-based) of the first and last one.
    pub controller: Option<(usize, usize)>,
}

/// What the demo did.
#[derive(Debug, Clone)]
pub struct DemoReport {
    /// The bridge run.
    pub bridge: Report,
    /// What the head received, decoded from the head-side file.
    pub phases: Vec<Phase>,
    /// Frames the decoder rejected in the head-side file (never expected).
    pub head_errors: usize,
    /// The controller's STATUS line the bridge drove: `(ns, high)` changes, the first
    /// at 0.
    pub status_line: Vec<(u64, bool)>,
    /// The directory.
    pub dir: PathBuf,
}

/// A healthy galvo: no alarm, no warning (the reserved bit at its normal level).
pub const HEALTHY: GalvoAlarms = GalvoAlarms::NONE;

/// A HANS-100 head's STATUS line (signal `status`): back-to-back frames alternating
/// the actual position (code 64, the centre) and velocities with `alarms` (code 65),
/// DATA3 the Z velocity with no alarm (code 15), from 1 us for `frames` frames.
pub fn hans_head_status(frames: usize, alarms: GalvoAlarms) -> Result<Waveform, SimError> {
    let bad = |e: &dyn fmt::Display| SimError::BadOption {
        option: "demo",
        message: format!("internal status frame: {e}"),
    };
    let position = GalvoStatus::Position {
        x: 0x8000,
        y: 0x8000,
    };
    let velocity = GalvoStatus::Velocity { x: 0, y: 0, alarms };
    let z = DeviceExt::ZVelocity {
        velocity: 0,
        alarms: ZAlarms::default(),
    }
    .to_data3()
    .map_err(|e| bad(&e))?;
    let mut records = Vec::with_capacity(frames);
    for i in 0..frames {
        let g = if i % 2 == 0 { position } else { velocity };
        let (d1, d2) = g.to_words().map_err(|e| bad(&e))?;
        records.push((
            i + 1,
            HansRecord::Frame {
                t_ns: None,
                data: [d1, d2, z],
            },
        ));
    }
    let enc = encode::hans(&records, 1000.0)?;
    let mut wave = Waveform::new();
    if let Some(s) = enc.wave.get(names::HANS[0]) {
        let mut s = s.clone();
        s.set_name(names::STATUS);
        wave.add(s)?;
    }
    Ok(wave)
}

fn io(path: &Path, e: std::io::Error) -> SimError {
    SimError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Runs the demo in `dir`.
pub fn run(dir: &Path) -> Result<DemoReport, SimError> {
    std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    let config = config();
    let toml_text = toml::to_string(&config).map_err(|e| SimError::Config {
        path: CONFIG_FILE.to_owned(),
        message: e.to_string(),
    })?;
    let config_path = dir.join(CONFIG_FILE);
    std::fs::write(
        &config_path,
        format!(
            "# bridge-sim demo: XY2-100 controller -> HANS-100 head (every key; see the\n\
             # repository's bridge.toml for what each one means).\n{toml_text}"
        ),
    )
    .map_err(|e| io(&config_path, e))?;

    // The controller: a circle, X line open from BREAK_US on.
    let opts = GenOptions {
        pattern: Pattern::Circle,
        frames: FRAMES,
        seed: 1,
        xy2_mode: config.controller.xy2.mode,
        xy3_size: shared::xy3::FrameSize::Bits24,
        command_every: 0,
        baud: 115_200.0,
    };
    let records = generate::forward_records(Link::Xy2, &opts);
    let xy2_link = shared::xy2::LinkConfig {
        mode: config.controller.xy2.mode,
        parity: config.controller.xy2.parity,
    };
    let timing = ForwardTiming {
        bit_rate_hz: 2e6,
        frame_period_ns: None,
        start_ns: 1000.0,
    };
    let mut enc = encode::forward(Link::Xy2, &records, &xy2_link, &timing)?;
    crate::impair::stuck_at(
        &mut enc.wave,
        names::XY2_DATA[0],
        BREAK_US * 1_000_000,
        true,
    )?;
    let input = dir.join(CONTROLLER_FILE);
    vcd_io::write_vcd_file(&input, &enc.wave, WriteTimescale::Ps)?;
    let status = dir.join(HEAD_STATUS_FILE);
    vcd_io::write_vcd_file(
        &status,
        &hans_head_status(FRAMES, HEALTHY)?,
        WriteTimescale::Ps,
    )?;

    let map = NameMap::new();
    let report = bridge::run(&bridge::BridgeRun {
        config,
        input: &input,
        head_status: Some(&status),
        map: &map,
        seed: 1,
        hans_sample_hz: 37_500_000,
        output_dir: dir,
    })?;

    // What the head got, through `decode` like any capture.
    let (head, _) = decode::hans(&dir.join(bridge::HEAD_FILE), &map, HansMode::Super, 4, 1)?;
    let mut expected: HashMap<(u32, u32), usize> = HashMap::new();
    for (k, (_, r)) in records.iter().enumerate() {
        if let (Some(x), Some(y)) = (head_pos(r.channel("x")), head_pos(r.channel("y"))) {
            expected.entry((x, y)).or_insert(k);
        }
    }
    let park = (config.failsafe.park_x, config.failsafe.park_y);
    let (phases, head_errors) = phases(&head, &expected, park);

    let status_wave = vcd_io::read_vcd_file(
        &dir.join(bridge::STATUS_FILE),
        &[names::STATUS],
        &NameMap::new(),
    )?;
    let status_line = status_wave
        .get(names::STATUS)
        .map(|s| {
            std::iter::once((0, s.initial()))
                .chain(s.changes().iter().map(|&(t, l)| ((t + 500) / 1000, l)))
                .collect()
        })
        .unwrap_or_default();
    Ok(DemoReport {
        bridge: report,
        phases,
        head_errors,
        status_line,
        dir: dir.to_owned(),
    })
}

/// A 16-bit controller position as the HANS-100 head's 20-bit word (the model's
/// widening rule).
fn head_pos(ch: Option<&Channel>) -> Option<u32> {
    match ch {
        Some(Channel::Pos { pos, bits }) => {
            Position::from_raw(*pos, *bits).ok().map(|p| p.to_raw(20))
        }
        _ => None,
    }
}

/// Groups the decoded head frames into runs of one kind; counts rejected frames.
fn phases(
    head: &[HansRecord],
    expected: &HashMap<(u32, u32), usize>,
    park: (u32, u32),
) -> (Vec<Phase>, usize) {
    let mut out: Vec<Phase> = Vec::new();
    let mut errors = 0;
    let mut prev: Option<(u32, u32)> = None;
    for r in head {
        let (t, xy) = match r {
            HansRecord::Frame {
                t_ns,
                data: [x, y, _],
            } => (t_ns.unwrap_or(0), (*x, *y)),
            HansRecord::Error { .. } => {
                errors += 1;
                continue;
            }
        };
        let (kind, k) = if prev == Some(xy) {
            (Kind::Repeated, None)
        } else if xy == park {
            (Kind::Parked, None)
        } else {
            match expected.get(&xy) {
                Some(&k) => (Kind::Forwarded, Some(k)),
                None => (Kind::Other, None),
            }
        };
        // A park position repeated is still parking.
        let kind = match (kind, out.last()) {
            (Kind::Repeated, Some(p)) if p.kind == Kind::Parked => Kind::Parked,
            _ => kind,
        };
        prev = Some(xy);
        match out.last_mut() {
            Some(p) if p.kind == kind => {
                p.to_ns = t;
                p.frames += 1;
                if let (Some((a, _)), Some(k)) = (p.controller, k) {
                    p.controller = Some((a, k));
                }
            }
            _ => out.push(Phase {
                kind,
                from_ns: t,
                to_ns: t,
                frames: 1,
                controller: k.map(|k| (k, k)),
            }),
        }
    }
    (out, errors)
}

impl fmt::Display for DemoReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let dir = self.dir.display();
        writeln!(
            f,
            "bridge-sim demo: an XY2-100 controller draws a circle ({FRAMES} frames at 100 kHz) \
             through the bridge to a HANS-100 head;\nthe controller's X line breaks (open, \
             reads high) at {}.\n",
            ms(BREAK_US * 1000)
        )?;
        write!(f, "{}", self.bridge)?;
        writeln!(
            f,
            "\nWhat the head received (decoded from {dir}/{}):",
            bridge::HEAD_FILE
        )?;
        for p in &self.phases {
            let what = match (p.kind, p.controller) {
                (Kind::Forwarded, Some((a, b))) => format!(
                    "the controller's positions, frames {} .. {} of the circle",
                    a + 1,
                    b + 1
                ),
                (Kind::Forwarded, None) => "the controller's positions".to_owned(),
                (Kind::Repeated, _) => {
                    "the last position again (nothing valid to forward)".to_owned()
                }
                (Kind::Parked, _) => "the park position (centre)".to_owned(),
                (Kind::Other, _) => "UNEXPECTED positions".to_owned(),
            };
            writeln!(
                f,
                "  {} .. {}: {:>5} frames: {what}",
                ms(p.from_ns),
                ms(p.to_ns),
                p.frames
            )?;
        }
        if self.head_errors > 0 {
            writeln!(
                f,
                "  {} frames failed their check (UNEXPECTED)",
                self.head_errors
            )?;
        }
        let status: Vec<String> = self
            .status_line
            .iter()
            .map(|&(t, high)| {
                format!(
                    "{} from {}",
                    if high { "high = fault" } else { "low = OK" },
                    ms(t)
                )
            })
            .collect();
        writeln!(
            f,
            "The controller's STATUS line (level, low = OK): {}",
            status.join(", ")
        )?;
        writeln!(
            f,
            "\nFiles in {dir}/: {CONTROLLER_FILE} (the controller's lines), {HEAD_STATUS_FILE} \
             (the head's STATUS), {CONFIG_FILE},\n  {} (head lines ch1..ch5 and laser_gate), {} \
             (the STATUS line to the controller).",
            bridge::HEAD_FILE,
            bridge::STATUS_FILE
        )?;
        writeln!(
            f,
            "Open them in PulseView or GTKWave, or replay and decode:\n  cargo sim bridge \
             --config {dir}/{CONFIG_FILE} --input {dir}/{CONTROLLER_FILE} --head-status \
             {dir}/{HEAD_STATUS_FILE} --output-dir out\n  cargo sim decode --protocol hans \
             --input {dir}/{}",
            bridge::HEAD_FILE
        )
    }
}
