//! VCD reading/writing: round trip, a hand-written fixture, and bad input.

use host_tests::vcd_io::{read_vcd, read_vcd_roles, write_vcd, NameMap, VcdError, WriteTimescale};
use host_tests::wave::{Signal, Waveform};
use proptest::prelude::*;

const FIXTURE: &str = include_str!("fixtures/scoped_10ns.vcd");

fn changes(w: &Waveform, name: &str) -> (bool, Vec<(u64, bool)>) {
    let s = w.get(name).unwrap();
    (s.initial(), s.changes().to_vec())
}

#[test]
fn fixture_reads_exact_edges() {
    let w = read_vcd(FIXTURE.as_bytes()).unwrap();
    // Only the three 1-bit variables; the vector and the real are skipped.
    assert_eq!(w.names(), vec!["D0", "D1", "D2"]);
    // 10 ns units -> ps. #7 has 1, 0, 1 for D0: the last value wins.
    assert_eq!(
        changes(&w, "D0"),
        (
            false,
            vec![
                (30_000, true),
                (50_000, false),
                (70_000, true),
                (120_000, false)
            ]
        )
    );
    // D1 starts high ($dumpvars), falls at #3; `z` at #7 holds low; rises at #12.
    assert_eq!(
        changes(&w, "D1"),
        (true, vec![(30_000, false), (120_000, true)])
    );
    // D2 is `x` in $dumpvars: low until its first defined value at #5.
    assert_eq!(
        changes(&w, "D2"),
        (false, vec![(50_000, true), (120_000, false)])
    );
}

#[test]
fn fixture_roles_by_leaf_and_path() {
    let mut map = NameMap::new();
    map.parse_arg("CLK=D0").unwrap();
    map.parse_arg("SYNC=top.probe.D1").unwrap();
    let w = read_vcd_roles(FIXTURE.as_bytes(), &["CLK", "SYNC", "D2"], &map).unwrap();
    assert_eq!(w.names(), vec!["CLK", "SYNC", "D2"]);
    assert_eq!(changes(&w, "CLK").1.len(), 4);
    assert!(w.get("SYNC").unwrap().initial());
}

#[test]
fn missing_signal_lists_available() {
    let mut map = NameMap::new();
    map.set("CLK", "SCK");
    let e = read_vcd_roles(FIXTURE.as_bytes(), &["CLK"], &map).unwrap_err();
    assert_eq!(
        e,
        VcdError::MissingSignal {
            role: "CLK".into(),
            name: "SCK".into(),
            available: vec!["D0".into(), "D1".into(), "D2".into()],
        }
    );
    let text = e.to_string();
    assert!(
        text.contains("SCK") && text.contains("D0, D1, D2"),
        "{text}"
    );
}

#[test]
fn vector_is_not_a_signal() {
    let mut map = NameMap::new();
    map.set("X", "bus");
    let e = read_vcd_roles(FIXTURE.as_bytes(), &["X"], &map).unwrap_err();
    assert_eq!(
        e,
        VcdError::NotSingleBit {
            name: "bus".into(),
            width: 8
        }
    );
}

#[test]
fn bad_mapping_argument() {
    let mut map = NameMap::new();
    for bad in ["CLK", "=D0", "CLK=", ""] {
        assert_eq!(
            map.parse_arg(bad),
            Err(VcdError::BadMapping { arg: bad.into() })
        );
    }
}

#[test]
fn duplicate_leaf_names() {
    let text = FIXTURE.replace("$var reg 1 % D2 $end", "$var reg 1 % D0 $end");
    let e = read_vcd(text.as_bytes()).unwrap_err();
    assert_eq!(
        e,
        VcdError::DuplicateName {
            name: "D0".into(),
            paths: vec!["top.probe.D0".into(), "top.other.D0".into()],
        }
    );
    // The full path resolves the ambiguity.
    let mut map = NameMap::new();
    map.set("A", "top.other.D0");
    let w = read_vcd_roles(text.as_bytes(), &["A"], &map).unwrap();
    assert_eq!(
        changes(&w, "A"),
        (false, vec![(50_000, true), (120_000, false)])
    );
}

#[test]
fn truncated_files() {
    let header_end = FIXTURE.find("$enddefinitions").unwrap();
    for cut in [
        &FIXTURE[..header_end],
        &FIXTURE[..FIXTURE.find("r1.5").unwrap()],
    ] {
        let e = read_vcd(cut.as_bytes()).unwrap_err();
        assert!(matches!(e, VcdError::Truncated { .. }), "{e:?}");
    }
    // A value change cut after its value, before the identifier.
    let cut = &FIXTURE[..FIXTURE.find("#5").unwrap() + 4];
    assert!(cut.ends_with("0"));
    let e = read_vcd(cut.as_bytes()).unwrap_err();
    assert!(matches!(e, VcdError::Truncated { .. }), "{e:?}");
    // Ending without a final newline is not truncation.
    let w = read_vcd(FIXTURE.trim_end().as_bytes()).unwrap();
    assert_eq!(w.signals().len(), 3);
}

#[test]
fn garbage_and_other_errors() {
    let e = read_vcd(&b"hello, this is not a VCD file"[..]).unwrap_err();
    assert!(matches!(e, VcdError::Syntax { line: 1, .. }), "{e:?}");
    let no_ts = FIXTURE.replace("$timescale 10 ns $end", "");
    assert_eq!(read_vcd(no_ts.as_bytes()), Err(VcdError::MissingTimescale));
    let unknown = FIXTURE.replace("#12\n0!", "#12\n0?");
    assert!(matches!(
        read_vcd(unknown.as_bytes()),
        Err(VcdError::UnknownIdCode { ref code, .. }) if code == "?"
    ));
    let back = FIXTURE.replace("#12", "#4");
    assert!(matches!(
        read_vcd(back.as_bytes()),
        Err(VcdError::TimeBackwards {
            time: 4,
            previous: 7,
            ..
        })
    ));
    let huge = FIXTURE.replace("$timescale 10 ns $end", "$timescale 100 s $end");
    let huge = huge.replace("#12", "#18446744073709551615");
    let r = read_vcd(huge.as_bytes());
    assert!(matches!(r, Err(VcdError::TimeOverflow { .. })), "{r:?}");
    let midline_garbage = FIXTURE.replace("#5\n", "#5\n@@@\n");
    assert!(matches!(
        read_vcd(midline_garbage.as_bytes()),
        Err(VcdError::Syntax { .. })
    ));
}

#[test]
fn timescales_convert_to_ps() {
    for (ts, ps_per_unit) in [
        ("1 s", 1_000_000_000_000u64),
        ("1 us", 1_000_000),
        ("100 ps", 100),
    ] {
        let text = FIXTURE.replace("10 ns", ts);
        let w = read_vcd(text.as_bytes()).unwrap();
        assert_eq!(
            w.get("D0").unwrap().changes()[0],
            (3 * ps_per_unit, true),
            "{ts}"
        );
    }
    // fs rounds to the nearest ps: 1500 fs -> 2 ps (half up), 4000 fs -> 4 ps.
    let text = FIXTURE.replace("10 ns", "1 fs").replace("#3\n", "#1500\n");
    let text = text.replace("#5\n", "#4000\n").replace("#7\n", "#6000\n");
    let text = text.replace("#12\n", "#12000\n").replace("#20", "#20000");
    let w = read_vcd(text.as_bytes()).unwrap();
    assert_eq!(w.get("D0").unwrap().changes()[..2], [(2, true), (4, false)]);
}

#[test]
fn write_is_standard_and_round_trips() {
    let mut w = Waveform::new();
    w.add(
        Signal::from_changes("CLK", false, [(0, true), (250_000, false), (500_001, true)]).unwrap(),
    )
    .unwrap();
    w.add(Signal::from_changes("SYNC", true, [(250_000, false)]).unwrap())
        .unwrap();
    w.add(Signal::new("Z", false)).unwrap();
    let mut out = Vec::new();
    write_vcd(&mut out, &w, WriteTimescale::Ps).unwrap();
    let text = String::from_utf8(out).unwrap();
    assert!(text.contains("$timescale 1 ps $end"), "{text}");
    assert!(text.contains("$scope module bridge $end"), "{text}");
    assert!(text.contains("$var wire 1 ! CLK $end"), "{text}");
    assert!(text.contains("$dumpvars"), "{text}");
    assert_eq!(read_vcd(text.as_bytes()).unwrap(), w);

    // 1 ns output rounds to whole ns.
    let mut out = Vec::new();
    write_vcd(&mut out, &w, WriteTimescale::Ns).unwrap();
    let back = read_vcd(out.as_slice()).unwrap();
    // (A change at 0 is the initial level.)
    assert!(back.get("CLK").unwrap().initial());
    assert_eq!(
        back.get("CLK").unwrap().changes(),
        &[(250_000, false), (500_000, true)]
    );

    let mut bad = Waveform::new();
    bad.add(Signal::new("has space", false)).unwrap();
    assert!(matches!(
        write_vcd(Vec::new(), &bad, WriteTimescale::Ps),
        Err(VcdError::InvalidName { .. })
    ));
}

fn arb_signal(name: &'static str) -> impl Strategy<Value = Signal> {
    (
        any::<bool>(),
        prop::collection::vec((1u64..1_000_000, any::<bool>()), 0..40),
    )
        .prop_map(move |(init, steps)| {
            let mut t = 0;
            let mut s = Signal::new(name, init);
            for (dt, l) in steps {
                t += dt;
                s.push(t, l).unwrap();
            }
            s
        })
}

proptest! {
    #[test]
    fn model_vcd_model_is_identity(a in arb_signal("CLK"), b in arb_signal("SYNC"), c in arb_signal("X")) {
        let mut w = Waveform::new();
        w.add(a).unwrap();
        w.add(b).unwrap();
        w.add(c).unwrap();
        let mut out = Vec::new();
        write_vcd(&mut out, &w, WriteTimescale::Ps).unwrap();
        prop_assert_eq!(read_vcd(out.as_slice()).unwrap(), w);
    }

    #[test]
    fn arbitrary_bytes_never_panic(data in prop::collection::vec(any::<u8>(), 0..400)) {
        let _ = read_vcd(data.as_slice());
    }

    #[test]
    fn any_prefix_of_fixture_never_panics(cut in 0usize..FIXTURE.len()) {
        if let Some(prefix) = FIXTURE.get(..cut) {
            let _ = read_vcd(prefix.as_bytes());
        }
    }
}

#[test]
fn written_text_layout() {
    let mut w = Waveform::new();
    w.add(Signal::from_changes("CLK", false, [(10, true), (20, false)]).unwrap())
        .unwrap();
    w.add(Signal::from_changes("SYNC", true, [(20, false)]).unwrap())
        .unwrap();
    let mut out = Vec::new();
    write_vcd(&mut out, &w, WriteTimescale::Ps).unwrap();
    let text = String::from_utf8(out).unwrap();
    let body = &text[text.find("$timescale").unwrap()..];
    assert_eq!(
        body,
        "$timescale 1 ps $end\n$scope module bridge $end\n$var wire 1 ! CLK $end\n\
         $var wire 1 \" SYNC $end\n$upscope $end\n$enddefinitions $end\n#0\n$dumpvars\n0!\n1\"\n\
         $end\n#10\n1!\n#20\n0!\n0\"\n"
    );
}

#[test]
fn file_helpers() {
    let dir = std::env::temp_dir().join(format!("host-tests-vcd-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("out.vcd");
    let mut w = Waveform::new();
    w.add(Signal::from_changes("CLK", false, [(5, true)]).unwrap())
        .unwrap();
    host_tests::vcd_io::write_vcd_file(&path, &w, WriteTimescale::Ps).unwrap();
    let back = host_tests::vcd_io::read_vcd_file(&path, &["CLK"], &NameMap::new()).unwrap();
    assert_eq!(back, w);
    let missing = dir.join("missing.vcd");
    let e = host_tests::vcd_io::read_vcd_file(&missing, &["CLK"], &NameMap::new()).unwrap_err();
    assert!(matches!(e, VcdError::Io { ref message } if message.contains("missing.vcd")));
    std::fs::remove_dir_all(&dir).unwrap();
}
