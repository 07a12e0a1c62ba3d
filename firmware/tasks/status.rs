//! Thread-mode status tasks: the XY3-100 backchannel (both sides), the XY2-100
//! STATUS level (head side in, controller side out) and the HANS-100 STATUS decoder
//! (head side). Status is slow (packets every
//! few milliseconds, a level that changes rarely), so none of this needs the
//! high-priority executor.

use embassy_stm32::gpio::{Input, Output};
use embassy_time::{with_timeout, Duration, Ticker};
use shared::model::HeadStatus;
use shared::xy2::{Health, StatusLevel};
use shared::xy3::back::neutral::apply;
use shared::xy3::back::{Event, Packet, Parser};

use core::sync::atomic::Ordering;

use shared::hans::rx::{HansRx, Mode as HansMode, RxEvent};
use shared::hans::StatusReceiver;
use shared::model::FaultKind;

use crate::board::HANS_FS_HZ;
use crate::channels::{
    Stats, BACK_RATE, BACK_TX, CTRL_STATUS_OK, HANS_STATUS_RAW, HEAD_STATUS, HEALTH, STATS,
};
use crate::drivers::backchannel::Backchannel;
use crate::drivers::status_level::{StatusIn, StatusOut};

/// How long a receive may wait before the rate signal is looked at again.
const RX_SLICE: Duration = Duration::from_millis(5);
/// With both directions running, how long a receive may hold back the bytes the
/// bridge queued for the controller.
const TX_POLL: Duration = Duration::from_millis(1);

/// XY3-100 backchannel on UART7. With `rx` it parses the head's packets into
/// [`HEAD_STATUS`]; with `tx` it sends what the bridge queued in [`BACK_TX`]
/// (`Bridge::xy3_back_poll`: the head's status merged with the bridge's alarms, its
/// own identification and frame-error counts, with the SYNC packets the bridge's
/// sender interleaves). [`BACK_RATE`] switches both directions once the bytes being
/// sent have left the UART.
#[embassy_executor::task]
pub async fn backchannel(mut back: Backchannel<'static>) {
    let mut parser = Parser::default();
    let mut status = HeadStatus::default();
    let mut rx_buf = [0u8; 64];
    let mut out = [0u8; 256];
    let has_rx = back.rx.is_some();
    loop {
        if let Some(rate) = BACK_RATE.try_take() {
            if let Some(tx) = back.tx.as_mut() {
                // The last byte of the old rate must be on the wire first.
                if tx.flush().await.is_err() {
                    Stats::bump(&STATS.back_errors);
                }
            }
            match back.set_baud(rate.baud()) {
                Ok(()) => defmt::info!("backchannel: {} baud", rate.baud()),
                Err(_) => defmt::error!("backchannel: cannot set {} baud", rate.baud()),
            }
        }
        if let Some(tx) = back.tx.as_mut() {
            let n = if has_rx {
                BACK_TX.try_read(&mut out).unwrap_or(0)
            } else {
                with_timeout(RX_SLICE, BACK_TX.read(&mut out))
                    .await
                    .unwrap_or(0)
            };
            if n > 0 && tx.write(out.get(..n).unwrap_or_default()).await.is_err() {
                Stats::bump(&STATS.back_errors);
            }
        }
        if let Some(rx) = back.rx.as_mut() {
            let slice = if back.tx.is_some() { TX_POLL } else { RX_SLICE };
            match with_timeout(slice, rx.read(&mut rx_buf)).await {
                Ok(Ok(n)) => {
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
                Ok(Err(_)) => Stats::bump(&STATS.back_errors),
                Err(_) => {}
            }
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
        let input_valid = health.try_get().is_some_and(|h| h.input_valid && !h.fault);
        output.set(if input_valid && CTRL_STATUS_OK.load(Ordering::Relaxed) {
            Health::Ok
        } else {
            Health::Fault
        });
        ticker.next().await;
    }
}

/// HANS-100 STATUS from the head: decodes the SPI6 halves `line::hans_status_in`
/// passes on (one in `HANS_STATUS_EVERY`, each a contiguous 205 us of signal) with a
/// fresh `shared::hans::rx::HansRx` per half (the halves are not contiguous with each
/// other), applies every frame that passed its checks through
/// `shared::hans::StatusReceiver` and publishes the head's status to [`HEAD_STATUS`]
/// when a half gave at least one frame (the bridge counts that as the status being
/// seen). Frames that failed a check are counted (`status_faults`), never applied.
/// Runs in thread mode: the decoder is too slow for the high-priority executor.
#[embassy_executor::task]
pub async fn hans_status() {
    let mode = HansMode::Normal { channel: 1 };
    let mut receiver = StatusReceiver::new();
    let mut status = HeadStatus::default();
    loop {
        let half = HANS_STATUS_RAW.receive().await;
        let mut rx = match HansRx::new(HANS_FS_HZ, mode) {
            Ok(rx) => rx,
            Err(e) => {
                defmt::error!("hans status: {}", e);
                return;
            }
        };
        let mut frames = 0u32;
        rx.push(&[&half], &mut |ev| match ev {
            RxEvent::Frame(frame) => {
                receiver.apply(&frame, &mut status);
                frames += 1;
            }
            RxEvent::Fault {
                kind: FaultKind::CheckFailed,
                ..
            } => Stats::bump(&STATS.status_faults),
            RxEvent::Fault { .. } => {}
        });
        if frames > 0 {
            HEAD_STATUS.sender().send(status.clone());
        }
    }
}
