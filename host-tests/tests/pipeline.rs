//! The whole bridge on the host (`host_tests::pipeline`): controller signals from the
//! `shared` line-level transmitters, impaired, captured into the firmware's DMA
//! buffers, through receiver -> `Bridge` -> head transmitter, and the head-side
//! output decoded again by an independent receiver configured for the head.

use host_tests::impair;
use host_tests::line::roles;
use host_tests::pipeline::check::{decode_head, expected, raw, HeadView};
use host_tests::pipeline::stimulus::{self, GenTiming, Stimulus, Timed};
use host_tests::pipeline::tasks::{self, TaskError, TaskRun};
use host_tests::pipeline::{Options, Pipeline, PipelineError};
use host_tests::wave::{Ps, Waveform};
use shared::bridge::{Config, FailSafe, HansDecode, LinkState, Protocol, Timing, ZSource};
use shared::model::{Alarms, Axis, ForwardFrame};
use shared::xy3::FrameSize;

const PROTOCOLS: [Protocol; 3] = [Protocol::Xy2, Protocol::Xy3, Protocol::Hans];

fn config(ctrl: Protocol, head: Protocol, timing: Timing) -> Config {
    let mut c = Config::default();
    c.controller.protocol = ctrl;
    c.head.protocol = head;
    c.z.source = ZSource::Input;
    c.output.timing = timing;
    c.failsafe.recovery_frames = 20;
    // Most runs carry no head status: not supervised, so the gate does not wait for
    // one (the tests of the head status turn the watchdog on).
    c.failsafe.status_timeout_us = 0;
    c
}

/// Frame `i` of a test run: positions unique per frame even at 16 bits, widened to
/// the controller's widths (exactly representable everywhere).
fn frames(c: &Config, t: &GenTiming, n: usize) -> Vec<ForwardFrame> {
    let w = stimulus::controller_widths(c, t.xy3_size);
    (0..n as u32)
        .map(|i| {
            let v16 = [
                (1000 + i * 37) & 0xFFFF,
                (60_000u32.wrapping_sub(i * 53)) & 0xFFFF,
                (300 + i * 11) & 0xFFFF,
            ];
            let [x, y, z] = [0, 1, 2].map(|k| v16[k] << (w[k] - 16));
            // U / W (used only where the controller drives them): XY3 widths.
            let uw = |v: u32| (v & 0xFFFF) << (t.xy3_size.position_bits() - 16);
            let (u, w) = (uw(20_000 + i * 17), uw(45_000u32.wrapping_sub(i * 23)));
            stimulus::frame_uw(c, t, [x, y, z, u, w], None)
        })
        .collect()
}

/// The controller's frames through the pipeline; `impair` edits the waveform.
fn run(
    c: &Config,
    t: &GenTiming,
    sent: &[ForwardFrame],
    impair: impl FnOnce(&mut Waveform),
    extra: Vec<Timed>,
    tail_ns: u64,
) -> (Pipeline, Stimulus, HeadView) {
    let mut stim = stimulus::controller_signal(c, sent, t).expect("stimulus");
    impair(&mut stim.wave);
    let opts = Options::default();
    let items = stimulus::capture(c, &stim.wave, opts.hans_sample_hz, 0.37).expect("capture");
    let items = stimulus::merge(vec![stimulus::chunk(items, 1_000), extra]);
    let mut p = Pipeline::new(c, opts).expect("pipeline");
    let end = stim.wave.end_time() / 1000 + tail_ns;
    stimulus::run(&mut p, &items, end).expect("run");
    let view = decode_head(c, &p.head_output()).expect("decode");
    (p, stim, view)
}

/// Every frame the head decoded is one the pipeline wrote, at its time (within
/// 2 us) and with its values; every frame written and played is decoded (a HANS-100
/// receiver may need the first few frames to acquire); none failed a check.
fn assert_output_is_sent(c: &Config, p: &Pipeline, view: &HeadView, label: &str) {
    assert_eq!(view.faults, 0, "{label}: the head saw a bad frame");
    let sent = p.sent();
    let near = |a: Ps, b: Ps| a.abs_diff(b) < 2_000_000;
    for d in &view.frames {
        let s = sent
            .iter()
            .find(|s| near(s.start_ps, d.start_ps))
            .unwrap_or_else(|| {
                panic!(
                    "{label}: decoded frame at {} ps was never written",
                    d.start_ps
                )
            });
        assert_eq!(
            raw(c, &d.frame),
            raw(c, &s.frame),
            "{label}: at {} ps",
            s.start_ps
        );
    }
    let end = p.head_output().end_ps();
    let played: Vec<_> = sent
        .iter()
        .filter(|s| s.start_ps + 10_000_000 <= end)
        .collect();
    let missing = played
        .iter()
        .filter(|s| !view.frames.iter().any(|d| near(s.start_ps, d.start_ps)))
        .count();
    // The head's HANS-100 receiver acquires first: hunt, rate, and the young
    // lock's periods that publish nothing (`shared::hans::rx::timing::SETTLED`).
    let allowed = if c.head.protocol == Protocol::Hans {
        11
    } else {
        0
    };
    assert!(
        missing <= allowed,
        "{label}: {missing} of {} written frames not decoded",
        played.len()
    );
}

/// Maps each frame sent while running (checked against the decoded output by
/// [`assert_output_is_sent`]) to the input frame it carries; asserts there is
/// one, in order, and returns the indices.
fn carried(c: &Config, stim: &Stimulus, p: &Pipeline) -> Vec<usize> {
    let exp: Vec<_> = stim.sent.iter().map(|s| expected(c, &s.frame)).collect();
    let mut out = Vec::new();
    let mut from = 0;
    for s in p.sent() {
        if s.state != LinkState::Running {
            continue;
        }
        let got = raw(c, &s.frame);
        // An axis the input frame did not carry (X of a command frame the head
        // cannot take) holds its last value.
        let fits = |e: &([Option<u32>; 5], Option<shared::model::Command>)| {
            e.1 == got.1 && e.0.iter().zip(&got.0).all(|(e, g)| e.is_none() || e == g)
        };
        let i = (from..exp.len())
            .find(|&i| fits(&exp[i]))
            .unwrap_or_else(|| panic!("output {got:?} is no input frame at or after {from}"));
        out.push(i);
        from = i;
    }
    out
}

fn pairing(ctrl: Protocol, head: Protocol, timing: Timing, xy3_size: FrameSize) {
    pairing_of(config(ctrl, head, timing), xy3_size);
}

/// [`pairing`] for a configuration `c`; returns the head's view.
fn pairing_of(mut c: Config, xy3_size: FrameSize) -> HeadView {
    let (ctrl, head, timing) = (c.controller.protocol, c.head.protocol, c.output.timing);
    if head == Protocol::Xy3 {
        c.head.xy3.frame_size = xy3_size;
    }
    let t = GenTiming {
        xy3_size,
        ..GenTiming::default()
    };
    let n = 300;
    let sent = frames(&c, &t, n);
    let names: Vec<String> = stimulus::controller_signal(&c, &sent[..1], &t)
        .unwrap()
        .wave
        .names();
    let (p, stim, view) = run(
        &c,
        &t,
        &sent,
        |w| {
            impair::rate_offset_ppm(w, 80.0).unwrap();
            let n: Vec<&str> = names.iter().map(String::as_str).collect();
            // Well inside every receiver's tolerance (HANS: 25 % of a bit).
            impair::jitter(w, &n, 8_000, 7).unwrap();
        },
        Vec::new(),
        // An XY3-100 input's last period waits for the step watch's
        // confirmation time (`shared::xy3::step::CONFIRM_NS`): no period follows.
        50_000
            + if ctrl == Protocol::Xy3 {
                shared::xy3::step::CONFIRM_NS
            } else {
                0
            },
    );
    let label = format!(
        "{ctrl:?} -> {head:?} {timing:?} {xy3_size:?} {:?}",
        c.xy3_head_lines()
    );
    assert_output_is_sent(&c, &p, &view, &label);
    let idx = carried(&c, &stim, &p);
    let counters = p.bridge_counters();
    let first = c.failsafe.recovery_frames as usize - 1;
    // The first N-1 valid frames prove the link; from the N-th on every input frame
    // reaches the head (slaved: exactly once; free-running: once, give or take a
    // repeat / skip where the clocks' phases cross).
    // (XY3-100 receivers first lock their bit alignment: two periods.)
    // (A HANS-100 receiver publishes after its young lock's periods.)
    let acquisition = if c.controller.protocol == Protocol::Hans {
        HANS_ACQUISITION
    } else {
        0
    };
    let got_first = idx.first().copied().unwrap_or(usize::MAX);
    assert!(
        (first..=first + 2 + acquisition).contains(&got_first),
        "{label}: {got_first}"
    );
    assert_eq!(idx.last().copied(), Some(n - 1), "{label}");
    let mut distinct = idx.clone();
    distinct.dedup();
    match timing {
        Timing::Slaved => {
            assert_eq!(distinct.len(), n - got_first, "{label}");
            assert_eq!(idx.len(), n - got_first, "{label}");
        }
        Timing::FreeRunning => {
            let skipped = counters.skipped as usize;
            assert_eq!(
                distinct.len() + skipped,
                n - got_first,
                "{label}: {counters:?} {idx:?}"
            );
            // Skips happen only where the input's phase (80 ppm off, jittered)
            // crosses the output slots', a handful of times in one crossing.
            assert!(skipped <= 6, "{label}: {counters:?} {idx:?}");
            assert_eq!(
                counters.repeated as usize,
                idx.len() - distinct.len(),
                "{label}"
            );
        }
    }
    // Receivers may need the first frame or two to lock (XY3-100 bit alignment,
    // HANS-100 acquisition); none is lost after that.
    let ok = counters.frames_ok as usize;
    assert!(
        (n - 2 - acquisition..=n).contains(&ok),
        "{label}: {counters:?}"
    );
    assert_eq!(n - ok, got_first - first, "{label}: {counters:?}");
    assert_eq!(counters.axis_check_failures(), [0; 5], "{label}");
    assert_eq!(p.bridge().state(), LinkState::Running, "{label}");
    assert!(p.gate_on(), "{label}");
    view
}

#[test]
fn all_nine_pairings_free_running() {
    for ctrl in PROTOCOLS {
        for head in PROTOCOLS {
            pairing(ctrl, head, Timing::FreeRunning, FrameSize::Bits24);
        }
    }
}

#[test]
fn slaved_pairings_and_32_bit_xy3() {
    for ctrl in PROTOCOLS {
        for head in [Protocol::Xy2, Protocol::Xy3] {
            pairing(ctrl, head, Timing::Slaved, FrameSize::Bits24);
        }
        pairing(ctrl, Protocol::Xy3, Timing::FreeRunning, FrameSize::Bits32);
    }
}

/// An XY3-100 controller on all five lines (and on X, Y, W without Z) into an
/// XY3-100 head: U and W reach the head's pairs 7 / 8 and decode there, frame for
/// frame (checked by `pairing_of` through `raw` / `expected`, which include U / W).
#[test]
fn xy3_u_and_w_reach_an_xy3_head() {
    use shared::xy3::rx::Lines;
    let cases = [
        (
            Lines::ALL,
            ZSource::Input,
            Timing::FreeRunning,
            FrameSize::Bits24,
        ),
        (
            Lines::ALL,
            ZSource::Input,
            Timing::Slaved,
            FrameSize::Bits32,
        ),
        (
            Lines::new(&[Axis::X, Axis::Y, Axis::W]).unwrap(),
            ZSource::None,
            Timing::FreeRunning,
            FrameSize::Bits24,
        ),
    ];
    for (lines, z, timing, size) in cases {
        let mut c = config(Protocol::Xy3, Protocol::Xy3, timing);
        c.controller.xy3.lines = lines;
        c.z.source = z;
        c.head.xy3.frame_size = size;
        let view = pairing_of(c, size);
        let bits = c.head.width(Axis::U);
        // The head really decoded U / W on every frame, and they move: not a
        // constant or an absent line passing for equal.
        for axis in [Axis::U, Axis::W] {
            let got: Vec<Option<u32>> = view
                .frames
                .iter()
                .map(|d| d.frame.axis(axis).map(|p| p.to_raw(bits)))
                .collect();
            assert!(got.len() > 250, "{lines:?}: {} frames", got.len());
            if lines.has(axis) {
                assert!(got.iter().all(Option::is_some), "{lines:?} {axis:?}");
                let mut distinct = got.clone();
                distinct.sort();
                distinct.dedup();
                assert!(distinct.len() > 250, "{lines:?} {axis:?}");
            } else {
                assert!(got.iter().all(Option::is_none), "{lines:?} {axis:?}");
            }
        }
    }
}

/// The head frame values of the configured park position (U / W where the head
/// gets them).
fn park_raw(c: &Config) -> [Option<u32>; 5] {
    let w = host_tests::pipeline::check::head_widths(c);
    let f = &c.failsafe;
    let p = |v: u32, bits: u8| {
        shared::model::Position::from_raw(v, 20)
            .unwrap()
            .to_raw(bits)
    };
    let lines = c.xy3_head_lines();
    let uw = |axis: Axis, v: u32| {
        (c.head.protocol == Protocol::Xy3 && lines.has(axis)).then(|| p(v, w[axis.index()]))
    };
    [
        Some(p(f.park_x, w[0])),
        Some(p(f.park_y, w[1])),
        Some(p(f.park_z, w[2])),
        uw(Axis::U, f.park_u),
        uw(Axis::W, f.park_w),
    ]
}

/// The alarms the controller learns in `[from_ns, to_ns)`, decoded from the
/// controller-side status output with fresh `shared` receivers. XY2-100 level: a
/// fault shows as `INPUT_LOST` (the level cannot say more); XY3-100: the union of
/// the ERROR_STATE packets' alarms; HANS-100: the union over the STATUS frames.
fn controller_alarms(c: &Config, p: &Pipeline, from_ns: u64, to_ns: u64) -> Alarms {
    let out = p.controller_status();
    let mut a = Alarms::NONE;
    match c.controller.protocol {
        Protocol::Xy2 if c.controller.xy2.status == shared::bridge::StatusForm::Word => {
            let link = shared::xy2::LinkConfig {
                mode: c.controller.xy2.mode,
                parity: c.controller.xy2.parity,
            };
            for &(t, w) in &out.words {
                if (from_ns..to_ns).contains(&t) {
                    let word = shared::xy2::StatusWord::from_frame(w, &link).unwrap();
                    a = a.union(word.alarms());
                }
            }
        }
        Protocol::Xy2 => {
            let sig = out.level_signal();
            let level = shared::xy2::StatusLevel {
                polarity: c.controller.xy2.polarity,
            };
            let fault = (from_ns..to_ns)
                .step_by(5_000)
                .any(|t| level.health(sig.level_at(t * 1000)) == shared::xy2::Health::Fault);
            a.set(Alarms::INPUT_LOST, fault);
        }
        Protocol::Xy3 => {
            let mut parser = shared::xy3::back::Parser::new();
            for b in &out.back {
                let t = b.start_ps / 1000;
                if let Some(shared::xy3::back::Event::Packet(raw)) = parser.push(b.value) {
                    if !(from_ns..to_ns).contains(&t) {
                        continue;
                    }
                    if let Ok(pk @ shared::xy3::back::Packet::ErrorState(_)) =
                        shared::xy3::back::Packet::decode(raw.ty, raw.payload)
                    {
                        let mut st = shared::model::HeadStatus::default();
                        shared::xy3::back::neutral::apply(&pk, &mut st);
                        a = a.union(st.alarms);
                    }
                }
            }
        }
        Protocol::Hans => {
            let (bytes, bits) = &out.hans;
            let fb = shared::hans::FRAME_BITS as u64;
            for k in (from_ns / 10_000)..(to_ns / 10_000).min(bits / fb) {
                if let Ok(f) = shared::hans::Frame::read_at(bytes, (k * fb) as usize) {
                    let mut st = shared::model::HeadStatus::default();
                    shared::hans::StatusReceiver::new().apply(&f, &mut st);
                    a = a.union(st.alarms);
                }
            }
        }
    }
    a
}

/// The controller's clock stops for 5 ms and restarts: communication alarm, laser
/// gate off, hold, then park (or stop), recovery only after N valid frames.
fn clock_stop(ctrl: Protocol, head: Protocol, after: shared::bridge::AfterHold) {
    clock_stop_of(config(ctrl, head, Timing::FreeRunning), after);
}

/// [`clock_stop`] for a configuration `c`.
fn clock_stop_of(mut c: Config, after: shared::bridge::AfterHold) {
    let (ctrl, head) = (c.controller.protocol, c.head.protocol);
    c.failsafe.hold_us = 2_000;
    c.failsafe.after_hold = after;
    let t = GenTiming::default();
    let n = 1200;
    let sent = frames(&c, &t, n);
    let (stop_ps, restart_ps): (Ps, Ps) = (4_000_000_000, 9_000_000_000);
    let label = format!("{ctrl:?} -> {head:?} {after:?} {:?}", c.xy3_head_lines());
    let (p, stim, view) = run(
        &c,
        &t,
        &sent,
        |w| {
            // XY2 / XY3: CLK held low; HANS-100 (no clock line): every channel idles.
            let lines: Vec<String> = if ctrl == Protocol::Hans {
                roles::HANS_CHANNELS.iter().map(|s| s.to_string()).collect()
            } else {
                vec![roles::CLK.to_string()]
            };
            for l in &lines {
                impair::gap(w, l, stop_ps, restart_ps, false).unwrap();
            }
        },
        Vec::new(),
        100_000,
    );
    assert_output_is_sent(&c, &p, &view, &label);
    let k = p.bridge_counters();
    assert_eq!(k.input_losses, 1, "{label}: {k:?}");
    assert_eq!(k.recoveries, 2, "{label}: {k:?}");
    // Last frame before the stop and first frame after the restart.
    let last_valid = stim
        .sent
        .iter()
        .filter(|s| s.last_bit_ps < stop_ps)
        .map(|s| s.last_bit_ps / 1000)
        .max()
        .unwrap();
    let states: Vec<(u64, LinkState)> = p.states().iter().map(|c| (c.t_ns, c.value)).collect();
    let kinds: Vec<LinkState> = states.iter().map(|s| s.1).collect();
    use LinkState::{Holding, Running, Safe};
    assert_eq!(
        kinds,
        [Safe, Running, Holding, Safe, Running],
        "{label}: {states:?}"
    );
    // Holding within a slot of last valid + T; Safe within a slot of + T + H.
    let slot = 10_000;
    let near = |t: u64, want: u64| t >= want && t <= want + 2 * slot;
    assert!(
        near(states[2].0, last_valid + 1_000_000),
        "{label}: {states:?} {last_valid}"
    );
    assert!(
        near(states[3].0, last_valid + 3_000_000),
        "{label}: {states:?}"
    );
    assert!(states[4].0 > restart_ps / 1000, "{label}");
    // The gate follows: on only while running.
    let gate: Vec<(u64, bool)> = p.gate().iter().map(|c| (c.t_ns, c.value)).collect();
    assert_eq!(gate.len(), 4, "{label}: {gate:?}");
    assert_eq!(
        (gate[1].1, gate[2].1, gate[3].1),
        (true, false, true),
        "{label}"
    );
    assert_eq!(gate[2].0, states[2].0, "{label}: gate off with the loss");
    assert_eq!(gate[3].0, states[4].0, "{label}: gate on with the recovery");
    // Output while holding: the last valid position; while safe: park or nothing.
    let hold_pos = p
        .sent()
        .iter()
        .rfind(|s| s.state == Running && s.decided_ns < states[2].0)
        .map(|s| raw(&c, &s.frame).0)
        .unwrap();
    let mut held = 0;
    let mut parked = 0;
    for s in p.sent() {
        match s.state {
            Holding => {
                assert_eq!(raw(&c, &s.frame).0, hold_pos, "{label}");
                assert!(s.frame.command.is_none() && s.frame.laser.is_none());
                held += 1;
            }
            Safe => {
                assert_eq!(raw(&c, &s.frame).0, park_raw(&c), "{label}");
                parked += 1;
            }
            Running => {}
        }
    }
    assert!((195..=205).contains(&held), "{label}: {held} held frames");
    match after {
        shared::bridge::AfterHold::Park => {
            assert!(parked > 150, "{label}: {parked} park frames")
        }
        shared::bridge::AfterHold::Stop => assert_eq!(parked, 0, "{label}"),
    }
    // Hysteresis: N - 1 valid frames after the restart are counted, not forwarded.
    let n_rec = u64::from(c.failsafe.recovery_frames);
    // Lost: the frames sent while the clock stood still, the ones it cut, and at
    // most a couple while a receiver locks at start-up.
    let in_gap = stim
        .sent
        .iter()
        .filter(|s| s.start_ps + 10_000_000 > stop_ps && s.start_ps < restart_ps)
        .count() as u64;
    let lost = n as u64 - k.frames_ok;
    // A HANS-100 receiver locks again after the restart: its young lock publishes
    // nothing for a few periods.
    let relock = if c.controller.protocol == Protocol::Hans {
        2 * HANS_ACQUISITION as u64
    } else {
        0
    };
    // An XY3-100 input whose CLK stops while SYNC runs on reports periods without
    // bytes: the out-of-step watch (`shared::xy3::step`) drops the good period it
    // held for confirmation when they begin, turns suspect and withholds the first
    // GOOD_RUN - 1 good periods after the restart, as the firmware does.
    let withheld = if c.controller.protocol == Protocol::Xy3 {
        u64::from(shared::xy3::step::GOOD_RUN)
    } else {
        0
    };
    assert_eq!(
        k.line(shared::model::Line::Framing).dropped,
        withheld,
        "{label}: {k:?}"
    );
    assert!(
        (in_gap + withheld..=in_gap + withheld + 3 + relock).contains(&lost),
        "{label}: {in_gap} {k:?}"
    );
    assert!(
        (2 * (n_rec - 1)..=2 * (n_rec - 1) + 2).contains(&k.not_forwarded),
        "{label}: {k:?}"
    );
    // No frame of the input is forwarded twice across the gap and none is invented:
    // `carried` maps every running output frame to an input frame in order.
    let idx = carried(&c, &stim, &p);
    let first_after = stim
        .sent
        .iter()
        .position(|s| s.start_ps >= restart_ps)
        .unwrap();
    let resumed = idx.iter().find(|&&i| i >= first_after).copied().unwrap();
    assert!(
        resumed >= first_after + n_rec as usize - 1,
        "{label}: {resumed}"
    );
    // Toward the controller: the communication alarm while not running, decoded
    // from what the controller receives, and gone after the recovery.
    let (lost_at, back_at) = (states[2].0, states[4].0);
    let during = controller_alarms(&c, &p, lost_at, back_at);
    assert!(
        during.contains(Alarms::INPUT_LOST) || during.contains(Alarms::COMMUNICATION),
        "{label}: {during:?}"
    );
    let after_rec = controller_alarms(&c, &p, back_at + 100_000, p.now_ns());
    assert!(!after_rec.any(), "{label}: {after_rec:?}");
    let a = p.bridge().alarms();
    assert!(
        !a.contains(shared::model::Alarms::INPUT_LOST),
        "{label}: {a:?}"
    );
}

#[test]
fn controller_clock_stops_and_restarts() {
    use shared::bridge::AfterHold;
    clock_stop(Protocol::Xy2, Protocol::Xy3, AfterHold::Park);
    clock_stop(Protocol::Xy3, Protocol::Xy2, AfterHold::Stop);
    clock_stop(Protocol::Hans, Protocol::Hans, AfterHold::Park);
    // XY3-100 on five lines: U / W held at their last value, then parked at
    // `failsafe.park_u` / `park_w` (compared by `park_raw`, which includes them).
    let mut c = config(Protocol::Xy3, Protocol::Xy3, Timing::FreeRunning);
    c.controller.xy3.lines = shared::xy3::rx::Lines::ALL;
    c.failsafe.park_u = 0x1_2345;
    c.failsafe.park_w = 0xF_EDCB;
    assert!(park_raw(&c)[3..].iter().all(Option::is_some));
    clock_stop_of(c, AfterHold::Park);
}

/// HANS-100 controller with one channel broken (open line: reads high) from
/// `from_ps`; returns the pipeline, the stimulus and the frames the receiver
/// delivered.
fn hans_broken(decode: HansDecode, channel: usize, from_ps: Ps) -> (Pipeline, Stimulus, Config) {
    let mut c = config(Protocol::Hans, Protocol::Xy2, Timing::FreeRunning);
    c.controller.hans.decode = decode;
    let t = GenTiming::default();
    let n = 400;
    let sent = frames(&c, &t, n);
    let label = format!("{decode:?} CH{channel} broken from {from_ps} ps");
    let (p, stim, view) = run(
        &c,
        &t,
        &sent,
        |w| impair::stuck_at(w, roles::HANS_CHANNELS[channel - 1], from_ps, true).unwrap(),
        Vec::new(),
        50_000,
    );
    assert_output_is_sent(&c, &p, &view, &label);
    // `carried` panics on any output frame that is not an input frame.
    let _ = carried(&c, &stim, &p);
    (p, stim, c)
}

#[test]
fn broken_hans_channel_in_each_decode_mode() {
    use shared::model::Line;
    let mid: Ps = 2_000_000_000;
    // Normal mode on the broken channel: the link is lost (hold), never a wrong frame.
    let (p, _, _) = hans_broken(HansDecode::Normal(1), 1, mid);
    let k = p.bridge_counters();
    assert_eq!(k.input_losses, 1, "{k:?}");
    // (Six fewer than the periods before the break: the young lock publishes none.)
    assert!((189..=205).contains(&k.frames_ok), "{k:?}");
    assert_eq!(p.bridge().state(), LinkState::Holding);
    assert!(!p.gate_on());
    // The dead channel is counted missing every period while the receiver hunts.
    let f = k.line(Line::HansChannel(1));
    assert!(f.missing.abs_diff(200) <= 3, "{f:?}");
    // Normal mode on another channel: unaffected.
    let (p, _, _) = hans_broken(HansDecode::Normal(1), 3, mid);
    assert!(
        p.bridge_counters().frames_ok >= 398 - HANS_ACQUISITION as u64,
        "{:?}",
        p.bridge_counters()
    );
    // The voting modes ride through one broken channel, mid-run and from power-up,
    // and count the channel's faults.
    for decode in [
        HansDecode::Vote3([1, 2, 3]),
        HansDecode::Vote5,
        HansDecode::Super,
    ] {
        for (ch, from) in [(2, mid), (3, 0)] {
            let (p, _, _) = hans_broken(decode, ch, from);
            let k = p.bridge_counters();
            let label = format!("{decode:?} CH{ch} from {from}");
            assert!(
                k.frames_ok >= 398 - HANS_ACQUISITION as u64,
                "{label}: {k:?}"
            );
            assert_eq!(k.input_losses, 0, "{label}: {k:?}");
            assert_eq!(p.bridge().state(), LinkState::Running, "{label}");
            assert!(p.gate_on(), "{label}");
            // Mid-run: the frame it cut fails and the channel loses alignment once;
            // then, like a channel dead from power-up, it is missing from every
            // frame period (an open line is missing frames, never wrong data).
            let f = k.line(Line::HansChannel(ch as u8));
            let want = u64::from(from > 0);
            assert!(
                f.check_failed <= want && f.resyncs == want,
                "{label}: {f:?}"
            );
            // 10 us frames: 200 periods from mid-run, 400 from power-up less the
            // two of the acquisition (not counted: no line seen yet).
            let dead = if from > 0 { 200 } else { 398 };
            assert!(f.missing.abs_diff(dead) <= 3, "{label}: {f:?}");
            for good in (1..=5u8).filter(|&c| usize::from(c) != ch) {
                let g = k.line(Line::HansChannel(good));
                assert_eq!(g, Default::default(), "{label}: CH{good}");
            }
            assert_eq!(k.line(Line::Framing), Default::default(), "{label}: {k:?}");
        }
    }
}

/// Noise bursts on the controller's lines: every damaged frame is rejected and
/// counted, none is forwarded, and bursts shorter than the input timeout do not
/// drop the link.
#[test]
fn noise_bursts() {
    for ctrl in PROTOCOLS {
        let c = config(ctrl, Protocol::Xy3, Timing::FreeRunning);
        let t = GenTiming::default();
        let n = 600;
        let sent = frames(&c, &t, n);
        let label = format!("{ctrl:?}");
        let lines: Vec<&str> = match ctrl {
            Protocol::Hans => vec![roles::HANS_CHANNELS[0]],
            _ => vec![roles::X, roles::CLK, roles::SYNC, roles::Y],
        };
        let (p, stim, view) = run(
            &c,
            &t,
            &sent,
            |w| {
                for (i, l) in lines.iter().enumerate() {
                    let from = 1_000_000_000 + i as Ps * 1_000_000_000;
                    impair::noise_burst(w, l, (from, from + 400_000_000), 25, 120_000, i as u64)
                        .unwrap();
                }
            },
            Vec::new(),
            50_000,
        );
        assert_output_is_sent(&c, &p, &view, &label);
        let idx = carried(&c, &stim, &p);
        let k = p.bridge_counters();
        use shared::model::{Axis, Line};
        let all_lines = Axis::ALL
            .map(Line::Axis)
            .into_iter()
            .chain((1..=5).map(Line::HansChannel))
            .chain([Line::Framing]);
        let faults: u64 = all_lines
            .map(|l| k.line(l))
            .map(|l| l.check_failed + l.framing + l.resyncs + l.disagree + l.dropped + l.missing)
            .sum();
        let lost = n as u64 - k.frames_ok;
        assert!(lost >= 10, "{label}: the bursts must hit frames: {k:?}");
        assert!(
            faults >= lost / 2,
            "{label}: lost frames are counted: {lost} {k:?}"
        );
        assert_eq!(k.input_losses, 0, "{label}: {k:?}");
        assert_eq!(p.bridge().state(), LinkState::Running, "{label}");
        // Every valid frame after the start-up reached the head (or was skipped,
        // counted): none invented, none lost silently.
        let mut distinct = idx.clone();
        distinct.dedup();
        assert!(
            distinct.len() as u64 + k.skipped + lost >= (n - 20) as u64,
            "{label}: {} {k:?}",
            distinct.len()
        );
    }
}

/// The head's backchannel: an ERROR_STATE packet (with `alarms`) every `every_us`
/// in `[from_us, to_us)`, through the head's `Sender` (SYNC first) and a UART.
fn head_back(baud: u32, from_us: u64, to_us: u64, every_us: u64, alarms: Alarms) -> Vec<Timed> {
    use shared::xy3::back::{neutral, Packet, Sender, SEND_BUF_LEN};
    let mut st = shared::model::HeadStatus {
        alarms,
        ..Default::default()
    };
    st.error_codes[0] = Some(if alarms.any() { 1 } else { 0 });
    let packet = Packet::ErrorState(neutral::error_codes_for(&st));
    let mut sender = Sender::default();
    let mut items = Vec::new();
    let byte_us = 10 * 1_000_000 / u64::from(baud) + 1;
    let mut free_us = 0;
    for t in (from_us..to_us).step_by(every_us as usize) {
        // The head's UART sends one packet after the other.
        let t = t.max(free_us);
        let mut out = [0u8; SEND_BUF_LEN];
        let n = sender.send(t, &packet, &mut out).unwrap();
        items.extend(stimulus::back_bytes(&out[..n], baud, t * 1_000_000).unwrap());
        free_us = t + n as u64 * byte_us;
    }
    items
}

/// The head's HANS-100 STATUS line: velocity/alarm frames (code 65 + code 15) back
/// to back in `[from_us, to_us)`.
fn head_hans_status(from_us: u64, to_us: u64, alarms: Alarms, fs: u32) -> Vec<Timed> {
    use shared::hans::{status_frame, DeviceExt, GalvoStatus};
    let st = shared::model::HeadStatus {
        alarms,
        velocity: [Some(0); 3],
        ..Default::default()
    };
    let galvo = GalvoStatus::velocity_from(&st);
    let devices = DeviceExt::all_from(&st);
    let frames: Vec<_> = (0..(to_us - from_us) / 10)
        .map(|i| status_frame(&galvo, &devices[i as usize % devices.len()]).unwrap())
        .collect();
    stimulus::hans_status(&frames, from_us * 1_000_000, fs).unwrap()
}

/// An XY3-100 BACK_RATE command mid-stream: the bridge forwards it to an XY3-100
/// head (and listens to the head at the new rate), or counts it as not carried,
/// and in both cases switches its own controller-side backchannel, SYNC first.
#[test]
fn backchannel_rate_change_mid_stream() {
    use shared::model::Command;
    use shared::xy3::{back, BackRate};
    for head in [Protocol::Xy3, Protocol::Xy2] {
        let c = config(Protocol::Xy3, head, Timing::FreeRunning);
        let t = GenTiming::default();
        let n = 3000;
        let mut sent = frames(&c, &t, n);
        let code = shared::xy3::Command::BackRate(BackRate::B230400).code();
        // A command frame carries the command on X in place of the position.
        sent[1500].command = Some(Command::Xy3(code));
        sent[1500].axes[0] = None;
        let label = format!("XY3 -> {head:?}");
        let (p, stim, view) = run(&c, &t, &sent, |_| {}, Vec::new(), 50_000);
        assert_output_is_sent(&c, &p, &view, &label);
        let _ = carried(&c, &stim, &p);
        let k = p.bridge_counters();
        let switch_ns = stim.sent[1500].last_bit_ps / 1000;
        let out = p.controller_status();
        assert_eq!(out.back_rates.len(), 1, "{label}");
        let ch = out.back_rates[0];
        assert_eq!(ch.value, BackRate::B230400);
        assert!(
            ch.t_ns >= switch_ns && ch.t_ns < switch_ns + 20_000,
            "{label}: {ch:?}"
        );
        match head {
            Protocol::Xy3 => {
                assert_eq!(k.commands_forwarded, 1, "{label}: {k:?}");
                assert_eq!(p.head_back_rate(), BackRate::B230400);
                let cmds: Vec<_> = view.frames.iter().filter_map(|d| d.frame.command).collect();
                assert_eq!(cmds, [Command::Xy3(code)], "{label}");
            }
            _ => {
                assert_eq!(k.commands_not_carried, 1, "{label}: {k:?}");
                assert_eq!(k.commands_forwarded, 0, "{label}: {k:?}");
            }
        }
        // The controller's UART: decode the line in two windows, each at its rate.
        let line = out.back_signal();
        // Bytes already queued finish at the old rate; the first byte at the new
        // rate starts after the switch.
        let cut = out
            .back
            .iter()
            .find(|b| b.baud == 230_400)
            .unwrap()
            .start_ps;
        assert!(cut >= ch.t_ns * 1000, "{label}");
        assert!(out
            .back
            .iter()
            .all(|b| (b.start_ps < cut) == (b.baud == 115_200)));
        let window = |from: Ps, to: Ps| {
            let ch = line
                .changes()
                .iter()
                .copied()
                .filter(|&(t, _)| t >= from && t < to);
            host_tests::wave::Signal::from_changes("UART", true, ch).unwrap()
        };
        let before = host_tests::line::uart::uart_decode(&window(0, cut), 115_200.0).unwrap();
        let after = host_tests::line::uart::uart_decode(&window(cut, Ps::MAX), 230_400.0).unwrap();
        assert!(
            before.len() > 10 && after.len() > 5,
            "{label}: {} {}",
            before.len(),
            after.len()
        );
        let bad: Vec<_> = before
            .iter()
            .chain(&after)
            .filter(|f| f.framing_error)
            .collect();
        assert!(bad.is_empty(), "{label}: {bad:?} cut {cut}");
        let bytes: Vec<u8> = before.iter().chain(&after).map(|f| f.value).collect();
        assert_eq!(bytes, out.back_bytes(), "{label}");
        // At the new rate the first packet is a SYNC, and every packet parses.
        let mut parser = back::Parser::new();
        let mut types = Vec::new();
        let mut errors = 0;
        for f in &after {
            match parser.push(f.value) {
                Some(back::Event::Packet(raw)) => types.push(raw.ty),
                Some(back::Event::Resynced { .. }) => types.push(back::wire::ty::SYNC),
                Some(back::Event::LostSync { .. }) => errors += 1,
                None => {}
            }
        }
        assert_eq!(errors, 0, "{label}");
        assert_eq!(
            types.first(),
            Some(&back::wire::ty::SYNC),
            "{label}: {types:?}"
        );
        assert!(types.len() >= 2, "{label}: {types:?}");
    }
}

/// The head's status stops for longer than `failsafe.status_timeout_us`: reported
/// (STATUS_LOST towards the controller, gate off), and cleared when it returns.
#[test]
fn head_status_disappears_and_returns() {
    for (ctrl, head) in [
        (Protocol::Xy2, Protocol::Xy3),
        (Protocol::Xy3, Protocol::Hans),
    ] {
        let mut c = config(ctrl, head, Timing::FreeRunning);
        c.failsafe.status_timeout_us = 5_000;
        let t = GenTiming::default();
        let n = 2500;
        let sent = frames(&c, &t, n);
        let label = format!("{ctrl:?} -> {head:?}");
        // Status from 0.1 to 8 ms, silence, back from 18 ms.
        let status: Vec<Timed> = match head {
            Protocol::Xy3 => [(100, 8_000), (18_000, 25_000)]
                .into_iter()
                .flat_map(|(a, b)| head_back(115_200, a, b, 1_000, Alarms::NONE))
                .collect(),
            _ => [(100, 8_000), (18_000, 25_000)]
                .into_iter()
                .flat_map(|(a, b)| {
                    head_hans_status(a, b, Alarms::NONE, Options::default().hans_status_sample_hz)
                })
                .collect(),
        };
        let status_times: Vec<u64> = status.iter().map(|s| s.t_ns).collect();
        let (p, _stim, view) = run(&c, &t, &sent, |_| {}, status, 50_000);
        assert_output_is_sent(&c, &p, &view, &label);
        let k = p.bridge_counters();
        assert_eq!(k.status_losses, 1, "{label}: {k:?}");
        assert_eq!(k.input_losses, 0, "{label}: {k:?}");
        assert!(
            p.counters().status_items > 10,
            "{label}: {:?}",
            p.counters()
        );
        // Each start of the status stream costs a resync (the backchannel parser's
        // first sync counts too), each stop at most a cut frame.
        assert!(
            p.counters().status_faults <= 4,
            "{label}: {:?}",
            p.counters()
        );
        // The gate: on after start-up, off at last status + timeout, on again when
        // the status is back.
        // The last status item before the silence (HANS-100: the last half with
        // frames, taken as the firmware takes them: the half that holds the
        // stream's end is completed only by the words after the silence).
        let last_status = match head {
            Protocol::Hans => {
                let halves = p.hans_status_halves();
                let last = halves
                    .iter()
                    .filter(|h| h.t_ns < 9_000_000 && !h.frames.is_empty())
                    .map(|h| h.t_ns)
                    .max()
                    .unwrap();
                // Within a half (205 us) of the stream's end: every half is decoded
                // (no HANS-100 controller here).
                assert!(
                    (8_000_000 - 205_000..=8_000_000).contains(&last),
                    "{label}: {last}"
                );
                last
            }
            _ => status_times
                .iter()
                .filter(|&&t| t < 9_000_000)
                .max()
                .copied()
                .unwrap(),
        };
        let gate: Vec<(u64, bool)> = p.gate().iter().map(|c| (c.t_ns, c.value)).collect();
        assert_eq!(gate.len(), 4, "{label}: {gate:?}");
        let lost_at = last_status + 5_000_000;
        assert!(
            gate[2].0 + 50_000 >= lost_at && gate[2].0 <= lost_at + 20_000 && !gate[2].1,
            "{label}: {gate:?} {last_status}"
        );
        assert!(
            gate[3].0 >= 18_000_000 && gate[3].0 <= 18_400_000,
            "{label}: {gate:?}"
        );
        let lost = controller_alarms(&c, &p, lost_at + 20_000, 18_000_000);
        let expect = match ctrl {
            Protocol::Xy2 => Alarms::INPUT_LOST, // the level says only "fault"
            _ => Alarms::COMMUNICATION,
        };
        assert!(lost.contains(expect), "{label}: {lost:?}");
        assert!(
            !controller_alarms(&c, &p, 19_000_000, 24_000_000).any(),
            "{label}"
        );
    }
}

/// The task graph (embassy-executor tasks over `embassy-sync` channels on a
/// simulated clock) gives exactly what the synchronous pipeline gives for the same
/// buffers; the supervisor's timer fires once per period, and never sees a stall.
fn same_as_tasks(c: &Config, items: &[Timed], end_ns: u64, label: &str) -> TaskRun {
    let mut p = Pipeline::new(c, Options::default()).unwrap();
    stimulus::run(&mut p, items, end_ns).unwrap();
    let r = tasks::run(c, Options::default(), items, end_ns).unwrap();
    let k = &r.core;
    assert_eq!(r.stalls, 0, "{label}");
    assert_eq!(
        u64::from(r.checks),
        end_ns / tasks::SUPERVISE_NS,
        "{label}: {} checks",
        r.checks
    );
    assert!(r.polls > 0, "{label}");
    assert_eq!(k.now_ns(), p.now_ns(), "{label}");
    assert_eq!(k.head_output(), p.head_output(), "{label}");
    assert_eq!(k.sent(), p.sent(), "{label}");
    assert_eq!(k.controller_status(), p.controller_status(), "{label}");
    assert_eq!(k.states(), p.states(), "{label}");
    assert_eq!(k.gate(), p.gate(), "{label}");
    assert_eq!(k.bridge_counters(), p.bridge_counters(), "{label}");
    assert_eq!(k.counters(), p.counters(), "{label}");
    r
}

#[test]
fn task_graph_matches_the_synchronous_core() {
    let t = GenTiming::default();
    for ctrl in PROTOCOLS {
        for head in PROTOCOLS {
            for timing in [Timing::FreeRunning, Timing::Slaved] {
                if head == Protocol::Hans && timing == Timing::Slaved {
                    continue;
                }
                let c = config(ctrl, head, timing);
                let sent = frames(&c, &t, 120);
                let mut stim = stimulus::controller_signal(&c, &sent, &t).unwrap();
                // A clock / line gap makes the fail-safe path run too.
                let line = if ctrl == Protocol::Hans {
                    roles::HANS_CHANNELS[0]
                } else {
                    roles::CLK
                };
                impair::gap(&mut stim.wave, line, 600_000_000, 800_000_000, false).unwrap();
                let items =
                    stimulus::capture(&c, &stim.wave, Options::default().hans_sample_hz, 0.2)
                        .unwrap();
                let items = stimulus::chunk(items, 2_000);
                let status: Vec<Timed> = match head {
                    Protocol::Xy2 => stimulus::level_samples(1_500_000, 10_000, |t| t > 900_000),
                    Protocol::Xy3 => head_back(115_200, 100, 1_200, 500, Alarms::TEMPERATURE),
                    Protocol::Hans => head_hans_status(100, 1_000, Alarms::POWER, 40_000_000),
                };
                let items = stimulus::merge(vec![items, status]);
                let r = same_as_tasks(
                    &c,
                    &items,
                    1_600_000,
                    &format!("{ctrl:?} -> {head:?} {timing:?}"),
                );
                assert!(!r.core.sent().is_empty(), "{ctrl:?} -> {head:?} {timing:?}");
            }
        }
    }
}

/// Tasks that wait only for time must be woken by the clock alone (a real
/// executor polls a task only after a wake): after the controller's last frame
/// nothing but the clock moves, yet the supervisor checks at each of its periods
/// and the bridge runs its output and fail-safe (input lost, hold, then park) up
/// to the end. With no buffers at all, the same.
#[test]
fn task_graph_runs_on_time_alone() {
    let t = GenTiming::default();
    for head in PROTOCOLS {
        let mut c = config(Protocol::Xy2, head, Timing::FreeRunning);
        c.failsafe.hold_us = 2_000;
        let label = format!("Xy2 -> {head:?}");
        let sent = frames(&c, &t, 30);
        let stim = stimulus::controller_signal(&c, &sent, &t).unwrap();
        let items =
            stimulus::capture(&c, &stim.wave, Options::default().hans_sample_hz, 0.2).unwrap();
        let items = stimulus::chunk(items, 2_000);
        let last = items.last().map(|it| it.t_ns).unwrap();
        let end = last + 5_000_000;
        let r = same_as_tasks(&c, &items, end, &label);
        assert_eq!(r.core.now_ns(), end, "{label}");
        let states = r.core.states();
        assert!(
            states.iter().any(|s| s.value == LinkState::Running),
            "{label}: {states:?}"
        );
        for lost in [LinkState::Holding, LinkState::Safe] {
            assert!(
                states.iter().any(|s| s.t_ns > last && s.value == lost),
                "{label}: no {lost:?} after the last buffer at {last} ns: {states:?}"
            );
        }
        assert!(
            r.core.gate().iter().all(|g| g.t_ns <= last || !g.value),
            "{label}: {:?}",
            r.core.gate()
        );
        // Free-running slots keep coming after the input stopped.
        let slots_after = r
            .core
            .sent()
            .iter()
            .filter(|f| f.decided_ns > last + 1_000_000);
        assert!(slots_after.count() > 100, "{label}");

        let r = same_as_tasks(&c, &[], 2_000_000, &format!("{label}, no buffers"));
        assert_eq!(r.core.now_ns(), 2_000_000, "{label}");
        assert_eq!(r.checks, 40, "{label}");
    }
}

/// A buffer the graph cannot take stops the run with the pipeline's error, not a
/// panic or a hang.
#[test]
fn task_graph_reports_bad_input() {
    let c = config(Protocol::Xy2, Protocol::Xy3, Timing::FreeRunning);
    let items = [Timed {
        t_ns: 10_000,
        buffers: stimulus::Buffers::Hans(Default::default()),
    }];
    let e = tasks::run(&c, Options::default(), &items, 100_000).err();
    assert!(
        matches!(
            e,
            Some(TaskError::Pipeline(PipelineError::WrongInput { .. }))
        ),
        "{e:?}"
    );
    let msg = e.map(|e| e.to_string()).unwrap_or_default();
    assert!(msg.contains("input is"), "{msg}");
}

/// Added latency (simulated time, so exact): slaved output within the modelled
/// 1 us turnaround plus the receiver's own delay; free-running output one slot
/// ahead (two for the HANS-100 ring) plus up to one slot of phase.
/// Decoded periods a new HANS-100 lock publishes nothing in
/// (`shared::hans::rx::timing::SETTLED` edges, two of them the hunt's).
const HANS_ACQUISITION: usize = 6;

#[test]
fn latency_bounds() {
    use host_tests::pipeline::latency::{config, measure};
    for ctrl in PROTOCOLS {
        for head in PROTOCOLS {
            // An XY3-100 input's good period waits for the next one to confirm
            // it (`shared::xy3::step`): one frame period more.
            let confirm = if ctrl == Protocol::Xy3 { 1.0 } else { 0.0 };
            let lead = if head == Protocol::Hans { 2.0 } else { 1.0 } + confirm;
            // A HANS-100 controller's acquisition takes six more frames.
            let n = if ctrl == Protocol::Hans { 40 } else { 30 };
            let l = measure(&config(ctrl, head, Timing::FreeRunning), 4, n).unwrap();
            let label = format!("{ctrl:?} -> {head:?}: {l:?}");
            assert!(l.frames >= 60, "{label}");
            assert!(l.min_ns >= lead * 10_000.0, "{label}");
            assert!(l.max_ns < (lead + 1.0) * 10_000.0 + 1_000.0, "{label}");
            assert!(
                l.max_ns - l.min_ns >= 7_000.0,
                "{label}: the phase sweep shows"
            );
            if head != Protocol::Hans {
                let s = measure(&config(ctrl, head, Timing::Slaved), 2, 30).unwrap();
                let c = confirm * 10_000.0;
                assert!(
                    s.min_ns >= 1_000.0 + c && s.max_ns < 2_000.0 + c,
                    "{ctrl:?} -> {head:?}: {s:?}"
                );
            }
        }
    }
}

/// Head alarms reach the controller in its protocol, for every head status form
/// and every controller status form, decoded on both sides with `shared`'s
/// receivers; the laser gate drops with the head alarm.
#[test]
fn head_alarm_reaches_the_controller() {
    use shared::bridge::StatusForm;
    use shared::xy2::StatusWord;
    let forms = [
        (Protocol::Xy2, StatusForm::Level),
        (Protocol::Xy2, StatusForm::Word),
        (Protocol::Xy3, StatusForm::Level),
        (Protocol::Hans, StatusForm::Level),
    ];
    let alarm_at: u64 = 2_000_000;
    for (head, hform) in forms {
        for (ctrl, cform) in forms {
            let mut c = config(ctrl, head, Timing::FreeRunning);
            // Supervised (the default): the gate waits for the head's first status.
            c.failsafe.status_timeout_us = FailSafe::default().status_timeout_us;
            c.head.xy2.status = hform;
            c.controller.xy2.status = cform;
            let label = format!("{head:?} {hform:?} -> {ctrl:?} {cform:?}");
            let t = GenTiming::default();
            let sent = frames(&c, &t, 400);
            let end = 4_000_000;
            let status: Vec<Timed> = match (head, hform) {
                (Protocol::Xy2, StatusForm::Level) => {
                    stimulus::level_samples(end, 10_000, |t| t >= alarm_at)
                }
                (Protocol::Xy2, _) => {
                    let link = shared::xy2::LinkConfig {
                        mode: c.head.xy2.mode,
                        parity: c.head.xy2.parity,
                    };
                    let ok = stimulus::status_words(StatusWord::ALL_OK, &link, 20, 400);
                    let hot = StatusWord::from_alarms(Alarms::TEMPERATURE);
                    let bad = stimulus::status_words(hot, &link, 20, 400);
                    ok.into_iter()
                        .zip(bad)
                        .map(|(o, b)| if o.t_ns <= alarm_at { o } else { b })
                        .collect()
                }
                (Protocol::Xy3, _) => {
                    let mut v = head_back(115_200, 100, 2_000, 500, Alarms::NONE);
                    v.extend(head_back(115_200, 2_000, 4_000, 500, Alarms::TEMPERATURE));
                    v
                }
                _ => {
                    let fs = Options::default().hans_status_sample_hz;
                    let mut v = head_hans_status(0, 2_000, Alarms::NONE, fs);
                    v.retain(|x| x.t_ns < alarm_at);
                    v.extend(head_hans_status(2_000, 4_000, Alarms::TEMPERATURE, fs));
                    v
                }
            };
            let first_status = status.iter().map(|s| s.t_ns).min().unwrap_or(u64::MAX);
            let (p, _stim, view) = run(&c, &t, &sent, |_| {}, status, 50_000);
            assert_output_is_sent(&c, &p, &view, &label);
            let k = p.counters();
            assert!(k.status_items > 5, "{label}: {k:?}");
            // (An XY3-100 controller's UART needs ~1 ms for the first packets.)
            let before = controller_alarms(&c, &p, 1_200_000, alarm_at);
            assert!(!before.any(), "{label}: {before:?} before the alarm");
            let after = controller_alarms(&c, &p, alarm_at, end);
            // What each path can say: an XY2 level only "fault" (electrical on the
            // way in, a fault level on the way out).
            let want = match (head, hform, ctrl, cform) {
                (_, _, Protocol::Xy2, StatusForm::Level) => Alarms::INPUT_LOST,
                (Protocol::Xy2, StatusForm::Level, Protocol::Xy2, _) => Alarms::POWER,
                (Protocol::Xy2, StatusForm::Level, Protocol::Hans, _) => Alarms::POWER,
                (Protocol::Xy2, StatusForm::Level, _, _) => Alarms::ELECTRICAL,
                _ => Alarms::TEMPERATURE,
            };
            assert!(after.contains(want), "{label}: {after:?}, want {want:?}");
            // The gate: on while running with a healthy head, off with the alarm.
            let gate: Vec<(u64, bool)> = p.gate().iter().map(|g| (g.t_ns, g.value)).collect();
            assert_eq!(gate.len(), 3, "{label}: {gate:?}");
            assert!(gate[1].1 && !gate[2].1, "{label}: {gate:?}");
            // Not before the link runs and the head's first status is in. A
            // backchannel head's first packet (from 0.18 ms, ~0.6 ms at 115200
            // baud) comes after the link runs (0.21 ms): the gate waits for it.
            let running_at = p.states()[1].t_ns;
            assert!(
                gate[1].0 >= running_at.max(first_status),
                "{label}: {gate:?} running at {running_at}, first status {first_status}"
            );
            if head == Protocol::Xy3 {
                assert!(gate[1].0 > running_at, "{label}: {gate:?}");
            }
            // (A backchannel head needs ~0.6 ms at 115200 baud for SYNC + packet.)
            assert!(
                gate[2].0 >= alarm_at && gate[2].0 < alarm_at + 700_000,
                "{label}: {gate:?}"
            );
            assert_eq!(p.bridge().state(), LinkState::Running, "{label}");
        }
    }
}
