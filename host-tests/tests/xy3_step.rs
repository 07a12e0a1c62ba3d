//! XY3-100 lines out of step, end to end on the host pipeline: one data line's SPI
//! slave sees clock edges the others miss (`impair::sck_glitch`), the pipeline's
//! XY3-100 input runs the firmware's `shared::xy3::step::StepWatch`, and
//! `stimulus::xy3_sessions` restarts the SPI slaves together when it asks, as the
//! firmware's line task does (`firmware/tasks/line.rs`, `xy3_in`).
//!
//! Run with `-- --nocapture` for the table of glitches, restart times and frames
//! lost.

use std::collections::HashMap;

use host_tests::impair;
use host_tests::line::roles;
use host_tests::line::sample::PartialByte;
use host_tests::pipeline::check::{expected, raw};
use host_tests::pipeline::stimulus::{self, GenTiming, SessionModel, Stimulus, Xy3Session};
use host_tests::pipeline::{Options, Pipeline};
use host_tests::wave::{Ps, Signal, Waveform};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use shared::bridge::{Config, LinkState, Protocol, Timing, Xy3Select, ZSource};
use shared::model::{Axis, FaultKind, ForwardFrame, Line};
use shared::xy3::step::{GOOD_RUN, MAX_BACKOFF, OUT_OF_STEP_NS};
use shared::xy3::FrameSize;

/// Controller frame period (100 kHz).
const PERIOD_PS: Ps = 10_000_000;
/// The received lines (`z.source = "input"`).
const LINES: [&str; 3] = [roles::X, roles::Y, roles::Z];

/// XY3-100 in and out, slaved (every forwarded frame is written to the head, so
/// the head output shows each one), Z received, the default fail-safe policy
/// (input timeout 1 ms, hold 10 ms then park, 100 recovery frames); no head status
/// supervision (no status line in these runs).
fn config() -> Config {
    let mut c = Config::default();
    c.controller.protocol = Protocol::Xy3;
    c.head.protocol = Protocol::Xy3;
    c.z.source = ZSource::Input;
    c.output.timing = Timing::Slaved;
    c.failsafe.status_timeout_us = 0;
    c
}

fn timing(size: FrameSize) -> GenTiming {
    GenTiming {
        start_ps: 2_000_000,
        period_ps: PERIOD_PS,
        xy3_size: size,
    }
}

/// `n` frames of random 16-bit positions (widened to the frame size): a line out
/// of step reads random bits, as the step watch's rule assumes.
fn frames(c: &Config, t: &GenTiming, n: usize, rng: &mut ChaCha8Rng) -> Vec<ForwardFrame> {
    let shift = t.xy3_size.position_bits() - 16;
    (0..n)
        .map(|_| {
            let mut v = || u32::from(rng.random::<u16>()) << shift;
            let xyz = [v(), v(), v()];
            stimulus::frame(c, t, xyz, None)
        })
        .collect()
}

/// One run through the session model, and what the head got.
struct Run {
    p: Pipeline,
    stim: Stimulus,
    sessions: Vec<Xy3Session>,
    /// Head-side raw values of each input frame -> its index.
    index: HashMap<[Option<u32>; 5], usize>,
}

impl Run {
    fn new(
        c: &Config,
        t: &GenTiming,
        sent: &[ForwardFrame],
        model: &SessionModel,
        impair: impl FnOnce(&mut Waveform),
    ) -> Run {
        let mut stim = stimulus::controller_signal(c, sent, t).expect("stimulus");
        impair(&mut stim.wave);
        let mut p = Pipeline::new(c, Options::default()).expect("pipeline");
        // Less than the input timeout past the end: the states show the run, not
        // the controller going quiet after it.
        let end_ns = stim.wave.end_time() / 1000 + 300_000;
        let sessions =
            stimulus::xy3_sessions(&mut p, c, &stim.wave, model, end_ns).expect("sessions");
        let index = stim
            .sent
            .iter()
            .enumerate()
            .map(|(i, s)| (expected(c, &s.frame).0, i))
            .collect();
        Run {
            p,
            stim,
            sessions,
            index,
        }
    }

    /// For each frame written to the head while the link ran or held: the input
    /// frame it carries. A frame no input frame carries (check (a)) must carry
    /// one on every line but `faulty` (the line the fault hit): an *escape*, a
    /// period of the faulty line that passed its check by chance before the
    /// watch withheld them (see [`GLITCH_ESCAPES`]). Anything else panics.
    fn carried(&self, c: &Config, faulty: Option<usize>, label: &str) -> Vec<Out> {
        let others = |v: &[Option<u32>; 5]| {
            let mut v = *v;
            if let Some(k) = faulty {
                v[k] = None;
            }
            v
        };
        let by_others: HashMap<[Option<u32>; 5], usize> =
            self.index.iter().map(|(v, &i)| (others(v), i)).collect();
        self.p
            .sent()
            .iter()
            .filter(|s| s.state != LinkState::Safe)
            .map(|s| {
                let got = raw(c, &s.frame).0;
                let (input, escape) = match self.index.get(&got) {
                    Some(&i) => (i, false),
                    None => match by_others.get(&others(&got)).filter(|_| faulty.is_some()) {
                        Some(&i) => (i, true),
                        None => panic!(
                            "{label}: the head got {got:?} at {} ns ({:?}), never sent",
                            s.decided_ns, s.state
                        ),
                    },
                };
                Out {
                    t_ns: s.decided_ns,
                    state: s.state,
                    input,
                    escape,
                }
            })
            .collect()
    }

    fn framing(&self, kind: FaultKind) -> u64 {
        let l = self.p.bridge_counters().line(Line::Framing);
        match kind {
            FaultKind::Dropped => l.dropped,
            FaultKind::Resync => l.resyncs,
            _ => unreachable!("only Dropped and Resync are counted here"),
        }
    }
}

/// The wrong frames [`glitched_line_restarts_the_session`] forwards (its seed):
/// (case, input frame after the glitch's) of each shifted period that passed
/// its check by chance and still got out. A period is released only when the
/// next one confirms it, and while a window is open (a bad period seen, no
/// good run since) only when the next two do
/// ([`shared::xy3::step::CONFIRM_OPEN`]); a command on a line other than X
/// without the same one on X is withheld. None at 48 glitches: the table was
/// `[(44, 2)]` (a line a byte early after missed edges, two chance passes
/// right after the first bad period) with one confirming period, and
/// `[(28, 1), (44, 2)]` without the frame-kind rule.
const GLITCH_ESCAPES: [(usize, usize); 0] = [];

/// [`GLITCH_ESCAPES`] for `XY3_STEP_CASES=400` (about 30 s): 9 frames in 9
/// runs, each the glitch's own frame (24-bit frames, slaves dropping partial
/// bytes, 1..3 extra edges: the spoilt frame passes its 2-bit parity, the line
/// is in step again from the next frame, which confirms it). None in the half
/// of the cases with slaves keeping partial bytes; with all 400 dropping them
/// 10 (these and case 374), with all 400 keeping them 3 (cases 84, 128, 232 of
/// [`SOFTWARE_SELECT_ESCAPES_400`]; measured 2026-12-04, not pinned). No bad period
/// comes before or after it, so no rule of the watch can refuse it; counting
/// each line's clock edges would (README "What is left"). Was 11 in 11 with
/// one confirming period (also `(44, 2)` and `(156, 1)`, lasting shifts), 17
/// in 16 without the frame-kind rule, 71 in 60 without the confirmation.
const GLITCH_ESCAPES_400: [(usize, usize); 9] = [
    (80, 0),
    (84, 0),
    (108, 0),
    (136, 0),
    (196, 0),
    (212, 0),
    (232, 0),
    (288, 0),
    (332, 0),
];

/// The wrong frames [`glitched_line_with_software_select`] forwards, 48 cases:
/// none.
const SOFTWARE_SELECT_ESCAPES: [(usize, usize); 0] = [];

/// [`SOFTWARE_SELECT_ESCAPES`] for `XY3_STEP_CASES=400`: 3 frames in 3 runs,
/// against 9 with the mixed slaves of [`GLITCH_ESCAPES_400`] (all in the half that
/// drops partial bytes) and 10 when all 400 drop them (those 9 and case 374:
/// every one the glitch's own frame of a glitch the line heals from). With no
/// NSS nothing heals: every glitch restarts the session, and what is left is
/// the same as with slaves that keep partial bytes in all 400 (3 in 3): the
/// glitch's own frame when the first shifted period after it passes its check
/// by chance and confirms it (cases 84 and 232, 24-bit, +1..3 edges; the hold
/// then repeats that frame with the laser gate off until the new session
/// runs), and one lasting shift whose third shifted period passed with the two
/// after it (case 128). Needing two confirming periods outside an open window
/// too would leave case 128 only (measured, not taken: one more period of
/// latency on every frame).
const SOFTWARE_SELECT_ESCAPES_400: [(usize, usize); 3] = [(84, 0), (128, 2), (232, 0)];

/// The wrong frames [`stuck_line_restarts_with_backoff_and_never_forwards`]
/// forwards: the case of each frame the line broke in that still passed its
/// check (the 24-bit parity misses half of such tails). None: the watch holds
/// every good period until the next one confirms it, and the period after the
/// break fails (it was `[0, 2]` without that confirmation).
const STUCK_ESCAPES: [usize; 0] = [];

/// A frame written to the head (not parked), and the input frame it carries.
#[derive(Debug, Clone, Copy)]
struct Out {
    /// When the bridge decided it, ns.
    t_ns: u64,
    state: LinkState,
    /// The input frame (index in the stimulus).
    input: usize,
    /// Wrong on the faulty line (see [`Run::carried`]).
    escape: bool,
}

/// The escapes of one run: the input frames (by index) a wrong frame stood for,
/// with the frames written while running and while holding.
struct Escapes(Vec<(usize, u32, u32)>);

impl Escapes {
    fn of(carried: &[Out]) -> Escapes {
        let mut v: Vec<(usize, u32, u32)> = Vec::new();
        for o in carried.iter().filter(|o| o.escape) {
            if v.last().is_none_or(|e| e.0 != o.input) {
                v.push((o.input, 0, 0));
            }
            if let Some(e) = v.last_mut() {
                match o.state {
                    LinkState::Running => e.1 += 1,
                    _ => e.2 += 1,
                }
            }
        }
        Escapes(v)
    }

    fn print(&self, fault_frame: usize) {
        for (i, run, hold) in &self.0 {
            println!(
                "  escape: input frame {i} (fault in {fault_frame}) wrong on the faulty line: \
                 {run} frame(s) running, {hold} holding"
            );
        }
    }
}

/// The state changes after the link first ran.
fn states_after_running(p: &Pipeline) -> Vec<(u64, LinkState)> {
    let s = p.states();
    let first = s
        .iter()
        .position(|c| c.value == LinkState::Running)
        .expect("the link ran");
    s[first..].iter().map(|c| (c.t_ns, c.value)).collect()
}

/// The clock edges a slave on `sck` samples in each frame (NSS low, up to and
/// including that frame's NSS rise; index 0 is before the first rise): the
/// slave ignores an edge while NSS is high.
fn sampled_per_frame(w: &Waveform, sck: &str) -> Vec<u32> {
    let nss = w.get(roles::SYNC).expect("SYNC");
    let ends: Vec<Ps> = nss.rising_edges().collect();
    let mut n = vec![0u32; ends.len() + 1];
    let sck = w.get(sck).expect("SCK");
    for t in sck.falling_edges().filter(|&t| !nss.level_at(t)) {
        n[ends.partition_point(|&e| e <= t)] += 1;
    }
    n
}

/// Whether the glitch on `line` in `w` leaves that line out of step until a
/// restart, from the edges its slave *samples* against the shared clock's: a
/// slave that keeps partial bytes, or one without SS (which samples every edge),
/// carries any bit shift on; one that drops them
/// at NSS release is out of step only when some frame ends with another number
/// of whole bytes (8 or more extra edges in that frame, or any missed one) and
/// drops up to 7 extra bits with the frame that had them. Not the glitch's
/// nominal edge count: the spikes of a glitch on a frame's last pulse fall in
/// the gap to the next frame, where NSS is high for most of it, and the slave
/// samples only those after NSS falls again (case 169 of 400 with the seed
/// below: +9 edges, one sampled; see [`glitch_on_a_frames_last_pulse`]).
fn persists(w: &Waveform, line: &str, partial: PartialByte) -> bool {
    let clk = sampled_per_frame(w, roles::CLK);
    let own = sampled_per_frame(w, &roles::spi_sck(line));
    assert_eq!(clk.len(), own.len());
    match partial {
        PartialByte::Discard => clk.iter().zip(&own).any(|(c, o)| c / 8 != o / 8),
        PartialByte::CarryOver => clk.iter().sum::<u32>() != own.iter().sum::<u32>(),
        // No NSS: every edge counts, also the spikes in a gap with SYNC high.
        PartialByte::Unselected => {
            let all = |n: &str| w.get(n).expect("SCK").falling_edges().count();
            all(roles::CLK) != all(&roles::spi_sck(line))
        }
    }
}

/// DMA half duration for `size` frames at [`PERIOD_PS`], ns.
fn half_ns(size: FrameSize) -> u64 {
    let bytes_per_frame = u64::from(size.bits()) / 8;
    stimulus::XY3_HALF as u64 * PERIOD_PS / 1000 / bytes_per_frame
}

/// Randomised over frame size, the slaves' partial-byte behaviour, the line, the
/// glitch time and the number of extra or missed edges: (a) no frame the head
/// gets was never sent; (b) the periods of the shifted session are withheld
/// (counted as faults, none forwarded); (c) a lasting shift restarts the session
/// within the watch's limit plus detection and the restart's own time, and
/// forwarding resumes with every frame in order; (d) meanwhile the bridge holds
/// the last position (never parks: the restart comes well inside the hold time);
/// a shift the slaves drop by themselves restarts nothing. SYNC is the slaves'
/// NSS (`controller.xy3.select = "sync"`); half of the cases model slaves that
/// drop a partial byte at NSS release, half slaves that keep it (RM0433 leaves
/// it open, `PartialByte`).
#[test]
fn glitched_line_restarts_the_session() {
    campaign(
        Xy3Select::Sync,
        |case| {
            if case % 4 < 2 {
                PartialByte::Discard
            } else {
                PartialByte::CarryOver
            }
        },
        &GLITCH_ESCAPES,
        &GLITCH_ESCAPES_400,
    );
}

/// The same glitches (same seed, so the same sizes, lines, times and edges) with
/// software slave select (`controller.xy3.select = "always"`): no slave ever drops
/// a bit, so every glitch shifts its line for good and restarts the session
/// (wrong frames that get out: [`SOFTWARE_SELECT_ESCAPES`]).
#[test]
fn glitched_line_with_software_select() {
    campaign(
        Xy3Select::Always,
        |_| PartialByte::Unselected,
        &SOFTWARE_SELECT_ESCAPES,
        &SOFTWARE_SELECT_ESCAPES_400,
    );
}

/// The glitch campaign of [`glitched_line_restarts_the_session`] with the slaves
/// selected by `select`, case `k` modelled as `partial_of(k)`; `want` and
/// `want_400` pin the escapes of 48 and 400 (`XY3_STEP_CASES=400`) cases.
fn campaign(
    select: Xy3Select,
    partial_of: impl Fn(usize) -> PartialByte,
    want_48: &[(usize, usize)],
    want_400: &[(usize, usize)],
) {
    let mut rng = ChaCha8Rng::seed_from_u64(0x0573_57E9);
    let mut c = config();
    c.controller.xy3.select = select;
    let n = 3_000;
    let mut withheld_total = 0;
    let mut restarted = 0;
    println!(
        "size  partial    line edges  glitch_us  request_us  restart_us  resume_us  lost  withheld"
    );
    let mut escapes = Vec::new();
    // 48 by default; `XY3_STEP_CASES=400` for the longer campaign (its escapes
    // are pinned too).
    let cases: usize = match std::env::var("XY3_STEP_CASES").as_deref() {
        Ok("400") => 400,
        Ok(other) => panic!("XY3_STEP_CASES={other}: 48 (unset) or 400"),
        Err(_) => 48,
    };
    for case in 0..cases {
        let size = if case % 2 == 0 {
            FrameSize::Bits24
        } else {
            FrameSize::Bits32
        };
        let partial = partial_of(case);
        let t = timing(size);
        let sent = frames(&c, &t, n, &mut rng);
        let faulty = rng.random_range(0..LINES.len());
        let line = LINES[faulty];
        // One to three edges, or more than a byte's worth.
        let mut edges = [1, 2, 3, 9][rng.random_range(0..4)];
        if rng.random::<bool>() {
            edges = -edges;
        }
        // Inside frame `f` (or its idle gap: the next pulse then is frame f + 1's).
        let f = rng.random_range(300..1_500);
        let at_ps = t.start_ps + f as Ps * PERIOD_PS + rng.random_range(0..PERIOD_PS);
        let model = SessionModel {
            partial,
            ..SessionModel::default()
        };
        let label = format!("case {case}: {size:?} {partial:?} {line} {edges:+} at {at_ps} ps");
        let run = Run::new(&c, &t, &sent, &model, |w| {
            impair::sck_glitch(w, roles::CLK, line, at_ps, edges).expect("glitch");
        });
        let lasting = persists(&run.stim.wave, line, partial);
        let at_ns = at_ps / 1000;
        let carried = run.carried(&c, Some(faulty), &label);
        let esc = Escapes::of(&carried);
        esc.print(f);
        for (k, &(i, running, held)) in esc.0.iter().enumerate() {
            escapes.push((case, i - f));
            let last = k + 1 == esc.0.len();
            // Written once while running. A lasting shift then loses the input:
            // the hold repeats the last one (with the laser gate off, below)
            // until the new session runs. A shift the slaves drop at the frame
            // end costs no more than that frame (the next one replaces it).
            assert_eq!(running, 1, "{label}");
            assert_eq!(held > 0, last && lasting, "{label}");
        }
        let states = states_after_running(&run.p);
        // (d) never parked.
        assert!(
            states.iter().all(|s| s.1 != LinkState::Safe),
            "{label}: parked {states:?}"
        );
        let dropped = run.framing(FaultKind::Dropped);
        let resyncs = run.framing(FaultKind::Resync);
        assert_eq!(resyncs as usize, run.sessions.len() - 1, "{label}");
        if !lasting {
            assert_eq!(run.sessions.len(), 1, "{label}: {:?}", run.sessions);
            // The bad period drops the good one the watch held for its
            // confirmation (when the period before the bad one was good); a
            // glitched period that passed its check as a command on a line
            // other than X is withheld too (its kinds disagree).
            assert!(dropped <= 2, "{label}: {dropped} dropped");
            assert!(
                states.iter().all(|s| s.1 == LinkState::Running),
                "{label}: {states:?}"
            );
            // At most the glitch's frame and the one held before it are lost.
            let idx: Vec<usize> = carried.iter().map(|c| c.input).collect();
            let gaps: usize = idx.windows(2).map(|w| w[1] - w[0] - 1).sum();
            assert!(gaps <= 1 + dropped as usize, "{label}: {gaps} frames lost");
            println!(
                "{:>4}  {:<9}  {line:>4} {edges:>+5}  {:>9}  {:>10}  {:>10}  {:>9}  {:>4}  {:>8}",
                size.bits(),
                format!("{partial:?}"),
                at_ns / 1000,
                "-",
                "-",
                "-",
                gaps,
                0
            );
            continue;
        }
        restarted += 1;
        assert_eq!(run.sessions.len(), 2, "{label}: {:?}", run.sessions);
        let (old, new) = (run.sessions[0], run.sessions[1]);
        let request = old.requested_ns.expect("requested");
        // (c) the request: the watch's window opens at the first bad period (in
        // the half after the glitch) and asks once it is OUT_OF_STEP_NS old, on a
        // half boundary.
        let h = half_ns(size);
        assert!(
            request >= at_ns + OUT_OF_STEP_NS && request <= at_ns + OUT_OF_STEP_NS + 3 * h,
            "{label}: asked {} us after the glitch",
            (request - at_ns) / 1000
        );
        // The line task ends the session one half later and starts the next.
        assert!(old.end_ns <= request + h + 1_000, "{label}: {old:?}");
        let new_ns = new.start_ps / 1000;
        // (b) nothing of the shifted session is forwarded: every frame written
        // while running carries an input frame from before the glitch or from the
        // new session.
        let first_new = run
            .stim
            .sent
            .iter()
            .position(|s| s.start_ps >= new.start_ps)
            .expect("frames after the restart");
        for o in carried.iter().filter(|o| !o.escape) {
            if o.state == LinkState::Running {
                assert!(
                    o.input <= f || o.input >= first_new,
                    "{label}: input frame {} (glitch in {f}, new session from {first_new}) forwarded at {} ns",
                    o.input,
                    o.t_ns
                );
            }
        }
        // Withheld (one `Dropped` each): the session change, the new session's
        // first GOOD_RUN - 1 good periods (the watch starts it suspect), and the
        // shifted session's periods that passed every check by chance.
        let fresh = 1 + u64::from(GOOD_RUN) - 1;
        assert!(dropped >= fresh, "{label}: {dropped} dropped");
        let withheld = dropped - fresh;
        withheld_total += withheld;
        // (d) held meanwhile: running, holding, running again.
        let kinds: Vec<LinkState> = states.iter().map(|s| s.1).collect();
        assert_eq!(
            kinds,
            [LinkState::Running, LinkState::Holding, LinkState::Running],
            "{label}: {states:?}"
        );
        let held_from = states[1].0;
        assert!(
            held_from > at_ns && held_from < request,
            "{label}: {states:?}"
        );
        // (c) forwarding resumes: the receiver's first periods of the new session
        // (a cut first frame, a hunt at a common bit offset), GOOD_RUN periods
        // the watch still withholds, the bridge's recovery frames, and a half to
        // deliver them.
        let resume = states[2].0;
        // The laser gate is on only while running: off from the hold to the
        // resumption, on again then.
        let gate: Vec<(u64, bool)> = run
            .p
            .gate()
            .iter()
            .filter(|g| g.t_ns > at_ns)
            .map(|g| (g.t_ns, g.value))
            .collect();
        assert!(
            gate.len() == 2 && gate[0] == (held_from, false) && gate[1].1 && gate[1].0 >= resume,
            "{label}: gate {gate:?}, states {states:?}"
        );
        let recovery = u64::from(c.failsafe.recovery_frames);
        let bound = (u64::from(GOOD_RUN) + recovery + 4) * PERIOD_PS / 1000 + 2 * h;
        assert!(
            resume >= new_ns && resume - new_ns <= bound,
            "{label}: resumed {} us after the new session (bound {} us)",
            (resume - new_ns) / 1000,
            bound / 1000
        );
        // From the resumption on, every input frame is forwarded once, in order,
        // up to the last half delivered.
        let after: Vec<usize> = carried
            .iter()
            .filter(|c| c.t_ns >= resume && c.state == LinkState::Running)
            .map(|c| c.input)
            .collect();
        assert!(
            after.windows(2).all(|w| w[1] == w[0] + 1),
            "{label}: frames lost or repeated after resuming"
        );
        let last_sent = after.last().copied().expect("frames after resuming");
        assert!(
            last_sent + 30 >= n,
            "{label}: forwarding stopped at {last_sent}"
        );
        let first_after = after.first().copied().expect("frames after resuming");
        let lost = first_after - f - 1;
        println!(
            "{:>4}  {:<9}  {line:>4} {edges:>+5}  {:>9}  {:>10}  {:>10}  {:>9}  {:>4}  {:>8}",
            size.bits(),
            format!("{partial:?}"),
            at_ns / 1000,
            (request - at_ns) / 1000,
            (new_ns - at_ns) / 1000,
            (resume - at_ns) / 1000,
            lost,
            withheld
        );
    }
    println!(
        "{restarted} of {cases} glitches restarted the session; {} wrong frame(s) forwarded in {} case(s); {withheld_total} shifted periods withheld",
        escapes.len(),
        {
            let mut c: Vec<usize> = escapes.iter().map(|e| e.0).collect();
            c.dedup();
            c.len()
        }
    );
    assert!(restarted >= 24, "only {restarted} cases restarted");
    // Some shifted periods pass every check by chance (random data: up to one in
    // eight for 24-bit frames); the watch must have withheld them.
    assert!(withheld_total > 0, "no period withheld in any case");
    let want = if cases == 400 { want_400 } else { want_48 };
    assert_eq!(escapes, want, "(case, frames after the glitch's)");
}

/// Case 169 of [`glitched_line_restarts_the_session`] run with 400 cases (32-bit
/// frames, slaves dropping partial bytes, +9 edges on Z), pinned: the glitch hit
/// a frame's last clock pulse, so its spikes fall in the gap to the next frame.
/// NSS is high there for all but the last of them, and the slave samples only
/// that one: a single extra bit in the next frame, dropped at that frame's end,
/// so the line is never out of step and nothing asks for a restart (a test-model
/// matter: the rule's nominal edge count was wrong, not the receiver or the
/// watch). Against it, the same glitch one pulse earlier (all 9 spikes sampled:
/// an extra byte) restarts; with slaves that keep partial bytes the one sampled
/// bit shifts the line for good and restarts too, and a +1 glitch there is not
/// sampled at all.
#[test]
fn glitch_on_a_frames_last_pulse() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x1A57);
    let c = config();
    let t = timing(FrameSize::Bits32);
    let sent = frames(&c, &t, 3_000, &mut rng);
    let clean = stimulus::controller_signal(&c, &sent, &t)
        .expect("stimulus")
        .wave;
    // Frame f ends at the f-th NSS rise (0-based); its last two clock pulses.
    let f = 1_000;
    let end = clean
        .get(roles::SYNC)
        .expect("SYNC")
        .rising_edges()
        .nth(f)
        .expect("frame end");
    let pulses: Vec<Ps> = clean
        .get(roles::CLK)
        .expect("CLK")
        .rising_edges()
        .filter(|&r| r < end)
        .collect();
    let (last, before) = (pulses[pulses.len() - 1], pulses[pulses.len() - 2]);
    let faulty = 2;
    let line = LINES[faulty];
    // (partial, edges, pulse) -> (frame, extra edges sampled), lasting shift.
    let cases = [
        (PartialByte::Discard, 9, last, (f + 1, 1), false),
        (PartialByte::Discard, 9, before, (f, 9), true),
        (PartialByte::CarryOver, 9, last, (f + 1, 1), true),
        (PartialByte::CarryOver, 1, last, (0, 0), false),
    ];
    for (partial, edges, at_ps, extra, lasting) in cases {
        let label = format!("{partial:?} {edges:+} at {at_ps} ps");
        let model = SessionModel {
            partial,
            ..SessionModel::default()
        };
        let run = Run::new(&c, &t, &sent, &model, |w| {
            impair::sck_glitch(w, roles::CLK, line, at_ps, edges).expect("glitch");
        });
        let w = &run.stim.wave;
        // What the glitched slave sampled beyond the shared clock, per frame.
        let clk = sampled_per_frame(w, roles::CLK);
        let own = sampled_per_frame(w, &roles::spi_sck(line));
        let diff: Vec<(usize, u32)> = clk
            .iter()
            .zip(&own)
            .enumerate()
            .filter(|(_, (c, o))| c != o)
            .map(|(k, (c, o))| (k, o - c))
            .collect();
        let want: Vec<(usize, u32)> = if extra.1 == 0 { vec![] } else { vec![extra] };
        assert_eq!(diff, want, "{label}");
        assert_eq!(persists(w, line, partial), lasting, "{label}");
        // The glitched line alone, against the clean run: same byte count
        // (Discard, a spare bit dropped; or nothing sampled), and only the
        // frame with the extra bit differs.
        let spi = |w: &Waveform| {
            host_tests::line::sample::xy3_spi_session(w, &[line], partial, 0)
                .expect("spi")
                .bytes
                .remove(0)
        };
        let (got, want) = (spi(w), spi(&clean));
        let differing: Vec<usize> = (0..got.len().min(want.len()))
            .filter(|&i| got[i] != want[i])
            .collect();
        if !lasting {
            assert_eq!(got.len(), want.len(), "{label}");
            assert!(
                differing.iter().all(|&i| i / 4 == extra.0),
                "{label}: bytes {differing:?} differ"
            );
        } else {
            assert!(differing.len() > 100, "{label}: {} differ", differing.len());
        }
        // The pipeline: no frame never sent reaches the head.
        let carried = run.carried(&c, Some(faulty), &label);
        let requests = run.p.xy3_restart_requests();
        if lasting {
            assert_eq!(requests.len(), 1, "{label}: {requests:?}");
            assert_eq!(run.sessions.len(), 2, "{label}");
            let r = requests[0];
            assert!(
                r >= at_ps / 1000 + OUT_OF_STEP_NS,
                "{label}: asked at {r} ns"
            );
        } else {
            assert!(requests.is_empty(), "{label}: {requests:?}");
            assert_eq!(run.sessions.len(), 1, "{label}");
            assert!(carried.iter().all(|o| !o.escape), "{label}");
            assert!(run.framing(FaultKind::Dropped) <= 1, "{label}");
            let states = states_after_running(&run.p);
            assert!(
                states.iter().all(|s| s.1 == LinkState::Running),
                "{label}: {states:?}"
            );
        }
    }
}

/// (e) A line that stays broken (stuck at either level) cannot be fixed by a
/// restart: the watch asks again and again, each time after twice the wait
/// (up to 2^MAX_BACKOFF times the limit), nothing after the break is forwarded,
/// and the bridge parks after its hold time.
#[test]
fn stuck_line_restarts_with_backoff_and_never_forwards() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5_70C4);
    let c = config();
    let mut stuck_escapes = Vec::new();
    for (case, (line, level, size)) in [
        (roles::Y, false, FrameSize::Bits24),
        (roles::X, true, FrameSize::Bits32),
        (roles::Z, true, FrameSize::Bits24),
    ]
    .into_iter()
    .enumerate()
    {
        let t = timing(size);
        let sent = frames(&c, &t, 9_000, &mut rng);
        let from_ps = t.start_ps + 1_000 * PERIOD_PS + PERIOD_PS / 3;
        let label = format!("case {case}: {line} stuck {level} ({size:?})");
        let model = SessionModel {
            partial: if case == 1 {
                PartialByte::CarryOver
            } else {
                PartialByte::Discard
            },
            ..SessionModel::default()
        };
        let run = Run::new(&c, &t, &sent, &model, |w| {
            impair::stuck_at(w, line, from_ps, level).expect("stuck");
        });
        let from_ns = from_ps / 1000;
        // Nothing after the break is forwarded.
        let faulty = LINES.iter().position(|&l| l == line);
        let carried = run.carried(&c, faulty, &label);
        let esc = Escapes::of(&carried);
        esc.print(1_000);
        if !esc.0.is_empty() {
            assert_eq!(
                esc.0.iter().map(|e| e.0).collect::<Vec<_>>(),
                [1_000],
                "{label}"
            );
            stuck_escapes.push(case);
        }
        for o in carried {
            if o.escape {
                continue;
            }
            if o.state == LinkState::Running {
                assert!(
                    o.input <= 1_000,
                    "{label}: input frame {} forwarded at {} ns",
                    o.input,
                    o.t_ns
                );
            }
        }
        let req = run.p.xy3_restart_requests();
        println!("{label}: restart requests at (ms after the break):");
        let mut prev = from_ns;
        for (k, &r) in req.iter().enumerate() {
            let limit = OUT_OF_STEP_NS << (k as u32).min(u32::from(MAX_BACKOFF));
            let gap = r - prev;
            println!(
                "  {:>3}.{:03}  (gap {} us, limit {} us)",
                (r - from_ns) / 1_000_000,
                (r - from_ns) / 1000 % 1000,
                gap / 1000,
                limit / 1000
            );
            // The window opens with the first bad period after the break (or the
            // first one of the new session) and asks once it is `limit` old:
            // plus a half to see it, a half and the set-up to restart.
            assert!(
                gap >= limit && gap <= limit + 700_000,
                "{label}: restart {k} {} us after the one before (limit {} us)",
                gap / 1000,
                limit / 1000
            );
            prev = r;
        }
        // 90 ms of a broken line: 2 + 4 + 8 + 16 + 32 ms, the next 64 ms wait
        // runs past the end.
        assert_eq!(req.len(), 5, "{label}: {req:?}");
        assert_eq!(run.sessions.len(), 6, "{label}");
        // Held for the hold time, then parked, and never running again.
        let states = states_after_running(&run.p);
        let kinds: Vec<LinkState> = states.iter().map(|s| s.1).collect();
        assert_eq!(
            kinds,
            [LinkState::Running, LinkState::Holding, LinkState::Safe],
            "{label}: {states:?}"
        );
        let hold = u64::from(c.failsafe.hold_us) * 1000;
        assert!(states[2].0 >= states[1].0 + hold, "{label}: {states:?}");
        assert!(run
            .p
            .sent()
            .last()
            .is_some_and(|s| s.state == LinkState::Safe));
    }
    assert_eq!(stuck_escapes, STUCK_ESCAPES);
}

/// (f) Clean lines never restart: 200 ms of frames (20 000 periods) per frame
/// size and partial-byte behaviour, one session, nothing withheld, every frame
/// forwarded in order.
#[test]
fn clean_lines_never_restart() {
    let mut rng = ChaCha8Rng::seed_from_u64(0xC1EA);
    for size in [FrameSize::Bits24, FrameSize::Bits32] {
        for (select, partial) in [
            (Xy3Select::Sync, PartialByte::Discard),
            (Xy3Select::Sync, PartialByte::CarryOver),
            (Xy3Select::Always, PartialByte::Unselected),
        ] {
            let mut c = config();
            c.controller.xy3.select = select;
            let label = format!("{size:?} {select:?} {partial:?}");
            let t = timing(size);
            let sent = frames(&c, &t, 20_000, &mut rng);
            let model = SessionModel {
                partial,
                ..SessionModel::default()
            };
            let run = Run::new(&c, &t, &sent, &model, |_| {});
            assert!(run.p.xy3_restart_requests().is_empty(), "{label}");
            assert_eq!(run.sessions.len(), 1, "{label}");
            assert_eq!(run.framing(FaultKind::Dropped), 0, "{label}");
            let k = run.p.bridge_counters();
            for axis in [Axis::X, Axis::Y, Axis::Z] {
                assert_eq!(k.line(Line::Axis(axis)).check_failed, 0, "{label}");
            }
            let idx: Vec<usize> = run
                .carried(&c, None, &label)
                .iter()
                .filter(|c| c.state == LinkState::Running)
                .map(|c| c.input)
                .collect();
            assert!(idx.windows(2).all(|w| w[1] == w[0] + 1), "{label}");
            // The last frames are in the half the waveform's end cut short.
            assert!(idx.last().is_some_and(|&i| i + 30 >= sent.len()), "{label}");
            assert_eq!(
                run.p.states().last().map(|s| s.value),
                Some(LinkState::Running)
            );
        }
    }
}

/// Adds one CLK pulse in every gap between frames, while SYNC is high: a
/// controller whose clock keeps running between frames.
fn clock_between_frames(w: &mut Waveform) {
    let nss = w.get(roles::SYNC).expect("SYNC").clone();
    let clk = w.get_mut(roles::CLK).expect("CLK");
    let mut changes = clk.changes().to_vec();
    let rises: Vec<Ps> = nss.rising_edges().collect();
    for r in rises {
        let Some(f) = nss.falling_edges().find(|&f| f > r) else {
            continue;
        };
        changes.push((r + (f - r) / 3, true));
        changes.push((r + 2 * (f - r) / 3, false));
    }
    changes.sort_unstable();
    *clk = Signal::from_changes(roles::CLK, clk.initial(), changes)
        .expect("CLK with pulses between frames");
}

/// `controller.xy3.select = "always"` needs a controller whose CLK has no falling
/// edge while SYNC is high. One that clocks between frames (here one pulse per
/// gap) shifts those edges into every line's stream: no period decodes, nothing
/// is ever forwarded, and the input restarts with back-off (fails safe). With
/// `"sync"` the same waveform is received whole: the slaves ignore the clock
/// while NSS is high.
#[test]
fn software_select_with_a_clock_between_frames_forwards_nothing() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5E1E);
    let t = timing(FrameSize::Bits24);
    for select in [Xy3Select::Always, Xy3Select::Sync] {
        let mut c = config();
        c.controller.xy3.select = select;
        let sent = frames(&c, &t, 4_000, &mut rng);
        let run = Run::new(
            &c,
            &t,
            &sent,
            &SessionModel::default(),
            clock_between_frames,
        );
        let label = format!("{select:?}");
        let running: Vec<usize> = run
            .carried(&c, None, &label)
            .iter()
            .filter(|o| o.state == LinkState::Running)
            .map(|o| o.input)
            .collect();
        match select {
            Xy3Select::Always => {
                assert!(running.is_empty(), "{label}: forwarded {running:?}");
                assert!(
                    run.p.states().iter().all(|s| s.value != LinkState::Running),
                    "{label}: {:?}",
                    run.p.states()
                );
                // 40 ms of input: restarts after 2, 4, 8, 16 ms of bad periods.
                assert!(run.sessions.len() >= 4, "{label}: {:?}", run.sessions);
            }
            Xy3Select::Sync => {
                assert_eq!(run.sessions.len(), 1, "{label}");
                assert!(running.windows(2).all(|w| w[1] == w[0] + 1), "{label}");
                assert!(running.last().is_some_and(|&i| i + 30 >= sent.len()));
            }
        }
    }
}

/// (g) Halves the bridge never gets (every tenth, as when the line task finds
/// the queue full) on clean lines, with the SYNC marks drained 2 us after a
/// half's last byte (so a half that ends on a frame boundary carries that
/// frame's end): each gap loses the half's frames, and the period held before
/// it when the period after it is whole (the watch takes only a held period's
/// direct successor as its confirmation; a cut first period drops it anyway).
/// No restart, never holding. The stream then stops on a half boundary with a
/// command (a laser-off, say) as its last frame: it still reaches the head
/// before the bridge's input timeout makes it hold.
#[test]
fn lost_halves_cost_the_held_frame_and_the_last_frame_still_arrives() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x6A95);
    let c = config();
    for size in [FrameSize::Bits24, FrameSize::Bits32] {
        let label = format!("{size:?}");
        let t = timing(size);
        // A whole number of halves (32-bit: 16 frames a half; 24-bit: 64 frames
        // in 3 halves), the last one delivered (not a tenth).
        let n = match size {
            FrameSize::Bits24 => 4_800,
            FrameSize::Bits32 => 4_784,
        };
        let halves = n * usize::from(size.bits()) / 8 / stimulus::XY3_HALF;
        let mut sent = frames(&c, &t, n, &mut rng);
        let off = shared::model::Command::Xy3(0x4_0000);
        if let Some(last) = sent.last_mut() {
            *last = stimulus::frame(&c, &t, [0; 3], Some(off));
        }
        let model = SessionModel {
            lose_every: 10,
            ends_lag_ns: 2_000,
            ..SessionModel::default()
        };
        let run = Run::new(&c, &t, &sent, &model, |_| {});
        let mut p = run.p;
        let end_ns = run.stim.wave.end_time() / 1000;
        p.run_until(end_ns + 2 * u64::from(c.failsafe.input_timeout_us) * 1000);
        assert!(p.xy3_restart_requests().is_empty(), "{label}");
        let running: Vec<_> = p
            .sent()
            .iter()
            .filter(|s| s.state == LinkState::Running)
            .collect();
        let last = running.last().expect("frames");
        assert_eq!(last.frame.command, Some(off), "{label}");
        // Released CONFIRM_NS after the last half, inside the input timeout,
        // and the link held only after it.
        let timeout = u64::from(c.failsafe.input_timeout_us) * 1000;
        let hold_from = p
            .states()
            .iter()
            .find(|s| s.value == LinkState::Holding)
            .map(|s| s.t_ns)
            .expect("holds once the input stopped");
        assert!(
            last.decided_ns < hold_from,
            "{label}: {} {hold_from}",
            last.decided_ns
        );
        assert!(last.decided_ns <= end_ns + shared::xy3::step::CONFIRM_NS + 20_000);
        assert!(
            hold_from >= end_ns + timeout - 20_000,
            "{label}: {hold_from}"
        );
        // The gaps: every tenth half lost, each the half's frames (16, or 21
        // and 22 for 24-bit frames, plus the one the gap cuts) and at most the
        // held one before it.
        let index: HashMap<[Option<u32>; 5], usize> = sent
            .iter()
            .enumerate()
            .map(|(i, f)| (expected(&c, f).0, i))
            .collect();
        let idx: Vec<usize> = running[..running.len() - 1]
            .iter()
            .map(|s| index[&raw(&c, &s.frame).0])
            .collect();
        let lost: Vec<usize> = idx
            .windows(2)
            .map(|w| w[1] - w[0] - 1)
            .filter(|&l| l > 0)
            .collect();
        let half = stimulus::XY3_HALF * 8 / usize::from(size.bits());
        let mut hist: Vec<(usize, usize)> = Vec::new();
        for &l in &lost {
            match hist.iter_mut().find(|h| h.0 == l) {
                Some(h) => h.1 += 1,
                None => hist.push((l, 1)),
            }
        }
        hist.sort_unstable();
        println!("{label}: frames lost per gap (lost, gaps): {hist:?}");
        assert_eq!(lost.len(), halves / 10, "{label}: {hist:?}");
        assert!(
            lost.iter().all(|&l| (half..=half + 3).contains(&l)),
            "{label}: {hist:?}"
        );
        if size == FrameSize::Bits32 {
            // A half is 16 whole frames: the period after the gap is whole and
            // good, but not the held one's successor, so that one is lost too.
            assert!(lost.iter().all(|&l| l == half + 1), "{label}: {hist:?}");
        }
        let states: Vec<LinkState> = states_after_running(&p).iter().map(|s| s.1).collect();
        assert_eq!(
            states[..2],
            [LinkState::Running, LinkState::Holding],
            "{label}"
        );
        assert_eq!(run.stim.sent.len(), sent.len());
    }
}

/// The session sampler from time 0 (`xy3_spi`) delivers the encoded frames;
/// started later, it sees only what comes after the start (here inside a
/// frame: the slaves count bytes from the start, drop the partial byte at
/// SYNC, and the next frames are whole; or carry it on, shifting every byte).
#[test]
fn session_sampler_matches_the_spi_model() {
    use host_tests::line::sample::{xy3_spi, xy3_spi_session};
    use shared::xy3::{encode, Frame};
    let mut rng = ChaCha8Rng::seed_from_u64(0x5E55);
    let c = config();
    let t = timing(FrameSize::Bits24);
    let sent = frames(&c, &t, 40, &mut rng);
    let stim = stimulus::controller_signal(&c, &sent, &t).expect("stimulus");
    for partial in [PartialByte::Discard, PartialByte::CarryOver] {
        let whole = xy3_spi(&stim.wave, &LINES, partial).expect("spi");
        // From time 0 every line holds its frames' wire words, 3 bytes a frame
        // (`shared::xy3::encode` as the reference), and each SYNC rise ends one.
        for (l, axis) in [Axis::X, Axis::Y, Axis::Z].into_iter().enumerate() {
            let want: Vec<u8> = stim
                .sent
                .iter()
                .flat_map(|s| {
                    let v = s.frame.axis(axis).expect("position").to_raw(20);
                    let (w, _) = encode(&Frame::Position24(v)).expect("frame");
                    w.to_be_bytes()[1..].to_vec()
                })
                .collect();
            assert_eq!(whole.bytes[l], want, "{partial:?} {axis:?}");
        }
        let ends: Vec<u32> = (1..=sent.len() as u32).map(|k| 3 * k).collect();
        assert_eq!(whole.frame_ends, ends);
        assert_eq!(whole.pending_bits, 0);
        // From the middle of frame 10 (bit 12 of 24).
        let start = t.start_ps + 10 * PERIOD_PS + PERIOD_PS * 12 / 24 / 2;
        let late = xy3_spi_session(&stim.wave, &LINES, partial, start).expect("late");
        let first = whole
            .end_times
            .iter()
            .position(|&e| e > start)
            .expect("an end after the start");
        if partial == PartialByte::Discard {
            // Fewer than 3 bytes of the cut frame (8-bit words from the start,
            // the rest dropped at SYNC), then frames 11.. exactly.
            let (w0, l0) = (
                whole.frame_ends[first] as usize,
                late.frame_ends[0] as usize,
            );
            assert!(l0 < 3, "{l0}");
            for (w, l) in whole.bytes.iter().zip(&late.bytes) {
                assert_eq!(&w[w0..], &l[l0..]);
            }
            assert_eq!(late.frame_ends.len(), whole.frame_ends.len() - first);
        } else {
            // Every bit from the start on, in one stream: the late slaves' bits
            // are the last ones of the whole run's, not on its byte boundaries.
            let bits = |v: &[u8]| -> Vec<bool> {
                v.iter()
                    .flat_map(|b| (0..8).rev().map(move |k| b >> k & 1 != 0))
                    .collect()
            };
            let total = |c: &host_tests::line::sample::SpiCapture| {
                8 * c.bytes[0].len() + usize::from(c.pending_bits)
            };
            let from = total(&whole) - total(&late);
            assert_ne!(from % 8, 0);
            for (w, l) in whole.bytes.iter().zip(&late.bytes) {
                let (w, l) = (bits(w), bits(l));
                assert_eq!(w[from..from + l.len()], l[..]);
            }
        }
    }
}

/// `sck_glitch` changes only the glitched slave's clock, by exactly the edges
/// asked for, and that slave alone then delivers other bytes.
#[test]
fn sck_glitch_adds_and_removes_edges_on_one_slave() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x611C);
    let c = config();
    let t = timing(FrameSize::Bits24);
    let sent = frames(&c, &t, 40, &mut rng);
    let stim = stimulus::controller_signal(&c, &sent, &t).expect("stimulus");
    let falls = |w: &Waveform, name: &str| w.get(name).expect("signal").falling_edges().count();
    let clk = falls(&stim.wave, roles::CLK);
    let at = t.start_ps + 20 * PERIOD_PS + PERIOD_PS / 4;
    for edges in [-3, -1, 1, 2, 9] {
        let mut w = stim.wave.clone();
        impair::sck_glitch(&mut w, roles::CLK, roles::Y, at, edges).expect("glitch");
        assert_eq!(falls(&w, roles::CLK), clk, "{edges}");
        let own = roles::spi_sck(roles::Y);
        assert_eq!(falls(&w, &own) as i64, clk as i64 + i64::from(edges));
        let cap = host_tests::line::sample::xy3_spi_session(&w, &LINES, PartialByte::CarryOver, 0)
            .expect("spi");
        let clean = host_tests::line::sample::xy3_spi(&stim.wave, &LINES, PartialByte::CarryOver)
            .expect("spi");
        // Frames 0..20 (60 bytes) are untouched everywhere; X and Z throughout
        // (cut to the glitched line's count: a slave behind holds the others).
        let n = cap.bytes[0].len();
        assert!(n + 1 >= clean.bytes[0].len(), "{edges}");
        assert_eq!(cap.bytes[0], clean.bytes[0][..n]);
        assert_eq!(cap.bytes[2], clean.bytes[2][..n]);
        assert_eq!(cap.bytes[1][..60], clean.bytes[1][..60]);
        assert_ne!(cap.bytes[1][61..100], clean.bytes[1][61..100], "{edges}");
    }
    let mut w = stim.wave.clone();
    assert!(impair::sck_glitch(&mut w, roles::CLK, roles::Y, at, 0).is_err());
    assert!(impair::sck_glitch(&mut w, roles::CLK, roles::Y, stim.wave.end_time(), 1).is_err());
}
