//! Thread-mode status tasks: the XY3-100 backchannel (both sides) and the XY2-100
//! STATUS level (head side in, controller side out). Status is slow (packets every
//! few milliseconds, a level that changes rarely), so none of this needs the
//! high-priority executor.

use embassy_stm32::gpio::{Input, Output};
use embassy_time::{with_timeout, Duration, Instant, Ticker};
use shared::model::HeadStatus;
use shared::xy2::{Health, StatusLevel};
use shared::xy3::back::neutral::{apply, status_packet, StatusItem};
use shared::xy3::back::{Event, Packet, Parser, Sender, SEND_BUF_LEN};

use core::sync::atomic::Ordering;

use crate::channels::{Stats, BACK_RATE, CTRL_STATUS_OK, HEAD_STATUS, HEALTH, STATS};
use crate::drivers::backchannel::Backchannel;
use crate::drivers::status_level::{StatusIn, StatusOut};

/// How long a receive may wait before the transmit side gets its turn.
const RX_SLICE: Duration = Duration::from_millis(5);
/// One status item is sent per period (XY3-100 §6 leaves the rate to the head).
const STATUS_ITEM_PERIOD: Duration = Duration::from_millis(20);

/// XY3-100 backchannel. With `rx` it parses the head's packets into [`HEAD_STATUS`];
/// with `tx` it sends the head status to the controller, one item at a time, with the
/// SYNC packets `shared`'s [`Sender`] interleaves.
#[embassy_executor::task]
pub async fn backchannel(mut back: Backchannel<'static>) {
    let mut parser = Parser::default();
    let mut sender = Sender::default();
    let mut status = HeadStatus::default();
    let mut watch = HEAD_STATUS.anon_receiver();
    let mut rx_buf = [0u8; 64];
    let mut out = [0u8; SEND_BUF_LEN];
    let mut item = 0usize;
    let mut next_item = Instant::now();
    loop {
        if let Some(rate) = BACK_RATE.try_take() {
            match back.set_baud(rate.baud()) {
                Ok(()) => sender.note_rate_change(),
                Err(_) => defmt::error!("backchannel: cannot set {} baud", rate.baud()),
            }
        }
        if let Some(rx) = back.rx.as_mut() {
            match with_timeout(RX_SLICE, rx.read(&mut rx_buf)).await {
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
        } else {
            embassy_time::Timer::after(RX_SLICE).await;
        }
        if let Some(tx) = back.tx.as_mut() {
            let now_us = Instant::now().as_micros();
            let head = watch.try_get().unwrap_or_default();
            let mut n = 0;
            if Instant::now() >= next_item {
                next_item += STATUS_ITEM_PERIOD;
                item = (item + 1) % StatusItem::ALL.len();
                let packet = StatusItem::ALL
                    .get(item)
                    .and_then(|&i| status_packet(&head, i));
                if let Some(packet) = packet {
                    n = sender.send(now_us, &packet, &mut out).unwrap_or(0);
                }
            }
            if n == 0 {
                n = sender.poll(now_us, &mut out).unwrap_or(0);
            }
            if n > 0 && tx.write(out.get(..n).unwrap_or_default()).await.is_err() {
                Stats::bump(&STATS.back_errors);
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
