//! Status tasks: the XY3-100 backchannel (one UART per side) and the XY2-100 STATUS
//! level (head side in, controller side out) in thread mode: status is slow (packets
//! every few milliseconds, a level that changes rarely), so none of this needs an
//! interrupt executor. The HANS-100 STATUS decoder (head side) runs in the decode
//! executor under the load governor (`super::governor`): its receiver costs as much
//! per frame as the controller input's, and in thread mode it would compete with the
//! supervisor instead of being governed.

use embassy_futures::select::{select, Either};
use embassy_stm32::gpio::{Input, Output};
use embassy_stm32::mode::Async;
use embassy_stm32::usart::{RingBufferedUartRx, UartTx};
use embassy_time::{Duration, Ticker};
use shared::model::HeadStatus;
use shared::xy2::{Health, StatusLevel};
use shared::xy3::back::neutral::apply;
use shared::xy3::back::{Event, Packet, Parser};

use core::sync::atomic::Ordering;

use shared::hans::follow::Follow;
use shared::hans::rx::{HansRx, Mode as HansMode, RxEvent};
use shared::hans::StatusReceiver;
use shared::model::FaultKind;

use shared::governor::Class;

use super::governor::{self, Busy};
use crate::board::HANS_FS_HZ;
use crate::channels::{
    Stats, BACK_RATE, BACK_TX, CTRL_STATUS_OK, HANS_HALF, HANS_STATUS_CONTIGUOUS, HANS_STATUS_RAW,
    HEAD_BACK_RATE, HEAD_STATUS, HEALTH, STATS,
};
use crate::drivers::status_level::{StatusIn, StatusOut};

/// XY3-100 backchannel towards the controller (UART7 TX + DE): sends what the bridge
/// queued in [`BACK_TX`] (`Bridge::xy3_back_poll`: the head's status merged with the
/// bridge's alarms, its own identification and frame-error counts, with the SYNC
/// packets the bridge's sender interleaves). [`BACK_RATE`] switches the rate; the
/// bridge raises it only once `BACK_TX` is empty, and the last byte of the write in
/// progress leaves the UART first.
#[embassy_executor::task]
pub async fn back_to_controller(mut tx: UartTx<'static, Async>) {
    let mut out = [0u8; 256];
    loop {
        match select(BACK_RATE.wait(), BACK_TX.read(&mut out)).await {
            Either::First(rate) => {
                if tx.flush().await.is_err() {
                    Stats::bump(&STATS.back_errors);
                }
                match tx.set_baudrate(rate.baud()) {
                    Ok(()) => defmt::info!("backchannel to controller: {} baud", rate.baud()),
                    Err(_) => defmt::error!("backchannel: cannot set {} baud", rate.baud()),
                }
            }
            Either::Second(n) => {
                if tx.write(out.get(..n).unwrap_or_default()).await.is_err() {
                    Stats::bump(&STATS.back_errors);
                }
            }
        }
    }
}

/// XY3-100 backchannel from the head (USART2 RX, its own rate): the head's packets
/// parsed into [`HEAD_STATUS`]. [`HEAD_BACK_RATE`] switches the rate when the bridge
/// forwards a BACK_RATE command to the head; bytes the head sent at the old rate
/// after that are lost to the parser's resync (counted), none are misread: every
/// packet is checked.
#[embassy_executor::task]
pub async fn back_from_head(mut rx: RingBufferedUartRx<'static>) {
    let mut parser = Parser::default();
    let mut status = HeadStatus::default();
    let mut rx_buf = [0u8; 64];
    loop {
        let n = match select(HEAD_BACK_RATE.wait(), rx.read(&mut rx_buf)).await {
            Either::First(rate) => {
                match rx.set_baudrate(rate.baud()) {
                    Ok(()) => defmt::info!("backchannel from head: {} baud", rate.baud()),
                    Err(_) => defmt::error!("backchannel: cannot set {} baud", rate.baud()),
                }
                continue;
            }
            Either::Second(Ok(n)) => n,
            Either::Second(Err(_)) => {
                Stats::bump(&STATS.back_errors);
                continue;
            }
        };
        let mut changed = false;
        for &byte in rx_buf.iter().take(n) {
            match parser.push(byte) {
                Some(Event::Packet(raw)) => {
                    Stats::bump(&STATS.back_packets);
                    if let Ok(packet) = Packet::decode(raw.ty, raw.payload) {
                        apply(&packet, &mut status);
                        changed = true;
                    }
                }
                Some(Event::Resynced { .. }) => Stats::bump(&STATS.back_resyncs),
                Some(Event::LostSync { .. }) => Stats::bump(&STATS.back_errors),
                None => {}
            }
        }
        if changed {
            HEAD_STATUS.sender().send(status.clone());
        }
    }
}

/// XY2-100 STATUS level from the head: debounced, published as the head's alarms.
#[embassy_executor::task]
pub async fn status_level_in(pin: Input<'static>, level: StatusLevel) {
    let mut input = StatusIn::new(pin, level);
    let mut status = HeadStatus::default();
    loop {
        let health = input.changed().await;
        Stats::bump(&STATS.status_changes);
        status.alarms = health.alarms();
        HEAD_STATUS.sender().send(status.clone());
    }
}

/// XY2-100 STATUS level to the controller, in the configured polarity: what the
/// bridge reports (`Bridge::xy2_status_line_high`: the head's alarms merged with the
/// bridge's own, e.g. input lost), and "fault" from reset on and whenever the
/// supervisor does not see valid input (a stalled bridge cannot report itself).
#[embassy_executor::task]
pub async fn status_level_out(pin: Output<'static>, level: StatusLevel) {
    let mut output = StatusOut::new(pin, level);
    let mut health = HEALTH.anon_receiver();
    let mut ticker = Ticker::every(Duration::from_millis(10));
    loop {
        let input_valid = health.try_get().is_some_and(|h| h.input_valid);
        output.set(if input_valid && CTRL_STATUS_OK.load(Ordering::Relaxed) {
            Health::Ok
        } else {
            Health::Fault
        });
        ticker.next().await;
    }
}

/// HANS-100 STATUS from the head (decode executor, optional work for the load
/// governor): decodes the SPI6 halves `line::hans_status_in` passes on (every
/// `shared::hans::follow::status_every`-th) with `shared::hans::rx::HansRx`, applies every frame
/// that passed its checks through `shared::hans::StatusReceiver` and publishes the
/// head's status to [`HEAD_STATUS`] when a half gave at least one frame (the bridge
/// counts that as the status being seen). Frames that failed a check are counted
/// (`status_faults`), never applied.
///
/// One receiver follows the signal across the halves it does not see, as the
/// controller input's decoder does (`shared::hans::follow`, the same rule): the
/// half number gives the words in between (halves not passed on, or dropped by the
/// governor), `HansRx::skip` is told of them and a settled lock coasts across, so
/// each half decoded publishes from its first frames on (from the second frame
/// wholly inside it: the first re-measures the phase) instead of hunting and
/// running the young fit, the receiver's most expensive state, all over again. A
/// new session (SPI6 lost words) or a gap beyond `HansRx::max_gap_words` starts a
/// fresh receiver. A young lock cannot coast (it is dropped at a gap), so while
/// the receiver's lock cannot coast yet (`HansRx::coasts`) the task
/// asks for every half ([`HANS_STATUS_CONTIGUOUS`]): an acquisition takes about two
/// contiguous halves, then the pairing's every second half resumes. The governor
/// decodes a half only with spare credit, so the controller input decoder keeps
/// its share.
#[embassy_executor::task]
pub async fn hans_status() {
    let mode = HansMode::Normal { channel: 1 };
    // The one constructor: the first receiver here, every fresh one in
    // `Follow::apply`.
    let fresh = || HansRx::new(HANS_FS_HZ, mode);
    let mut receiver = StatusReceiver::new();
    let mut status = HeadStatus::default();
    let mut rx = match fresh() {
        Ok(rx) => rx,
        Err(e) => {
            // Not expected (channel 1 and the 40 MHz fs are valid); without it
            // the head's status is never seen and the bridge reports it lost.
            defmt::error!("hans status: {}; no head status", e);
            return;
        }
    };
    let mut follow = Follow::new();
    let count = |ev: &RxEvent| {
        if let RxEvent::Fault {
            kind: FaultKind::CheckFailed,
            ..
        } = ev
        {
            Stats::bump(&STATS.status_faults);
        }
    };
    loop {
        let raw = HANS_STATUS_RAW.receive().await;
        if !governor::admit(Class::Optional, raw.ready).await {
            continue;
        }
        let first_word = raw.half.wrapping_mul(HANS_HALF as u32);
        let mut frames = 0u32;
        let mut busy = Busy::new();
        busy.run(|| {
            // The skip reports only a dropped lock's resyncs and missing periods.
            follow.apply(
                &mut rx,
                raw.session,
                first_word,
                HANS_HALF as u32,
                fresh,
                &mut |ev| count(&ev),
            );
            rx.push(&[&raw.words], &mut |ev| {
                count(&ev);
                if let RxEvent::Frame(frame) = ev {
                    receiver.apply(&frame, &mut status);
                    frames += 1;
                }
            })
        });
        busy.report(Class::Optional);
        HANS_STATUS_CONTIGUOUS.store(!rx.coasts(), Ordering::Relaxed);
        if frames > 0 {
            HEAD_STATUS.sender().send(status.clone());
        }
    }
}
