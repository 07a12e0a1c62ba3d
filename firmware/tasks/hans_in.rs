//! HANS-100 controller input: the five oversampled channels (`drivers::hans_lines`)
//! -> `shared::hans::rx::HansRx` in the configured decode mode -> the bridge's
//! [`LineEvent`]s.
//!
//! Two tasks, because the receiver is the most expensive code of the firmware
//! (README "Measured figures": about 1 950 instructions per 10 us frame in normal
//! mode, 3 110 for vote3, 3 920..4 080 for vote5 / super, against 4 800 cycles per
//! frame at 480 MHz):
//! * [`hans_in`] (line executor) only moves DMA halves into [`HANS_INPUT`], like the
//!   other line tasks;
//! * [`hans_decode`] (decode executor, below the line executor and above thread
//!   mode) decodes them and queues the events in [`HANS_EVENTS`], which the bridge
//!   loop drains like the XY2 / XY3 receivers' events ([`take_events`], called from
//!   `bridge_core`).
//!
//! Decoding in the bridge loop, as for XY2 / XY3, would block it for a whole half
//! (about 100 us in normal mode, 200 us in super mode): the HANS-100 head loop must
//! write a slot every 10 us and the waveform loop has one queued batch of slack. In
//! the decode executor both output loops preempt the decoder, and the decoder
//! preempts thread mode, so its latency does not depend on thread-mode work. The
//! load governor (`super::governor`) keeps it from starving thread mode when it
//! cannot keep up: it pauses the decoder beyond its share of the core and drops
//! halves that waited too long (counted; the bridge sees the gaps as faults and its
//! input timeout decides). The receiver coasts across such a gap (`HansRx::skip`):
//! shedding a half does not cost a new acquisition (hunt, then the young lock's
//! ~1.7x CPU for 32 frames, nothing published for the first 8).

use embassy_futures::yield_now;
use embassy_time::{Instant, Timer};
use heapless::Vec;
use shared::bridge::HansDecode;
use shared::governor::Class;
use shared::hans::follow::Follow;
use shared::hans::rx::{HansRx, Mode};
use shared::model::{FaultKind, Line, LineEvent};

use super::governor::{self, Busy};
use super::Irqs;
use crate::board::{HansInRes, Xy3InRes, HANS_FS_HZ};
use crate::channels::{
    HansRaw, Stats, HANS_EVENTS, HANS_EVENTS_DEPTH, HANS_INPUT, HANS_IN_HALF, STATS,
};
use crate::drivers::hans_lines::{HansInput, CHANNELS};
use crate::drivers::oversample_clock::Fs;
use crate::drivers::spi_slave_rx::RxError;
use crate::hans_rings;

/// Words fed to the receiver at a time: about 2.5 frame periods, so the events of
/// one chunk always fit [`CHUNK_EVENTS`] and reach the bridge without waiting for
/// the rest of the half.
const CHUNK: usize = 64;

/// Events one chunk can produce at most: each of its (at most 3) frame periods
/// gives a frame or a period fault, and per channel a check failure, resync,
/// disagreement or missing pattern.
const CHUNK_EVENTS: usize = 3 * (2 + 2 * CHANNELS);

/// The receiver's mode for `controller.hans.decode`.
pub fn mode_of(decode: HansDecode) -> Mode {
    match decode {
        HansDecode::Normal(channel) => Mode::Normal { channel },
        HansDecode::Vote3(channels) => Mode::Vote3 { channels },
        HansDecode::Vote5 => Mode::Vote5,
        HansDecode::Super => Mode::Super,
    }
}

/// HANS-100 controller input (controller side): the channels `mode` uses, on
/// SPI1..5 clocked by fs (TIM3 CH1 on the SCK bus). Every DMA half of the used
/// channels goes to [`HANS_INPUT`] without waiting. An overrun on any channel ends
/// the session (the channels are no longer aligned); a new one starts them together
/// again, and the decoder starts a new receiver on the new session.
#[embassy_executor::task]
pub async fn hans_in(x: Xy3InRes, h: HansInRes, fs: Fs, mode: Mode) {
    let mut fs = fs;
    let mut input = HansInput::new(x, h, hans_rings!(2 * HANS_IN_HALF));
    let used = mode.channel_mask();
    let mut session = 0u32;
    loop {
        let e = hans_session(&mut input, &mut fs, used, session).await;
        fs.hold_low();
        defmt::warn!("hans in: {}; restarting all channels together", e);
        Stats::bump(&STATS.input_overruns);
        // A failure that repeats at once must not spin the high-priority executor.
        Timer::after_millis(1).await;
        session = session.wrapping_add(1);
    }
}

/// One session of [`hans_in`]: returns when a channel fails (never otherwise).
async fn hans_session(
    input: &mut HansInput<'static>,
    fs: &mut Fs,
    used: u8,
    session: u32,
) -> RxError {
    let mut lines = match input.start(used, Irqs, fs) {
        Ok(l) => l,
        Err(e) => return e,
    };
    let mut raw = HansRaw {
        session,
        first_word: 0,
        ready: 0,
        words: [[0; HANS_IN_HALF]; CHANNELS],
    };
    loop {
        if let Err(e) = lines.read(&mut raw.words).await {
            return e;
        }
        raw.ready = Instant::now().as_ticks();
        // Never wait for the decoder: a full queue loses this half (the decoder
        // sees the gap in `first_word`).
        if HANS_INPUT.try_send(raw.clone()).is_ok() {
            Stats::bump(&STATS.input_halves);
        } else {
            Stats::bump(&STATS.input_overruns);
        }
        raw.first_word = raw.first_word.wrapping_add(HANS_IN_HALF as u32);
    }
}

/// HANS-100 controller decoder (decode executor, see the module docs): each half
/// from [`HANS_INPUT`] the governor admits goes through `HansRx` in `mode`
/// ([`CHUNK`] words at a time) and the events go to [`HANS_EVENTS`] in order. A half
/// that does not continue the last decoded one is reported as a `Dropped` fault on
/// the framing line. Which receiver decodes it is `shared::hans::follow`'s rule
/// (the head STATUS decoder follows it too): when halves of the same session are
/// missing (lost on a full queue or dropped by the governor) the receiver is told
/// how many words (`HansRx::skip`, the gap from `first_word`): the sender's clock
/// ran on, so a settled lock coasts across and decodes again from the first frame
/// after the gap, instead of paying a new hunt and young lock for the shed load. A
/// new session (the channels restarted, their words no longer the same stream) or
/// a gap beyond `HansRx::max_gap_words` starts a fresh receiver.
#[embassy_executor::task]
pub async fn hans_decode(mode: Mode) {
    // The one constructor: the first receiver here, every fresh one in
    // `Follow::apply`.
    let fresh = || HansRx::new(HANS_FS_HZ, mode);
    let mut rx = match fresh() {
        Ok(rx) => rx,
        Err(e) => {
            // Not expected (the configuration was validated and fs is in range);
            // without a decoder the bridge sees no input and keeps the gate off.
            defmt::error!("hans decode: {}; no controller input", e);
            return;
        }
    };
    let mut follow = Follow::new();
    let mut events: Vec<(u32, LineEvent), CHUNK_EVENTS> = Vec::new();
    loop {
        let raw = HANS_INPUT.receive().await;
        // Pauses here while over its share of the core; a dropped half leaves a
        // gap in `first_word`, so the next decoded one reports it.
        if !governor::admit(Class::Essential, raw.ready).await {
            continue;
        }
        let mut busy = Busy::new();
        // Only a dropped lock reports anything (at most one resync per channel, a
        // period resync and a missing per channel).
        let step = busy.run(|| {
            follow.apply(
                &mut rx,
                raw.session,
                raw.first_word,
                HANS_IN_HALF as u32,
                fresh,
                &mut |ev| {
                    if events.push((raw.first_word, ev.to_line_event())).is_err() {
                        Stats::bump(&STATS.input_overruns);
                    }
                },
            )
        });
        if step.lost() {
            let gap = LineEvent::Fault {
                line: Line::Framing,
                kind: FaultKind::Dropped,
            };
            HANS_EVENTS.send((raw.first_word, gap)).await;
        }
        for ev in events.drain(..) {
            HANS_EVENTS.send(ev).await;
        }
        for at in (0..HANS_IN_HALF).step_by(CHUNK) {
            let chunk = |n: usize| {
                raw.words
                    .get(n)
                    .and_then(|w| w.get(at..at + CHUNK))
                    .unwrap_or_default()
            };
            let chunks = [chunk(0), chunk(1), chunk(2), chunk(3), chunk(4)];
            // Each event with its word position in the input stream (the bridge
            // loop spreads them over its output slots by it).
            let base = raw.first_word.wrapping_add(at as u32);
            busy.run(|| {
                rx.push_at(&chunks, &mut |pos, ev| {
                    let word = base.wrapping_add(pos as u32);
                    if events.push((word, ev.to_line_event())).is_err() {
                        // Not reachable (CHUNK_EVENTS bounds a chunk), but never silent.
                        Stats::bump(&STATS.input_overruns);
                    }
                })
            });
            for ev in events.drain(..) {
                HANS_EVENTS.send(ev).await;
            }
        }
        busy.report(Class::Essential);
        // `receive` does not yield when the next half is already queued: let the
        // HANS STATUS decoder on the same executor have its turn.
        yield_now().await;
    }
}

/// The decoded events waiting for the bridge, in order (the bridge loop's input for
/// a HANS-100 controller), each as `(position, units, event)` for
/// `shared::bridge::pacing::batch_slot`: its word position counted from the first
/// event taken, and the span from the first to the last event taken (the decoder
/// runs apart from the bridge loop, so the span of the input halves is not known
/// here). At most one queue's worth is taken per call.
pub(super) fn take_events(sink: &mut impl FnMut(u32, u32, LineEvent)) {
    let mut taken: Vec<(u32, LineEvent), HANS_EVENTS_DEPTH> = Vec::new();
    while !taken.is_full() {
        let Ok(ev) = HANS_EVENTS.try_receive() else {
            break;
        };
        // Cannot fail: the loop stops when `taken` is full.
        let _ = taken.push(ev);
    }
    let (Some(&(first, _)), Some(&(last, _))) = (taken.first(), taken.last()) else {
        return;
    };
    let units = last.wrapping_sub(first).saturating_add(1);
    for (word, ev) in taken {
        sink(word.wrapping_sub(first), units, ev);
    }
}
