//! Bridge engine tests at the neutral level: the configuration file, all protocol
//! pairings through the real codecs, free-running / slaved timing, status
//! back-translation per controller protocol and a fault-injection campaign against
//! an independent model of the supervision state machine.

use shared::bridge::status::{BRIDGE_FIRMWARE, BRIDGE_VENDOR};
use shared::bridge::{
    AfterHold, Bridge, Config, ConfigError, LinkState, Output, Protocol, StatusForm, Timing,
    Xy3Select,
};
use shared::model::{Alarms, Axis, FaultKind, ForwardFrame, HeadStatus, Line, LineEvent, Text};
use shared::xy2::{self, Mode, Parity};
use shared::xy3::back::{self, neutral as back_neutral, Packet, Parser};
use shared::xy3::{self, FrameSize};
use shared::{hans, model};

const US: u64 = 1_000;
const MS: u64 = 1_000_000;

/// xorshift64*: small, seeded, good enough to pick faults.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

// ------------------------------------------------------------ configuration file

const EXAMPLE: &str = include_str!("../../bridge.toml");

#[test]
fn example_file_parses_and_validates() {
    let cfg: Config = toml::from_str(EXAMPLE).unwrap();
    assert_eq!(cfg.validate(), Ok(()));
    assert_eq!(cfg.controller.protocol, Protocol::Xy2);
    assert_eq!(cfg.head.protocol, Protocol::Xy3);
    // Every other value in the example is the default.
    let mut want = Config::default();
    want.head.protocol = Protocol::Xy3;
    assert_eq!(cfg, want);
    // Serialising gives a file that reads back the same.
    let text = toml::to_string(&cfg).unwrap();
    assert_eq!(toml::from_str::<Config>(&text).unwrap(), cfg);
    // An empty file is the default configuration.
    assert_eq!(toml::from_str::<Config>("").unwrap(), Config::default());
}

#[test]
fn file_values_reach_the_types() {
    let cfg: Config = toml::from_str(
        r#"
        [controller]
        protocol = "hans"
        hans.decode = { vote3 = [1, 3, 5] }
        xy3.back_rate = 921600
        xy3.lines = ["w", "x", "y"]
        xy3.select = "always"
        [head]
        protocol = "xy2"
        xy2 = { mode = "extended18", enhanced_commands = false, parity = "data_only", status = "word", polarity = "high_is_ok" }
        xy3.frame_bits = 32
        [output]
        timing = "slaved"
        [failsafe]
        after_hold = "stop"
        "#,
    )
    .unwrap();
    assert_eq!(cfg.validate(), Ok(()));
    assert_eq!(
        cfg.controller.hans.decode,
        shared::bridge::HansDecode::Vote3([1, 3, 5])
    );
    assert_eq!(cfg.controller.xy3.back_rate, xy3::BackRate::B921600);
    assert_eq!(
        cfg.controller.xy3.lines,
        xy3::rx::Lines::new(&[Axis::X, Axis::Y, Axis::W]).unwrap()
    );
    assert_eq!(cfg.controller.xy3.select, Xy3Select::Always);
    // Written back in axis order.
    let text = toml::to_string(&cfg).unwrap();
    assert!(text.contains("lines = [\"x\", \"y\", \"w\"]"), "{text}");
    assert!(text.contains("select = \"always\""), "{text}");
    assert_eq!(cfg.head.xy2.mode, Mode::Extended18);
    assert_eq!(cfg.head.xy2.parity, Parity::DataOnly);
    assert_eq!(cfg.head.xy2.status, StatusForm::Word);
    assert_eq!(cfg.head.xy2.polarity, xy2::Polarity::HighIsOk);
    assert_eq!(cfg.head.xy3.frame_size, FrameSize::Bits32);
    assert_eq!(cfg.output.timing, Timing::Slaved);
    assert_eq!(cfg.failsafe.after_hold, AfterHold::Stop);
    for (text, want) in [
        ("decode = \"vote5\"", shared::bridge::HansDecode::Vote5),
        ("decode = \"super\"", shared::bridge::HansDecode::Super),
        (
            "decode = { normal = 4 }",
            shared::bridge::HansDecode::Normal(4),
        ),
    ] {
        let cfg: Config = toml::from_str(&format!("[controller.hans]\n{text}")).unwrap();
        assert_eq!(cfg.controller.hans.decode, want);
    }
}

#[test]
fn bad_files_name_the_key() {
    #[rustfmt::skip]
    let cases = [
        // unknown keys, at several depths
        ("[axes]\nswap_xyz = true", "swap_xyz"),
        ("[head.xy3]\nframe_size = 24", "frame_size"),
        ("[head.hans]\nrate = 1", "hans"),
        ("bogus = 1", "bogus"),
        // bad values
        ("[controller.xy3]\nback_rate = 1234", "back_rate"),
        ("[head.xy3]\nframe_bits = 28", "frame_bits"),
        ("[head]\nprotocol = \"xy4\"", "protocol"),
        ("[controller.xy2]\nparity = \"odd\"", "parity"),
        ("[failsafe]\ninput_timeout_us = -1", "input_timeout_us"),
        ("[controller.hans]\ndecode = { vote7 = 1 }", "decode"),
        ("[controller.xy3]\nlines = [\"x\", \"y\", \"v\"]", "unknown variant `v`"),
        ("[controller.xy3]\nlines = [\"x\", \"y\", \"x\"]", "a line listed twice"),
        ("[controller.xy3]\nlines = [\"x\", \"z\"]", "without \"x\" or \"y\""),
        ("[controller.xy3]\nlines = [\"y\"]", "without \"x\" or \"y\""),
        ("[controller.xy3]\nlines = []", "without \"x\" or \"y\""),
        ("[controller.xy3]\nlines = \"xyz\"", "expected a list of distinct XY3-100 lines"),
        ("[controller.xy3]\nselect = \"nss\"", "select"),
    ];
    for (text, key) in cases {
        let err = toml::from_str::<Config>(text).unwrap_err().to_string();
        assert!(err.contains(key), "{text:?}: {err}");
        // toml shows the offending line, so a bad value's key is named too.
        if text.contains("lines") {
            assert!(err.contains("lines = "), "{text:?}: {err}");
        }
    }
    // Well-formed files with invalid combinations: validate() names the key.
    #[rustfmt::skip]
    let invalid = [
        ("[head]\nprotocol = \"xy2\"\nxy2.mode = \"extended18\"", "head.xy2.enhanced_commands"),
        ("[head]\nprotocol = \"hans\"\n[output]\nframe_rate_hz = 200000", "output.frame_rate_hz"),
        ("[output]\nframe_rate_hz = 500", "output.frame_rate_hz"),
        ("[controller]\nprotocol = \"hans\"\nhans.decode = { normal = 6 }", "controller.hans.decode"),
        ("[controller]\nprotocol = \"hans\"\nhans.decode = { vote3 = [2, 2, 3] }", "controller.hans.decode"),
        ("[failsafe]\npark_x = 0x100000", "failsafe.park_x"),
        ("[controller]\nprotocol = \"xy3\"\nxy3.lines = [\"x\", \"y\", \"u\"]", "controller.xy3.lines"),
    ];
    for (text, key) in invalid {
        let cfg: Config = toml::from_str(text).unwrap();
        let err: ConfigError = cfg.validate().unwrap_err();
        assert_eq!(err.key(), key, "{text:?}");
        assert!(err.to_string().starts_with(key));
    }
}

// ------------------------------------------------------------ pairings

/// One side's protocol with its width option.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Side {
    Xy2(Mode),
    Xy3(FrameSize),
    Hans,
}

const SIDES: [Side; 5] = [
    Side::Xy2(Mode::Standard16),
    Side::Xy2(Mode::Extended18),
    Side::Xy3(FrameSize::Bits24),
    Side::Xy3(FrameSize::Bits32),
    Side::Hans,
];

fn config(controller: Side, head: Side) -> Config {
    let mut c = Config::default();
    match controller {
        Side::Xy2(m) => {
            c.controller.protocol = Protocol::Xy2;
            c.controller.xy2.mode = m;
        }
        Side::Xy3(_) => c.controller.protocol = Protocol::Xy3,
        Side::Hans => c.controller.protocol = Protocol::Hans,
    }
    match head {
        Side::Xy2(m) => {
            c.head.protocol = Protocol::Xy2;
            c.head.xy2.mode = m;
            c.head.xy2.enhanced_commands = m == Mode::Standard16;
        }
        Side::Xy3(s) => {
            c.head.protocol = Protocol::Xy3;
            c.head.xy3.frame_size = s;
        }
        Side::Hans => c.head.protocol = Protocol::Hans,
    }
    c.failsafe.recovery_frames = 1;
    c
}

/// Position widths of a side for X, Y, Z.
fn widths(side: Side) -> [u8; 3] {
    match side {
        Side::Xy2(Mode::Standard16) => [16; 3],
        Side::Xy2(Mode::Extended18) => [18; 3],
        Side::Xy3(s) => [s.position_bits(); 3],
        Side::Hans => [20, 20, 16],
    }
}

/// The controller's raw X, Y, Z through its real codec into a neutral frame, the way
/// a receiver builds it.
fn controller_frame(side: Side, raw: [u32; 3]) -> ForwardFrame {
    let mut f = ForwardFrame::default();
    match side {
        Side::Xy2(mode) => {
            let link = xy2::LinkConfig {
                mode,
                parity: Parity::WholeFrame,
            };
            for (axis, &v) in Axis::ALL.iter().zip(raw.iter()) {
                let frame = match mode {
                    Mode::Standard16 => xy2::Frame::Position16(v as u16),
                    Mode::Extended18 => xy2::Frame::Position18(v),
                };
                let word = xy2::encode(frame, &link).unwrap();
                match xy2::decode(word, &link).unwrap().to_model().unwrap() {
                    xy2::AxisItem::Position(p) => f.axes[axis.index()] = Some(p),
                    xy2::AxisItem::Command(_) => unreachable!(),
                }
            }
        }
        Side::Xy3(size) => {
            for (axis, &v) in Axis::ALL.iter().zip(raw.iter()) {
                let frame = match size {
                    FrameSize::Bits24 => xy3::Frame::Position24(v),
                    FrameSize::Bits32 => xy3::Frame::Position32(v),
                };
                let (word, size) = xy3::encode(&frame).unwrap();
                let back = xy3::decode(word, size).unwrap();
                xy3::neutral::apply(&back, *axis, &mut f).unwrap();
            }
        }
        Side::Hans => {
            let frame = hans::Frame::new(raw[0], raw[1], raw[2] << 4).unwrap();
            f = hans::Frame::decode(frame.encode()).unwrap().to_forward();
        }
    }
    f
}

/// The head's frame through its real codec and back: the raw X, Y, Z the head gets.
fn head_receives(side: Side, f: &ForwardFrame) -> [u32; 3] {
    let p = |a: Axis| f.axis(a).unwrap();
    match side {
        Side::Xy2(mode) => {
            let link = xy2::LinkConfig {
                mode,
                parity: Parity::WholeFrame,
            };
            [Axis::X, Axis::Y, Axis::Z].map(|a| {
                let word = xy2::encode(xy2::Frame::from_position(p(a), mode), &link).unwrap();
                match xy2::decode(word, &link).unwrap() {
                    xy2::Frame::Position16(v) => u32::from(v),
                    xy2::Frame::Position18(v) => v,
                    other => panic!("{other:?}"),
                }
            })
        }
        Side::Xy3(size) => [Axis::X, Axis::Y, Axis::Z].map(|a| {
            let (word, s) = xy3::encode(&xy3::neutral::position_frame(p(a), size)).unwrap();
            match xy3::neutral::to_neutral(&xy3::decode(word, s).unwrap()).unwrap() {
                xy3::neutral::Neutral::Position(q) => q.to_raw(size.position_bits()),
                other => panic!("{other:?}"),
            }
        }),
        Side::Hans => {
            let frame = hans::Frame::from_forward(f, &hans::Frame::CENTRE).unwrap();
            let back = hans::Frame::decode(frame.encode()).unwrap().to_forward();
            [(Axis::X, 20), (Axis::Y, 20), (Axis::Z, 16)]
                .map(|(a, bits)| back.axis(a).unwrap().to_raw(bits))
        }
    }
}

fn through(b: &mut Bridge, t: u64, f: ForwardFrame) -> Output {
    match b.on_line_event(t, LineEvent::Frame(f)) {
        Some(out) => out,
        None => b.tick(t + 1),
    }
}

#[test]
fn all_pairings_through_the_codecs() {
    let mut rng = Rng(0x5EED_0001);
    let mut pairs = 0;
    for controller in SIDES {
        for head in SIDES {
            let mut bridge = Bridge::new(&config(controller, head)).unwrap();
            let win = widths(controller);
            let wout = widths(head);
            let max = |bits: u8| (1u32 << bits) - 1;
            let mut t = 0;
            for i in 0..3000 {
                let raw: [u32; 3] = match i {
                    0 => [0; 3],
                    1 => win.map(|b| 1 << (b - 1)),
                    2 => win.map(max),
                    _ => win.map(|b| (rng.next() as u32) & max(b)),
                };
                let input = controller_frame(controller, raw);
                let out = through(&mut bridge, t, input);
                t += 10 * US;
                assert_eq!(out.state, LinkState::Running);
                let f = out.frame.unwrap();
                for (a, &bits) in wout.iter().enumerate() {
                    assert_eq!(f.axes[a].unwrap().bits(), bits, "{controller:?}->{head:?}");
                }
                let want: [u32; 3] = [0, 1, 2].map(|a| input.axes[a].unwrap().to_raw(wout[a]));
                assert_eq!(
                    head_receives(head, &f),
                    want,
                    "{controller:?}->{head:?} raw {raw:x?}"
                );
                if i == 1 {
                    // The centre stays the centre at every width.
                    assert_eq!(want, wout.map(|b| 1 << (b - 1)));
                }
            }
            pairs += 1;
        }
    }
    assert_eq!(pairs, 25);
}

// ------------------------------------------------------------ timing

/// Runs inputs with period `p_in` against 10 us output slots and checks the
/// repeat / skip counts against the slot arithmetic.
fn rate_mismatch(p_in: u64, slots: u64) {
    let mut cfg = config(Side::Xy2(Mode::Standard16), Side::Xy3(FrameSize::Bits32));
    cfg.output.timing = Timing::FreeRunning;
    let mut b = Bridge::new(&cfg).unwrap();
    let p_out = 10 * US;
    let (mut next_in, mut n) = (0u64, 0u32);
    let (mut repeats, mut skips) = (0u64, 0u64);
    let mut newest = None;
    for k in 1..=slots {
        let t = k * p_out;
        let mut m = 0;
        while next_in <= t {
            let f = controller_frame(Side::Xy2(Mode::Standard16), [n & 0xFFFF, 0, 0]);
            b.on_line_event(next_in, LineEvent::Frame(f));
            newest = Some(n & 0xFFFF);
            n += 1;
            m += 1;
            next_in += p_in;
        }
        let out = b.tick(t);
        match m {
            0 => repeats += 1,
            m => skips += m - 1,
        }
        let x = out.frame.unwrap().axis(Axis::X).unwrap().to_raw(16);
        assert_eq!(Some(x), newest, "slot {k}");
    }
    let c = b.counters();
    assert_eq!((c.repeated, c.skipped), (repeats, skips), "p_in {p_in}");
    assert_eq!(c.frames_ok, u64::from(n));
    // Every slot is either a new frame or a repeat; every input is sent or skipped.
    assert_eq!(c.frames_ok - c.skipped + c.repeated, slots);
}

#[test]
fn free_running_repeat_and_skip_are_counted_exactly() {
    rate_mismatch(10 * US, 2000);
    rate_mismatch(9_900, 20_000); // input 1 % fast: ~1 skip per 100 slots
    rate_mismatch(10_100, 20_000); // input 1 % slow: ~1 repeat per 100 slots
    rate_mismatch(5 * US, 2000);
    rate_mismatch(20 * US, 2000);
    rate_mismatch(7_777, 5000);
}

#[test]
fn slaved_mode_outputs_one_frame_per_input() {
    let mut cfg = config(Side::Xy3(FrameSize::Bits24), Side::Xy2(Mode::Standard16));
    cfg.output.timing = Timing::Slaved;
    let mut b = Bridge::new(&cfg).unwrap();
    let mut outputs = 0;
    let mut t = 0;
    for i in 0..1000u32 {
        // Irregular input spacing: the output follows it.
        t += 3 * US + u64::from(i % 7) * US;
        let f = controller_frame(Side::Xy3(FrameSize::Bits24), [i << 4, 0, 0]);
        let out = b.on_line_event(t, LineEvent::Frame(f)).unwrap();
        assert_eq!(out.frame.unwrap().axis(Axis::X).unwrap().to_raw(16), i);
        outputs += 1;
        assert_eq!(
            b.tick(t + 1).frame,
            None,
            "no frame from the own clock while running"
        );
    }
    assert_eq!(outputs, 1000);
    let c = b.counters();
    assert_eq!((c.repeated, c.skipped), (0, 0));
}

// ------------------------------------------------------------ status

/// A running bridge for `controller` -> `head`.
fn running_bridge(controller: Side, head: Side) -> (Bridge, u64) {
    let mut b = Bridge::new(&config(controller, head)).unwrap();
    b.on_line_event(0, LineEvent::Frame(controller_frame(controller, [0; 3])));
    b.status_seen(0);
    assert_eq!(b.state(), LinkState::Running);
    (b, 0)
}

fn text(s: &str) -> Text {
    Text::from_slice(s.as_bytes()).unwrap()
}

#[test]
fn xy2_controller_status_level_and_word() {
    let mut cfg = config(Side::Xy2(Mode::Standard16), Side::Xy3(FrameSize::Bits24));
    cfg.controller.xy2.status = StatusForm::Word;
    let mut b = Bridge::new(&cfg).unwrap();
    let link = xy2::LinkConfig::default();
    let word = |b: &Bridge| xy2::StatusWord::from_frame(b.xy2_status_frame(), &link).unwrap();
    // Power-up: INPUT_LOST -> fault level, "power not OK" in the word.
    assert!(b.xy2_status_line_high(), "low = OK polarity: high = fault");
    assert!(!word(&b).power_ok);
    b.on_line_event(
        0,
        LineEvent::Frame(controller_frame(Side::Xy2(Mode::Standard16), [1, 2, 3])),
    );
    b.status_seen(0);
    assert!(!b.xy2_status_line_high());
    assert_eq!(word(&b).to_word(), 0xFDFD);
    // Head alarms through XY3 ERROR_STATE: temperature on the head.
    let error_state = |code: u8| Packet::decode(0x07, &[code]).unwrap();
    back_neutral::apply(&error_state(1), b.head_status_mut());
    let w = word(&b);
    assert!(!w.temperature_ok && w.power_ok && w.position_ack_x);
    assert!(b.xy2_status_line_high());
    // Status lost raises a fault too.
    back_neutral::apply(&error_state(0), b.head_status_mut());
    b.on_line_event(
        150 * MS,
        LineEvent::Frame(controller_frame(Side::Xy2(Mode::Standard16), [1, 2, 3])),
    );
    b.on_line_event(
        200 * MS,
        LineEvent::Frame(controller_frame(Side::Xy2(Mode::Standard16), [1, 2, 3])),
    );
    assert!(b.alarms().contains(Alarms::STATUS_LOST));
    assert!(!word(&b).power_ok);
}

/// What an XY3-100 controller makes of the bridge's backchannel.
struct Xy3Controller {
    parser: Parser,
    seen: HeadStatus,
    packets: u32,
}

impl Xy3Controller {
    fn new() -> Self {
        Xy3Controller {
            parser: Parser::new(),
            seen: HeadStatus::default(),
            packets: 0,
        }
    }

    /// Polls the bridge's backchannel once per millisecond over `duration` and
    /// applies the packets as the controller would.
    fn listen(&mut self, b: &mut Bridge, from: u64, duration: u64) {
        let mut buf = [0u8; back::SEND_BUF_LEN];
        let mut t = from;
        while t < from + duration {
            let n = b.xy3_back_poll(t, &mut buf).unwrap();
            for &byte in &buf[..n] {
                if let Some(back::Event::Packet(raw)) = self.parser.push(byte) {
                    let p = Packet::decode(raw.ty, raw.payload).unwrap();
                    back_neutral::apply(&p, &mut self.seen);
                    self.packets += 1;
                }
            }
            t += MS;
        }
    }
}

#[test]
fn xy3_controller_backchannel() {
    let (mut b, _) = running_bridge(Side::Xy3(FrameSize::Bits24), Side::Hans);
    // The head (HANS) reports over temperature and its actual values; an XY3 head
    // would have given identification: simulate one with a serial and model.
    {
        let h = b.head_status_mut();
        h.identification.serial = text("SN-0042");
        h.identification.model = text("GalvoHead 9");
        h.temperatures[0] = Some(4_250);
        h.working_hours[0] = Some(1234);
        h.alarms = Alarms::TEMPERATURE;
    }
    // Controller-side check failures the bridge counted.
    for (axis, n) in [(Axis::X, 3), (Axis::Y, 1), (Axis::W, 2)] {
        for _ in 0..n {
            let e = LineEvent::Fault {
                line: Line::Axis(axis),
                kind: FaultKind::CheckFailed,
            };
            b.on_line_event(1, e);
        }
    }
    // Keep input and status alive for 200 ms while polling.
    let mut ctl = Xy3Controller::new();
    let mut t = 0;
    while t < 200 * MS {
        b.on_line_event(
            t,
            LineEvent::Frame(controller_frame(Side::Xy3(FrameSize::Bits24), [0; 3])),
        );
        b.status_seen(t);
        ctl.listen(&mut b, t, 500 * US);
        t += 500 * US;
    }
    // One packet per 10 ms, minus what the parser needs to gain sync.
    assert!(ctl.packets >= 15, "{} packets in 200 ms", ctl.packets);
    let seen = &ctl.seen;
    assert_eq!(seen.identification.vendor, text(BRIDGE_VENDOR));
    assert_eq!(seen.identification.firmware, text(BRIDGE_FIRMWARE));
    assert_eq!(
        seen.identification.model,
        text("XY bridge / head: GalvoHead 9")
    );
    assert_eq!(seen.identification.serial, text("SN-0042"));
    assert_eq!(seen.temperatures[0], Some(4_250));
    assert_eq!(seen.working_hours[0], Some(1234));
    assert_eq!(seen.frame_errors, Some([3, 1, 0, 0, 2]));
    assert!(seen.alarms.contains(Alarms::TEMPERATURE));
    assert_eq!(seen.error_codes[0], Some(1), "head slot: temperature");
    assert_eq!(seen.error_codes[1], None, "no bridge alarm yet");
    // Input lost: the DSP slot reports a data error at once (alarm change).
    ctl.listen(&mut b, t + 2 * MS, 1);
    assert_eq!(ctl.seen.error_codes[1], Some(2));
    assert!(ctl.seen.alarms.contains(Alarms::COMMUNICATION));
}

#[test]
fn xy3_backchannel_rate_change_sends_sync_first() {
    let (mut b, _) = running_bridge(Side::Xy3(FrameSize::Bits24), Side::Xy3(FrameSize::Bits24));
    let mut buf = [0u8; back::SEND_BUF_LEN];
    let n = b.xy3_back_poll(0, &mut buf).unwrap();
    assert_eq!(&buf[..3], &[0x48, 0x41, 0x00], "first packet after a SYNC");
    assert!(n > 3);
    let mut f = controller_frame(Side::Xy3(FrameSize::Bits24), [0; 3]);
    f.command = Some(model::Command::Xy3(xy3::BackRate::B460800.code()));
    let out = b
        .on_line_event(MS, LineEvent::Frame(f))
        .unwrap_or_else(|| b.tick(MS + 1));
    assert_eq!(out.controller_back_rate, Some(xy3::BackRate::B460800));
    assert_eq!(out.head_back_rate, Some(xy3::BackRate::B460800));
    assert_eq!(b.controller_back_rate(), xy3::BackRate::B460800);
    let n = b.xy3_back_poll(20 * MS, &mut buf).unwrap();
    assert!(n > 3);
    assert_eq!(&buf[..3], &[0x48, 0x41, 0x00], "SYNC after the rate change");
}

#[test]
fn hans_controller_status_frames() {
    let (mut b, _) = running_bridge(Side::Hans, Side::Hans);
    // The head reports through HANS status frames: actual positions, a following
    // error, a laser alarm, and Z actual.
    let mut rx = hans::StatusReceiver::new();
    let head_frames = [
        hans::status_frame(
            &hans::GalvoStatus::Position {
                x: 0x1234,
                y: 0xABCD,
            },
            &hans::DeviceExt::ZActual(0x4321),
        ),
        hans::status_frame(
            &hans::GalvoStatus::Velocity {
                x: 5,
                y: 6,
                alarms: hans::GalvoAlarms {
                    following_error: true,
                    reserved_level: true,
                    ..Default::default()
                },
            },
            &hans::DeviceExt::LaserAlarms(hans::LaserAlarms(hans::LaserAlarms::SEED)),
        ),
    ];
    for f in head_frames {
        rx.apply(&f.unwrap(), b.head_status_mut());
    }
    let decode = |b: &mut Bridge, n: usize| {
        let mut rx = hans::StatusReceiver::new();
        let mut seen = HeadStatus::default();
        let mut codes = std::collections::BTreeSet::new();
        for _ in 0..n {
            let f = hans::Frame::decode(b.hans_status_frame().encode()).unwrap();
            codes.insert((f.data1() & 0xF) << 4 | (f.data2() & 0xF));
            rx.apply(&f, &mut seen);
        }
        (seen, codes)
    };
    let (seen, codes) = decode(&mut b, 20);
    assert!(codes.contains(&64) && codes.contains(&65), "{codes:?}");
    assert_eq!(seen.actual[0].unwrap().to_raw(16), 0x1234);
    assert_eq!(seen.actual[1].unwrap().to_raw(16), 0xABCD);
    assert_eq!(seen.actual[2].unwrap().to_raw(16), 0x4321);
    assert_eq!(seen.velocity[0], Some(5));
    assert!(seen
        .alarms
        .contains(Alarms::POSITION_X.union(Alarms::POSITION_Y)));
    assert!(seen.alarms.contains(Alarms::LASER));
    assert!(!seen.alarms.contains(Alarms::COMMUNICATION));
    // Input lost -> communication alarm; status lost -> power alarm.
    b.tick(MS);
    let (seen, _) = decode(&mut b, 4);
    assert!(seen.alarms.contains(Alarms::COMMUNICATION));
    assert!(!seen.alarms.contains(Alarms::POWER));
    b.tick(300 * MS);
    let (seen, _) = decode(&mut b, 4);
    assert!(seen.alarms.contains(Alarms::POWER));
}

#[test]
fn hans_controller_status_without_head_data_still_reports_alarms() {
    // An XY2 level head: nothing but a fault level.
    let (mut b, _) = running_bridge(Side::Hans, Side::Xy2(Mode::Standard16));
    b.head_status_mut().alarms = xy2::Health::Fault.alarms();
    let mut rx = hans::StatusReceiver::new();
    let mut seen = HeadStatus::default();
    for _ in 0..4 {
        let f = hans::Frame::decode(b.hans_status_frame().encode()).unwrap();
        rx.apply(&f, &mut seen);
    }
    // ELECTRICAL has no HANS-100 bit: it is reported as the power alarm.
    assert!(seen.alarms.contains(Alarms::POWER));
}

// ------------------------------------------------------------ fault campaign

/// An independent model of the documented state machine (module docs of
/// `shared::bridge`), used as the oracle of the campaign.
struct Oracle {
    running: bool,
    last_valid: Option<u64>,
    hold_end: u64,
    run: u32,
    t: u64,
    h: u64,
    n: u32,
}

impl Oracle {
    fn poll(&mut self, now: u64) {
        let stale = self.last_valid.is_none_or(|l| now - l >= self.t);
        if self.running && stale {
            self.running = false;
            self.hold_end = self.last_valid.unwrap() + self.t + self.h;
            self.run = 0;
        }
        if !self.running && stale {
            self.run = 0;
        }
    }
    /// A valid frame: whether it is forwarded.
    fn valid(&mut self, now: u64) -> bool {
        self.last_valid = Some(now);
        if self.running {
            return true;
        }
        self.run += 1;
        if self.run >= self.n {
            self.running = true;
            self.run = 0;
        }
        self.running
    }
    fn state(&self, now: u64) -> LinkState {
        if self.running {
            LinkState::Running
        } else if now < self.hold_end {
            LinkState::Holding
        } else {
            LinkState::Safe
        }
    }
}

/// Decodes one axis word like an XY2-100 receiver; a failed check is a fault.
fn receive(words: [u32; 3], link: &xy2::LinkConfig) -> Result<ForwardFrame, Line> {
    let mut f = ForwardFrame::default();
    for (i, w) in words.iter().enumerate() {
        let axis = Axis::ALL[i];
        match xy2::decode(*w, link).map(|fr| fr.to_model()) {
            Ok(Ok(xy2::AxisItem::Position(p))) => f.axes[i] = Some(p),
            _ => return Err(Line::Axis(axis)),
        }
    }
    Ok(f)
}

#[test]
fn fault_campaign_never_forwards_a_faulted_period() {
    let mut cfg = config(Side::Xy2(Mode::Standard16), Side::Xy3(FrameSize::Bits32));
    cfg.failsafe.recovery_frames = 8;
    cfg.failsafe.hold_us = 2_000;
    cfg.failsafe.park_x = 0x1_0000; // park X = 0x1000 at 16 bits: never a tag
    cfg.failsafe.status_timeout_us = 0; // the head's status is not part of this test
    let mut b = Bridge::new(&cfg).unwrap();
    let mut oracle = Oracle {
        running: false,
        last_valid: None,
        hold_end: 0,
        run: 0,
        t: MS,
        h: 2 * MS,
        n: 8,
    };
    let link = xy2::LinkConfig::default();
    let mut rng = Rng(0xFA17_0000_0001);
    // Tags: X carries the period number's low 16 bits, Y the high bits, so every
    // period's positions are unique; faulted periods' tags are remembered.
    let mut poisoned = std::collections::HashSet::new();
    let mut sent_tag: Option<u32> = None; // newest forwarded tag not yet output
    let mut last_out: Option<(u32, u32)> = None;
    let (mut events, mut faults, mut periods) = (0u64, 0u64, 0u32);
    let mut t: u64 = 0;
    let mut tag: u32 = 0x1_0000; // start past the park tag
    while events < 1_000_000 {
        periods += 1;
        t += 10 * US;
        // Occasionally the controller stops for 0.2 .. 4 ms.
        if rng.below(2000) == 0 {
            t += 200 * US + rng.below(3800) * US;
        }
        let now_in = t + rng.below(9) * US;
        tag += 1;
        let (x, y) = (tag & 0xFFFF, tag >> 16);
        let mut words =
            [x, y, 0x8000].map(|v| xy2::encode(xy2::Frame::Position16(v as u16), &link).unwrap());
        let roll = rng.below(100);
        let event = if roll < 8 {
            // A single-bit error on a random line and bit: always detected.
            let line = rng.below(3) as usize;
            words[line] ^= 1 << rng.below(20);
            match receive(words, &link) {
                Ok(_) => panic!("single-bit error not detected"),
                Err(line) => LineEvent::Fault {
                    line,
                    kind: FaultKind::CheckFailed,
                },
            }
        } else if roll < 10 {
            let kind =
                [FaultKind::Framing, FaultKind::Resync, FaultKind::Dropped][rng.below(3) as usize];
            LineEvent::Fault {
                line: Line::Framing,
                kind,
            }
        } else {
            LineEvent::Frame(receive(words, &link).unwrap())
        };
        oracle.poll(now_in);
        match event {
            LineEvent::Fault { .. } => {
                poisoned.insert((x, y));
                faults += 1;
                if !oracle.running {
                    oracle.run = 0;
                }
            }
            LineEvent::Frame(_) => {
                if oracle.valid(now_in) {
                    sent_tag = Some(tag);
                }
            }
        }
        if oracle.state(now_in) != LinkState::Running {
            sent_tag = None;
        }
        assert_eq!(b.on_line_event(now_in, event), None);
        events += 1;
        assert_eq!(b.state(), oracle.state(now_in), "event at {now_in}");

        // One output slot per period.
        let slot = t + 9 * US + 500;
        oracle.poll(slot);
        let out = b.tick(slot);
        events += 1;
        let state = oracle.state(slot);
        assert_eq!(out.state, state, "slot at {slot}");
        assert_eq!(out.laser.gate, state == LinkState::Running);
        assert_eq!(
            out.alarms.contains(Alarms::INPUT_LOST),
            state != LinkState::Running
        );
        let f = out.frame.expect("park policy always sends");
        let x = f.axis(Axis::X).unwrap().to_raw(16);
        let y = f.axis(Axis::Y).unwrap().to_raw(16);
        assert!(
            !poisoned.contains(&(x, y)),
            "faulted period forwarded: {x:#x} {y:#x}"
        );
        match state {
            LinkState::Running => {
                let want = match sent_tag.take() {
                    Some(tag) => (tag & 0xFFFF, tag >> 16),
                    None => last_out.expect("running implies a forwarded frame"),
                };
                assert_eq!((x, y), want, "slot at {slot}");
                last_out = Some((x, y));
            }
            LinkState::Holding => assert_eq!(Some((x, y)), last_out, "hold"),
            LinkState::Safe => {
                assert_eq!((x, y), (0x1000, 0x8000), "park");
            }
        }
    }
    let c = b.counters();
    assert_eq!(
        c.frames_ok + faults,
        u64::from(periods),
        "every period is a frame or a fault"
    );
    assert!(c.input_losses > 100 && c.recoveries > 100, "{c:?}");
    assert!(c.line(Line::Axis(Axis::X)).check_failed > 1000);
}
