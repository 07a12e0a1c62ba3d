//! The once-a-second defmt summary: what the line tasks counted ([`STATS`], taken and
//! zeroed), the output ring guards' misses (read from the guards, which keep on
//! counting while the bridge loop is stalled), the head's alarms, and the bridge
//! engine's own view (counters, link state, alarms) from a [`BridgeSnapshot`] the
//! bridge task copies on request.

use core::sync::atomic::Ordering;

use embassy_time::{with_timeout, Duration, Ticker};
use shared::bridge::{Counters, LineCounters};
use shared::model::{Axis, Line};

use crate::channels::{
    BridgeSnapshot, Stats, BRIDGE_SNAPSHOT, HEAD_STATUS, SNAPSHOT_WANTED, STATS,
};

/// How long to wait for the bridge's snapshot: it answers within one output batch
/// (at most 250 us); longer means it is not running (stalled, or never started).
const SNAPSHOT_WAIT: Duration = Duration::from_millis(5);

/// Every line the bridge counts faults on, in print order.
const LINES: [Line; 13] = [
    Line::Axis(Axis::X),
    Line::Axis(Axis::Y),
    Line::Axis(Axis::Z),
    Line::Axis(Axis::U),
    Line::Axis(Axis::W),
    Line::HansChannel(1),
    Line::HansChannel(2),
    Line::HansChannel(3),
    Line::HansChannel(4),
    Line::HansChannel(5),
    Line::Framing,
    Line::Status,
    Line::Backchannel,
];

/// `now - before` per field (the bridge's counters saturate, so they never go back).
fn line_delta(now: LineCounters, before: LineCounters) -> LineCounters {
    LineCounters {
        check_failed: now.check_failed.saturating_sub(before.check_failed),
        framing: now.framing.saturating_sub(before.framing),
        resyncs: now.resyncs.saturating_sub(before.resyncs),
        dropped: now.dropped.saturating_sub(before.dropped),
        missing: now.missing.saturating_sub(before.missing),
        disagree: now.disagree.saturating_sub(before.disagree),
    }
}

/// Prints the bridge's view: link state, gate and alarms, then what its counters
/// gained since `before`, then one line per input line that had faults.
fn print_bridge(s: &BridgeSnapshot, before: &Counters) {
    let c = &s.counters;
    let d = |now: u64, old: u64| now.saturating_sub(old);
    defmt::info!(
        "1 s bridge: {}, gate {}, alarms own {=u32:#x} reported {=u32:#x}; frames ok {}, \
         not forwarded {}, repeated {}, skipped {}, commands forwarded {} / not carried {}, \
         laser not carried {}, input losses {}, recoveries {}, status losses {}",
        s.state,
        s.gate,
        s.alarms.0,
        s.reported.0,
        d(c.frames_ok, before.frames_ok),
        d(c.not_forwarded, before.not_forwarded),
        d(c.repeated, before.repeated),
        d(c.skipped, before.skipped),
        d(c.commands_forwarded, before.commands_forwarded),
        d(c.commands_not_carried, before.commands_not_carried),
        d(c.laser_not_carried, before.laser_not_carried),
        d(c.input_losses, before.input_losses),
        d(c.recoveries, before.recoveries),
        d(c.status_losses, before.status_losses),
    );
    for line in LINES {
        let f = line_delta(c.line(line), before.line(line));
        if f.total() > 0 {
            defmt::info!(
                "1 s bridge {}: check failed {}, framing {}, resyncs {}, dropped {}, missing {}, \
                 disagree {}",
                line,
                f.check_failed,
                f.framing,
                f.resyncs,
                f.dropped,
                f.missing,
                f.disagree,
            );
        }
    }
}

/// The decode executor's second (HANS-100 decoders and their load governor), if it
/// did anything: halves decoded and dropped per decoder, the governor's pauses, and
/// the busy time (the share of the second, and the longest half).
fn print_decode() {
    let s = &STATS;
    let decoded = Stats::take(&s.decoded_halves);
    let drops = Stats::take(&s.decode_drops);
    let status = Stats::take(&s.status_decoded);
    let status_drops = Stats::take(&s.status_drops);
    let pauses = Stats::take(&s.decode_pauses);
    let paused_us = Stats::take(&s.decode_paused_us);
    let busy_us = Stats::take(&s.decode_busy_us);
    let busy_max_us = Stats::take(&s.decode_busy_max_us);
    if decoded + drops + status + status_drops + pauses == 0 {
        return;
    }
    // Per mille of the second (the ticker's period).
    let busy_permille = busy_us / 1_000;
    defmt::info!(
        "1 s decode: input {} halves ({} dropped), status {} halves ({} dropped), \
         {} pauses ({} us), busy {}.{} % (longest half {} us)",
        decoded,
        drops,
        status,
        status_drops,
        pauses,
        paused_us,
        busy_permille / 10,
        busy_permille % 10,
        busy_max_us,
    );
}

/// Once a second: a defmt summary of what the line tasks counted, the head's alarms
/// and the bridge's own counters, link state and alarms.
#[embassy_executor::task]
pub async fn stats() {
    let mut head = HEAD_STATUS.anon_receiver();
    let mut ticker = Ticker::every(Duration::from_secs(1));
    let mut before = Counters::default();
    // `output_frames` counts on (the activity LED watches it), `input_overruns`
    // too (the HIL tests compare it across a run, `super::input_overruns`), and the
    // guards' misses live in the guards (`super::guard_misses`): print their gain.
    let mut frames_before = STATS.output_frames.load(Ordering::Relaxed);
    let mut overruns_before = super::input_overruns();
    let mut misses_before = super::guard_misses();
    loop {
        ticker.next().await;
        // Ask first: the bridge answers after its current batch, while the line
        // counters below are printed.
        BRIDGE_SNAPSHOT.reset();
        SNAPSHOT_WANTED.store(true, Ordering::Relaxed);
        let alarms = head.try_get().map(|s| s.alarms.0).unwrap_or(0);
        let s = &STATS;
        let frames = s.output_frames.load(Ordering::Relaxed);
        let overruns = super::input_overruns();
        let misses = super::guard_misses();
        defmt::info!(
            "1 s: in {} halves ({} lost, {} SYNC marks), out {} frames ({} refused), {} halves \
             ({} underruns, {} guard misses, {} status realigns), back {} packets ({} resyncs, \
             {} errors), status changes {} ({} bad frames), head alarms {=u32:#x}",
            Stats::take(&s.input_halves),
            overruns.wrapping_sub(overruns_before),
            Stats::take(&s.sync_marks),
            frames.wrapping_sub(frames_before),
            Stats::take(&s.output_refused),
            Stats::take(&s.output_halves),
            Stats::take(&s.output_underruns),
            misses.wrapping_sub(misses_before),
            Stats::take(&s.status_realigns),
            Stats::take(&s.back_packets),
            Stats::take(&s.back_resyncs),
            Stats::take(&s.back_errors),
            Stats::take(&s.status_changes),
            Stats::take(&s.status_faults),
            alarms,
        );
        frames_before = frames;
        overruns_before = overruns;
        misses_before = misses;
        print_decode();
        match with_timeout(SNAPSHOT_WAIT, BRIDGE_SNAPSHOT.wait()).await {
            Ok(snap) => {
                print_bridge(&snap, &before);
                before = snap.counters;
            }
            Err(_) => {
                SNAPSHOT_WANTED.store(false, Ordering::Relaxed);
                defmt::warn!("1 s bridge: no snapshot (bridge loop not running)");
            }
        }
    }
}
