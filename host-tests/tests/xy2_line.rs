//! XY2-100 end to end at line level: `xy2::tx` BSRR words -> waveform -> impairments ->
//! the input DMA's port samples -> `xy2::rx`, at 0.5, 2 and 4 MHz.
//!
//! What is checked, per run of a few thousand random frames:
//! - every `LineEvent::Frame` equals the frame sent at its place (the accepted frames
//!   are a strictly increasing subsequence of the sent ones; frames carry 48 random
//!   bits, so a corrupted frame matching a later one by chance is not a concern);
//! - every frame no impairment touched is recovered;
//! - any chunking of the sample buffer gives identical events.
//!
//! The impairments keep to what a receiver can be expected to catch (see the `rx`
//! module docs): at most one glitch per frame on one line (a burst of several on
//! CLK, which only ever adds edges), jitter and skew inside the half-bit sampling
//! margin, clock stops with every line held (transmitter pauses), CLK-only dropouts
//! that lose a number of bits that is not a multiple of 20, and a line stuck or broken
//! for the rest of the run.

use std::collections::BTreeSet;

use host_tests::impair;
use host_tests::line::drive::{bsrr_to_wave, OutPinMap as DriveMap};
use host_tests::line::roles;
use host_tests::line::sample::{xy2_port_words, PinMap as SampleMap};
use host_tests::wave::{Ps, Waveform};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use shared::model::{Command, ForwardFrame, LineEvent, Position};
use shared::xy2::rx::{PinMap, Receiver};
use shared::xy2::tx::{OutPinMap, Transmitter, TxFrame};
use shared::xy2::{Frame, LinkConfig, Mode, Parity};

/// Output port: CLK 0, SYNC 3, X 5, Y 9, Z 12.
const OUT: OutPinMap = OutPinMap {
    clk: 0,
    sync: 3,
    x: 5,
    y: 9,
    z: Some(12),
};
/// Input port, wired differently: SYNC 2, X 7, Y 1, Z 14.
const IN: PinMap = PinMap {
    sync: 2,
    x: 7,
    y: 1,
    z: Some(14),
};

/// How a line fails for the rest of the run.
#[derive(Clone, Copy, Debug)]
enum Stuck {
    None,
    Line(&'static str, bool),
}

struct Run {
    rate_hz: f64,
    frames: usize,
    seed: u64,
    stuck: Stuck,
    /// With [`Parity::Ignore`] only the header checks a word, so the SYNC framing is
    /// what stands between a misaligned word and the bridge: those runs glitch CLK and
    /// SYNC only (a flipped data bit would pass, by design of that setting).
    parity: Parity,
}

/// The neutral frame the receiver should report for a sent frame.
fn expected(f: &TxFrame) -> ForwardFrame {
    let mut out = ForwardFrame::default();
    let pos = |v: u16| Position::from_raw(u32::from(v), 16).ok();
    match f.x {
        Frame::Position16(v) => out.axes[0] = pos(v),
        Frame::Command { command, parameter } => {
            out.command = Some(Command::Xy2Enhanced { command, parameter })
        }
        Frame::Position18(_) => unreachable!("16-bit link"),
    }
    if let Frame::Position16(v) = f.y {
        out.axes[1] = pos(v);
    }
    if let Some(Frame::Position16(v)) = f.z {
        out.axes[2] = pos(v);
    }
    out
}

fn random_frame(rng: &mut ChaCha8Rng) -> TxFrame {
    let x = if rng.random_range(0..20) == 0 {
        Frame::Command {
            command: rng.random(),
            parameter: rng.random(),
        }
    } else {
        Frame::Position16(rng.random())
    };
    TxFrame {
        x,
        y: Frame::Position16(rng.random()),
        z: Some(Frame::Position16(rng.random())),
    }
}

fn drive_map() -> DriveMap {
    DriveMap {
        clk: OUT.clk,
        sync: OUT.sync,
        x: OUT.x,
        y: OUT.y,
        z: OUT.z,
        u: None,
        w: None,
    }
}

fn sample_map() -> SampleMap {
    SampleMap {
        sync: IN.sync,
        x: IN.x,
        y: IN.y,
        z: IN.z,
        status: None,
    }
}

fn falling(wave: &Waveform) -> usize {
    wave.get(roles::CLK)
        .map_or(0, |s| s.falling_edges().count())
}

/// Runs one scenario; returns (frames sent, frames received).
fn run(r: &Run) -> (usize, usize) {
    let mut rng = ChaCha8Rng::seed_from_u64(r.seed);
    let ticks = [40, 40, 44, 52][rng.random_range(0..4)];
    let link = LinkConfig {
        mode: Mode::Standard16,
        parity: r.parity,
    };
    let tx = Transmitter::new(OUT, ticks, link).unwrap();
    let sent: Vec<TxFrame> = (0..r.frames).map(|_| random_frame(&mut rng)).collect();
    let mut buf = vec![0u32; ticks * sent.len()];
    tx.write_half(&mut buf, &sent).unwrap();

    // Transmitter pauses: the clock stops (high or low) with every line held, then
    // goes on. Invisible to the receiver. Frame start ticks are tracked through them.
    let mut words = Vec::with_capacity(buf.len() * 2);
    let mut starts = Vec::with_capacity(sent.len() + 1);
    for slot in buf.chunks_exact(ticks) {
        starts.push(words.len());
        for (k, &w) in slot.iter().enumerate() {
            words.push(w);
            if rng.random_range(0..400) == 0 && k < 40 {
                let pause = rng.random_range(1..300);
                words.extend(std::iter::repeat_n(0u32, pause));
            }
        }
    }
    starts.push(words.len());

    let tick_ps = 1e12 / (2.0 * r.rate_hz);
    let t0: Ps = 1_000_000;
    let mut wave = bsrr_to_wave(&words, tick_ps, t0, &drive_map(), &[]).unwrap();

    // Frames that an impairment may have cost (frame 0: a fresh receiver cannot know
    // that the first high SYNC sample it sees is bit 1).
    let mut affected = BTreeSet::from([0usize]);
    let ppm = rng.random_range(-20_000.0..20_000.0);
    // Time of `tick` ticks after frame n's start, before and after the rate offset.
    let raw = |n: usize, tick: f64| t0 as f64 + (starts[n] as f64 + tick) * tick_ps;
    let time = |n: usize, tick: f64| (raw(n, tick) / (1.0 + ppm * 1e-6)) as Ps;

    // CLK-only dropouts (a loose clock wire) while the other lines go on. Each must
    // lose a number of samples that is not a multiple of 20, or SYNC could not tell
    // (see the rx module docs); the length is nudged until it does.
    for _ in 0..r.frames / 300 {
        let n = rng.random_range(1..r.frames - 4);
        let from = raw(n, rng.random_range(0.0..ticks as f64)) as Ps;
        let mut to = from + (rng.random_range(1.0..2.5 * ticks as f64) * tick_ps) as Ps;
        let before = falling(&wave);
        loop {
            let mut w = wave.clone();
            impair::gap(&mut w, roles::CLK, from, to, false).unwrap();
            let lost = before - falling(&w);
            if !lost.is_multiple_of(20) {
                wave = w;
                break;
            }
            to += (tick_ps / 2.0) as Ps;
        }
        let last = (0..starts.len())
            .take_while(|&k| raw(k, 0.0) <= to as f64)
            .count();
        affected.extend(n..=last);
    }

    impair::rate_offset_ppm(&mut wave, ppm).unwrap();
    let margin = (tick_ps / 8.0) as u64;
    impair::jitter(&mut wave, &[], margin, rng.random()).unwrap();
    let skews: Vec<(&str, i64)> = [roles::SYNC, roles::X, roles::Y, roles::Z]
        .iter()
        .map(|&name| (name, rng.random_range(-(margin as i64)..=margin as i64)))
        .collect();
    impair::skew(&mut wave, &skews).unwrap();

    // Single glitches: one line per impaired frame, never two neighbouring frames.
    let lines = if r.parity == Parity::Ignore {
        &[roles::CLK, roles::SYNC][..]
    } else {
        &[roles::CLK, roles::SYNC, roles::X, roles::Y, roles::Z][..]
    };
    let mut n = 1;
    while n + 2 < r.frames {
        n += rng.random_range(3..20);
        if n + 2 >= r.frames {
            break;
        }
        let line = lines[rng.random_range(0..lines.len())];
        // A glitch up to 1.5 ticks wide covers at most one sampling edge (they are two
        // ticks apart, jitter included); several on CLK only add edges.
        let (count, width) = if line == roles::CLK {
            (rng.random_range(1..5), tick_ps / 2.0)
        } else {
            (1, tick_ps * 1.5)
        };
        let window = (time(n, 1.0), time(n + 1, -1.0));
        let width = width as u64;
        impair::noise_burst(&mut wave, line, window, count, width, rng.random()).unwrap();
        affected.extend([n, n + 1]);
    }

    let stuck_from = r.frames * 6 / 7;
    if let Stuck::Line(name, level) = r.stuck {
        impair::stuck_at(&mut wave, name, time(stuck_from, 0.5), level).unwrap();
        affected.extend(stuck_from..r.frames);
    }

    let samples = xy2_port_words(&wave, &sample_map()).unwrap();
    let mut rx = Receiver::new(IN, link).unwrap();
    let mut events = Vec::new();
    rx.feed(&samples, &mut |e| events.push(e));

    // Any chunking, identical events.
    let mut chunked = Vec::new();
    let mut rx2 = Receiver::new(IN, link).unwrap();
    let mut rest = &samples[..];
    while !rest.is_empty() {
        let k = rng.random_range(1..=rest.len().min(3000));
        let (a, b) = rest.split_at(k);
        rx2.feed(a, &mut |e| chunked.push(e));
        rest = b;
    }
    assert_eq!(
        chunked, events,
        "seed {}: chunking changed the events",
        r.seed
    );

    // Every accepted frame is the sent frame at its place.
    let want: Vec<ForwardFrame> = sent.iter().map(expected).collect();
    let mut next = 0;
    let mut received = BTreeSet::new();
    for e in &events {
        e.line_events(&mut |le| {
            if let LineEvent::Frame(f) = le {
                let k = (next..want.len())
                    .find(|&k| want[k] == f)
                    .unwrap_or_else(|| {
                        panic!("seed {}: frame {f:?} was never sent after #{next}", r.seed)
                    });
                received.insert(k);
                next = k + 1;
            }
        });
    }
    for k in 0..r.frames {
        assert!(
            affected.contains(&k) || received.contains(&k),
            "seed {} rate {} ticks {ticks}: intact frame {k} lost",
            r.seed,
            r.rate_hz
        );
    }
    if let Stuck::Line(..) = r.stuck {
        assert!(
            received.iter().all(|&k| k < stuck_from + 1),
            "seed {}",
            r.seed
        );
    }
    let c = rx.counters();
    assert!(c.framing > 0, "the glitches must have been seen");
    (r.frames, received.len())
}

#[test]
fn impaired_links_at_three_clock_rates() {
    let stucks = [
        Stuck::None,
        Stuck::Line(roles::X, true),
        Stuck::Line(roles::Y, false),
        Stuck::Line(roles::SYNC, true),
        Stuck::Line(roles::SYNC, false),
        Stuck::Line(roles::CLK, false),
        Stuck::Line(roles::Z, true),
    ];
    let mut total = (0, 0);
    for (i, rate_hz) in [0.5e6, 2e6, 4e6].into_iter().enumerate() {
        for (s, parity) in [Parity::WholeFrame, Parity::Ignore, Parity::DataOnly]
            .into_iter()
            .enumerate()
        {
            let seed = (s * 3 + i) as u64;
            let r = Run {
                rate_hz,
                frames: 2500,
                seed,
                stuck: stucks[seed as usize % stucks.len()],
                parity,
            };
            let (s, g) = run(&r);
            total = (total.0 + s, total.1 + g);
        }
    }
    // Most frames get through: impairments touch a small share.
    assert!(total.1 * 10 > total.0 * 8, "{total:?}");
}
