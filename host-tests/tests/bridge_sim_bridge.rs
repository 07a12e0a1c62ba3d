//! `bridge-sim bridge` and the demo, through the built binary: generated controller
//! captures for several pairings go through the whole bridge; the head-side file is
//! decoded back with `decode` and compared with what `generate` says it sent (resized
//! with the model's rule, axis-mapped by hand), never with the bridge's own record.
//! Plus the status path (a head status capture -> the controller's status line), bad
//! input, and the demo.

use std::path::{Path, PathBuf};

mod common;

use common::{ok_in, records, run_in, Out};
use host_tests::sim::demo::{hans_head_status, HEALTHY};
use host_tests::sim::jsonl::{self, BackRecord, Channel, ForwardRecord, HansRecord};
use host_tests::vcd_io::{read_vcd_file, write_vcd_file, NameMap, WriteTimescale};
use host_tests::wave::{Signal, Waveform};
use shared::hans::GalvoAlarms;
use shared::model::Position;
use shared::xy2;

fn dir(test: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("bridge_sim_bridge_{test}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `generate` in `d`; returns the frames sent.
fn generate(d: &Path, name: &str, args: &[&str]) -> Vec<String> {
    let (_, text) = common::generate(d, name, args);
    text.lines().map(str::to_owned).collect()
}

/// `generate` of `frames` frames of `pattern` on `protocol`; returns the frames sent.
fn generate_pattern(
    d: &Path,
    name: &str,
    protocol: &str,
    pattern: &str,
    frames: &str,
) -> Vec<String> {
    let args = [
        "--protocol",
        protocol,
        "--pattern",
        pattern,
        "--frames",
        frames,
    ];
    generate(d, name, &args)
}

/// The controller's `status` line the bridge wrote (`out/controller-status.vcd`).
fn controller_status(d: &Path) -> Signal {
    let path = d.join("out/controller-status.vcd");
    let wave = read_vcd_file(&path, &["status"], &NameMap::new()).unwrap();
    wave.get("status").unwrap().clone()
}

fn bridge(d: &Path, config: &str, input: &str, extra: &[&str]) -> Out {
    std::fs::write(d.join("bridge.toml"), config).unwrap();
    let mut a = vec![
        "bridge",
        "--config",
        "bridge.toml",
        "--input",
        input,
        "--output-dir",
        "out",
    ];
    a.extend_from_slice(extra);
    ok_in(d, &a)
}

/// [`bridge`], then `decode` of its output file `out/{file}` with `args` (`--protocol`
/// and its options): the bridge's and `decode`'s output.
fn bridge_and_decode(
    d: &Path,
    config: &str,
    input: &str,
    extra: &[&str],
    file: &str,
    args: &[&str],
) -> (Out, Out) {
    let o = bridge(d, config, input, extra);
    let path = format!("out/{file}");
    let mut a = vec!["decode"];
    a.extend_from_slice(args);
    a.extend(["--input", path.as_str()]);
    (o, ok_in(d, &a))
}

/// The bridge's printout lists its output file `out/{file}` with the signals `names`
/// (as documented).
fn assert_listed(o: &Out, file: &str, names: &str) {
    let listed = format!("out/{file} ({names})");
    assert!(o.stderr.contains(&listed), "no `{listed}` in {}", o.stderr);
}

/// The bridge's printout reports the head's `alarm` at the end of the run and a laser
/// gate that never opened.
fn assert_alarm_keeps_gate_off(o: &Out, alarm: &str) {
    let alarm = format!("alarms at the end: {alarm}");
    for want in [alarm.as_str(), "laser gate: off at 0.000 ms\n"] {
        assert!(o.stderr.contains(want), "no `{want}` in {}", o.stderr);
    }
}

/// The time in ms right after `prefix` in the bridge's printout.
fn ms_after(stderr: &str, prefix: &str) -> f64 {
    let at = stderr
        .find(prefix)
        .unwrap_or_else(|| panic!("no `{prefix}` in {stderr}"));
    stderr[at + prefix.len()..]
        .split(" ms")
        .next()
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no time after `{prefix}` in {stderr}"))
}

/// A counter from the bridge's printout (`name N`).
fn counter(stderr: &str, name: &str) -> u64 {
    let at = stderr
        .find(&format!("{name} "))
        .unwrap_or_else(|| panic!("no `{name}` in {stderr}"));
    stderr[at + name.len() + 1..]
        .split(|c: char| !c.is_ascii_digit())
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

/// An X/Y position of a generated or decoded forward / HANS record, as a position.
fn xy_forward(r: &ForwardRecord) -> Option<(Position, Position)> {
    let p = |l: &str| match r.channel(l) {
        Some(Channel::Pos { pos, bits }) => Position::from_raw(*pos, *bits).ok(),
        _ => None,
    };
    Some((p("x")?, p("y")?))
}

/// [`bridge_and_decode`] of the head-side file as `head` (xy2 / xy3 / hans) with
/// `bits`-bit positions: the bridge's output, X/Y as head-width raw values, and the
/// number of error records.
fn bridge_to_head(
    d: &Path,
    config: &str,
    input: &str,
    extra: &[&str],
    head: &str,
    bits: u8,
) -> (Out, Vec<(u32, u32)>, usize) {
    let mut args = vec!["--protocol", head];
    if head == "xy2" && bits == 18 {
        args.extend(["--xy2-mode", "18"]);
    }
    let (bridged, o) = bridge_and_decode(d, config, input, extra, "head.vcd", &args);
    let mut pos = Vec::new();
    let mut errors = 0;
    if head == "hans" {
        let mut records = jsonl::parse::<HansRecord>(&o.stdout).unwrap();
        // The capture's last frame has no successor whose start edge confirms the
        // receiver's timing (`shared::hans::rx`), so it ends as a check failure:
        // not an error of the bridge's output.
        if matches!(records.last(), Some((_, HansRecord::Error { .. }))) {
            records.pop();
        }
        for (_, r) in records {
            match r {
                HansRecord::Frame { data, .. } => pos.push((data[0], data[1])),
                HansRecord::Error { .. } => errors += 1,
            }
        }
    } else {
        for (_, r) in jsonl::parse::<ForwardRecord>(&o.stdout).unwrap() {
            match xy_forward(&r) {
                Some((x, y)) => {
                    assert_eq!(x.bits(), bits);
                    pos.push((x.to_raw(bits), y.to_raw(bits)));
                }
                None => errors += 1,
            }
        }
    }
    (bridged, pos, errors)
}

/// What a head-side file must show.
struct Expect {
    /// The head's position width.
    bits: u8,
    /// `axes.swap_xy`.
    swap: bool,
    /// Frames of the streams the receivers need to lock (HANS-100 in or out: about
    /// two each plus [`HANS_YOUNG`]).
    skip: usize,
    /// The bridge's `repeated` counter.
    repeated: u64,
}

/// The periods of a young HANS-100 lock, verified but not published until
/// `timing::SETTLED` start edges are measured (`shared::hans::rx`).
const HANS_YOUNG: usize = shared::hans::rx::timing::SETTLED as usize - 2;

/// Frames the head may stop short of the last one sent (the tail of the run).
const TAIL: usize = 3;

/// The head must show exactly the controller's frames from the `RECOVERY`-th on,
/// resized (and swapped), in order, each at least once (a repeat is the previous
/// frame again), ending within the last [`TAIL`] frames.
fn check_forwarded(sent: &[(Position, Position)], got: &[(u32, u32)], e: &Expect) {
    let (bits, swap, recovery, skip_head, tail, repeated) =
        (e.bits, e.swap, RECOVERY, e.skip, TAIL, e.repeated);
    let want: Vec<(u32, u32)> = sent
        .iter()
        .map(|(x, y)| {
            let (x, y) = if swap { (y, x) } else { (x, y) };
            (x.to_raw(bits), y.to_raw(bits))
        })
        .collect();
    let first = want
        .iter()
        .position(|w| Some(w) == got.first())
        .unwrap_or_else(|| panic!("first head frame {:?} was never sent", got.first()));
    assert!(
        first + 1 >= recovery && first < recovery + skip_head,
        "first forwarded frame is controller frame {} (recovery {recovery})",
        first + 1
    );
    let mut k = first;
    let mut repeats = 0u64;
    for (i, g) in got.iter().enumerate().skip(1) {
        if *g == want[k] {
            repeats += 1;
            continue;
        }
        k += 1;
        assert_eq!(*g, want[k], "head frame {i}: not the next controller frame");
    }
    assert!(
        k + tail >= want.len(),
        "head stops at frame {k} of {}",
        want.len()
    );
    // Every repeat the head shows was counted by the bridge (the bridge may repeat
    // a few more at the end, after the last frame the decoder could close).
    assert!(
        repeats <= repeated,
        "{repeats} repeats seen, {repeated} counted"
    );
}

fn sent_positions(lines: &[String]) -> Vec<(Position, Position)> {
    lines
        .iter()
        .map(|l| {
            let r: ForwardRecord = serde_json::from_str(l).unwrap();
            xy_forward(&r).unwrap()
        })
        .collect()
}

fn sent_hans(lines: &[String]) -> Vec<(Position, Position)> {
    lines
        .iter()
        .map(|l| match serde_json::from_str::<HansRecord>(l).unwrap() {
            HansRecord::Frame { data, .. } => (
                Position::from_raw(data[0], 20).unwrap(),
                Position::from_raw(data[1], 20).unwrap(),
            ),
            HansRecord::Error { .. } => panic!("generate made an error frame"),
        })
        .collect()
}

const RECOVERY: usize = 10;

/// The X/Y positions `generate` sent.
type Sent = [(Position, Position)];

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn config(controller: &str, head: &str, extra: &str) -> String {
    format!(
        "[controller]\nprotocol = \"{controller}\"\n[head]\nprotocol = \"{head}\"\n\
         [failsafe]\nrecovery_frames = {RECOVERY}\nstatus_timeout_us = 0\n{extra}"
    )
}

#[test]
fn xy2_to_xy3_and_hans_heads() {
    let d = dir("xy2");
    let sent = sent_positions(&generate_pattern(&d, "in", "xy2", "circle", "300"));
    for (head, bits, skip, extra) in [
        ("xy3", 20, 1, ""),
        ("xy3", 26, 1, "[head.xy3]\nframe_bits = 32\n"),
        ("hans", 20, 3 + HANS_YOUNG, ""),
        // Slaved: one output frame per input frame, never a repeat.
        ("xy3", 20, 1, "[output]\ntiming = \"slaved\"\n"),
    ] {
        let cfg = config("xy2", head, extra);
        let (o, got, errors) = bridge_to_head(&d, &cfg, "in.vcd", &[], head, bits);
        assert_eq!(counter(&o.stderr, "frames ok"), 300, "{}", o.stderr);
        assert_eq!(counter(&o.stderr, "check failures"), 0);
        assert!(o.stderr.contains("link: Safe at 0.000 ms, Running at"));
        assert_eq!(errors, 0, "{head}");
        let e = Expect {
            bits,
            swap: false,
            skip,
            repeated: counter(&o.stderr, "repeated"),
        };
        check_forwarded(&sent, &got, &e);
        // The head-side file names its signals as documented.
        let names = if head == "hans" {
            "ch1 ch2 ch3 ch4 ch5 laser_gate"
        } else {
            "clk sync x y z laser_gate"
        };
        assert_listed(&o, "head.vcd", names);
    }
}

#[test]
fn xy3_and_hans_controllers_with_axis_map() {
    let d = dir("xy3_hans");
    // XY3-100 (24-bit, 2.4 MHz: 96 kHz frames) -> XY2-100 16-bit: narrowing, the
    // output faster than the input (repeats), X and Y swapped.
    let sent = sent_positions(&generate_pattern(&d, "xy3", "xy3", "random", "300"));
    let cfg = config("xy3", "xy2", "[axes]\nswap_xy = true\n");
    let (o, got, errors) = bridge_to_head(&d, &cfg, "xy3.vcd", &[], "xy2", 16);
    assert_eq!(counter(&o.stderr, "frames ok"), 300, "{}", o.stderr);
    let repeated = counter(&o.stderr, "repeated");
    assert!(
        repeated >= 5,
        "a 96 kHz input into 100 kHz slots repeats: {repeated}"
    );
    assert_eq!(errors, 0);
    let e = Expect {
        bits: 16,
        swap: true,
        skip: 1,
        repeated,
    };
    check_forwarded(&sent, &got, &e);

    // HANS-100 (super mode) -> XY3-100 32-bit: widening 20 -> 26 bits.
    let sent = sent_hans(&generate_pattern(&d, "hans", "hans", "raster", "300"));
    let cfg = config(
        "hans",
        "xy3",
        "[controller.hans]\ndecode = \"super\"\n[head.xy3]\nframe_bits = 32\n",
    );
    let oversample = ["--hans-oversample", "4"];
    let (o, got, errors) = bridge_to_head(&d, &cfg, "hans.vcd", &oversample, "xy3", 26);
    // The HANS-100 receiver needs about two frames to lock, then publishes after
    // its young lock's periods.
    assert!(
        counter(&o.stderr, "frames ok") >= 297 - HANS_YOUNG as u64,
        "{}",
        o.stderr
    );
    assert_eq!(errors, 0);
    let e = Expect {
        bits: 26,
        swap: false,
        skip: 3 + HANS_YOUNG,
        repeated: counter(&o.stderr, "repeated"),
    };
    check_forwarded(&sent, &got, &e);
}

#[test]
fn the_other_pairings() {
    let d = dir("others");
    let xy3 = sent_positions(&generate_pattern(&d, "xy3", "xy3", "random", "300"));
    let hans = sent_hans(&generate_pattern(&d, "hans", "hans", "random", "300"));
    // (controller, capture, frames sent, head, head bits, extra keys, frames the
    // receivers need to lock: HANS-100 in and out take about two each, plus
    // HANS_YOUNG).
    let cases: [(&str, &str, &Sent, &str, u8, &str, usize); 5] = [
        (
            "xy3",
            "xy3.vcd",
            &xy3,
            "xy3",
            26,
            "[head.xy3]\nframe_bits = 32\n",
            1,
        ),
        ("xy3", "xy3.vcd", &xy3, "hans", 20, "", 3 + HANS_YOUNG),
        // U and W received too (`generate` drives them at the centre).
        (
            "xy3",
            "xy3.vcd",
            &xy3,
            "xy3",
            20,
            "[controller.xy3]\nlines = [\"x\", \"y\", \"z\", \"u\", \"w\"]\n",
            1,
        ),
        (
            "hans",
            "hans.vcd",
            &hans,
            "xy2",
            18,
            "[head.xy2]\nmode = \"extended18\"\nenhanced_commands = false\n",
            3 + HANS_YOUNG,
        ),
        (
            "hans",
            "hans.vcd",
            &hans,
            "hans",
            20,
            "",
            6 + 2 * HANS_YOUNG,
        ),
    ];
    for (ctrl, input, sent, head, bits, extra, skip) in cases {
        let cfg = config(ctrl, head, extra);
        let (o, got, errors) = bridge_to_head(&d, &cfg, input, &[], head, bits);
        let young = if ctrl == "hans" { HANS_YOUNG as u64 } else { 0 };
        assert!(
            counter(&o.stderr, "frames ok") >= 298 - young,
            "{}",
            o.stderr
        );
        assert_eq!(counter(&o.stderr, "check failures"), 0, "{}", o.stderr);
        assert_eq!(errors, 0, "{ctrl} -> {head}");
        // Each HANS-100 receiver (bridge input, head decode) publishes after its
        // young lock's periods.
        let young_head = if head == "hans" { HANS_YOUNG } else { 0 };
        let least = 280 - young as usize - young_head;
        assert!(got.len() >= least, "{ctrl} -> {head}: {} frames", got.len());
        let e = Expect {
            bits,
            swap: false,
            skip,
            repeated: counter(&o.stderr, "repeated"),
        };
        check_forwarded(sent, &got, &e);
    }
    // The head's U and W pairs are driven then: `head.vcd` has them, and the head
    // decodes them in every frame (`generate` sends them at the centre; the pipeline
    // tests check moving values).
    let five = "[controller.xy3]\nlines = [\"x\", \"y\", \"z\", \"u\", \"w\"]\n";
    let xy3_head = ["--protocol", "xy3"];
    let cfg = config("xy3", "xy3", five);
    let (_, o) = bridge_and_decode(&d, &cfg, "xy3.vcd", &[], "head.vcd", &xy3_head);
    let records = jsonl::parse::<ForwardRecord>(&o.stdout).unwrap();
    assert!(records.len() >= 280, "{} records", records.len());
    for (_, r) in &records {
        for line in ["u", "w"] {
            match r.channel(line) {
                Some(Channel::Pos { pos, bits: 20 }) => assert_eq!(*pos, 0x8_0000),
                other => panic!("{line}: {other:?} in {r:?}"),
            }
        }
    }
    // Without U / W from the controller the head's pairs 7 / 8 stay undriven.
    let cfg = config("xy3", "xy3", "");
    let (_, o) = bridge_and_decode(&d, &cfg, "xy3.vcd", &[], "head.vcd", &xy3_head);
    for (_, r) in jsonl::parse::<ForwardRecord>(&o.stdout).unwrap() {
        assert!(
            r.channel("u").is_none() && r.channel("w").is_none(),
            "{r:?}"
        );
    }
    // The configured lines are the ones read: U renamed to a signal the capture does
    // not have is an error only once U is listed (and the head can carry it).
    let u_gone = ["--map", "u=no_such_signal"];
    let lines = "[controller.xy3]\nlines = [\"x\", \"y\", \"z\", \"u\"]\n";
    bridge(&d, &config("xy3", "xy3", ""), "xy3.vcd", &u_gone);
    bridge(&d, &config("xy3", "hans", lines), "xy3.vcd", &u_gone);
    std::fs::write(d.join("bridge.toml"), config("xy3", "xy3", lines)).unwrap();
    let o = run_in(
        &d,
        &[
            "bridge",
            "--config",
            "bridge.toml",
            "--input",
            "xy3.vcd",
            "--output-dir",
            "out_u",
            u_gone[0],
            u_gone[1],
        ],
    );
    assert_eq!(o.code, 1, "{}", o.stderr);
    assert!(o.stderr.contains("no_such_signal"), "{}", o.stderr);
}

/// `fixtures/xy2_capture_10ns.vcd` (a logic analyser's conventions: 10 ns timescale,
/// signals D0..D3, other signals, the clock stopping between two frames, no Z) through
/// an XY2-100 -> XY2-100 bridge: the position, then the enhanced command passed on
/// X (a one-off: the next slots hold X's last position), each slot as expected.
#[test]
fn capture_from_another_tool_through_the_bridge() {
    let d = dir("fixture");
    let vcd = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/xy2_capture_10ns.vcd");
    let cfg = "[controller]\nprotocol = \"xy2\"\n[head]\nprotocol = \"xy2\"\n\
               [z]\nsource = \"none\"\n[failsafe]\nrecovery_frames = 1\n";
    let map = [
        "--map", "clk=D0", "--map", "sync=D1", "--map", "x=D2", "--map", "y=D3",
    ];
    let input = vcd.to_str().unwrap();
    let xy2_head = ["--protocol", "xy2"];
    let (o, dec) = bridge_and_decode(&d, cfg, input, &map, "head.vcd", &xy2_head);
    assert_eq!(counter(&o.stderr, "frames ok"), 2, "{}", o.stderr);
    assert_eq!(counter(&o.stderr, "(forwarded"), 1, "{}", o.stderr);
    assert_listed(&o, "head.vcd", "clk sync x y laser_gate");
    let want = concat!(
        r#"{"t_ns":30000,"x":{"pos":0,"bits":16},"y":{"pos":32768,"bits":16}}"#,
        "\n",
        r#"{"t_ns":40000,"x":{"cmd":4660},"y":{"pos":65535,"bits":16}}"#,
        "\n",
        r#"{"t_ns":50000,"x":{"pos":0,"bits":16},"y":{"pos":65535,"bits":16}}"#,
        "\n",
        r#"{"t_ns":60000,"x":{"pos":0,"bits":16},"y":{"pos":65535,"bits":16}}"#,
        "\n",
    );
    assert_eq!(dec.stdout, want);
}

#[test]
fn broken_line_is_never_forwarded_then_hold_and_park() {
    let d = dir("broken");
    // 3000 XY2-100 frames (30 ms); Y opens at 10 ms: every frame from then on fails.
    let sent = sent_positions(&generate(
        &d,
        "in",
        &[
            "--protocol",
            "xy2",
            "--pattern",
            "random",
            "--frames",
            "3000",
            "--broken",
            "y,10000",
        ],
    ));
    let cfg = config("xy2", "xy3", "");
    let (o, got, errors) = bridge_to_head(&d, &cfg, "in.vcd", &[], "xy3", 20);
    assert!(counter(&o.stderr, "check failures") >= 1999, "{}", o.stderr);
    assert_eq!(counter(&o.stderr, "input losses"), 1);
    // Lost 1 ms after the last good frame, parked 10 ms later.
    assert!(
        o.stderr.contains("Holding at 11.000 ms, Safe at 21.000 ms"),
        "{}",
        o.stderr
    );
    assert!(o.stderr.contains("laser gate: off at 0.000 ms, on at"));
    assert!(o.stderr.contains("off at 11.000 ms"), "{}", o.stderr);
    assert_eq!(errors, 0);
    let want: Vec<(u32, u32)> = sent
        .iter()
        .map(|(x, y)| (x.to_raw(20), y.to_raw(20)))
        .collect();
    let valid = &want[..999];
    let park = (0x8_0000, 0x8_0000);
    let last_valid = *got.iter().rfind(|g| valid.contains(g)).unwrap();
    let mut parked = 0;
    for g in &got {
        // Never anything but a valid controller frame or the park position.
        assert!(valid.contains(g) || *g == park, "{g:?} was never sent");
        parked += usize::from(*g == park);
    }
    // The head holds the last valid position, then parks for the last ~9 ms.
    assert_eq!(last_valid, *valid.last().unwrap());
    assert!((880..=920).contains(&parked), "{parked} park frames");
    assert_eq!(got.last(), Some(&park));
}

#[test]
fn head_status_reaches_the_controller() {
    let d = dir("status");
    generate_pattern(&d, "in", "xy2", "circle", "400");
    // A healthy HANS-100 head: the controller's STATUS (level, low = OK) goes OK once
    // the link runs, and the gate opens.
    let status = d.join("status.vcd");
    write_vcd_file(
        &status,
        &hans_head_status(400, HEALTHY).unwrap(),
        WriteTimescale::Ps,
    )
    .unwrap();
    // The link runs after 10 frames (0.11 ms), before the head's first status: the
    // STATUS words are taken in 512-word halves as the firmware takes them, so
    // nothing of the head is known before the first half ends (205 us at 40 MHz).
    // The gate waits for that status (with `off_on_head_alarm` and the watchdog on).
    let cfg = "[controller]\nprotocol = \"xy2\"\n[head]\nprotocol = \"hans\"\n\
               [failsafe]\nrecovery_frames = 10\n";
    let o = bridge(&d, cfg, "in.vcd", &["--head-status", "status.vcd"]);
    let running = ms_after(&o.stderr, "link: Safe at 0.000 ms, Running at ");
    let gate_on = ms_after(&o.stderr, "laser gate: off at 0.000 ms, on at ");
    assert!((0.10..0.12).contains(&running), "{}", o.stderr);
    assert!(gate_on >= 0.205 && gate_on > running, "{}", o.stderr);
    // The STATUS words are taken in whole 512-word halves, as the firmware does:
    // 400 frames are 19.5 halves at 40 MHz, the 19 whole ones hold 389 frames,
    // less the acquisition's first ~8 (measured: 381 items).
    assert!(
        counter(&o.stderr, "head status received:") >= 378,
        "{}",
        o.stderr
    );
    assert_eq!(counter(&o.stderr, "head status losses"), 0);
    let s = controller_status(&d);
    assert!(s.initial(), "fault (high) before the link runs");
    assert!(!s.level_at(3_000_000_000), "OK at 3 ms");

    // The same head with a power alarm: the controller sees a fault all along and
    // the gate never opens (laser.off_on_head_alarm), not even in the 0.1 ms the
    // link runs before the first status is in.
    let alarm = GalvoAlarms {
        power: true,
        ..HEALTHY
    };
    write_vcd_file(
        &status,
        &hans_head_status(400, alarm).unwrap(),
        WriteTimescale::Ps,
    )
    .unwrap();
    let o = bridge(&d, cfg, "in.vcd", &["--head-status", "status.vcd"]);
    assert_alarm_keeps_gate_off(&o, "power");
    let running = ms_after(&o.stderr, "link: Safe at 0.000 ms, Running at ");
    assert!((0.10..0.12).contains(&running), "{}", o.stderr);
    assert!(controller_status(&d).level_at(3_000_000_000));

    // No status capture: STATUS_LOST once status_timeout_us has passed, and the
    // gate never opened.
    let cfg_short = format!("{cfg}status_timeout_us = 1000\n");
    let o = bridge(&d, &cfg_short, "in.vcd", &[]);
    assert_eq!(counter(&o.stderr, "head status losses"), 1, "{}", o.stderr);
    assert!(o.stderr.contains("STATUS_LOST"), "{}", o.stderr);
    assert!(
        o.stderr.contains("laser gate: off at 0.000 ms\n"),
        "{}",
        o.stderr
    );
}

/// An XY2-100 head's STATUS line sending `word` in every output frame period of a
/// head at `rate` Hz, as a head answers on the bridge's clock: bit k changes at the
/// start of output tick 2k + 2 of its period (after bit k's CLK falling edge, tick
/// 2k + 1, where the bridge read bit k - 1), so the bridge, sampling one per bit
/// from the period's start (`tasks/head_word.rs`), finds the frame's first bit in
/// sample 1 of the period; with an odd number of ticks per period (41 at 97.56 kHz)
/// bit 19 changes on the idle tick.
fn xy2_status_word_line(word: xy2::StatusWord, periods: usize, rate: u32) -> Waveform {
    let frame = word.to_frame(&xy2::LinkConfig::default());
    let ticks = shared::head_port::XY2_TICK_HZ / rate;
    let tick_ps = 1e12 / f64::from(rate) / f64::from(ticks);
    let mut s = Signal::new("status", false);
    for p in 0..periods {
        for i in 0..20u32 {
            let tick = p as f64 * f64::from(ticks) + f64::from(2 * i + 2);
            s.push((tick * tick_ps).round() as u64, frame >> (19 - i) & 1 != 0)
                .unwrap();
        }
    }
    let mut w = Waveform::new();
    w.add(s).unwrap();
    w
}

/// The status words on the controller's `status` line, read at the controller's
/// own CLK falling edges, one per controller frame (20 samples ending in SYNC low).
fn xy2_status_words_at_controller(d: &Path) -> Vec<Result<xy2::StatusWord, xy2::StatusError>> {
    let ctrl = read_vcd_file(&d.join("in.vcd"), &["clk", "sync"], &NameMap::new()).unwrap();
    let line = controller_status(d);
    let sync = ctrl.get("sync").unwrap();
    let mut words = Vec::new();
    let (mut acc, mut n) = (0u32, 0);
    for t in ctrl.get("clk").unwrap().falling_edges() {
        acc = (acc << 1 | u32::from(line.level_at(t))) & 0xF_FFFF;
        n += 1;
        if !sync.level_at(t) {
            if n == 20 {
                words.push(xy2::StatusWord::from_frame(
                    acc,
                    &xy2::LinkConfig::default(),
                ));
            }
            n = 0;
        }
    }
    words
}

/// The head's STATUS word at 100 kHz (40 output ticks per frame period, 20
/// samples) and at 97.56 kHz (41 ticks: 20 bits and an idle tick, 21 samples, as
/// the firmware's `head_word` thins them; before, bridge-sim sampled every two
/// ticks across the periods and drifted half a bit a period there, so no word
/// passed), from a 100 kHz controller.
#[test]
fn xy2_status_words_both_ways() {
    let d = dir("xy2_word");
    generate_pattern(&d, "in", "xy2", "circle", "400");
    // The head reports an over-temperature in every word.
    let hot = xy2::StatusWord {
        temperature_ok: false,
        ..xy2::StatusWord::ALL_OK
    };
    for rate in [100_000u32, 97_560] {
        write_vcd_file(
            &d.join("status.vcd"),
            &xy2_status_word_line(hot, 400, rate),
            WriteTimescale::Ps,
        )
        .unwrap();
        let cfg = config(
            "xy2",
            "xy2",
            &format!(
                "[controller.xy2]\nstatus = \"word\"\n[head.xy2]\nstatus = \"word\"\n\
                 [output]\nframe_rate_hz = {rate}\n"
            ),
        );
        let o = bridge(&d, &cfg, "in.vcd", &["--head-status", "status.vcd"]);
        // A word from every head period of the 4 ms input, less a few at its ends
        // (390 of 400 at 100 kHz), none failing its check.
        let want = 390 * u64::from(rate) / 100_000;
        assert!(
            counter(&o.stderr, "head status received:") >= want,
            "{rate} Hz: {}",
            o.stderr
        );
        assert_eq!(counter(&o.stderr, "items,"), 0, "{rate} Hz: {}", o.stderr);
        assert_alarm_keeps_gate_off(&o, "temperature");
        // The controller reads a valid status word in every frame after the first:
        // INPUT_LOST (power bit cleared) until the link runs, then the head's
        // over-temperature.
        let words = xy2_status_words_at_controller(&d);
        assert_eq!(words.len(), 400);
        let words: Vec<xy2::StatusWord> = words[1..].iter().map(|w| w.unwrap()).collect();
        assert!(!words[0].power_ok);
        let running = words.iter().position(|w| w.power_ok).unwrap();
        assert!(
            (8..=12).contains(&running),
            "{rate} Hz: running from frame {running}"
        );
        for w in &words[running..] {
            assert_eq!(*w, hot, "{rate} Hz");
        }
    }
}

/// The `laser gate:` timeline of the printout as (on, ms) pairs.
fn gate_changes(stderr: &str) -> Vec<(bool, f64)> {
    let line = stderr
        .lines()
        .find_map(|l| l.trim().strip_prefix("laser gate: "))
        .unwrap();
    line.split(", ")
        .map(|c| {
            let (state, t) = c.split_once(" at ").unwrap();
            (state == "on", t.trim_end_matches(" ms").parse().unwrap())
        })
        .collect()
}

#[test]
fn xy3_head_backchannel_alarm_turns_the_gate_off() {
    let d = dir("back");
    generate_pattern(&d, "in", "xy2", "circle", "2000");
    // The head's backchannel as `generate` makes it: a cycle of status packets whose
    // ERROR_STATE reports nothing at first, then an error code.
    let packets: Vec<(u64, u8, Vec<u8>)> =
        generate(&d, "back", &["--protocol", "xy3-back", "--frames", "10"])
            .iter()
            .map(|l| match serde_json::from_str::<BackRecord>(l).unwrap() {
                BackRecord::Packet { t_ns, ty, payload } => (t_ns.unwrap(), ty, payload),
                BackRecord::Error { .. } => panic!("generate made an error"),
            })
            .collect();
    let (t_err, _, payload) = packets
        .iter()
        .find(|(_, ty, p)| *ty == 7 && p.iter().any(|&b| b != 0))
        .unwrap();
    // The packet is complete after its 3 + N bytes at 115200 baud.
    let done_ms = (*t_err as f64 + (3 + payload.len()) as f64 * 10.0 / 115_200.0 * 1e9) / 1e6;
    let o = bridge(
        &d,
        &config("xy2", "xy3", "[laser]\noff_on_head_alarm = true\n"),
        "in.vcd",
        &["--head-status", "back.vcd"],
    );
    assert_eq!(
        counter(&o.stderr, "head status received:"),
        packets.len() as u64,
        "{}",
        o.stderr
    );
    let gate = gate_changes(&o.stderr);
    assert_eq!(gate.len(), 3, "{}", o.stderr);
    assert!(gate[1].0 && !gate[2].0);
    assert!(
        gate[2].1 >= done_ms - 0.01 && gate[2].1 <= done_ms + 0.1,
        "gate off at {} ms, the alarm arrived at {done_ms} ms",
        gate[2].1
    );
    // The controller's STATUS level shows the fault from then on.
    let s = controller_status(&d);
    assert!(!s.level_at(((done_ms - 0.2) * 1e9) as u64));
    assert!(s.level_at(((done_ms + 0.2) * 1e9) as u64));
}

#[test]
fn controller_status_files_decode() {
    let d = dir("ctrl_status");
    // An XY3-100 controller gets the backchannel, which the `decode` backchannel
    // parser takes without a single error: SYNC first, then the error state: DSP
    // data error (code 2) while the link is not running, cleared once it runs.
    generate_pattern(&d, "xy3", "xy3", "steps", "300");
    let (file, cfg) = ("controller-status.vcd", config("xy3", "xy2", ""));
    let back = ["--protocol", "xy3-back"];
    let (o, dec) = bridge_and_decode(&d, &cfg, "xy3.vcd", &[], file, &back);
    assert_listed(&o, file, "back");
    let packets: Vec<(u8, String)> = jsonl::parse::<BackRecord>(&dec.stdout)
        .unwrap()
        .into_iter()
        .map(|(_, p)| match p {
            BackRecord::Packet { ty, payload, .. } => (ty, hex(&payload)),
            BackRecord::Error { error, .. } => panic!("backchannel error: {error}"),
        })
        .collect();
    assert_eq!(packets.first(), Some(&(0x41, String::new())), "{packets:?}");
    let lost = packets.iter().position(|p| *p == (7, "0002".to_owned()));
    let clear = packets.iter().position(|p| *p == (7, "00".to_owned()));
    assert!(
        matches!((lost, clear), (Some(a), Some(b)) if a < b),
        "{packets:?}"
    );

    // A HANS-100 controller gets STATUS frames on `status`: decoded as channel 1.
    generate_pattern(&d, "hans", "hans", "circle", "200");
    let cfg = config("hans", "xy3", "");
    let ch1 = [
        "--protocol",
        "hans",
        "--hans-mode",
        "normal:1",
        "--map",
        "ch1=status",
    ];
    let (o, dec) = bridge_and_decode(&d, &cfg, "hans.vcd", &[], file, &ch1);
    assert_listed(&o, file, "status");
    let frames = jsonl::parse::<HansRecord>(&dec.stdout).unwrap();
    assert!(frames.len() >= 150, "{}", dec.stderr);
    assert!(frames
        .iter()
        .all(|(_, f)| matches!(f, HansRecord::Frame { .. })));
}

#[test]
fn bad_input_fails_cleanly() {
    let d = dir("bad");
    generate(&d, "xy2", &["--protocol", "xy2", "--frames", "50"]);
    generate(&d, "hans", &["--protocol", "hans", "--frames", "20"]);
    let good = std::fs::read_to_string(d.join("xy2.vcd")).unwrap();
    let header_end = good.find("$enddefinitions").unwrap();
    std::fs::write(d.join("cut.vcd"), &good[..header_end]).unwrap();
    std::fs::write(d.join("junk.vcd"), b"\x00\xff$$ not a capture").unwrap();
    let check = |config: &str, input: &str, extra: &[&str], want: &str| {
        std::fs::write(d.join("b.toml"), config).unwrap();
        let mut a = vec![
            "bridge",
            "--config",
            "b.toml",
            "--input",
            input,
            "--output-dir",
            "bad_out",
        ];
        a.extend_from_slice(extra);
        let o = run_in(&d, &a);
        assert_eq!(o.code, 1, "{a:?}: {}", o.stderr);
        assert!(o.stderr.starts_with("bridge-sim: error: "), "{}", o.stderr);
        assert!(o.stderr.contains(want), "{config} {a:?}: {}", o.stderr);
        assert_eq!(o.stderr.trim().lines().count(), 1, "{}", o.stderr);
        assert!(
            !d.join("bad_out").exists(),
            "nothing is written on an error"
        );
    };
    let xy2 = "[controller]\nprotocol = \"xy2\"\n[head]\nprotocol = \"xy3\"\n";
    // Configuration: unknown key (the key and its table named), bad value, a rule of
    // Config::validate (the key named), not TOML, no file.
    check(
        "[controller.xy2]\nparity_mode = \"data_only\"\n",
        "xy2.vcd",
        &[],
        "b.toml: line 2: unknown field `parity_mode`",
    );
    check(
        "[controller.xy2]\nparity_mode = 1\n",
        "xy2.vcd",
        &[],
        "in [controller.xy2]: `parity_mode = 1`",
    );
    check(
        "[failsafe]\nrecovery_frames = -3\n",
        "xy2.vcd",
        &[],
        "`recovery_frames = -3`",
    );
    check(
        "[head]\nprotocol = \"xy2\"\n[head.xy2]\nmode = \"extended18\"\n",
        "xy2.vcd",
        &[],
        "b.toml: head.xy2.enhanced_commands:",
    );
    check(
        "[head]\nprotocol = \"hans\"\n[output]\nframe_rate_hz = 50000\n",
        "xy2.vcd",
        &[],
        "output.frame_rate_hz",
    );
    check("this is = = not toml", "xy2.vcd", &[], "b.toml: line 1:");
    let o = run_in(
        &d,
        &[
            "bridge",
            "--config",
            "none.toml",
            "--input",
            "xy2.vcd",
            "--output-dir",
            "x",
        ],
    );
    assert_eq!(o.code, 1);
    assert!(o.stderr.contains("none.toml:"), "{}", o.stderr);
    // Captures: truncated, garbage, missing, the wrong protocol (no `clk`), a line
    // the configuration needs renamed away (Z with z.source = "input").
    check(xy2, "cut.vcd", &[], "truncated");
    check(xy2, "junk.vcd", &[], "VCD");
    check(xy2, "nope.vcd", &[], "nope.vcd");
    check(xy2, "hans.vcd", &[], "signal `clk`");
    check(xy2, "xy2.vcd", &["--map", "z=Z9"], "signal `Z9`");
    // Head status: an XY3-100 head's status is the backchannel.
    check(
        xy2,
        "xy2.vcd",
        &["--head-status", "hans.vcd"],
        "signal `back`",
    );
    // Command line: bad oversampling ratio is a usage error.
    let o = run_in(
        &d,
        &[
            "bridge",
            "--config",
            "b.toml",
            "--input",
            "hans.vcd",
            "--output-dir",
            "x",
            "--hans-oversample",
            "7",
        ],
    );
    assert_eq!(o.code, 2);
}

#[test]
fn demo_runs_and_its_files_decode() {
    let d = dir("demo");
    let o = ok_in(&d, &[]);
    let demo = d.join("bridge-sim-demo");
    for f in [
        "controller.vcd",
        "head-status.vcd",
        "bridge.toml",
        "head.vcd",
        "controller-status.vcd",
    ] {
        assert!(demo.join(f).exists(), "{f}");
        assert!(o.stdout.contains(f), "{f} not named: {}", o.stdout);
    }
    assert!(
        o.stdout.contains("Holding at 16.000 ms, Safe at 26.000 ms"),
        "{}",
        o.stdout
    );
    assert!(!o.stdout.contains("UNEXPECTED"), "{}", o.stdout);

    // The controller's frames as `decode` sees them: good until the break, errors on
    // X after it.
    let ctrl = ok_in(
        &d,
        &[
            "decode",
            "--protocol",
            "xy2",
            "--input",
            "bridge-sim-demo/controller.vcd",
        ],
    );
    let ctrl: Vec<ForwardRecord> = records(&ctrl.stdout);
    assert_eq!(ctrl.len(), 3000);
    let valid: Vec<(u32, u32)> = ctrl
        .iter()
        .filter_map(xy_forward)
        .map(|(x, y)| (x.to_raw(20), y.to_raw(20)))
        .collect();
    assert_eq!(valid.len(), 1499, "frames before the break at 15 ms");

    // The head's frames: valid controller positions, the last one held, then the
    // park position from 26 ms on; never anything else.
    let head = ok_in(
        &d,
        &[
            "decode",
            "--protocol",
            "hans",
            "--input",
            "bridge-sim-demo/head.vcd",
        ],
    );
    let mut last_forwarded = None;
    let mut parked_from = None;
    for (_, r) in jsonl::parse::<HansRecord>(&head.stdout).unwrap() {
        let HansRecord::Frame {
            t_ns: Some(t),
            data: [x, y, _],
        } = r
        else {
            panic!("head frame rejected: {r:?}");
        };
        if (x, y) == (0x8_0000, 0x8_0000) {
            parked_from.get_or_insert(t);
        } else {
            assert!(
                valid.contains(&(x, y)),
                "({x}, {y}) at {t} ns was never sent"
            );
            assert!(parked_from.is_none(), "a position after parking");
            last_forwarded = Some((x, y));
        }
    }
    assert_eq!(last_forwarded, valid.last().copied());
    let parked = parked_from.unwrap();
    assert!(
        (26_000_000..26_100_000).contains(&parked),
        "parked at {parked} ns"
    );

    // The replay the demo prints gives the same head-side file.
    ok_in(
        &d,
        &[
            "bridge",
            "--config",
            "bridge-sim-demo/bridge.toml",
            "--input",
            "bridge-sim-demo/controller.vcd",
            "--head-status",
            "bridge-sim-demo/head-status.vcd",
            "--output-dir",
            "replay",
        ],
    );
    assert_eq!(
        std::fs::read(d.join("replay/head.vcd")).unwrap(),
        std::fs::read(demo.join("head.vcd")).unwrap()
    );

    // The laser gate: on once the link runs, off at the loss (16 ms).
    let wave = read_vcd_file(&demo.join("head.vcd"), &["laser_gate"], &NameMap::new()).unwrap();
    let gate = wave.get("laser_gate").unwrap();
    assert!(gate.level_at(10_000_000_000));
    assert!(!gate.level_at(16_000_000_000));
    assert_eq!(gate.changes().len(), 2);
}
