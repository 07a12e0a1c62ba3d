//! Unit tests of the bridge: configuration rules, the supervision state machine
//! with exact timings, translation and command / laser handling. Pairings through
//! the codecs, status back-translation and the fault campaign are in
//! `host-tests/tests/bridge_engine.rs`.

use super::*;
use crate::model::Position;
use crate::model::{Alarms, Axis, Command, FaultKind, ForwardFrame, LaserControl, Line, LineEvent};
use crate::xy2::{Mode, Parity};
use crate::xy3::rx::Lines;
use crate::xy3::{BackRate, FrameSize};

const US: u64 = 1_000;
const MS: u64 = 1_000_000;
/// Input frame period, 100 kHz.
const FP: u64 = 10 * US;

fn pos(raw: u32, bits: u8) -> Position {
    Position::from_raw(raw, bits).unwrap()
}

fn xyz16(x: u16, y: u16, z: u16) -> ForwardFrame {
    let mut f = ForwardFrame::default();
    f.axes[0] = Some(pos(x.into(), 16));
    f.axes[1] = Some(pos(y.into(), 16));
    f.axes[2] = Some(pos(z.into(), 16));
    f
}

fn ev(f: ForwardFrame) -> LineEvent {
    LineEvent::Frame(f)
}

fn fault() -> LineEvent {
    LineEvent::Fault {
        line: Line::Axis(Axis::X),
        kind: FaultKind::CheckFailed,
    }
}

fn raw(out: &Output, axis: Axis, bits: u8) -> Option<u32> {
    out.frame.and_then(|f| f.axis(axis)).map(|p| p.to_raw(bits))
}

/// A running bridge (XY2 -> XY2 by default) whose last valid frame arrived at the
/// returned time, with the head's status seen (no alarm) at 0.
fn running(cfg: &Config) -> (Bridge, u64) {
    let mut b = Bridge::new(cfg).unwrap();
    b.status_seen(0);
    let mut t = 0;
    for i in 0..cfg.failsafe.recovery_frames {
        t = u64::from(i) * FP;
        b.on_line_event(t, ev(xyz16(0x1000, 0x2000, 0x3000)));
    }
    assert_eq!(b.state(), LinkState::Running);
    (b, t)
}

// ---------------------------------------------------------------- configuration

#[test]
fn default_config_is_valid_and_repeats_xy2() {
    let c = Config::default();
    assert_eq!(c.validate(), Ok(()));
    assert_eq!(c.controller.protocol, Protocol::Xy2);
    assert_eq!(c.head.protocol, Protocol::Xy2);
    assert_eq!(c.failsafe.input_timeout_us, 1_000);
    assert_eq!(c.output.frame_rate_hz, 100_000);
}

#[test]
fn every_rule_names_its_key() {
    type Edit = fn(&mut Config);
    #[rustfmt::skip]
    let cases: &[(Edit, ConfigError, &str)] = &[
        (|c| c.head.xy2.mode = Mode::Extended18,
            ConfigError::EnhancedCommandsIn18Bit, "head.xy2.enhanced_commands"),
        (|c| c.controller.xy2.parity = Parity::Ignore,
            ConfigError::UncheckedInput, "controller.xy2.parity"),
        (|c| c.output.frame_rate_hz = 200_001,
            ConfigError::FrameRate(200_001), "output.frame_rate_hz"),
        (|c| c.output.frame_rate_hz = 999,
            ConfigError::FrameRate(999), "output.frame_rate_hz"),
        (|c| { c.head.protocol = Protocol::Hans; c.output.frame_rate_hz = 200_000 },
            ConfigError::HansFixedRate(200_000), "output.frame_rate_hz"),
        (|c| { c.head.protocol = Protocol::Hans; c.output.timing = Timing::Slaved },
            ConfigError::HansNotSlavable, "output.timing"),
        (|c| { c.controller.protocol = Protocol::Hans; c.controller.hans.decode = HansDecode::Normal(0) },
            ConfigError::HansChannel(0), "controller.hans.decode"),
        (|c| { c.controller.protocol = Protocol::Hans; c.controller.hans.decode = HansDecode::Vote3([1, 6, 2]) },
            ConfigError::HansChannel(6), "controller.hans.decode"),
        (|c| { c.controller.protocol = Protocol::Hans; c.controller.hans.decode = HansDecode::Vote3([1, 3, 1]) },
            ConfigError::Vote3NotDistinct([1, 3, 1]), "controller.hans.decode"),
        (|c| c.laser.gate = GateSource::HansMoPa,
            ConfigError::GateNeedsHans, "laser.gate"),
        (|c| { c.controller.protocol = Protocol::Xy3; c.controller.xy3.lines = xy3_lines(&[Axis::X, Axis::Z]) },
            ConfigError::Xy3LinesWithoutY, "controller.xy3.lines"),
        (|c| { c.controller.protocol = Protocol::Xy3; c.controller.xy3.lines = xy3_lines(&[Axis::X, Axis::Y, Axis::U]) },
            ConfigError::Xy3ZNotDriven, "controller.xy3.lines"),
        (|c| c.axes.offset_y = 0x1_0000,
            ConfigError::OutOfRange { key: "axes.offset_y", value: 0x1_0000, min: -0xFFFF, max: 0xFFFF },
            "axes.offset_y"),
        (|c| c.z.fixed = 0x10_0000,
            ConfigError::OutOfRange { key: "z.fixed", value: 0x10_0000, min: 0, max: 0xF_FFFF }, "z.fixed"),
        (|c| c.failsafe.input_timeout_us = 9,
            ConfigError::OutOfRange { key: "failsafe.input_timeout_us", value: 9, min: 10, max: 1_000_000 },
            "failsafe.input_timeout_us"),
        (|c| c.failsafe.park_y = 0x10_0000,
            ConfigError::OutOfRange { key: "failsafe.park_y", value: 0x10_0000, min: 0, max: 0xF_FFFF },
            "failsafe.park_y"),
        (|c| c.failsafe.park_u = 0x10_0000,
            ConfigError::OutOfRange { key: "failsafe.park_u", value: 0x10_0000, min: 0, max: 0xF_FFFF },
            "failsafe.park_u"),
        // Checked whatever the head: a file is wrong or right on its own.
        (|c| c.failsafe.park_w = u32::MAX,
            ConfigError::OutOfRange { key: "failsafe.park_w", value: 0xFFFF_FFFF, min: 0, max: 0xF_FFFF },
            "failsafe.park_w"),
        (|c| c.failsafe.recovery_frames = 0,
            ConfigError::OutOfRange { key: "failsafe.recovery_frames", value: 0, min: 1, max: 1_000_000 },
            "failsafe.recovery_frames"),
        (|c| c.failsafe.status_timeout_us = 999,
            ConfigError::OutOfRange { key: "failsafe.status_timeout_us", value: 999, min: 1_000, max: 10_000_000 },
            "failsafe.status_timeout_us"),
        (|c| c.failsafe.hold_us = 10_000_001,
            ConfigError::OutOfRange { key: "failsafe.hold_us", value: 10_000_001, min: 0, max: 10_000_000 },
            "failsafe.hold_us"),
    ];
    for (edit, want, key) in cases {
        let mut c = Config::default();
        edit(&mut c);
        assert_eq!(c.validate(), Err(*want), "{key}");
        assert_eq!(want.key(), *key);
        let text = std::format!("{want}");
        assert!(text.starts_with(key), "{text}");
        assert!(Bridge::new(&c).is_err());
    }
}

fn xy3_lines(axes: &[Axis]) -> Lines {
    Lines::new(axes).unwrap()
}

#[test]
fn xy3_lines_what_the_bridge_receives() {
    use Axis::{U, W, X, Y, Z};
    let mut c = Config::default();
    c.controller.protocol = Protocol::Xy3;
    // The default: X, Y, and Z while the bridge takes Z from the input (as before
    // the key existed).
    assert_eq!(c.controller.xy3.lines, Lines::XYZ);
    assert_eq!(c.xy3_input_lines(), Lines::XYZ);
    c.z.source = ZSource::Fixed;
    assert_eq!(c.validate(), Ok(()));
    assert_eq!(c.xy3_input_lines(), Lines::XY);
    // A controller without a Z line is fine once Z does not come from the input.
    c.controller.xy3.lines = xy3_lines(&[X, Y]);
    assert_eq!(c.validate(), Ok(()));
    c.z.source = ZSource::None;
    assert_eq!(c.validate(), Ok(()));
    assert_eq!(c.xy3_input_lines(), Lines::XY);
    // U and W reach only an XY3-100 head, so only then are they received.
    c.controller.xy3.lines = Lines::ALL;
    c.z.source = ZSource::Input;
    assert_eq!(c.validate(), Ok(()));
    assert_eq!(c.xy3_input_lines(), Lines::XYZ);
    c.head.protocol = Protocol::Xy3;
    assert_eq!(c.xy3_input_lines(), Lines::ALL);
    c.controller.xy3.lines = xy3_lines(&[W, Y, X]);
    c.z.source = ZSource::Fixed;
    assert_eq!(c.validate(), Ok(()));
    assert_eq!(c.xy3_input_lines(), xy3_lines(&[X, Y, W]));
    assert!(Bridge::new(&c).is_ok());
    // X always stays in a set.
    assert_eq!(Lines::XY.without(X), Lines::XY);
    assert_eq!(Lines::ALL.without(U).without(Z), xy3_lines(&[X, Y, W]));
    // The lines of another controller protocol are not checked.
    c.controller.protocol = Protocol::Xy2;
    c.controller.xy3.lines = xy3_lines(&[X]);
    c.z.source = ZSource::Input;
    assert_eq!(c.validate(), Ok(()));
}

#[test]
fn xy3_head_lines_follow_the_received_lines() {
    use Axis::{W, X, Y, Z};
    let mut c = Config::default();
    c.head.protocol = Protocol::Xy3;
    // XY2-100 controller: no U / W source, so X Y Z (Z unless `z.source = "none"`).
    assert_eq!(c.xy3_head_lines(), Lines::XYZ);
    c.z.source = ZSource::None;
    assert_eq!(c.xy3_head_lines(), Lines::XY);
    c.z.source = ZSource::Fixed;
    assert_eq!(c.xy3_head_lines(), Lines::XYZ);
    // XY3-100 controller: U / W driven exactly when received.
    c.controller.protocol = Protocol::Xy3;
    c.controller.xy3.lines = Lines::ALL;
    assert_eq!(c.xy3_head_lines(), Lines::ALL);
    c.controller.xy3.lines = xy3_lines(&[X, Y, W]);
    assert_eq!(c.xy3_head_lines(), xy3_lines(&[X, Y, Z, W]));
    c.z.source = ZSource::None;
    assert_eq!(c.xy3_head_lines(), xy3_lines(&[X, Y, W]));
    // A HANS-100 controller's lines key is not used.
    c.controller.protocol = Protocol::Hans;
    c.controller.xy3.lines = Lines::ALL;
    assert_eq!(c.xy3_head_lines(), Lines::XY);
}

/// An XY3 -> XY3 bridge on all five lines, 20-bit positions.
fn five_lines() -> Config {
    let mut c = Config::default();
    c.controller.protocol = Protocol::Xy3;
    c.controller.xy3.lines = Lines::ALL;
    c.head.protocol = Protocol::Xy3;
    c.failsafe.park_u = 0x1_1111;
    c.failsafe.park_w = 0xE_EEEE;
    c.failsafe.recovery_frames = 3;
    c
}

fn xyzuw20(v: [u32; 5]) -> ForwardFrame {
    ForwardFrame {
        axes: v.map(|r| Some(pos(r, 20))),
        ..ForwardFrame::default()
    }
}

#[test]
fn u_and_w_forwarded_held_and_parked() {
    use Axis::{U, W, X};
    let c = five_lines();
    let mut b = Bridge::new(&c).unwrap();
    // Power-up: the park frame carries U and W at their park positions.
    let out = b.tick(0);
    assert_eq!(out.state, LinkState::Safe);
    assert_eq!(raw(&out, U, 20), Some(0x1_1111));
    assert_eq!(raw(&out, W, 20), Some(0xE_EEEE));
    assert_eq!(raw(&out, X, 20), Some(0x8_0000));
    for i in 0..3 {
        b.on_line_event(
            i * FP,
            ev(xyzuw20([1, 2, 3, 0x4_0000 + i as u32, 0x5_0000])),
        );
    }
    let out = b.tick(2 * FP + 1);
    assert_eq!(out.state, LinkState::Running);
    assert_eq!(raw(&out, U, 20), Some(0x4_0002));
    assert_eq!(raw(&out, W, 20), Some(0x5_0000));
    // Holding: the last received U / W; safe: park again.
    let out = b.tick(2 * FP + MS);
    assert_eq!(out.state, LinkState::Holding);
    assert_eq!(raw(&out, U, 20), Some(0x4_0002));
    assert_eq!(raw(&out, W, 20), Some(0x5_0000));
    let out = b.tick(2 * FP + 11 * MS);
    assert_eq!(out.state, LinkState::Safe);
    assert_eq!(raw(&out, U, 20), Some(0x1_1111));
    assert_eq!(raw(&out, W, 20), Some(0xE_EEEE));
    // 32-bit head: the park position resized to 26 bits.
    let mut c32 = five_lines();
    c32.head.xy3.frame_size = FrameSize::Bits32;
    let out = Bridge::new(&c32).unwrap().tick(0);
    assert_eq!(raw(&out, U, 26), Some(0x1_1111 << 6));
    assert_eq!(raw(&out, W, 26), Some(0xE_EEEE << 6));
}

#[test]
fn park_has_no_u_or_w_where_the_head_does_not_drive_them() {
    use Axis::{U, W};
    // Only W received: U has no park position (the head does not drive it).
    let mut c = five_lines();
    c.controller.xy3.lines = xy3_lines(&[Axis::X, Axis::Y, Axis::Z, W]);
    let out = Bridge::new(&c).unwrap().tick(0);
    assert_eq!((raw(&out, U, 20), raw(&out, W, 20)), (None, Some(0xE_EEEE)));
    // Other heads and controllers: none at all.
    for (ctrl, head) in [
        (Protocol::Xy2, Protocol::Xy3),
        (Protocol::Xy3, Protocol::Xy2),
        (Protocol::Xy3, Protocol::Hans),
    ] {
        let mut c = five_lines();
        c.controller.protocol = ctrl;
        c.head.protocol = head;
        let out = Bridge::new(&c).unwrap().tick(0);
        assert!(out.frame.is_some(), "{ctrl:?} -> {head:?}");
        assert_eq!((raw(&out, U, 20), raw(&out, W, 20)), (None, None));
    }
}

#[test]
fn valid_corner_configurations() {
    let mut c = Config::default();
    c.head.xy2.mode = Mode::Extended18;
    c.head.xy2.enhanced_commands = false;
    c.controller.protocol = Protocol::Hans;
    c.controller.hans.decode = HansDecode::Vote3([5, 1, 3]);
    c.laser.gate = GateSource::HansMoPa;
    c.output.frame_rate_hz = 200_000;
    c.failsafe.status_timeout_us = 0;
    c.failsafe.hold_us = 0;
    c.axes.offset_x = -0x3_FFFF;
    assert_eq!(c.validate(), Ok(()));
    // Options of protocols not in use are not checked.
    c.controller.xy2.parity = Parity::Ignore;
    assert_eq!(c.validate(), Ok(()));
    // Offsets are in head LSBs: 26-bit XY3 heads allow larger ones.
    let mut c = Config::default();
    c.head.protocol = Protocol::Xy3;
    c.head.xy3.frame_size = FrameSize::Bits32;
    c.axes.offset_z = 0x3FF_FFFF;
    assert_eq!(c.validate(), Ok(()));
}

#[test]
fn head_widths() {
    let mut h = HeadSide::default();
    assert_eq!(h.width(Axis::X), 16);
    h.xy2.mode = Mode::Extended18;
    assert_eq!(h.width(Axis::Z), 18);
    h.protocol = Protocol::Xy3;
    assert_eq!(h.width(Axis::U), 20);
    h.xy3.frame_size = FrameSize::Bits32;
    assert_eq!(h.width(Axis::Y), 26);
    h.protocol = Protocol::Hans;
    assert_eq!(
        (h.width(Axis::X), h.width(Axis::Y), h.width(Axis::Z)),
        (20, 20, 16)
    );
}

// ---------------------------------------------------------------- supervision

#[test]
fn power_up_is_safe_until_n_valid_frames() {
    let cfg = Config::default();
    let mut b = Bridge::new(&cfg).unwrap();
    let out = b.tick(0);
    assert_eq!(out.state, LinkState::Safe);
    assert!(out.alarms.contains(Alarms::INPUT_LOST));
    assert!(!out.laser.gate);
    // Park at the centre (default), 16-bit head.
    assert_eq!(raw(&out, Axis::X, 16), Some(0x8000));
    for i in 0..99u16 {
        assert_eq!(b.on_line_event(u64::from(i) * FP, ev(xyz16(i, i, i))), None);
        assert_eq!(b.tick(u64::from(i) * FP + 1).state, LinkState::Safe);
    }
    assert_eq!(b.counters().not_forwarded, 99);
    b.on_line_event(99 * FP, ev(xyz16(0x1234, 0x5678, 0x9ABC)));
    let out = b.tick(99 * FP + 1);
    assert_eq!(out.state, LinkState::Running);
    assert_eq!(out.alarms, Alarms::NONE);
    assert!(!out.laser.gate, "no head status seen yet");
    assert_eq!(raw(&out, Axis::X, 16), Some(0x1234));
    assert_eq!(raw(&out, Axis::Z, 16), Some(0x9ABC));
    assert_eq!(b.counters().recoveries, 1);
    b.status_seen(99 * FP + 2);
    assert!(b.tick(100 * FP).laser.gate);
}

#[test]
fn gate_waits_for_the_first_head_status() {
    // The default: watchdog on (200 ms), `off_on_head_alarm`.
    let cfg = Config::default();
    let mut b = Bridge::new(&cfg).unwrap();
    let mut t = 0;
    for i in 0..cfg.failsafe.recovery_frames {
        t = u64::from(i) * FP;
        b.on_line_event(t, ev(xyz16(1, 2, 3)));
    }
    // Running, the input kept alive, no status: the gate stays off, and the wait is
    // no alarm until the watchdog's timeout.
    while t + FP < 200 * MS {
        t += FP;
        b.on_line_event(t, ev(xyz16(1, 2, 3)));
        let out = b.tick(t + 1);
        assert_eq!(out.state, LinkState::Running);
        assert_eq!(out.alarms, Alarms::NONE, "at {t} ns");
        assert!(!out.laser.gate, "at {t} ns");
    }
    // The first status reports an alarm: still off.
    b.head_status_mut().alarms = Alarms::TEMPERATURE;
    b.status_seen(t + 2);
    assert!(!b.tick(t + 3).laser.gate);
    // The alarm clears: on.
    b.head_status_mut().alarms = Alarms::NONE;
    b.status_seen(t + 4);
    assert!(b.tick(t + 5).laser.gate);

    // No status at all: `STATUS_LOST` at the timeout, and the gate never opened.
    let mut b = Bridge::new(&cfg).unwrap();
    let mut t = 0;
    let mut lost_at = None;
    while t < 201 * MS {
        b.on_line_event(t, ev(xyz16(1, 2, 3)));
        let out = b.tick(t + 1);
        assert!(!out.laser.gate, "at {t} ns");
        if lost_at.is_none() && out.alarms.contains(Alarms::STATUS_LOST) {
            lost_at = Some(t + 1);
        }
        t += FP;
    }
    // The watchdog counts from the first time the bridge saw the clock (0).
    assert_eq!(lost_at, Some(200 * MS + 1));

    // A status seen before the link runs counts: the gate opens with `Running`.
    let mut b = Bridge::new(&cfg).unwrap();
    b.status_seen(0);
    for i in 0..cfg.failsafe.recovery_frames {
        let t = u64::from(i) * FP;
        b.on_line_event(t, ev(xyz16(1, 2, 3)));
        assert_eq!(
            b.tick(t + 1).laser.gate,
            i + 1 == cfg.failsafe.recovery_frames
        );
    }

    // Without `off_on_head_alarm`, or with the watchdog off (no status expected),
    // the link alone opens the gate.
    for (off_on_alarm, timeout_us) in [(false, 200_000), (true, 0)] {
        let mut cfg = Config::default();
        cfg.laser.off_on_head_alarm = off_on_alarm;
        cfg.failsafe.status_timeout_us = timeout_us;
        let mut b = Bridge::new(&cfg).unwrap();
        for i in 0..cfg.failsafe.recovery_frames {
            b.on_line_event(u64::from(i) * FP, ev(xyz16(1, 2, 3)));
        }
        let out = b.tick(100 * FP);
        assert_eq!(out.state, LinkState::Running);
        assert!(out.laser.gate, "{off_on_alarm} {timeout_us}");
    }
}

#[test]
fn timeout_hold_park_with_exact_timings() {
    let cfg = Config::default();
    let (mut b, t0) = running(&cfg);
    let t = 1_000 * US;
    let h = 10 * MS;
    let out = b.tick(t0 + t - 1);
    assert_eq!(out.state, LinkState::Running);
    assert!(out.laser.gate);
    let out = b.tick(t0 + t);
    assert_eq!(out.state, LinkState::Holding);
    assert!(out.alarms.contains(Alarms::INPUT_LOST));
    assert!(!out.laser.gate);
    assert_eq!(
        raw(&out, Axis::Y, 16),
        Some(0x2000),
        "holds the last position"
    );
    assert_eq!(b.counters().input_losses, 1);
    assert_eq!(b.tick(t0 + t + h - 1).state, LinkState::Holding);
    let out = b.tick(t0 + t + h);
    assert_eq!(out.state, LinkState::Safe);
    assert_eq!(raw(&out, Axis::Y, 16), Some(0x8000), "parked");
    assert!(out.alarms.contains(Alarms::INPUT_LOST));
}

#[test]
fn stop_policy_sends_nothing_and_late_poll_skips_hold() {
    let mut cfg = Config::default();
    cfg.failsafe.after_hold = AfterHold::Stop;
    cfg.failsafe.park_x = 0;
    let (mut b, t0) = running(&cfg);
    // The first poll comes long after timeout + hold: straight to Safe.
    let out = b.tick(t0 + 50 * MS);
    assert_eq!(out.state, LinkState::Safe);
    assert_eq!(out.frame, None);
    assert_eq!(b.counters().input_losses, 1);
}

#[test]
fn zero_hold_parks_at_the_timeout() {
    let mut cfg = Config::default();
    cfg.failsafe.hold_us = 0;
    cfg.failsafe.park_x = 0;
    let (mut b, t0) = running(&cfg);
    let out = b.tick(t0 + MS);
    assert_eq!(out.state, LinkState::Safe);
    assert_eq!(raw(&out, Axis::X, 16), Some(0));
}

#[test]
fn recovery_needs_n_consecutive_valid_frames() {
    let mut cfg = Config::default();
    cfg.failsafe.recovery_frames = 10;
    let (mut b, t0) = running(&cfg);
    let mut t = t0 + 2 * MS;
    assert_eq!(b.tick(t).state, LinkState::Holding);
    // 9 valid, a fault, 9 valid: still holding.
    for i in 0..19 {
        t += FP;
        let e = if i == 9 { fault() } else { ev(xyz16(7, 7, 7)) };
        assert_eq!(b.on_line_event(t, e), None);
        assert_eq!(b.state(), LinkState::Holding, "frame {i}");
    }
    // A gap of the timeout also breaks the run.
    t += MS;
    b.on_line_event(t, ev(xyz16(7, 7, 7)));
    assert_eq!(b.state(), LinkState::Holding);
    for _ in 0..9 {
        t += FP;
        b.on_line_event(t, ev(xyz16(8, 8, 8)));
    }
    assert_eq!(b.state(), LinkState::Running);
    let out = b.tick(t + 1);
    assert_eq!(raw(&out, Axis::X, 16), Some(8));
    assert_eq!(b.counters().recoveries, 2);
    // Head-side faults do not break a run.
    let (mut b, t0) = running(&cfg);
    let mut t = t0 + 2 * MS;
    b.tick(t);
    for i in 0..10 {
        t += FP;
        b.on_line_event(t, ev(xyz16(1, 1, 1)));
        let line = if i % 2 == 0 {
            Line::Status
        } else {
            Line::Backchannel
        };
        b.on_line_event(
            t,
            LineEvent::Fault {
                line,
                kind: FaultKind::Framing,
            },
        );
    }
    assert_eq!(b.state(), LinkState::Running);
    assert_eq!(b.counters().line(Line::Status).framing, 5);
}

fn hans_fault(line: Line, kind: FaultKind) -> LineEvent {
    LineEvent::Fault { line, kind }
}

/// A HANS-100 controller in `decode`, running, then holding after an input loss.
fn hans_holding(decode: HansDecode) -> (Bridge, u64) {
    let mut cfg = Config::default();
    cfg.controller.protocol = Protocol::Hans;
    cfg.controller.hans.decode = decode;
    cfg.failsafe.recovery_frames = 10;
    let (mut b, t0) = running(&cfg);
    let t = t0 + 2 * MS;
    assert_eq!(b.tick(t).state, LinkState::Holding);
    (b, t)
}

/// Vote and super modes: backup channels that fault every period, in every way a
/// channel can (missing, check failed, minority, resync), while the mode publishes
/// a verified frame each period: every fault is counted on its channel, and the
/// link recovers after exactly `N` frames, as with clean channels.
#[test]
fn noisy_backup_hans_channels_do_not_block_recovery() {
    let kinds = [
        FaultKind::Missing,
        FaultKind::CheckFailed,
        FaultKind::Disagree,
        FaultKind::Resync,
    ];
    for decode in [
        HansDecode::Vote3([1, 2, 3]),
        HansDecode::Vote5,
        HansDecode::Super,
    ] {
        let (mut b, mut t) = hans_holding(decode);
        for i in 0..10 {
            t += FP;
            assert_eq!(b.state(), LinkState::Holding, "{decode:?} period {i}");
            for (c, kind) in [(2, kinds[i % 4]), (3, kinds[(i + 1) % 4])] {
                b.on_line_event(t, hans_fault(Line::HansChannel(c), kind));
            }
            b.on_line_event(t, ev(xyz16(7, 7, 7)));
        }
        assert_eq!(b.state(), LinkState::Running, "{decode:?}");
        let c = b.counters();
        assert_eq!(c.recoveries, 2, "{decode:?}");
        for ch in [2, 3] {
            let l = c.line(Line::HansChannel(ch));
            assert_eq!(l.total(), 10, "{decode:?} CH{ch}: {l:?}");
            assert_eq!(
                [l.missing, l.check_failed, l.disagree, l.resyncs].map(|n| n >= 2),
                [true; 4],
                "{decode:?} CH{ch}: {l:?}"
            );
        }
        assert_eq!(c.line(Line::Framing), LineCounters::default());
    }
}

/// Vote and super modes: a period the receiver could not publish (vote failed, no
/// channel verified, no majority, timing lost, input dropped) breaks the run, so a
/// link whose every channel is noisy does not recover on scattered verified frames.
#[test]
fn lost_hans_periods_break_the_recovery_run() {
    let lost = [
        FaultKind::CheckFailed,
        FaultKind::Disagree,
        FaultKind::Resync,
        FaultKind::Dropped,
    ];
    for decode in [
        HansDecode::Vote3([1, 2, 3]),
        HansDecode::Vote5,
        HansDecode::Super,
    ] {
        for kind in lost {
            let (mut b, mut t) = hans_holding(decode);
            // Nine good periods, then one lost one every ninth: never ten in a row.
            for i in 0..50 {
                t += FP;
                if i % 10 == 9 {
                    b.on_line_event(t, hans_fault(Line::HansChannel(1), FaultKind::CheckFailed));
                    b.on_line_event(t, hans_fault(Line::Framing, kind));
                } else {
                    b.on_line_event(t, ev(xyz16(7, 7, 7)));
                }
                assert_eq!(b.state(), LinkState::Holding, "{decode:?} {kind:?} {i}");
            }
            // 9 of the start-up's run, then every frame here.
            assert_eq!(b.counters().not_forwarded, 9 + 45);
            // Ten clean periods recover it.
            for _ in 0..10 {
                t += FP;
                b.on_line_event(t, ev(xyz16(8, 8, 8)));
            }
            assert_eq!(b.state(), LinkState::Running, "{decode:?} {kind:?}");
        }
    }
}

/// Normal mode: the one channel's faults are the period's; each breaks the run.
#[test]
fn normal_mode_channel_faults_break_the_recovery_run() {
    for kind in [
        FaultKind::CheckFailed,
        FaultKind::Resync,
        FaultKind::Missing,
    ] {
        let (mut b, mut t) = hans_holding(HansDecode::Normal(4));
        for i in 0..50 {
            t += FP;
            if i % 10 == 9 {
                b.on_line_event(t, hans_fault(Line::HansChannel(4), kind));
            } else {
                b.on_line_event(t, ev(xyz16(7, 7, 7)));
            }
            assert_eq!(b.state(), LinkState::Holding, "{kind:?} {i}");
        }
        assert_eq!(b.counters().line(Line::HansChannel(4)).total(), 5);
    }
}

#[test]
fn faults_while_running_are_counted_never_forwarded() {
    let (mut b, t0) = running(&Config::default());
    let before = b.tick(t0 + 1);
    b.on_line_event(t0 + FP, fault());
    b.on_line_event(
        t0 + FP,
        LineEvent::Fault {
            line: Line::Framing,
            kind: FaultKind::Resync,
        },
    );
    let out = b.tick(t0 + FP + 1);
    assert_eq!(out.frame, before.frame, "a fault repeats the last frame");
    assert_eq!(out.state, LinkState::Running);
    let c = b.counters();
    assert_eq!(c.line(Line::Axis(Axis::X)).check_failed, 1);
    assert_eq!(c.line(Line::Framing).resyncs, 1);
    assert_eq!(c.repeated, 1);
    assert_eq!(c.axis_check_failures(), [1, 0, 0, 0, 0]);
}

#[test]
fn status_watchdog() {
    let mut cfg = Config::default(); // status timeout 200 ms
    cfg.failsafe.input_timeout_us = 1_000_000;
    let (mut b, t0) = running(&cfg);
    b.status_seen(t0);
    let out = b.tick(t0 + 200 * MS - 1);
    assert!(!out.alarms.contains(Alarms::STATUS_LOST));
    // Keep the input alive.
    b.on_line_event(t0 + 200 * MS - 1, ev(xyz16(1, 2, 3)));
    let out = b.tick(t0 + 200 * MS);
    assert!(out.alarms.contains(Alarms::STATUS_LOST));
    assert_eq!(out.state, LinkState::Running);
    assert!(!out.laser.gate, "status lost gates the laser off");
    assert_eq!(b.counters().status_losses, 1);
    b.status_seen(t0 + 200 * MS + 5);
    let out = b.tick(t0 + 200 * MS + 6);
    assert_eq!(out.alarms, Alarms::NONE);
    assert!(out.laser.gate);
}

#[test]
fn head_alarm_gates_laser_unless_configured_not_to() {
    for off in [true, false] {
        let mut cfg = Config::default();
        cfg.laser.off_on_head_alarm = off;
        let (mut b, t0) = running(&cfg);
        b.head_status_mut().alarms = Alarms::TEMPERATURE;
        let out = b.tick(t0 + 1);
        assert_eq!(out.laser.gate, !off);
        assert_eq!(
            out.alarms,
            Alarms::NONE,
            "head alarms are not the bridge's own"
        );
        assert_eq!(b.reported_alarms(), Alarms::TEMPERATURE);
    }
}

// ---------------------------------------------------------------- translation

#[test]
fn axis_map_swap_invert_offset_saturating() {
    let mut cfg = Config::default();
    cfg.head.protocol = Protocol::Xy3; // 20 bits
    cfg.axes.swap_xy = true;
    cfg.axes.invert_x = true;
    cfg.axes.offset_y = 0x10;
    cfg.axes.offset_z = -0x20;
    cfg.failsafe.recovery_frames = 1;
    cfg.output.timing = Timing::Slaved;
    let mut b = Bridge::new(&cfg).unwrap();
    #[rustfmt::skip]
    let rows: &[([u16; 3], [u32; 3])] = &[
        // controller 16-bit (x, y, z) -> head 20-bit (x, y, z)
        // x' = ~(y << 4) & 0xFFFFF, y' = (x << 4) + 0x10, z' = (z << 4) - 0x20
        ([0x0000, 0x0000, 0x0000], [0xF_FFFF, 0x0_0010, 0x0_0000]), // z clamps at 0
        ([0x8000, 0x8000, 0x8000], [0x7_FFFF, 0x8_0010, 0x7_FFE0]),
        ([0xFFFF, 0xFFFF, 0xFFFF], [0x0_000F, 0xF_FFFF, 0xF_FFD0]), // y clamps at full scale
        ([0x1234, 0xABCD, 0x0001], [0x5_432F, 0x1_2350, 0x0_0000]),
    ];
    for (i, &([x, y, z], want)) in rows.iter().enumerate() {
        let out = b.on_line_event(i as u64 * FP, ev(xyz16(x, y, z))).unwrap();
        let f = out.frame.unwrap();
        let got: [u32; 3] = [0, 1, 2].map(|a| f.axes[a].unwrap().to_raw(20));
        assert_eq!(got, want, "row {i}");
        assert!(f.axes.iter().take(3).all(|p| p.unwrap().bits() == 20));
    }
}

#[test]
fn z_source_fixed_and_none() {
    let mut cfg = Config::default();
    cfg.failsafe.recovery_frames = 1;
    cfg.output.timing = Timing::Slaved;
    cfg.z.source = ZSource::Fixed;
    cfg.z.fixed = 0x1_2348; // 20-bit; 16-bit head: 0x1234 + round(8/16) = 0x1235
    let mut b = Bridge::new(&cfg).unwrap();
    let out = b.on_line_event(0, ev(xyz16(1, 2, 3))).unwrap();
    assert_eq!(raw(&out, Axis::Z, 16), Some(0x1235));
    cfg.z.source = ZSource::None;
    let mut b = Bridge::new(&cfg).unwrap();
    let out = b.on_line_event(0, ev(xyz16(1, 2, 3))).unwrap();
    assert_eq!(out.frame.unwrap().axis(Axis::Z), None);
}

fn slaved(controller: Protocol, head: Protocol) -> Bridge {
    let mut cfg = Config::default();
    cfg.controller.protocol = controller;
    cfg.head.protocol = head;
    cfg.failsafe.recovery_frames = 1;
    if head != Protocol::Hans {
        cfg.output.timing = Timing::Slaved;
    }
    let mut b = Bridge::new(&cfg).unwrap();
    b.status_seen(0);
    b
}

/// Sends one frame and returns the output carrying it.
fn pass(b: &mut Bridge, t: u64, f: ForwardFrame) -> Output {
    match b.on_line_event(t, ev(f)) {
        Some(out) => out,
        None => b.tick(t + 1),
    }
}

#[test]
fn commands_carried_or_counted() {
    let rate = Command::Xy3(BackRate::B921600.code());
    let enh = Command::Xy2Enhanced {
        command: 5,
        parameter: 1,
    };
    #[rustfmt::skip]
    let cases = [
        // (controller, head, command, carried)
        (Protocol::Xy3, Protocol::Xy3, rate, true),
        (Protocol::Xy3, Protocol::Xy2, rate, false),
        (Protocol::Xy3, Protocol::Hans, rate, false),
        (Protocol::Xy2, Protocol::Xy2, enh, true),
        (Protocol::Xy2, Protocol::Xy3, enh, false),
        (Protocol::Xy2, Protocol::Hans, enh, false),
    ];
    for (c, h, cmd, carried) in cases {
        let mut b = slaved(c, h);
        let mut f = xyz16(1, 2, 3);
        f.command = Some(cmd);
        let out = pass(&mut b, 0, f);
        let frame = out.frame.unwrap();
        assert_eq!(frame.command.is_some(), carried, "{c:?}->{h:?}");
        assert_eq!(b.counters().commands_not_carried, u64::from(!carried));
        assert_eq!(b.counters().commands_forwarded, u64::from(carried));
        if cmd == rate {
            // The controller-side backchannel switches whatever the head is.
            assert_eq!(out.controller_back_rate, Some(BackRate::B921600));
            assert_eq!(b.controller_back_rate(), BackRate::B921600);
            let head = carried.then_some(BackRate::B921600);
            assert_eq!(out.head_back_rate, head);
        }
        // One-offs are not repeated.
        let again = b.tick(FP);
        if let Some(f) = again.frame {
            assert_eq!(f.command, None);
        }
    }
    // 18-bit XY2 head without enhanced commands: counted.
    let mut cfg = Config::default();
    cfg.head.xy2.mode = Mode::Extended18;
    cfg.head.xy2.enhanced_commands = false;
    cfg.failsafe.recovery_frames = 1;
    let mut b = Bridge::new(&cfg).unwrap();
    let mut f = xyz16(1, 2, 3);
    f.command = Some(enh);
    let out = pass(&mut b, 0, f);
    assert_eq!(out.frame.unwrap().command, None);
    assert_eq!(b.counters().commands_not_carried, 1);
}

#[test]
fn laser_control_forwarded_or_exposed() {
    let power = LaserControl::Power {
        power: 200,
        mo: true,
        pa: true,
        red_pointer: false,
        reserved: 0,
    };
    for head in [Protocol::Hans, Protocol::Xy2, Protocol::Xy3] {
        let mut b = slaved(Protocol::Hans, head);
        let mut f = xyz16(1, 2, 3);
        f.laser = Some(power);
        let out = pass(&mut b, 0, f);
        let forwarded = head == Protocol::Hans;
        assert_eq!(out.frame.unwrap().laser.is_some(), forwarded, "{head:?}");
        assert_eq!(b.counters().laser_not_carried, u64::from(!forwarded));
        assert_eq!(out.laser.power, Some(200));
        assert!(out.laser.gate);
    }
    // MO/PA gate.
    let mut cfg = Config::default();
    cfg.controller.protocol = Protocol::Hans;
    cfg.laser.gate = GateSource::HansMoPa;
    cfg.failsafe.recovery_frames = 1;
    cfg.output.timing = Timing::Slaved;
    let mut b = Bridge::new(&cfg).unwrap();
    b.status_seen(0);
    let out = pass(&mut b, 0, xyz16(1, 2, 3));
    assert!(!out.laser.gate, "no MO/PA yet");
    let mut f = xyz16(1, 2, 3);
    f.laser = Some(power);
    assert!(pass(&mut b, FP, f).laser.gate);
    f.laser = Some(LaserControl::Power {
        power: 10,
        mo: true,
        pa: false,
        red_pointer: false,
        reserved: 0,
    });
    let out = pass(&mut b, 2 * FP, f);
    assert!(!out.laser.gate);
    // Input lost: power reads 0, gate off.
    let out = b.tick(2 * FP + MS);
    assert_eq!(
        out.laser,
        LaserOutputs {
            gate: false,
            power: Some(0)
        }
    );
    // After recovery the MO/PA gate needs a fresh code 3.
    let out = pass(&mut b, 3 * MS, xyz16(1, 2, 3));
    assert_eq!(out.state, LinkState::Running);
    assert!(!out.laser.gate);
}

#[test]
fn hans_head_laser_is_switched_off_on_input_loss() {
    let power = LaserControl::Power {
        power: 99,
        mo: true,
        pa: true,
        red_pointer: true,
        reserved: 0,
    };
    let mut b = slaved(Protocol::Hans, Protocol::Hans);
    let mut f = xyz16(1, 2, 3);
    f.laser = Some(power);
    assert_eq!(pass(&mut b, 0, f).frame.unwrap().laser, Some(power));
    let first = b.tick(MS);
    assert_eq!(first.state, LinkState::Holding);
    let f = first.frame.unwrap();
    assert_eq!(f.laser, Some(LASER_OFF));
    assert_eq!(f.axis(Axis::X).unwrap().to_raw(20), 1 << 4, "still holding");
    // Only once; a second loss without laser control in between sends nothing.
    assert_eq!(b.tick(MS + FP).frame.unwrap().laser, None);
    pass(&mut b, 2 * MS, xyz16(1, 2, 3));
    assert_eq!(b.tick(4 * MS).frame.unwrap().laser, None);
    // Heads that cannot carry laser control never get it.
    let mut b = slaved(Protocol::Hans, Protocol::Xy3);
    let mut f = xyz16(1, 2, 3);
    f.laser = Some(power);
    pass(&mut b, 0, f);
    assert_eq!(b.tick(MS).frame.unwrap().laser, None);
}

/// The skip rules with laser control (HANS-100 head, laser forwarded) and with a
/// newer command the head refuses: the older one-off rides on wherever the newer
/// frame brings none the head takes; where it does, the older is lost and counted.
#[test]
fn free_running_skip_keeps_laser_and_refused_commands() {
    let power = |p| LaserControl::Power {
        power: p,
        mo: true,
        pa: true,
        red_pointer: false,
        reserved: 0,
    };
    let mut cfg = Config::default();
    cfg.failsafe.recovery_frames = 1;
    cfg.controller.protocol = Protocol::Hans;
    cfg.head.protocol = Protocol::Hans;
    cfg.laser.forward = true;
    let mut b = Bridge::new(&cfg).unwrap();
    let with = |x, laser, command| {
        let mut f = xyz16(x, x, x);
        f.laser = laser;
        f.command = command;
        f
    };
    // Older laser control, newer frame without: it rides on.
    b.on_line_event(0, ev(with(1, Some(power(10)), None)));
    b.on_line_event(1, ev(with(2, None, None)));
    let f = b.tick(2).frame.unwrap();
    assert_eq!(
        (f.laser, f.axis(Axis::X).unwrap().to_raw(16)),
        (Some(power(10)), 2)
    );
    assert_eq!(b.counters().laser_not_carried, 0);
    // Both have laser control: the newer wins, the older is counted.
    b.on_line_event(3, ev(with(3, Some(power(20)), None)));
    b.on_line_event(4, ev(with(4, Some(power(30)), None)));
    assert_eq!(b.tick(5).frame.unwrap().laser, Some(power(30)));
    assert_eq!(b.counters().laser_not_carried, 1);
    // A HANS-100 head takes no XY3-100 command: the newer one is dropped (counted),
    // the older, refused too, was counted on its own arrival; nothing rides on.
    let c = Command::Xy3(0x2_0001);
    b.on_line_event(6, ev(with(5, None, Some(c))));
    b.on_line_event(7, ev(with(6, None, Some(c))));
    assert_eq!(b.tick(8).frame.unwrap().command, None);
    assert_eq!(b.counters().commands_not_carried, 2);
    assert_eq!(b.counters().skipped, 3);

    // An XY3-100 head: an older command it takes rides on past a newer one it
    // refuses (an XY2-100 command), which is counted as not carried.
    let mut cfg = Config::default();
    cfg.failsafe.recovery_frames = 1;
    cfg.head.protocol = Protocol::Xy3;
    let mut b = Bridge::new(&cfg).unwrap();
    let refused = Command::Xy2Enhanced {
        command: 1,
        parameter: 2,
    };
    b.on_line_event(0, ev(with(1, None, Some(c))));
    b.on_line_event(1, ev(with(2, None, Some(refused))));
    let f = b.tick(2).frame.unwrap();
    assert_eq!(
        (f.command, f.axis(Axis::X).unwrap().to_raw(16)),
        (Some(c), 2)
    );
    assert_eq!(b.counters().commands_not_carried, 1);
    assert_eq!(b.counters().skipped, 1);
}

#[test]
fn free_running_skip_keeps_one_offs() {
    let mut cfg = Config::default();
    cfg.failsafe.recovery_frames = 1;
    cfg.head.protocol = Protocol::Xy3;
    cfg.controller.protocol = Protocol::Xy3;
    let mut b = Bridge::new(&cfg).unwrap();
    let c1 = Command::Xy3(0x8_0001);
    let c2 = Command::Xy3(0x2_0001);
    let mut f1 = xyz16(1, 1, 1);
    f1.command = Some(c1);
    b.on_line_event(0, ev(f1));
    b.on_line_event(1, ev(xyz16(2, 2, 2)));
    let out = b.tick(2);
    let f = out.frame.unwrap();
    assert_eq!(f.command, Some(c1), "the skipped frame's command rides on");
    assert_eq!(f.axis(Axis::X).unwrap().to_raw(16), 2);
    assert_eq!(b.counters().skipped, 1);
    // Two commands in one slot: the older one is lost and counted.
    let mut f2 = xyz16(3, 3, 3);
    f2.command = Some(c1);
    let mut f3 = xyz16(4, 4, 4);
    f3.command = Some(c2);
    b.on_line_event(3, ev(f2));
    b.on_line_event(4, ev(f3));
    assert_eq!(b.tick(5).frame.unwrap().command, Some(c2));
    assert_eq!(b.counters().commands_not_carried, 1);
    // Nothing new: repeat without the command.
    let out = b.tick(6);
    assert_eq!(out.frame.unwrap().command, None);
    assert_eq!(b.counters().repeated, 1);
}

#[test]
fn missing_axes_hold_their_last_position() {
    let mut b = slaved(Protocol::Xy2, Protocol::Xy2);
    pass(&mut b, 0, xyz16(10, 20, 30));
    // An XY2 command frame on X carries no X position.
    let mut f = xyz16(0, 21, 31);
    f.axes[0] = None;
    f.command = Some(Command::Xy2Enhanced {
        command: 1,
        parameter: 2,
    });
    let out = pass(&mut b, FP, f);
    let got = out.frame.unwrap();
    assert_eq!(got.axis(Axis::X).unwrap().to_raw(16), 10);
    assert_eq!(got.axis(Axis::Y).unwrap().to_raw(16), 21);
}

#[test]
fn slaved_ticks_only_clock_failsafe_frames() {
    let mut cfg = Config::default();
    cfg.output.timing = Timing::Slaved;
    let (mut b, t0) = running(&cfg);
    assert_eq!(b.tick(t0 + 1).frame, None);
    assert!(b.on_line_event(t0 + FP, ev(xyz16(5, 5, 5))).is_some());
    let out = b.tick(t0 + FP + MS);
    assert_eq!(out.state, LinkState::Holding);
    assert_eq!(raw(&out, Axis::X, 16), Some(5));
}

proptest::proptest! {
    /// Resize, invert and offset equal plain integer arithmetic at the head width,
    /// clamped to the field; values at and near full scale as often as elsewhere
    /// (the rounding saturates there).
    #[test]
    fn axis_map_is_integer_arithmetic(
        v in proptest::prop_oneof![
            proptest::prelude::any::<u32>(),
            proptest::strategy::Strategy::prop_map(0u32..64, |d| u32::MAX - d),
        ],
        from in proptest::sample::select(&[16u8, 18, 20, 26][..]),
        to in proptest::sample::select(&[16u8, 18, 20, 26][..]),
        invert in proptest::prelude::any::<bool>(),
        offset in -(1i32 << 26)..(1i32 << 26),
    ) {
        let v = v & ((1 << from) - 1);
        let p = pos(v, from);
        let max = (1i64 << to) - 1;
        let resized = i64::from(p.to_raw(to));
        let inv = if invert { max - resized } else { resized };
        let want = (inv + i64::from(offset)).clamp(0, max);
        let got = translate::map_position(p, to, invert, offset);
        proptest::prop_assert_eq!(got.bits(), to);
        proptest::prop_assert_eq!(i64::from(got.to_raw(to)), want);
    }
}
