//! The check against synthetic captures: the waveform a USART with the firmware's
//! settings makes (100 MHz kernel clock, DE lead and tail 8 sixteenths of a bit,
//! 240 MHz capture clock), then the same with one thing broken at a time.

use super::*;
use proptest::prelude::*;
use std::vec::Vec;

/// The firmware's backchannel at 921600 baud (BRR 109) or 115200 (BRR 868).
fn setup(kernel_clocks_per_bit: u32) -> Setup {
    Setup {
        kernel_hz: 100_000_000,
        kernel_clocks_per_bit,
        samples_per_bit: 16,
        lead_samples: 8,
        tail_samples: 8,
        capture_hz: 240_000_000,
        tolerance_ns: 40,
    }
}

const FAST: u32 = 109;
const SLOW: u32 = 868;

/// One bit in capture ticks.
fn bit_ticks(s: &Setup) -> f64 {
    f64::from(s.kernel_clocks_per_bit) * f64::from(s.capture_hz) / f64::from(s.kernel_hz)
}

/// `samples` sample times in capture ticks.
fn samples(s: &Setup, samples: f64) -> f64 {
    samples * bit_ticks(s) / f64::from(s.samples_per_bit)
}

/// How the synthetic USART behaves.
#[derive(Clone, Copy)]
struct Behaviour {
    /// DE lead and tail, capture ticks.
    lead: f64,
    tail: f64,
    /// Bit time actually sent, capture ticks.
    bit: f64,
    /// Idle time between messages, capture ticks.
    gap: f64,
}

fn nominal(s: &Setup) -> Behaviour {
    Behaviour {
        lead: samples(s, 8.0),
        tail: samples(s, 8.0),
        bit: bit_ticks(s),
        gap: 40.0 * bit_ticks(s),
    }
}

/// TX and DE edge times (rounded to capture ticks) of `messages` sent as `b` says,
/// the first DE edge 1000 ticks into the capture.
fn wave(b: Behaviour, messages: &[&[u8]]) -> (Vec<u32>, Vec<u32>) {
    let mut tx = Vec::new();
    let mut de = Vec::new();
    let tick = |t: f64| t.round() as u32;
    let mut t = 1000.0 + b.lead;
    for msg in messages {
        de.push(tick(t - b.lead));
        for &v in *msg {
            // Start bit, data LSB first, stop bit; the line is high before.
            let levels = core::iter::once(false)
                .chain((0..8).map(|i| v >> i & 1 == 1))
                .chain(core::iter::once(true));
            let mut high = true;
            for (k, level) in levels.enumerate() {
                if level != high {
                    tx.push(tick(t + k as f64 * b.bit));
                    high = level;
                }
            }
            t += 10.0 * b.bit;
        }
        de.push(tick(t + b.tail));
        t += b.gap;
    }
    (tx, de)
}

fn run(s: &Setup, tx: &[u32], de: &[u32], messages: &[&[u8]]) -> Result<Measured, DeError> {
    check(
        s,
        Edges {
            initial_high: true,
            times: tx,
        },
        Edges {
            initial_high: false,
            times: de,
        },
        messages,
    )
}

/// Two messages whose bytes give every edge pattern: 0x00 (one edge in the stop bit
/// only), 0xFF (the start bit only), alternating bits.
const MSG_A: &[u8] = &[0x48, 0x41, 0x00, 0x48, 0x06, 0x14, 0xFF, 0x55];
const MSG_B: &[u8] = &[0xAA, 0x00, 0xFF, 0x01, 0x80, 0x7E];
const BOTH: &[&[u8]] = &[MSG_A, MSG_B];

#[test]
fn usart_waveform_passes_at_both_rates() {
    for (brr, lead_ns) in [(FAST, 545), (SLOW, 4340)] {
        let s = setup(brr);
        let (tx, de) = wave(nominal(&s), BOTH);
        let m = run(&s, &tx, &de, BOTH).unwrap();
        for span in [m.lead_ns, m.tail_ns] {
            // Configured: 8/16 of BRR kernel clocks at 100 MHz; ticks are 4.2 ns.
            assert!((span.min - lead_ns).abs() <= 5, "{brr}: {span:?}");
            assert!((span.max - lead_ns).abs() <= 5, "{brr}: {span:?}");
        }
        // Window: configured - 40 ns .. configured + one sample + 40 ns.
        let sample = lead_ns / 8;
        let w = m.lead_window_ns;
        assert!((w.min - (lead_ns - 40)).abs() <= 1, "{w:?}");
        assert!((w.max - (lead_ns + sample + 40)).abs() <= 1, "{w:?}");
        assert_eq!(m.tail_window_ns, m.lead_window_ns);
    }
}

#[test]
fn de_lead_bounds() {
    let s = setup(FAST);
    let b = nominal(&s);
    let tol = 40.0 * 0.24;
    let cases = [
        // Up to one sample long: the USART's sample-clock quantisation.
        (b.lead + samples(&s, 1.0), true),
        (b.lead - tol / 2.0, true),
        (b.lead - 2.0 * tol, false),
        (b.lead + samples(&s, 1.0) + 2.0 * tol, false),
        (0.0, false),
        (-samples(&s, 4.0), false),
    ];
    for (lead, ok) in cases {
        let (tx, de) = wave(Behaviour { lead, ..b }, BOTH);
        let r = run(&s, &tx, &de, BOTH);
        match r {
            Ok(_) => assert!(ok, "lead {lead} passed"),
            Err(DeError::DeLate {
                message: 0,
                lead_ns,
            }) => {
                assert!(!ok && lead < b.lead, "lead {lead}: late {lead_ns}");
                assert!((lead_ns as f64 - lead / 0.24).abs() < 5.0);
            }
            Err(DeError::DeEarly { message: 0, .. }) => assert!(!ok && lead > b.lead),
            Err(e) => panic!("lead {lead}: {e}"),
        }
    }
}

#[test]
fn de_tail_bounds() {
    let s = setup(SLOW);
    let b = nominal(&s);
    let cases = [
        (b.tail + samples(&s, 0.9), true),
        (b.tail - 5.0, true),
        // Released at the end of the stop bit: DEDT not applied.
        (0.0, false),
        // Inside the stop bit: the last stop bit is cut on the bus.
        (-samples(&s, 8.0), false),
        (b.tail + samples(&s, 3.0), false),
        // Held on for a byte time: the reply would collide.
        (10.0 * b.bit, false),
    ];
    for (tail, ok) in cases {
        let (tx, de) = wave(Behaviour { tail, ..b }, BOTH);
        match run(&s, &tx, &de, BOTH) {
            Ok(_) => assert!(ok, "tail {tail} passed"),
            Err(DeError::DeReleasedEarly {
                message: 0,
                tail_ns,
            }) => {
                assert!(!ok && tail < b.tail, "tail {tail}");
                assert!((tail_ns as f64 - tail / 0.24).abs() < 5.0);
            }
            Err(DeError::DeHeld { message: 0, .. }) => assert!(!ok && tail > b.tail),
            Err(e) => panic!("tail {tail}: {e}"),
        }
    }
}

#[test]
fn de_outside_the_messages_fails() {
    let s = setup(FAST);
    let (tx, de) = wave(nominal(&s), BOTH);
    // A pulse in the idle time between the messages (e.g. while receiving).
    let between = (de[1] + de[2]) / 2;
    let mut extra = de.clone();
    extra.splice(2..2, [between, between + 500]);
    assert_eq!(
        run(&s, &tx, &extra, BOTH),
        Err(DeError::DeEdges {
            got: 6,
            expected: 4
        })
    );
    // Never released after the last message.
    assert_eq!(
        run(&s, &tx, &de[..3], BOTH),
        Err(DeError::DeEdges {
            got: 3,
            expected: 4
        })
    );
    // No DE at all (a GPIO held low, or DEM off).
    assert_eq!(
        run(&s, &tx, &[], BOTH),
        Err(DeError::DeEdges {
            got: 0,
            expected: 4
        })
    );
    // Asserted from the start.
    let r = check(
        &s,
        Edges {
            initial_high: true,
            times: &tx,
        },
        Edges {
            initial_high: true,
            times: &de,
        },
        BOTH,
    );
    assert_eq!(r, Err(DeError::DeAssertedAtStart));
    // One pulse over both messages: the count is short, and DE was high between them.
    let one = [de[0], de[3]];
    assert!(matches!(
        run(&s, &tx, &one, BOTH),
        Err(DeError::DeEdges { got: 2, .. })
    ));
}

#[test]
fn tx_faults_fail() {
    let s = setup(FAST);
    let b = nominal(&s);
    let (tx, de) = wave(b, BOTH);

    // A different byte on the line.
    let mut wrong = MSG_B.to_vec();
    wrong[3] ^= 0x10;
    let sent: &[&[u8]] = &[MSG_A, &wrong];
    assert_eq!(
        run(&s, &tx, &de, sent),
        Err(DeError::TxByte {
            message: 1,
            index: 3,
            got: 0x01,
            expected: 0x11
        })
    );
    // A byte fewer sent than expected, or one more.
    let longer = [MSG_B, &[0x42]].concat();
    let sent: &[&[u8]] = &[MSG_A, &longer];
    assert_eq!(
        run(&s, &tx, &de, sent),
        Err(DeError::TxCount {
            got: 14,
            expected: 15
        })
    );
    let sent: &[&[u8]] = &[MSG_A, &MSG_B[..5]];
    assert_eq!(
        run(&s, &tx, &de, sent),
        Err(DeError::TxCount {
            got: 14,
            expected: 13
        })
    );
    // A glitch pair in the middle of a bit of byte 2.
    let mut glitch = tx.clone();
    let at = tx[4] + 60;
    let i = glitch.partition_point(|&t| t < at);
    glitch.splice(i..i, [at, at + 10]);
    assert!(matches!(
        run(&s, &glitch, &de, BOTH),
        Err(DeError::TxOffGrid { .. })
    ));
    // 2 % slow: the grid drifts out of tolerance within a frame.
    let (slow_tx, slow_de) = wave(
        Behaviour {
            bit: b.bit * 1.02,
            ..b
        },
        BOTH,
    );
    assert!(matches!(
        run(&s, &slow_tx, &slow_de, BOTH),
        Err(DeError::TxOffGrid { byte: 0, .. })
    ));
    // Idle before the capture started: TX low.
    let r = check(
        &s,
        Edges {
            initial_high: false,
            times: &tx,
        },
        Edges {
            initial_high: false,
            times: &de,
        },
        BOTH,
    );
    assert_eq!(r, Err(DeError::TxNotIdle));
    // A break (line low from a start edge on): the stop bit is low.
    assert_eq!(
        run(&s, &tx[..1], &de[..2], &[&[0x00]]),
        Err(DeError::TxFraming { byte: 0 })
    );
}

#[test]
fn a_gap_inside_a_message_fails() {
    let s = setup(FAST);
    let b = nominal(&s);
    // Message A in two parts, 3 bits apart, with DE around the whole.
    let (first, _) = wave(b, &[&MSG_A[..4]]);
    let (second, _) = wave(b, &[&MSG_A[4..]]);
    let shift = (4.0 * 10.0 * b.bit + 3.0 * b.bit).round() as u32;
    let tx: Vec<u32> = first
        .iter()
        .copied()
        .chain(second.iter().map(|t| t + shift))
        .collect();
    let end = tx[tx.len() - 1] + (2.0 * b.bit) as u32;
    let de = [1000, end];
    match run(&s, &tx, &de, &[MSG_A]) {
        Err(DeError::TxGap {
            message: 0,
            index: 4,
            gap_ns,
        }) => assert!((gap_ns - 3270).abs() < 10, "{gap_ns}"),
        r => panic!("{r:?}"),
    }
}

#[test]
fn bad_input_is_refused() {
    let s = setup(FAST);
    let (tx, de) = wave(nominal(&s), BOTH);
    let mut unordered = tx.clone();
    unordered.swap(5, 6);
    assert_eq!(
        run(&s, &unordered, &de, BOTH),
        Err(DeError::Unordered {
            pin: Pin::Tx,
            index: 6
        })
    );
    let de_twice = [de[0], de[0], de[2], de[3]];
    assert_eq!(
        run(&s, &tx, &de_twice, BOTH),
        Err(DeError::Unordered {
            pin: Pin::De,
            index: 1
        })
    );
    for bad in [
        Setup {
            samples_per_bit: 12,
            ..s
        },
        Setup { kernel_hz: 0, ..s },
        Setup { capture_hz: 0, ..s },
        // 0.5 capture ticks per bit.
        Setup {
            kernel_clocks_per_bit: 2,
            capture_hz: 25_000_000,
            ..s
        },
        Setup {
            kernel_clocks_per_bit: u32::MAX,
            kernel_hz: 1,
            capture_hz: u32::MAX,
            ..s
        },
    ] {
        assert_eq!(run(&bad, &tx, &de, BOTH), Err(DeError::BadSetup));
    }
    assert_eq!(run(&s, &tx, &de, &[]), Err(DeError::BadSetup));
    assert_eq!(run(&s, &tx, &de, &[MSG_A, &[]]), Err(DeError::BadSetup));
    // Every error has a message.
    let e = DeError::DeHeld {
        message: 1,
        tail_ns: 9000,
    };
    assert_eq!(
        e.to_string(),
        "DE fell 9000 ns after message 1's stop bit, more than configured"
    );
}

fn messages() -> impl Strategy<Value = Vec<Vec<u8>>> {
    prop::collection::vec(prop::collection::vec(any::<u8>(), 1..12), 1..4)
}

proptest! {
    /// Any bytes, any lead and tail inside the window, either rate: accepted, and
    /// the measured times are the ones synthesised.
    #[test]
    fn usart_waveforms_pass(
        msgs in messages(),
        fast in any::<bool>(),
        lead_frac in 0.0f64..1.0,
        tail_frac in 0.0f64..1.0,
    ) {
        let s = setup(if fast { FAST } else { SLOW });
        let b = nominal(&s);
        let b = Behaviour {
            lead: b.lead + lead_frac * samples(&s, 1.0),
            tail: b.tail + tail_frac * samples(&s, 1.0),
            ..b
        };
        let refs: Vec<&[u8]> = msgs.iter().map(Vec::as_slice).collect();
        let (tx, de) = wave(b, &refs);
        let m = run(&s, &tx, &de, &refs).unwrap();
        prop_assert!((m.lead_ns.min as f64 - b.lead / 0.24).abs() < 5.0);
        prop_assert!((m.tail_ns.max as f64 - b.tail / 0.24).abs() < 5.0);
    }

    /// One TX edge lost (a capture overrun, a dropped edge): never accepted.
    #[test]
    fn a_lost_tx_edge_fails(msgs in messages(), which in any::<prop::sample::Index>()) {
        let s = setup(FAST);
        let refs: Vec<&[u8]> = msgs.iter().map(Vec::as_slice).collect();
        let (mut tx, de) = wave(nominal(&s), &refs);
        tx.remove(which.index(tx.len()));
        prop_assert!(run(&s, &tx, &de, &refs).is_err());
    }

    /// One DE edge moved by more than a sample plus the tolerance: never accepted.
    #[test]
    fn a_moved_de_edge_fails(
        msgs in messages(),
        which in any::<prop::sample::Index>(),
        later in any::<bool>(),
        extra in 1.0f64..30.0,
    ) {
        let s = setup(FAST);
        let refs: Vec<&[u8]> = msgs.iter().map(Vec::as_slice).collect();
        let (tx, mut de) = wave(nominal(&s), &refs);
        let i = which.index(de.len());
        let by = (samples(&s, 1.0) + 10.0 + extra).round() as u32;
        de[i] = if later { de[i] + by } else { de[i] - by };
        prop_assert!(run(&s, &tx, &de, &refs).is_err());
    }
}
